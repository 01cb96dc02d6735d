//! BOP'24 detections image by image. Their targets are images, not objects, and each estimate
//! is a true positive, a false positive or ignored at one error and threshold, so these views
//! stand beside the localization ones: a submission's target images with their counts, worst
//! first; one image's estimates, each with its verdict; two submissions side by side per image.
//! Each is one view, rendered as a page and as JSON. The verdicts are the evaluator's
//! (`evaluator::detection::verdicts`): the scores' own cap, errors and matching, run again on
//! the stored file, so the true positives are those the AP counted.

use std::collections::BTreeMap;

use evaluator::detection::verdicts::{
    self, Criterion, EstimateVerdict, ImageVerdicts, InstanceVerdict, Tally,
};
use evaluator::detection::{DetectionError, DetectionReport};
use serde::Serialize;

use super::{Choice, Named, ScorePair, field, number};
use crate::app::App;
use crate::error::{AppError, AppResult};
use crate::service::inspection;
use crate::store::submissions::SubmissionRow;

/// The reader's criterion from a [`Choice`]: `error` and `threshold` (a bop24 submission has
/// one protocol and no VSD, so `protocol` may only name it and `tau` does not apply).
fn criterion(choice: &Choice) -> AppResult<Criterion> {
    if let Some(p) = field(&choice.protocol)
        && p != evaluator::detection::PROTOCOL
    {
        return Err(AppError::BadRequest(format!(
            "a bop24 submission is scored under bop24 only, not `{p}`"
        )));
    }
    if field(&choice.tau).is_some() {
        return Err(AppError::BadRequest(
            "`tau` applies to VSD, which bop24 does not compute (its errors are mssd, mssd_mm \
             and mspd)"
                .to_string(),
        ));
    }
    Criterion::choose(
        field(&choice.error),
        number("threshold", &choice.threshold)?,
    )
    .map_err(AppError::BadRequest)
}

/// The criterion as shown, with what else the pages offer: every error, and the thresholds
/// of the chosen one.
#[derive(Clone, Debug, Serialize)]
pub struct Chosen {
    pub error: DetectionError,
    pub threshold: f64,
    pub description: String,
    /// The chosen error's thresholds (the only ones the scores count at).
    pub thresholds: Vec<f64>,
    pub unit: &'static str,
    #[serde(skip)]
    pub errors: Vec<DetectionError>,
}

impl Chosen {
    fn of(c: &Criterion) -> Chosen {
        Chosen {
            error: c.error,
            threshold: c.threshold,
            description: c.description(),
            thresholds: c.error.thresholds(),
            unit: verdicts::unit(c.error),
            errors: DetectionError::ALL.to_vec(),
        }
    }

    /// The query choosing another error, at its default threshold: the chosen threshold is
    /// in another unit.
    pub fn with_error(&self, error: &DetectionError) -> String {
        format!("error={}", error.name())
    }

    /// The query of this criterion at another threshold of its error.
    pub fn with_threshold(&self, threshold: &f64) -> String {
        format!(
            "error={}&threshold={}",
            self.error.name(),
            verdicts::short(*threshold)
        )
    }

    /// The query of this criterion.
    pub fn query(&self) -> String {
        self.with_threshold(&self.threshold)
    }

    /// A threshold as the links show it (`0.15`, not bop19's `0.15000000000000002`).
    pub fn label(&self, threshold: &f64) -> String {
        verdicts::short(*threshold)
    }
}

fn image_url(id: crate::domain::SubmissionId, scene: u32, im: u32, c: &Chosen) -> String {
    format!("/submissions/{id}/targets/{scene}/{im}?{}", c.query())
}

/// From the stored report: the mAP of the criterion's error (missing when nothing was counted),
/// and each object's AP at the criterion's threshold, shown beside the counts they come from.
fn report_aps(report: &DetectionReport, c: &Criterion) -> (Option<f64>, BTreeMap<u32, f64>) {
    let Some(scores) = report.errors.iter().find(|s| s.error == c.error) else {
        return (None, BTreeMap::new());
    };
    let at = scores.thresholds.iter().position(|&t| t == c.threshold);
    let objects = scores
        .objects
        .iter()
        .filter_map(|o| Some((o.obj_id, *o.ap_per_threshold.get(at?)?)))
        .collect();
    (Some(scores.map).filter(|m| m.is_finite()), objects)
}

