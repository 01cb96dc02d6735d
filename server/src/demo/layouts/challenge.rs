//! Miniatures of the datasets the BOP challenge added in 2024: BOP-Industrial (IPD, XYZ-IBD,
//! ITODD-MV) and BOP-H3 (HOPEv2, HANDAL, HOT3D), laid out as bop_toolkit's `dataset_params.py`
//! reads them, at their published image sizes.
//!
//! HOPEv2 and HANDAL keep the classic layout (HANDAL's RGB as JPEG). The industrial datasets
//! record each scene with several sensors: every sensor gets its own annotations
//! (`scene_gt_{sensor}.json`, `scene_camera_{sensor}.json`, `scene_gt_info_{sensor}.json`) and
//! camera file (`camera_{sensor}.json`, intrinsics scaled to its size), and the sensor the
//! toolkit evaluates also its images (`gray_xyz/`, `depth_xyz/`, ...); the other sensors'
//! images are not written, as no evaluation reads them. HOT3D has Quest 3 scenes (ids from
//! 1288, evaluated on the `gray1` stream) and Aria scenes (ids from 3365, on `rgb`), each
//! stream with its own annotations, JPEG images, no depth and a `cam_model` FISHEYE624 camera
//! in place of `cam_K`. Its distortion coefficients are the Taylor series of `tan(θ) / θ`, so
//! the fisheye model reproduces the pinhole renders of the synthetic scenes to a small
//! fraction of a pixel: the ground truth still lies where the images show it.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};

use super::super::files::{write_depth_tiff, write_json_list, write_json_object};
use super::super::scenes::cam_k;
use super::super::{SynthOptions, write_dataset};
use super::{read_json, read_png, rename, to_gray};

/// How the evaluated images of a sensor are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Images {
    /// `rgb/*.png` (the synthetic dataset's).
    RgbPng,
    /// `rgb/*.jpg`.
    RgbJpeg,
    /// `gray/*.png`.
    GrayPng,
    /// `gray/*.tif` with depth as TIFF too (ITODD's sensors).
    GrayTiff,
    /// `gray1/*.jpg` (HOT3D's Quest 3 stream).
    GrayJpeg,
}

/// One of the datasets the challenge added in 2024.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChallengeLayout {
    /// The BOP name: the folder and the dataset part of result file names.
    pub name: &'static str,
    /// (width, height) of the evaluated images, as `dataset_params.py` states them (for
    /// HOT3D those of the Quest 3 stream; Aria's RGB is 1408 x 1408).
    pub published_size: (u32, u32),
    kind: Kind,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Classic(Images),
    /// The evaluated sensor with its image modality, then the others with their sizes.
    Sensors {
        eval: &'static str,
        images: Images,
        others: &'static [(&'static str, (u32, u32))],
    },
    Hot3d,
}

/// HOPEv2, HANDAL, IPD, XYZ-IBD, ITODD-MV and HOT3D, after `dataset_params.py`.
pub const CHALLENGE_LAYOUTS: [ChallengeLayout; 6] = [
    ChallengeLayout {
        name: "hopev2",
        published_size: (1920, 1080),
        kind: Kind::Classic(Images::RgbPng),
    },
    ChallengeLayout {
        name: "handal",
        published_size: (1920, 1440),
        kind: Kind::Classic(Images::RgbJpeg),
    },
    ChallengeLayout {
        name: "ipd",
        published_size: (2064, 1544),
        kind: Kind::Sensors {
            eval: "photoneo",
            images: Images::RgbPng,
            others: &[
                ("cam1", (3840, 2160)),
                ("cam2", (3840, 2160)),
                ("cam3", (3840, 2160)),
            ],
        },
    },
    ChallengeLayout {
        name: "xyzibd",
        published_size: (1440, 1080),
        kind: Kind::Sensors {
            eval: "xyz",
            images: Images::GrayPng,
            others: &[("photoneo", (2064, 1544)), ("realsense", (1280, 720))],
        },
    },
    ChallengeLayout {
        name: "itoddmv",
        published_size: (1280, 960),
        kind: Kind::Sensors {
            eval: "3dlong",
            images: Images::GrayTiff,
            others: &[
                ("cam0", (4224, 2838)),
                ("cam1", (4224, 2838)),
                ("cam2", (4224, 2838)),
            ],
        },
    },
    ChallengeLayout {
        name: "hot3d",
        published_size: (1280, 1024),
        kind: Kind::Hot3d,
    },
];

