//! The data behind each page, built once and rendered twice: as HTML by the templates and as
//! JSON by the API, so that a page and its JSON twin can never disagree.

pub mod targets;

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::CocoReport;
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::report::{Parameters, parameters};
use serde::{Deserialize, Serialize};

use crate::app::App;
use crate::clock::now_ms;
use crate::demo::DEMO_DATASET;
use crate::domain::{BoardProtocol, CocoProtocol, FieldError, Modality, TrainingData, optional};
use crate::error::{AppError, AppResult};
use crate::preflight::Preflight;
use crate::service::{publishing, visibility};
use crate::store::accounts::User;
use crate::store::coco_scores::CocoBoardEntry;
use crate::store::datasets::DatasetRow;
use crate::store::scores::{BoardEntry, ScoreRecord};
use crate::store::submissions::{QueuePlace, Status, SubmissionRow};
use crate::web::auth::Viewer;
use crate::web::render::chart::Chart;
use crate::wording;

#[derive(Clone, Debug, Serialize)]
pub struct Cell {
    pub submission_id: i64,
    pub score: f64,
    pub recall: Option<f64>,
    pub ar_vsd: Option<f64>,
    pub ar_mssd: Option<f64>,
    pub ar_mspd: Option<f64>,
    pub time: Option<f64>,
    /// The method's owner pinned this submission as its entry (otherwise it is the best).
    pub pinned: bool,
    /// How the score can be reproduced (6D boards).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub record: Option<ScoreRecord>,
    /// The bootstrap 95 % interval of `score` (resampling the dataset's images); absent for a
    /// score stored before intervals were, until it is re-scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95: Option<[f64; 2]>,
    /// The stored score whose bootstrap replicates the row's interval is made of (6D boards).
    #[serde(skip)]
    pub score_id: Option<i64>,
    /// 2D boards: the twelve AP/AR numbers of the report under the toolkit's keys.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub stats: BTreeMap<&'static str, f64>,
}

