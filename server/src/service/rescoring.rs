//! Re-scoring when the evaluator changes: at start, `serve` and `worker` flag the finished
//! submissions whose scores an older evaluator computed (idle workers then re-score them), and
//! `/rescoring` lists every number that changed.
//!
//! Only versions older than the running one are flagged, never merely different ones: during a
//! rolling upgrade an old worker and a new one share the database, and "different" would have
//! each re-score the other's scores back and forth. Scores of a newer evaluator stay as they
//! are when an older one runs (a rollback), and are re-scored once a version at least as new
//! runs again.

use serde::Serialize;

use crate::app::App;
use crate::error::AppResult;
use crate::store::accounts::User;
use crate::store::rescoring::{Reader, ScoreChange};
use crate::store::{Store, StoreResult};

/// The most changes one answer lists.
const LISTED: i64 = 1000;

/// Whether scores recorded with evaluator `stored` predate the `running` one: their numeric
/// components (`0.1.0` as 0, 1, 0; anything else in between separates them) compared in order.
pub fn is_older(stored: &str, running: &str) -> bool {
    let key = |v: &str| -> Vec<u64> {
        v.split(|c: char| !c.is_ascii_digit())
            .filter(|p| !p.is_empty())
            .map(|p| p.parse().unwrap_or(u64::MAX))
            .collect()
    };
    key(stored) < key(running)
}

/// Flags for re-scoring what an older evaluator (or none recorded) scored, and scores without
/// bootstrap replicates; how many submissions were flagged.
pub async fn flag_stale(store: &Store) -> StoreResult<u64> {
    let running = evaluator::report::EVALUATOR_VERSION;
    let stale: Vec<String> = store
        .finished_evaluator_versions()
        .await?
        .into_iter()
        .flatten()
        .filter(|v| is_older(v, running))
        .collect();
    let flagged = store.flag_rescoring(&stale).await?;
    if flagged > 0 {
        tracing::info!(
            flagged,
            evaluator = running,
            "submissions queued for re-scoring"
        );
    }
    Ok(flagged)
}

/// The `/rescoring` page and its JSON twin.
#[derive(Clone, Debug, Serialize)]
pub struct Rescoring {
    /// The evaluator version this server runs.
    pub evaluator_version: &'static str,
    /// Newest first: those of public submissions, and of the viewer's own (all for admins).
    pub changes: Vec<ScoreChange>,
}

/// The changes `reader` (signed in, or not) may see.
pub async fn view(app: &App, reader: Option<&User>) -> AppResult<Rescoring> {
    let reader = Reader {
        user_id: reader.map(|u| u.id),
        admin: reader.is_some_and(|u| u.is_admin),
    };
    Ok(Rescoring {
        evaluator_version: evaluator::report::EVALUATOR_VERSION,
        changes: app.store.score_changes(reader, LISTED).await?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_compare_by_their_numbers() {
        assert!(is_older("0.1.0", "0.2.0"));
        assert!(is_older("0.9.0", "0.10.0"));
        assert!(is_older("0.0.0-before", "0.1.0"));
        assert!(!is_older("0.1.0", "0.1.0"));
        assert!(!is_older("0.2.0", "0.1.0"));
        assert!(is_older("", "0.1.0"));
    }
}
