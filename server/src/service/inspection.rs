//! What the pages that look inside a submission read: its targets one by one, two submissions
//! compared target by target, its worst targets, a target's picture. They show evidence behind
//! scores, so they read only what [`visibility`] lets the reader see, and the verdicts are
//! made from the errors stored with the scores (the very numbers the scores counted). BOP'24
//! detections store no errors: theirs are computed again from the stored file by the
//! evaluator's own steps, which give the same numbers.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use evaluator::coco::{self, CocoReport, ImageOutcome};
use evaluator::dataset::Target;
use evaluator::detection::DetectionReport;
use evaluator::detection::verdicts::{self, Criterion, ImageVerdicts};
use evaluator::protocol::ProtocolName;
use evaluator::results::{self, Results};
use evaluator::{Dataset, Report};

use crate::app::App;
use crate::datasets::{self, uploaded_file};
use crate::domain::{CocoProtocol, SubmissionId, Task};
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

/// The submissions `s` can be compared with: finished, on its dataset, visible to `reader`,
/// and scored under a protocol `s` was scored under (a 6D submission with a 6D one, a 2D one
/// with one of its task), newest first (of the newest 200 on the dataset).
pub async fn comparable(
    app: &App,
    s: &SubmissionRow,
    reader: Option<&User>,
) -> AppResult<Vec<SubmissionRow>> {
    if s.status != Status::Done {
        return Ok(Vec::new());
    }
    let reader_id = reader.map(|u| u.id);
    let mut rows = app
        .store
        .finished_on_dataset(s.dataset_id, s.id, reader_id, 200)
        .await?;
    rows.retain(|o| share_a_protocol((&s.protocols, s.task), (&o.protocols, o.task)));
    Ok(rows)
}

/// Whether two submissions, each with its 6D protocols or its task (2D, or BOP'24 detection),
/// were scored under a protocol in common that compares side by side: the rule of what
/// compares.
pub fn share_a_protocol(
    (a, a_task): (&[ProtocolName], Option<Task>),
    (b, b_task): (&[ProtocolName], Option<Task>),
) -> bool {
    match (a_task, b_task) {
        (Some(Task::Coco(x)), Some(Task::Coco(y))) => x == y,
        (Some(Task::Bop24), Some(Task::Bop24)) => true,
        (None, None) => a.iter().any(|p| b.contains(p)),
        _ => false,
    }
}

/// What COCOeval counts image by image and category at IoU 0.5 for the 2D submission `s`
/// (one has been checked visible and finished), from its stored file scored again on the
/// dataset's ground truth as the worker scored it.
pub async fn coco_outcomes(
    app: &App,
    s: &SubmissionRow,
    task: CocoProtocol,
) -> AppResult<Vec<ImageOutcome>> {
    let root = dataset_of(app, s).await?.root.clone();
    let bytes = uploaded_file::fetch(&app.store, &app.config.submissions_dir(), &s.file_sha256)
        .await
        .map_err(|e| AppError::failed("reading the stored result file", e))?;
    app.on_pool("scoring a stored 2D file", move || {
        let results = coco::parse_coco_results(&bytes[..])
            .map_err(|p| AppError::Internal(format!("the stored file no longer parses: {p}")))?;
        let gt = datasets::config::coco_gt(&root, task == CocoProtocol::Segmentation)
            .map_err(|e| AppError::failed("reading the COCO ground truth", e))?;
        let evaluation = coco::evaluation(&gt, &results, task.task())
            .map_err(|e| AppError::failed("scoring a stored 2D file", e))?;
        Ok(evaluation
            .images
            .map(|images| images.outcomes_at_50(&gt))
            .unwrap_or_default())
    })
    .await
}

/// The stored report of the 2D submission `id` (one has been checked visible).
pub async fn coco_report(app: &App, id: SubmissionId) -> AppResult<CocoReport> {
    app.store
        .coco_report(id)
        .await?
        .ok_or_else(|| AppError::BadRequest(format!("submission {id} has no 2D scores")))
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
    let results = parsed_results(app, &s).await?;
    Ok(PictureInputs {
        dataset,
        results,
        target: found,
        protocol,
    })
}

/// The estimates of the 6D submission `s` (one checked visible), read from its stored upload
/// and parsed once per file (see `parsed_files`).
async fn parsed_results(app: &App, s: &SubmissionRow) -> AppResult<Arc<Results>> {
    let sha256 = &s.file_sha256;
    app.parsed_files
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
        .await
}

/// The stored report of the bop24 submission `id` (one checked visible).
pub async fn bop24_report(app: &App, id: SubmissionId) -> AppResult<DetectionReport> {
    app.store
        .bop24_report(id)
        .await?
        .ok_or_else(|| AppError::BadRequest(format!("submission {id} has no bop24 scores")))
}

/// Every estimate of the bop24 submission `s` (one checked visible and finished) at
/// `criterion`, image by image (only `image`, a (scene, image) pair, when given): its stored
/// file evaluated again on the dataset with the cap of its report, through the evaluator's own
/// cap, errors and matching (`evaluator::detection::verdicts`), so the true positives are the
/// ones its AP counted. BOP'24 errors need no rendering, so they are computed on demand, on the
/// evaluation threads.
pub async fn bop24_verdicts(
    app: &App,
    s: &SubmissionRow,
    report: &DetectionReport,
    criterion: Criterion,
    image: Option<(u32, u32)>,
) -> AppResult<Vec<ImageVerdicts>> {
    let row = app
        .store
        .dataset(s.dataset_id)
        .await?
        .ok_or_else(|| AppError::Internal(format!("dataset {} is gone", s.dataset_id)))?;
    let dataset = app.bop24_dataset(&row).await?.ok_or_else(|| {
        AppError::Internal(format!(
            "dataset `{}` no longer has its test_targets_bop24.json",
            row.name
        ))
    })?;
    let results = parsed_results(app, s).await?;
    let cap = report.parameters.max_estimates_per_image;
    app.on_pool("matching bop24 estimates", move || {
        verdicts::inspect(&dataset, &results, cap, image, &AtomicBool::new(false))
            .map(|inspection| inspection.verdicts(&dataset, &criterion))
            .map_err(|e| AppError::failed("computing bop24 errors", e))
    })
    .await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_submissions_scored_alike_compare() {
        use ProtocolName::{Bop19, Eccv18};
        let det = Some(Task::Coco(CocoProtocol::Detection));
        let seg = Some(Task::Coco(CocoProtocol::Segmentation));
        let bop24 = Some(Task::Bop24);
        assert!(share_a_protocol((&[Bop19, Eccv18], None), (&[Bop19], None)));
        assert!(!share_a_protocol((&[Eccv18], None), (&[Bop19], None)));
        // A 6D submission never compares with a 2D one, whatever its (empty) protocols.
        assert!(!share_a_protocol((&[Bop19], None), (&[], det)));
        assert!(!share_a_protocol((&[], det), (&[Bop19], None)));
        assert!(share_a_protocol((&[], det), (&[], det)));
        assert!(!share_a_protocol((&[], det), (&[], seg)));
        // BOP'24 detections compare with each other only.
        assert!(share_a_protocol((&[], bop24), (&[], bop24)));
        assert!(!share_a_protocol((&[], bop24), (&[], det)));
        assert!(!share_a_protocol((&[], bop24), (&[Bop19], None)));
    }
}
