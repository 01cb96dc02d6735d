//! A method's home, and what its owner does with it. Its page (and JSON twin) gathers where
//! the method stands on every board and its submissions over time, as [`visibility`] lets the
//! reader see them. The owner (any member of a team's method's team, or an administrator)
//! states its details and chooses which submission is its entry on a dataset; anyone else who
//! can see the method is refused (403), and a method or submission they cannot see answers as
//! missing.

use crate::app::App;
use crate::domain::{MethodForm, MethodId, SubmissionId};
use crate::error::{AppError, AppResult};
use crate::service::leaderboard::{self, Standing};
use crate::service::submission_details::{self, Owned};
use crate::service::visibility;
use crate::store::accounts::User;
use crate::store::methods::MethodRow;
use crate::store::submissions::{Status, SubmissionRow};

/// What a method's page shows.
pub struct MethodHome {
    pub method: MethodRow,
    /// Its public entries' scores and ranks, per board and dataset.
    pub standings: Vec<Standing>,
    /// Its submissions the reader may see, newest first, with their headline scores.
    pub submissions: Vec<Owned>,
    /// The reader may change it (see [`may_change`]).
    pub may_edit: bool,
}

/// Method `id` as `reader` may see it (see [`visibility::method`]): to its owner even before
/// anything of it is public.
pub async fn home(app: &App, id: MethodId, reader: Option<&User>) -> AppResult<MethodHome> {
    let (method, rows) = visibility::method(app, id, reader).await?;
    let may_edit = match reader {
        Some(user) => may_change(app, user, &method).await?,
        None => false,
    };
    Ok(MethodHome {
        may_edit,
        standings: leaderboard::standings(app, id).await?,
        submissions: submission_details::of_method(app, id, rows).await?,
        method,
    })
}

/// Whether `user` may change `method`: its owner, any member of its team, or an administrator.
async fn may_change(app: &App, user: &User, method: &MethodRow) -> AppResult<bool> {
    visibility::sees_private_of(app, Some(user), method.owner_id, method.team_id).await
}

/// Method `id` if `user` may change it; a method they can see but not change is refused
/// (403, naming no one), one they cannot see is missing.
async fn changeable(app: &App, user: &User, id: MethodId) -> AppResult<MethodRow> {
    let method = app.store.method(id).await?.ok_or(AppError::NotFound)?;
    if !may_change(app, user, &method).await? {
        let public = !app.store.public_submissions_of_method(id).await?.is_empty();
        return Err(if public {
            // An anonymous method's team is not told: that would name who is behind it.
            AppError::Forbidden(match &method.team {
                Some(team) if !method.anonymous => {
                    format!("only the members of team `{team}` may change it")
                }
                _ => "only the method's owner may change it".into(),
            })
        } else {
            AppError::NotFound
        });
    }
    Ok(method)
}

/// Replaces the details `form` gives (the others stay) and returns the method as stored.
pub async fn edit(app: &App, user: &User, id: MethodId, form: MethodForm) -> AppResult<MethodRow> {
    let method = changeable(app, user, id).await?;
    let details = form.parse(method.as_form())?;
    app.store.set_method_details(id, &details).await?;
    app.store.method(id).await?.ok_or(AppError::NotFound)
}

/// Ends a method's double-blind review in one action, its owner's (or an administrator's):
/// every live page, board and list names the owner again, with the authors and links. A
/// snapshot taken meanwhile stays as it was taken, anonymous: it is a frozen record.
pub async fn reveal(app: &App, user: &User, id: MethodId) -> AppResult<MethodRow> {
    changeable(app, user, id).await?;
    app.store.set_method_anonymous(id, false).await?;
    app.store.method(id).await?.ok_or(AppError::NotFound)
}

/// Why `s` cannot be pinned, if it cannot: only a public finished submission is ever an entry,
/// so a pin on any other would be answered yet change nothing.
pub fn pin_refusal(s: &SubmissionRow) -> Option<String> {
    let why = match s.status {
        Status::Queued => "it is queued; pin it once its scores are in",
        Status::Running => "it is being evaluated; pin it once its scores are in",
        Status::Failed => "its evaluation failed",
        Status::Done if s.hidden => "an administrator hid it",
        Status::Done if s.held => {
            "its publication is held back by red flags; confirm publishing it first"
        }
        Status::Done if !s.is_public() => "it is private; publish it first",
        Status::Done => return None,
    };
    Some(format!(
        "only a public finished submission can be pinned: {why}"
    ))
}

/// Pins a submission as its method's entry on its dataset (for every protocol), or unpins it:
/// the best public finished submission is the entry again, by whoever may change the method
/// (its owner, any member of a team's method's team, an administrator). Pinning one that
/// cannot be an entry is refused (409) with the reason; unpinning always may.
pub async fn pin(
    app: &App,
    user: &User,
    submission_id: SubmissionId,
    pinned: bool,
) -> AppResult<()> {
    let submission = app
        .store
        .submission(submission_id)
        .await?
        .ok_or(AppError::NotFound)?;
    let method = app
        .store
        .method(submission.method_id)
        .await?
        .ok_or(AppError::NotFound)?;
    if !may_change(app, user, &method).await? {
        return Err(if submission.is_public() {
            AppError::Forbidden("only the method's owner may choose its entry".into())
        } else {
            AppError::NotFound
        });
    }
    if let Some(why) = pin_refusal(&submission).filter(|_| pinned) {
        return Err(AppError::Conflict(why));
    }
    app.store.set_pinned(submission_id, pinned).await?;
    Ok(())
}
