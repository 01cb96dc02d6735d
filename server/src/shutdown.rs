//! Stopping on SIGINT or SIGTERM: one signal that every part of a process watches. The HTTP
//! server stops accepting, idle workers stop claiming, and a running evaluation is cancelled and
//! its job released at once (queued again, no attempt lost), so another worker takes it without
//! waiting for the lease to expire.

use tokio::sync::watch;

/// The process-wide stop signal; cheap to clone.
#[derive(Clone)]
pub struct Shutdown {
    rx: watch::Receiver<bool>,
}

impl Shutdown {
    /// A signal set when the process receives SIGINT or SIGTERM.
    pub fn on_signals() -> std::io::Result<Shutdown> {
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate())?;
        let mut int = signal(SignalKind::interrupt())?;
        let (tx, rx) = watch::channel(false);
        tokio::spawn(async move {
            let name = tokio::select! {
                _ = term.recv() => "SIGTERM",
                _ = int.recv() => "SIGINT",
            };
            tracing::info!(
                signal = name,
                "stopping: no new jobs, running ones released"
            );
            let _ = tx.send(true);
        });
        Ok(Shutdown { rx })
    }

    pub fn is_set(&self) -> bool {
        *self.rx.borrow()
    }

    /// Resolves once the signal is set.
    pub async fn wait(&self) {
        let mut rx = self.rx.clone();
        let _ = rx.wait_for(|set| *set).await;
    }
}
