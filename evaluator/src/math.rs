//! Small geometric types shared by every module. Poses and intrinsics are `f64` like the
//! reference toolkit (numpy float64), so that errors agree to the last digits.

use nalgebra::{Matrix3, Point3, Vector3};

pub type Mat3 = Matrix3<f64>;
pub type Vec3 = Vector3<f64>;
pub type Pt3 = Point3<f64>;

/// A rigid transformation from model to camera coordinates: `x_c = r * x_m + t` (t in mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub r: Mat3,
    pub t: Vec3,
}

impl Pose {
    pub fn new(r: Mat3, t: Vec3) -> Self {
        Pose { r, t }
    }

    /// Builds a pose from a row-major 3x3 rotation and a translation, the layout of every BOP file.
    pub fn from_row_major(r: &[f64; 9], t: &[f64; 3]) -> Self {
        Pose {
            r: Mat3::from_row_slice(r),
            t: Vec3::new(t[0], t[1], t[2]),
        }
    }

    pub fn identity() -> Self {
        Pose {
            r: Mat3::identity(),
            t: Vec3::zeros(),
        }
    }

    #[inline]
    pub fn transform(&self, p: &Pt3) -> Vec3 {
        self.r * p.coords + self.t
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose {
            r: self.r * other.r,
            t: self.r * other.t + self.t,
        }
    }
}

/// Pinhole intrinsics of one image (`cam_K` of scene_camera.json), kept whole because MSPD
/// projects with the full matrix (skew included) while the renderer uses fx, fy, cx, cy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub k: Mat3,
}

impl Intrinsics {
    pub fn from_row_major(k: &[f64; 9]) -> Self {
        Intrinsics {
            k: Mat3::from_row_slice(k),
        }
    }
    pub fn fx(&self) -> f64 {
        self.k[(0, 0)]
    }
    pub fn fy(&self) -> f64 {
        self.k[(1, 1)]
    }
    pub fn cx(&self) -> f64 {
        self.k[(0, 2)]
    }
    pub fn cy(&self) -> f64 {
        self.k[(1, 2)]
    }
}
