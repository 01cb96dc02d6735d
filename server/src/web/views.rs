//! The data behind each page, built once and rendered twice: as HTML by the templates and as
//! JSON by the API, so that a page and its JSON twin can never disagree.

pub mod challenges;
pub mod targets;

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::CocoReport;
use evaluator::detection::DetectionReport;
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::report::{Parameters, parameters};
use serde::Serialize;

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{
    BoardProtocol, CocoProtocol, MethodId, PageNumber, SnapshotId, SubmissionId, Task,
};
use crate::error::AppResult;
use crate::preflight::Preflight;
use crate::service::catalogue::{self, RECENT_PER_PAGE, RecentPage};
pub use crate::service::groups::core_datasets;
use crate::service::leaderboard::{self, Curves};
pub use crate::service::leaderboard::{BoardFilter, OVERLAID};
pub use crate::service::ranking::{BoardRow, Cell};
use crate::service::{publishing, submission_details};
use crate::store::accounts::User;
use crate::store::datasets::DatasetRow;
use crate::store::scores::ScoreRecord;
use crate::store::submissions::{QueuePlace, Status, SubmissionRow};
use crate::web::auth::Viewer;
use crate::web::render::chart::{self, Chart};
use crate::wording;

#[derive(Clone, Debug, Serialize)]
pub struct Leaderboard {
    pub protocol: BoardProtocol,
    pub score_name: &'static str,
    pub time_unit: &'static str,
    /// The 6D protocol's parameters (none for a 2D task: COCOeval's are fixed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameters: Option<Parameters>,
    /// The bop24 board: per dataset shown, the estimates kept per image (the toolkit's cap).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_estimates_per_image: Option<BTreeMap<String, usize>>,
    /// 2D boards: the keys of the AP/AR numbers, in COCOeval's order (each cell's `stats`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stat_names: Vec<&'static str>,
    /// Every dataset served (each has its own board).
    pub datasets: Vec<DatasetRow>,
    /// The group of datasets ranked over (`?group=`; `core` by default).
    pub group: String,
    /// Every group's name, the default first: the groups the page offers.
    pub groups: Vec<String>,
    /// The names of the group's datasets served here: the columns of the main table (the
    /// default group's are the core datasets, hence the key).
    pub core: Vec<String>,
    /// The datasets shown as columns: the group's, or the one selected.
    pub columns: Vec<DatasetRow>,
    /// With `?dataset=NAME`, that dataset (and the rows carry per-object scores).
    pub dataset: Option<DatasetRow>,
    pub object_ids: Vec<i64>,
    pub filter: BoardFilter,
    /// What the rows are ordered by: `average`, `time`, `method` or a dataset name.
    pub sorted_by: String,
    pub rows: Vec<BoardRow>,
    /// With one dataset selected: the curves of its best entries (at most [`OVERLAID`]),
    /// overlaid one chart per curve: recall curves on a 6D board, precision-recall on a 2D one.
    #[serde(skip)]
    pub overlays: Vec<Chart>,
    /// With one dataset selected: every ranked method, whether its curves are drawn, and the
    /// link that draws them or stops drawing them (none when [`OVERLAID`] are drawn already).
    #[serde(skip)]
    pub curve_choices: Vec<CurveChoice>,
}

/// A method offered for the overlaid curves of a dataset's board.
#[derive(Clone, Debug)]
pub struct CurveChoice {
    pub method: String,
    pub drawn: bool,
    pub href: Option<String>,
}

/// The links a board's page makes from its query: URLs are the web layer's, so they are
/// written here, on the service's type.
impl BoardFilter {
    /// Whether the reader chose the methods the curves overlay.
    pub fn curves_chosen(&self) -> bool {
        self.curves.as_deref().is_some_and(|c| !c.is_empty())
    }

    /// Whether the filter leaves out methods by their training data, input or categories.
    pub fn narrows(&self) -> bool {
        [
            &self.training,
            &self.modality,
            &self.objects,
            &self.onboarding,
        ]
        .iter()
        .any(|v| v.as_deref().is_some_and(|v| !v.trim().is_empty()))
    }

    /// The query string of this board without the filters on methods.
    pub fn unfiltered(&self) -> String {
        BoardFilter {
            training: None,
            modality: None,
            objects: None,
            onboarding: None,
            ..self.clone()
        }
        .query()
    }

