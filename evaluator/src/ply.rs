//! PLY reader for object models. Hand-written because the PLY crates are unmaintained and
//! BOP needs only a small subset (ASCII and binary little endian, vertex positions, polygon
//! faces), while the files come from users: the reader must never panic or allocate on the
//! word of a header, and its errors must say which element and property are wrong.

use std::path::Path;

use crate::error::{Error, Result};
use crate::math::Pt3;
use crate::mesh::Mesh;

/// Reads a PLY file; see [`parse_ply`].
pub fn read_ply(path: &Path) -> Result<Mesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_ply(&bytes, path)
}

/// Parses PLY content into a triangle mesh: polygons are fan-triangulated (0, i, i+1) and
/// every property other than the vertex position and the face corner list is skipped.
/// `path` is only used in error messages.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<Mesh> {
    parse(bytes).map_err(|message| Error::format(path, message))
}

/// Internal results carry just the message; the path is attached once, in `parse_ply`.
type Parse<T> = std::result::Result<T, String>;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The value range of an integer type, `None` for floating-point types.
    fn int_range(self) -> Option<(i64, i64)> {
        match self {
            Scalar::I8 => Some((i8::MIN.into(), i8::MAX.into())),
            Scalar::U8 => Some((0, u8::MAX.into())),
            Scalar::I16 => Some((i16::MIN.into(), i16::MAX.into())),
            Scalar::U16 => Some((0, u16::MAX.into())),
            Scalar::I32 => Some((i32::MIN.into(), i32::MAX.into())),
            Scalar::U32 => Some((0, u32::MAX.into())),
            Scalar::F32 | Scalar::F64 => None,
        }
    }
}

#[derive(Debug)]
enum Kind {
    Scalar(Scalar),
    /// `count` is always an integer type (checked while reading the header).
    List {
        count: Scalar,
        item: Scalar,
    },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

impl Element {
    fn property(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }

    /// A lower bound of the bytes one record occupies, so that capacities derived from the
    /// header count never exceed what the remaining data can hold.
    fn min_record_bytes(&self, encoding: Encoding) -> usize {
        let fixed: usize = self
            .properties
            .iter()
            .map(|p| match (encoding, &p.kind) {
                (Encoding::Ascii, _) => 1,
                (Encoding::BinaryLittleEndian, Kind::Scalar(s)) => s.size(),
                (Encoding::BinaryLittleEndian, Kind::List { count, .. }) => count.size(),
            })
            .sum();
        fixed.max(1)
    }
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Offset of the first byte after the `end_header` line.
    body_start: usize,
}

fn parse(bytes: &[u8]) -> Parse<Mesh> {
    let header = parse_header(bytes)?;
    let layout = Layout::of(&header.elements)?;
    let mut body = Body {
        encoding: header.encoding,
        data: bytes,
        pos: header.body_start,
        line: &[],
    };
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for (index, element) in header.elements.iter().enumerate() {
        // A record without properties occupies no bytes; iterating over a count of billions
        // of them would only burn time.
        if element.properties.is_empty() {
            continue;
        }
        if index == layout.vertex {
            vertices = read_vertices(&mut body, element, layout.xyz)?;
        } else if let Some((face, corners)) = layout.face
            && index == face
        {
            let vertex_count = header.elements[layout.vertex].count;
            triangles = read_faces(&mut body, element, corners, vertex_count)?;
        } else {
            skip_element(&mut body, element)?;
        }
    }
    Ok(Mesh {
        vertices,
        triangles,
    })
}

fn parse_header(bytes: &[u8]) -> Parse<Header> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if pos >= bytes.len() {
            return Err(if line_no == 0 {
                "empty file".to_string()
            } else {
                "header: no `end_header` line".to_string()
            });
        }
        let rest = &bytes[pos..];
        let (raw, next) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], pos + i + 1),
            None => (rest, bytes.len()),
        };
        pos = next;
        line_no += 1;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        // Keywords, types and names are ASCII; only comments may hold other encodings.
        let line = String::from_utf8_lossy(raw);
        if line_no == 1 {
            if line.trim_end() != "ply" {
                return Err("not a PLY file (the first line is not `ply`)".to_string());
            }
            continue;
        }
        let at = |msg: String| format!("header line {line_no}: {msg}");
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let args: Vec<&str> = words.collect();
        match keyword {
            "comment" | "obj_info" => {}
            "format" => {
                if encoding.is_some() {
                    return Err(at("second `format` line".to_string()));
                }
                let [format, version] = args[..] else {
                    return Err(at(format!("expected `format <type> 1.0`, found `{line}`")));
                };
                encoding = Some(match format {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => {
                        return Err(at("format binary_big_endian is not supported \
                             (only ascii and binary_little_endian)"
                            .to_string()));
                    }
                    other => return Err(at(format!("unknown format `{other}`"))),
                });
                if version != "1.0" {
                    return Err(at(format!("unsupported PLY version `{version}`")));
                }
            }
            "element" => {
                let [name, count] = args[..] else {
                    return Err(at(format!(
                        "expected `element <name> <count>`, found `{line}`"
                    )));
                };
                let count = count
                    .parse::<u64>()
                    .map_err(|_| at(format!("element `{name}`: invalid count `{count}`")))?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(at(format!("element `{name}` declared twice")));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(at("property before any element".to_string()));
                };
                let property = parse_property(&args, &element.name).map_err(at)?;
                if element.property(&property.name).is_some() {
                    return Err(at(format!(
                        "property `{}` declared twice on element `{}`",
                        property.name, element.name
                    )));
                }
                element.properties.push(property);
            }
            "end_header" => {
                let encoding = encoding.ok_or("header: no `format` line")?;
                return Ok(Header {
                    encoding,
                    elements,
                    body_start: pos,
                });
            }
            other => return Err(at(format!("unknown keyword `{other}`"))),
        }
    }
}

