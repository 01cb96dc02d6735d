//! Registration, signing in and out, personal API tokens, and the account's teams and the
//! invitations waiting for it (their forms post to the team routes).

use askama::Template;
use askama_web::WebTemplate;
use axum::Router;
use std::net::SocketAddr;

use axum::extract::{ConnectInfo, Form, Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum_extra::extract::cookie::{Cookie, CookieJar};
use serde::Deserialize;

use crate::app::AppState;
use crate::domain::{Password, TokenLabel, UserName};
use crate::error::{AppError, AppResult};
use crate::service::accounts;
use crate::store::accounts::TokenRow;
use crate::store::teams::{InvitationRow, TeamRow};
use crate::web::auth::{self, SESSION_COOKIE, Viewer};
use crate::web::routes::pages::{filters, site_url};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/login", get(login_form).post(login))
        .route("/register", get(register_form).post(register))
        .route("/logout", post(logout))
        .route("/account", get(account))
        .route("/account/tokens", post(create_token))
        .route("/account/tokens/{id}/revoke", post(revoke_token))
}

#[derive(Template, WebTemplate, Default)]
#[template(path = "login.html")]
struct LoginPage {
    register: bool,
    name: String,
    next: String,
    error: Option<String>,
}

#[derive(Deserialize, Default)]
struct NextQuery {
    next: Option<String>,
}

/// Only paths of this site are followed after signing in (no open redirect): one leading `/`
/// not followed by another or by a backslash (`//host` and `/\host` name another host), and only
/// visible ASCII, so no backslash, space or control character (browsers drop tabs and newlines,
/// turning `/\t/host` into `//host`) and nothing a `Location` header cannot hold.
fn safe_next(next: Option<&str>) -> String {
    match next {
        Some(n)
            if n.starts_with('/')
                && !n.starts_with("//")
                && n.bytes().all(|b| b.is_ascii_graphic() && b != b'\\') =>
        {
            n.to_string()
        }
        _ => "/account".to_string(),
    }
}

async fn login_form(Query(q): Query<NextQuery>) -> LoginPage {
    LoginPage {
        next: safe_next(q.next.as_deref()),
        ..LoginPage::default()
    }
}

async fn register_form(Query(q): Query<NextQuery>) -> LoginPage {
    LoginPage {
        register: true,
        next: safe_next(q.next.as_deref()),
        ..LoginPage::default()
    }
}

#[derive(Deserialize)]
struct Credentials {
    name: String,
    password: String,
    next: Option<String>,
}

async fn login(
    State(app): State<AppState>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    jar: CookieJar,
    Form(c): Form<Credentials>,
) -> AppResult<Response> {
    if !auth::same_origin(&headers) {
        return Err(AppError::Forbidden("cross-site sign-in refused".into()));
    }
    let next = safe_next(c.next.as_deref());
    let Some(secret) = accounts::open_session(&app, &c.name, &c.password, peer.ip()).await? else {
        let page = LoginPage {
            name: c.name,
            next,
            error: Some("unknown name or wrong password".into()),
            ..LoginPage::default()
        };
        return Ok((StatusCode::UNAUTHORIZED, page).into_response());
    };
    Ok(signed_in(secret, &headers, jar, &next))
}

/// The browser is signed in with the session `secret`: its cookie, and on to `next`.
fn signed_in(secret: String, headers: &HeaderMap, jar: CookieJar, next: &str) -> Response {
    let jar = jar
        .add(auth::session_cookie(secret, headers))
        .add(auth::signed_in_cookie(headers));
    (jar, Redirect::to(next)).into_response()
}

async fn register(
    State(app): State<AppState>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    jar: CookieJar,
    Form(c): Form<Credentials>,
) -> AppResult<Response> {
    if !auth::same_origin(&headers) {
        return Err(AppError::Forbidden(
            "cross-site registration refused".into(),
        ));
    }
    let next = safe_next(c.next.as_deref());
    let refuse = |status, problem: String| {
        let page = LoginPage {
            register: true,
            name: c.name.trim().to_string(),
            next: next.clone(),
            error: Some(problem),
        };
        Ok((status, page).into_response())
    };
    let parsed = UserName::parse(&c.name).and_then(|n| Ok((n, Password::parse(&c.password)?)));
    let (name, password) = match parsed {
        Ok(p) => p,
        Err(e) => return refuse(StatusCode::UNPROCESSABLE_ENTITY, e.problem_sentence()),
    };
    let secret = match accounts::open_account(&app, &name, &password, peer.ip()).await {
        Ok(secret) => secret,
        Err(AppError::Conflict(msg)) => return refuse(StatusCode::CONFLICT, msg),
        Err(e) => return Err(e),
    };
    Ok(signed_in(secret, &headers, jar, &next))
}

#[derive(Deserialize)]
struct CsrfForm {
    /// Missing counts as wrong: refused with 403 like a forged one.
    #[serde(default)]
    csrf: String,
    #[serde(default)]
    name: String,
}

async fn logout(
    State(app): State<AppState>,
    viewer: Viewer,
    jar: CookieJar,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    viewer.check_csrf(&f.csrf)?;
    if let Some(cookie) = jar.get(SESSION_COOKIE) {
        accounts::close_session(&app, cookie.value()).await?;
    }
    let jar = jar
        .remove(Cookie::build(SESSION_COOKIE).path("/"))
        .remove(Cookie::build(auth::SIGNED_IN_COOKIE).path("/"));
    Ok((jar, Redirect::to("/")).into_response())
}

#[derive(Template, WebTemplate)]
#[template(path = "account.html")]
struct AccountPage {
    name: String,
    csrf: String,
    tokens: Vec<TokenRow>,
    teams: Vec<TeamRow>,
    invitations: Vec<InvitationRow>,
    /// A token just created: shown this once, never again.
    new_token: Option<String>,
    /// This service's address, so that the `curl` example runs as copied.
    site: String,
}

async fn account_page(
    app: &AppState,
    viewer: &Viewer,
    headers: &HeaderMap,
    new_token: Option<String>,
) -> AppResult<Response> {
    let Some(session) = &viewer.session else {
        return Ok(Redirect::to("/login?next=/account").into_response());
    };
    let home = accounts::home(app, &session.user).await?;
    Ok(AccountPage {
        name: session.user.name.clone(),
        csrf: session.csrf_token.clone(),
        tokens: home.tokens,
        teams: home.teams,
        invitations: home.invitations,
        new_token,
        site: site_url(app, headers),
    }
    .into_response())
}

async fn account(
    State(app): State<AppState>,
    viewer: Viewer,
    headers: HeaderMap,
) -> AppResult<Response> {
    account_page(&app, &viewer, &headers, None).await
}

async fn create_token(
    State(app): State<AppState>,
    viewer: Viewer,
    headers: HeaderMap,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?.clone();
    let label = TokenLabel::parse(&f.name)?;
    let token = accounts::new_token(&app, &user, &label).await?;
    account_page(&app, &viewer, &headers, Some(token)).await
}

async fn revoke_token(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<i64>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?.clone();
    accounts::revoke_token(&app, &user, id).await?;
    Ok(Redirect::to("/account").into_response())
}
