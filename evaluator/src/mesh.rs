//! A triangle mesh reduced to what the pose errors and the depth renderer need. Vertices are
//! `f64` because bop_toolkit widens the PLY floats to float64 before any arithmetic; keeping
//! the same precision keeps our errors bit-comparable with its output.

use crate::math::Pt3;

#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<Pt3>,
    /// Indices into `vertices`, always in range (the PLY reader checks them).
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Axis-aligned bounding box (min corner, max corner) of all vertices, including vertices
    /// no triangle uses: bop_toolkit computes it from the whole point array, and the renderer's
    /// clipping planes must agree with it. A mesh without vertices gives an inverted box
    /// (min = +inf, max = -inf).
    pub fn bbox(&self) -> (Pt3, Pt3) {
        let inf = f64::INFINITY;
        let mut lo = Pt3::new(inf, inf, inf);
        let mut hi = Pt3::new(-inf, -inf, -inf);
        for v in &self.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        (lo, hi)
    }

    /// The 8 corners of [`Mesh::bbox`], x varying slowest and z fastest: the order of the
    /// corner list bop_toolkit's renderers build to place their near and far clipping planes.
    pub fn bbox_corners(&self) -> [Pt3; 8] {
        let (lo, hi) = self.bbox();
        let mut corners = [Pt3::origin(); 8];
        let mut i = 0;
        for x in [lo.x, hi.x] {
            for y in [lo.y, hi.y] {
                for z in [lo.z, hi.z] {
                    corners[i] = Pt3::new(x, y, z);
                    i += 1;
                }
            }
        }
        corners
    }
}

/// An axis-aligned cube of side `2 * half` centred at the origin, for tests of the renderer
/// and of VSD.
#[cfg(test)]
pub(crate) fn test_cube(half: f64) -> Mesh {
    let mut vertices = Vec::new();
    for x in [-half, half] {
        for y in [-half, half] {
            for z in [-half, half] {
                vertices.push(Pt3::new(x, y, z));
            }
        }
    }
    // Vertex index = 4 * (x > 0) + 2 * (y > 0) + (z > 0).
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let triangles = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh {
        vertices,
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bbox_includes_unreferenced_vertices() {
        let mesh = Mesh {
            vertices: vec![
                Pt3::new(0.0, 0.0, 0.0),
                Pt3::new(1.0, 2.0, 3.0),
                Pt3::new(1.0, 0.0, 0.0),
                Pt3::new(-5.0, 7.0, -1.0),
            ],
            triangles: vec![[0, 1, 2]],
        };
        let (lo, hi) = mesh.bbox();
        assert_eq!(lo, Pt3::new(-5.0, 0.0, -1.0));
        assert_eq!(hi, Pt3::new(1.0, 7.0, 3.0));
        let c = mesh.bbox_corners();
        assert_eq!(c[0], lo);
        assert_eq!(c[1], Pt3::new(-5.0, 0.0, 3.0));
        assert_eq!(c[2], Pt3::new(-5.0, 7.0, -1.0));
        assert_eq!(c[4], Pt3::new(1.0, 0.0, -1.0));
        assert_eq!(c[7], hi);
    }
}
