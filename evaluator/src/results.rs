//! Reading a BOP'19 result file (`scene_id,im_id,obj_id,score,R,t,time`, one pose estimate per
//! line).
//!
//! The aim is twofold. First, accept every file that bop_toolkit's `inout.load_bop_results`
//! accepts and read it into the same numbers, so that the scores agree: the header is optional
//! (line 1 is skipped only when it *contains* the header), fields are split on `,` exactly like
//! Python's `str.split(",")`, numbers follow Python's `int()` / `float()` syntax (surrounding
//! whitespace, `+3`, `1e-3`, `.5`, `5.`, `1_000`), `\n`, `\r\n` and `\r` all end a line (Python's
//! universal newlines), and the time of an image must agree on all its lines within 0.001 s
//! (`check_consistent_timings`), a negative time meaning "not measured".
//!
//! Second, reject what is meaningless — which bop_toolkit sometimes accepts silently (NaN,
//! infinite values, a matrix that is not a rotation, negative ids) and sometimes refuses with a
//! message that names neither the line nor the field — and name *every* offending line rather
//! than stopping at the first, so one run tells the author of the file everything to fix.
//!
//! The file is streamed: only the estimates themselves (and one time per image) are kept, never
//! the text; a single line is buffered up to [`MAX_LINE_BYTES`] bytes.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use crate::error::Error;
use crate::math::{Mat3, Pose};

pub mod problems;

pub use problems::{Field, MAX_PROBLEMS, Problem, ProblemKind, Problems};

/// The header of a BOP'19 result file. bop_toolkit skips line 1 when it contains this text.
pub const HEADER: &str = "scene_id,im_id,obj_id,score,R,t,time";

/// How far a matrix may be from a rotation and still be accepted as one: both
/// `max_ij |(R Rᵀ − I)_ij|` and `|det R − 1|` must be at most this.
///
/// Result files are text, so matrices are often rounded. Rounding every entry of a rotation `R`
/// to `d` decimals adds an error `E` with `|E_ij| <= ε = 0.5·10^-d`. Then
/// `(R+E)(R+E)ᵀ − I = R Eᵀ + E Rᵀ + E Eᵀ`, and since every row of `R` has Euclidean norm 1 (so an
/// L1 norm of at most √3), each entry is at most `2√3·ε + 3ε²`. The determinant changes by
/// `Σ cof(R)_ij E_ij + O(ε²)`, and the cofactor matrix of a rotation is the rotation itself, so by
/// at most `3√3·ε + O(ε²)`. For 3 decimals (ε = 5e-4) that is 1.8e-3 and 2.6e-3: a tolerance of
/// 1e-2 accepts every rotation printed with 3 or more decimals (or computed in `f32`) with a
/// margin of almost 4. A matrix within it maps lengths to within about 0.5 % of a rigid motion,
/// which the pose errors tolerate; a scaled (1.5x: 1.25 off), sheared, or otherwise garbled
/// matrix, or a reflection (det −1), is far outside it and would make the errors meaningless.
pub const ROTATION_TOLERANCE: f64 = 1e-2;

/// The longest line kept in memory (bytes, without the line end). A valid line is a few hundred
/// bytes; a longer one is reported as a problem and skipped without being stored.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// bop_toolkit's tolerance on the times of one image (seconds).
const TIME_TOLERANCE: f64 = 0.001;

/// At most this many characters of offending text are quoted in a message.
const QUOTE_CHARS: usize = 80;

/// One pose estimate, i.e. one data line of the result file.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    pub score: f64,
    pub pose: Pose,
    /// Seconds for the whole image; negative = not given.
    pub time: f64,
    /// The line of the file (from 1; the header, when present, is line 1).
    pub line: u64,
}

/// Everything read from a valid result file.
#[derive(Clone, Debug, PartialEq)]
pub struct Results {
    /// In file order (so a stable sort by score keeps ties in file order, like bop_toolkit).
    pub estimates: Vec<Estimate>,
    /// The time of each image (scene_id, im_id): the first non-negative time given for it. Images
    /// whose lines all give a negative time are absent.
    pub image_times: BTreeMap<(u32, u32), f64>,
    /// False when some line gives a negative time ("not measured"); bop_toolkit then reports no
    /// average time.
    pub times_available: bool,
}

impl Results {
    /// bop_toolkit's `bop19_average_time_per_image`: the mean over images of the image's time.
    /// `None` when a time is missing (negative) or there is no image.
    ///
    /// The images are summed in the order in which they first appear in the file, with numpy's
    /// pairwise summation, as `np.mean(list(times.values()))` does, so the value agrees to the
    /// last bit.
    pub fn average_time_per_image(&self) -> Option<f64> {
        if !self.times_available || self.image_times.is_empty() {
            return None;
        }
        let mut seen = BTreeSet::new();
        let mut times = Vec::with_capacity(self.image_times.len());
        for e in &self.estimates {
            let key = (e.scene_id, e.im_id);
            if let Some(&t) = self.image_times.get(&key)
                && seen.insert(key)
            {
                times.push(t);
            }
        }
        // Images without an estimate (only possible for hand-made `Results`) come last.
        for (key, &t) in &self.image_times {
            if !seen.contains(key) {
                times.push(t);
            }
        }
        Some(crate::stats::mean(&times))
    }
}

/// Reads a result file from `reader`. All problems are collected (see [`Problems`]); a read
/// error becomes a problem too. An empty file, or one with only the header, gives no estimate.
pub fn parse_results<R: Read>(reader: R) -> std::result::Result<Results, Problems> {
    match parse(reader) {
        Outcome::Done(result) => result,
        Outcome::Io {
            error,
            line,
            mut problems,
        } => {
            problems.push(
                line,
                ProblemKind::Io {
                    message: error.to_string(),
                },
            );
            Err(problems)
        }
    }
}

/// Reads the result file at `path`: `Error::Io` naming the path when it cannot be read,
/// `Error::Results` with every problem of its content.
pub fn load_results(path: &Path) -> crate::Result<Results> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    match parse(file) {
        Outcome::Done(result) => result.map_err(Error::Results),
        Outcome::Io { error, .. } => Err(Error::io(path, error)),
    }
}

/// The parts of a result file name, `METHOD_DATASET-SPLIT[...].EXT`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ResultName {
    pub method: String,
    pub dataset: String,
    pub split: String,
}

