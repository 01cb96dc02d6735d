//! CPU depth rendering of a mesh at a pose that reproduces, pixel for pixel and to the last bit
//! of depth, what bop_toolkit's vispy renderer reads back from OpenGL on a machine without a
//! GPU, where Mesa's llvmpipe rasterises. VSD counts pixels and compares depths with thresholds,
//! so every step that can move a pixel across an edge or a depth across a threshold follows the
//! reference's arithmetic in the reference's precision (read from renderer_vispy.py, vispy's
//! gloo and Mesa's llvmpipe; `tests/vsd_agreement.rs` measures the result):
//!
//! 1. **Vertex path in float32.** The toolkit puts R and t into a float32 view matrix (y and z
//!    negated for OpenGL's camera), builds the model-view-projection matrix in float64 from it,
//!    K and the near/far planes, and uploads it as float32; the vertex shader computes
//!    `clip = M·(x, y, z, 1)` in float32, column by column. The viewport transform multiplies by
//!    `1/w` (a float32 reciprocal) and maps to window coordinates with y pointing up, as OpenGL
//!    renders into a framebuffer object; the toolkit flips the image when reading it back.
//! 2. **8 sub-pixel bits.** GL rasterisers snap window coordinates to a fixed-point grid before
//!    edge set-up: llvmpipe rounds `(x - 0.5) · 256` to the nearest integer (ties to even), so
//!    pixel centres fall on multiples of 256 and every inside test is exact integer arithmetic;
//!    a triangle whose snapped area is 0 draws nothing. Without the snap, pixel centres within
//!    1/512 pixel of an edge were decided differently about one VSD value in eight.
//! 3. **Tie rule.** With snapped coordinates, pixel centres exactly on an edge are common.
//!    llvmpipe's rule for framebuffer objects counts such a sample as inside when the edge is a
//!    left edge of the triangle, or a horizontal edge with the triangle above it in window
//!    coordinates: after the toolkit's flip, a *left or bottom* edge in image coordinates. It is
//!    a rule in which two triangles sharing an edge never both take, and never both miss, a
//!    sample on it. On the reference data any such watertight rule (top-left, inclusive) gives
//!    the same values; excluding every edge sample loses 261 of 3850.
//! 4. **A 16-bit depth buffer.** vispy creates the toolkit's depth render buffer as
//!    `GL_DEPTH_COMPONENT16`. Window depth `z_w = z_ndc/2 + 1/2` is interpolated linearly in
//!    screen space from a float32 plane set up as llvmpipe sets it up (from the unsnapped float32
//!    vertex positions, origin at the pixel-centre offset), evaluated at the pixel centre,
//!    clamped to [0, 1] and converted as llvmpipe converts float to 16-bit unorm
//!    (`round(z · (1 - 2^-16) · 2^16)`, ties to even); the smallest wins, ties keep the first
//!    triangle drawn (`GL_LESS`). The toolkit reads it back as float32 (`z16 · (1/65535)`) and
//!    linearises it in float32 as `mult / (z + addi)` (renderer_vispy `_draw_depth`), with
//!    `mult = n f / (n - f)` and `addi = f / (n - f)` computed in float64 and rounded to float32
//!    by NumPy 1.x's scalar casting. A depth step is then about a thousandth of a millimetre,
//!    which decides pixels whose discrepancy lies that close to a tau.
//! 5. **Clipping planes.** Near and far are the extreme camera-space z of the model's bounding
//!    box corners under the float32 pose; a box reaching to or behind the camera renders
//!    nothing.
//!
//! Not reproduced: OpenGL's geometric clipping of triangles crossing the near or far plane
//! (vertices lie inside the box, so only float32 rounding can put one outside) or the guard band
//! (a pose millimetres from the camera); the toolkit draws such triangles clipped, which moves
//! their edges by rounding amounts. Triangles with a vertex further than 2^21 pixels off screen
//! are dropped.
//!
//! Speed comes from work that cannot change a pixel: only the screen box of the object is
//! rasterised, into a [`DepthWindow`]; a triangle whose fixed-point bounding box holds no pixel
//! centre (most faces of a fine scan) is rejected before any set-up; a narrow triangle's box
//! is tested row by row in fixed-width lanes of 32-bit edge values, without a branch per pixel
//! (on coarse meshes, whose triangles cover a few pixels each, the branches of a pixel-by-pixel
//! test were mispredicted and were most of a render); a wide triangle's rows visit only their
//! runs of covered pixels (each edge's bound stepped exactly from row to row in 64-bit
//! integers); depths are computed without branches, several at once, rounded to 16 bits in
//! float32 and read from the float's bits; the whole draw is built also for AVX2 and chosen at
//! run time; [`screen_box`] bounds a render without drawing it. Faces
//! are not culled even on closed meshes: with 16-bit depth a back face at a silhouette can be a
//! depth step nearer than the front face and win the pixel, as it does in the toolkit.

use crate::math::{Intrinsics, Pose, Pt3};
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