    /// The query string of this filter as it stands (for the links to the board's exports).
    pub fn query(&self) -> String {
        self.with("", "")
    }

    /// The query string that keeps this filter but changes one key (for links on the page,
    /// after their path: empty when nothing is left, so that no link ends in a bare `?`).
    pub fn with(&self, key: &str, value: &str) -> String {
        let mut pairs: Vec<(&str, String)> = Vec::new();
        for (k, v) in [
            ("dataset", &self.dataset),
            ("group", &self.group),
            ("training", &self.training),
            ("modality", &self.modality),
            ("objects", &self.objects),
            ("onboarding", &self.onboarding),
            ("sort", &self.sort),
            ("curves", &self.curves),
        ] {
            if k == key {
                if !value.is_empty() {
                    pairs.push((k, value.to_string()));
                }
            } else if let Some(v) = v.as_ref().filter(|v| !v.is_empty()) {
                pairs.push((k, v.clone()));
            }
        }
        let q: Vec<String> = pairs
            .iter()
            .map(|(k, v)| format!("{k}={}", urlencode(v)))
            .collect();
        if q.is_empty() {
            String::new()
        } else {
            format!("?{}", q.join("&"))
        }
    }
}

/// The page of one board of snapshot `id` (its JSON twin is the same under `/api/v1`).
pub fn snapshot_board_url(id: SnapshotId, protocol: BoardProtocol, dataset: &str) -> String {
    format!("/snapshots/{id}{}", board_query(protocol, dataset))
}

/// The query naming one board: `?protocol=P` and, for one dataset's board, `&dataset=D`.
pub fn board_query(protocol: BoardProtocol, dataset: &str) -> String {
    if dataset.is_empty() {
        format!("?protocol={}", protocol.as_str())
    } else {
        format!(
            "?protocol={}&dataset={}",
            protocol.as_str(),
            urlencode(dataset)
        )
    }
}

/// `s` as a query string value.
pub fn urlencode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

pub fn score_name(p: BoardProtocol) -> &'static str {
    match p {
        BoardProtocol::Pose(ProtocolName::Eccv18) => "recall (VSD, tau 20 mm, theta 0.3)",
        BoardProtocol::Pose(ProtocolName::Bop19) => {
            "average recall AR = (AR_VSD + AR_MSSD + AR_MSPD) / 3"
        }
        BoardProtocol::Bop24 => {
            "bop24_mAP = (mAP_MSSD + mAP_MSPD) / 2, average precision of 6D detection (the objects and instances of an image are not given)"
        }
        BoardProtocol::Coco(CocoProtocol::Detection) => {
            "AP of the amodal boxes (COCOeval bbox: mean over IoU 0.50:0.05:0.95, 101 recall points, 100 detections per image); the average over the core datasets is AP_C"
        }
        BoardProtocol::Coco(CocoProtocol::Segmentation) => {
            "AP of the visible masks (COCOeval segm: mean over IoU 0.50:0.05:0.95, 101 recall points, 100 detections per image); the average over the core datasets is AP_C"
        }
    }
}

/// Builds a leaderboard: the ranked board of the service, with its charts and the links that
/// choose them.
pub async fn leaderboard(
    app: &App,
    protocol: BoardProtocol,
    filter: &BoardFilter,
) -> AppResult<Leaderboard> {
    let board = leaderboard::board(app, protocol, filter).await?;
    let overlays = match &board.curves {
        Some(Curves::Pose(methods)) => chart::overlays(methods),
        // A dataset's 2D board: the precision-recall curves.
        Some(Curves::Coco(reports)) if !reports.is_empty() => {
            let reports: Vec<(String, &CocoReport)> =
                reports.iter().map(|(m, r)| (m.clone(), r)).collect();
            vec![chart::precision_recall_of_methods(&reports)]
        }
        Some(Curves::Bop24(reports)) if !reports.is_empty() => {
            let reports: Vec<(String, &DetectionReport)> =
                reports.iter().map(|(m, r)| (m.clone(), r)).collect();
            vec![chart::detection_precision_recall_of_methods(&reports)]
        }
        Some(Curves::Coco(_) | Curves::Bop24(_)) | None => Vec::new(),
    };
    let curve_choices = if board.selected.is_some() {
        curve_choices(&board.ranked, &board.drawn, filter)
    } else {
        Vec::new()
    };
    Ok(Leaderboard {
        protocol,
        score_name: score_name(protocol),
        time_unit: match protocol {
            BoardProtocol::Pose(ProtocolName::Eccv18) => "s per target",
            _ => "s per image",
        },
        parameters: match protocol {
            BoardProtocol::Pose(p) => Some(parameters(&Protocol::named(p)).as_defined()),
            BoardProtocol::Bop24 | BoardProtocol::Coco(_) => None,
        },
        max_estimates_per_image: (protocol == BoardProtocol::Bop24).then(|| {
            board
                .columns
                .iter()
                .map(|d| {
                    let cap = evaluator::detection::default_max_estimates_per_image(&d.name);
                    (d.name.clone(), cap)
                })
                .collect()
        }),
        stat_names: board.stat_names,
        group: board.group,
        groups: board.groups,
        core: board.core.into_iter().map(|d| d.name).collect(),
        columns: board.columns,
        datasets: board.datasets,
        dataset: board.selected,
        object_ids: board.object_ids,
        filter: filter.clone(),
        sorted_by: board.sort.name(),
        rows: board.rows,
        overlays,
        curve_choices,
    })
}

