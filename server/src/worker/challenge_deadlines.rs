//! The watch on the challenges' deadlines: a task of the server process that takes the
//! snapshot of every challenge whose deadline has passed, at start (a deadline that passed
//! while no server ran is caught up then, the snapshot still dated at the deadline) and then
//! periodically. Every server runs one; the database decides which takes each snapshot (see
//! [`crate::store::challenges`]), so several servers on one database take it once.
//!
//! The boards are rendered by the caller's [`Boards`] (the web layer's), handed in so that the
//! workers stay free of it.

use std::time::Duration;

use tokio::task::JoinHandle;

use crate::app::AppState;
use crate::error::Chain;
use crate::service::challenges;
use crate::service::snapshots::Boards;
use crate::shutdown::Shutdown;

/// Starts the watch: it looks now and then every `every`, until `shutdown` is set.
pub fn spawn_deadline_watch<B>(
    app: &AppState,
    boards: B,
    shutdown: &Shutdown,
    every: Duration,
) -> JoinHandle<()>
where
    B: Boards + Send + 'static,
{
    let (app, shutdown) = (app.clone(), shutdown.clone());
    tokio::spawn(async move {
        while !shutdown.is_set() {
            if let Err(e) = challenges::take_due_snapshots(&app, &boards).await {
                tracing::error!(error = %Chain(&e), "looking for challenges past their deadline");
            }
            tokio::select! {
                _ = shutdown.wait() => break,
                _ = tokio::time::sleep(every) => {}
            }
        }
    })
}
