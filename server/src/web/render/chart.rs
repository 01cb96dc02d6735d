//! Recall curves (the paper's Fig. 5) and the 2D tasks' and bop24's precision-recall curves as
//! server-rendered SVG: the geometry is computed here and
//! the template only places it, so pages need no JavaScript and no plotting crate (plotters'
//! defaults need fontconfig).

use evaluator::Report;
use evaluator::coco::CocoReport;
use evaluator::detection::{DetectionError, DetectionReport};
use evaluator::report::VisibBin;

/// Plot area inside the SVG viewBox (0 0 360 240).
const LEFT: f64 = 44.0;
const RIGHT: f64 = 344.0;
const TOP: f64 = 16.0;
const BOTTOM: f64 = 204.0;

#[derive(Clone, Debug)]
pub struct Series {
    pub label: String,
    /// `points` attribute of an SVG polyline.
    pub points: String,
    /// Marker positions.
    pub dots: Vec<(f64, f64)>,
    pub class: String,
}

#[derive(Clone, Debug)]
pub struct Tick {
    pub pos: f64,
    pub label: String,
}

#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub series: Vec<Series>,
    pub x_ticks: Vec<Tick>,
    pub y_ticks: Vec<Tick>,
    /// Above a point, how many instances it stands for (a recall over 3 instances is not one
    /// over 300): `pos` is the x of the point.
    pub counts: Vec<Tick>,
    /// What the counts count, for the caption (empty when there are none).
    pub counts_note: String,
}

fn sx(x: f64, max: f64) -> f64 {
    LEFT + (RIGHT - LEFT) * (x / max).clamp(0.0, 1.0)
}

fn sy(y: f64) -> f64 {
    BOTTOM - (BOTTOM - TOP) * y.clamp(0.0, 1.0)
}

/// A curve to draw: its legend and its (x, y) points.
type Line = (String, Vec<(f64, f64)>);

/// The charts of one report: the paper's Fig. 5 for eccv18, recall against the threshold of
/// correctness per error type for bop19.
pub fn charts(report: &Report) -> Vec<Chart> {
    let mut out = Vec::new();
    if !report.recall_vs_theta.is_empty() {
        let lines = report
            .recall_vs_theta
            .iter()
            .map(|c| (format!("tau = {} mm", c.tau), c.points.clone()))
            .collect();
        out.push(chart(
            "Recall vs threshold of correctness",
            "theta",
            1.0,
            lines,
        ));
    }
    let bins: Vec<&VisibBin> = report
        .recall_vs_visib
        .iter()
        .filter(|b| b.instances > 0)
        .collect();
    if !bins.is_empty() {
        // Visibility bins are plotted at their centres.
        let centre = |b: &VisibBin| (b.visib_from + b.visib_to) / 2.0;
        let mut c = chart(
            "Recall vs visible fraction of the target",
            "visible fraction",
            1.0,
            vec![(
                "recall".to_string(),
                bins.iter().map(|b| (centre(b), b.recall)).collect(),
            )],
        );
        c.counts = bins
            .iter()
            .map(|b| Tick {
                pos: sx(centre(b), 1.0),
                label: b.instances.to_string(),
            })
            .collect();
        let total: usize = bins.iter().map(|b| b.instances).sum();
        c.counts_note = format!(
            "numbers above: target instances per bin ({} in all, visible at least {})",
            total, report.parameters.visib_gt_min
        );
        out.push(c);
    }
    for curve in &report.recall_vs_threshold {
        let (title, x_label) = threshold_titles(&curve.error);
        out.push(chart(
            &title,
            x_label,
            x_max(&curve.points),
            vec![("recall".to_string(), curve.points.clone())],
        ));
    }
    out
}

/// The title and x axis of an error type's recall-vs-threshold chart.
fn threshold_titles(error: &str) -> (String, &'static str) {
    match error {
        "vsd" => (
            "VSD recall vs threshold (mean over taus)".to_string(),
            "theta",
        ),
        "mspd" => ("MSPD recall vs threshold".to_string(), "threshold (px)"),
        other => (
            format!("{} recall vs threshold", other.to_uppercase()),
            "threshold (x diameter)",
        ),
    }
}

fn x_max(points: &[(f64, f64)]) -> f64 {
    points.iter().map(|p| p.0).fold(0.0, f64::max).max(1e-9)
}

