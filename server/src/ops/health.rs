//! Readiness: whether this process can do its work now. A load balancer or orchestrator sends
//! traffic to (and a deployment waits for) a process whose database answers, whose schema is
//! the one this binary was built for (a newer version's migration on a shared database makes
//! an older process unfit), and which has every served dataset loaded.

use std::time::Duration;

use serde::Serialize;

use crate::app::App;
use crate::clock::now_ms;
use crate::error::Chain;

/// A database that does not answer within this is taken to be unreachable (the pool would
/// otherwise wait its full acquire timeout).
const DATABASE_TIMEOUT: Duration = Duration::from_secs(3);

/// One check that is not passing, and why.
#[derive(Clone, Debug, Serialize)]
pub struct NotReady {
    /// `database`, `migrations` or `datasets`.
    pub check: &'static str,
    pub reason: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Readiness {
    pub ready: bool,
    pub not_ready: Vec<NotReady>,
}

/// Runs the checks; the later ones need the database, so they are skipped without it.
pub async fn readiness(app: &App) -> Readiness {
    let mut not_ready = Vec::new();
    let fail = |check, reason: String| NotReady { check, reason };
    match tokio::time::timeout(DATABASE_TIMEOUT, app.store.ping()).await {
        Err(_) => not_ready.push(fail(
            "database",
            format!("no answer within {DATABASE_TIMEOUT:?}"),
        )),
        Ok(Err(e)) => not_ready.push(fail("database", e.to_string())),
        Ok(Ok(())) => {
            match app.store.migration_state().await {
                Ok(m) if m.is_current() => {}
                Ok(m) => {
                    let mut why = Vec::new();
                    if !m.pending.is_empty() {
                        why.push(format!("not applied: {:?}", m.pending));
                    }
                    if !m.unknown.is_empty() {
                        why.push(format!(
                            "applied by a newer version of poseboard: {:?}",
                            m.unknown
                        ));
                    }
                    not_ready.push(fail("migrations", why.join("; ")));
                }
                Err(e) => not_ready.push(fail("migrations", e.to_string())),
            }
            match app.store.datasets().await {
                Ok(rows) => {
                    for row in rows {
                        if let Err(e) = app.dataset(&row).await {
                            not_ready.push(fail("datasets", Chain(&e).to_string()));
                        }
                    }
                }
                Err(e) => not_ready.push(fail("datasets", e.to_string())),
            }
        }
    }
    Readiness {
        ready: not_ready.is_empty(),
        not_ready,
    }
}

/// The metrics exposition, with the queue depth and the age of the newest worker beat read
/// from the database first (each kept at its last value, and the failure logged, when the
/// database does not answer).
pub async fn metrics_text(app: &App) -> String {
    match tokio::time::timeout(DATABASE_TIMEOUT, app.store.queue_depth()).await {
        Ok(Ok(counts)) => crate::ops::metrics::set_queue_depth(&counts),
        Ok(Err(e)) => tracing::warn!(error = %e, "queue depth not read"),
        Err(_) => tracing::warn!("queue depth not read: the database did not answer"),
    }
    match tokio::time::timeout(DATABASE_TIMEOUT, app.store.newest_beat()).await {
        Ok(Ok(newest)) => crate::ops::metrics::set_heartbeat_age(
            newest.map(|at| (now_ms() - at).max(0) as f64 / 1000.0),
        ),
        Ok(Err(e)) => tracing::warn!(error = %e, "worker beats not read"),
        Err(_) => tracing::warn!("worker beats not read: the database did not answer"),
    }
    crate::ops::metrics::render()
}
