//! Teams over HTTP: the team page and its JSON twin, the account page's and the team page's
//! forms (each with the session's CSRF token), and the API calls scripts rely on:
//! `POST /api/v1/teams {name}`, `POST /api/v1/teams/{name}/invitations {user}`,
//! `POST /api/v1/teams/{name}/accept`, `POST /api/v1/teams/{name}/leave` and
//! `POST /api/v1/teams/{name}/members/{user}/remove`.

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::{Form, Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::app::AppState;
use crate::domain::{TeamName, UserName};
use crate::error::AppResult;
use crate::service::teams::{self, TeamHome};
use crate::store::methods::MethodRow;
use crate::store::teams::{MemberRow, TeamRow};
use crate::web::auth::Viewer;
use crate::web::routes::pages::filters;
use crate::web::views;

/// The team page and the forms of the account and team pages.
pub fn page_router() -> Router<AppState> {
    Router::new()
        .route("/teams", post(create_form))
        .route("/teams/{name}", get(page))
        .route("/teams/{name}/invitations", post(invite_form))
        .route("/teams/{name}/accept", post(accept_form))
        .route("/teams/{name}/leave", post(leave_form))
        .route("/teams/{name}/members/{user}/remove", post(remove_form))
}

/// Their JSON twins.
pub fn api_router() -> Router<AppState> {
    Router::new()
        .route("/api/v1/teams", post(create))
        .route("/api/v1/teams/{name}", get(team_json))
        .route("/api/v1/teams/{name}/invitations", post(invite))
        .route("/api/v1/teams/{name}/accept", post(accept))
        .route("/api/v1/teams/{name}/leave", post(leave))
        .route("/api/v1/teams/{name}/members/{user}/remove", post(remove))
}

/// A team as its page and JSON show it.
#[derive(Template, WebTemplate, Serialize)]
#[template(path = "team.html")]
pub struct TeamPage {
    pub team: TeamRow,
    pub members: Vec<MemberRow>,
    pub methods: Vec<MethodRow>,
    /// The reader is a member.
    pub member: bool,
    /// The reader may remove members (the creator or an administrator).
    pub may_remove: bool,
    /// The session's CSRF token for the page's forms (a signed-in browser only).
    #[serde(skip)]
    csrf: Option<String>,
}

impl TeamPage {
    fn of(home: TeamHome, viewer: &Viewer) -> TeamPage {
        TeamPage {
            team: home.team,
            members: home.members,
            methods: home.methods,
            member: home.member,
            may_remove: home.may_remove,
            csrf: viewer.session.as_ref().map(|s| s.csrf_token.clone()),
        }
    }
}

async fn page(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<TeamPage> {
    let name = TeamName::parse("team", &name)?;
    let home = teams::home(&app, &name, viewer.user.as_ref()).await?;
    Ok(TeamPage::of(home, &viewer))
}

async fn team_json(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<TeamPage>> {
    let name = TeamName::parse("team", &name)?;
    let home = teams::home(&app, &name, viewer.user.as_ref()).await?;
    Ok(Json(TeamPage::of(home, &viewer)))
}

fn team_url(name: &TeamName) -> String {
    format!("/teams/{}", views::urlencode(name.as_str()))
}

#[derive(Deserialize)]
struct NewTeam {
    #[serde(default)]
    name: String,
}

/// `POST /api/v1/teams {name}`: 201 with the team.
async fn create(
    State(app): State<AppState>,
    viewer: Viewer,
    Json(body): Json<NewTeam>,
) -> AppResult<Response> {
    let user = viewer.require_user()?;
    let name = TeamName::parse("name", &body.name)?;
    let team = teams::create(&app, user, &name).await?;
    let body = json!({ "team": team, "url": team_url(&name) });
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

#[derive(Deserialize)]
struct Invitation {
    #[serde(default)]
    user: String,
}

async fn invite(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Json(body): Json<Invitation>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?;
    let (name, invitee) = (
        TeamName::parse("team", &name)?,
        UserName::parse(&body.user).map_err(|e| e.named("user"))?,
    );
    teams::invite(&app, user, &name, &invitee).await?;
    Ok(Json(
        json!({ "ok": true, "team": name, "invited": invitee }),
    ))
}

async fn accept(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?;
    let name = TeamName::parse("team", &name)?;
    let team = teams::accept(&app, user, &name).await?;
    Ok(Json(json!({ "ok": true, "team": team })))
}

async fn leave(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?;
    let name = TeamName::parse("team", &name)?;
    teams::leave(&app, user, &name).await?;
    Ok(Json(json!({ "ok": true, "team": name, "left": user.name })))
}

async fn remove(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((name, member)): Path<(String, String)>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?;
    let (name, member) = (
        TeamName::parse("team", &name)?,
        UserName::parse(&member).map_err(|e| e.named("user"))?,
    );
    teams::remove(&app, user, &name, &member).await?;
    Ok(Json(json!({ "ok": true, "team": name, "removed": member })))
}

/// A form of the account or team page: the CSRF token, and the name it asks for if any.
#[derive(Deserialize)]
struct TeamForm {
    #[serde(default)]
    csrf: String,
    #[serde(default)]
    name: String,
    #[serde(default)]
    user: String,
}

async fn create_form(
    State(app): State<AppState>,
    viewer: Viewer,
    Form(f): Form<TeamForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    let name = TeamName::parse("name", &f.name)?;
    teams::create(&app, user, &name).await?;
    Ok(Redirect::to(&team_url(&name)).into_response())
}

async fn invite_form(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<TeamForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    let (name, invitee) = (
        TeamName::parse("team", &name)?,
        UserName::parse(&f.user).map_err(|e| e.named("user"))?,
    );
    teams::invite(&app, user, &name, &invitee).await?;
    Ok(Redirect::to(&team_url(&name)).into_response())
}

async fn accept_form(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<TeamForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    let name = TeamName::parse("team", &name)?;
    teams::accept(&app, user, &name).await?;
    Ok(Redirect::to(&team_url(&name)).into_response())
}

async fn leave_form(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<TeamForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    let name = TeamName::parse("team", &name)?;
    teams::leave(&app, user, &name).await?;
    Ok(Redirect::to("/account").into_response())
}

async fn remove_form(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((name, member)): Path<(String, String)>,
    Form(f): Form<TeamForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    let (name, member) = (
        TeamName::parse("team", &name)?,
        UserName::parse(&member).map_err(|e| e.named("user"))?,
    );
    teams::remove(&app, user, &name, &member).await?;
    Ok(Redirect::to(&team_url(&name)).into_response())
}
