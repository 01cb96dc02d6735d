//! The HTML pages: leaderboards, methods, submissions, the upload form. Each renders the same
//! view as its JSON twin under `/api/v1`.

use askama::Template;
use askama_web::WebTemplate;
use axum::Router;
use axum::extract::multipart::MultipartRejection;
use axum::extract::{DefaultBodyLimit, Form, Multipart, Path, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::from_fn;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use evaluator::Report;
use evaluator::protocol::ProtocolName;
use serde::Deserialize;

use crate::app::{App, AppState};
use crate::board_cache::Format;
use crate::domain::{
    BoardProtocol, DEFAULT_GROUP, FileKind, MethodForm, MethodId, Modality, ModelScope, Objects,
    Onboarding, SnapshotId, SubmissionId, TrainingData, UploadTask, Visibility,
};
use crate::error::{AppError, AppResult};
use crate::service::catalogue::ServedDataset;
use crate::service::groups::{self, Group};
use crate::service::leaderboard::Standing;
use crate::service::submission_details::Owned;
use crate::service::submissions;
use crate::service::submissions::quota::{self, Quota};
use crate::service::{catalogue, methods, publishing};
use crate::store::datasets::DatasetRow;
use crate::store::methods::MethodRow;
use crate::store::preparations::{PreparationRow, PreparationState};
use crate::store::submissions::Fault;
use crate::web::auth::Viewer;
use crate::web::error::ErrorBody;
use crate::web::routes::boards;
use crate::web::routes::deadlines;
use crate::web::routes::submissions::read_upload;
use crate::web::views::targets;
use crate::web::views::{self, BoardFilter, Leaderboard, MySubmissions, SubmissionView};

pub fn router(max_upload: u64) -> Router<AppState> {
    Router::new()
        .route("/", get(home))
        .route("/leaderboards/{protocol}", get(leaderboard))
        .route("/datasets", get(datasets))
        .route("/groups", get(dataset_groups))
        .route("/methods/{id}", get(method).post(edit_method))
        .route("/methods/{id}/reveal", post(reveal_method))
        .route("/submissions/{id}", get(submission))
        .route("/submissions/{id}/pin", post(pin))
        .route("/submissions/{id}/unpin", post(unpin))
        .route("/submissions/{id}/visibility", post(change_visibility))
        .route("/submissions/{id}/delete", post(delete_submission))
        .route("/me/submissions", get(my_submissions))
        .route(
            "/submit",
            get(submit_form).merge(
                post(submit)
                    .layer(DefaultBodyLimit::max(max_upload as usize + 64 * 1024))
                    .layer(from_fn(deadlines::by_progress)),
            ),
        )
}

/// Formats scores and times for the templates.
pub(crate) mod filters {
    #[askama::filter_fn]
    pub fn pct(v: &f64, _: &dyn askama::Values) -> askama::Result<String> {
        Ok(format!("{:.1}", v * 100.0))
    }

    /// A score that may be missing, whether the template holds it or computed it.
    pub trait MaybeScore {
        fn get(&self) -> Option<f64>;
    }
    impl MaybeScore for Option<f64> {
        fn get(&self) -> Option<f64> {
            *self
        }
    }
    impl MaybeScore for &Option<f64> {
        fn get(&self) -> Option<f64> {
            **self
        }
    }
    /// A mean that is NaN when nothing was counted (bop24's mAPs) is missing too.
    impl MaybeScore for f64 {
        fn get(&self) -> Option<f64> {
            Some(*self).filter(|v| v.is_finite())
        }
    }
    impl MaybeScore for &f64 {
        fn get(&self) -> Option<f64> {
            (*self).get()
        }
    }

    #[askama::filter_fn]
    pub fn opt_pct(v: impl MaybeScore, _: &dyn askama::Values) -> askama::Result<String> {
        Ok(v.get()
            .map_or("–".to_string(), |v| format!("{:.1}", v * 100.0)))
    }

    /// A time in seconds; missing or negative (bop_toolkit's -1: not measured) shows as "–".
    #[askama::filter_fn]
    pub fn opt_secs(v: impl MaybeScore, _: &dyn askama::Values) -> askama::Result<String> {
        Ok(v.get()
            .filter(|v| *v >= 0.0)
            .map_or("–".to_string(), |v| format!("{v:.3}")))
    }

    /// A dataset as BOP shows it (`tless` -> `T-LESS`).
    #[askama::filter_fn]
    pub fn dataset_name(name: &str, _: &dyn askama::Values) -> askama::Result<String> {
        Ok(evaluator::dataset::display_name(name).to_string())
    }

    /// A count with its noun, singular for exactly one: "1 estimate", "2 estimates".
    #[askama::filter_fn]
    pub fn plural(
        n: impl std::fmt::Display,
        _: &dyn askama::Values,
        one: &str,
        many: &str,
    ) -> askama::Result<String> {
        Ok(crate::wording::count(n, one, many))
    }

    /// A bootstrap 95 % interval, for the hover of a score.
    #[askama::filter_fn]
    pub fn ci95(v: &[f64; 2], _: &dyn askama::Values) -> askama::Result<String> {
        Ok(format!(
            "95 % bootstrap interval: {:.1} to {:.1}",
            v[0] * 100.0,
            v[1] * 100.0
        ))
    }

    #[askama::filter_fn]
    pub fn date(ms: &i64, _: &dyn askama::Values) -> askama::Result<String> {
        Ok(crate::wording::utc_minute(*ms))
    }
}

/// The address this service is reached at, for examples to copy: the configured public URL,
/// else the scheme and host the request came with.
pub(crate) fn site_url(app: &AppState, headers: &HeaderMap) -> String {
    if let Some(url) = &app.config.public_url {
        return url.trim_end_matches('/').to_string();
    }
    let host = headers
        .get(axum::http::header::HOST)
        .and_then(|v| v.to_str().ok())
        .filter(|h| !h.is_empty())
        .unwrap_or("localhost:8080");
    let tls = headers
        .get("x-forwarded-proto")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.eq_ignore_ascii_case("https"));
    format!("{}://{host}", if tls { "https" } else { "http" })
}

