//! Single targets of submissions: two submissions on one dataset compared target by target, the
//! estimates of one target with their errors, and a submission's worst targets per object. Each
//! is one view, rendered as a page and as JSON. The verdicts are the evaluator's outcomes
//! (`evaluator::outcomes`) made from the per-estimate errors stored with the scores, so they are
//! the verdicts the scores count; the errors are read and matched on the evaluation threads.
//! BOP'24 detections, whose targets are images, have their own views in [`bop24`].

pub mod bop24;

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::{CocoReport, ImageOutcome};
use evaluator::matching::EstimateErrors;
use evaluator::outcomes::{Criterion, TargetOutcome, outcomes};
use evaluator::protocol::{ErrorKind, Protocol, ProtocolName, columns, normalised_error};
use serde::{Deserialize, Serialize};

use crate::app::App;
use crate::domain::{CocoProtocol, MethodId, SubmissionId, Task};
use crate::error::{AppError, AppResult};
use crate::service::inspection;
use crate::store::submissions::SubmissionRow;
use crate::web::auth::Viewer;
use crate::web::views::urlencode;

/// How many of each object's worst targets the gallery shows.
pub const WORST_PER_OBJECT: usize = 8;

/// What a reader chose, as a form sends it (an empty field is unset): the protocol whose
/// outcomes are shown, and when a target counts as correct (see `evaluator::outcomes`).
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
pub struct Choice {
    pub protocol: Option<String>,
    pub error: Option<String>,
    pub tau: Option<String>,
    pub threshold: Option<String>,
}

fn field(v: &Option<String>) -> Option<&str> {
    v.as_deref().map(str::trim).filter(|s| !s.is_empty())
}

fn number(name: &str, v: &Option<String>) -> AppResult<Option<f64>> {
    field(v)
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| AppError::BadRequest(format!("`{name}` must be a number, not `{s}`")))
        })
        .transpose()
}

