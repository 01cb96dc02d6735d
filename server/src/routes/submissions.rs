//! Receiving a result file, from the browser form or the REST API alike: streamed to disk under
//! a size bound while hashed, validated with the evaluator's parser (every problem with its
//! line), checked for coverage against the dataset, then stored and queued. A rejected upload
//! leaves neither a file nor a row behind.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::str::FromStr;

use axum::extract::Multipart;
use axum::extract::multipart::Field;
use evaluator::Dataset;
use evaluator::protocol::{NTop, Protocol, ProtocolName};
use evaluator::results::{self, Results};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;

use crate::app::AppState;
use crate::error::{AppError, AppResult, LineProblem};
use crate::store::accounts::User;
use crate::store::{MethodMeta, NewSubmission, SubmissionRow};

/// Longest accepted text field (method description and the like).
const MAX_TEXT_FIELD: usize = 10_000;
/// Values of the method metadata the BOP site asks for.
pub const TRAINING_DATA: &[&str] = &["synthetic", "real", "both"];
pub const MODALITIES: &[&str] = &["rgb", "depth", "rgb-d"];
/// Evaluation cost assumed before any job has been timed, in seconds per evaluated estimate.
const SECONDS_PER_ESTIMATE: f64 = 0.004;

/// The fields of an upload.
#[derive(Debug, Default)]
pub struct Upload {
    pub method: String,
    pub dataset: String,
    pub protocol: Option<String>,
    pub description: String,
    pub paper_url: String,
    pub code_url: String,
    /// `synthetic`, `real` or `both`.
    pub training_data: String,
    /// `rgb`, `depth` or `rgb-d`.
    pub modality: String,
    pub hardware: String,
    pub public: bool,
    /// The CSRF token of a browser form (the API authenticates by token instead).
    pub csrf: String,
    pub file: Option<UploadedFile>,
}

#[derive(Debug)]
pub struct UploadedFile {
    pub name: String,
    pub tmp: tempfile::TempPath,
    pub sha256: String,
    pub size: u64,
}

/// What the pre-flight check found, shown before evaluation and kept with the submission.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Preflight {
    pub estimates: usize,
    pub images: usize,
    pub targets: usize,
    pub targets_without_estimate: usize,
    /// Estimates for images or objects that are not test targets (ignored by the evaluation).
    pub estimates_not_for_targets: usize,
    /// Estimates for an object that does not appear in the image at all.
    pub estimates_for_absent_objects: usize,
    /// Per protocol, estimates beyond those it considers per target (n_top).
    pub estimates_beyond_n_top: BTreeMap<String, usize>,
    pub warnings: Vec<String>,
    pub queue_position: i64,
    pub estimated_seconds: f64,
}

pub struct Accepted {
    pub submission: SubmissionRow,
    pub duplicate: bool,
    pub preflight: Preflight,
}

/// Reads a multipart upload, streaming the file to a temporary file in the data directory.
pub async fn read_upload(
    app: &AppState,
    mut multipart: Multipart,
    limit: u64,
) -> AppResult<Upload> {
    let mut upload = Upload {
        public: true,
        ..Upload::default()
    };
    while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
        let name = field.name().unwrap_or_default().to_string();
        match name.as_str() {
            "file" => upload.file = Some(save_file(app, field, limit).await?),
            "method" => upload.method = text(field).await?.trim().to_string(),
            "dataset" => upload.dataset = text(field).await?.trim().to_string(),
            "protocol" => {
                let p = text(field).await?.trim().to_string();
                upload.protocol = (!p.is_empty()).then_some(p);
            }
            "description" => upload.description = text(field).await?.trim().to_string(),
            "paper_url" => upload.paper_url = text(field).await?.trim().to_string(),
            "code_url" => upload.code_url = text(field).await?.trim().to_string(),
            "training_data" => upload.training_data = text(field).await?.trim().to_lowercase(),
            "modality" => upload.modality = text(field).await?.trim().to_lowercase(),
            "hardware" => upload.hardware = text(field).await?.trim().to_string(),
            "csrf" => upload.csrf = text(field).await?.trim().to_string(),
            "public" | "visibility" => {
                let v = text(field).await?;
                upload.public = matches!(v.trim(), "1" | "true" | "on" | "yes" | "public");
            }
            _ => {
                // Unknown fields are drained and ignored.
                text(field).await?;
            }
        }
    }
    Ok(upload)
}

