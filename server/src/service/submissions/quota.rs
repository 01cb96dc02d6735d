//! How many submissions a user has left on a dataset under the fair-use limit, and when the
//! next one is allowed. The upload form shows it before a researcher spends an upload, the API
//! answers it (`GET /api/v1/me/quota?dataset=`), and the CLI prints it when an upload is
//! refused: all from the store's one count of what the upload's own check counts, so the
//! number shown is the number enforced.

use serde::Serialize;

use crate::app::App;
use crate::clock::now_ms;
use crate::error::AppResult;
use crate::service::datasets::served;
use crate::store::accounts::User;
use crate::store::datasets::DatasetRow;
use crate::wording;

/// A user's fair-use quota on one dataset, now.
#[derive(Clone, Debug, Serialize)]
pub struct Quota {
    pub dataset: String,
    /// Submissions allowed per dataset within the window; `None`: no limit.
    pub limit: Option<u64>,
    /// The window, in seconds (a day by default).
    pub window_secs: u64,
    /// Submissions within the window that count (those that failed through the service's
    /// fault do not).
    pub used: u64,
    /// Submissions left now; `None`: no limit.
    pub left: Option<u64>,
    /// When none is left: when the next one is allowed, epoch milliseconds.
    pub next_at: Option<i64>,
    /// The same as a date and time, "2026-12-04 17:20 UTC" (rounded up to the minute).
    pub next_at_utc: Option<String>,
    /// In words, as the form and the CLI say it: "3 of 5 submissions left today", "none left
    /// today: the next at 2026-12-04 17:20 UTC", "no limit".
    pub summary: String,
}

impl Quota {
    fn summarise(&self) -> String {
        let within = if self.window_secs == 86_400 {
            "today".to_string()
        } else {
            format!("within {} s", self.window_secs)
        };
        match (self.limit, self.left, &self.next_at_utc) {
            (None, _, _) | (_, None, _) => "no limit".to_string(),
            (Some(_), Some(0), Some(at)) => format!("none left {within}: the next at {at}"),
            (Some(limit), Some(left), _) => format!(
                "{left} of {} left {within}",
                wording::count(limit, "submission", "submissions")
            ),
        }
    }
}

/// The moment `ms` as a date and time to the minute, rounded up: a retry at the minute shown is
/// never early.
pub fn retry_time(ms: i64) -> String {
    wording::utc_minute((ms + 59_999).div_euclid(60_000) * 60_000)
}

/// `owner`'s quota on the served dataset `name`.
pub async fn quota(app: &App, owner: &User, name: &str) -> AppResult<Quota> {
    let dataset = served(app, name, "the parameter `dataset`").await?;
    of(app, owner, &dataset).await
}

/// `owner`'s quota on every served dataset, in the catalogue's order: what the upload form
/// offers.
pub async fn every_dataset(app: &App, owner: &User) -> AppResult<Vec<(DatasetRow, Quota)>> {
    let mut out = Vec::new();
    for dataset in app.store.datasets().await? {
        let quota = of(app, owner, &dataset).await?;
        out.push((dataset, quota));
    }
    Ok(out)
}

async fn of(app: &App, owner: &User, dataset: &DatasetRow) -> AppResult<Quota> {
    let config = &app.config;
    let window_ms = config.limit_window_ms();
    let now = now_ms();
    let times = app
        .store
        .counted_times(owner.id, dataset.id, now - window_ms)
        .await?;
    let used = times.len() as u64;
    let limit = (config.submissions_per_window > 0).then_some(config.submissions_per_window);
    let left = limit.map(|l| l.saturating_sub(used));
    // The next one is allowed once the oldest of the last `limit` counted leaves the window.
    let next_at = match (limit, left) {
        (Some(l), Some(0)) => times
            .len()
            .checked_sub(l as usize)
            .and_then(|i| times.get(i))
            .map(|t| t + window_ms),
        _ => None,
    };
    let mut quota = Quota {
        dataset: dataset.name.clone(),
        limit,
        window_secs: config.limit_window_secs,
        used,
        left,
        next_at,
        next_at_utc: next_at.map(retry_time),
        summary: String::new(),
    };
    quota.summary = quota.summarise();
    Ok(quota)
}
