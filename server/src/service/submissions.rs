//! The upload flow, one way for every caller (the form, the REST API, the demo set-up): each
//! file's dataset is the `dataset` field or, without it, the one its BOP name
//! (`METHOD_DATASET-SPLIT.csv`) says, and the two must agree, since a file for the wrong
//! dataset is the commonest mistake; the file is validated with the evaluator's parser (every
//! problem with its line), checked for coverage against the dataset, and stored compressed in
//! the database under its content hash with its job; the method (get or create), the duplicate
//! checks and the fair-use limit are decided with the inserts in one transaction. An upload of
//! several files (one per dataset, or a zip of them) becomes one submission per file, every
//! file is checked before any is stored, so one bad file refuses them all, and all are created
//! in one transaction, so a limit met at the fourth file leaves none of the first three behind.
//! Callers hand over values already parsed at their edge (`MethodName`,
//! `Visibility`, ...). A refused upload leaves no row behind.
//!
//! An upload with a `team` is for that team's method of the given name (created as the team's
//! if new), for the team's members only: anyone else is told the team is not one of theirs
//! (404), before a file is looked at. Each submission stays its uploader's, so the fair-use
//! limit counts the uploader's submissions whatever method they are for.
//!
//! A `.json` file (or any file when a 2D task is asked for) is a BOP'22 2D result file: parsed
//! with the evaluator's COCO parser (each problem naming its entry and key), its task the one
//! asked for or read from its content, and pre-flighted against the dataset's target images.
//!
//! A `bop24` upload (BOP'24 6D detection) is a BOP'19 CSV file, parsed as any, pre-flighted
//! against the images of the dataset's `test_targets_bop24.json`; a dataset without that file
//! takes none.

pub mod quota;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::sync::Arc;

use evaluator::protocol::ProtocolName;
use evaluator::{coco, results};
use intake::archive;

use crate::app::App;
use crate::clock::now_ms;
use crate::datasets;
use crate::datasets::config::BOP24_TARGETS;
use crate::datasets::uploaded_file;
use crate::domain::{
    CocoProtocol, DatasetId, Hardware, MethodName, Task, TeamId, TeamName, Visibility,
};
use crate::error::{AppError, AppResult, LineProblem};
use crate::preflight::Preflight;
use crate::service::datasets::served;
use crate::service::{publishing, teams};
use crate::store::accounts::User;
use crate::store::methods::MethodMeta;
use crate::store::submissions::{CreatedAll, CreatedOne, FairUse, NewSubmission, SubmissionRow};
use crate::wording;

pub use intake::UploadedFile;

/// Estimate evaluations per second assumed until this service has measured its own speed.
const ASSUMED_SPEED: f64 = 250.0;

/// Estimate evaluations per second: as measured on this service's recent jobs, else assumed.
pub async fn speed(app: &App) -> AppResult<f64> {
    Ok(app.store.measured_speed().await?.unwrap_or(ASSUMED_SPEED))
}

/// How far a running evaluation is, in the unit its pages count in: a 2D file's detections;
/// a 6D file's estimates under its protocol, or, under several, evaluations (an estimate
/// counts once under each protocol), with the estimates each protocol evaluates, as the
/// pre-flight announced them. `None` before the work is known.
pub fn progress_words(s: &SubmissionRow) -> Option<String> {
    if s.work <= 0 {
        return None;
    }
    let done = s.work_done.clamp(0, s.work);
    let per = &s.preflight.estimates_evaluated;
    Some(match per.iter().collect::<Vec<_>>().as_slice() {
        _ if s.task == Some(Task::Bop24) => format!(
            "{done} of {} evaluated under bop24",
            wording::count(s.work, "estimate", "estimates")
        ),
        _ if s.task.is_some() => format!(
            "{done} of {} evaluated",
            wording::count(s.work, "detection", "detections")
        ),
        [(protocol, _)] => format!(
            "{done} of {} evaluated under {}",
            wording::count(s.work, "estimate", "estimates"),
            protocol.as_str()
        ),
        [] => format!(
            "{done} of {} done",
            wording::count(s.work, "evaluation", "evaluations")
        ),
        several => {
            let each: Vec<String> = several
                .iter()
                .enumerate()
                .map(|(i, (protocol, n))| {
                    let n = match i {
                        0 => wording::count(n, "estimate", "estimates"),
                        _ => n.to_string(),
                    };
                    format!("{n} under {}", protocol.as_str())
                })
                .collect();
            format!(
                "{done} of {} done ({})",
                wording::count(s.work, "evaluation", "evaluations"),
                each.join(", ")
            )
        }
    })
}

