//! The evaluation `poseboard eval` runs, for Python: a dataset loaded once and reused,
//! `evaluate` giving the report as the JSON text `poseboard eval --out` writes, and
//! `check_results`. The work runs without the GIL on a thread of its own, while the calling
//! thread forwards progress to the caller's callback and turns Ctrl-C into a cancellation.

use std::collections::{BTreeSet, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Duration;

use evaluator::dataset::DatasetOptions;
use evaluator::detection;
use evaluator::{Dataset, Error, Evaluation, Progress, results};
use pyo3::exceptions::{
    PyFileNotFoundError, PyOSError, PyPermissionError, PyRuntimeError, PyUserWarning, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::protocol::{self, Overrides};

/// A BOP dataset loaded once (models, ground truth, targets), for evaluating many result sets.
#[pyclass(frozen, name = "Dataset", module = "poseboard._native")]
pub struct PyDataset {
    inner: Arc<Dataset>,
}

#[pymethods]
impl PyDataset {
    #[new]
    #[pyo3(signature = (path, targets_file=None))]
    fn new(py: Python<'_>, path: PathBuf, targets_file: Option<String>) -> PyResult<Self> {
        let mut options = DatasetOptions::default();
        if let Some(file) = targets_file {
            options.targets_file = file;
        }
        let dataset = py
            .detach(|| Dataset::load_with(&path, &options))
            .map_err(|e| dataset_error(&path, &e))?;
        Ok(PyDataset {
            inner: Arc::new(dataset),
        })
    }

    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    #[getter]
    fn root(&self) -> PathBuf {
        self.inner.root.clone()
    }

    #[getter]
    fn obj_ids(&self) -> Vec<u32> {
        self.inner.objects.keys().copied().collect()
    }

    /// The model's points (float64 bytes, n x 3) and triangles (uint32 bytes, m x 3).
    fn model<'py>(
        &self,
        py: Python<'py>,
        obj_id: u32,
    ) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>)> {
        let mesh = &self.object(obj_id)?.mesh;
        let pts: Vec<u8> = mesh
            .vertices
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .flat_map(f64::to_ne_bytes)
            .collect();
        let faces: Vec<u8> = mesh
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_ne_bytes())
            .collect();
        Ok((PyBytes::new(py, &pts), PyBytes::new(py, &faces)))
    }

    /// The models_info.json entry: diameter, discrete symmetries (row-major 4x4), continuous
    /// symmetries (axis, offset).
    #[allow(clippy::type_complexity)]
    fn model_info(
        &self,
        obj_id: u32,
    ) -> PyResult<(f64, Vec<[f64; 16]>, Vec<([f64; 3], [f64; 3])>)> {
        let info = &self.object(obj_id)?.info;
        Ok((
            info.diameter,
            info.symmetries_discrete.clone(),
            info.symmetries_continuous
                .iter()
                .map(|s| (s.axis, s.offset))
                .collect(),
        ))
    }

    /// The depth image of a target image in mm (float32 bytes, row-major), width, height:
    /// the values VSD compares with.
    fn load_depth<'py>(
        &self,
        py: Python<'py>,
        scene_id: u32,
        im_id: u32,
    ) -> PyResult<(Bound<'py, PyBytes>, u32, u32)> {
        let depth = py
            .detach(|| self.inner.load_depth(scene_id, im_id))
            .map_err(|e| error(&e, String::new()))?;
        let bytes: Vec<u8> = depth.data.iter().flat_map(|d| d.to_ne_bytes()).collect();
        Ok((PyBytes::new(py, &bytes), depth.width, depth.height))
    }
}

impl PyDataset {
    fn object(&self, obj_id: u32) -> PyResult<&evaluator::dataset::Object> {
        self.inner.objects.get(&obj_id).ok_or_else(|| {
            PyValueError::new_err(format!("{} has no object {obj_id}", self.inner.name))
        })
    }
}

/// A dataset as `evaluate` and `check_results` take it: loaded already, or a folder to load.
#[derive(FromPyObject)]
pub enum DatasetArg {
    Loaded(Py<PyDataset>),
    Dir(PathBuf),
}

