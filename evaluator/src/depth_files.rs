//! Depth images as BOP publishes them: 16-bit grayscale PNG for most datasets, 16-bit
//! grayscale TIFF for ITODD (bop_toolkit's `dataset_params.py` gives it the `.tif` extension
//! for depth and gray images). Values become millimetres as bop_toolkit computes them: the
//! stored integer as f32 times `depth_scale` as f32. Both decoders are bounded by the file's
//! size, so a small file cannot claim a huge image and exhaust memory.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

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

/// Reads a depth image in millimetres.
pub fn read_depth(path: &Path, format: DepthFormat, depth_scale: f32) -> Result<DepthImage> {
    match format {
        DepthFormat::Png => read_depth_png(path, depth_scale),
        DepthFormat::Tiff => read_depth_tiff(path, depth_scale),
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

pub(crate) fn read_depth_png(path: &Path, depth_scale: f32) -> Result<DepthImage> {
    let file_len = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    let mut reader = png_decoder(path)?
        .read_info()
        .map_err(|e| png_error(path, e))?;
    let (color, bits) = (reader.info().color_type, reader.info().bit_depth);
    let sixteen = match (color, bits) {
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => true,
        (png::ColorType::Grayscale, png::BitDepth::Eight) => false,
        _ => {
            return Err(Error::format(
                path,
                format!(
                    "depth image must be 16-bit (or 8-bit) grayscale, found colour type \
                     {color:?} with bit depth {}",
                    bits as u8
                ),
            ));
        }
    };
    let (width, height) = (reader.info().width, reader.info().height);
    let size = reader
        .output_buffer_size()
        .filter(|&n| n as u64 <= file_len.saturating_mul(MAX_DEFLATE_RATIO))
        .ok_or_else(|| {
            Error::format(
                path,
                format!("{width}x{height} pixels cannot be held by a file of {file_len} bytes"),
            )
        })?;
    let mut buf = vec![0u8; size];
    reader
        .next_frame(&mut buf)
        .map_err(|e| png_error(path, e))?;
    // Samples are big-endian and rows unpadded at 8 and 16 bits. Pairs of bytes mapped
    // straight into the new buffer vectorise (an indexed loop or `chunks_exact` did not).
    let data: Vec<f32> = if sixteen {
        let (samples, _) = buf.as_chunks::<2>();
        samples
            .iter()
            .map(|&b| f32::from(u16::from_be_bytes(b)) * depth_scale)
            .collect()
    } else {
        buf.iter().map(|&v| f32::from(v) * depth_scale).collect()
    };
    Ok(DepthImage {
        width,
        height,
        data,
    })
}

/// An LZW code of at most 12 bits yields at most 4096 bytes: no TIFF compression BOP data
/// uses expands more than this.
const MAX_TIFF_RATIO: u64 = 4096;

fn tiff_error(path: &Path, e: tiff::TiffError) -> Error {
    match e {
        tiff::TiffError::IoError(e) => Error::io(path, e),
        other => Error::format(path, format!("invalid TIFF: {other}")),
    }
}

fn tiff_decoder(path: &Path) -> Result<tiff::decoder::Decoder<BufReader<File>>> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut limits = tiff::decoder::Limits::default();
    limits.decoding_buffer_size = limits
        .decoding_buffer_size
        .min(usize::try_from(file_len.saturating_mul(MAX_TIFF_RATIO)).unwrap_or(usize::MAX));
    Ok(tiff::decoder::Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits))
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
