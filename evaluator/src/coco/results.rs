//! Reading a BOP'22 detection or segmentation result file, `METHOD_DATASET-test.json`: one JSON
//! list of `{scene_id, image_id, category_id, score, bbox, segmentation, time}`.
//!
//! What bop_toolkit's `check_coco_results` accepts is accepted (integer ids, an integer or
//! float score, an optional time that is the same within 0.001 s for all entries of an image,
//! RLE counts in either form), and what it lets through but cannot score is refused: a box
//! that is not four numbers with a non-negative size, RLE counts that do not add up to the
//! mask's pixels (pycocotools then overruns the mask or loops forever), negative ids. Every
//! problem names the entry (counted from 0, as `results[i]` in Python) and the key, and all
//! of them are reported, not only the first.
//!
//! Which keys a task needs is checked separately ([`CocoResults::require`]), so that one file
//! can be checked once and scored for detection and for segmentation.

use std::collections::HashMap;
use std::fmt;
use std::io::Read;
use std::path::Path;

use serde::de::{DeserializeSeed, SeqAccess, Visitor};
use serde_json::{Map, Value};

use super::CocoTask;
use super::gt::segmentation;
use super::problems::EntryProblems;
use super::rle::Rle;
use crate::error::Error;

/// bop_toolkit's tolerance on the times of one image (seconds).
const TIME_TOLERANCE: f64 = 0.001;

/// One entry of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct CocoEntry {
    pub scene_id: u32,
    pub image_id: u32,
    pub category_id: i64,
    pub score: f64,
    /// `[x, y, width, height]` in pixels.
    pub bbox: Option<[f64; 4]>,
    /// The visible part of the object.
    pub segmentation: Option<Rle>,
    /// Seconds for the whole image; `None` or negative: not given.
    pub time: Option<f64>,
}

/// Everything read from a valid file, entries in file order.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct CocoResults {
    pub entries: Vec<CocoEntry>,
}

impl CocoResults {
    /// Checks that every entry has what `task` scores: a box for detection, a mask for
    /// segmentation. For segmentation the boxes must be in every entry or in none, because the
    /// toolkit takes the detections' areas (which decide the area ranges) from the boxes when
    /// its first result has one, and fails when a later one has none.
    pub fn require(&self, task: CocoTask) -> Result<(), EntryProblems> {
        let mut problems = EntryProblems::default();
        match task {
            CocoTask::Detection(_) => {
                for (i, e) in self.entries.iter().enumerate() {
                    if e.bbox.is_none() {
                        problems.push(
                            Some(i),
                            Some("bbox"),
                            "missing: detection results need a box [x, y, width, height]".into(),
                        );
                    }
                }
            }
            CocoTask::Segmentation => {
                let first_has_box = self.entries.first().is_some_and(|e| e.bbox.is_some());
                for (i, e) in self.entries.iter().enumerate() {
                    if e.segmentation.is_none() {
                        problems.push(
                            Some(i),
                            Some("segmentation"),
                            "missing: segmentation results need an RLE mask".into(),
                        );
                    }
                    if e.bbox.is_some() != first_has_box {
                        problems.push(
                            Some(i),
                            Some("bbox"),
                            format!(
                                "{} while entry 0 {}: give a box in every entry or in none \
                                 (the toolkit takes the detections' areas from the boxes when \
                                 the first entry has one)",
                                if first_has_box { "missing" } else { "given" },
                                if first_has_box { "has one" } else { "has none" }
                            ),
                        );
                    }
                }
            }
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(problems)
        }
    }

    /// The mean over the file's images of the time given for the image, images in the order
    /// they first appear (numpy's summation order); `None` when some entry gives no time or a
    /// negative one ("not measured"), as bop_toolkit then writes -1.
    ///
    /// This is not what `eval_bop22_coco.py` computes when the file has entries for images that
    /// are not targets: it groups the times by (scene, image) only after its scene merge has
    /// shifted the image ids of the target entries in place, so a shifted id can collide with a
    /// non-target image's and its consistency check stops early, leaving the mean over a part
    /// of the images. The plain mean is what the 6D tasks report, and what the toolkit gives
    /// whenever no ids collide.
    pub fn average_time_per_image(&self) -> Option<f64> {
        let mut seen = HashMap::new();
        let mut times = Vec::new();
        for e in &self.entries {
            let t = e.time.filter(|t| *t >= 0.0)?;
            seen.entry((e.scene_id, e.image_id)).or_insert_with(|| {
                times.push(t);
            });
        }
        if times.is_empty() {
            return None;
        }
        Some(crate::stats::mean(&times))
    }

