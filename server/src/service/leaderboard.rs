//! A leaderboard's use case: check the query, load the entries of the datasets shown, rank them
//! with [`crate::service::ranking`] (the rules, free of I/O), and load what the ranking decided
//! to show (the bootstrap replicates of the averages, the curves of the drawn entries). The web
//! layer turns the result into the page, its JSON twin, the exports and the snapshots, and
//! keeps what it rendered through [`cached`] while the boards stand.

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::Arc;

use evaluator::Report;
use evaluator::coco::CocoReport;
use evaluator::detection::{DetectionError, DetectionReport};
use serde::{Deserialize, Serialize};

use crate::app::App;
use crate::board_cache::{BoardKey, Rendered};
use crate::datasets::config::BOP24_TARGETS;
use crate::domain::{
    BoardProtocol, FieldError, MethodId, Modality, Objects, Onboarding, SubmissionId, TrainingData,
    optional,
};
use crate::error::{AppError, AppResult};
use crate::service::groups;
use crate::service::ranking::{self, BoardRow, Cell, Entry, Sort};
use crate::service::visibility;
use crate::store::board_rows::EntryHead;
use crate::store::bop24_scores::Bop24BoardEntry;
use crate::store::coco_scores::CocoBoardEntry;
use crate::store::datasets::DatasetRow;
use crate::store::scores::BoardEntry;

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
    /// Only methods for test objects seen in training or not (`seen`, `unseen`).
    pub objects: Option<String>,
    /// Only methods onboarding objects this way (`model-based`, `model-free`).
    pub onboarding: Option<String>,
    /// The group of datasets ranked over (see [`groups`]); without it, the default group.
    pub group: Option<String>,
    /// With one dataset: the methods whose curves the charts overlay, as method ids separated
    /// by commas (at most [`OVERLAID`]); without it, the best ranked entries.
    pub curves: Option<String>,
}

/// A leaderboard query with every value checked: unknown sorts and filter values are errors.
struct Query {
    sort: Sort,
    training: Option<TrainingData>,
    modality: Option<Modality>,
    objects: Option<Objects>,
    onboarding: Option<Onboarding>,
    /// The methods chosen for the curves, when chosen.
    curves: Option<Vec<MethodId>>,
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
        // The query names its parameters `training`, `modality`, `objects` and `onboarding`,
        // whatever the fields of a method are called.
        fn parameter(name: &'static str) -> impl Fn(FieldError) -> AppError {
            move |e| AppError::BadRequest(format!("parameter `{name}` {}", e.problem))
        }
        Ok(Query {
            sort,
            training: optional(&field(&filter.training)).map_err(parameter("training"))?,
            modality: optional(&field(&filter.modality)).map_err(parameter("modality"))?,
            objects: optional(&field(&filter.objects)).map_err(parameter("objects"))?,
            onboarding: optional(&field(&filter.onboarding)).map_err(parameter("onboarding"))?,
            curves: curves(&field(&filter.curves))?,
        })
    }

    fn matches(&self, e: &Entry) -> bool {
        self.training.is_none_or(|t| e.training_data == Some(t))
            && self.modality.is_none_or(|m| e.modality == Some(m))
            && self.objects.is_none_or(|o| e.test_objects == Some(o))
            && self.onboarding.is_none_or(|o| e.onboarding == Some(o))
    }
}

