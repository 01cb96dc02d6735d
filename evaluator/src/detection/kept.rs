//! The estimates BOP'24 scores: at most N per image, the best-scored over all objects (the
//! method does not know which objects are present, so it may spread its guesses), and the
//! time per image read from those only, as bop_toolkit's `load_bop_results` and
//! `check_consistent_timings` do in `eval_bop24_pose.py`.

use std::cmp::Ordering;
use std::collections::HashMap;

use crate::results::Results;
use crate::stats;

/// The kept estimates, as indices into [`Results::estimates`].
pub struct Kept {
    /// Grouped by image (in order of the image's first line in the file), each group in
    /// decreasing score, ties in file order: the order bop_toolkit goes on with.
    pub order: Vec<usize>,
    /// Estimates left out because their image had more than the cap.
    pub beyond_cap: usize,
}

/// The best `cap` estimates of each image.
pub fn keep(results: &Results, cap: usize) -> Kept {
    let mut slots: HashMap<(u32, u32), usize> = HashMap::new();
    let mut images: Vec<Vec<usize>> = Vec::new();
    for (i, e) in results.estimates.iter().enumerate() {
        let slot = *slots.entry((e.scene_id, e.im_id)).or_insert_with(|| {
            images.push(Vec::new());
            images.len() - 1
        });
        images[slot].push(i);
    }
    let mut order = Vec::with_capacity(results.estimates.len().min(images.len() * cap));
    let mut beyond_cap = 0;
    for mut image in images {
        // A stable sort, as Python's `sorted(..., reverse=True)`: ties keep file order.
        image.sort_by(|&a, &b| {
            let (a, b) = (&results.estimates[a], &results.estimates[b]);
            b.score.partial_cmp(&a.score).unwrap_or(Ordering::Equal)
        });
        beyond_cap += image.len().saturating_sub(cap);
        image.truncate(cap);
        order.extend(image);
    }
    Kept { order, beyond_cap }
}

/// `bop24_average_time_per_image`: the mean over images of the first time among the kept
/// estimates, summed in the order of the images; `None` (the toolkit's -1) when a kept
/// estimate gives no time.
///
/// The file's times already agree within bop_toolkit's tolerance on every line of an image
/// (the result parser refuses them otherwise); which line gives an image's time still matters
/// within that tolerance, so it is the toolkit's: the best-scored one.
pub fn average_time_per_image(results: &Results, kept: &Kept) -> Option<f64> {
    let mut seen = HashMap::new();
    let mut times = Vec::new();
    for &i in &kept.order {
        let e = &results.estimates[i];
        if e.time < 0.0 {
            return None;
        }
        seen.entry((e.scene_id, e.im_id)).or_insert_with(|| {
            times.push(e.time);
        });
    }
    (!times.is_empty()).then(|| stats::mean(&times))
}