/// Parses the words after `property`.
fn parse_property(words: &[&str], element: &str) -> Parse<Property> {
    let scalar = |name: &str| {
        Scalar::from_name(name)
            .ok_or_else(|| format!("unknown type `{name}` on element `{element}`"))
    };
    match words {
        ["list", count, item, name] => {
            let count = scalar(count)?;
            if count.int_range().is_none() {
                return Err(format!(
                    "list `{name}` of element `{element}`: count type `{}` is not an integer type",
                    count.name()
                ));
            }
            Ok(Property {
                name: name.to_string(),
                kind: Kind::List {
                    count,
                    item: scalar(item)?,
                },
            })
        }
        [ty, name] if *ty != "list" => Ok(Property {
            name: name.to_string(),
            kind: Kind::Scalar(scalar(ty)?),
        }),
        _ => Err(format!(
            "expected `property <type> <name>` or `property list <count type> <type> <name>`, \
             found `property {}`",
            words.join(" ")
        )),
    }
}

/// Where the data the mesh needs sits among the header's elements and properties.
struct Layout {
    vertex: usize,
    xyz: [usize; 3],
    /// The face element and its corner-list property, if the file has faces.
    face: Option<(usize, usize)>,
}

impl Layout {
    fn of(elements: &[Element]) -> Parse<Layout> {
        let vertex = elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or("header: no element `vertex`")?;
        let v = &elements[vertex];
        let mut xyz = [0; 3];
        for (slot, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
            let index = v
                .property(axis)
                .ok_or_else(|| format!("header: property `{axis}` missing on element `vertex`"))?;
            if matches!(v.properties[index].kind, Kind::List { .. }) {
                return Err(format!(
                    "header: property `{axis}` of element `vertex` is a list, expected a number"
                ));
            }
            *slot = index;
        }
        let face = match elements.iter().position(|e| e.name == "face") {
            None => None,
            Some(f) => {
                let element = &elements[f];
                let corners = element
                    .properties
                    .iter()
                    .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
                    .ok_or("header: element `face` has no `vertex_indices` list")?;
                let property = &element.properties[corners];
                match property.kind {
                    Kind::List { item, .. } if item.int_range().is_some() => {}
                    Kind::List { item, .. } => {
                        return Err(format!(
                            "header: list `{}` of element `face` has non-integer index type `{}`",
                            property.name,
                            item.name()
                        ));
                    }
                    Kind::Scalar(_) => {
                        return Err(format!(
                            "header: property `{}` of element `face` is not a list",
                            property.name
                        ));
                    }
                }
                Some((f, corners))
            }
        };
        Ok(Layout { vertex, xyz, face })
    }
}

