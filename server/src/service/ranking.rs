//! The rules that turn a board's entries into its rows: group by method, average over the
//! datasets shown, rank, order. Kept free of I/O so each BOP rule (a shared rank for scores that
//! read the same, unranked rows after the ranked ones, a dataset's own board, `#` kept under
//! another order) is tested on small tables, and the page, its JSON twin, the exports and the
//! snapshots rank with the same code. Loading the entries and the bootstrap replicates is
//! [`crate::service::boards`]'s.

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use crate::domain::{
    DatasetId, MethodId, Modality, Objects, Onboarding, SubmissionId, TrainingData,
};
use crate::preflight::RedFlag;
use crate::store::datasets::DatasetRow;
use crate::store::scores::ScoreRecord;

#[derive(Clone, Debug, Serialize)]
pub struct Cell {
    pub submission_id: SubmissionId,
    pub score: f64,
    /// The breakdowns a protocol has (eccv18: the recall; bop19: the three ARs); the others
    /// are left out of the JSON rather than written as null.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recall: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ar_vsd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ar_mssd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ar_mspd: Option<f64>,
    pub time: Option<f64>,
    /// The method's owner pinned this submission as its entry (otherwise it is the best).
    pub pinned: bool,
    /// How the score can be reproduced.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub record: Option<ScoreRecord>,
    /// The bootstrap 95 % interval of `score` (resampling the dataset's images); absent for a
    /// score stored before intervals were, until it is re-scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95: Option<[f64; 2]>,
    /// The stored score whose bootstrap replicates the row's interval is made of (in the 6D
    /// or the 2D scores, as the board is).
    #[serde(skip)]
    pub score_id: Option<i64>,
    /// 2D boards: the twelve AP/AR numbers of the report under the toolkit's keys.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub stats: BTreeMap<&'static str, f64>,
    /// The pre-flight's red flags its owner confirmed publishing it despite; empty for a clean
    /// file (a public submission with red flags was published by that confirmation).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub red_flags: Vec<RedFlag>,
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
    pub method_id: MethodId,
    pub method: String,
    /// The account the method belongs to.
    pub owner: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub onboarding: Option<Onboarding>,
    /// The method's `objects` (seen or unseen); named apart from `objects`, the per-object
    /// scores.
    pub test_objects: Option<Objects>,
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

/// A method's entry on a dataset, as any board shows it.
#[derive(Clone, Debug)]
pub struct Entry {
    pub method_id: MethodId,
    pub method: String,
    pub owner: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub onboarding: Option<Onboarding>,
    pub test_objects: Option<Objects>,
    pub hardware: String,
    pub dataset_id: DatasetId,
    pub dataset: String,
    pub cell: Cell,
    pub objects: BTreeMap<i64, f64>,
}

/// How a leaderboard's rows are ordered.
#[derive(Clone, Debug, PartialEq)]
pub enum Sort {
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

impl Sort {
    /// The name of the order, as the board's query gives it.
    pub fn name(&self) -> String {
        match self {
            Sort::Average => "average".to_string(),
            Sort::Time => "time".to_string(),
            Sort::Method => "method".to_string(),
            Sort::Dataset(name) => name.clone(),
        }
    }
}

/// A score as the page shows it: two scores that read the same share a rank.
pub fn shown(score: f64) -> String {
    format!("{:.1}", score * 100.0)
}

/// The rows of a board whose columns are `columns`: one per method with an entry on one of
/// them, with its coverage, mean, time and (with a score on each column) average; with
/// `per_object` (a dataset's own board) the per-object scores too. Also the object ids met.
/// The rows are neither ranked nor ordered yet (see [`rank`]).
pub fn rows(
    entries: &[Entry],
    columns: &[DatasetRow],
    per_object: bool,
) -> (Vec<BoardRow>, Vec<i64>) {
    let mut by_method: BTreeMap<MethodId, BoardRow> = BTreeMap::new();
    let mut object_ids = BTreeSet::new();
    for e in entries
        .iter()
        .filter(|e| columns.iter().any(|d| d.id == e.dataset_id))
    {
        let row = by_method.entry(e.method_id).or_insert_with(|| BoardRow {
            rank: None,
            method_id: e.method_id,
            method: e.method.clone(),
            owner: e.owner.clone(),
            training_data: e.training_data,
            modality: e.modality,
            onboarding: e.onboarding,
            test_objects: e.test_objects,
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
        if per_object {
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
    (rows, object_ids.into_iter().collect())
}

/// The cells of `row` under `columns`, in the columns' order.
fn cells<'a>(row: &'a BoardRow, columns: &[DatasetRow]) -> Vec<&'a Cell> {
    columns
        .iter()
        .filter_map(|d| row.scores.get(&d.name))
        .collect()
}

/// The stored scores whose bootstrap replicates [`intervals`] needs: none with one column (a
/// single score carries its own interval), else those of every row with an average.
pub fn replicates_needed(rows: &[BoardRow], columns: &[DatasetRow]) -> Vec<i64> {
    if columns.len() == 1 {
        return Vec::new();
    }
    rows.iter()
        .filter(|r| r.average.is_some())
        .flat_map(|r| cells(r, columns).into_iter().filter_map(|c| c.score_id))
        .collect()
}

/// The interval of each row's average: a single score's own, or, over several datasets, the
/// percentiles of the means of their replicates taken replicate by replicate (in the order and
/// with the sum the average uses). `replicates` holds those of [`replicates_needed`]; a row
/// with a score lacking them, or with replicate counts that differ, gets none.
pub fn intervals(
    rows: &mut [BoardRow],
    columns: &[DatasetRow],
    replicates: &BTreeMap<i64, Vec<f64>>,
) {
    for row in rows.iter_mut().filter(|r| r.average.is_some()) {
        let cells = cells(row, columns);
        if columns.len() == 1 {
            row.ci95 = cells.first().and_then(|c| c.ci95);
            continue;
        }
        let sets: Option<Vec<&Vec<f64>>> = cells
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
}

/// Puts `rows` in rank order and numbers the ranked ones: rows with an average first, best
/// first, then the others by coverage and mean; ties by age (the older method first). Rows
/// whose averages read the same at the precision shown share the rank of the first of them.
pub fn rank(rows: &mut [BoardRow]) {
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
}

/// The ranked rows (of `rows` in rank order) whose curves a dataset's board draws: the methods
/// `chosen`, or without a choice the first `best`.
pub fn drawn<'a>(
    rows: &'a [BoardRow],
    chosen: Option<&[MethodId]>,
    best: usize,
) -> Vec<&'a BoardRow> {
    let ranked = rows.iter().filter(|r| r.rank.is_some());
    match chosen {
        None => ranked.take(best).collect(),
        Some(ids) => ranked.filter(|r| ids.contains(&r.method_id)).collect(),
    }
}

/// Orders ranked rows (see [`rank`]) by `by`, each keeping its rank: `#` is always the score's.
/// Rows without the value sorted by go last; the sort is stable, so equal values keep rank
/// order.
pub fn sort(rows: &mut [BoardRow], by: &Sort) {
    let last = |v: Option<f64>| v.map_or((1, 0.0), |v| (0, v));
    match by {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dataset(id: i64, name: &str) -> DatasetRow {
        DatasetRow::named(DatasetId::new(id), name)
    }

    /// The datasets of the tables below: `lmo` (1), `tless` (2), `ycbv` (3).
    fn columns(names: &[&str]) -> Vec<DatasetRow> {
        names
            .iter()
            .map(|n| match *n {
                "lmo" => dataset(1, "lmo"),
                "tless" => dataset(2, "tless"),
                "ycbv" => dataset(3, "ycbv"),
                other => panic!("no dataset {other}"),
            })
            .collect()
    }

    /// Method `method_id`'s entry on `dataset` (see [`columns`]) with `score` and `time`; its
    /// score id is `method_id * 10 + dataset id`.
    fn entry(method_id: i64, dataset: &str, score: f64, time: Option<f64>) -> Entry {
        let d = &columns(&[dataset])[0];
        let d_id = d.id.get();
        Entry {
            method_id: MethodId::new(method_id),
            method: format!("M{method_id}"),
            owner: "someone".to_string(),
            training_data: None,
            modality: None,
            onboarding: None,
            test_objects: None,
            hardware: String::new(),
            dataset_id: d.id,
            dataset: d.name.clone(),
            cell: Cell {
                submission_id: SubmissionId::new(method_id * 100 + d_id),
                score,
                recall: None,
                ar_vsd: None,
                ar_mssd: None,
                ar_mspd: None,
                time,
                pinned: false,
                record: None,
                ci95: Some([score - 0.01, score + 0.01]),
                score_id: Some(method_id * 10 + d_id),
                stats: BTreeMap::new(),
                red_flags: Vec::new(),
            },
            objects: BTreeMap::from([(d_id, score), (d_id + 10, score / 2.0)]),
        }
    }

    /// The board of `entries` over `names`, ranked (no replicates).
    fn ranked(entries: &[Entry], names: &[&str]) -> Vec<BoardRow> {
        let columns = columns(names);
        let (mut rows, _) = rows(entries, &columns, names.len() == 1);
        intervals(&mut rows, &columns, &BTreeMap::new());
        rank(&mut rows);
        rows
    }

    /// Each row as (method id, rank).
    fn ranks(rows: &[BoardRow]) -> Vec<(i64, Option<usize>)> {
        rows.iter().map(|r| (r.method_id.get(), r.rank)).collect()
    }

    #[test]
    fn ties_are_judged_at_the_precision_shown() {
        assert_eq!(shown(0.12341), shown(0.12349));
        assert_ne!(shown(0.1234), shown(0.1236));
    }

    #[test]
    fn averages_that_read_the_same_share_a_rank_and_the_next_skips() {
        // Averages 0.6, 0.60004 and 0.6004 all read 60.0; 0.5 comes fourth, not second.
        let entries = [
            entry(1, "lmo", 0.5, None),
            entry(1, "tless", 0.5, None),
            entry(2, "lmo", 0.6, None),
            entry(2, "tless", 0.6, None),
            entry(3, "lmo", 0.6, None),
            entry(3, "tless", 0.60008, None),
            entry(4, "lmo", 0.7, None),
            entry(4, "tless", 0.5008, None),
        ];
        let rows = ranked(&entries, &["lmo", "tless"]);
        assert_eq!(
            ranks(&rows),
            [(4, Some(1)), (3, Some(1)), (2, Some(1)), (1, Some(4))]
        );
        // Within the tie, the better exact average first.
        assert!(rows[0].average > rows[1].average && rows[1].average > rows[2].average);
    }

    #[test]
    fn equal_averages_keep_the_older_method_first() {
        let entries = [entry(7, "lmo", 0.4, None), entry(3, "lmo", 0.4, None)];
        assert_eq!(
            ranks(&ranked(&entries, &["lmo"])),
            [(3, Some(1)), (7, Some(1))]
        );
    }

    #[test]
    fn rows_without_every_dataset_are_unranked_after_by_coverage_then_mean() {
        let entries = [
            // Two of three datasets, mean 0.9.
            entry(1, "lmo", 0.9, None),
            entry(1, "tless", 0.9, None),
            // One dataset, mean 0.95: fewer datasets, so after method 1 despite its mean.
            entry(2, "ycbv", 0.95, None),
            // Every dataset, average 0.2: ranked, so first.
            entry(3, "lmo", 0.2, None),
            entry(3, "tless", 0.2, None),
            entry(3, "ycbv", 0.2, None),
            // Two of three, mean 0.5: after method 1 (same coverage, lower mean).
            entry(4, "lmo", 0.4, None),
            entry(4, "ycbv", 0.6, None),
        ];
        let rows = ranked(&entries, &["lmo", "tless", "ycbv"]);
        assert_eq!(
            ranks(&rows),
            [(3, Some(1)), (1, None), (4, None), (2, None)]
        );
        let row = |id| {
            rows.iter()
                .find(|r| r.method_id == MethodId::new(id))
                .unwrap()
        };
        assert_eq!((row(1).covered, row(1).average), (2, None));
        assert_eq!(row(4).mean, Some(0.5));
        assert_eq!(row(3).average, Some((0.2 + 0.2 + 0.2) / 3.0));
    }

    #[test]
    fn entries_off_the_columns_are_not_counted() {
        let entries = [
            entry(1, "lmo", 0.3, None),
            entry(1, "ycbv", 0.9, None),
            entry(2, "ycbv", 0.9, None),
        ];
        let rows = ranked(&entries, &["lmo"]);
        assert_eq!(ranks(&rows), [(1, Some(1))]);
        assert_eq!(rows[0].scores.keys().collect::<Vec<_>>(), ["lmo"]);
        assert_eq!(rows[0].average, Some(0.3));
    }

    #[test]
    fn a_time_is_averaged_only_when_every_dataset_covered_has_one() {
        let entries = [
            entry(1, "lmo", 0.5, Some(2.0)),
            entry(1, "tless", 0.5, Some(4.0)),
            entry(2, "lmo", 0.5, Some(2.0)),
            entry(2, "tless", 0.5, None),
            // A negative time is no time.
            entry(3, "lmo", 0.5, Some(-1.0)),
        ];
        let rows = ranked(&entries, &["lmo", "tless"]);
        let time = |id| {
            rows.iter()
                .find(|r| r.method_id == MethodId::new(id))
                .unwrap()
                .time
        };
        assert_eq!((time(1), time(2), time(3)), (Some(3.0), None, None));
    }

    #[test]
    fn a_dataset_board_ranks_by_its_score_with_its_objects_and_interval() {
        let entries = [
            entry(1, "tless", 0.41, None),
            entry(2, "tless", 0.73, None),
            entry(2, "lmo", 0.99, None),
        ];
        let columns = columns(&["tless"]);
        let (mut rows, objects) = rows(&entries, &columns, true);
        assert_eq!(objects, [2, 12]);
        // One column: the score's own interval, no replicates wanted.
        assert!(replicates_needed(&rows, &columns).is_empty());
        intervals(&mut rows, &columns, &BTreeMap::new());
        rank(&mut rows);
        assert_eq!(ranks(&rows), [(2, Some(1)), (1, Some(2))]);
        assert_eq!(rows[0].ci95, Some([0.73 - 0.01, 0.73 + 0.01]));
        assert_eq!(
            rows[0].objects,
            BTreeMap::from([(2, 0.73), (12, 0.73 / 2.0)])
        );
        // The main board leaves the per-object scores out.
        let (main, objects) = super::rows(&entries, &columns, false);
        assert!(objects.is_empty() && main.iter().all(|r| r.objects.is_empty()));
    }

    #[test]
    fn an_average_interval_comes_from_the_replicate_wise_means() {
        let entries = [
            entry(1, "lmo", 0.5, None),
            entry(1, "tless", 0.5, None),
            entry(2, "lmo", 0.5, None),
            entry(2, "tless", 0.5, None),
            entry(3, "lmo", 0.5, None),
        ];
        let columns = columns(&["lmo", "tless"]);
        let (mut rows, _) = rows(&entries, &columns, false);
        // Only the rows with an average want replicates, in the columns' order.
        assert_eq!(replicates_needed(&rows, &columns), [11, 12, 21, 22]);
        let lmo: Vec<f64> = (0..100).map(|i| f64::from(i) / 100.0).collect();
        let tless: Vec<f64> = lmo.iter().map(|v| v + 0.5).collect();
        let replicates = BTreeMap::from([
            (11, lmo.clone()),
            (12, tless.clone()),
            (21, lmo.clone()),
            // Method 2's replicate counts differ: no interval.
            (22, tless[..50].to_vec()),
        ]);
        intervals(&mut rows, &columns, &replicates);
        let means: Vec<f64> = lmo.iter().zip(&tless).map(|(a, b)| (a + b) / 2.0).collect();
        assert_eq!(rows[0].ci95, Some(evaluator::bootstrap::interval95(&means)));
        assert_eq!((rows[1].ci95, rows[2].ci95), (None, None));
    }

    #[test]
    fn another_order_keeps_each_rows_rank() {
        let mut rows = ranked(
            &[
                entry(1, "lmo", 0.9, Some(5.0)),
                entry(1, "tless", 0.8, Some(5.0)),
                entry(2, "lmo", 0.5, Some(1.0)),
                entry(2, "tless", 0.95, None),
                entry(3, "lmo", 0.7, Some(0.5)),
                entry(3, "tless", 0.7, Some(0.5)),
                entry(4, "tless", 0.99, Some(0.1)),
            ],
            &["lmo", "tless"],
        );
        let before = ranks(&rows);
        assert_eq!(
            before,
            [(1, Some(1)), (2, Some(2)), (3, Some(3)), (4, None)]
        );
        let by = |rows: &mut Vec<BoardRow>, sort: Sort| {
            super::sort(rows, &sort);
            let mut now = ranks(rows);
            let order: Vec<i64> = now.iter().map(|r| r.0).collect();
            now.sort();
            // The same ranks, whatever the order.
            assert_eq!(now, before);
            order
        };
        // Fastest first; rows without a time last.
        assert_eq!(by(&mut rows, Sort::Time), [4, 3, 1, 2]);
        // Best on lmo first; rows without an lmo score last.
        assert_eq!(by(&mut rows, Sort::Dataset("lmo".into())), [1, 3, 2, 4]);
        assert_eq!(by(&mut rows, Sort::Dataset("tless".into())), [4, 2, 1, 3]);
        for r in &mut rows {
            r.method = format!(
                "{}{}",
                if r.method_id.get() % 2 == 0 { "a" } else { "B" },
                r.method_id
            );
        }
        assert_eq!(by(&mut rows, Sort::Method), [2, 4, 1, 3]);
        rank(&mut rows);
        assert_eq!(ranks(&rows), before);
    }

    #[test]
    fn the_curves_drawn_are_the_best_ranked_or_those_chosen() {
        let entries: Vec<Entry> = (1..=4)
            .map(|m| entry(m, "lmo", m as f64 / 10.0, None))
            .chain([entry(5, "tless", 0.9, None)])
            .collect();
        let rows = ranked(&entries, &["lmo"]);
        let ids =
            |drawn: Vec<&BoardRow>| drawn.iter().map(|r| r.method_id.get()).collect::<Vec<_>>();
        assert_eq!(ids(drawn(&rows, None, 2)), [4, 3]);
        // Chosen ones in rank order; an unranked or unknown method is not drawn.
        assert_eq!(
            ids(drawn(&rows, Some(&[1, 3, 5, 99].map(MethodId::new)), 2)),
            [3, 1]
        );
    }
}
