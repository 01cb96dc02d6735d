//! The COCO ground truth BOP ships with a dataset: per test scene, `scene_gt_coco.json`
//! (boxes around the full silhouette, "amodal") and `scene_gt_coco_modal.json` (boxes around
//! the visible part), made by bop_toolkit's `calc_gt_coco.py` from the visible masks, with
//! `ignore` set on instances less than 10 % visible. A dataset recorded with several sensors
//! (IPD, XYZ-IBD, ITODD-MV, HOT3D) has them per sensor, and the evaluated sensor's are read
//! (`scene_gt_coco_photoneo.json`), the one its 6D ground truth is read from.
//!
//! Only the images of the targets file count, and the scenes are merged into one evaluation
//! as `eval_bop22_coco.py` merges them: scenes in the order they first appear in the targets
//! file, and each later scene's image and annotation ids shifted past the largest id so far.
//! The shifted ids are kept because they decide two things: the order in which images enter
//! the accumulation (ties between detections of different images are broken by it), and
//! which matches count (COCOeval takes a match to an annotation with id 0 for no match).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::Value;

use super::rle::Rle;
use crate::dataset::{DatasetOptions, find_split, read_json, scene_dir};
use crate::error::{Error, Result};
use crate::sensors::eval_sensor;

/// Which boxes the ground truth has: the file a scene's annotations are read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BboxType {
    /// Boxes around the full silhouette: `scene_gt_coco.json`, the toolkit's default.
    Amodal,
    /// Boxes around the visible part: `scene_gt_coco_modal.json`.
    Modal,
}

impl BboxType {
    pub fn as_str(self) -> &'static str {
        match self {
            BboxType::Amodal => "amodal",
            BboxType::Modal => "modal",
        }
    }

    /// The scene's file of these boxes; in a dataset recorded with several sensors, the
    /// evaluated sensor's (`scene_gt_coco_photoneo.json`, `scene_gt_coco_modal_photoneo.json`,
    /// as `dataset_params.py` names them and `eval_bop22_coco.py` reads them).
    pub fn file_name(self, sensor: Option<&str>) -> String {
        let stem = match self {
            BboxType::Amodal => "scene_gt_coco",
            BboxType::Modal => "scene_gt_coco_modal",
        };
        match sensor {
            Some(suffix) => format!("{stem}_{suffix}.json"),
            None => format!("{stem}.json"),
        }
    }
}

impl std::str::FromStr for BboxType {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "amodal" => Ok(BboxType::Amodal),
            "modal" => Ok(BboxType::Modal),
            other => Err(format!("unknown bbox type `{other}` (amodal or modal)")),
        }
    }
}

/// One image of the evaluation, in the merged order.
#[derive(Clone, Debug, PartialEq)]
pub struct GtImage {
    pub scene_id: u32,
    pub im_id: u32,
    /// The id the toolkit's merge gives the image.
    pub merged_id: i64,
}

/// One ground-truth annotation.
#[derive(Clone, Debug, PartialEq)]
pub struct GtAnnotation {
    /// Index into [`CocoGt::images`].
    pub image: usize,
    /// The id after the toolkit's merge.
    pub merged_id: i64,
    pub category_id: i64,
    /// The `area` field (the visible pixels), not recomputed: COCOeval sorts ground truth into
    /// the area ranges by this field.
    pub area: f64,
    pub ignore: bool,
    pub iscrowd: bool,
    pub bbox: [f64; 4],
    /// Read only for segmentation: a detection file is scored on boxes without it.
    pub segmentation: Option<Rle>,
}

/// The merged ground truth of the target images of a dataset split.
#[derive(Clone, Debug, PartialEq)]
pub struct CocoGt {
    pub name: String,
    pub split_dir: PathBuf,
    pub bbox_type: BboxType,
    /// Sorted by merged id.
    pub images: Vec<GtImage>,
    /// In the merged files' order.
    pub annotations: Vec<GtAnnotation>,
    /// Every category of the files (the dataset's objects), sorted.
    pub categories: Vec<i64>,
    /// The files read, one per target scene.
    pub files: Vec<PathBuf>,
    index: HashMap<(u32, u32), usize>,
}

