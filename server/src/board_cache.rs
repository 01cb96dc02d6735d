//! Rendered leaderboards kept in memory: the HTML page and the JSON of each protocol and query,
//! as bytes (and gzipped bytes), so that a reader costs a hash lookup instead of a database query
//! and a render.
//!
//! What is cached is only what every reader sees alike: the leaderboards show finished public
//! submissions only and their handlers never look at who asks, so one entry serves everyone.
//! Pages that depend on the viewer (a submission's page, the account page, the admin pages)
//! never go through this cache.
//!
//! Staleness. Boards change only when a job ends or a submission or dataset changes state, and
//! each such change bumps one number in the database in its own transaction
//! (`store::board_version`). Entries are tagged with the version they were rendered under and
//! dropped when it moves. The cache learns the version two ways:
//! - changes made by this process (its store) are counted in memory, and the next request after
//!   one re-reads the version at once, so this server never shows its own stale board;
//! - changes made elsewhere (a worker on another machine, another server on the same
//!   PostgreSQL or SQLite file) are seen by re-reading the version when the last look is older
//!   than `recheck` (250 ms by default): at most one small indexed query per interval per
//!   server, whatever the load, and the same code on both databases.
//!
//! LISTEN/NOTIFY would tell PostgreSQL servers sooner, but it needs a dedicated connection
//! outside the `sqlx::Any` pool with its own reconnection logic, and SQLite has no equivalent;
//! a quarter of a second behind another process is well within what a leaderboard needs.
//!
//! Rendering is single-flight per key: when a board goes stale under load, one request renders
//! it and the others wait for that result instead of all querying the database at once.
//! The cache is bounded in bytes; the oldest entries go first.

use std::collections::{HashMap, VecDeque};
use std::future::Future;
use std::io::Write;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use hyper::body::Bytes;
use tokio::sync::OnceCell;

use crate::domain::BoardProtocol;
use crate::store::{Store, StoreError};

/// Which rendering of a board.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    Html,
    Json,
}

/// A board as asked for: the format, the protocol and the query with its values as given (the
/// page and the JSON repeat the query, so `?sort=average` and no sort are different bytes).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BoardKey {
    pub format: Format,
    pub protocol: BoardProtocol,
    /// The query's (dataset, sort, training, modality, curves, objects, onboarding, group).
    pub query: [Option<String>; 8],
}

/// A rendered board.
#[derive(Debug)]
pub struct Rendered {
    pub body: Bytes,
    /// The same body gzipped, for clients that accept it (compressing on every request would
    /// cost more than everything else a cached answer does). None when the cache is off: the
    /// answer is then compressed on its way out, like any other.
    pub gzip: Option<Bytes>,
}

impl Rendered {
    fn uncached(body: Vec<u8>) -> Rendered {
        Rendered {
            body: body.into(),
            gzip: None,
        }
    }

    fn new(body: Vec<u8>) -> Rendered {
        Rendered {
            gzip: Some(gzip(&body).into()),
            body: body.into(),
        }
    }

    fn size(&self) -> usize {
        self.body.len() + self.gzip.as_ref().map_or(0, Bytes::len)
    }
}

/// `body` gzip-compressed, as boards are kept (in this cache and in snapshots).
pub fn gzip(body: &[u8]) -> Vec<u8> {
    let mut encoder =
        flate2::write::GzEncoder::new(Vec::with_capacity(body.len() / 4), Default::default());
    // Writing into a Vec cannot fail.
    encoder
        .write_all(body)
        .and_then(|()| encoder.finish())
        .unwrap_or_default()
}

pub struct BoardCache {
    /// Most bytes held; 0 turns the cache off (every request renders).
    capacity: usize,
    /// How old the last look at the database's board version may be.
    recheck: Duration,
    state: Mutex<State>,
    /// One version look at a time; the others wait for its answer.
    looking: tokio::sync::Mutex<()>,
}

type Slot = Arc<OnceCell<Arc<Rendered>>>;

