//! The fisheye cameras of HOT3D (Meta's Aria glasses and Quest 3 headset): `cam_model` in
//! `scene_camera_*.json` with the `CameraModelType.FISHEYE624` projection instead of `cam_K`.
//!
//! bop_toolkit projects these (for MSPD) with the Hand Tracking Toolkit's `OVR624CameraModel`:
//! an arctan projection, 6 radial, 2 tangential and 4 thin-prism coefficients, then focal length
//! and principal point. The same steps are done here in the same order, so that the projected
//! pixels agree with the toolkit's (checked against values computed with it, in
//! `tests/fixtures/fisheye/`).

use serde::Deserialize;

use crate::math::{Intrinsics, Vec3};

/// The `projection_model_type` of HOT3D's fisheye cameras.
pub const FISHEYE624: &str = "CameraModelType.FISHEYE624";

/// One fisheye camera: `(fx, fy)`, `(cx, cy)` and the twelve distortion coefficients
/// `k1..k6, p1, p2, s1..s4`, window coordinates with pixel centres on integers (OpenCV's
/// convention, as the toolkit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fisheye624 {
    pub f: (f64, f64),
    pub c: (f64, f64),
    pub coeffs: [f64; 12],
}

/// `cam_model` as HOT3D writes it.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct RawCamModel {
    pub projection_model_type: String,
    pub projection_params: Vec<f64>,
}

impl Fisheye624 {
    pub(crate) fn from_cam_model(raw: &RawCamModel) -> Result<Self, String> {
        Self::from_projection(&raw.projection_model_type, &raw.projection_params)
    }

    /// Reads `cam_model`'s type and parameters: 15 (Aria: one focal length `f, cx, cy`) or 16
    /// (`fx, fy, cx, cy`), then the twelve coefficients, as the toolkit's
    /// `create_camera_model` reads them.
    pub fn from_projection(model_type: &str, p: &[f64]) -> Result<Self, String> {
        if model_type != FISHEYE624 {
            return Err(format!(
                "projection_model_type `{model_type}` is not supported (expected \
                 {FISHEYE624}, or cam_K for a pinhole camera)"
            ));
        }
        let (f, c, rest) = match p.len() {
            15 => ((p[0], p[0]), (p[1], p[2]), &p[3..]),
            16 => ((p[0], p[1]), (p[2], p[3]), &p[4..]),
            n => {
                return Err(format!(
                    "projection_params: expected 15 (f, cx, cy and 12 coefficients) or 16 (fx, \
                     fy, cx, cy and 12 coefficients) numbers, found {n}"
                ));
            }
        };
        let coeffs: [f64; 12] = rest
            .try_into()
            .map_err(|_| "projection_params: expected 12 coefficients".to_string())?;
        if p.iter().any(|v| !v.is_finite()) {
            return Err("projection_params: every number must be finite".into());
        }
        Ok(Fisheye624 { f, c, coeffs })
    }

    /// The pinhole camera with the same focal length and principal point, for what can only
    /// use a pinhole (the renderer): it is exact only near the image centre.
    pub fn pinhole_part(&self) -> Intrinsics {
        let (fx, fy) = self.f;
        let (cx, cy) = self.c;
        Intrinsics::from_row_major(&[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0])
    }

    /// A point in camera coordinates (mm) to window coordinates (px): the toolkit's
    /// `eye_to_window`.
    pub fn project(&self, v: &Vec3) -> [f64; 2] {
        // Arctan projection: |uv| is the angle from the optical axis.
        let (x, y, z) = (v.x, v.y, v.z);
        let r = (x * x + y * y).sqrt();
        let s = r.atan2(z) / r.max(2f64.powi(-128));
        let (px, py) = (x * s, y * s);

        let [k1, k2, k3, k4, k5, k6, p1, p2, s1, s2, s3, s4] = self.coeffs;
        let r2 = (px * px + py * py).clamp(
            -(std::f64::consts::PI.powi(2)),
            std::f64::consts::PI.powi(2),
        );
        let r4 = r2 * r2;
        let r6 = r2 * r4;
        let r8 = r4 * r4;
        let r10 = r4 * r6;
        let r12 = r6 * r6;
        let radial = 1.0 + k1 * r2 + k2 * r4 + k3 * r6 + k4 * r8 + k5 * r10 + k6 * r12;
        let (ux, uy) = (px * radial, py * radial);

        let x2 = ux * ux;
        let y2 = uy * uy;
        let xy = ux * uy;
        let r2 = x2 + y2;
        let mut qx = ux + (2.0 * p2 * xy + p1 * (r2 + 2.0 * x2));
        let mut qy = uy + (2.0 * p1 * xy + p2 * (r2 + 2.0 * y2));
        let r4 = r2 * r2;
        qx += s1 * r2 + s2 * r4;
        qy += s3 * r2 + s4 * r4;

        [qx * self.f.0 + self.c.0, qy * self.f.1 + self.c.1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(params: Vec<f64>) -> RawCamModel {
        RawCamModel {
            projection_model_type: FISHEYE624.into(),
            projection_params: params,
        }
    }

    #[test]
    fn without_distortion_the_angle_from_the_axis_is_the_radius() {
        let mut params = vec![100.0, 320.0, 240.0];
        params.extend([0.0; 12]);
        let cam = Fisheye624::from_cam_model(&raw(params)).unwrap();
        assert_eq!(cam.project(&Vec3::new(0.0, 0.0, 5.0)), [320.0, 240.0]);
        // 45 degrees off the axis: pi / 4 focal lengths from the centre.
        let [u, v] = cam.project(&Vec3::new(3.0, 0.0, 3.0));
        assert!((u - (320.0 + 100.0 * std::f64::consts::FRAC_PI_4)).abs() < 1e-12);
        assert_eq!(v, 240.0);
    }

    #[test]
    fn bad_cam_models_are_explained() {
        let msg = Fisheye624::from_cam_model(&raw(vec![1.0; 14])).unwrap_err();
        assert!(msg.contains("expected 15"), "{msg}");
        let mut other = raw(vec![1.0; 16]);
        other.projection_model_type = "Rational".into();
        let msg = Fisheye624::from_cam_model(&other).unwrap_err();
        assert!(msg.contains("`Rational` is not supported"), "{msg}");
        let mut nan = vec![1.0; 16];
        nan[5] = f64::NAN;
        assert!(Fisheye624::from_cam_model(&raw(nan)).is_err());
    }
}