#[derive(Template, WebTemplate)]
#[template(path = "leaderboard.html")]
pub(crate) struct LeaderboardPage {
    pub(crate) board: Leaderboard,
    pub(crate) protocols: [BoardProtocol; 5],
    /// The snapshot this page is kept in, if it is: its links then lead to the snapshot's own
    /// stored boards and exports, and what a snapshot did not store (other orders, the
    /// filters, the live pages of methods and submissions) is not offered, so that a reader
    /// of a cited board never lands on today's numbers unawares.
    pub(crate) snapshot: Option<SnapshotId>,
}

impl LeaderboardPage {
    /// The page of a board as it stands: served live, and kept by snapshots.
    pub(crate) async fn of(
        app: &App,
        protocol: BoardProtocol,
        q: &BoardFilter,
    ) -> AppResult<LeaderboardPage> {
        Ok(LeaderboardPage {
            board: views::leaderboard(app, protocol, q).await?,
            protocols: BoardProtocol::ALL,
            snapshot: None,
        })
    }

    /// The name of this board's dataset; empty for the board of all datasets.
    fn dataset_name(&self) -> &str {
        self.board.dataset.as_ref().map_or("", |d| d.name.as_str())
    }

    /// The board of `protocol` (a tab), keeping the dataset (and live, the filters).
    pub(crate) fn protocol_href(&self, protocol: &BoardProtocol) -> String {
        match self.snapshot {
            Some(id) => views::snapshot_board_url(id, *protocol, self.dataset_name()),
            None => format!(
                "/leaderboards/{}{}",
                protocol.as_str(),
                self.board.filter.with("sort", "")
            ),
        }
    }