/// Per object, the counts of its instances and estimates over `images`.
fn per_object(images: &[ImageVerdicts]) -> BTreeMap<u32, Tally> {
    let mut out: BTreeMap<u32, Tally> = BTreeMap::new();
    for image in images {
        for obj_id in image.objects() {
            out.entry(obj_id)
                .or_default()
                .add(image.object_tally(obj_id));
        }
    }
    out
}

// ---- the gallery ---------------------------------------------------------------------------

/// One object of a submission over every target image.
#[derive(Clone, Debug, Serialize)]
pub struct ObjectRow {
    pub obj_id: u32,
    #[serde(flatten)]
    pub tally: Tally,
    /// The report's AP of the object at the criterion (objects without a counted instance
    /// have none).
    pub ap: Option<f64>,
}

/// One target image of a submission.
#[derive(Clone, Debug, Serialize)]
pub struct ImageRow {
    pub scene_id: u32,
    pub im_id: u32,
    #[serde(flatten)]
    pub tally: Tally,
    pub url: String,
}

/// A bop24 submission's target images, worst first.
#[derive(Clone, Debug, Serialize)]
pub struct Bop24Gallery {
    pub submission: Named,
    pub task: &'static str,
    pub criterion: Chosen,
    /// The report's mAP under the criterion's error.
    pub map: Option<f64>,
    pub max_estimates_per_image: usize,
    /// Over every target image.
    pub totals: Tally,
    pub objects: Vec<ObjectRow>,
    /// How the images are ordered, in words.
    pub order: &'static str,
    pub images: Vec<ImageRow>,
}

pub const IMAGE_ORDER: &str = "the images with the most mistakes (counted instances missed plus \
    false positives) first, then the most missed, then by scene and image";

/// The target images of the bop24 submission `s` (checked visible and finished) at the
/// reader's criterion.
pub async fn gallery(app: &App, s: &SubmissionRow, choice: &Choice) -> AppResult<Bop24Gallery> {
    let c = criterion(choice)?;
    let report = inspection::bop24_report(app, s.id).await?;
    let images = inspection::bop24_verdicts(app, s, &report, c, None).await?;
    let chosen = Chosen::of(&c);
    let (map, aps) = report_aps(&report, &c);
    let mut totals = Tally::default();
    let mut rows: Vec<ImageRow> = images
        .iter()
        .map(|image| {
            let tally = image.tally();
            totals.add(tally);
            ImageRow {
                scene_id: image.scene_id,
                im_id: image.im_id,
                tally,
                url: image_url(s.id, image.scene_id, image.im_id, &chosen),
            }
        })
        .collect();
    rows.sort_by(|a, b| {
        (b.tally.mistakes(), b.tally.missed)
            .cmp(&(a.tally.mistakes(), a.tally.missed))
            .then((a.scene_id, a.im_id).cmp(&(b.scene_id, b.im_id)))
    });
    let objects = per_object(&images)
        .into_iter()
        .map(|(obj_id, tally)| ObjectRow {
            obj_id,
            tally,
            ap: aps.get(&obj_id).copied(),
        })
        .collect();
    Ok(Bop24Gallery {
        submission: Named::of(s),
        task: evaluator::detection::PROTOCOL,
        criterion: chosen,
        map,
        max_estimates_per_image: report.parameters.max_estimates_per_image,
        totals,
        objects,
        order: IMAGE_ORDER,
        images: rows,
    })
}

// ---- one image -----------------------------------------------------------------------------

/// One target image of a bop24 submission: every estimate with its verdict, and every
/// ground-truth instance with the estimate that took it.
#[derive(Clone, Debug, Serialize)]
pub struct Bop24Image {
    pub submission: Named,
    pub scene_id: u32,
    pub im_id: u32,
    pub criterion: Chosen,
    pub tally: Tally,
    pub instances: Vec<InstanceVerdict>,
    /// The kept estimates of its objects in the order the matching takes them (objects by
    /// their first instance, each in decreasing score), then those left out before matching.
    pub estimates: Vec<EstimateVerdict>,
    pub gallery_url: String,
}

