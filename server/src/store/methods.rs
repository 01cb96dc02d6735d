//! Methods: a name per account, with what its owner says about it.

use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::{Store, StoreResult, parse_column};
use crate::domain::{
    Description, Link, MethodDetails, MethodForm, MethodId, Modality, ModelScope, Objects,
    Onboarding, TeamId, TrainingData, UserId,
};

/// A method as the BOP site shows it: who submits it and how it works.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodRow {
    pub id: MethodId,
    pub name: String,
    /// The name of the team or account it belongs to (empty for a method from before
    /// accounts).
    pub owner: String,
    /// The account it belongs to; none for a team's method, which belongs to no one member.
    #[serde(skip)]
    pub owner_id: Option<UserId>,
    /// The team it belongs to, if it is a team's: every member submits to it and edits it.
    pub team: Option<String>,
    #[serde(skip)]
    pub team_id: Option<TeamId>,
    pub description: String,
    pub authors: String,
    pub year: Option<i64>,
    pub paper_url: String,
    pub code_url: String,
    pub training_data: Option<TrainingData>,
    /// The input of the detection stage.
    pub detection_modality: Option<Modality>,
    /// The input of the pose stage.
    pub modality: Option<Modality>,
    pub refinement: String,
    pub detections: String,
    pub model_scope: Option<ModelScope>,
    /// What the reported times were measured on.
    pub hardware: String,
    /// Under double-blind review: its owner is not named to the public until revealed.
    pub anonymous: bool,
    pub onboarding: Option<Onboarding>,
    pub objects: Option<Objects>,
    pub created_at: i64,
}

impl MethodRow {
    /// The stored details as the text a form would send, so that an edit can leave fields out.
    pub fn as_form(&self) -> MethodForm {
        let word = |w: Option<&str>| Some(w.unwrap_or_default().to_string());
        MethodForm {
            description: Some(self.description.clone()),
            authors: Some(self.authors.clone()),
            year: Some(self.year.map(|y| y.to_string()).unwrap_or_default()),
            paper_url: Some(self.paper_url.clone()),
            code_url: Some(self.code_url.clone()),
            training_data: word(self.training_data.map(|t| t.as_str())),
            detection_modality: word(self.detection_modality.map(|m| m.as_str())),
            modality: word(self.modality.map(|m| m.as_str())),
            refinement: Some(self.refinement.clone()),
            detections: Some(self.detections.clone()),
            model_scope: word(self.model_scope.map(|m| m.as_str())),
            hardware: Some(self.hardware.clone()),
            anonymous: Some(self.anonymous.to_string()),
            onboarding: word(self.onboarding.map(|o| o.as_str())),
            objects: word(self.objects.map(|o| o.as_str())),
        }
    }
}

/// What a submitter says about their method with an upload; `None` and empty fields leave
/// stored values as they are.
#[derive(Clone, Debug, Default)]
pub struct MethodMeta {
    pub description: Description,
    pub paper_url: Link,
    pub code_url: Link,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    /// Under double-blind review from now on (`Some(true)`) or not; `None` leaves it.
    pub anonymous: Option<bool>,
    pub onboarding: Option<Onboarding>,
    pub objects: Option<Objects>,
}

/// An optional enumeration stored as text, empty when not given.
pub(crate) fn optional_column<T: std::str::FromStr>(
    row: &AnyRow,
    column: &'static str,
) -> StoreResult<Option<T>> {
    let value: String = row.try_get(column)?;
    if value.is_empty() {
        Ok(None)
    } else {
        parse_column(column, value).map(Some)
    }
}

/// Selects a method with its owner's name: its team's, or its account's.
pub(super) const SELECT_METHOD: &str = "SELECT m.*, COALESCE(t.name, u.name, '') AS owner, \
     t.name AS team FROM methods m LEFT JOIN users u ON u.id = m.owner_id \
     LEFT JOIN teams t ON t.id = m.team_id";

pub(crate) fn method(row: &AnyRow) -> StoreResult<MethodRow> {
    Ok(MethodRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        owner: row.try_get("owner")?,
        owner_id: row.try_get("owner_id")?,
        team: row.try_get("team")?,
        team_id: row.try_get("team_id")?,
        description: row.try_get("description")?,
        authors: row.try_get("authors")?,
        year: row.try_get("year")?,
        paper_url: row.try_get("paper_url")?,
        code_url: row.try_get("code_url")?,
        training_data: optional_column(row, "training_data")?,
        detection_modality: optional_column(row, "detection_modality")?,
        modality: optional_column(row, "modality")?,
        refinement: row.try_get("refinement")?,
        detections: row.try_get("detections")?,
        model_scope: optional_column(row, "model_scope")?,
        hardware: row.try_get("hardware")?,
        anonymous: row.try_get::<i64, _>("anonymous")? != 0,
        onboarding: optional_column(row, "onboarding")?,
        objects: optional_column(row, "objects")?,
        created_at: row.try_get("created_at")?,
    })
}

impl Store {
    pub async fn method(&self, id: MethodId) -> StoreResult<Option<MethodRow>> {
        let row = sqlx::query(sqlx::AssertSqlSafe(format!(
            "{SELECT_METHOD} WHERE m.id = $1"
        )))
        .bind(id)
        .fetch_optional(&self.pool)
        .await?;
        row.as_ref().map(method).transpose()
    }

    /// Methods with at least one public submission, by name.
    pub async fn public_methods(&self) -> StoreResult<Vec<MethodRow>> {
        let rows = sqlx::query(sqlx::AssertSqlSafe(format!(
            "{SELECT_METHOD} WHERE EXISTS (SELECT 1 FROM submissions s \
             WHERE s.method_id = m.id AND s.public = 1 AND s.hidden = 0) ORDER BY m.name, m.id"
        )))
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(method).collect()
    }

    /// Replaces a method's details (the boards show some of them).
    pub async fn set_method_details(&self, id: MethodId, d: &MethodDetails) -> StoreResult<bool> {
        let word = |w: Option<&'static str>| w.unwrap_or_default();
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query(
            "UPDATE methods SET description = $1, authors = $2, year = $3, paper_url = $4, \
             code_url = $5, training_data = $6, detection_modality = $7, modality = $8, \
             refinement = $9, detections = $10, model_scope = $11, hardware = $12, \
             anonymous = $13, onboarding = $14, objects = $15 WHERE id = $16",
        )
        .bind(d.description.as_str())
        .bind(d.authors.as_str())
        .bind(d.year)
        .bind(d.paper_url.as_str())
        .bind(d.code_url.as_str())
        .bind(word(d.training_data.map(|t| t.as_str())))
        .bind(word(d.detection_modality.map(|m| m.as_str())))
        .bind(word(d.modality.map(|m| m.as_str())))
        .bind(d.refinement.as_str())
        .bind(d.detections.as_str())
        .bind(word(d.model_scope.map(|m| m.as_str())))
        .bind(d.hardware.as_str())
        .bind(i64::from(d.anonymous))
        .bind(word(d.onboarding.map(|o| o.as_str())))
        .bind(word(d.objects.map(|o| o.as_str())))
        .bind(id)
        .execute(&mut *tx)
        .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Ends (or starts) a method's double-blind review: the boards name its owner again at
    /// once, so the board version moves. False when there is no such method.
    pub async fn set_method_anonymous(&self, id: MethodId, anonymous: bool) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query("UPDATE methods SET anonymous = $1 WHERE id = $2")
            .bind(i64::from(anonymous))
            .bind(id)
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }
}
