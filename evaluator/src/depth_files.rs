//! Depth images as BOP publishes them: 16-bit grayscale PNG for most datasets, 16-bit
//! grayscale TIFF for ITODD (bop_toolkit's `dataset_params.py` gives it the `.tif` extension
//! for depth and gray images). Values become millimetres as bop_toolkit computes them: the
//! stored integer as f32 times `depth_scale` as f32. Both decoders are bounded by the file's
//! size, so a small file cannot claim a huge image and exhaust memory.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::depth_png::Png;
use crate::error::{Error, Result};

/// A depth image in millimetres; 0 means no measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    pub width: u32,
    pub height: u32,
    /// Row-major: `data[y * width + x]`.
    pub data: Vec<f32>,
}

/// The file format of a dataset's depth images, found from the files on disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthFormat {
    Png,
    Tiff,
}

impl DepthFormat {
    /// The file extension, without the dot, as bop_toolkit spells it.
    pub fn extension(self) -> &'static str {
        match self {
            DepthFormat::Png => "png",
            DepthFormat::Tiff => "tif",
        }
    }

    /// The format of the depth image `{stem}.png` or `{stem}.tif` in `dir`, whichever exists
    /// (PNG when neither does, so that the error names the usual file).
    pub fn find(dir: &Path, stem: &str) -> DepthFormat {
        if !dir.join(format!("{stem}.png")).is_file() && dir.join(format!("{stem}.tif")).is_file() {
            DepthFormat::Tiff
        } else {
            DepthFormat::Png
        }
    }
}

/// (width, height) of a depth image, from its header.
pub fn depth_size(path: &Path, format: DepthFormat) -> Result<(u32, u32)> {
    match format {
        DepthFormat::Png => png_size(path),
        DepthFormat::Tiff => tiff_decoder(path)?
            .dimensions()
            .map_err(|e| tiff_error(path, e)),
    }
}

fn png_error(path: &Path, e: png::DecodingError) -> Error {
    match e {
        png::DecodingError::IoError(e) => Error::io(path, e),
        other => Error::format(path, format!("invalid PNG: {other}")),
    }
}

fn png_decoder(path: &Path) -> Result<png::Decoder<BufReader<File>>> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    // Raw samples: no expansion or 16-to-8 stripping may alter the depth values.
    decoder.set_transformations(png::Transformations::IDENTITY);
    Ok(decoder)
}

fn png_size(path: &Path) -> Result<(u32, u32)> {
    let mut decoder = png_decoder(path)?;
    let info = decoder.read_header_info().map_err(|e| png_error(path, e))?;
    Ok((info.width, info.height))
}

/// Deflate expands data at most about 1032-fold; a header promising more pixels than that
/// is corrupt, and is rejected before its buffer is allocated.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// A depth PNG read into memory, its header checked.
///
/// Inflating a whole 640x480 16-bit image costs about as much as rendering and scoring all the
/// estimates of its target, while the objects of an image lie in a band of its rows: a deflate
/// stream cannot be entered in the middle, but it can be left as soon as the last row a render
/// covers is out, and rows above the band need not be converted. A file damaged below the
/// rows read is therefore not noticed, as it cannot change a score.
pub struct DepthPng {
    path: PathBuf,
    png: Png,
    depth_scale: f32,
}

/// Rows `y0..y0 + rows` of a depth image in mm (0 = no measurement).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthRows {
    pub width: u32,
    /// Height of the whole image.
    pub height: u32,
    pub y0: u32,
    /// Row-major: `data[(y - y0) * width + x]`.
    pub data: Vec<f32>,
}

impl DepthPng {
    fn open(path: PathBuf, depth_scale: f32) -> Result<DepthPng> {
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        let file_len = bytes.len() as u64;
        let png =
            Png::parse(bytes).map_err(|e| Error::format(&path, format!("invalid PNG: {e}")))?;
        let header = png.header;
        if header.color_type != 0 || !matches!(header.bit_depth, 8 | 16) {
            return Err(Error::format(
                &path,
                format!(
                    "depth image must be 16-bit (or 8-bit) grayscale, found colour type \
                     {} with bit depth {}",
                    header.color_name(),
                    header.bit_depth
                ),
            ));
        }
        let (width, height) = (header.width, header.height);
        let pixels_bytes = (png.row_bytes() as u64 + 1) * u64::from(height);
        if pixels_bytes > file_len.saturating_mul(MAX_DEFLATE_RATIO) {
            return Err(Error::format(
                &path,
                format!("{width}x{height} pixels cannot be held by a file of {file_len} bytes"),
            ));
        }
        Ok(DepthPng {
            path,
            png,
            depth_scale,
        })
    }

    /// (width, height) in pixels, as the header states.
    pub fn size(&self) -> (u32, u32) {
        (self.png.header.width, self.png.header.height)
    }

