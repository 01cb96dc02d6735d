//! The picture of a target seen through a submission (see `evaluator::overlay` for what it
//! shows and its colours), as a PNG. The estimates are read from the stored upload, as the
//! worker read them (parsed once per file, see `parsed_files`), and the picture is drawn and
//! encoded on the evaluation threads.

use evaluator::overlay::{RgbImage, target_picture};
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::results;

use crate::app::App;
use crate::datasets::uploaded_file;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::service::visibility;
use crate::web::auth::Viewer;

/// A test target: (scene_id, im_id, obj_id).
#[derive(Clone, Copy, Debug)]
pub struct TargetId {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
}

/// The PNG of `target` for submission `id` as `viewer` may see it: a private submission of
/// another account, a target its dataset does not have, or a protocol it was not submitted for
/// answer as missing. The estimates drawn are those the evaluation under `protocol` considers
/// (its n_top); without one, under the submission's first protocol.
pub async fn target_png(
    app: &App,
    viewer: &Viewer,
    id: SubmissionId,
    target: TargetId,
    protocol: Option<ProtocolName>,
) -> AppResult<Vec<u8>> {
    let s = visibility::submission(app, id, viewer.user.as_ref()).await?;
    let protocol = match protocol {
        Some(p) if s.protocols.contains(&p) => p,
        Some(_) => return Err(AppError::NotFound),
        None => *s.protocols.first().ok_or(AppError::NotFound)?,
    };
    let row = app
        .store
        .dataset(s.dataset_id)
        .await?
        .ok_or(AppError::NotFound)?;
    let dataset = app.dataset(&row).await?;
    let found = dataset
        .targets
        .iter()
        .find(|t| (t.scene_id, t.im_id, t.obj_id) == (target.scene_id, target.im_id, target.obj_id))
        .copied()
        .ok_or(AppError::NotFound)?;
    let sha256 = &s.file_sha256;
    let results = app
        .parsed_files
        .get_or_parse(sha256, move || async move {
            let bytes = uploaded_file::fetch(&app.store, &app.config.submissions_dir(), sha256)
                .await
                .map_err(|e| AppError::failed("reading the stored result file", e))?;
            app.on_pool("parsing the stored file", move || {
                results::parse_results(&bytes[..]).map_err(|p| {
                    AppError::Internal(format!("the stored file no longer parses: {p}"))
                })
            })
            .await
        })
        .await?;
    app.on_pool("drawing the picture", move || {
        let n_top = Protocol::named(protocol).n_top;
        let picture = target_picture(&dataset, &results, &found, n_top)
            .map_err(|e| AppError::failed("drawing a target picture", e))?;
        encode(&picture)
    })
    .await
}

/// An 8-bit RGB PNG, compressed fast: it is drawn on request.
fn encode(image: &RgbImage) -> AppResult<Vec<u8>> {
    let failed = |e: png::EncodingError| AppError::failed("encoding a PNG", e);
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, image.width, image.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().map_err(failed)?;
    writer.write_image_data(&image.data).map_err(failed)?;
    writer.finish().map_err(failed)?;
    Ok(out)
}