/// Several methods' curves on one chart each, one series per method in the order given (a
/// dataset's board passes its best entries): bop19, recall against the threshold per error
/// type; eccv18, recall against theta at the main tau.
pub fn overlays(methods: &[(String, Report)]) -> Vec<Chart> {
    let Some((_, first)) = methods.first() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for curve in &first.recall_vs_threshold {
        let lines: Vec<Line> = methods
            .iter()
            .filter_map(|(name, r)| {
                let c = r
                    .recall_vs_threshold
                    .iter()
                    .find(|c| c.error == curve.error)?;
                Some((name.clone(), c.points.clone()))
            })
            .collect();
        let max = lines.iter().map(|l| x_max(&l.1)).fold(1e-9, f64::max);
        let (title, x_label) = threshold_titles(&curve.error);
        out.push(chart(&title, x_label, max, lines));
    }
    let tau = first.parameters.main_tau;
    let lines: Vec<Line> = methods
        .iter()
        .filter_map(|(name, r)| {
            let c = r.recall_vs_theta.iter().find(|c| c.tau == tau)?;
            Some((name.clone(), c.points.clone()))
        })
        .collect();
    if !lines.is_empty() {
        out.push(chart(
            &format!("Recall vs threshold of correctness at tau = {tau} mm"),
            "theta",
            1.0,
            lines,
        ));
    }
    out
}

/// COCOeval's precision at the 101 recall points as (recall, precision) points, without the
/// points where it is undefined (-1: no ground truth, or the recall is never reached).
fn pr_points(precision: &[f64]) -> Vec<(f64, f64)> {
    precision
        .iter()
        .enumerate()
        .filter(|(_, p)| **p >= 0.0)
        .map(|(i, &p)| (i as f64 / 100.0, p))
        .collect()
}

/// The precision-recall curves of a 2D report (all areas, 100 detections, mean over the
/// categories): at IoU 0.5, at 0.75, and averaged over the ten thresholds, as AP averages it.
pub fn precision_recall(report: &CocoReport) -> Chart {
    let pr = &report.precision_recall;
    pr_chart(
        "Precision vs recall",
        vec![
            ("IoU 0.50:0.95 (mean)".to_string(), pr_points(&pr.iou_mean)),
            ("IoU 0.50".to_string(), pr_points(&pr.iou_50)),
            ("IoU 0.75".to_string(), pr_points(&pr.iou_75)),
        ],
    )
}

/// The precision-recall curve averaged over the IoU thresholds (the one AP is the mean of) of
/// each labelled report, one series each, for a dataset's board.
pub fn precision_recall_of_methods(reports: &[(String, &CocoReport)]) -> Chart {
    pr_chart(
        "Precision vs recall, mean over IoU 0.50:0.95",
        reports
            .iter()
            .map(|(label, r)| (label.clone(), pr_points(&r.precision_recall.iou_mean)))
            .collect(),
    )
}

/// How a bop24 error is named in a legend.
fn detection_label(error: DetectionError) -> &'static str {
    match error {
        DetectionError::Mssd => "MSSD (0.05..0.5 x diameter)",
        DetectionError::MssdMm => "MSSD (2..20 mm)",
        DetectionError::Mspd => "MSPD (5..50 px)",
    }
}

/// The precision-recall curves of a bop24 report, one per error (averaged over its objects and
/// thresholds, as its mAP averages them); an error that counted nothing has none.
pub fn detection_precision_recall(report: &DetectionReport) -> Chart {
    pr_chart(
        "Precision vs recall (bop24)",
        report
            .errors
            .iter()
            .filter(|e| !e.precision_recall.is_empty())
            .map(|e| {
                (
                    detection_label(e.error).to_string(),
                    pr_points(&e.precision_recall),
                )
            })
            .collect(),
    )
}

/// The bop24 board's precision-recall curves: each labelled report's MSSD and MSPD curves
/// averaged (the curve bop24_mAP is the mean of), one series per method.
pub fn detection_precision_recall_of_methods(reports: &[(String, &DetectionReport)]) -> Chart {
    pr_chart(
        "Precision vs recall, mean of MSSD and MSPD",
        reports
            .iter()
            .map(|(label, r)| {
                let curve = |error: DetectionError| {
                    r.errors
                        .iter()
                        .find(|e| e.error == error)
                        .map(|e| e.precision_recall.clone())
                        .unwrap_or_default()
                };
                let (mssd, mspd) = (curve(DetectionError::Mssd), curve(DetectionError::Mspd));
                let mean: Vec<f64> = mssd.iter().zip(&mspd).map(|(a, b)| (a + b) / 2.0).collect();
                (label.clone(), pr_points(&mean))
            })
            .collect(),
    )
}

