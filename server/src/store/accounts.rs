//! Users, browser sessions and API tokens. Secrets (passwords, session cookies, tokens) are
//! never stored: passwords as argon2id hashes, session secrets and tokens as SHA-256 (they are
//! 256-bit random, so a fast hash is enough and argon2 per request would be too slow).

use serde::Serialize;
use sqlx::Row;

use super::{Store, StoreError, StoreResult};
use crate::clock::now_ms;
use crate::domain::{TokenLabel, UserId, UserName};

#[derive(Clone, Debug, Serialize)]
pub struct User {
    pub id: UserId,
    pub name: String,
    pub is_admin: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct TokenRow {
    pub id: i64,
    pub name: String,
    pub created_at: i64,
    pub last_used_at: Option<i64>,
    pub revoked_at: Option<i64>,
}

/// A signed-in browser: who, and the token its forms must carry.
#[derive(Clone, Debug)]
pub struct Session {
    pub user: User,
    pub csrf_token: String,
}

impl Store {
    /// Creates an account; a taken name is [`StoreError::Unique`].
    pub async fn create_user(
        &self,
        name: &UserName,
        password_hash: &str,
        is_admin: bool,
    ) -> StoreResult<UserId> {
        let row = sqlx::query(
            "INSERT INTO users (name, password_hash, is_admin, created_at) VALUES ($1, $2, $3, $4) \
             ON CONFLICT (name) DO NOTHING RETURNING id",
        )
        .bind(name.as_str())
        .bind(password_hash)
        .bind(is_admin as i64)
        .bind(now_ms())
        .fetch_optional(&self.pool)
        .await?;
        match row {
            Some(row) => Ok(row.try_get("id")?),
            None => Err(StoreError::Unique {
                constraint: Some("users_name".into()),
            }),
        }
    }

    /// The user and their password hash, for signing in.
    pub async fn user_for_login(&self, name: &str) -> StoreResult<Option<(User, String)>> {
        let row =
            sqlx::query("SELECT id, name, is_admin, password_hash FROM users WHERE name = $1")
                .bind(name)
                .fetch_optional(&self.pool)
                .await?;
        row.map(|r| Ok((user(&r)?, r.try_get("password_hash")?)))
            .transpose()
    }

    pub async fn user_by_name(&self, name: &str) -> StoreResult<Option<User>> {
        Ok(self.user_for_login(name).await?.map(|(u, _)| u))
    }

    pub async fn create_session(
        &self,
        user_id: UserId,
        secret_hash: &str,
        csrf_token: &str,
        ttl_ms: i64,
    ) -> StoreResult<()> {
        let now = now_ms();
        sqlx::query(
            "INSERT INTO sessions (secret_hash, user_id, csrf_token, created_at, expires_at) \
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(secret_hash)
        .bind(user_id)
        .bind(csrf_token)
        .bind(now)
        .bind(now + ttl_ms)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    pub async fn session(&self, secret_hash: &str) -> StoreResult<Option<Session>> {
        let row = sqlx::query(
            "SELECT u.id, u.name, u.is_admin, s.csrf_token FROM sessions s \
             JOIN users u ON u.id = s.user_id WHERE s.secret_hash = $1 AND s.expires_at > $2",
        )
        .bind(secret_hash)
        .bind(now_ms())
        .fetch_optional(&self.pool)
        .await?;
        row.map(|r| {
            Ok(Session {
                user: user(&r)?,
                csrf_token: r.try_get("csrf_token")?,
            })
        })
        .transpose()
    }

    pub async fn delete_session(&self, secret_hash: &str) -> StoreResult<()> {
        sqlx::query("DELETE FROM sessions WHERE secret_hash = $1")
            .bind(secret_hash)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    pub async fn create_token(
        &self,
        user_id: UserId,
        label: &TokenLabel,
        token_hash: &str,
    ) -> StoreResult<i64> {
        let row = sqlx::query(
            "INSERT INTO api_tokens (user_id, name, token_hash, created_at) VALUES ($1, $2, $3, $4) RETURNING id",
        )
        .bind(user_id)
        .bind(label.as_str())
        .bind(token_hash)
        .bind(now_ms())
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    /// The owner of a live token, recording its use.
    pub async fn user_for_token(&self, token_hash: &str) -> StoreResult<Option<User>> {
        let row = sqlx::query(
            "UPDATE api_tokens SET last_used_at = $1 WHERE token_hash = $2 AND revoked_at IS NULL \
             RETURNING user_id",
        )
        .bind(now_ms())
        .bind(token_hash)
        .fetch_optional(&self.pool)
        .await?;
        let Some(row) = row else { return Ok(None) };
        let id: UserId = row.try_get("user_id")?;
        let row = sqlx::query("SELECT id, name, is_admin FROM users WHERE id = $1")
            .bind(id)
            .fetch_one(&self.pool)
            .await?;
        Ok(Some(user(&row)?))
    }

    pub async fn tokens(&self, user_id: UserId) -> StoreResult<Vec<TokenRow>> {
        let rows = sqlx::query(
            "SELECT id, name, created_at, last_used_at, revoked_at FROM api_tokens \
             WHERE user_id = $1 ORDER BY id DESC",
        )
        .bind(user_id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(TokenRow {
                    id: r.try_get("id")?,
                    name: r.try_get("name")?,
                    created_at: r.try_get("created_at")?,
                    last_used_at: r.try_get("last_used_at")?,
                    revoked_at: r.try_get("revoked_at")?,
                })
            })
            .collect()
    }

    /// Revokes one of the user's own tokens; false when there is no such live token.
    pub async fn revoke_token(&self, user_id: UserId, token_id: i64) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE api_tokens SET revoked_at = $1 WHERE id = $2 AND user_id = $3 AND revoked_at IS NULL",
        )
        .bind(now_ms())
        .bind(token_id)
        .bind(user_id)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }
}

/// A rate-limit counter: attempts counted since `since`, and the earliest time the next one is
/// allowed. What the numbers mean is the caller's policy; the store only keeps them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Counter {
    pub attempts: i64,
    pub since: i64,
    pub next_at: i64,
}

impl Store {
    /// The counter of `key`, if there is one.
    pub async fn counter(&self, key: &str) -> StoreResult<Option<Counter>> {
        let row = sqlx::query("SELECT attempts, since, next_at FROM rate_counters WHERE key = $1")
            .bind(key)
            .fetch_optional(&self.pool)
            .await?;
        row.map(|r| {
            Ok(Counter {
                attempts: r.try_get("attempts")?,
                since: r.try_get("since")?,
                next_at: r.try_get("next_at")?,
            })
        })
        .transpose()
    }

