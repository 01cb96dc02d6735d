//! A reader for the one kind of PNG BOP stores depth in (16-bit or 8-bit grayscale), fast
//! where the evaluation spends its time: inflating the image data. The png crate inflates with
//! fdeflate; zlib-rs (through flate2) inflates the same streams about 1.35 times faster, and
//! inflating is the largest single cost of an evaluation. The file is read whole, its chunks
//! are walked, and the image data is inflated straight into one buffer, only as far as the rows
//! asked for, then unfiltered in place. Interlaced files (which no BOP dataset uses) are left to
//! the png crate by the caller.
//!
//! Chunk CRCs are checked for the chunks before the image data and for every image data chunk
//! read to its end, as the png crate checks them: a file damaged only below the rows read is
//! not noticed, as it cannot change a score.

use flate2::{Decompress, FlushDecompress, Status};

/// The PNG file signature.
const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];

/// What the header of a PNG states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    /// PNG colour type (0 grayscale, 2 RGB, 3 indexed, 4 grayscale + alpha, 6 RGBA).
    pub color_type: u8,
    pub interlaced: bool,
}

impl Header {
    /// The colour type under the png crate's name, for messages.
    pub fn color_name(&self) -> String {
        match self.color_type {
            0 => "Grayscale".into(),
            2 => "Rgb".into(),
            3 => "Indexed".into(),
            4 => "GrayscaleAlpha".into(),
            6 => "Rgba".into(),
            other => format!("{other}"),
        }
    }
}

/// A PNG's bytes with its header read and its image data found.
pub struct Png {
    bytes: Vec<u8>,
    pub header: Header,
    /// Offset of the first image data (IDAT) chunk.
    idat: usize,
}

/// One chunk as found in the file: `crc` is `None` when the file ends inside it (its data is
/// then what there is).
struct Chunk<'a> {
    kind: [u8; 4],
    data: &'a [u8],
    crc: Option<u32>,
    /// Offset of the next chunk.
    next: usize,
}

impl Chunk<'_> {
    fn crc_ok(&self) -> bool {
        self.crc.is_some_and(|stored| {
            let mut crc = flate2::Crc::new();
            crc.update(&self.kind);
            crc.update(self.data);
            crc.sum() == stored
        })
    }
}

fn chunk_at(bytes: &[u8], pos: usize) -> Option<Chunk<'_>> {
    let head = bytes.get(pos..pos.checked_add(8)?)?;
    let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
    let kind = [head[4], head[5], head[6], head[7]];
    let start = pos + 8;
    let end = start.saturating_add(len);
    Some(match bytes.get(end..end.saturating_add(4)) {
        Some(crc) => Chunk {
            kind,
            data: &bytes[start..end],
            crc: Some(u32::from_be_bytes([crc[0], crc[1], crc[2], crc[3]])),
            next: end + 4,
        },
        None => Chunk {
            kind,
            data: &bytes[start..end.min(bytes.len())],
            crc: None,
            next: bytes.len(),
        },
    })
}

impl Png {
    /// Reads the signature, the header and the chunks up to the image data.
    pub fn parse(bytes: Vec<u8>) -> Result<Png, String> {
        if !bytes.starts_with(&SIGNATURE) {
            return Err("not a PNG file (no PNG signature)".into());
        }
        let ihdr = chunk_at(&bytes, SIGNATURE.len())
            .filter(|c| &c.kind == b"IHDR" && c.data.len() == 13)
            .ok_or("no image header (IHDR) after the signature")?;
        if !ihdr.crc_ok() {
            return Err("CRC error in the image header".into());
        }
        let d = ihdr.data;
        let header = Header {
            width: u32::from_be_bytes([d[0], d[1], d[2], d[3]]),
            height: u32::from_be_bytes([d[4], d[5], d[6], d[7]]),
            bit_depth: d[8],
            color_type: d[9],
            interlaced: d[12] == 1,
        };
        if header.width == 0 || header.height == 0 || header.width > 1 << 31 {
            return Err(format!(
                "invalid image size {}x{}",
                header.width, header.height
            ));
        }
        if d[10] != 0 || d[11] != 0 || d[12] > 1 {
            return Err("unknown compression, filter or interlace method".into());
        }
        let mut pos = ihdr.next;
        loop {
            let chunk = chunk_at(&bytes, pos).ok_or("the file ends before the image data")?;
            if &chunk.kind == b"IDAT" {
                break;
            }
            if &chunk.kind == b"IEND" {
                return Err("no image data (IDAT)".into());
            }
            if !chunk.crc_ok() {
                return Err(format!(
                    "CRC error in chunk {}",
                    String::from_utf8_lossy(&chunk.kind)
                ));
            }
            pos = chunk.next;
        }
        Ok(Png {
            bytes,
            header,
            idat: pos,
        })
    }

    /// The whole file, for decoders that need it (interlaced images).
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    /// Bytes per pixel of a non-interlaced grayscale image of 8 or 16 bits.
    fn bytes_per_pixel(&self) -> usize {
        usize::from(self.header.bit_depth).div_ceil(8)
    }