fn multipart_error(e: axum::extract::multipart::MultipartError) -> AppError {
    if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        AppError::TooLarge { limit: 0 }
    } else {
        AppError::BadRequest(format!("malformed upload: {}", e.body_text()))
    }
}

async fn text(mut field: Field<'_>) -> AppResult<String> {
    let mut bytes = Vec::new();
    while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
        bytes.extend_from_slice(&chunk);
        if bytes.len() > MAX_TEXT_FIELD {
            return Err(AppError::BadRequest(format!(
                "field `{}` is longer than {MAX_TEXT_FIELD} bytes",
                field.name().unwrap_or_default()
            )));
        }
    }
    String::from_utf8(bytes)
        .map_err(|_| AppError::BadRequest("a text field is not valid UTF-8".into()))
}

async fn save_file(app: &AppState, mut field: Field<'_>, limit: u64) -> AppResult<UploadedFile> {
    // Only the last path component of the client's file name is kept, for display.
    let name = field
        .file_name()
        .unwrap_or("results.csv")
        .rsplit(['/', '\\'])
        .next()
        .unwrap_or("results.csv")
        .chars()
        .filter(|c| !c.is_control())
        .take(200)
        .collect::<String>();
    let tmp = tempfile::Builder::new()
        .prefix("upload-")
        .tempfile_in(app.config.submissions_dir())?
        .into_temp_path();
    let mut out = tokio::fs::File::create(&tmp).await?;
    let mut hasher = Sha256::new();
    let mut size = 0u64;
    while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
        size += chunk.len() as u64;
        if size > limit {
            return Err(AppError::TooLarge { limit });
        }
        hasher.update(&chunk);
        out.write_all(&chunk).await?;
    }
    out.flush().await?;
    Ok(UploadedFile {
        name,
        tmp,
        sha256: hex::encode(hasher.finalize()),
        size,
    })
}