/// The methods a dataset's board offers for its curves: each ranked row, with the link that
/// adds it to the drawn ones or takes it away (leaving none draws the best again).
fn curve_choices(
    ranked: &[(MethodId, String)],
    ids: &[MethodId],
    filter: &BoardFilter,
) -> Vec<CurveChoice> {
    let link = |ids: Vec<MethodId>| {
        let list: Vec<String> = ids.iter().map(MethodId::to_string).collect();
        filter.with("curves", &list.join(","))
    };
    ranked
        .iter()
        .map(|(id, method)| {
            let on = ids.contains(id);
            let href = if on {
                Some(link(ids.iter().copied().filter(|i| i != id).collect()))
            } else if ids.len() < OVERLAID {
                Some(link(ids.iter().copied().chain([*id]).collect()))
            } else {
                None
            };
            CurveChoice {
                method: method.clone(),
                drawn: on,
                href,
            }
        })
        .collect()
}

/// A submission with everything its page shows.
#[derive(Clone, Debug, Serialize)]
pub struct SubmissionView {
    #[serde(flatten)]
    pub submission: SubmissionRow,
    /// Queued submissions ahead of this one (queued only).
    pub queue_position: Option<i64>,
    /// Where it stands in the queue (queued only).
    pub queue: Option<QueuePlace>,
    /// "public", "private: ...", or "held: <the red flags>".
    pub publication: String,
    /// While queued or running, in plain words: the place in the queue or the estimates
    /// done, and when the scores are expected.
    pub progress_text: Option<String>,
    /// Seconds until the scores are expected, from the speed measured on this server; none
    /// while no worker runs.
    pub eta_seconds: Option<f64>,
    /// Queued or running, but no evaluation worker has been seen for longer than a lease: the
    /// submission waits, safe, for one to start.
    pub no_worker: bool,
    pub preflight: Preflight,
    /// The pre-flight's expectation at upload, in plain words.
    pub preflight_text: String,
    /// Per protocol, the full report (the same keys as `poseboard eval --out`).
    pub scores: BTreeMap<ProtocolName, Report>,
    /// Per protocol scored, how the score can be reproduced.
    pub records: BTreeMap<BoardProtocol, ScoreRecord>,
    /// A 2D task's report (the keys of `poseboard eval --protocol bop22-det|bop22-seg --out`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coco: Option<CocoReport>,
    /// A bop24 submission's report (the keys of `poseboard eval --protocol bop24 --out`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop24: Option<DetectionReport>,
    /// A bop24 submission's per-object AP as its board shows it (see
    /// [`leaderboard::bop24_objects`]), with the object's AP under each error of the report.
    #[serde(skip)]
    pub bop24_objects: Vec<Bop24Object>,
    /// Per protocol with a public entry: the method's entry on this dataset, and whether it is
    /// this submission.
    pub entries: Vec<EntryStatus>,
    /// Its owner pinned it as the method's entry on this dataset.
    pub pinned: bool,
    /// Why it cannot be pinned, if it cannot: the page then offers no pin button.
    #[serde(skip)]
    pub pin_refusal: Option<String>,
    /// For its owner and the administrators: where to download it and what they can do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub owner: Option<OwnerLinks>,
    #[serde(skip)]
    pub charts: Vec<Chart>,
}

