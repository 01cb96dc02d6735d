//! Values that come from outside (forms, the API, the command line), parsed and checked once at
//! the edge. Past the edge, a `MethodName` or a `Visibility` is known to be valid, so the
//! services and the store never re-check or re-interpret strings. The server's `domain`
//! module adds the records' ids, which the database reads and writes.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use unicode_normalization::UnicodeNormalization;

/// The name of the demo dataset, which is also its folder name. Here rather than in `demo`
/// because the boards' rule for core datasets (a service) leaves it out once another is served.
pub const DEMO_DATASET: &str = "synthdemo";

/// The group of datasets a board ranks over when no other is asked for: the core datasets
/// (see `service::groups`).
pub const DEFAULT_GROUP: &str = "core";

/// A value that does not parse, with the field it came from.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("field `{field}` {problem}")]
pub struct FieldError {
    pub field: &'static str,
    pub problem: String,
}

impl FieldError {
    /// The problem as a sentence about the field ("the name must have ..."), for forms.
    pub fn problem_sentence(&self) -> String {
        format!("the {} {}", self.field.replace('_', " "), self.problem)
    }

    /// The same problem of a value sent in another field (an account's name sent as `user`).
    pub fn named(self, field: &'static str) -> FieldError {
        FieldError { field, ..self }
    }

    fn new(field: &'static str, problem: impl Into<String>) -> Self {
        FieldError {
            field,
            problem: problem.into(),
        }
    }
}

/// Characters that change how text reads without being seen: zero-width characters, bidi
/// controls and the byte-order mark. In a name they let two different names look the same.
fn is_invisible(c: char) -> bool {
    c.is_control()
        || matches!(c, '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2060}'..='\u{2064}' | '\u{2066}'..='\u{2069}' | '\u{FEFF}' | '\u{00AD}')
}

/// Text as it is compared and stored: trimmed, in Unicode normal form C. "é" can be typed as
/// one character or as "e" and a combining accent; both must name the same method or account,
/// so they are made one before any check, lookup or insert.
pub fn normalized(value: &str) -> String {
    value.trim().nfc().collect()
}

/// Trimmed text of 1 to `max` characters without control or invisible characters, in NFC.
fn plain_text(field: &'static str, value: &str, max: usize) -> Result<String, FieldError> {
    let value = normalized(value);
    if value.is_empty() {
        return Err(FieldError::new(field, "is required"));
    }
    if value.chars().count() > max || value.chars().any(is_invisible) {
        return Err(FieldError::new(
            field,
            format!("must be at most {max} characters, without control or invisible characters"),
        ));
    }
    Ok(value)
}

macro_rules! text_newtype {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
        #[serde(transparent)]
        pub struct $name(String);

        impl $name {
            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
    };
}

text_newtype!(
    /// The name of a method, unique per account: 1 to 100 visible characters.
    MethodName
);
text_newtype!(
    /// An account name: 1 to 40 letters, digits, `-`, `_` or `.` (it appears in URLs and logs).
    UserName
);
text_newtype!(
    /// The name of a team: 1 to 40 letters, digits, `-`, `_` or `.`, as an account's (it is
    /// shown as the owner of the team's methods and appears in URLs).
    TeamName
);
text_newtype!(
    /// The label of an API token, so its owner can tell tokens apart: 1 to 100 characters.
    TokenLabel
);
text_newtype!(
    /// Where the reported times were measured: at most 200 characters, possibly empty.
    #[derive(Default)]
    Hardware
);
text_newtype!(
    /// A link to a paper or code: an `http(s)://` URL, or empty.
    #[derive(Default)]
    Link
);
text_newtype!(
    /// What a submitter says about the method: at most 10,000 characters, possibly empty.
    #[derive(Default)]
    Description
);
text_newtype!(
    /// A short free-text answer about a method (its authors, its refinement, the detections
    /// it uses): at most 1,000 characters, possibly empty.
    #[derive(Default)]
    Note
);

