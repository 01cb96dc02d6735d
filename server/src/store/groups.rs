//! Named groups of datasets, each a board's columns (`?group=NAME`). Members are dataset names,
//! so a group may name a dataset not served yet; which members a board shows is the service's
//! rule. The default group (`core`) is not stored here but in the datasets' core flags.

use serde::Serialize;
use sqlx::Row;

use super::{Store, StoreResult};
use crate::clock::now_ms;
use crate::domain::{DatasetName, GroupName};

/// A stored group with its members, by name.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupRow {
    pub name: String,
    pub datasets: Vec<String>,
}

impl Store {
    /// Every stored group, in the order they were created, with their members by name.
    pub async fn groups(&self) -> StoreResult<Vec<GroupRow>> {
        let rows = sqlx::query(
            "SELECT g.name, m.dataset FROM dataset_groups g \
             LEFT JOIN dataset_group_members m ON m.group_id = g.id ORDER BY g.id, m.dataset",
        )
        .fetch_all(&self.pool)
        .await?;
        let mut out: Vec<GroupRow> = Vec::new();
        for r in &rows {
            let name: String = r.try_get("name")?;
            let dataset: Option<String> = r.try_get("dataset")?;
            if out.last().is_none_or(|g| g.name != name) {
                out.push(GroupRow {
                    name,
                    datasets: Vec::new(),
                });
            }
            if let (Some(d), Some(g)) = (dataset, out.last_mut()) {
                g.datasets.push(d);
            }
        }
        Ok(out)
    }

    /// Creates group `name` with `datasets`, or replaces the members of the group of that
    /// name; true when it was created. The boards change with it.
    pub async fn save_group(
        &self,
        name: &GroupName,
        datasets: &[DatasetName],
    ) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let existing: Option<i64> = sqlx::query("SELECT id FROM dataset_groups WHERE name = $1")
            .bind(name.as_str())
            .fetch_optional(&mut *tx)
            .await?
            .map(|r| r.try_get("id"))
            .transpose()?;
        let (id, created) = match existing {
            Some(id) => {
                sqlx::query("DELETE FROM dataset_group_members WHERE group_id = $1")
                    .bind(id)
                    .execute(&mut *tx)
                    .await?;
                (id, false)
            }
            None => {
                let id: i64 = sqlx::query(
                    "INSERT INTO dataset_groups (name, created_at) VALUES ($1, $2) RETURNING id",
                )
                .bind(name.as_str())
                .bind(now_ms())
                .fetch_one(&mut *tx)
                .await?
                .try_get("id")?;
                (id, true)
            }
        };
        for d in datasets {
            sqlx::query("INSERT INTO dataset_group_members (group_id, dataset) VALUES ($1, $2)")
                .bind(id)
                .bind(d.as_str())
                .execute(&mut *tx)
                .await?;
        }
        self.commit_board_change(tx, true).await?;
        Ok(created)
    }

    /// Deletes group `name`; false when there is none of that name.
    pub async fn delete_group(&self, name: &GroupName) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        // Its members go with it (ON DELETE CASCADE).
        let done = sqlx::query("DELETE FROM dataset_groups WHERE name = $1")
            .bind(name.as_str())
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }
}
