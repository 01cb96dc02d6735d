//! The datasets an instance serves. A dataset is registered when its folder is found at start
//! or added by an administrator; a retired one keeps its row (its submissions point at it) and
//! stays retired across restarts until an administrator adds it again.

use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::{Store, StoreResult};
use crate::clock::now_ms;
use crate::domain::DatasetId;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DatasetRow {
    pub id: DatasetId,
    pub name: String,
    #[serde(skip)]
    pub path: String,
    pub objects_count: i64,
    pub scenes_count: i64,
    pub images_count: i64,
    pub targets_count: i64,
    pub instances_count: i64,
    pub image_width: i64,
    pub image_height: i64,
    pub added_at: i64,
    pub retired: bool,
    /// Hash of the files that decide the scores, as the server that registered it read them
    /// (`None` for a dataset not registered again since the hash was introduced).
    #[serde(skip)]
    pub content_hash: Option<String>,
    /// Whether it is a core dataset as set by `--core-datasets` or an administrator; `None`:
    /// never set, the default rule decides (see `service::groups::core_datasets`).
    #[serde(skip)]
    pub core: Option<bool>,
}

#[cfg(test)]
impl DatasetRow {
    /// A registered dataset with nothing counted, for the service's unit tests.
    pub(crate) fn named(id: DatasetId, name: &str) -> DatasetRow {
        DatasetRow {
            id,
            name: name.to_string(),
            path: String::new(),
            objects_count: 0,
            scenes_count: 0,
            images_count: 0,
            targets_count: 0,
            instances_count: 0,
            image_width: 0,
            image_height: 0,
            added_at: 0,
            retired: false,
            content_hash: None,
            core: None,
        }
    }
}

fn dataset(row: &AnyRow) -> StoreResult<DatasetRow> {
    Ok(DatasetRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        path: row.try_get("path")?,
        objects_count: row.try_get("objects_count")?,
        scenes_count: row.try_get("scenes_count")?,
        images_count: row.try_get("images_count")?,
        targets_count: row.try_get("targets_count")?,
        instances_count: row.try_get("instances_count")?,
        image_width: row.try_get("image_width")?,
        image_height: row.try_get("image_height")?,
        added_at: row.try_get("added_at")?,
        retired: row.try_get::<i64, _>("retired")? != 0,
        content_hash: row.try_get("content_hash")?,
        core: row.try_get::<Option<i64>, _>("core")?.map(|c| c != 0),
    })
}

impl Store {
    /// Registers a dataset, or refreshes the description of the one of that name; returns the
    /// row as stored, whose `retired` flag is left as it was (see [`Store::revive_dataset`]).
    pub async fn register_dataset(&self, d: &DatasetRow) -> StoreResult<DatasetRow> {
        let mut tx = self.write_transaction().await?;
        let row = sqlx::query(
            "INSERT INTO datasets (name, path, objects_count, scenes_count, images_count, \
             targets_count, instances_count, image_width, image_height, added_at, content_hash) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11) \
             ON CONFLICT (name) DO UPDATE SET path = excluded.path, \
             objects_count = excluded.objects_count, scenes_count = excluded.scenes_count, \
             images_count = excluded.images_count, targets_count = excluded.targets_count, \
             instances_count = excluded.instances_count, image_width = excluded.image_width, \
             image_height = excluded.image_height, content_hash = excluded.content_hash \
             RETURNING *",
        )
        .bind(&d.name)
        .bind(&d.path)
        .bind(d.objects_count)
        .bind(d.scenes_count)
        .bind(d.images_count)
        .bind(d.targets_count)
        .bind(d.instances_count)
        .bind(d.image_width)
        .bind(d.image_height)
        .bind(now_ms())
        .bind(&d.content_hash)
        .fetch_one(&mut *tx)
        .await?;
        let row = dataset(&row)?;
        self.commit_board_change(tx, true).await?;
        Ok(row)
    }

    /// Serves a retired dataset again; false when there is no retired dataset of that name.
    pub async fn revive_dataset(&self, name: &str) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query("UPDATE datasets SET retired = 0 WHERE name = $1 AND retired = 1")
            .bind(name)
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Stops serving a dataset; false when no served dataset has that name.
    pub async fn retire_dataset(&self, name: &str) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query("UPDATE datasets SET retired = 1 WHERE name = $1 AND retired = 0")
            .bind(name)
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Makes a served dataset core or not; false when no served dataset has that name.
    pub async fn set_dataset_core(&self, name: &str, core: bool) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query("UPDATE datasets SET core = $1 WHERE name = $2 AND retired = 0")
            .bind(i64::from(core))
            .bind(name)
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Makes exactly the served datasets named core, and every other one not; when a name is
    /// not a served dataset nothing changes and the unknown names are returned.
    pub async fn set_core_datasets(&self, names: &[String]) -> StoreResult<Vec<String>> {
        let mut tx = self.write_transaction().await?;
        sqlx::query("UPDATE datasets SET core = 0 WHERE retired = 0")
            .execute(&mut *tx)
            .await?;
        let mut unknown = Vec::new();
        for name in names {
            let done = sqlx::query("UPDATE datasets SET core = 1 WHERE name = $1 AND retired = 0")
                .bind(name)
                .execute(&mut *tx)
                .await?;
            if done.rows_affected() == 0 {
                unknown.push(name.clone());
            }
        }
        if !unknown.is_empty() {
            tx.rollback().await?;
            return Ok(unknown);
        }
        self.commit_board_change(tx, true).await?;
        Ok(unknown)
    }

    /// The datasets served, by name.
    pub async fn datasets(&self) -> StoreResult<Vec<DatasetRow>> {
        let rows = sqlx::query("SELECT * FROM datasets WHERE retired = 0 ORDER BY name")
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(dataset).collect()
    }

    /// A served dataset by name.
    pub async fn dataset_by_name(&self, name: &str) -> StoreResult<Option<DatasetRow>> {
        let row = sqlx::query("SELECT * FROM datasets WHERE name = $1 AND retired = 0")
            .bind(name)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(dataset).transpose()
    }

    /// A dataset by id, served or retired (old submissions still name it).
    pub async fn dataset(&self, id: DatasetId) -> StoreResult<Option<DatasetRow>> {
        let row = sqlx::query("SELECT * FROM datasets WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(dataset).transpose()
    }
}
