//! poseboard's service: the HTTP server, its storage, the evaluation workers, and the
//! `poseboard` command line. The evaluation itself lives in the `evaluator` crate; data flows
//! one way: upload → validate → queue → evaluate → store → page.

pub mod app;
pub mod board_cache;
pub mod cli;
pub mod clock;
pub mod config;
pub mod datasets;
pub mod demo;
pub mod domain;
pub mod error;
pub mod ops;
pub mod preflight;
pub mod service;
pub mod shutdown;
pub mod store;
pub mod web;
pub mod wording;
pub mod worker;
