//! Form bodies and query strings, deserialised by axum's `Form` and `Query` extractors as the
//! server's handlers deserialise them, then parsed into domain values. The first byte of an
//! input chooses what the rest is: the method page's edit form (`MethodEditForm`, whose
//! flattened details take text or numbers and text or booleans), or a query string whose
//! parameters go through the parser of the value they name on the site's pages and API
//! (`page`, `visibility`, `protocol`, `group`, the method filters, ...).
#![no_main]

use std::collections::BTreeMap;
use std::str::FromStr;

use axum::body::Body;
use axum::extract::{Form, FromRequest, Query};
use axum::http::{Request, Uri, header};
use intake::domain::{
    BoardProtocol, GroupName, MethodEditForm, MethodForm, MethodName, Modality, ModelScope,
    Objects, Onboarding, PageNumber, Task, TeamName, TrainingData, UserName, Visibility, flag,
    optional, year,
};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    if selector % 2 == 0 {
        form(rest);
    } else {
        query(rest);
    }
});

fn form(body: &[u8]) {
    let request = Request::builder()
        .method("POST")
        .uri("/methods/1")
        .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
        .body(Body::from(body.to_vec()))
        .expect("a request");
    let form = futures_executor::block_on(Form::<MethodEditForm>::from_request(request, &()));
    if let Ok(Form(f)) = form {
        let _ = f.fields.parse(MethodForm::default());
    }
}

fn query(raw: &[u8]) {
    // Bytes a URI cannot hold are refused before any handler runs.
    let Ok(query) = std::str::from_utf8(raw) else {
        return;
    };
    let Ok(uri) = Uri::from_str(&format!("/leaderboard?{query}")) else {
        return;
    };
    let Ok(Query(params)) = Query::<BTreeMap<String, String>>::try_from_uri(&uri) else {
        return;
    };
    for (name, value) in &params {
        match name.as_str() {
            "page" => drop(PageNumber::parse(value)),
            "visibility" => drop(value.trim().parse::<Visibility>()),
            "protocol" => {
                let _ = BoardProtocol::from_str(value);
                let _ = Task::from_str(value);
            }
            "group" => drop(GroupName::parse(value)),
            "training" | "training_data" => drop(optional::<TrainingData>(value)),
            "modality" => drop(optional::<Modality>(value)),
            "objects" => drop(optional::<Objects>(value)),
            "onboarding" => drop(optional::<Onboarding>(value)),
            "model_scope" => drop(optional::<ModelScope>(value)),
            "method" => drop(MethodName::parse(value)),
            "team" => drop(TeamName::parse("team", value)),
            "user" => drop(UserName::parse(value)),
            "year" => drop(year(value)),
            "confirm" | "anonymous" => drop(flag("confirm", value)),
            _ => {}
        }
    }
}
