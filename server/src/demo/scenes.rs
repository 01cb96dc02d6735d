//! The test images: objects resting on a table, seen from above at an angle, with a depth
//! sensor's flaws. The ground-truth annotations are computed from the very depth images
//! written and with the evaluator's own renderer, distance maps and visibility test, so that
//! `scene_gt_info.json` and the targets agree with what poseboard's evaluation sees, pixel for
//! pixel, instead of approximating bop_toolkit's `calc_gt_info.py` from the outside.
//!
//! Each image draws from its own random stream (seed, scene, image), so an image does not
//! change when another one is added or laid out differently.

use std::collections::BTreeMap;
use std::f64::consts::TAU;
use std::path::Path;

use anyhow::Result;
use evaluator::coco::rle::Rle;
use evaluator::math::{Intrinsics, Mat3, Pose, Vec3};
use evaluator::pose_error::vsd::PixelRays;
use evaluator::render::{DepthWindow, Renderer};
use evaluator::visibility::{VisibMode, visible};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;

use super::SynthOptions;
use super::files::{write_depth_png, write_json_object, write_rgb_png};
use super::shapes::{Shape, TOWER, rotation};

/// The size the scenes are laid out at; other sizes see them through scaled intrinsics.
pub(super) const WIDTH: u32 = 640;
pub(super) const HEIGHT: u32 = 480;
/// The intrinsics of the LINEMOD Kinect, the best known BOP camera, at 640 x 480.
const CAM_K: [f64; 9] = [572.4, 0.0, 325.3, 0.0, 573.6, 242.0, 0.0, 0.0, 1.0];

/// The intrinsics for images of `size`: LINEMOD's scaled, so that the camera sees the same
/// field of view at every size (a published size then shows the same scenes).
pub(super) fn cam_k((width, height): (u32, u32)) -> [f64; 9] {
    let (sx, sy) = (
        f64::from(width) / f64::from(WIDTH),
        f64::from(height) / f64::from(HEIGHT),
    );
    let mut k = CAM_K;
    k[0] *= sx;
    k[2] *= sx;
    k[4] *= sy;
    k[5] *= sy;
    k
}
/// Depth PNG values are tenths of a millimetre, as in T-LESS and YCB-V, rather than the
/// millimetres of LINEMOD: the demo then exercises the scaling of depth images, which a
/// dataset in millimetres would leave untested, and keeps sub-millimetre steps.
pub(super) const DEPTH_SCALE: f64 = 0.1;

/// bop_toolkit's tolerance for the visibility of ground truth (`calc_gt_info.py`).
const VISIB_DELTA: f32 = 15.0;
/// Instances less visible than this are annotated but are no test target (BOP'19).
const MIN_VISIB_FRACT: f64 = 0.1;
const NOISE_SIGMA_MM: f64 = 1.5;
/// A measurement this much behind a neighbouring one is dropped, as structured-light sensors
/// see nothing in the shadow along the far side of depth edges.
const DISCONTINUITY_MM: f64 = 25.0;
const HOLE_FRACTION: f64 = 0.02;
/// The table is a finite rectangle around the world origin; beyond it the sensor sees nothing.
const TABLE_HALF_SIZE: [f64; 2] = [700.0, 500.0];
/// Objects stand within this distance of the point the camera looks at, so they overlap in
/// the image.
const CLUSTER_RADIUS: f64 = 150.0;
/// Gap kept between the footprints of two objects, mm.
const CLEARANCE: f64 = 2.0;
/// Objects are slid into place in steps of this many mm.
const SLIDE_STEP: f64 = 4.0;
const SLIDE_STEPS: usize = 100;
/// The visible fraction sought for the instance hidden behind another one, in the noiseless
/// scene: the sensor's holes then reveal a little more of it (missing depth counts as visible).
const HIDDEN_VISIB: std::ops::RangeInclusive<f64> = 0.005..=0.05;
const TRIES: usize = 60;

const BACKGROUND: [u8; 3] = [38, 42, 50];
const TABLE_COLOURS: [[u8; 3]; 2] = [[205, 178, 140], [188, 160, 122]];
/// Labels of the colour pass: 0 nothing, then the two table colours, then the instances.
const FIRST_INSTANCE_LABEL: u8 = 3;

/// One line of test_targets_bop19.json, keys in bop_toolkit's (sorted) order.
#[derive(Serialize)]
pub(super) struct Target {
    pub(super) im_id: u32,
    inst_count: u32,
    obj_id: u32,
    pub(super) scene_id: u32,
}