/// One HOT3D device: its evaluated stream and that stream's size, the other streams with
/// theirs, and the id before its first test scene.
type Device = (
    &'static str,
    (u32, u32),
    &'static [(&'static str, (u32, u32))],
    u32,
);
const HOT3D_QUEST3: Device = ("gray1", (1280, 1024), &[("gray2", (1280, 1024))], 1287);
const HOT3D_ARIA: Device = (
    "rgb",
    (1408, 1408),
    &[("gray1", (640, 480)), ("gray2", (640, 480))],
    3364,
);

/// Writes the synthetic dataset of `opts` into `dir` laid out as `layout`, with
/// `test_targets_bop19.json` and the BOP'24 image list `test_targets_bop24.json`.
pub fn write_challenge_miniature(
    dir: &Path,
    layout: &ChallengeLayout,
    opts: &SynthOptions,
) -> Result<()> {
    match layout.kind {
        Kind::Classic(images) => {
            write_dataset(dir, &sized(opts, layout.published_size))?;
            for scene in scene_dirs(dir)? {
                convert_images(&scene, images, "")?;
            }
        }
        Kind::Sensors {
            eval,
            images,
            others,
        } => {
            write_dataset(dir, &sized(opts, layout.published_size))?;
            let camera: serde_json::Map<String, Value> = read_json(&dir.join("camera.json"))?;
            std::fs::remove_file(dir.join("camera.json"))?;
            write_camera_file(dir, eval, &camera, layout.published_size)?;
            for &(sensor, size) in others {
                write_camera_file(dir, sensor, &camera, size)?;
            }
            for scene in scene_dirs(dir)? {
                for &(sensor, size) in others {
                    copy_annotations(&scene, sensor, Some(size))?;
                }
                suffix_annotations(&scene, eval)?;
                convert_images(&scene, images, &format!("_{eval}"))?;
                rename(&scene.join("depth"), &scene.join(format!("depth_{eval}")))?;
            }
        }
        Kind::Hot3d => write_hot3d(dir, opts)?,
    }
    write_bop24_targets(dir)
}

fn sized(opts: &SynthOptions, image_size: (u32, u32)) -> SynthOptions {
    SynthOptions {
        image_size,
        ..opts.clone()
    }
}

/// HOT3D: the synthetic scenes written twice, at the Quest 3 and at the Aria size; odd scenes
/// become Quest 3 scenes, even ones Aria scenes, renumbered into the test ids of each device.
fn write_hot3d(dir: &Path, opts: &SynthOptions) -> Result<()> {
    // The parts are written inside `dir` (so on its file system) and removed at the end.
    let parts = dir.join(".parts");
    let mut targets: Vec<Value> = Vec::new();
    for (odd, (stream, size, others, first_id)) in [(true, HOT3D_QUEST3), (false, HOT3D_ARIA)] {
        let part = parts.join(stream);
        if odd {
            if dir.read_dir().is_ok_and(|mut d| d.next().is_some()) {
                bail!("{} is not empty", dir.display());
            }
            write_dataset(&part, &sized(opts, size))?;
            // The models are the same in both parts.
            std::fs::create_dir_all(dir.join("test"))?;
            rename(&part.join("models"), &dir.join("models"))?;
            rename(&part.join("models_eval"), &dir.join("models_eval"))?;
        } else {
            write_dataset(&part, &sized(opts, size))?;
        }
        let part_targets: Vec<Value> = read_json(&part.join("test_targets_bop19.json"))?;
        for scene_id in 1..=opts.scenes {
            if (scene_id % 2 == 1) != odd {
                continue;
            }
            let new_id = first_id + scene_id;
            let scene = dir.join("test").join(format!("{new_id:06}"));
            rename(&part.join("test").join(format!("{scene_id:06}")), &scene)?;
            std::fs::remove_dir_all(scene.join("depth"))?;
            for &(other, other_size) in others {
                copy_annotations(&scene, other, Some(other_size))?;
                fisheye_cameras(
                    &scene.join(format!("scene_camera_{other}.json")),
                    other_size,
                )?;
            }
            suffix_annotations(&scene, stream)?;
            fisheye_cameras(&scene.join(format!("scene_camera_{stream}.json")), size)?;
            let images = if stream == "rgb" {
                Images::RgbJpeg
            } else {
                Images::GrayJpeg
            };
            convert_images(&scene, images, "")?;
            targets.extend(
                part_targets
                    .iter()
                    .filter(|t| t["scene_id"] == json!(scene_id))
                    .map(|t| {
                        let mut t = t.clone();
                        t["scene_id"] = json!(new_id);
                        t
                    }),
            );
        }
    }
    std::fs::remove_dir_all(&parts)
        .with_context(|| format!("cannot remove {}", parts.display()))?;
    targets.sort_by_key(|t| {
        (
            t["scene_id"].as_u64(),
            t["im_id"].as_u64(),
            t["obj_id"].as_u64(),
        )
    });
    write_json_list(&dir.join("test_targets_bop19.json"), &targets)
}

