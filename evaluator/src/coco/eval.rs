//! COCOeval for boxes (`bbox`) and masks (`segm`), following `pycocotools/cocoeval.py` of the
//! fork bop_toolkit runs (MartinSmeyer/cocoapi) step by step, so that every AP and AR agrees
//! with it to the last bit:
//!
//! - the fork keeps the ground truth's `ignore` flag (stock pycocotools overwrites it with
//!   `iscrowd`): a detection matched to an ignored instance is neither a true nor a false
//!   positive;
//! - per image and category, detections are sorted by score with a stable sort (numpy's
//!   mergesort: ties keep file order) and cut to the largest max-detections (100); ground
//!   truth is sorted ignored-last, also stably; IoUs come from maskApi ([`super::rle`]);
//! - greedy matching per IoU threshold: each detection takes the best remaining instance at
//!   least as good as the threshold (a later instance with an equal IoU wins), and stops at
//!   the first ignored instance once it holds a regular one;
//! - the area ranges use the ground truth's `area` field and the detection's area (its box's
//!   `w * h` when the results have boxes, else its mask's pixels, as `loadRes` sets it);
//!   unmatched detections outside a range are ignored in it;
//! - accumulation over images in the order of their (merged) ids, detections of all images
//!   sorted stably by score, cumulative sums in float, precision `tp / (tp + fp + eps)` with
//!   numpy's `spacing(1)`, the precision envelope, 101 recall points by a left
//!   `searchsorted`, and the means of `summarize` with numpy's pairwise summation.
//!
//! Thresholds are made as `np.linspace` makes them (`start + i * step`, the last one set to
//! `stop`), so that `iouThr == .75` finds its threshold exactly as numpy does.

use rayon::prelude::*;

use super::gt::CocoGt;
use super::rle::{Rle, bbox_iou, rle_iou};
use crate::stats::mean;

/// numpy's `spacing(1)`.
const EPS: f64 = f64::EPSILON;

/// The largest of COCO's max-detections (per image and category).
pub const MAX_DETS: [usize; 3] = [1, 10, 100];

/// COCO's area ranges: all, small (< 32²), medium (< 96²), large; bounds inclusive.
pub const AREA_RANGES: [[f64; 2]; 4] =
    [[0.0, 1e10], [0.0, 1024.0], [1024.0, 9216.0], [9216.0, 1e10]];

/// What is compared: boxes or masks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IouType {
    Bbox,
    Segm,
}

impl IouType {
    pub fn as_str(self) -> &'static str {
        match self {
            IouType::Bbox => "bbox",
            IouType::Segm => "segm",
        }
    }
}

/// One detection to score.
#[derive(Clone, Debug)]
pub struct Detection<'a> {
    /// Index into [`CocoGt::images`].
    pub image: usize,
    pub category_id: i64,
    pub score: f64,
    /// What `loadRes` sets as the area (see the module documentation).
    pub area: f64,
    pub bbox: [f64; 4],
    pub mask: Option<&'a Rle>,
}

/// numpy's `linspace(start, stop, num)` (endpoint included), value for value.
pub fn linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    let div = (num - 1) as f64;
    let step = (stop - start) / div;
    let mut v: Vec<f64> = (0..num).map(|i| i as f64 * step + start).collect();
    if num > 1 {
        v[num - 1] = stop;
    }
    v
}

/// COCOeval's IoU thresholds, 0.50:0.05:0.95.
pub fn iou_thresholds() -> Vec<f64> {
    linspace(0.5, 0.95, 10)
}

/// COCOeval's recall points, 0:0.01:1.
pub fn recall_thresholds() -> Vec<f64> {
    linspace(0.0, 1.0, 101)
}

/// The accumulated precision and recall (COCOeval's `eval`): -1 where a category has no
/// regular ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulated {
    pub iou_thresholds: Vec<f64>,
    pub recall_thresholds: Vec<f64>,
    pub categories: Vec<i64>,
    /// `[T][R][K][A][M]`, C order.
    pub precision: Vec<f64>,
    /// `[T][K][A][M]`, C order.
    pub recall: Vec<f64>,
}

