//! Maximum Symmetry-Aware Projection Distance (BOP'19): the largest 2D displacement (pixels) of
//! a projected model point, minimised over the object's symmetries. Suited to RGB-only methods,
//! which cannot see errors along the optical axis.

use crate::fisheye::Fisheye624;
use crate::math::{Intrinsics, Mat3, Pose, Pt3, Vec3};

/// `min over s of max over x of |proj(P_est x) - proj(P_gt s x)|` in pixels, projecting with
/// the full camera matrix like bop_toolkit's `project_pts` (`P = K [R|t]`).
pub fn mspd(
    est: &Pose,
    gt: &Pose,
    k: &Intrinsics,
    pts: &[Pt3],
    syms: &[Pose],
    scratch: &mut Vec<[f64; 2]>,
) -> f64 {
    let (pr, pt) = projection(k, est);
    scratch.clear();
    scratch.extend(pts.iter().map(|p| project(&pr, &pt, p)));
    super::min_over_symmetries(
        syms,
        pts.len(),
        |sym| projection(k, &gt.compose(sym)),
        |(r, t), i| {
            let (e, g) = (scratch[i], project(r, t, &pts[i]));
            (e[0] - g[0]).powi(2) + (e[1] - g[1]).powi(2)
        },
    )
}

/// MSPD for a fisheye camera (HOT3D), as bop_toolkit's `pose_error_htt.mspd`: the points are
/// moved by each pose, then projected with the camera model.
pub fn mspd_fisheye(
    est: &Pose,
    gt: &Pose,
    cam: &Fisheye624,
    pts: &[Pt3],
    syms: &[Pose],
    scratch: &mut Vec<[f64; 2]>,
) -> f64 {
    scratch.clear();
    scratch.extend(pts.iter().map(|p| cam.project(&est.transform(p))));
    super::min_over_symmetries(
        syms,
        pts.len(),
        |sym| gt.compose(sym),
        |pose, i| {
            let (e, g) = (scratch[i], cam.project(&pose.transform(&pts[i])));
            (e[0] - g[0]).powi(2) + (e[1] - g[1]).powi(2)
        },
    )
}

fn projection(k: &Intrinsics, pose: &Pose) -> (Mat3, Vec3) {
    (k.k * pose.r, k.k * pose.t)
}

#[inline]
fn project(r: &Mat3, t: &Vec3, p: &Pt3) -> [f64; 2] {
    let h = r * p.coords + t;
    [h.x / h.z, h.y / h.z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shift_along_the_optical_axis_is_nearly_invisible_but_a_lateral_one_is_not() {
        let k = Intrinsics::from_row_major(&[500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]);
        let gt = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 1000.0));
        let pts = [Pt3::new(0.0, 0.0, 0.0), Pt3::new(10.0, 0.0, 0.0)];
        let syms = [Pose::identity()];
        let mut s = Vec::new();
        assert_eq!(mspd(&gt, &gt, &k, &pts, &syms, &mut s), 0.0);
        let lateral = Pose::new(gt.r, gt.t + Vec3::new(2.0, 0.0, 0.0));
        assert!((mspd(&lateral, &gt, &k, &pts, &syms, &mut s) - 1.0).abs() < 1e-12);
        let depth = Pose::new(gt.r, gt.t + Vec3::new(0.0, 0.0, 30.0));
        // The offset point moves from 5.0 px to 10 * 500 / 1030 px from the centre.
        let e = mspd(&depth, &gt, &k, &pts, &syms, &mut s);
        assert!((e - (5.0 - 5000.0 / 1030.0)).abs() < 1e-12);
    }
}