/// Validates, pre-flights, stores and queues an upload by `owner`.
pub async fn accept(app: &AppState, upload: Upload, owner: &User) -> AppResult<Accepted> {
    let method = check_name("method", &upload.method)?;
    if upload.dataset.is_empty() {
        return Err(AppError::BadRequest("field `dataset` is required".into()));
    }
    let protocols: Vec<ProtocolName> = match &upload.protocol {
        None => vec![ProtocolName::Bop19, ProtocolName::Eccv18],
        Some(p) => vec![ProtocolName::from_str(p).map_err(AppError::BadRequest)?],
    };
    for (field, url) in [
        ("paper_url", &upload.paper_url),
        ("code_url", &upload.code_url),
    ] {
        if !(url.is_empty() || url.starts_with("https://") || url.starts_with("http://")) {
            return Err(AppError::BadRequest(format!(
                "field `{field}` must be an http(s) link"
            )));
        }
    }
    for (field, value, allowed) in [
        ("training_data", &upload.training_data, TRAINING_DATA),
        ("modality", &upload.modality, MODALITIES),
    ] {
        if !value.is_empty() && !allowed.contains(&value.as_str()) {
            return Err(AppError::BadRequest(format!(
                "field `{field}` must be one of {}",
                allowed.join(", ")
            )));
        }
    }
    if upload.hardware.chars().count() > 200 || upload.hardware.chars().any(|c| c.is_control()) {
        return Err(AppError::BadRequest(
            "field `hardware` must be at most 200 characters, without control characters".into(),
        ));
    }
    let file = upload
        .file
        .ok_or_else(|| AppError::BadRequest("field `file` (the result file) is required".into()))?;
    let row = app
        .store
        .dataset_by_name(&upload.dataset)
        .await?
        .ok_or_else(|| AppError::BadRequest(format!("unknown dataset `{}`", upload.dataset)))?;
    let dataset = app.dataset(&row).await?;

    let tmp_path: PathBuf = file.tmp.to_path_buf();
    // Parsing and the coverage check are CPU work: off the async threads, in one go.
    let (ds, ps) = (dataset.clone(), protocols.clone());
    let parsed = tokio::task::spawn_blocking(move || {
        results::load_results(&tmp_path).map(|r| {
            let p = preflight(&ds, &r, &ps);
            (r.estimates.len(), p)
        })
    })
    .await
    .map_err(|e| AppError::Internal(e.to_string()))?;
    let (estimates_count, mut preflight) = match parsed {
        Ok(r) => r,
        Err(evaluator::Error::Results(problems)) => {
            let mut list: Vec<LineProblem> = problems
                .problems
                .iter()
                .map(|p| LineProblem {
                    line: p.line,
                    message: p.to_string(),
                })
                .collect();
            if problems.omitted > 0 {
                list.push(LineProblem {
                    line: 0,
                    message: format!("... and {} more problems", problems.omitted),
                });
            }
            return Err(AppError::Invalid {
                message: format!("{} is not a valid result file", file.name),
                problems: list,
            });
        }
        Err(e) => return Err(AppError::Internal(e.to_string())),
    };
    if estimates_count == 0 {
        return Err(AppError::Invalid {
            message: format!("{} contains no estimate", file.name),
            problems: Vec::new(),
        });
    }

    let method_id = app
        .store
        .ensure_method(
            &method,
            &MethodMeta {
                description: upload.description.clone(),
                paper_url: upload.paper_url.clone(),
                code_url: upload.code_url.clone(),
                training_data: upload.training_data.clone(),
                modality: upload.modality.clone(),
            },
            owner.id,
        )
        .await?;
    if let Some(existing) = app
        .store
        .find_same_file(method_id, row.id, &file.sha256, &protocols)
        .await?
    {
        let preflight = serde_json::from_str(&existing.preflight_json).unwrap_or_default();
        return Ok(Accepted {
            submission: existing,
            duplicate: true,
            preflight,
        });
    }

    check_fair_use(app, owner.id, row.id).await?;
    let ahead = app.store.estimates_ahead(i64::MAX).await?;
    preflight.estimated_seconds =
        (ahead as f64 + preflight.estimates as f64 * protocols.len() as f64) * SECONDS_PER_ESTIMATE;
    preflight.queue_position = app.store.queue_position(i64::MAX).await?;

    let stored = app.stored_file(&file.sha256);
    file.tmp
        .persist(&stored)
        .map_err(|e| AppError::Internal(format!("cannot store the upload: {e}")))?;
    let preflight_json =
        serde_json::to_string(&preflight).map_err(|e| AppError::Internal(e.to_string()))?;
    let id = app
        .store
        .insert_submission(&NewSubmission {
            method_id,
            dataset_id: row.id,
            protocols: &protocols,
            public: upload.public,
            file_name: &file.name,
            file_sha256: &file.sha256,
            file_size: file.size as i64,
            estimates_count: estimates_count as i64,
            hardware: &upload.hardware,
            preflight_json: &preflight_json,
            owner_id: owner.id,
        })
        .await?;
    app.wake.notify_waiters();
    let submission = app
        .store
        .submission(id)
        .await?
        .ok_or_else(|| AppError::Internal("the new submission vanished".into()))?;
    Ok(Accepted {
        submission,
        duplicate: false,
        preflight,
    })
}

/// The per-user, per-dataset limit that keeps anyone from tuning on the test set.
async fn check_fair_use(app: &AppState, owner_id: i64, dataset_id: i64) -> AppResult<()> {
    let limit = app.config.submissions_per_window as usize;
    if limit == 0 {
        return Ok(());
    }
    let window = app.config.limit_window_secs as i64 * 1000;
    let times = app
        .store
        .recent_submission_times(owner_id, dataset_id, crate::store::now_ms() - window)
        .await?;
    if times.len() < limit {
        return Ok(());
    }
    // The next one is allowed once the oldest of the last `limit` leaves the window.
    let retry_at = times[times.len() - limit] + window;
    Err(AppError::TooMany {
        message: format!(
            "at most {limit} submissions per dataset within {} s: the next one is allowed in {} s",
            window / 1000,
            ((retry_at - crate::store::now_ms()).max(0) + 999) / 1000
        ),
        retry_at,
    })
}

