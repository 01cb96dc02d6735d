//! CPU depth rendering of a mesh at a pose, following the conventions of bop_toolkit's
//! OpenGL renderer so that silhouettes agree with it pixel for pixel (up to samples lying
//! exactly on a triangle edge, where float32 GPU arithmetic decides differently).
//!
//! Written by hand because it is the core of the product: no crate reproduces those conventions.
//! - Pixel (i, j) is sampled at image coordinates (i + 0.5, j + 0.5), where `u = fx X/Z + cx`.
//! - The depth of a sample is the perspective-correct interpolation of camera-space Z across the
//!   triangle (what the OpenGL depth buffer holds once linearised), nearest surface wins.
//! - Near and far planes are the min and max camera-space Z of the model's bounding-box
//!   corners at that pose; a sample whose window depth rounds to 1.0 in the 24-bit depth
//!   buffer is background, and a box reaching to or behind the camera renders nothing (OpenGL
//!   clips everything when the near plane is not in front of the camera).
//! - Faces are not culled.
//!
//! Only the object's screen bounding box is rasterised, into a [`DepthWindow`]; the rest of the
//! image is implicitly 0.

use crate::math::{Intrinsics, Pose, Vec3};
use crate::mesh::Mesh;

/// A rectangle of a depth image (mm, 0 = no surface) holding everything one object covers.
#[derive(Clone, Debug, Default)]
pub struct DepthWindow {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl DepthWindow {
    pub fn empty() -> Self {
        Self::default()
    }

    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// Depth at image pixel (x, y); 0 outside the window.
    #[inline]
    pub fn at(&self, x: u32, y: u32) -> f32 {
        if x < self.x0 || y < self.y0 {
            return 0.0;
        }
        let (dx, dy) = (x - self.x0, y - self.y0);
        if dx >= self.width || dy >= self.height {
            return 0.0;
        }
        self.data[(dy * self.width + dx) as usize]
    }

    /// Pixels with a surface.
    pub fn count_nonzero(&self) -> usize {
        self.data.iter().filter(|&&d| d > 0.0).count()
    }
}

/// Reusable buffers, so rendering thousands of poses allocates once per thread.
#[derive(Default)]
pub struct Renderer {
    cam: Vec<Vec3>,
    screen: Vec<[f64; 2]>,
    zbuf: Vec<f64>,
}

/// The 24-bit depth buffer stores window depth in [0, 1]; values within half a step of 1.0
/// become 1.0, which the reference reads as background.
const FAR_CUTOFF: f64 = 1.0 - 1.0 / ((1u64 << 25) as f64);

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `mesh` at `pose` seen by a camera with intrinsics `k` into an image of
    /// `width` x `height` pixels, returning only the covered window.
    pub fn render(
        &mut self,
        mesh: &Mesh,
        bbox_corners: &[crate::math::Pt3; 8],
        pose: &Pose,
        k: &Intrinsics,
        width: u32,
        height: u32,
    ) -> DepthWindow {
        let (near, far) = clip_planes(bbox_corners, pose);
        let usable = near.is_finite() && far.is_finite() && near > 0.0 && far > near;
        if !usable {
            return DepthWindow::empty();
        }
        let (fx, fy, cx, cy) = (k.fx(), k.fy(), k.cx(), k.cy());

        self.cam.clear();
        self.screen.clear();
        let (mut umin, mut umax, mut vmin, mut vmax) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for v in &mesh.vertices {
            let p = pose.transform(v);
            let u = fx * p.x / p.z + cx;
            let w = fy * p.y / p.z + cy;
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(w);
            vmax = vmax.max(w);
            self.cam.push(p);
            self.screen.push([u, w]);
        }
        // Pixels whose sample point (i + 0.5) lies in [min, max].
        let Some((x0, x1)) = pixel_span(umin, umax, width) else {
            return DepthWindow::empty();
        };
        let Some((y0, y1)) = pixel_span(vmin, vmax, height) else {
            return DepthWindow::empty();
        };
        let (ww, wh) = (x1 - x0 + 1, y1 - y0 + 1);
        self.zbuf.clear();
        self.zbuf.resize((ww * wh) as usize, f64::INFINITY);

        let inv_near = 1.0 / near;
        let inv_range = 1.0 / (inv_near - 1.0 / far);
        for tri in &mesh.triangles {
            let [a, b, c] = tri.map(|i| i as usize);
            let (pa, pb, pc) = (self.screen[a], self.screen[b], self.screen[c]);
            let area = edge(pa, pb, pc);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            let inv_area = 1.0 / area;
            let (iza, izb, izc) = (
                1.0 / self.cam[a].z,
                1.0 / self.cam[b].z,
                1.0 / self.cam[c].z,
            );
            let tu0 = pa[0].min(pb[0]).min(pc[0]);
            let tu1 = pa[0].max(pb[0]).max(pc[0]);
            let tv0 = pa[1].min(pb[1]).min(pc[1]);
            let tv1 = pa[1].max(pb[1]).max(pc[1]);
            let Some((tx0, tx1)) = pixel_span(tu0, tu1, width) else {
                continue;
            };
            let Some((ty0, ty1)) = pixel_span(tv0, tv1, height) else {
                continue;
            };
            for y in ty0..=ty1 {
                let sy = y as f64 + 0.5;
                let row = ((y - y0) * ww) as usize;
                for x in tx0..=tx1 {
                    let s = [x as f64 + 0.5, sy];
                    // Barycentric weights, made positive for either winding by the area's sign.
                    let wa = edge(pb, pc, s) * inv_area;
                    let wb = edge(pc, pa, s) * inv_area;
                    let wc = edge(pa, pb, s) * inv_area;
                    if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                        continue;
                    }
                    let inv_z = wa * iza + wb * izb + wc * izc;
                    let window_depth = (inv_near - inv_z) * inv_range;
                    // No near test: every vertex lies at or beyond the near plane, so only
                    // rounding could put a sample in front of it, and the surface is there.
                    if window_depth >= FAR_CUTOFF || window_depth.is_nan() {
                        continue;
                    }
                    let z = 1.0 / inv_z;
                    let slot = &mut self.zbuf[row + (x - x0) as usize];
                    if z < *slot {
                        *slot = z;
                    }
                }
            }
        }
        DepthWindow {
            x0,
            y0,
            width: ww,
            height: wh,
            data: self
                .zbuf
                .iter()
                .map(|&z| if z.is_finite() { z as f32 } else { 0.0 })
                .collect(),
        }
    }
}