#[derive(Serialize)]
struct CameraEntry {
    #[serde(rename = "cam_K")]
    cam_k: [f64; 9],
    depth_scale: f64,
}

#[derive(Serialize)]
struct GtEntry {
    #[serde(rename = "cam_R_m2c")]
    cam_r_m2c: [f64; 9],
    cam_t_m2c: [f64; 3],
    obj_id: u32,
}

/// One entry of scene_gt_info.json, as bop_toolkit's `calc_gt_info.py` defines it.
#[derive(Serialize)]
struct GtInfo {
    bbox_obj: [i64; 4],
    bbox_visib: [i64; 4],
    px_count_all: u64,
    px_count_valid: u64,
    px_count_visib: u64,
    visib_fract: f64,
}

/// Writes `test/{scene_id:06}/` and returns its targets, sorted by image and object.
pub(super) fn write_scene(
    split_dir: &Path,
    scene_id: u32,
    opts: &SynthOptions,
    shapes: &[Shape],
) -> Result<Vec<Target>> {
    let dir = split_dir.join(format!("{scene_id:06}"));
    for sub in ["depth", "rgb"] {
        std::fs::create_dir_all(dir.join(sub))?;
    }
    let mut cameras = BTreeMap::new();
    let mut gts = BTreeMap::new();
    let mut infos = BTreeMap::new();
    let mut coco = CocoFiles::default();
    let mut targets = Vec::new();
    let mut copies = Copies::new(shapes.len() as u32, opts.objects);
    let n = opts.images_per_scene;
    for im_id in 0..n {
        let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
        rng.set_stream((u64::from(scene_id) << 32) | u64::from(im_id));
        let roles = Roles {
            truncated: im_id == 1 % n,
            hidden: im_id == 2 % n,
        };
        let mut image = make_image(&mut rng, shapes, roles, opts.image_size);
        for (gt, info) in image.gt.iter_mut().zip(&image.info) {
            if info.visib_fract >= MIN_VISIB_FRACT {
                gt.obj_id = copies.next(gt.obj_id);
            }
        }
        let name = format!("{im_id:06}.png");
        write_depth_png(
            &dir.join("depth").join(&name),
            opts.image_size,
            &image.depth,
        )?;
        write_rgb_png(&dir.join("rgb").join(&name), opts.image_size, &image.rgb)?;

        let mut counts = BTreeMap::new();
        for (gt, info) in image.gt.iter().zip(&image.info) {
            if info.visib_fract >= MIN_VISIB_FRACT {
                *counts.entry(gt.obj_id).or_insert(0) += 1;
            }
        }
        targets.extend(counts.into_iter().map(|(obj_id, inst_count)| Target {
            im_id,
            inst_count,
            obj_id,
            scene_id,
        }));
        cameras.insert(
            im_id,
            CameraEntry {
                cam_k: cam_k(opts.image_size),
                depth_scale: DEPTH_SCALE,
            },
        );
        coco.add_image(im_id, opts.image_size, &image);
        gts.insert(im_id, image.gt);
        infos.insert(im_id, image.info);
    }
    write_json_object(&dir.join("scene_camera.json"), &cameras)?;
    write_json_object(&dir.join("scene_gt.json"), &gts)?;
    write_json_object(&dir.join("scene_gt_info.json"), &infos)?;
    let categories: Vec<u32> = (1..=opts.objects).collect();
    coco.write(&dir, &categories)?;
    Ok(targets)
}

/// The object ids of a scene's instances when there are more objects than shapes: object
/// `s + k * shapes` is a copy of shape `s`, and the visible instances of a shape (the targets)
/// take its copies' ids in turn, so that every id is a target once a shape has been seen as
/// often as it has copies; an instance too hidden to be a target keeps its shape's id.
/// With as many objects as shapes every instance keeps its shape's id (and the random draws,
/// hence the files, are the same as without copies).
struct Copies {
    shapes: u32,
    objects: u32,
    /// Instances of each shape so far, by shape id.
    placed: BTreeMap<u32, u32>,
}

impl Copies {
    fn new(shapes: u32, objects: u32) -> Copies {
        Copies {
            shapes,
            objects,
            placed: BTreeMap::new(),
        }
    }

    /// The id of the next instance of shape `shape_id`.
    fn next(&mut self, shape_id: u32) -> u32 {
        let copies = (self.objects - shape_id) / self.shapes + 1;
        let n = self.placed.entry(shape_id).or_insert(0);
        let id = shape_id + (*n % copies) * self.shapes;
        *n += 1;
        id
    }
}