impl Choice {
    /// The protocol asked for among those `available`; by default the paper's (eccv18, whose
    /// single threshold makes the verdicts plain), else the first.
    fn protocol(&self, available: &[ProtocolName]) -> AppResult<ProtocolName> {
        let list = || {
            available
                .iter()
                .map(|p| p.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        match field(&self.protocol) {
            Some(p) => {
                let name: ProtocolName = p.parse().map_err(AppError::BadRequest)?;
                if available.contains(&name) {
                    Ok(name)
                } else {
                    Err(AppError::BadRequest(format!(
                        "no scores under {p} to show (available: {})",
                        list()
                    )))
                }
            }
            None if available.contains(&ProtocolName::Eccv18) => Ok(ProtocolName::Eccv18),
            None => available.first().copied().ok_or_else(|| {
                AppError::BadRequest("no protocol with scores in common".to_string())
            }),
        }
    }

    fn criterion(&self, protocol: &Protocol) -> AppResult<Criterion> {
        Criterion::choose(
            protocol,
            field(&self.error),
            number("tau", &self.tau)?,
            number("threshold", &self.threshold)?,
        )
        .map_err(AppError::BadRequest)
    }

    /// This choice as a query string (for the links between the pages), without the leading
    /// `?` and with a trailing `&` when not empty.
    pub fn query(&self) -> String {
        [
            ("protocol", &self.protocol),
            ("error", &self.error),
            ("tau", &self.tau),
            ("threshold", &self.threshold),
        ]
        .iter()
        .filter_map(|(k, v)| field(v).map(|v| format!("{k}={}&", urlencode(v))))
        .collect()
    }
}

/// A submission as these views name it.
#[derive(Clone, Debug, Serialize)]
pub struct Named {
    pub id: SubmissionId,
    pub method_id: MethodId,
    pub method: String,
    pub file_name: String,
    pub dataset: String,
}

impl Named {
    fn of(s: &SubmissionRow) -> Named {
        Named {
            id: s.id,
            method_id: s.method_id,
            method: s.method.clone(),
            file_name: s.file_name.clone(),
            dataset: s.dataset.clone(),
        }
    }
}

/// The link to the page of one target, keeping the reader's choice.
pub fn target_url(id: SubmissionId, scene: u32, im: u32, obj: u32, choice: &Choice) -> String {
    let q = choice.query();
    let q = q.trim_end_matches('&');
    let q = if q.is_empty() {
        String::new()
    } else {
        format!("?{q}")
    };
    format!("/submissions/{id}/targets/{scene}/{im}/{obj}{q}")
}

/// The overlay of one target: the test image with the ground-truth and estimated silhouettes.
pub fn image_url(id: SubmissionId, scene: u32, im: u32, obj: u32) -> String {
    format!("/api/v1/submissions/{id}/targets/{scene}/{im}/{obj}.png")
}

// ---- comparing two submissions -------------------------------------------------------------

/// The query of a comparison: the two submissions and the reader's choice (see [`Choice`]).
#[derive(Clone, Debug, Default, Deserialize)]
pub struct CompareQuery {
    pub a: Option<String>,
    pub b: Option<String>,
    pub protocol: Option<String>,
    pub error: Option<String>,
    pub tau: Option<String>,
    pub threshold: Option<String>,
}

impl CompareQuery {
    fn choice(&self) -> Choice {
        Choice {
            protocol: self.protocol.clone(),
            error: self.error.clone(),
            tau: self.tau.clone(),
            threshold: self.threshold.clone(),
        }
    }
}

/// One score of both submissions.
#[derive(Clone, Debug, Serialize)]
pub struct ScorePair {
    pub name: &'static str,
    /// `recall` or `fraction` (both shown in percent), or `seconds`.
    pub unit: &'static str,
    pub a: Option<f64>,
    pub b: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ObjectPair {
    pub obj_id: u32,
    pub a: Option<f64>,
    pub b: Option<f64>,
}

/// One bin of the recall-vs-visibility curve (ECCV'18) of both submissions.
#[derive(Clone, Debug, Serialize)]
pub struct VisibPair {
    pub visib_from: f64,
    pub visib_to: f64,
    pub a_instances: usize,
    pub a: f64,
    pub b_instances: usize,
    pub b: f64,
}

/// The scores of both submissions under one protocol, from their reports.
#[derive(Clone, Debug, Serialize)]
pub struct ProtocolScores {
    pub protocol: ProtocolName,
    /// The headline first, then its parts and the time.
    pub scores: Vec<ScorePair>,
    /// Per object: recall (eccv18) or average recall (bop19).
    pub objects: Vec<ObjectPair>,
    /// Per visibility bin (eccv18 only).
    pub visibility: Vec<VisibPair>,
}

fn protocol_scores(protocol: ProtocolName, a: &Report, b: &Report) -> ProtocolScores {
    let pair = |name, unit, f: &dyn Fn(&Report) -> Option<f64>| ScorePair {
        name,
        unit,
        a: f(a),
        b: f(b),
    };
    let objects = |f: &dyn Fn(&Report) -> BTreeMap<u32, f64>| {
        let (fa, fb) = (f(a), f(b));
        let mut ids: Vec<u32> = fa.keys().chain(fb.keys()).copied().collect();
        ids.sort_unstable();
        ids.dedup();
        ids.into_iter()
            .map(|obj_id| ObjectPair {
                obj_id,
                a: fa.get(&obj_id).copied(),
                b: fb.get(&obj_id).copied(),
            })
            .collect()
    };
    match protocol {
        ProtocolName::Eccv18 => ProtocolScores {
            protocol,
            scores: vec![
                pair("Recall", "recall", &|r| {
                    r.localization.as_ref().map(|l| l.recall)
                }),
                pair("Mean object recall", "recall", &|r| {
                    r.localization.as_ref().map(|l| l.mean_obj_recall)
                }),
                pair("Mean scene recall", "recall", &|r| {
                    r.localization.as_ref().map(|l| l.mean_scene_recall)
                }),
                pair("Time per target", "seconds", &|r| r.average_time_per_target),
            ],
            objects: objects(&|r| {
                r.localization
                    .as_ref()
                    .map(|l| l.obj_recalls.clone())
                    .unwrap_or_default()
            }),
            visibility: a
                .recall_vs_visib
                .iter()
                .zip(&b.recall_vs_visib)
                .map(|(x, y)| VisibPair {
                    visib_from: x.visib_from,
                    visib_to: x.visib_to,
                    a_instances: x.instances,
                    a: x.recall,
                    b_instances: y.instances,
                    b: y.recall,
                })
                .collect(),
        },
        ProtocolName::Bop19 => ProtocolScores {
            protocol,
            scores: vec![
                pair("AR", "recall", &|r| r.bop19_average_recall),
                pair("AR_VSD", "recall", &|r| r.bop19_average_recall_vsd),
                pair("AR_MSSD", "recall", &|r| r.bop19_average_recall_mssd),
                pair("AR_MSPD", "recall", &|r| r.bop19_average_recall_mspd),
                pair("Time per image", "seconds", &|r| {
                    r.bop19_average_time_per_image
                }),
            ],
            objects: objects(&|r| r.obj_average_recalls.clone()),
            visibility: Vec::new(),
        },
    }
}

/// Target instances counted by the recall, paired between the two submissions.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PairedCounts {
    /// Instances the recall counts (the same for both: they depend on the dataset only).
    pub instances: usize,
    pub both: usize,
    pub only_a: usize,
    pub only_b: usize,
    pub neither: usize,
}

/// One side of a target in a comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Side {
    /// Of the target's counted instances, how many this submission found (matched correctly).
    pub found: usize,
    /// The lowest error among them: the matched estimate's, or the near miss's (see
    /// `TargetOutcome::error`); `None` without a finite one.
    pub error: Option<f64>,
    pub url: String,
}

/// A target (scene, image, object) that one submission found more of than the other.
#[derive(Clone, Debug, Serialize)]
pub struct TargetPair {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    /// Its instances the recall counts.
    pub instances: usize,
    pub a: Side,
    pub b: Side,
}

/// Two submissions on one dataset, side by side.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub dataset: String,
    pub a: Named,
    pub b: Named,
    /// Per protocol both were scored under, their scores.
    pub scores: Vec<ProtocolScores>,
    /// The protocol whose outcomes are paired, and when an instance counts as correct.
    pub protocol: ProtocolName,
    pub protocols: Vec<ProtocolName>,
    pub criterion: Criterion,
    /// Paired per target: of its n counted instances a found k_a and b found k_b, so
    /// min(k_a, k_b) count as found by both, the excess of either as found by it only, and the
    /// rest as by neither (which instance an estimate is matched to is the matching's choice,
    /// not a property of the target). `both + only_a` is a's true positives.
    pub counts: PairedCounts,
    /// Every target where one found more instances than the other, by scene, image, object.
    pub targets: Vec<TargetPair>,
    #[serde(skip)]
    pub choice: Choice,
}