    /// Bytes per unfiltered row, without the filter byte.
    pub fn row_bytes(&self) -> usize {
        self.header.width as usize * self.bytes_per_pixel()
    }

    /// Inflates and unfilters the first `rows` rows of a non-interlaced 8- or 16-bit
    /// grayscale image into `out` (resized to `rows` rows of [`Png::row_bytes`] + 1 bytes,
    /// each starting with its filter byte).
    pub fn inflate_rows(&self, rows: u32, out: &mut Vec<u8>) -> Result<(), String> {
        let stride = self.row_bytes() + 1;
        let need = stride * rows as usize;
        out.clear();
        out.resize(need, 0);
        let mut z = Decompress::new(true);
        let mut done = 0usize;
        let mut pos = self.idat;
        while done < need {
            let Some(chunk) = chunk_at(&self.bytes, pos).filter(|c| &c.kind == b"IDAT") else {
                break;
            };
            let mut input = chunk.data;
            let mut ended = false;
            while done < need && !input.is_empty() {
                let (in0, out0) = (z.total_in(), z.total_out());
                let status = z
                    .decompress(input, &mut out[done..], FlushDecompress::None)
                    .map_err(|e| format!("corrupt image data: {e}"))?;
                let used = (z.total_in() - in0) as usize;
                let made = (z.total_out() - out0) as usize;
                input = &input[used..];
                done += made;
                if status == Status::StreamEnd || (used == 0 && made == 0) {
                    ended = true;
                    break;
                }
            }
            if input.is_empty() && chunk.crc.is_some() && !chunk.crc_ok() {
                return Err("CRC error in the image data".into());
            }
            if ended {
                break;
            }
            pos = chunk.next;
        }
        if done < need {
            return Err(format!("image data ends at row {}", done / stride));
        }
        unfilter(out, stride, self.bytes_per_pixel())
    }
}

/// Reverses the PNG row filters in place, row by row (each row's filter byte first).
fn unfilter(data: &mut [u8], stride: usize, bpp: usize) -> Result<(), String> {
    let zero = vec![0u8; stride - 1];
    for start in (0..data.len()).step_by(stride) {
        let (before, rest) = data.split_at_mut(start);
        let prev = if start == 0 {
            &zero[..]
        } else {
            &before[start - stride + 1..]
        };
        let (filter, cur) = rest[..stride].split_at_mut(1);
        match filter[0] {
            0 => {}
            1 => {
                for i in bpp..cur.len() {
                    cur[i] = cur[i].wrapping_add(cur[i - bpp]);
                }
            }
            2 => {
                for (c, &p) in cur.iter_mut().zip(prev) {
                    *c = c.wrapping_add(p);
                }
            }
            3 => {
                for i in 0..cur.len() {
                    let left = if i >= bpp { cur[i - bpp] } else { 0 };
                    let avg = ((u16::from(left) + u16::from(prev[i])) >> 1) as u8;
                    cur[i] = cur[i].wrapping_add(avg);
                }
            }
            4 => {
                for i in 0..cur.len() {
                    let (a, c) = if i >= bpp {
                        (cur[i - bpp], prev[i - bpp])
                    } else {
                        (0, 0)
                    };
                    cur[i] = cur[i].wrapping_add(paeth(a, prev[i], c));
                }
            }
            other => {
                return Err(format!(
                    "unknown filter type {other} in row {}",
                    start / stride
                ));
            }
        }
    }
    Ok(())
}