    /// Inflates the image up to the end of `rows` (clamped to the image) and returns those
    /// rows; nothing after them is read (except in interlaced files, where every pass covers
    /// the whole image).
    pub fn read_rows(self, rows: Range<u32>) -> Result<DepthRows> {
        let (width, height) = self.size();
        let (y1, y0) = (rows.end.min(height), rows.start.min(rows.end).min(height));
        let mut data = Vec::with_capacity(width as usize * (y1 - y0) as usize);
        let (scale, sixteen) = (self.depth_scale, self.png.header.bit_depth == 16);
        // Samples are big-endian and rows unpadded at 8 and 16 bits. Pairs of bytes mapped
        // straight into the buffer vectorise (an indexed loop did not).
        let mut push = |row: &[u8]| {
            if sixteen {
                let (samples, _) = row.as_chunks::<2>();
                data.extend(
                    samples
                        .iter()
                        .map(|&b| f32::from(u16::from_be_bytes(b)) * scale),
                );
            } else {
                data.extend(row.iter().map(|&v| f32::from(v) * scale));
            }
        };
        let path = &self.path;
        if self.png.header.interlaced {
            let mut decoder = png::Decoder::new(std::io::Cursor::new(self.png.into_bytes()));
            decoder.set_transformations(png::Transformations::IDENTITY);
            let mut reader = decoder.read_info().map_err(|e| png_error(path, e))?;
            let size = reader.output_buffer_size().unwrap_or(0);
            let mut buf = vec![0u8; size];
            reader
                .next_frame(&mut buf)
                .map_err(|e| png_error(path, e))?;
            let line = size / height.max(1) as usize;
            for y in y0..y1 {
                push(&buf[y as usize * line..(y as usize + 1) * line]);
            }
        } else {
            let mut raw = Vec::new();
            self.png
                .inflate_rows(y1, &mut raw)
                .map_err(|e| Error::format(path, format!("invalid PNG: {e}")))?;
            let stride = self.png.row_bytes() + 1;
            for row in raw.chunks_exact(stride).skip(y0 as usize) {
                push(&row[1..]);
            }
        }
        Ok(DepthRows {
            width,
            height,
            y0,
            data,
        })
    }
}

/// A depth image opened for reading: a PNG is inflated only as far as the rows asked for; a
/// TIFF (ITODD, a handful of images per target) is decoded whole when opened.
pub enum DepthFile {
    Png(Box<DepthPng>),
    Tiff(DepthImage),
}

impl DepthFile {
    pub fn open(path: PathBuf, format: DepthFormat, depth_scale: f32) -> Result<DepthFile> {
        Ok(match format {
            DepthFormat::Png => DepthFile::Png(Box::new(DepthPng::open(path, depth_scale)?)),
            DepthFormat::Tiff => DepthFile::Tiff(read_depth_tiff(&path, depth_scale)?),
        })
    }

    /// (width, height) in pixels.
    pub fn size(&self) -> (u32, u32) {
        match self {
            DepthFile::Png(png) => png.size(),
            DepthFile::Tiff(image) => (image.width, image.height),
        }
    }

    /// The rows `rows` (clamped to the image).
    pub fn read_rows(self, rows: Range<u32>) -> Result<DepthRows> {
        match self {
            DepthFile::Png(png) => png.read_rows(rows),
            DepthFile::Tiff(image) => {
                let (y1, y0) = (
                    rows.end.min(image.height),
                    rows.start.min(rows.end).min(image.height),
                );
                let w = image.width as usize;
                Ok(DepthRows {
                    width: image.width,
                    height: image.height,
                    y0,
                    data: image.data[y0 as usize * w..y1 as usize * w].to_vec(),
                })
            }
        }
    }
}

/// An LZW code of at most 12 bits yields at most 4096 bytes: no TIFF compression BOP data
/// uses expands more than this.
const MAX_TIFF_RATIO: u64 = 4096;

pub(crate) fn tiff_error(path: &Path, e: tiff::TiffError) -> Error {
    match e {
        // The decoder reads offsets the file states: running out of bytes is a broken file,
        // not a failing disk.
        tiff::TiffError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::format(
                path,
                "invalid TIFF: the file ends before the data it points to",
            )
        }
        tiff::TiffError::IoError(e) => Error::io(path, e),
        other => Error::format(path, format!("invalid TIFF: {other}")),
    }
}

pub(crate) fn tiff_decoder(path: &Path) -> Result<tiff::decoder::Decoder<BufReader<File>>> {
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if let Some(problem) =
        oversized_tiff_value(&mut file, file_len).map_err(|e| Error::io(path, e))?
    {
        return Err(Error::format(path, format!("invalid TIFF: {problem}")));
    }
    let mut limits = tiff::decoder::Limits::default();
    limits.decoding_buffer_size = limits
        .decoding_buffer_size
        .min(usize::try_from(file_len.saturating_mul(MAX_TIFF_RATIO)).unwrap_or(usize::MAX));
    Ok(tiff::decoder::Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits))
}