/// A target: (scene, image, object).
type TargetKey = (u32, u32, u32);

/// Of a target: its counted instances, the found ones, the lowest error.
type Tally = (usize, usize, Option<f64>);

fn per_target(list: &[TargetOutcome]) -> BTreeMap<TargetKey, Tally> {
    let mut out: BTreeMap<TargetKey, Tally> = BTreeMap::new();
    for o in list {
        let t = out.entry((o.scene_id, o.im_id, o.obj_id)).or_default();
        t.0 += 1;
        t.1 += usize::from(o.correct);
        t.2 = match (t.2, o.error) {
            (Some(x), Some(y)) => Some(x.min(y)),
            (x, y) => x.or(y),
        };
    }
    out
}

fn pair(
    a: &[TargetOutcome],
    b: &[TargetOutcome],
    ids: (SubmissionId, SubmissionId),
    choice: &Choice,
) -> (PairedCounts, Vec<TargetPair>) {
    let (ta, tb) = (per_target(a), per_target(b));
    let mut keys: Vec<TargetKey> = ta.keys().chain(tb.keys()).copied().collect();
    keys.sort_unstable();
    keys.dedup();
    let mut counts = PairedCounts::default();
    let mut targets = Vec::new();
    for key @ (scene_id, im_id, obj_id) in keys {
        let (na, fa, ea) = ta.get(&key).copied().unwrap_or_default();
        let (nb, fb, eb) = tb.get(&key).copied().unwrap_or_default();
        let n = na.max(nb);
        counts.instances += n;
        counts.both += fa.min(fb);
        counts.only_a += fa.saturating_sub(fb);
        counts.only_b += fb.saturating_sub(fa);
        counts.neither += n - fa.max(fb);
        if fa != fb {
            let side = |id, found, error| Side {
                found,
                error,
                url: target_url(id, scene_id, im_id, obj_id, choice),
            };
            targets.push(TargetPair {
                scene_id,
                im_id,
                obj_id,
                instances: n,
                a: side(ids.0, fa, ea),
                b: side(ids.1, fb, eb),
            });
        }
    }
    (counts, targets)
}

/// Two submissions compared: 6D ones target by target, 2D ones and BOP'24 detections image by
/// image.
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub enum Compared {
    Pose(Box<Comparison>),
    Coco(Box<CocoComparison>),
    Bop24(Box<bop24::Bop24Comparison>),
}

/// What COCOeval counts of one submission at IoU 0.5 in an image and category (or summed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MatchCounts {
    pub matched: usize,
    pub missed: usize,
    pub false_positives: usize,
}

impl MatchCounts {
    fn of(o: &ImageOutcome) -> MatchCounts {
        MatchCounts {
            matched: o.matched,
            missed: o.missed(),
            false_positives: o.false_positives,
        }
    }

    fn add(&mut self, c: MatchCounts) {
        self.matched += c.matched;
        self.missed += c.missed;
        self.false_positives += c.false_positives;
    }
}

/// An image and category where two 2D submissions differ.
#[derive(Clone, Debug, Serialize)]
pub struct ImagePair {
    pub scene_id: u32,
    pub im_id: u32,
    pub category_id: i64,
    /// Its ground-truth instances that count (not ignored).
    pub instances: usize,
    pub a: MatchCounts,
    pub b: MatchCounts,
}

