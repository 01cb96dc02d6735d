//! A picture of one target for people to look at: the test image with the silhouettes of the
//! object's ground-truth instances and of the estimates its evaluation considered drawn over
//! it, rendered by the same [`Renderer`] the pose errors use, so what a reader sees is what was
//! scored. Nothing here changes a score.
//!
//! The convention (there is no legend in the picture): each silhouette is filled with a
//! half-transparent tint and outlined in the solid colour, green ([`GROUND_TRUTH`]) for the
//! ground truth, magenta ([`ESTIMATE`]) for the estimates, the estimates drawn on top. Only
//! pixels inside a silhouette change, so the picture can be checked against the renderer's
//! masks pixel by pixel.
//!
//! The test image is the dataset's `rgb/` image (PNG or JPEG, as BOP ships them), else its
//! `gray/` image (ITODD ships TIFF), else the depth image scaled to 8-bit gray; an image whose
//! size differs from the camera's (so that the silhouettes would not line up) is passed over
//! for the next one.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

use crate::dataset::{Dataset, Target, scene_dir};
use crate::depth_files::{tiff_decoder, tiff_error};
use crate::error::{Error, Result};
use crate::matching::NTop;
use crate::math::{Intrinsics, Pose};
use crate::render::{Model, Renderer};
use crate::results::Results;
use crate::selection::target_estimates;

/// The tint and outline of ground-truth silhouettes (green).
pub const GROUND_TRUTH: [u8; 3] = [0, 200, 0];
/// The tint and outline of estimated silhouettes (magenta).
pub const ESTIMATE: [u8; 3] = [230, 0, 230];

/// An 8-bit RGB image, row-major, three bytes per pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl RgbImage {
    fn pixel(&self, i: usize) -> [u8; 3] {
        [self.data[3 * i], self.data[3 * i + 1], self.data[3 * i + 2]]
    }

    fn set(&mut self, i: usize, p: [u8; 3]) {
        self.data[3 * i..3 * i + 3].copy_from_slice(&p);
    }
}

/// The pixels of an image a render covers (a depth above 0), row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    pub width: u32,
    pub height: u32,
    pub data: Vec<bool>,
}

impl Mask {
    fn covers(&self, x: i64, y: i64) -> bool {
        x >= 0
            && y >= 0
            && x < i64::from(self.width)
            && y < i64::from(self.height)
            && self.data[(y * i64::from(self.width) + x) as usize]
    }

    /// A covered pixel with a 4-neighbour outside the mask (or beyond the image border).
    fn is_edge(&self, i: usize) -> bool {
        let w = self.width as usize;
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        self.data[i]
            && [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)]
                .iter()
                .any(|&(nx, ny)| !self.covers(nx, ny))
    }
}

/// The silhouette of `model` at `pose` seen by `camera` in a `width` x `height` image.
pub fn silhouette(
    renderer: &mut Renderer,
    model: &Model,
    pose: &Pose,
    camera: &Intrinsics,
    width: u32,
    height: u32,
) -> Mask {
    let window = renderer.render_model(model, pose, camera, width, height);
    let mut data = vec![false; width as usize * height as usize];
    for dy in 0..window.height {
        for dx in 0..window.width {
            if window.data[(dy * window.width + dx) as usize] > 0.0 {
                let (x, y) = (window.x0 + dx, window.y0 + dy);
                data[(y * width + x) as usize] = true;
            }
        }
    }
    Mask {
        width,
        height,
        data,
    }
}

/// `base` seen through a half-transparent `colour` (rounded half up).
pub fn tint(base: [u8; 3], colour: [u8; 3]) -> [u8; 3] {
    std::array::from_fn(|c| (u16::from(base[c]) + u16::from(colour[c])).div_ceil(2) as u8)
}

/// `image` with the silhouettes drawn over it (see the module documentation); every mask must
/// have the image's size.
pub fn compose(image: &RgbImage, ground_truth: &[Mask], estimates: &[Mask]) -> RgbImage {
    let n = image.width as usize * image.height as usize;
    for m in ground_truth.iter().chain(estimates) {
        assert_eq!(
            (m.width, m.height),
            (image.width, image.height),
            "a mask must have the image's size"
        );
    }
    let mut out = image.clone();
    for (masks, colour) in [(ground_truth, GROUND_TRUTH), (estimates, ESTIMATE)] {
        for i in (0..n).filter(|&i| masks.iter().any(|m| m.data[i])) {
            out.set(i, tint(out.pixel(i), colour));
        }
    }
    for (masks, colour) in [(ground_truth, GROUND_TRUTH), (estimates, ESTIMATE)] {
        for m in masks {
            for i in (0..n).filter(|&i| m.is_edge(i)) {
                out.set(i, colour);
            }
        }
    }
    out
}