/// Near and far clipping planes of the reference renderer: the extreme camera-space Z of the
/// model's bounding-box corners.
pub fn clip_planes(corners: &[crate::math::Pt3; 8], pose: &Pose) -> (f64, f64) {
    let row = pose.r.row(2);
    corners
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(n, f), c| {
            let z = row[0] * c.x + row[1] * c.y + row[2] * c.z + pose.t.z;
            (n.min(z), f.max(z))
        })
}

/// Twice the signed area of (a, b, c).
#[inline(always)]
fn edge(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// The pixels `i` in `[0, size)` whose sample point `i + 0.5` lies in `[lo, hi]`.
fn pixel_span(lo: f64, hi: f64, size: u32) -> Option<(u32, u32)> {
    if lo.is_nan() || hi.is_nan() || lo > hi || size == 0 {
        return None;
    }
    let first = (lo - 0.5).ceil().max(0.0);
    let last = (hi - 0.5).floor().min(size as f64 - 1.0);
    (first <= last).then_some((first as u32, last as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Mat3, Pt3};

    fn quad(half: f64) -> Mesh {
        Mesh {
            vertices: vec![
                Pt3::new(-half, -half, 0.0),
                Pt3::new(half, -half, 0.0),
                Pt3::new(half, half, 0.0),
                Pt3::new(-half, half, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    fn camera() -> Intrinsics {
        Intrinsics::from_row_major(&[500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0])
    }

    fn render(mesh: &Mesh, pose: &Pose) -> DepthWindow {
        let corners = mesh.bbox_corners();
        Renderer::new().render(mesh, &corners, pose, &camera(), 640, 480)
    }

    #[test]
    fn a_cube_facing_the_camera_covers_the_pixels_whose_centres_its_face_contains() {
        // The front face at z = 950 spans u in 320 ± 500 * 50 / 950 = [293.68, 346.32]:
        // the pixels whose centres i + 0.5 lie inside are 294..=345.
        let pose = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 1000.0));
        let d = render(&crate::mesh::test_cube(50.0), &pose);
        assert_eq!((d.x0, d.width), (294, 52));
        assert_eq!((d.y0, d.height), (214, 52));
        assert_eq!(d.count_nonzero(), 52 * 52);
        assert!((d.at(320, 240) as f64 - 950.0).abs() < 1e-3);
        assert_eq!(d.at(293, 240), 0.0);
    }

    #[test]
    fn a_flat_model_has_no_depth_range_and_renders_nothing() {
        let pose = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 1000.0));
        assert!(render(&quad(50.0), &pose).is_empty());
    }

    #[test]
    fn depth_is_perspective_correct_on_a_tilted_plane() {
        let rot = nalgebra::Rotation3::from_euler_angles(0.0, 0.5, 0.0).into_inner();
        let pose = Pose::new(rot, Vec3::new(0.0, 0.0, 800.0));
        let d = render(&quad(60.0), &pose);
        let k = camera();
        // Analytic depth of the plane through t with normal R e_z along the ray of each sample.
        let n = rot.column(2).into_owned();
        for (x, y) in [(300u32, 240u32), (330, 250), (310, 230)] {
            let ray = Vec3::new(
                (x as f64 + 0.5 - k.cx()) / k.fx(),
                (y as f64 + 0.5 - k.cy()) / k.fy(),
                1.0,
            );
            let z = n.dot(&pose.t) / n.dot(&ray);
            assert!((d.at(x, y) as f64 - z).abs() < 1e-3, "{x},{y}");
        }
    }

    #[test]
    fn an_object_crossing_the_camera_plane_renders_nothing() {
        let pose = Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 20.0));
        let tilt = nalgebra::Rotation3::from_euler_angles(1.2, 0.0, 0.0).into_inner();
        let d = render(&quad(50.0), &Pose::new(tilt, pose.t));
        assert!(d.is_empty());
        let behind = Pose::new(tilt, Vec3::new(0.0, 0.0, -500.0));
        assert!(render(&quad(50.0), &behind).is_empty());
    }

    #[test]
    fn off_screen_objects_render_nothing() {
        let pose = Pose::new(Mat3::identity(), Vec3::new(5000.0, 0.0, 1000.0));
        assert!(render(&quad(50.0), &pose).is_empty());
    }

    #[test]
    fn pixel_span_uses_pixel_centres() {
        assert_eq!(pixel_span(325.3, 330.0, 640), Some((325, 329)));
        assert_eq!(pixel_span(325.6, 325.9, 640), None);
        assert_eq!(pixel_span(-10.0, 2.0, 640), Some((0, 1)));
        assert_eq!(pixel_span(630.0, 900.0, 640), Some((630, 639)));
    }
}