/// Two 2D submissions of one task on one dataset, side by side: their stored AP/AR numbers,
/// and what COCOeval counts image by image and category at IoU 0.5 (the counts behind AP50).
#[derive(Clone, Debug, Serialize)]
pub struct CocoComparison {
    pub dataset: String,
    pub a: Named,
    pub b: Named,
    pub task: CocoProtocol,
    /// AP first, then the other eleven numbers and the time per image.
    pub scores: Vec<ScorePair>,
    /// Ground-truth instances that count, over every target image.
    pub instances: usize,
    /// Summed over the images and categories.
    pub a_total: MatchCounts,
    pub b_total: MatchCounts,
    /// Every image and category where they differ, in the dataset's image order.
    pub images: Vec<ImagePair>,
}

/// The images and categories of two submissions' outcomes (each in the same image order,
/// listing the images and categories with ground truth or detections), paired.
fn pair_images(
    a: &[ImageOutcome],
    b: &[ImageOutcome],
) -> (usize, MatchCounts, MatchCounts, Vec<ImagePair>) {
    type Key = (u32, u32, i64);
    let by_key = |list: &[ImageOutcome]| -> BTreeMap<Key, ImageOutcome> {
        list.iter()
            .map(|o| ((o.scene_id, o.im_id, o.category_id), o.clone()))
            .collect()
    };
    let (ma, mb) = (by_key(a), by_key(b));
    let (mut ta, mut tb) = (MatchCounts::default(), MatchCounts::default());
    let mut instances = 0;
    let mut images = Vec::new();
    // The image order of `a` then any key of `b` alone (an image only b detected in).
    let mut keys: Vec<Key> = a
        .iter()
        .map(|o| (o.scene_id, o.im_id, o.category_id))
        .collect();
    keys.extend(
        b.iter()
            .map(|o| (o.scene_id, o.im_id, o.category_id))
            .filter(|k| !ma.contains_key(k)),
    );
    for key @ (scene_id, im_id, category_id) in keys {
        let (oa, ob) = (ma.get(&key), mb.get(&key));
        let n = oa.or(ob).map_or(0, |o| o.instances);
        instances += n;
        // A submission without the image and category detected nothing there.
        let counts = |o: Option<&ImageOutcome>| {
            o.map_or(
                MatchCounts {
                    missed: n,
                    ..MatchCounts::default()
                },
                MatchCounts::of,
            )
        };
        let (ca, cb) = (counts(oa), counts(ob));
        ta.add(ca);
        tb.add(cb);
        if ca != cb {
            images.push(ImagePair {
                scene_id,
                im_id,
                category_id,
                instances: n,
                a: ca,
                b: cb,
            });
        }
    }
    (instances, ta, tb, images)
}

/// The AP/AR numbers of two 2D reports side by side (undefined ones, COCOeval's -1, absent).
fn coco_scores(a: &CocoReport, b: &CocoReport) -> Vec<ScorePair> {
    let defined = |v: f64| (v >= 0.0).then_some(v);
    let mut scores: Vec<ScorePair> = a
        .stats()
        .iter()
        .zip(b.stats())
        .map(|((name, x), (_, y))| ScorePair {
            name,
            unit: "fraction",
            a: defined(*x),
            b: defined(y),
        })
        .collect();
    scores.push(ScorePair {
        name: "Time per image",
        unit: "seconds",
        a: defined(a.average_time_per_image),
        b: defined(b.average_time_per_image),
    });
    scores
}

/// Compares 2D submissions `sa` and `sb` of `task` (both checked visible and finished).
async fn compare_coco(
    app: &App,
    sa: &SubmissionRow,
    sb: &SubmissionRow,
    task: CocoProtocol,
) -> AppResult<CocoComparison> {
    let (ra, rb) = (
        inspection::coco_report(app, sa.id).await?,
        inspection::coco_report(app, sb.id).await?,
    );
    let oa = inspection::coco_outcomes(app, sa, task).await?;
    let ob = inspection::coco_outcomes(app, sb, task).await?;
    let (instances, a_total, b_total, images) = pair_images(&oa, &ob);
    Ok(CocoComparison {
        dataset: sa.dataset.clone(),
        a: Named::of(sa),
        b: Named::of(sb),
        task,
        scores: coco_scores(&ra, &rb),
        instances,
        a_total,
        b_total,
        images,
    })
}

