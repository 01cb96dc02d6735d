//! poseboard's service: the HTTP server, its storage, the evaluation workers, and the
//! `poseboard` command line. The evaluation itself lives in the `evaluator` crate; data flows
//! one way: upload → validate → queue → evaluate → store → page.

pub mod accounts;
pub mod app;
pub mod auth;
pub mod board_cache;
pub mod chart;
pub mod cli;
pub mod clock;
pub mod config;
pub mod dataset_config;
pub mod dataset_hash;
pub mod demo;
pub mod demo_setup;
pub mod domain;
pub mod error;
pub mod exports;
pub mod jobs;
pub mod logging;
pub mod methods;
pub mod metrics;
pub mod moderation;
pub mod openapi;
pub mod ops;
pub mod overlay;
pub mod parsed_files;
pub mod preflight;
pub mod publishing;
pub mod rescoring;
pub mod routes;
pub mod serve;
pub mod shutdown;
pub mod store;
pub mod submissions;
pub mod targets;
pub mod uploaded_file;
pub mod views;
pub mod wording;
