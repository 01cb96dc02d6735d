//! What can be wrong with a result file, each problem with its line: kept apart from the parser
//! so that the crate's error type can carry them without depending on the parser.

use std::fmt;

use super::{HEADER, MAX_LINE_BYTES};

/// At most this many problems are kept in [`Problems`] (and in the COCO parser's problems); the
/// others are only counted.
pub const MAX_PROBLEMS: usize = 100;

/// A field of a data line, named as in the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    SceneId,
    ImId,
    ObjId,
    Score,
    R,
    T,
    Time,
}

impl Field {
    pub fn name(self) -> &'static str {
        match self {
            Field::SceneId => "scene_id",
            Field::ImId => "im_id",
            Field::ObjId => "obj_id",
            Field::Score => "score",
            Field::R => "R",
            Field::T => "t",
            Field::Time => "time",
        }
    }

    /// Whether the field is a list of numbers (R, t) rather than a single value.
    fn is_list(self) -> bool {
        matches!(self, Field::R | Field::T)
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What is wrong with a line. Quoted text (`found`, `text`) is cut to about 80 characters.
#[derive(Clone, Debug, PartialEq)]
pub enum ProblemKind {
    /// The input could not be read (only from [`parse_results`]; [`load_results`] returns
    /// `Error::Io` instead).
    Io {
        message: String,
    },
    /// The line is longer than [`MAX_LINE_BYTES`].
    TooLong {
        bytes: u64,
    },
    InvalidUtf8,
    /// An empty (or blank) line before the end of the file.
    Empty,
    /// Line 1 is neither the header nor data.
    BadHeader {
        found: String,
    },
    /// A line after line 1 contains the header.
    RepeatedHeader,
    /// The fields are separated by `;` or a tab instead of commas (a spreadsheet's CSV): said
    /// once, at the first line, rather than for every line.
    Separator {
        separator: char,
    },
    /// Not 7 comma-separated fields.
    FieldCount {
        found: usize,
    },
    /// An id that is not a non-negative integer.
    BadInteger {
        field: Field,
        text: String,
    },
    /// An id larger than `u32::MAX`.
    IntegerTooLarge {
        field: Field,
        text: String,
    },
    /// A value (of score, time, or one of the numbers of R or t) that is not a number.
    NotANumber {
        field: Field,
        text: String,
    },
    /// NaN or infinity (also a number too large for `f64`).
    NonFinite {
        field: Field,
        text: String,
    },
    /// R without 9 numbers or t without 3.
    WrongCount {
        field: Field,
        found: usize,
        expected: usize,
    },
    /// R is not within [`ROTATION_TOLERANCE`] of a rotation.
    NotRotation {
        det: f64,
        max_deviation: f64,
    },
    /// R is (nearly) orthonormal with determinant −1.
    Reflection {
        det: f64,
    },
    /// The time differs by more than 0.001 s from the first time given for the image.
    /// The times as written in the file.
    InconsistentTime {
        scene_id: u32,
        im_id: u32,
        time: String,
        first_time: String,
        first_line: u64,
    },
}

/// One problem of a result file, on line `line` (from 1; the header is line 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub line: u64,
    pub kind: ProblemKind,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.line;
        match &self.kind {
            ProblemKind::Io { message } => write!(f, "reading line {n} failed: {message}"),
            ProblemKind::TooLong { bytes } => write!(
                f,
                "line {n} is too long ({bytes} bytes, at most {MAX_LINE_BYTES} are accepted)"
            ),
            ProblemKind::InvalidUtf8 => write!(f, "line {n} is not valid UTF-8"),
            ProblemKind::Empty => write!(f, "line {n} is empty"),
            ProblemKind::BadHeader { found } => {
                write!(
                    f,
                    "bad header on line {n}: expected `{HEADER}`, found `{found}`"
                )
            }
            ProblemKind::Separator { separator: '\t' } => write!(
                f,
                "the file is separated by tabs; BOP result files use commas"
            ),
            ProblemKind::Separator { separator } => write!(
                f,
                "the file is separated by `{separator}`; BOP result files use commas"
            ),
            ProblemKind::RepeatedHeader => {
                write!(
                    f,
                    "line {n} repeats the header (only line 1 may be the header)"
                )
            }
            ProblemKind::FieldCount { found } => {
                let s = if *found == 1 { "" } else { "s" };
                write!(f, "line {n} has {found} field{s}, expected 7")
            }
            ProblemKind::BadInteger { field, text } => {
                write!(
                    f,
                    "line {n}: {field} `{text}` is not a non-negative integer"
                )
            }
            ProblemKind::IntegerTooLarge { field, text } => write!(
                f,
                "line {n}: {field} `{text}` is too large (at most {})",
                u32::MAX
            ),
            ProblemKind::NotANumber { field, text } => {
                let value = if field.is_list() { " value" } else { "" };
                write!(f, "line {n}: {field}{value} `{text}` is not a number")
            }
            ProblemKind::NonFinite { field, text } => {
                write!(f, "non-finite number on line {n} ({field}): `{text}`")
            }
            ProblemKind::WrongCount {
                field,
                found,
                expected,
            } => {
                let s = if *found == 1 { "" } else { "s" };
                write!(
                    f,
                    "line {n}: {field} has {found} number{s}, expected {expected}"
                )
            }
            ProblemKind::NotRotation { det, max_deviation } => write!(
                f,
                "R on line {n} is not a rotation matrix (det {}, max |RRᵀ-I| {})",
                short(*det),
                short(*max_deviation)
            ),
            ProblemKind::Reflection { det } => write!(
                f,
                "R on line {n} is a reflection (det {}), not a rotation matrix",
                short(*det)
            ),
            ProblemKind::InconsistentTime {
                scene_id,
                im_id,
                time,
                first_time,
                first_line,
            } => write!(
                f,
                "line {n}: time {time} for scene {scene_id}, image {im_id} differs from \
                 {first_time} given on line {first_line} (the time must be the same for every \
                 estimate of an image)"
            ),
        }
    }
}

