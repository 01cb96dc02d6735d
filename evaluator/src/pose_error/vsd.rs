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
    /// Distance map of the test image over `window`.
    test_dist: Vec<f64>,
    visib: Vec<bool>,
}

impl GtView {
    pub fn new(test: &TestImage, render: DepthWindow, params: &VsdParams) -> Self {
        let delta = params.delta as f32;
        let n = render.data.len();
        let (mut dist, mut test_dist, mut visib) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for dy in 0..render.height {
            let y = render.y0 + dy;
            for dx in 0..render.width {
                let x = render.x0 + dx;
                // A pixel without surface is at distance 0 (what `distance` gives for it too,
                // square root and all); the window's corners around an object are often half
                // of it.
                let depth = render.data[(dy * render.width + dx) as usize];
                let d = if depth == 0.0 {
                    0.0
                } else {
                    test.rays.distance(x, y, depth)
                };
                let t = test.at(x, y);
                visib.push(visible(params.visib_mode, t, d, delta));
                dist.push(d);
                test_dist.push(t);
            }
        }
        GtView {
            window: render,
            dist,
            test_dist,
            visib,
        }
    }

    #[inline]
    fn contains(&self, x: u32, y: u32) -> bool {
        let w = &self.window;
        x >= w.x0 && y >= w.y0 && x - w.x0 < w.width && y - w.y0 < w.height
    }
}

/// VSD of the estimate rendered as `est` against `gt`, one error per tau of `params` written to
/// `out` (its length must equal the number of taus). An empty union gives 1 for every tau.
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
    let mut union = 0usize;
    let mut inter = 0usize;
    // Per tau, the intersection pixels whose distances differ by at least tau.
    let mut far = vec![0usize; params.taus.len()];
    let mut count_pixel = |d_gt: f64, visib_gt: bool, d_est: f64, visib_est: bool| {
        if !(visib_gt || visib_est) {
            return;
        }
        union += 1;
        if visib_gt && visib_est {
            inter += 1;
            let mut diff = (d_gt - d_est).abs();
            if params.normalized_by_diameter {
                diff /= diameter;
            }
            for (n, &tau) in far.iter_mut().zip(&params.taus) {
                if diff >= tau {
                    *n += 1;
                }
            }
        }
    };

    // Pixels of the ground-truth window, with the estimate where it covers them.
    let gw = &gt.window;
    for dy in 0..gw.height {
        let y = gw.y0 + dy;
        for dx in 0..gw.width {
            let x = gw.x0 + dx;
            let i = (dy * gw.width + dx) as usize;
            let (d_gt, visib_gt) = (gt.dist[i], gt.visib[i]);
            let depth_est = est.at(x, y);
            if depth_est <= 0.0 {
                count_pixel(d_gt, visib_gt, 0.0, false);
                continue;
            }
            let d_est = test.rays.distance(x, y, depth_est);
            let visib_est = visible(params.visib_mode, gt.test_dist[i], d_est, delta) || visib_gt;
            count_pixel(d_gt, visib_gt, d_est, visib_est);
        }
    }
    // Pixels the estimate covers outside the ground-truth window.
    for dy in 0..est.height {
        let y = est.y0 + dy;
        for dx in 0..est.width {
            let x = est.x0 + dx;
            if gt.contains(x, y) {
                continue;
            }
            let depth_est = est.data[(dy * est.width + dx) as usize];
            if depth_est <= 0.0 {
                continue;
            }
            let d_est = test.rays.distance(x, y, depth_est);
            let visib_est = visible(params.visib_mode, test.at(x, y), d_est, delta);
            count_pixel(0.0, false, d_est, visib_est);
        }
    }

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
