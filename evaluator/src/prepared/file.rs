//! The file of one prepared image: its test depth and its ground-truth renders, LZ4-compressed,
//! behind a header that ties the file to one dataset content and one evaluator. A file that
//! fails any check is refused, so a score is never computed from a stale, foreign or damaged
//! file.
//!
//! The depth is cut into tiles of [`BAND_ROWS`] rows by [`TILE_COLS`] columns compressed
//! apart, so that an evaluation inflates only the tiles its renders cover. It inflated whole
//! rows of bands before: on images of 960 x 720 with objects of BOP's sizes the bands were a
//! quarter of a one-thread evaluation, while the renders of an image cover a tenth of its
//! pixels. Each ground-truth render is compressed apart, as most estimates meet only one.
//! Depth that is an integer times the image's depth scale (every PNG and TIFF of BOP) is stored
//! as those 16-bit integers, row-differenced, and turned back into millimetres with the very
//! float32 product the depth reader uses; anything else is stored as float32 as is.
//!
//! The header is followed by an index of every block (its lengths and its CRC-32), with a
//! checksum of its own, and then the blocks. Opening a file reads only the header and the
//! index, and checks the file's size against it (a truncated or padded file is refused at
//! once); a block is read (positioned reads) and checked against its CRC when it is asked for.
//! Reading whole files and checksumming all of them was 15 % of a one-thread evaluation of a
//! large set, though an evaluation needs only the bands its renders cover and the renders of
//! the instances its estimates meet. A damaged block is thus found when it is needed, or by
//! [`PreparedImage::verify`], which a preparation runs on every file it keeps.

use std::fs::File;
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::Path;

use crate::render::{DepthWindow, PixelBox};

/// The first bytes of every prepared image file.
const MAGIC: &[u8; 8] = b"PBPREP\r\n";

/// The layout of the files; a change to it, or to what is stored, makes older files stale.
/// 2: an index of the blocks with a CRC-32 each, instead of one checksum of the whole file.
/// 3: depth in tiles instead of bands of whole rows.
pub const FORMAT: u32 = 3;

/// Rows per band of depth tiles.
pub const BAND_ROWS: u32 = 16;

/// Columns per depth tile (the last of a band may be narrower): an object's render is 50 to
/// 300 pixels wide, and a smaller tile compresses worse and lengthens the index.
pub const TILE_COLS: u32 = 64;

/// Images larger than this are refused (a BOP image has at most a few million pixels); it keeps
/// a damaged size from asking for an absurd allocation.
const MAX_PIXELS: u64 = 1 << 28;

/// Bytes read first on opening a file: the header and index of an image of up to about
/// 1,280 x 1,024 pixels (12 bytes per tile) with a few dozen instances; a longer index is read
/// with a second read.
const FIRST_READ: u64 = 16384;

/// What a file must have been made for: one dataset content, one evaluator, one image.
#[derive(Clone, Copy, Debug)]
pub struct Stamp<'a> {
    pub content_hash: &'a str,
    pub evaluator: &'a str,
    pub scene_id: u32,
    pub im_id: u32,
}