    /// The `group` of the query choosing group `name`: none for the default group, so that
    /// its links stay those of the board without a group.
    pub(crate) fn group_value<'a>(&self, name: &'a str) -> &'a str {
        if name == DEFAULT_GROUP { "" } else { name }
    }

    /// This protocol's board of dataset `name` (empty: all datasets).
    pub(crate) fn dataset_href(&self, name: &str) -> String {
        match self.snapshot {
            Some(id) => views::snapshot_board_url(id, self.board.protocol, name),
            None => self.live_href(self.board.filter.with("dataset", name)),
        }
    }

    /// This board ordered by `key`; none in a snapshot, which keeps one order.
    pub(crate) fn sort_href(&self, key: &str) -> Option<String> {
        self.snapshot
            .is_none()
            .then(|| self.live_href(self.board.filter.with("sort", key)))
    }

    /// The live board with `query`.
    pub(crate) fn live_href(&self, query: impl AsRef<str>) -> String {
        let query = query.as_ref();
        format!("/leaderboards/{}{query}", self.board.protocol.as_str())
    }

    /// This board's JSON twin.
    pub(crate) fn json_href(&self) -> String {
        match self.snapshot {
            Some(id) => format!(
                "/api/v1{}",
                views::snapshot_board_url(id, self.board.protocol, self.dataset_name())
            ),
            None => format!(
                "/api/v1{}",
                self.live_href(self.board.filter.with("sort", ""))
            ),
        }
    }

    /// This board's export as `extension` (`csv`, `json`, `tex`): a snapshot's are those it
    /// kept (CSV and JSON).
    pub(crate) fn export_href(&self, extension: &str) -> Option<String> {
        match self.snapshot {
            Some(_) if extension == "tex" => None,
            Some(id) => Some(format!(
                "/snapshots/{id}/export.{extension}{}",
                views::board_query(self.board.protocol, self.dataset_name())
            )),
            None => Some(format!(
                "/leaderboards/{}/export.{extension}{}",
                self.board.protocol.as_str(),
                self.board.filter.query()
            )),
        }
    }
}

/// A page's HTML.
pub(crate) fn html(page: &impl Template) -> AppResult<Vec<u8>> {
    page.render()
        .map(String::into_bytes)
        .map_err(|e| AppError::failed("rendering a page", e))
}

async fn home(
    State(app): State<AppState>,
    headers: HeaderMap,
    Query(q): Query<BoardFilter>,
) -> AppResult<Response> {
    leaderboard_page(&app, &headers, ProtocolName::Bop19.into(), q).await
}

async fn leaderboard(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(protocol): Path<String>,
    Query(q): Query<BoardFilter>,
) -> AppResult<Response> {
    let protocol = BoardProtocol::named(&protocol).ok_or(AppError::NotFound)?;
    leaderboard_page(&app, &headers, protocol, q).await
}

/// The page is the same for every reader (it shows public submissions only and does not look at
/// who asks), so it comes from the board cache; the home page is the BOP'19 board.
async fn leaderboard_page(
    app: &AppState,
    headers: &HeaderMap,
    protocol: BoardProtocol,
    q: BoardFilter,
) -> AppResult<Response> {
    let key = boards::key(Format::Html, protocol, &q);
    boards::answer(app, headers, key, || async move {
        html(&LeaderboardPage::of(app, protocol, &q).await?)
    })
    .await
}

#[derive(Template, WebTemplate)]
#[template(path = "datasets.html")]
struct DatasetsPage {
    datasets: Vec<ServedDataset>,
    /// The names of the core datasets.
    core: Vec<String>,
    /// For an administrator's browser: the CSRF token of the add, retire and core forms.
    admin_csrf: Option<String>,
}

impl DatasetsPage {
    fn is_core(&self, name: &str) -> bool {
        self.core.iter().any(|c| c == name)
    }

    /// One host's preparation in words: "preparing, 3 / 8 images", "ready, 8 images",
    /// "failed: why".
    fn preparation(&self, p: &PreparationRow) -> String {
        let images = if p.images_total > 0 {
            format!(", {} / {} images", p.images_done, p.images_total)
        } else {
            String::new()
        };
        match (p.state, &p.detail) {
            (PreparationState::Preparing, Some(detail)) => format!("preparing{images} ({detail})"),
            (PreparationState::Preparing, None) => format!("preparing{images}"),
            (PreparationState::Ready, _) => format!("ready, {} images", p.images_total),
            (PreparationState::Failed, detail) => {
                format!(
                    "failed: {}",
                    detail.as_deref().unwrap_or("no reason recorded")
                )
            }
        }
    }
}

