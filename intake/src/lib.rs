//! What the service reads from bytes it is sent, parsed where nothing of the HTTP server or
//! the database is needed. Kept out of the `server` crate so that the fuzz targets (`fuzz/`),
//! built with coverage instrumentation from nothing on every CI run, link these parsers and
//! their few dependencies instead of the whole service (sqlx, rustls, askama, hyper's server:
//! about 330 crates to instrument and compile where the fuzz build has about 130).

pub mod archive;
pub mod domain;
pub mod upload;
pub mod uploaded_file;

pub use uploaded_file::UploadedFile;
