//! Challenges: an administrator names boards (tasks x dataset groups, narrowed to a category
//! of methods if asked) and a deadline; at the deadline the service snapshots the boards by
//! itself, once whatever the number of servers, dated at the deadline even when it is taken
//! later (no server was running at the minute: the next start takes it). Submissions stay
//! welcome afterwards and carry "after the deadline" on the challenge's boards.
//!
//! Awards are decided on the rows frozen with the snapshot (each task's board over the first
//! group, with the method fields as they stood), never on today's, so a method edited after
//! the deadline keeps or misses its award as it was; an organiser may override one, with a
//! note, audited. The rules themselves are [`awards`], free of I/O.

pub mod awards;

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{
    Award, BoardProtocol, ChallengeSlug, ChallengeSpec, FieldError, MethodId, Note, SnapshotId,
};
use crate::error::{AppError, AppResult, Chain};
use crate::service::leaderboard::{self, BoardFilter};
use crate::service::snapshots::{self, Boards};
use crate::service::{groups, visibility};
use crate::store::StoreError;
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::store::challenges::{AwardOverride, ChallengeRow, FrozenEntry};

/// How long a process holds a challenge while it takes its snapshot: another may take over
/// once this has passed without one recorded (the first process died meanwhile).
const CLAIM_MS: i64 = 10 * 60 * 1000;

/// Creates a challenge (audited); its deadline must be ahead and its groups must exist.
pub async fn create(app: &App, actor: &User, spec: ChallengeSpec) -> AppResult<ChallengeRow> {
    if spec.deadline <= now_ms() {
        return Err(FieldError {
            field: "deadline",
            problem: "must be in the future".into(),
        }
        .into());
    }
    let known: Vec<String> = groups::all(app)
        .await?
        .into_iter()
        .map(|g| g.name)
        .collect();
    if let Some(unknown) = spec.groups.iter().find(|g| !known.contains(&g.to_string())) {
        return Err(FieldError {
            field: "groups",
            problem: format!(
                "names `{unknown}`, which is no group: the groups are {}",
                known.join(", ")
            ),
        }
        .into());
    }
    match app.store.create_challenge(&spec, actor.id).await {
        Ok(_) => {}
        Err(StoreError::Unique { .. }) => {
            return Err(AppError::Conflict(format!(
                "a challenge `{}` exists: choose another slug",
                spec.slug
            )));
        }
        Err(e) => return Err(e.into()),
    }
    app.store
        .audit(actor.id, AdminAction::CreateChallenge, spec.slug.as_str())
        .await?;
    app.store
        .challenge_by_slug(spec.slug.as_str())
        .await?
        .ok_or(AppError::NotFound)
}

/// Every challenge, the latest deadline first.
pub async fn list(app: &App) -> AppResult<Vec<ChallengeRow>> {
    Ok(app.store.challenges().await?)
}

/// A row of a challenge's board as it stands.
#[derive(Clone, Debug)]
pub struct Line {
    pub rank: Option<usize>,
    pub method_id: MethodId,
    pub method: String,
    /// As every reader sees it (`anonymous` for a method under review).
    pub owner: String,
    pub average: Option<f64>,
    pub time: Option<f64>,
    /// One of its entries was submitted after the deadline.
    pub after_deadline: bool,
}

/// One board of a challenge: a task over a group, as it stands.
#[derive(Clone, Debug)]
pub struct Board {
    pub protocol: BoardProtocol,
    pub group: String,
    /// The query of the live board it is (group and categories).
    pub filter: BoardFilter,
    /// The group's datasets served here.
    pub columns: Vec<String>,
    pub lines: Vec<Line>,
}

/// An award of one task, decided.
#[derive(Clone, Debug)]
pub struct Decided {
    pub protocol: BoardProtocol,
    pub award: Award,
    pub rule: String,
    /// The winner (rule's or organisers'); none: nobody qualifies, or not awarded.
    pub winner: Option<FrozenEntry>,
    /// The organisers' override of the rule, if any.
    pub overridden: Option<AwardOverride>,
}

/// A challenge with its boards, its snapshot and, once taken, its awards.
#[derive(Clone, Debug)]
pub struct Challenge {
    pub row: ChallengeRow,
    pub boards: Vec<Board>,
    pub awards: Vec<Decided>,
}

