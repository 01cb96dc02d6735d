//! The audit log: who did what, and when, for every administrator action, and for every member
//! leaving a team or removed from it (which changes who may act on the team's methods).

use std::fmt;
use std::str::FromStr;

use serde::Serialize;
use sqlx::Row;

use super::{Store, StoreResult, parse_column};
use crate::clock::now_ms;
use crate::domain::UserId;

/// What an administrator can do, and a team's member leaving or being removed; stored as its
/// name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum AdminAction {
    #[serde(rename = "hide")]
    Hide,
    #[serde(rename = "unhide")]
    Unhide,
    #[serde(rename = "rerun")]
    Rerun,
    #[serde(rename = "delete")]
    Delete,
    #[serde(rename = "add dataset")]
    AddDataset,
    #[serde(rename = "retire dataset")]
    RetireDataset,
    #[serde(rename = "core dataset")]
    CoreDataset,
    #[serde(rename = "not core dataset")]
    NotCoreDataset,
    #[serde(rename = "snapshot")]
    Snapshot,
    #[serde(rename = "leave team")]
    LeaveTeam,
    #[serde(rename = "remove team member")]
    RemoveTeamMember,
    #[serde(rename = "save group")]
    SaveGroup,
    #[serde(rename = "delete group")]
    DeleteGroup,
    #[serde(rename = "create challenge")]
    CreateChallenge,
    #[serde(rename = "override award")]
    OverrideAward,
}

impl AdminAction {
    pub fn as_str(self) -> &'static str {
        match self {
            AdminAction::Hide => "hide",
            AdminAction::Unhide => "unhide",
            AdminAction::Rerun => "rerun",
            AdminAction::Delete => "delete",
            AdminAction::AddDataset => "add dataset",
            AdminAction::RetireDataset => "retire dataset",
            AdminAction::CoreDataset => "core dataset",
            AdminAction::NotCoreDataset => "not core dataset",
            AdminAction::Snapshot => "snapshot",
            AdminAction::LeaveTeam => "leave team",
            AdminAction::RemoveTeamMember => "remove team member",
            AdminAction::SaveGroup => "save group",
            AdminAction::DeleteGroup => "delete group",
            AdminAction::CreateChallenge => "create challenge",
            AdminAction::OverrideAward => "override award",
        }
    }
}

impl FromStr for AdminAction {
    type Err = ();
    fn from_str(s: &str) -> Result<Self, ()> {
        [
            AdminAction::Hide,
            AdminAction::Unhide,
            AdminAction::Rerun,
            AdminAction::Delete,
            AdminAction::AddDataset,
            AdminAction::RetireDataset,
            AdminAction::CoreDataset,
            AdminAction::NotCoreDataset,
            AdminAction::Snapshot,
            AdminAction::LeaveTeam,
            AdminAction::RemoveTeamMember,
            AdminAction::SaveGroup,
            AdminAction::DeleteGroup,
            AdminAction::CreateChallenge,
            AdminAction::OverrideAward,
        ]
        .into_iter()
        .find(|a| a.as_str() == s)
        .ok_or(())
    }
}

impl fmt::Display for AdminAction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AuditEntry {
    pub actor: String,
    pub action: AdminAction,
    pub target: String,
    pub at: i64,
}

impl Store {
    pub async fn audit(
        &self,
        actor_id: UserId,
        action: AdminAction,
        target: &str,
    ) -> StoreResult<()> {
        sqlx::query("INSERT INTO audit_log (actor_id, action, target, at) VALUES ($1, $2, $3, $4)")
            .bind(actor_id)
            .bind(action.as_str())
            .bind(target)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// The latest administrator actions, newest first.
    pub async fn audit_log(&self, limit: i64) -> StoreResult<Vec<AuditEntry>> {
        let rows = sqlx::query(
            "SELECT u.name AS actor, a.action, a.target, a.at FROM audit_log a \
             JOIN users u ON u.id = a.actor_id ORDER BY a.id DESC LIMIT $1",
        )
        .bind(limit)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(AuditEntry {
                    actor: r.try_get("actor")?,
                    action: parse_column("action", r.try_get("action")?)?,
                    target: r.try_get("target")?,
                    at: r.try_get("at")?,
                })
            })
            .collect()
    }
}