/// A row of a bop24 submission's per-object table.
#[derive(Clone, Debug)]
pub struct Bop24Object {
    pub obj_id: i64,
    /// The mean of its MSSD and MSPD APs, as the board shows it.
    pub ap: f64,
    /// Its AP under each error, in the report's order (none where it has no counted instance).
    pub per_error: Vec<Option<f64>>,
}

/// The per-object table of a bop24 report.
fn bop24_objects(r: &DetectionReport) -> Vec<Bop24Object> {
    leaderboard::bop24_objects(r)
        .into_iter()
        .map(|(obj_id, ap)| Bop24Object {
            obj_id,
            ap,
            per_error: r
                .errors
                .iter()
                .map(|e| {
                    e.objects
                        .iter()
                        .find(|o| i64::from(o.obj_id) == obj_id)
                        .map(|o| o.ap)
                })
                .collect(),
        })
        .collect()
}

#[derive(Clone, Debug, Serialize)]
pub struct EntryStatus {
    pub protocol: BoardProtocol,
    /// The submission that is the method's entry on the dataset under this protocol.
    pub submission_id: SubmissionId,
    /// It is this submission.
    pub is_this: bool,
    /// Why it is the entry: `pinned` by the owner, or `best` public finished submission.
    pub reason: &'static str,
}

/// The downloads and actions of a submission, for its owner.
#[derive(Clone, Debug, Serialize)]
pub struct OwnerLinks {
    /// The uploaded file, as sent.
    pub file: String,
    /// The JSON reports, one per protocol.
    pub report: String,
    /// Per protocol evaluated, every evaluated estimate's errors (JSON).
    pub errors: BTreeMap<ProtocolName, String>,
    /// POST `visibility=public|private` (and `confirm=true` for a held one).
    pub visibility: String,
    /// DELETE (API) or POST (page, `/submissions/{id}/delete`).
    pub delete: String,
}

impl OwnerLinks {
    fn of(s: &SubmissionRow) -> OwnerLinks {
        let base = format!("/api/v1/submissions/{}", s.id);
        OwnerLinks {
            file: format!("{base}/file"),
            report: format!("{base}/report"),
            errors: if s.status == Status::Done {
                s.protocols
                    .iter()
                    .map(|p| (*p, format!("{base}/errors/{}", p.as_str())))
                    .collect()
            } else {
                BTreeMap::new()
            },
            visibility: format!("{base}/visibility"),
            delete: base,
        }
    }
}

/// A submission as `viewer` may see it (see [`crate::service::visibility::submission`]).
pub async fn submission(app: &App, id: SubmissionId, viewer: &Viewer) -> AppResult<SubmissionView> {
    let details = submission_details::details(app, id, viewer.user.as_ref()).await?;
    let submission = details.submission;
    let manages = viewer.can_see(submission.owner_id);
    let now = now_ms();
    let progress_text = match (submission.status, &details.queue, details.eta_seconds) {
        _ if details.no_worker => Some(submission_details::NO_WORKER.to_string()),
        (Status::Queued, Some(place), Some(eta)) => Some(format!(
            "{}; scores expected {}",
            wording::queue_place(place.queued_ahead, place.running),
            wording::wait_until(eta, now)
        )),
        (Status::Running, _, Some(eta)) => Some(match crate::service::submissions::progress_words(
            &submission,
        ) {
            Some(words) => format!("{words}; scores expected {}", wording::wait_until(eta, now)),
            None => format!("scores expected {}", wording::wait_until(eta, now)),
        }),
        _ => None,
    };
    let mut charts: Vec<Chart> = details.reports.iter().flat_map(chart::charts).collect();
    charts.extend(details.coco.as_ref().map(chart::precision_recall));
    charts.extend(
        details
            .bop24
            .as_ref()
            .map(chart::detection_precision_recall),
    );
    let entries = details
        .entries
        .into_iter()
        .map(|(protocol, submission_id, pinned)| EntryStatus {
            protocol,
            submission_id,
            is_this: submission_id == id,
            reason: if pinned { "pinned" } else { "best" },
        })
        .collect();
    Ok(SubmissionView {
        entries,
        pinned: details.pinned,
        pin_refusal: details.pin_refusal,
        preflight_text: preflight_text(&submission),
        preflight: submission.preflight.clone(),
        queue_position: details.queue.map(|q| q.queued_ahead),
        queue: details.queue,
        publication: publishing::state(&submission),
        progress_text,
        eta_seconds: details.eta_seconds,
        no_worker: details.no_worker,
        owner: manages.then(|| OwnerLinks::of(&submission)),
        submission,
        scores: details
            .reports
            .into_iter()
            .map(|r| (r.protocol, r))
            .collect(),
        records: details
            .records
            .into_iter()
            .map(|r| (r.protocol, r))
            .collect(),
        coco: details.coco,
        bop24_objects: details
            .bop24
            .as_ref()
            .map(bop24_objects)
            .unwrap_or_default(),
        bop24: details.bop24,
        charts,
    })
}