/// The 6D protocols of an upload: those it is scored under and those its pre-flight speaks
/// for.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Protocols {
    pub scored: Vec<ProtocolName>,
    /// Whose selection of estimates the pre-flight warns about: a BOP'19 file holds several
    /// estimates per target, which eccv18 (one per target) would flag on every upload.
    pub warned: Vec<ProtocolName>,
}

impl Protocols {
    /// The protocols the uploader chose; without a choice, the file is scored under both and
    /// warned about for bop19 only, the protocol its format is written for.
    pub fn asked(asked: &[ProtocolName]) -> Protocols {
        match asked {
            [] => Protocols {
                scored: vec![ProtocolName::Bop19, ProtocolName::Eccv18],
                warned: vec![ProtocolName::Bop19],
            },
            some => Protocols {
                scored: some.to_vec(),
                warned: some.to_vec(),
            },
        }
    }
}

/// An upload, parsed.
#[derive(Debug)]
pub struct Upload {
    pub method: MethodName,
    /// The team whose method `method` is; `None`: the uploader's own.
    pub team: Option<TeamName>,
    /// The name of a served dataset; `None`: each file's name says it.
    pub dataset: Option<String>,
    /// The protocols to evaluate a 6D (CSV) file under, and those the uploader chose (see
    /// [`Protocols::asked`]).
    pub protocols: Protocols,
    /// The task asked for (bop24 or a 2D one); `None`: a `.json` file's 2D task is inferred
    /// from its content, a `.csv` file is scored under `protocols`.
    pub task: Option<Task>,
    pub meta: MethodMeta,
    pub hardware: Hardware,
    /// As asked; `None`: private for a new submission, and unchanged for a file already
    /// submitted (so a retry that leaves the field out never publishes a private one). Asking
    /// for public publishes once evaluated, unless red flags hold it back (see `publishing`).
    pub visibility: Option<Visibility>,
    /// One result file per dataset.
    pub files: Vec<UploadedFile>,
}

pub struct Accepted {
    pub submission: SubmissionRow,
    /// The same file had been submitted for the method: this is that submission, with the
    /// visibility the upload asked for.
    pub duplicate: bool,
    pub preflight: Preflight,
}

/// A file that passed every check, ready to be stored.
struct Checked {
    file: UploadedFile,
    dataset_id: DatasetId,
    /// The task of a bop24 or BOP'22 file (scored for it instead of the protocols).
    task: Option<Task>,
    estimates_count: usize,
    preflight: Preflight,
}

/// Whether an upload counts against its owner's fair-use limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// A user's upload, through a form or the API.
    FairUse,
    /// The service's own demo submissions at first start: they are more than a user may
    /// make in a day, and nobody is waiting for the limit to protect them.
    Exempt,
}

/// Validates, pre-flights, stores and queues an upload by `owner`: one submission per file, in
/// the order of the files. With several files, every refused one is named in one 422 and
/// none is stored.
pub async fn submit(app: &App, owner: &User, upload: Upload) -> AppResult<Vec<Accepted>> {
    submit_under(app, owner, upload, Limit::FairUse).await
}