impl Cell {
    /// A 2D board's number `name` (a key of `stats`).
    pub fn stat(&self, name: &str) -> Option<f64> {
        self.stats.get(name).copied()
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct BoardRow {
    /// Rank by the average (by the score with one dataset); `None` for a row without a score on
    /// every dataset shown. Rows whose scores read the same at the precision shown share it.
    pub rank: Option<usize>,
    pub method_id: i64,
    pub method: String,
    /// The account the method belongs to.
    pub owner: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    /// The method's hardware, which its times were measured on.
    pub hardware: String,
    /// Per dataset shown, the score of the method's entry there.
    pub scores: BTreeMap<String, Cell>,
    /// How many of the datasets shown the method has a score on.
    pub covered: usize,
    /// Mean of the scores over the datasets shown; only when the method has a score on each.
    pub average: Option<f64>,
    /// The bootstrap 95 % interval of `average`: the percentiles of the replicate-wise means
    /// over the datasets (replicate b of each); absent when a score has no replicates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95: Option<[f64; 2]>,
    /// Mean of the scores over the datasets covered (what orders unranked rows).
    pub mean: Option<f64>,
    /// Mean of the times over the datasets covered (per image for bop19, per target for
    /// eccv18); only when each of them has a time.
    pub time: Option<f64>,
    /// With one dataset selected: the per-object scores (recall or AR).
    pub objects: BTreeMap<i64, f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Leaderboard {
    pub protocol: BoardProtocol,
    pub score_name: &'static str,
    pub time_unit: &'static str,
    /// The 6D protocol's parameters (none for a 2D task: COCOeval's are fixed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameters: Option<Parameters>,
    /// 2D boards: the keys of the AP/AR numbers, in COCOeval's order (each cell's `stats`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stat_names: Vec<&'static str>,
    /// Every dataset served (each has its own board).
    pub datasets: Vec<DatasetRow>,
    /// The names of the core datasets: the columns of the main table.
    pub core: Vec<String>,
    /// The datasets shown as columns: the core ones, or the one selected.
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

/// How many of a dataset's best entries its board's charts overlay.
pub const OVERLAID: usize = 5;

/// The query of a leaderboard page or its JSON twin, as given (the page's links keep it).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct BoardFilter {
    /// One dataset (its per-object table) instead of all.
    pub dataset: Option<String>,
    /// `average` (default), `time`, `method`, or a dataset name.
    pub sort: Option<String>,
    /// Only methods trained on this data (`synthetic`, `real`, `both`).
    pub training: Option<String>,
    /// Only methods using this input (`rgb`, `depth`, `rgb-d`).
    pub modality: Option<String>,
    /// With one dataset: the methods whose curves the charts overlay, as method ids separated
    /// by commas (at most [`OVERLAID`]); without it, the best ranked entries.
    pub curves: Option<String>,
}

impl BoardFilter {
    /// Whether the reader chose the methods the curves overlay.
    pub fn curves_chosen(&self) -> bool {
        self.curves.as_deref().is_some_and(|c| !c.is_empty())
    }

    /// Whether the filter leaves out methods by their training data or input.
    pub fn narrows(&self) -> bool {
        [&self.training, &self.modality]
            .iter()
            .any(|v| v.as_deref().is_some_and(|v| !v.trim().is_empty()))
    }

    /// The query string of this board without the filters on methods.
    pub fn unfiltered(&self) -> String {
        BoardFilter {
            training: None,
            modality: None,
            ..self.clone()
        }
        .query()
    }

    /// The query string of this filter as it stands (for the links to the board's exports).
    pub fn query(&self) -> String {
        self.with("", "")
    }

    /// The query string that keeps this filter but changes one key (for links on the page).
    pub fn with(&self, key: &str, value: &str) -> String {
        let mut pairs: Vec<(&str, String)> = Vec::new();
        for (k, v) in [
            ("dataset", &self.dataset),
            ("training", &self.training),
            ("modality", &self.modality),
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
            "?".to_string()
        } else {
            format!("?{}", q.join("&"))
        }
    }
}

/// How a leaderboard's rows are ordered.
#[derive(Clone, Debug, PartialEq)]
enum Sort {
    /// By rank: the average over the datasets shown (or the one dataset's score), best first,
    /// then the unranked rows.
    Average,
    /// By the reported time, fastest first.
    Time,
    /// By method name.
    Method,
    /// By the score on one dataset, best first.
    Dataset(String),
}

/// A leaderboard query with every value checked: unknown sorts and filter values are errors.
struct Query {
    sort: Sort,
    training: Option<TrainingData>,
    modality: Option<Modality>,
    /// The methods chosen for the curves, when chosen.
    curves: Option<Vec<i64>>,
}

impl Query {
    fn parse(filter: &BoardFilter, datasets: &[DatasetRow]) -> AppResult<Query> {
        let field = |v: &Option<String>| v.clone().unwrap_or_default();
        let sort = match field(&filter.sort).as_str() {
            "" | "average" => Sort::Average,
            "time" => Sort::Time,
            "method" => Sort::Method,
            name if datasets.iter().any(|d| d.name == name) => Sort::Dataset(name.to_string()),
            other => {
                return Err(AppError::BadRequest(format!(
                    "cannot sort by `{other}`: use average, time, method or a dataset name"
                )));
            }
        };
        // The query names its parameters `training` and `modality`, whatever the fields of a
        // method are called.
        fn parameter(name: &'static str) -> impl Fn(FieldError) -> AppError {
            move |e| AppError::BadRequest(format!("parameter `{name}` {}", e.problem))
        }
        Ok(Query {
            sort,
            training: optional(&field(&filter.training)).map_err(parameter("training"))?,
            modality: optional(&field(&filter.modality)).map_err(parameter("modality"))?,
            curves: curves(&field(&filter.curves))?,
        })
    }

    fn matches(&self, e: &Placed) -> bool {
        self.training.is_none_or(|t| e.training_data == Some(t))
            && self.modality.is_none_or(|m| e.modality == Some(m))
    }
}

/// The `curves` of a board query: method ids separated by commas, at most [`OVERLAID`].
fn curves(value: &str) -> AppResult<Option<Vec<i64>>> {
    if value.is_empty() {
        return Ok(None);
    }
    let mut ids = Vec::new();
    for part in value.split(',') {
        let id = part.trim().parse::<i64>().map_err(|_| {
            AppError::BadRequest(format!(
                "curves takes method ids separated by commas, not `{part}`"
            ))
        })?;
        if !ids.contains(&id) {
            ids.push(id);
        }
        if ids.len() > OVERLAID {
            return Err(AppError::BadRequest(format!(
                "curves takes at most {OVERLAID} methods"
            )));
        }
    }
    Ok(Some(ids))
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
        BoardProtocol::Coco(CocoProtocol::Detection) => {
            "AP of the amodal boxes (COCOeval bbox: mean over IoU 0.50:0.05:0.95, 101 recall points, 100 detections per image); the average over the core datasets is AP_C"
        }
        BoardProtocol::Coco(CocoProtocol::Segmentation) => {
            "AP of the visible masks (COCOeval segm: mean over IoU 0.50:0.05:0.95, 101 recall points, 100 detections per image); the average over the core datasets is AP_C"
        }
    }
}

/// A method's entry on a dataset, as any board shows it.
struct Placed {
    method_id: i64,
    method: String,
    owner: String,
    training_data: Option<TrainingData>,
    modality: Option<Modality>,
    hardware: String,
    dataset_id: i64,
    dataset: String,
    cell: Cell,
    objects: BTreeMap<i64, f64>,
}

impl Placed {
    fn pose(e: BoardEntry) -> Placed {
        Placed {
            cell: cell(&e),
            method_id: e.method_id,
            method: e.method,
            owner: e.owner,
            training_data: e.training_data,
            modality: e.modality,
            hardware: e.hardware,
            dataset_id: e.dataset_id,
            dataset: e.dataset,
            objects: e.object_scores,
        }
    }

    fn coco(e: &CocoBoardEntry) -> Placed {
        Placed {
            cell: Cell {
                submission_id: e.submission_id,
                score: e.report.ap,
                recall: None,
                ar_vsd: None,
                ar_mssd: None,
                ar_mspd: None,
                time: e.time_avg,
                pinned: e.pinned,
                record: None,
                ci95: None,
                score_id: None,
                stats: e.report.stats().into_iter().collect(),
            },
            method_id: e.method_id,
            method: e.method.clone(),
            owner: e.owner.clone(),
            training_data: e.training_data,
            modality: e.modality,
            hardware: e.hardware.clone(),
            dataset_id: e.dataset_id,
            dataset: e.dataset.clone(),
            objects: BTreeMap::new(),
        }
    }
}

/// The core datasets: those flagged core, and of those never flagged, every one but the demo
/// dataset once another is served (the demo is there to try the service, not to rank methods).
pub fn core_datasets(datasets: &[DatasetRow]) -> Vec<DatasetRow> {
    let others = datasets.iter().any(|d| d.name != DEMO_DATASET);
    datasets
        .iter()
        .filter(|d| d.core.unwrap_or(!(others && d.name == DEMO_DATASET)))
        .cloned()
        .collect()
}

/// A score as the page shows it: two scores that read the same share a rank.
fn shown(score: f64) -> String {
    format!("{:.1}", score * 100.0)
}

/// Builds a leaderboard.
pub async fn leaderboard(
    app: &App,
    protocol: BoardProtocol,
    filter: &BoardFilter,
) -> AppResult<Leaderboard> {
    let dataset = filter.dataset.as_deref();
    let datasets = app.store.datasets().await?;
    let selected = match dataset {
        Some(name) if !name.is_empty() => Some(
            datasets
                .iter()
                .find(|d| d.name == name)
                .cloned()
                .ok_or_else(|| {
                    AppError::Unknown(crate::service::datasets::unknown(
                        name,
                        "the parameter `dataset`",
                        &datasets,
                    ))
                })?,
        ),
        _ => None,
    };
    let query = Query::parse(filter, &datasets)?;
    let selected_id = selected.as_ref().map(|d| d.id);
    let (entries, coco_entries): (Vec<Placed>, Vec<CocoBoardEntry>) = match protocol {
        BoardProtocol::Pose(p) => (
            app.store
                .leaderboard(p, selected_id)
                .await?
                .into_iter()
                .map(Placed::pose)
                .collect(),
            Vec::new(),
        ),
        BoardProtocol::Coco(t) => {
            let coco = app.store.coco_leaderboard(t, selected_id).await?;
            (coco.iter().map(Placed::coco).collect(), coco)
        }
    };
    let core = core_datasets(&datasets);
    let columns: Vec<DatasetRow> = match &selected {
        Some(d) => vec![d.clone()],
        None => core.clone(),
    };
    let mut by_method: BTreeMap<i64, BoardRow> = BTreeMap::new();
    let mut object_ids = std::collections::BTreeSet::new();
    let entries = entries
        .iter()
        .filter(|e| query.matches(e) && columns.iter().any(|d| d.id == e.dataset_id));
    for e in entries {
        let row = by_method.entry(e.method_id).or_insert_with(|| BoardRow {
            rank: None,
            method_id: e.method_id,
            method: e.method.clone(),
            owner: e.owner.clone(),
            training_data: e.training_data,
            modality: e.modality,
            hardware: e.hardware.clone(),
            scores: BTreeMap::new(),
            covered: 0,
            average: None,
            ci95: None,
            mean: None,
            time: None,
            objects: BTreeMap::new(),
        });
        row.scores.insert(e.dataset.clone(), e.cell.clone());
        if selected.is_some() {
            row.objects = e.objects.clone();
            object_ids.extend(e.objects.keys().copied());
        }
    }
    let mut rows: Vec<BoardRow> = by_method.into_values().collect();
    for row in &mut rows {
        let cells: Vec<&Cell> = columns
            .iter()
            .filter_map(|d| row.scores.get(&d.name))
            .collect();
        row.covered = cells.len();
        let n = cells.len() as f64;
        if !cells.is_empty() {
            row.mean = Some(cells.iter().map(|c| c.score).sum::<f64>() / n);
            let times: Option<Vec<f64>> =
                cells.iter().map(|c| c.time.filter(|t| *t >= 0.0)).collect();
            row.time = times.map(|t| t.iter().sum::<f64>() / n);
        }
        if row.covered == columns.len() {
            row.average = row.mean;
        }
    }
    average_intervals(app, &mut rows, &columns).await?;
    // Ranked rows by their average, then the others by coverage and mean; ties by age.
    rows.sort_by(|a, b| {
        b.average
            .is_some()
            .cmp(&a.average.is_some())
            .then_with(|| {
                b.average
                    .unwrap_or(0.0)
                    .total_cmp(&a.average.unwrap_or(0.0))
            })
            .then_with(|| b.covered.cmp(&a.covered))
            .then_with(|| b.mean.unwrap_or(0.0).total_cmp(&a.mean.unwrap_or(0.0)))
            .then_with(|| a.method_id.cmp(&b.method_id))
    });
    let mut previous: Option<(String, usize)> = None;
    for (i, row) in rows.iter_mut().enumerate() {
        let Some(average) = row.average else { break };
        let key = shown(average);
        let rank = match &previous {
            Some((k, r)) if *k == key => *r,
            _ => i + 1,
        };
        row.rank = Some(rank);
        previous = Some((key, rank));
    }
    // The rows whose curves a dataset's board draws, in rank order.
    let drawn: Vec<&BoardRow> = match &query.curves {
        _ if selected.is_none() => Vec::new(),
        None => rows
            .iter()
            .filter(|r| r.rank.is_some())
            .take(OVERLAID)
            .collect(),
        Some(ids) => rows
            .iter()
            .filter(|r| r.rank.is_some() && ids.contains(&r.method_id))
            .collect(),
    };
    let overlays = match (&selected, protocol) {
        (Some(d), BoardProtocol::Pose(p)) => overlays(app, p, &d.name, &drawn).await?,
        // A dataset's 2D board: the precision-recall curves.
        (Some(d), BoardProtocol::Coco(_)) => {
            let reports: Vec<(String, &CocoReport)> = drawn
                .iter()
                .filter_map(|r| {
                    let id = r.scores.get(&d.name)?.submission_id;
                    let e = coco_entries.iter().find(|e| e.submission_id == id)?;
                    Some((r.method.clone(), &e.report))
                })
                .collect();
            if reports.is_empty() {
                Vec::new()
            } else {
                vec![crate::web::render::chart::precision_recall_of_methods(
                    &reports,
                )]
            }
        }
        (None, _) => Vec::new(),
    };
    let curve_choices = if selected.is_some() {
        curve_choices(&rows, &drawn, filter)
    } else {
        Vec::new()
    };
    // Another order keeps each row's rank: `#` is always the score's.
    let last = |v: Option<f64>| v.map_or((1, 0.0), |v| (0, v));
    match &query.sort {
        Sort::Average => {}
        Sort::Time => rows.sort_by(|a, b| {
            let (x, y) = (last(a.time), last(b.time));
            x.0.cmp(&y.0).then_with(|| x.1.total_cmp(&y.1))
        }),
        Sort::Method => rows.sort_by_key(|r| r.method.to_lowercase()),
        Sort::Dataset(name) => rows.sort_by(|a, b| {
            let score = |r: &BoardRow| last(r.scores.get(name).map(|c| c.score));
            let (x, y) = (score(a), score(b));
            x.0.cmp(&y.0).then_with(|| y.1.total_cmp(&x.1))
        }),
    }
    Ok(Leaderboard {
        protocol,
        score_name: score_name(protocol),
        time_unit: match protocol {
            BoardProtocol::Pose(ProtocolName::Eccv18) => "s per target",
            _ => "s per image",
        },
        parameters: match protocol {
            BoardProtocol::Pose(p) => Some(parameters(&Protocol::named(p)).as_defined()),
            BoardProtocol::Coco(_) => None,
        },
        stat_names: match &coco_entries[..] {
            [] => Vec::new(),
            [first, ..] => first.report.stats().iter().map(|(k, _)| *k).collect(),
        },
        core: core.into_iter().map(|d| d.name).collect(),
        columns,
        datasets,
        dataset: selected,
        object_ids: object_ids.into_iter().collect(),
        filter: filter.clone(),
        sorted_by: match &query.sort {
            Sort::Average => "average".to_string(),
            Sort::Time => "time".to_string(),
            Sort::Method => "method".to_string(),
            Sort::Dataset(name) => name.clone(),
        },
        rows,
        overlays,
        curve_choices,
    })
}

/// The methods a dataset's board offers for its curves: each ranked row, with the link that
/// adds it to the drawn ones or takes it away (leaving none draws the best again).
fn curve_choices(rows: &[BoardRow], drawn: &[&BoardRow], filter: &BoardFilter) -> Vec<CurveChoice> {
    let ids: Vec<i64> = drawn.iter().map(|r| r.method_id).collect();
    let link = |ids: Vec<i64>| {
        let list: Vec<String> = ids.iter().map(i64::to_string).collect();
        filter.with("curves", &list.join(","))
    };
    rows.iter()
        .filter(|r| r.rank.is_some())
        .map(|r| {
            let on = ids.contains(&r.method_id);
            let href = if on {
                Some(link(
                    ids.iter().copied().filter(|&i| i != r.method_id).collect(),
                ))
            } else if ids.len() < OVERLAID {
                Some(link(ids.iter().copied().chain([r.method_id]).collect()))
            } else {
                None
            };
            CurveChoice {
                method: r.method.clone(),
                drawn: on,
                href,
            }
        })
        .collect()
}

/// The charts of a dataset's board: the curves of the entries of `rows` (in rank order), from
/// their stored reports.
async fn overlays(
    app: &App,
    protocol: ProtocolName,
    dataset: &str,
    rows: &[&BoardRow],
) -> AppResult<Vec<Chart>> {
    let mut methods = Vec::new();
    for row in rows {
        let Some(cell) = row.scores.get(dataset) else {
            continue;
        };
        let reports = app.store.reports_of_submission(cell.submission_id).await?;
        if let Some(report) = reports.into_iter().find(|r| r.protocol == protocol) {
            methods.push((row.method.clone(), report));
        }
    }
    Ok(crate::web::render::chart::overlays(&methods))
}

/// The interval of each row's average: a single score's own, or, over several datasets, the
/// percentiles of the means of their replicates taken replicate by replicate (in the order and
/// with the sum the average uses).
async fn average_intervals(
    app: &App,
    rows: &mut [BoardRow],
    columns: &[DatasetRow],
) -> AppResult<()> {
    let cells = |row: &BoardRow| -> Vec<Cell> {
        columns
            .iter()
            .filter_map(|d| row.scores.get(&d.name).cloned())
            .collect()
    };
    if columns.len() == 1 {
        for row in rows.iter_mut().filter(|r| r.average.is_some()) {
            row.ci95 = cells(&*row).first().and_then(|c| c.ci95);
        }
        return Ok(());
    }
    let ids: Vec<i64> = rows
        .iter()
        .filter(|r| r.average.is_some())
        .flat_map(|r| cells(r).into_iter().filter_map(|c| c.score_id))
        .collect();
    let replicates = app.store.replicates(&ids).await?;
    for row in rows.iter_mut().filter(|r| r.average.is_some()) {
        let sets: Option<Vec<&Vec<f64>>> = cells(&*row)
            .iter()
            .map(|c| c.score_id.and_then(|id| replicates.get(&id)))
            .collect();
        let Some(sets) = sets.filter(|s| !s.is_empty()) else {
            continue;
        };
        let b = sets[0].len();
        if sets.iter().any(|s| s.len() != b) {
            continue;
        }
        let n = sets.len() as f64;
        let means: Vec<f64> = (0..b)
            .map(|i| sets.iter().map(|s| s[i]).sum::<f64>() / n)
            .collect();
        row.ci95 = Some(evaluator::bootstrap::interval95(&means));
    }
    Ok(())
}

fn cell(e: &BoardEntry) -> Cell {
    Cell {
        submission_id: e.submission_id,
        score: e.score.score,
        recall: e.score.recall,
        ar_vsd: e.score.ar_vsd,
        ar_mssd: e.score.ar_mssd,
        ar_mspd: e.score.ar_mspd,
        time: e.score.time_avg,
        pinned: e.pinned,
        record: Some(e.score.record.clone()),
        ci95: e.score.ci95,
        score_id: Some(e.score.id),
        stats: BTreeMap::new(),
    }
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
    /// Seconds until the scores are expected, from the speed measured on this server.
    pub eta_seconds: Option<f64>,
    pub preflight: Preflight,
    /// The pre-flight's expectation at upload, in plain words.
    pub preflight_text: String,
    /// Per protocol, the full report (the same keys as `poseboard eval --out`).
    pub scores: BTreeMap<ProtocolName, Report>,
    /// Per protocol scored, how the score can be reproduced.
    pub records: BTreeMap<ProtocolName, ScoreRecord>,
    /// A 2D task's report (the keys of `poseboard eval --protocol bop22-det|bop22-seg --out`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coco: Option<CocoReport>,
    /// Per protocol with a public entry: the method's entry on this dataset, and whether it is
    /// this submission.
    pub entries: Vec<EntryStatus>,
    /// Its owner pinned it as the method's entry on this dataset.
    pub pinned: bool,
    /// For its owner and the administrators: where to download it and what they can do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub owner: Option<OwnerLinks>,
    #[serde(skip)]
    pub charts: Vec<Chart>,
}

#[derive(Clone, Debug, Serialize)]
pub struct EntryStatus {
    pub protocol: BoardProtocol,
    /// The submission that is the method's entry on the dataset under this protocol.
    pub submission_id: i64,
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

/// A submission as `viewer` may see it (see [`visibility::submission`]).
pub async fn submission(app: &App, id: i64, viewer: &Viewer) -> AppResult<SubmissionView> {
    let submission = visibility::submission(app, id, viewer.user.as_ref()).await?;
    let manages = viewer.can_see(submission.owner_id);
    let speed = crate::service::submissions::speed(app).await?;
    let now = now_ms();
    let (queue, eta_seconds, progress_text) = match submission.status {
        Status::Queued => {
            let place = app.store.queue_place(id).await?;
            let eta = (app.store.work_ahead(id).await? + remaining(&submission)) as f64 / speed;
            let text = format!(
                "{}; scores expected {}",
                wording::queue_place(place.queued_ahead, place.running),
                wording::wait_until(eta, now)
            );
            (Some(place), Some(eta), Some(text))
        }
        Status::Running => {
            let eta = remaining(&submission) as f64 / speed;
            let text = match crate::service::submissions::progress_words(&submission) {
                Some(words) => {
                    format!("{words}; scores expected {}", wording::wait_until(eta, now))
                }
                None => format!("scores expected {}", wording::wait_until(eta, now)),
            };
            (None, Some(eta), Some(text))
        }
        Status::Done | Status::Failed => (None, None, None),
    };
    let reports = app.store.reports_of_submission(id).await?;
    let records = app.store.score_records(id).await?;
    let coco = match submission.task {
        Some(_) => app.store.coco_report(id).await?,
        None => None,
    };
    let mut charts: Vec<Chart> = reports
        .iter()
        .flat_map(crate::web::render::chart::charts)
        .collect();
    charts.extend(
        coco.as_ref()
            .map(crate::web::render::chart::precision_recall),
    );
    let entry = |protocol: BoardProtocol, submission_id: i64, pinned: bool| EntryStatus {
        protocol,
        submission_id,
        is_this: submission_id == id,
        reason: if pinned { "pinned" } else { "best" },
    };
    let mut entries: Vec<EntryStatus> = app
        .store
        .entries(submission.method_id, submission.dataset_id)
        .await?
        .into_iter()
        .map(|e| entry(e.protocol.into(), e.submission_id, e.pinned))
        .collect();
    if let Some(task) = submission.task {
        let found = app
            .store
            .coco_entry(task, submission.method_id, submission.dataset_id)
            .await?;
        entries.extend(found.map(|(sid, pinned)| entry(BoardProtocol::Coco(task), sid, pinned)));
    }
    Ok(SubmissionView {
        entries,
        pinned: app.store.is_pinned(id).await?,
        preflight_text: preflight_text(&submission),
        preflight: submission.preflight.clone(),
        queue_position: queue.map(|q| q.queued_ahead),
        queue,
        publication: publishing::state(&submission),
        progress_text,
        eta_seconds,
        owner: manages.then(|| OwnerLinks::of(&submission)),
        submission,
        scores: reports.into_iter().map(|r| (r.protocol, r)).collect(),
        records: records.into_iter().map(|r| (r.protocol, r)).collect(),
        coco,
        charts,
    })
}

/// Estimate evaluations the job still has to do.
fn remaining(s: &SubmissionRow) -> i64 {
    if s.work > 0 {
        (s.work - s.work_done).max(0)
    } else {
        s.estimates_count * s.protocols.len().max(1) as i64
    }
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
    let work = if s.task.is_some() {
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
    let rows = app.store.submissions_of_owner(user.id).await?;
    let mut scores: BTreeMap<i64, BTreeMap<ProtocolName, f64>> = BTreeMap::new();
    for sc in app.store.scores_of_owner(user.id).await? {
        scores
            .entry(sc.submission_id)
            .or_default()
            .insert(sc.protocol, sc.score);
    }
    let mut aps: BTreeMap<i64, f64> = app
        .store
        .coco_scores_of_owner(user.id)
        .await?
        .into_iter()
        .collect();
    Ok(MySubmissions {
        submissions: rows
            .into_iter()
            .map(|s| MySubmission {
                publication: publishing::state(&s),
                scores: scores.remove(&s.id).unwrap_or_default(),
                ap: aps.remove(&s.id),
                url: format!("/submissions/{}", s.id),
                links: OwnerLinks::of(&s),
                submission: s,
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dataset(name: &str, core: Option<bool>) -> DatasetRow {
        DatasetRow {
            id: 0,
            name: name.to_string(),
            path: String::new(),
            objects_count: 0,
            scenes_count: 0,
            images_count: 0,
            targets_count: 0,
            instances_count: 0,
            image_width: 0,
            image_height: 0,
            added_at: 0,
            retired: false,
            content_hash: None,
            core,
        }
    }

    fn names(datasets: &[DatasetRow]) -> Vec<String> {
        core_datasets(datasets)
            .into_iter()
            .map(|d| d.name)
            .collect()
    }

    #[test]
    fn the_demo_is_core_only_alone_unless_set() {
        assert_eq!(names(&[dataset(DEMO_DATASET, None)]), [DEMO_DATASET]);
        let both = [dataset("lmo", None), dataset(DEMO_DATASET, None)];
        assert_eq!(names(&both), ["lmo"]);
        let set = [
            dataset("lmo", Some(false)),
            dataset(DEMO_DATASET, Some(true)),
        ];
        assert_eq!(names(&set), [DEMO_DATASET]);
    }

    #[test]
    fn ties_are_judged_at_the_precision_shown() {
        assert_eq!(shown(0.12341), shown(0.12349));
        assert_ne!(shown(0.1234), shown(0.1236));
    }
}