impl DatasetArg {
    fn into_source(self) -> DatasetSource {
        match self {
            DatasetArg::Loaded(d) => DatasetSource::Loaded(d.get().inner.clone()),
            DatasetArg::Dir(p) => DatasetSource::Dir(p),
        }
    }
}

/// [`DatasetArg`] without Python objects, to cross into the worker thread.
enum DatasetSource {
    Loaded(Arc<Dataset>),
    Dir(PathBuf),
}

impl DatasetSource {
    /// A folder is read with `targets_file`; a loaded dataset keeps the targets it was loaded
    /// with.
    fn load(self, targets_file: &str) -> Result<Arc<Dataset>, Failure> {
        match self {
            DatasetSource::Loaded(d) => Ok(d),
            DatasetSource::Dir(p) => {
                let options = DatasetOptions {
                    targets_file: targets_file.to_string(),
                    ..DatasetOptions::default()
                };
                Dataset::load_with(&p, &options)
                    .map(Arc::new)
                    .map_err(|e| Failure::Dataset(p, e))
            }
        }
    }
}

enum ResultsSource<'a> {
    File(PathBuf),
    /// The text [`results_csv`] made of rows.
    Rows(&'a [u8]),
}

/// Why an evaluation stopped, kept apart from `PyErr` so the worker never touches Python.
enum Failure {
    Dataset(PathBuf, Error),
    /// A result file (path) or rows (`None`) that do not parse.
    Results(Option<PathBuf>, Error),
    Evaluation(Error),
    Threads(String),
}

impl Failure {
    fn into_py(self, py: Python<'_>) -> PyErr {
        match self {
            Failure::Dataset(path, e) => dataset_error(&path, &e),
            Failure::Results(source, Error::Results(problems)) => {
                let what = match &source {
                    Some(path) => format!("{} is not a valid result file", path.display()),
                    None => "the result rows are not valid (row i is line i + 1)".to_string(),
                };
                let err = PyValueError::new_err(format!("{what}:\n{problems}"));
                let list: Vec<(u64, String)> = problems
                    .problems
                    .iter()
                    .map(|p| (p.line, p.to_string()))
                    .collect();
                // A failing setattr would only lose the structured copy of the message.
                let _ = err.value(py).setattr("problems", list);
                err
            }
            Failure::Results(_, e) => error(&e, String::new()),
            Failure::Evaluation(e) => error(&e, "evaluation failed: ".to_string()),
            Failure::Threads(message) => PyRuntimeError::new_err(message),
        }
    }
}

fn dataset_error(path: &Path, e: &Error) -> PyErr {
    let context = format!("cannot load the dataset in {}: ", path.display());
    // The loader explains a missing folder in words; to Python it is still a missing file.
    if !path.exists() {
        return PyFileNotFoundError::new_err(format!("{context}{e}"));
    }
    error(e, context)
}

