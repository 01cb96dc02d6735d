//! Visible Surface Discrepancy (paper, eq. 1): the fraction of the union of the visible
//! surfaces at the estimated and the ground-truth pose where the two disagree by `tau` or more.
//!
//! Work is split by how often it can be shared: the test image's distance map once per image,
//! the ground-truth render and its visibility mask once per GT instance ([`GtView`]), and only
//! the estimate is rendered per evaluation. All taus are counted in the same pass.

use crate::dataset::{DepthImage, DepthRows};
use crate::math::Intrinsics;
use crate::prepared::file::DepthRegion;
use crate::render::DepthWindow;
use crate::visibility::{VisibMode, visible};

/// VSD's parameters apart from the taus' meaning, which `normalized_by_diameter` gives.
#[derive(Clone, Debug, PartialEq)]
pub struct VsdParams {
    /// Visibility tolerance in mm.
    pub delta: f64,
    /// Misalignment tolerances: mm, or fractions of the diameter when `normalized_by_diameter`.
    pub taus: Vec<f64>,
    pub normalized_by_diameter: bool,
    pub visib_mode: VisibMode,
}

/// Pixel geometry of one image: the factors that turn depth into distance from the camera
/// centre, `d = sqrt((x' d)² + (y' d)² + d²)` with `x' = (x - cx) / fx` at the integer pixel
/// position (bop_toolkit's `depth_im_to_dist_im_fast`, which unlike the renderer does not add 0.5).
#[derive(Clone, Debug)]
pub struct PixelRays {
    pub width: u32,
    pub height: u32,
    xs: Vec<f64>,
    ys: Vec<f64>,
}

impl PixelRays {
    pub fn new(k: &Intrinsics, width: u32, height: u32) -> Self {
        PixelRays {
            width,
            height,
            xs: (0..width).map(|x| (x as f64 - k.cx()) / k.fx()).collect(),
            ys: (0..height).map(|y| (y as f64 - k.cy()) / k.fy()).collect(),
        }
    }

    /// Distance from the camera centre of the surface point seen at pixel (x, y) at `depth` mm.
    #[inline]
    pub fn distance(&self, x: u32, y: u32, depth: f32) -> f64 {
        let d = depth as f64;
        let a = self.xs[x as usize] * d;
        let b = self.ys[y as usize] * d;
        (a * a + b * b + d * d).sqrt()
    }
}

/// The test image prepared for VSD: its depth, turned into distances only where a render
/// needs them (an object covers a few thousand of the image's pixels, and a whole distance map
/// cost more than all of an image's renders). It may hold only a rectangle
/// ([`TestImage::from_rows`], [`TestImage::from_region`]): one holding the renders of its image.
pub struct TestImage {
    pub rays: PixelRays,
    /// First column and row held.
    x0: u32,
    y0: u32,
    /// Columns held.
    cols: u32,
    depth: Vec<f32>,
}

impl TestImage {
    pub fn new(depth: DepthImage, k: &Intrinsics) -> Self {
        TestImage {
            rays: PixelRays::new(k, depth.width, depth.height),
            x0: 0,
            y0: 0,
            cols: depth.width,
            depth: depth.data,
        }
    }

    /// A test image of which only `depth`'s rows are known; every render compared with it
    /// must lie within them.
    pub fn from_rows(depth: DepthRows, k: &Intrinsics) -> Self {
        TestImage {
            rays: PixelRays::new(k, depth.width, depth.height),
            x0: 0,
            y0: depth.y0,
            cols: depth.width,
            depth: depth.data,
        }
    }

    /// A test image of which only `depth`'s region is known (and there only the tiles read):
    /// every render compared with it must lie within the tiles read.
    pub fn from_region(depth: DepthRegion, k: &Intrinsics) -> Self {
        TestImage {
            rays: PixelRays::new(k, depth.width, depth.height),
            x0: depth.x0,
            y0: depth.y0,
            cols: depth.cols,
            depth: depth.data,
        }
    }

