//! Bootstrap 95 % confidence intervals of the headline score: the dataset's target images are
//! resampled with replacement, and each replicate's score is computed from the resampled
//! images' target and true-positive counts exactly as the score itself is defined (eccv18: the
//! recall, true positives over targets summed over the images; bop19: the mean over VSD, MSSD
//! and MSPD of the mean over their (tau,) threshold settings of those recalls). The interval is
//! the 2.5th and 97.5th percentile of the replicates.
//!
//! An interval must be reproducible: the same result file on the same dataset gives the same
//! bounds to the last bit, on any machine, with any version of the dependencies. The random
//! numbers therefore come from SplitMix64 (Steele, Lea and Flood, 2014) written out here rather
//! than from a crate, whose generator's sequence may change with an upgrade. SplitMix64's state
//! advances by a constant, so replicate `b` starts `b * images` draws into the stream without
//! drawing the ones before: replicates run in parallel and still read one fixed sequence.
//!
//! The seed is a function of the dataset's name only ([`dataset_seed`]): every method's
//! replicate `b` on a dataset resamples the same images (paired, like for like), while
//! different datasets resample independently, so that replicate-wise means over datasets give
//! an interval of the average over datasets.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::stats::{mean, recall};

/// Replicates the service draws for every score.
pub const REPLICATES: usize = 1000;

/// What the headline score sums, per target image, in the order the scores are computed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageCounts {
    /// Per image, its targets (the same for every error and threshold).
    pub(crate) targets: Vec<u32>,
    /// Per group the headline averages (one error type), per member (a column and threshold,
    /// in the order the report averages them), per image, its true positives.
    pub(crate) groups: Vec<Vec<Vec<u32>>>,
}

impl ImageCounts {
    /// The target images.
    pub fn images(&self) -> usize {
        self.targets.len()
    }

    /// The headline score with image `i` counted `weights[i]` times: with every weight 1, the
    /// report's own headline, to the last bit. `None` for a protocol without a headline here.
    pub fn weighted_score(&self, weights: &[u32]) -> Option<f64> {
        if self.groups.is_empty() {
            return None;
        }
        let dot = |counts: &[u32]| -> usize {
            counts
                .iter()
                .zip(weights)
                .map(|(&c, &w)| c as usize * w as usize)
                .sum()
        };
        let targets = dot(&self.targets);
        let group_means: Vec<f64> = self
            .groups
            .iter()
            .map(|members| {
                let recalls: Vec<f64> = members
                    .iter()
                    .map(|tps| recall(dot(tps), targets))
                    .collect();
                mean(&recalls)
            })
            .collect();
        Some(mean(&group_means))
    }
}

/// The replicates of one score and how they were drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct Bootstrap {
    pub seed: u64,
    /// Replicate `b`'s score, in order.
    pub replicates: Vec<f64>,
}

/// What a report records of its bootstrap: enough to draw the replicates again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootstrapSummary {
    pub seed: u64,
    pub replicates: usize,
    /// The 2.5th and 97.5th percentiles of the replicates.
    pub ci95: [f64; 2],
}

impl Bootstrap {
    pub fn ci95(&self) -> [f64; 2] {
        interval95(&self.replicates)
    }

    pub fn summary(&self) -> BootstrapSummary {
        BootstrapSummary {
            seed: self.seed,
            replicates: self.replicates.len(),
            ci95: self.ci95(),
        }
    }
}

/// `replicates` bootstrap replicates of the headline score; `None` when there is no target
/// image or no headline.
pub fn bootstrap(counts: &ImageCounts, seed: u64, replicates: usize) -> Option<Bootstrap> {
    if counts.groups.is_empty() {
        return None;
    }
    resample(counts.images(), seed, replicates, |w| {
        counts.weighted_score(w)
    })
}

/// `replicates` bootstrap replicates of a score over `images` target images, `score` giving
/// it with image `i` counted `weights[i]` times: the one resampling every score shares (the
/// 6D headlines here, the 2D tasks' AP in the `coco` module), so that replicate `b` of any
/// score on a dataset draws the same images. `None` when there is no image or no score.
pub fn resample(
    images: usize,
    seed: u64,
    replicates: usize,
    score: impl Fn(&[u32]) -> Option<f64> + Sync,
) -> Option<Bootstrap> {
    let n = images;
    if n == 0 {
        return None;
    }
    let scores = (0..replicates)
        .into_par_iter()
        .map(|b| {
            let mut rng = SplitMix64::at(seed, (b as u64).wrapping_mul(n as u64));
            let mut weights = vec![0u32; n];
            for _ in 0..n {
                weights[rng.below(n)] += 1;
            }
            score(&weights)
        })
        .collect::<Option<Vec<f64>>>()?;
    Some(Bootstrap {
        seed,
        replicates: scores,
    })
}

