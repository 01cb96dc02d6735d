//! The one error type of the evaluator. Every variant names the file (and the field or line)
//! that is wrong, because the person reading the message has only their files to go on.

use std::path::PathBuf;

use crate::coco::problems::EntryProblems;
use crate::results::problems::Problems;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file exists but its content cannot be used; `message` names the field or position.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// A result file with line-numbered problems.
    #[error("{0}")]
    Results(Problems),
    /// A JSON (BOP'22 detection or segmentation) result file with entry-numbered problems.
    #[error("{0}")]
    CocoResults(EntryProblems),
    /// Protocol parameters that make no sense (e.g. an empty list of thresholds).
    #[error("invalid parameters: {0}")]
    Parameters(String),
    #[error("evaluation cancelled")]
    Cancelled,
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}
