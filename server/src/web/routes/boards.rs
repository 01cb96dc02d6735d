//! Leaderboard answers (the HTML pages and their JSON twins) served from the board cache: the
//! cached bytes go out as they are, gzipped ones to clients that accept gzip (with the cache
//! off, the compression layer gzips each answer as it goes out).

use std::future::Future;

use crate::domain::BoardProtocol;
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};

use crate::app::App;
use crate::board_cache::{BoardKey, Format};
use crate::error::AppResult;
use crate::service::leaderboard;
use crate::web::views::BoardFilter;

/// The cache key of a board query.
pub fn key(format: Format, protocol: BoardProtocol, q: &BoardFilter) -> BoardKey {
    BoardKey {
        format,
        protocol,
        query: [
            q.dataset.clone(),
            q.sort.clone(),
            q.training.clone(),
            q.modality.clone(),
            q.curves.clone(),
            q.objects.clone(),
            q.onboarding.clone(),
            q.group.clone(),
        ],
    }
}

/// The board of `key`, from the cache or rendered by `render`.
pub async fn answer<F, Fut>(
    app: &App,
    headers: &HeaderMap,
    key: BoardKey,
    render: F,
) -> AppResult<Response>
where
    F: FnOnce() -> Fut,
    Fut: Future<Output = AppResult<Vec<u8>>>,
{
    let content_type = match key.format {
        Format::Html => "text/html; charset=utf-8",
        Format::Json => "application/json",
    };
    let rendered = leaderboard::cached(app, key, render).await?;
    let mut response = match &rendered.gzip {
        Some(gzip) if accepts_gzip(headers) => {
            let mut r = gzip.clone().into_response();
            r.headers_mut()
                .insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
            r
        }
        _ => rendered.body.clone().into_response(),
    };
    let h = response.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(header::VARY, HeaderValue::from_static("accept-encoding"));
    Ok(response)
}

/// Whether `Accept-Encoding` takes gzip (by name or `*`, with a non-zero quality).
pub(crate) fn accepts_gzip(headers: &HeaderMap) -> bool {
    headers
        .get_all(header::ACCEPT_ENCODING)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|item| {
            let mut parts = item.split(';').map(str::trim);
            let name = parts.next().unwrap_or_default();
            let zero = parts.any(|p| {
                p.strip_prefix("q=")
                    .and_then(|q| q.parse::<f32>().ok())
                    .is_some_and(|q| q <= 0.0)
            });
            (name.eq_ignore_ascii_case("gzip") || name == "*") && !zero
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(
            header::ACCEPT_ENCODING,
            HeaderValue::from_str(value).expect("header value"),
        );
        h
    }

    #[test]
    fn gzip_is_taken_only_when_offered() {
        assert!(accepts_gzip(&with("gzip, deflate, br")));
        assert!(accepts_gzip(&with("br;q=1.0, gzip;q=0.8")));
        assert!(accepts_gzip(&with("*")));
        assert!(!accepts_gzip(&with("gzip;q=0")));
        assert!(!accepts_gzip(&with("br, deflate")));
        assert!(!accepts_gzip(&HeaderMap::new()));
    }
}
