//! The evaluator's pose error kernels for callers with their own loops. The Python layer
//! (`poseboard/__init__.py`) checks shapes and hands over row-major float64 values, points as
//! the raw bytes of an `(n, 3)` array, so the numbers reach the very functions the evaluation
//! runs. Each call releases the GIL: a caller may spread its estimates over Python threads.

use evaluator::dataset::{ContinuousSymmetry, DepthImage, ModelInfo};
use evaluator::math::{Intrinsics, Mat3, Pose, Pt3, Vec3};
use evaluator::mesh::Mesh;
use evaluator::pose_error::vsd::{GtView, TestImage, VsdParams, vsd as vsd_kernel};
use evaluator::pose_error::{self, symmetry_transformations};
use evaluator::render::Renderer;
use evaluator::visibility::VisibMode;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A rotation and a translation as the Python layer passes them: row-major `R`, then `t`.
type Rt = ([f64; 9], [f64; 3]);

fn pose(r: &[f64; 9], t: &[f64; 3]) -> Pose {
    Pose::from_row_major(r, t)
}

/// Native-endian float64 triples (numpy's `tobytes()` of a C-contiguous `(n, 3)` array).
fn points(bytes: &[u8]) -> PyResult<Vec<Pt3>> {
    if bytes.is_empty() || !bytes.len().is_multiple_of(24) {
        return Err(PyValueError::new_err("pts must be a non-empty n x 3 array"));
    }
    Ok(bytes
        .chunks_exact(24)
        .map(|c| {
            let f = |i: usize| f64::from_ne_bytes(c[i..i + 8].try_into().expect("8 bytes"));
            Pt3::new(f(0), f(8), f(16))
        })
        .collect())
}

/// Symmetry transformations as the native-endian bytes of a `(k, 12)` float64 array: row-major
/// R, then t, per row (a few hundred per object, so one buffer rather than k Python objects).
fn symmetries(bytes: &[u8]) -> PyResult<Vec<Pose>> {
    if bytes.is_empty() || !bytes.len().is_multiple_of(96) {
        return Err(PyValueError::new_err(
            "syms must hold at least one transformation (the identity)",
        ));
    }
    Ok(bytes
        .chunks_exact(96)
        .map(|c| {
            let f = |i: usize| f64::from_ne_bytes(c[8 * i..8 * i + 8].try_into().expect("8 bytes"));
            pose(&std::array::from_fn(f), &[f(9), f(10), f(11)])
        })
        .collect())
}

#[pyfunction]
pub fn add(py: Python<'_>, est: Rt, gt: Rt, pts: &[u8]) -> PyResult<f64> {
    let pts = points(pts)?;
    Ok(py.detach(|| pose_error::add(&pose(&est.0, &est.1), &pose(&gt.0, &gt.1), &pts)))
}

#[pyfunction]
pub fn adi(py: Python<'_>, est: Rt, gt: Rt, pts: &[u8]) -> PyResult<f64> {
    let pts = points(pts)?;
    Ok(py.detach(|| pose_error::adi(&pose(&est.0, &est.1), &pose(&gt.0, &gt.1), &pts)))
}

#[pyfunction]
pub fn mssd(py: Python<'_>, est: Rt, gt: Rt, pts: &[u8], syms: &[u8]) -> PyResult<f64> {
    let pts = points(pts)?;
    let syms = symmetries(syms)?;
    Ok(py.detach(|| {
        pose_error::mssd(
            &pose(&est.0, &est.1),
            &pose(&gt.0, &gt.1),
            &pts,
            &syms,
            &mut Vec::new(),
        )
    }))
}

#[pyfunction]
pub fn mspd(
    py: Python<'_>,
    est: Rt,
    gt: Rt,
    k: [f64; 9],
    pts: &[u8],
    syms: &[u8],
) -> PyResult<f64> {
    let pts = points(pts)?;
    let syms = symmetries(syms)?;
    Ok(py.detach(|| {
        pose_error::mspd(
            &pose(&est.0, &est.1),
            &pose(&gt.0, &gt.1),
            &Intrinsics::from_row_major(&k),
            &pts,
            &syms,
            &mut Vec::new(),
        )
    }))
}

#[pyfunction]
pub fn re(r_est: [f64; 9], r_gt: [f64; 9]) -> f64 {
    pose_error::re(&Mat3::from_row_slice(&r_est), &Mat3::from_row_slice(&r_gt))
}

#[pyfunction]
pub fn te(t_est: [f64; 3], t_gt: [f64; 3]) -> f64 {
    pose_error::te(&Vec3::from(t_est), &Vec3::from(t_gt))
}