async fn datasets(State(app): State<AppState>, viewer: Viewer) -> AppResult<DatasetsPage> {
    let datasets = catalogue::datasets(&app).await?;
    let rows: Vec<DatasetRow> = datasets.iter().map(|d| d.dataset.clone()).collect();
    Ok(DatasetsPage {
        core: views::core_datasets(&rows)
            .into_iter()
            .map(|d| d.name)
            .collect(),
        datasets,
        admin_csrf: viewer
            .session
            .as_ref()
            .filter(|s| s.user.is_admin)
            .map(|s| s.csrf_token.clone()),
    })
}

#[derive(Template, WebTemplate)]
#[template(path = "groups.html")]
struct GroupsPage {
    groups: Vec<Group>,
    /// For an administrator's browser: the CSRF token of the save and delete forms.
    admin_csrf: Option<String>,
}

async fn dataset_groups(State(app): State<AppState>, viewer: Viewer) -> AppResult<GroupsPage> {
    Ok(GroupsPage {
        groups: groups::all(&app).await?,
        admin_csrf: viewer
            .session
            .as_ref()
            .filter(|s| s.user.is_admin)
            .map(|s| s.csrf_token.clone()),
    })
}

#[derive(Template, WebTemplate)]
#[template(path = "method.html")]
struct MethodPage {
    method: MethodRow,
    /// Where it stands on every board it has a public entry on.
    standings: Vec<Standing>,
    /// The submissions the reader may see (the owner: all), newest first, with their scores.
    submissions: Vec<Owned>,
    /// The reader is its owner (or an administrator): private and held ones are listed too.
    owner_view: bool,
    /// For its owner's (or an administrator's) browser: the CSRF token of the edit form.
    edit_csrf: Option<String>,
    model_scopes: &'static [ModelScope],
    modalities: &'static [Modality],
    training: &'static [TrainingData],
    onboardings: &'static [Onboarding],
    object_kinds: &'static [Objects],
}

impl MethodPage {
    /// The dataset's board of the task `standing` is on.
    fn board_url(&self, standing: &Standing) -> String {
        format!(
            "/leaderboards/{}?dataset={}",
            standing.protocol.as_str(),
            views::urlencode(&standing.dataset)
        )
    }

    /// What the score of `standing` is, as its board names it.
    fn score_label(&self, standing: &Standing) -> &'static str {
        match standing.protocol {
            BoardProtocol::Pose(ProtocolName::Bop19) => "AR",
            BoardProtocol::Pose(ProtocolName::Eccv18) => "recall",
            BoardProtocol::Bop24 => "mAP",
            BoardProtocol::Coco(_) => "AP",
        }
    }
}

async fn method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
) -> AppResult<MethodPage> {
    let home = methods::home(&app, id, viewer.user.as_ref()).await?;
    let method = home.method;
    let may_edit = home.may_edit;
    Ok(MethodPage {
        standings: home.standings,
        submissions: home.submissions,
        owner_view: may_edit,
        edit_csrf: viewer
            .session
            .as_ref()
            .filter(|_| may_edit)
            .map(|s| s.csrf_token.clone()),
        method,
        model_scopes: ModelScope::ALL,
        modalities: Modality::ALL,
        training: TrainingData::ALL,
        onboardings: Onboarding::ALL,
        object_kinds: Objects::ALL,
    })
}

#[derive(Deserialize)]
struct MethodEditForm {
    #[serde(default)]
    csrf: String,
    #[serde(flatten)]
    fields: MethodForm,
}

async fn edit_method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
    Form(f): Form<MethodEditForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?;
    methods::edit(&app, user, id, f.fields).await?;
    Ok(Redirect::to(&format!("/methods/{id}")).into_response())
}

#[derive(Deserialize)]
struct CsrfForm {
    #[serde(default)]
    csrf: String,
}

/// The method page's reveal button.
async fn reveal_method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    methods::reveal(&app, viewer.check_csrf(&f.csrf)?, id).await?;
    Ok(Redirect::to(&format!("/methods/{id}")).into_response())
}

