//! Accounts as the service sees them, whoever asks (a form, the API, `poseboard admin`, the
//! demo set-up): one account policy, one way to hash a password and to mint a token. Secrets
//! are never stored: passwords as argon2id hashes, tokens and session secrets as SHA-256 (they
//! are 256-bit random, so a fast hash is enough and argon2 per request would be too slow).

use std::net::IpAddr;
use std::sync::LazyLock;

use argon2::{Argon2, PasswordHash, PasswordHasher, PasswordVerifier};
use rand::RngCore;
use sha2::{Digest, Sha256};

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{Password, TokenLabel, UserId, UserName, normalized};
use crate::error::{AppError, AppResult};
use crate::service::visibility;
use crate::store::accounts::{Counter, Session, TokenRow, User};
use crate::store::teams::{InvitationRow, TeamRow};
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

/// Argon2 takes ~19 MiB and tens of milliseconds per hash: they run one at a time, however many
/// sign-ups and sign-ins arrive together, and the others wait their turn (after their attempt
/// was counted against the limits). One, not a few: the allocator holds on to the memory of
/// earlier hashes (about 7 of them, per thread that ran one), so memory grows with every extra
/// hashing thread (measured, 50 parallel sign-ups: 885 MB peak unbounded, ~500 MB with 2 hashes
/// at a time on the blocking pool, 357 MB on 2 threads of their own, under 300 MB on one).
const PARALLEL_HASHES: usize = 1;

/// The threads hashing runs on, of their own rather than the blocking pool's, whose many threads
/// would each hold such memory.
static HASHING: LazyLock<rayon::ThreadPool> = LazyLock::new(|| {
    rayon::ThreadPoolBuilder::new()
        .num_threads(PARALLEL_HASHES)
        .thread_name(|i| format!("password-hashing-{i}"))
        .build()
        .expect("password hashing threads start")
});

/// Runs password hashing work on its own thread, in turn.
async fn hashing<T: Send + 'static>(work: impl FnOnce() -> T + Send + 'static) -> AppResult<T> {
    let (done, result) = tokio::sync::oneshot::channel();
    HASHING.spawn(move || {
        // The requester may have gone away; then nobody needs the answer.
        let _ = done.send(work());
    });
    result
        .await
        .map_err(|_| AppError::Internal("password hashing stopped".into()))
}

/// An argon2id hash; slow on purpose.
pub async fn hash_password(password: &Password) -> AppResult<String> {
    let password = password.clone();
    hashing(move || {
        Argon2::default()
            .hash_password(password.expose().as_bytes())
            .map(|h| h.to_string())
            .map_err(|e| AppError::Internal(format!("password hashing failed: {e}")))
    })
    .await?
}

/// What unknown names are checked against: a hash made like every real one (same algorithm and
/// parameters) of a random secret, so an unknown name costs the same work and time as a known
/// one with a wrong password, and the answer's timing does not tell which names exist.
static DUMMY_HASH: LazyLock<String> = LazyLock::new(|| {
    Argon2::default()
        .hash_password(new_secret().as_bytes())
        .map(|h| h.to_string())
        .expect("argon2 hashes a random secret")
});

/// Checks a password against a stored hash (against [`DUMMY_HASH`] when there is none, which
/// no password matches).
pub async fn verify_password(password: &str, stored: Option<&str>) -> AppResult<bool> {
    let (password, stored) = (password.to_string(), stored.map(str::to_string));
    hashing(move || {
        let known = stored.is_some();
        let stored = stored.unwrap_or_else(|| DUMMY_HASH.clone());
        let matches = PasswordHash::new(&stored).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        });
        known && matches
    })
    .await
}

/// A fixed window: at most `max` attempts per `ms`.
struct Window {
    max: i64,
    ms: i64,
}