/// The scene's `scene_gt_coco.json` (amodal boxes) and `scene_gt_coco_modal.json` (modal
/// boxes), as bop_toolkit's `calc_gt_coco.py` makes them from the visible masks: one
/// annotation per instance with a visible pixel, its mask as uncompressed RLE, its area the
/// visible pixels, `ignore` set below 10 % visible.
#[derive(Default)]
struct CocoFiles {
    images: Vec<serde_json::Value>,
    /// Per annotation: the fields both files share, the amodal and the modal box.
    annotations: Vec<(serde_json::Value, [i64; 4], [i64; 4])>,
}

impl CocoFiles {
    fn add_image(&mut self, im_id: u32, (width, height): (u32, u32), image: &ImageData) {
        self.images.push(serde_json::json!({
            "id": im_id, "file_name": format!("rgb/{im_id:06}.png"),
            "width": width, "height": height,
        }));
        for ((gt, info), mask) in image.gt.iter().zip(&image.info).zip(&image.masks) {
            let Some(modal) = mask.bbox else { continue };
            let fields = serde_json::json!({
                "id": self.annotations.len() + 1, "image_id": im_id, "category_id": gt.obj_id,
                "iscrowd": 0, "area": mask.rle.area(),
                "segmentation": {"counts": mask.rle.counts(), "size": [height, width]},
                "width": width, "height": height,
                "ignore": info.visib_fract < MIN_VISIB_FRACT,
            });
            self.annotations.push((fields, info.bbox_obj, modal));
        }
    }

    /// The supercategory is not the dataset's name, as in BOP's files, but fixed: the same
    /// options must give the same bytes in any folder.
    fn write(&self, dir: &Path, categories: &[u32]) -> Result<()> {
        let categories: Vec<serde_json::Value> = categories
            .iter()
            .map(|id| serde_json::json!({"id": id, "name": id.to_string(), "supercategory": "synthetic"}))
            .collect();
        for (file, modal) in [
            ("scene_gt_coco.json", false),
            ("scene_gt_coco_modal.json", true),
        ] {
            let annotations: Vec<serde_json::Value> = self
                .annotations
                .iter()
                .map(|(fields, amodal_box, modal_box)| {
                    let mut a = fields.clone();
                    a["bbox"] = serde_json::json!(if modal { modal_box } else { amodal_box });
                    a
                })
                .collect();
            let content = serde_json::json!({
                "images": self.images, "annotations": annotations, "categories": categories,
            });
            std::fs::write(dir.join(file), content.to_string())?;
        }
        Ok(())
    }
}

/// Special instances an image gets besides its cluster of objects.
#[derive(Clone, Copy)]
struct Roles {
    /// One cut by the left or right image border.
    truncated: bool,
    /// One almost completely hidden behind another object.
    hidden: bool,
}

struct ImageData {
    gt: Vec<GtEntry>,
    info: Vec<GtInfo>,
    masks: Vec<VisibleMask>,
    depth: Vec<u16>,
    rgb: Vec<u8>,
}

/// An object instance standing on the table.
struct Placed {
    shape: usize,
    model_to_world: Pose,
    /// Convex hull of its footprint on the table (world x, y), counter-clockwise.
    hull: Vec<[f64; 2]>,
    /// Largest distance of the footprint from `centre()`, for a quick test before the exact one.
    radius: f64,
}

impl Placed {
    /// `shape` resting in `rest` orientation, turned by `yaw`, its origin above the world origin.
    fn new(shape: &Shape, index: usize, rest: &Mat3, yaw: f64) -> Placed {
        let r = rotation(Vec3::z(), yaw) * rest;
        let points: Vec<Vec3> = shape.mesh.vertices.iter().map(|v| r * v.coords).collect();
        let bottom = points.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let hull = convex_hull(points.iter().map(|p| [p.x, p.y]).collect());
        Placed {
            shape: index,
            model_to_world: Pose::new(r, Vec3::new(0.0, 0.0, -bottom)),
            radius: hull.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max),
            hull,
        }
    }

    fn random(rng: &mut ChaCha8Rng, shapes: &[Shape], index: usize) -> Placed {
        let shape = &shapes[index];
        let rest = shape.rests[rng.random_range(0..shape.rests.len())];
        Placed::new(shape, index, &rest, rng.random_range(0.0..TAU))
    }

    /// Where the model origin stands on the table.
    fn centre(&self) -> [f64; 2] {
        [self.model_to_world.t.x, self.model_to_world.t.y]
    }

    fn shifted(mut self, by: [f64; 2]) -> Placed {
        self.model_to_world.t.x += by[0];
        self.model_to_world.t.y += by[1];
        for p in &mut self.hull {
            p[0] += by[0];
            p[1] += by[1];
        }
        self
    }

    fn moved_to(self, at: [f64; 2]) -> Placed {
        let c = self.centre();
        self.shifted([at[0] - c[0], at[1] - c[1]])
    }

    fn clear_of(&self, others: &[Placed]) -> bool {
        let on_table = self
            .hull
            .iter()
            .all(|p| p[0].abs() < TABLE_HALF_SIZE[0] && p[1].abs() < TABLE_HALF_SIZE[1]);
        on_table
            && others.iter().all(|o| {
                let (a, b) = (self.centre(), o.centre());
                let far = (a[0] - b[0]).hypot(a[1] - b[1]) > self.radius + o.radius + CLEARANCE;
                far || separated(&self.hull, &o.hull)
            })
    }

    /// Placed at `from`, then pushed along the unit vector `dir` until it no longer
    /// intersects `others`: the objects end up next to each other, as on a real table.
    fn slid(self, from: [f64; 2], dir: [f64; 2], others: &[Placed]) -> Option<Placed> {
        let mut p = self.moved_to(from);
        for _ in 0..SLIDE_STEPS {
            if p.clear_of(others) {
                return Some(p);
            }
            p = p.shifted([dir[0] * SLIDE_STEP, dir[1] * SLIDE_STEP]);
        }
        None
    }
}