async fn pin(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    methods::pin(&app, viewer.check_csrf(&f.csrf)?, id, true).await?;
    Ok(Redirect::to(&format!("/submissions/{id}")).into_response())
}

async fn unpin(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    methods::pin(&app, viewer.check_csrf(&f.csrf)?, id, false).await?;
    Ok(Redirect::to(&format!("/submissions/{id}")).into_response())
}

#[derive(Template, WebTemplate)]
#[template(path = "submission.html")]
struct SubmissionPage {
    view: SubmissionView,
    bop19: Option<Report>,
    eccv18: Option<Report>,
    /// For an administrator's browser: the CSRF token of the moderation buttons.
    admin_csrf: Option<String>,
    /// For its owner's (or an administrator's) browser: the CSRF token of the pin, publish,
    /// withdraw and delete buttons.
    owner_csrf: Option<String>,
    /// The submissions it can be compared with (finished, on its dataset).
    compare_with: Vec<targets::Named>,
}

async fn submission(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<SubmissionPage> {
    let view = views::submission(&app, id, &viewer).await?;
    let compare_with = targets::comparable(&app, &view.submission, &viewer).await?;
    Ok(SubmissionPage {
        compare_with,
        bop19: view.scores.get(&ProtocolName::Bop19).cloned(),
        eccv18: view.scores.get(&ProtocolName::Eccv18).cloned(),
        owner_csrf: viewer
            .session
            .as_ref()
            .filter(|_| view.owner.is_some())
            .map(|s| s.csrf_token.clone()),
        view,
        admin_csrf: viewer
            .session
            .as_ref()
            .filter(|s| s.user.is_admin)
            .map(|s| s.csrf_token.clone()),
    })
}

#[derive(Deserialize)]
struct VisibilityForm {
    #[serde(default)]
    csrf: String,
    visibility: String,
    #[serde(default)]
    confirm: bool,
}

/// The publish and withdraw buttons of a submission's page.
async fn change_visibility(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Form(f): Form<VisibilityForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?.clone();
    let asked = f.visibility.trim().parse::<Visibility>()?;
    publishing::set_visibility(&app, &user, id, asked, f.confirm).await?;
    Ok(Redirect::to(&format!("/submissions/{id}")).into_response())
}

/// The delete button (which asks first) of a submission's page and of the owner's list.
async fn delete_submission(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let user = viewer.check_csrf(&f.csrf)?.clone();
    publishing::delete(&app, &user, id).await?;
    Ok(Redirect::to("/me/submissions").into_response())
}

#[derive(Template, WebTemplate)]
#[template(path = "my_submissions.html")]
struct MySubmissionsPage {
    list: MySubmissions,
    csrf: String,
}

async fn my_submissions(State(app): State<AppState>, viewer: Viewer) -> AppResult<Response> {
    let Some(user) = viewer.user.as_ref().filter(|_| viewer.session.is_some()) else {
        return Ok(Redirect::to("/login?next=/me/submissions").into_response());
    };
    Ok(MySubmissionsPage {
        list: views::my_submissions(&app, user).await?,
        csrf: viewer.csrf_token(),
    }
    .into_response())
}

#[derive(Template, WebTemplate, Default)]
#[template(path = "submit.html")]
struct SubmitPage {
    /// The served datasets, each with the viewer's submissions left on it.
    datasets: Vec<(DatasetRow, Quota)>,
    error: Option<ErrorBody>,
    method: String,
    team: String,
    dataset: String,
    protocol: String,
    description: String,
    paper_url: String,
    code_url: String,
    hardware: String,
    /// The "anonymous (double-blind review)" box was ticked.
    anonymous: bool,
    max_upload_mb: u64,
    csrf: String,
}

impl SubmitPage {
    /// The tasks the service scores, from the domain's one list.
    fn tasks(&self) -> &'static [UploadTask] {
        UploadTask::ALL
    }

    /// The result file kinds the service takes.
    fn file_kinds(&self) -> &'static [FileKind] {
        FileKind::ALL
    }

    fn accept(&self) -> String {
        FileKind::accept()
    }
}