/// Splits a result file name like bop_toolkit's `inout.parse_result_filename`: the base name up
/// to the first `.`, split on `_`; the method is the first part, and the second part split on
/// `-` gives the dataset and the split (`METHOD_DATASET-SPLIT.csv`,
/// `METHOD_DATASET-SPLIT-TYPE.csv`, `METHOD_DATASET-SPLIT_ID.csv`). `None` where bop_toolkit
/// fails (no `_`, or no `-` in the second part). Like bop_toolkit, the extension is not checked
/// and empty parts are not refused.
pub fn parse_result_filename(file_name: &str) -> Option<ResultName> {
    let base = file_name.rsplit('/').next().unwrap_or_default();
    let result_name = base.split('.').next().unwrap_or_default();
    let mut info = result_name.split('_');
    let method = info.next()?;
    let mut dataset_info = info.next()?.split('-');
    let dataset = dataset_info.next()?;
    let split = dataset_info.next()?;
    Some(ResultName {
        method: method.to_string(),
        dataset: dataset.to_string(),
        split: split.to_string(),
    })
}

// ---------------------------------------------------------------------------------------------
// Reading lines

/// Splits a byte stream into lines ended by `\n`, `\r\n` or `\r` (Python's universal newlines),
/// keeping at most [`MAX_LINE_BYTES`] of each.
struct LineReader<R> {
    inner: BufReader<R>,
    buf: Vec<u8>,
    /// Length of the current line; more than `buf.len()` when the line is too long.
    len: u64,
    /// The previous line ended with `\r`, so a `\n` right after it is part of its line end.
    after_cr: bool,
}

impl<R: Read> LineReader<R> {
    fn new(reader: R) -> Self {
        LineReader {
            inner: BufReader::with_capacity(64 * 1024, reader),
            buf: Vec::new(),
            len: 0,
            after_cr: false,
        }
    }

    /// Reads the next line into `buf` (without its end); `false` at the end of the input.
    fn next_line(&mut self) -> io::Result<bool> {
        self.buf.clear();
        self.len = 0;
        let mut started = false;
        loop {
            let available = match self.inner.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if available.is_empty() {
                return Ok(started);
            }
            if self.after_cr {
                self.after_cr = false;
                if available[0] == b'\n' {
                    self.inner.consume(1);
                    continue;
                }
            }
            started = true;
            match available.iter().position(|&b| b == b'\n' || b == b'\r') {
                Some(i) => {
                    let cr = available[i] == b'\r';
                    keep(&mut self.buf, &mut self.len, &available[..i]);
                    self.inner.consume(i + 1);
                    self.after_cr = cr;
                    return Ok(true);
                }
                None => {
                    let n = available.len();
                    keep(&mut self.buf, &mut self.len, available);
                    self.inner.consume(n);
                }
            }
        }
    }
}

fn keep(buf: &mut Vec<u8>, len: &mut u64, chunk: &[u8]) {
    let room = MAX_LINE_BYTES.saturating_sub(buf.len());
    buf.extend_from_slice(&chunk[..chunk.len().min(room)]);
    *len += chunk.len() as u64;
}

// ---------------------------------------------------------------------------------------------
// Parsing

enum Outcome {
    Done(std::result::Result<Results, Problems>),
    Io {
        error: io::Error,
        line: u64,
        problems: Problems,
    },
}

/// The separator a line is written with when it is not the comma: `;` or a tab, when it splits
/// the line into the seven fields of the header (or the header itself) and the comma does not.
fn other_separator(text: &str) -> Option<char> {
    if text.split(',').count() == 7 {
        return None;
    }
    [';', '\t']
        .into_iter()
        .find(|&sep| text.split(sep).count() == 7 || text.replace(sep, ",").contains(HEADER))
}

fn parse<R: Read>(reader: R) -> Outcome {
    let mut lines = LineReader::new(reader);
    let mut parser = Parser::new();
    loop {
        match lines.next_line() {
            Ok(true) => parser.line(&lines.buf, lines.len),
            Ok(false) => return Outcome::Done(parser.finish()),
            Err(error) => {
                parser.flush_blank_lines();
                return Outcome::Io {
                    error,
                    line: parser.line_no + 1,
                    problems: parser.problems,
                };
            }
        }
    }
}

struct Parser {
    /// The number of the last line read.
    line_no: u64,
    /// A run of blank lines not yet known to be at the end of the file: (first line, count).
    blank_run: Option<(u64, u64)>,
    problems: Problems,
    estimates: Vec<Estimate>,
    /// Per image: the first non-negative time, its line, and its text as written (a problem
    /// quotes the file, not a float's re-rendering of it).
    first_times: BTreeMap<(u32, u32), (f64, u64, String)>,
    times_available: bool,
    /// The file's lines are separated by another character than the comma: said once, and
    /// the lines after are not read.
    separated_otherwise: bool,
}

impl Parser {
    fn new() -> Self {
        Parser {
            line_no: 0,
            blank_run: None,
            problems: Problems::default(),
            estimates: Vec::new(),
            first_times: BTreeMap::new(),
            times_available: true,
            separated_otherwise: false,
        }
    }

    fn finish(self) -> std::result::Result<Results, Problems> {
        // Blank lines at the end of the file are fine.
        if !self.problems.is_empty() {
            return Err(self.problems);
        }
        Ok(Results {
            estimates: self.estimates,
            image_times: self
                .first_times
                .into_iter()
                .map(|(key, (t, _, _))| (key, t))
                .collect(),
            times_available: self.times_available,
        })
    }

    /// Reports the pending blank lines: they are followed by more text.
    fn flush_blank_lines(&mut self) {
        if let Some((first, count)) = self.blank_run.take() {
            for line in first..first + count {
                self.problems.push(line, ProblemKind::Empty);
            }
        }
    }