/// The evaluator, as stamped on prepared files: its version, the files' format and the
/// fingerprint of its source (see `build.rs`), so that a form made by any other code is stale.
pub fn evaluator_version() -> String {
    format!(
        "{} format {FORMAT} source {}",
        env!("CARGO_PKG_VERSION"),
        env!("EVALUATOR_SOURCE")
    )
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

/// Columns `x0..x0 + cols` of rows `y0..` of a depth image (mm, 0 = no measurement), as
/// [`PreparedImage::region`] reads it: the pixels of tiles it was not asked for are 0, not the
/// image's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthRegion {
    pub width: u32,
    pub height: u32,
    pub x0: u32,
    pub y0: u32,
    pub cols: u32,
    /// Row-major: `data[(y - y0) * cols + (x - x0)]`.
    pub data: Vec<f32>,
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
    /// The file's bytes: header, index, then the compressed blocks.
    pub fn encode(&self, stamp: &Stamp) -> Vec<u8> {
        let kind = if self
            .depth
            .iter()
            .all(|&d| as_sample(d, self.depth_scale).is_some())
        {
            DepthKind::Scaled
        } else {
            DepthKind::Floats
        };
        let mut index = Vec::new();
        let mut blocks = Vec::new();
        put_u32(&mut index, self.width);
        put_u32(&mut index, self.height);
        index.push(match kind {
            DepthKind::Scaled => 0,
            DepthKind::Floats => 1,
        });
        index.extend_from_slice(&self.depth_scale.to_le_bytes());
        put_u32(&mut index, BAND_ROWS);
        put_u32(&mut index, TILE_COLS);
        let width = self.width as usize;
        for tile in tiles(self.width, self.height) {
            let mut raw = Vec::with_capacity(tile.pixels() * 4);
            let mut prev = 0u16;
            for y in tile.rows() {
                let row = &self.depth[y * width..][tile.cols()];
                match kind {
                    // Differences along the tile's rows, read in order: depth changes little
                    // from one pixel to the next, and small differences compress well.
                    DepthKind::Scaled => {
                        for &d in row {
                            let s = as_sample(d, self.depth_scale).unwrap_or(0);
                            raw.extend_from_slice(&s.wrapping_sub(prev).to_le_bytes());
                            prev = s;
                        }
                    }
                    DepthKind::Floats => {
                        for &d in row {
                            raw.extend_from_slice(&d.to_le_bytes());
                        }
                    }
                }
            }
            put_block(&mut index, &mut blocks, &raw);
        }
        put_u32(&mut index, self.gts.len() as u32);
        for w in &self.gts {
            for v in [w.x0, w.y0, w.width, w.height] {
                put_u32(&mut index, v);
            }
            let raw: Vec<u8> = w.data.iter().flat_map(|d| d.to_le_bytes()).collect();
            put_block(&mut index, &mut blocks, &raw);
        }

        let mut out = Vec::with_capacity(index.len() + blocks.len() + 128);
        out.extend_from_slice(MAGIC);
        put_u32(&mut out, FORMAT);
        put_str(&mut out, stamp.evaluator);
        put_str(&mut out, stamp.content_hash);
        put_u32(&mut out, stamp.scene_id);
        put_u32(&mut out, stamp.im_id);
        put_u32(&mut out, index.len() as u32);
        put_u32(&mut out, crc32fast::hash(&index));
        out.extend_from_slice(&index);
        out.extend_from_slice(&blocks);
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

/// One tile of depth: rows `y0..y1` and columns `x0..x1` of the image.
#[derive(Clone, Copy, Debug)]
struct Tile {
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
}

impl Tile {
    fn rows(&self) -> Range<usize> {
        self.y0 as usize..self.y1 as usize
    }

    fn cols(&self) -> Range<usize> {
        self.x0 as usize..self.x1 as usize
    }

    fn pixels(&self) -> usize {
        self.rows().len() * self.cols().len()
    }
}

/// The tiles of an image of `width` x `height`, band by band and left to right in a band: the
/// order of their blocks in a file.
fn tiles(width: u32, height: u32) -> impl Iterator<Item = Tile> {
    (0..height.div_ceil(BAND_ROWS)).flat_map(move |b| {
        (0..width.div_ceil(TILE_COLS)).map(move |t| Tile {
            x0: t * TILE_COLS,
            x1: ((t + 1) * TILE_COLS).min(width),
            y0: b * BAND_ROWS,
            y1: ((b + 1) * BAND_ROWS).min(height),
        })
    })
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u16).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// The block's raw length, compressed length and CRC-32 into the index, its compressed bytes
/// after the others.
fn put_block(index: &mut Vec<u8>, blocks: &mut Vec<u8>, raw: &[u8]) {
    let compressed = lz4_flex::block::compress(raw);
    put_u32(index, raw.len() as u32);
    put_u32(index, compressed.len() as u32);
    put_u32(index, crc32fast::hash(&compressed));
    blocks.extend_from_slice(&compressed);
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

    /// A block's index entry; `at` is where the block starts in the file, moved past it.
    fn block(&mut self, at: &mut u64) -> Result<Block, String> {
        let (raw, len, crc) = (self.u32()? as usize, self.u32()?, self.u32()?);
        let block = Block {
            raw,
            at: *at,
            len: len as usize,
            crc,
        };
        *at += u64::from(len);
        Ok(block)
    }
}

/// Where a compressed block is in its file, and what it must be.
#[derive(Clone, Debug)]
struct Block {
    /// Length once inflated.
    raw: usize,
    at: u64,
    len: usize,
    crc: u32,
}

/// A prepared image file whose header and index were verified; its blocks are read, checked
/// and inflated on demand.
#[derive(Debug)]
pub struct PreparedImage {
    file: File,
    width: u32,
    height: u32,
    kind: DepthKind,
    depth_scale: f32,
    /// Per tile of depth (in the order of [`tiles`]), where it is and its block.
    tiles: Vec<(Tile, Block)>,
    /// Tiles per band.
    across: usize,
    /// Per ground-truth instance, its window and block.
    gts: Vec<(DepthWindow, Block)>,
}

impl PreparedImage {
    /// Opens the file at `path`, checks its header against `stamp`, its index against its
    /// checksum and its size against its index; the message says what is wrong.
    pub fn open(path: &Path, stamp: &Stamp) -> Result<PreparedImage, String> {
        let file = File::open(path).map_err(|e| e.to_string())?;
        let size = file.metadata().map_err(|e| e.to_string())?.len();
        let mut head = read_at(&file, 0, FIRST_READ.min(size) as usize)?;
        let mut c = Cursor {
            bytes: &head,
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
        let (index_len, index_crc) = (u64::from(c.u32()?), c.u32()?);
        let index_at = c.at as u64;
        let index_end = index_at + index_len;
        if index_end > size {
            return Err(format!(
                "truncated: {size} bytes, ending inside the index of {index_len} bytes"
            ));
        }
        if index_end > head.len() as u64 {
            let rest = read_at(
                &file,
                head.len() as u64,
                (index_end - head.len() as u64) as usize,
            )?;
            head.extend_from_slice(&rest);
        }
        let index = &head[index_at as usize..index_end as usize];
        if crc32fast::hash(index) != index_crc {
            return Err("checksum mismatch: the file's index is damaged".into());
        }

        let mut c = Cursor {
            bytes: index,
            at: 0,
        };
        let mut at = index_end;
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
        let (band_rows, tile_cols) = (c.u32()?, c.u32()?);
        if (band_rows, tile_cols) != (BAND_ROWS, TILE_COLS) {
            return Err(format!(
                "tiles of {band_rows} x {tile_cols}, this evaluator reads {BAND_ROWS} x {TILE_COLS}"
            ));
        }
        let sample = match kind {
            DepthKind::Scaled => 2,
            DepthKind::Floats => 4,
        };
        let mut tiles_read = Vec::new();
        for (i, tile) in tiles(width, height).enumerate() {
            let block = c.block(&mut at)?;
            if block.raw != tile.pixels() * sample {
                return Err(format!("depth tile {i} has the wrong length"));
            }
            tiles_read.push((tile, block));
        }
        let n_gts = c.u32()? as usize;
        let mut gts = Vec::with_capacity(n_gts.min(index.len()));
        for g in 0..n_gts {
            let w = DepthWindow {
                x0: c.u32()?,
                y0: c.u32()?,
                width: c.u32()?,
                height: c.u32()?,
                data: Vec::new(),
            };
            let block = c.block(&mut at)?;
            let fits = u64::from(w.x0) + u64::from(w.width) <= u64::from(width)
                && u64::from(w.y0) + u64::from(w.height) <= u64::from(height);
            if !fits || block.raw != (w.width * w.height) as usize * 4 {
                return Err(format!("ground-truth render {g} does not fit the image"));
            }
            gts.push((w, block));
        }
        if c.at != index.len() {
            return Err("data after the index's last ground-truth render".into());
        }
        if at != size {
            return Err(format!(
                "truncated or padded: {size} bytes where the index states {at}"
            ));
        }
        Ok(PreparedImage {
            file,
            width,
            height,
            kind,
            depth_scale,
            tiles: tiles_read,
            across: width.div_ceil(TILE_COLS) as usize,
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

    /// The compressed bytes of the blocks from `first` to `last` (which follow each other in
    /// the file), read at once.
    fn read_span(&self, first: &Block, last: &Block) -> Result<Vec<u8>, String> {
        read_at(
            &self.file,
            first.at,
            (last.at - first.at) as usize + last.len,
        )
    }

    /// One block's bytes (`bytes`, as read), checked against its CRC and inflated into `out`.
    fn inflate(block: &Block, bytes: &[u8], what: &str, out: &mut Vec<u8>) -> Result<(), String> {
        if crc32fast::hash(bytes) != block.crc {
            return Err(format!("checksum mismatch: {what} is damaged"));
        }
        out.resize(block.raw, 0);
        let n = lz4_flex::block::decompress_into(bytes, out)
            .map_err(|e| format!("{what} is invalid: {e}"))?;
        if n != block.raw {
            return Err(format!("{what} has the wrong length"));
        }
        Ok(())
    }

    /// Reads every block and checks it against its CRC, without inflating: a file that passes
    /// is as it was written.
    pub fn verify(&self) -> Result<(), String> {
        let all: Vec<&Block> = self
            .tiles
            .iter()
            .map(|(_, b)| b)
            .chain(self.gts.iter().map(|(_, b)| b))
            .collect();
        let (Some(first), Some(last)) = (all.first(), all.last()) else {
            return Ok(());
        };
        let bytes = self.read_span(first, last)?;
        for (i, block) in all.iter().enumerate() {
            let at = (block.at - first.at) as usize;
            if crc32fast::hash(&bytes[at..at + block.len]) != block.crc {
                return Err(format!("checksum mismatch: block {i} is damaged"));
            }
        }
        Ok(())
    }

    /// The depth under `boxes`: the smallest rectangle of whole tiles holding them all, where
    /// only the tiles that meet a box are read (the others are left 0).
    pub fn region(&self, boxes: &[PixelBox]) -> Result<DepthRegion, String> {
        let (width, height) = (self.width, self.height);
        let boxes: Vec<PixelBox> = boxes
            .iter()
            .filter(|b| b.x0 < width && b.y0 < height)
            .map(|b| PixelBox {
                x1: b.x1.min(width - 1),
                y1: b.y1.min(height - 1),
                ..*b
            })
            .collect();
        let Some(union) = boxes.iter().copied().reduce(|a, b| PixelBox {
            x0: a.x0.min(b.x0),
            y0: a.y0.min(b.y0),
            x1: a.x1.max(b.x1),
            y1: a.y1.max(b.y1),
        }) else {
            return Ok(DepthRegion {
                width,
                height,
                x0: 0,
                y0: 0,
                cols: 0,
                data: Vec::new(),
            });
        };
        let (t0, t1) = (union.x0 / TILE_COLS, union.x1 / TILE_COLS);
        let (b0, b1) = (union.y0 / BAND_ROWS, union.y1 / BAND_ROWS);
        let (x0, y0) = (t0 * TILE_COLS, b0 * BAND_ROWS);
        let cols = (((t1 + 1) * TILE_COLS).min(width) - x0) as usize;
        let rows = (((b1 + 1) * BAND_ROWS).min(height) - y0) as usize;
        let mut data = vec![0f32; cols * rows];
        let mut raw = Vec::new();
        for b in b0..=b1 {
            let band = b as usize * self.across;
            let needed: Vec<usize> = (t0..=t1)
                .map(|t| band + t as usize)
                .filter(|&i| {
                    let tile = &self.tiles[i].0;
                    boxes.iter().any(|p| {
                        tile.x0 <= p.x1 && p.x0 < tile.x1 && tile.y0 <= p.y1 && p.y0 < tile.y1
                    })
                })
                .collect();
            let (Some(&first), Some(&last)) = (needed.first(), needed.last()) else {
                continue;
            };
            let (start, end) = (&self.tiles[first].1, &self.tiles[last].1);
            let bytes = self.read_span(start, end)?;
            for i in needed {
                let (tile, block) = &self.tiles[i];
                let at = (block.at - start.at) as usize;
                let what = format!("depth tile {i}");
                Self::inflate(block, &bytes[at..at + block.len], &what, &mut raw)?;
                let w = tile.cols().len();
                let mut prev = 0u16;
                for (r, y) in tile.rows().enumerate() {
                    let from = (y - y0 as usize) * cols + (tile.x0 - x0) as usize;
                    let dst = &mut data[from..from + w];
                    match self.kind {
                        DepthKind::Scaled => {
                            let src = &raw.as_chunks::<2>().0[r * w..(r + 1) * w];
                            for (d, &s) in dst.iter_mut().zip(src) {
                                prev = prev.wrapping_add(u16::from_le_bytes(s));
                                *d = f32::from(prev) * self.depth_scale;
                            }
                        }
                        DepthKind::Floats => {
                            let src = &raw.as_chunks::<4>().0[r * w..(r + 1) * w];
                            for (d, &s) in dst.iter_mut().zip(src) {
                                *d = f32::from_le_bytes(s);
                            }
                        }
                    }
                }
            }
        }
        Ok(DepthRegion {
            width,
            height,
            x0,
            y0,
            cols: cols as u32,
            data,
        })
    }

    /// The render of ground-truth instance `i`.
    pub fn gt(&self, i: usize) -> Result<DepthWindow, String> {
        let (w, block) = self
            .gts
            .get(i)
            .ok_or_else(|| format!("no render of ground-truth instance {i}"))?;
        let bytes = self.read_span(block, block)?;
        let what = format!("the render of ground-truth instance {i}");
        let mut raw = Vec::new();
        Self::inflate(block, &bytes, &what, &mut raw)?;
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

    /// Everything the file holds, decoded (to check or rewrite a file whole).
    pub fn decode(&self) -> Result<ImageData, String> {
        Ok(ImageData {
            width: self.width,
            height: self.height,
            depth: self
                .region(&[PixelBox {
                    x0: 0,
                    y0: 0,
                    x1: self.width.saturating_sub(1),
                    y1: self.height.saturating_sub(1),
                }])?
                .data,
            depth_scale: self.depth_scale,
            gts: (0..self.gts.len())
                .map(|i| self.gt(i))
                .collect::<Result<_, _>>()?,
        })
    }
}

/// `len` bytes of `file` from `at`; a file that ends before is truncated.
fn read_at(file: &File, at: u64, len: usize) -> Result<Vec<u8>, String> {
    let mut buf = vec![0u8; len];
    file.read_exact_at(&mut buf, at)
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                format!("truncated: ends before byte {}", at + len as u64)
            }
            _ => e.to_string(),
        })?;
    Ok(buf)
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

    /// `bytes` written to a file in `dir` and opened.
    fn open(dir: &Path, bytes: &[u8], stamp: &Stamp) -> Result<PreparedImage, String> {
        let path = dir.join("image.pbprep");
        std::fs::write(&path, bytes).unwrap();
        PreparedImage::open(&path, stamp)
    }

    /// Equal to the bit (f32's `==` would take -0 for 0, and no NaN for itself).
    fn identical(a: &ImageData, b: &ImageData) -> bool {
        let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<u32>>();
        a.width == b.width
            && a.height == b.height
            && a.depth_scale.to_bits() == b.depth_scale.to_bits()
            && bits(&a.depth) == bits(&b.depth)
            && a.gts.len() == b.gts.len()
            && a.gts.iter().zip(&b.gts).all(|(a, b)| {
                (a.x0, a.y0, a.width, a.height) == (b.x0, b.y0, b.width, b.height)
                    && bits(&a.data) == bits(&b.data)
            })
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
        let dir = tempfile::tempdir().unwrap();
        for data in [image(scale, scaled), image(scale, floats)] {
            let bytes = data.encode(&stamp());
            let back = open(dir.path(), &bytes, &stamp()).unwrap();
            back.verify().unwrap();
            assert!(identical(&back.decode().unwrap(), &data));
            // A band from the middle: whole tiles covering rows 20..22.
            let rows = back
                .region(&[PixelBox {
                    x0: 1,
                    y0: 20,
                    x1: 3,
                    y1: 21,
                }])
                .unwrap();
            assert_eq!((rows.x0, rows.y0, rows.cols), (0, 16, 5));
            assert_eq!(rows.data, data.depth[16 * 5..32 * 5]);
        }
    }

    #[test]
    fn a_region_reads_the_tiles_its_boxes_meet() {
        let (width, height) = (150u32, 40u32);
        let depth: Vec<f32> = (0..width * height)
            .map(|i| f32::from((i % 977) as u16) * 0.5)
            .collect();
        let data = ImageData {
            width,
            height,
            depth,
            depth_scale: 0.5,
            gts: Vec::new(),
        };
        let dir = tempfile::tempdir().unwrap();
        let back = open(dir.path(), &data.encode(&stamp()), &stamp()).unwrap();
        // Two boxes: one in the first band's last tile, one in the third band's first tile.
        let boxes = [
            PixelBox {
                x0: 140,
                y0: 3,
                x1: 149,
                y1: 5,
            },
            PixelBox {
                x0: 10,
                y0: 33,
                x1: 12,
                y1: 39,
            },
        ];
        let region = back.region(&boxes).unwrap();
        assert_eq!((region.x0, region.y0, region.cols), (0, 0, width));
        assert_eq!(region.data.len(), (width * height) as usize);
        let at = |x: u32, y: u32| region.data[(y * width + x) as usize];
        for (x, y) in [(140, 3), (149, 5), (128, 0), (10, 33), (0, 32), (63, 39)] {
            assert_eq!(at(x, y), data.depth[(y * width + x) as usize], "({x}, {y})");
        }
        // The tiles no box meets are not read.
        for (x, y) in [(64, 0), (127, 15), (0, 16), (149, 39)] {
            assert_eq!(at(x, y), 0.0, "({x}, {y})");
        }
    }

    #[test]
    fn a_file_for_another_image_dataset_or_evaluator_is_refused() {
        let bytes = image(1.0, vec![1.0; 200]).encode(&stamp());
        let dir = tempfile::tempdir().unwrap();
        let other = |s: Stamp| open(dir.path(), &bytes, &s).unwrap_err();
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

    /// A truncated file is refused on opening (its size disagrees with its index); a flipped
    /// byte is refused on opening when it is in the header or the index, else by the CRC of its
    /// block, when that block is read and by `verify`.
    #[test]
    fn every_truncation_and_every_flipped_byte_is_refused() {
        let bytes = image(1.0, vec![3.0; 200]).encode(&stamp());
        let dir = tempfile::tempdir().unwrap();
        let intact = open(dir.path(), &bytes, &stamp()).unwrap();
        let blocks_at = intact.tiles[0].1.at as usize;
        for n in 0..bytes.len() {
            assert!(
                open(dir.path(), &bytes[..n], &stamp()).is_err(),
                "{n} bytes"
            );
            let mut flipped = bytes.clone();
            flipped[n] ^= 0x10;
            match open(dir.path(), &flipped, &stamp()) {
                Err(_) => assert!(n < blocks_at, "byte {n} of a block refused on opening"),
                Ok(file) => {
                    assert!(n >= blocks_at, "byte {n} of the header or index flipped");
                    assert!(file.verify().unwrap_err().contains("checksum mismatch"));
                    assert!(file.decode().unwrap_err().contains("checksum mismatch"));
                }
            }
        }
    }
}