/// Compares submissions `a` and `b`, both visible to `viewer`, finished, on one dataset and
/// scored alike: 6D ones target by target, 2D ones of one task and BOP'24 detections image by
/// image.
pub async fn compare(app: &App, q: &CompareQuery, viewer: &Viewer) -> AppResult<Compared> {
    let id = |name: &str, v: &Option<String>| -> AppResult<SubmissionId> {
        let s = field(v).ok_or_else(|| {
            AppError::BadRequest(format!("`{name}` (a submission id) is required"))
        })?;
        s.parse()
            .map_err(|_| AppError::BadRequest(format!("`{name}` must be a submission id")))
    };
    let (ia, ib) = (id("a", &q.a)?, id("b", &q.b)?);
    let choice = q.choice();
    let sa = inspection::finished(app, ia, viewer.user.as_ref()).await?;
    let sb = inspection::finished(app, ib, viewer.user.as_ref()).await?;
    if sa.dataset_id != sb.dataset_id {
        return Err(AppError::BadRequest(format!(
            "submission {ia} is on {} and submission {ib} on {}: only submissions on the same \
             dataset compare",
            sa.dataset, sb.dataset
        )));
    }
    match (sa.task, sb.task) {
        (Some(Task::Coco(ta)), Some(Task::Coco(tb))) if ta == tb => {
            return Ok(Compared::Coco(Box::new(
                compare_coco(app, &sa, &sb, ta).await?,
            )));
        }
        (Some(Task::Bop24), Some(Task::Bop24)) => {
            return Ok(Compared::Bop24(Box::new(
                bop24::compare(app, &sa, &sb, &choice).await?,
            )));
        }
        (None, None) => {}
        _ => {
            let scored = |s: &SubmissionRow| match s.task {
                Some(t) => t.as_str().to_string(),
                None => s
                    .protocols
                    .iter()
                    .map(|p| p.as_str())
                    .collect::<Vec<_>>()
                    .join(" and "),
            };
            return Err(AppError::BadRequest(format!(
                "submission {ia} is scored under {} and submission {ib} under {}: only \
                 submissions with a protocol in common compare (the page of submission {ia} \
                 offers those)",
                scored(&sa),
                scored(&sb)
            )));
        }
    }
    let reports_a = inspection::reports(app, ia).await?;
    let reports_b = inspection::reports(app, ib).await?;
    let protocols: Vec<ProtocolName> = reports_a
        .keys()
        .filter(|p| reports_b.contains_key(p))
        .copied()
        .collect();
    let name = choice.protocol(&protocols)?;
    let protocol = Protocol::named(name);
    let criterion = choice.criterion(&protocol)?;
    let scores = protocols
        .iter()
        .map(|p| protocol_scores(*p, &reports_a[p], &reports_b[p]))
        .collect();

    let (ea, eb) = (
        inspection::stored_errors(app, &sa, name).await?,
        inspection::stored_errors(app, &sb, name).await?,
    );
    let dataset = inspection::dataset_of(app, &sa).await?;
    let (c, p) = (criterion.clone(), protocol.clone());
    let (oa, ob) = app
        .on_pool("matching stored errors", move || {
            let a = outcomes(&dataset, &p, &ea.estimates(&p)?, &c);
            let b = outcomes(&dataset, &p, &eb.estimates(&p)?, &c);
            Ok((a, b))
        })
        .await?;
    let (counts, targets) = pair(&oa, &ob, (ia, ib), &choice);
    Ok(Compared::Pose(Box::new(Comparison {
        dataset: sa.dataset.clone(),
        a: Named::of(&sa),
        b: Named::of(&sb),
        scores,
        protocol: name,
        protocols,
        criterion,
        counts,
        targets,
        choice,
    })))
}

/// The submissions a submission's page offers to compare with: finished, on its dataset,
/// visible to the viewer.
pub async fn comparable(app: &App, s: &SubmissionRow, viewer: &Viewer) -> AppResult<Vec<Named>> {
    Ok(inspection::comparable(app, s, viewer.user.as_ref())
        .await?
        .iter()
        .map(Named::of)
        .collect())
}

/// Submission `s` (visible to the reader and finished) if it has targets of objects in images:
/// a 2D submission has none (its detections are scored per image and category), and a BOP'24
/// detection's targets are whole images, so asking for them answers where its evidence is
/// instead.
fn with_targets(s: SubmissionRow) -> AppResult<SubmissionRow> {
    let id = s.id;
    match s.task {
        None => Ok(s),
        Some(Task::Bop24) => Err(AppError::NotHere {
            message: format!(
                "submission {id} is a bop24 (6D detection) submission: its targets are whole \
                 images, each at /submissions/{id}/targets/SCENE/IMAGE with every estimate's \
                 verdict, not objects in images"
            ),
            links: vec![
                (
                    format!("Submission {id}: its target images"),
                    format!("/submissions/{id}/targets"),
                ),
                (
                    "The bop24 board".to_string(),
                    format!("/leaderboards/bop24?dataset={}", urlencode(&s.dataset)),
                ),
            ],
        }),
        Some(task) => Err(AppError::NotHere {
            message: format!(
                "submission {id} is a {} (2D) submission: it has no 6D targets; its detections \
                 are scored per image and category, which its page shows and a comparison with \
                 another {} submission lays out image by image",
                task.as_str(),
                task.as_str()
            ),
            links: vec![
                (
                    format!("Submission {id}: its scores and curves"),
                    format!("/submissions/{id}"),
                ),
                (
                    format!("The {} board", task.as_str()),
                    format!(
                        "/leaderboards/{}?dataset={}",
                        task.as_str(),
                        urlencode(&s.dataset)
                    ),
                ),
            ],
        }),
    }
}

