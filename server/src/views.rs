//! The data behind each page, built once and rendered twice: as HTML by the templates and as
//! JSON by the API, so that a page and its JSON twin can never disagree.

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::report::{Parameters, parameters};
use serde::{Deserialize, Serialize};

use crate::app::App;
use crate::auth::Viewer;
use crate::chart::Chart;
use crate::domain::{Modality, TrainingData, optional};
use crate::error::{AppError, AppResult};
use crate::preflight::Preflight;
use crate::store::datasets::DatasetRow;
use crate::store::scores::BoardEntry;
use crate::store::submissions::{Status, SubmissionRow};

#[derive(Clone, Debug, Serialize)]
pub struct Cell {
    pub submission_id: i64,
    pub score: f64,
    pub recall: Option<f64>,
    pub ar_vsd: Option<f64>,
    pub ar_mssd: Option<f64>,
    pub ar_mspd: Option<f64>,
    pub time: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct BoardRow {
    pub rank: usize,
    pub method_id: i64,
    pub method: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    /// The hardware of the method's latest submission shown.
    pub hardware: String,
    /// Per dataset name, the method's score there.
    pub scores: BTreeMap<String, Cell>,
    /// Mean of the per-dataset scores; only when the method has a score on every dataset.
    pub average: Option<f64>,
    /// Mean of the reported times over the datasets that have one.
    pub time: Option<f64>,
    /// With one dataset selected: the per-object scores (recall or AR).
    pub objects: BTreeMap<i64, f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Leaderboard {
    pub protocol: ProtocolName,
    pub score_name: &'static str,
    pub time_unit: &'static str,
    pub parameters: Parameters,
    pub datasets: Vec<DatasetRow>,
    /// With `?dataset=NAME`, that dataset (and the rows carry per-object scores).
    pub dataset: Option<DatasetRow>,
    pub object_ids: Vec<i64>,
    pub filter: BoardFilter,
    pub rows: Vec<BoardRow>,
}

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
}

impl BoardFilter {
    /// The query string that keeps this filter but changes one key (for links on the page).
    pub fn with(&self, key: &str, value: &str) -> String {
        let mut pairs: Vec<(&str, String)> = Vec::new();
        for (k, v) in [
            ("dataset", &self.dataset),
            ("training", &self.training),
            ("modality", &self.modality),
            ("sort", &self.sort),
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
    /// By the average over the datasets shown (or the one dataset's score), best first.
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
        Ok(Query {
            sort,
            training: optional(&field(&filter.training))?,
            modality: optional(&field(&filter.modality))?,
        })
    }

    fn matches(&self, e: &BoardEntry) -> bool {
        self.training.is_none_or(|t| e.training_data == Some(t))
            && self.modality.is_none_or(|m| e.modality == Some(m))
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

pub fn score_name(p: ProtocolName) -> &'static str {
    match p {
        ProtocolName::Eccv18 => "recall (VSD, tau 20 mm, theta 0.3)",
        ProtocolName::Bop19 => "average recall AR = (AR_VSD + AR_MSSD + AR_MSPD) / 3",
    }
}

/// Builds a leaderboard.
pub async fn leaderboard(
    app: &App,
    protocol: ProtocolName,
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
                .ok_or(AppError::NotFound)?,
        ),
        _ => None,
    };
    let query = Query::parse(filter, &datasets)?;
    let entries = app
        .store
        .leaderboard(protocol, selected.as_ref().map(|d| d.id))
        .await?;
    let shown: Vec<&DatasetRow> = match &selected {
        Some(d) => vec![d],
        None => datasets.iter().collect(),
    };
    let mut by_method: BTreeMap<i64, BoardRow> = BTreeMap::new();
    let mut object_ids = std::collections::BTreeSet::new();
    for e in entries.iter().filter(|e| query.matches(e)) {
        let row = by_method.entry(e.method_id).or_insert_with(|| BoardRow {
            rank: 0,
            method_id: e.method_id,
            method: e.method.clone(),
            training_data: e.training_data,
            modality: e.modality,
            hardware: e.hardware.clone(),
            scores: BTreeMap::new(),
            average: None,
            time: None,
            objects: BTreeMap::new(),
        });
        row.scores.insert(e.dataset.clone(), cell(e));
        if selected.is_some() {
            row.objects = e.object_scores.clone();
            object_ids.extend(e.object_scores.keys().copied());
        }
    }
    let mut rows: Vec<BoardRow> = by_method.into_values().collect();
    for row in &mut rows {
        let scores: Vec<f64> = shown
            .iter()
            .filter_map(|d| row.scores.get(&d.name).map(|c| c.score))
            .collect();
        if !scores.is_empty() && scores.len() == shown.len() {
            row.average = Some(scores.iter().sum::<f64>() / scores.len() as f64);
        }
        let times: Vec<f64> = row.scores.values().filter_map(|c| c.time).collect();
        if !times.is_empty() {
            row.time = Some(times.iter().sum::<f64>() / times.len() as f64);
        }
    }
    let key = |r: &BoardRow| -> f64 {
        match &query.sort {
            Sort::Average | Sort::Method => r.average.unwrap_or(-1.0),
            Sort::Time => -r.time.unwrap_or(f64::INFINITY),
            Sort::Dataset(name) => r.scores.get(name).map_or(-1.0, |c| c.score),
        }
    };
    if query.sort == Sort::Method {
        rows.sort_by_key(|r| r.method.to_lowercase());
    } else {
        rows.sort_by(|a, b| {
            key(b)
                .total_cmp(&key(a))
                .then_with(|| a.method.cmp(&b.method))
        });
    }
    for (i, row) in rows.iter_mut().enumerate() {
        row.rank = i + 1;
    }
    Ok(Leaderboard {
        protocol,
        score_name: score_name(protocol),
        time_unit: match protocol {
            ProtocolName::Eccv18 => "s per target",
            ProtocolName::Bop19 => "s per image",
        },
        parameters: parameters(&Protocol::named(protocol)),
        datasets,
        dataset: selected,
        object_ids: object_ids.into_iter().collect(),
        filter: filter.clone(),
        rows,
    })
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
    }
}

/// A submission with everything its page shows.
#[derive(Clone, Debug, Serialize)]
pub struct SubmissionView {
    #[serde(flatten)]
    pub submission: SubmissionRow,
    pub queue_position: Option<i64>,
    pub preflight: Preflight,
    /// Per protocol, the full report (the same keys as `poseboard eval --out`).
    pub scores: BTreeMap<ProtocolName, Report>,
    #[serde(skip)]
    pub charts: Vec<Chart>,
}

/// A submission as `viewer` may see it: a private one answers as missing to everyone but its
/// owner and the admins, exactly like one that does not exist.
pub async fn submission(app: &App, id: i64, viewer: &Viewer) -> AppResult<SubmissionView> {
    let submission = app.store.submission(id).await?.ok_or(AppError::NotFound)?;
    if !submission.is_public() && !viewer.can_see(submission.owner_id) {
        return Err(AppError::NotFound);
    }
    let queue_position = match submission.status {
        Status::Queued => Some(app.store.queue_position(id).await?),
        _ => None,
    };
    let reports = app.store.reports_of_submission(id).await?;
    let charts = reports.iter().flat_map(crate::chart::charts).collect();
    Ok(SubmissionView {
        preflight: submission.preflight.clone(),
        submission,
        queue_position,
        scores: reports.into_iter().map(|r| (r.protocol, r)).collect(),
        charts,
    })
}
