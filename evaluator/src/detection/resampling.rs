//! Bootstrap replicates of `bop24_mAP`, drawn over the target images as every other score's
//! are ([`crate::bootstrap::resample`]: the same seed draws the same images, so a method's
//! replicate `b` on a dataset is paired with every other method's). A replicate counts image
//! `i` `weights[i]` times: its counted instances that many times over, and each of its ranked
//! estimates that many times in a row where the estimate stands in its object's ranking. The
//! ranking itself (scores, the toolkit's tie order) and every match stay as evaluated, since a
//! copy of an image is matched as the image was. With every weight 1 a replicate is the
//! report's `bop24_mAP` to the last bit.
//!
//! Only MSSD and MSPD are kept: `bop24_mAP` is their mean, the millimetre MSSD is a side key.

use super::ap;
use crate::stats;

/// What a replicate re-weights, per object with a counted instance, in the order the toolkit
/// averages objects (their ids as strings).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageOutcomes {
    pub(super) images: usize,
    pub(super) objects: Vec<ObjectOutcomes>,
}

#[derive(Clone, Debug, PartialEq)]
pub(super) struct ObjectOutcomes {
    /// The images holding counted instances, and how many each holds.
    pub(super) counted: Vec<(u32, u32)>,
    /// For MSSD then MSPD, per threshold, the ranked (image, true positive) of the object's
    /// estimates, the ignored ones left out.
    pub(super) ranked: [Vec<Vec<(u32, bool)>>; 2],
}

impl ImageOutcomes {
    /// The target images.
    pub fn images(&self) -> usize {
        self.images
    }

    /// `bop24_mAP` with image `i` counted `weights[i]` times; `None` when the replicate holds
    /// no counted instance (its mAP is undefined).
    pub fn weighted_map(&self, weights: &[u32]) -> Option<f64> {
        let mut maps = [0.0; 2];
        for (e, map) in maps.iter_mut().enumerate() {
            let mut aps = Vec::with_capacity(self.objects.len());
            for object in &self.objects {
                let instances: usize = object
                    .counted
                    .iter()
                    .map(|&(image, n)| n as usize * weights[image as usize] as usize)
                    .sum();
                if instances == 0 {
                    continue;
                }
                let per_threshold: Vec<f64> = object.ranked[e]
                    .iter()
                    .map(|ranked| {
                        ap::average_precision(&ap::weighted_precision(ranked, weights, instances))
                    })
                    .collect();
                aps.push(stats::mean(&per_threshold));
            }
            if aps.is_empty() {
                return None;
            }
            *map = stats::mean(&aps);
        }
        Some(stats::mean(&maps))
    }
}