/// Target image (scene, image) of the BOP'24 detection `id`, visible to `viewer` and finished;
/// a submission of another kind has no whole images as targets, and answers where to look.
pub async fn image(
    app: &App,
    id: SubmissionId,
    at: (u32, u32),
    choice: &Choice,
    viewer: &Viewer,
) -> AppResult<bop24::Bop24Image> {
    let s = inspection::finished(app, id, viewer.user.as_ref()).await?;
    match s.task {
        Some(Task::Bop24) => bop24::image(app, &s, at, choice).await,
        None => Err(AppError::NotHere {
            message: format!(
                "submission {id} is a 6D localization submission: its targets are objects in \
                 images, each at /submissions/{id}/targets/SCENE/IMAGE/OBJECT"
            ),
            links: vec![(
                format!("Submission {id}: its worst targets"),
                format!("/submissions/{id}/targets"),
            )],
        }),
        // A 2D submission: why it has no targets.
        Some(_) => with_targets(s).and(Err(AppError::NotFound)),
    }
}

// ---- one target ----------------------------------------------------------------------------

/// An error column as shown: its name with its unit.
#[derive(Clone, Debug, Serialize)]
pub struct ColumnHead {
    /// bop_toolkit's error signature (the key in the stored errors).
    pub signature: String,
    pub label: String,
}

fn label(protocol: &Protocol, column: &evaluator::protocol::Column) -> String {
    match &protocol.errors[column.error].kind {
        ErrorKind::Vsd(p) => {
            let tau = column.tau.unwrap_or_default();
            if p.normalized_by_diameter {
                format!("VSD τ={tau:.2}·d")
            } else {
                format!("VSD τ={tau} mm")
            }
        }
        ErrorKind::Mspd => "MSPD (px at 640 wide)".to_string(),
        kind => format!("{} / diameter", kind.name().to_uppercase()),
    }
}

/// One estimate of the target against one ground-truth instance of its object.
#[derive(Clone, Debug, Serialize)]
pub struct Against {
    pub gt_id: u32,
    /// Per column, the normalised error (what the thresholds apply to); `None`: infinite.
    pub errors: Vec<Option<f64>>,
}

#[derive(Clone, Debug, Serialize)]
pub struct EstimateRow {
    pub est_id: u32,
    pub score: f64,
    pub against: Vec<Against>,
}

/// The verdicts on the target's counted instances at one criterion, and the instances of its
/// object in the image that the recall leaves out, each with why.
#[derive(Clone, Debug, Serialize)]
pub struct Verdicts {
    pub criterion: Criterion,
    pub outcomes: Vec<TargetOutcome>,
    pub not_counted: Vec<NotCounted>,
}

/// An instance of the target's object in its image that the recall does not count.
#[derive(Clone, Debug, Serialize)]
pub struct NotCounted {
    pub gt_id: u32,
    pub visib_fract: f64,
    /// Why, in the protocol's terms ("under 10 % visible ...").
    pub reason: String,
}

/// The instances of object `obj_id` in `image` that are not among `counted` (gt ids), each with
/// why the protocol leaves it out: `valid_gts`' rule (under `visib_gt_min`, or beyond the
/// instance count the targets file gives, most visible first) or else n_top (the recall counts
/// at most that many of the valid instances, matched and more visible first).
fn not_counted(
    image: &evaluator::dataset::Image,
    image_targets: &[(u32, u32)],
    protocol: &Protocol,
    obj_id: u32,
    counted: &[u32],
) -> Vec<NotCounted> {
    let valid = evaluator::matching::valid_gts(image, image_targets, protocol.visib_gt_min);
    let listed = image_targets
        .iter()
        .find(|t| t.0 == obj_id)
        .map_or(0, |t| t.1);
    image
        .gt
        .iter()
        .enumerate()
        .filter(|(gt, g)| g.obj_id == obj_id && !counted.contains(&(*gt as u32)))
        .map(|(gt, g)| {
            let visible = format!("{:.1} % visible", g.visib_fract * 100.0);
            let reason = if valid[gt] {
                format!(
                    "{visible}, but the protocol's n_top ({}) counts fewer instances of the \
                     object per image: the matched and the more visible ones first",
                    protocol.n_top.as_i64()
                )
            } else if protocol.visib_gt_min >= 0.0 {
                format!(
                    "{visible}: under the protocol's minimum visibility (visib_gt_min) of {} %",
                    protocol.visib_gt_min * 100.0
                )
            } else {
                format!(
                    "{visible}: the targets file counts {} of the object in this image, the \
                     most visible first (BOP lists the instances at least 10 % visible)",
                    crate::wording::count(listed, "instance", "instances")
                )
            };
            NotCounted {
                gt_id: gt as u32,
                visib_fract: g.visib_fract,
                reason,
            }
        })
        .collect()
}

