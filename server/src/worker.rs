//! The evaluation workers: they claim queued submissions from the store, evaluate them on the
//! evaluation threads and store the scores. They run in the server process or alone (`poseboard
//! worker`), so they depend on the services and the store, never on the web layer.

pub mod jobs;
