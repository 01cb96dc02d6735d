//! Numbers, waits and places in the queue as a reader says them: "1 estimate", "in 23 h 57 min
//! (2026-12-02 15:10 UTC)", "2 submissions ahead of yours; 1 being evaluated now". One place,
//! so the pages, the JSON and the command line word them alike.

/// `n` and the noun, singular for exactly one (any integer type).
pub fn count(n: impl std::fmt::Display, one: &str, many: &str) -> String {
    let n = n.to_string();
    if n == "1" {
        format!("1 {one}")
    } else {
        format!("{n} {many}")
    }
}

/// A span of `seconds` in at most two units, rounded up: "3 s", "4 min 10 s", "23 h 57 min".
pub fn duration(seconds: f64) -> String {
    let s = seconds.max(0.0).ceil() as i64;
    let (h, m, sec) = (s / 3600, s % 3600 / 60, s % 60);
    if h > 0 {
        format!("{h} h {m} min")
    } else if m > 0 {
        format!("{m} min {sec} s")
    } else {
        format!("{} s", sec.max(1))
    }
}

/// A wait of `seconds` from now: "in 3 s", "in 23 h 57 min".
pub fn wait(seconds: f64) -> String {
    format!("in {}", duration(seconds))
}

/// A wait and the time it ends: "in 23 h 57 min (2026-12-02 15:10 UTC)".
pub fn wait_until(seconds: f64, now_ms: i64) -> String {
    let at = now_ms + (seconds.max(0.0) * 1000.0).ceil() as i64;
    format!("{} ({})", wait(seconds), utc_minute(at))
}

/// Epoch milliseconds as "2026-12-02 15:10 UTC".
pub fn utc_minute(ms: i64) -> String {
    let secs = ms.div_euclid(1000);
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60
    )
}

/// Epoch milliseconds as RFC 3339 in UTC to the second, "2026-12-02T15:10:05Z": the dates of
/// a feed, which readers parse.
pub fn rfc3339(ms: i64) -> String {
    let secs = ms.div_euclid(1000);
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Days since 1970-01-01 to a proleptic Gregorian date (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Where a queued submission stands: "2 submissions ahead of yours; 1 being evaluated now".
pub fn queue_place(queued_ahead: i64, running: i64) -> String {
    let ahead = match queued_ahead {
        0 => "next in the queue".to_string(),
        n => format!("{} ahead of yours", count(n, "submission", "submissions")),
    };
    match running {
        0 => ahead,
        n => format!("{ahead}; {n} being evaluated now"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_words() {
        assert_eq!(count(1, "estimate", "estimates"), "1 estimate");
        assert_eq!(count(2, "estimate", "estimates"), "2 estimates");
        assert_eq!(count(0, "estimate", "estimates"), "0 estimates");
        assert_eq!(wait(0.2), "in 1 s");
        assert_eq!(wait(250.0), "in 4 min 10 s");
        assert_eq!(wait(86_220.0), "in 23 h 57 min");
        // 2026-12-01 15:13 UTC plus 23 h 57 min.
        let now = 1_796_138_000_000;
        assert_eq!(utc_minute(now), "2026-12-01 15:13 UTC");
        assert_eq!(rfc3339(now + 5_999), "2026-12-01T15:13:25Z");
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(
            wait_until(86_220.0, now),
            "in 23 h 57 min (2026-12-02 15:10 UTC)"
        );
        assert_eq!(
            queue_place(2, 1),
            "2 submissions ahead of yours; 1 being evaluated now"
        );
        assert_eq!(queue_place(1, 0), "1 submission ahead of yours");
        assert_eq!(
            queue_place(0, 1),
            "next in the queue; 1 being evaluated now"
        );
    }
}
