//! What a row of any board says of its method and entry, whatever task was scored. The 6D,
//! 2D and bop24 boards select these columns with one SQL fragment and read them with one
//! function, so that the boards cannot disagree on who a method is or whose it is; a method
//! field that the boards show is added here once.
//!
//! The scores that tables keep per submission (the 2D AP, the bop24 mAP) are read for an
//! owner's or a method's list by [`Store::headline_scores`], parameterised by table and column.

use serde::de::DeserializeOwned;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::methods::optional_column;
use super::{Store, StoreError, StoreResult};
use crate::domain::{
    DatasetId, MethodId, Modality, Objects, Onboarding, SubmissionId, TrainingData,
};

/// A method's entry on a dataset, as every board names it.
#[derive(Clone, Debug, PartialEq)]
pub struct EntryHead {
    pub method_id: MethodId,
    pub method: String,
    /// The name of the team or account the method belongs to (whether the public is told it
    /// is the service's rule, by `anonymous`).
    pub owner: String,
    /// The method is under double-blind review.
    pub anonymous: bool,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub onboarding: Option<Onboarding>,
    /// The method's `objects` (seen or unseen).
    pub test_objects: Option<Objects>,
    pub hardware: String,
    pub dataset_id: DatasetId,
    pub dataset: String,
    pub submission_id: SubmissionId,
    /// Its owner pinned it (otherwise it is the best).
    pub pinned: bool,
}

/// The columns [`head`] reads (all but `submission_id`, which each board's score table gives),
/// for a query that joins `submissions s` with [`HEAD_JOINS`].
pub(super) const HEAD_COLUMNS: &str = "s.method_id, m.name AS method, \
     COALESCE(t.name, u.name, '') AS owner, m.anonymous, m.training_data, m.modality, \
     m.onboarding, m.objects, m.hardware, \
     s.dataset_id, d.name AS dataset, \
     CAST(CASE WHEN EXISTS (SELECT 1 FROM entry_pins p WHERE p.submission_id = s.id) \
     THEN 1 ELSE 0 END AS BIGINT) AS pinned";

/// The joins [`HEAD_COLUMNS`] reads from.
pub(super) const HEAD_JOINS: &str = "JOIN methods m ON m.id = s.method_id \
     JOIN datasets d ON d.id = s.dataset_id LEFT JOIN users u ON u.id = m.owner_id \
     LEFT JOIN teams t ON t.id = m.team_id";

pub(super) fn head(row: &AnyRow) -> StoreResult<EntryHead> {
    Ok(EntryHead {
        method_id: row.try_get("method_id")?,
        method: row.try_get("method")?,
        owner: row.try_get("owner")?,
        anonymous: row.try_get::<i64, _>("anonymous")? != 0,
        training_data: optional_column(row, "training_data")?,
        modality: optional_column(row, "modality")?,
        onboarding: optional_column(row, "onboarding")?,
        test_objects: optional_column(row, "objects")?,
        hardware: row.try_get("hardware")?,
        dataset_id: row.try_get("dataset_id")?,
        dataset: row.try_get("dataset")?,
        submission_id: row.try_get("submission_id")?,
        pinned: row.try_get::<i64, _>("pinned")? != 0,
    })
}

/// A stored bootstrap 95 % interval (`ci_low`, `ci_high`), where one was drawn.
pub(super) fn ci95(row: &AnyRow) -> StoreResult<Option<[f64; 2]>> {
    Ok(match (row.try_get("ci_low")?, row.try_get("ci_high")?) {
        (Some(low), Some(high)) => Some([low, high]),
        _ => None,
    })
}

/// An evaluator report kept whole as JSON in `report_json`, read back typed.
pub(super) fn report_json<T: DeserializeOwned>(row: &AnyRow) -> StoreResult<T> {
    let json: String = row.try_get("report_json")?;
    serde_json::from_str(&json).map_err(|_| StoreError::Corrupt {
        column: "report_json",
        value: json,
    })
}

/// The submissions whose headline scores a list wants: an owner's or a method's.
#[derive(Clone, Copy, Debug)]
pub enum Whose {
    Owner(crate::domain::UserId),
    Method(MethodId),
}

/// A table of scores kept one row per submission.
#[derive(Clone, Copy, Debug)]
pub(super) struct ScoreTable {
    pub(super) table: &'static str,
    /// The headline column; a NULL there (nothing counted) is left out.
    pub(super) column: &'static str,
}

impl Store {
    /// The headline score of every scored submission of `whose` in `table`, private ones
    /// included, by submission.
    pub(super) async fn headline_scores(
        &self,
        table: ScoreTable,
        whose: Whose,
    ) -> StoreResult<Vec<(SubmissionId, f64)>> {
        let (filter, value) = match whose {
            Whose::Owner(id) => ("s.owner_id", id.get()),
            Whose::Method(id) => ("s.method_id", id.get()),
        };
        let ScoreTable { table, column } = table;
        let sql = format!(
            "SELECT t.submission_id, t.{column} AS headline FROM {table} t \
             JOIN submissions s ON s.id = t.submission_id \
             WHERE {filter} = $1 AND t.{column} IS NOT NULL ORDER BY t.submission_id"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(value)
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| Ok((r.try_get("submission_id")?, r.try_get("headline")?)))
            .collect()
    }

    /// A method's entry on a dataset by `entry_sql` (an expression over `s.method_id` and
    /// `s.dataset_id` whose own parameters, if any, are `binds` from `$1`): the submission and
    /// whether it is pinned.
    pub(super) async fn entry_by(
        &self,
        entry_sql: &str,
        binds: &[&'static str],
        method_id: MethodId,
        dataset_id: DatasetId,
    ) -> StoreResult<Option<(SubmissionId, bool)>> {
        let (m, d) = (binds.len() + 1, binds.len() + 2);
        let sql = format!(
            "SELECT {entry_sql} AS entry, (SELECT p.submission_id FROM entry_pins p \
             WHERE p.method_id = ${m} AND p.dataset_id = ${d}) AS pin \
             FROM (SELECT CAST(${m} AS BIGINT) AS method_id, \
             CAST(${d} AS BIGINT) AS dataset_id) s"
        );
        let mut query = sqlx::query(sqlx::AssertSqlSafe(sql));
        for b in binds {
            query = query.bind(*b);
        }
        let row = query
            .bind(method_id)
            .bind(dataset_id)
            .fetch_one(&self.pool)
            .await?;
        let entry: Option<SubmissionId> = row.try_get("entry")?;
        let pin: Option<SubmissionId> = row.try_get("pin")?;
        Ok(entry.map(|id| (id, pin == Some(id))))
    }
}
