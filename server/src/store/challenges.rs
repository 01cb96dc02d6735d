//! Challenges: their definition, the snapshot taken at their deadline with the rows and method
//! fields the awards are decided on, and the organisers' overrides of awards.
//!
//! The snapshot at a deadline is taken once across every process sharing the database: a
//! process first claims the challenge for a while ([`Store::claim_challenge`], a conditional
//! update only one process can win until the claim runs out), then stores the snapshot's
//! boards, the frozen rows and the challenge's `snapshot_id` in one transaction that only
//! commits while `snapshot_id` is still unset. A process that dies while holding the claim
//! leaves the challenge to the next one once the claim has run out; two can never both record
//! a snapshot.

use sqlx::Row;
use sqlx::any::AnyRow;

use super::methods::optional_column;
use super::snapshots::{SnapshotBoard, insert_boards};
use super::{Store, StoreResult, fetch_in, parse_column};
use crate::clock::now_ms;
use crate::domain::{
    Award, BoardProtocol, ChallengeId, ChallengeSpec, MethodId, Modality, ModelScope, SnapshotId,
    SubmissionId, TrainingData, UserId,
};

/// A challenge as stored.
#[derive(Clone, Debug)]
pub struct ChallengeRow {
    pub id: ChallengeId,
    pub slug: String,
    pub name: String,
    pub tasks: Vec<BoardProtocol>,
    /// Dataset group names; the first is the one the awards are decided on.
    pub groups: Vec<String>,
    /// The categories filter (`seen`/`unseen`, `model-based`/`model-free`); empty: any.
    pub objects: String,
    pub onboarding: String,
    /// Epoch milliseconds, UTC.
    pub deadline: i64,
    pub fast_seconds: f64,
    pub awards: Vec<Award>,
    pub created_by: UserId,
    pub created_at: i64,
    /// The snapshot taken at the deadline, once taken.
    pub snapshot_id: Option<SnapshotId>,
}

/// A method's row on a challenge's awards board as it stood at the deadline, with the method
/// fields the awards read, as they were then.
#[derive(Clone, Debug, PartialEq)]
pub struct FrozenEntry {
    pub protocol: BoardProtocol,
    pub method_id: MethodId,
    pub method: String,
    /// The owner as the public saw it then (`anonymous` for a method under review).
    pub owner: String,
    /// The average over the group's datasets; none when the method missed one.
    pub average: Option<f64>,
    /// Mean time over the datasets covered (per image; per target for eccv18).
    pub time: Option<f64>,
    pub training_data: Option<TrainingData>,
    pub detection_modality: Option<Modality>,
    pub modality: Option<Modality>,
    /// Empty when none was given (or hidden, for a method under review).
    pub code_url: String,
    pub model_scope: Option<ModelScope>,
    pub detections: String,
}

/// An organiser's decision on one award of one task, in place of the rule's.
#[derive(Clone, Debug, PartialEq)]
pub struct AwardOverride {
    pub protocol: BoardProtocol,
    pub award: Award,
    /// The method given the award; none: not awarded.
    pub method_id: Option<MethodId>,
    pub note: String,
    /// The administrator who decided.
    pub set_by: String,
    pub set_at: i64,
}

/// Values kept as a list in one column.
fn joined<T>(items: &[T], word: impl Fn(&T) -> &str) -> String {
    items.iter().map(word).collect::<Vec<_>>().join(",")
}

fn list<T: std::str::FromStr>(column: &'static str, value: String) -> StoreResult<Vec<T>> {
    value
        .split(',')
        .filter(|v| !v.is_empty())
        .map(|v| parse_column(column, v.to_string()))
        .collect()
}