/// The Paeth predictor of the PNG specification.
#[inline]
fn paeth(a: u8, b: u8, c: u8) -> u8 {
    let (ia, ib, ic) = (i16::from(a), i16::from(b), i16::from(c));
    let p = ia + ib - ic;
    let (pa, pb, pc) = ((p - ia).abs(), (p - ib).abs(), (p - ic).abs());
    if pa <= pb && pa <= pc {
        a
    } else if pb <= pc {
        b
    } else {
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `width` x `height` grayscale PNG of `bits` bits whose samples mix smooth ramps and
    /// noise, so that every filter has work to do, encoded by the png crate with `filter`.
    fn encode(width: u32, height: u32, bits: png::BitDepth, filter: png::Filter) -> Vec<u8> {
        let bpp = if bits == png::BitDepth::Sixteen { 2 } else { 1 };
        let mut seed = 0x2545_f491_u32;
        let data: Vec<u8> = (0..width * height * bpp)
            .map(|i| {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                if i % 7 < 4 {
                    (i / 3 % 251) as u8
                } else {
                    seed as u8
                }
            })
            .collect();
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(bits);
        encoder.set_filter(filter);
        let mut writer = encoder.write_header().unwrap();
        writer.write_image_data(&data).unwrap();
        writer.finish().unwrap();
        out
    }

    /// The same PNG with its image data split into IDAT chunks of at most `size` bytes.
    fn split_idat(bytes: &[u8], size: usize) -> Vec<u8> {
        let mut out = bytes[..8].to_vec();
        let mut pos = 8;
        let mut data = Vec::new();
        while let Some(c) = chunk_at(bytes, pos) {
            if &c.kind == b"IDAT" {
                data.extend_from_slice(c.data);
            } else {
                if &c.kind == b"IEND" {
                    for part in data.chunks(size) {
                        write_chunk(&mut out, *b"IDAT", part);
                    }
                }
                write_chunk(&mut out, c.kind, c.data);
            }
            pos = c.next;
        }
        out
    }

    fn write_chunk(out: &mut Vec<u8>, kind: [u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        out.extend_from_slice(&kind);
        out.extend_from_slice(data);
        let mut crc = flate2::Crc::new();
        crc.update(&kind);
        crc.update(data);
        out.extend_from_slice(&crc.sum().to_be_bytes());
    }

    /// The png crate's decoding: rows without filter bytes.
    fn reference(bytes: &[u8]) -> Vec<u8> {
        let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        decoder.set_transformations(png::Transformations::IDENTITY);
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buf).unwrap();
        buf
    }

    fn decode(bytes: &[u8], rows: u32) -> Result<Vec<u8>, String> {
        let png = Png::parse(bytes.to_vec())?;
        let mut raw = Vec::new();
        png.inflate_rows(rows, &mut raw)?;
        let stride = png.row_bytes() + 1;
        Ok(raw
            .chunks_exact(stride)
            .flat_map(|r| &r[1..])
            .copied()
            .collect())
    }

    #[test]
    fn every_filter_and_chunking_decodes_as_the_png_crate_does() {
        use png::{BitDepth, Filter};
        for bits in [BitDepth::Sixteen, BitDepth::Eight] {
            for filter in [
                Filter::NoFilter,
                Filter::Sub,
                Filter::Up,
                Filter::Avg,
                Filter::Paeth,
                Filter::Adaptive,
            ] {
                let bytes = encode(37, 23, bits, filter);
                let expected = reference(&bytes);
                let png = Png::parse(bytes.clone()).unwrap();
                assert_eq!(
                    (png.header.width, png.header.height, png.header.color_type),
                    (37, 23, 0)
                );
                let row = png.row_bytes();
                assert_eq!(decode(&bytes, 23).unwrap(), expected, "{bits:?} {filter:?}");
                assert_eq!(decode(&bytes, 9).unwrap(), expected[..9 * row]);
                assert_eq!(decode(&split_idat(&bytes, 50), 23).unwrap(), expected);
                assert_eq!(
                    decode(&split_idat(&bytes, 1), 17).unwrap(),
                    expected[..17 * row]
                );
            }
        }
    }

    #[test]
    fn damaged_image_data_fails_when_read_and_not_below_the_rows_read() {
        let bytes = split_idat(
            &encode(40, 30, png::BitDepth::Sixteen, png::Filter::Sub),
            100,
        );
        let expected = reference(&bytes);
        // Flip a bit in the data of the last IDAT chunk: its CRC no longer matches.
        let mut pos = 8;
        let mut last = 0;
        while let Some(c) = chunk_at(&bytes, pos) {
            if &c.kind == b"IDAT" {
                last = pos;
            }
            pos = c.next;
        }
        let mut damaged = bytes.clone();
        damaged[last + 9] ^= 0x10;
        let err = decode(&damaged, 30).unwrap_err();
        assert!(err.contains("CRC") || err.contains("corrupt"), "{err}");
        assert_eq!(decode(&damaged, 2).unwrap(), expected[..2 * 80]);
        // A file cut short ends the rows it can give.
        let err = decode(&bytes[..bytes.len() / 2], 30).unwrap_err();
        assert!(err.contains("ends at row"), "{err}");
    }

    #[test]
    fn files_that_are_not_depth_pngs_are_refused_with_a_reason() {
        assert!(
            Png::parse(b"not a png".to_vec())
                .err()
                .unwrap()
                .contains("signature")
        );
        let bytes = encode(4, 4, png::BitDepth::Eight, png::Filter::NoFilter);
        let mut bad_header = bytes.clone();
        bad_header[20] ^= 1;
        assert!(Png::parse(bad_header).err().unwrap().contains("CRC"));
        let mut bad_filter = bytes.clone();
        // The first row's filter byte is the first inflated byte; rewrite it as filter 9.
        let png = Png::parse(bytes).unwrap();
        let mut raw = Vec::new();
        png.inflate_rows(4, &mut raw).unwrap();
        raw[0] = 9;
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut z, &raw).unwrap();
        let idat = z.finish().unwrap();
        bad_filter.truncate(png.idat);
        write_chunk(&mut bad_filter, *b"IDAT", &idat);
        write_chunk(&mut bad_filter, *b"IEND", &[]);
        let err = decode(&bad_filter, 4).unwrap_err();
        assert!(err.contains("filter type 9"), "{err}");
    }
}