/// Sign-in attempts per address (successful ones are given back).
const SIGN_IN_PER_ADDRESS: Window = Window {
    max: 20,
    ms: 15 * 60 * 1000,
};
/// New accounts per address.
const REGISTER_PER_ADDRESS: Window = Window {
    max: 5,
    ms: 3600 * 1000,
};
/// Failed sign-ins an account takes, from addresses it has never signed in from, before each
/// further attempt waits: `ACCOUNT_FIRST_DELAY_MS`, doubling up to `ACCOUNT_MAX_DELAY_MS`. A
/// delay, not a lock: the owner, from an address of an earlier sign-in, does not wait at all.
const ACCOUNT_FREE_FAILURES: i64 = 5;
const ACCOUNT_FIRST_DELAY_MS: i64 = 30 * 1000;
const ACCOUNT_MAX_DELAY_MS: i64 = 15 * 60 * 1000;
/// An account's failures are forgotten a day after the last one.
const ACCOUNT_MEMORY_MS: i64 = 24 * 3600 * 1000;
/// Reads and compare-and-sets of one counter before a request gives up.
const COUNTER_TRIES: usize = 8;

fn too_many(retry_at: i64) -> AppError {
    AppError::TooMany {
        message: "too many attempts: wait a few minutes and try again".into(),
        retry_at,
    }
}

/// Counts one attempt against `key`, before any work is done for it. `step` turns the counter
/// (none yet, at `now`) into the counter with this attempt counted, or refuses with the time the
/// next attempt is allowed. The counter moves by compare-and-set, so of parallel attempts each
/// is counted exactly once and none passes a limit.
async fn count_attempt(
    store: &Store,
    key: &str,
    step: impl Fn(Option<Counter>, i64) -> Result<Counter, i64>,
) -> AppResult<()> {
    for _ in 0..COUNTER_TRIES {
        let seen = store.counter(key).await?;
        let new = step(seen, now_ms()).map_err(too_many)?;
        if store.swap_counter(key, seen.as_ref(), &new).await? {
            return Ok(());
        }
    }
    // Contended on every try: a burst that busy is over any limit.
    Err(too_many(now_ms() + 1000))
}

/// Gives back one attempt of a window (a successful sign-in is not held against its address).
async fn give_back(store: &Store, key: &str) -> AppResult<()> {
    for _ in 0..COUNTER_TRIES {
        let Some(seen) = store.counter(key).await?.filter(|c| c.attempts > 0) else {
            return Ok(());
        };
        let new = Counter {
            attempts: seen.attempts - 1,
            ..seen
        };
        if store.swap_counter(key, Some(&seen), &new).await? {
            return Ok(());
        }
    }
    Ok(())
}

fn window_step(window: Window) -> impl Fn(Option<Counter>, i64) -> Result<Counter, i64> {
    move |seen, now| match seen {
        Some(c) if now < c.since + window.ms && c.attempts >= window.max => {
            Err(c.since + window.ms)
        }
        Some(c) if now < c.since + window.ms => Ok(Counter {
            attempts: c.attempts + 1,
            ..c
        }),
        _ => Ok(Counter {
            attempts: 1,
            since: now,
            next_at: now + window.ms,
        }),
    }
}

/// The wait after an account's `failures`-th failed sign-in.
fn account_delay(failures: i64) -> i64 {
    if failures < ACCOUNT_FREE_FAILURES {
        0
    } else {
        let doublings = (failures - ACCOUNT_FREE_FAILURES).min(20) as u32;
        (ACCOUNT_FIRST_DELAY_MS << doublings).min(ACCOUNT_MAX_DELAY_MS)
    }
}

/// An account's counter: attempts, the last one's time (`since`), and when the next is allowed.
fn account_step(seen: Option<Counter>, now: i64) -> Result<Counter, i64> {
    let attempts = match seen {
        Some(c) if now < c.since + ACCOUNT_MEMORY_MS => {
            if now < c.next_at {
                return Err(c.next_at);
            }
            c.attempts + 1
        }
        _ => 1,
    };
    Ok(Counter {
        attempts,
        since: now,
        next_at: now + account_delay(attempts),
    })
}

