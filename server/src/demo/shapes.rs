//! The object models, built from a few primitives rather than shipped as files, so the demo
//! needs no assets and each shape can be chosen for what it exercises in the evaluation: an
//! asymmetric object, discrete symmetries whose transformations carry a translation, continuous
//! symmetries with and without a flip, and a shape symmetric only about an in-plane axis.
//!
//! Vertices are rounded to `f32` as soon as a shape is built, so that the generator renders
//! exactly the geometry the PLY files hold and the evaluator will read back.

use std::path::Path;

use anyhow::Result;
use evaluator::math::{Mat3, Pose, Pt3, Vec3};
use evaluator::mesh::Mesh;
use nalgebra::{Unit, UnitQuaternion};
use serde::Serialize;

use super::files::{write_json_object, write_ply};

/// Segments around the axis of the round shapes: fine enough that the declared continuous
/// symmetry is a good description of the mesh.
const ROUND_SEGMENTS: usize = 48;

/// How many shapes [`shapes`] makes.
pub(super) const SHAPES: u32 = 6;

pub(super) struct Shape {
    pub id: u32,
    pub mesh: Mesh,
    /// Outward unit normal of each vertex.
    pub normals: Vec<Vec3>,
    /// Proper rotations (with translations, mm) that map the model onto itself.
    pub symmetries_discrete: Vec<Pose>,
    /// Axis through the model origin of a continuous rotational symmetry.
    pub continuous_axis: Option<Vec3>,
    /// Orientations in which the shape rests stably on a table (model to world rotations,
    /// world z up), before the random rotation about the vertical.
    pub rests: Vec<Mat3>,
    /// Flat colour in the RGB images.
    pub colour: [u8; 3],
}

/// The tallest stable pose among the shapes (index, rest): the carton standing on its end,
/// behind which smaller objects can hide.
pub(super) const TOWER: (usize, usize) = (1, 2);

/// The demo's objects, ids 1 to 6.
pub(super) fn shapes() -> Vec<Shape> {
    let down = |x: f64, y: f64, z: f64| rest_on(Vec3::new(x, y, z));
    vec![
        // 1: an L-bracket with unequal arms: no proper symmetry at all. Centred on its
        // bounding box, like BOP models, whose origin lies inside the object.
        finish(
            1,
            centred(extrude(
                &[
                    [0.0, 0.0],
                    [110.0, 0.0],
                    [110.0, 14.0],
                    [14.0, 14.0],
                    [14.0, 70.0],
                    [0.0, 70.0],
                ],
                40.0,
            )),
            Vec::new(),
            None,
            vec![
                down(0.0, 0.0, -1.0),
                down(0.0, 0.0, 1.0),
                down(0.0, -1.0, 0.0),
            ],
            [214, 93, 62],
        ),
        // 2: a carton 140 x 80 x 50 with its origin at the centre of the bottom face, so two
        // of its half turns need a translation of the box height. Standing, it hides things.
        finish(
            2,
            extrude(
                &[[-70.0, -40.0], [70.0, -40.0], [70.0, 40.0], [-70.0, 40.0]],
                50.0,
            ),
            vec![
                half_turn(Vec3::z(), 0.0),
                half_turn(Vec3::x(), 50.0),
                half_turn(Vec3::y(), 50.0),
            ],
            None,
            vec![
                down(0.0, 0.0, -1.0),
                down(0.0, 1.0, 0.0),
                down(1.0, 0.0, 0.0),
            ],
            [70, 130, 200],
        ),
        // 3: a can, continuous about its axis plus an upside-down flip.
        finish(
            3,
            can(33.0, 100.0),
            vec![half_turn(Vec3::x(), 100.0)],
            Some(Vec3::z()),
            vec![down(0.0, 0.0, -1.0), down(0.0, 1.0, 0.0)],
            [235, 190, 60],
        ),
        // 4: a cone, continuous about its axis but with no flip.
        finish(
            4,
            cone(35.0, 70.0),
            Vec::new(),
            Some(Vec3::z()),
            // Upright, or lying on its side (the outward normal of one generator pointing down).
            vec![down(0.0, 0.0, -1.0), down(0.0, 70.0, 35.0)],
            [90, 180, 110],
        ),
        // 5: a small ring centred on its origin: continuous plus a flip without translation.
        finish(
            5,
            torus(26.0, 8.0),
            vec![half_turn(Vec3::x(), 0.0)],
            Some(Vec3::z()),
            vec![down(0.0, 0.0, -1.0)],
            [170, 90, 190],
        ),
        // 6: a T, symmetric only under a half turn about its stem (through the origin).
        finish(
            6,
            centred(extrude(
                &[
                    [-12.0, 0.0],
                    [12.0, 0.0],
                    [12.0, 70.0],
                    [45.0, 70.0],
                    [45.0, 94.0],
                    [-45.0, 94.0],
                    [-45.0, 70.0],
                    [-12.0, 70.0],
                ],
                24.0,
            )),
            vec![half_turn(Vec3::y(), 0.0)],
            None,
            vec![
                down(0.0, 0.0, -1.0),
                down(0.0, -1.0, 0.0),
                down(0.0, 1.0, 0.0),
            ],
            [60, 180, 190],
        ),
    ]
}

