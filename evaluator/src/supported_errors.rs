//! Which pose errors a dataset can be scored with. bop_toolkit's `dataset_params.py` lists the
//! supported error types per dataset and leaves VSD out where a dataset has no depth images or
//! its sensors are not the pinhole cameras the renderer models; a protocol needing VSD is then
//! refused before any work, with the reason, rather than failing on a missing depth image.

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::protocol::{ErrorKind, Protocol};
use crate::sensors::vsd_unsupported;

/// Refuses a protocol with a pose error `dataset` cannot be scored with, naming why: VSD where
/// bop_toolkit does not compute it, or on images with a fisheye camera.
pub fn check_errors(dataset: &Dataset, protocol: &Protocol) -> Result<()> {
    if !protocol
        .errors
        .iter()
        .any(|e| matches!(e.kind, ErrorKind::Vsd(_)))
    {
        return Ok(());
    }
    let refuse = |why: String| {
        Err(Error::Parameters(format!(
            "protocol {} needs VSD, which {} cannot be scored with: {why}",
            protocol.name.as_str(),
            dataset.name
        )))
    };
    if let Some(why) = vsd_unsupported(&dataset.name) {
        return refuse(why.to_string());
    }
    for scene in dataset.scenes.values() {
        if let Some(image) = scene.images.values().find(|i| i.fisheye.is_some()) {
            return refuse(format!(
                "scene {}, image {} has a fisheye camera (cam_model), and VSD renders with a \
                 pinhole one",
                scene.id, image.id
            ));
        }
    }
    Ok(())
}