/// `scene_camera_{stream}.json` with each `cam_K` replaced by a `cam_model` as HOT3D writes
/// it. Real Aria cameras state one focal length (15 parameters); the synthetic intrinsics
/// scaled to a square image have two, so every stream gets the 16-parameter form the toolkit
/// reads as well.
fn fisheye_cameras(path: &Path, (width, height): (u32, u32)) -> Result<()> {
    // tan(θ) / θ = 1 + θ²/3 + 2θ⁴/15 + 17θ⁶/315 + 62θ⁸/2835 + 1382θ¹⁰/155925 + ...
    let radial = [
        1.0 / 3.0,
        2.0 / 15.0,
        17.0 / 315.0,
        62.0 / 2835.0,
        1382.0 / 155_925.0,
        21_844.0 / 6_081_075.0,
    ];
    let mut cameras: BTreeMap<u32, Value> = read_json(path)?;
    for cam in cameras.values_mut() {
        let k: Vec<f64> = serde_json::from_value(cam["cam_K"].take())?;
        let mut params = vec![k[0], k[4], k[2], k[5]];
        params.extend(radial);
        params.extend([0.0; 6]);
        let fields = cam.as_object_mut().context("a camera entry is no object")?;
        fields.remove("cam_K");
        fields.remove("depth_scale");
        fields.insert(
            "cam_model".into(),
            json!({
                "image_width": width,
                "image_height": height,
                "projection_model_type": "CameraModelType.FISHEYE624",
                "projection_params": params,
            }),
        );
    }
    write_json_object(path, cameras)
}

/// `camera_{sensor}.json`: the synthetic camera's intrinsics scaled to `size`.
fn write_camera_file(
    dir: &Path,
    sensor: &str,
    camera: &serde_json::Map<String, Value>,
    size: (u32, u32),
) -> Result<()> {
    let k = cam_k(size);
    let mut camera = camera.clone();
    for (key, value) in [("fx", k[0]), ("fy", k[4]), ("cx", k[2]), ("cy", k[5])] {
        camera.insert(key.into(), json!(value));
    }
    camera.insert("width".into(), json!(size.0));
    camera.insert("height".into(), json!(size.1));
    write_json_object(&dir.join(format!("camera_{sensor}.json")), camera)
}

/// Copies the scene's annotations as another sensor's (`scene_gt_{sensor}.json`, ...), with the
/// intrinsics scaled to that sensor's size when it has one of its own.
fn copy_annotations(scene: &Path, sensor: &str, size: Option<(u32, u32)>) -> Result<()> {
    for stem in ["scene_gt", "scene_gt_info"] {
        let to = scene.join(format!("{stem}_{sensor}.json"));
        std::fs::copy(scene.join(format!("{stem}.json")), &to)
            .with_context(|| format!("cannot write {}", to.display()))?;
    }
    let mut cameras: BTreeMap<u32, Value> = read_json(&scene.join("scene_camera.json"))?;
    if let Some(size) = size {
        for cam in cameras.values_mut() {
            cam["cam_K"] = json!(cam_k(size));
        }
    }
    write_json_object(&scene.join(format!("scene_camera_{sensor}.json")), cameras)
}

/// Renames the scene's annotations to the evaluated sensor's (`scene_gt.json` ->
/// `scene_gt_{sensor}.json`, the COCO files likewise).
fn suffix_annotations(scene: &Path, sensor: &str) -> Result<()> {
    for stem in [
        "scene_gt",
        "scene_camera",
        "scene_gt_info",
        "scene_gt_coco",
        "scene_gt_coco_modal",
    ] {
        let from = scene.join(format!("{stem}.json"));
        if from.exists() {
            rename(&from, &scene.join(format!("{stem}_{sensor}.json")))?;
        }
    }
    Ok(())
}

