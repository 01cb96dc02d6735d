//! The files behind the evaluation: dataset folders (their options and content hashes), their
//! prepared forms, and result files (uploaded, compressed and kept; parsed again for pictures).
//! The evaluation itself is the `evaluator` crate's; this is how the service finds and keeps
//! its inputs.

pub mod config;
pub mod hash;
pub mod parsed_files;
pub mod prepared;
pub mod uploaded_file;
