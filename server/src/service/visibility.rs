//! Who may see what, decided here and nowhere else. A public submission is everyone's; a
//! private one is its owner's and the administrators' (and, for a team's method, every
//! member's), and to anyone else it answers as missing, exactly like one that does not exist
//! (its existence is not told). A method is seen by everyone once one of its submissions is
//! public, and always by its owner (its team's members) and the administrators. Every page, API
//! route and picture asks these functions, so the page and the API of one thing can never
//! disagree.
//!
//! Who is behind a method is decided here too: a method under double-blind review (anonymous)
//! is named "anonymous" to everyone but its owner and the administrators, without authors,
//! paper or code links, by [`discloses`]. What every reader sees alike (the boards, their
//! exports and snapshots, the recent list and its feed) is the public's view.

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

/// What the public is shown instead of the owner of an anonymous method.
pub const ANONYMOUS: &str = "anonymous";

/// Whether `reader` is told who is behind a method of `owner` (its owner's name, authors,
/// paper and code links): always, unless it is `anonymous`; then only its owner and the
/// administrators are, so that double-blind review holds on every page, API answer and file.
pub fn discloses(reader: Option<&User>, owner: Option<UserId>, anonymous: bool) -> bool {
    !anonymous || sees_private(reader, owner)
}

/// `method` as `reader` may see it: an anonymous method's owner, authors and links are left out
/// for anyone [`discloses`] does not tell (its description, an account of the method, stays).
pub fn method_as_seen(mut method: MethodRow, reader: Option<&User>) -> MethodRow {
    if !discloses(reader, method.owner_id, method.anonymous) {
        method.owner = ANONYMOUS.to_string();
        method.team = None;
        method.authors.clear();
        method.paper_url.clear();
        method.code_url.clear();
    }
    method
}

/// The owner a list every reader sees alike names (a board row, the recent list, the feed).
pub fn public_owner(owner: String, anonymous: bool) -> String {
    if discloses(None, None, anonymous) {
        owner
    } else {
        ANONYMOUS.to_string()
    }
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

/// A method `reader` may see (as [`method_as_seen`]), with the submissions of it they may see
/// (newest first): every one for its owner and the administrators, the public ones for everyone
/// else; otherwise missing.
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
    Ok((method_as_seen(method, reader), submissions))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::MethodId;

    fn user(id: i64, is_admin: bool) -> User {
        User {
            id: UserId::new(id),
            name: format!("user{id}"),
            is_admin,
        }
    }

    #[test]
    fn an_anonymous_method_is_told_only_to_its_owner_and_the_administrators() {
        let (owner, other, admin) = (user(1, false), user(2, false), user(3, true));
        let mut method = MethodRow {
            id: MethodId::new(7),
            name: "blind".into(),
            owner: "user1".into(),
            owner_id: Some(owner.id),
            team: None,
            team_id: None,
            description: "how it works".into(),
            authors: "A. Author".into(),
            year: Some(2026),
            paper_url: "https://example.org/paper".into(),
            code_url: "https://example.org/code".into(),
            training_data: None,
            detection_modality: None,
            modality: None,
            refinement: String::new(),
            detections: String::new(),
            model_scope: None,
            hardware: String::new(),
            onboarding: None,
            objects: None,
            anonymous: true,
            created_at: 0,
        };
        for reader in [Some(&owner), Some(&admin)] {
            assert_eq!(method_as_seen(method.clone(), reader), method);
        }
        for reader in [None, Some(&other)] {
            let seen = method_as_seen(method.clone(), reader);
            assert_eq!(seen.owner, ANONYMOUS);
            assert!(seen.authors.is_empty() && seen.paper_url.is_empty());
            assert!(seen.code_url.is_empty());
            assert_eq!(seen.description, "how it works");
            // Nor the team behind it.
            let team = MethodRow {
                team: Some("zq_team".into()),
                ..method.clone()
            };
            assert_eq!(method_as_seen(team, reader).team, None);
        }
        assert_eq!(public_owner("user1".into(), true), ANONYMOUS);
        method.anonymous = false;
        assert_eq!(method_as_seen(method.clone(), None), method);
        assert_eq!(public_owner("user1".into(), false), "user1");
    }
}
