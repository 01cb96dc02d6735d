//! Methods: a name per account, with what its owner says about it.

use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::{Store, StoreResult, parse_column};
use crate::domain::{Description, Link, Modality, TrainingData};

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodRow {
    pub id: i64,
    pub name: String,
    pub description: String,
    pub paper_url: String,
    pub code_url: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub created_at: i64,
}

/// What a submitter says about their method; `None` and empty fields leave stored values as
/// they are.
#[derive(Clone, Debug, Default)]
pub struct MethodMeta {
    pub description: Description,
    pub paper_url: Link,
    pub code_url: Link,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
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

pub(crate) fn method(row: &AnyRow) -> StoreResult<MethodRow> {
    Ok(MethodRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        description: row.try_get("description")?,
        paper_url: row.try_get("paper_url")?,
        code_url: row.try_get("code_url")?,
        training_data: optional_column(row, "training_data")?,
        modality: optional_column(row, "modality")?,
        created_at: row.try_get("created_at")?,
    })
}

impl Store {
    pub async fn method(&self, id: i64) -> StoreResult<Option<MethodRow>> {
        let row = sqlx::query("SELECT * FROM methods WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(method).transpose()
    }

    /// Methods with at least one public submission, by name.
    pub async fn public_methods(&self) -> StoreResult<Vec<MethodRow>> {
        let rows = sqlx::query(
            "SELECT * FROM methods m WHERE EXISTS (SELECT 1 FROM submissions s \
             WHERE s.method_id = m.id AND s.public = 1 AND s.hidden = 0) ORDER BY m.name, m.id",
        )
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(method).collect()
    }
}