/// A mesh prepared for rendering once per evaluation: float32 vertices (what the toolkit
/// uploads) and its bounding-box corners (for the clipping planes).
#[derive(Clone, Debug)]
pub struct Model {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    corners: [Pt3; 8],
}

impl Model {
    pub fn new(mesh: &Mesh) -> Self {
        Self::with_corners(mesh, mesh.bbox_corners())
    }

    fn with_corners(mesh: &Mesh, corners: [Pt3; 8]) -> Self {
        Model {
            vertices: mesh
                .vertices
                .iter()
                .map(|v| [v.x as f32, v.y as f32, v.z as f32])
                .collect(),
            triangles: mesh.triangles.clone(),
            corners,
        }
    }
}

/// One vertex after the vertex stage: float32 window coordinates (y up) and the snapped
/// fixed-point position (1/256 pixel, pixel centres at multiples of 256).
#[derive(Clone, Copy, Debug, Default)]
struct WinVertex {
    x: f32,
    y: f32,
    z: f32,
    fx: i64,
    fy: i64,
    /// Within the guard band (see the module documentation).
    usable: bool,
}

/// Fixed-point sub-pixel resolution: 8 bits, as llvmpipe's `FIXED_ORDER`.
const SUBPIXEL_BITS: u32 = 8;
const FIXED_ONE: i64 = 1 << SUBPIXEL_BITS;
/// Vertices further than this off screen (in fixed point) are beyond the guard band.
const GUARD_BAND: f32 = (1u32 << (21 + SUBPIXEL_BITS)) as f32;
/// The largest 16-bit depth value, the cleared buffer; it never passes `GL_LESS`.
const DEPTH_MAX: u32 = (1 << 16) - 1;
/// A depth no buffer value is above, so that keeping the smaller draws nothing.
const NO_DEPTH: u32 = DEPTH_MAX + 1;

/// Reusable buffers, so rendering thousands of poses allocates once per thread.
#[derive(Default)]
pub struct Renderer {
    verts: Vec<WinVertex>,
    zbuf: Vec<u32>,
}

/// Rounds to the nearest integer, ties to even (SSE `cvtps2dq` under the default rounding
/// mode), for |v| < 2^51; a float64 add-and-subtract of 1.5 · 2^52 does it without a libm call.
#[inline(always)]
fn round_even(v: f64) -> f64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    (v + MAGIC) - MAGIC
}

/// The projection the toolkit hands to OpenGL for one pose: the float32 MVP matrix (rows, as
/// OpenGL applies it), and the float32 constants that linearise the depth buffer.
struct Projection {
    mvp: [[f32; 4]; 4],
    mult: f32,
    addi: f32,
}

impl Projection {
    /// `None` when the bounding box reaches to or behind the camera (nothing is drawn).
    fn new(
        pose: &Pose,
        corners: &[Pt3; 8],
        k: &Intrinsics,
        width: u32,
        height: u32,
    ) -> Option<Self> {
        let (near, far) = clip_planes(corners, pose);
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far > near) {
            return None;
        }
        // The float32 view matrix, OpenCV's camera turned into OpenGL's (y and z negated).
        let mut view = [[0f64; 4]; 4];
        for (i, row) in view.iter_mut().take(3).enumerate() {
            let sign = if i == 0 { 1.0 } else { -1.0 };
            for (j, v) in row.iter_mut().take(3).enumerate() {
                *v = sign * f64::from(pose.r[(i, j)] as f32);
            }
            row[3] = sign * f64::from(pose.t[i] as f32);
        }
        view[3][3] = 1.0;
        // The toolkit's projection of K (skew dropped), in float64 like its NumPy code.
        let (w, h) = (f64::from(width), f64::from(height));
        let depth = far - near;
        let proj = [
            [2.0 * k.fx() / w, -0.0, (-2.0 * k.cx() + w) / w, 0.0],
            [0.0, 2.0 * k.fy() / h, (2.0 * k.cy() - h) / h, 0.0],
            [0.0, 0.0, -(far + near) / depth, -2.0 * (far * near) / depth],
            [0.0, 0.0, -1.0, 0.0],
        ];
        let mut mvp = [[0f32; 4]; 4];
        for (i, row) in mvp.iter_mut().enumerate() {
            for (j, m) in row.iter_mut().enumerate() {
                let mut sum = 0.0;
                for (kk, p) in proj[i].iter().enumerate() {
                    sum += p * view[kk][j];
                }
                *m = sum as f32;
            }
        }
        Some(Projection {
            mvp,
            mult: ((near * far) / (near - far)) as f32,
            addi: (far / (near - far)) as f32,
        })
    }

    /// The vertex stage: clip coordinates in float32, then `1/w` and the viewport transform
    /// (y up), then the snap to 1/256 pixel relative to the pixel centre.
    #[inline(always)]
    fn vertex(&self, v: &[f32; 3], half_w: f32, half_h: f32) -> WinVertex {
        let m = &self.mvp;
        let clip = |r: &[f32; 4]| ((r[0] * v[0] + r[1] * v[1]) + r[2] * v[2]) + r[3];
        let (cx, cy, cz, cw) = (clip(&m[0]), clip(&m[1]), clip(&m[2]), clip(&m[3]));
        let inv_w = 1.0 / cw;
        let x = (cx * inv_w) * half_w + half_w;
        let y = (cy * inv_w) * half_h + half_h;
        let z = (cz * inv_w) * 0.5 + 0.5;
        let sx = (x - 0.5) * FIXED_ONE as f32;
        let sy = (y - 0.5) * FIXED_ONE as f32;
        let usable = cw > 0.0 && sx.abs() < GUARD_BAND && sy.abs() < GUARD_BAND;
        WinVertex {
            x,
            y,
            z,
            fx: if usable {
                round_even(f64::from(sx)) as i64
            } else {
                0
            },
            fy: if usable {
                round_even(f64::from(sy)) as i64
            } else {
                0
            },
            usable,
        }
    }

    /// The depth read back from a 16-bit buffer value, linearised as the toolkit does.
    #[inline(always)]
    fn linear_depth(&self, z16: u32) -> f32 {
        // Through i32, whose conversion to float32 is one instruction for several lanes; exact,
        // as a 16-bit value is.
        let z = z16 as i32 as f32 * (1.0f32 / DEPTH_MAX as f32);
        self.mult / (z + self.addi)
    }
}