fn pr_chart(title: &str, lines: Vec<Line>) -> Chart {
    let mut c = chart(title, "recall", 1.0, lines);
    // 101 points a curve: a marker on each would hide the line.
    for s in &mut c.series {
        s.dots.clear();
    }
    c
}

fn chart(title: &str, x_label: &str, x_max: f64, lines: Vec<Line>) -> Chart {
    let series = lines
        .into_iter()
        .enumerate()
        .map(|(i, (label, mut xy))| {
            xy.sort_by(|a, b| a.0.total_cmp(&b.0));
            let dots: Vec<(f64, f64)> = xy.iter().map(|&(x, y)| (sx(x, x_max), sy(y))).collect();
            Series {
                label,
                points: dots
                    .iter()
                    .map(|(x, y)| format!("{x:.1},{y:.1}"))
                    .collect::<Vec<_>>()
                    .join(" "),
                dots,
                class: format!("series-{i}"),
            }
        })
        .collect();
    Chart {
        title: title.to_string(),
        x_label: x_label.to_string(),
        series,
        x_ticks: (0..=5)
            .map(|i| {
                let v = x_max * i as f64 / 5.0;
                Tick {
                    pos: sx(v, x_max),
                    label: trim(v),
                }
            })
            .collect(),
        y_ticks: (0..=5)
            .map(|i| {
                let v = i as f64 / 5.0;
                Tick {
                    pos: sy(v),
                    label: trim(v),
                }
            })
            .collect(),
        counts: Vec::new(),
        counts_note: String::new(),
    }
}

fn trim(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_map_into_the_plot_area() {
        let c = chart(
            "t",
            "theta",
            1.0,
            vec![
                ("tau = 20 mm".into(), vec![(1.0, 1.0), (0.0, 0.0)]),
                ("tau = 80 mm".into(), vec![(0.5, 0.5)]),
            ],
        );
        assert_eq!(c.series.len(), 2);
        assert_eq!(
            c.series[0].points,
            format!("{LEFT:.1},{BOTTOM:.1} {RIGHT:.1},{TOP:.1}")
        );
        assert_eq!(c.series[1].label, "tau = 80 mm");
        assert_eq!(c.y_ticks.last().map(|t| t.label.as_str()), Some("1"));
    }

    #[test]
    fn overlays_draw_one_line_per_method_on_a_shared_axis() {
        let report = |scale: f64| -> Report {
            let mut r: Report = serde_json::from_value(serde_json::json!({
                "evaluator_version": "0", "dataset": "d", "protocol": "bop19",
                "parameters": {"n_top": -1, "visib_gt_min": -1.0, "max_sym_disc_step": 0.01,
                    "main_tau": 20.0, "main_theta": 0.3, "errors": []},
                "estimates_count": 0, "estimates_evaluated": 0, "estimates_ignored": 0,
                "targets_without_estimate": 0, "warnings": [],
                "average_recalls": {}, "per_error_recall_per_threshold": {}
            }))
            .expect("a report");
            r.recall_vs_threshold = ["vsd", "mssd", "mspd"]
                .iter()
                .map(|e| evaluator::report::ThresholdCurve {
                    error: e.to_string(),
                    points: vec![(0.1 * scale, 0.2), (0.5 * scale, 0.9)],
                })
                .collect();
            r
        };
        let methods: Vec<(String, Report)> = (1..=3)
            .map(|i| (format!("m{i}"), report(i as f64)))
            .collect();
        let charts = overlays(&methods);
        assert_eq!(charts.len(), 3);
        for c in &charts {
            let labels: Vec<&str> = c.series.iter().map(|s| s.label.as_str()).collect();
            assert_eq!(labels, ["m1", "m2", "m3"]);
            // The widest curve reaches the right edge; the others stop short of it.
            assert!(
                c.series[2]
                    .points
                    .ends_with(&format!("{RIGHT:.1},{:.1}", sy(0.9)))
            );
            assert!(!c.series[0].points.contains(&format!("{RIGHT:.1},")));
        }
        assert!(overlays(&[]).is_empty());
    }
}
