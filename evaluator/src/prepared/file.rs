//! The file of one prepared image: its test depth and its ground-truth renders, LZ4-compressed,
//! behind a header that ties the file to one dataset content and one evaluator and carries a
//! checksum of everything after it. A file that fails any of these is refused as a whole, so a
//! score is never computed from a stale, foreign or damaged file.
//!
//! The depth is cut into bands of [`BAND_ROWS`] rows compressed apart, so that an evaluation
//! inflates only the rows its renders cover (as it does with a PNG, but also skipping the rows
//! above them); each ground-truth render is compressed apart, as most estimates meet only one.
//! Depth that is an integer times the image's depth scale (every PNG and TIFF of BOP) is stored
//! as those 16-bit integers, row-differenced, and turned back into millimetres with the very
//! float32 product the depth reader uses; anything else is stored as float32 as is.

use std::ops::Range;

use crate::depth_files::DepthRows;
use crate::render::DepthWindow;

/// The first bytes of every prepared image file.
const MAGIC: &[u8; 8] = b"PBPREP\r\n";

/// The layout of the files; a change to it, or to what is stored, makes older files stale.
pub const FORMAT: u32 = 1;

/// Rows per separately compressed band of depth.
pub const BAND_ROWS: u32 = 16;

/// Images larger than this are refused (a BOP image has at most a few million pixels); it keeps
/// a damaged size from asking for an absurd allocation.
const MAX_PIXELS: u64 = 1 << 28;

/// What a file must have been made for: one dataset content, one evaluator, one image.
#[derive(Clone, Copy, Debug)]
pub struct Stamp<'a> {
    pub content_hash: &'a str,
    pub evaluator: &'a str,
    pub scene_id: u32,
    pub im_id: u32,
}

/// The evaluator's version, as stamped on prepared files.
pub fn evaluator_version() -> String {
    format!("{} format {FORMAT}", env!("CARGO_PKG_VERSION"))
}

/// Everything prepared for one image, decoded.
#[derive(Clone, Debug)]
pub struct ImageData {
    pub width: u32,
    pub height: u32,
    /// Row-major depth in mm, 0 = no measurement.
    pub depth: Vec<f32>,
    /// The image's depth scale as the depth reader multiplies by it.
    pub depth_scale: f32,
    /// One render per ground-truth instance, in the order of the image's ground truth (empty
    /// for objects without a model).
    pub gts: Vec<DepthWindow>,
}

/// How the depth of a file is stored.
#[derive(Clone, Copy, Debug, PartialEq)]
enum DepthKind {
    /// 16-bit integers times the depth scale.
    Scaled,
    /// float32 as is.
    Floats,
}

impl ImageData {
    /// Equal to the bit (f32's `==` would take -0 for 0, and no NaN for itself).
    pub fn identical(&self, other: &ImageData) -> bool {
        let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<u32>>();
        self.width == other.width
            && self.height == other.height
            && self.depth_scale.to_bits() == other.depth_scale.to_bits()
            && bits(&self.depth) == bits(&other.depth)
            && self.gts.len() == other.gts.len()
            && self.gts.iter().zip(&other.gts).all(|(a, b)| {
                (a.x0, a.y0, a.width, a.height) == (b.x0, b.y0, b.width, b.height)
                    && bits(&a.data) == bits(&b.data)
            })
    }