    fn line(&mut self, bytes: &[u8], len: u64) {
        self.line_no += 1;
        let n = self.line_no;
        if self.separated_otherwise {
            return;
        }
        if len > MAX_LINE_BYTES as u64 {
            self.flush_blank_lines();
            self.problems.push(n, ProblemKind::TooLong { bytes: len });
            return;
        }
        let bytes = if n == 1 {
            bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes)
        } else {
            bytes
        };
        let Ok(text) = std::str::from_utf8(bytes) else {
            self.flush_blank_lines();
            self.problems.push(n, ProblemKind::InvalidUtf8);
            return;
        };
        if trim_py(text).is_empty() {
            match &mut self.blank_run {
                Some((_, count)) => *count += 1,
                None => self.blank_run = Some((n, 1)),
            }
            return;
        }
        self.flush_blank_lines();
        if text.contains(HEADER) {
            if n != 1 {
                self.problems.push(n, ProblemKind::RepeatedHeader);
            }
            return;
        }
        let first_content = self.estimates.is_empty() && self.problems.is_empty();
        if let Some(separator) = other_separator(text).filter(|_| first_content) {
            self.problems.push(n, ProblemKind::Separator { separator });
            self.separated_otherwise = true;
            return;
        }
        if n == 1 {
            let first = text.split(',').next().unwrap_or_default();
            if parse_py_float(first).is_none() {
                let found = quote(trim_py(text));
                self.problems.push(n, ProblemKind::BadHeader { found });
                return;
            }
        }
        self.data_line(n, text);
    }

    fn data_line(&mut self, n: u64, text: &str) {
        let mut fields = [""; 7];
        let mut count = 0usize;
        for (i, f) in text.split(',').enumerate() {
            if let Some(slot) = fields.get_mut(i) {
                *slot = f;
            }
            count += 1;
        }
        if count != 7 {
            self.problems
                .push(n, ProblemKind::FieldCount { found: count });
            return;
        }
        let scene_id = self.id(n, Field::SceneId, fields[0]);
        let im_id = self.id(n, Field::ImId, fields[1]);
        let obj_id = self.id(n, Field::ObjId, fields[2]);
        let score = self.scalar(n, Field::Score, fields[3]);
        let r = self.list::<9>(n, Field::R, fields[4]);
        let r = r.and_then(|r| self.rotation(n, &r));
        let t = self.list::<3>(n, Field::T, fields[5]);
        let time = self.scalar(n, Field::Time, fields[6]);

        if let (Some(scene_id), Some(im_id), Some(time)) = (scene_id, im_id, time) {
            self.check_time(n, scene_id, im_id, time, fields[6]);
        }

        if let (
            Some(scene_id),
            Some(im_id),
            Some(obj_id),
            Some(score),
            Some(r),
            Some(t),
            Some(time),
        ) = (scene_id, im_id, obj_id, score, r, t, time)
        {
            // Once the file is known to be invalid, the estimates are of no use.
            if self.problems.is_empty() {
                self.estimates.push(Estimate {
                    scene_id,
                    im_id,
                    obj_id,
                    score,
                    pose: Pose::new(r, crate::math::Vec3::new(t[0], t[1], t[2])),
                    time,
                    line: n,
                });
            }
        }
    }

    fn id(&mut self, n: u64, field: Field, text: &str) -> Option<u32> {
        match parse_py_u32(text) {
            Ok(v) => Some(v),
            Err(IntError::Invalid) => {
                let text = quote(trim_py(text));
                self.problems
                    .push(n, ProblemKind::BadInteger { field, text });
                None
            }
            Err(IntError::TooLarge) => {
                let text = quote(trim_py(text));
                self.problems
                    .push(n, ProblemKind::IntegerTooLarge { field, text });
                None
            }
        }
    }

    fn scalar(&mut self, n: u64, field: Field, text: &str) -> Option<f64> {
        match parse_py_float(text) {
            Some(v) if v.is_finite() => Some(v),
            Some(_) => {
                let text = quote(trim_py(text));
                self.problems
                    .push(n, ProblemKind::NonFinite { field, text });
                None
            }
            None => {
                let text = quote(trim_py(text));
                self.problems
                    .push(n, ProblemKind::NotANumber { field, text });
                None
            }
        }
    }

    /// A whitespace-separated list of exactly `N` finite numbers (Python's `str.split()`).
    fn list<const N: usize>(&mut self, n: u64, field: Field, text: &str) -> Option<[f64; N]> {
        let mut values = [0.0; N];
        let mut count = 0usize;
        let mut non_finite: Option<&str> = None;
        for token in text.split(is_py_space).filter(|s| !s.is_empty()) {
            match parse_py_float(token) {
                Some(v) => {
                    if let Some(slot) = values.get_mut(count) {
                        *slot = v;
                    }
                    if !v.is_finite() && non_finite.is_none() {
                        non_finite = Some(token);
                    }
                }
                None => {
                    let text = quote(token);
                    self.problems
                        .push(n, ProblemKind::NotANumber { field, text });
                    return None;
                }
            }
            count += 1;
        }
        if count != N {
            self.problems.push(
                n,
                ProblemKind::WrongCount {
                    field,
                    found: count,
                    expected: N,
                },
            );
            return None;
        }
        if let Some(token) = non_finite {
            let text = quote(token);
            self.problems
                .push(n, ProblemKind::NonFinite { field, text });
            return None;
        }
        Some(values)
    }

    fn rotation(&mut self, n: u64, values: &[f64; 9]) -> Option<Mat3> {
        let r = Mat3::from_row_slice(values);
        let det = r.determinant();
        let max_deviation = (r * r.transpose() - Mat3::identity()).amax();
        if max_deviation <= ROTATION_TOLERANCE && (det - 1.0).abs() <= ROTATION_TOLERANCE {
            return Some(r);
        }
        let kind = if max_deviation <= ROTATION_TOLERANCE && (det + 1.0).abs() <= ROTATION_TOLERANCE
        {
            ProblemKind::Reflection { det }
        } else {
            ProblemKind::NotRotation { det, max_deviation }
        };
        self.problems.push(n, kind);
        None
    }

    /// bop_toolkit's `check_consistent_timings`: a negative time means "not given" (and no
    /// average time); the others must agree within 0.001 s with the first one of their image.
    fn check_time(&mut self, n: u64, scene_id: u32, im_id: u32, time: f64, text: &str) {
        if time < 0.0 {
            self.times_available = false;
            return;
        }
        match self.first_times.get(&(scene_id, im_id)) {
            Some((first_time, first_line, first_text)) => {
                if (first_time - time).abs() > TIME_TOLERANCE {
                    let kind = ProblemKind::InconsistentTime {
                        scene_id,
                        im_id,
                        time: quote(trim_py(text)),
                        first_time: first_text.clone(),
                        first_line: *first_line,
                    };
                    self.problems.push(n, kind);
                }
            }
            None => {
                let written = quote(trim_py(text));
                self.first_times
                    .insert((scene_id, im_id), (time, n, written));
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Python number syntax

/// Python's `str.isspace()`: Unicode white space plus the ASCII separators 0x1c..0x1f.
fn is_py_space(c: char) -> bool {
    c.is_whitespace() || ('\u{1c}'..='\u{1f}').contains(&c)
}

fn trim_py(s: &str) -> &str {
    s.trim_matches(is_py_space)
}

/// Python allows `_` in numbers only between two digits (`1_000`, `1e1_0`).
fn underscores_ok(s: &str) -> bool {
    let b = s.as_bytes();
    b.iter().enumerate().all(|(i, &c)| {
        c != b'_'
            || (i > 0
                && b[i - 1].is_ascii_digit()
                && b.get(i + 1).is_some_and(|d| d.is_ascii_digit()))
    })
}

/// Python's `float()` on an ASCII string: Rust's `f64` syntax is the same (`1e-3`, `.5`, `5.`,
/// `+1`, `inf`, `nan`, any case) once surrounding white space and digit-separating `_` are
/// removed. Both round correctly, so the values are identical.
fn parse_py_float(s: &str) -> Option<f64> {
    let s = trim_py(s);
    if s.contains('_') {
        if !underscores_ok(s) {
            return None;
        }
        s.replace('_', "").parse().ok()
    } else {
        s.parse().ok()
    }
}

enum IntError {
    /// Not an integer, or negative.
    Invalid,
    TooLarge,
}

/// Python's `int()` (base 10, ASCII digits) restricted to `0..=u32::MAX`.
fn parse_py_u32(s: &str) -> std::result::Result<u32, IntError> {
    let s = trim_py(s);
    let (negative, digits) = match s.as_bytes().first() {
        Some(b'+') => (false, &s[1..]),
        Some(b'-') => (true, &s[1..]),
        _ => (false, s),
    };
    let b = digits.as_bytes();
    let valid = b.first().is_some_and(u8::is_ascii_digit)
        && b.iter().all(|&c| c.is_ascii_digit() || c == b'_')
        && underscores_ok(digits);
    if !valid {
        return Err(IntError::Invalid);
    }
    let mut value: u64 = 0;
    let mut too_large = false;
    for c in b.iter().filter(|&&c| c != b'_') {
        value = value * 10 + u64::from(c - b'0');
        if value > u64::from(u32::MAX) {
            too_large = true;
            break;
        }
    }
    if negative && (too_large || value != 0) {
        return Err(IntError::Invalid);
    }
    if too_large {
        return Err(IntError::TooLarge);
    }
    Ok(value as u32)
}

// ---------------------------------------------------------------------------------------------
// Messages

/// At most [`QUOTE_CHARS`] characters of `s`, control characters escaped.
fn quote(s: &str) -> String {
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i == QUOTE_CHARS {
            out.push_str("...");
            break;
        }
        if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const REFERENCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/reference");
    const IDENTITY: &str = "1 0 0 0 1 0 0 0 1";

    fn reference(rel: &str) -> std::path::PathBuf {
        Path::new(REFERENCE).join(rel)
    }

    fn row(scene: u32, im: u32, obj: u32, score: &str, r: &str, t: &str, time: &str) -> String {
        format!("{scene},{im},{obj},{score},{r},{t},{time}\n")
    }

    fn ok_row(scene: u32, im: u32, obj: u32) -> String {
        row(scene, im, obj, "0.5", IDENTITY, "1 2 300", "0.25")
    }

    fn parse_str(s: &str) -> std::result::Result<Results, Problems> {
        parse_results(s.as_bytes())
    }

    fn problems_of(s: &str) -> Problems {
        match parse_str(s) {
            Ok(r) => panic!("accepted ({} estimates): {s:?}", r.estimates.len()),
            Err(p) => p,
        }
    }

    /// The message of the only problem of `s`.
    fn only_problem(s: &str) -> String {
        let p = problems_of(s);
        assert_eq!(p.total(), 1, "{p}");
        p.problems[0].to_string()
    }

    fn r_string(values: &[f64]) -> String {
        values
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    }

    fn with_header(body: &str) -> String {
        format!("{HEADER}\n{body}")
    }

    // --- reference files -----------------------------------------------------------------

    #[test]
    fn reference_files_parse() {
        let expected = [
            ("extra", 38),
            ("gtexact", 35),
            ("missing", 26),
            ("multi", 105),
            ("noiselarge", 35),
            ("noisemedium", 35),
            ("noisesmall", 35),
            ("random", 35),
            ("symflip", 35),
        ];
        for (name, count) in expected {
            let path = reference(&format!("results/{name}_synthA-test.csv"));
            let results = load_results(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(results.estimates.len(), count, "{name}");
            for (i, e) in results.estimates.iter().enumerate() {
                assert_eq!(e.line, i as u64 + 2, "{name}");
            }
            assert!(results.times_available, "{name}");
            assert_eq!(results.image_times.len(), 8, "{name}");
            let parsed = parse_result_filename(&format!("{name}_synthA-test.csv")).unwrap();
            assert_eq!(parsed.method, name);
            assert_eq!(parsed.dataset, "synthA");
            assert_eq!(parsed.split, "test");
        }
    }

    #[test]
    fn reference_values_are_exact() {
        let results = load_results(&reference("results/noisemedium_synthA-test.csv")).unwrap();
        let e = &results.estimates[0];
        assert_eq!((e.scene_id, e.im_id, e.obj_id, e.line), (1, 0, 3, 2));
        assert_eq!(e.score, 0.734262);
        assert_eq!(e.pose.r[(0, 0)], 0.6136552008868564);
        assert_eq!(e.pose.r[(0, 1)], 0.7895707854685305);
        assert_eq!(e.pose.r[(1, 0)], 0.3671698858859188);
        assert_eq!(e.pose.r[(2, 2)], -0.4634413298218308);
        assert_eq!(e.pose.t.x, 186.99940801157723);
        assert_eq!(e.pose.t.z, 820.9974312350029);
        assert_eq!(e.time, 0.8762);
        assert_eq!(results.image_times[&(1, 0)], 0.8762);
        assert_eq!(results.image_times[&(2, 3)], 1.5768);
    }

    #[test]
    fn reference_average_time() {
        for name in ["noisemedium", "multi", "missing"] {
            let path = reference(&format!("results/{name}_synthA-test.csv"));
            let avg = load_results(&path)
                .unwrap()
                .average_time_per_image()
                .unwrap();
            assert!((avg - 1.175025).abs() < 1e-12, "{name}: {avg}");
            // bop19.json holds numpy's value in its shortest repr; ours is bit-identical.
            assert_eq!(avg, 1.175025, "{name}");
        }
    }

    // --- malformed reference files -------------------------------------------------------

    fn malformed(name: &str) -> String {
        let path = reference(&format!("results/malformed/{name}_synthA-test.csv"));
        match load_results(&path) {
            Ok(r) => panic!("{name}: accepted {} estimates", r.estimates.len()),
            Err(Error::Results(p)) => p.to_string(),
            Err(e) => panic!("{name}: unexpected error {e}"),
        }
    }

    #[test]
    fn malformed_reference_files_are_rejected() {
        let m = malformed("bad-header");
        assert!(m.contains("bad header on line 1"), "{m}");
        assert!(
            m.contains("found `scene,image,object,confidence,R,t,time`"),
            "{m}"
        );
        let m = malformed("nan");
        assert!(m.contains("non-finite number on line 4"), "{m}");
        assert!(m.contains("(t)"), "{m}");
        let m = malformed("not-rotation");
        assert!(m.contains("R on line 5 is not a rotation matrix"), "{m}");
        assert!(m.contains("det 3.375"), "{m}");
        let m = malformed("wrong-columns");
        assert!(m.contains("line 6 has 6 fields, expected 7"), "{m}");
        let m = malformed("inconsistent-time");
        assert!(m.contains("line 3"), "{m}");
        assert!(m.contains("scene 1"), "{m}");
        assert!(m.contains("image 0"), "{m}");
        for name in [
            "bad-header",
            "nan",
            "not-rotation",
            "wrong-columns",
            "inconsistent-time",
        ] {
            let m = malformed(name);
            assert!(
                m.starts_with("the result file has 1 problem:\n"),
                "{name}: {m}"
            );
        }
    }

    // --- each kind of problem ------------------------------------------------------------

    #[test]
    fn empty_line_in_the_middle() {
        let s = with_header(&format!("{}\n{}", ok_row(1, 0, 1), ok_row(1, 0, 2)));
        assert_eq!(only_problem(&s), "line 3 is empty");
        let s = with_header(&format!("{} \t\r\n{}", ok_row(1, 0, 1), ok_row(1, 0, 2)));
        assert_eq!(only_problem(&s), "line 3 is empty");
        // Line 1 empty, data after it.
        assert_eq!(
            only_problem(&format!("\n{}", ok_row(1, 0, 1))),
            "line 1 is empty"
        );
    }

    #[test]
    fn trailing_empty_lines_are_fine() {
        let s = with_header(&format!("{}\n\n  \r\n", ok_row(1, 0, 1)));
        assert_eq!(parse_str(&s).unwrap().estimates.len(), 1);
        let s = with_header(ok_row(1, 0, 1).trim_end());
        assert_eq!(parse_str(&s).unwrap().estimates.len(), 1);
    }

    #[test]
    fn empty_and_header_only_files() {
        for s in [
            "",
            "\n",
            HEADER,
            &format!("{HEADER}\n"),
            &format!("{HEADER}\r\n\r\n"),
        ] {
            let r = parse_str(s).unwrap();
            assert!(r.estimates.is_empty(), "{s:?}");
            assert_eq!(r.average_time_per_image(), None);
        }
    }

    #[test]
    fn bad_ids() {
        let s =
            with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1").replace("1,0,1,", "1,0,abc,"));
        assert_eq!(
            only_problem(&s),
            "line 2: obj_id `abc` is not a non-negative integer"
        );
        let s =
            with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1").replace("1,0,1,", "1,3.0,1,"));
        assert_eq!(
            only_problem(&s),
            "line 2: im_id `3.0` is not a non-negative integer"
        );
        let s =
            with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1").replace("1,0,1,", "1,0,-1,"));
        assert_eq!(
            only_problem(&s),
            "line 2: obj_id `-1` is not a non-negative integer"
        );
        let s =
            with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1").replace("1,0,1,", ",0,1,"));
        assert_eq!(
            only_problem(&s),
            "line 2: scene_id `` is not a non-negative integer"
        );
        let s = with_header(
            &row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1").replace("1,0,1,", "4294967296,0,1,"),
        );
        assert_eq!(
            only_problem(&s),
            "line 2: scene_id `4294967296` is too large (at most 4294967295)"
        );
        for bad in ["1__0", "_1", "1_", "+-1", "+", "- 1", "0x1", "1e3", "٣"] {
            let s = with_header(&format!("1,0,{bad},0.5,{IDENTITY},0 0 1,1\n"));
            let m = only_problem(&s);
            assert!(
                m.contains("obj_id") && m.contains("not a non-negative integer"),
                "{bad}: {m}"
            );
        }
    }

    #[test]
    fn python_integer_syntax_is_accepted() {
        let s = with_header(&format!(
            "+3, 0 ,\t7 ,0.5,{IDENTITY},0 0 1,1\n0_1,-0,4294967295,0.5,{IDENTITY},0 0 1,1\n007,1_0,2,0.5,{IDENTITY},0 0 1,1\n"
        ));
        let r = parse_str(&s).unwrap();
        let ids: Vec<_> = r
            .estimates
            .iter()
            .map(|e| (e.scene_id, e.im_id, e.obj_id))
            .collect();
        assert_eq!(ids, [(3, 0, 7), (1, 0, 4294967295), (7, 10, 2)]);
    }

    #[test]
    fn wrong_counts_of_r_and_t() {
        let s = with_header(&row(1, 0, 1, "0.5", "1 0 0 0 1 0 0 0", "0 0 1", "1"));
        assert_eq!(only_problem(&s), "line 2: R has 8 numbers, expected 9");
        let s = with_header(&row(1, 0, 1, "0.5", "", "0 0 1", "1"));
        assert_eq!(only_problem(&s), "line 2: R has 0 numbers, expected 9");
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1 4", "1"));
        assert_eq!(only_problem(&s), "line 2: t has 4 numbers, expected 3");
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "1", "1"));
        assert_eq!(only_problem(&s), "line 2: t has 1 number, expected 3");
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 x 1", "1"));
        assert_eq!(only_problem(&s), "line 2: t value `x` is not a number");
        let s = with_header(&row(1, 0, 1, "0.5", "1 0 0 0 1 0 0 0 1;", "0 0 1", "1"));
        assert_eq!(only_problem(&s), "line 2: R value `1;` is not a number");
    }

    #[test]
    fn non_finite_numbers() {
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "inf"));
        assert_eq!(
            only_problem(&s),
            "non-finite number on line 2 (time): `inf`"
        );
        let s = with_header(&row(1, 0, 1, "NaN", IDENTITY, "0 0 1", "1"));
        assert_eq!(
            only_problem(&s),
            "non-finite number on line 2 (score): `NaN`"
        );
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1e400", "1"));
        assert_eq!(only_problem(&s), "non-finite number on line 2 (t): `1e400`");
        let s = with_header(&row(
            1,
            0,
            1,
            "0.5",
            "1 0 0 0 1 0 0 0 -Infinity",
            "0 0 1",
            "1",
        ));
        assert_eq!(
            only_problem(&s),
            "non-finite number on line 2 (R): `-Infinity`"
        );
        let s = with_header(&row(1, 0, 1, "high", IDENTITY, "0 0 1", "1"));
        assert_eq!(only_problem(&s), "line 2: score `high` is not a number");
        let s = with_header(&row(1, 0, 1, "0.5", IDENTITY, "0 0 1", ""));
        assert_eq!(only_problem(&s), "line 2: time `` is not a number");
    }

    #[test]
    fn python_float_syntax_is_accepted() {
        let s = with_header(&format!(
            "1,0,1, 1e-3 ,{},1E+02 -.5 5.,+1\n1,1,1,1_0.2_5,{IDENTITY},0 0 1e1_0,-1\n",
            "1.0e0 0 0 0 +1. 0 0 0 1_0e-1"
        ));
        let r = parse_str(&s).unwrap();
        let e = &r.estimates[0];
        assert_eq!(e.score, 1e-3);
        assert_eq!(e.pose.t, crate::math::Vec3::new(100.0, -0.5, 5.0));
        assert_eq!(e.pose.r, Mat3::identity());
        assert_eq!(e.time, 1.0);
        assert_eq!(r.estimates[1].score, 10.25);
        assert_eq!(r.estimates[1].pose.t.z, 1e10);
        for bad in [
            "1_", "_1", "1__0", "1_.5", "1._5", "1_e5", "e5", ".", "1e", "0x10", "1 5",
        ] {
            assert_eq!(parse_py_float(bad), None, "{bad}");
        }
        assert_eq!(parse_py_float("1,5"), None);
        assert_eq!(parse_py_float("\u{1f} 2.5\u{a0}"), Some(2.5));
    }

    #[test]
    fn rotations_reflections_and_scaling() {
        let scaled = r_string(&[1.5, 0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 1.5]);
        let s = with_header(&row(1, 0, 1, "0.5", &scaled, "0 0 1", "1"));
        assert_eq!(
            only_problem(&s),
            "R on line 2 is not a rotation matrix (det 3.375, max |RRᵀ-I| 1.25)"
        );
        let reflection = "1 0 0 0 1 0 0 0 -1";
        let s = with_header(&row(1, 0, 1, "0.5", reflection, "0 0 1", "1"));
        assert_eq!(
            only_problem(&s),
            "R on line 2 is a reflection (det -1), not a rotation matrix"
        );
        let zeros = "0 0 0 0 0 0 0 0 0";
        let s = with_header(&row(1, 0, 1, "0.5", zeros, "0 0 1", "1"));
        assert_eq!(
            only_problem(&s),
            "R on line 2 is not a rotation matrix (det 0, max |RRᵀ-I| 1)"
        );
        let huge = "1e300 0 0 0 1e300 0 0 0 1e300";
        let s = with_header(&row(1, 0, 1, "0.5", huge, "0 0 1", "1"));
        assert!(only_problem(&s).starts_with("R on line 2 is not a rotation matrix"));
    }

    fn rotation_from(q: [f64; 4]) -> Option<Mat3> {
        let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm < 1e-3 {
            return None;
        }
        let quat = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
        let unit = nalgebra::UnitQuaternion::from_quaternion(quat);
        Some(unit.to_rotation_matrix().into_inner())
    }

    fn rounded(r: &Mat3, decimals: i32) -> Vec<f64> {
        let f = 10f64.powi(decimals);
        let mut v = Vec::new();
        for i in 0..3 {
            for j in 0..3 {
                v.push((r[(i, j)] * f).round() / f);
            }
        }
        v
    }

    proptest! {
        #[test]
        fn rounded_rotations_are_accepted(q in proptest::array::uniform4(-1.0f64..1.0)) {
            let Some(r) = rotation_from(q) else { return Ok(()); };
            for decimals in [3, 4] {
                let text = r_string(&rounded(&r, decimals));
                let s = row(1, 0, 1, "0.5", &text, "0 0 1", "1");
                prop_assert!(parse_str(&s).is_ok(), "{} decimals: {}", decimals, text);
            }
            // The same rotation composed with a mirror, or scaled, is refused.
            let mirrored = r * Mat3::from_diagonal(&crate::math::Vec3::new(1.0, 1.0, -1.0));
            let s = row(1, 0, 1, "0.5", &r_string(&rounded(&mirrored, 3)), "0 0 1", "1");
            let m = problems_of(&s).to_string();
            prop_assert!(m.contains("is a reflection"), "{}", m);
            let s = row(1, 0, 1, "0.5", &r_string(&rounded(&(r * 1.5), 6)), "0 0 1", "1");
            let m = problems_of(&s).to_string();
            prop_assert!(m.contains("R on line 1 is not a rotation matrix"), "{}", m);
        }
    }

    #[test]
    fn three_decimal_rotations_have_margin() {
        // Deterministic sweep: the worst deviation of 3-decimal rotations stays well within
        // the tolerance (the bound in the doc of ROTATION_TOLERANCE is 2.6e-3).
        let mut worst: f64 = 0.0;
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..20_000 {
            let Some(r) = rotation_from([next(), next(), next(), next()]) else {
                continue;
            };
            let q = Mat3::from_row_slice(&rounded(&r, 3));
            let dev = (q * q.transpose() - Mat3::identity()).amax();
            worst = worst.max(dev).max((q.determinant() - 1.0).abs());
        }
        assert!(worst < 2.7e-3, "{worst}");
        assert!(worst * 3.0 < ROTATION_TOLERANCE);
    }

    #[test]
    fn placeholder_and_behind_camera_translations_are_accepted() {
        let s = format!(
            "{}{}",
            row(1, 0, 1, "0.5", IDENTITY, "0 0 0", "1"),
            row(1, 0, 2, "0.5", IDENTITY, "10 -20 -500", "1")
        );
        let r = parse_str(&s).unwrap();
        assert_eq!(r.estimates[1].pose.t.z, -500.0);
    }

    #[test]
    fn inconsistent_times() {
        let s = with_header(&format!(
            "{}{}{}",
            row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "0.8762"),
            row(1, 0, 2, "0.5", IDENTITY, "0 0 1", "1.3762"),
            row(1, 0, 3, "0.5", IDENTITY, "0 0 1", "0.8771")
        ));
        assert_eq!(
            only_problem(&s),
            "line 3: time 1.3762 for scene 1, image 0 differs from 0.8762 given on line 2 \
             (the time must be the same for every estimate of an image)"
        );
    }

    #[test]
    fn inconsistent_times_are_quoted_as_written() {
        let s = with_header(&format!(
            "{}{}",
            row(1, 0, 1, "0.5", IDENTITY, "0 0 1", " 2.50E+0"),
            row(1, 0, 2, "0.5", IDENTITY, "0 0 1", "1_0.0")
        ));
        let m = only_problem(&s);
        assert!(
            m.starts_with("line 3: time 1_0.0 for scene 1, image 0 differs from 2.50E+0 given"),
            "{m}"
        );
    }

    #[test]
    fn negative_times_disable_the_average() {
        let s = format!(
            "{}{}{}",
            row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "-1"),
            row(1, 0, 2, "0.5", IDENTITY, "0 0 1", "0.5"),
            row(1, 1, 2, "0.5", IDENTITY, "0 0 1", "0.7")
        );
        let r = parse_str(&s).unwrap();
        assert!(!r.times_available);
        assert_eq!(r.average_time_per_image(), None);
        assert_eq!(r.image_times[&(1, 0)], 0.5);
        // The non-negative times of an image must still agree.
        let s = format!("{s}{}", row(1, 0, 3, "0.5", IDENTITY, "0 0 1", "0.9"));
        let m = only_problem(&s);
        assert!(
            m.starts_with("line 4: time 0.9 for scene 1, image 0 differs from 0.5 given on line 2"),
            "{m}"
        );
        // All times given: the mean over images.
        let s = format!(
            "{}{}{}",
            row(2, 0, 1, "0.5", IDENTITY, "0 0 1", "0.5"),
            row(1, 1, 2, "0.5", IDENTITY, "0 0 1", "1.0"),
            row(2, 0, 3, "0.5", IDENTITY, "0 0 1", "0.5005")
        );
        let r = parse_str(&s).unwrap();
        assert_eq!(r.average_time_per_image(), Some(0.75));
    }

    #[test]
    fn invalid_utf8_and_long_lines() {
        let mut bytes = with_header(&ok_row(1, 0, 1)).into_bytes();
        bytes.extend_from_slice(b"1,0,2,0.5,\xff\xfe,0 0 1,1\n");
        bytes.extend_from_slice(ok_row(1, 0, 3).as_bytes());
        let p = parse_results(&bytes[..]).unwrap_err();
        assert_eq!(p.total(), 1);
        assert_eq!(p.problems[0].to_string(), "line 3 is not valid UTF-8");

        let long = format!(
            "{}{}{}",
            "9".repeat(MAX_LINE_BYTES + 10),
            ok_row(1, 0, 1),
            ok_row(1, 0, 2)
        );
        let p = parse_str(&long).unwrap_err();
        assert_eq!(p.total(), 1);
        assert_eq!(
            p.problems[0].kind,
            ProblemKind::TooLong {
                bytes: (MAX_LINE_BYTES + 10 + ok_row(1, 0, 1).len() - 1) as u64
            }
        );
        assert!(p.to_string().contains("line 1 is too long"));

        // A long (but accepted) line quotes at most 80 characters.
        let junk = "x".repeat(10_000);
        let s = with_header(&row(1, 0, 1, &junk, IDENTITY, "0 0 1", "1"));
        let m = only_problem(&s);
        assert!(m.len() < 150, "{m}");
        assert!(m.ends_with("...` is not a number"), "{m}");
    }

    #[test]
    fn wrong_field_counts() {
        let s = with_header("1,0,1,0.5\n1,0,1,0.5,1 0 0 0 1 0 0 0 1,0 0 1,1,extra\nnothing\n");
        let p = problems_of(&s);
        let m: Vec<String> = p.problems.iter().map(|p| p.to_string()).collect();
        assert_eq!(
            m,
            [
                "line 2 has 4 fields, expected 7",
                "line 3 has 8 fields, expected 7",
                "line 4 has 1 field, expected 7"
            ]
        );
        // Quoted fields are not CSV-quoted, exactly like Python's split(",").
        let s = with_header(&format!("1,0,1,\"0,5\",{IDENTITY},0 0 1,1\n"));
        assert_eq!(only_problem(&s), "line 2 has 8 fields, expected 7");
    }

    #[test]
    fn several_problems_are_all_reported() {
        let s = with_header(&format!(
            "{}1,0,x,nan,{IDENTITY},0 0 1,0.25\n{}\n1,0,4,0.5,1 0 0,0 0 1,0.25\n{}",
            ok_row(1, 0, 1),
            ok_row(1, 0, 2),
            ok_row(1, 0, 5)
        ));
        let p = problems_of(&s);
        let lines: Vec<u64> = p.problems.iter().map(|p| p.line).collect();
        assert_eq!(lines, [3, 3, 5, 6]);
        assert_eq!(
            p.problems[0].to_string(),
            "line 3: obj_id `x` is not a non-negative integer"
        );
        assert_eq!(
            p.problems[1].to_string(),
            "non-finite number on line 3 (score): `nan`"
        );
        assert_eq!(p.problems[2].to_string(), "line 5 is empty");
        assert_eq!(
            p.problems[3].to_string(),
            "line 6: R has 3 numbers, expected 9"
        );
        assert!(
            p.to_string()
                .starts_with("the result file has 4 problems:\n  line 3: obj_id")
        );
    }

    #[test]
    fn problems_are_bounded() {
        let mut s = String::from(HEADER);
        s.push('\n');
        for i in 0..250 {
            s.push_str(&format!("{i},0,1,0.5\n"));
        }
        let p = problems_of(&s);
        assert_eq!(p.problems.len(), MAX_PROBLEMS);
        assert_eq!(p.omitted, 150);
        assert_eq!(p.problems[99].line, 101);
        let text = p.to_string();
        assert!(text.starts_with("the result file has 250 problems:\n"));
        assert!(text.ends_with("\n  ... and 150 more"));
        assert_eq!(text.lines().count(), 1 + MAX_PROBLEMS + 1);
    }

    #[test]
    fn line_endings() {
        let lf = with_header(&format!("{}{}", ok_row(1, 0, 1), ok_row(1, 1, 2)));
        let crlf = lf.replace('\n', "\r\n");
        let cr = lf.replace('\n', "\r");
        for s in [&lf, &crlf, &cr] {
            let r = parse_str(s).unwrap();
            let lines: Vec<u64> = r.estimates.iter().map(|e| e.line).collect();
            assert_eq!(lines, [2, 3], "{s:?}");
        }
        // CRLF split across reads.
        let reader = Read::chain(Read::take(crlf.as_bytes(), 37), &crlf.as_bytes()[37..]);
        assert_eq!(parse_results(reader).unwrap().estimates.len(), 2);
        let m = only_problem(&format!(
            "{}\r\n\r\n{}",
            ok_row(1, 0, 1).trim_end(),
            ok_row(1, 0, 2)
        ));
        assert_eq!(m, "line 2 is empty");
    }

    #[test]
    fn headers() {
        // Optional header.
        let s = format!("{}{}", ok_row(1, 0, 1), ok_row(1, 0, 2));
        let r = parse_str(&s).unwrap();
        assert_eq!(r.estimates[0].line, 1);
        // Line 1 is skipped when it contains the header (bop_toolkit's test), BOM allowed.
        let s = format!("\u{feff} {HEADER},extra \n{}", ok_row(1, 0, 1));
        assert_eq!(parse_str(&s).unwrap().estimates[0].line, 2);
        let s = format!("\u{feff}{}", ok_row(1, 0, 1));
        assert_eq!(parse_str(&s).unwrap().estimates[0].line, 1);
        // Something else that is not data.
        let s = format!(
            "scene_id, im_id, obj_id, score, R, t, time\n{}",
            ok_row(1, 0, 1)
        );
        assert_eq!(
            only_problem(&s),
            "bad header on line 1: expected `scene_id,im_id,obj_id,score,R,t,time`, \
             found `scene_id, im_id, obj_id, score, R, t, time`"
        );
        // A spreadsheet's CSV, separated by `;` (decimal commas and all) or tabs: said once.
        for (sep, said) in [(";", "`;`"), ("\t", "tabs")] {
            let rows: Vec<String> = (0..3)
                .map(|i| ok_row(1, i, 1).trim_end().replace(',', sep))
                .collect();
            let with_header = format!("{}\n{}\n", HEADER.replace(',', sep), rows.join("\n"));
            assert_eq!(
                only_problem(&with_header),
                format!("the file is separated by {said}; BOP result files use commas")
            );
            assert_eq!(
                only_problem(&format!("{}\n", rows.join("\n"))),
                format!("the file is separated by {said}; BOP result files use commas")
            );
        }
        let decimal_commas = "1;0;1;0,5;1 0 0 0 1 0 0 0 1;0 0 500;-1\n".repeat(3);
        assert_eq!(
            only_problem(&decimal_commas),
            "the file is separated by `;`; BOP result files use commas"
        );
        // Line 1 whose first field is a number is data.
        assert_eq!(only_problem("1.5,0,1\n"), "line 1 has 3 fields, expected 7");
        // A header later on.
        let s = format!("{}{HEADER}\n", ok_row(1, 0, 1));
        assert_eq!(
            only_problem(&s),
            "line 2 repeats the header (only line 1 may be the header)"
        );
    }

    #[test]
    fn tied_scores_keep_file_order() {
        let s = with_header(&format!(
            "{}{}{}",
            row(1, 0, 1, "0.5", IDENTITY, "0 0 1", "1"),
            row(1, 0, 1, "0.9", IDENTITY, "0 0 2", "1"),
            row(1, 0, 1, "0.5", IDENTITY, "0 0 3", "1")
        ));
        let r = parse_str(&s).unwrap();
        let mut order: Vec<&Estimate> = r.estimates.iter().collect();
        order.sort_by(|a, b| b.score.total_cmp(&a.score));
        let zs: Vec<f64> = order.iter().map(|e| e.pose.t.z).collect();
        assert_eq!(zs, [2.0, 1.0, 3.0]);
        let lines: Vec<u64> = r.estimates.iter().map(|e| e.line).collect();
        assert_eq!(lines, [2, 3, 4]);
    }

    struct FailingReader {
        sent: bool,
    }

    impl Read for FailingReader {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.sent {
                return Err(io::Error::other("disk on fire"));
            }
            self.sent = true;
            let row = format!("{HEADER}\n{}", ok_row(1, 0, 1));
            let n = row.len().min(buf.len());
            buf[..n].copy_from_slice(&row.as_bytes()[..n]);
            Ok(n)
        }
    }

    #[test]
    fn read_errors() {
        let p = parse_results(FailingReader { sent: false }).unwrap_err();
        assert_eq!(
            p.problems[0].to_string(),
            "reading line 3 failed: disk on fire"
        );

        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nothing_here-test.csv");
        match load_results(&missing) {
            Err(e @ Error::Io { .. }) => assert!(e.to_string().contains("nothing_here-test.csv")),
            other => panic!("{other:?}"),
        }
        let path = dir.path().join("m_d-test.csv");
        std::fs::write(&path, with_header(&ok_row(1, 0, 1))).unwrap();
        assert_eq!(load_results(&path).unwrap().estimates.len(), 1);
    }

    #[test]
    fn result_file_names() {
        let name = |s: &str| parse_result_filename(s).map(|r| (r.method, r.dataset, r.split));
        let t = |a: &str, b: &str, c: &str| Some((a.to_string(), b.to_string(), c.to_string()));
        assert_eq!(
            name("noisesmall_synthA-test.csv"),
            t("noisesmall", "synthA", "test")
        );
        assert_eq!(name("dir/x.y/m_lmo-test.csv"), t("m", "lmo", "test"));
        assert_eq!(name("m_ycbv-test-pbr.csv"), t("m", "ycbv", "test"));
        assert_eq!(name("m_tless-test_3.csv"), t("m", "tless", "test"));
        assert_eq!(name("m_hb-val.json.gz"), t("m", "hb", "val"));
        // bop_toolkit takes the second `_` part as DATASET-SPLIT: it must contain a `-`.
        assert_eq!(name("a_b_lmo-test.csv"), None);
        assert_eq!(name("a_b-x_lmo-test.csv"), t("a", "b", "x"));
        assert_eq!(name("method-lmo-test.csv"), None);
        assert_eq!(name("m_lmo.csv"), None);
        assert_eq!(name("m_lmo-test"), t("m", "lmo", "test"));
        assert_eq!(name(""), None);
        assert_eq!(name("dir/"), None);
    }

    #[test]
    fn quoting_escapes_control_characters() {
        assert_eq!(quote("a\tb"), "a\\tb");
    }

    // --- robustness ----------------------------------------------------------------------

    fn check_invariants(input: &[u8]) {
        match parse_results(input) {
            Ok(r) => {
                let mut last = 0;
                for e in &r.estimates {
                    assert!(e.line > last);
                    last = e.line;
                    assert!(e.score.is_finite() && e.time.is_finite());
                }
            }
            Err(p) => {
                assert!(p.total() > 0);
                assert!(p.problems.len() <= MAX_PROBLEMS);
                assert!(p.problems.windows(2).all(|w| w[0].line <= w[1].line));
                let _ = p.to_string();
            }
        }
    }

    fn token() -> impl Strategy<Value = String> {
        prop_oneof![
            Just("1".to_string()),
            Just("0".to_string()),
            Just("-1".to_string()),
            Just("+3".to_string()),
            Just("3.0".to_string()),
            Just("nan".to_string()),
            Just("-inf".to_string()),
            Just("1e-3".to_string()),
            Just(".5".to_string()),
            Just("1_0".to_string()),
            Just("4294967296".to_string()),
            Just(IDENTITY.to_string()),
            Just("0 1 0 1 0 0 0 0 1".to_string()),
            Just("1 2 3".to_string()),
            Just(HEADER.to_string()),
            Just(String::new()),
            Just(" ".to_string()),
            Just("\r".to_string()),
            Just("\u{feff}".to_string()),
            Just("é".to_string()),
            "[ -~]{0,12}",
            any::<f64>().prop_map(|x| x.to_string()),
        ]
    }

    fn line() -> impl Strategy<Value = String> {
        prop::collection::vec(token(), 0..9).prop_map(|t| t.join(","))
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
            check_invariants(&bytes);
        }

        #[test]
        fn plausible_lines_never_panic(
            lines in prop::collection::vec(line(), 0..20),
            ending in prop_oneof![Just("\n"), Just("\r\n"), Just("\r")],
        ) {
            let text = lines.join(ending);
            check_invariants(text.as_bytes());
        }

        #[test]
        fn valid_rows_always_parse(
            rows in prop::collection::vec((0u32..5, 0u32..5, 1u32..30, -10.0f64..10.0), 0..30),
        ) {
            let mut s = format!("{HEADER}\n");
            for &(scene, im, obj, score) in &rows {
                s.push_str(&row(scene, im, obj, &format!("{score:?}"), IDENTITY, "0 0 1", "0.5"));
            }
            let r = parse_results(s.as_bytes()).unwrap();
            prop_assert_eq!(r.estimates.len(), rows.len());
            for (e, &(scene, im, obj, score)) in r.estimates.iter().zip(&rows) {
                prop_assert_eq!((e.scene_id, e.im_id, e.obj_id, e.score), (scene, im, obj, score));
            }
        }
    }
}
