//! Dated snapshots of every leaderboard, for papers to cite. Taking one is a use case with a
//! rule on each side of the rendering: which boards a snapshot holds (each protocol, over all
//! datasets and over each one, as HTML and JSON, with the CSV and JSON exports), that it is shown nowhere until every board is
//! kept and is discarded if one fails, and that the administrator's act is audited. The
//! rendering itself is the web layer's (the very templates and JSON of the live boards, so a
//! snapshot reads like the page it froze), so the web layer hands its renderer in as a
//! [`Boards`]: the service decides what to render and keeps the bytes, the web layer only turns
//! one board into bytes. A trait rather than a closure, so that the future it returns can be
//! required to be `Send` (the handler's future must be).

use std::future::Future;

use crate::app::App;
use crate::board_cache::gzip;
use crate::clock::now_ms;
use crate::domain::{BoardProtocol, SnapshotId};
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::store::snapshots::{BoardFormat, SnapshotBoard, SnapshotRow};

/// One board of the snapshot being taken.
pub struct Board<'a> {
    /// The snapshot's id (its permalink names it).
    pub snapshot: SnapshotId,
    pub taken_at: i64,
    pub protocol: BoardProtocol,
    /// Empty for the board of all datasets.
    pub dataset: &'a str,
}

/// A board rendered every way a snapshot keeps it: the page, its JSON twin, and the exports
/// the page offers (so that they download the snapshot's rows, not today's).
pub struct Rendered {
    pub html: Vec<u8>,
    pub json: Vec<u8>,
    pub csv: Vec<u8>,
    pub export_json: Vec<u8>,
}

/// What renders the boards of a snapshot: the web layer.
pub trait Boards: Sync {
    fn render(&self, board: &Board<'_>) -> impl Future<Output = AppResult<Rendered>> + Send;
}

/// Takes a snapshot of every board now, by `actor` (an administrator), rendering each with
/// `boards`; a failed rendering discards it.
pub async fn take(app: &App, actor: &User, boards: &impl Boards) -> AppResult<SnapshotRow> {
    let taken_at = now_ms();
    let id = app.store.begin_snapshot(actor.id, taken_at).await?;
    match render_every_board(app, boards, id, taken_at).await {
        Ok(kept) => app.store.complete_snapshot(id, &kept).await?,
        Err(e) => {
            app.store.discard_snapshot(id).await?;
            return Err(e);
        }
    }
    app.store
        .audit(actor.id, AdminAction::Snapshot, &id.to_string())
        .await?;
    app.store.snapshot(id).await?.ok_or(AppError::NotFound)
}

/// Renders every board for snapshot `snapshot`, dated `taken_at` (a challenge's is dated at its
/// deadline, whenever it is taken).
pub(crate) async fn render_every_board(
    app: &App,
    boards: &impl Boards,
    snapshot: SnapshotId,
    taken_at: i64,
) -> AppResult<Vec<SnapshotBoard>> {
    let mut datasets = vec![String::new()];
    datasets.extend(app.store.datasets().await?.into_iter().map(|d| d.name));
    let mut kept = Vec::with_capacity(4 * BoardProtocol::ALL.len() * datasets.len());
    for protocol in BoardProtocol::ALL {
        for dataset in &datasets {
            let board = Board {
                snapshot,
                taken_at,
                protocol,
                dataset,
            };
            let rendered = boards.render(&board).await?;
            for (format, bytes) in [
                (BoardFormat::Html, rendered.html),
                (BoardFormat::Json, rendered.json),
                (BoardFormat::Csv, rendered.csv),
                (BoardFormat::ExportJson, rendered.export_json),
            ] {
                kept.push(SnapshotBoard {
                    protocol,
                    dataset: dataset.clone(),
                    format,
                    gzip: gzip(&bytes),
                });
            }
        }
    }
    Ok(kept)
}

/// Every complete snapshot, newest first.
pub async fn list(app: &App) -> AppResult<Vec<SnapshotRow>> {
    Ok(app.store.snapshots().await?)
}

/// The stored bytes (gzip-compressed) of one board of snapshot `id`; missing if there is no
/// such board.
pub async fn board(
    app: &App,
    id: SnapshotId,
    protocol: BoardProtocol,
    dataset: &str,
    format: BoardFormat,
) -> AppResult<Vec<u8>> {
    app.store
        .snapshot_board(id, protocol, dataset, format)
        .await?
        .ok_or(AppError::NotFound)
}