/// The silhouettes of a target: of every ground-truth instance of its object in its image, and
/// of each estimate its evaluation considers under `n_top` (in decreasing score order).
pub struct TargetSilhouettes {
    pub ground_truth: Vec<Mask>,
    pub estimates: Vec<Mask>,
}

/// Renders the silhouettes of `target` at the dataset's image size.
pub fn target_silhouettes(
    dataset: &Dataset,
    results: &Results,
    target: &Target,
    n_top: NTop,
) -> Result<TargetSilhouettes> {
    let missing = |what: String| Error::format(&dataset.targets_path, what);
    let image = dataset
        .scenes
        .get(&target.scene_id)
        .and_then(|s| s.images.get(&target.im_id))
        .ok_or_else(|| {
            missing(format!(
                "scene {}, image {} is not among the target images",
                target.scene_id, target.im_id
            ))
        })?;
    let object = dataset
        .objects
        .get(&target.obj_id)
        .ok_or_else(|| missing(format!("object {} has no model", target.obj_id)))?;
    let model = Model::new(&object.mesh);
    let (width, height) = dataset.image_size;
    let mut renderer = Renderer::new();
    let mut draw =
        |pose: &Pose| silhouette(&mut renderer, &model, pose, &image.camera, width, height);
    let ground_truth = image
        .gt
        .iter()
        .filter(|g| g.obj_id == target.obj_id)
        .map(|g| draw(&g.pose))
        .collect();
    let estimates = target_estimates(results, target, n_top)
        .into_iter()
        .map(|i| draw(&results.estimates[i].pose))
        .collect();
    Ok(TargetSilhouettes {
        ground_truth,
        estimates,
    })
}

/// The picture of `target`: its test image with the silhouettes of [`target_silhouettes`].
pub fn target_picture(
    dataset: &Dataset,
    results: &Results,
    target: &Target,
    n_top: NTop,
) -> Result<RgbImage> {
    let s = target_silhouettes(dataset, results, target, n_top)?;
    let image = test_image(dataset, target.scene_id, target.im_id)?;
    Ok(compose(&image, &s.ground_truth, &s.estimates))
}

/// [`target_picture`] cut to the object: the box around the ground-truth silhouettes (the
/// estimates' when no instance is in view) with a margin of a quarter of its longer side, at
/// least [`THUMBNAIL_MARGIN_MIN`] pixels, within the image; the whole picture when nothing is
/// drawn. In a gallery of small pictures the object, which covers a few thousand of a scene's
/// 300,000 pixels, is then what is seen.
pub fn target_thumbnail(
    dataset: &Dataset,
    results: &Results,
    target: &Target,
    n_top: NTop,
) -> Result<RgbImage> {
    let s = target_silhouettes(dataset, results, target, n_top)?;
    let image = test_image(dataset, target.scene_id, target.im_id)?;
    let picture = compose(&image, &s.ground_truth, &s.estimates);
    let around = bounding_box(&s.ground_truth).or_else(|| bounding_box(&s.estimates));
    Ok(match around {
        Some(b) => crop(&picture, with_margin(b, picture.width, picture.height)),
        None => picture,
    })
}

/// The least margin of a thumbnail around the object, in pixels.
pub const THUMBNAIL_MARGIN_MIN: u32 = 16;

/// A box of pixels: columns `x0..x1`, rows `y0..y1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// The smallest box holding every covered pixel of `masks`; `None` when none is covered.
pub fn bounding_box(masks: &[Mask]) -> Option<PixelBox> {
    let mut b: Option<PixelBox> = None;
    for m in masks {
        let w = m.width as usize;
        for i in (0..m.data.len()).filter(|&i| m.data[i]) {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            b = Some(match b {
                None => PixelBox {
                    x0: x,
                    y0: y,
                    x1: x + 1,
                    y1: y + 1,
                },
                Some(b) => PixelBox {
                    x0: b.x0.min(x),
                    y0: b.y0.min(y),
                    x1: b.x1.max(x + 1),
                    y1: b.y1.max(y + 1),
                },
            });
        }
    }
    b
}