    /// The file's bytes: header, then the compressed payload.
    pub fn encode(&self, stamp: &Stamp) -> Vec<u8> {
        let mut payload = Vec::new();
        let kind = if self
            .depth
            .iter()
            .all(|&d| as_sample(d, self.depth_scale).is_some())
        {
            DepthKind::Scaled
        } else {
            DepthKind::Floats
        };
        put_u32(&mut payload, self.width);
        put_u32(&mut payload, self.height);
        payload.push(match kind {
            DepthKind::Scaled => 0,
            DepthKind::Floats => 1,
        });
        payload.extend_from_slice(&self.depth_scale.to_le_bytes());
        put_u32(&mut payload, BAND_ROWS);
        let width = self.width.max(1) as usize;
        for band in self.depth.chunks(width * BAND_ROWS as usize) {
            let mut raw = Vec::with_capacity(band.len() * 4);
            match kind {
                DepthKind::Scaled => {
                    let mut prev = 0u16;
                    for &d in band {
                        let s = as_sample(d, self.depth_scale).unwrap_or(0);
                        raw.extend_from_slice(&s.wrapping_sub(prev).to_le_bytes());
                        prev = s;
                    }
                }
                DepthKind::Floats => {
                    for &d in band {
                        raw.extend_from_slice(&d.to_le_bytes());
                    }
                }
            }
            put_block(&mut payload, &raw);
        }
        put_u32(&mut payload, self.gts.len() as u32);
        for w in &self.gts {
            for v in [w.x0, w.y0, w.width, w.height] {
                put_u32(&mut payload, v);
            }
            let raw: Vec<u8> = w.data.iter().flat_map(|d| d.to_le_bytes()).collect();
            put_block(&mut payload, &raw);
        }

        let mut out = Vec::with_capacity(payload.len() + 128);
        out.extend_from_slice(MAGIC);
        put_u32(&mut out, FORMAT);
        put_str(&mut out, stamp.evaluator);
        put_str(&mut out, stamp.content_hash);
        put_u32(&mut out, stamp.scene_id);
        put_u32(&mut out, stamp.im_id);
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        put_u32(&mut out, crc32fast::hash(&payload));
        out.extend_from_slice(&payload);
        out
    }
}

/// The depth sample whose product with `scale` is `d` bit for bit, if there is one.
fn as_sample(d: f32, scale: f32) -> Option<u16> {
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let v = (d / scale).round();
    if !(0.0..=65535.0).contains(&v) {
        return None;
    }
    let s = v as u16;
    (f32::from(s) * scale)
        .to_bits()
        .eq(&d.to_bits())
        .then_some(s)
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u16).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// Raw length, compressed length, compressed bytes.
fn put_block(out: &mut Vec<u8>, raw: &[u8]) {
    let compressed = lz4_flex::block::compress(raw);
    put_u32(out, raw.len() as u32);
    put_u32(out, compressed.len() as u32);
    out.extend_from_slice(&compressed);
}

/// Reads the fields of a file in order; running out of bytes is an error, never a panic.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| format!("ends at byte {} inside a field", self.bytes.len()))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    fn str(&mut self) -> Result<&'a str, String> {
        let n = u16::from_le_bytes(self.array()?) as usize;
        std::str::from_utf8(self.take(n)?).map_err(|_| "a header field is not UTF-8".to_string())
    }

    /// A compressed block: (raw length, compressed bytes).
    fn block(&mut self) -> Result<(usize, Range<usize>), String> {
        let raw = self.u32()? as usize;
        let n = self.u32()? as usize;
        let start = self.at;
        self.take(n)?;
        Ok((raw, start..start + n))
    }
}

/// A prepared image file whose header and checksum were verified; its blocks are inflated on
/// demand.
#[derive(Debug)]
pub struct PreparedImage {
    bytes: Vec<u8>,
    width: u32,
    height: u32,
    kind: DepthKind,
    depth_scale: f32,
    band_rows: u32,
    /// Per band of depth, its compressed block.
    bands: Vec<Range<usize>>,
    /// Per ground-truth instance, its window and compressed block.
    gts: Vec<(DepthWindow, Range<usize>)>,
}

