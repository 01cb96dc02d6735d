//! Recall curves as server-rendered SVG (the paper's Fig. 5): the geometry is computed here and
//! the template only places it, so pages need no JavaScript and no plotting crate (plotters'
//! defaults need fontconfig).

use evaluator::protocol::ProtocolName;

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
}

fn sx(x: f64, max: f64) -> f64 {
    LEFT + (RIGHT - LEFT) * (x / max).clamp(0.0, 1.0)
}

fn sy(y: f64) -> f64 {
    BOTTOM - (BOTTOM - TOP) * y.clamp(0.0, 1.0)
}

/// Charts of one score from its stored curve points `(curve, series, x, y)`.
pub fn charts(protocol: ProtocolName, points: &[(String, f64, f64, f64)]) -> Vec<Chart> {
    let mut out = Vec::new();
    let curves: &[(&str, &str, &str)] = match protocol {
        ProtocolName::Eccv18 => &[
            (
                "recall_vs_theta",
                "Recall vs threshold of correctness",
                "theta",
            ),
            (
                "recall_vs_visib",
                "Recall vs visible fraction of the target",
                "visible fraction",
            ),
        ],
        ProtocolName::Bop19 => &[
            (
                "recall_vs_th_vsd",
                "VSD recall vs threshold (mean over taus)",
                "theta",
            ),
            (
                "recall_vs_th_mssd",
                "MSSD recall vs threshold",
                "threshold (x diameter)",
            ),
            (
                "recall_vs_th_mspd",
                "MSPD recall vs threshold",
                "threshold (px)",
            ),
        ],
    };
    for &(curve, title, x_label) in curves {
        let pts: Vec<&(String, f64, f64, f64)> = points.iter().filter(|p| p.0 == curve).collect();
        if pts.is_empty() {
            continue;
        }
        let x_max = match curve {
            "recall_vs_visib" | "recall_vs_theta" => 1.0,
            _ => pts.iter().map(|p| p.2).fold(0.0, f64::max).max(1e-9),
        };
        let mut series_keys: Vec<f64> = pts.iter().map(|p| p.1).collect();
        series_keys.sort_by(|a, b| a.total_cmp(b));
        series_keys.dedup();
        let series = series_keys
            .iter()
            .enumerate()
            .map(|(i, &key)| {
                let mut xy: Vec<(f64, f64)> = pts
                    .iter()
                    .filter(|p| p.1 == key)
                    // Visibility bins are plotted at their centres.
                    .map(|p| {
                        (
                            if curve == "recall_vs_visib" {
                                p.2 + 0.05
                            } else {
                                p.2
                            },
                            p.3,
                        )
                    })
                    .collect();
                xy.sort_by(|a, b| a.0.total_cmp(&b.0));
                let dots: Vec<(f64, f64)> =
                    xy.iter().map(|&(x, y)| (sx(x, x_max), sy(y))).collect();
                Series {
                    label: if curve == "recall_vs_theta" {
                        format!("tau = {key} mm")
                    } else {
                        "recall".to_string()
                    },
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
        out.push(Chart {
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
        });
    }
    out
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
        let pts = vec![
            ("recall_vs_theta".to_string(), 20.0, 0.0, 0.0),
            ("recall_vs_theta".to_string(), 20.0, 1.0, 1.0),
            ("recall_vs_theta".to_string(), 80.0, 0.5, 0.5),
        ];
        let charts = charts(ProtocolName::Eccv18, &pts);
        assert_eq!(charts.len(), 1);
        let c = &charts[0];
        assert_eq!(c.series.len(), 2);
        assert_eq!(
            c.series[0].points,
            format!("{LEFT:.1},{BOTTOM:.1} {RIGHT:.1},{TOP:.1}")
        );
        assert_eq!(c.series[1].label, "tau = 80 mm");
        assert_eq!(c.y_ticks.last().map(|t| t.label.as_str()), Some("1"));
    }
}
