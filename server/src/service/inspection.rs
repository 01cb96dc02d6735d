//! What the pages that look inside a submission read: its targets one by one, two submissions
//! compared target by target, its worst targets, a target's picture. They show evidence behind
//! scores, so they read only what [`visibility`] lets the reader see, and the verdicts are
//! made from the errors stored with the scores (the very numbers the scores counted).

use std::collections::BTreeMap;
use std::sync::Arc;

use evaluator::dataset::Target;
use evaluator::protocol::ProtocolName;
use evaluator::results::{self, Results};
use evaluator::{Dataset, Report};

use crate::app::App;
use crate::datasets::uploaded_file;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::service::visibility;
use crate::store::accounts::User;
use crate::store::pose_errors::StoredErrors;
use crate::store::submissions::{Status, SubmissionRow};

/// Submission `id` if `reader` may see it and it is finished: only those have stored errors.
pub async fn finished(
    app: &App,
    id: SubmissionId,
    reader: Option<&User>,
) -> AppResult<SubmissionRow> {
    let s = visibility::submission(app, id, reader).await?;
    if s.status != Status::Done {
        return Err(AppError::BadRequest(format!(
            "submission {id} is {}: only finished submissions have targets to show",
            s.status
        )));
    }
    Ok(s)
}

/// The stored errors of `s` under `protocol`, still compressed: inflating and parsing them is
/// work for the evaluation threads.
pub async fn stored_errors(
    app: &App,
    s: &SubmissionRow,
    protocol: ProtocolName,
) -> AppResult<StoredErrors> {
    app.store
        .estimate_errors(s.id, protocol)
        .await?
        .ok_or_else(|| {
            AppError::BadRequest(format!(
                "submission {} has no per-estimate errors under {}",
                s.id,
                protocol.as_str()
            ))
        })
}

/// The dataset `s` was evaluated on, as this process loaded it.
pub async fn dataset_of(app: &App, s: &SubmissionRow) -> AppResult<Arc<Dataset>> {
    let row = app
        .store
        .dataset(s.dataset_id)
        .await?
        .ok_or_else(|| AppError::Internal(format!("dataset {} is gone", s.dataset_id)))?;
    app.dataset(&row).await
}

/// The reports of submission `id` (one has been checked visible), by protocol.
pub async fn reports(app: &App, id: SubmissionId) -> AppResult<BTreeMap<ProtocolName, Report>> {
    Ok(app
        .store
        .reports_of_submission(id)
        .await?
        .into_iter()
        .map(|r| (r.protocol, r))
        .collect())
}

/// The submissions `s` can be compared with: finished, on its dataset, visible to `reader`
/// (at most 200).
pub async fn comparable(
    app: &App,
    s: &SubmissionRow,
    reader: Option<&User>,
) -> AppResult<Vec<SubmissionRow>> {
    if s.status != Status::Done {
        return Ok(Vec::new());
    }
    let reader_id = reader.map(|u| u.id);
    Ok(app
        .store
        .finished_on_dataset(s.dataset_id, s.id, reader_id, 200)
        .await?)
}

/// A test target: (scene_id, im_id, obj_id).
#[derive(Clone, Copy, Debug)]
pub struct TargetId {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
}

/// What a target's picture is drawn from.
pub struct PictureInputs {
    pub dataset: Arc<Dataset>,
    /// The submission's estimates, as the worker read them.
    pub results: Arc<Results>,
    pub target: Target,
    /// The protocol whose n_top decides the estimates drawn.
    pub protocol: ProtocolName,
}

/// What the picture of `target` seen through submission `id` is drawn from, as `reader` may see
/// it: a private submission of another account, a target its dataset does not have, or a
/// protocol it was not submitted for answer as missing; without a protocol, its first. The
/// estimates are read from the stored upload, parsed once per file (see `parsed_files`).
pub async fn picture_inputs(
    app: &App,
    reader: Option<&User>,
    id: SubmissionId,
    target: TargetId,
    protocol: Option<ProtocolName>,
) -> AppResult<PictureInputs> {
    let s = visibility::submission(app, id, reader).await?;
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
    Ok(PictureInputs {
        dataset,
        results,
        target: found,
        protocol,
    })
}
