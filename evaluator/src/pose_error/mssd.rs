//! Maximum Symmetry-Aware Surface Distance (BOP'19): the largest 3D displacement of a model
//! point, minimised over the object's symmetries.

use crate::math::{Pose, Pt3, Vec3};

/// `min over s of max over x of |P_est x - P_gt s x|` in mm. `syms` must contain the identity.
/// `scratch` holds the estimated points between calls (one buffer per thread).
pub fn mssd(est: &Pose, gt: &Pose, pts: &[Pt3], syms: &[Pose], scratch: &mut Vec<Vec3>) -> f64 {
    scratch.clear();
    scratch.extend(pts.iter().map(|p| est.transform(p)));
    super::min_over_symmetries(
        syms,
        pts.len(),
        |sym| gt.compose(sym),
        |g, i| (scratch[i] - g.transform(&pts[i])).norm_squared(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Mat3;

    fn cube_pts() -> Vec<Pt3> {
        let mut v = Vec::new();
        for x in [-10.0, 10.0] {
            for y in [-10.0, 10.0] {
                for z in [-10.0, 10.0] {
                    v.push(Pt3::new(x, y, z));
                }
            }
        }
        v
    }

    #[test]
    fn gt_pose_gives_zero_and_a_shift_gives_its_length() {
        let gt = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 500.0));
        let pts = cube_pts();
        let syms = [Pose::identity()];
        let mut s = Vec::new();
        assert_eq!(mssd(&gt, &gt, &pts, &syms, &mut s), 0.0);
        let shifted = Pose::new(gt.r, gt.t + Vec3::new(0.0, 0.0, 30.0));
        assert!((mssd(&shifted, &gt, &pts, &syms, &mut s) - 30.0).abs() < 1e-12);
    }

    #[test]
    fn a_declared_symmetry_makes_the_flip_correct() {
        let gt = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 500.0));
        let flip = Pose::new(
            Mat3::from_diagonal(&Vec3::new(-1.0, -1.0, 1.0)),
            Vec3::zeros(),
        );
        let est = gt.compose(&flip);
        let pts = cube_pts();
        let mut s = Vec::new();
        let without = mssd(&est, &gt, &pts, &[Pose::identity()], &mut s);
        // Every corner moves by (2x, 2y, 0).
        assert!((without - 2.0 * 200.0f64.sqrt()).abs() < 1e-9);
        let with = mssd(&est, &gt, &pts, &[Pose::identity(), flip], &mut s);
        assert!(with < 1e-12);
    }
}