    /// The number of distinct images the file has entries for.
    pub fn image_count(&self) -> usize {
        let mut seen: Vec<(u32, u32)> = self
            .entries
            .iter()
            .map(|e| (e.scene_id, e.image_id))
            .collect();
        seen.sort_unstable();
        seen.dedup();
        seen.len()
    }
}

/// Reads a result file; all problems are collected.
pub fn parse_coco_results<R: Read>(reader: R) -> Result<CocoResults, EntryProblems> {
    let mut state = State::default();
    let mut de = serde_json::Deserializer::from_reader(std::io::BufReader::new(reader));
    let outcome = (&mut state).deserialize(&mut de).and_then(|()| de.end());
    if let Err(e) = outcome {
        let entry = (state.started && !state.finished).then_some(state.index);
        let at = if e.line() > 0 {
            format!(" (line {}, column {})", e.line(), e.column())
        } else {
            String::new()
        };
        let message = if e.is_io() {
            format!("cannot be read{at}: {e}")
        } else {
            let text = e.to_string();
            let text = text
                .split(" at line ")
                .next()
                .unwrap_or_default()
                .to_string();
            format!("not valid JSON{at}: {text}")
        };
        state.problems.push(entry, None, message);
    }
    check_times(&state.results, &state.indices, &mut state.problems);
    if state.problems.is_empty() {
        Ok(state.results)
    } else {
        Err(state.problems)
    }
}

/// Reads the result file at `path`: `Error::Io` when it cannot be read, `Error::CocoResults`
/// with every problem of its content.
pub fn load_coco_results(path: &Path) -> crate::Result<CocoResults> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    parse_coco_results(file).map_err(Error::CocoResults)
}

#[derive(Default)]
struct State {
    results: CocoResults,
    /// The entry index of each kept entry (entries with problems are not kept).
    indices: Vec<usize>,
    problems: EntryProblems,
    /// The index of the entry being read (the number read so far).
    index: usize,
    /// The top-level list was entered.
    started: bool,
    /// ... and left: a syntax error now is after the last entry.
    finished: bool,
}

impl<'de> DeserializeSeed<'de> for &mut State {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for &mut State {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a JSON list of results")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        self.started = true;
        while let Some(value) = seq.next_element::<Value>()? {
            let i = self.index;
            match entry(&value) {
                Ok(e) => {
                    self.results.entries.push(e);
                    self.indices.push(i);
                }
                Err(list) => {
                    for (key, message) in list {
                        self.problems.push(Some(i), key, message);
                    }
                }
            }
            self.index += 1;
        }
        self.finished = true;
        Ok(())
    }
}