text_newtype!(
    /// The name of a group of datasets: 1 to 60 ASCII letters, digits, `-`, `_` or `.` (it is
    /// written in board URLs as `?group=NAME`).
    GroupName
);
text_newtype!(
    /// A dataset as a group names it: its folder name, served here or not, 1 to 100 visible
    /// characters without `/`, `\`, `,` or a leading `.`.
    DatasetName
);

impl GroupName {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let name = value.trim();
        if name.is_empty()
            || name.len() > 60
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        {
            return Err(FieldError::new(
                "name",
                "must have 1 to 60 letters, digits, `-`, `_` or `.`",
            ));
        }
        Ok(GroupName(name.to_string()))
    }
}

impl DatasetName {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let name = plain_text("datasets", value, 100)?;
        if name.starts_with('.') || name.contains(['/', '\\', ',']) {
            return Err(FieldError::new(
                "datasets",
                format!("names folders: `{name}` is not a folder name"),
            ));
        }
        Ok(DatasetName(name))
    }
}

impl MethodName {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        plain_text("method", value, 100).map(MethodName)
    }
}

impl UserName {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let name = normalized(value);
        if name.is_empty() || name.chars().count() > 40 {
            return Err(FieldError::new("name", "must have 1 to 40 characters"));
        }
        if !name
            .chars()
            .all(|c| c.is_alphanumeric() && !is_invisible(c) || "-_.".contains(c))
        {
            return Err(FieldError::new(
                "name",
                "may contain letters, digits, `-`, `_` and `.`",
            ));
        }
        Ok(UserName(name))
    }
}

impl TeamName {
    /// The name given in `field` (`name` when a team is created, `team` with an upload).
    pub fn parse(field: &'static str, value: &str) -> Result<Self, FieldError> {
        UserName::parse(value)
            .map(|n| TeamName(n.0))
            .map_err(|e| e.named(field))
    }
}

impl TokenLabel {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        plain_text("name", value, 100).map(TokenLabel)
    }
}

impl Hardware {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        if value.trim().is_empty() {
            return Ok(Hardware(String::new()));
        }
        plain_text("hardware", value, 200).map(Hardware)
    }
}

impl Link {
    pub fn parse(field: &'static str, value: &str) -> Result<Self, FieldError> {
        let value = value.trim();
        if value.is_empty() {
            return Ok(Link(String::new()));
        }
        let url = plain_text(field, value, 2000)?;
        if !(url.starts_with("https://") || url.starts_with("http://")) || url.contains(' ') {
            return Err(FieldError::new(field, "must be an http(s) link"));
        }
        Ok(Link(url))
    }
}

impl Description {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let value = normalized(value);
        if value.chars().count() > 10_000 {
            return Err(FieldError::new(
                "description",
                "must be at most 10000 characters",
            ));
        }
        Ok(Description(value))
    }
}

impl Note {
    pub fn parse(field: &'static str, value: &str) -> Result<Self, FieldError> {
        if value.trim().is_empty() {
            return Ok(Note(String::new()));
        }
        plain_text(field, value, 1000).map(Note)
    }
}

/// The year a method was published: empty, or a year from 1900 to 2100.
pub fn year(value: &str) -> Result<Option<i64>, FieldError> {
    let value = value.trim();
    if value.is_empty() {
        return Ok(None);
    }
    match value.parse::<i64>() {
        Ok(y) if (1900..=2100).contains(&y) => Ok(Some(y)),
        _ => Err(FieldError::new("year", "must be a year from 1900 to 2100")),
    }
}

/// A password as typed: 10 to 1024 characters. Never printed, not even in debug output.
#[derive(Clone)]
pub struct Password(String);

impl Password {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let n = value.chars().count();
        if !(10..=1024).contains(&n) {
            return Err(FieldError::new(
                "password",
                "must have 10 to 1024 characters",
            ));
        }
        Ok(Password(value.to_string()))
    }

    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Password {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Password(..)")
    }
}

