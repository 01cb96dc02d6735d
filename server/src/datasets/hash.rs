//! The content hash of a dataset lives in the evaluator ([`evaluator::content_hash`]), which
//! keys prepared datasets with it; the service names it here.

pub use evaluator::content_hash::content_hash;