type KeyProblems = Vec<(Option<&'static str>, String)>;

fn entry(value: &Value) -> Result<CocoEntry, KeyProblems> {
    let Value::Object(o) = value else {
        return Err(vec![(None, format!("{} is not an object", kind(value)))]);
    };
    let mut problems = KeyProblems::new();
    let scene_id = id(o, "scene_id", &mut problems);
    let image_id = id(o, "image_id", &mut problems);
    let category_id = id(o, "category_id", &mut problems);
    let score = match o.get("score") {
        Some(Value::Number(n)) => n.as_f64(),
        Some(v) => {
            problems.push((Some("score"), format!("{} is not a number", kind(v))));
            None
        }
        None => {
            problems.push((Some("score"), "missing".into()));
            None
        }
    };
    let bbox = match o.get("bbox") {
        None => None,
        Some(v) => match bbox(v) {
            Ok(b) => Some(b),
            Err(m) => {
                problems.push((Some("bbox"), m));
                None
            }
        },
    };
    let segm = match o.get("segmentation") {
        None => None,
        Some(v) => match segmentation(v) {
            Ok(r) => Some(r),
            Err(m) => {
                problems.push((Some("segmentation"), m));
                None
            }
        },
    };
    let time = match o.get("time") {
        None => None,
        Some(Value::Number(n)) => n.as_f64(),
        Some(v) => {
            problems.push((Some("time"), format!("{} is not a number", kind(v))));
            None
        }
    };
    match (scene_id, image_id, category_id, score) {
        (Some(scene_id), Some(image_id), Some(category_id), Some(score)) if problems.is_empty() => {
            Ok(CocoEntry {
                scene_id,
                image_id,
                category_id: i64::from(category_id),
                score,
                bbox,
                segmentation: segm,
                time,
            })
        }
        _ => Err(problems),
    }
}

fn id(o: &Map<String, Value>, key: &'static str, problems: &mut KeyProblems) -> Option<u32> {
    match o.get(key) {
        None => {
            problems.push((Some(key), "missing".into()));
            None
        }
        Some(Value::Number(n)) => {
            let v = n.as_u64().and_then(|x| u32::try_from(x).ok());
            if v.is_none() {
                problems.push((
                    Some(key),
                    format!("{n} is not an id (an integer from 0 to {})", u32::MAX),
                ));
            }
            v
        }
        Some(v) => {
            problems.push((Some(key), format!("{} is not an integer", kind(v))));
            None
        }
    }
}

fn bbox(v: &Value) -> Result<[f64; 4], String> {
    let wrong = || format!("{} is not [x, y, width, height]", short(v));
    let Value::Array(a) = v else {
        return Err(wrong());
    };
    if a.len() != 4 {
        return Err(wrong());
    }
    let mut b = [0.0; 4];
    for (slot, x) in b.iter_mut().zip(a) {
        *slot = x.as_f64().ok_or_else(wrong)?;
    }
    if b[2] < 0.0 || b[3] < 0.0 {
        return Err(format!(
            "width and height must not be negative: {}",
            short(v)
        ));
    }
    Ok(b)
}

/// bop_toolkit's `check_consistent_timings`: all entries of an image give the same time within
/// 0.001 s. Every disagreeing entry is named, with the entry whose time it contradicts.
fn check_times(results: &CocoResults, indices: &[usize], problems: &mut EntryProblems) {
    let mut first: HashMap<(u32, u32), (f64, usize)> = HashMap::new();
    for (e, &i) in results.entries.iter().zip(indices) {
        let Some(t) = e.time.filter(|t| *t >= 0.0) else {
            continue;
        };
        match first.get(&(e.scene_id, e.image_id)) {
            Some(&(t0, i0)) if (t0 - t).abs() > TIME_TOLERANCE => problems.push(
                Some(i),
                Some("time"),
                format!(
                    "{t} s, but entry {i0} gives {t0} s for the same image (scene {}, image \
                     {}): the time is the image's, the same in all its entries",
                    e.scene_id, e.image_id
                ),
            ),
            Some(_) => {}
            None => {
                first.insert((e.scene_id, e.image_id), (t, i));
            }
        }
    }
    problems.problems.sort_by_key(|p| p.entry);
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

/// A JSON value cut to a length that fits in a message.
fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 60 {
        format!("{}...", s.chars().take(60).collect::<String>())
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn problems(text: &str) -> Vec<String> {
        parse_coco_results(text.as_bytes())
            .expect_err("refused")
            .problems
            .iter()
            .map(|p| p.to_string())
            .collect()
    }

    #[test]
    fn names_entry_and_key() {
        let p = problems(
            r#"[{"scene_id": 1, "image_id": 2, "category_id": 1, "score": 0.5, "bbox": [1, 2, 3]},
                {"scene_id": 1.5, "image_id": 2, "category_id": 1, "score": "high"}]"#,
        );
        assert_eq!(p.len(), 3, "{p:?}");
        assert!(p[0].starts_with("entry 0, `bbox`"), "{p:?}");
        assert!(p[1].starts_with("entry 1, `scene_id`"), "{p:?}");
        assert!(p[2].starts_with("entry 1, `score`"), "{p:?}");
    }

    #[test]
    fn syntax_error_names_the_entry_being_read() {
        let p = problems(
            r#"[{"scene_id": 1, "image_id": 2, "category_id": 1, "score": 1}, {"scene_id": }]"#,
        );
        assert_eq!(p.len(), 1);
        assert!(
            p[0].starts_with("entry 1: not valid JSON (line 1, column"),
            "{p:?}"
        );
        let p = problems(r#"{"scene_id": 1}"#);
        assert!(p[0].contains("a JSON list of results"), "{p:?}");
    }

    #[test]
    fn inconsistent_times_name_both_entries() {
        let p = problems(
            r#"[{"scene_id": 1, "image_id": 2, "category_id": 1, "score": 1, "time": 0.5},
                {"scene_id": 1, "image_id": 2, "category_id": 2, "score": 1, "time": 0.6}]"#,
        );
        assert_eq!(p.len(), 1);
        assert!(
            p[0].starts_with("entry 1, `time`: 0.6 s, but entry 0 gives 0.5 s"),
            "{p:?}"
        );
    }
}
