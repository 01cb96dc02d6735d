//! A leaderboard as a download: CSV, JSON, or a LaTeX `tabular` laid out as the results tables
//! of the ECCV'18 paper (methods by rows; the datasets, the average and the time as columns;
//! the best of each column in bold). Each is written from the very [`Leaderboard`] the page
//! shows, so an export holds every row of the board and can never disagree with it, and each
//! score comes with its reproducibility record.

use std::fmt::Write;

use evaluator::protocol::ProtocolName;
use serde_json::json;

use crate::domain::BoardProtocol;
use crate::error::{AppError, AppResult};
use crate::store::scores::ScoreRecord;
use crate::web::views::{BoardRow, Cell as BoardCell, Leaderboard};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Export {
    Csv,
    Json,
    Tex,
}

impl Export {
    pub fn content_type(self) -> &'static str {
        match self {
            Export::Csv => "text/csv; charset=utf-8",
            Export::Json => "application/json",
            Export::Tex => "application/x-tex; charset=utf-8",
        }
    }

    pub fn extension(self) -> &'static str {
        match self {
            Export::Csv => "csv",
            Export::Json => "json",
            Export::Tex => "tex",
        }
    }

    /// The board in this format.
    pub fn render(self, board: &Leaderboard) -> AppResult<Vec<u8>> {
        Ok(match self {
            Export::Csv => csv(board).into_bytes(),
            Export::Json => {
                let mut out = json!({
                    "protocol": board.protocol,
                    "score_name": board.score_name,
                    "time_unit": board.time_unit,
                    "dataset": board.dataset.as_ref().map(|d| &d.name),
                    "columns": board.columns.iter().map(|d| &d.name).collect::<Vec<_>>(),
                    "filter": board.filter,
                    "rows": board.rows,
                });
                // A 2D board's parameters are COCOeval's; its numbers are named in `stats`.
                // BOP'24's are its errors with their thresholds and the visibility below which
                // ground truth is not counted.
                let parameters = match board.protocol {
                    BoardProtocol::Pose(_) => json!(board.parameters),
                    BoardProtocol::Bop24 => json!({
                        "errors": evaluator::detection::DetectionError::ALL
                            .iter()
                            .map(|e| json!({"name": e.name(), "thresholds": e.thresholds()}))
                            .collect::<Vec<_>>(),
                        "visib_gt_min": evaluator::detection::VISIB_GT_MIN,
                    }),
                    BoardProtocol::Coco(t) => json!(t.task().parameters()),
                };
                out["parameters"] = parameters;
                if !board.stat_names.is_empty() {
                    out["stats"] = json!(board.stat_names);
                }
                serde_json::to_vec_pretty(&out)
                    .map_err(|e| AppError::failed("writing the export JSON", e))?
            }
            Export::Tex => latex(board).into_bytes(),
        })
    }

    /// The name a browser saves the board under: `poseboard-bop19[-DATASET].csv`.
    pub fn file_name(self, board: &Leaderboard) -> String {
        let dataset = board
            .dataset
            .as_ref()
            .map_or(String::new(), |d| format!("-{}", d.name));
        format!(
            "poseboard-{}{dataset}.{}",
            board.protocol.as_str(),
            self.extension()
        )
    }
}

/// The record's columns (empty for a score without one).
fn record_fields(r: Option<&ScoreRecord>) -> [String; 5] {
    match r {
        Some(r) => [
            r.evaluator_version.clone().unwrap_or_default(),
            r.protocol.as_str().to_string(),
            parameters(r),
            r.dataset_hash.clone().unwrap_or_default(),
            r.file_sha256.clone(),
        ],
        None => Default::default(),
    }
}

/// The parameters of a record as compact JSON (empty when not recorded).
fn parameters(r: &ScoreRecord) -> String {
    r.parameters
        .as_ref()
        .and_then(|p| serde_json::to_string(p).ok())
        .unwrap_or_default()
}

/// One CSV field, quoted when it must be.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn number(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

/// What every score has after its numbers: its submission and reproducibility record.
const RECORD: [&str; 7] = [
    "submission_id",
    "pinned",
    "evaluator_version",
    "protocol",
    "parameters",
    "dataset_hash",
    "file_sha256",
];

/// A 6D score's numbers, per dataset.
const POSE_NUMBERS: [&str; 6] = ["score", "recall", "ar_vsd", "ar_mssd", "ar_mspd", "time"];

