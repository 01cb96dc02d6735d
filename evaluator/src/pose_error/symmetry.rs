//! Symmetry transformations of an object, discretised exactly as bop_toolkit's
//! `misc.get_symmetry_transformations` does, because MSSD and MSPD take the minimum over this
//! set and any other sampling changes the errors.

use crate::dataset::ModelInfo;
use crate::math::{Mat3, Pose, Vec3};

/// The identity, the discrete symmetries, and each of them combined with every step of each
/// continuous symmetry sampled so that the farthest point moves at most `max_sym_disc_step`
/// of the diameter between steps.
pub fn symmetry_transformations(info: &ModelInfo, max_sym_disc_step: f64) -> Vec<Pose> {
    let mut discrete = vec![Pose::identity()];
    for m in &info.symmetries_discrete {
        discrete.push(Pose::new(
            Mat3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]),
            Vec3::new(m[3], m[7], m[11]),
        ));
    }
    let mut continuous = Vec::new();
    for sym in &info.symmetries_continuous {
        let axis = Vec3::from(sym.axis);
        let offset = Vec3::from(sym.offset);
        let steps = (std::f64::consts::PI / max_sym_disc_step).ceil() as usize;
        let step = 2.0 * std::f64::consts::PI / steps as f64;
        for i in 0..steps {
            let r = rotation_about(i as f64 * step, &axis);
            continuous.push(Pose::new(r, -(r * offset) + offset));
        }
    }
    if continuous.is_empty() {
        return discrete;
    }
    discrete
        .iter()
        .flat_map(|d| continuous.iter().map(move |c| c.compose(d)))
        .collect()
}

/// Rotation by `angle` about `direction` (normalised here), with the same formula as the
/// `transformations` module bop_toolkit uses: cos I + (1 - cos) d dᵀ + sin [d]ₓ.
fn rotation_about(angle: f64, direction: &Vec3) -> Mat3 {
    let (sin, cos) = angle.sin_cos();
    let d = direction / direction.dot(direction).sqrt();
    let mut r = Mat3::from_diagonal_element(cos) + d * d.transpose() * (1.0 - cos);
    let s = d * sin;
    r += Mat3::new(0.0, -s.z, s.y, s.z, 0.0, -s.x, -s.y, s.x, 0.0);
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::ContinuousSymmetry;

    fn info(discrete: Vec<[f64; 16]>, continuous: Vec<ContinuousSymmetry>) -> ModelInfo {
        ModelInfo {
            diameter: 100.0,
            symmetries_discrete: discrete,
            symmetries_continuous: continuous,
        }
    }

    #[test]
    fn asymmetric_objects_have_only_the_identity() {
        let syms = symmetry_transformations(&info(vec![], vec![]), 0.01);
        assert_eq!(syms, vec![Pose::identity()]);
    }

    #[test]
    fn continuous_symmetry_is_sampled_at_315_steps_per_discrete_one() {
        let flip = [
            1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 90.0, 0.0, 0.0, 0.0, 1.0,
        ];
        let cont = ContinuousSymmetry {
            axis: [0.0, 0.0, 1.0],
            offset: [0.0, 0.0, 0.0],
        };
        let syms = symmetry_transformations(&info(vec![flip], vec![cont]), 0.01);
        assert_eq!(syms.len(), 2 * 315);
        assert_eq!(syms[0], Pose::identity());
        // Step 1 rotates by 2π/315 about z.
        let a = 2.0 * std::f64::consts::PI / 315.0;
        assert!((syms[1].r[(0, 0)] - a.cos()).abs() < 1e-15);
        assert!((syms[1].r[(1, 0)] - a.sin()).abs() < 1e-15);
        // The flip keeps its translation (the rotation about z does not move it).
        assert!((syms[315].t - Vec3::new(0.0, 0.0, 90.0)).norm() < 1e-12);
    }

    #[test]
    fn an_offset_axis_rotates_about_the_offset_point() {
        let cont = ContinuousSymmetry {
            axis: [0.0, 0.0, 2.0],
            offset: [10.0, 0.0, 0.0],
        };
        let syms = symmetry_transformations(&info(vec![], vec![cont]), 0.01);
        let half_turn = &syms[315 / 2 + 1]; // close to π
        let fixed = half_turn.transform(&crate::math::Pt3::new(10.0, 0.0, 5.0));
        assert!((fixed - Vec3::new(10.0, 0.0, 5.0)).norm() < 1e-9);
    }
}