impl CocoGt {
    /// Reads the ground truth of the split and targets file `opts` names. `with_masks`: decode
    /// the segmentations (needed for `segm` only).
    pub fn load(
        root: &Path,
        opts: &DatasetOptions,
        bbox_type: BboxType,
        with_masks: bool,
    ) -> Result<CocoGt> {
        if !root.is_dir() {
            return Err(Error::format(
                root,
                "no such folder: expected a BOP dataset folder",
            ));
        }
        let (split_dir, split_type) = find_split(root, opts)?;
        let name = dataset_name(root);
        let targets_path = root.join(&opts.targets_file);
        if !targets_path.is_file() {
            return Err(Error::format(
                &targets_path,
                "no such file: expected the list of test targets (BOP: test_targets_bop19.json)",
            ));
        }
        let targets: Vec<RawTarget> = read_json(&targets_path)?;
        if targets.is_empty() {
            return Err(Error::format(&targets_path, "the file lists no targets"));
        }
        let mut scene_order: Vec<u32> = Vec::new();
        let mut target_images: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
        for t in &targets {
            if !target_images.contains_key(&t.scene_id) {
                scene_order.push(t.scene_id);
            }
            target_images.entry(t.scene_id).or_default().insert(t.im_id);
        }

        let mut gt = CocoGt {
            name: name.clone(),
            split_dir: split_dir.clone(),
            bbox_type,
            images: Vec::new(),
            annotations: Vec::new(),
            categories: Vec::new(),
            files: Vec::new(),
            index: HashMap::new(),
        };
        let mut categories = BTreeSet::new();
        for (n, &scene_id) in scene_order.iter().enumerate() {
            let dir = scene_dir(&split_dir, scene_id);
            let sensor = eval_sensor(&name, split_type.as_deref(), scene_id)
                .map_err(|m| Error::format(&dir, m))?;
            let path = dir.join(bbox_type.file_name(sensor.map(|s| s.suffix)));
            if !path.is_file() {
                return Err(Error::format(
                    &path,
                    format!(
                        "no such file: the COCO ground truth of scene {scene_id} (bop_toolkit's \
                         calc_gt_coco.py{} makes it)",
                        match bbox_type {
                            BboxType::Amodal => "",
                            BboxType::Modal => " --bbox_type modal",
                        }
                    ),
                ));
            }
            let file: RawFile = read_json(&path)?;
            let wanted = &target_images[&scene_id];
            let (image_offset, ann_offset) = if n == 0 {
                (0, 0)
            } else {
                let image_offset = gt.images.iter().map(|i| i.merged_id).max().unwrap_or(-1) + 1;
                let ann_offset = gt
                    .annotations
                    .iter()
                    .map(|a| a.merged_id)
                    .max()
                    .map_or(0, |m| m + 1);
                (image_offset, ann_offset)
            };
            let mut listed = BTreeSet::new();
            for image in &file.images {
                if let Ok(im_id) = u32::try_from(image.id)
                    && wanted.contains(&im_id)
                    && listed.insert(im_id)
                {
                    gt.index.insert((scene_id, im_id), gt.images.len());
                    gt.images.push(GtImage {
                        scene_id,
                        im_id,
                        merged_id: image.id + image_offset,
                    });
                }
            }
            if let Some(missing) = wanted.iter().find(|id| !listed.contains(id)) {
                return Err(Error::format(
                    &path,
                    format!(
                        "image {missing} is a target ({}) but is not among the file's images",
                        targets_path.display()
                    ),
                ));
            }
            categories.extend(file.categories.iter().map(|c| c.id));
            for (i, ann) in file.annotations.into_iter().enumerate() {
                let Ok(im_id) = u32::try_from(ann.image_id) else {
                    continue;
                };
                let Some(&image) = gt.index.get(&(scene_id, im_id)) else {
                    continue;
                };
                let at = |m: String| Error::format(&path, format!("annotation {i}: {m}"));
                let segmentation = if with_masks {
                    Some(segmentation(&ann.segmentation).map_err(at)?)
                } else {
                    None
                };
                gt.annotations.push(GtAnnotation {
                    image,
                    merged_id: ann.id + ann_offset,
                    category_id: ann.category_id,
                    area: ann.area,
                    ignore: ann.ignore.as_ref().is_some_and(truthy),
                    iscrowd: ann.iscrowd.as_ref().is_some_and(truthy),
                    bbox: ann.bbox,
                    segmentation,
                });
            }
            gt.files.push(path);
        }
        gt.categories = categories.into_iter().collect();
        let mut order: Vec<usize> = (0..gt.images.len()).collect();
        order.sort_by_key(|&i| gt.images[i].merged_id);
        let mut new_index = vec![0; order.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        gt.images = order.iter().map(|&i| gt.images[i].clone()).collect();
        for a in &mut gt.annotations {
            a.image = new_index[a.image];
        }
        for v in gt.index.values_mut() {
            *v = new_index[*v];
        }
        Ok(gt)
    }

    /// The index of a target image, `None` for any other image.
    pub fn image_index(&self, scene_id: u32, im_id: u32) -> Option<usize> {
        self.index.get(&(scene_id, im_id)).copied()
    }
}

/// Python's truth value of a JSON value, as `if gt['ignore']` reads it.
fn truthy(v: &Value) -> bool {
    match v {
        Value::Null => false,
        Value::Bool(b) => *b,
        Value::Number(n) => n.as_f64().is_some_and(|x| x != 0.0),
        Value::String(s) => !s.is_empty(),
        Value::Array(a) => !a.is_empty(),
        Value::Object(o) => !o.is_empty(),
    }
}

/// An RLE in either count form; polygons (which BOP's ground truth never has) are refused.
pub(crate) fn segmentation(v: &Value) -> std::result::Result<Rle, String> {
    let Value::Object(o) = v else {
        return Err("the segmentation is not an RLE ({\"counts\": ..., \"size\": [h, w]})".into());
    };
    let size = match o.get("size") {
        Some(Value::Array(s)) if s.len() == 2 => {
            let dim = |v: &Value| v.as_u64().and_then(|x| u32::try_from(x).ok());
            match (dim(&s[0]), dim(&s[1])) {
                (Some(h), Some(w)) => (h, w),
                _ => return Err("`size` is not [height, width] in pixels".into()),
            }
        }
        Some(_) => return Err("`size` is not [height, width] in pixels".into()),
        None => return Err("the RLE has no `size`".into()),
    };
    match o.get("counts") {
        Some(Value::String(s)) => Rle::from_compressed(s, size.0, size.1),
        Some(Value::Array(list)) => {
            let counts = list
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    c.as_u64()
                        .and_then(|x| u32::try_from(x).ok())
                        .ok_or_else(|| format!("count {i} is {c}, not a pixel count"))
                })
                .collect::<std::result::Result<Vec<u32>, String>>()?;
            Rle::from_counts(size.0, size.1, counts)
        }
        Some(_) => Err("`counts` is neither a list nor a compressed string".into()),
        None => Err("the RLE has no `counts`".into()),
    }
}

