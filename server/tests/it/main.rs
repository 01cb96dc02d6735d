//! The server's integration tests, as one binary: a module per area (each was a test binary of
//! its own) and `common`, the harness they share.
//!
//! Why one binary: each test binary linked the whole server and its dependencies, and with ~30
//! of them CI spent much of its time linking; one binary links once. The tests run on threads
//! of one process, so nothing here may change process-wide state (environment, current
//! folder): settings reach a server through its command line and the environment of its
//! child process, and every test makes its own folders, databases and ports.
//! `server/tests/layers.rs` stays apart: it reads sources and needs no server.
//!
//! `cargo test -p server --test it MODULE::` runs one area.

mod accounts;
mod admin;
mod anonymous;
mod backup;
mod board_cache;
mod bop24;
mod bop24_cli;
mod bop24_pages;
mod broken_dataset;
mod browser;
mod challenge_datasets;
mod challenges;
mod coco_boards;
mod coco_cli;
mod coco_service;
mod common;
mod compare;
mod compare_tasks;
mod connections;
mod copy_db;
mod datasets;
mod db_faults;
mod demo_start;
mod deployment;
mod eval_cli;
mod exports;
mod fair_use;
mod first_use;
mod full_disk;
mod groups;
mod hostile_input;
mod method_page;
mod ops;
mod own_cluster;
mod parallel_uploads;
mod pinning;
mod polish;
mod prepare_cli;
mod prepared_service;
mod publishing;
mod ranking;
mod reader_pages;
mod recent;
mod recovery;
mod reupload;
mod scale_out;
mod security;
mod snapshots;
mod store;
mod submit_cli;
mod submit_form;
mod target_png;
mod teams;
mod trust;
mod unicode_names;
mod uploads;
