//! What anyone may list, signed in or not: the datasets served, the methods with a public
//! submission, the latest public submissions. Plain reads, but they go through here like every
//! other use case so that the web layer never reaches the store, and a rule added to a list
//! (paging, a filter) has one place to live.

use crate::app::App;
use crate::error::AppResult;
use crate::store::datasets::DatasetRow;
use crate::store::methods::MethodRow;
use crate::store::submissions::SubmissionRow;

/// The datasets served (not retired), by name.
pub async fn datasets(app: &App) -> AppResult<Vec<DatasetRow>> {
    Ok(app.store.datasets().await?)
}

/// The methods with a public submission, by name.
pub async fn public_methods(app: &App) -> AppResult<Vec<MethodRow>> {
    Ok(app.store.public_methods().await?)
}

/// The latest public submissions, newest first, at most `limit`.
pub async fn recent_submissions(app: &App, limit: i64) -> AppResult<Vec<SubmissionRow>> {
    Ok(app.store.recent_public_submissions(limit).await?)
}