/// A value of the first directory that claims more bytes than the file has, said as a problem.
/// The `tiff` crate reserves room for each value's declared count as it reads the first
/// directory, inside `Decoder::new`, before any limits set on the decoder apply (under its
/// default ones, up to 256 MiB): fuzzing found a 506-byte file that made it allocate 153 MB. A
/// value that does not fit in its entry is stored in the file, so a count beyond the file's
/// length is invalid anyway; anything else about the header is left to the crate. Leaves the
/// file at its start.
fn oversized_tiff_value(file: &mut File, file_len: u64) -> std::io::Result<Option<String>> {
    let mut head = [0u8; 16];
    let got = read_up_to(file, &mut head)?;
    let (little, big) = match &head[..4.min(got)] {
        b"II*\0" => (true, false),
        b"MM\0*" => (false, false),
        b"II+\0" => (true, true),
        b"MM\0+" => (false, true),
        _ => return rewound(file, None),
    };
    let number = |bytes: &[u8]| {
        let next = |n: u64, b: &u8| (n << 8) | u64::from(*b);
        if little {
            bytes.iter().rev().fold(0, next)
        } else {
            bytes.iter().fold(0, next)
        }
    };
    let (directory, count_len, entry_len, value_count_len) = if big {
        (number(&head[8..16]), 8, 20, 8)
    } else {
        (number(&head[4..8]), 2, 12, 4)
    };
    if directory >= file_len {
        return rewound(file, None);
    }
    file.seek(SeekFrom::Start(directory))?;
    let mut count = [0u8; 8];
    if read_up_to(file, &mut count[..count_len])? < count_len {
        return rewound(file, None);
    }
    let entries = number(&count[..count_len]);
    if entries.saturating_mul(entry_len) > file_len {
        return rewound(
            file,
            Some(format!(
                "the first directory has {entries} entries, more than the file holds"
            )),
        );
    }
    let mut entry = [0u8; 20];
    for _ in 0..entries {
        let entry = &mut entry[..entry_len as usize];
        if read_up_to(file, entry)? < entry.len() {
            break;
        }
        let tag = number(&entry[0..2]);
        let value_size = match number(&entry[2..4]) {
            3 | 8 => 2,
            4 | 9 | 11 | 13 => 4,
            5 | 10 | 12 | 16..=18 => 8,
            _ => 1,
        };
        let values = number(&entry[4..4 + value_count_len]);
        if values.saturating_mul(value_size) > file_len {
            return rewound(
                file,
                Some(format!(
                    "tag {tag} declares {values} values, more than the file's {file_len} bytes hold"
                )),
            );
        }
    }
    rewound(file, None)
}

fn rewound(file: &mut File, problem: Option<String>) -> std::io::Result<Option<String>> {
    file.seek(SeekFrom::Start(0))?;
    Ok(problem)
}

/// Reads until `buf` is full or the file ends; how many bytes were read.
fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match file.read(&mut buf[got..])? {
            0 => break,
            n => got += n,
        }
    }
    Ok(got)
}

/// A 16-bit (or 8-bit) grayscale TIFF, uncompressed or compressed with LZW, Deflate or
/// PackBits; its first image only.
fn read_depth_tiff(path: &Path, depth_scale: f32) -> Result<DepthImage> {
    let mut decoder = tiff_decoder(path)?;
    let (width, height) = decoder.dimensions().map_err(|e| tiff_error(path, e))?;
    let color = decoder.colortype().map_err(|e| tiff_error(path, e))?;
    if !matches!(color, tiff::ColorType::Gray(16) | tiff::ColorType::Gray(8)) {
        return Err(Error::format(
            path,
            format!("depth image must be 16-bit (or 8-bit) grayscale, found {color:?}"),
        ));
    }
    let data: Vec<f32> = match decoder.read_image().map_err(|e| tiff_error(path, e))? {
        tiff::decoder::DecodingResult::U16(v) => {
            v.into_iter().map(|d| f32::from(d) * depth_scale).collect()
        }
        tiff::decoder::DecodingResult::U8(v) => {
            v.into_iter().map(|d| f32::from(d) * depth_scale).collect()
        }
        _ => {
            return Err(Error::format(
                path,
                format!("depth image must hold unsigned integers, found {color:?}"),
            ));
        }
    };
    if data.len() as u64 != u64::from(width) * u64::from(height) {
        return Err(Error::format(
            path,
            format!(
                "{width}x{height} pixels, but {} samples (one sample per pixel is expected)",
                data.len()
            ),
        ));
    }
    Ok(DepthImage {
        width,
        height,
        data,
    })
}