/// The Python exception for an evaluator error: OSError (or its subclasses) for files that
/// cannot be read, ValueError for content or parameters that are wrong.
fn error(e: &Error, context: String) -> PyErr {
    let message = format!("{context}{e}");
    match e {
        Error::Io { source, .. } => match source.kind() {
            std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        Error::Cancelled => PyRuntimeError::new_err(message),
        _ => PyValueError::new_err(message),
    }
}

/// Evaluates and returns the report as `poseboard eval --out` writes it, and with
/// `with_errors` every evaluated estimate's errors as `--errors-out` writes them. `bop24`
/// reads a folder's `test_targets_bop24.json` and takes none of the localization options.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (
    dataset, protocol, *, results_path=None, results_csv=None, threads=None, progress=None,
    with_errors=false, prepared=None, unprepared=false, visib_mode=None, tau=None, tau_normalized=None, theta=None, delta=None,
    n_top=None, visib_gt_min=None, max_sym_disc_step=None, extra_errors=Vec::new(),
    ad_threshold=0.1, max_estimates_per_image=None,
))]
pub fn evaluate(
    py: Python<'_>,
    dataset: DatasetArg,
    protocol: &str,
    results_path: Option<PathBuf>,
    results_csv: Option<&[u8]>,
    threads: Option<usize>,
    progress: Option<Bound<'_, PyAny>>,
    with_errors: bool,
    prepared: Option<PathBuf>,
    unprepared: bool,
    visib_mode: Option<String>,
    tau: Option<Vec<f64>>,
    tau_normalized: Option<bool>,
    theta: Option<Vec<f64>>,
    delta: Option<f64>,
    n_top: Option<i64>,
    visib_gt_min: Option<f64>,
    max_sym_disc_step: Option<f64>,
    extra_errors: Vec<String>,
    ad_threshold: f64,
    max_estimates_per_image: Option<usize>,
) -> PyResult<(String, Option<String>)> {
    let overrides = Overrides {
        visib_mode,
        tau,
        tau_normalized,
        theta,
        delta,
        n_top,
        visib_gt_min,
        max_sym_disc_step,
        extra_errors,
        ad_threshold,
    };
    let task = if protocol == detection::PROTOCOL {
        if overrides.any() || with_errors {
            return Err(PyValueError::new_err(
                "bop24 has fixed errors and thresholds: the options of the localization \
                 protocols (tau, n_top, with_errors, ...) do not apply",
            ));
        }
        Task::Bop24(max_estimates_per_image)
    } else {
        if max_estimates_per_image.is_some() {
            return Err(PyValueError::new_err(
                "max_estimates_per_image is for protocol=\"bop24\" only",
            ));
        }
        Task::Localization(protocol::build(protocol, &overrides).map_err(PyValueError::new_err)?)
    };
    let targets_file = match task {
        Task::Bop24(_) => "test_targets_bop24.json".to_string(),
        Task::Localization(_) => DatasetOptions::default().targets_file,
    };
    let source = match (results_path, results_csv) {
        (Some(path), None) => ResultsSource::File(path),
        (None, Some(csv)) => ResultsSource::Rows(csv),
        _ => {
            return Err(PyValueError::new_err(
                "give exactly one of results_path and results_csv",
            ));
        }
    };
    let dataset = dataset.into_source();
    let outcome = run_detached(
        py,
        progress.as_ref(),
        |progress, cancel| -> Result<_, Failure> {
            let dataset = dataset.load(&targets_file)?;
            let results = match &source {
                ResultsSource::File(path) => {
                    results::load_results(path).map_err(|e| Failure::Results(Some(path.clone()), e))
                }
                ResultsSource::Rows(csv) => results::parse_results(*csv)
                    .map_err(|p| Failure::Results(None, Error::Results(p))),
            }?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.unwrap_or(0))
                .build()
                .map_err(|e| Failure::Threads(format!("cannot start the worker threads: {e}")))?;
            match &task {
                Task::Localization(protocol) => {
                    let mut notes = Vec::new();
                    let prepared = if unprepared {
                        None
                    } else {
                        pool.install(|| evaluator::prepared::find(&dataset, prepared.as_deref()))
                            .unwrap_or_else(|why| {
                                notes.push(format!(
                                    "{why}; `poseboard dataset prepare {}` rebuilds it",
                                    dataset.root.display()
                                ));
                                None
                            })
                    };
                    let evaluation = pool
                        .install(|| {
                            evaluator::evaluate_prepared(
                                &dataset,
                                &results,
                                protocol,
                                prepared.as_ref(),
                                progress,
                                cancel,
                            )
                        })
                        .map_err(Failure::Evaluation)?;
                    if let Some(prepared) = &prepared {
                        notes.extend(prepared.damaged().into_iter().map(|problem| {
                            format!(
                                "prepared file refused, its image computed from the dataset: {problem}"
                            )
                        }));
                    }
                    let report = serde_json::to_string_pretty(&evaluation.report)
                        .expect("a report serialises");
                    Ok((report, with_errors.then(|| errors_json(&evaluation)), notes))
                }
                Task::Bop24(cap) => {
                    let cap = cap.unwrap_or_else(|| {
                        detection::default_max_estimates_per_image(&dataset.name)
                    });
                    let report = pool
                        .install(|| detection::evaluate(&dataset, &results, cap, progress, cancel))
                        .map_err(Failure::Evaluation)?;
                    let report =
                        serde_json::to_string_pretty(&report).expect("a report serialises");
                    Ok((report, None, Vec::new()))
                }
            }
        },
    )?;
    let (report, errors, notes) = outcome.map_err(|f| f.into_py(py))?;
    // A prepared form that could not be used only made the evaluation slower: a warning.
    for note in notes {
        let message = std::ffi::CString::new(note.replace('\0', " ")).expect("no NUL left");
        PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
    }
    Ok((report, errors))
}