/// Enumerations written as lowercase words in forms, the API and the database.
macro_rules! word_enum {
    ($(#[$doc:meta])* $name:ident, $field:literal { $($variant:ident = $word:literal),+ $(,)? }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
        pub enum $name {
            $(#[serde(rename = $word)] $variant),+
        }

        impl $name {
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$variant => $word),+
                }
            }
        }

        impl FromStr for $name {
            type Err = FieldError;
            fn from_str(s: &str) -> Result<Self, FieldError> {
                match s {
                    $($word => Ok($name::$variant),)+
                    _ => Err(FieldError::new(
                        $field,
                        format!("must be one of {}", [$($word),+].join(", ")),
                    )),
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

mod challenge;

pub use challenge::{Award, ChallengeForm, ChallengeName, ChallengeSlug, ChallengeSpec};

word_enum!(
    /// Who may see a submission: everyone (and the leaderboards), or its owner and the admins.
    Visibility, "visibility" { Public = "public", Private = "private" }
);
word_enum!(
    /// The training images of a method, as the BOP site asks.
    TrainingData, "training_data" { Synthetic = "synthetic", Real = "real", Both = "both" }
);
word_enum!(
    /// The input a method uses, as the BOP site asks.
    Modality, "modality" { Rgb = "rgb", Depth = "depth", RgbD = "rgb-d" }
);

word_enum!(
    /// How a method onboards the test objects, as the BOP site's boards tell apart: from
    /// their 3D models, or from reference images without a model.
    Onboarding, "onboarding" { ModelBased = "model-based", ModelFree = "model-free" }
);
word_enum!(
    /// Whether a method was trained on images of the test objects (`seen`) or onboards them
    /// only at test time (`unseen`), as the BOP site's boards tell apart.
    Objects, "objects" { Seen = "seen", Unseen = "unseen" }
);

word_enum!(
    /// Whether a method uses one model for all objects or one per object, as the BOP site asks.
    ModelScope, "model_scope" { All = "all", PerObject = "per-object" }
);

word_enum!(
    /// A BOP'22 2D task, as uploads name it and its board is keyed: detection (boxes, against
    /// the amodal ground-truth boxes, as the BOP site ranks it) or segmentation (masks).
    CocoProtocol, "protocol" { Detection = "bop22-det", Segmentation = "bop22-seg" }
);

impl CocoProtocol {
    /// What the evaluator scores for it.
    pub fn task(self) -> evaluator::coco::CocoTask {
        match self {
            CocoProtocol::Detection => {
                evaluator::coco::CocoTask::Detection(evaluator::coco::BboxType::Amodal)
            }
            CocoProtocol::Segmentation => evaluator::coco::CocoTask::Segmentation,
        }
    }
}

/// What a submission is scored for instead of the 6D localization protocols (bop19, eccv18): a
/// BOP'22 2D task, or BOP'24 6D detection. Each has its own result format, scores table and
/// board, so a submission holds one task alone. Written as its name (`bop22-det`, `bop22-seg`,
/// `bop24`) in uploads, the `protocols` column and JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Task {
    Coco(CocoProtocol),
    /// 6D detection: BOP'19 CSV files scored by average precision on the dataset's
    /// `test_targets_bop24.json` (`evaluator::detection`).
    Bop24,
}

impl Task {
    pub fn as_str(self) -> &'static str {
        match self {
            Task::Coco(t) => t.as_str(),
            Task::Bop24 => evaluator::detection::PROTOCOL,
        }
    }

    /// The 2D task, if it is one.
    pub fn coco(self) -> Option<CocoProtocol> {
        match self {
            Task::Coco(t) => Some(t),
            Task::Bop24 => None,
        }
    }

    /// Its board.
    pub fn board(self) -> BoardProtocol {
        match self {
            Task::Coco(t) => BoardProtocol::Coco(t),
            Task::Bop24 => BoardProtocol::Bop24,
        }
    }
}

impl FromStr for Task {
    type Err = FieldError;

    fn from_str(s: &str) -> Result<Self, FieldError> {
        match s {
            evaluator::detection::PROTOCOL => Ok(Task::Bop24),
            other => other.parse().map(Task::Coco),
        }
    }
}

impl Serialize for Task {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl fmt::Display for Task {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A task an upload can be scored for: the value of the upload's `protocol` field (the form's
/// and the API's), and what it means. The one list the upload form offers and the errors name,
/// so that a task added here is offered wherever a task is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UploadTask {
    /// The `protocol` field's value; empty: the default.
    pub value: &'static str,
    /// What it scores, for the form.
    pub label: &'static str,
}

impl UploadTask {
    pub const ALL: &'static [UploadTask] = &[
        UploadTask {
            value: "",
            label: "6D poses: bop19, scored under eccv18 as well (the default)",
        },
        UploadTask {
            value: "bop19",
            label: "6D poses: bop19 only, the BOP Challenge average recall",
        },
        UploadTask {
            value: "eccv18",
            label: "6D poses: eccv18 only, the ECCV'18 paper's VSD recall",
        },
        UploadTask {
            value: "bop19,eccv18",
            label: "6D poses: both, with each one's warnings (eccv18 considers one estimate per target)",
        },
        UploadTask {
            value: "bop24",
            label: "6D detection: bop24, the BOP Challenge's main task since 2024, scored by average precision (BOP'19 CSV)",
        },
        UploadTask {
            value: "bop22-det",
            label: "2D detection: bop22-det, boxes scored by AP (BOP'22 COCO JSON)",
        },
        UploadTask {
            value: "bop22-seg",
            label: "2D segmentation: bop22-seg, masks scored by AP (BOP'22 COCO JSON)",
        },
    ];

    /// The values, for a message: "bop19, eccv18, bop19,eccv18, bop24, bop22-det or bop22-seg".
    pub fn values() -> String {
        let named: Vec<&str> = UploadTask::ALL
            .iter()
            .map(|t| t.value)
            .filter(|v| !v.is_empty())
            .collect();
        match named.split_last() {
            Some((last, [])) => (*last).to_string(),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
            None => String::new(),
        }
    }
}

/// A kind of result file an upload takes, told apart by its name's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileKind {
    /// ".csv"
    pub extension: &'static str,
    /// Its media type, for the form's file chooser.
    pub media_type: &'static str,
    /// What it holds and is for.
    pub purpose: &'static str,
}

impl FileKind {
    pub const ALL: &'static [FileKind] = &[
        FileKind {
            extension: ".csv",
            media_type: "text/csv",
            purpose: "BOP'19 6D pose results, one file per dataset named METHOD_DATASET-test.csv: \
                      scene_id,im_id,obj_id,score,R,t,time with R row-major (9 numbers), t in mm \
                      and the time of the whole image in seconds",
        },
        FileKind {
            extension: ".json",
            media_type: "application/json",
            purpose: "BOP'22 2D detections or segmentations (COCO format), one file per dataset \
                      named METHOD_DATASET-test.json: a list of {scene_id, image_id, category_id, \
                      score, bbox, segmentation, time}; the task is read from the content unless \
                      chosen above",
        },
        FileKind {
            extension: ".zip",
            media_type: "application/zip",
            purpose: "several .csv files at once, e.g. for the seven core datasets: one \
                      submission per file (an archive holds .csv files only)",
        },
    ];

    /// The form's `accept` attribute: every extension and media type.
    pub fn accept() -> String {
        FileKind::ALL
            .iter()
            .flat_map(|k| [k.extension, k.media_type])
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// What a leaderboard ranks: a 6D protocol's scores, BOP'24 6D detection's mAP or a 2D task's
/// AP. Written as its name (`bop19`, `eccv18`, `bop24`, `bop22-det`, `bop22-seg`) in URLs and
/// JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum BoardProtocol {
    Pose(evaluator::protocol::ProtocolName),
    Bop24,
    Coco(CocoProtocol),
}

impl BoardProtocol {
    /// Every board, in the order the pages list them.
    pub const ALL: [BoardProtocol; 5] = [
        BoardProtocol::Pose(evaluator::protocol::ProtocolName::Bop19),
        BoardProtocol::Pose(evaluator::protocol::ProtocolName::Eccv18),
        BoardProtocol::Bop24,
        BoardProtocol::Coco(CocoProtocol::Detection),
        BoardProtocol::Coco(CocoProtocol::Segmentation),
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            BoardProtocol::Pose(p) => p.as_str(),
            BoardProtocol::Bop24 => Task::Bop24.as_str(),
            BoardProtocol::Coco(t) => t.as_str(),
        }
    }

    /// The board named `name`, if there is one.
    pub fn named(name: &str) -> Option<BoardProtocol> {
        BoardProtocol::ALL.into_iter().find(|b| b.as_str() == name)
    }
}