/// [`submit`] under the given limit.
pub async fn submit_under(
    app: &App,
    owner: &User,
    upload: Upload,
    limit: Limit,
) -> AppResult<Vec<Accepted>> {
    let Upload {
        method,
        team,
        dataset,
        protocols,
        task,
        meta,
        hardware,
        visibility,
        files,
    } = upload;
    if files.is_empty() {
        return Err(AppError::BadRequest(
            "field `file` (the result file) is required".into(),
        ));
    }
    let team = match &team {
        Some(name) => Some(teams::member_team(app, owner, name).await?.id),
        None => None,
    };
    let files = unpack_archives(app, files).await?;
    let several = files.len() > 1;
    let total = files.len();
    let mut checked = Vec::new();
    let mut problems = Vec::new();
    let mut refused = 0;
    let mut seen: BTreeMap<String, String> = BTreeMap::new();
    for file in files {
        let name = file.name.clone();
        // Where the dataset's name was read, for an answer that it is not served.
        let from = match &dataset {
            Some(_) => "the field `dataset`".to_string(),
            None => format!("the file name {name}"),
        };
        let result = match file_dataset(dataset.as_deref(), &name) {
            Ok(ds) => match seen.insert(ds.clone(), name.clone()) {
                Some(first) => Err(AppError::Invalid {
                    message: format!("{first} and {name} are both for dataset `{ds}`"),
                    problems: Vec::new(),
                }),
                None if task == Some(Task::Bop24) => check_bop24(app, &ds, &from, file).await,
                None if task.is_some() || is_coco_file(&name) => {
                    check_coco(app, &ds, &from, file, task.and_then(Task::coco)).await
                }
                None => check(app, &ds, &from, file, &protocols).await,
            },
            Err(e) => Err(e),
        };
        match result {
            Ok(c) => checked.push(c),
            Err(e) if !several => return Err(e),
            Err(e) if !e.is_internal() => {
                refused += 1;
                problems.extend(file_problems(&name, e));
            }
            Err(e) => return Err(e),
        }
    }
    if refused > 0 {
        return Err(AppError::Invalid {
            message: format!("{refused} of {total} files are refused, so none was submitted"),
            problems,
        });
    }

    store_all(
        app,
        owner,
        &Described {
            method: &method,
            team,
            meta: &meta,
            protocols: &protocols.scored,
            visibility,
            hardware: &hardware,
        },
        checked,
        limit,
    )
    .await
}

/// The upload's files with every zip archive replaced by the result files it holds.
async fn unpack_archives(app: &App, files: Vec<UploadedFile>) -> AppResult<Vec<UploadedFile>> {
    let mut out = Vec::with_capacity(files.len());
    for file in files {
        if !archive::is_zip(&file) {
            out.push(file);
            continue;
        }
        let (dir, limit) = (app.config.submissions_dir(), app.config.max_upload_bytes());
        // Inflating is CPU work and blocking reads: off the async threads.
        let unpacked = tokio::task::spawn_blocking(move || {
            let reader = BufReader::new(File::open(&file.tmp)?);
            archive::unpack(&dir, &file.name, reader, limit)
        })
        .await
        .map_err(|e| AppError::failed("unpacking a zip archive", e))??;
        out.extend(unpacked);
    }
    Ok(out)
}

/// The dataset a file is for: the field when given, else the one its name
/// `METHOD_DATASET-SPLIT.csv` says; both given must agree.
pub fn file_dataset(field: Option<&str>, file_name: &str) -> AppResult<String> {
    let named = results::parse_result_filename(file_name).map(|n| n.dataset);
    match (field, named) {
        (Some(field), Some(named)) if field != named => Err(AppError::Invalid {
            message: format!(
                "{file_name} is named for dataset `{named}`, but the field `dataset` says \
                 `{field}`: is it the file for the right dataset?"
            ),
            problems: Vec::new(),
        }),
        (Some(field), _) => Ok(field.to_string()),
        (None, Some(named)) => Ok(named),
        (None, None) => Err(AppError::BadRequest(format!(
            "field `dataset` is required unless the file is named METHOD_DATASET-SPLIT.csv \
             (e.g. my-method_tless-test.csv); {file_name} is not"
        ))),
    }
}

/// A refused file's problems, each naming the file.
fn file_problems(file_name: &str, e: AppError) -> Vec<LineProblem> {
    let problems = match &e {
        AppError::Invalid { problems, .. } => problems.clone(),
        _ => Vec::new(),
    };
    std::iter::once(LineProblem {
        file: Some(file_name.to_string()),
        line: 0,
        message: e.to_string(),
    })
    .chain(problems.into_iter().map(|p| LineProblem {
        file: Some(file_name.to_string()),
        message: format!("{file_name}: {}", p.message),
        ..p
    }))
    .collect()
}