/// What `evaluate` runs: a localization protocol, or BOP'24 detection with its cap.
enum Task {
    Localization(evaluator::Protocol),
    Bop24(Option<usize>),
}

fn errors_json(evaluation: &Evaluation) -> String {
    serde_json::to_string_pretty(&evaluation.error_rows()).expect("errors serialise")
}

/// Validates a result file; with a dataset, also counts the targets it leaves without an
/// estimate and the estimates it would have ignored.
#[pyfunction]
#[pyo3(signature = (path, dataset=None))]
pub fn check_results<'py>(
    py: Python<'py>,
    path: PathBuf,
    dataset: Option<DatasetArg>,
) -> PyResult<Bound<'py, PyDict>> {
    let dataset = dataset.map(DatasetArg::into_source);
    let checked = py.detach(|| -> Result<_, Failure> {
        let results =
            results::load_results(&path).map_err(|e| Failure::Results(Some(path.clone()), e))?;
        let targets_file = DatasetOptions::default().targets_file;
        let dataset = dataset.map(|d| d.load(&targets_file)).transpose()?;
        Ok((results, dataset))
    });
    let (results, dataset) = checked.map_err(|f| f.into_py(py))?;

    let out = PyDict::new(py);
    let images: BTreeSet<(u32, u32)> = results
        .estimates
        .iter()
        .map(|e| (e.scene_id, e.im_id))
        .collect();
    out.set_item("estimates", results.estimates.len())?;
    out.set_item("images", images.len())?;
    if let Some(dataset) = dataset {
        let targets: HashSet<(u32, u32, u32)> = dataset
            .targets
            .iter()
            .map(|t| (t.scene_id, t.im_id, t.obj_id))
            .collect();
        let covered: HashSet<(u32, u32, u32)> = results
            .estimates
            .iter()
            .map(|e| (e.scene_id, e.im_id, e.obj_id))
            .collect();
        let ignored = results
            .estimates
            .iter()
            .filter(|e| !targets.contains(&(e.scene_id, e.im_id, e.obj_id)))
            .count();
        out.set_item("dataset", dataset.name.as_str())?;
        out.set_item("targets", targets.len())?;
        out.set_item(
            "targets_without_estimate",
            targets.difference(&covered).count(),
        )?;
        out.set_item("estimates_ignored", ignored)?;
    }
    Ok(out)
}

/// Result rows as the text of a result file without header, so that rows pass the very
/// checks (and name the same problems) as a file: row i becomes line i + 1. Ids are int64,
/// the rest float64, each column the native-endian bytes of a C-contiguous numpy array
/// (`r`: n x 9 row-major, `t`: n x 3). Floats are written in their shortest round-trip form.
#[pyfunction]
pub fn results_csv<'py>(
    py: Python<'py>,
    ids: &[u8],
    score: &[u8],
    r: &[u8],
    t: &[u8],
    time: &[u8],
) -> PyResult<Bound<'py, PyBytes>> {
    let n = score.len() / 8;
    if ids.len() != 24 * n || r.len() != 72 * n || t.len() != 24 * n || time.len() != 8 * n {
        return Err(PyValueError::new_err("result columns of different lengths"));
    }
    let word = |b: &[u8], i: usize| -> [u8; 8] { b[8 * i..8 * i + 8].try_into().expect("8 bytes") };
    let float = |b: &[u8], i: usize| f64::from_ne_bytes(word(b, i));
    let int = |i: usize| i64::from_ne_bytes(word(ids, i));
    let mut text = String::with_capacity(n * 200);
    for i in 0..n {
        use std::fmt::Write;
        let _ = write!(
            text,
            "{},{},{},{},",
            int(3 * i),
            int(3 * i + 1),
            int(3 * i + 2),
            float(score, i)
        );
        for j in 0..9 {
            let sep = if j < 8 { " " } else { "," };
            let _ = write!(text, "{}{sep}", float(r, 9 * i + j));
        }
        for j in 0..3 {
            let sep = if j < 2 { " " } else { "," };
            let _ = write!(text, "{}{sep}", float(t, 3 * i + j));
        }
        let _ = writeln!(text, "{}", float(time, i));
    }
    Ok(PyBytes::new(py, text.as_bytes()))
}