/// The seed of a dataset's bootstrap: FNV-1a of its name (a fixed, documented function, so
/// the seed never changes either).
pub fn dataset_seed(dataset: &str) -> u64 {
    dataset.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The percentile interval `[2.5 %, 97.5 %]` of `values`, with numpy's default (linear)
/// interpolation between order statistics. NaN bounds for no values.
pub fn interval95(values: &[f64]) -> [f64; 2] {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    [percentile(&sorted, 0.025), percentile(&sorted, 0.975)]
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let Some(last) = sorted.len().checked_sub(1) else {
        return f64::NAN;
    };
    let h = q * last as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(last);
    let t = h - lo as f64;
    let (a, b) = (sorted[lo], sorted[hi]);
    // Never outside its two neighbours, whatever the rounding.
    (a + (b - a) * t).clamp(a, b)
}

/// SplitMix64: a 64-bit state advanced by a fixed odd constant, each output a bijective mix of
/// the state.
struct SplitMix64 {
    state: u64,
}

const GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

impl SplitMix64 {
    /// The generator seeded with `seed`, `skip` outputs on.
    fn at(seed: u64, skip: u64) -> Self {
        SplitMix64 {
            state: seed.wrapping_add(skip.wrapping_mul(GAMMA)),
        }
    }

    fn next(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GAMMA);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A draw in `0..n` by multiply-and-shift (Lemire): its bias, below n / 2^64, is
    /// negligible for any number of images.
    fn below(&mut self, n: usize) -> usize {
        ((u128::from(self.next()) * n as u128) >> 64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_gives_its_published_sequence() {
        // The reference outputs of SplitMix64 seeded with 1234567 (Vigna's splitmix64.c).
        let mut rng = SplitMix64::at(1_234_567, 0);
        let first: Vec<u64> = (0..3).map(|_| rng.next()).collect();
        assert_eq!(
            first,
            [
                6457827717110365317,
                3203168211198807973,
                9817491932198370423
            ]
        );
        // Skipping ahead lands where drawing would.
        let mut skipped = SplitMix64::at(1_234_567, 2);
        assert_eq!(skipped.next(), first[2]);
    }

    fn counts() -> ImageCounts {
        ImageCounts {
            targets: vec![2, 3, 1, 4, 2],
            groups: vec![
                vec![vec![1, 3, 0, 2, 2], vec![0, 1, 0, 1, 1]],
                vec![vec![2, 3, 1, 4, 1]],
            ],
        }
    }

    #[test]
    fn unit_weights_give_the_score() {
        let c = counts();
        let expected = mean(&[mean(&[8.0 / 12.0, 3.0 / 12.0]), 11.0 / 12.0]);
        assert_eq!(c.weighted_score(&[1; 5]), Some(expected));
        // Image 3 twice, image 0 never.
        let w = [0, 1, 1, 2, 1];
        let expected = mean(&[mean(&[9.0 / 14.0, 4.0 / 14.0]), 13.0 / 14.0]);
        assert_eq!(c.weighted_score(&w), Some(expected));
    }

    #[test]
    fn replicates_are_reproducible_and_seed_dependent() {
        let c = counts();
        let a = bootstrap(&c, 7, 200).expect("replicates");
        let b = bootstrap(&c, 7, 200).expect("replicates");
        assert_eq!(a, b);
        assert_eq!(a.replicates.len(), 200);
        assert_ne!(bootstrap(&c, 8, 200), Some(a.clone()));
        let [lo, hi] = a.ci95();
        assert!(lo <= hi);
        assert!(bootstrap(&ImageCounts::default(), 7, 10).is_none());
    }

    #[test]
    fn percentiles_interpolate_as_numpy_does() {
        let v: Vec<f64> = (0..=100).map(f64::from).collect();
        assert_eq!(interval95(&v), [2.5, 97.5]);
        assert_eq!(interval95(&[3.0]), [3.0, 3.0]);
        assert!(interval95(&[])[0].is_nan());
    }

    #[test]
    fn dataset_seeds_are_fnv1a() {
        assert_eq!(dataset_seed(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(dataset_seed("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