impl PreparedImage {
    /// Checks `bytes` against `stamp` and its checksum, and indexes its blocks; the message
    /// says what is wrong.
    pub fn parse(bytes: Vec<u8>, stamp: &Stamp) -> Result<PreparedImage, String> {
        let mut c = Cursor {
            bytes: &bytes,
            at: 0,
        };
        if c.take(MAGIC.len()).ok() != Some(MAGIC.as_slice()) {
            return Err("not a prepared image file".into());
        }
        let format = c.u32()?;
        if format != FORMAT {
            return Err(format!(
                "file format {format}, this evaluator reads {FORMAT}"
            ));
        }
        let evaluator = c.str()?;
        if evaluator != stamp.evaluator {
            return Err(format!(
                "made by evaluator {evaluator}, this is {}",
                stamp.evaluator
            ));
        }
        let hash = c.str()?;
        if hash != stamp.content_hash {
            return Err(format!(
                "made for dataset content {hash}, not {}",
                stamp.content_hash
            ));
        }
        let (scene_id, im_id) = (c.u32()?, c.u32()?);
        if (scene_id, im_id) != (stamp.scene_id, stamp.im_id) {
            return Err(format!(
                "holds scene {scene_id} image {im_id}, not scene {} image {}",
                stamp.scene_id, stamp.im_id
            ));
        }
        let len = u64::from_le_bytes(c.array()?);
        let crc = c.u32()?;
        let start = c.at;
        if (bytes.len() - start) as u64 != len {
            return Err(format!(
                "truncated or padded: {} bytes of data where the header states {len}",
                bytes.len() - start
            ));
        }
        if crc32fast::hash(&bytes[start..]) != crc {
            return Err("checksum mismatch: the file is damaged".into());
        }

        let (width, height) = (c.u32()?, c.u32()?);
        if u64::from(width) * u64::from(height) > MAX_PIXELS {
            return Err(format!("{width}x{height} pixels is not a depth image size"));
        }
        let kind = match c.take(1)?[0] {
            0 => DepthKind::Scaled,
            1 => DepthKind::Floats,
            other => return Err(format!("unknown depth storage {other}")),
        };
        let depth_scale = f32::from_le_bytes(c.array()?);
        let band_rows = c.u32()?;
        if band_rows == 0 {
            return Err("bands of 0 rows".into());
        }
        let n_bands = height.div_ceil(band_rows);
        let sample = match kind {
            DepthKind::Scaled => 2,
            DepthKind::Floats => 4,
        };
        let mut bands = Vec::with_capacity(n_bands as usize);
        for b in 0..n_bands {
            let rows = band_rows.min(height - b * band_rows);
            let (raw, block) = c.block()?;
            if raw != (rows * width) as usize * sample {
                return Err(format!("depth band {b} has the wrong length"));
            }
            bands.push(block);
        }
        let n_gts = c.u32()? as usize;
        let mut gts = Vec::with_capacity(n_gts.min(bytes.len()));
        for g in 0..n_gts {
            let w = DepthWindow {
                x0: c.u32()?,
                y0: c.u32()?,
                width: c.u32()?,
                height: c.u32()?,
                data: Vec::new(),
            };
            let (raw, block) = c.block()?;
            let fits = u64::from(w.x0) + u64::from(w.width) <= u64::from(width)
                && u64::from(w.y0) + u64::from(w.height) <= u64::from(height);
            if !fits || raw != (w.width * w.height) as usize * 4 {
                return Err(format!("ground-truth render {g} does not fit the image"));
            }
            gts.push((w, block));
        }
        if c.at != bytes.len() {
            return Err("data after the last ground-truth render".into());
        }
        Ok(PreparedImage {
            bytes,
            width,
            height,
            kind,
            depth_scale,
            band_rows,
            bands,
            gts,
        })
    }

    /// (width, height) of the depth image.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Number of ground-truth renders.
    pub fn gt_count(&self) -> usize {
        self.gts.len()
    }

    fn inflate(&self, block: &Range<usize>, raw: usize) -> Result<Vec<u8>, String> {
        let mut out = vec![0u8; raw];
        let n = lz4_flex::block::decompress_into(&self.bytes[block.clone()], &mut out)
            .map_err(|e| format!("a compressed block is invalid: {e}"))?;
        if n != raw {
            return Err("a compressed block has the wrong length".into());
        }
        Ok(out)
    }

    /// The whole bands of depth covering `rows` (clamped to the image).
    pub fn rows(&self, rows: Range<u32>) -> Result<DepthRows, String> {
        let (y1, y0) = (
            rows.end.min(self.height),
            rows.start.min(rows.end).min(self.height),
        );
        let (b0, b1) = (y0 / self.band_rows, y1.div_ceil(self.band_rows));
        let w = self.width as usize;
        let mut data = Vec::with_capacity(w * ((b1 - b0) * self.band_rows) as usize);
        for b in b0..b1 {
            let rows = self.band_rows.min(self.height - b * self.band_rows) as usize;
            match self.kind {
                DepthKind::Scaled => {
                    let raw = self.inflate(&self.bands[b as usize], rows * w * 2)?;
                    let mut prev = 0u16;
                    let scale = self.depth_scale;
                    data.extend(raw.as_chunks::<2>().0.iter().map(|&b| {
                        prev = prev.wrapping_add(u16::from_le_bytes(b));
                        f32::from(prev) * scale
                    }));
                }
                DepthKind::Floats => {
                    let raw = self.inflate(&self.bands[b as usize], rows * w * 4)?;
                    data.extend(
                        raw.as_chunks::<4>()
                            .0
                            .iter()
                            .map(|&b| f32::from_le_bytes(b)),
                    );
                }
            }
        }
        Ok(DepthRows {
            width: self.width,
            height: self.height,
            y0: (b0 * self.band_rows).min(y1),
            data,
        })
    }