/// The board query of challenge `c`'s board of `group`.
fn filter(c: &ChallengeRow, group: &str) -> BoardFilter {
    let given = |v: &str| (!v.is_empty()).then(|| v.to_string());
    BoardFilter {
        group: Some(group.to_string()),
        objects: given(&c.objects),
        onboarding: given(&c.onboarding),
        ..BoardFilter::default()
    }
}

/// The challenge of `slug` with its boards as they stand and its awards.
pub async fn show(app: &App, slug: &str) -> AppResult<Challenge> {
    let slug = ChallengeSlug::parse(slug).map_err(|_| AppError::NotFound)?;
    let row = app
        .store
        .challenge_by_slug(slug.as_str())
        .await?
        .ok_or(AppError::NotFound)?;
    let mut boards = Vec::new();
    for protocol in row.tasks.clone() {
        for group in &row.groups {
            boards.push(board(app, &row, protocol, group).await?);
        }
    }
    let awards = match row.snapshot_id {
        Some(_) => decide(app, &row).await?,
        None => Vec::new(),
    };
    Ok(Challenge {
        row,
        boards,
        awards,
    })
}

async fn board(
    app: &App,
    c: &ChallengeRow,
    protocol: BoardProtocol,
    group: &str,
) -> AppResult<Board> {
    let filter = filter(c, group);
    let ranked = leaderboard::board(app, protocol, &filter).await?;
    let ids: Vec<_> = ranked
        .rows
        .iter()
        .flat_map(|r| r.scores.values().map(|cell| cell.submission_id))
        .collect();
    let submitted = app.store.submitted_at(&ids).await?;
    let lines = ranked
        .rows
        .into_iter()
        .map(|r| Line {
            after_deadline: r.scores.values().any(|cell| {
                submitted
                    .get(&cell.submission_id)
                    .is_some_and(|at| *at > c.deadline)
            }),
            rank: r.rank,
            method_id: r.method_id,
            method: r.method,
            owner: r.owner,
            average: r.average,
            time: r.time,
        })
        .collect();
    Ok(Board {
        protocol,
        group: ranked.group,
        filter,
        columns: ranked.columns.into_iter().map(|d| d.name).collect(),
        lines,
    })
}

/// Each task's awards from the rows frozen at the deadline, with the organisers' overrides.
async fn decide(app: &App, c: &ChallengeRow) -> AppResult<Vec<Decided>> {
    let entries = app.store.frozen_entries(c.id).await?;
    let overrides = app.store.award_overrides(c.id).await?;
    let mut out = Vec::new();
    for &protocol in &c.tasks {
        for &award in &c.awards {
            let overridden = overrides
                .iter()
                .find(|o| o.protocol == protocol && o.award == award)
                .cloned();
            let winner = match &overridden {
                Some(o) => o.method_id.and_then(|id| {
                    entries
                        .iter()
                        .find(|e| e.protocol == protocol && e.method_id == id)
                }),
                None => awards::winner(award, protocol, &entries, c.fast_seconds),
            };
            out.push(Decided {
                protocol,
                award,
                rule: awards::rule(award, c.fast_seconds),
                winner: winner.cloned(),
                overridden,
            });
        }
    }
    Ok(out)
}

/// The organisers' decision on an award, as sent: the task and award it is about, the method
/// it goes to (none: not awarded) and why.
pub struct OverrideRequest {
    pub task: String,
    pub award: String,
    pub method_id: Option<MethodId>,
    pub note: String,
}