fn finish(
    id: u32,
    built: Builder,
    symmetries_discrete: Vec<Pose>,
    continuous_axis: Option<Vec3>,
    rests: Vec<Mat3>,
    colour: [u8; 3],
) -> Shape {
    let vertices = built
        .vertices
        .iter()
        .map(|p| Pt3::new(p.x as f32 as f64, p.y as f32 as f64, p.z as f32 as f64))
        .collect();
    Shape {
        id,
        mesh: Mesh {
            vertices,
            triangles: built.triangles,
        },
        normals: built.normals,
        symmetries_discrete,
        continuous_axis,
        rests,
        colour,
    }
}

/// Moves the origin to the centre of the bounding box.
fn centred(mut b: Builder) -> Builder {
    let (mut lo, mut hi) = (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY));
    for v in &b.vertices {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    let centre = (lo + hi) / 2.0;
    for v in &mut b.vertices {
        *v -= centre;
    }
    b
}

/// The rotation that turns the face with outward normal `normal` (model frame) to face down.
fn rest_on(normal: Vec3) -> Mat3 {
    UnitQuaternion::rotation_between(&normal.normalize(), &-Vec3::z())
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vec3::x_axis(), std::f64::consts::PI))
        .to_rotation_matrix()
        .into_inner()
}

/// A half turn about a coordinate axis through the origin, then a shift of `lift` along z:
/// written with exact entries so models_info.json holds clean 1, -1 and 0.
fn half_turn(axis: Vec3, lift: f64) -> Pose {
    let r = Mat3::from_diagonal(&axis.map(|a| if a != 0.0 { 1.0 } else { -1.0 }));
    Pose::new(r, Vec3::new(0.0, 0.0, lift))
}

/// Triangles with per-vertex normals; a flat face gets vertices of its own so its normal is
/// the face's.
#[derive(Default)]
struct Builder {
    vertices: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.vertices.push(p);
        self.normals.push(n.normalize());
        (self.vertices.len() - 1) as u32
    }
}

/// A prism: the counter-clockwise polygon `outline` (xy) extruded from z = 0 to `height`.
fn extrude(outline: &[[f64; 2]], height: f64) -> Builder {
    let mut b = Builder::default();
    let caps = triangulate(outline);
    for (z, normal) in [(0.0, -Vec3::z()), (height, Vec3::z())] {
        let first = b.vertices.len() as u32;
        for p in outline {
            b.vertex(Vec3::new(p[0], p[1], z), normal);
        }
        for &[i, j, k] in &caps {
            let [i, j, k] = [i, j, k].map(|n| first + n as u32);
            // The bottom cap faces down: reversed winding.
            b.triangles
                .push(if z == 0.0 { [i, k, j] } else { [i, j, k] });
        }
    }
    for (i, p) in outline.iter().enumerate() {
        let q = outline[(i + 1) % outline.len()];
        // Right of a counter-clockwise edge is outside.
        let normal = Vec3::new(q[1] - p[1], p[0] - q[0], 0.0);
        let a = b.vertex(Vec3::new(p[0], p[1], 0.0), normal);
        let c = b.vertex(Vec3::new(q[0], q[1], 0.0), normal);
        let d = b.vertex(Vec3::new(q[0], q[1], height), normal);
        let e = b.vertex(Vec3::new(p[0], p[1], height), normal);
        b.triangles.push([a, c, d]);
        b.triangles.push([a, d, e]);
    }
    b
}

