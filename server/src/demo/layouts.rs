//! Miniatures of the seven core BOP datasets as they are published: the synthetic dataset
//! rendered at each one's published image size and rearranged into its folder and file names,
//! split type, camera file, depth scale, targets files, image modality and image file format
//! (ITODD's TIFFs), so that tests load every layout the loader must know without the gigabytes
//! of the real ones.
//!
//! The scenes stay the synthetic dataset's, seen through LINEMOD's intrinsics scaled to the
//! published size: scores on a miniature must equal those on a plain dataset of the same size,
//! and only the layout may differ. Sizes and formats are those of bop_toolkit's
//! `dataset_params.py` for the test split (of the default split type).

mod challenge;

use std::path::Path;

pub use challenge::{CHALLENGE_LAYOUTS, ChallengeLayout, write_challenge_miniature};

use anyhow::{Context, Result, bail};

use super::files::{write_depth_png, write_depth_tiff, write_gray_png, write_gray_tiff};
use super::{SynthOptions, write_dataset};

/// How one core BOP dataset lays out its test split (after bop_toolkit's `dataset_params.py`
/// and the published archives).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoreLayout {
    /// The BOP name: the folder and the dataset part of result file names.
    pub name: &'static str,
    /// The test split's type: the split folder is `test_{type}`.
    pub split_type: Option<&'static str>,
    /// The camera file in the dataset folder.
    pub camera_file: &'static str,
    /// Depth PNG value to millimetres, in `scene_camera.json` of every image.
    pub depth_scale: f64,
    /// Grayscale images only (`gray/` instead of `rgb/`).
    pub gray: bool,
    /// (width, height) of the published test images, which the miniature has too.
    pub published_size: (u32, u32),
    /// Depth and gray images as TIFF (`.tif`, ITODD) instead of PNG.
    pub tiff: bool,
}

/// LM-O, T-LESS, TUD-L, IC-BIN, ITODD, HB and YCB-V, the datasets of the BOP leaderboards'
/// core.
pub const CORE_LAYOUTS: [CoreLayout; 7] = [
    CoreLayout {
        name: "lmo",
        split_type: None,
        camera_file: "camera.json",
        depth_scale: 1.0,
        gray: false,
        published_size: (640, 480),
        tiff: false,
    },
    CoreLayout {
        name: "tless",
        split_type: Some("primesense"),
        camera_file: "camera_primesense.json",
        depth_scale: 0.1,
        gray: false,
        published_size: (720, 540),
        tiff: false,
    },
    CoreLayout {
        name: "tudl",
        split_type: None,
        camera_file: "camera.json",
        depth_scale: 1.0,
        gray: false,
        published_size: (640, 480),
        tiff: false,
    },
    CoreLayout {
        name: "icbin",
        split_type: None,
        camera_file: "camera.json",
        depth_scale: 0.1,
        gray: false,
        published_size: (640, 480),
        tiff: false,
    },
    CoreLayout {
        name: "itodd",
        split_type: None,
        camera_file: "camera.json",
        depth_scale: 0.1,
        gray: true,
        published_size: (1280, 960),
        tiff: true,
    },
    CoreLayout {
        name: "hb",
        split_type: Some("primesense"),
        camera_file: "camera_primesense.json",
        depth_scale: 0.1,
        gray: false,
        published_size: (640, 480),
        tiff: false,
    },
    CoreLayout {
        name: "ycbv",
        split_type: None,
        camera_file: "camera_uw.json",
        depth_scale: 0.1,
        gray: false,
        published_size: (640, 480),
        tiff: false,
    },
];