    /// The measured depth of `len` pixels of row `y` from column `x`.
    #[inline]
    fn row(&self, y: u32, x: u32, len: usize) -> &[f32] {
        let start = ((y - self.y0) * self.cols + (x - self.x0)) as usize;
        &self.depth[start..start + len]
    }

    /// Distance of the measured surface at pixel (x, y), 0 where depth is missing.
    #[inline]
    fn at(&self, x: u32, y: u32) -> f64 {
        let d = self.depth[((y - self.y0) * self.cols + (x - self.x0)) as usize];
        self.rays.distance(x, y, d)
    }
}

/// A ground-truth instance rendered once and compared with every estimate of its object.
pub struct GtView {
    window: DepthWindow,
    /// Distance map of the render over `window` (0 = no surface).
    dist: Vec<f64>,
    /// Distance map of the test image over `window` where the render has a surface, 0
    /// elsewhere: there only an estimate covering the pixel needs it, and [`vsd`] computes it
    /// then (an object's window is often half empty, and most pixels of an image's windows are
    /// compared with one estimate, if any).
    test_dist: Vec<f64>,
    visib: Vec<bool>,
}

impl GtView {
    pub fn new(test: &TestImage, render: DepthWindow, params: &VsdParams) -> Self {
        let delta = params.delta as f32;
        let n = render.data.len();
        let (mut dist, mut test_dist, mut visib) = (vec![0.0; n], vec![0.0; n], vec![false; n]);
        let width = render.width as usize;
        if width == 0 {
            return GtView {
                window: render,
                dist,
                test_dist,
                visib,
            };
        }
        let x0 = render.x0;
        for (dy, depths) in render.data.chunks_exact(width).enumerate() {
            let y = render.y0 + dy as u32;
            let row = dy * width;
            let range = row..row + width;
            let measured = test.row(y, x0, width);
            let rows = dist[range.clone()]
                .iter_mut()
                .zip(&mut test_dist[range.clone()])
                .zip(&mut visib[range]);
            for (k, ((&depth, ((d, t), v)), &m)) in
                depths.iter().zip(rows).zip(measured).enumerate()
            {
                // A pixel without surface is at distance 0 (what `distance` gives for it too,
                // square root and all) and visible in no mode.
                if depth != 0.0 {
                    let x = x0 + k as u32;
                    *d = test.rays.distance(x, y, depth);
                    *t = test.rays.distance(x, y, m);
                    *v = visible(params.visib_mode, *t, *d, delta);
                }
            }
        }
        GtView {
            window: render,
            dist,
            test_dist,
            visib,
        }
    }
}

/// The columns `x0..x1` of a window, or none when `y` is not one of its rows.
#[inline]
fn columns_at(w: &DepthWindow, y: u32) -> std::ops::Range<u32> {
    if y >= w.y0 && y - w.y0 < w.height {
        w.x0..w.x0 + w.width
    } else {
        0..0
    }
}

/// VSD's pixel counts: the union and intersection of the visible surfaces, and per tau the
/// intersection pixels whose distances differ by at least tau.
struct Counts<'a> {
    params: &'a VsdParams,
    diameter: f64,
    union: usize,
    inter: usize,
    far: Vec<usize>,
}

impl Counts<'_> {
    #[inline]
    fn pixel(&mut self, d_gt: f64, visib_gt: bool, d_est: f64, visib_est: bool) {
        if !(visib_gt || visib_est) {
            return;
        }
        self.union += 1;
        if visib_gt && visib_est {
            self.inter += 1;
            let mut diff = (d_gt - d_est).abs();
            if self.params.normalized_by_diameter {
                diff /= self.diameter;
            }
            for (n, &tau) in self.far.iter_mut().zip(&self.params.taus) {
                if diff >= tau {
                    *n += 1;
                }
            }
        }
    }
}