#[derive(Clone, Copy, Debug)]
enum Num {
    Int(i64),
    Float(f64),
}

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Num::Int(i) => write!(f, "{i}"),
            Num::Float(x) => write!(f, "{x}"),
        }
    }
}

impl Num {
    fn as_f64(self) -> f64 {
        match self {
            Num::Int(i) => i as f64,
            Num::Float(f) => f,
        }
    }
}

/// The element data after the header. In ASCII files every record is one line (blank lines
/// are ignored) and must hold exactly the values its properties declare, so that a missing
/// or extra value is reported on its record instead of shifting every later one.
struct Body<'a> {
    encoding: Encoding,
    data: &'a [u8],
    pos: usize,
    /// ASCII only: the unread rest of the current record's line.
    line: &'a [u8],
}

const END_OF_DATA: &str = "unexpected end of data";

impl<'a> Body<'a> {
    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn start_record(&mut self) -> Parse<()> {
        if self.encoding == Encoding::BinaryLittleEndian {
            return Ok(());
        }
        loop {
            let rest = self.data.get(self.pos..).unwrap_or_default();
            if rest.is_empty() {
                return Err(END_OF_DATA.to_string());
            }
            let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            self.line = &rest[..end];
            self.pos += end + 1;
            if self.line.iter().any(|b| !b.is_ascii_whitespace()) {
                return Ok(());
            }
        }
    }

    fn finish_record(&mut self) -> Parse<()> {
        match self.token() {
            Some(extra) => Err(format!(
                "unexpected extra value `{}` at the end of the line",
                String::from_utf8_lossy(extra)
            )),
            None => Ok(()),
        }
    }

    /// ASCII only: the next whitespace-separated token of the current line.
    fn token(&mut self) -> Option<&'a [u8]> {
        let line = self.line;
        let start = line.iter().position(|b| !b.is_ascii_whitespace())?;
        let len = line[start..]
            .iter()
            .position(|b| b.is_ascii_whitespace())
            .unwrap_or(line.len() - start);
        self.line = &line[start + len..];
        Some(&line[start..start + len])
    }

    fn bytes<const N: usize>(&mut self) -> Parse<[u8; N]> {
        let chunk: [u8; N] = self
            .data
            .get(self.pos..self.pos + N)
            .and_then(|s| s.try_into().ok())
            .ok_or(END_OF_DATA)?;
        self.pos += N;
        Ok(chunk)
    }

    fn read(&mut self, ty: Scalar) -> Parse<Num> {
        match self.encoding {
            Encoding::BinaryLittleEndian => Ok(match ty {
                Scalar::I8 => Num::Int(i8::from_le_bytes(self.bytes()?).into()),
                Scalar::U8 => Num::Int(u8::from_le_bytes(self.bytes()?).into()),
                Scalar::I16 => Num::Int(i16::from_le_bytes(self.bytes()?).into()),
                Scalar::U16 => Num::Int(u16::from_le_bytes(self.bytes()?).into()),
                Scalar::I32 => Num::Int(i32::from_le_bytes(self.bytes()?).into()),
                Scalar::U32 => Num::Int(u32::from_le_bytes(self.bytes()?).into()),
                Scalar::F32 => Num::Float(f32::from_le_bytes(self.bytes()?).into()),
                Scalar::F64 => Num::Float(f64::from_le_bytes(self.bytes()?)),
            }),
            Encoding::Ascii => {
                let token = self.token().ok_or("unexpected end of line")?;
                let invalid = || {
                    format!(
                        "`{}` is not a valid {}",
                        String::from_utf8_lossy(token),
                        ty.name()
                    )
                };
                let text = std::str::from_utf8(token).map_err(|_| invalid())?;
                match ty.int_range() {
                    Some((min, max)) => match text.parse::<i64>() {
                        Ok(v) if (min..=max).contains(&v) => Ok(Num::Int(v)),
                        _ => Err(invalid()),
                    },
                    // Parsed straight to f64 like bop_toolkit's `float(str)`, also for `float`.
                    None => text.parse::<f64>().map(Num::Float).map_err(|_| invalid()),
                }
            }
        }
    }

    fn read_list_len(&mut self, count: Scalar) -> Parse<u64> {
        match self.read(count)? {
            Num::Int(n) => u64::try_from(n).map_err(|_| format!("negative list length {n}")),
            Num::Float(_) => Err("list length is not an integer".to_string()),
        }
    }

    fn skip(&mut self, ty: Scalar, n: u64) -> Parse<()> {
        match self.encoding {
            Encoding::BinaryLittleEndian => {
                let len = usize::try_from(n)
                    .ok()
                    .and_then(|n| n.checked_mul(ty.size()))
                    .filter(|&len| len <= self.remaining())
                    .ok_or(END_OF_DATA)?;
                self.pos += len;
            }
            Encoding::Ascii => {
                for _ in 0..n {
                    self.token().ok_or("unexpected end of line")?;
                }
            }
        }
        Ok(())
    }

    fn skip_property(&mut self, kind: &Kind) -> Parse<()> {
        match *kind {
            Kind::Scalar(ty) => self.skip(ty, 1),
            Kind::List { count, item } => {
                let n = self.read_list_len(count)?;
                self.skip(item, n)
            }
        }
    }
}

