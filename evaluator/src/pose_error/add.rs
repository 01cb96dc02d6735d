//! The classic errors: ADD (average distance of corresponding model points), ADI or ADD-S
//! (average distance to the nearest model point, for symmetric objects), and the rotation and
//! translation errors RE and TE.

use kiddo::dist::SquaredEuclidean;
use kiddo::{Eytzinger, FlatVec, KdTree};

use crate::math::{Mat3, Pose, Pt3, Vec3};

type PointTree = KdTree<f64, u32, Eytzinger, FlatVec<f64, u32, 3, 32>, 3, 32>;

/// Mean of `|P_est x - P_gt x|` over the model points, in mm.
pub fn add(est: &Pose, gt: &Pose, pts: &[Pt3]) -> f64 {
    if pts.is_empty() {
        return 0.0;
    }
    let sum: f64 = pts
        .iter()
        .map(|p| (est.transform(p) - gt.transform(p)).norm())
        .sum();
    sum / pts.len() as f64
}

/// Mean over the ground-truth points of the distance to the nearest estimated point, in mm.
/// Nearest neighbours come from a k-d tree over the estimated points: O(n log n), not O(n²).
pub fn adi(est: &Pose, gt: &Pose, pts: &[Pt3]) -> f64 {
    if pts.is_empty() {
        return 0.0;
    }
    let est_pts: Vec<[f64; 3]> = pts.iter().map(|p| est.transform(p).into()).collect();
    let tree = PointTree::new_from_slice(&est_pts).expect("a non-empty point set builds a tree");
    let sum: f64 = pts
        .iter()
        .map(|p| {
            let q: [f64; 3] = gt.transform(p).into();
            tree.query(&q)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute()
                .distance
                .sqrt()
        })
        .sum();
    sum / pts.len() as f64
}

/// Rotation error in degrees: the angle of `R_est R_gt⁻¹`.
pub fn re(r_est: &Mat3, r_gt: &Mat3) -> f64 {
    let inv = r_gt.try_inverse().unwrap_or_else(|| r_gt.transpose());
    let cos = (0.5 * ((r_est * inv).trace() - 1.0)).clamp(-1.0, 1.0);
    cos.acos().to_degrees()
}

/// Translation error in mm.
pub fn te(t_est: &Vec3, t_gt: &Vec3) -> f64 {
    (t_gt - t_est).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts() -> Vec<Pt3> {
        // An asymmetric L of points.
        vec![
            Pt3::new(0.0, 0.0, 0.0),
            Pt3::new(40.0, 0.0, 0.0),
            Pt3::new(0.0, 20.0, 0.0),
            Pt3::new(0.0, 0.0, 10.0),
        ]
    }

    #[test]
    fn gt_pose_gives_zero() {
        let gt = Pose::new(Mat3::identity(), Vec3::new(1.0, 2.0, 700.0));
        assert_eq!(add(&gt, &gt, &pts()), 0.0);
        assert_eq!(adi(&gt, &gt, &pts()), 0.0);
        assert_eq!(re(&gt.r, &gt.r), 0.0);
        assert_eq!(te(&gt.t, &gt.t), 0.0);
    }

    #[test]
    fn a_symmetric_flip_is_wrong_under_add_and_correct_under_adi() {
        // A square of points is symmetric under a half-turn about z.
        let square = [
            Pt3::new(-10.0, -10.0, 0.0),
            Pt3::new(10.0, -10.0, 0.0),
            Pt3::new(10.0, 10.0, 0.0),
            Pt3::new(-10.0, 10.0, 0.0),
        ];
        let gt = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 500.0));
        let half_turn = Mat3::from_diagonal(&Vec3::new(-1.0, -1.0, 1.0));
        let est = Pose::new(half_turn, gt.t);
        assert!((add(&est, &gt, &square) - 800.0f64.sqrt()).abs() < 1e-12);
        assert!(adi(&est, &gt, &square) < 1e-12);
        assert!((re(&est.r, &gt.r) - 180.0).abs() < 1e-9);
    }

    #[test]
    fn shifts_give_their_length() {
        let gt = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 500.0));
        let est = Pose::new(gt.r, gt.t + Vec3::new(0.0, 0.0, 30.0));
        assert!((add(&est, &gt, &pts()) - 30.0).abs() < 1e-12);
        assert!((te(&est.t, &gt.t) - 30.0).abs() < 1e-12);
    }
}
