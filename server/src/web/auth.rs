//! Who is asking: a browser with a session cookie, a script with a personal API token
//! (`Authorization: Bearer TOKEN`), or nobody; and the session cookie and CSRF checks of the
//! browser's forms.

use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::{HeaderMap, Method, header};
use axum_extra::extract::cookie::{Cookie, CookieJar, SameSite};

use crate::app::AppState;
use crate::domain::UserId;
use crate::error::{AppError, AppResult};
use crate::service::accounts::{self, same_secret};
use crate::service::visibility;
use crate::store::accounts::{Session, User};

pub const SESSION_COOKIE: &str = "pb_session";

/// A cookie that only says "signed in" (no secret, readable by the pages' script), so that the
/// menu of pages served the same to every reader (the cached boards) can offer a signed-in
/// browser its submissions and account, and anyone else Sign in and Register. It comes and goes
/// with the session cookie; it grants nothing.
pub const SIGNED_IN_COOKIE: &str = "pb_signed_in";

/// Whether a form post comes from our own pages. Browsers send `Origin` with every form post;
/// a post whose origin names another host is cross-site (login CSRF and the like). Requests
/// without `Origin` come from scripts, which cannot ride on a victim's cookies.
pub fn same_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok()) else {
        return true;
    };
    let host = headers
        .get(header::HOST)
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default();
    origin
        .split_once("://")
        .is_some_and(|(_, rest)| rest.trim_end_matches('/') == host)
}

/// The header a page's scripts send the session's CSRF token in, for the JSON API.
pub const CSRF_HEADER: &str = "x-csrf-token";

/// Whether a browser session may act on this request. Forms carry their CSRF token in the body
/// (checked by [`Viewer::check_csrf`]); on the JSON API, a request that changes something counts
/// the session cookie only together with the session's CSRF token in `X-CSRF-Token` and an
/// `Origin` of this host, since SameSite=Lax still sends the cookie from sibling origins (other
/// ports and subdomains). Scripts use bearer tokens instead, which no other site can send.
fn session_may_act(parts: &Parts, session: &Session) -> bool {
    let changes = !matches!(parts.method, Method::GET | Method::HEAD | Method::OPTIONS);
    if !changes || !parts.uri.path().starts_with("/api/") {
        return true;
    }
    let token = parts.headers.get(CSRF_HEADER).and_then(|v| v.to_str().ok());
    token.is_some_and(|t| same_secret(&session.csrf_token, t))
        && parts.headers.contains_key(header::ORIGIN)
        && same_origin(&parts.headers)
}

/// The requester.
#[derive(Clone, Debug, Default)]
pub struct Viewer {
    pub user: Option<User>,
    /// Present for a signed-in browser; its CSRF token guards every form.
    pub session: Option<Session>,
}

impl Viewer {
    pub fn require_user(&self) -> AppResult<&User> {
        self.user.as_ref().ok_or_else(|| {
            AppError::Unauthorized(
                "sign in, or send an API token as `Authorization: Bearer TOKEN`".into(),
            )
        })
    }

    /// Checks the CSRF token a form sent against the session's.
    pub fn check_csrf(&self, sent: &str) -> AppResult<&User> {
        match &self.session {
            Some(s) if same_secret(&s.csrf_token, sent) => Ok(&s.user),
            Some(_) => Err(AppError::Forbidden(
                "the form is stale or forged: reload the page and try again".into(),
            )),
            None => Err(AppError::Unauthorized("sign in first".into())),
        }
    }

    pub fn csrf_token(&self) -> String {
        self.session
            .as_ref()
            .map(|s| s.csrf_token.clone())
            .unwrap_or_default()
    }

    /// Whether this viewer may see something owned by `owner` (admins see everything).
    pub fn can_see(&self, owner: Option<UserId>) -> bool {
        visibility::sees_private(self.user.as_ref(), owner)
    }
}

impl FromRequestParts<AppState> for Viewer {
    type Rejection = AppError;

    async fn from_request_parts(
        parts: &mut Parts,
        app: &AppState,
    ) -> Result<Self, Self::Rejection> {
        // Already worked out by a layer in front of the handler (the admin routes' guard).
        if let Some(viewer) = parts.extensions.get::<Viewer>() {
            return Ok(viewer.clone());
        }
        if let Some(value) = parts.headers.get(header::AUTHORIZATION) {
            let token = value
                .to_str()
                .ok()
                .and_then(|v| v.strip_prefix("Bearer "))
                .map(str::trim)
                .ok_or_else(|| AppError::Unauthorized("malformed Authorization header".into()))?;
            let user = accounts::token_user(app, token).await?;
            return Ok(Viewer {
                user: Some(user),
                session: None,
            });
        }
        let jar = CookieJar::from_headers(&parts.headers);
        if let Some(cookie) = jar.get(SESSION_COOKIE)
            && let Some(session) = accounts::session(app, cookie.value()).await?
            && session_may_act(parts, &session)
        {
            return Ok(Viewer {
                user: Some(session.user.clone()),
                session: Some(session),
            });
        }
        Ok(Viewer::default())
    }
}

/// The session cookie: HttpOnly, SameSite=Lax, and Secure when the request came over TLS
/// (directly or through a proxy that says so). It lives as long as the browser session; the
/// server forgets it after [`accounts::SESSION_TTL_MS`] in any case.
pub fn session_cookie(secret: String, headers: &HeaderMap) -> Cookie<'static> {
    Cookie::build((SESSION_COOKIE, secret))
        .path("/")
        .http_only(true)
        .same_site(SameSite::Lax)
        .secure(over_tls(headers))
        .build()
}

/// The [`SIGNED_IN_COOKIE`] set beside a new session cookie, with the same lifetime.
pub fn signed_in_cookie(headers: &HeaderMap) -> Cookie<'static> {
    Cookie::build((SIGNED_IN_COOKIE, "1"))
        .path("/")
        .same_site(SameSite::Lax)
        .secure(over_tls(headers))
        .build()
}

/// Whether the request came over TLS (directly or through a proxy that says so).
fn over_tls(headers: &HeaderMap) -> bool {
    headers
        .get("x-forwarded-proto")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.eq_ignore_ascii_case("https"))
}
