//! Long work reports its progress: an evaluation counts estimates, a dataset's preparation
//! images; the CLI draws a bar, the service stores a percentage.

/// Told how much work there is and how much is done.
pub trait Progress: Sync {
    fn start(&self, total: u64);
    fn advance(&self, done: u64);
}

/// For callers that do not follow progress.
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&self, _: u64) {}
    fn advance(&self, _: u64) {}
}