/// Andrew's monotone chain; the result is counter-clockwise without repeated points.
fn convex_hull(mut points: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    points.dedup();
    let turn = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let chain = |points: &mut dyn Iterator<Item = &[f64; 2]>| {
        let mut chain: Vec<[f64; 2]> = Vec::new();
        for &p in points {
            while chain.len() >= 2 && turn(chain[chain.len() - 2], chain[chain.len() - 1], p) <= 0.0
            {
                chain.pop();
            }
            chain.push(p);
        }
        chain.pop();
        chain
    };
    let mut hull = chain(&mut points.iter());
    hull.extend(chain(&mut points.iter().rev()));
    hull
}

/// Whether two convex polygons are at least `CLEARANCE` apart along one of their edge
/// normals (the separating axis theorem).
fn separated(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    let extent = |poly: &[[f64; 2]], axis: [f64; 2]| {
        poly.iter()
            .map(|p| p[0] * axis[0] + p[1] * axis[1])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    [a, b].into_iter().any(|poly| {
        (0..poly.len()).any(|i| {
            let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
            let len = (q[0] - p[0]).hypot(q[1] - p[1]);
            let axis = [(q[1] - p[1]) / len, (p[0] - q[0]) / len];
            let (a0, a1) = extent(a, axis);
            let (b0, b1) = extent(b, axis);
            a1 + CLEARANCE <= b0 || b1 + CLEARANCE <= a0
        })
    })
}

/// A unit vector in the table plane at `angle` from the x axis.
fn direction(angle: f64) -> [f64; 2] {
    [angle.cos(), angle.sin()]
}

/// The camera of one image; world frame: the table top is z = 0, z up.
struct View {
    w2c: Pose,
    eye: Vec3,
    width: u32,
    height: u32,
    k: Intrinsics,
    /// The same camera on bop_toolkit's canvas three times the image size, whose centre third
    /// is the image: renders there include what lies beyond the image border.
    k_large: Intrinsics,
}

impl View {
    fn looking_at(eye: Vec3, target: Vec3, (width, height): (u32, u32)) -> View {
        let z = (target - eye).normalize();
        let x = z.cross(&Vec3::z()).normalize();
        let y = z.cross(&x);
        let r = Mat3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let k = cam_k((width, height));
        let mut large = k;
        large[2] += f64::from(width);
        large[5] += f64::from(height);
        View {
            w2c: Pose::new(r, -(r * eye)),
            eye,
            width,
            height,
            k: Intrinsics::from_row_major(&k),
            k_large: Intrinsics::from_row_major(&large),
        }
    }

    /// The camera ray through image point (u, v), in camera coordinates.
    fn ray(&self, u: f64, v: f64) -> Vec3 {
        let k = &self.k;
        Vec3::new((u - k.cx()) / k.fx(), (v - k.cy()) / k.fy(), 1.0)
    }

    /// Where the ray through image point (u, v) meets the table plane (world x, y), if it does.
    fn on_table(&self, u: f64, v: f64) -> Option<[f64; 2]> {
        let dir = self.w2c.r.transpose() * self.ray(u, v);
        if dir.z >= 0.0 {
            return None;
        }
        let p = self.eye + dir * (-self.eye.z / dir.z);
        Some([p.x, p.y])
    }

    fn model_to_camera(&self, p: &Placed) -> Pose {
        self.w2c.compose(&p.model_to_world)
    }

    fn render(&self, renderer: &mut Renderer, shape: &Shape, pose: &Pose) -> DepthWindow {
        let corners = shape.mesh.bbox_corners();
        renderer.render(
            &shape.mesh,
            &corners,
            pose,
            &self.k_large,
            3 * self.width,
            3 * self.height,
        )
    }
}

/// Calls `f(x, y, depth)` for the pixels of a render on the large canvas that lie in the image
/// of `width` x `height`.
fn for_each_in_image(
    w: &DepthWindow,
    (width, height): (u32, u32),
    mut f: impl FnMut(u32, u32, f32),
) {
    let xs = w.x0.max(width)..(w.x0 + w.width).min(2 * width);
    for y in w.y0.max(height)..(w.y0 + w.height).min(2 * height) {
        for x in xs.clone() {
            let d = w.data[((y - w.y0) * w.width + x - w.x0) as usize];
            if d > 0.0 {
                f(x - width, y - height, d);
            }
        }
    }
}

/// The noiseless scene: nearest surface depth (mm, 0 = none) and what it belongs to.
struct Canvas {
    width: u32,
    height: u32,
    depth: Vec<f32>,
    label: Vec<u8>,
}

impl Canvas {
    fn table(view: &View) -> Canvas {
        let (width, height) = (view.width, view.height);
        let size = (width * height) as usize;
        let mut canvas = Canvas {
            width,
            height,
            depth: vec![0.0; size],
            label: vec![0; size],
        };
        // Plain arithmetic rather than nalgebra, whose generic code is slow in unoptimised
        // builds, as this runs for every pixel. The ray through (u, v) has camera z 1, so its
        // world direction is a x + b y + z (the camera axes in world coordinates, the rows of
        // w2c.r), and where it meets the table its depth is the ray parameter.
        let r = &view.w2c.r;
        let axis = |row: usize| [r[(row, 0)], r[(row, 1)], r[(row, 2)]];
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        let (k, eye) = (&view.k, view.eye);
        for y in 0..height {
            // Sampled at the pixel centre, like the renderer.
            let b = (f64::from(y) + 0.5 - k.cy()) / k.fy();
            let row = [b * ay[0] + az[0], b * ay[1] + az[1], b * ay[2] + az[2]];
            for x in 0..width {
                let a = (f64::from(x) + 0.5 - k.cx()) / k.fx();
                let dir = [a * ax[0] + row[0], a * ax[1] + row[1], a * ax[2] + row[2]];
                let z = -eye.z / dir[2];
                if !z.is_finite() || z <= 0.0 {
                    continue;
                }
                let (wx, wy) = (eye.x + z * dir[0], eye.y + z * dir[1]);
                if wx.abs() > TABLE_HALF_SIZE[0] || wy.abs() > TABLE_HALF_SIZE[1] {
                    continue;
                }
                // 50 mm squares.
                let square = ((wx / 50.0).floor() + (wy / 50.0).floor()) as i64;
                let i = (y * width + x) as usize;
                canvas.depth[i] = z as f32;
                canvas.label[i] = 1 + square.rem_euclid(2) as u8;
            }
        }
        canvas
    }

    fn add(&mut self, render: &DepthWindow, label: u8) {
        let width = self.width;
        for_each_in_image(render, (width, self.height), |x, y, d| {
            let i = (y * width + x) as usize;
            if self.depth[i] == 0.0 || d < self.depth[i] {
                self.depth[i] = d;
                self.label[i] = label;
            }
        });
    }

    /// The fraction of the silhouette of `render` (inside the image or not) in front of
    /// everything on the canvas.
    fn visible_fraction(&self, render: &DepthWindow) -> f64 {
        let mut seen = 0usize;
        for_each_in_image(render, (self.width, self.height), |x, y, d| {
            let here = self.depth[(y * self.width + x) as usize];
            if here == 0.0 || d <= here {
                seen += 1;
            }
        });
        seen as f64 / render.count_nonzero().max(1) as f64
    }
}

/// One image of `size`. The scene is laid out (and its hidden instance placed) at 640 x 480
/// before anything is drawn at `size`, so the ground truth is the same at every size.
fn make_image(rng: &mut ChaCha8Rng, shapes: &[Shape], roles: Roles, size: (u32, u32)) -> ImageData {
    let (eye, target) = camera(rng);
    let base = View::looking_at(eye, target, (WIDTH, HEIGHT));
    let mut placed = lay_out(rng, shapes, &base, target, roles);
    let mut renderer = Renderer::new();
    let draw = |view: &View, renderer: &mut Renderer, placed: &[Placed]| {
        let renders: Vec<DepthWindow> = placed
            .iter()
            .map(|p| view.render(renderer, &shapes[p.shape], &view.model_to_camera(p)))
            .collect();
        let mut canvas = Canvas::table(view);
        for (i, r) in renders.iter().enumerate() {
            canvas.add(r, FIRST_INSTANCE_LABEL + i as u8);
        }
        (renders, canvas)
    };
    let (mut renders, mut canvas) = draw(&base, &mut renderer, &placed);
    if let Some(tower) = placed
        .first()
        .filter(|p| roles.hidden && p.shape == TOWER.0)
    {
        let hidden = hide_one(rng, shapes, &base, tower, &placed, &canvas, &mut renderer);
        if let Some((p, render)) = hidden {
            canvas.add(&render, FIRST_INSTANCE_LABEL + placed.len() as u8);
            placed.push(p);
            renders.push(render);
        }
    }
    let view = if size == (WIDTH, HEIGHT) {
        base
    } else {
        let view = View::looking_at(eye, target, size);
        (renders, canvas) = draw(&view, &mut renderer, &placed);
        view
    };

    let (width, height) = size;
    let depth = sensor(rng, &canvas.depth, size);
    let rays = PixelRays::new(&view.k, width, height);
    let scale = DEPTH_SCALE as f32;
    let mut measured = Vec::with_capacity(depth.len());
    for y in 0..height {
        for x in 0..width {
            // The millimetres the evaluator reads: f32 value times f32 scale.
            let mm = f32::from(depth[(y * width + x) as usize]) * scale;
            measured.push(rays.distance(x, y, mm));
        }
    }
    let (info, masks) = renders
        .iter()
        .map(|r| gt_info(r, size, &rays, &measured))
        .unzip();
    let gt = placed
        .iter()
        .map(|p| {
            let pose = view.model_to_camera(p);
            GtEntry {
                cam_r_m2c: std::array::from_fn(|i| pose.r[(i / 3, i % 3)]),
                cam_t_m2c: [pose.t.x, pose.t.y, pose.t.z],
                obj_id: shapes[p.shape].id,
            }
        })
        .collect();
    let colours: Vec<[u8; 3]> = placed.iter().map(|p| shapes[p.shape].colour).collect();
    ImageData {
        gt,
        info,
        masks,
        depth,
        rgb: colour_image(&view, &canvas, &colours),
    }
}

/// A camera looking down at the table from 30 to 60 degrees above it, and the point on the
/// table it looks at.
fn camera(rng: &mut ChaCha8Rng) -> (Vec3, Vec3) {
    let elevation = rng.random_range(30f64..60.0).to_radians();
    let azimuth = rng.random_range(0.0..TAU);
    let distance = rng.random_range(620.0..880.0);
    let target = Vec3::new(
        rng.random_range(-40.0..40.0),
        rng.random_range(-40.0..40.0),
        0.0,
    );
    let eye = target
        + distance
            * Vec3::new(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            );
    (eye, target)
}

/// A cluster of objects next to each other around `target`, plus the special instances of
/// `roles` but the hidden one, which needs the rendered scene.
fn lay_out(
    rng: &mut ChaCha8Rng,
    shapes: &[Shape],
    view: &View,
    target: Vec3,
    roles: Roles,
) -> Vec<Placed> {
    let extras = usize::from(roles.truncated) + usize::from(roles.hidden);
    let count = rng.random_range(3..=5usize).saturating_sub(extras).max(3);
    let mut kinds: Vec<usize> = (0..shapes.len()).collect();
    kinds.shuffle(rng);
    kinds.truncate(count);
    if roles.hidden {
        kinds[0] = TOWER.0;
    }
    // Now and then a second instance of the same object.
    if rng.random_bool(0.4) {
        kinds[count - 1] = kinds[0];
    }
    let mut placed: Vec<Placed> = Vec::new();
    for (n, kind) in kinds.into_iter().enumerate() {
        for _ in 0..TRIES {
            // The first object of an image with a hidden instance stands tall, to hide it.
            let p = if roles.hidden && n == 0 {
                let (tower, rest) = TOWER;
                let yaw = rng.random_range(0.0..TAU);
                Placed::new(&shapes[tower], tower, &shapes[tower].rests[rest], yaw)
            } else {
                Placed::random(rng, shapes, kind)
            };
            let from = match placed.len() {
                0 => [target.x, target.y],
                n => placed[rng.random_range(0..n)].centre(),
            };
            let dir = direction(rng.random_range(0.0..TAU));
            let Some(p) = p.slid(from, dir, &placed) else {
                continue;
            };
            let c = p.centre();
            if (c[0] - target.x).hypot(c[1] - target.y) < CLUSTER_RADIUS {
                placed.push(p);
                break;
            }
        }
    }
    if roles.truncated {
        for _ in 0..TRIES {
            let kind = rng.random_range(0..shapes.len());
            let p = Placed::random(rng, shapes, kind);
            let inset = rng.random_range(-10.0..30.0);
            let u = if rng.random_bool(0.5) {
                inset
            } else {
                f64::from(view.width) - inset
            };
            let v = rng.random_range(0.35..0.7) * f64::from(view.height);
            let Some(at) = view.on_table(u, v) else {
                continue;
            };
            let p = p.moved_to(at);
            if p.clear_of(&placed) {
                placed.push(p);
                break;
            }
        }
    }
    placed
}

/// An instance right behind `occluder`, as seen from the camera, of which only a sliver
/// shows: pushed away from the occluder step by step until a little of it appears.
fn hide_one(
    rng: &mut ChaCha8Rng,
    shapes: &[Shape],
    view: &View,
    occluder: &Placed,
    placed: &[Placed],
    canvas: &Canvas,
    renderer: &mut Renderer,
) -> Option<(Placed, DepthWindow)> {
    for _ in 0..3 * TRIES {
        let kind = rng.random_range(0..shapes.len());
        let c = occluder.centre();
        let away = (c[1] - view.eye.y).atan2(c[0] - view.eye.x);
        let dir = direction(away + rng.random_range(-0.3..0.3));
        let Some(mut p) = Placed::random(rng, shapes, kind).slid(c, dir, placed) else {
            continue;
        };
        for _ in 0..SLIDE_STEPS {
            let render = view.render(renderer, &shapes[p.shape], &view.model_to_camera(&p));
            let seen = canvas.visible_fraction(&render);
            if HIDDEN_VISIB.contains(&seen) {
                return Some((p, render));
            }
            if seen > *HIDDEN_VISIB.end() {
                break;
            }
            p = p.shifted([dir[0] * SLIDE_STEP, dir[1] * SLIDE_STEP]);
            if !p.clear_of(placed) {
                break;
            }
        }
    }
    None
}

/// The depth image as a sensor would deliver it: Gaussian noise, quantised to units of
/// `DEPTH_SCALE`, no measurement on the far side of depth edges, and small holes.
fn sensor(rng: &mut ChaCha8Rng, clean: &[f32], (width, height): (u32, u32)) -> Vec<u16> {
    let mut depth: Vec<u16> = clean
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                return 0;
            }
            let noise: f64 = rng.sample(StandardNormal);
            let units = ((f64::from(d) + NOISE_SIGMA_MM * noise) / DEPTH_SCALE).round();
            if (1.0..=f64::from(u16::MAX)).contains(&units) {
                units as u16
            } else {
                0
            }
        })
        .collect();

    // A pixel just beyond a jump in depth lies in the shadow of the nearer surface, where
    // the sensor measures nothing.
    let (w, h) = (width as usize, height as usize);
    let limit = DISCONTINUITY_MM / DEPTH_SCALE;
    let behind = |d: u16, other: u16| other > 0 && f64::from(d) - f64::from(other) > limit;
    let shadowed: Vec<usize> = (0..w * h)
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            let d = depth[i];
            (x > 0 && behind(d, depth[i - 1]))
                || (x + 1 < w && behind(d, depth[i + 1]))
                || (y > 0 && behind(d, depth[i - w]))
                || (y + 1 < h && behind(d, depth[i + w]))
        })
        .collect();
    for i in shadowed {
        depth[i] = 0;
    }

    let mut covered = 0.0;
    while covered < HOLE_FRACTION * (w * h) as f64 {
        let (cx, cy) = (rng.random_range(0..w as i64), rng.random_range(0..h as i64));
        let r = rng.random_range(1..=4i64);
        for y in (cy - r).max(0)..=(cy + r).min(h as i64 - 1) {
            for x in (cx - r).max(0)..=(cx + r).min(w as i64 - 1) {
                if (x - cx).pow(2) + (y - cy).pow(2) <= r * r {
                    depth[y as usize * w + x as usize] = 0;
                    covered += 1.0;
                }
            }
        }
    }
    depth
}

