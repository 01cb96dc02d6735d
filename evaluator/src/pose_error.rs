//! The pose error functions of the BOP benchmark, one file each, named after the paper's
//! quantities. Each is a pure function of poses, model points and (for VSD) depth maps.

pub mod add;
pub mod mspd;
pub mod mssd;
pub mod symmetry;
pub mod vsd;

pub use add::{add, adi, re, te};
pub use mspd::{mspd, mspd_fisheye};
pub use mssd::mssd;
pub use symmetry::symmetry_transformations;

use crate::math::{Pose, Vec3};

/// bop_toolkit skips MSSD, ADD and ADI (error = infinity) when the model's bounding spheres at
/// the two poses cannot touch: the centres are at least a diameter apart.
pub fn spheres_overlap(t_est: &Vec3, t_gt: &Vec3, diameter: f64) -> bool {
    (t_est - t_gt).norm() < diameter
}

/// bop_toolkit's approximate test of whether the image projections of the two bounding spheres
/// overlap; when they do not, VSD is 1 without rendering. Reproduced as is (including poses
/// behind the camera, for which it answers "no overlap"), since it decides the error.
pub fn sphere_projections_overlap(radius: f64, p1: &Vec3, p2: &Vec3) -> bool {
    if p1.z == 0.0 || p2.z == 0.0 {
        return false;
    }
    let (x1, y1) = (p1.x / p1.z, p1.y / p1.z);
    let (x2, y2) = (p2.x / p2.z, p2.y / p2.z);
    let dist = ((x1 - x2).powi(2) + (y1 - y2).powi(2)).sqrt();
    dist < radius * (1.0 / p1.z + 1.0 / p2.z)
}

/// `min over symmetries s of max over points i of sqrt(dist_sq(prepare(s), i))`, the shape of
/// MSSD and MSPD. A symmetry's points stop being visited once it cannot beat the best one, which
/// leaves the minimum unchanged.
fn min_over_symmetries<T>(
    syms: &[Pose],
    n_points: usize,
    prepare: impl Fn(&Pose) -> T,
    dist_sq: impl Fn(&T, usize) -> f64,
) -> f64 {
    let mut best_sq = f64::INFINITY;
    // The point that last decided a symmetry: neighbouring symmetries (the steps of a
    // continuous one) are decided by the same point, so it is visited first, and a symmetry that
    // cannot win usually stops at its first point. The maximum does not depend on the order.
    let mut first = 0;
    for sym in syms {
        let prepared = prepare(sym);
        let mut worst_sq = 0.0f64;
        let start = first;
        for i in (n_points > 0)
            .then_some(start)
            .into_iter()
            .chain(0..n_points)
        {
            let d = dist_sq(&prepared, i);
            if d > worst_sq {
                worst_sq = d;
                first = i;
                if worst_sq >= best_sq {
                    break;
                }
            }
        }
        best_sq = best_sq.min(worst_sq);
    }
    best_sq.sqrt()
}