fn challenge(r: &AnyRow) -> StoreResult<ChallengeRow> {
    Ok(ChallengeRow {
        id: r.try_get("id")?,
        slug: r.try_get("slug")?,
        name: r.try_get("name")?,
        tasks: list("tasks", r.try_get("tasks")?)?,
        groups: r
            .try_get::<String, _>("board_groups")?
            .split(',')
            .filter(|g| !g.is_empty())
            .map(str::to_string)
            .collect(),
        objects: r.try_get("objects")?,
        onboarding: r.try_get("onboarding")?,
        deadline: r.try_get("deadline")?,
        fast_seconds: r.try_get("fast_seconds")?,
        awards: list("awards", r.try_get("awards")?)?,
        created_by: r.try_get("created_by")?,
        created_at: r.try_get("created_at")?,
        snapshot_id: r.try_get("snapshot_id")?,
    })
}

impl Store {
    /// Stores a new challenge; a slug already taken is [`super::StoreError::Unique`].
    pub async fn create_challenge(
        &self,
        spec: &ChallengeSpec,
        created_by: UserId,
    ) -> StoreResult<ChallengeId> {
        let row = sqlx::query(
            "INSERT INTO challenges (slug, name, tasks, board_groups, objects, onboarding, \
             deadline, fast_seconds, awards, created_by, created_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11) RETURNING id",
        )
        .bind(spec.slug.as_str())
        .bind(spec.name.as_str())
        .bind(joined(&spec.tasks, |t| t.as_str()))
        .bind(joined(&spec.groups, |g| g.as_str()))
        .bind(spec.objects.map_or("", |o| o.as_str()))
        .bind(spec.onboarding.map_or("", |o| o.as_str()))
        .bind(spec.deadline)
        .bind(spec.fast_seconds)
        .bind(joined(&spec.awards, |a| a.as_str()))
        .bind(created_by)
        .bind(now_ms())
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    /// Every challenge, the latest deadline first.
    pub async fn challenges(&self) -> StoreResult<Vec<ChallengeRow>> {
        let rows = sqlx::query("SELECT * FROM challenges ORDER BY deadline DESC, id DESC")
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(challenge).collect()
    }

    pub async fn challenge_by_slug(&self, slug: &str) -> StoreResult<Option<ChallengeRow>> {
        let row = sqlx::query("SELECT * FROM challenges WHERE slug = $1")
            .bind(slug)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(challenge).transpose()
    }

    /// The challenges whose deadline has passed at `now` without a snapshot yet.
    pub async fn due_challenges(&self, now: i64) -> StoreResult<Vec<ChallengeRow>> {
        let rows = sqlx::query(
            "SELECT * FROM challenges WHERE deadline <= $1 AND snapshot_id IS NULL ORDER BY id",
        )
        .bind(now)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(challenge).collect()
    }

    /// Claims challenge `id` for taking its snapshot until `until`: true for the one caller
    /// that wins, while no snapshot is recorded and no other claim runs at `now`.
    pub async fn claim_challenge(
        &self,
        id: ChallengeId,
        now: i64,
        until: i64,
    ) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE challenges SET claimed_until = $1 \
             WHERE id = $2 AND snapshot_id IS NULL AND claimed_until < $3",
        )
        .bind(until)
        .bind(id)
        .bind(now)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Stores the boards of snapshot `snapshot` and the frozen rows of challenge `id`, and
    /// records the snapshot as the challenge's, all at once; false (nothing stored, the
    /// snapshot left incomplete for the caller to discard) if the challenge has one already.
    pub async fn complete_challenge_snapshot(
        &self,
        id: ChallengeId,
        snapshot: SnapshotId,
        boards: &[SnapshotBoard],
        entries: &[FrozenEntry],
    ) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let recorded = sqlx::query(
            "UPDATE challenges SET snapshot_id = $1 WHERE id = $2 AND snapshot_id IS NULL",
        )
        .bind(snapshot)
        .bind(id)
        .execute(&mut *tx)
        .await?;
        if recorded.rows_affected() != 1 {
            tx.rollback().await?;
            return Ok(false);
        }
        insert_boards(&mut tx, snapshot, boards).await?;
        for e in entries {
            sqlx::query(
                "INSERT INTO challenge_entries (challenge_id, protocol, method_id, method, owner, \
                 average, mean_time, training_data, detection_modality, modality, code_url, \
                 model_scope, detections) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13)",
            )
            .bind(id)
            .bind(e.protocol.as_str())
            .bind(e.method_id)
            .bind(&e.method)
            .bind(&e.owner)
            .bind(e.average)
            .bind(e.time)
            .bind(e.training_data.map_or("", |t| t.as_str()))
            .bind(e.detection_modality.map_or("", |m| m.as_str()))
            .bind(e.modality.map_or("", |m| m.as_str()))
            .bind(&e.code_url)
            .bind(e.model_scope.map_or("", |m| m.as_str()))
            .bind(&e.detections)
            .execute(&mut *tx)
            .await?;
        }
        tx.commit().await?;
        Ok(true)
    }

    /// The rows of challenge `id`'s awards boards as they stood at its deadline.
    pub async fn frozen_entries(&self, id: ChallengeId) -> StoreResult<Vec<FrozenEntry>> {
        let rows = sqlx::query(
            "SELECT * FROM challenge_entries WHERE challenge_id = $1 ORDER BY protocol, method",
        )
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(FrozenEntry {
                    protocol: parse_column("protocol", r.try_get("protocol")?)?,
                    method_id: r.try_get("method_id")?,
                    method: r.try_get("method")?,
                    owner: r.try_get("owner")?,
                    average: r.try_get("average")?,
                    time: r.try_get("mean_time")?,
                    training_data: optional_column(r, "training_data")?,
                    detection_modality: optional_column(r, "detection_modality")?,
                    modality: optional_column(r, "modality")?,
                    code_url: r.try_get("code_url")?,
                    model_scope: optional_column(r, "model_scope")?,
                    detections: r.try_get("detections")?,
                })
            })
            .collect()
    }

    /// Sets (or replaces) the organisers' decision on one award of one task.
    pub async fn set_award_override(
        &self,
        id: ChallengeId,
        o: &AwardOverride,
        set_by: UserId,
    ) -> StoreResult<()> {
        let mut tx = self.write_transaction().await?;
        sqlx::query(
            "DELETE FROM challenge_award_overrides \
             WHERE challenge_id = $1 AND protocol = $2 AND award = $3",
        )
        .bind(id)
        .bind(o.protocol.as_str())
        .bind(o.award.as_str())
        .execute(&mut *tx)
        .await?;
        sqlx::query(
            "INSERT INTO challenge_award_overrides \
             (challenge_id, protocol, award, method_id, note, set_by, set_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7)",
        )
        .bind(id)
        .bind(o.protocol.as_str())
        .bind(o.award.as_str())
        .bind(o.method_id)
        .bind(&o.note)
        .bind(set_by)
        .bind(o.set_at)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(())
    }

    /// The organisers' decisions on challenge `id`'s awards.
    pub async fn award_overrides(&self, id: ChallengeId) -> StoreResult<Vec<AwardOverride>> {
        let rows = sqlx::query(
            "SELECT o.protocol, o.award, o.method_id, o.note, u.name, o.set_at \
             FROM challenge_award_overrides o JOIN users u ON u.id = o.set_by \
             WHERE o.challenge_id = $1",
        )
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(AwardOverride {
                    protocol: parse_column("protocol", r.try_get("protocol")?)?,
                    award: parse_column("award", r.try_get("award")?)?,
                    method_id: r.try_get("method_id")?,
                    note: r.try_get("note")?,
                    set_by: r.try_get("name")?,
                    set_at: r.try_get("set_at")?,
                })
            })
            .collect()
    }

    /// When each of `ids` was submitted (epoch milliseconds).
    pub async fn submitted_at(
        &self,
        ids: &[SubmissionId],
    ) -> StoreResult<std::collections::BTreeMap<SubmissionId, i64>> {
        let rows = fetch_in(
            &self.pool,
            "SELECT id, created_at FROM submissions WHERE id IN",
            ids,
        )
        .await?;
        rows.iter()
            .map(|r| Ok((r.try_get("id")?, r.try_get("created_at")?)))
            .collect()
    }
}
