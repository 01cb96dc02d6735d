//! Running the service in production: readiness, Prometheus metrics and logging. Kept apart
//! from the use cases so that what an operator watches can change without touching them.

pub mod health;
pub mod logging;
pub mod metrics;