/// Near and far clipping planes of the reference renderer: the extreme camera-space z of the
/// model's bounding-box corners, with R and t rounded to float32 as in its view matrix.
pub fn clip_planes(corners: &[Pt3; 8], pose: &Pose) -> (f64, f64) {
    let f = |v: f64| f64::from(v as f32);
    let row = [f(pose.r[(2, 0)]), f(pose.r[(2, 1)]), f(pose.r[(2, 2)])];
    let tz = f(pose.t.z);
    corners
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(n, fa), c| {
            let z = row[0] * c.x + row[1] * c.y + row[2] * c.z + tz;
            (n.min(z), fa.max(z))
        })
}

/// An inclusive rectangle of image pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl PixelBox {
    pub fn overlaps(&self, other: &PixelBox) -> bool {
        self.x0 <= other.x1 && other.x0 <= self.x1 && self.y0 <= other.y1 && other.y0 <= self.y1
    }

    /// The pixels of a non-empty window.
    pub fn of_window(w: &DepthWindow) -> Option<PixelBox> {
        (!w.is_empty()).then(|| PixelBox {
            x0: w.x0,
            y0: w.y0,
            x1: w.x0 + w.width - 1,
            y1: w.y0 + w.height - 1,
        })
    }
}

/// Margin, in pixels, around the projected bounding box in [`screen_box`]: far above the
/// float32 vertex path's error, which is a small fraction of a pixel.
const SCREEN_BOX_MARGIN: f64 = 2.0;

/// A rectangle holding every pixel [`Renderer::render_model`] can cover for `model` at `pose`,
/// found without rendering: the mesh lies in its bounding box, which lies in front of the
/// camera whenever anything is drawn, so its projection lies within the projected corners.
/// `None` when the render is certainly empty. Two renders whose boxes do not overlap share no
/// pixel, and their VSD is exactly 1.
pub fn screen_box(
    model: &Model,
    pose: &Pose,
    k: &Intrinsics,
    width: u32,
    height: u32,
) -> Option<PixelBox> {
    let (near, far) = clip_planes(&model.corners, pose);
    if !(near.is_finite() && far.is_finite() && near > 0.0 && far > near) {
        return None;
    }
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for c in &model.corners {
        let p = pose.transform(c);
        let (u, v) = (k.fx() * p.x / p.z + k.cx(), k.fy() * p.y / p.z + k.cy());
        (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
    }
    // Pixel i is sampled at i + 0.5.
    let first = |lo: f64| (lo - SCREEN_BOX_MARGIN - 0.5).ceil().max(0.0);
    let last = |hi: f64, size: u32| {
        (hi + SCREEN_BOX_MARGIN - 0.5)
            .floor()
            .min(f64::from(size) - 1.0)
    };
    let (x0, x1) = (first(u0), last(u1, width));
    let (y0, y1) = (first(v0), last(v1, height));
    (x0 <= x1 && y0 <= y1).then_some(PixelBox {
        x0: x0 as u32,
        y0: y0 as u32,
        x1: x1 as u32,
        y1: y1 as u32,
    })
}

/// `ceil(a / FIXED_ONE)` for fixed-point `a`.
#[inline(always)]
fn ceil_px(a: i64) -> i64 {
    -((-a) >> SUBPIXEL_BITS)
}

/// `floor(a / FIXED_ONE)` for fixed-point `a`.
#[inline(always)]
fn floor_px(a: i64) -> i64 {
    a >> SUBPIXEL_BITS
}

impl Renderer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `mesh` at `pose` seen by a camera with intrinsics `k` into an image of
    /// `width` x `height` pixels, returning only the covered window. To render one mesh many
    /// times, prepare it once as a [`Model`] and use [`Renderer::render_model`].
    pub fn render(
        &mut self,
        mesh: &Mesh,
        bbox_corners: &[Pt3; 8],
        pose: &Pose,
        k: &Intrinsics,
        width: u32,
        height: u32,
    ) -> DepthWindow {
        let model = Model::with_corners(mesh, *bbox_corners);
        self.render_model(&model, pose, k, width, height)
    }

    /// Renders a prepared model (see [`Renderer::render`]).
    pub fn render_model(
        &mut self,
        model: &Model,
        pose: &Pose,
        k: &Intrinsics,
        width: u32,
        height: u32,
    ) -> DepthWindow {
        if width == 0 || height == 0 {
            return DepthWindow::empty();
        }
        let Some(proj) = Projection::new(pose, &model.corners, k, width, height) else {
            return DepthWindow::empty();
        };
        draw(&proj, model, width, height, &mut self.verts, &mut self.zbuf)
    }
}