impl Serialize for BoardProtocol {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

/// As stored (a snapshot's boards) and named in URLs.
impl FromStr for BoardProtocol {
    type Err = ();

    fn from_str(name: &str) -> Result<Self, ()> {
        BoardProtocol::named(name).ok_or(())
    }
}

impl From<evaluator::protocol::ProtocolName> for BoardProtocol {
    fn from(p: evaluator::protocol::ProtocolName) -> Self {
        BoardProtocol::Pose(p)
    }
}

/// A method's details as its owner states them on the method page or through the API. Each
/// field is the text sent; a field left out (`None`) keeps its stored value, an empty one
/// clears it.
#[derive(Clone, Debug, Default, Deserialize)]
pub struct MethodForm {
    pub description: Option<String>,
    pub authors: Option<String>,
    #[serde(default, deserialize_with = "text_or_number")]
    pub year: Option<String>,
    pub paper_url: Option<String>,
    pub code_url: Option<String>,
    pub training_data: Option<String>,
    pub detection_modality: Option<String>,
    pub modality: Option<String>,
    pub refinement: Option<String>,
    pub detections: Option<String>,
    pub model_scope: Option<String>,
    pub hardware: Option<String>,
    pub onboarding: Option<String>,
    pub objects: Option<String>,
    /// `true`: under double-blind review (see [`MethodDetails::anonymous`]).
    #[serde(default, deserialize_with = "text_or_flag")]
    pub anonymous: Option<String>,
}

/// A flag sent as a JSON boolean or as text (forms send text, and a flattened form cannot
/// deserialize a boolean).
/// The method page's edit form: the details with the CSRF token of the browser form.
#[derive(Debug, Deserialize)]
pub struct MethodEditForm {
    #[serde(default)]
    pub csrf: String,
    #[serde(flatten)]
    pub fields: MethodForm,
}

fn text_or_flag<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Flag {
        Text(String),
        Bool(bool),
    }
    Ok(Option::<Flag>::deserialize(d)?.map(|f| match f {
        Flag::Text(t) => t,
        Flag::Bool(b) => b.to_string(),
    }))
}

