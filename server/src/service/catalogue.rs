//! What anyone may list, signed in or not: the datasets served (with how far each host has
//! prepared them), the methods with a public submission, the latest public finished
//! submissions. Plain reads, but they go through here
//! like every other use case so that the web layer never reaches the store, and a rule added to
//! a list (paging, a filter, who a method is shown to be) has one place to live.

use evaluator::protocol::ProtocolName;
use serde::Serialize;

use crate::app::App;
use crate::domain::{BoardProtocol, MethodId, PageNumber, SubmissionId, Task};
use crate::error::AppResult;
use crate::service::visibility;
use crate::store::datasets::DatasetRow;
use crate::store::methods::MethodRow;
use crate::store::preparations::PreparationRow;
use crate::store::submissions::RecentRow;

/// How many submissions a page of the recent list (and its feed) holds.
pub const RECENT_PER_PAGE: u32 = 50;

/// A served dataset with how far each evaluating host has prepared it.
#[derive(Clone, Debug, Serialize)]
pub struct ServedDataset {
    #[serde(flatten)]
    pub dataset: DatasetRow,
    /// One per host and prepared folder that has begun preparing it.
    pub prepared: Vec<PreparationRow>,
}

/// The datasets served (not retired), by name, with their preparations.
pub async fn datasets(app: &App) -> AppResult<Vec<ServedDataset>> {
    let preparations = app.store.preparations().await?;
    Ok(app
        .store
        .datasets()
        .await?
        .into_iter()
        .map(|dataset| ServedDataset {
            prepared: preparations
                .iter()
                .filter(|p| p.dataset_id == dataset.id)
                .cloned()
                .collect(),
            dataset,
        })
        .collect())
}

/// The methods with a public submission, by name, as the public sees them (see
/// [`visibility::method_as_seen`]).
pub async fn public_methods(app: &App) -> AppResult<Vec<MethodRow>> {
    Ok(app
        .store
        .public_methods()
        .await?
        .into_iter()
        .map(|m| visibility::method_as_seen(m, None))
        .collect())
}

/// A public finished submission as the recent list and its feed show it: "date – method –
/// dataset – task by owner", with its headline score.
#[derive(Clone, Debug, Serialize)]
pub struct Recent {
    pub id: SubmissionId,
    /// When it was submitted and when its scores came (epoch ms).
    pub created_at: i64,
    pub finished_at: Option<i64>,
    pub method_id: MethodId,
    pub method: String,
    pub dataset: String,
    /// What it is scored for: its 6D protocols (`bop19, eccv18`) or its task.
    pub task: String,
    /// Its method's owner, or "anonymous" while the method is under double-blind review.
    pub owner: String,
    pub score: Option<Headline>,
}

/// The score a submission is known by: its first board's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Headline {
    pub board: BoardProtocol,
    /// What the number is on that board: `AR`, `recall`, `AP` or `mAP`.
    pub name: &'static str,
    /// A fraction.
    pub value: f64,
}

/// One page of the recent list, newest first.
#[derive(Clone, Debug, Serialize)]
pub struct RecentPage {
    pub page: PageNumber,
    pub submissions: Vec<Recent>,
    /// Older submissions follow on the next page.
    pub more: bool,
}

/// Page `page` of the public finished submissions, newest first, [`RECENT_PER_PAGE`] a page;
/// each names its owner as every reader may see it.
pub async fn recent(app: &App, page: PageNumber) -> AppResult<RecentPage> {
    let per_page = i64::from(RECENT_PER_PAGE);
    let offset = i64::from(page.get() - 1) * per_page;
    let mut rows = app
        .store
        .recent_public_finished(per_page + 1, offset)
        .await?;
    let more = rows.len() as i64 > per_page;
    rows.truncate(RECENT_PER_PAGE as usize);
    Ok(RecentPage {
        page,
        submissions: rows.into_iter().map(recent_of).collect(),
        more,
    })
}

fn recent_of(row: RecentRow) -> Recent {
    let score = headline(row.submission.task, &row.submission.protocols, &row);
    let s = row.submission;
    let task = match s.task {
        Some(t) => t.as_str().to_string(),
        None => s
            .protocols
            .iter()
            .map(|p| p.as_str())
            .collect::<Vec<_>>()
            .join(", "),
    };
    Recent {
        score,
        owner: visibility::public_owner(row.owner, row.anonymous),
        id: s.id,
        created_at: s.created_at,
        finished_at: s.finished_at,
        method_id: s.method_id,
        method: s.method,
        dataset: s.dataset,
        task,
    }
}

/// The headline of a submission scored for `task` or under `protocols`: a task's own score,
/// else the first 6D protocol's (bop19's AR before eccv18's recall, as the boards list them).
fn headline(task: Option<Task>, protocols: &[ProtocolName], row: &RecentRow) -> Option<Headline> {
    let (board, name, value) = match task {
        Some(Task::Coco(t)) => (BoardProtocol::Coco(t), "AP", row.ap),
        Some(Task::Bop24) => (BoardProtocol::Bop24, "mAP", row.map),
        None if protocols.contains(&ProtocolName::Bop19) && row.bop19.is_some() => {
            (ProtocolName::Bop19.into(), "AR", row.bop19)
        }
        None => (ProtocolName::Eccv18.into(), "recall", row.eccv18),
    };
    value
        .filter(|v| v.is_finite())
        .map(|value| Headline { board, name, value })
}