/// Writes the synthetic dataset of `opts` into `dir` at the layout's published image size, laid
/// out as `layout`: the split folder `test` or `test_{type}`, the camera file, depth images
/// (PNG or TIFF) and `depth_scale` in the layout's unit, `gray/` images for grayscale datasets,
/// and besides `test_targets_bop19.json` the BOP'24 image list `test_targets_bop24.json` (both
/// written by [`write_dataset`]).
pub fn write_core_miniature(dir: &Path, layout: &CoreLayout, opts: &SynthOptions) -> Result<()> {
    let opts = SynthOptions {
        image_size: layout.published_size,
        ..opts.clone()
    };
    write_dataset(dir, &opts)?;
    let split = match layout.split_type {
        Some(t) => format!("test_{t}"),
        None => "test".to_string(),
    };
    if split != "test" {
        rename(&dir.join("test"), &dir.join(&split))?;
    }
    let mut camera: serde_json::Map<String, serde_json::Value> =
        read_json(&dir.join("camera.json"))?;
    let plain_scale = camera["depth_scale"].as_f64().unwrap_or(1.0);
    camera.insert("depth_scale".into(), layout.depth_scale.into());
    std::fs::remove_file(dir.join("camera.json"))?;
    super::files::write_json_object(&dir.join(layout.camera_file), camera)?;

    for scene in std::fs::read_dir(dir.join(&split))? {
        let scene = scene?.path();
        let cameras_path = scene.join("scene_camera.json");
        let mut cameras: std::collections::BTreeMap<u32, serde_json::Value> =
            read_json(&cameras_path)?;
        for (im_id, cam) in &mut cameras {
            cam["depth_scale"] = layout.depth_scale.into();
            let name = format!("{im_id:06}.png");
            let depth = scene.join("depth").join(&name);
            rescale_depth(&depth, plain_scale / layout.depth_scale, layout.tiff)?;
            if layout.gray {
                let gray_dir = scene.join("gray");
                std::fs::create_dir_all(&gray_dir)?;
                let (size, gray) = to_gray(&scene.join("rgb").join(&name))?;
                write_gray(&gray_dir, *im_id, size, &gray, layout.tiff)?;
            }
        }
        if layout.gray {
            std::fs::remove_dir_all(scene.join("rgb"))?;
        }
        super::files::write_json_object(&cameras_path, cameras)?;
    }
    Ok(())
}

fn rename(from: &Path, to: &Path) -> Result<()> {
    std::fs::rename(from, to)
        .with_context(|| format!("cannot rename {} to {}", from.display(), to.display()))
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| format!("{} is not valid", path.display()))
}

/// Rewrites a 16-bit depth PNG with every value times `factor`, rounded, as a PNG or, with
/// `tiff`, as the TIFF `{stem}.tif` in place of the PNG.
fn rescale_depth(path: &Path, factor: f64, tiff: bool) -> Result<()> {
    if factor == 1.0 && !tiff {
        return Ok(());
    }
    let (size, bytes) = read_png(path)?;
    let values: Vec<u16> = bytes
        .chunks_exact(2)
        .map(|b| (f64::from(u16::from_be_bytes([b[0], b[1]])) * factor).round() as u16)
        .collect();
    if tiff {
        write_depth_tiff(&path.with_extension("tif"), size, &values)?;
        std::fs::remove_file(path).with_context(|| format!("cannot remove {}", path.display()))
    } else {
        write_depth_png(path, size, &values)
    }
}

/// The luma (ITU-R BT.601) of an 8-bit RGB PNG, with the image size.
fn to_gray(rgb_path: &Path) -> Result<((u32, u32), Vec<u8>)> {
    let (size, rgb) = read_png(rgb_path)?;
    let gray: Vec<u8> = rgb
        .chunks_exact(3)
        .map(|p| {
            (0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])).round()
                as u8
        })
        .collect();
    Ok((size, gray))
}

/// Writes an 8-bit grayscale image as the image `im_id` of `gray_dir`, PNG or TIFF.
fn write_gray(
    gray_dir: &Path,
    im_id: u32,
    size: (u32, u32),
    gray: &[u8],
    tiff: bool,
) -> Result<()> {
    if tiff {
        write_gray_tiff(&gray_dir.join(format!("{im_id:06}.tif")), size, gray)
    } else {
        write_gray_png(&gray_dir.join(format!("{im_id:06}.png")), size, gray)
    }
}

fn read_png(path: &Path) -> Result<((u32, u32), Vec<u8>)> {
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info()?;
    let Some(size) = reader.output_buffer_size() else {
        bail!("{} is too large", path.display());
    };
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf)?;
    buf.truncate(info.buffer_size());
    Ok(((info.width, info.height), buf))
}
