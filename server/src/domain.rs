//! Values that come from outside (forms, the API, the command line), parsed and checked once at
//! the edge. Past the edge, a `MethodName` or a `Visibility` is known to be valid, so the
//! services and the store never re-check or re-interpret strings.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use unicode_normalization::UnicodeNormalization;

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
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
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

/// An optional enumerated field: empty means not given.
pub fn optional<T: FromStr<Err = FieldError>>(value: &str) -> Result<Option<T>, FieldError> {
    let value = value.trim().to_lowercase();
    if value.is_empty() {
        Ok(None)
    } else {
        value.parse().map(Some)
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