/// The numbers of a score in the CSV, per dataset: a 6D protocol's headline and breakdowns, or
/// a 2D task's twelve AP/AR numbers, each with its time (and a 2D score its interval, which
/// the JSON of either kind carries as `ci95`).
fn numbers(board: &Leaderboard) -> Vec<&'static str> {
    match board.protocol {
        BoardProtocol::Pose(_) => POSE_NUMBERS.to_vec(),
        BoardProtocol::Bop24 => {
            let mut names = vec!["bop24_mAP"];
            names.extend(board.stat_names.iter().copied());
            names.push("time");
            names
        }
        BoardProtocol::Coco(_) => {
            let mut names = board.stat_names.clone();
            names.extend(["time", "ci95_low", "ci95_high"]);
            names
        }
    }
}

/// The values of [`numbers`] of a cell.
fn number_fields(board: &Leaderboard, c: &BoardCell) -> Vec<String> {
    match board.protocol {
        BoardProtocol::Pose(_) => vec![
            c.score.to_string(),
            number(c.recall),
            number(c.ar_vsd),
            number(c.ar_mssd),
            number(c.ar_mspd),
            number(c.time),
        ],
        BoardProtocol::Bop24 => {
            let mut values = vec![c.score.to_string()];
            values.extend(board.stat_names.iter().map(|k| number(c.stat(k))));
            values.push(number(c.time));
            values
        }
        BoardProtocol::Coco(_) => {
            let mut values: Vec<String> =
                board.stat_names.iter().map(|k| number(c.stat(k))).collect();
            values.extend([
                number(c.time),
                number(c.ci95.map(|v| v[0])),
                number(c.ci95.map(|v| v[1])),
            ]);
            values
        }
    }
}

/// Every row with every column: the method's facts; per dataset shown, its score with the
/// breakdowns (a 2D board: its AP/AR numbers and interval), time, submission and
/// reproducibility record; the row's average, mean, coverage and time; and with one dataset,
/// the per-object scores. Scores are fractions, at full precision.
fn csv(board: &Leaderboard) -> String {
    let per_dataset: Vec<&str> = numbers(board).into_iter().chain(RECORD).collect();
    let mut header: Vec<String> = [
        "rank",
        "method",
        "owner",
        "training_data",
        "modality",
        "objects",
        "onboarding",
        "hardware",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for d in &board.columns {
        header.extend(per_dataset.iter().map(|k| format!("{} {k}", d.name)));
    }
    header.extend(["average", "mean", "covered", "time"].map(String::from));
    header.extend(board.object_ids.iter().map(|o| format!("obj {o}")));
    let mut out = line(&header);
    for row in &board.rows {
        let mut cells = vec![
            row.rank.map_or(String::new(), |r| r.to_string()),
            row.method.clone(),
            row.owner.clone(),
            row.training_data.map_or("", |t| t.as_str()).to_string(),
            row.modality.map_or("", |m| m.as_str()).to_string(),
            row.test_objects.map_or("", |o| o.as_str()).to_string(),
            row.onboarding.map_or("", |o| o.as_str()).to_string(),
            row.hardware.clone(),
        ];
        for d in &board.columns {
            match row.scores.get(&d.name) {
                Some(c) => {
                    cells.extend(number_fields(board, c));
                    cells.extend([c.submission_id.to_string(), c.pinned.to_string()]);
                    cells.extend(record_fields(c.record.as_ref()));
                }
                None => cells.extend(per_dataset.iter().map(|_| String::new())),
            }
        }
        cells.extend([
            number(row.average),
            number(row.mean),
            row.covered.to_string(),
            number(row.time),
        ]);
        cells.extend(
            board
                .object_ids
                .iter()
                .map(|o| number(row.objects.get(o).copied())),
        );
        out.push_str(&line(&cells));
    }
    out
}

fn line(cells: &[String]) -> String {
    let fields: Vec<String> = cells.iter().map(|c| field(c)).collect();
    format!("{}\r\n", fields.join(","))
}

/// `s` as LaTeX text: its special characters escaped.
pub fn tex_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\textbackslash{}"),
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// A cell of the LaTeX table as shown, from its row (`None`: no value).
type Cell<'a> = Box<dyn Fn(&BoardRow) -> Option<String> + 'a>;

/// A column of the LaTeX table: its heading, its value in a row, and whether lower is better.
struct Column<'a> {
    heading: String,
    value: Cell<'a>,
    lower_is_better: bool,
}

/// A score as the page shows it, in %.
fn percent(v: f64) -> String {
    format!("{:.1}", v * 100.0)
}

