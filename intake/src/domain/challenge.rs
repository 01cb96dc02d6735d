//! What an administrator states when creating a challenge, parsed once at the edge: its slug
//! (in its URL), name, tasks, dataset groups, categories, deadline (RFC 3339, kept as epoch
//! milliseconds in UTC), the awards it gives and the time under which a method counts as fast.
//! Each problem names the field it came from, so the form and the API say which one to fix.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{
    BoardProtocol, DEFAULT_GROUP, FieldError, GroupName, Objects, Onboarding, optional, plain_text,
};

text_newtype!(
    /// A challenge as its URL names it (`/challenges/bop-2026`): 1 to 60 lowercase ASCII
    /// letters, digits and `-`.
    ChallengeSlug
);
text_newtype!(
    /// A challenge's title, as its page shows it: 1 to 200 visible characters.
    ChallengeName
);

impl ChallengeSlug {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        let slug = value.trim();
        if slug.is_empty()
            || slug.len() > 60
            || !slug
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
        {
            return Err(FieldError::new(
                "slug",
                "must have 1 to 60 lowercase letters, digits or `-`",
            ));
        }
        Ok(ChallengeSlug(slug.to_string()))
    }
}

impl ChallengeName {
    pub fn parse(value: &str) -> Result<Self, FieldError> {
        plain_text("name", value, 200).map(ChallengeName)
    }
}

word_enum!(
    /// An award a challenge gives, decided on its boards as they stood at the deadline.
    Award, "awards" {
        Overall = "overall",
        RgbOnly = "rgb-only",
        Fast = "fast",
        OpenSource = "open-source",
        SingleModel = "single-model",
        Synthetic = "synthetic",
        DefaultDetections = "default-detections",
    }
);

/// The time under which a method is fast when a challenge does not say: a second per image.
pub const DEFAULT_FAST_SECONDS: f64 = 1.0;

/// A challenge as its creator sends it, every field as text (the form's and the API's).
#[derive(Clone, Debug, Default, Deserialize)]
pub struct ChallengeForm {
    #[serde(default)]
    pub slug: String,
    #[serde(default)]
    pub name: String,
    /// Board protocols (`bop19`, `bop24`, `bop22-det`, ...).
    #[serde(default)]
    pub tasks: Vec<String>,
    /// Dataset group names; none: the default group.
    #[serde(default)]
    pub groups: Vec<String>,
    /// RFC 3339, e.g. `2026-10-01T23:59:00Z`.
    #[serde(default)]
    pub deadline: String,
    /// The categories filter: `seen` or `unseen`; empty: any.
    #[serde(default)]
    pub objects: String,
    /// The categories filter: `model-based` or `model-free`; empty: any.
    #[serde(default)]
    pub onboarding: String,
    /// Seconds per image under which a method is fast; none: [`DEFAULT_FAST_SECONDS`].
    pub fast_seconds: Option<f64>,
    /// The awards given; none: every award.
    pub awards: Option<Vec<String>>,
}

/// A challenge's definition, every field checked.
#[derive(Clone, Debug, PartialEq)]
pub struct ChallengeSpec {
    pub slug: ChallengeSlug,
    pub name: ChallengeName,
    pub tasks: Vec<BoardProtocol>,
    pub groups: Vec<GroupName>,
    pub objects: Option<Objects>,
    pub onboarding: Option<Onboarding>,
    /// Epoch milliseconds, UTC.
    pub deadline: i64,
    pub fast_seconds: f64,
    pub awards: Vec<Award>,
}

impl ChallengeForm {
    pub fn parse(self) -> Result<ChallengeSpec, FieldError> {
        let tasks = distinct(&self.tasks, |t| {
            BoardProtocol::named(t).ok_or_else(|| {
                let names: Vec<&str> = BoardProtocol::ALL.iter().map(|b| b.as_str()).collect();
                FieldError::new(
                    "tasks",
                    format!("names boards: `{t}` is none of {}", names.join(", ")),
                )
            })
        })?;
        if tasks.is_empty() {
            return Err(FieldError::new("tasks", "must name at least one board"));
        }
        let mut groups = distinct(&self.groups, |g| {
            GroupName::parse(g).map_err(|e| e.named("groups"))
        })?;
        if groups.is_empty() {
            groups.push(GroupName(DEFAULT_GROUP.to_string()));
        }
        let fast_seconds = self.fast_seconds.unwrap_or(DEFAULT_FAST_SECONDS);
        if !(fast_seconds.is_finite() && fast_seconds > 0.0) {
            return Err(FieldError::new(
                "fast_seconds",
                "must be a number of seconds above 0",
            ));
        }
        let awards = match &self.awards {
            None => Award::ALL.to_vec(),
            Some(named) => distinct(named, |a| a.parse::<Award>())?,
        };
        Ok(ChallengeSpec {
            slug: ChallengeSlug::parse(&self.slug)?,
            name: ChallengeName::parse(&self.name)?,
            tasks,
            groups,
            objects: optional(&self.objects)?,
            onboarding: optional(&self.onboarding)?,
            deadline: rfc3339(&self.deadline)
                .map_err(|problem| FieldError::new("deadline", problem))?,
            fast_seconds,
            awards,
        })
    }
}

/// Each of `values` parsed, without repeats, in the order given (empty values skipped).
fn distinct<T: PartialEq>(
    values: &[String],
    parse: impl Fn(&str) -> Result<T, FieldError>,
) -> Result<Vec<T>, FieldError> {
    let mut out = Vec::new();
    for v in values.iter().map(|v| v.trim()).filter(|v| !v.is_empty()) {
        let parsed = parse(v)?;
        if !out.contains(&parsed) {
            out.push(parsed);
        }
    }
    Ok(out)
}