impl Accumulated {
    fn dims(&self) -> (usize, usize, usize, usize, usize) {
        (
            self.iou_thresholds.len(),
            self.recall_thresholds.len(),
            self.categories.len(),
            AREA_RANGES.len(),
            MAX_DETS.len(),
        )
    }

    pub fn precision_at(&self, t: usize, r: usize, k: usize, a: usize, m: usize) -> f64 {
        let (_, rn, kn, an, mn) = self.dims();
        self.precision[(((t * rn + r) * kn + k) * an + a) * mn + m]
    }

    pub fn recall_at(&self, t: usize, k: usize, a: usize, m: usize) -> f64 {
        let (_, _, kn, an, mn) = self.dims();
        self.recall[((t * kn + k) * an + a) * mn + m]
    }

    /// COCOeval's `summarize` for detection: AP, AP50, AP75, AP_small, AP_medium, AP_large,
    /// AR1, AR10, AR100, AR_small, AR_medium, AR_large.
    pub fn summarize(&self) -> [f64; 12] {
        [
            self.summary(true, None, 0, 2),
            self.summary(true, Some(0.5), 0, 2),
            self.summary(true, Some(0.75), 0, 2),
            self.summary(true, None, 1, 2),
            self.summary(true, None, 2, 2),
            self.summary(true, None, 3, 2),
            self.summary(false, None, 0, 0),
            self.summary(false, None, 0, 1),
            self.summary(false, None, 0, 2),
            self.summary(false, None, 1, 2),
            self.summary(false, None, 2, 2),
            self.summary(false, None, 3, 2),
        ]
    }

    /// One `_summarize`: the mean of the values above -1, or -1 when there is none.
    fn summary(&self, ap: bool, iou: Option<f64>, a: usize, m: usize) -> f64 {
        let (tn, rn, kn, _, _) = self.dims();
        let ts: Vec<usize> = (0..tn)
            .filter(|&t| iou.is_none_or(|v| self.iou_thresholds[t] == v))
            .collect();
        let mut values = Vec::new();
        for &t in &ts {
            if ap {
                for r in 0..rn {
                    for k in 0..kn {
                        values.push(self.precision_at(t, r, k, a, m));
                    }
                }
            } else {
                for k in 0..kn {
                    values.push(self.recall_at(t, k, a, m));
                }
            }
        }
        values.retain(|&v| v > -1.0);
        if values.is_empty() {
            -1.0
        } else {
            mean(&values)
        }
    }

    /// The precision at each recall point, area "all", 100 detections, averaged over the
    /// categories that have ground truth; at one IoU threshold, or averaged over all of them
    /// (`None`): the curves whose means are AP50, AP75 and AP. -1 where nothing is defined.
    pub fn precision_curve(&self, iou: Option<f64>) -> Vec<f64> {
        let (tn, rn, kn, _, _) = self.dims();
        (0..rn)
            .map(|r| {
                let mut values = Vec::new();
                for t in (0..tn).filter(|&t| iou.is_none_or(|v| self.iou_thresholds[t] == v)) {
                    for k in 0..kn {
                        values.push(self.precision_at(t, r, k, 0, 2));
                    }
                }
                values.retain(|&v| v > -1.0);
                if values.is_empty() {
                    -1.0
                } else {
                    mean(&values)
                }
            })
            .collect()
    }
}

/// The per-image, per-category, per-area-range result (COCOeval's `evaluateImg`).
struct ImageEval {
    /// Scores of the (at most 100) detections, best first.
    scores: Vec<f64>,
    /// `[T][D]`: the id of the matched ground truth, 0 for none (an id of 0 reads as none, as
    /// in COCOeval).
    matches: Vec<i64>,
    /// `[T][D]`.
    ignored: Vec<bool>,
    gt_ignored: Vec<bool>,
}