/// The `curves` of a board query: method ids separated by commas, at most [`OVERLAID`].
fn curves(value: &str) -> AppResult<Option<Vec<MethodId>>> {
    if value.is_empty() {
        return Ok(None);
    }
    let mut ids = Vec::new();
    for part in value.split(',') {
        let id = part.trim().parse::<MethodId>().map_err(|_| {
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

/// Whether a dataset takes bop24 uploads: its folder (the server's, which serves the boards)
/// has `test_targets_bop24.json`. Only those are the bop24 board's core columns, since a
/// method could never cover the others.
fn takes_bop24(d: &DatasetRow) -> bool {
    std::path::Path::new(&d.path).join(BOP24_TARGETS).is_file()
}

/// The curves of a dataset's board, per drawn method in rank order, from their stored reports.
pub enum Curves {
    /// A 6D board: each method's report (its recall curves).
    Pose(Vec<(String, Report)>),
    /// A 2D board: each method's COCO report (its precision-recall curve).
    Coco(Vec<(String, CocoReport)>),
    /// The bop24 board: each method's detection report (its precision-recall curves).
    Bop24(Vec<(String, DetectionReport)>),
}

/// The parts of bop24_mAP the bop24 board shows next to it, with the toolkit's keys: the MSSD
/// and MSPD mAPs it is the mean of, MSSD in millimetres, and BOP'25's MSSD-only scores.
pub const BOP24_PARTS: [&str; 5] = [
    "bop24_mAP_mssd",
    "bop24_mAP_mspd",
    "bop24_mAP_mssd_mm",
    "bop25_mAP",
    "bop25_mAP_mm",
];

/// A ranked board, as every rendering of it needs it.
pub struct Ranked {
    /// Every dataset served.
    pub datasets: Vec<DatasetRow>,
    /// The group ranked over: its name, and every group's name to choose from.
    pub group: String,
    pub groups: Vec<String>,
    /// The group's datasets served here (the default group's: the core datasets).
    pub core: Vec<DatasetRow>,
    /// The datasets shown as columns: the group's, or the one selected.
    pub columns: Vec<DatasetRow>,
    /// The dataset asked for, if one was.
    pub selected: Option<DatasetRow>,
    /// With one dataset selected, the objects of its per-object table.
    pub object_ids: Vec<i64>,
    /// The order asked for.
    pub sort: Sort,
    /// The rows, ranked and in the order asked for.
    pub rows: Vec<BoardRow>,
    /// With one dataset selected: every ranked method (id, name) in rank order.
    pub ranked: Vec<(MethodId, String)>,
    /// The methods whose curves are drawn, in rank order.
    pub drawn: Vec<MethodId>,
    /// With one dataset selected, the curves drawn.
    pub curves: Option<Curves>,
    /// 2D boards: the keys of the AP/AR numbers, in COCOeval's order; the bop24 board: the
    /// parts of its mAP ([`BOP24_PARTS`]).
    pub stat_names: Vec<&'static str>,
}

/// The leaderboard of `protocol` under `filter`.
pub async fn board(app: &App, protocol: BoardProtocol, filter: &BoardFilter) -> AppResult<Ranked> {
    let datasets = app.store.datasets().await?;
    let selected = match filter.dataset.as_deref() {
        Some(name) if !name.is_empty() => Some(
            datasets
                .iter()
                .find(|d| d.name == name)
                .cloned()
                .ok_or_else(|| {
                    AppError::Unknown(super::datasets::unknown(
                        name,
                        "the parameter `dataset`",
                        &datasets,
                    ))
                })?,
        ),
        _ => None,
    };
    let query = Query::parse(filter, &datasets)?;
    let group = groups::of_board(app, filter.group.as_deref(), &datasets).await?;
    let selected_id = selected.as_ref().map(|d| d.id);
    let (mut coco, mut bop24): (Vec<CocoBoardEntry>, Vec<Bop24BoardEntry>) =
        (Vec::new(), Vec::new());
    let entries: Vec<Entry> = match protocol {
        BoardProtocol::Pose(p) => app
            .store
            .leaderboard(p, selected_id)
            .await?
            .into_iter()
            .map(pose_entry)
            .collect(),
        BoardProtocol::Coco(t) => {
            coco = app.store.coco_leaderboard(t, selected_id).await?;
            coco.iter().map(coco_entry).collect()
        }
        BoardProtocol::Bop24 => {
            // A file that matched no counted instance has no mAP to rank by.
            bop24 = app.store.bop24_leaderboard(selected_id).await?;
            bop24.retain(|e| e.report.bop24_map.is_finite());
            bop24.iter().map(bop24_entry).collect()
        }
    };
    let core: Vec<DatasetRow> = match protocol {
        BoardProtocol::Bop24 => group.columns.into_iter().filter(takes_bop24).collect(),
        BoardProtocol::Pose(_) | BoardProtocol::Coco(_) => group.columns,
    };
    let columns: Vec<DatasetRow> = match &selected {
        Some(d) => vec![d.clone()],
        None => core.clone(),
    };
    let entries: Vec<Entry> = entries.into_iter().filter(|e| query.matches(e)).collect();
    let (mut rows, object_ids) = ranking::rows(&entries, &columns, selected.is_some());
    let needed = ranking::replicates_needed(&rows, &columns);
    let replicates = if needed.is_empty() {
        BTreeMap::new()
    } else {
        app.store.replicates(&needed, protocol).await?
    };
    ranking::intervals(&mut rows, &columns, &replicates);
    ranking::rank(&mut rows);
    let shown: Vec<SubmissionId> = rows
        .iter()
        .flat_map(|r| r.scores.values().map(|c| c.submission_id))
        .collect();
    let flags = app.store.red_flags(&shown).await?;
    for cell in rows.iter_mut().flat_map(|r| r.scores.values_mut()) {
        if let Some(f) = flags.get(&cell.submission_id) {
            cell.red_flags = f.clone();
        }
    }
    let drawn: Vec<&BoardRow> = match &selected {
        None => Vec::new(),
        Some(_) => ranking::drawn(&rows, query.curves.as_deref(), OVERLAID),
    };
    let curves = match (&selected, protocol) {
        (Some(d), BoardProtocol::Pose(p)) => {
            let mut methods = Vec::new();
            for row in &drawn {
                let Some(cell) = row.scores.get(&d.name) else {
                    continue;
                };
                let reports = app.store.reports_of_submission(cell.submission_id).await?;
                if let Some(report) = reports.into_iter().find(|r| r.protocol == p) {
                    methods.push((row.method.clone(), report));
                }
            }
            Some(Curves::Pose(methods))
        }
        (Some(d), BoardProtocol::Coco(_)) => Some(Curves::Coco(
            drawn
                .iter()
                .filter_map(|r| {
                    let id = r.scores.get(&d.name)?.submission_id;
                    let e = coco.iter().find(|e| e.head.submission_id == id)?;
                    Some((r.method.clone(), e.report.clone()))
                })
                .collect(),
        )),
        (Some(d), BoardProtocol::Bop24) => Some(Curves::Bop24(
            drawn
                .iter()
                .filter_map(|r| {
                    let id = r.scores.get(&d.name)?.submission_id;
                    let e = bop24.iter().find(|e| e.head.submission_id == id)?;
                    Some((r.method.clone(), e.report.clone()))
                })
                .collect(),
        )),
        (None, _) => None,
    };
    let drawn: Vec<MethodId> = drawn.iter().map(|r| r.method_id).collect();
    let ranked = match &selected {
        Some(_) => rows
            .iter()
            .filter(|r| r.rank.is_some())
            .map(|r| (r.method_id, r.method.clone()))
            .collect(),
        None => Vec::new(),
    };
    ranking::sort(&mut rows, &query.sort);
    Ok(Ranked {
        stat_names: match protocol {
            BoardProtocol::Pose(_) => Vec::new(),
            BoardProtocol::Bop24 => BOP24_PARTS.to_vec(),
            BoardProtocol::Coco(_) => evaluator::coco::STAT_NAMES.to_vec(),
        },
        datasets,
        group: group.name,
        groups: group.names,
        core,
        columns,
        selected,
        object_ids,
        sort: query.sort,
        rows,
        ranked,
        drawn,
        curves,
    })
}

/// Where a method stands on one dataset's board of one task.
#[derive(Clone, Debug, Serialize)]
pub struct Standing {
    pub protocol: BoardProtocol,
    pub dataset: String,
    /// Its rank on the dataset's board (shared by scores that read the same).
    pub rank: Option<usize>,
    /// How many methods that board ranks.
    pub ranked: usize,
    /// The headline score of its entry (AR, recall or AP).
    pub score: f64,
    /// Its entry: the best public finished submission, or the one pinned.
    pub submission_id: SubmissionId,
    pub pinned: bool,
}

/// Where method `id` stands on every board (each task, each dataset) it has a public entry
/// on, ranked as that dataset's board ranks it; boards in [`BoardProtocol::ALL`]'s order, then
/// datasets by name.
pub async fn standings(app: &App, id: MethodId) -> AppResult<Vec<Standing>> {
    let datasets = app.store.datasets().await?;
    let mut out = Vec::new();
    for protocol in BoardProtocol::ALL {
        let entries: Vec<Entry> = match protocol {
            BoardProtocol::Pose(p) => app
                .store
                .leaderboard(p, None)
                .await?
                .into_iter()
                .map(pose_entry)
                .collect(),
            BoardProtocol::Coco(t) => app
                .store
                .coco_leaderboard(t, None)
                .await?
                .iter()
                .map(coco_entry)
                .collect(),
            BoardProtocol::Bop24 => app
                .store
                .bop24_leaderboard(None)
                .await?
                .iter()
                // As on the board: a file that matched no counted instance is not ranked.
                .filter(|e| e.report.bop24_map.is_finite())
                .map(bop24_entry)
                .collect(),
        };
        for dataset in &datasets {
            if !entries
                .iter()
                .any(|e| e.method_id == id && e.dataset_id == dataset.id)
            {
                continue;
            }
            let here: Vec<Entry> = entries
                .iter()
                .filter(|e| e.dataset_id == dataset.id)
                .cloned()
                .collect();
            let (mut rows, _) = ranking::rows(&here, std::slice::from_ref(dataset), false);
            ranking::rank(&mut rows);
            let ranked = rows.iter().filter(|r| r.rank.is_some()).count();
            let mine = rows.iter().find(|r| r.method_id == id);
            if let Some((row, cell)) = mine.and_then(|r| Some((r, r.scores.get(&dataset.name)?))) {
                out.push(Standing {
                    protocol,
                    dataset: dataset.name.clone(),
                    rank: row.rank,
                    ranked,
                    score: cell.score,
                    submission_id: cell.submission_id,
                    pinned: cell.pinned,
                });
            }
        }
    }
    Ok(out)
}

/// The rendered board of `key`: kept while the boards stand (see [`crate::board_cache`]),
/// otherwise rendered by `render`.
pub async fn cached<F, Fut>(app: &App, key: BoardKey, render: F) -> AppResult<Arc<Rendered>>
where
    F: FnOnce() -> Fut,
    Fut: Future<Output = AppResult<Vec<u8>>>,
{
    app.boards.get_or_render(&app.store, key, render).await
}

fn pose_entry(e: BoardEntry) -> Entry {
    let cell = Cell {
        recall: e.score.recall,
        ar_vsd: e.score.ar_vsd,
        ar_mssd: e.score.ar_mssd,
        ar_mspd: e.score.ar_mspd,
        record: Some(e.score.record.clone()),
        ci95: e.score.ci95,
        score_id: Some(e.score.id),
        ..headline(&e.head, e.score.score, e.score.time_avg)
    };
    entry(e.head, cell, e.object_scores)
}

fn coco_entry(e: &CocoBoardEntry) -> Entry {
    let cell = Cell {
        record: Some(e.record.clone()),
        ci95: e.ci95,
        score_id: Some(e.score_id),
        stats: e.report.stats().into_iter().collect(),
        ..headline(&e.head, e.report.ap, e.time_avg)
    };
    entry(e.head.clone(), cell, BTreeMap::new())
}

fn bop24_entry(e: &Bop24BoardEntry) -> Entry {
    let r = &e.report;
    let cell = Cell {
        stats: BOP24_PARTS
            .into_iter()
            .zip([
                r.bop24_map_mssd,
                r.bop24_map_mspd,
                r.bop24_map_mssd_mm,
                r.bop25_map,
                r.bop25_map_mm,
            ])
            .filter(|(_, v)| v.is_finite())
            .collect(),
        ci95: e.ci95,
        score_id: Some(e.score_id),
        ..headline(&e.head, r.bop24_map, e.time_avg)
    };
    entry(e.head.clone(), cell, bop24_objects(r))
}

/// A board's cell with only its headline: what every task has.
fn headline(head: &EntryHead, score: f64, time: Option<f64>) -> Cell {
    Cell {
        submission_id: head.submission_id,
        score,
        recall: None,
        ar_vsd: None,
        ar_mssd: None,
        ar_mspd: None,
        time,
        pinned: head.pinned,
        record: None,
        ci95: None,
        score_id: None,
        stats: BTreeMap::new(),
        red_flags: Vec::new(),
    }
}

/// A board's entry: who the method is, from the row every board reads alike, and its cell.
/// Every reader sees a board alike, so an anonymous method's owner is never named on one.
fn entry(head: EntryHead, cell: Cell, objects: BTreeMap<i64, f64>) -> Entry {
    Entry {
        cell,
        method_id: head.method_id,
        method: head.method,
        owner: visibility::public_owner(head.owner, head.anonymous),
        training_data: head.training_data,
        modality: head.modality,
        onboarding: head.onboarding,
        test_objects: head.test_objects,
        hardware: head.hardware,
        dataset_id: head.dataset_id,
        dataset: head.dataset,
        objects,
    }
}

/// The per-object AP of a bop24 report as its mAP is made: per object, the mean of its MSSD
/// and MSPD APs (their mean over the objects is bop24_mAP, since both count the same objects).
pub fn bop24_objects(r: &DetectionReport) -> BTreeMap<i64, f64> {
    let of = |error: DetectionError| {
        r.errors
            .iter()
            .find(|s| s.error == error)
            .map(|s| {
                s.objects
                    .iter()
                    .map(|o| (i64::from(o.obj_id), o.ap))
                    .collect::<BTreeMap<i64, f64>>()
            })
            .unwrap_or_default()
    };
    let mspd = of(DetectionError::Mspd);
    of(DetectionError::Mssd)
        .into_iter()
        .filter_map(|(o, mssd)| Some((o, (mssd + mspd.get(&o)?) / 2.0)))
        .collect()
}