/// How long the calling thread waits between looks at Ctrl-C and progress: short enough to
/// feel immediate, long enough to cost nothing.
const POLL: Duration = Duration::from_millis(100);

/// Progress shared by the worker (which counts) and the calling thread (which reports).
#[derive(Default)]
struct Watch {
    total: AtomicU64,
    done: AtomicU64,
    events: Mutex<Events>,
    wake: Condvar,
}

#[derive(Clone, Copy, Default, PartialEq)]
struct Events {
    /// The total is known.
    started: bool,
    /// The work returned (or panicked).
    finished: bool,
}

impl Watch {
    fn signal(&self, f: impl FnOnce(&mut Events)) {
        f(&mut self.events.lock().unwrap_or_else(PoisonError::into_inner));
        self.wake.notify_all();
    }

    /// The events once they differ from `seen`, or after `POLL`.
    fn wait(&self, seen: Events) -> Events {
        let guard = self.events.lock().unwrap_or_else(PoisonError::into_inner);
        let (guard, _) = self
            .wake
            .wait_timeout_while(guard, POLL, |e| *e == seen)
            .unwrap_or_else(PoisonError::into_inner);
        *guard
    }
}

impl Progress for Watch {
    fn start(&self, total: u64) {
        self.total.store(total, Ordering::Relaxed);
        self.signal(|e| e.started = true);
    }

    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
}

/// Marks the work finished however it ends, so the calling thread never waits for a worker
/// that panicked.
struct Finish<'a>(&'a Watch);

impl Drop for Finish<'_> {
    fn drop(&mut self) {
        self.0.signal(|e| e.finished = true);
    }
}

/// Runs `work` on a new thread without the GIL. Meanwhile the calling thread calls
/// `callback(done, total)` whenever progress changed (and once at the end) and checks for
/// signals; an exception from either cancels the work and is raised once it has stopped.
fn run_detached<T: Send>(
    py: Python<'_>,
    callback: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&dyn Progress, &AtomicBool) -> T + Send,
) -> PyResult<T> {
    let watch = Watch::default();
    let cancel = AtomicBool::new(false);
    let mut pending: Option<PyErr> = None;
    let mut reported: Option<(u64, u64)> = None;
    let joined = std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let _finish = Finish(&watch);
            work(&watch, &cancel)
        });
        let mut seen = Events::default();
        loop {
            seen = py.detach(|| watch.wait(seen));
            if pending.is_none() {
                let step = py.check_signals().and_then(|()| match callback {
                    Some(cb) if seen.started => {
                        let now = (
                            watch.done.load(Ordering::Relaxed),
                            watch.total.load(Ordering::Relaxed),
                        );
                        if reported == Some(now) {
                            return Ok(());
                        }
                        reported = Some(now);
                        cb.call1(now).map(drop)
                    }
                    _ => Ok(()),
                });
                if let Err(e) = step {
                    pending = Some(e);
                    cancel.store(true, Ordering::Relaxed);
                }
            }
            if seen.finished {
                break;
            }
        }
        py.detach(|| worker.join())
    });
    let value = joined.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
    match pending {
        Some(e) => Err(e),
        None => Ok(value),
    }
}