/// Ear clipping of a simple counter-clockwise polygon; indices into `poly`.
fn triangulate(poly: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let cross = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut left: Vec<usize> = (0..poly.len()).collect();
    let mut out = Vec::new();
    while left.len() > 3 {
        let n = left.len();
        let corners = |i: usize| [left[(i + n - 1) % n], left[i], left[(i + 1) % n]];
        let ear = (0..n)
            .find(|&i| {
                let [a, b, c] = corners(i).map(|k| poly[k]);
                cross(a, b, c) > 0.0
                    && left.iter().all(|&k| {
                        let p = poly[k];
                        [a, b, c].contains(&p)
                            || cross(a, b, p) < 0.0
                            || cross(b, c, p) < 0.0
                            || cross(c, a, p) < 0.0
                    })
            })
            .expect("every simple polygon has an ear");
        out.push(corners(ear));
        left.remove(ear);
    }
    out.push([left[0], left[1], left[2]]);
    out
}

fn ring(radius: f64, z: f64) -> impl Iterator<Item = Vec3> {
    (0..ROUND_SEGMENTS).map(move |k| {
        let a = std::f64::consts::TAU * k as f64 / ROUND_SEGMENTS as f64;
        Vec3::new(radius * a.cos(), radius * a.sin(), z)
    })
}

/// A flat disc at height `z` facing `normal` (+z or -z).
fn disc(b: &mut Builder, radius: f64, z: f64, normal: Vec3) {
    let centre = b.vertex(Vec3::new(0.0, 0.0, z), normal);
    let first = b.vertices.len() as u32;
    for p in ring(radius, z) {
        b.vertex(p, normal);
    }
    let n = ROUND_SEGMENTS as u32;
    for k in 0..n {
        let (i, j) = (first + k, first + (k + 1) % n);
        b.triangles.push(if normal.z > 0.0 {
            [centre, i, j]
        } else {
            [centre, j, i]
        });
    }
}

/// A closed cylinder of `radius` from z = 0 to `height`.
fn can(radius: f64, height: f64) -> Builder {
    let mut b = Builder::default();
    disc(&mut b, radius, 0.0, -Vec3::z());
    disc(&mut b, radius, height, Vec3::z());
    let first = b.vertices.len() as u32;
    for (bottom, top) in ring(radius, 0.0).zip(ring(radius, height)) {
        let normal = Vec3::new(bottom.x, bottom.y, 0.0);
        b.vertex(bottom, normal);
        b.vertex(top, normal);
    }
    let n = ROUND_SEGMENTS as u32;
    for k in 0..n {
        let (b0, t0) = (first + 2 * k, first + 2 * k + 1);
        let (b1, t1) = (first + 2 * ((k + 1) % n), first + 2 * ((k + 1) % n) + 1);
        b.triangles.push([b0, b1, t1]);
        b.triangles.push([b0, t1, t0]);
    }
    b
}

/// A cone with its base disc of `radius` at z = 0 and its apex at `height`.
fn cone(radius: f64, height: f64) -> Builder {
    let mut b = Builder::default();
    disc(&mut b, radius, 0.0, -Vec3::z());
    let side_normal = |p: Vec3| Vec3::new(height * p.x, height * p.y, radius * radius);
    let base: Vec<Vec3> = ring(radius, 0.0).collect();
    let n = base.len();
    for k in 0..n {
        let (p, q) = (base[k], base[(k + 1) % n]);
        let a = b.vertex(p, side_normal(p));
        let c = b.vertex(q, side_normal(q));
        // One apex vertex per segment, with the normal of the segment's middle.
        let apex = b.vertex(Vec3::new(0.0, 0.0, height), side_normal(p + q));
        b.triangles.push([a, c, apex]);
    }
    b
}

