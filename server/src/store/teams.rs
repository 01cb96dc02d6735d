//! Teams: accounts that submit methods together. A team has members, invitations waiting for
//! their account's answer, and methods of its own (`methods.team_id`); membership is what lets
//! an account submit to, edit and see the private submissions of a team's methods.

use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::methods::{MethodRow, SELECT_METHOD, method};
use super::{Store, StoreError, StoreResult};
use crate::clock::now_ms;
use crate::domain::{TeamId, TeamName, UserId};

/// A team, with the name of the account that created it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TeamRow {
    #[serde(skip)]
    pub id: TeamId,
    pub name: String,
    #[serde(skip)]
    pub creator_id: UserId,
    /// The account that created it: the one (with the administrators) who may remove members.
    pub creator: String,
    pub created_at: i64,
}

/// A member of a team.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MemberRow {
    pub name: String,
    pub joined_at: i64,
}

/// An invitation waiting for its account to accept it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InvitationRow {
    pub team: String,
    pub invited_by: String,
    pub created_at: i64,
}

const SELECT_TEAM: &str = "SELECT t.id, t.name, t.creator_id, u.name AS creator, t.created_at \
     FROM teams t JOIN users u ON u.id = t.creator_id";

fn team(row: &AnyRow) -> StoreResult<TeamRow> {
    Ok(TeamRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        creator_id: row.try_get("creator_id")?,
        creator: row.try_get("creator")?,
        created_at: row.try_get("created_at")?,
    })
}

impl Store {
    /// Creates team `name` with `creator` as its first member; a taken name is
    /// [`StoreError::Unique`].
    pub async fn create_team(&self, name: &TeamName, creator: UserId) -> StoreResult<TeamId> {
        let mut tx = self.write_transaction().await?;
        let now = now_ms();
        let row = sqlx::query(
            "INSERT INTO teams (name, creator_id, created_at) VALUES ($1, $2, $3) \
             ON CONFLICT (name) DO NOTHING RETURNING id",
        )
        .bind(name.as_str())
        .bind(creator)
        .bind(now)
        .fetch_optional(&mut *tx)
        .await?;
        let Some(row) = row else {
            tx.rollback().await?;
            return Err(StoreError::Unique {
                constraint: Some("teams_name".into()),
            });
        };
        let id: TeamId = row.try_get("id")?;
        sqlx::query("INSERT INTO team_members (team_id, user_id, joined_at) VALUES ($1, $2, $3)")
            .bind(id)
            .bind(creator)
            .bind(now)
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(id)
    }

    pub async fn team_by_name(&self, name: &str) -> StoreResult<Option<TeamRow>> {
        let sql = format!("{SELECT_TEAM} WHERE t.name = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(name)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(team).transpose()
    }

    /// The teams `user` is a member of, by name.
    pub async fn teams_of(&self, user: UserId) -> StoreResult<Vec<TeamRow>> {
        let sql = format!(
            "{SELECT_TEAM} WHERE EXISTS (SELECT 1 FROM team_members tm \
             WHERE tm.team_id = t.id AND tm.user_id = $1) ORDER BY t.name"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(user)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(team).collect()
    }

    pub async fn is_member(&self, team: TeamId, user: UserId) -> StoreResult<bool> {
        let row =
            sqlx::query("SELECT 1 AS one FROM team_members WHERE team_id = $1 AND user_id = $2")
                .bind(team)
                .bind(user)
                .fetch_optional(&self.pool)
                .await?;
        Ok(row.is_some())
    }

    /// The members of a team, in the order they joined.
    pub async fn members(&self, team: TeamId) -> StoreResult<Vec<MemberRow>> {
        let rows = sqlx::query(
            "SELECT u.name, tm.joined_at FROM team_members tm JOIN users u ON u.id = tm.user_id \
             WHERE tm.team_id = $1 ORDER BY tm.joined_at, u.name",
        )
        .bind(team)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(MemberRow {
                    name: r.try_get("name")?,
                    joined_at: r.try_get("joined_at")?,
                })
            })
            .collect()
    }

    /// Invites `user` to `team` on behalf of `by`; inviting again keeps the first invitation.
    pub async fn invite(&self, team: TeamId, user: UserId, by: UserId) -> StoreResult<()> {
        sqlx::query(
            "INSERT INTO team_invitations (team_id, user_id, invited_by, created_at) \
             VALUES ($1, $2, $3, $4) ON CONFLICT (team_id, user_id) DO NOTHING",
        )
        .bind(team)
        .bind(user)
        .bind(by)
        .bind(now_ms())
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// The invitations waiting for `user`, oldest first.
    pub async fn invitations_of(&self, user: UserId) -> StoreResult<Vec<InvitationRow>> {
        let rows = sqlx::query(
            "SELECT t.name AS team, u.name AS invited_by, i.created_at FROM team_invitations i \
             JOIN teams t ON t.id = i.team_id JOIN users u ON u.id = i.invited_by \
             WHERE i.user_id = $1 ORDER BY i.created_at, t.name",
        )
        .bind(user)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(InvitationRow {
                    team: r.try_get("team")?,
                    invited_by: r.try_get("invited_by")?,
                    created_at: r.try_get("created_at")?,
                })
            })
            .collect()
    }

    /// Makes `user` a member of `team` by its invitation, which it uses up; false (and
    /// nothing changed) when there was none.
    pub async fn accept_invitation(&self, team: TeamId, user: UserId) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let used = sqlx::query("DELETE FROM team_invitations WHERE team_id = $1 AND user_id = $2")
            .bind(team)
            .bind(user)
            .execute(&mut *tx)
            .await?;
        if used.rows_affected() == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        sqlx::query(
            "INSERT INTO team_members (team_id, user_id, joined_at) VALUES ($1, $2, $3) \
             ON CONFLICT (team_id, user_id) DO NOTHING",
        )
        .bind(team)
        .bind(user)
        .bind(now_ms())
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(true)
    }

    /// Ends `user`'s membership of `team`; false when they were not a member.
    pub async fn remove_member(&self, team: TeamId, user: UserId) -> StoreResult<bool> {
        let done = sqlx::query("DELETE FROM team_members WHERE team_id = $1 AND user_id = $2")
            .bind(team)
            .bind(user)
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected() == 1)
    }

    /// The methods of a team, by name: every one, or (`public_only`) those with a public
    /// submission.
    pub async fn team_methods(
        &self,
        team: TeamId,
        public_only: bool,
    ) -> StoreResult<Vec<MethodRow>> {
        let public = if public_only {
            "AND EXISTS (SELECT 1 FROM submissions s \
             WHERE s.method_id = m.id AND s.public = 1 AND s.hidden = 0)"
        } else {
            ""
        };
        let sql = format!("{SELECT_METHOD} WHERE m.team_id = $1 {public} ORDER BY m.name, m.id");
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(team)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(method).collect()
    }
}