/// Overrides an award of challenge `slug` (audited): only once the deadline's snapshot is
/// taken, for a task and award of the challenge, to a method on that task's board then.
pub async fn override_award(
    app: &App,
    actor: &User,
    slug: &str,
    request: OverrideRequest,
) -> AppResult<Challenge> {
    let c = show(app, slug).await?;
    if c.row.snapshot_id.is_none() {
        return Err(AppError::Conflict(
            "the awards are decided at the deadline: nothing to override yet".into(),
        ));
    }
    let protocol = BoardProtocol::named(request.task.trim())
        .filter(|p| c.row.tasks.contains(p))
        .ok_or_else(|| field("task", "is none of the challenge's tasks"))?;
    let award: Award = request.award.trim().parse()?;
    if !c.row.awards.contains(&award) {
        return Err(field("award", "is not one the challenge gives").into());
    }
    let note = Note::parse("note", &request.note)?;
    if note.as_str().is_empty() {
        return Err(field("note", "is required: say why the rule is overridden").into());
    }
    if let Some(id) = request.method_id {
        let entries = app.store.frozen_entries(c.row.id).await?;
        if !entries
            .iter()
            .any(|e| e.protocol == protocol && e.method_id == id)
        {
            return Err(field(
                "method_id",
                "is no method on the task's board at the deadline",
            )
            .into());
        }
    }
    app.store
        .set_award_override(
            c.row.id,
            &AwardOverride {
                protocol,
                award,
                method_id: request.method_id,
                note: note.to_string(),
                set_by: actor.name.clone(),
                set_at: now_ms(),
            },
            actor.id,
        )
        .await?;
    let target = format!(
        "{} {} {}: {}",
        c.row.slug,
        protocol.as_str(),
        award.as_str(),
        request
            .method_id
            .map_or("not awarded".to_string(), |m| format!("method {m}"))
    );
    app.store
        .audit(actor.id, AdminAction::OverrideAward, &target)
        .await?;
    show(app, slug).await
}

fn field(field: &'static str, problem: &str) -> FieldError {
    FieldError {
        field,
        problem: problem.to_string(),
    }
}

/// Takes the snapshot of every challenge whose deadline has passed without one, rendering
/// the boards with `boards`; the challenges another process holds are left to it. Returns the
/// snapshots taken here.
pub async fn take_due_snapshots(app: &App, boards: &impl Boards) -> AppResult<Vec<SnapshotId>> {
    let now = now_ms();
    let mut taken = Vec::new();
    for c in app.store.due_challenges(now).await? {
        if !app.store.claim_challenge(c.id, now, now + CLAIM_MS).await? {
            continue;
        }
        match take_at_deadline(app, &c, boards).await {
            Ok(Some(id)) => {
                tracing::info!(challenge = %c.slug, snapshot = %id, "snapshot at the deadline taken");
                taken.push(id);
            }
            Ok(None) => {}
            Err(e) => {
                tracing::error!(challenge = %c.slug, error = %Chain(&e), "snapshot at the deadline failed");
            }
        }
    }
    Ok(taken)
}

/// Takes challenge `c`'s snapshot, dated at its deadline: every board rendered, and the rows
/// of each task's board over the first group frozen with their method fields; none when
/// another process recorded one first.
async fn take_at_deadline(
    app: &App,
    c: &ChallengeRow,
    boards: &impl Boards,
) -> AppResult<Option<SnapshotId>> {
    let entries = freeze(app, c).await?;
    let id = app.store.begin_snapshot(c.created_by, c.deadline).await?;
    let kept = match snapshots::render_every_board(app, boards, id, c.deadline).await {
        Ok(kept) => kept,
        Err(e) => {
            app.store.discard_snapshot(id).await?;
            return Err(e);
        }
    };
    if app
        .store
        .complete_challenge_snapshot(c.id, id, &kept, &entries)
        .await?
    {
        Ok(Some(id))
    } else {
        app.store.discard_snapshot(id).await?;
        Ok(None)
    }
}

/// The rows of each task's board over the first group, as they stood at the deadline: a row
/// with an entry submitted later is left out (the check may run after the deadline), and each
/// keeps its method's fields as they are now, which is then.
async fn freeze(app: &App, c: &ChallengeRow) -> AppResult<Vec<FrozenEntry>> {
    let Some(group) = c.groups.first() else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for &protocol in &c.tasks {
        let board = board(app, c, protocol, group).await?;
        for line in board.lines.into_iter().filter(|l| !l.after_deadline) {
            let Some(method) = app.store.method(line.method_id).await? else {
                continue;
            };
            // What the public was shown then: no code link of a method under review.
            let method = visibility::method_as_seen(method, None);
            out.push(FrozenEntry {
                protocol,
                method_id: line.method_id,
                method: line.method,
                owner: line.owner,
                average: line.average,
                time: line.time,
                training_data: method.training_data,
                detection_modality: method.detection_modality,
                modality: method.modality,
                code_url: method.code_url,
                model_scope: method.model_scope,
                detections: method.detections,
            });
        }
    }
    Ok(out)
}