/// One target of a submission: its estimates with their errors, and which counted as correct.
#[derive(Clone, Debug, Serialize)]
pub struct TargetView {
    pub submission: Named,
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    pub protocol: ProtocolName,
    pub protocols: Vec<ProtocolName>,
    pub columns: Vec<ColumnHead>,
    /// The evaluated estimates of the object in the image, in decreasing score order (the
    /// order the matching takes them in).
    pub estimates: Vec<EstimateRow>,
    /// The reader's criterion first (by default the protocol's), then each other error of the
    /// protocol at its default.
    pub verdicts: Vec<Verdicts>,
    pub image_url: String,
    pub gallery_url: String,
    #[serde(skip)]
    pub choice: Choice,
}

fn protocols_of(s: &SubmissionRow) -> Vec<ProtocolName> {
    let mut p = s.protocols.clone();
    p.sort();
    p
}

/// Target (scene, image, object) of submission `id`.
pub async fn target(
    app: &App,
    id: SubmissionId,
    (scene_id, im_id, obj_id): (u32, u32, u32),
    choice: &Choice,
    viewer: &Viewer,
) -> AppResult<TargetView> {
    let s = with_targets(inspection::finished(app, id, viewer.user.as_ref()).await?)?;
    let protocols = protocols_of(&s);
    let name = choice.protocol(&protocols)?;
    let protocol = Protocol::named(name);
    let mut criteria = vec![choice.criterion(&protocol)?];
    for spec in &protocol.errors {
        let c = Criterion::choose(&protocol, Some(spec.kind.name()), None, None)
            .map_err(AppError::Internal)?;
        if !criteria.iter().any(|k| k.column == c.column) {
            criteria.push(c);
        }
    }
    let dataset = inspection::dataset_of(app, &s).await?;
    if !dataset
        .targets
        .iter()
        .any(|t| (t.scene_id, t.im_id, t.obj_id) == (scene_id, im_id, obj_id))
    {
        return Err(AppError::NotFound);
    }
    let job = inspection::stored_errors(app, &s, name).await?;
    let p = protocol.clone();
    let (estimates, verdicts) = app
        .on_pool("matching stored errors", move || {
            let all = job.estimates(&p)?;
            let image = dataset
                .scenes
                .get(&scene_id)
                .and_then(|sc| sc.images.get(&im_id));
            // The image's targets, once each, in the targets file's order (as `outcomes`).
            let mut image_targets: Vec<(u32, u32)> = Vec::new();
            for t in &dataset.targets {
                if (t.scene_id, t.im_id) == (scene_id, im_id)
                    && !image_targets.iter().any(|x| x.0 == t.obj_id)
                {
                    image_targets.push((t.obj_id, t.inst_count));
                }
            }
            let verdicts = criteria
                .into_iter()
                .map(|criterion| {
                    let outcomes: Vec<TargetOutcome> = outcomes(&dataset, &p, &all, &criterion)
                        .into_iter()
                        .filter(|o| (o.scene_id, o.im_id, o.obj_id) == (scene_id, im_id, obj_id))
                        .collect();
                    let counted: Vec<u32> = outcomes.iter().map(|o| o.gt_id).collect();
                    Verdicts {
                        criterion,
                        outcomes,
                        not_counted: image.map_or_else(Vec::new, |image| {
                            not_counted(image, &image_targets, &p, obj_id, &counted)
                        }),
                    }
                })
                .collect();
            let cols = columns(&p);
            let mut mine: Vec<&EstimateErrors> = all
                .iter()
                .filter(|e| (e.scene_id, e.im_id, e.obj_id) == (scene_id, im_id, obj_id))
                .collect();
            mine.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.est_id.cmp(&b.est_id)));
            let estimates = mine
                .into_iter()
                .map(|e| EstimateRow {
                    est_id: e.est_id,
                    score: e.score,
                    against: e
                        .gt_ids
                        .iter()
                        .enumerate()
                        .map(|(i, &gt_id)| Against {
                            gt_id,
                            errors: cols
                                .iter()
                                .enumerate()
                                .map(|(c, col)| {
                                    let kind = &p.errors[col.error].kind;
                                    Some(normalised_error(&dataset, kind, e, e.errors[c][i]))
                                        .filter(|v| v.is_finite())
                                })
                                .collect(),
                        })
                        .collect(),
                })
                .collect();
            Ok((estimates, verdicts))
        })
        .await?;
    Ok(TargetView {
        submission: Named::of(&s),
        scene_id,
        im_id,
        obj_id,
        protocol: name,
        protocols,
        columns: columns(&protocol)
            .iter()
            .map(|c| ColumnHead {
                signature: c.signature.clone(),
                label: label(&protocol, c),
            })
            .collect(),
        estimates,
        verdicts,
        image_url: image_url(id, scene_id, im_id, obj_id),
        gallery_url: format!("/submissions/{id}/targets?{}", choice.query())
            .trim_end_matches(['?', '&'])
            .to_string(),
        choice: choice.clone(),
    })
}