/// VSD of the estimate rendered as `est` against `gt`, one error per tau of `params` written to
/// `out` (its length must equal the number of taus). An empty union gives 1 for every tau.
///
/// The pixels are visited row by row in three kinds of runs: the ground truth's alone (only its
/// visible pixels count), both windows, and the estimate's alone; no pixel asks which window
/// holds it.
pub fn vsd(
    test: &TestImage,
    gt: &GtView,
    est: &DepthWindow,
    diameter: f64,
    params: &VsdParams,
    out: &mut [f64],
) {
    debug_assert_eq!(out.len(), params.taus.len());
    let delta = params.delta as f32;
    let mode = params.visib_mode;
    let mut counts = Counts {
        params,
        diameter,
        union: 0,
        inter: 0,
        far: vec![0; params.taus.len()],
    };
    let gw = &gt.window;

    for dy in 0..gw.height {
        let y = gw.y0 + dy;
        let row = (dy * gw.width) as usize;
        let cols = columns_at(est, y);
        // The estimate's columns within the ground truth's, as offsets in its row.
        let from = cols.start.clamp(gw.x0, gw.x0 + gw.width) - gw.x0;
        let to = cols.end.clamp(gw.x0, gw.x0 + gw.width) - gw.x0;
        let (from, to) = (from.min(to) as usize, to as usize);
        // Without an estimate, a pixel is in the union where the ground truth is visible.
        let alone = gt.visib[row..row + from]
            .iter()
            .chain(&gt.visib[row + to..row + gw.width as usize]);
        counts.union += alone.filter(|&&v| v).count();
        if from == to {
            continue;
        }
        let est_start = ((y - est.y0) * est.width + (gw.x0 + from as u32 - est.x0)) as usize;
        let ests = &est.data[est_start..est_start + (to - from)];
        let (i0, i1) = (row + from, row + to);
        let gts = gw.data[i0..i1]
            .iter()
            .zip(&gt.dist[i0..i1])
            .zip(&gt.visib[i0..i1])
            .zip(&gt.test_dist[i0..i1]);
        for (k, (&depth_est, (((&depth_gt, &d_gt), &visib_gt), &t))) in
            ests.iter().zip(gts).enumerate()
        {
            if depth_est <= 0.0 {
                counts.pixel(d_gt, visib_gt, 0.0, false);
                continue;
            }
            let x = gw.x0 + (from + k) as u32;
            let d_est = test.rays.distance(x, y, depth_est);
            let d_test = if depth_gt == 0.0 { test.at(x, y) } else { t };
            let visib_est = visible(mode, d_test, d_est, delta) || visib_gt;
            counts.pixel(d_gt, visib_gt, d_est, visib_est);
        }
    }
    // Pixels the estimate covers outside the ground-truth window.
    for dy in 0..est.height {
        let y = est.y0 + dy;
        let row = (dy * est.width) as usize;
        let gt_cols = columns_at(gw, y);
        let (left, right) = if gt_cols.is_empty() {
            (est.x0 + est.width, est.x0 + est.width)
        } else {
            let end = est.x0 + est.width;
            (
                gt_cols.start.clamp(est.x0, end),
                gt_cols.end.clamp(est.x0, end),
            )
        };
        for x in (est.x0..left).chain(right..est.x0 + est.width) {
            let depth_est = est.data[row + (x - est.x0) as usize];
            if depth_est <= 0.0 {
                continue;
            }
            let d_est = test.rays.distance(x, y, depth_est);
            let visib_est = visible(mode, test.at(x, y), d_est, delta);
            counts.pixel(0.0, false, d_est, visib_est);
        }
    }

    let Counts {
        union, inter, far, ..
    } = counts;
    if union == 0 {
        out.fill(1.0);
        return;
    }
    let comp = union - inter;
    for (o, n) in out.iter_mut().zip(far) {
        *o = (n + comp) as f64 / union as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Pose, Vec3};
    use crate::mesh::Mesh;
    use crate::render::Renderer;

    fn k() -> Intrinsics {
        Intrinsics::from_row_major(&[572.4, 0.0, 325.3, 0.0, 573.6, 242.0, 0.0, 0.0, 1.0])
    }

    /// A scene whose measured depth is the cube itself at `gt` (a perfect sensor).
    fn scene(mesh: &Mesh, gt: &Pose) -> (TestImage, DepthWindow) {
        let render = Renderer::new().render(mesh, &mesh.bbox_corners(), gt, &k(), 640, 480);
        let mut depth = DepthImage {
            width: 640,
            height: 480,
            data: vec![0.0; 640 * 480],
        };
        for y in 0..480 {
            for x in 0..640 {
                depth.data[(y * 640 + x) as usize] = render.at(x, y);
            }
        }
        (TestImage::new(depth, &k()), render)
    }

    fn params(taus: Vec<f64>) -> VsdParams {
        VsdParams {
            delta: 15.0,
            taus,
            normalized_by_diameter: false,
            visib_mode: VisibMode::Bop19,
        }
    }

    fn error(mesh: &Mesh, gt: &Pose, est: &Pose, p: &VsdParams) -> Vec<f64> {
        let (test, gt_render) = scene(mesh, gt);
        let view = GtView::new(&test, gt_render, p);
        let est = Renderer::new().render(mesh, &mesh.bbox_corners(), est, &k(), 640, 480);
        let mut out = vec![0.0; p.taus.len()];
        vsd(&test, &view, &est, 103.9, p, &mut out);
        out
    }

    fn gt_pose() -> Pose {
        let r = nalgebra::Rotation3::from_euler_angles(0.4, -0.3, 0.2).into_inner();
        Pose::new(r, Vec3::new(10.0, -5.0, 800.0))
    }

    #[test]
    fn the_gt_pose_gives_zero() {
        let mesh = crate::mesh::test_cube(30.0);
        let gt = gt_pose();
        assert_eq!(error(&mesh, &gt, &gt, &params(vec![20.0])), vec![0.0]);
    }

    #[test]
    fn a_30mm_shift_along_the_optical_axis_fails_tau_20_and_passes_tau_80() {
        let mesh = crate::mesh::test_cube(30.0);
        let gt = gt_pose();
        let est = Pose::new(gt.r, gt.t * (830.0 / 800.0));
        let e = error(&mesh, &gt, &est, &params(vec![20.0, 80.0]));
        // Everything is still seen (bop19 counts the far estimate as visible where the GT is),
        // but every pixel is ~30 mm off: above tau 20, below tau 80.
        assert!(e[0] > 0.9, "{e:?}");
        assert!(e[1] < 0.1, "{e:?}");
    }

    #[test]
    fn a_symmetric_flip_of_a_cube_is_correct() {
        let mesh = crate::mesh::test_cube(30.0);
        let gt = gt_pose();
        let quarter = nalgebra::Rotation3::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2)
            .into_inner();
        let est = gt.compose(&Pose::new(quarter, Vec3::zeros()));
        let e = error(&mesh, &gt, &est, &params(vec![20.0]));
        assert!(e[0] < 0.01, "{e:?}");
    }

    #[test]
    fn disjoint_silhouettes_give_one() {
        let mesh = crate::mesh::test_cube(30.0);
        let gt = gt_pose();
        let est = Pose::new(gt.r, gt.t + Vec3::new(200.0, 0.0, 0.0));
        assert_eq!(error(&mesh, &gt, &est, &params(vec![20.0])), vec![1.0]);
    }

    #[test]
    fn distance_follows_the_integer_pixel_convention() {
        let rays = PixelRays::new(&k(), 640, 480);
        // At the principal point's integer neighbour the ray is almost the optical axis.
        let d = rays.distance(325, 242, 1000.0);
        let expected = 1000.0 * (((325.0 - 325.3) / 572.4f64).powi(2) + 1.0).sqrt();
        assert!((d - expected).abs() < 1e-9);
    }
}
