//! The challenges' list and page, built once and rendered as HTML and JSON: the challenge's
//! definition, its boards as they stand (rows submitted after the deadline marked), its
//! snapshot once taken, and its awards with their rules.

use serde::Serialize;

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{Award, BoardProtocol, MethodId, SnapshotId};
use crate::error::AppResult;
use crate::service::challenges::{self, Board, Challenge, Decided, Line};
use crate::store::challenges::ChallengeRow;
use crate::web::views::urlencode;
use crate::wording;

/// A challenge as listed, and the head of its page.
#[derive(Clone, Debug, Serialize)]
pub struct ChallengeSummary {
    pub slug: String,
    pub name: String,
    pub tasks: Vec<BoardProtocol>,
    pub groups: Vec<String>,
    /// The categories filter; empty: any.
    pub objects: String,
    pub onboarding: String,
    /// Epoch milliseconds, and as RFC 3339 in UTC.
    pub deadline: i64,
    pub deadline_utc: String,
    /// The deadline has passed.
    pub closed: bool,
    pub fast_seconds: f64,
    pub awards: Vec<Award>,
    /// The snapshot taken at the deadline, once taken.
    pub snapshot_id: Option<SnapshotId>,
    pub url: String,
    pub json_url: String,
}

impl From<&ChallengeRow> for ChallengeSummary {
    fn from(c: &ChallengeRow) -> ChallengeSummary {
        let url = format!("/challenges/{}", c.slug);
        ChallengeSummary {
            slug: c.slug.clone(),
            name: c.name.clone(),
            tasks: c.tasks.clone(),
            groups: c.groups.clone(),
            objects: c.objects.clone(),
            onboarding: c.onboarding.clone(),
            deadline: c.deadline,
            deadline_utc: wording::rfc3339(c.deadline),
            closed: c.deadline <= now_ms(),
            fast_seconds: c.fast_seconds,
            awards: c.awards.clone(),
            snapshot_id: c.snapshot_id,
            json_url: format!("/api/v1{url}"),
            url,
        }
    }
}

/// A row of a challenge's board.
#[derive(Clone, Debug, Serialize)]
pub struct RowView {
    pub rank: Option<usize>,
    pub method_id: MethodId,
    pub method: String,
    pub owner: String,
    pub average: Option<f64>,
    pub time: Option<f64>,
    /// One of its entries was submitted after the deadline.
    pub after_deadline: bool,
}

impl From<Line> for RowView {
    fn from(l: Line) -> RowView {
        RowView {
            rank: l.rank,
            method_id: l.method_id,
            method: l.method,
            owner: l.owner,
            average: l.average,
            time: l.time,
            after_deadline: l.after_deadline,
        }
    }
}

/// A board of a challenge: a task over a group.
#[derive(Clone, Debug, Serialize)]
pub struct BoardView {
    pub protocol: BoardProtocol,
    pub group: String,
    pub columns: Vec<String>,
    /// The live board it is, with its per-dataset columns and filters.
    pub url: String,
    pub rows: Vec<RowView>,
}

impl From<Board> for BoardView {
    fn from(b: Board) -> BoardView {
        BoardView {
            url: format!("/leaderboards/{}{}", b.protocol.as_str(), b.filter.query()),
            protocol: b.protocol,
            group: b.group,
            columns: b.columns,
            rows: b.lines.into_iter().map(Into::into).collect(),
        }
    }
}

/// Who won an award.
#[derive(Clone, Debug, Serialize)]
pub struct WinnerView {
    pub method_id: MethodId,
    pub method: String,
    pub owner: String,
    pub average: Option<f64>,
}

/// The organisers' override of an award.
#[derive(Clone, Debug, Serialize)]
pub struct OverrideView {
    pub note: String,
    pub by: String,
    pub at: i64,
}

/// An award of one task, with its rule.
#[derive(Clone, Debug, Serialize)]
pub struct AwardView {
    pub task: BoardProtocol,
    pub award: Award,
    pub title: &'static str,
    pub rule: String,
    /// None: nobody qualifies, or the organisers did not award it.
    pub winner: Option<WinnerView>,
    #[serde(rename = "override")]
    pub overridden: Option<OverrideView>,
}

impl From<Decided> for AwardView {
    fn from(d: Decided) -> AwardView {
        AwardView {
            task: d.protocol,
            award: d.award,
            title: challenges::awards::title(d.award),
            rule: d.rule,
            winner: d.winner.map(|w| WinnerView {
                method_id: w.method_id,
                method: w.method,
                owner: w.owner,
                average: w.average,
            }),
            overridden: d.overridden.map(|o| OverrideView {
                note: o.note,
                by: o.set_by,
                at: o.set_at,
            }),
        }
    }
}

/// A challenge's page.
#[derive(Clone, Debug, Serialize)]
pub struct ChallengeView {
    #[serde(flatten)]
    pub summary: ChallengeSummary,
    /// The snapshot's page, once taken.
    pub snapshot_url: Option<String>,
    pub boards: Vec<BoardView>,
    /// Decided at the deadline: empty before.
    pub awards: Vec<AwardView>,
}

impl From<Challenge> for ChallengeView {
    fn from(c: Challenge) -> ChallengeView {
        ChallengeView {
            snapshot_url: c.row.snapshot_id.map(|id| format!("/snapshots/{id}")),
            summary: (&c.row).into(),
            boards: c.boards.into_iter().map(Into::into).collect(),
            awards: c.awards.into_iter().map(Into::into).collect(),
        }
    }
}

/// Every challenge, the latest deadline first.
pub async fn list(app: &App) -> AppResult<Vec<ChallengeSummary>> {
    Ok(challenges::list(app)
        .await?
        .iter()
        .map(Into::into)
        .collect())
}

/// The page of challenge `slug`.
pub async fn page(app: &App, slug: &str) -> AppResult<ChallengeView> {
    Ok(challenges::show(app, slug).await?.into())
}

/// A challenge's page address.
pub fn challenge_url(slug: &str) -> String {
    format!("/challenges/{}", urlencode(slug))
}