// ---- the worst targets -----------------------------------------------------------------------

/// One of an object's worst targets.
#[derive(Clone, Debug, Serialize)]
pub struct Worst {
    #[serde(flatten)]
    pub outcome: TargetOutcome,
    pub url: String,
    pub image_url: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct ObjectWorst {
    pub obj_id: u32,
    /// Counted instances of the object, and how many are correct.
    pub instances: usize,
    pub correct: usize,
    /// At most [`WORST_PER_OBJECT`], worst first.
    pub worst: Vec<Worst>,
}

/// A submission's worst targets per object.
#[derive(Clone, Debug, Serialize)]
pub struct Gallery {
    pub submission: Named,
    pub protocol: ProtocolName,
    pub protocols: Vec<ProtocolName>,
    pub criterion: Criterion,
    /// How the targets are ordered, in words.
    pub order: &'static str,
    pub objects: Vec<ObjectWorst>,
    #[serde(skip)]
    pub choice: Choice,
}

/// Worst first: missed before correct; among the missed, those without any estimate, then by
/// decreasing error (an infinite error, a far-off estimate, before any finite one); among the
/// correct, by decreasing error; ties by scene, image and gt id.
fn worst_first(a: &TargetOutcome, b: &TargetOutcome) -> std::cmp::Ordering {
    let rank = |o: &TargetOutcome| {
        let error = match (o.estimates, o.error) {
            (0, _) => f64::INFINITY,
            (_, Some(e)) => e,
            (_, None) => f64::MAX,
        };
        (o.correct, -error)
    };
    let (ra, rb) = (rank(a), rank(b));
    ra.0.cmp(&rb.0)
        .then(ra.1.total_cmp(&rb.1))
        .then((a.scene_id, a.im_id, a.gt_id).cmp(&(b.scene_id, b.im_id, b.gt_id)))
}

pub const WORST_ORDER: &str = "missed targets first (those without any estimate, then by \
    decreasing error of the nearest estimate), then correct ones by decreasing error";

/// A submission's targets: the worst per object of a 6D localization, the images of a BOP'24
/// detection.
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub enum Galleries {
    Pose(Box<Gallery>),
    Bop24(Box<bop24::Bop24Gallery>),
}

/// The targets of submission `id` visible to `viewer` and finished: the worst of each object,
/// or for a BOP'24 detection its target images, worst first.
pub async fn gallery(
    app: &App,
    id: SubmissionId,
    choice: &Choice,
    viewer: &Viewer,
) -> AppResult<Galleries> {
    let s = inspection::finished(app, id, viewer.user.as_ref()).await?;
    if s.task == Some(Task::Bop24) {
        return Ok(Galleries::Bop24(Box::new(
            bop24::gallery(app, &s, choice).await?,
        )));
    }
    worst(app, with_targets(s)?, choice)
        .await
        .map(|g| Galleries::Pose(Box::new(g)))
}

/// The worst targets of each object of the 6D localization `s`.
async fn worst(app: &App, s: SubmissionRow, choice: &Choice) -> AppResult<Gallery> {
    let id = s.id;
    let protocols = protocols_of(&s);
    let name = choice.protocol(&protocols)?;
    let protocol = Protocol::named(name);
    let criterion = choice.criterion(&protocol)?;
    let dataset = inspection::dataset_of(app, &s).await?;
    let job = inspection::stored_errors(app, &s, name).await?;
    let (p, c) = (protocol.clone(), criterion.clone());
    let list = app
        .on_pool("matching stored errors", move || {
            Ok(outcomes(&dataset, &p, &job.estimates(&p)?, &c))
        })
        .await?;
    let mut per_obj: BTreeMap<u32, Vec<TargetOutcome>> = BTreeMap::new();
    for o in list {
        per_obj.entry(o.obj_id).or_default().push(o);
    }
    let objects = per_obj
        .into_iter()
        .map(|(obj_id, mut list)| {
            let correct = list.iter().filter(|o| o.correct).count();
            let instances = list.len();
            list.sort_by(worst_first);
            list.truncate(WORST_PER_OBJECT);
            ObjectWorst {
                obj_id,
                instances,
                correct,
                worst: list
                    .into_iter()
                    .map(|o| Worst {
                        url: target_url(id, o.scene_id, o.im_id, o.obj_id, choice),
                        image_url: image_url(id, o.scene_id, o.im_id, o.obj_id),
                        outcome: o,
                    })
                    .collect(),
            }
        })
        .collect();
    Ok(Gallery {
        submission: Named::of(&s),
        protocol: name,
        protocols,
        criterion,
        order: WORST_ORDER,
        objects,
        choice: choice.clone(),
    })
}