fn columns(board: &Leaderboard) -> Vec<Column<'_>> {
    let mut columns: Vec<Column> = Vec::new();
    let name = |n: &str| tex_escape(evaluator::dataset::display_name(n));
    match &board.dataset {
        Some(d) => {
            for &o in &board.object_ids {
                columns.push(Column {
                    heading: format!("Obj. {o}"),
                    value: Box::new(move |r| r.objects.get(&o).map(|v| percent(*v))),
                    lower_is_better: false,
                });
            }
            let dataset = d.name.clone();
            columns.push(Column {
                heading: name(&d.name),
                value: Box::new(move |r| r.scores.get(&dataset).map(|c| percent(c.score))),
                lower_is_better: false,
            });
        }
        None => {
            for d in &board.columns {
                let dataset = d.name.clone();
                columns.push(Column {
                    heading: name(&d.name),
                    value: Box::new(move |r| r.scores.get(&dataset).map(|c| percent(c.score))),
                    lower_is_better: false,
                });
            }
            columns.push(Column {
                heading: "Average".into(),
                value: Box::new(|r| r.average.map(percent)),
                lower_is_better: false,
            });
        }
    }
    columns.push(Column {
        heading: "Time (s)".into(),
        value: Box::new(|r| r.time.map(|t| format!("{t:.3}"))),
        lower_is_better: true,
    });
    columns
}

/// The board as a `tabular` (booktabs rules), then the reproducibility record of every score
/// as comment lines.
fn latex(board: &Leaderboard) -> String {
    let columns = columns(board);
    let values: Vec<Vec<Option<String>>> = board
        .rows
        .iter()
        .map(|r| columns.iter().map(|c| (c.value)(r)).collect())
        .collect();
    // The best of a column as shown: equal values at the precision shown are all bold.
    let best: Vec<Option<f64>> = columns
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let shown = values
                .iter()
                .filter_map(|v| v[i].as_deref()?.parse::<f64>().ok());
            if c.lower_is_better {
                shown.reduce(f64::min)
            } else {
                shown.reduce(f64::max)
            }
        })
        .collect();
    let what = match board.protocol {
        BoardProtocol::Pose(ProtocolName::Eccv18) => "recall",
        BoardProtocol::Pose(ProtocolName::Bop19) => "average recall",
        BoardProtocol::Bop24 | BoardProtocol::Coco(_) => "average precision",
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "% poseboard, {} leaderboard{}: {} ({}) in %, time in {}; best per column in bold.",
        board.protocol.as_str(),
        board
            .dataset
            .as_ref()
            .map_or(String::new(), |d| format!(" of {}", d.name)),
        what,
        board.score_name,
        board.time_unit
    );
    let _ = writeln!(out, "% Needs \\usepackage{{booktabs}}.");
    let _ = writeln!(out, "\\begin{{tabular}}{{l{}}}", "r".repeat(columns.len()));
    let _ = writeln!(out, "\\toprule");
    let headings: Vec<&str> = columns.iter().map(|c| c.heading.as_str()).collect();
    let _ = writeln!(out, "Method & {} \\\\", headings.join(" & "));
    let _ = writeln!(out, "\\midrule");
    for (row, vals) in board.rows.iter().zip(&values) {
        let cells: Vec<String> = vals
            .iter()
            .zip(&best)
            .map(|(v, b)| match v {
                Some(v) if v.parse::<f64>().ok() == *b => format!("\\textbf{{{v}}}"),
                Some(v) => v.clone(),
                None => "--".to_string(),
            })
            .collect();
        let _ = writeln!(
            out,
            "{} & {} \\\\",
            tex_escape(&row.method),
            cells.join(" & ")
        );
    }
    let _ = writeln!(out, "\\bottomrule");
    let _ = writeln!(out, "\\end{{tabular}}");
    let _ = writeln!(
        out,
        "% Reproducibility record of each score: method; dataset; submission; evaluator version; \
         protocol; parameters; dataset content hash; result file SHA-256."
    );
    for row in &board.rows {
        for (dataset, c) in &row.scores {
            let Some(r) = &c.record else {
                continue;
            };
            let _ = writeln!(
                out,
                "% {}; {}; {}; {}; {}; {}; {}; {}",
                tex_escape(&row.method),
                tex_escape(dataset),
                c.submission_id,
                r.evaluator_version.as_deref().unwrap_or("not recorded"),
                r.protocol.as_str(),
                parameters(r),
                r.dataset_hash.as_deref().unwrap_or("not recorded"),
                r.file_sha256
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latex_specials_are_escaped() {
        assert_eq!(
            tex_escape(r"a_b & 50% #1 {x} $y ~z ^w \v"),
            r"a\_b \& 50\% \#1 \{x\} \$y \textasciitilde{}z \textasciicircum{}w \textbackslash{}v"
        );
        assert_eq!(tex_escape("line\nbreak"), "line break");
    }

    #[test]
    fn csv_fields_are_quoted_when_needed() {
        assert_eq!(field("plain"), "plain");
        assert_eq!(field("a,b"), "\"a,b\"");
        assert_eq!(field("say \"hi\""), "\"say \"\"hi\"\"\"");
    }
}