/// Signs in with a name and a password from `addr`: the user, or `None` for an unknown name or
/// a wrong password. Every attempt is counted before any password is checked, first against
/// the address (a fixed window), then, unless the account has signed in from this address
/// before, against the account (growing delays); over either, the answer is `TooMany`. An
/// unknown name takes the same steps, a password check included, as a known one.
pub async fn sign_in(
    store: &Store,
    name: &str,
    password: &str,
    addr: IpAddr,
) -> AppResult<Option<User>> {
    // As the name was stored: "é" typed either way signs in to one account and counts against
    // one account's limit.
    let name = normalized(name);
    let name = name.as_str();
    let addr = addr.to_string();
    let addr_key = format!("signin-addr:{addr}");
    count_attempt(store, &addr_key, window_step(SIGN_IN_PER_ADDRESS)).await?;
    let account_key = if store.signed_in_from(name, &addr).await? {
        None
    } else {
        Some(format!("signin-user:{name}"))
    };
    if let Some(key) = &account_key {
        count_attempt(store, key, account_step).await?;
    }
    let (user, hash) = store.user_for_login(name).await?.unzip();
    let verified = verify_password(password, hash.as_deref()).await?;
    let Some(user) = user.filter(|_| verified) else {
        return Ok(None);
    };
    give_back(store, &addr_key).await?;
    if let Some(key) = &account_key {
        store.delete_counter(key).await?;
    }
    store.remember_sign_in(name, &addr).await?;
    Ok(Some(user))
}

/// Creates an account; a taken name is a conflict that says so, and so is "anonymous" (in any
/// case): the boards show it for the owners of methods under double-blind review, and an
/// account of that name would pass for one of them.
pub async fn register(
    store: &Store,
    name: &UserName,
    password: &Password,
    is_admin: bool,
) -> AppResult<UserId> {
    if name.as_str().eq_ignore_ascii_case(visibility::ANONYMOUS) {
        return Err(AppError::Conflict(format!(
            "the name `{name}` is reserved: the boards show it for methods under double-blind review"
        )));
    }
    let hash = hash_password(password).await?;
    match store.create_user(name, &hash, is_admin).await {
        Ok(id) => Ok(id),
        Err(StoreError::Unique { .. }) => {
            Err(AppError::Conflict(format!("the name `{name}` is taken")))
        }
        Err(e) => Err(e.into()),
    }
}

/// Registers from a browser at `addr` (counted against the address's limit before the password
/// is hashed), which then counts as an address the account signed in from.
pub async fn sign_up(
    store: &Store,
    name: &UserName,
    password: &Password,
    addr: IpAddr,
) -> AppResult<UserId> {
    let key = format!("register:{addr}");
    count_attempt(store, &key, window_step(REGISTER_PER_ADDRESS)).await?;
    let id = register(store, name, password, false).await?;
    store
        .remember_sign_in(name.as_str(), &addr.to_string())
        .await?;
    Ok(id)
}

/// Mints a personal API token for a user: returned once, only its hash is kept.
pub async fn create_token(store: &Store, user_id: UserId, label: &TokenLabel) -> AppResult<String> {
    let token = format!("{TOKEN_PREFIX}{}", new_secret());
    store
        .create_token(user_id, label, &sha256_hex(&token))
        .await?;
    Ok(token)
}

/// Sessions last two weeks.
pub const SESSION_TTL_MS: i64 = 14 * 24 * 3600 * 1000;

/// A browser signs in (see [`sign_in`]): the secret of its new session, or `None` for an
/// unknown name or a wrong password.
pub async fn open_session(
    app: &App,
    name: &str,
    password: &str,
    addr: IpAddr,
) -> AppResult<Option<String>> {
    match sign_in(&app.store, name, password, addr).await? {
        Some(user) => Ok(Some(start_session(app, user.id).await?)),
        None => Ok(None),
    }
}

