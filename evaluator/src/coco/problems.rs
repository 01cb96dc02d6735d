//! What can be wrong with a BOP'22 result file, each problem with its entry: kept apart from the
//! parser so that the crate's error type can carry them without depending on the parser.

use std::fmt;

use crate::results::problems::MAX_PROBLEMS;

/// A problem of one entry (or of the file, when `entry` is `None`).
#[derive(Clone, Debug, PartialEq)]
pub struct EntryProblem {
    pub entry: Option<usize>,
    pub key: Option<&'static str>,
    pub message: String,
}

impl fmt::Display for EntryProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.entry, self.key) {
            (Some(i), Some(k)) => write!(f, "entry {i}, `{k}`: {}", self.message),
            (Some(i), None) => write!(f, "entry {i}: {}", self.message),
            (None, _) => write!(f, "{}", self.message),
        }
    }
}

/// The problems of a result file, in entry order: at most [`MAX_PROBLEMS`], the rest counted.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct EntryProblems {
    pub problems: Vec<EntryProblem>,
    pub omitted: usize,
}

impl EntryProblems {
    pub fn total(&self) -> usize {
        self.problems.len() + self.omitted
    }

    pub fn is_empty(&self) -> bool {
        self.total() == 0
    }

    pub(super) fn push(
        &mut self,
        entry: Option<usize>,
        key: Option<&'static str>,
        message: String,
    ) {
        if self.problems.len() < MAX_PROBLEMS {
            self.problems.push(EntryProblem {
                entry,
                key,
                message,
            });
        } else {
            self.omitted += 1;
        }
    }
}

impl fmt::Display for EntryProblems {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let total = self.total();
        let s = if total == 1 { "" } else { "s" };
        write!(
            f,
            "the result file has {total} problem{s} (entries counted from 0):"
        )?;
        for p in &self.problems {
            write!(f, "\n  {p}")?;
        }
        if self.omitted > 0 {
            write!(f, "\n  ... and {} more", self.omitted)?;
        }
        Ok(())
    }
}