/// The vertex stage, rasterisation and read-back of [`Renderer::render_model`], compiled also
/// for AVX2 and chosen when the processor has it (runtime detection, no unsafe code here):
/// the loops that run several pixels at once then run twice as many. Every operation is the
/// same IEEE operation in either build (Rust never fuses a multiply and an add on its own), so
/// the depths are the same to the bit.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn draw(
    proj: &Projection,
    model: &Model,
    width: u32,
    height: u32,
    verts: &mut Vec<WinVertex>,
    zbuf: &mut Vec<u32>,
) -> DepthWindow {
    let (half_w, half_h) = (width as f32 * 0.5, height as f32 * 0.5);
    verts.clear();
    let (mut lo_x, mut hi_x, mut lo_y, mut hi_y) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
    for v in &model.vertices {
        let wv = proj.vertex(v, half_w, half_h);
        if wv.usable {
            lo_x = lo_x.min(wv.fx);
            hi_x = hi_x.max(wv.fx);
            lo_y = lo_y.min(wv.fy);
            hi_y = hi_y.max(wv.fy);
        }
        verts.push(wv);
    }
    // Window coordinates (y up) of the pixels whose centres the vertices span.
    let x0 = ceil_px(lo_x).max(0);
    let x1 = floor_px(hi_x).min(i64::from(width) - 1);
    let y0 = ceil_px(lo_y).max(0);
    let y1 = floor_px(hi_y).min(i64::from(height) - 1);
    if x0 > x1 || y0 > y1 {
        return DepthWindow::empty();
    }
    let win = Window {
        x0,
        x1,
        y0,
        y1,
        top: i64::from(height) - 1 - y1,
        width: (x1 - x0 + 1) as usize,
        image_height: i64::from(height),
    };
    let pixels = win.width * (y1 - y0 + 1) as usize;
    zbuf.clear();
    // The lanes of the last row's narrow triangles reach past the window (see `draw_lanes`).
    zbuf.resize(pixels + LANES_MAX, DEPTH_MAX);

    for tri in &model.triangles {
        let [a, b, c] = tri.map(|i| verts[i as usize]);
        rasterise::<BOUND_FROM>(zbuf, &win, a, b, c);
    }

    DepthWindow {
        x0: x0 as u32,
        y0: win.top as u32,
        width: win.width as u32,
        height: (y1 - y0 + 1) as u32,
        // Every pixel is converted and the cleared ones then zeroed, without a branch, so
        // that the compiler does several divisions at once.
        data: zbuf[..pixels]
            .iter()
            .map(|&z| {
                let depth = proj.linear_depth(z);
                if z == DEPTH_MAX { 0.0 } else { depth }
            })
            .collect(),
    }
}

/// The rasterised rectangle: window-coordinate pixel ranges (y up) and the layout of the
/// depth buffer, stored in image row order (row 0 = window row `y1`).
struct Window {
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
    /// Image row of window row `y1`.
    top: i64,
    width: usize,
    image_height: i64,
}

impl Window {
    /// Where window row `y` (y up) starts in the depth buffer.
    #[inline(always)]
    fn row_start(&self, y: i64) -> usize {
        (self.image_height - 1 - y - self.top) as usize * self.width
    }
}