/// Runs COCOeval (`evaluate`, then `accumulate`) on the ground truth and the detections, the
/// detections in the toolkit's merged order (file order within an image). Also returns the
/// per-image evaluations the headline AP is accumulated from, for its bootstrap.
pub fn evaluate(
    gt: &CocoGt,
    detections: &[Detection<'_>],
    iou_type: IouType,
) -> (Accumulated, ImageEvals) {
    let iou_thrs = iou_thresholds();
    let rec_thrs = recall_thresholds();
    let categories = gt.categories.clone();
    let k_of = |c: i64| categories.binary_search(&c).ok();
    let (n_images, n_cats) = (gt.images.len(), categories.len());

    // Per (image, category): ground truth and detections in file order.
    let mut gts: Vec<Vec<usize>> = vec![Vec::new(); n_images * n_cats];
    for (i, a) in gt.annotations.iter().enumerate() {
        if let Some(k) = k_of(a.category_id) {
            gts[a.image * n_cats + k].push(i);
        }
    }
    let mut dts: Vec<Vec<usize>> = vec![Vec::new(); n_images * n_cats];
    for (i, d) in detections.iter().enumerate() {
        if let Some(k) = k_of(d.category_id) {
            dts[d.image * n_cats + k].push(i);
        }
    }

    // evalImgs[k][a][i], as COCOeval lays them out.
    let cells: Vec<[Option<ImageEval>; 4]> = (0..n_images * n_cats)
        .into_par_iter()
        .map(|cell| evaluate_cell(gt, detections, &gts[cell], &dts[cell], iou_type, &iou_thrs))
        .collect();

    let (tn, rn, an, mn) = (
        iou_thrs.len(),
        rec_thrs.len(),
        AREA_RANGES.len(),
        MAX_DETS.len(),
    );
    let blocks: Vec<(Vec<f64>, Vec<f64>)> = (0..n_cats * an)
        .into_par_iter()
        .map(|ka| {
            let (k, a) = (ka / an, ka % an);
            let evals: Vec<&ImageEval> = (0..n_images)
                .filter_map(|i| cells[i * n_cats + k][a].as_ref())
                .collect();
            // [M][T][R] precision and [M][T] recall of this category and area range.
            let mut precision = vec![-1.0; mn * tn * rn];
            let mut recall = vec![-1.0; mn * tn];
            for (m, &max_det) in MAX_DETS.iter().enumerate() {
                accumulate(&evals, max_det, tn, &rec_thrs, |t, r, v| {
                    precision[(m * tn + t) * rn + r] = v
                })
                .into_iter()
                .enumerate()
                .for_each(|(t, v)| {
                    if let Some(v) = v {
                        recall[m * tn + t] = v;
                    }
                });
            }
            (precision, recall)
        })
        .collect();

    let mut precision = vec![-1.0; tn * rn * n_cats * an * mn];
    let mut recall = vec![-1.0; tn * n_cats * an * mn];
    for (ka, (p, r)) in blocks.iter().enumerate() {
        let (k, a) = (ka / an, ka % an);
        for m in 0..mn {
            for t in 0..tn {
                recall[((t * n_cats + k) * an + a) * mn + m] = r[m * tn + t];
                for ri in 0..rn {
                    precision[(((t * rn + ri) * n_cats + k) * an + a) * mn + m] =
                        p[(m * tn + t) * rn + ri];
                }
            }
        }
    }
    let mut per_category: Vec<Vec<(usize, ImageEval)>> = (0..n_cats).map(|_| Vec::new()).collect();
    for (cell, [all, ..]) in cells.into_iter().enumerate() {
        if let Some(ev) = all {
            per_category[cell % n_cats].push((cell / n_cats, ev));
        }
    }
    let images = ImageEvals {
        images: n_images,
        iou_thresholds: tn,
        recall_thresholds: rec_thrs.clone(),
        categories: per_category
            .into_iter()
            .zip(&categories)
            .map(|(evals, &id)| CategoryEvals::new(id, evals))
            .collect(),
    };
    (
        Accumulated {
            iou_thresholds: iou_thrs,
            recall_thresholds: rec_thrs,
            categories,
            precision,
            recall,
        },
        images,
    )
}

/// What the headline AP (area "all", 100 detections) is accumulated from, per target image:
/// each image's evaluation per category, so that the AP can be computed again with the images
/// counted any number of times (the bootstrap of [`crate::coco::CocoEvaluation::bootstrap`]).
pub struct ImageEvals {
    images: usize,
    iou_thresholds: usize,
    recall_thresholds: Vec<f64>,
    categories: Vec<CategoryEvals>,
}

/// One category's image evaluations (in image order) and their detections in accumulation
/// order, as runs of one image's detections with one score.
struct CategoryEvals {
    category_id: i64,
    evals: Vec<(usize, ImageEval)>,
    /// `(index into evals, first detection, end)`.
    runs: Vec<(usize, usize, usize)>,
}

impl CategoryEvals {
    fn new(category_id: i64, evals: Vec<(usize, ImageEval)>) -> CategoryEvals {
        let refs: Vec<&ImageEval> = evals.iter().map(|(_, ev)| ev).collect();
        let mut runs: Vec<(usize, usize, usize)> = Vec::new();
        for (e, d) in sorted_detections(&refs, MAX_DETS[2]) {
            match runs.last_mut() {
                Some(run)
                    if run.0 == e && run.2 == d && refs[e].scores[d - 1] == refs[e].scores[d] =>
                {
                    run.2 = d + 1;
                }
                _ => runs.push((e, d, d + 1)),
            }
        }
        CategoryEvals {
            category_id,
            evals,
            runs,
        }
    }
}

/// What COCOeval counts in one image and category at IoU 0.5 (area "all", the 100 best
/// detections): the counts behind AP50, for reading two methods side by side image by image.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ImageOutcome {
    pub scene_id: u32,
    pub im_id: u32,
    pub category_id: i64,
    /// Ground-truth instances that are not ignored (e.g. under 10 % visible).
    pub instances: usize,
    /// Detections matched to one of them: the true positives.
    pub matched: usize,
    /// Detections matched to none (and not to an ignored instance either).
    pub false_positives: usize,
}

