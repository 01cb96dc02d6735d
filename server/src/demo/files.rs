//! Writers for the few BOP file formats the generator produces. They live apart from the
//! geometry so that the byte layout (PLY header, PNG sample order, JSON key order) is decided in
//! one place: those are what readers elsewhere (bop_toolkit, poseboard's own parser) depend on.

use std::fmt::Display;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use evaluator::math::Vec3;
use evaluator::mesh::Mesh;
use serde::Serialize;

/// JSON laid out like bop_toolkit's `inout.save_json`: one line per entry of the top-level
/// object or list, each entry compact with `", "` and `": "` separators. It keeps files of
/// poses and boxes readable (one image or one target a line) and diffable.
struct Spaced;

impl serde_json::ser::Formatter for Spaced {
    fn begin_array_value<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> io::Result<()> {
        if first { Ok(()) } else { w.write_all(b", ") }
    }

    fn begin_object_key<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> io::Result<()> {
        if first { Ok(()) } else { w.write_all(b", ") }
    }

    fn begin_object_value<W: ?Sized + io::Write>(&mut self, w: &mut W) -> io::Result<()> {
        w.write_all(b": ")
    }
}

fn create(path: &Path) -> Result<BufWriter<File>> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    Ok(BufWriter::new(file))
}

fn dumps<T: Serialize + ?Sized>(value: &T) -> Result<String> {
    let mut out = Vec::new();
    value.serialize(&mut serde_json::Serializer::with_formatter(
        &mut out, Spaced,
    ))?;
    Ok(String::from_utf8(out)?)
}

fn write_lines(path: &Path, open: &str, lines: &[String], close: &str) -> Result<()> {
    let mut out = create(path)?;
    writeln!(out, "{open}")?;
    for (i, line) in lines.iter().enumerate() {
        let comma = if i + 1 < lines.len() { "," } else { "" };
        writeln!(out, "  {line}{comma}")?;
    }
    writeln!(out, "{close}")?;
    out.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// A JSON object with the entries in the order given (ids in numeric order, unlike a
/// string-keyed map, which would put "10" before "2").
pub(super) fn write_json_object<K: Display, V: Serialize>(
    path: &Path,
    entries: impl IntoIterator<Item = (K, V)>,
) -> Result<()> {
    let lines = entries
        .into_iter()
        .map(|(k, v)| Ok(format!("{}: {}", dumps(&k.to_string())?, dumps(&v)?)))
        .collect::<Result<Vec<_>>>()?;
    write_lines(path, "{", &lines, "}")
}

pub(super) fn write_json_list<T: Serialize>(path: &Path, items: &[T]) -> Result<()> {
    let lines = items.iter().map(dumps).collect::<Result<Vec<_>>>()?;
    write_lines(path, "[", &lines, "]")
}

/// Binary little-endian PLY with float positions and normals and `uchar int` triangle lists,
/// the layout of the BOP datasets' own models.
pub(super) fn write_ply(path: &Path, mesh: &Mesh, normals: &[Vec3]) -> Result<()> {
    let mut out = create(path)?;
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment poseboard synthetic model, mm\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for (p, n) in mesh.vertices.iter().zip(normals) {
        for v in [p.x, p.y, p.z, n.x, n.y, n.z] {
            out.write_all(&(v as f32).to_le_bytes())?;
        }
    }
    for tri in &mesh.triangles {
        out.write_all(&[3])?;
        for &i in tri {
            out.write_all(&(i as i32).to_le_bytes())?;
        }
    }
    out.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

fn write_png(
    path: &Path,
    (width, height): (u32, u32),
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<()> {
    let mut encoder = png::Encoder::new(create(path)?, width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(data)?;
    writer
        .finish()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// 16-bit grayscale; PNG stores samples big-endian.
pub(super) fn write_depth_png(path: &Path, size: (u32, u32), values: &[u16]) -> Result<()> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    write_png(
        path,
        size,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
        &bytes,
    )
}

pub(super) fn write_gray_png(path: &Path, size: (u32, u32), gray: &[u8]) -> Result<()> {
    write_png(
        path,
        size,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        gray,
    )
}

pub(super) fn write_rgb_png(path: &Path, size: (u32, u32), rgb: &[u8]) -> Result<()> {
    write_png(path, size, png::ColorType::Rgb, png::BitDepth::Eight, rgb)
}

/// A TIFF of one grayscale image (`C`: 8 or 16 bits), uncompressed: the baseline every TIFF
/// reader knows, as ITODD's depth and gray images are TIFFs.
fn write_tiff<C: tiff::encoder::colortype::ColorType>(
    path: &Path,
    (width, height): (u32, u32),
    samples: &[C::Inner],
) -> Result<()>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut out = create(path)?;
    tiff::encoder::TiffEncoder::new(&mut out)
        .and_then(|mut e| e.write_image::<C>(width, height, samples))
        .with_context(|| format!("cannot write {}", path.display()))?;
    out.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

pub(super) fn write_depth_tiff(path: &Path, size: (u32, u32), values: &[u16]) -> Result<()> {
    write_tiff::<tiff::encoder::colortype::Gray16>(path, size, values)
}

pub(super) fn write_gray_tiff(path: &Path, size: (u32, u32), gray: &[u8]) -> Result<()> {
    write_tiff::<tiff::encoder::colortype::Gray8>(path, size, gray)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn json_has_one_entry_a_line_with_ids_in_numeric_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.json");
        let map: BTreeMap<u32, Vec<f64>> = [(10, vec![1.5]), (2, vec![0.1, -2.0])]
            .into_iter()
            .collect();
        write_json_object(&path, &map).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "{\n  \"2\": [0.1, -2.0],\n  \"10\": [1.5]\n}\n");
        let back: BTreeMap<String, Vec<f64>> = serde_json::from_str(&text).unwrap();
        assert_eq!(back["2"], [0.1, -2.0]);

        #[derive(Serialize)]
        struct Entry {
            a: u32,
            b: [i64; 2],
        }
        write_json_list(&path, &[Entry { a: 1, b: [-1, 2] }]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "[\n  {\"a\": 1, \"b\": [-1, 2]}\n]\n");
        write_json_list::<Entry>(&path, &[]).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "[\n]\n");
    }
}
