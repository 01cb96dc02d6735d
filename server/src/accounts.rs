//! Accounts as the service sees them, whoever asks (a form, the API, `poseboard admin`, the
//! demo set-up): one account policy, one way to hash a password and to mint a token. Secrets
//! are never stored: passwords as argon2id hashes, tokens and session secrets as SHA-256 (they
//! are 256-bit random, so a fast hash is enough and argon2 per request would be too slow).

use std::net::IpAddr;

use argon2::{Argon2, PasswordHash, PasswordHasher, PasswordVerifier};
use rand::RngCore;
use sha2::{Digest, Sha256};

use crate::clock::now_ms;
use crate::domain::{Password, TokenLabel, UserName};
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::{Store, StoreError};

/// Personal tokens carry a prefix so that leaked ones are easy to recognise.
pub const TOKEN_PREFIX: &str = "pbt_";

/// 256 random bits, hex-encoded.
pub fn new_secret() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    hex::encode(bytes)
}

pub fn sha256_hex(secret: &str) -> String {
    hex::encode(Sha256::digest(secret.as_bytes()))
}

/// Compares without an early exit, so the time taken does not tell how much of a guess was right.
pub fn same_secret(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

/// An argon2id hash; slow on purpose, so it runs on the blocking pool.
pub async fn hash_password(password: &Password) -> AppResult<String> {
    let password = password.clone();
    tokio::task::spawn_blocking(move || {
        Argon2::default()
            .hash_password(password.expose().as_bytes())
            .map(|h| h.to_string())
            .map_err(|e| AppError::Internal(format!("password hashing failed: {e}")))
    })
    .await
    .map_err(|e| AppError::Internal(e.to_string()))?
}

/// Checks a password against a stored hash, on the blocking pool.
pub async fn verify_password(password: &str, stored: &str) -> AppResult<bool> {
    let (password, stored) = (password.to_string(), stored.to_string());
    tokio::task::spawn_blocking(move || {
        PasswordHash::new(&stored).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        })
    })
    .await
    .map_err(|e| AppError::Internal(e.to_string()))
}

/// Sign-in attempts allowed per account, and per address, within `LOGIN_WINDOW_MS`.
const LOGIN_FAILURES_PER_ACCOUNT: usize = 5;
const LOGIN_FAILURES_PER_ADDRESS: usize = 20;
const LOGIN_WINDOW_MS: i64 = 15 * 60 * 1000;

/// Signs in with a name and a password from `addr`: the user, or `None` for an unknown name or
/// a wrong password (recorded against the account and the address). While either has failed
/// too often recently, the answer is `TooMany` before any password is checked.
pub async fn sign_in(
    store: &Store,
    name: &str,
    password: &str,
    addr: IpAddr,
) -> AppResult<Option<User>> {
    let name = name.trim();
    let account_key = format!("user:{name}");
    let keys = [
        (account_key.clone(), LOGIN_FAILURES_PER_ACCOUNT),
        (format!("addr:{addr}"), LOGIN_FAILURES_PER_ADDRESS),
    ];
    let since = now_ms() - LOGIN_WINDOW_MS;
    for (key, limit) in &keys {
        let failures = store.login_failures(key, since).await?;
        if failures.len() >= *limit {
            return Err(AppError::TooMany {
                message: "too many failed sign-ins: wait a few minutes and try again".into(),
                retry_at: failures[failures.len() - limit] + LOGIN_WINDOW_MS,
            });
        }
    }
    let verified = match store.user_for_login(name).await? {
        Some((user, hash)) => verify_password(password, &hash).await?.then_some(user),
        None => None,
    };
    match &verified {
        Some(_) => store.clear_login_failures(&account_key).await?,
        None => {
            let keys: Vec<String> = keys.into_iter().map(|(k, _)| k).collect();
            store.record_login_failure(&keys).await?;
        }
    }
    Ok(verified)
}

/// Creates an account; a taken name is a conflict that says so.
pub async fn register(
    store: &Store,
    name: &UserName,
    password: &Password,
    is_admin: bool,
) -> AppResult<i64> {
    let hash = hash_password(password).await?;
    match store.create_user(name, &hash, is_admin).await {
        Ok(id) => Ok(id),
        Err(StoreError::Unique { .. }) => {
            Err(AppError::Conflict(format!("the name `{name}` is taken")))
        }
        Err(e) => Err(e.into()),
    }
}

/// Mints a personal API token for a user: returned once, only its hash is kept.
pub async fn create_token(store: &Store, user_id: i64, label: &TokenLabel) -> AppResult<String> {
    let token = format!("{TOKEN_PREFIX}{}", new_secret());
    store
        .create_token(user_id, label, &sha256_hex(&token))
        .await?;
    Ok(token)
}
