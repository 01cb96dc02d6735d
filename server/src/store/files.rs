//! Uploaded result files, kept in the database gzip-compressed, one row per content hash: the
//! database is the copy every worker reads, wherever it runs. A file is written in the
//! transaction that creates its first submission and deleted with its last one.

use sqlx::Row;

use super::{Store, StoreResult};
use crate::clock::now_ms;

/// A stored file as the database holds it.
pub struct StoredFile {
    /// Size of the file itself, uncompressed.
    pub size: i64,
    pub gzip: Vec<u8>,
}

/// Writes the file of content hash `sha256` unless it is stored already.
pub(super) async fn put_file(
    conn: &mut sqlx::AnyConnection,
    sha256: &str,
    size: i64,
    gzip: &[u8],
) -> StoreResult<()> {
    sqlx::query(
        "INSERT INTO submission_files (sha256, size, gzip, created_at) VALUES ($1, $2, $3, $4) \
         ON CONFLICT (sha256) DO NOTHING",
    )
    .bind(sha256)
    .bind(size)
    .bind(gzip)
    .bind(now_ms())
    .execute(&mut *conn)
    .await?;
    Ok(())
}

impl Store {
    /// The stored file of content hash `sha256`, if the database has it.
    pub async fn submission_file(&self, sha256: &str) -> StoreResult<Option<StoredFile>> {
        let row = sqlx::query("SELECT size, gzip FROM submission_files WHERE sha256 = $1")
            .bind(sha256)
            .fetch_optional(&self.pool)
            .await?;
        row.map(|r| {
            Ok(StoredFile {
                size: r.try_get("size")?,
                gzip: r.try_get("gzip")?,
            })
        })
        .transpose()
    }

    /// Stores a file kept only on disk by an older version (see [`Store::files_missing`]).
    pub async fn import_file(&self, sha256: &str, size: i64, gzip: &[u8]) -> StoreResult<()> {
        let mut conn = self.pool.acquire().await?;
        put_file(&mut conn, sha256, size, gzip).await
    }

    /// Content hashes of submissions whose file is not in the database: uploads taken by a
    /// version that kept them on disk only.
    pub async fn files_missing(&self) -> StoreResult<Vec<String>> {
        let rows = sqlx::query(
            "SELECT DISTINCT file_sha256 FROM submissions WHERE file_sha256 NOT IN \
             (SELECT sha256 FROM submission_files) ORDER BY file_sha256",
        )
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(|r| Ok(r.try_get("file_sha256")?)).collect()
    }
}
