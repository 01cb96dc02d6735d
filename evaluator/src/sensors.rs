//! The datasets of the BOP'24 and later challenges that record each scene with several sensors:
//! BOP-Industrial (IPD, XYZ-IBD, ITODD-MV) and HOT3D of BOP-H3. Their scene folders hold one set
//! of annotations per sensor (`scene_gt_photoneo.json`, `depth_photoneo/`, ...) or, for HOT3D,
//! per image stream (`scene_gt_rgb.json`, `scene_gt_gray1.json`), and one of them is the one
//! evaluated. Which one, the image size MSPD is normalised by, and which pose errors bop_toolkit
//! computes on each dataset are decided by the dataset's name, as in the toolkit's
//! `dataset_params.py`; the rest of the evaluator only sees the chosen files.

/// The sensor (or image stream) a scene is evaluated on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EvalSensor {
    /// The suffix of the scene's files: `scene_gt_{suffix}.json`, `depth_{suffix}/`.
    pub suffix: &'static str,
    /// (width, height) of its images as `dataset_params.py` states them; MSPD is normalised
    /// by this width.
    pub size: (u32, u32),
}

/// HOT3D's scene ids: Quest 3 scenes are evaluated on the `gray1` stream, Aria scenes on
/// `rgb` (`dataset_params.py`: `test_quest3_scene_ids` etc.).
const HOT3D_QUEST3: [std::ops::Range<u32>; 2] = [0..1288, 1288..1849];
const HOT3D_ARIA: [std::ops::Range<u32>; 2] = [1849..3365, 3365..3832];

/// The sensor a scene of `dataset` is evaluated on; `None` for the classic layout (one
/// `scene_gt.json` per scene, `depth/`). XYZ-IBD's and ITODD-MV's PBR training images are in
/// the classic layout.
pub fn eval_sensor(
    dataset: &str,
    split_type: Option<&str>,
    scene_id: u32,
) -> Result<Option<EvalSensor>, String> {
    let pbr = split_type == Some("pbr");
    let sensor = |suffix, size| Ok(Some(EvalSensor { suffix, size }));
    match dataset {
        "ipd" => sensor("photoneo", (2064, 1544)),
        "xyzibd" if !pbr => sensor("xyz", (1440, 1080)),
        "itoddmv" if !pbr => sensor("3dlong", (1280, 960)),
        "hot3d" => {
            if HOT3D_QUEST3.iter().any(|r| r.contains(&scene_id)) {
                sensor("gray1", (1280, 1024))
            } else if HOT3D_ARIA.iter().any(|r| r.contains(&scene_id)) {
                sensor("rgb", (1408, 1408))
            } else {
                Err(format!(
                    "scene {scene_id} is not a HOT3D scene: Quest 3 scenes are 0 to 1848, Aria \
                     scenes 1849 to 3831"
                ))
            }
        }
        _ => Ok(None),
    }
}

/// Why bop_toolkit computes no VSD on a dataset (its `supported_error_types` leave it out).
pub fn vsd_unsupported(dataset: &str) -> Option<&'static str> {
    match dataset {
        "hot3d" => Some(
            "HOT3D has no depth images and fisheye cameras; bop_toolkit computes only ad, add, \
             adi, mssd and mspd on it",
        ),
        "ipd" | "xyzibd" | "itoddmv" => Some(
            "bop_toolkit computes only ad, add, adi, mssd and mspd on the BOP-Industrial \
             datasets (dataset_params.py)",
        ),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sensors_follow_dataset_params() {
        assert_eq!(
            eval_sensor("ipd", None, 3).unwrap().unwrap().suffix,
            "photoneo"
        );
        assert_eq!(
            eval_sensor("xyzibd", None, 1).unwrap().unwrap().size,
            (1440, 1080)
        );
        assert_eq!(eval_sensor("xyzibd", Some("pbr"), 1).unwrap(), None);
        assert_eq!(
            eval_sensor("itoddmv", None, 1).unwrap().unwrap().suffix,
            "3dlong"
        );
        assert_eq!(
            eval_sensor("hot3d", None, 1288).unwrap().unwrap().suffix,
            "gray1"
        );
        assert_eq!(
            eval_sensor("hot3d", None, 3831).unwrap().unwrap().size,
            (1408, 1408)
        );
        let msg = eval_sensor("hot3d", None, 4000).unwrap_err();
        assert!(msg.contains("scene 4000 is not a HOT3D scene"), "{msg}");
        assert_eq!(eval_sensor("tless", Some("primesense"), 1).unwrap(), None);
        assert_eq!(eval_sensor("handal", None, 11).unwrap(), None);
        assert!(vsd_unsupported("hopev2").is_none());
        assert!(vsd_unsupported("itoddmv").is_some());
    }
}