/// A yes-or-no field sent as text: `true` or `false` (empty is `false`), nothing else.
pub fn flag(field: &'static str, value: &str) -> Result<bool, FieldError> {
    match value.trim() {
        "true" => Ok(true),
        "false" | "" => Ok(false),
        other => Err(FieldError::new(
            field,
            format!("is true or false, not `{other}`"),
        )),
    }
}

/// A year sent as a JSON number or as text (forms send text).
fn text_or_number<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Year {
        Text(String),
        Number(i64),
    }
    Ok(Option::<Year>::deserialize(d)?.map(|y| match y {
        Year::Text(t) => t,
        Year::Number(n) => n.to_string(),
    }))
}

/// A method's details, every field checked.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MethodDetails {
    pub description: Description,
    pub authors: Note,
    pub year: Option<i64>,
    pub paper_url: Link,
    pub code_url: Link,
    pub training_data: Option<TrainingData>,
    /// The input of the detection stage.
    pub detection_modality: Option<Modality>,
    /// The input of the pose stage.
    pub modality: Option<Modality>,
    pub refinement: Note,
    pub detections: Note,
    pub model_scope: Option<ModelScope>,
    pub hardware: Hardware,
    /// Under double-blind review: everyone but its owner and the administrators is shown
    /// "anonymous" instead of the owner, and no authors, paper or code links.
    pub anonymous: bool,
    pub onboarding: Option<Onboarding>,
    pub objects: Option<Objects>,
}