/// VSD of one estimate: renders the model at both poses into the test image's frame, exactly as
/// the evaluation does, one error per tau.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (est, gt, depth, width, height, k, delta, taus, normalized_by_diameter, diameter, pts, faces, visib_mode))]
pub fn vsd(
    py: Python<'_>,
    est: Rt,
    gt: Rt,
    depth: &[u8],
    width: u32,
    height: u32,
    k: [f64; 9],
    delta: f64,
    taus: Vec<f64>,
    normalized_by_diameter: bool,
    diameter: f64,
    pts: &[u8],
    faces: &[u8],
    visib_mode: &str,
) -> PyResult<Vec<f64>> {
    let mesh = mesh(pts, faces)?;
    let params = VsdParams {
        delta,
        taus,
        normalized_by_diameter,
        visib_mode: visib_mode
            .parse::<VisibMode>()
            .map_err(PyValueError::new_err)?,
    };
    if params.taus.is_empty() {
        return Err(PyValueError::new_err("taus is empty"));
    }
    if depth.len() != 4 * width as usize * height as usize {
        return Err(PyValueError::new_err(
            "depth_test must be a height x width array",
        ));
    }
    Ok(py.detach(|| {
        // The test depth image: float32 millimetres, row-major.
        let depth = DepthImage {
            width,
            height,
            data: depth
                .chunks_exact(4)
                .map(|c| f32::from_ne_bytes(c.try_into().expect("4 bytes")))
                .collect(),
        };
        let k = Intrinsics::from_row_major(&k);
        let test = TestImage::new(depth, &k);
        let corners = mesh.bbox_corners();
        let mut renderer = Renderer::new();
        let mut render =
            |p: &Rt| renderer.render(&mesh, &corners, &pose(&p.0, &p.1), &k, width, height);
        let gt_view = GtView::new(&test, render(&gt), &params);
        let est_render = render(&est);
        let mut out = vec![0.0; params.taus.len()];
        vsd_kernel(&test, &gt_view, &est_render, diameter, &params, &mut out);
        out
    }))
}

/// A mesh from `(n, 3)` float64 points and `(m, 3)` uint32 triangle corners, refusing corners
/// that name no point (the renderer indexes with them).
fn mesh(pts: &[u8], faces: &[u8]) -> PyResult<Mesh> {
    let vertices = points(pts)?;
    if !faces.len().is_multiple_of(12) {
        return Err(PyValueError::new_err("faces must be an m x 3 array"));
    }
    let triangles: Vec<[u32; 3]> = faces
        .chunks_exact(12)
        .map(|c| {
            let f = |i: usize| u32::from_ne_bytes(c[i..i + 4].try_into().expect("4 bytes"));
            [f(0), f(4), f(8)]
        })
        .collect();
    if triangles
        .iter()
        .flatten()
        .any(|&i| i as usize >= vertices.len())
    {
        return Err(PyValueError::new_err(
            "faces refer to points that pts does not have",
        ));
    }
    Ok(Mesh {
        vertices,
        triangles,
    })
}

/// bop_toolkit's `misc.get_symmetry_transformations` for one `models_info.json` entry, as
/// the evaluation computes them: (row-major R, t) pairs, the identity first.
#[pyfunction]
pub fn symmetry_transformations_of(
    symmetries_discrete: Vec<Vec<f64>>,
    symmetries_continuous: Vec<([f64; 3], [f64; 3])>,
    max_sym_disc_step: f64,
) -> PyResult<Vec<Rt>> {
    if !(max_sym_disc_step > 0.0 && max_sym_disc_step <= 1.0) {
        return Err(PyValueError::new_err(format!(
            "max_sym_disc_step must be in (0, 1], not {max_sym_disc_step}"
        )));
    }
    let discrete = symmetries_discrete
        .iter()
        .map(|m| {
            <[f64; 16]>::try_from(m.as_slice()).map_err(|_| {
                PyValueError::new_err("a discrete symmetry must be a 4x4 matrix (16 numbers)")
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let info = ModelInfo {
        // Only the symmetries matter here; the diameter does not enter the transformations.
        diameter: 1.0,
        symmetries_discrete: discrete,
        symmetries_continuous: symmetries_continuous
            .into_iter()
            .map(|(axis, offset)| ContinuousSymmetry { axis, offset })
            .collect(),
    };
    Ok(symmetry_transformations(&info, max_sym_disc_step)
        .iter()
        .map(|p| {
            let r = &p.r;
            (
                [
                    r[(0, 0)],
                    r[(0, 1)],
                    r[(0, 2)],
                    r[(1, 0)],
                    r[(1, 1)],
                    r[(1, 2)],
                    r[(2, 0)],
                    r[(2, 1)],
                    r[(2, 2)],
                ],
                [p.t.x, p.t.y, p.t.z],
            )
        })
        .collect())
}
