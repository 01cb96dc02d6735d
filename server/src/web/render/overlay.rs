//! The picture of a target seen through a submission (see `evaluator::overlay` for what it
//! shows and its colours), as a PNG. What it is drawn from is the service's
//! ([`inspection::picture_inputs`]); the picture is drawn and encoded on the evaluation threads.

use evaluator::overlay::{RgbImage, target_picture, target_thumbnail};
use evaluator::protocol::{Protocol, ProtocolName};

use crate::app::App;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::service::inspection;
pub use crate::service::inspection::TargetId;
use crate::web::auth::Viewer;

/// The PNG of `target` for submission `id` as `viewer` may see it (see
/// [`inspection::picture_inputs`]). The estimates drawn are those the evaluation under
/// `protocol` considers (its n_top); without one, under the submission's first protocol. With
/// `thumbnail`, the picture is cut to the object (a gallery's small pictures).
pub async fn target_png(
    app: &App,
    viewer: &Viewer,
    id: SubmissionId,
    target: TargetId,
    protocol: Option<ProtocolName>,
    thumbnail: bool,
) -> AppResult<Vec<u8>> {
    let inputs =
        inspection::picture_inputs(app, viewer.user.as_ref(), id, target, protocol).await?;
    app.on_pool("drawing the picture", move || {
        let n_top = Protocol::named(inputs.protocol).n_top;
        let draw = if thumbnail {
            target_thumbnail
        } else {
            target_picture
        };
        let picture = draw(&inputs.dataset, &inputs.results, &inputs.target, n_top)
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