impl MethodForm {
    /// Checks every field sent; those left out are taken from `stored` (the method's
    /// current details, as text).
    pub fn parse(self, stored: MethodForm) -> Result<MethodDetails, FieldError> {
        let text = |sent: Option<String>, kept: Option<String>| sent.or(kept).unwrap_or_default();
        Ok(MethodDetails {
            description: Description::parse(&text(self.description, stored.description))?,
            authors: Note::parse("authors", &text(self.authors, stored.authors))?,
            year: year(&text(self.year, stored.year))?,
            paper_url: Link::parse("paper_url", &text(self.paper_url, stored.paper_url))?,
            code_url: Link::parse("code_url", &text(self.code_url, stored.code_url))?,
            training_data: optional(&text(self.training_data, stored.training_data))?,
            detection_modality: optional(&text(self.detection_modality, stored.detection_modality))
                .map_err(|e: FieldError| FieldError::new("detection_modality", e.problem))?,
            modality: optional(&text(self.modality, stored.modality))?,
            refinement: Note::parse("refinement", &text(self.refinement, stored.refinement))?,
            detections: Note::parse("detections", &text(self.detections, stored.detections))?,
            model_scope: optional(&text(self.model_scope, stored.model_scope))?,
            hardware: Hardware::parse(&text(self.hardware, stored.hardware))?,
            anonymous: flag("anonymous", &text(self.anonymous, stored.anonymous))?,
            onboarding: optional(&text(self.onboarding, stored.onboarding))?,
            objects: optional(&text(self.objects, stored.objects))?,
        })
    }
}

/// An optional enumerated field: empty means not given.
pub fn optional<T: FromStr<Err = FieldError>>(value: &str) -> Result<Option<T>, FieldError> {
    let value = value.trim().to_lowercase();
    if value.is_empty() {
        Ok(None)
    } else {
        value.parse().map(Some)
    }
}

/// A page of a paged list (`?page=N`), from 1. Bounded, so that no offset overflows and no
/// reader asks the database to skip more rows than a list will ever hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PageNumber(u32);

impl PageNumber {
    pub const FIRST: PageNumber = PageNumber(1);
    const LAST: u32 = 100_000;

    pub fn parse(value: &str) -> Result<PageNumber, FieldError> {
        match value.trim().parse::<u32>() {
            Ok(n) if (1..=Self::LAST).contains(&n) => Ok(PageNumber(n)),
            _ => Err(FieldError::new(
                "page",
                format!("is a page number from 1 to {}, not `{value}`", Self::LAST),
            )),
        }
    }

    pub fn get(self) -> u32 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_refuse_invisible_and_control_characters() {
        assert_eq!(
            MethodName::parse("  CosyPose ").unwrap().as_str(),
            "CosyPose"
        );
        assert!(MethodName::parse("").is_err());
        assert!(MethodName::parse("a\u{200B}b").is_err());
        assert!(MethodName::parse("a\u{202E}b").is_err());
        assert!(MethodName::parse("a\nb").is_err());
        assert!(MethodName::parse(&"x".repeat(101)).is_err());
        assert!(UserName::parse("alice.b-2_x").is_ok());
        assert!(UserName::parse("alice b").is_err());
        assert!(UserName::parse("al\u{200D}ice").is_err());
        assert!(UserName::parse(&"a".repeat(41)).is_err());
    }

