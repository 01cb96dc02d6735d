//! What a page or a download is drawn with, apart from the templates: SVG charts, leaderboard
//! exports (CSV, JSON, LaTeX), the OpenAPI document and the overlay picture of a target. Kept
//! apart from the views so that a view gathers data and a renderer only draws it.

pub mod chart;
pub mod exports;
pub mod feed;
pub mod openapi;
pub mod overlay;