fn check_name(field: &str, value: &str) -> AppResult<String> {
    let value = value.trim();
    if value.is_empty() {
        return Err(AppError::BadRequest(format!("field `{field}` is required")));
    }
    if value.chars().count() > 100 || value.chars().any(|c| c.is_control()) {
        return Err(AppError::BadRequest(format!(
            "field `{field}` must be at most 100 characters, without control characters"
        )));
    }
    Ok(value.to_string())
}

/// Coverage of a valid result file against the dataset's targets.
pub fn preflight(dataset: &Dataset, results: &Results, protocols: &[ProtocolName]) -> Preflight {
    let targets: BTreeMap<(u32, u32, u32), u32> = dataset
        .targets
        .iter()
        .map(|t| ((t.scene_id, t.im_id, t.obj_id), t.inst_count))
        .collect();
    let mut per_target: BTreeMap<(u32, u32, u32), usize> = BTreeMap::new();
    let mut not_for_targets = 0;
    let mut absent = 0;
    let mut images = HashSet::new();
    for e in &results.estimates {
        images.insert((e.scene_id, e.im_id));
        let key = (e.scene_id, e.im_id, e.obj_id);
        if targets.contains_key(&key) {
            *per_target.entry(key).or_default() += 1;
        } else {
            not_for_targets += 1;
            let in_image = dataset
                .scenes
                .get(&e.scene_id)
                .and_then(|s| s.images.get(&e.im_id))
                .is_some_and(|im| im.gt.iter().any(|g| g.obj_id == e.obj_id));
            if !in_image {
                absent += 1;
            }
        }
    }
    let mut beyond = BTreeMap::new();
    for &p in protocols {
        let n_top = Protocol::named(p).n_top;
        let over: usize = per_target
            .iter()
            .map(|(key, &n)| {
                let keep = match n_top {
                    NTop::Top(k) => k as usize,
                    NTop::InstCount => targets[key] as usize,
                    NTop::All => usize::MAX,
                };
                n.saturating_sub(keep)
            })
            .sum();
        beyond.insert(p.as_str().to_string(), over);
    }

    let mut warnings = Vec::new();
    let without = targets.len() - per_target.len();
    if without > 0 {
        warnings.push(format!(
            "{without} of {} targets have no estimate; they will count as misses",
            targets.len()
        ));
    }
    if not_for_targets > 0 {
        warnings.push(format!(
            "{not_for_targets} estimates are for images or objects that are not test targets; they will be ignored"
        ));
    }
    if absent > 0 {
        warnings.push(format!(
            "{absent} estimates are for objects that do not appear in their image"
        ));
    }
    for (p, n) in &beyond {
        if *n > 0 {
            warnings.push(format!(
                "{n} estimates are beyond what {p} considers per target (the highest-scored are used)"
            ));
        }
    }
    if let Some(w) = unit_warning(dataset, results) {
        warnings.push(w);
    }
    Preflight {
        estimates: results.estimates.len(),
        images: images.len(),
        targets: targets.len(),
        targets_without_estimate: without,
        estimates_not_for_targets: not_for_targets,
        estimates_for_absent_objects: absent,
        estimates_beyond_n_top: beyond,
        warnings,
        queue_position: 0,
        estimated_seconds: 0.0,
    }
}

/// Translations in metres instead of millimetres are a common mistake: the estimated
/// distances are then about a thousand times smaller than the ground truth's.
fn unit_warning(dataset: &Dataset, results: &Results) -> Option<String> {
    let median = |mut v: Vec<f64>| -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        Some(v[v.len() / 2])
    };
    let est = median(results.estimates.iter().map(|e| e.pose.t.norm()).collect())?;
    let gt = median(
        dataset
            .scenes
            .values()
            .flat_map(|s| s.images.values())
            .flat_map(|im| im.gt.iter().map(|g| g.pose.t.norm()))
            .collect(),
    )?;
    (est > 0.0 && est * 100.0 < gt).then(|| {
        format!(
            "translations look like metres (median distance {est:.3} against {gt:.0} mm in the ground truth): t must be in millimetres"
        )
    })
}
