//! A BOP dataset exactly as it lies on disk, read once before an evaluation so that every
//! file problem surfaces up front, naming the file and the field, instead of halfway through
//! hours of rendering. Only the scenes the targets file asks for are read (real datasets hold
//! many more), and depth images are decoded on demand because they dominate the memory.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Display;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::DeserializeOwned;

use crate::depth_files::depth_size;
pub use crate::depth_files::{DepthFile, DepthFormat, DepthImage, DepthRows};
use crate::error::{Error, Result};
use crate::fisheye::{Fisheye624, RawCamModel};
use crate::math::{Intrinsics, Pose};
use crate::mesh::Mesh;
use crate::ply::read_ply;
use crate::sensors::{EvalSensor, eval_sensor, vsd_unsupported};

/// The BOP datasets by the names BOP uses for their folders and result files, with the names
/// the BOP site and papers show.
pub const BOP_DATASETS: &[(&str, &str)] = &[
    ("lm", "LM"),
    ("lmo", "LM-O"),
    ("tless", "T-LESS"),
    ("tudl", "TUD-L"),
    ("tyol", "TYO-L"),
    ("ruapc", "RU-APC"),
    ("icmi", "IC-MI"),
    ("icbin", "IC-BIN"),
    ("itodd", "ITODD"),
    ("itoddmv", "ITODD-MV"),
    ("hb", "HB"),
    ("hbs", "HB"),
    ("ycbv", "YCB-V"),
    ("hope", "HOPE"),
    ("hopev2", "HOPEv2"),
    ("hot3d", "HOT3D"),
    ("handal", "HANDAL"),
    ("ipd", "IPD"),
    ("xyzibd", "XYZ-IBD"),
];

/// How a dataset is shown: BOP's display name for a BOP dataset (`tless` -> `T-LESS`), the
/// name itself for any other.
pub fn display_name(name: &str) -> &str {
    BOP_DATASETS
        .iter()
        .find(|(n, _)| *n == name)
        .map_or(name, |(_, display)| display)
}

/// A continuous rotational symmetry about `axis` through the point `offset` (model frame, mm).
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousSymmetry {
    pub axis: [f64; 3],
    pub offset: [f64; 3],
}

/// One entry of models_info.json.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    pub diameter: f64,
    /// Row-major 4x4 transformations, translation in mm.
    pub symmetries_discrete: Vec<[f64; 16]>,
    pub symmetries_continuous: Vec<ContinuousSymmetry>,
}

impl ModelInfo {
    /// Whether any symmetry is declared (bop_toolkit's `symmetric_obj_ids`).
    pub fn is_symmetric(&self) -> bool {
        !self.symmetries_discrete.is_empty() || !self.symmetries_continuous.is_empty()
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub id: u32,
    pub mesh: Mesh,
    pub info: ModelInfo,
}

/// One ground-truth instance; its index in [`Image::gt`] is the GT id of the BOP files.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GtInstance {
    pub obj_id: u32,
    pub pose: Pose,
    pub visib_fract: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub id: u32,
    /// The pinhole camera (`cam_K`), or for a fisheye camera its pinhole part (see
    /// [`Fisheye624::pinhole_part`]).
    pub camera: Intrinsics,
    /// HOT3D's fisheye camera (`cam_model`), which MSPD projects with when present.
    pub fisheye: Option<Fisheye624>,
    /// Multiplier from depth PNG values to millimetres.
    pub depth_scale: f64,
    pub gt: Vec<GtInstance>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub id: u32,
    /// The sensor whose files were read (BOP-Industrial, HOT3D); `None` for the classic layout.
    pub sensor: Option<EvalSensor>,
    pub images: BTreeMap<u32, Image>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    pub inst_count: u32,
}

/// What a targets file names. The 6D localization protocols need objects and instance counts;
/// BOP'24's 6D detection names images only (the method is not told what is in them), and
/// bop_toolkit then takes every object of an image's ground truth as a target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TargetsForm {
    /// One entry per image and object with `inst_count` (`test_targets_bop19.json`).
    Objects,
    /// One entry per image (`test_targets_bop24.json`); [`Dataset::targets`] then holds every
    /// object of each listed image's ground truth with all its instances, in the order of the
    /// file's images and of the objects' first instance in `scene_gt.json`.
    Images,
}

/// Which split and targets file to read; BOP'19 evaluates `test` with `test_targets_bop19.json`.
///
/// BOP publishes a split in the folder `{split}` or, for datasets recorded with several sensors
/// (T-LESS and HB: `test_primesense`), `{split}_{split_type}`, with the camera file
/// `camera_{split_type}.json`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DatasetOptions {
    pub split: String,
    /// `None`: found from the folders, which works when exactly one of `{split}` and
    /// `{split}_*` exists.
    pub split_type: Option<String>,
    pub targets_file: String,
}