impl ImageOutcome {
    /// Instances no detection was matched to.
    pub fn missed(&self) -> usize {
        self.instances - self.matched
    }
}

impl ImageEvals {
    /// The target images.
    pub fn images(&self) -> usize {
        self.images
    }

    /// Per image (in the merged order) and category with ground truth or detections, what
    /// COCOeval counts at IoU 0.5; `gt` is the ground truth these were evaluated on.
    pub fn outcomes_at_50(&self, gt: &CocoGt) -> Vec<ImageOutcome> {
        let mut out: Vec<ImageOutcome> = self
            .categories
            .iter()
            .flat_map(|c| {
                c.evals.iter().map(|(i, ev)| {
                    let n = ev.scores.len();
                    // IoU 0.5 is the first threshold.
                    let counted = (0..n).filter(|&d| !ev.ignored[d]);
                    let matched = counted.clone().filter(|&d| ev.matches[d] != 0).count();
                    ImageOutcome {
                        scene_id: gt.images[*i].scene_id,
                        im_id: gt.images[*i].im_id,
                        category_id: c.category_id,
                        instances: ev.regular_instances(),
                        matched,
                        false_positives: counted.count() - matched,
                    }
                })
            })
            .collect();
        let position: std::collections::HashMap<(u32, u32), usize> = gt
            .images
            .iter()
            .enumerate()
            .map(|(i, im)| ((im.scene_id, im.im_id), i))
            .collect();
        out.sort_by_key(|o| (position[&(o.scene_id, o.im_id)], o.category_id));
        out
    }

    /// The AP with target image `i` counted `weights[i]` times, as COCOeval computes it on the
    /// ground truth and detections with each image repeated that often (the copies of an image
    /// next to each other in the image order): a stable sort by score puts tied detections of
    /// one image together, so each such run is repeated as a whole. With every weight 1, the
    /// report's AP to the last bit. -1 when no category has a regular instance.
    pub fn weighted_ap(&self, weights: &[u32]) -> f64 {
        let (tn, rn, kn) = (
            self.iou_thresholds,
            self.recall_thresholds.len(),
            self.categories.len(),
        );
        // [T][R][K], the order `summarize` takes them in.
        let mut precision = vec![-1.0; tn * rn * kn];
        let (mut rc, mut pr) = (Vec::new(), Vec::new());
        for (k, c) in self.categories.iter().enumerate() {
            let npig: usize = c
                .evals
                .iter()
                .map(|(i, ev)| weights[*i] as usize * ev.regular_instances())
                .sum();
            if npig == 0 {
                continue;
            }
            let mut order: Vec<(&ImageEval, usize)> = Vec::new();
            for &(e, d0, d1) in &c.runs {
                let (image, ev) = &c.evals[e];
                for _ in 0..weights[*image] {
                    order.extend((d0..d1).map(|d| (ev, d)));
                }
            }
            for t in 0..tn {
                precision_at_threshold(
                    &order,
                    t,
                    npig as f64,
                    &self.recall_thresholds,
                    (&mut rc, &mut pr),
                    |r, v| precision[(t * rn + r) * kn + k] = v,
                );
            }
        }
        precision.retain(|&v| v > -1.0);
        if precision.is_empty() {
            -1.0
        } else {
            mean(&precision)
        }
    }
}