/// `b` grown by the thumbnail's margin on every side, within a `width` x `height` image.
pub fn with_margin(b: PixelBox, width: u32, height: u32) -> PixelBox {
    let margin = ((b.x1 - b.x0).max(b.y1 - b.y0) / 4).max(THUMBNAIL_MARGIN_MIN);
    PixelBox {
        x0: b.x0.saturating_sub(margin),
        y0: b.y0.saturating_sub(margin),
        x1: (b.x1 + margin).min(width),
        y1: (b.y1 + margin).min(height),
    }
}

/// The pixels of `image` inside `b` (a box within it).
pub fn crop(image: &RgbImage, b: PixelBox) -> RgbImage {
    let row = 3 * image.width as usize;
    let data = (b.y0..b.y1)
        .flat_map(|y| {
            let start = y as usize * row + 3 * b.x0 as usize;
            image.data[start..start + 3 * (b.x1 - b.x0) as usize]
                .iter()
                .copied()
        })
        .collect();
    RgbImage {
        width: b.x1 - b.x0,
        height: b.y1 - b.y0,
        data,
    }
}

/// The test image of an image of the dataset as a person looks at it (see the module
/// documentation for which file is taken).
pub fn test_image(dataset: &Dataset, scene_id: u32, im_id: u32) -> Result<RgbImage> {
    let dir = scene_dir(&dataset.split_dir, scene_id);
    let size = dataset.image_size;
    for folder in ["rgb", "gray"] {
        for ext in ["png", "jpg", "jpeg", "tif", "tiff"] {
            let path = dir.join(folder).join(format!("{im_id:06}.{ext}"));
            if !path.is_file() {
                continue;
            }
            let image = match ext {
                "png" => read_png(&path)?,
                "jpg" | "jpeg" => read_jpeg(&path)?,
                _ => read_tiff(&path)?,
            };
            if (image.width, image.height) == size {
                return Ok(image);
            }
        }
    }
    let depth = dataset.load_depth(scene_id, im_id)?;
    let measured = depth.data.iter().copied().filter(|&d| d > 0.0);
    let (near, far) = measured.fold((f32::MAX, 0f32), |(n, f), d| (n.min(d), f.max(d)));
    let span = (far - near).max(f32::EPSILON);
    // Near is bright, far is dark gray, no measurement black.
    let data = depth
        .data
        .iter()
        .flat_map(|&d| {
            let g = if d > 0.0 {
                (255.0 - (d - near) / span * 191.0).round() as u8
            } else {
                0
            };
            [g, g, g]
        })
        .collect();
    Ok(RgbImage {
        width: depth.width,
        height: depth.height,
        data,
    })
}

/// Samples of 1 to 4 channels (gray, gray + alpha, RGB, RGBA) as RGB.
fn to_rgb(
    path: &Path,
    width: u32,
    height: u32,
    channels: usize,
    samples: &[u8],
) -> Result<RgbImage> {
    let n = width as usize * height as usize;
    if !(1..=4).contains(&channels) || samples.len() < n * channels {
        return Err(Error::format(
            path,
            format!("{width}x{height} pixels, but {} samples", samples.len()),
        ));
    }
    let data = samples
        .chunks_exact(channels)
        .take(n)
        .flat_map(|p| match p.len() {
            1 | 2 => [p[0], p[0], p[0]],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    Ok(RgbImage {
        width,
        height,
        data,
    })
}

fn read_png(path: &Path) -> Result<RgbImage> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let invalid = |e: png::DecodingError| Error::format(path, format!("invalid PNG: {e}"));
    let mut reader = decoder.read_info().map_err(invalid)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Error::format(path, "invalid PNG: the image is too large"))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(invalid)?;
    let channels = info.color_type.samples();
    to_rgb(
        path,
        info.width,
        info.height,
        channels,
        &buf[..info.buffer_size()],
    )
}

fn read_jpeg(path: &Path) -> Result<RgbImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(std::io::Cursor::new(bytes), options);
    let invalid = |e: String| Error::format(path, format!("invalid JPEG: {e}"));
    let pixels = decoder.decode().map_err(|e| invalid(e.to_string()))?;
    let info = decoder
        .info()
        .ok_or_else(|| invalid("no image information".into()))?;
    to_rgb(path, info.width.into(), info.height.into(), 3, &pixels)
}

