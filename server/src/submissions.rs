//! The upload flow, one way for every caller (the form, the REST API, the demo set-up): the
//! file is validated with the evaluator's parser (every problem with its line), checked for
//! coverage against the dataset, stored under its content hash, and queued; the method (get or
//! create), the duplicate check and the fair-use limit are decided with the insert in one
//! transaction. Callers hand over values already parsed at their edge (`MethodName`,
//! `Visibility`, ...). A refused upload leaves no row behind.

use std::io::Write;
use std::path::Path;

use evaluator::protocol::ProtocolName;
use evaluator::results;
use sha2::{Digest, Sha256};

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{Hardware, MethodName, Visibility};
use crate::error::{AppError, AppResult, LineProblem};
use crate::preflight::Preflight;
use crate::store::accounts::User;
use crate::store::methods::MethodMeta;
use crate::store::submissions::{Created, FairUse, NewSubmission, SubmissionRow};

/// Evaluation cost assumed per evaluated estimate and protocol, in seconds, for the estimate
/// of the waiting time shown at upload.
const SECONDS_PER_ESTIMATE: f64 = 0.004;

/// An upload, parsed.
#[derive(Debug)]
pub struct Upload {
    pub method: MethodName,
    /// The name of a served dataset.
    pub dataset: String,
    /// The protocols to evaluate under.
    pub protocols: Vec<ProtocolName>,
    pub meta: MethodMeta,
    pub hardware: Hardware,
    pub visibility: Visibility,
    pub file: UploadedFile,
}

/// A result file received into a temporary file of the submissions folder (removed unless it
/// is kept), with its content hash.
#[derive(Debug)]
pub struct UploadedFile {
    /// The client's name for it, for display.
    pub name: String,
    pub tmp: tempfile::TempPath,
    pub sha256: String,
    pub size: u64,
}

impl UploadedFile {
    /// A file from bytes already in memory (the demo set-up).
    pub fn from_bytes(dir: &Path, name: &str, bytes: &[u8]) -> std::io::Result<UploadedFile> {
        let mut tmp = tempfile::Builder::new()
            .prefix("upload-")
            .tempfile_in(dir)?;
        tmp.write_all(bytes)?;
        tmp.flush()?;
        Ok(UploadedFile {
            name: name.to_string(),
            tmp: tmp.into_temp_path(),
            sha256: hex::encode(Sha256::digest(bytes)),
            size: bytes.len() as u64,
        })
    }
}

pub struct Accepted {
    pub submission: SubmissionRow,
    /// The same file had been submitted for the method: this is that submission.
    pub duplicate: bool,
    pub preflight: Preflight,
}

/// Validates, pre-flights, stores and queues an upload by `owner`.
pub async fn submit(app: &App, owner: &User, upload: Upload) -> AppResult<Accepted> {
    let Upload {
        method,
        dataset,
        protocols,
        meta,
        hardware,
        visibility,
        file,
    } = upload;
    let row = app
        .store
        .dataset_by_name(&dataset)
        .await?
        .ok_or_else(|| AppError::BadRequest(format!("unknown dataset `{dataset}`")))?;
    let loaded = app.dataset(&row).await?;

    // Parsing and the coverage check are CPU work: off the async threads, in one go.
    let (path, ps) = (file.tmp.to_path_buf(), protocols.clone());
    let parsed = tokio::task::spawn_blocking(move || {
        results::load_results(&path).map(|r| (r.estimates.len(), Preflight::of(&loaded, &r, &ps)))
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

    let ahead = app.store.estimates_ahead(i64::MAX).await?;
    preflight.estimated_seconds =
        (ahead as f64 + preflight.estimates as f64 * protocols.len() as f64) * SECONDS_PER_ESTIMATE;
    preflight.queue_position = app.store.queue_position(i64::MAX).await?;

    // The file is in place before its job exists, so no worker can find the job without it.
    let stored = app.stored_file(&file.sha256);
    file.tmp
        .persist(&stored)
        .map_err(|e| AppError::Internal(format!("cannot store the upload: {e}")))?;

    let config = &app.config;
    let fair_use = (config.submissions_per_window > 0).then(|| FairUse {
        limit: config.submissions_per_window as usize,
        since: now_ms() - config.limit_window_ms(),
    });
    let created = app
        .store
        .create_submission(
            &NewSubmission {
                owner_id: owner.id,
                method: &method,
                meta: &meta,
                dataset_id: row.id,
                protocols: &protocols,
                visibility,
                file_name: &file.name,
                file_sha256: &file.sha256,
                file_size: file.size as i64,
                estimates_count: estimates_count as i64,
                hardware: &hardware,
                preflight: &preflight,
            },
            fair_use,
        )
        .await?;
    let (id, duplicate) = match created {
        Created::New(id) => {
            app.wake.notify_waiters();
            (id, false)
        }
        Created::Duplicate(id) => (id, true),
        Created::Limited { times } => {
            if !app.store.file_in_use(&file.sha256).await? {
                let _ = tokio::fs::remove_file(&stored).await;
            }
            return Err(over_limit(
                config.submissions_per_window as usize,
                config.limit_window_ms(),
                &times,
            ));
        }
    };
    let submission = app
        .store
        .submission(id)
        .await?
        .ok_or_else(|| AppError::Internal("the new submission vanished".into()))?;
    if duplicate {
        preflight = submission.preflight.clone();
    }
    Ok(Accepted {
        submission,
        duplicate,
        preflight,
    })
}

/// The answer to an upload over the fair-use limit: the next one is allowed once the oldest of
/// the last `limit` counted submissions leaves the window.
fn over_limit(limit: usize, window_ms: i64, times: &[i64]) -> AppError {
    let retry_at = times[times.len() - limit] + window_ms;
    AppError::TooMany {
        message: format!(
            "at most {limit} submissions per dataset within {} s: the next one is allowed in {} s",
            window_ms / 1000,
            ((retry_at - now_ms()).max(0) + 999) / 1000
        ),
        retry_at,
    }
}
