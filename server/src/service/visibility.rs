//! Who may see what, decided here and nowhere else. A public submission is everyone's; a
//! private one is its owner's and the administrators' (and, for a team's method, every
//! member's), and to anyone else it answers as missing, exactly like one that does not exist
//! (its existence is not told). A method is seen by everyone once one of its submissions is
//! public, and always by its owner (its team's members) and the administrators. Every page, API route and picture asks these functions, so the page and the
//! API of one thing can never disagree.

use crate::app::App;
use crate::domain::{MethodId, SubmissionId, TeamId, UserId};
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::methods::MethodRow;
use crate::store::submissions::SubmissionRow;

/// Whether `reader` may see what `owner` owns beyond what is public: the owner and the
/// administrators may.
pub fn sees_private(reader: Option<&User>, owner: Option<UserId>) -> bool {
    reader.is_some_and(|u| u.is_admin || Some(u.id) == owner)
}

/// [`sees_private`], or `reader` is a member of `team`, the team whose method it is.
pub async fn sees_private_of(
    app: &App,
    reader: Option<&User>,
    owner: Option<UserId>,
    team: Option<TeamId>,
) -> AppResult<bool> {
    if sees_private(reader, owner) {
        return Ok(true);
    }
    Ok(match (reader, team) {
        (Some(u), Some(team)) => app.store.is_member(team, u.id).await?,
        _ => false,
    })
}

/// Submission `id` if `reader` may see it; otherwise missing.
pub async fn submission(
    app: &App,
    id: SubmissionId,
    reader: Option<&User>,
) -> AppResult<SubmissionRow> {
    let submission = app.store.submission(id).await?.ok_or(AppError::NotFound)?;
    if !submission.is_public()
        && !sees_private_of(app, reader, submission.owner_id, submission.team_id).await?
    {
        return Err(AppError::NotFound);
    }
    Ok(submission)
}

/// A method `reader` may see, with the submissions of it they may see (newest first): every
/// one for its owner and the administrators, the public ones for everyone else; otherwise
/// missing.
pub async fn method(
    app: &App,
    id: MethodId,
    reader: Option<&User>,
) -> AppResult<(MethodRow, Vec<SubmissionRow>)> {
    let method = app.store.method(id).await?.ok_or(AppError::NotFound)?;
    if sees_private_of(app, reader, method.owner_id, method.team_id).await? {
        let submissions = app.store.submissions_of_method(id).await?;
        return Ok((method, submissions));
    }
    let submissions = app.store.public_submissions_of_method(id).await?;
    if submissions.is_empty() {
        return Err(AppError::NotFound);
    }
    Ok((method, submissions))
}