/// A torus about z: `major` radius of the tube's centre line, `minor` radius of the tube.
fn torus(major: f64, minor: f64) -> Builder {
    const AROUND_TUBE: usize = 16;
    let mut b = Builder::default();
    for i in 0..ROUND_SEGMENTS {
        let u = std::f64::consts::TAU * i as f64 / ROUND_SEGMENTS as f64;
        for j in 0..AROUND_TUBE {
            let v = std::f64::consts::TAU * j as f64 / AROUND_TUBE as f64;
            let normal = Vec3::new(v.cos() * u.cos(), v.cos() * u.sin(), v.sin());
            let centre = Vec3::new(major * u.cos(), major * u.sin(), 0.0);
            b.vertex(centre + minor * normal, normal);
        }
    }
    let index = |i: usize, j: usize| ((i % ROUND_SEGMENTS) * AROUND_TUBE + j % AROUND_TUBE) as u32;
    for i in 0..ROUND_SEGMENTS {
        for j in 0..AROUND_TUBE {
            let (a, c) = (index(i, j), index(i + 1, j + 1));
            b.triangles.push([a, index(i + 1, j), c]);
            b.triangles.push([a, c, index(i, j + 1)]);
        }
    }
    b
}

/// The largest distance between two vertices, bop_toolkit's model diameter.
pub(super) fn diameter(mesh: &Mesh) -> f64 {
    let v = &mesh.vertices;
    let mut best = 0.0f64;
    for (i, a) in v.iter().enumerate() {
        for b in &v[i + 1..] {
            best = best.max((a - b).norm_squared());
        }
    }
    best.sqrt()
}

#[derive(Serialize)]
struct ContinuousInfo {
    axis: [f64; 3],
    offset: [f64; 3],
}

/// One entry of models_info.json, keys in bop_toolkit's (sorted) order.
#[derive(Serialize)]
struct ModelInfo {
    diameter: f64,
    min_x: f64,
    min_y: f64,
    min_z: f64,
    size_x: f64,
    size_y: f64,
    size_z: f64,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    symmetries_continuous: Vec<ContinuousInfo>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    symmetries_discrete: Vec<[f64; 16]>,
}

fn model_info(shape: &Shape) -> ModelInfo {
    let (lo, hi) = shape.mesh.bbox();
    ModelInfo {
        diameter: diameter(&shape.mesh),
        min_x: lo.x,
        min_y: lo.y,
        min_z: lo.z,
        size_x: hi.x - lo.x,
        size_y: hi.y - lo.y,
        size_z: hi.z - lo.z,
        symmetries_continuous: shape
            .continuous_axis
            .iter()
            .map(|a| ContinuousInfo {
                axis: [a.x, a.y, a.z],
                offset: [0.0; 3],
            })
            .collect(),
        symmetries_discrete: shape
            .symmetries_discrete
            .iter()
            .map(|s| {
                let (r, t) = (s.r, s.t);
                [
                    r[(0, 0)],
                    r[(0, 1)],
                    r[(0, 2)],
                    t.x,
                    r[(1, 0)],
                    r[(1, 1)],
                    r[(1, 2)],
                    t.y,
                    r[(2, 0)],
                    r[(2, 1)],
                    r[(2, 2)],
                    t.z,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                ]
            })
            .collect(),
    }
}

/// Writes `models/` and its identical copy `models_eval/` (bop_toolkit evaluates with the
/// latter).
/// Objects 1 to `objects`: object `id` is shape `(id - 1) % shapes.len()`.
pub(super) fn write_models(root: &Path, shapes: &[Shape], objects: u32) -> Result<()> {
    let shape_of = |id: u32| &shapes[(id as usize - 1) % shapes.len()];
    let infos: Vec<(u32, ModelInfo)> = (1..=objects)
        .map(|id| (id, model_info(shape_of(id))))
        .collect();
    for folder in ["models", "models_eval"] {
        let dir = root.join(folder);
        std::fs::create_dir_all(&dir)?;
        for id in 1..=objects {
            let s = shape_of(id);
            write_ply(&dir.join(format!("obj_{id:06}.ply")), &s.mesh, &s.normals)?;
        }
        write_json_object(
            &dir.join("models_info.json"),
            infos.iter().map(|(id, i)| (id, i)),
        )?;
    }
    Ok(())
}