/// Turns the scene's `rgb/*.png` into the images of `images`, in the folder named after the
/// modality and `suffix` (`gray_xyz/`).
fn convert_images(scene: &Path, images: Images, suffix: &str) -> Result<()> {
    let rgb = scene.join("rgb");
    let (modality, ext) = match images {
        Images::RgbPng => ("rgb", "png"),
        Images::RgbJpeg => ("rgb", "jpg"),
        Images::GrayPng => ("gray", "png"),
        Images::GrayTiff => ("gray", "tif"),
        Images::GrayJpeg => ("gray1", "jpg"),
    };
    let out = scene.join(format!("{modality}{suffix}"));
    if images == Images::RgbPng {
        return if out == rgb {
            Ok(())
        } else {
            rename(&rgb, &out)
        };
    }
    // Moved aside first: the converted images may go to a folder of the same name (`rgb/`).
    let pngs = scene.join(".rgb-png");
    rename(&rgb, &pngs)?;
    std::fs::create_dir_all(&out)?;
    let mut names: Vec<_> = std::fs::read_dir(&pngs)?
        .map(|e| Ok(e?.path()))
        .collect::<Result<_>>()?;
    names.sort();
    for png in names {
        let im_id: u32 = png
            .file_stem()
            .and_then(|s| s.to_str()?.parse().ok())
            .with_context(|| format!("{} is not an image of the scene", png.display()))?;
        let target = out.join(format!("{im_id:06}.{ext}"));
        match images {
            Images::RgbJpeg => {
                let (size, pixels) = read_png(&png)?;
                write_jpeg(&target, size, &pixels, jpeg_encoder::ColorType::Rgb)?;
            }
            Images::GrayJpeg => {
                let (size, gray) = to_gray(&png)?;
                write_jpeg(&target, size, &gray, jpeg_encoder::ColorType::Luma)?;
            }
            Images::GrayPng | Images::GrayTiff => {
                let (size, gray) = to_gray(&png)?;
                super::write_gray(&out, im_id, size, &gray, images == Images::GrayTiff)?;
            }
            Images::RgbPng => {
                std::fs::copy(&png, &target)
                    .with_context(|| format!("cannot write {}", target.display()))?;
            }
        }
    }
    std::fs::remove_dir_all(&pngs)?;
    if images == Images::GrayTiff {
        // ITODD's sensors store depth as TIFF too.
        for entry in std::fs::read_dir(scene.join("depth"))? {
            let path = entry?.path();
            let (size, bytes) = read_png(&path)?;
            let values: Vec<u16> = bytes
                .chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]]))
                .collect();
            write_depth_tiff(&path.with_extension("tif"), size, &values)?;
            std::fs::remove_file(&path)?;
        }
    }
    Ok(())
}

fn write_jpeg(
    path: &Path,
    (width, height): (u32, u32),
    pixels: &[u8],
    color: jpeg_encoder::ColorType,
) -> Result<()> {
    let (w, h) = (u16::try_from(width)?, u16::try_from(height)?);
    jpeg_encoder::Encoder::new_file(path, 95)
        .and_then(|e| e.encode(pixels, w, h, color))
        .with_context(|| format!("cannot write {}", path.display()))
}

fn scene_dirs(dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    let mut scenes: Vec<_> = std::fs::read_dir(dir.join("test"))?
        .map(|e| Ok(e?.path()))
        .collect::<Result<_>>()?;
    scenes.sort();
    Ok(scenes)
}

/// `test_targets_bop24.json`: every image of the BOP'19 targets, once.
fn write_bop24_targets(dir: &Path) -> Result<()> {
    let targets: Vec<Value> = read_json(&dir.join("test_targets_bop19.json"))?;
    let mut images: Vec<(u64, u64)> = targets
        .iter()
        .filter_map(|t| Some((t["scene_id"].as_u64()?, t["im_id"].as_u64()?)))
        .collect();
    images.sort();
    images.dedup();
    let images: Vec<Value> = images
        .into_iter()
        .map(|(scene_id, im_id)| json!({"im_id": im_id, "scene_id": scene_id}))
        .collect();
    write_json_list(&dir.join("test_targets_bop24.json"), &images)
}