/// Rasterises one triangle into the 16-bit depth buffer `zbuf` over `win`, as llvmpipe does:
/// boxes narrower than `LANES_BELOW` pixels in lanes ([`draw_lanes`]), the others by their
/// rows' runs ([`EdgeBound`]); [`draw`] passes [`BOUND_FROM`], and a test draws with each
/// path alone to compare them. It and the helpers below are inlined into [`draw`], so that
/// they are built for its targets.
#[inline(always)]
fn rasterise<const LANES_BELOW: i64>(
    zbuf: &mut [u32],
    win: &Window,
    mut a: WinVertex,
    mut b: WinVertex,
    c: WinVertex,
) {
    if !(a.usable && b.usable && c.usable) {
        return;
    }
    // Pixel centres inside the triangle's fixed-point bounding box, within the window: most
    // faces of a fine mesh hold none, so this test comes first.
    let tx0 = ceil_px(a.fx.min(b.fx).min(c.fx)).max(win.x0);
    let tx1 = floor_px(a.fx.max(b.fx).max(c.fx)).min(win.x1);
    let ty0 = ceil_px(a.fy.min(b.fy).min(c.fy)).max(win.y0);
    let ty1 = floor_px(a.fy.max(b.fy).max(c.fy)).min(win.y1);
    if tx0 > tx1 || ty0 > ty1 {
        return;
    }
    // Twice the signed area in fixed point; llvmpipe draws positive triangles and swaps the
    // first two vertices of negative ones.
    let area = (a.fx - b.fx) * (c.fy - a.fy) - (c.fx - a.fx) * (a.fy - b.fy);
    if area == 0 {
        return;
    }
    if area < 0 {
        std::mem::swap(&mut a, &mut b);
    }

    // Edge functions E = dcdx (x_i - X) - dcdy (y_i - Y) of the edges (a, b), (b, c), (c, a),
    // positive inside; a sample on an edge (E = 0) is inside for left edges (dcdx < 0) and for
    // horizontal edges with dcdy > 0, llvmpipe's rule for framebuffer objects. `f` holds
    // E - 1 + bias, so that "inside" is `f >= 0` for all three.
    let edge = |p: &WinVertex, q: &WinVertex| {
        let dcdx = p.fy - q.fy;
        let dcdy = p.fx - q.fx;
        let bias = i64::from(dcdx < 0 || (dcdx == 0 && dcdy > 0));
        let at = dcdx * (p.fx - tx0 * FIXED_ONE) - dcdy * (p.fy - ty0 * FIXED_ONE) + bias - 1;
        (at, -dcdx * FIXED_ONE, dcdy * FIXED_ONE)
    };
    let edges = [edge(&a, &b), edge(&b, &c), edge(&c, &a)];
    let (last, rows) = (tx1 - tx0, ty1 - ty0);
    // Narrow triangles (most of a mesh's) test every pixel of their box, row by row in
    // fixed-width lanes of 32-bit edge values, when those hold every value the box takes
    // (an edge function is linear, so its extremes lie at the box's corners).
    let fits = edges.iter().all(|&(at, sx, sy)| {
        [
            at,
            at + last * sx,
            at + rows * sy,
            at + last * sx + rows * sy,
        ]
        .iter()
        .all(|&v| i32::try_from(v).is_ok())
    });
    if last < LANES_BELOW && fits {
        let plane = DepthPlane::new(&a, &b, &c);
        let edges = edges.map(|(at, sx, sy)| [at as i32, sx as i32, sy as i32]);
        let corner = (tx0, ty0, last as i32, rows);
        if last < 8 {
            draw_lanes::<8>(zbuf, win, &plane, corner, edges);
        } else {
            draw_lanes::<LANES_MAX>(zbuf, win, &plane, corner, edges);
        }
        return;
    }
    // The depth plane is set up only once a sample is found inside: a large triangle clipped
    // to the window may cover none, and the set-up has a division.
    let mut plane: Option<DepthPlane> = None;
    let [(e0, sx0, sy0), (e1, sx1, sy1), (e2, sx2, sy2)] = edges;
    // Each edge bounds a row's run on one side; its bound moves by a constant step from row to
    // row, kept exact in integers (a quotient and a remainder) without a division per row.
    let mut bounds = [
        EdgeBound::new(e0, sx0, sy0),
        EdgeBound::new(e1, sx1, sy1),
        EdgeBound::new(e2, sx2, sy2),
    ];
    for y in ty0..=ty1 {
        let (mut lo, mut hi) = (0, last);
        for bound in &mut bounds {
            bound.narrow(&mut lo, &mut hi);
            bound.step();
        }
        if lo <= hi {
            let p = plane.get_or_insert_with(|| DepthPlane::new(&a, &b, &c));
            let row = win.row_start(y) + (tx0 - win.x0) as usize;
            p.draw_run(
                &mut zbuf[row + lo as usize..=row + hi as usize],
                tx0 + lo,
                y,
            );
        }
    }
}

