//! Wall-clock time as the database stores it: epoch milliseconds (`sqlx::Any` carries no
//! timestamp type, and integers compare and subtract the same in SQLite and PostgreSQL).

use std::time::{SystemTime, UNIX_EPOCH};

pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