    /// The render of ground-truth instance `i`.
    pub fn gt(&self, i: usize) -> Result<DepthWindow, String> {
        let (w, block) = self
            .gts
            .get(i)
            .ok_or_else(|| format!("no render of ground-truth instance {i}"))?;
        let raw = self.inflate(block, (w.width * w.height) as usize * 4)?;
        Ok(DepthWindow {
            data: raw
                .as_chunks::<4>()
                .0
                .iter()
                .map(|&b| f32::from_le_bytes(b))
                .collect(),
            ..w.clone()
        })
    }

    /// Everything the file holds, decoded (to compare with a fresh computation).
    pub fn decode(&self) -> Result<ImageData, String> {
        Ok(ImageData {
            width: self.width,
            height: self.height,
            depth: self.rows(0..self.height)?.data,
            depth_scale: self.depth_scale,
            gts: (0..self.gts.len())
                .map(|i| self.gt(i))
                .collect::<Result<_, _>>()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp() -> Stamp<'static> {
        Stamp {
            content_hash: "abc",
            evaluator: "test",
            scene_id: 1,
            im_id: 2,
        }
    }

    fn image(depth_scale: f32, depth: Vec<f32>) -> ImageData {
        ImageData {
            width: 5,
            height: 40,
            depth,
            depth_scale,
            gts: vec![
                DepthWindow {
                    x0: 1,
                    y0: 17,
                    width: 2,
                    height: 3,
                    data: vec![0.0, 1.5, 700.25, 701.0, 0.0, 699.0],
                },
                DepthWindow::empty(),
            ],
        }
    }

    #[test]
    fn scaled_and_float_depth_come_back_bit_for_bit() {
        let scale = 0.1f32;
        let scaled: Vec<f32> = (0..200u16).map(|v| f32::from(v * 7) * scale).collect();
        let floats: Vec<f32> = (0..200).map(|v| v as f32 * 0.37 + 0.001).collect();
        for data in [image(scale, scaled), image(scale, floats)] {
            let bytes = data.encode(&stamp());
            let back = PreparedImage::parse(bytes, &stamp()).unwrap();
            assert!(back.decode().unwrap().identical(&data));
            // A band from the middle: whole bands covering rows 20..22.
            let rows = back.rows(20..22).unwrap();
            assert_eq!(rows.y0, 16);
            assert_eq!(rows.data, data.depth[16 * 5..32 * 5]);
        }
    }

    #[test]
    fn a_file_for_another_image_dataset_or_evaluator_is_refused() {
        let bytes = image(1.0, vec![1.0; 200]).encode(&stamp());
        let other = |s: Stamp| PreparedImage::parse(bytes.clone(), &s).unwrap_err();
        assert!(
            other(Stamp {
                im_id: 3,
                ..stamp()
            })
            .contains("scene 1 image 2")
        );
        assert!(
            other(Stamp {
                content_hash: "abd",
                ..stamp()
            })
            .contains("dataset content abc")
        );
        assert!(
            other(Stamp {
                evaluator: "new",
                ..stamp()
            })
            .contains("evaluator test")
        );
    }

    #[test]
    fn every_truncation_and_every_flipped_byte_is_refused() {
        let bytes = image(1.0, vec![3.0; 200]).encode(&stamp());
        for n in 0..bytes.len() {
            assert!(PreparedImage::parse(bytes[..n].to_vec(), &stamp()).is_err());
            let mut flipped = bytes.clone();
            flipped[n] ^= 0x10;
            assert!(
                PreparedImage::parse(flipped, &stamp()).is_err(),
                "byte {n} flipped"
            );
        }
    }
}
