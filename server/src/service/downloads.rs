//! What an owner downloads of a submission: the file as uploaded and every evaluated
//! estimate's errors. Both are theirs alone (and the administrators'), whatever the
//! submission's visibility: a public score does not publish the estimates behind it.

use evaluator::protocol::ProtocolName;

use crate::app::App;
use crate::datasets::uploaded_file;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::service::publishing;
use crate::store::accounts::User;
use crate::store::submissions::SubmissionRow;

/// Submission `id`'s file as it was sent, for `user` if they own it (see
/// [`publishing::owned`]).
pub async fn file(app: &App, user: &User, id: SubmissionId) -> AppResult<(SubmissionRow, Vec<u8>)> {
    let s = publishing::owned(app, user, id).await?;
    let bytes = uploaded_file::fetch(&app.store, &app.config.submissions_dir(), &s.file_sha256)
        .await
        .map_err(|e| AppError::failed("reading the uploaded file", e))?;
    Ok((s, bytes))
}

/// Every evaluated estimate's errors of submission `id` under `protocol`, as JSON (the layout
/// of `poseboard eval --errors-out`), for `user` if they own it; missing when not evaluated
/// under `protocol`.
pub async fn errors(
    app: &App,
    user: &User,
    id: SubmissionId,
    protocol: ProtocolName,
) -> AppResult<Vec<u8>> {
    let s = publishing::owned(app, user, id).await?;
    let stored = app
        .store
        .estimate_errors(s.id, protocol)
        .await?
        .ok_or(AppError::NotFound)?;
    // Inflating is CPU work: off the async threads.
    tokio::task::spawn_blocking(move || stored.json())
        .await
        .map_err(|e| AppError::failed("inflating the errors", e))?
        .map_err(AppError::from)
}
