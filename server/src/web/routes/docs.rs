//! `/docs/api`: the JSON API as a page for people, rendered from the same OpenAPI document as
//! `/api/v1/openapi.json` (a route added there appears here), with the limits of this server.

use askama::Template;
use askama_web::WebTemplate;
use axum::Router;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::routing::get;
use serde_json::Value;

use crate::app::AppState;
use crate::web::render::openapi;
use crate::web::routes::pages::site_url;
use crate::wording::count;

pub fn router() -> Router<AppState> {
    Router::new().route("/docs/api", get(api_page))
}

struct Route {
    path: String,
    operations: Vec<Operation>,
}

struct Operation {
    method: String,
    summary: String,
    needs_token: bool,
    parameters: Vec<Field>,
    body: Vec<Field>,
    answers: Vec<Answer>,
}

/// A path or query parameter, or a field of an uploaded form.
struct Field {
    name: String,
    place: String,
    required: bool,
    kind: String,
    description: String,
}

struct Answer {
    code: String,
    description: String,
    /// The schema's name, when the answer has one.
    schema: Option<String>,
}

struct SchemaField {
    name: String,
    kind: String,
    description: String,
}

#[derive(Template, WebTemplate)]
#[template(path = "api.html")]
struct ApiPage {
    title: String,
    version: String,
    description: String,
    site: String,
    max_upload: String,
    fair_use: String,
    routes: Vec<Route>,
    error_fields: Vec<SchemaField>,
}

async fn api_page(State(app): State<AppState>, headers: HeaderMap) -> ApiPage {
    let doc = openapi::document();
    let text = |v: &Value, key: &str| v[key].as_str().unwrap_or_default().to_string();
    let per_window = app.config.submissions_per_window;
    let fair_use = if per_window == 0 {
        "no limit on submissions".to_string()
    } else {
        format!(
            "at most {} per dataset and account within {}",
            count(per_window, "submission", "submissions"),
            window(app.config.limit_window_secs)
        )
    };
    ApiPage {
        title: text(&doc["info"], "title"),
        version: text(&doc["info"], "version"),
        description: text(&doc["info"], "description"),
        site: site_url(&app, &headers),
        max_upload: format!("{} MiB", app.config.max_upload_mb),
        fair_use,
        routes: routes(&doc),
        error_fields: schema_fields(&doc["components"]["schemas"]["Error"]),
    }
}

/// A window in the largest whole unit: `1 day`, `6 hours`, `90 seconds`.
fn window(secs: u64) -> String {
    match secs {
        s if s >= 86_400 && s % 86_400 == 0 => count(s / 86_400, "day", "days"),
        s if s >= 3600 && s % 3600 == 0 => count(s / 3600, "hour", "hours"),
        s if s >= 60 && s % 60 == 0 => count(s / 60, "minute", "minutes"),
        s => count(s, "second", "seconds"),
    }
}

fn routes(doc: &Value) -> Vec<Route> {
    let Some(paths) = doc["paths"].as_object() else {
        return Vec::new();
    };
    paths
        .iter()
        .map(|(path, item)| Route {
            path: path.clone(),
            operations: item
                .as_object()
                .into_iter()
                .flatten()
                .map(|(method, op)| operation(method, op))
                .collect(),
        })
        .collect()
}

fn operation(method: &str, op: &Value) -> Operation {
    let parameters = op["parameters"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|p| Field {
            name: p["name"].as_str().unwrap_or_default().to_string(),
            place: p["in"].as_str().unwrap_or_default().to_string(),
            required: p["required"].as_bool().unwrap_or(false),
            kind: kind(&p["schema"]),
            description: p["description"].as_str().unwrap_or_default().to_string(),
        })
        .collect();
    let form = &op["requestBody"]["content"]["multipart/form-data"]["schema"];
    let required: Vec<&str> = form["required"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .collect();
    let body = schema_fields(form)
        .into_iter()
        .map(|f| Field {
            required: required.contains(&f.name.as_str()),
            place: "form".to_string(),
            name: f.name,
            kind: f.kind,
            description: f.description,
        })
        .collect();
    let answers = op["responses"]
        .as_object()
        .into_iter()
        .flatten()
        .map(|(code, a)| Answer {
            code: code.clone(),
            description: a["description"].as_str().unwrap_or_default().to_string(),
            schema: a["content"]["application/json"]["schema"]["$ref"]
                .as_str()
                .and_then(|r| r.rsplit('/').next())
                .map(str::to_string),
        })
        .collect();
    Operation {
        method: method.to_uppercase(),
        summary: op["summary"].as_str().unwrap_or_default().to_string(),
        needs_token: op.get("security").is_some(),
        parameters,
        body,
        answers,
    }
}

fn schema_fields(schema: &Value) -> Vec<SchemaField> {
    schema["properties"]
        .as_object()
        .into_iter()
        .flatten()
        .map(|(name, s)| SchemaField {
            name: name.clone(),
            kind: kind(s),
            description: s["description"].as_str().unwrap_or_default().to_string(),
        })
        .collect()
}

/// A schema's type as a reader wants it: `bop19 | eccv18`, `array of binary`, `string (at
/// most 100)`.
fn kind(schema: &Value) -> String {
    if let Some(values) = schema["enum"].as_array() {
        let values: Vec<&str> = values.iter().filter_map(Value::as_str).collect();
        return values.join(" | ");
    }
    let base = schema["type"].as_str().unwrap_or("object");
    let base = match base {
        "array" => format!("array of {}", kind(&schema["items"])),
        "string" => match schema["format"].as_str() {
            Some(format) => format.to_string(),
            None => "string".to_string(),
        },
        other => other.to_string(),
    };
    match schema["maxLength"].as_u64().or(schema["maxItems"].as_u64()) {
        Some(max) => format!("{base} (at most {max})"),
        None => base,
    }
}
