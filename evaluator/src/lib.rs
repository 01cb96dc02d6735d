//! poseboard's evaluator: reads BOP datasets and BOP'19 result files, renders object models
//! into depth maps on the CPU, computes the pose errors of the BOP benchmark (VSD, MSSD, MSPD,
//! ADD, ADI, RE, TE), matches estimates to ground truth and computes the scores of the ECCV'18
//! paper and of the BOP'19 challenge, agreeing with the official bop_toolkit; and scores the 2D
//! detection and segmentation tasks of BOP'22 with COCO's metrics ([`coco`]).
//!
//! A pure library: no HTTP, no database, no global state. Parallelism runs on the caller's
//! rayon pool, so a service can bound it.

pub mod bootstrap;
pub mod coco;
pub mod content_hash;
pub mod dataset;
pub mod depth_files;
mod depth_png;
pub mod detection;
pub mod error;
pub mod fisheye;
pub mod matching;
pub mod math;
pub mod mesh;
pub mod outcomes;
pub mod overlay;
pub mod pipeline;
pub mod ply;
pub mod pose_error;
pub mod prepared;
pub mod progress;
pub mod protocol;
pub mod render;
pub mod report;
pub mod results;
pub mod score;
pub mod selection;
pub mod sensors;
pub mod stats;
pub mod supported_errors;
pub mod visibility;

pub use dataset::Dataset;
pub use error::{Error, Result};
pub use pipeline::{Evaluation, NoProgress, Progress, evaluate, evaluate_prepared};
pub use prepared::Prepared;
pub use protocol::{Protocol, ProtocolName};
pub use report::Report;
pub use results::Results;