/// Stable sort of indices by descending score (numpy's `argsort(-scores, kind='mergesort')`).
fn by_score(indices: &mut [usize], score: impl Fn(usize) -> f64) {
    indices.sort_by(|&a, &b| score(b).total_cmp(&score(a)));
}

/// The (image, detection) pairs of `evals`, at most `max_det` per image, concatenated in image
/// order and sorted stably by score: the order `accumulate` takes detections in.
fn sorted_detections(evals: &[&ImageEval], max_det: usize) -> Vec<(usize, usize)> {
    let dets: Vec<(usize, usize)> = evals
        .iter()
        .enumerate()
        .flat_map(|(e, ev)| (0..ev.scores.len().min(max_det)).map(move |d| (e, d)))
        .collect();
    let mut order: Vec<usize> = (0..dets.len()).collect();
    by_score(&mut order, |i| evals[dets[i].0].scores[dets[i].1]);
    order.into_iter().map(|i| dets[i]).collect()
}

/// `computeIoU` and `evaluateImg` of one image and category, for the four area ranges.
fn evaluate_cell(
    gt: &CocoGt,
    detections: &[Detection<'_>],
    gt_ids: &[usize],
    dt_ids: &[usize],
    iou_type: IouType,
    iou_thrs: &[f64],
) -> [Option<ImageEval>; 4] {
    if gt_ids.is_empty() && dt_ids.is_empty() {
        return [None, None, None, None];
    }
    let mut dt: Vec<usize> = dt_ids.to_vec();
    by_score(&mut dt, |i| detections[i].score);
    dt.truncate(MAX_DETS[2]);
    let g: Vec<&super::gt::GtAnnotation> = gt_ids.iter().map(|&i| &gt.annotations[i]).collect();
    let d: Vec<&Detection<'_>> = dt.iter().map(|&i| &detections[i]).collect();
    let (nd, ng) = (d.len(), g.len());

    // ious[d][g], ground truth in file order.
    let mut ious = vec![0.0; nd * ng];
    for (di, det) in d.iter().enumerate() {
        for (gi, ann) in g.iter().enumerate() {
            ious[di * ng + gi] = match iou_type {
                IouType::Bbox => bbox_iou(&det.bbox, &ann.bbox, ann.iscrowd),
                IouType::Segm => match (det.mask, &ann.segmentation) {
                    (Some(dm), Some(gm)) => rle_iou(dm, gm, ann.iscrowd),
                    _ => 0.0,
                },
            };
        }
    }

    let tn = iou_thrs.len();
    std::array::from_fn(|a| {
        let [lo, hi] = AREA_RANGES[a];
        let ignore: Vec<bool> = g
            .iter()
            .map(|ann| ann.ignore || ann.area < lo || ann.area > hi)
            .collect();
        let mut order: Vec<usize> = (0..ng).collect();
        order.sort_by_key(|&i| ignore[i]);
        let gt_ignored: Vec<bool> = order.iter().map(|&i| ignore[i]).collect();
        let iscrowd: Vec<bool> = order.iter().map(|&i| g[i].iscrowd).collect();
        let mut gt_matched = vec![false; tn * ng];
        let mut matches = vec![0i64; tn * nd];
        let mut ignored = vec![false; tn * nd];
        if nd > 0 && ng > 0 {
            for (t, &thr) in iou_thrs.iter().enumerate() {
                for di in 0..nd {
                    let mut best = thr.min(1.0 - 1e-10);
                    let mut m: Option<usize> = None;
                    for (gi, &og) in order.iter().enumerate() {
                        if gt_matched[t * ng + gi] && !iscrowd[gi] {
                            continue;
                        }
                        if let Some(mm) = m
                            && !gt_ignored[mm]
                            && gt_ignored[gi]
                        {
                            break;
                        }
                        let v = ious[di * ng + og];
                        if v < best {
                            continue;
                        }
                        best = v;
                        m = Some(gi);
                    }
                    if let Some(mm) = m {
                        ignored[t * nd + di] = gt_ignored[mm];
                        matches[t * nd + di] = g[order[mm]].merged_id;
                        gt_matched[t * ng + mm] = true;
                    }
                }
            }
        }
        for (di, det) in d.iter().enumerate() {
            if det.area < lo || det.area > hi {
                for t in 0..tn {
                    if matches[t * nd + di] == 0 {
                        ignored[t * nd + di] = true;
                    }
                }
            }
        }
        Some(ImageEval {
            scores: d.iter().map(|det| det.score).collect(),
            matches,
            ignored,
            gt_ignored,
        })
    })
}

impl ImageEval {
    /// Its ground truth that is not ignored.
    fn regular_instances(&self) -> usize {
        self.gt_ignored.iter().filter(|&&i| !i).count()
    }
}

/// `accumulate` for one category, area range and max-detections: sets the precision at each
/// (threshold, recall point) through `set` and returns the recall per threshold (`None` when
/// the category has no regular ground truth: it stays -1).
fn accumulate(
    evals: &[&ImageEval],
    max_det: usize,
    tn: usize,
    rec_thrs: &[f64],
    mut set: impl FnMut(usize, usize, f64),
) -> Vec<Option<f64>> {
    let npig = evals.iter().map(|e| e.regular_instances()).sum::<usize>();
    if npig == 0 {
        return vec![None; tn];
    }
    let order: Vec<(&ImageEval, usize)> = sorted_detections(evals, max_det)
        .into_iter()
        .map(|(e, d)| (evals[e], d))
        .collect();
    let (mut rc, mut pr) = (Vec::new(), Vec::new());
    (0..tn)
        .map(|t| {
            Some(precision_at_threshold(
                &order,
                t,
                npig as f64,
                rec_thrs,
                (&mut rc, &mut pr),
                |r, v| set(t, r, v),
            ))
        })
        .collect()
}

/// One IoU threshold `t` of `accumulate`, the detections taken in `order`: sets the precision
/// at each recall point through `set` and returns the recall reached. `scratch` holds the
/// recall and precision after each detection.
fn precision_at_threshold(
    order: &[(&ImageEval, usize)],
    t: usize,
    npig: f64,
    rec_thrs: &[f64],
    (rc, pr): (&mut Vec<f64>, &mut Vec<f64>),
    mut set: impl FnMut(usize, f64),
) -> f64 {
    let nd = order.len();
    rc.clear();
    pr.clear();
    let (mut tp, mut fp) = (0u64, 0u64);
    for &(ev, d) in order {
        let n = ev.scores.len();
        if !ev.ignored[t * n + d] {
            if ev.matches[t * n + d] != 0 {
                tp += 1;
            } else {
                fp += 1;
            }
        }
        let (tpf, fpf) = (tp as f64, fp as f64);
        rc.push(tpf / npig);
        pr.push(tpf / (fpf + tpf + EPS));
    }
    let recall = if nd > 0 { rc[nd - 1] } else { 0.0 };
    for i in (1..nd).rev() {
        if pr[i] > pr[i - 1] {
            pr[i - 1] = pr[i];
        }
    }
    for (r, &thr) in rec_thrs.iter().enumerate() {
        let pi = rc.partition_point(|&v| v < thr);
        // COCOeval stops at the first recall point beyond the last detection; the rest
        // keep 0.
        set(r, if pi < nd { pr[pi] } else { 0.0 });
    }
    recall
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_as_numpy_makes_them() {
        let t = iou_thresholds();
        assert_eq!(t.len(), 10);
        assert_eq!(t[0], 0.5);
        assert_eq!(t[5], 0.75);
        assert_eq!(t[9], 0.95);
        let r = recall_thresholds();
        assert_eq!(r.len(), 101);
        assert_eq!(r[100], 1.0);
    }
}