/// Min and max corner of a set of pixels.
#[derive(Default)]
struct Bounds(Option<[i64; 4]>);

impl Bounds {
    fn add(&mut self, x: i64, y: i64) {
        let b = self.0.get_or_insert([x, y, x, y]);
        *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
    }

    /// bop_toolkit's `calc_2d_bbox`: [x, y, w, h] with w = max - min (a single pixel has
    /// width 0), not clipped to the image.
    fn bbox(&self) -> [i64; 4] {
        self.0
            .map_or([-1; 4], |[x0, y0, x1, y1]| [x0, y0, x1 - x0, y1 - y0])
    }
}

/// `calc_gt_info.py` for one instance rendered on the large canvas, against the distance map
/// of the measured depth.
fn gt_info(
    render: &DepthWindow,
    (width, height): (u32, u32),
    rays: &PixelRays,
    measured: &[f64],
) -> (GtInfo, VisibleMask) {
    let mut all = Bounds::default();
    let mut px_count_all = 0;
    for y in 0..render.height {
        for x in 0..render.width {
            if render.data[(y * render.width + x) as usize] > 0.0 {
                px_count_all += 1;
                all.add(
                    i64::from(render.x0 + x) - i64::from(width),
                    i64::from(render.y0 + y) - i64::from(height),
                );
            }
        }
    }
    let (mut px_count_valid, mut px_count_visib) = (0, 0);
    let mut visib = Bounds::default();
    let mut mask = vec![false; (width * height) as usize];
    for_each_in_image(render, (width, height), |x, y, d| {
        let test = measured[(y * width + x) as usize];
        if test > 0.0 {
            px_count_valid += 1;
        }
        if visible(VisibMode::Bop19, test, rays.distance(x, y, d), VISIB_DELTA) {
            px_count_visib += 1;
            visib.add(i64::from(x), i64::from(y));
            mask[(y * width + x) as usize] = true;
        }
    });
    let visible_mask = VisibleMask {
        rle: Rle::encode_row_major(&mask, height, width)
            .expect("a mask of the image's size encodes"),
        // pycoco_utils' `bbox_from_binary_mask`: a single pixel is 1 wide.
        bbox: visib
            .0
            .map(|[x0, y0, x1, y1]| [x0, y0, x1 - x0 + 1, y1 - y0 + 1]),
    };
    let info = GtInfo {
        // bop_toolkit leaves the object's box unset too when nothing of it is visible.
        bbox_obj: if px_count_visib > 0 {
            all.bbox()
        } else {
            [-1; 4]
        },
        bbox_visib: visib.bbox(),
        px_count_all,
        px_count_valid,
        px_count_visib,
        visib_fract: if px_count_all > 0 {
            px_count_visib as f64 / px_count_all as f64
        } else {
            0.0
        },
    };
    (info, visible_mask)
}