    #[test]
    fn names_are_compared_in_normal_form_c() {
        let (composed, decomposed) = ("Caf\u{e9}", "Cafe\u{301}");
        assert_eq!(
            MethodName::parse(decomposed).unwrap(),
            MethodName::parse(composed).unwrap()
        );
        assert_eq!(MethodName::parse(decomposed).unwrap().as_str(), composed);
        // A combining accent alone is no letter, but the account name it composes is valid.
        assert_eq!(
            UserName::parse("Jose\u{301}").unwrap(),
            UserName::parse("Jos\u{e9}").unwrap()
        );
        assert_eq!(
            TokenLabel::parse(" cafe\u{301} laptop ").unwrap().as_str(),
            "caf\u{e9} laptop"
        );
        assert_eq!(Hardware::parse(decomposed).unwrap().as_str(), composed);
        assert_eq!(Description::parse(decomposed).unwrap().as_str(), composed);
        // Lengths count the stored characters: 100 accented letters typed decomposed fit.
        assert!(MethodName::parse(&"e\u{301}".repeat(100)).is_ok());
        assert_eq!(normalized(" A\u{30a} "), "\u{c5}");
    }

    #[test]
    fn enumerations_are_strict() {
        assert_eq!("public".parse::<Visibility>(), Ok(Visibility::Public));
        assert!("Public".parse::<Visibility>().is_err());
        assert!("yes".parse::<Visibility>().is_err());
        assert_eq!(optional::<Modality>(" RGB-D "), Ok(Some(Modality::RgbD)));
        assert_eq!(optional::<TrainingData>(""), Ok(None));
        let e = optional::<TrainingData>("imagenet").unwrap_err();
        assert_eq!(
            e.to_string(),
            "field `training_data` must be one of synthetic, real, both"
        );
    }

    #[test]
    fn flags_and_pages_are_strict() {
        assert_eq!(flag("anonymous", " true "), Ok(true));
        assert_eq!(flag("anonymous", ""), Ok(false));
        assert_eq!(
            flag("anonymous", "yes").unwrap_err().to_string(),
            "field `anonymous` is true or false, not `yes`"
        );
        assert_eq!(PageNumber::parse("2").map(PageNumber::get), Ok(2));
        for bad in ["0", "-1", "x", "", "100001", "99999999999"] {
            assert!(PageNumber::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn method_details_keep_what_is_not_sent() {
        let stored = MethodForm {
            authors: Some("A. Author".into()),
            year: Some("2020".into()),
            hardware: Some("a GPU".into()),
            ..MethodForm::default()
        };
        let sent = MethodForm {
            year: Some("".into()),
            model_scope: Some("per-object".into()),
            ..MethodForm::default()
        };
        let details = sent.parse(stored.clone()).unwrap();
        assert_eq!(details.authors.as_str(), "A. Author");
        assert_eq!(details.year, None);
        assert_eq!(details.model_scope, Some(ModelScope::PerObject));
        assert_eq!(details.hardware.as_str(), "a GPU");
        for (bad, field) in [
            (
                MethodForm {
                    year: Some("20x0".into()),
                    ..MethodForm::default()
                },
                "year",
            ),
            (
                MethodForm {
                    year: Some("1492".into()),
                    ..MethodForm::default()
                },
                "year",
            ),
            (
                MethodForm {
                    model_scope: Some("some".into()),
                    ..MethodForm::default()
                },
                "model_scope",
            ),
            (
                MethodForm {
                    detection_modality: Some("lidar".into()),
                    ..MethodForm::default()
                },
                "detection_modality",
            ),
            (
                MethodForm {
                    refinement: Some("x".repeat(1001)),
                    ..MethodForm::default()
                },
                "refinement",
            ),
        ] {
            assert_eq!(bad.parse(stored.clone()).unwrap_err().field, field);
        }
    }

    #[test]
    fn links_and_passwords() {
        assert!(Link::parse("paper_url", "https://arxiv.org/abs/1808.08319").is_ok());
        assert!(Link::parse("paper_url", "javascript:alert(1)").is_err());
        assert_eq!(Link::parse("code_url", " ").unwrap().as_str(), "");
        assert!(Password::parse("short").is_err());
        assert_eq!(
            format!("{:?}", Password::parse("a long secret").unwrap()),
            "Password(..)"
        );
    }
}