/// What the pre-flight check expected at upload: the work and the wait it announced.
fn preflight_text(s: &SubmissionRow) -> String {
    let p = &s.preflight;
    let evaluated: Vec<String> = p
        .estimates_evaluated
        .iter()
        .map(|(protocol, n)| {
            format!(
                "{} under {}",
                wording::count(*n, "estimate", "estimates"),
                protocol.as_str()
            )
        })
        .collect();
    let work = if s.task == Some(Task::Bop24) {
        wording::count(p.estimates, "estimate", "estimates") + " under bop24"
    } else if s.task.is_some() {
        wording::count(p.estimates, "detection", "detections")
    } else if evaluated.is_empty() {
        wording::count(p.estimates, "estimate", "estimates")
    } else {
        evaluated.join(", ")
    };
    format!(
        "{work} to evaluate; at upload, scores were expected after {} ({})",
        wording::duration(p.estimated_seconds),
        wording::utc_minute(s.created_at + (p.estimated_seconds * 1000.0).ceil() as i64)
    )
}

/// The owner's list of their submissions, private ones included.
#[derive(Clone, Debug, Serialize)]
pub struct MySubmissions {
    pub submissions: Vec<MySubmission>,
}

#[derive(Clone, Debug, Serialize)]
pub struct MySubmission {
    #[serde(flatten)]
    pub submission: SubmissionRow,
    pub publication: String,
    /// Per protocol, the headline score (AR for bop19, recall for eccv18).
    pub scores: BTreeMap<ProtocolName, f64>,
    /// A 2D task's AP, once scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ap: Option<f64>,
    pub url: String,
    /// Downloads and actions.
    pub links: OwnerLinks,
}

impl MySubmission {
    /// The headline score under `protocol`, once evaluated.
    pub fn score(&self, protocol: ProtocolName) -> Option<f64> {
        self.scores.get(&protocol).copied()
    }
}

/// Every submission of `user`, newest first, with scores, state, downloads and actions.
pub async fn my_submissions(app: &App, user: &User) -> AppResult<MySubmissions> {
    Ok(MySubmissions {
        submissions: submission_details::of_owner(app, user)
            .await?
            .into_iter()
            .map(|o| MySubmission {
                publication: publishing::state(&o.submission),
                scores: o.scores,
                ap: o.ap,
                url: format!("/submissions/{}", o.submission.id),
                links: OwnerLinks::of(&o.submission),
                submission: o.submission,
            })
            .collect(),
    })
}

/// A page of the recent submissions, as its HTML page and `GET /api/v1/submissions` show it.
#[derive(Clone, Debug, Serialize)]
pub struct RecentList {
    #[serde(flatten)]
    pub list: RecentPage,
    pub per_page: u32,
    /// The page numbers of the newer and the older submissions (none at either end).
    pub newer: Option<u32>,
    pub older: Option<u32>,
    /// The Atom feed of the newest page.
    pub feed: &'static str,
}

/// The path of the recent list's page `page` under `base` (`/submissions` or its JSON twin):
/// the first page is the bare path.
pub fn recent_href(base: &str, page: u32) -> String {
    if page <= 1 {
        base.to_string()
    } else {
        format!("{base}?page={page}")
    }
}

/// Page `page` of the recent submissions, with the links to its neighbours.
pub async fn recent(app: &App, page: PageNumber) -> AppResult<RecentList> {
    let list = catalogue::recent(app, page).await?;
    let n = page.get();
    Ok(RecentList {
        per_page: RECENT_PER_PAGE,
        newer: (n > 1).then(|| n - 1),
        older: list.more.then(|| n + 1),
        feed: "/submissions.atom",
        list,
    })
}