impl Default for DatasetOptions {
    fn default() -> Self {
        DatasetOptions {
            split: "test".to_string(),
            split_type: None,
            targets_file: "test_targets_bop19.json".to_string(),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The folder name, which is the dataset name in result file names.
    pub name: String,
    pub root: PathBuf,
    pub split_dir: PathBuf,
    /// The split type the split folder was found with (`primesense` for `test_primesense`).
    pub split_type: Option<String>,
    pub objects: BTreeMap<u32, Object>,
    pub scenes: BTreeMap<u32, Scene>,
    /// In the order of the targets file.
    pub targets: Vec<Target>,
    pub targets_form: TargetsForm,
    /// (width, height) in pixels.
    pub image_size: (u32, u32),
    /// The files read for the targets and the objects' information.
    pub targets_path: PathBuf,
    pub models_info_path: PathBuf,
    /// `models_eval` when present, else `models`: where the meshes are read from.
    pub models_dir: PathBuf,
    /// PNG, or TIFF as ITODD publishes its depth (found from the first target's image).
    pub depth_format: DepthFormat,
}

impl Dataset {
    /// Loads the `test` split (of the one split type there is) with `test_targets_bop19.json`.
    pub fn load(root: &Path) -> Result<Dataset> {
        Dataset::load_with(root, &DatasetOptions::default())
    }

    pub fn load_with(root: &Path, opts: &DatasetOptions) -> Result<Dataset> {
        if !root.is_dir() {
            return Err(Error::format(
                root,
                "no such folder: expected a BOP dataset folder",
            ));
        }
        let (split_dir, split_type) = find_split(root, opts)?;
        let targets_path = root.join(&opts.targets_file);
        let (targets_form, listed) = load_targets(&targets_path)?;

        let models_dir = [root.join("models_eval"), root.join("models")]
            .into_iter()
            .find(|d| d.is_dir())
            .unwrap_or_else(|| root.join("models"));
        let models_info_path = models_info_path(root, &models_dir);
        let infos = load_models_info(&models_info_path)?;

        let name = root
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .or_else(|| {
                let canonical = root.canonicalize().ok()?;
                Some(canonical.file_name()?.to_string_lossy().into_owned())
            })
            .unwrap_or_default();

        let scene_ids: BTreeSet<u32> = listed.iter().map(|t| t.scene_id).collect();
        let scenes = scene_ids
            .into_iter()
            .map(|id| {
                let sensor = eval_sensor(&name, split_type.as_deref(), id)
                    .map_err(|m| Error::format(scene_dir(&split_dir, id), m))?;
                Ok((id, load_scene(&split_dir, id, sensor)?))
            })
            .collect::<Result<BTreeMap<u32, Scene>>>()?;

        // Checked before the meshes are read: a wrong target is cheaper to report than a
        // large mesh is to parse.
        for (n, t) in listed.iter().enumerate() {
            let which = match t.obj_id {
                Some(obj_id) => format!(
                    "target {n} (scene_id {}, im_id {}, obj_id {obj_id})",
                    t.scene_id, t.im_id
                ),
                None => format!("target {n} (scene_id {}, im_id {})", t.scene_id, t.im_id),
            };
            if let Some(obj_id) = t.obj_id
                && !infos.contains_key(&obj_id)
            {
                return Err(Error::format(
                    &targets_path,
                    format!(
                        "{which}: object {obj_id} has no entry in {}",
                        models_dir.join("models_info.json").display()
                    ),
                ));
            }
            if !scenes[&t.scene_id].images.contains_key(&t.im_id) {
                return Err(Error::format(
                    &targets_path,
                    format!(
                        "{which}: image {} is not in {}",
                        t.im_id,
                        scene_dir(&split_dir, t.scene_id)
                            .join(suffixed("scene_gt", scenes[&t.scene_id].sensor))
                            .display()
                    ),
                ));
            }
        }
        let targets = match targets_form {
            TargetsForm::Objects => listed
                .iter()
                .map(|t| Target {
                    scene_id: t.scene_id,
                    im_id: t.im_id,
                    obj_id: t.obj_id.unwrap_or_default(),
                    inst_count: t.inst_count.unwrap_or_default(),
                })
                .collect(),
            TargetsForm::Images => image_targets(&listed, &scenes, &targets_path, &infos)?,
        };

        let objects = infos
            .into_iter()
            .map(|(id, info)| {
                let mesh = read_ply(&models_dir.join(format!("obj_{id:06}.ply")))?;
                Ok((id, Object { id, mesh, info }))
            })
            .collect::<Result<BTreeMap<u32, Object>>>()?;

        let first = targets[0];
        let depth_format = DepthFormat::find(
            &scene_dir(&split_dir, first.scene_id)
                .join(depth_dir_name(scenes[&first.scene_id].sensor)),
            &format!("{:06}", first.im_id),
        );
        let mut dataset = Dataset {
            depth_format,
            name,
            root: root.to_path_buf(),
            split_dir,
            split_type,
            objects,
            scenes,
            targets,
            targets_form,
            image_size: (0, 0),
            targets_path,
            models_info_path,
            models_dir,
        };
        dataset.image_size = dataset.find_image_size()?;
        Ok(dataset)
    }

    /// Every file whose content decides this dataset's scores, each once, in a fixed order: the
    /// targets file, the objects' information and meshes, the camera files of the dataset's
    /// folder (they give the image size), the ground-truth files of the target scenes and the
    /// depth images of the target images. RGB images, masks and other splits are not among
    /// them: they change no score.
    pub fn score_files(&self) -> Result<Vec<PathBuf>> {
        let mut files = vec![self.targets_path.clone(), self.models_info_path.clone()];
        files.extend(
            self.objects
                .keys()
                .map(|id| self.models_dir.join(format!("obj_{id:06}.ply"))),
        );
        let mut cameras = Vec::new();
        for entry in std::fs::read_dir(&self.root).map_err(|e| Error::io(&self.root, e))? {
            let entry = entry.map_err(|e| Error::io(&self.root, e))?;
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with("camera") && name.ends_with(".json") {
                cameras.push(entry.path());
            }
        }
        cameras.sort();
        files.extend(cameras);
        for (&scene_id, scene) in &self.scenes {
            let dir = scene_dir(&self.split_dir, scene_id);
            for name in ["scene_camera", "scene_gt", "scene_gt_info"] {
                files.push(dir.join(suffixed(name, scene.sensor)));
            }
        }
        // Depth decides only VSD: where the toolkit computes none, the images change no score.
        if vsd_unsupported(&self.name).is_none() {
            let images: BTreeSet<(u32, u32)> =
                self.targets.iter().map(|t| (t.scene_id, t.im_id)).collect();
            files.extend(images.into_iter().map(|(s, i)| self.depth_path(s, i)));
        }
        Ok(files)
    }

    /// The image width MSPD is normalised by in a scene: its sensor's, else the dataset's.
    pub fn image_width(&self, scene_id: u32) -> u32 {
        self.scenes
            .get(&scene_id)
            .and_then(|s| s.sensor)
            .map_or(self.image_size.0, |s| s.size.0)
    }

    pub fn depth_path(&self, scene_id: u32, im_id: u32) -> PathBuf {
        let sensor = self.scenes.get(&scene_id).and_then(|s| s.sensor);
        scene_dir(&self.split_dir, scene_id)
            .join(depth_dir_name(sensor))
            .join(format!("{im_id:06}.{}", self.depth_format.extension()))
    }

    /// Depth in mm: the PNG or TIFF value (as f32) times `depth_scale` (as f32), the float32
    /// arithmetic of bop_toolkit, so that VSD sees the very same depths. 0 = no measurement.
    pub fn load_depth(&self, scene_id: u32, im_id: u32) -> Result<DepthImage> {
        let file = self.open_depth(scene_id, im_id)?;
        let (width, height) = file.size();
        let band = file.read_rows(0..height)?;
        Ok(DepthImage {
            width,
            height,
            data: band.data,
        })
    }

    /// The depth image of a target with only its header read, so that a caller can inflate
    /// just the rows it needs ([`DepthFile::read_rows`]).
    pub fn open_depth(&self, scene_id: u32, im_id: u32) -> Result<DepthFile> {
        let path = self.depth_path(scene_id, im_id);
        let image = self
            .scenes
            .get(&scene_id)
            .and_then(|s| s.images.get(&im_id))
            .ok_or_else(|| {
                Error::format(
                    &path,
                    format!("scene {scene_id}, image {im_id} is not among the target images"),
                )
            })?;
        DepthFile::open(path, self.depth_format, image.depth_scale as f32)
    }

    /// The camera files state the sensor size: the split type's (`camera_primesense.json`)
    /// first, then `camera.json`, then any other (YCB-V has only `camera_uw.json` and
    /// `camera_cmu.json`); only datasets without them fall back to the size of a depth image.
    fn find_image_size(&self) -> Result<(u32, u32)> {
        let mut candidates = Vec::new();
        if let Some(t) = &self.split_type {
            candidates.push(self.root.join(format!("camera_{t}.json")));
        }
        let first = self.targets[0];
        let sensor = self.scenes[&first.scene_id].sensor;
        if let Some(s) = sensor {
            candidates.push(self.root.join(format!("camera_{}.json", s.suffix)));
        }
        candidates.push(self.root.join("camera.json"));
        candidates.retain(|p| p.is_file());
        let entries = std::fs::read_dir(&self.root).map_err(|e| Error::io(&self.root, e))?;
        let mut others = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&self.root, e))?;
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with("camera")
                && name.ends_with(".json")
                && !candidates.contains(&entry.path())
            {
                others.push(entry.path());
            }
        }
        others.sort();
        candidates.extend(others);
        for path in candidates {
            if let Some(size) = parse_camera_size(&read(&path)?, &path)? {
                return Ok(size);
            }
        }
        // HOT3D has neither camera files nor depth: its sensors' published size.
        if let Some(s) = sensor {
            return Ok(s.size);
        }
        depth_size(
            &self.depth_path(first.scene_id, first.im_id),
            self.depth_format,
        )
    }
}