/// A browser registers (see [`sign_up`]): the secret of the new account's first session.
pub async fn open_account(
    app: &App,
    name: &UserName,
    password: &Password,
    addr: IpAddr,
) -> AppResult<String> {
    let id = sign_up(&app.store, name, password, addr).await?;
    start_session(app, id).await
}

/// A new session of `user_id`, with its own CSRF token; only the hash of its secret is kept.
async fn start_session(app: &App, user_id: UserId) -> AppResult<String> {
    let secret = new_secret();
    app.store
        .create_session(user_id, &sha256_hex(&secret), &new_secret(), SESSION_TTL_MS)
        .await?;
    Ok(secret)
}

/// The session whose cookie holds `secret`, while it lasts.
pub async fn session(app: &App, secret: &str) -> AppResult<Option<Session>> {
    Ok(app.store.session(&sha256_hex(secret)).await?)
}

/// Ends the session whose cookie holds `secret`.
pub async fn close_session(app: &App, secret: &str) -> AppResult<()> {
    Ok(app.store.delete_session(&sha256_hex(secret)).await?)
}

/// The user of a personal API token, which counts as used; refused when unknown or revoked.
pub async fn token_user(app: &App, token: &str) -> AppResult<User> {
    app.store
        .user_for_token(&sha256_hex(token))
        .await?
        .ok_or_else(|| AppError::Unauthorized("invalid or revoked token".into()))
}

/// What an account's page shows its owner.
pub struct AccountHome {
    /// Its personal API tokens, newest first.
    pub tokens: Vec<TokenRow>,
    /// The teams it is a member of, by name.
    pub teams: Vec<TeamRow>,
    /// The invitations to teams waiting for it to accept them, oldest first.
    pub invitations: Vec<InvitationRow>,
}

/// The account page of `user`.
pub async fn home(app: &App, user: &User) -> AppResult<AccountHome> {
    Ok(AccountHome {
        tokens: app.store.tokens(user.id).await?,
        teams: app.store.teams_of(user.id).await?,
        invitations: app.store.invitations_of(user.id).await?,
    })
}

/// `user` mints a token on their account page (see [`create_token`]).
pub async fn new_token(app: &App, user: &User, label: &TokenLabel) -> AppResult<String> {
    create_token(&app.store, user.id, label).await
}

/// `user` revokes their token `id`; another's token, or one revoked already, is missing.
pub async fn revoke_token(app: &App, user: &User, id: i64) -> AppResult<()> {
    if app.store.revoke_token(user.id, id).await? {
        Ok(())
    } else {
        Err(AppError::NotFound)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An unknown name must cost what a known one costs: its stand-in hash is made with the same
    /// algorithm and parameters as real ones, is really checked, and matches nothing.
    #[tokio::test]
    async fn unknown_names_are_checked_against_a_real_hash() {
        let real = hash_password(&Password::parse("correct horse battery").unwrap())
            .await
            .unwrap();
        let (real, dummy) = (
            PasswordHash::new(&real).unwrap(),
            PasswordHash::new(&DUMMY_HASH).unwrap(),
        );
        assert_eq!(real.algorithm, dummy.algorithm);
        assert_eq!(real.version, dummy.version);
        assert_eq!(real.params, dummy.params);
        assert!(
            !verify_password("correct horse battery", None)
                .await
                .unwrap()
        );
    }

    #[test]
    fn account_delays_grow_and_stay_bounded() {
        let delays: Vec<i64> = (1..=30).map(account_delay).collect();
        assert!(delays[..4].iter().all(|&d| d == 0));
        assert_eq!(delays[4], ACCOUNT_FIRST_DELAY_MS);
        assert_eq!(delays[5], 2 * ACCOUNT_FIRST_DELAY_MS);
        assert!(delays.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(delays[29], ACCOUNT_MAX_DELAY_MS);
    }
}