/// The problems of a result file, in line order: at most [`MAX_PROBLEMS`], the rest counted in
/// `omitted`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Problems {
    pub problems: Vec<Problem>,
    pub omitted: usize,
}

impl Problems {
    /// The number of problems found, kept or not.
    pub fn total(&self) -> usize {
        self.problems.len() + self.omitted
    }

    pub fn is_empty(&self) -> bool {
        self.total() == 0
    }

    pub(super) fn push(&mut self, line: u64, kind: ProblemKind) {
        if self.problems.len() < MAX_PROBLEMS {
            self.problems.push(Problem { line, kind });
        } else {
            self.omitted += 1;
        }
    }
}

impl fmt::Display for Problems {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let total = self.total();
        let s = if total == 1 { "" } else { "s" };
        write!(f, "the result file has {total} problem{s}:")?;
        for p in &self.problems {
            write!(f, "\n  {p}")?;
        }
        if self.omitted > 0 {
            write!(f, "\n  ... and {} more", self.omitted)?;
        }
        Ok(())
    }
}

/// A number in a few significant digits: `3.375`, `1.25`, `-1`, `2.5e-5`.
fn short(x: f64) -> String {
    if x != 0.0 && x.is_finite() && (x.abs() < 1e-3 || x.abs() >= 1e6) {
        return format!("{x:.3e}");
    }
    let s = format!("{x:.4}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_formatting() {
        assert_eq!(short(3.375), "3.375");
        assert_eq!(short(3.3750000001), "3.375");
        assert_eq!(short(1.25), "1.25");
        assert_eq!(short(-1.0), "-1");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(2.5e-5), "2.500e-5");
        assert_eq!(short(f64::INFINITY), "inf");
    }
}