/// Rotation by `angle` about `axis` (need not be unit length).
pub(super) fn rotation(axis: Vec3, angle: f64) -> Mat3 {
    UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle)
        .to_rotation_matrix()
        .into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn key(p: &Pt3) -> [i64; 3] {
        [p.x, p.y, p.z].map(|c| (c * 1e3).round() as i64)
    }

    #[test]
    fn meshes_are_closed_with_outward_normals() {
        for s in shapes() {
            let m = &s.mesh;
            // Closed: every directed edge (by position) is matched by its reverse.
            let mut edges: HashMap<([i64; 3], [i64; 3]), i32> = HashMap::new();
            let mut volume = 0.0;
            for t in &m.triangles {
                let p = t.map(|i| m.vertices[i as usize]);
                for k in 0..3 {
                    let (a, b) = (key(&p[k]), key(&p[(k + 1) % 3]));
                    *edges.entry((a, b)).or_default() += 1;
                    *edges.entry((b, a)).or_default() -= 1;
                }
                let face = (p[1] - p[0]).cross(&(p[2] - p[0]));
                assert!(face.norm() > 1e-9, "object {}: degenerate triangle", s.id);
                for &i in t {
                    assert!(
                        s.normals[i as usize].dot(&face) > 0.0,
                        "object {}: vertex normal against its face",
                        s.id
                    );
                }
                volume += p[0].coords.dot(&p[1].coords.cross(&p[2].coords)) / 6.0;
            }
            assert!(edges.values().all(|&n| n == 0), "object {} is open", s.id);
            assert!(volume > 0.0, "object {} is inside out", s.id);
            assert_eq!(m.vertices.len(), s.normals.len());
        }
    }

    #[test]
    fn declared_symmetries_map_each_model_onto_itself() {
        for s in shapes() {
            let positions: std::collections::HashSet<_> = s.mesh.vertices.iter().map(key).collect();
            let mut syms = s.symmetries_discrete.clone();
            if let Some(axis) = s.continuous_axis {
                // Exact for the mesh only at multiples of the segment angle.
                let step = std::f64::consts::TAU / ROUND_SEGMENTS as f64;
                syms.push(Pose::new(rotation(axis, 5.0 * step), Vec3::zeros()));
            }
            for sym in syms {
                for v in &s.mesh.vertices {
                    let w = Pt3::from(sym.transform(v));
                    // Rounded positions of f32 vertices: allow the neighbouring key.
                    let near = (-1..=1).any(|d| {
                        let k = key(&w);
                        positions.contains(&[k[0] + d, k[1], k[2]])
                            || positions.contains(&[k[0], k[1] + d, k[2]])
                            || positions.contains(&[k[0], k[1], k[2] + d])
                    });
                    assert!(near, "object {}: {v:?} maps to {w:?}", s.id);
                }
            }
        }
    }

    #[test]
    fn the_l_bracket_has_no_symmetry() {
        // Its arms differ, so the half turns that would swap them do not map it onto itself.
        let l = &shapes()[0];
        let positions: std::collections::HashSet<_> = l.mesh.vertices.iter().map(key).collect();
        for axis in [Vec3::x(), Vec3::y(), Vec3::z()] {
            let turn = half_turn(axis, 0.0);
            let moved = l
                .mesh
                .vertices
                .iter()
                .filter(|v| !positions.contains(&key(&Pt3::from(turn.transform(v)))))
                .count();
            assert!(moved > 0);
        }
    }

    #[test]
    fn rests_put_the_support_face_down() {
        for s in shapes() {
            for r in &s.rests {
                assert!((r * r.transpose() - Mat3::identity()).norm() < 1e-12);
                // The shape touches the table along an edge or a face, not at a single corner.
                let zs: Vec<f64> = s.mesh.vertices.iter().map(|v| (r * v.coords).z).collect();
                let low = zs.iter().copied().fold(f64::INFINITY, f64::min);
                assert!(zs.iter().filter(|&&z| z < low + 1e-3).count() >= 2);
            }
        }
    }

    #[test]
    fn diameter_of_the_box_is_its_space_diagonal() {
        let b = &shapes()[1];
        let expected = (140.0f64 * 140.0 + 80.0 * 80.0 + 50.0 * 50.0).sqrt();
        assert!((diameter(&b.mesh) - expected).abs() < 1e-9);
    }
}