/// The split folder: `{split}_{split_type}` when a type is chosen, otherwise the one folder
/// among `{split}` and `{split}_*` (BOP ships some datasets with one sensor per split type).
pub(crate) fn find_split(root: &Path, opts: &DatasetOptions) -> Result<(PathBuf, Option<String>)> {
    let split = &opts.split;
    if let Some(t) = &opts.split_type {
        let dir = root.join(format!("{split}_{t}"));
        if !dir.is_dir() {
            return Err(Error::format(
                &dir,
                format!("no such folder: expected the split `{split}` of split type `{t}` here"),
            ));
        }
        return Ok((dir, Some(t.clone())));
    }
    let mut candidates: Vec<(PathBuf, Option<String>)> = Vec::new();
    if root.join(split).is_dir() {
        candidates.push((root.join(split), None));
    }
    let prefix = format!("{split}_");
    let entries = std::fs::read_dir(root).map_err(|e| Error::io(root, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(root, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(t) = name.strip_prefix(&prefix)
            && !t.is_empty()
            && entry.path().is_dir()
        {
            candidates.push((entry.path(), Some(t.to_string())));
        }
    }
    candidates.sort();
    match candidates.len() {
        1 => Ok(candidates.remove(0)),
        0 => Err(Error::format(
            root,
            format!(
                "no split folder: expected `{split}/` or `{split}_TYPE/` (as T-LESS's \
                 `test_primesense/`)"
            ),
        )),
        _ => {
            let names: Vec<String> = candidates
                .iter()
                .map(|(p, _)| {
                    p.file_name()
                        .unwrap_or_default()
                        .to_string_lossy()
                        .into_owned()
                })
                .collect();
            Err(Error::format(
                root,
                format!(
                    "several folders hold the split `{split}` ({}): choose the split type",
                    names.join(", ")
                ),
            ))
        }
    }
}

fn load_targets(path: &Path) -> Result<(TargetsForm, Vec<ListedTarget>)> {
    if !path.is_file() {
        return Err(Error::format(
            path,
            "no such file: expected the list of test targets (BOP: test_targets_bop19.json)",
        ));
    }
    parse_targets(&read(path)?, path)
}

// The parsers of a dataset's JSON files, one per file, from its bytes (`path` names the file
// in errors). `Dataset::load` reads each file and hands it to one of them; they are public so
// that each file can be checked alone: parsing one costs microseconds where a whole load
// costs every file, the meshes among them (the fuzz targets of `fuzz/` call them so).

/// The entries of a targets file, and which form they all share: with `obj_id` and
/// `inst_count` (BOP'19) or without (BOP'24 detection, images only).
pub fn parse_targets(bytes: &[u8], path: &Path) -> Result<(TargetsForm, Vec<ListedTarget>)> {
    let raw = parse_json::<Vec<ListedTarget>>(bytes, path)?;
    let Some(first) = raw.first() else {
        return Err(Error::format(path, "the file lists no targets"));
    };
    let form = match (first.obj_id, first.inst_count) {
        (Some(_), Some(_)) => TargetsForm::Objects,
        _ => TargetsForm::Images,
    };
    for (n, t) in raw.iter().enumerate() {
        if t.obj_id.is_some() != t.inst_count.is_some() {
            return Err(Error::format(
                path,
                format!("target {n} has only one of obj_id and inst_count"),
            ));
        }
        let ok = match form {
            TargetsForm::Objects => t.obj_id.is_some() && t.inst_count.is_some(),
            TargetsForm::Images => t.obj_id.is_none() && t.inst_count.is_none(),
        };
        if !ok {
            return Err(Error::format(
                path,
                format!(
                    "target {n} mixes the two forms of targets: give every entry an obj_id \
                     and an inst_count (as test_targets_bop19.json), or none (a list of \
                     images, as test_targets_bop24.json)"
                ),
            ));
        }
    }
    Ok((form, raw))
}

/// bop_toolkit's detection targets (`get_im_targets`): every object in a listed image's
/// ground truth, whatever its visibility, counting all its instances. An image listed twice
/// is taken once.
fn image_targets(
    listed: &[ListedTarget],
    scenes: &BTreeMap<u32, Scene>,
    path: &Path,
    infos: &BTreeMap<u32, ModelInfo>,
) -> Result<Vec<Target>> {
    let mut seen = BTreeSet::new();
    let mut targets: Vec<Target> = Vec::new();
    for t in listed {
        if !seen.insert((t.scene_id, t.im_id)) {
            continue;
        }
        let image = &scenes[&t.scene_id].images[&t.im_id];
        let first = targets.len();
        for (gt_id, g) in image.gt.iter().enumerate() {
            if !infos.contains_key(&g.obj_id) {
                return Err(Error::format(
                    path,
                    format!(
                        "scene {} image {} instance {gt_id}: object {} has no entry in \
                         models_info.json",
                        t.scene_id, t.im_id, g.obj_id
                    ),
                ));
            }
            match targets[first..].iter_mut().find(|x| x.obj_id == g.obj_id) {
                Some(x) => x.inst_count += 1,
                None => targets.push(Target {
                    scene_id: t.scene_id,
                    im_id: t.im_id,
                    obj_id: g.obj_id,
                    inst_count: 1,
                }),
            }
        }
    }
    if targets.is_empty() {
        return Err(Error::format(
            path,
            "no listed image holds a ground-truth instance: nothing to evaluate",
        ));
    }
    Ok(targets)
}

pub(crate) fn scene_dir(split_dir: &Path, scene_id: u32) -> PathBuf {
    split_dir.join(format!("{scene_id:06}"))
}

/// `{stem}.json`, or `{stem}_{sensor}.json` for a scene evaluated on a sensor.
fn suffixed(stem: &str, sensor: Option<EvalSensor>) -> String {
    match sensor {
        Some(s) => format!("{stem}_{}.json", s.suffix),
        None => format!("{stem}.json"),
    }
}

/// `depth`, or `depth_{sensor}` for a scene evaluated on a sensor.
fn depth_dir_name(sensor: Option<EvalSensor>) -> String {
    match sensor {
        Some(s) => format!("depth_{}", s.suffix),
        None => "depth".to_string(),
    }
}

/// An entry of a targets file as listed: an object's instances in an image (BOP'19), or an
/// image alone (BOP'24 detection).
#[derive(Clone, Copy, Debug, Deserialize)]
pub struct ListedTarget {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: Option<u32>,
    pub inst_count: Option<u32>,
}

#[derive(Deserialize)]
struct RawModelInfo {
    diameter: f64,
    #[serde(default)]
    symmetries_discrete: Vec<Vec<f64>>,
    #[serde(default)]
    symmetries_continuous: Vec<RawContinuousSymmetry>,
}

#[derive(Deserialize)]
struct RawContinuousSymmetry {
    axis: Vec<f64>,
    offset: Vec<f64>,
}

#[derive(Deserialize)]
struct RawCamera {
    #[serde(rename = "cam_K")]
    cam_k: Option<Vec<f64>>,
    cam_model: Option<RawCamModel>,
    depth_scale: Option<f64>,
}

#[derive(Deserialize)]
struct RawGt {
    obj_id: u32,
    #[serde(rename = "cam_R_m2c")]
    cam_r_m2c: Vec<f64>,
    cam_t_m2c: Vec<f64>,
}

#[derive(Deserialize)]
struct RawGtInfo {
    visib_fract: f64,
}

#[derive(Deserialize)]
struct RawCameraSize {
    width: Option<u32>,
    height: Option<u32>,
}

/// A dataset's camera file (`camera.json`, `camera_{sensor}.json`): the image size, when it
/// gives both sides.
pub fn parse_camera_size(bytes: &[u8], path: &Path) -> Result<Option<(u32, u32)>> {
    let raw = parse_json::<RawCameraSize>(bytes, path)?;
    Ok(raw.width.zip(raw.height))
}

pub(crate) fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T> {
    parse_json(&read(path)?, path)
}

fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

fn parse_json<T: DeserializeOwned>(bytes: &[u8], path: &Path) -> Result<T> {
    serde_json::from_slice(bytes).map_err(|e| Error::format(path, e.to_string()))
}

/// Parses a JSON object whose keys are ids ("3") into a map keyed by number.
fn parse_id_map<T: DeserializeOwned>(
    bytes: &[u8],
    path: &Path,
    what: &str,
) -> Result<BTreeMap<u32, T>> {
    parse_json::<BTreeMap<String, T>>(bytes, path)?
        .into_iter()
        .map(|(key, value)| {
            let id = key
                .parse::<u32>()
                .map_err(|_| Error::format(path, format!("key \"{key}\" is not {what} id")))?;
            Ok((id, value))
        })
        .collect()
}

/// A fixed-size field, with an error naming where it is when the length is wrong.
fn fixed<const N: usize>(
    values: &[f64],
    path: &Path,
    place: impl Display,
    field: &str,
) -> Result<[f64; N]> {
    values.try_into().map_err(|_| {
        Error::format(
            path,
            format!(
                "{place}: field {field}: expected {N} numbers, found {}",
                values.len()
            ),
        )
    })
}

/// `models_info.json` of the meshes' folder, else that of `models/`.
fn models_info_path(root: &Path, models_dir: &Path) -> PathBuf {
    let path = models_dir.join("models_info.json");
    if path.is_file() {
        path
    } else {
        root.join("models").join("models_info.json")
    }
}

fn load_models_info(path: &Path) -> Result<BTreeMap<u32, ModelInfo>> {
    parse_models_info(&read(path)?, path)
}

/// `models_info.json`: each object's diameter and symmetries.
pub fn parse_models_info(bytes: &[u8], path: &Path) -> Result<BTreeMap<u32, ModelInfo>> {
    parse_id_map::<RawModelInfo>(bytes, path, "an object")?
        .into_iter()
        .map(|(id, raw)| {
            let place = format!("object \"{id}\"");
            let symmetries_discrete = raw
                .symmetries_discrete
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    fixed(
                        m,
                        path,
                        format_args!("{place}, symmetry {i}"),
                        "symmetries_discrete",
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            let symmetries_continuous = raw
                .symmetries_continuous
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    let at = format!("{place}, continuous symmetry {i}");
                    Ok(ContinuousSymmetry {
                        axis: fixed(&s.axis, path, &at, "axis")?,
                        offset: fixed(&s.offset, path, &at, "offset")?,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let info = ModelInfo {
                diameter: raw.diameter,
                symmetries_discrete,
                symmetries_continuous,
            };
            Ok((id, info))
        })
        .collect()
}

/// Images are those of scene_gt.json; scene_camera.json and scene_gt_info.json must
/// describe each of them, instance for instance, since GT ids are list positions.
fn load_scene(split_dir: &Path, scene_id: u32, sensor: Option<EvalSensor>) -> Result<Scene> {
    let dir = scene_dir(split_dir, scene_id);
    let camera_path = dir.join(suffixed("scene_camera", sensor));
    let gt_path = dir.join(suffixed("scene_gt", sensor));
    let info_path = dir.join(suffixed("scene_gt_info", sensor));
    if sensor.is_none() && !gt_path.exists() {
        explain_sensor_files(&dir, &gt_path)?;
    }
    parse_scene(
        scene_id,
        sensor,
        SceneFiles {
            camera: (&camera_path, &read(&camera_path)?),
            gt: (&gt_path, &read(&gt_path)?),
            gt_info: (&info_path, &read(&info_path)?),
        },
    )
}

/// The three files of a scene, each as its path (for errors) and its bytes.
#[derive(Clone, Copy, Debug)]
pub struct SceneFiles<'a> {
    /// `scene_camera.json`
    pub camera: (&'a Path, &'a [u8]),
    /// `scene_gt.json`
    pub gt: (&'a Path, &'a [u8]),
    /// `scene_gt_info.json`
    pub gt_info: (&'a Path, &'a [u8]),
}

/// A scene from its three files, parsed together since ground-truth ids are list positions
/// in two of them.
pub fn parse_scene(
    scene_id: u32,
    sensor: Option<EvalSensor>,
    files: SceneFiles<'_>,
) -> Result<Scene> {
    let (camera_path, info_path, gt_path) = (files.camera.0, files.gt_info.0, files.gt.0);
    let cameras = parse_id_map::<RawCamera>(files.camera.1, camera_path, "an image")?;
    let gts = parse_id_map::<Vec<RawGt>>(files.gt.1, gt_path, "an image")?;
    let infos = parse_id_map::<Vec<RawGtInfo>>(files.gt_info.1, info_path, "an image")?;

    let mut images = BTreeMap::new();
    for (im_id, gt) in gts {
        let missing = |path: &Path| {
            Error::format(
                path,
                format!(
                    "image \"{im_id}\" is missing (it is listed in {})",
                    suffixed("scene_gt", sensor)
                ),
            )
        };
        let camera = cameras.get(&im_id).ok_or_else(|| missing(camera_path))?;
        let info = infos.get(&im_id).ok_or_else(|| missing(info_path))?;
        if info.len() != gt.len() {
            return Err(Error::format(
                info_path,
                format!(
                    "image \"{im_id}\": {} instances, but {} has {}",
                    info.len(),
                    suffixed("scene_gt", sensor),
                    gt.len()
                ),
            ));
        }
        let (camera_k, fisheye) = read_camera(camera, camera_path, im_id)?;
        let gt = gt
            .iter()
            .zip(info)
            .enumerate()
            .map(|(i, (g, info))| {
                let place = format!("image \"{im_id}\", instance {i}");
                let r = fixed(&g.cam_r_m2c, gt_path, &place, "cam_R_m2c")?;
                let t = fixed(&g.cam_t_m2c, gt_path, &place, "cam_t_m2c")?;
                Ok(GtInstance {
                    obj_id: g.obj_id,
                    pose: Pose::from_row_major(&r, &t),
                    visib_fract: info.visib_fract,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let image = Image {
            id: im_id,
            camera: camera_k,
            fisheye,
            depth_scale: camera.depth_scale.unwrap_or(1.0),
            gt,
        };
        images.insert(im_id, image);
    }
    Ok(Scene {
        id: scene_id,
        sensor,
        images,
    })
}

/// A pinhole camera from `cam_K`, or a fisheye one from `cam_model` (HOT3D); bop_toolkit
/// refuses a camera with both, and so does this.
fn read_camera(
    camera: &RawCamera,
    path: &Path,
    im_id: u32,
) -> Result<(Intrinsics, Option<Fisheye624>)> {
    let place = format!("image \"{im_id}\"");
    match (&camera.cam_k, &camera.cam_model) {
        (Some(k), None) => Ok((
            Intrinsics::from_row_major(&fixed(k, path, &place, "cam_K")?),
            None,
        )),
        (None, Some(model)) => {
            let fisheye = Fisheye624::from_cam_model(model)
                .map_err(|m| Error::format(path, format!("{place}: field cam_model: {m}")))?;
            Ok((fisheye.pinhole_part(), Some(fisheye)))
        }
        (Some(_), Some(_)) => Err(Error::format(
            path,
            format!("{place}: both cam_K and cam_model: expected one of them"),
        )),
        (None, None) => Err(Error::format(
            path,
            format!("{place}: missing field `cam_K` (or `cam_model` for a fisheye camera)"),
        )),
    }
}

/// A scene without `scene_gt.json` that holds per-sensor files belongs to a dataset recorded
/// with several sensors, whose evaluated sensor is known by the dataset's name only.
fn explain_sensor_files(dir: &Path, gt_path: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    let mut suffixed: Vec<String> = entries
        .filter_map(|e| Some(e.ok()?.file_name().to_string_lossy().into_owned()))
        .filter(|n| {
            n.starts_with("scene_gt_")
                && n.ends_with(".json")
                && !n.starts_with("scene_gt_info")
                && !n.starts_with("scene_gt_coco")
        })
        .collect();
    if suffixed.is_empty() {
        return Ok(());
    }
    suffixed.sort();
    Err(Error::format(
        gt_path,
        format!(
            "no such file, but the scene holds per-sensor annotations ({}): a dataset recorded \
             with several sensors is read by its BOP name (ipd, xyzibd, itoddmv, hot3d), which \
             decides the sensor evaluated; name the folder so",
            suffixed.join(", ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs::File;

    const REFERENCE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/fixtures/reference/dataset"
    );

    fn reference() -> Dataset {
        Dataset::load(Path::new(REFERENCE)).unwrap()
    }

    /// A writable copy of the reference dataset (without the RGB images nobody reads).
    fn copy() -> tempfile::TempDir {
        fn copy_dir(from: &Path, to: &Path) {
            std::fs::create_dir_all(to).unwrap();
            for entry in std::fs::read_dir(from).unwrap() {
                let entry = entry.unwrap();
                let target = to.join(entry.file_name());
                if entry.file_type().unwrap().is_dir() {
                    if entry.file_name() != "rgb" {
                        copy_dir(&entry.path(), &target);
                    }
                } else {
                    std::fs::copy(entry.path(), target).unwrap();
                }
            }
        }
        let dir = tempfile::tempdir().unwrap();
        copy_dir(Path::new(REFERENCE), &dir.path().join("synthA"));
        dir
    }

    fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
        let mut value: serde_json::Value =
            serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
        edit(&mut value);
        std::fs::write(path, serde_json::to_vec(&value).unwrap()).unwrap();
    }

    fn load_error(dir: &tempfile::TempDir) -> Error {
        Dataset::load(&dir.path().join("synthA")).unwrap_err()
    }

    #[test]
    fn loads_the_reference_dataset() {
        let d = reference();
        assert_eq!(d.name, "dataset");
        assert_eq!(d.split_dir, Path::new(REFERENCE).join("test"));
        assert_eq!(d.objects.keys().copied().collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert_eq!(d.objects[&1].mesh.vertices.len(), 772);
        assert_eq!(d.objects[&1].mesh.triangles.len(), 1536);
        assert!(!d.objects[&1].info.is_symmetric());
        assert!((d.objects[&1].info.diameter - 101.61200716450787).abs() < 1e-12);
        assert_eq!(d.objects[&2].info.symmetries_discrete.len(), 3);
        assert!(d.objects[&2].info.symmetries_continuous.is_empty());
        let cylinder = &d.objects[&3].info;
        assert_eq!(cylinder.symmetries_discrete.len(), 1);
        assert_eq!(cylinder.symmetries_continuous.len(), 1);
        assert_eq!(cylinder.symmetries_continuous[0].axis, [0.0, 0.0, 1.0]);
        assert!(cylinder.is_symmetric());

        assert_eq!(d.scenes.keys().copied().collect::<Vec<_>>(), [1, 2]);
        for scene in d.scenes.values() {
            assert_eq!(
                scene.images.keys().copied().collect::<Vec<_>>(),
                [0, 1, 2, 3]
            );
        }
        assert_eq!(d.targets.len(), 28);
        assert_eq!(d.targets.iter().map(|t| t.inst_count).sum::<u32>(), 33);
        assert_eq!(
            d.targets[0],
            Target {
                scene_id: 1,
                im_id: 0,
                obj_id: 3,
                inst_count: 2
            }
        );
        assert_eq!(d.image_size, (640, 480));

        let image = &d.scenes[&1].images[&0];
        assert_eq!(image.id, 0);
        assert_eq!(image.depth_scale, 1.0);
        assert_eq!(image.camera.fx(), 572.4);
        assert_eq!(image.camera.cy(), 242.0);
        assert_eq!(image.gt[0].visib_fract, 0.5205811138014528);
        let r = image.gt[0].pose.r;
        assert!((r * r.transpose() - crate::math::Mat3::identity()).norm() < 1e-6);
        assert!(image.gt[0].pose.t.z > 100.0);
    }

    #[test]
    fn each_file_parses_alone_as_the_load_parses_it() {
        let d = reference();
        let read = |name: &str| std::fs::read(Path::new(REFERENCE).join(name)).unwrap();
        let (gt, camera, info) = (
            read("test/000001/scene_gt.json"),
            read("test/000001/scene_camera.json"),
            read("test/000001/scene_gt_info.json"),
        );
        let files = SceneFiles {
            camera: (Path::new("scene_camera.json"), &camera),
            gt: (Path::new("scene_gt.json"), &gt),
            gt_info: (Path::new("scene_gt_info.json"), &info),
        };
        assert_eq!(parse_scene(1, None, files).unwrap(), d.scenes[&1]);
        let infos = parse_models_info(&read("models/models_info.json"), Path::new("m")).unwrap();
        assert_eq!(infos[&3], d.objects[&3].info);
        let (form, listed) =
            parse_targets(&read("test_targets_bop19.json"), Path::new("t")).unwrap();
        assert_eq!((form, listed.len()), (d.targets_form, d.targets.len()));
        assert_eq!(
            parse_camera_size(&read("camera.json"), Path::new("c")).unwrap(),
            Some(d.image_size)
        );
        let e = parse_scene(
            1,
            None,
            SceneFiles {
                gt: (Path::new("g"), &b"[1]"[..]),
                ..files
            },
        );
        assert!(e.unwrap_err().to_string().contains("g"));
    }

    #[test]
    fn score_files_are_the_files_read_and_the_target_depths() {
        let d = reference();
        let files = d.score_files().unwrap();
        assert!(files.iter().all(|f| f.is_file()), "{files:?}");
        assert_eq!(files[0], d.targets_path);
        assert!(files.contains(&d.depth_path(1, 2)));
        assert!(files.contains(&Path::new(REFERENCE).join("camera.json")));
        let unique: BTreeSet<&PathBuf> = files.iter().collect();
        assert_eq!(unique.len(), files.len(), "each file once");
        assert!(!files.iter().any(|f| f.to_string_lossy().contains("rgb")));
    }

    #[test]
    fn loads_depth_on_demand() {
        let d = reference();
        assert_eq!(
            d.depth_path(1, 2),
            Path::new(REFERENCE).join("test/000001/depth/000002.png")
        );
        let depth = d.load_depth(1, 0).unwrap();
        assert_eq!((depth.width, depth.height), (640, 480));
        assert_eq!(depth.data.len(), 640 * 480);
        // The table fills the lower image rows, about 0.5 to 1 m away.
        let v = depth.data[460 * 640 + 100];
        assert!(v > 0.0 && v < 2000.0, "{v}");
        assert!(depth.data.iter().all(|&v| (0.0..2000.0).contains(&v)));
        assert!(depth.data.iter().filter(|&&v| v > 0.0).count() > 640 * 480 / 2);
        assert!(matches!(d.load_depth(7, 0), Err(Error::Format { .. })));
    }

    #[test]
    fn depth_scale_is_applied_in_f32() {
        let dir = copy();
        let root = dir.path().join("synthA");
        edit_json(&root.join("test/000001/scene_camera.json"), |v| {
            v["0"]["depth_scale"] = serde_json::json!(0.1);
        });
        let d = Dataset::load(&root).unwrap();
        let raw = reference().load_depth(1, 0).unwrap();
        let scaled = d.load_depth(1, 0).unwrap();
        for (a, b) in raw.data.iter().zip(&scaled.data) {
            assert_eq!(*b, a * 0.1_f32);
        }
    }

    fn write_png(path: &Path, color: png::ColorType, depth: png::BitDepth, data: &[u8]) {
        let file = std::io::BufWriter::new(File::create(path).unwrap());
        let mut encoder = png::Encoder::new(file, 2, 2);
        encoder.set_color(color);
        encoder.set_depth(depth);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(data)
            .unwrap();
    }

    #[test]
    fn depth_png_formats() {
        let dir = copy();
        let root = dir.path().join("synthA");
        let d = Dataset::load(&root).unwrap();
        let path = d.depth_path(1, 0);

        write_png(
            &path,
            png::ColorType::Grayscale,
            png::BitDepth::Eight,
            &[0, 1, 200, 255],
        );
        assert_eq!(d.load_depth(1, 0).unwrap().data, [0.0, 1.0, 200.0, 255.0]);

        let big_endian = [0x00, 0x00, 0x01, 0x02, 0xff, 0xff, 0x12, 0x34];
        write_png(
            &path,
            png::ColorType::Grayscale,
            png::BitDepth::Sixteen,
            &big_endian,
        );
        let depth = d.load_depth(1, 0).unwrap();
        assert_eq!((depth.width, depth.height), (2, 2));
        assert_eq!(depth.data, [0.0, 258.0, 65535.0, 4660.0]);

        write_png(&path, png::ColorType::Rgb, png::BitDepth::Eight, &[0; 12]);
        let msg = d.load_depth(1, 0).unwrap_err().to_string();
        assert!(msg.contains("000000.png") && msg.contains("Rgb"), "{msg}");

        std::fs::write(&path, b"not a png").unwrap();
        assert!(matches!(d.load_depth(1, 0), Err(Error::Format { .. })));
    }

    /// Rewrites every depth image of `root`'s test split as a 16-bit TIFF (ITODD's format).
    fn depth_to_tiff(d: &Dataset, compression: tiff::encoder::Compression) {
        for t in &d.targets {
            let png = d.depth_path(t.scene_id, t.im_id);
            if !png.exists() {
                continue;
            }
            let depth = d.load_depth(t.scene_id, t.im_id).unwrap();
            let values: Vec<u16> = depth.data.iter().map(|&v| v as u16).collect();
            let file = std::io::BufWriter::new(File::create(png.with_extension("tif")).unwrap());
            tiff::encoder::TiffEncoder::new(file)
                .unwrap()
                .with_compression(compression)
                .write_image::<tiff::encoder::colortype::Gray16>(depth.width, depth.height, &values)
                .unwrap();
            std::fs::remove_file(png).unwrap();
        }
    }

    #[test]
    fn a_tiff_declaring_more_values_than_it_holds_is_refused_before_decoding() {
        // Found by fuzzing: this 506-byte file made the tiff crate allocate 153 MB.
        let input = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fuzz/regressions/depth_tiff/oom-328a1de69a01afa6c9e31eb6a5f0893754dfd35c");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000000.tif");
        std::fs::copy(input, &path).unwrap();
        let Err(e) = DepthFile::open(path, DepthFormat::Tiff, 1.0) else {
            panic!("the file is refused");
        };
        assert!(e.to_string().contains("invalid TIFF: tag"), "{e}");
        assert!(
            e.to_string()
                .contains("more than the file's 506 bytes hold"),
            "{e}"
        );
    }

    #[test]
    fn depth_tiff_as_itodd_publishes_it() {
        use tiff::encoder::{Compression, DeflateLevel};
        let expected = reference().load_depth(1, 0).unwrap();
        for compression in [
            Compression::Uncompressed,
            Compression::Lzw,
            Compression::Deflate(DeflateLevel::Fast),
            Compression::Packbits,
        ] {
            let dir = copy();
            let root = dir.path().join("synthA");
            depth_to_tiff(&Dataset::load(&root).unwrap(), compression);
            let d = Dataset::load(&root).unwrap();
            assert_eq!(d.depth_format, DepthFormat::Tiff);
            assert_eq!(
                d.depth_path(1, 0),
                root.join("test/000001/depth/000000.tif")
            );
            assert_eq!(d.load_depth(1, 0).unwrap(), expected);
            // Without camera files the size comes from the first TIFF's header.
            std::fs::remove_file(root.join("camera.json")).unwrap();
            assert_eq!(Dataset::load(&root).unwrap().image_size, (640, 480));
        }

        let dir = copy();
        let root = dir.path().join("synthA");
        let d = Dataset::load(&root).unwrap();
        depth_to_tiff(&d, Compression::Uncompressed);
        let d = Dataset::load(&root).unwrap();
        let path = d.depth_path(1, 0);
        let write = |w: &mut dyn FnMut(&mut tiff::encoder::TiffEncoder<File>)| {
            let mut encoder =
                tiff::encoder::TiffEncoder::new(File::create(&path).unwrap()).unwrap();
            w(&mut encoder);
        };
        write(&mut |e| {
            e.write_image::<tiff::encoder::colortype::Gray8>(2, 2, &[0, 1, 200, 255])
                .unwrap()
        });
        assert_eq!(d.load_depth(1, 0).unwrap().data, [0.0, 1.0, 200.0, 255.0]);
        write(&mut |e| {
            e.write_image::<tiff::encoder::colortype::RGB8>(1, 1, &[1, 2, 3])
                .unwrap()
        });
        let msg = d.load_depth(1, 0).unwrap_err().to_string();
        assert!(
            msg.contains("000000.tif") && msg.contains("16-bit (or 8-bit) grayscale"),
            "{msg}"
        );
        std::fs::write(&path, b"II*\0 not a tiff").unwrap();
        let msg = d.load_depth(1, 0).unwrap_err().to_string();
        assert!(msg.contains("invalid TIFF"), "{msg}");
    }

    #[test]
    fn a_band_of_rows_equals_those_rows_of_the_whole_image() {
        let d = reference();
        let whole = d.load_depth(1, 0).unwrap();
        let png = d.open_depth(1, 0).unwrap();
        assert_eq!(png.size(), (640, 480));
        let band = png.read_rows(150..310).unwrap();
        assert_eq!((band.width, band.height, band.y0), (640, 480, 150));
        assert_eq!(band.data, whole.data[150 * 640..310 * 640]);
        // Ranges are clamped to the image; an empty one reads no samples.
        let tail = d.open_depth(1, 0).unwrap().read_rows(470..900).unwrap();
        assert_eq!(tail.data, whole.data[470 * 640..]);
        let none = d.open_depth(1, 0).unwrap().read_rows(0..0).unwrap();
        assert!(none.data.is_empty());
        assert!(matches!(d.open_depth(7, 0), Err(Error::Format { .. })));
    }

    #[test]
    fn a_truncated_depth_png_fails_only_when_the_missing_rows_are_read() {
        let dir = copy();
        let root = dir.path().join("synthA");
        let d = Dataset::load(&root).unwrap();
        let path = d.depth_path(1, 0);
        let whole = d.load_depth(1, 0).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        let top = d.open_depth(1, 0).unwrap().read_rows(0..10).unwrap();
        assert_eq!(top.data, whole.data[..10 * 640]);
        let err = d.open_depth(1, 0).unwrap().read_rows(0..480).unwrap_err();
        assert!(err.to_string().contains("000000.png"), "{err}");
    }

    #[test]
    fn image_size_falls_back_to_other_cameras_then_depth() {
        let dir = copy();
        let root = dir.path().join("synthA");
        std::fs::remove_file(root.join("camera.json")).unwrap();
        std::fs::write(
            root.join("camera_b.json"),
            r#"{"width": 720, "height": 540}"#,
        )
        .unwrap();
        std::fs::write(root.join("camera_a.json"), r#"{"fx": 1.0}"#).unwrap();
        assert_eq!(Dataset::load(&root).unwrap().image_size, (720, 540));
        std::fs::remove_file(root.join("camera_b.json")).unwrap();
        assert_eq!(Dataset::load(&root).unwrap().image_size, (640, 480));
    }

    #[test]
    fn models_fall_back_to_models_folder() {
        let dir = copy();
        let root = dir.path().join("synthA");
        std::fs::remove_dir_all(root.join("models_eval")).unwrap();
        assert_eq!(Dataset::load(&root).unwrap().objects.len(), 4);
    }

    #[test]
    fn missing_scene_gt_info_names_the_path() {
        let dir = copy();
        std::fs::remove_file(dir.path().join("synthA/test/000002/scene_gt_info.json")).unwrap();
        let err = load_error(&dir);
        assert!(matches!(err, Error::Io { .. }));
        assert!(
            err.to_string().contains("test/000002/scene_gt_info.json"),
            "{err}"
        );
    }

    #[test]
    fn short_cam_k_names_the_field() {
        let dir = copy();
        edit_json(
            &dir.path().join("synthA/test/000001/scene_camera.json"),
            |v| {
                v["3"]["cam_K"].as_array_mut().unwrap().pop();
            },
        );
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains(
                "scene_camera.json: image \"3\": field cam_K: expected 9 numbers, found 8"
            ),
            "{msg}"
        );
    }

    #[test]
    fn short_rotation_names_image_and_instance() {
        let dir = copy();
        edit_json(&dir.path().join("synthA/test/000001/scene_gt.json"), |v| {
            v["2"][1]["cam_R_m2c"].as_array_mut().unwrap().pop();
        });
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains(
                "test/000001/scene_gt.json: image \"2\", instance 1: field cam_R_m2c: \
                 expected 9 numbers, found 8"
            ),
            "{msg}"
        );
    }

    #[test]
    fn missing_field_reports_serde_position() {
        let dir = copy();
        edit_json(
            &dir.path().join("synthA/test/000001/scene_camera.json"),
            |v| {
                v["1"].as_object_mut().unwrap().remove("cam_K");
            },
        );
        let msg = load_error(&dir).to_string();
        assert!(msg.contains("missing field `cam_K`"), "{msg}");
    }

    #[test]
    fn gt_info_must_match_gt() {
        let dir = copy();
        let path = dir.path().join("synthA/test/000001/scene_gt_info.json");
        edit_json(&path, |v| {
            v["1"].as_array_mut().unwrap().pop();
        });
        let msg = load_error(&dir).to_string();
        assert!(msg.contains("scene_gt_info.json: image \"1\":"), "{msg}");

        edit_json(&path, |v| {
            v.as_object_mut().unwrap().remove("1");
        });
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains("scene_gt_info.json: image \"1\" is missing"),
            "{msg}"
        );
    }

    #[test]
    fn unknown_object_in_targets_is_named() {
        let dir = copy();
        edit_json(&dir.path().join("synthA/test_targets_bop19.json"), |v| {
            v[5]["obj_id"] = serde_json::json!(99);
        });
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains("test_targets_bop19.json: target 5 (scene_id")
                && msg.contains("object 99 has no entry"),
            "{msg}"
        );
    }

    #[test]
    fn unknown_image_in_targets_is_named() {
        let dir = copy();
        edit_json(&dir.path().join("synthA/test_targets_bop19.json"), |v| {
            v[0]["im_id"] = serde_json::json!(42);
        });
        let msg = load_error(&dir).to_string();
        assert!(msg.contains("image 42 is not in"), "{msg}");
    }

    #[test]
    fn custom_split_and_targets_file() {
        let dir = copy();
        let root = dir.path().join("synthA");
        std::fs::rename(root.join("test"), root.join("val")).unwrap();
        std::fs::write(
            root.join("val_targets.json"),
            r#"[{"scene_id": 2, "im_id": 3, "obj_id": 1, "inst_count": 1, "extra": true}]"#,
        )
        .unwrap();
        let opts = DatasetOptions {
            split: "val".to_string(),
            split_type: None,
            targets_file: "val_targets.json".to_string(),
        };
        let d = Dataset::load_with(&root, &opts).unwrap();
        assert_eq!(d.name, "synthA");
        assert_eq!(d.scenes.keys().copied().collect::<Vec<_>>(), [2]);
        assert_eq!(d.depth_path(2, 3), root.join("val/000002/depth/000003.png"));
        let msg = Dataset::load(&root).unwrap_err().to_string();
        assert!(
            msg.contains("no split folder: expected `test/` or `test_TYPE/`"),
            "{msg}"
        );
    }

    #[test]
    fn bop_names_are_displayed_as_bop_shows_them() {
        assert_eq!(display_name("lmo"), "LM-O");
        assert_eq!(display_name("tless"), "T-LESS");
        assert_eq!(display_name("ycbv"), "YCB-V");
        assert_eq!(display_name("synthdemo"), "synthdemo");
    }

    #[test]
    fn split_type_is_found_when_there_is_one() {
        let dir = copy();
        let root = dir.path().join("synthA");
        std::fs::rename(root.join("test"), root.join("test_primesense")).unwrap();
        std::fs::rename(
            root.join("camera.json"),
            root.join("camera_primesense.json"),
        )
        .unwrap();
        std::fs::write(
            root.join("camera_kinect.json"),
            r#"{"width": 9, "height": 9}"#,
        )
        .unwrap();
        let d = Dataset::load(&root).unwrap();
        assert_eq!(d.split_type.as_deref(), Some("primesense"));
        assert_eq!(d.split_dir, root.join("test_primesense"));
        // The split type's camera file states the size, not the alphabetically first one.
        assert_eq!(d.image_size, (640, 480));
        assert_eq!(d.targets, reference().targets);

        std::fs::create_dir(root.join("test_kinect")).unwrap();
        let msg = Dataset::load(&root).unwrap_err().to_string();
        assert!(
            msg.contains("several folders hold the split `test` (test_kinect, test_primesense)"),
            "{msg}"
        );
        let chosen = DatasetOptions {
            split_type: Some("primesense".into()),
            ..DatasetOptions::default()
        };
        assert_eq!(
            Dataset::load_with(&root, &chosen).unwrap().targets.len(),
            28
        );
        let missing = DatasetOptions {
            split_type: Some("canon".into()),
            ..DatasetOptions::default()
        };
        let msg = Dataset::load_with(&root, &missing).unwrap_err().to_string();
        assert!(
            msg.contains(
                "test_canon: no such folder: expected the split `test` of split type `canon`"
            ),
            "{msg}"
        );
    }

    #[test]
    fn targets_file_problems_are_named() {
        let dir = copy();
        let root = dir.path().join("synthA");
        let bop24 = DatasetOptions {
            targets_file: "test_targets_bop24.json".into(),
            ..DatasetOptions::default()
        };
        std::fs::write(
            root.join("test_targets_bop24.json"),
            r#"[{"scene_id": 1, "im_id": 0}, {"scene_id": 1, "im_id": 1, "obj_id": 2}]"#,
        )
        .unwrap();
        let msg = Dataset::load_with(&root, &bop24).unwrap_err().to_string();
        assert!(
            msg.contains("test_targets_bop24.json: target 1 has only one of obj_id and inst_count"),
            "{msg}"
        );
        std::fs::write(
            root.join("test_targets_bop24.json"),
            r#"[{"scene_id": 1, "im_id": 0}, {"scene_id": 1, "im_id": 1, "obj_id": 2, "inst_count": 1}]"#,
        )
        .unwrap();
        let msg = Dataset::load_with(&root, &bop24).unwrap_err().to_string();
        assert!(
            msg.contains("test_targets_bop24.json: target 1 mixes the two forms of targets"),
            "{msg}"
        );
        std::fs::remove_file(root.join("test_targets_bop19.json")).unwrap();
        let msg = Dataset::load(&root).unwrap_err().to_string();
        assert!(
            msg.contains(
                "test_targets_bop19.json: no such file: expected the list of test targets"
            ),
            "{msg}"
        );
    }

    /// The reference dataset as IPD lays out its scenes: the evaluated sensor's files
    /// (`_photoneo`) beside another sensor's (`_cam1`, with other intrinsics), which must not
    /// be read.
    fn as_ipd() -> (tempfile::TempDir, PathBuf) {
        let dir = copy();
        let root = dir.path().join("ipd");
        std::fs::rename(dir.path().join("synthA"), &root).unwrap();
        std::fs::rename(root.join("camera.json"), root.join("camera_photoneo.json")).unwrap();
        for scene in ["000001", "000002"] {
            let s = root.join("test").join(scene);
            for stem in ["scene_gt", "scene_camera", "scene_gt_info"] {
                let plain = s.join(format!("{stem}.json"));
                std::fs::copy(&plain, s.join(format!("{stem}_cam1.json"))).unwrap();
                std::fs::rename(&plain, s.join(format!("{stem}_photoneo.json"))).unwrap();
            }
            std::fs::rename(s.join("depth"), s.join("depth_photoneo")).unwrap();
            edit_json(&s.join("scene_camera_cam1.json"), |v| {
                for camera in v.as_object_mut().unwrap().values_mut() {
                    camera["cam_K"][0] = serde_json::json!(1.0);
                }
            });
        }
        (dir, root)
    }

    #[test]
    fn industrial_scenes_are_read_from_the_evaluated_sensors_files() {
        let (dir, root) = as_ipd();
        let d = Dataset::load(&root).unwrap();
        let r = reference();
        assert_eq!(d.targets, r.targets);
        for (id, scene) in &d.scenes {
            assert_eq!(scene.sensor.map(|s| s.suffix), Some("photoneo"));
            assert_eq!(scene.images, r.scenes[id].images);
        }
        assert_eq!(d.image_size, (640, 480));
        // MSPD is normalised by the sensor's published width, as the toolkit does.
        assert_eq!(d.image_width(1), 2064);
        assert_eq!(
            d.depth_path(1, 0),
            root.join("test/000001/depth_photoneo/000000.png")
        );
        assert_eq!(d.load_depth(1, 0).unwrap(), r.load_depth(1, 0).unwrap());
        let files = d.score_files().unwrap();
        assert!(files.contains(&root.join("test/000002/scene_gt_photoneo.json")));
        assert!(!files.iter().any(|f| f.to_string_lossy().contains("depth")));

        let msg = crate::supported_errors::check_errors(&d, &crate::Protocol::bop19())
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("protocol bop19 needs VSD, which ipd cannot be scored with: bop_toolkit"),
            "{msg}"
        );
        let mut mssd_only = crate::Protocol::bop19();
        mssd_only.errors.remove(0);
        crate::supported_errors::check_errors(&d, &mssd_only).unwrap();

        std::fs::rename(&root, dir.path().join("other")).unwrap();
        let msg = Dataset::load(&dir.path().join("other"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(
                "scene_gt.json: no such file, but the scene holds per-sensor annotations \
                 (scene_gt_cam1.json, scene_gt_photoneo.json)"
            ),
            "{msg}"
        );
    }

    #[test]
    fn fisheye_cameras_are_read_from_cam_model() {
        let dir = copy();
        let root = dir.path().join("synthA");
        let path = root.join("test/000001/scene_camera.json");
        let mut params = vec![600.0, 601.0, 320.0, 240.0];
        params.extend([0.0; 12]);
        edit_json(&path, |v| {
            let camera = v["0"].as_object_mut().unwrap();
            camera.remove("cam_K");
            camera.insert(
                "cam_model".into(),
                serde_json::json!({"image_width": 640, "image_height": 480,
                    "projection_model_type": "CameraModelType.FISHEYE624",
                    "projection_params": params}),
            );
        });
        let d = Dataset::load(&root).unwrap();
        let image = &d.scenes[&1].images[&0];
        assert_eq!(
            image.fisheye.map(|f| (f.f, f.c)),
            Some(((600.0, 601.0), (320.0, 240.0)))
        );
        assert_eq!((image.camera.fx(), image.camera.cy()), (600.0, 240.0));
        assert!(d.scenes[&1].images[&1].fisheye.is_none());
        let msg = crate::supported_errors::check_errors(&d, &crate::Protocol::eccv18())
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("scene 1, image 0 has a fisheye camera"),
            "{msg}"
        );

        // 16 parameters (fx, fy, ...) or 15 (one f) are valid; 14 is neither.
        edit_json(&path, |v| {
            let params = v["0"]["cam_model"]["projection_params"]
                .as_array_mut()
                .unwrap();
            params.truncate(14);
        });
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains("image \"0\": field cam_model: projection_params: expected 15"),
            "{msg}"
        );
        edit_json(&path, |v| {
            v["0"]["cam_K"] = serde_json::json!([1, 0, 0, 0, 1, 0, 0, 0, 1]);
        });
        let msg = load_error(&dir).to_string();
        assert!(
            msg.contains("image \"0\": both cam_K and cam_model"),
            "{msg}"
        );
    }

    #[test]
    fn a_list_of_images_targets_every_object_of_their_ground_truth() {
        let dir = copy();
        let root = dir.path().join("synthA");
        // Image 0 of scene 1 listed twice, and an image of scene 2 before it.
        std::fs::write(
            root.join("test_targets_bop24.json"),
            r#"[{"scene_id": 2, "im_id": 0}, {"scene_id": 1, "im_id": 0}, {"scene_id": 1, "im_id": 0}]"#,
        )
        .unwrap();
        let bop24 = DatasetOptions {
            targets_file: "test_targets_bop24.json".into(),
            ..DatasetOptions::default()
        };
        let d = Dataset::load_with(&root, &bop24).unwrap();
        assert_eq!(d.targets_form, TargetsForm::Images);
        let mut expected = Vec::new();
        for (scene_id, im_id) in [(2, 0), (1, 0)] {
            let image = &d.scenes[&scene_id].images[&im_id];
            for g in &image.gt {
                if !expected.iter().any(|t: &Target| {
                    t.scene_id == scene_id && t.im_id == im_id && t.obj_id == g.obj_id
                }) {
                    let inst_count =
                        image.gt.iter().filter(|h| h.obj_id == g.obj_id).count() as u32;
                    expected.push(Target {
                        scene_id,
                        im_id,
                        obj_id: g.obj_id,
                        inst_count,
                    });
                }
            }
        }
        assert_eq!(d.targets, expected);
        assert!(d.targets.iter().any(|t| t.inst_count > 1) || d.targets.len() > 2);
        assert_eq!(reference().targets_form, TargetsForm::Objects);
    }
}
