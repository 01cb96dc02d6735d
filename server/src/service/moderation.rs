//! What administrators do, whichever way they ask (the API or a button on a page): hide, show,
//! re-run and delete submissions, add and retire datasets. Every action is written to the audit
//! log.

use crate::app::App;
use crate::datasets::uploaded_file;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::audit::{AdminAction, AuditEntry};
use crate::store::datasets::DatasetRow;
use crate::store::submissions::Deleted;

/// Applies a submission action (hide, unhide, rerun, delete) and records it.
pub async fn submission_action(
    app: &App,
    actor: &User,
    id: SubmissionId,
    action: AdminAction,
) -> AppResult<()> {
    let done = match action {
        AdminAction::Hide => app.store.set_hidden(id, true).await?,
        AdminAction::Unhide => app.store.set_hidden(id, false).await?,
        AdminAction::Rerun => {
            let queued = app.store.rerun(id).await?;
            app.wake.notify_waiters();
            queued
        }
        AdminAction::Delete => match app.store.delete_submission(id).await? {
            Some(deleted) => {
                discard_file(app, &deleted).await;
                true
            }
            None => false,
        },
        AdminAction::AddDataset
        | AdminAction::RetireDataset
        | AdminAction::CoreDataset
        | AdminAction::NotCoreDataset
        | AdminAction::Snapshot
        | AdminAction::LeaveTeam
        | AdminAction::RemoveTeamMember
        | AdminAction::SaveGroup
        | AdminAction::DeleteGroup
        | AdminAction::CreateChallenge
        | AdminAction::OverrideAward => return Err(AppError::NotFound),
    };
    if !done {
        return Err(AppError::BadRequest(format!(
            "cannot {action} submission {id} (missing, or not finished for a re-run)"
        )));
    }
    app.store
        .audit(actor.id, action, &format!("submission {id}"))
        .await?;
    Ok(())
}

/// Serves the dataset in a folder of the datasets directory, named by a plain folder name;
/// a retired dataset of that name is served again.
pub async fn add_dataset(app: &App, actor: &User, folder: &str) -> AppResult<DatasetRow> {
    // Only a plain folder name: no path separators, no `..`.
    if folder.is_empty() || folder.contains(['/', '\\']) || folder.starts_with('.') {
        return Err(AppError::BadRequest(
            "`name` must be a folder name inside the datasets directory".into(),
        ));
    }
    let mut row = app
        .register_dataset(&app.config.datasets_dir().join(folder))
        .await?;
    if row.retired {
        app.store.revive_dataset(&row.name).await?;
        row.retired = false;
    }
    app.store
        .audit(actor.id, AdminAction::AddDataset, &row.name)
        .await?;
    Ok(row)
}

/// Stops serving a dataset (its submissions and scores stay).
pub async fn retire_dataset(app: &App, actor: &User, name: &str) -> AppResult<()> {
    if !app.store.retire_dataset(name).await? {
        return Err(AppError::NotFound);
    }
    app.store
        .audit(actor.id, AdminAction::RetireDataset, name)
        .await?;
    Ok(())
}

/// Makes a served dataset core (a column of the main leaderboards, in their average) or not.
pub async fn set_core(app: &App, actor: &User, name: &str, core: bool) -> AppResult<()> {
    if !app.store.set_dataset_core(name, core).await? {
        return Err(AppError::NotFound);
    }
    let action = if core {
        AdminAction::CoreDataset
    } else {
        AdminAction::NotCoreDataset
    };
    app.store.audit(actor.id, action, name).await?;
    Ok(())
}

/// The latest administrator actions (at most `limit`), newest first.
pub async fn audit_log(app: &App, limit: i64) -> AppResult<Vec<AuditEntry>> {
    Ok(app.store.audit_log(limit).await?)
}

/// What stays of a deleted submission's file once no other submission has its content goes
/// too: the database copy went with the row, a disk copy an older version kept is removed, and
/// its parse for the target pictures is dropped from memory.
pub(crate) async fn discard_file(app: &App, deleted: &Deleted) {
    if deleted.file_unused {
        let legacy =
            uploaded_file::legacy_path(&app.config.submissions_dir(), &deleted.file_sha256);
        let _ = tokio::fs::remove_file(legacy).await;
        app.parsed_files.forget(&deleted.file_sha256);
    }
}
