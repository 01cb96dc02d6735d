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
        ray_distance(self.xs[x as usize], self.ys[y as usize], depth)
    }

    /// The distances of `depths`, pixels of row `y` from column `x`, into `out`: a loop without
    /// branches, which the compiler runs on several pixels at once.
    #[inline(always)]
    fn distances(&self, x: u32, y: u32, depths: &[f32], out: &mut [f64]) {
        let xs = &self.xs[x as usize..x as usize + depths.len()];
        let y = self.ys[y as usize];
        for ((o, &xr), &depth) in out.iter_mut().zip(xs).zip(depths) {
            *o = ray_distance(xr, y, depth);
        }
    }
}

/// `depth` (0 = none, giving 0) turned into distance along the ray `(x, y, 1)`.
#[inline(always)]
fn ray_distance(x: f64, y: f64, depth: f32) -> f64 {
    let d = depth as f64;
    let a = x * d;
    let b = y * d;
    (a * a + b * b + d * d).sqrt()
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
    /// Row by row without branches (the distances of pixels without surface are computed too,
    /// and are 0): a loop the compiler runs on several pixels at once, faster than skipping them.
    pub fn new(test: &TestImage, render: DepthWindow, params: &VsdParams) -> Self {
        let n = render.data.len();
        let mut view = GtView {
            window: render,
            dist: vec![0.0; n],
            test_dist: vec![0.0; n],
            visib: vec![false; n],
        };
        gt_view_maps(test, &mut view, params);
        view
    }
}

/// The maps of [`GtView::new`], built also for AVX2 (see `render::draw`): with it the square
/// roots run four at once instead of two, and each is the same IEEE operation.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn gt_view_maps(test: &TestImage, view: &mut GtView, params: &VsdParams) {
    let delta = params.delta as f32;
    let render = &view.window;
    let width = render.width as usize;
    if width == 0 {
        return;
    }
    for (dy, depths) in render.data.chunks_exact(width).enumerate() {
        let y = render.y0 + dy as u32;
        let row = dy * width..(dy + 1) * width;
        let (d, t) = (
            &mut view.dist[row.clone()],
            &mut view.test_dist[row.clone()],
        );
        test.rays.distances(render.x0, y, depths, d);
        test.rays
            .distances(render.x0, y, test.row(y, render.x0, width), t);
        for ((v, &d), &t) in view.visib[row].iter_mut().zip(&*d).zip(&*t) {
            *v = visible(params.visib_mode, t, d, delta);
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

/// VSD of the estimate rendered as `est` against `gt`, one error per tau of `params` written to
/// `out` (its length must equal the number of taus). An empty union gives 1 for every tau.
///
/// The pixels are visited row by row in three kinds of runs: the ground truth's alone (only its
/// visible pixels count), both windows, and the estimate's alone; no pixel asks which window
/// holds it. Within a run each pixel is computed without branches (the compiler does several
/// at once): its membership of the union and the intersection, and for the intersection the
/// discrepancy, kept per row and compared with each tau after. Built also for AVX2 (see
/// `render::draw`).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
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
    let (mut union, mut inter) = (0usize, 0usize);
    // Per tau, the intersection pixels whose distances differ by at least tau.
    let mut far = vec![0usize; params.taus.len()];
    // Per pixel of a run, its distance at the estimate, then its discrepancy (-inf outside the
    // intersection, below every tau).
    let mut d_est = Vec::new();
    let mut diffs = Vec::new();
    let gw = &gt.window;

    for dy in 0..gw.height {
        let y = gw.y0 + dy;
        let row = (dy * gw.width) as usize;
        let cols = columns_at(est, y);
        // The estimate's columns within the ground truth's, as offsets in its row.
        let from = cols.start.clamp(gw.x0, gw.x0 + gw.width) - gw.x0;
        let to = cols.end.clamp(gw.x0, gw.x0 + gw.width) - gw.x0;
        let (from, to) = (from as usize, to as usize);
        // Without an estimate, a pixel is in the union where the ground truth is visible.
        let alone = gt.visib[row..row + from]
            .iter()
            .chain(&gt.visib[row + to..row + gw.width as usize]);
        union += alone.filter(|&&v| v).count();
        if from == to {
            continue;
        }
        let x = gw.x0 + from as u32;
        let est_start = ((y - est.y0) * est.width + (x - est.x0)) as usize;
        let depths = &est.data[est_start..est_start + (to - from)];
        d_est.resize(depths.len(), 0.0);
        diffs.resize(depths.len(), 0.0);
        test.rays.distances(x, y, depths, &mut d_est);
        let (i0, i1) = (row + from, row + to);
        let gts = gt.dist[i0..i1]
            .iter()
            .zip(&gt.visib[i0..i1])
            .zip(&gt.test_dist[i0..i1]);
        for ((diff, (&depth, &d_e)), ((&d_gt, &visib_gt), &d_test)) in
            diffs.iter_mut().zip(depths.iter().zip(&d_est)).zip(gts)
        {
            // Where the estimate has no surface it is not visible, and bop19 counts it visible
            // wherever the ground truth is.
            let visib_est = (depth > 0.0) & (visible(mode, d_test, d_e, delta) | visib_gt);
            union += usize::from(visib_gt | visib_est);
            let both = visib_gt & visib_est;
            inter += usize::from(both);
            let mut d = (d_gt - d_e).abs();
            if params.normalized_by_diameter {
                d /= diameter;
            }
            *diff = if both { d } else { f64::NEG_INFINITY };
        }
        for (n, &tau) in far.iter_mut().zip(&params.taus) {
            *n += diffs.iter().filter(|&&d| d >= tau).count();
        }
    }
    // Pixels the estimate covers outside the ground-truth window: in the union where visible.
    let mut d_test = Vec::new();
    for dy in 0..est.height {
        let y = est.y0 + dy;
        let row = (dy * est.width) as usize;
        // The estimate's columns left and right of the ground truth's (all of them in a row
        // the ground truth does not reach, whose empty range clamps to the row's start).
        let gt_cols = columns_at(gw, y);
        let end = est.x0 + est.width;
        let (left, right) = (
            gt_cols.start.clamp(est.x0, end),
            gt_cols.end.clamp(est.x0, end),
        );
        for (x0, x1) in [(est.x0, left), (right, end)] {
            if x0 == x1 {
                continue;
            }
            let len = (x1 - x0) as usize;
            let start = row + (x0 - est.x0) as usize;
            let depths = &est.data[start..start + len];
            d_est.resize(len, 0.0);
            d_test.resize(len, 0.0);
            test.rays.distances(x0, y, depths, &mut d_est);
            test.rays
                .distances(x0, y, test.row(y, x0, len), &mut d_test);
            union += d_est
                .iter()
                .zip(&d_test)
                .filter(|&(&d_e, &d_t)| visible(mode, d_t, d_e, delta))
                .count();
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