    /// Sets the counter of `key` to `new` only if it still is `seen` (`None`: no counter yet):
    /// false when another request changed it first. One statement each way, so of parallel
    /// requests that read the same counter exactly one moves it on, on both databases.
    pub async fn swap_counter(
        &self,
        key: &str,
        seen: Option<&Counter>,
        new: &Counter,
    ) -> StoreResult<bool> {
        let done = match seen {
            None => {
                // Counters untouched for a day are past every window: dropped as new ones come.
                sqlx::query("DELETE FROM rate_counters WHERE since < $1 AND next_at < $1")
                    .bind(now_ms() - 24 * 3600 * 1000)
                    .execute(&self.pool)
                    .await?;
                sqlx::query(
                    "INSERT INTO rate_counters (key, attempts, since, next_at) \
                     VALUES ($1, $2, $3, $4) ON CONFLICT (key) DO NOTHING",
                )
                .bind(key)
                .bind(new.attempts)
                .bind(new.since)
                .bind(new.next_at)
                .execute(&self.pool)
                .await?
            }
            Some(old) => {
                sqlx::query(
                    "UPDATE rate_counters SET attempts = $1, since = $2, next_at = $3 \
                     WHERE key = $4 AND attempts = $5 AND since = $6 AND next_at = $7",
                )
                .bind(new.attempts)
                .bind(new.since)
                .bind(new.next_at)
                .bind(key)
                .bind(old.attempts)
                .bind(old.since)
                .bind(old.next_at)
                .execute(&self.pool)
                .await?
            }
        };
        Ok(done.rows_affected() == 1)
    }

    pub async fn delete_counter(&self, key: &str) -> StoreResult<()> {
        sqlx::query("DELETE FROM rate_counters WHERE key = $1")
            .bind(key)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// Whether the account `name` has signed in (or registered) from `addr`.
    pub async fn signed_in_from(&self, name: &str, addr: &str) -> StoreResult<bool> {
        let row = sqlx::query("SELECT at FROM sign_in_addresses WHERE name = $1 AND addr = $2")
            .bind(name)
            .bind(addr)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.is_some())
    }

    pub async fn remember_sign_in(&self, name: &str, addr: &str) -> StoreResult<()> {
        sqlx::query(
            "INSERT INTO sign_in_addresses (name, addr, at) VALUES ($1, $2, $3) \
             ON CONFLICT (name, addr) DO UPDATE SET at = excluded.at",
        )
        .bind(name)
        .bind(addr)
        .bind(now_ms())
        .execute(&self.pool)
        .await?;
        Ok(())
    }
}

fn user(r: &sqlx::any::AnyRow) -> StoreResult<User> {
    Ok(User {
        id: r.try_get("id")?,
        name: r.try_get("name")?,
        is_admin: r.try_get::<i64, _>("is_admin")? != 0,
    })
}