/// Parses and pre-flights one file against its dataset, storing nothing.
async fn check(
    app: &App,
    dataset: &str,
    from: &str,
    file: UploadedFile,
    protocols: &Protocols,
) -> AppResult<Checked> {
    let row = served(app, dataset, from).await?;
    let loaded: Arc<evaluator::Dataset> = app.dataset(&row).await?;

    // Parsing and the coverage check are CPU work: off the async threads, in one go.
    let (path, ps) = (file.tmp.to_path_buf(), protocols.clone());
    let parsed = tokio::task::spawn_blocking(move || {
        results::load_results(&path).map(|r| {
            let preflight = Preflight::of(&loaded, &r, &ps.scored, &ps.warned);
            (r.estimates.len(), preflight)
        })
    })
    .await
    .map_err(|e| AppError::failed("checking a result file", e))?;
    checked_csv(file, row.id, None, parsed)
}

/// What the CSV checks of [`check`] and [`check_bop24`] share once the file is parsed and
/// pre-flighted: a parse failure refused line by line, an empty file refused, else the file
/// kept for its task.
fn checked_csv(
    file: UploadedFile,
    dataset_id: DatasetId,
    task: Option<Task>,
    parsed: Result<(usize, Preflight), evaluator::Error>,
) -> AppResult<Checked> {
    let (estimates_count, preflight) = match parsed {
        Ok(r) => r,
        Err(evaluator::Error::Results(problems)) => {
            return Err(line_problems(&file.name, &problems));
        }
        Err(e) => return Err(AppError::failed("reading a result file", e)),
    };
    if estimates_count == 0 {
        return Err(AppError::Invalid {
            message: format!("{} contains no estimate", file.name),
            problems: Vec::new(),
        });
    }
    Ok(Checked {
        file,
        dataset_id,
        task,
        estimates_count,
        preflight,
    })
}

/// The problems of a refused BOP'19 CSV file, each with its line.
fn line_problems(file_name: &str, problems: &results::Problems) -> AppError {
    let mut list: Vec<LineProblem> = problems
        .problems
        .iter()
        .map(|p| LineProblem {
            file: None,
            line: p.line,
            message: p.to_string(),
        })
        .collect();
    if problems.omitted > 0 {
        list.push(LineProblem {
            file: None,
            line: 0,
            message: format!("... and {} more problems", problems.omitted),
        });
    }
    AppError::Invalid {
        message: format!("{file_name} is not a valid result file"),
        problems: list,
    }
}

/// Whether a file is a BOP'22 2D result file (`METHOD_DATASET-test.json`) by its name.
fn is_coco_file(name: &str) -> bool {
    name.to_ascii_lowercase().ends_with(".json")
}

/// [`check`] for a BOP'22 2D file: parsed with the evaluator's parser (each problem naming its
/// entry and key), its task the one asked for or, without one, segmentation when an entry has
/// a mask and detection otherwise; then checked to hold what the task scores, and pre-flighted
/// against the dataset's target images.
async fn check_coco(
    app: &App,
    dataset: &str,
    from: &str,
    file: UploadedFile,
    asked: Option<CocoProtocol>,
) -> AppResult<Checked> {
    let row = served(app, dataset, from).await?;
    let root = app.dataset(&row).await?.root.clone();
    let path = file.tmp.to_path_buf();
    let name = file.name.clone();
    let parsed = tokio::task::spawn_blocking(move || -> AppResult<_> {
        let results = match coco::load_coco_results(&path) {
            Ok(r) => r,
            Err(evaluator::Error::CocoResults(problems)) => {
                return Err(entry_problems(&name, &problems));
            }
            Err(e) => return Err(AppError::failed("reading a BOP'22 result file", e)),
        };
        let task = asked.unwrap_or(
            if results.entries.iter().any(|e| e.segmentation.is_some()) {
                CocoProtocol::Segmentation
            } else {
                CocoProtocol::Detection
            },
        );
        results
            .require(task.task())
            .map_err(|problems| entry_problems(&name, &problems))?;
        let gt = datasets::config::coco_gt(&root, false).map_err(|e| AppError::Invalid {
            message: format!(
                "dataset `{}` has no usable 2D ground truth (scene_gt_coco.json): {e}",
                root.file_name().unwrap_or_default().to_string_lossy()
            ),
            problems: Vec::new(),
        })?;
        Ok((
            results.entries.len(),
            task,
            Preflight::of_coco(&gt, &results),
        ))
    })
    .await
    .map_err(|e| AppError::failed("checking a BOP'22 result file", e))?;
    let (estimates_count, task, preflight) = parsed?;
    if estimates_count == 0 {
        return Err(AppError::Invalid {
            message: format!("{} contains no entry", file.name),
            problems: Vec::new(),
        });
    }
    Ok(Checked {
        file,
        dataset_id: row.id,
        task: Some(Task::Coco(task)),
        estimates_count,
        preflight,
    })
}