/// An RFC 3339 date and time (`2026-10-01T23:59:00Z`, `2026-10-02T01:59:00+02:00`, seconds
/// optionally with a fraction) as epoch milliseconds in UTC.
pub fn rfc3339(value: &str) -> Result<i64, String> {
    let bad = || {
        format!(
            "must be a date and time in RFC 3339 with its offset, e.g. 2026-10-01T23:59:00Z, not `{value}`"
        )
    };
    let v = value.trim();
    let b = v.as_bytes();
    if b.len() < 20 || b[4] != b'-' || b[7] != b'-' || !matches!(b[10], b'T' | b't' | b' ') {
        return Err(bad());
    }
    if b[13] != b':' || b[16] != b':' {
        return Err(bad());
    }
    let num = |s: &str| {
        i64::from_str(s)
            .ok()
            .filter(|_| s.bytes().all(|c| c.is_ascii_digit()))
    };
    let field = |from: usize, to: usize| v.get(from..to).and_then(num).ok_or_else(bad);
    let (year, month, day) = (field(0, 4)?, field(5, 7)?, field(8, 10)?);
    let (hour, minute, second) = (field(11, 13)?, field(14, 16)?, field(17, 19)?);
    let mut rest = &v[19..];
    let mut millis = 0;
    if let Some(fraction) = rest.strip_prefix('.') {
        let digits = fraction.bytes().take_while(u8::is_ascii_digit).count();
        if digits == 0 {
            return Err(bad());
        }
        let kept: String = fraction[..digits]
            .chars()
            .chain("00".chars())
            .take(3)
            .collect();
        millis = num(&kept).ok_or_else(bad)?;
        rest = &fraction[digits..];
    }
    let offset_minutes = match rest {
        "Z" | "z" => 0,
        _ if rest.len() == 6 && matches!(&rest[..1], "+" | "-") && &rest[3..4] == ":" => {
            let (h, m) = (
                num(&rest[1..3]).ok_or_else(bad)?,
                num(&rest[4..6]).ok_or_else(bad)?,
            );
            if h > 23 || m > 59 {
                return Err(bad());
            }
            let sign = if rest.starts_with('-') { -1 } else { 1 };
            sign * (h * 60 + m)
        }
        _ => return Err(bad()),
    };
    let leap = year % 4 == 0 && (year % 100 != 0 || year % 400 == 0);
    let days_in_month = match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return Err(bad()),
    };
    if day < 1 || day > days_in_month || hour > 23 || minute > 59 || second > 60 {
        return Err(bad());
    }
    let seconds =
        days_from_civil(year, month, day) * 86_400 + hour * 3600 + minute * 60 + second.min(59)
            - offset_minutes * 60;
    Ok(seconds * 1000 + millis)
}

/// A proleptic Gregorian date to days since 1970-01-01 (H. Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y.rem_euclid(400);
    let mp = if m > 2 { m - 3 } else { m + 9 };
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadlines_read_as_rfc_3339() {
        assert_eq!(rfc3339("1970-01-01T00:00:00Z"), Ok(0));
        // 2026-12-01 15:13 UTC, as `wording` writes it.
        assert_eq!(rfc3339("2026-12-01T15:13:20Z"), Ok(1_796_138_000_000));
        assert_eq!(rfc3339("2026-12-01T17:13:20+02:00"), Ok(1_796_138_000_000));
        assert_eq!(rfc3339("2026-12-01T15:13:20.25Z"), Ok(1_796_138_000_250));
        assert_eq!(rfc3339("2024-02-29T00:00:00Z"), Ok(1_709_164_800_000));
        for bad in [
            "",
            "2026-12-01",
            "2026-12-01T15:13:20",
            "2026-13-01T00:00:00Z",
            "2025-02-29T00:00:00Z",
            "2026-12-01T24:00:00Z",
            "2026-12-01T15:13:20+2:00",
            "tomorrow at noon",
        ] {
            assert!(rfc3339(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_challenge_form_names_the_field_at_fault() {
        let good = ChallengeForm {
            slug: "bop-2026".into(),
            name: "BOP Challenge 2026".into(),
            tasks: vec!["bop19".into(), "bop24".into(), "bop19".into()],
            groups: Vec::new(),
            deadline: "2026-10-01T23:59:00Z".into(),
            ..ChallengeForm::default()
        };
        let spec = good.clone().parse().unwrap();
        assert_eq!(spec.tasks.len(), 2);
        assert_eq!(spec.groups[0].as_str(), DEFAULT_GROUP);
        assert_eq!(spec.awards, Award::ALL.to_vec());
        assert_eq!(spec.fast_seconds, DEFAULT_FAST_SECONDS);
        let field_of = |form: ChallengeForm| form.parse().unwrap_err().field;
        assert_eq!(
            field_of(ChallengeForm {
                slug: "BOP 2026".into(),
                ..good.clone()
            }),
            "slug"
        );
        assert_eq!(
            field_of(ChallengeForm {
                tasks: vec!["bop99".into()],
                ..good.clone()
            }),
            "tasks"
        );
        assert_eq!(
            field_of(ChallengeForm {
                deadline: "next week".into(),
                ..good.clone()
            }),
            "deadline"
        );
        assert_eq!(
            field_of(ChallengeForm {
                awards: Some(vec!["prettiest".into()]),
                ..good.clone()
            }),
            "awards"
        );
        assert_eq!(
            field_of(ChallengeForm {
                fast_seconds: Some(0.0),
                ..good
            }),
            "fast_seconds"
        );
    }
}
