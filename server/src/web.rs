//! The web layer: everything that speaks HTTP. The router and its tower layers, the handlers,
//! the views that gather each page's data, the renderers (charts, exports, the OpenAPI
//! document, overlay pictures), the extractors of who is asking, and the mapping of errors to
//! statuses. It is the only layer that names axum or askama: the services below it take and
//! return plain values, so the worker and the command line use them without a web server.

pub mod auth;
pub mod error;
pub mod render;
pub mod routes;
pub mod serve;
pub mod views;