/// [`check`] for a bop24 file: a BOP'19 CSV file, parsed as any, pre-flighted against the
/// images of the dataset's `test_targets_bop24.json` with the toolkit's cap of estimates per
/// image.
async fn check_bop24(
    app: &App,
    dataset: &str,
    from: &str,
    file: UploadedFile,
) -> AppResult<Checked> {
    if is_coco_file(&file.name) {
        return Err(AppError::BadRequest(format!(
            "{} is a BOP'22 JSON file: bop24 (6D detection) reads BOP'19 CSV result files",
            file.name
        )));
    }
    let row = served(app, dataset, from).await?;
    let Some(loaded) = app.bop24_dataset(&row).await? else {
        return Err(AppError::BadRequest(format!(
            "dataset `{}` has no {BOP24_TARGETS}, the image targets of 6D detection: it takes \
             no bop24 upload (ask its operator to add the file, or choose bop19)",
            row.name
        )));
    };
    let path = file.tmp.to_path_buf();
    let parsed = tokio::task::spawn_blocking(move || {
        results::load_results(&path).map(|r| {
            let cap = evaluator::detection::default_max_estimates_per_image(&loaded.name);
            (r.estimates.len(), Preflight::of_bop24(&loaded, &r, cap))
        })
    })
    .await
    .map_err(|e| AppError::failed("checking a result file", e))?;
    checked_csv(file, row.id, Some(Task::Bop24), parsed)
}

/// The problems of a refused BOP'22 file, each naming its entry (from 0) and key.
fn entry_problems(file_name: &str, problems: &coco::problems::EntryProblems) -> AppError {
    let mut list: Vec<LineProblem> = problems
        .problems
        .iter()
        .map(|p| LineProblem {
            file: None,
            line: 0,
            message: p.to_string(),
        })
        .collect();
    if problems.omitted > 0 {
        list.push(LineProblem {
            file: None,
            line: 0,
            message: format!("... and {} more problems", problems.omitted),
        });
    }
    AppError::Invalid {
        message: format!("{file_name} is not a valid BOP'22 result file"),
        problems: list,
    }
}

/// What every file of one upload shares.
struct Described<'a> {
    method: &'a MethodName,
    team: Option<TeamId>,
    meta: &'a MethodMeta,
    protocols: &'a [ProtocolName],
    visibility: Option<Visibility>,
    hardware: &'a Hardware,
}

