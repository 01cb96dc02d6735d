//! The pages of single targets and their JSON twins: two submissions compared target by target
//! (or image by image), one target of a submission, a submission's worst targets, and for a
//! BOP'24 detection its target images and one image's estimates (see
//! `crate::web::views::targets`).

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::{Path, Query, State};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use evaluator::protocol::ProtocolName;

use crate::app::AppState;
use crate::domain::SubmissionId;
use crate::error::{AppError, AppResult};
use crate::web::auth::Viewer;
use crate::web::routes::pages::filters;
use crate::web::views::targets::bop24::{Bop24Comparison, Bop24Gallery, Bop24Image};
use crate::web::views::targets::{
    self, Choice, CocoComparison, CompareQuery, Compared, Comparison, Galleries, Gallery,
    TargetView,
};

pub fn page_router() -> Router<AppState> {
    Router::new()
        .route("/compare", get(compare_page))
        .route("/submissions/{id}/targets", get(gallery_page))
        .route("/submissions/{id}/targets/{scene}/{im}", get(image_page))
        .route(
            "/submissions/{id}/targets/{scene}/{im}/{obj}",
            get(target_page),
        )
}

/// The JSON twins. One target's is under the stored errors it comes from: the path of the
/// target page under `/api/v1` is its overlay image's.
pub fn api_router() -> Router<AppState> {
    Router::new()
        .route("/api/v1/compare", get(compare_json))
        .route("/api/v1/submissions/{id}/targets", get(gallery_json))
        .route(
            "/api/v1/submissions/{id}/targets/{scene}/{im}",
            get(image_json),
        )
        .route(
            "/api/v1/submissions/{id}/errors/{protocol}/{scene}/{im}/{obj}",
            get(target_json),
        )
}

#[derive(Template, WebTemplate)]
#[template(path = "compare.html")]
struct ComparePage {
    view: Box<Comparison>,
}

#[derive(Template, WebTemplate)]
#[template(path = "compare_coco.html")]
struct CocoComparePage {
    view: Box<CocoComparison>,
}

#[derive(Template, WebTemplate)]
#[template(path = "compare_bop24.html")]
struct Bop24ComparePage {
    view: Box<Bop24Comparison>,
}

async fn compare_page(
    State(app): State<AppState>,
    viewer: Viewer,
    Query(q): Query<CompareQuery>,
) -> AppResult<Response> {
    Ok(match targets::compare(&app, &q, &viewer).await? {
        Compared::Pose(view) => ComparePage { view }.into_response(),
        Compared::Coco(view) => CocoComparePage { view }.into_response(),
        Compared::Bop24(view) => Bop24ComparePage { view }.into_response(),
    })
}

async fn compare_json(
    State(app): State<AppState>,
    viewer: Viewer,
    Query(q): Query<CompareQuery>,
) -> AppResult<Json<Compared>> {
    Ok(Json(targets::compare(&app, &q, &viewer).await?))
}

#[derive(Template, WebTemplate)]
#[template(path = "targets.html")]
struct GalleryPage {
    view: Box<Gallery>,
}

#[derive(Template, WebTemplate)]
#[template(path = "targets_bop24.html")]
struct Bop24GalleryPage {
    view: Box<Bop24Gallery>,
}

async fn gallery_page(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Query(choice): Query<Choice>,
) -> AppResult<Response> {
    Ok(match targets::gallery(&app, id, &choice, &viewer).await? {
        Galleries::Pose(view) => GalleryPage { view }.into_response(),
        Galleries::Bop24(view) => Bop24GalleryPage { view }.into_response(),
    })
}

async fn gallery_json(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    Query(choice): Query<Choice>,
) -> AppResult<Json<Galleries>> {
    Ok(Json(targets::gallery(&app, id, &choice, &viewer).await?))
}

#[derive(Template, WebTemplate)]
#[template(path = "target_image.html")]
struct ImagePage {
    view: Bop24Image,
}

async fn image_page(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, scene, im)): Path<(SubmissionId, u32, u32)>,
    Query(choice): Query<Choice>,
) -> AppResult<ImagePage> {
    Ok(ImagePage {
        view: targets::image(&app, id, (scene, im), &choice, &viewer).await?,
    })
}

async fn image_json(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, scene, im)): Path<(SubmissionId, u32, u32)>,
    Query(choice): Query<Choice>,
) -> AppResult<Json<Bop24Image>> {
    Ok(Json(
        targets::image(&app, id, (scene, im), &choice, &viewer).await?,
    ))
}

#[derive(Template, WebTemplate)]
#[template(path = "target.html")]
struct TargetPage {
    view: TargetView,
}

async fn target_page(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, scene, im, obj)): Path<(SubmissionId, u32, u32, u32)>,
    Query(choice): Query<Choice>,
) -> AppResult<TargetPage> {
    Ok(TargetPage {
        view: targets::target(&app, id, (scene, im, obj), &choice, &viewer).await?,
    })
}

async fn target_json(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, protocol, scene, im, obj)): Path<(SubmissionId, String, u32, u32, u32)>,
    Query(mut choice): Query<Choice>,
) -> AppResult<Json<TargetView>> {
    let protocol: ProtocolName = protocol.parse().map_err(|_| AppError::NotFound)?;
    choice.protocol = Some(protocol.as_str().to_string());
    Ok(Json(
        targets::target(&app, id, (scene, im, obj), &choice, &viewer).await?,
    ))
}