/// Target image (scene, image) of the bop24 submission `s` (checked visible and finished).
pub async fn image(
    app: &App,
    s: &SubmissionRow,
    (scene_id, im_id): (u32, u32),
    choice: &Choice,
) -> AppResult<Bop24Image> {
    let c = criterion(choice)?;
    let report = inspection::bop24_report(app, s.id).await?;
    let image = inspection::bop24_verdicts(app, s, &report, c, Some((scene_id, im_id)))
        .await?
        .pop()
        .ok_or(AppError::NotFound)?;
    let chosen = Chosen::of(&c);
    Ok(Bop24Image {
        submission: Named::of(s),
        scene_id,
        im_id,
        tally: image.tally(),
        instances: image.instances,
        estimates: image.estimates,
        gallery_url: format!("/submissions/{}/targets?{}", s.id, chosen.query()),
        criterion: chosen,
    })
}

// ---- two submissions -----------------------------------------------------------------------

/// One target image of two submissions.
#[derive(Clone, Debug, Serialize)]
pub struct ImagePair {
    pub scene_id: u32,
    pub im_id: u32,
    pub a: Tally,
    pub b: Tally,
    pub a_url: String,
    pub b_url: String,
}

/// Two bop24 submissions on one dataset, side by side: their scores, and per target image
/// their counts at one criterion.
#[derive(Clone, Debug, Serialize)]
pub struct Bop24Comparison {
    pub dataset: String,
    pub a: Named,
    pub b: Named,
    pub task: &'static str,
    /// The mAPs, then the time per image.
    pub scores: Vec<ScorePair>,
    pub criterion: Chosen,
    pub a_total: Tally,
    pub b_total: Tally,
    /// Every target image, by scene and image.
    pub images: Vec<ImagePair>,
}

fn detection_scores(a: &DetectionReport, b: &DetectionReport) -> Vec<ScorePair> {
    let defined = |v: f64| Some(v).filter(|v| v.is_finite());
    let pair = |name, f: fn(&DetectionReport) -> f64| ScorePair {
        name,
        unit: "fraction",
        a: defined(f(a)),
        b: defined(f(b)),
    };
    vec![
        pair("bop24_mAP", |r| r.bop24_map),
        pair("bop24_mAP_mssd", |r| r.bop24_map_mssd),
        pair("bop24_mAP_mssd_mm", |r| r.bop24_map_mssd_mm),
        pair("bop24_mAP_mspd", |r| r.bop24_map_mspd),
        pair("bop25_mAP", |r| r.bop25_map),
        pair("bop25_mAP_mm", |r| r.bop25_map_mm),
        ScorePair {
            name: "Time per image",
            unit: "seconds",
            a: Some(a.bop24_average_time_per_image).filter(|t| *t >= 0.0),
            b: Some(b.bop24_average_time_per_image).filter(|t| *t >= 0.0),
        },
    ]
}

/// Compares the bop24 submissions `sa` and `sb` (both checked visible, finished and on one
/// dataset) at the reader's criterion.
pub async fn compare(
    app: &App,
    sa: &SubmissionRow,
    sb: &SubmissionRow,
    choice: &Choice,
) -> AppResult<Bop24Comparison> {
    let c = criterion(choice)?;
    let (ra, rb) = (
        inspection::bop24_report(app, sa.id).await?,
        inspection::bop24_report(app, sb.id).await?,
    );
    let va = inspection::bop24_verdicts(app, sa, &ra, c, None).await?;
    let vb = inspection::bop24_verdicts(app, sb, &rb, c, None).await?;
    let chosen = Chosen::of(&c);
    let tallies = |list: &[ImageVerdicts]| -> BTreeMap<(u32, u32), Tally> {
        list.iter()
            .map(|i| ((i.scene_id, i.im_id), i.tally()))
            .collect()
    };
    let (ta, tb) = (tallies(&va), tallies(&vb));
    let (mut a_total, mut b_total) = (Tally::default(), Tally::default());
    let images = ta
        .iter()
        .map(|(&(scene_id, im_id), &a)| {
            let b = tb.get(&(scene_id, im_id)).copied().unwrap_or_default();
            a_total.add(a);
            b_total.add(b);
            ImagePair {
                scene_id,
                im_id,
                a,
                b,
                a_url: image_url(sa.id, scene_id, im_id, &chosen),
                b_url: image_url(sb.id, scene_id, im_id, &chosen),
            }
        })
        .collect();
    Ok(Bop24Comparison {
        dataset: sa.dataset.clone(),
        a: Named::of(sa),
        b: Named::of(sb),
        task: evaluator::detection::PROTOCOL,
        scores: detection_scores(&ra, &rb),
        criterion: chosen,
        a_total,
        b_total,
        images,
    })
}