/// Starting capacity for `count` records: never more than the remaining bytes can hold.
fn capacity(body: &Body, element: &Element) -> usize {
    let fit = body.remaining() / element.min_record_bytes(body.encoding);
    usize::try_from(element.count).map_or(fit, |count| count.min(fit))
}

fn in_record(
    element: &Element,
    index: u64,
    property: Option<&Property>,
) -> impl Fn(String) -> String {
    let place = match property {
        Some(p) => format!("{} {index}, property `{}`", element.name, p.name),
        None => format!("{} {index}", element.name),
    };
    move |what| format!("{what} in {place}")
}

fn read_vertices(body: &mut Body, element: &Element, xyz: [usize; 3]) -> Parse<Vec<Pt3>> {
    let mut vertices = Vec::with_capacity(capacity(body, element));
    for i in 0..element.count {
        body.start_record().map_err(in_record(element, i, None))?;
        let mut p = [0.0; 3];
        for (k, property) in element.properties.iter().enumerate() {
            let at = in_record(element, i, Some(property));
            match (xyz.iter().position(|&j| j == k), &property.kind) {
                (Some(axis), Kind::Scalar(ty)) => p[axis] = body.read(*ty).map_err(at)?.as_f64(),
                (_, kind) => body.skip_property(kind).map_err(at)?,
            }
        }
        body.finish_record().map_err(in_record(element, i, None))?;
        vertices.push(Pt3::new(p[0], p[1], p[2]));
    }
    Ok(vertices)
}

fn read_faces(
    body: &mut Body,
    element: &Element,
    corners_property: usize,
    vertex_count: u64,
) -> Parse<Vec<[u32; 3]>> {
    let mut triangles = Vec::with_capacity(capacity(body, element));
    let mut corners: Vec<u32> = Vec::new();
    for i in 0..element.count {
        body.start_record().map_err(in_record(element, i, None))?;
        for (k, property) in element.properties.iter().enumerate() {
            let at = in_record(element, i, Some(property));
            let (count, item) = match property.kind {
                Kind::List { count, item } if k == corners_property => (count, item),
                ref kind => {
                    body.skip_property(kind).map_err(at)?;
                    continue;
                }
            };
            let n = body.read_list_len(count).map_err(&at)?;
            if n < 3 {
                return Err(format!("face {i}: {n} corners, a face needs at least 3"));
            }
            corners.clear();
            for _ in 0..n {
                let value = body.read(item).map_err(&at)?;
                let index = match value {
                    Num::Int(v) => u32::try_from(v)
                        .ok()
                        .filter(|&v| u64::from(v) < vertex_count),
                    Num::Float(_) => None,
                };
                let index = index.ok_or_else(|| {
                    format!("face {i}: vertex index {value} out of range ({vertex_count} vertices)")
                })?;
                corners.push(index);
            }
        }
        body.finish_record().map_err(in_record(element, i, None))?;
        for w in corners.windows(2).skip(1) {
            triangles.push([corners[0], w[0], w[1]]);
        }
    }
    Ok(triangles)
}