/// The rows of a narrow triangle's box from window pixel `(x0, y0)`, `last + 1` columns and
/// `rows + 1` rows, `N` lanes at a time with no branch per pixel: every lane computes its
/// edge values and depth and keeps the smaller depth where it is inside. The branches of
/// testing pixel by pixel (how many columns, which pixel is inside) were mispredicted on most
/// of the small triangles of a coarse mesh and were most of its render. Lanes past the box
/// store what they read: `zbuf` has `N` slots beyond its last row for them. `edges` holds each
/// edge's value at `(x0, y0)`, its step along a row and its step from row to row; values of
/// lanes past the box may wrap, and are never used.
#[inline(always)]
fn draw_lanes<const N: usize>(
    zbuf: &mut [u32],
    win: &Window,
    plane: &DepthPlane,
    (x0, y0, last, rows): (i64, i64, i32, i64),
    edges: [[i32; 3]; 3],
) {
    let mut values: [[i32; N]; 3] = edges
        .map(|[at, sx, _]| std::array::from_fn(|k| at.wrapping_add((k as i32).wrapping_mul(sx))));
    // Exact: columns are below 2^24. (Converting from 64 bits has no vector instruction.)
    let first = x0 as f32;
    let xs: [f32; N] = std::array::from_fn(|k| first + k as f32);
    for y in y0..=y0 + rows {
        let dzdy_y = plane.dzdy * y as f32;
        let start = win.row_start(y) + (x0 - win.x0) as usize;
        let slots = &mut zbuf[start..start + N];
        for k in 0..N {
            let inside = ((values[0][k] | values[1][k] | values[2][k]) >= 0) & (k as i32 <= last);
            // Outside, the cleared value, which no slot is above: every lane stores. (Storing
            // the slot itself became a masked store, which a later load cannot forward from.)
            let z16 = plane.depth16_at(xs[k], dzdy_y);
            slots[k] = slots[k].min(if inside { z16 } else { DEPTH_MAX });
        }
        for (lane, [_, _, sy]) in values.iter_mut().zip(edges) {
            for v in lane.iter_mut() {
                *v = v.wrapping_add(sy);
            }
        }
    }
}

/// The most lanes [`draw_lanes`] runs: every narrow triangle's box is this wide at most.
const LANES_MAX: usize = BOUND_FROM as usize;

/// Triangle bounding boxes this many pixels wide or wider find each row's covered pixels from
/// their edges' bounds ([`EdgeBound`]); narrower ones test every pixel of the box in lanes
/// ([`draw_lanes`]), which costs less than the bounds' set-up (two divisions per edge).
const BOUND_FROM: i64 = 16;

/// Where one edge function `E(k) = f + k s` (at column offset `k` of a row, `f` growing by `t`
/// from row to row) is `>= 0`: from `-floor(f / s)` on when it grows along the row, up to
/// `floor(f / -s)` when it shrinks, everywhere or nowhere when it is constant. The floor is
/// kept as a quotient and a remainder in `[0, |s|)` and stepped with `t`'s, so every row's
/// bound is exactly the one testing every pixel finds, in a few additions; stepping across the
/// covered pixels instead was most of a large triangle's time.
#[derive(Clone, Copy, Debug)]
struct EdgeBound {
    /// `s`'s sign: 1 a lower bound, -1 an upper one, 0 none (then `q` is `f` itself).
    sign: i64,
    /// `|s|`.
    d: i64,
    q: i64,
    r: i64,
    /// `t`, or its quotient and remainder by `d`.
    tq: i64,
    tr: i64,
}

impl EdgeBound {
    fn new(f: i64, s: i64, t: i64) -> Self {
        let d = s.abs();
        if d == 0 {
            return EdgeBound {
                sign: 0,
                d,
                q: f,
                r: 0,
                tq: t,
                tr: 0,
            };
        }
        EdgeBound {
            sign: s.signum(),
            d,
            q: f.div_euclid(d),
            r: f.rem_euclid(d),
            tq: t.div_euclid(d),
            tr: t.rem_euclid(d),
        }
    }

    /// Narrows the row's run `lo..=hi` (column offsets) to where this edge holds.
    #[inline(always)]
    fn narrow(&self, lo: &mut i64, hi: &mut i64) {
        match self.sign {
            1 => *lo = (*lo).max(-self.q),
            -1 => *hi = (*hi).min(self.q),
            _ => {
                if self.q < 0 {
                    *hi = -1;
                }
            }
        }
    }

    /// Moves to the next row.
    #[inline(always)]
    fn step(&mut self) {
        self.q += self.tq;
        self.r += self.tr;
        if self.d != 0 && self.r >= self.d {
            self.r -= self.d;
            self.q += 1;
        }
    }
}

/// Window depth as a float32 plane through the unsnapped vertices, origin at the pixel centre
/// offset, as llvmpipe's triangle set-up computes it.
struct DepthPlane {
    z0: f32,
    dzdx: f32,
    dzdy: f32,
}

impl DepthPlane {
    #[inline(always)]
    fn new(a: &WinVertex, b: &WinVertex, c: &WinVertex) -> Self {
        let x0c = a.x - 0.5;
        let y0c = a.y - 0.5;
        let (dx01, dy01) = (a.x - b.x, a.y - b.y);
        let (dx20, dy20) = (c.x - a.x, c.y - a.y);
        let ooa = 1.0 / (dx01 * dy20 - dy01 * dx20);
        let (dx20, dy20, dx01, dy01) = (dx20 * ooa, dy20 * ooa, dx01 * ooa, dy01 * ooa);
        let (dz01, dz20) = (a.z - b.z, c.z - a.z);
        let dzdx = dz01 * dy20 - dz20 * dy01;
        let dzdy = dz20 * dx01 - dz01 * dx20;
        DepthPlane {
            z0: a.z - (dzdx * x0c + dzdy * y0c),
            dzdx,
            dzdy,
        }
    }