/// The visible part of an instance, as `mask_visib/` holds it: what the COCO ground truth is
/// made of.
struct VisibleMask {
    rle: Rle,
    /// The box around it (modal); `None` when nothing of the instance is visible.
    bbox: Option<[i64; 4]>,
}

/// Flat colours, lit by a light above the camera using normals from the noiseless depth.
fn colour_image(view: &View, canvas: &Canvas, colours: &[[u8; 3]]) -> Vec<u8> {
    let light = Vec3::new(0.2, -0.5, -1.0).normalize();
    let (width, height) = (canvas.width, canvas.height);
    let point = |x: u32, y: u32| {
        let d = f64::from(canvas.depth[(y * width + x) as usize]);
        view.ray(f64::from(x) + 0.5, f64::from(y) + 0.5) * d
    };
    let mut rgb = Vec::with_capacity((width * height * 3) as usize);
    for y in 0..height {
        for x in 0..width {
            let i = (y * width + x) as usize;
            let label = canvas.label[i];
            let colour = match label {
                0 => BACKGROUND,
                1 | 2 => TABLE_COLOURS[usize::from(label - 1)],
                _ => {
                    let base = colours[usize::from(label - FIRST_INSTANCE_LABEL)];
                    let same = |j: usize| canvas.label[j] == label;
                    let shade = if x + 1 < width
                        && y + 1 < height
                        && same(i + 1)
                        && same(i + width as usize)
                    {
                        let p = point(x, y);
                        let n = (point(x, y + 1) - p).cross(&(point(x + 1, y) - p));
                        let n = n.normalize();
                        let n = if n.z > 0.0 { -n } else { n };
                        0.35 + 0.65 * n.dot(&light).max(0.0)
                    } else {
                        0.7
                    };
                    base.map(|c| (f64::from(c) * shade).round() as u8)
                }
            };
            rgb.extend_from_slice(&colour);
        }
    }
    rgb
}