async fn submit_form(State(app): State<AppState>, viewer: Viewer) -> AppResult<Response> {
    let Some(user) = viewer.user.as_ref().filter(|_| viewer.session.is_some()) else {
        return Ok(Redirect::to("/login?next=/submit").into_response());
    };
    Ok(SubmitPage {
        datasets: quota::every_dataset(&app, user).await?,
        max_upload_mb: app.config.max_upload_mb,
        csrf: viewer.csrf_token(),
        ..SubmitPage::default()
    }
    .into_response())
}

/// The form posts here; a valid upload redirects to its submission's page (to the method's
/// page for several files), an invalid one shows the form again with every problem and the
/// values typed so far.
async fn submit(
    State(app): State<AppState>,
    viewer: Viewer,
    multipart: Result<Multipart, MultipartRejection>,
) -> AppResult<Response> {
    // Anonymous posts are refused before the body is looked at, even a malformed one; the CSRF
    // token, which travels in the body, is checked once read.
    viewer.require_user()?;
    let multipart = multipart.map_err(|e| AppError::BadRequest(e.body_text()))?;
    let (mut fields, files) = read_upload(&app, multipart, app.config.max_upload_bytes()).await?;
    let owner = viewer.check_csrf(&fields.csrf)?.clone();
    // The form's "publish when evaluated" box: a browser sends it only when ticked.
    fields.visibility = if fields.publish.is_empty() {
        "private"
    } else {
        "public"
    }
    .to_string();
    let typed = SubmitPage {
        method: fields.method.clone(),
        team: fields.team.clone(),
        dataset: fields.dataset.clone(),
        protocol: fields.protocol.clone(),
        description: fields.description.clone(),
        paper_url: fields.paper_url.clone(),
        code_url: fields.code_url.clone(),
        hardware: fields.hardware.clone(),
        anonymous: fields.anonymous.trim() == "true",
        max_upload_mb: app.config.max_upload_mb,
        csrf: viewer.csrf_token(),
        ..SubmitPage::default()
    };
    let accepted = match fields.parse(files) {
        Ok(upload) => submissions::submit(&app, &owner, upload).await,
        Err(e) => Err(e),
    };
    match accepted {
        Ok(accepted) => {
            let to = match accepted.as_slice() {
                [one] => format!("/submissions/{}", one.submission.id),
                [first, ..] => format!("/methods/{}", first.submission.method_id),
                [] => return Err(AppError::Internal("an upload without files".into())),
            };
            Ok(Redirect::to(&to).into_response())
        }
        Err(e) if e.status().is_client_error() => {
            let status = e.status();
            let page = SubmitPage {
                datasets: quota::every_dataset(&app, &owner).await?,
                error: Some(e.body()),
                ..typed
            };
            Ok((status, page).into_response())
        }
        Err(e) => Err(e),
    }
}

#[derive(Template, WebTemplate)]
#[template(path = "error.html")]
struct ErrorPage {
    status: u16,
    body: ErrorBody,
}

/// Error responses of page routes become HTML pages (the JSON API keeps its JSON bodies).
pub async fn html_errors(
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    error_page(next.run(request).await)
}

/// An error response as an HTML page; any other response as it is.
pub fn error_page(response: Response) -> Response {
    let status = response.status();
    match response.extensions().get::<ErrorBody>() {
        Some(body) if status.is_client_error() || status.is_server_error() => {
            let page = ErrorPage {
                status: status.as_u16(),
                body: body.clone(),
            };
            // When to try again (a limit, an unavailable database) holds for the page too.
            let retry_after = response.headers().get(header::RETRY_AFTER).cloned();
            let mut page = (status, page).into_response();
            if let Some(v) = retry_after {
                page.headers_mut().insert(header::RETRY_AFTER, v);
            }
            page
        }
        _ => response,
    }
}

/// The page for any path that matches no route.
pub async fn not_found() -> Response {
    let page = ErrorPage {
        status: 404,
        body: AppError::NotFound.body(),
    };
    (StatusCode::NOT_FOUND, page).into_response()
}
