//! Who sees a submission, decided in one place for every caller (the API, the buttons on the
//! pages, a re-upload). A submission is private to its owner (and the administrators) until
//! published; everyone else gets 404 for all of it, as for one that does not exist. Red flags
//! of the pre-flight check (metres, most targets without an estimate, objects the dataset
//! lacks) would put meaningless scores on the boards, so they hold publication back until the
//! owner confirms. Every change goes through the store, which bumps the board version.

use crate::app::App;
use crate::domain::{SubmissionId, Visibility};
use crate::error::{AppError, AppResult};
use crate::preflight::{Preflight, RedFlag};
use crate::service::moderation;
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::store::submissions::SubmissionRow;

/// Where a submission stands, as its page and JSON say it.
pub fn state(s: &SubmissionRow) -> String {
    match (s.visibility, s.held) {
        (Visibility::Public, _) if s.hidden => "public, but hidden by an administrator".to_string(),
        (Visibility::Public, _) => "public".to_string(),
        (Visibility::Private, true) => format!("held: {}", reasons(&s.preflight.red_flags)),
        (Visibility::Private, false) => {
            "private: only you (and the administrators) can see it".to_string()
        }
    }
}

fn reasons(flags: &[RedFlag]) -> String {
    flags
        .iter()
        .map(RedFlag::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// What a new upload becomes: the visibility it gets and whether its publication is held.
pub fn initial(asked: Visibility, preflight: &Preflight) -> (Visibility, bool) {
    match asked {
        Visibility::Public if !preflight.red_flags.is_empty() => (Visibility::Private, true),
        v => (v, false),
    }
}

/// Submission `id` if `user` owns it or administers the service; 404 otherwise, whether it
/// exists or not.
pub async fn owned(app: &App, user: &User, id: SubmissionId) -> AppResult<SubmissionRow> {
    match app.store.submission(id).await? {
        Some(s) if user.is_admin || s.owner_id == Some(user.id) => Ok(s),
        _ => Err(AppError::NotFound),
    }
}

/// Publishes or withdraws a submission for its owner or an administrator. Publishing a file
/// with red flags needs `confirm`; without it the answer is 409 naming them, and the
/// submission is marked held (it stays private).
pub async fn set_visibility(
    app: &App,
    user: &User,
    id: SubmissionId,
    visibility: Visibility,
    confirm: bool,
) -> AppResult<SubmissionRow> {
    let s = owned(app, user, id).await?;
    apply(app, s, visibility, confirm).await
}

/// [`set_visibility`] on a submission already known to be the caller's.
pub async fn apply(
    app: &App,
    mut s: SubmissionRow,
    visibility: Visibility,
    confirm: bool,
) -> AppResult<SubmissionRow> {
    let flags = &s.preflight.red_flags;
    let publishing = visibility == Visibility::Public && s.visibility == Visibility::Private;
    if publishing && !flags.is_empty() && !confirm {
        app.store.hold_publication(s.id).await?;
        return Err(AppError::Conflict(format!(
            "publication is held: {}; confirm to publish anyway (`confirm=true`)",
            reasons(flags)
        )));
    }
    if !app.store.set_visibility(s.id, visibility).await? {
        return Err(AppError::NotFound);
    }
    s.visibility = visibility;
    s.held = false;
    Ok(s)
}

/// Deletes a submission for its owner (or an administrator, recorded in the audit log): its
/// file, scores and errors go with it, and the boards change.
pub async fn delete(app: &App, user: &User, id: SubmissionId) -> AppResult<()> {
    let s = owned(app, user, id).await?;
    if s.owner_id != Some(user.id) {
        return moderation::submission_action(app, user, id, AdminAction::Delete).await;
    }
    let deleted = app
        .store
        .delete_submission(id)
        .await?
        .ok_or(AppError::NotFound)?;
    moderation::discard_file(app, &deleted).await;
    Ok(())
}