fn read_tiff(path: &Path) -> Result<RgbImage> {
    let mut decoder = tiff_decoder(path)?;
    let (width, height) = decoder.dimensions().map_err(|e| tiff_error(path, e))?;
    let channels = match decoder.colortype().map_err(|e| tiff_error(path, e))? {
        tiff::ColorType::Gray(_) => 1,
        tiff::ColorType::GrayA(_) => 2,
        tiff::ColorType::RGB(_) => 3,
        tiff::ColorType::RGBA(_) => 4,
        other => {
            return Err(Error::format(
                path,
                format!("a test image must be gray or RGB, found {other:?}"),
            ));
        }
    };
    let samples: Vec<u8> = match decoder.read_image().map_err(|e| tiff_error(path, e))? {
        tiff::decoder::DecodingResult::U8(v) => v,
        tiff::decoder::DecodingResult::U16(v) => v.into_iter().map(|s| (s >> 8) as u8).collect(),
        _ => {
            return Err(Error::format(
                path,
                "a test image must hold 8- or 16-bit unsigned samples",
            ));
        }
    };
    to_rgb(path, width, height, channels, &samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(width: u32, height: u32, on: &[(u32, u32)]) -> Mask {
        let mut data = vec![false; (width * height) as usize];
        for &(x, y) in on {
            data[(y * width + x) as usize] = true;
        }
        Mask {
            width,
            height,
            data,
        }
    }

    #[test]
    fn only_silhouette_pixels_change_in_their_colours() {
        let image = RgbImage {
            width: 5,
            height: 5,
            data: vec![100; 75],
        };
        let square: Vec<(u32, u32)> = (1..4).flat_map(|y| (1..4).map(move |x| (x, y))).collect();
        let gt = mask(5, 5, &square);
        let est = mask(5, 5, &[(3, 3), (4, 3), (3, 4), (4, 4)]);
        let out = compose(&image, &[gt], &[est]);
        let at = |x: usize, y: usize| out.pixel(y * 5 + x);
        // Outside both: untouched.
        assert_eq!(at(0, 0), [100; 3]);
        assert_eq!(at(4, 0), [100; 3]);
        // The centre of the square is inside, not on its edge: tinted green.
        assert_eq!(at(2, 2), tint([100; 3], GROUND_TRUTH));
        // Edges take the solid colour; the estimate's is drawn last.
        assert_eq!(at(1, 1), GROUND_TRUTH);
        assert_eq!(at(3, 3), ESTIMATE);
        assert_eq!(at(4, 4), ESTIMATE);
        let changed = (0..25).filter(|&i| out.pixel(i) != [100; 3]).count();
        assert_eq!(changed, 9 + 3);
    }

    #[test]
    fn a_thumbnail_is_the_object_with_its_margin_within_the_image() {
        let (w, h) = (200, 100);
        let object = mask(w, h, &[(100, 40), (139, 40), (120, 59)]);
        let b = bounding_box(std::slice::from_ref(&object)).expect("covered");
        assert_eq!(
            b,
            PixelBox {
                x0: 100,
                y0: 40,
                x1: 140,
                y1: 60
            }
        );
        // A quarter of the longer side (40 px) is under the least margin: 16 px each side.
        assert_eq!(
            with_margin(b, w, h),
            PixelBox {
                x0: 84,
                y0: 24,
                x1: 156,
                y1: 76
            }
        );
        // Near the border the box stops at the image; a large object gets a quarter.
        let big = mask(w, h, &[(0, 0), (119, 99)]);
        let b = bounding_box(&[big]).expect("covered");
        assert_eq!(
            with_margin(b, w, h),
            PixelBox {
                x0: 0,
                y0: 0,
                x1: 150,
                y1: 100
            }
        );
        assert_eq!(bounding_box(&[mask(w, h, &[])]), None);

        let image = RgbImage {
            width: 4,
            height: 3,
            data: (0..36).collect(),
        };
        let cut = crop(
            &image,
            PixelBox {
                x0: 1,
                y0: 1,
                x1: 3,
                y1: 3,
            },
        );
        assert_eq!((cut.width, cut.height), (2, 2));
        assert_eq!(cut.data, [15, 16, 17, 18, 19, 20, 27, 28, 29, 30, 31, 32]);
    }
}