/// Stores and queues the checked files of one upload, all or none: the files are put in place
/// first (so no worker can find a job without its file), then every submission is created in
/// one store transaction; when that refuses (the fair-use limit) or fails, the files no
/// submission uses are removed again.
async fn store_all(
    app: &App,
    owner: &User,
    what: &Described<'_>,
    checked: Vec<Checked>,
    limit: Limit,
) -> AppResult<Vec<Accepted>> {
    let Described {
        method,
        team,
        meta,
        protocols,
        visibility,
        hardware,
    } = *what;
    // The waiting time of each file counts the files of the upload before it.
    let mut ahead = app.store.work_ahead(None).await?;
    let place = app.store.queue_place(None).await?;
    let speed = speed(app).await?;
    let mut kept = Vec::with_capacity(checked.len());
    for Checked {
        file,
        dataset_id,
        task,
        estimates_count,
        mut preflight,
    } in checked
    {
        let work = preflight.work();
        preflight.estimated_seconds = (ahead + work) as f64 / speed;
        preflight.queue_position = place.queued_ahead;
        ahead += work;
        // The file goes into the database with its job (compressed off the async threads), so
        // any worker, on any machine, finds the two together.
        let path = file.tmp.to_path_buf();
        let gzip =
            tokio::task::spawn_blocking(move || uploaded_file::compress(&std::fs::read(path)?))
                .await
                .map_err(|e| AppError::failed("compressing the upload", e))?
                .map_err(|e| AppError::failed("compressing the upload", e))?;
        kept.push(Kept {
            name: file.name,
            sha256: file.sha256,
            size: file.size,
            gzip,
            dataset_id,
            task,
            estimates_count,
            preflight,
        });
    }

    let config = &app.config;
    let limited = limit == Limit::FairUse && config.submissions_per_window > 0;
    let fair_use = limited.then(|| FairUse {
        limit: config.submissions_per_window as usize,
        since: now_ms() - config.limit_window_ms(),
    });
    let news: Vec<NewSubmission> = kept
        .iter()
        .map(|k| {
            let (visibility, held) =
                publishing::initial(visibility.unwrap_or(Visibility::Private), &k.preflight);
            NewSubmission {
                owner_id: owner.id,
                team_id: team,
                method,
                meta,
                dataset_id: k.dataset_id,
                protocols,
                task: k.task,
                visibility,
                held,
                file_name: &k.name,
                file_sha256: &k.sha256,
                file_size: k.size as i64,
                file_gzip: &k.gzip,
                estimates_count: k.estimates_count as i64,
                hardware,
                preflight: &k.preflight,
            }
        })
        .collect();
    // Files and submissions go in together or not at all: a refusal leaves nothing behind.
    let created = match app.store.create_submissions(&news, fair_use).await? {
        CreatedAll::All(created) => created,
        CreatedAll::Limited { index, times } => {
            return Err(over_limit(
                config.submissions_per_window as usize,
                config.limit_window_ms(),
                &times,
                &kept[index].name,
                kept.len(),
            ));
        }
    };
    if created.iter().any(|c| matches!(c, CreatedOne::New(_))) {
        app.wake.notify_waiters();
    }
    let mut accepted = Vec::with_capacity(created.len());
    for (c, k) in created.into_iter().zip(kept) {
        let (id, duplicate) = match c {
            CreatedOne::New(id) => (id, false),
            CreatedOne::Duplicate(id) => (id, true),
        };
        let mut submission = app
            .store
            .submission(id)
            .await?
            .ok_or_else(|| AppError::Internal("the new submission vanished".into()))?;
        let preflight = if duplicate {
            // Re-sending a file with another visibility is how its owner publishes or
            // withdraws it: nothing is lost and what they asked for holds, red flags holding
            // publication back. On a team's method the duplicate may be another member's
            // upload, whose publication stays theirs to decide.
            let own = submission.owner_id == Some(owner.id);
            if let Some(asked) = visibility.filter(|v| own && *v != submission.visibility) {
                match publishing::initial(asked, &submission.preflight) {
                    (_, true) => {
                        app.store.hold_publication(id).await?;
                        submission.held = true;
                    }
                    (v, false) => {
                        app.store.set_visibility(id, v).await?;
                        submission.visibility = v;
                        submission.held = false;
                    }
                }
            }
            submission.preflight.clone()
        } else {
            k.preflight
        };
        accepted.push(Accepted {
            submission,
            duplicate,
            preflight,
        });
    }
    Ok(accepted)
}

/// A checked file, compressed, about to get its submission.
struct Kept {
    name: String,
    sha256: String,
    size: u64,
    gzip: Vec<u8>,
    dataset_id: DatasetId,
    task: Option<Task>,
    estimates_count: usize,
    preflight: Preflight,
}

/// The fair-use window in words: "24 hours" for the default day, else its seconds.
fn window(ms: i64) -> String {
    if ms % 3_600_000 == 0 {
        wording::count(ms / 3_600_000, "hour", "hours")
    } else {
        wording::count(ms / 1000, "second", "seconds")
    }
}

/// The answer to an upload over the fair-use limit at file `file` of `files`: the next one is
/// allowed once the oldest of the last `limit` counted submissions leaves the window.
fn over_limit(limit: usize, window_ms: i64, times: &[i64], file: &str, files: usize) -> AppError {
    let retry_at = times
        .len()
        .checked_sub(limit)
        .and_then(|i| times.get(i))
        .map_or_else(now_ms, |t| t + window_ms);
    let none = if files > 1 {
        format!("; none of the {files} files was submitted")
    } else {
        String::new()
    };
    AppError::TooMany {
        message: format!(
            "{file}: at most {limit} submissions per dataset within {}: the next one is \
             allowed at {}{none}",
            window(window_ms),
            quota::retry_time(retry_at)
        ),
        retry_at,
    }
}