fn dataset_name(root: &Path) -> String {
    root.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .or_else(|| {
            let canonical = root.canonicalize().ok()?;
            Some(canonical.file_name()?.to_string_lossy().into_owned())
        })
        .unwrap_or_default()
}

/// A target: only the image counts here, so BOP'24's image-only targets work as well.
#[derive(Deserialize)]
struct RawTarget {
    scene_id: u32,
    im_id: u32,
}

#[derive(Deserialize)]
struct RawFile {
    images: Vec<RawImage>,
    annotations: Vec<RawAnnotation>,
    categories: Vec<RawCategory>,
}

#[derive(Deserialize)]
struct RawImage {
    id: i64,
}

#[derive(Deserialize)]
struct RawCategory {
    id: i64,
}

#[derive(Deserialize)]
struct RawAnnotation {
    id: i64,
    image_id: i64,
    category_id: i64,
    area: f64,
    bbox: [f64; 4],
    #[serde(default)]
    segmentation: Value,
    ignore: Option<Value>,
    iscrowd: Option<Value>,
}

#[cfg(test)]
impl CocoGt {
    /// This ground truth with image `i` repeated `weights[i]` times (copies next to each other,
    /// fresh merged ids), and per original image the indices of its copies: what a bootstrap
    /// replicate stands for, to check the weighted AP against COCOeval run on it.
    pub(crate) fn repeated(&self, weights: &[u32]) -> (CocoGt, Vec<Vec<usize>>) {
        let mut images = Vec::new();
        let mut copies = vec![Vec::new(); self.images.len()];
        for (i, image) in self.images.iter().enumerate() {
            for _ in 0..weights[i] {
                copies[i].push(images.len());
                images.push(GtImage {
                    merged_id: images.len() as i64 + 1,
                    ..image.clone()
                });
            }
        }
        let mut annotations = Vec::new();
        for a in &self.annotations {
            for &image in &copies[a.image] {
                annotations.push(GtAnnotation {
                    image,
                    merged_id: annotations.len() as i64 + 1,
                    ..a.clone()
                });
            }
        }
        let gt = CocoGt {
            images,
            annotations,
            index: HashMap::new(),
            ..self.clone()
        };
        (gt, copies)
    }
}
