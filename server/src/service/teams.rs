//! Teams: accounts that submit methods together. Any account creates a team and becomes its
//! first member; members invite accounts by name, and an invited account joins by accepting on
//! its account page. A team's method is submitted to, edited and seen whole (private
//! submissions included) by every member, and shown everywhere under the team's name; the
//! fair-use limit still counts each uploader's own submissions. A member leaves when they
//! like; the team's creator (or an administrator) removes members; both are written to the
//! audit log, since they change who may act on the team's methods.
//!
//! Teams and their members are public (a team is the owner shown on the boards). A request
//! about a team the caller is not a member of answers 404 naming the team as not one of theirs,
//! so nothing about the team's private methods is told.

use crate::app::App;
use crate::domain::{TeamName, UserName};
use crate::error::{AppError, AppResult};
use crate::store::StoreError;
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::store::methods::MethodRow;
use crate::store::teams::{MemberRow, TeamRow};

/// What a team's page shows to its reader.
pub struct TeamHome {
    pub team: TeamRow,
    pub members: Vec<MemberRow>,
    /// Its methods the reader may see: every one for its members and the administrators,
    /// those with a public submission for everyone else.
    pub methods: Vec<MethodRow>,
    /// The reader is a member (may invite, submit and leave).
    pub member: bool,
    /// The reader may remove members: the team's creator or an administrator.
    pub may_remove: bool,
}

/// The answer to a request about a team the caller is not a member of (or that does not
/// exist): the same words either way.
fn not_yours(name: &str) -> AppError {
    AppError::Unknown(format!("team `{name}` is not one of your teams"))
}

/// Creates team `name` with `user` as its creator and first member; a taken name is 409.
pub async fn create(app: &App, user: &User, name: &TeamName) -> AppResult<TeamRow> {
    match app.store.create_team(name, user.id).await {
        Ok(_) => team(app, name.as_str()).await,
        Err(StoreError::Unique { .. }) => Err(AppError::Conflict(format!(
            "a team named `{name}` exists already: choose another name"
        ))),
        Err(e) => Err(e.into()),
    }
}

async fn team(app: &App, name: &str) -> AppResult<TeamRow> {
    app.store
        .team_by_name(name)
        .await?
        .ok_or_else(|| AppError::Unknown(format!("there is no team named `{name}`")))
}

/// Team `name` if `user` is a member; otherwise the 404 of [`not_yours`].
pub async fn member_team(app: &App, user: &User, name: &TeamName) -> AppResult<TeamRow> {
    match app.store.team_by_name(name.as_str()).await? {
        Some(t) if app.store.is_member(t.id, user.id).await? => Ok(t),
        _ => Err(not_yours(name.as_str())),
    }
}

/// Team `name` as `reader` may see it.
pub async fn home(app: &App, name: &TeamName, reader: Option<&User>) -> AppResult<TeamHome> {
    let team = team(app, name.as_str()).await?;
    let member = match reader {
        Some(u) => app.store.is_member(team.id, u.id).await?,
        None => false,
    };
    let admin = reader.is_some_and(|u| u.is_admin);
    let mut methods = app.store.team_methods(team.id, !(member || admin)).await?;
    // A method under double-blind review is not listed as the team's to anyone outside it.
    methods.retain(|m| member || admin || !m.anonymous);
    Ok(TeamHome {
        members: app.store.members(team.id).await?,
        may_remove: admin || reader.is_some_and(|u| u.id == team.creator_id),
        methods,
        member,
        team,
    })
}

/// A member of team `name` invites the account `invitee`; it joins once it accepts. Inviting
/// a member is 409; inviting again keeps the first invitation.
pub async fn invite(app: &App, user: &User, name: &TeamName, invitee: &UserName) -> AppResult<()> {
    let team = member_team(app, user, name).await?;
    let invited = app
        .store
        .user_by_name(invitee.as_str())
        .await?
        .ok_or_else(|| AppError::Unknown(format!("there is no account named `{invitee}`")))?;
    if app.store.is_member(team.id, invited.id).await? {
        return Err(AppError::Conflict(format!(
            "`{invitee}` is a member of team `{name}` already"
        )));
    }
    app.store.invite(team.id, invited.id, user.id).await?;
    Ok(())
}

/// `user` accepts their invitation to team `name` and becomes a member.
pub async fn accept(app: &App, user: &User, name: &TeamName) -> AppResult<TeamRow> {
    let none = || AppError::Unknown(format!("no invitation to team `{name}` waits for you"));
    let team = app
        .store
        .team_by_name(name.as_str())
        .await?
        .ok_or_else(none)?;
    if !app.store.accept_invitation(team.id, user.id).await? {
        return Err(none());
    }
    Ok(team)
}

/// `user` leaves team `name` (audited): they can no longer submit to its methods, edit them or
/// see their private submissions, apart from their own uploads, which stay theirs.
pub async fn leave(app: &App, user: &User, name: &TeamName) -> AppResult<()> {
    let team = member_team(app, user, name).await?;
    if app.store.remove_member(team.id, user.id).await? {
        app.store
            .audit(user.id, AdminAction::LeaveTeam, &format!("team {name}"))
            .await?;
    }
    Ok(())
}

/// The team's creator or an administrator removes `member` from team `name` (audited). A
/// member who did not create the team is refused (403); anyone else is told the team is not
/// theirs.
pub async fn remove(app: &App, user: &User, name: &TeamName, member: &UserName) -> AppResult<()> {
    let team = match app.store.team_by_name(name.as_str()).await? {
        Some(t) if user.is_admin || t.creator_id == user.id => t,
        Some(t) if app.store.is_member(t.id, user.id).await? => {
            return Err(AppError::Forbidden(format!(
                "only the creator of team `{name}` ({}) or an administrator may remove a member",
                t.creator
            )));
        }
        _ => return Err(not_yours(name.as_str())),
    };
    let not_member = || AppError::Unknown(format!("`{member}` is not a member of team `{name}`"));
    let removed = app
        .store
        .user_by_name(member.as_str())
        .await?
        .ok_or_else(not_member)?;
    if !app.store.remove_member(team.id, removed.id).await? {
        return Err(not_member());
    }
    app.store
        .audit(
            user.id,
            AdminAction::RemoveTeamMember,
            &format!("team {name}: {member}"),
        )
        .await?;
    Ok(())
}