fn skip_element(body: &mut Body, element: &Element) -> Parse<()> {
    for i in 0..element.count {
        body.start_record().map_err(in_record(element, i, None))?;
        for property in &element.properties {
            body.skip_property(&property.kind)
                .map_err(in_record(element, i, Some(property)))?;
        }
        body.finish_record().map_err(in_record(element, i, None))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse_str(text: &str) -> Result<Mesh> {
        parse_ply(text.as_bytes(), Path::new("test.ply"))
    }

    fn message(result: Result<Mesh>) -> String {
        match result {
            Ok(mesh) => panic!("expected an error, got {mesh:?}"),
            Err(Error::Format { message, .. }) => message,
            Err(other) => panic!("expected a format error, got {other}"),
        }
    }

    /// A binary file: `header` (without `ply`/`format`/`end_header`) followed by `body`.
    fn binary(header: &str, body: &[u8]) -> Vec<u8> {
        let mut bytes =
            format!("ply\nformat binary_little_endian 1.0\n{header}end_header\n").into_bytes();
        bytes.extend_from_slice(body);
        bytes
    }

    fn f32s(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    const TRIANGLE: &str = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 3\n\
        property float x\nproperty float y\nproperty float z\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n\
        0 0 0\n1.5 0 0\n0 2 -3.25\n3 0 1 2\n";

    #[test]
    fn ascii_triangle() {
        let mesh = parse_str(TRIANGLE).unwrap();
        assert_eq!(
            mesh.vertices,
            vec![
                Pt3::new(0.0, 0.0, 0.0),
                Pt3::new(1.5, 0.0, 0.0),
                Pt3::new(0.0, 2.0, -3.25)
            ]
        );
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn ascii_with_crlf_header_and_blank_lines() {
        let text = TRIANGLE
            .replace("\n", "\r\n")
            .replace("1.5 0 0\r\n", "1.5 0 0\r\n\r\n");
        assert_eq!(parse_str(&text).unwrap(), parse_str(TRIANGLE).unwrap());
    }

    #[test]
    fn ascii_reads_floats_as_f64_like_bop_toolkit() {
        let text = TRIANGLE.replace("1.5 0 0", "0.1 0 0");
        assert_eq!(parse_str(&text).unwrap().vertices[1].x, 0.1_f64);
    }

    #[test]
    fn binary_mesh() {
        let header = "element vertex 4\nproperty float x\nproperty float y\nproperty double z\n\
            element face 2\nproperty list uchar int vertex_indices\n";
        let mut body = Vec::new();
        for (x, y, z) in [
            (0.0, 0.0, 0.0),
            (0.1, 0.0, 0.0),
            (0.0, 1.0, 0.5),
            (1.0, 1.0, -2.0),
        ] {
            body.extend(f32s(&[x, y]));
            body.extend(f64::to_le_bytes(z));
        }
        for face in [[0i32, 1, 2], [1, 3, 2]] {
            body.push(3);
            body.extend(face.iter().flat_map(|i| i.to_le_bytes()));
        }
        let mesh = parse_ply(&binary(header, &body), Path::new("b.ply")).unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        // A binary float is widened exactly, not re-rounded through its decimal form.
        assert_eq!(mesh.vertices[1].x, f64::from(0.1_f32));
        assert_eq!(mesh.vertices[3], Pt3::new(1.0, 1.0, -2.0));
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [1, 3, 2]]);
    }

    #[test]
    fn polygons_are_fan_triangulated() {
        let text = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
            property float z\nelement face 2\nproperty list uchar uint vertex_index\nend_header\n\
            0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n4 0 1 2 3\n5 0 1 2 3 4\n";
        let mesh = parse_str(text).unwrap();
        assert_eq!(
            mesh.triangles,
            vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3], [0, 3, 4]]
        );
    }

    #[test]
    fn unknown_properties_and_elements_are_skipped_in_ascii() {
        let text = "ply\nformat ascii 1.0\nelement material 1\nproperty uchar shininess\n\
            property list uchar float tint\nelement vertex 3\nproperty float confidence\n\
            property double z\nproperty float nx\nproperty float y\nproperty float x\n\
            property uchar red\nproperty list ushort int neighbours\nelement face 1\n\
            property uchar flags\nproperty list uchar float texcoord\n\
            property list uchar int vertex_indices\nproperty int material_index\n\
            element edge 2\nproperty int vertex1\nproperty int vertex2\nend_header\n\
            7 3 0.5 0.5 0.5\n\
            0.9 3 0.1 2 1 255 0\n0.8 6 0.2 5 4 0 2 0 1\n0.7 9 0.3 8 7 128 1 2\n\
            1 6 0 0 1 0 0 1 3 2 0 1 0\n\
            0 1\n1 2\n";
        let mesh = parse_str(text).unwrap();
        assert_eq!(
            mesh.vertices,
            vec![
                Pt3::new(1.0, 2.0, 3.0),
                Pt3::new(4.0, 5.0, 6.0),
                Pt3::new(7.0, 8.0, 9.0)
            ]
        );
        assert_eq!(mesh.triangles, vec![[2, 0, 1]]);
    }

    #[test]
    fn unknown_properties_and_elements_are_skipped_in_binary() {
        let header = "element vertex 3\nproperty float x\nproperty float confidence\n\
            property float y\nproperty float z\nproperty uchar red\n\
            element face 1\nproperty list uchar float texcoord\n\
            property list int short vertex_indices\nproperty char flags\n\
            element material 1\nproperty double shininess\n";
        let mut body = Vec::new();
        for i in 0..3u8 {
            let v = f32::from(i);
            body.extend(f32s(&[v, 0.5, v + 10.0, v + 20.0]));
            body.push(200);
        }
        body.push(6);
        body.extend(f32s(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]));
        body.extend(3i32.to_le_bytes());
        body.extend([0i16, 2, 1].iter().flat_map(|i| i.to_le_bytes()));
        body.push(0xff);
        body.extend(0.25f64.to_le_bytes());
        let mesh = parse_ply(&binary(header, &body), Path::new("b.ply")).unwrap();
        assert_eq!(mesh.vertices[2], Pt3::new(2.0, 12.0, 22.0));
        assert_eq!(mesh.triangles, vec![[0, 2, 1]]);
    }

    #[test]
    fn point_cloud_without_faces() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty int x\nproperty int y\n\
            property int z\nend_header\n1 2 3\n-4 5 6\n";
        let mesh = parse_str(text).unwrap();
        assert_eq!(mesh.vertices[1], Pt3::new(-4.0, 5.0, 6.0));
        assert!(mesh.triangles.is_empty());
    }

    #[test]
    fn header_errors() {
        // An ASCII file whose header lines after `format` are `lines`.
        let ascii = |lines: &str| format!("ply\nformat ascii 1.0\n{lines}end_header\n");
        let xyz = "element vertex 0\nproperty float x\nproperty float y\nproperty float z\n";
        let cases = [
            (String::new(), "empty file"),
            ("solid cube\n".to_string(), "not a PLY file"),
            (
                "ply\nformat ascii 1.0\nelement vertex 0\n".to_string(),
                "no `end_header`",
            ),
            (
                "ply\nformat binary_big_endian 1.0\nend_header\n".to_string(),
                "binary_big_endian is not supported",
            ),
            (
                "ply\nformat ascii 2.0\nend_header\n".to_string(),
                "version `2.0`",
            ),
            (
                "ply\nelement vertex 0\nend_header\n".to_string(),
                "no `format` line",
            ),
            (ascii(""), "no element `vertex`"),
            (
                ascii("property float x\n"),
                "line 3: property before any element",
            ),
            (
                ascii("element vertex -1\n"),
                "element `vertex`: invalid count `-1`",
            ),
            (
                ascii("element vertex 1\nproperty half x\n"),
                "unknown type `half`",
            ),
            (
                ascii("element vertex 1\nproperty float\n"),
                "expected `property <type> <name>`",
            ),
            (
                ascii("element vertex 1\nproperty float x\nproperty float x\n"),
                "property `x` declared twice",
            ),
            (
                ascii("element vertex 1\nelement vertex 1\n"),
                "element `vertex` declared twice",
            ),
            (
                ascii("elemnt vertex 1\n"),
                "line 3: unknown keyword `elemnt`",
            ),
            (
                ascii("element vertex 1\nproperty float x\nproperty float z\n"),
                "header: property `y` missing on element `vertex`",
            ),
            (
                ascii(&xyz.replace("float z", "list uchar float z")),
                "property `z` of element `vertex` is a list",
            ),
            (
                ascii(&format!(
                    "{xyz}element face 0\nproperty list uchar int corners\n"
                )),
                "element `face` has no `vertex_indices` list",
            ),
            (
                ascii(&format!(
                    "{xyz}element face 0\nproperty int vertex_indices\n"
                )),
                "`vertex_indices` of element `face` is not a list",
            ),
            (
                ascii(&format!(
                    "{xyz}element face 0\nproperty list uchar float vertex_indices\n"
                )),
                "non-integer index type `float`",
            ),
            (
                ascii("element face 0\nproperty list float int vertex_indices\n"),
                "count type `float` is not an integer type",
            ),
        ];
        for (text, expected) in cases {
            let msg = message(parse_str(&text));
            assert!(
                msg.contains(expected),
                "{text:?}: {msg:?} lacks {expected:?}"
            );
        }
    }

    #[test]
    fn data_errors() {
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
            property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
            0 0 0\n1 0 0\n0 1 0\n";
        let cases = [
            (
                "3 0 1 2\n3 0 1 9\n",
                "face 1: vertex index 9 out of range (3 vertices)",
            ),
            (
                "3 0 1 2\n3 0 -1 2\n",
                "face 1: vertex index -1 out of range (3 vertices)",
            ),
            (
                "3 0 1 2\n2 0 1\n",
                "face 1: 2 corners, a face needs at least 3",
            ),
            ("3 0 1 2\n", "unexpected end of data in face 1"),
            (
                "3 0 1 2\n3 0 1\n",
                "unexpected end of line in face 1, property `vertex_indices`",
            ),
            (
                "3 0 1 2\n3 0 1 2 7\n",
                "unexpected extra value `7` at the end of the line in face 1",
            ),
            (
                "3 0 1 2\n3 0 x 2\n",
                "`x` is not a valid int in face 1, property `vertex_indices`",
            ),
            (
                "3 0 1 2\n300 0 1 2\n",
                "`300` is not a valid uchar in face 1",
            ),
        ];
        for (body, expected) in cases {
            let msg = message(parse_str(&format!("{head}{body}")));
            assert!(
                msg.contains(expected),
                "{body:?}: {msg:?} lacks {expected:?}"
            );
        }
        let msg = message(parse_str(&head.replace("1 0 0\n", "1 0 zero\n")));
        assert!(
            msg.contains("`zero` is not a valid float in vertex 1, property `z`"),
            "{msg}"
        );
    }

    #[test]
    fn binary_truncation_and_huge_counts_fail_cleanly() {
        let header = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        let body = f32s(&[0.0; 8]);
        let msg = message(parse_ply(&binary(header, &body), Path::new("b.ply")));
        assert_eq!(msg, "unexpected end of data in vertex 2, property `z`");

        let huge = "element vertex 4000000000\nproperty float x\nproperty float y\n\
            property float z\n";
        let msg = message(parse_ply(
            &binary(huge, &f32s(&[0.0; 25])),
            Path::new("b.ply"),
        ));
        assert!(msg.contains("unexpected end of data in vertex 8"), "{msg}");

        let header = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
            element face 4000000000\nproperty list uint int vertex_indices\n\
            element nothing 18446744073709551615\n";
        let mut body = f32s(&[0.0; 3]);
        body.extend(u32::MAX.to_le_bytes());
        let msg = message(parse_ply(&binary(header, &body), Path::new("b.ply")));
        assert!(msg.contains("unexpected end of data in face 0"), "{msg}");

        let skipped = "element vertex 0\nproperty float x\nproperty float y\nproperty float z\n\
            element blob 1\nproperty list uint double samples\n";
        let msg = message(parse_ply(
            &binary(skipped, &u32::MAX.to_le_bytes()),
            Path::new("b.ply"),
        ));
        assert!(msg.contains("in blob 0, property `samples`"), "{msg}");
    }

    #[test]
    fn errors_name_the_file() {
        let err = parse_ply(b"nope", Path::new("models/obj_000001.ply")).unwrap_err();
        assert!(
            err.to_string().starts_with("models/obj_000001.ply: "),
            "{err}"
        );
        let err = read_ply(Path::new("/nonexistent/obj.ply")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
    }

    #[test]
    fn reference_models() {
        let dir = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/fixtures/reference/dataset/models_eval"
        );
        let mut sizes = Vec::new();
        for id in 1..=4 {
            let mesh = read_ply(&Path::new(dir).join(format!("obj_{id:06}.ply"))).unwrap();
            let n = mesh.vertices.len() as u32;
            assert!(mesh.triangles.iter().flatten().all(|&i| i < n));
            sizes.push((mesh.vertices.len(), mesh.triangles.len()));
            if id == 2 {
                // The box of models_info.json: min (-50, -30, 0), size (100, 60, 40).
                assert_eq!(
                    mesh.bbox(),
                    (Pt3::new(-50.0, -30.0, 0.0), Pt3::new(50.0, 30.0, 40.0))
                );
            }
        }
        assert_eq!(sizes[0], (772, 1536));
        assert!(sizes.iter().all(|&(v, t)| v > 0 && t > 0));
    }

    fn valid_files() -> Vec<Vec<u8>> {
        let header = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
            property uchar red\nelement face 1\nproperty list uchar int vertex_indices\n\
            property list uchar float texcoord\n";
        let mut body = Vec::new();
        for i in 0..3u8 {
            body.extend(f32s(&[f32::from(i), 1.0, 2.0]));
            body.push(i);
        }
        body.push(3);
        body.extend([0i32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        body.push(2);
        body.extend(f32s(&[0.5, 0.5]));
        vec![TRIANGLE.as_bytes().to_vec(), binary(header, &body)]
    }

    #[test]
    fn mutation_seeds_are_valid() {
        for file in valid_files() {
            parse_ply(&file, Path::new("seed.ply")).unwrap();
        }
    }

    #[derive(Clone, Debug)]
    enum Mutation {
        Set(usize, u8),
        Insert(usize, Vec<u8>),
        Remove(usize, usize),
        Truncate(usize),
    }

    fn mutation() -> impl Strategy<Value = Mutation> {
        let interesting = prop::sample::select(vec![
            b"0".to_vec(),
            b" ".to_vec(),
            b"\n".to_vec(),
            b"-1".to_vec(),
            b"4294967295".to_vec(),
            b"18446744073709551616".to_vec(),
            b"property list uint int vertex_indices\n".to_vec(),
            b"element vertex 4000000000\n".to_vec(),
            b"element face 3\n".to_vec(),
            b"\xff\xff\xff\xff".to_vec(),
            b"nan".to_vec(),
        ]);
        prop_oneof![
            (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Set(i, b)),
            (
                any::<usize>(),
                prop_oneof![interesting, prop::collection::vec(any::<u8>(), 1..8)]
            )
                .prop_map(|(i, b)| Mutation::Insert(i, b)),
            (any::<usize>(), 1..16usize).prop_map(|(i, n)| Mutation::Remove(i, n)),
            any::<usize>().prop_map(Mutation::Truncate),
        ]
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
            let _ = parse_ply(&bytes, Path::new("fuzz.ply"));
            let mut with_header = b"ply\nformat binary_little_endian 1.0\n".to_vec();
            with_header.extend_from_slice(&bytes);
            let _ = parse_ply(&with_header, Path::new("fuzz.ply"));
        }

        #[test]
        fn mutated_files_never_panic(
            seed in 0..2usize,
            mutations in prop::collection::vec(mutation(), 1..6),
        ) {
            let mut file = valid_files().swap_remove(seed);
            for m in mutations {
                let len = file.len();
                match m {
                    Mutation::Set(i, b) if len > 0 => file[i % len] = b,
                    Mutation::Set(..) => {}
                    Mutation::Insert(i, bytes) => {
                        let at = i % (len + 1);
                        file.splice(at..at, bytes);
                    }
                    Mutation::Remove(i, n) => {
                        let at = i % (len + 1);
                        file.drain(at..(at + n).min(len));
                    }
                    Mutation::Truncate(i) => file.truncate(i % (len + 1)),
                }
            }
            let _ = parse_ply(&file, Path::new("fuzz.ply"));
        }
    }
}