#[derive(Default)]
struct State {
    /// The board version the entries were rendered under.
    version: Option<i64>,
    checked_at: Option<Instant>,
    /// The store's count of its own board changes at the last look.
    local_seen: u64,
    entries: HashMap<BoardKey, Slot>,
    /// Filled entries, oldest first, with their sizes.
    order: VecDeque<(BoardKey, usize)>,
    bytes: usize,
}

impl State {
    fn fresh(&self, local: u64, recheck: Duration) -> Option<i64> {
        match (self.version, self.checked_at) {
            (Some(v), Some(at)) if self.local_seen == local && at.elapsed() < recheck => Some(v),
            _ => None,
        }
    }
}

impl BoardCache {
    pub fn new(capacity_bytes: usize, recheck: Duration) -> BoardCache {
        BoardCache {
            capacity: capacity_bytes,
            recheck,
            state: Mutex::new(State::default()),
            looking: tokio::sync::Mutex::new(()),
        }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // The state is consistent after every statement, so a panic elsewhere leaves it usable.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The board of `key`: from memory when rendered under the current board version,
    /// otherwise rendered by `render` (only successes are kept).
    pub async fn get_or_render<E, F, Fut>(
        &self,
        store: &Store,
        key: BoardKey,
        render: F,
    ) -> Result<Arc<Rendered>, E>
    where
        E: From<StoreError>,
        F: FnOnce() -> Fut,
        Fut: Future<Output = Result<Vec<u8>, E>>,
    {
        if self.capacity == 0 {
            return Ok(Arc::new(Rendered::uncached(render().await?)));
        }
        let version = self.current_version(store).await?;
        let slot = {
            let mut state = self.state();
            if state.version != Some(version) {
                // A newer version was seen meanwhile: render, but keep nothing.
                None
            } else {
                Some(state.entries.entry(key.clone()).or_default().clone())
            }
        };
        let Some(slot) = slot else {
            return Ok(Arc::new(Rendered::new(render().await?)));
        };
        let rendered = slot
            .get_or_try_init(|| async {
                let rendered = Arc::new(Rendered::new(render().await?));
                self.account(&key, version, rendered.size());
                Ok::<_, E>(rendered)
            })
            .await;
        match rendered {
            Ok(rendered) => Ok(rendered.clone()),
            Err(e) => {
                // No empty slot stays behind for a query that fails (an unknown sort, say), so
                // bad queries cannot grow the map.
                let mut state = self.state();
                if state
                    .entries
                    .get(&key)
                    .is_some_and(|s| Arc::ptr_eq(s, &slot) && !s.initialized())
                {
                    state.entries.remove(&key);
                }
                Err(e)
            }
        }
    }

    /// Counts a freshly rendered entry and evicts the oldest ones beyond the capacity (this one
    /// too when it alone is larger).
    fn account(&self, key: &BoardKey, version: i64, size: usize) {
        let mut state = self.state();
        if state.version != Some(version) {
            return;
        }
        state.order.push_back((key.clone(), size));
        state.bytes += size;
        while state.bytes > self.capacity {
            let Some((old, old_size)) = state.order.pop_front() else {
                break;
            };
            state.entries.remove(&old);
            state.bytes -= old_size;
        }
    }

    /// The board version the cached entries must carry, looked up in the database when this
    /// process changed a board since the last look or the last look is older than `recheck`;
    /// entries of an older version are dropped.
    async fn current_version(&self, store: &Store) -> Result<i64, StoreError> {
        let local = store.local_board_changes();
        if let Some(v) = self.state().fresh(local, self.recheck) {
            return Ok(v);
        }
        let _one_look = self.looking.lock().await;
        if let Some(v) = self.state().fresh(local, self.recheck) {
            return Ok(v);
        }
        let checked_at = Instant::now();
        let version = store.board_version().await?;
        let mut state = self.state();
        if state.version != Some(version) {
            state.entries.clear();
            state.order.clear();
            state.bytes = 0;
            state.version = Some(version);
        }
        state.checked_at = Some(checked_at);
        state.local_seen = local;
        Ok(version)
    }
}