    /// The 16-bit depth at window pixel (x, y) given `dzdy · y`, clamped to the depth range;
    /// [`NO_DEPTH`] for NaN (a float32 set-up of zero area) or infinity, which draw nothing. The
    /// plane is `(z0 + dzdx x) + dzdy y` in this order, as llvmpipe evaluates it.
    #[inline(always)]
    fn depth16_at(&self, x: f32, dzdy_y: f32) -> u32 {
        let z = (self.z0 + self.dzdx * x) + dzdy_y;
        // `v · 2^16` is exact in float32 and below 2^16, so adding 1.5 · 2^23 rounds it to
        // the nearest integer, ties to even, as the float64 path would, and leaves that
        // integer in the low bits of the sum (whose unit in the last place is 1): reading it
        // from the bits spares the saturating float-to-integer conversion. Multiplying by
        // 65535 rounds as multiplying by `65535 / 65536` and then by `2^16` (exact) does.
        const MAGIC: f32 = 12_582_912.0;
        let v = z.clamp(0.0, 1.0) * 65535.0;
        let z16 = (v + MAGIC).to_bits().wrapping_sub(MAGIC.to_bits());
        if z.is_finite() { z16 } else { NO_DEPTH }
    }

    /// Draws the run of window row `y` from column `first` into `slots` (one per pixel),
    /// keeping the smaller depth (`GL_LESS`: a tie keeps the triangle drawn first). Without
    /// branches, so that the compiler can do several pixels at once.
    #[inline(always)]
    fn draw_run(&self, slots: &mut [u32], first: i64, y: i64) {
        let dzdy_y = self.dzdy * y as f32;
        let first = first as i32;
        for (i, slot) in slots.iter_mut().enumerate() {
            let z16 = self.depth16_at((first + i as i32) as f32, dzdy_y);
            *slot = (*slot).min(z16);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Mat3, Pt3, Vec3};

    /// An edge's bound on each row is exactly the columns a test of every pixel finds: random
    /// edge functions of the magnitudes the rasteriser steps (fixed-point coordinates times edge
    /// deltas), over rows where the run is whole, partial, at a row's ends or empty.
    #[test]
    fn an_edge_bounds_each_row_as_testing_every_pixel_does() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |range: i64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % (2 * range as u64 + 1)) as i64 - range
        };
        for _ in 0..20_000 {
            let width = next(40).abs();
            let s =
                [next(3) * 256 * next(8), next(3) * 256, next(600) * 256][(next(1) + 1) as usize];
            let t = [next(3) * 256, next(600) * 256 * next(3), 0][(next(1) + 1) as usize];
            let mut f = [next(20_000), next(5_000), next(100_000)][(next(1) + 1) as usize];
            let mut bound = EdgeBound::new(f, s, t);
            for row in 0..30 {
                let inside: Vec<i64> = (0..=width).filter(|&k| f + k * s >= 0).collect();
                let expected = inside.first().map(|&a| (a, *inside.last().unwrap()));
                let (mut lo, mut hi) = (0, width);
                bound.narrow(&mut lo, &mut hi);
                let found = (lo <= hi).then_some((lo, hi));
                assert_eq!(found, expected, "f {f} s {s} t {t} width {width} row {row}");
                bound.step();
                f += t;
            }
        }
    }

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

    /// A vertex at fixed-point window position (x, y), window depth 0.5.
    fn fixed(x: i64, y: i64) -> WinVertex {
        WinVertex {
            x: x as f32 / 256.0 + 0.5,
            y: y as f32 / 256.0 + 0.5,
            z: 0.5,
            fx: x,
            fy: y,
            usable: true,
        }
    }

    /// Rasterises one triangle over a 4x4 window, returning the covered window pixels (x, y up).
    fn coverage(a: WinVertex, b: WinVertex, c: WinVertex) -> Vec<(i64, i64)> {
        let win = Window {
            x0: 0,
            x1: 3,
            y0: 0,
            y1: 3,
            top: 0,
            width: 4,
            image_height: 4,
        };
        let mut zbuf = vec![DEPTH_MAX; 16 + LANES_MAX];
        rasterise::<BOUND_FROM>(&mut zbuf, &win, a, b, c);
        let mut out = Vec::new();
        for y in 0..4 {
            for x in 0..4 {
                if zbuf[((3 - y) * 4 + x) as usize] != DEPTH_MAX {
                    out.push((x, y));
                }
            }
        }
        out
    }

    /// The lanes of narrow triangles draw exactly what the rows' runs draw: random triangles
    /// up to 20 pixels across (so both lane widths and the boxes too wide for lanes occur),
    /// partly outside a 24 x 20 window, drawn over each other with random depths.
    #[test]
    fn narrow_triangles_draw_in_lanes_what_the_runs_draw() {
        let win = Window {
            x0: 0,
            x1: 23,
            y0: 0,
            y1: 19,
            top: 0,
            width: 24,
            image_height: 20,
        };
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % n
        };
        for mesh in 0..2_000 {
            let (mut lanes, mut runs) = (vec![DEPTH_MAX; 480 + LANES_MAX], vec![DEPTH_MAX; 480]);
            for _ in 0..8 {
                let (cx, cy) = (next(28 * 256) as i64 - 512, next(24 * 256) as i64 - 512);
                let span = [1, 3, 8, 20][next(4) as usize] * 256;
                let mut vertex = || {
                    let mut v = fixed(
                        cx + next(span as u64) as i64 - span / 2,
                        cy + next(span as u64) as i64 - span / 2,
                    );
                    v.z = next(1 << 20) as f32 / (1 << 20) as f32;
                    v
                };
                let (a, b, c) = (vertex(), vertex(), vertex());
                rasterise::<BOUND_FROM>(&mut lanes, &win, a, b, c);
                rasterise::<0>(&mut runs, &win, a, b, c);
            }
            assert_eq!(lanes[..480], runs[..], "mesh {mesh}");
            assert!(lanes[480..].iter().all(|&z| z == DEPTH_MAX), "mesh {mesh}");
        }
    }

    #[test]
    fn samples_on_left_and_lower_edges_are_inside_and_on_right_and_upper_edges_outside() {
        // A right triangle with its legs through the centres of column 1 and row 1 (window
        // coordinates, y up) and its hypotenuse between samples: the left and lower legs keep
        // their samples, whichever way the vertices are listed.
        let (a, b, c) = (
            fixed(256, 256),
            fixed(256 * 3 + 128, 256),
            fixed(256, 256 * 3 + 128),
        );
        let expected = vec![(1, 1), (2, 1), (3, 1), (1, 2), (2, 2), (1, 3)];
        assert_eq!(coverage(a, b, c), expected);
        assert_eq!(coverage(a, c, b), expected);
        // Mirrored: with its legs on the right (column 2) and on top (row 2), the triangle
        // loses their samples and keeps only (1, 1).
        let (a, b, c) = (fixed(512, 512), fixed(-128, 512), fixed(512, -128));
        assert_eq!(coverage(a, b, c), vec![(1, 1)]);
    }

    #[test]
    fn two_triangles_sharing_an_edge_through_samples_cover_each_sample_once() {
        // A square from sample (0, 0) to sample (3, 3) split along its diagonal, which passes
        // through samples (1, 1) and (2, 2): its left and lower sides are in, its right and
        // upper sides out, and every sample within is covered by exactly one half.
        let (p, q, r, s) = (fixed(0, 0), fixed(768, 0), fixed(768, 768), fixed(0, 768));
        let mut both = coverage(p, q, r);
        both.extend(coverage(p, r, s));
        both.sort();
        let square: Vec<_> = (0..3).flat_map(|x| (0..3).map(move |y| (x, y))).collect();
        assert_eq!(both, square);
    }

    #[test]
    fn window_coordinates_snap_to_a_256th_of_a_pixel_ties_to_even() {
        assert_eq!(round_even(2.5), 2.0);
        assert_eq!(round_even(3.5), 4.0);
        assert_eq!(round_even(-2.5), -2.0);
        assert_eq!(round_even(1.499_999), 1.0);
        // A vertex 1/1024 pixel right of a pixel centre snaps onto it.
        let k = camera();
        let proj = Projection::new(
            &Pose::new(Mat3::identity(), Vec3::new(0.0, 0.0, 1000.0)),
            &crate::mesh::test_cube(50.0).bbox_corners(),
            &k,
            640,
            480,
        )
        .expect("in front of the camera");
        let x = (300.5 + 1.0 / 1024.0 - k.cx()) / k.fx() * 1000.0;
        let v = proj.vertex(&[x as f32, 0.0, 0.0], 320.0, 240.0);
        assert_eq!(v.fx, 300 * 256);
    }

    proptest::proptest! {
        #[test]
        fn depth_rounds_in_float32_as_the_float64_path_does(z in -0.5f32..1.5, bits in 0u32..1 << 16) {
            // Both a spread of depths and every exact half-step between 16-bit values (ties).
            let tie = (bits as f32 + 0.5) / (65535.0f32 / 65536.0) / 65536.0;
            for z in [z, tie] {
                let plane = DepthPlane { z0: z, dzdx: 0.0, dzdy: 0.0 };
                let v = z.clamp(0.0, 1.0) * (65535.0f32 / 65536.0);
                let expected = round_even(f64::from(v) * 65536.0) as u32;
                proptest::prop_assert_eq!(plane.depth16_at(0.0, 0.0), expected);
            }
        }
    }

    #[test]
    fn a_nan_depth_draws_nothing() {
        let plane = DepthPlane {
            z0: f32::NAN,
            dzdx: 0.0,
            dzdy: 0.0,
        };
        assert_eq!(plane.depth16_at(3.0, 4.0), NO_DEPTH);
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
}
