//! Upload bodies (`multipart/form-data`), read as the server reads the upload form's and the
//! REST API's: axum's `Multipart` extractor (multer underneath) over the body, with the
//! boundary of its content type; file fields drained under an upload limit, at most
//! `MAX_FILES` of them, text fields held to `MAX_TEXT_FIELD` bytes of UTF-8 and put in their
//! `UploadFields` slot, then each parsed into the domain value the server makes of it
//! (`parse_fields` in server/src/web/routes/submissions.rs). An input's first line is the
//! boundary and the rest the body, so that the fuzzer varies both.
#![no_main]

use std::str::FromStr;

use axum::body::Body;
use axum::extract::{FromRequest, Multipart};
use axum::http::{HeaderValue, Request, header};
use evaluator::protocol::ProtocolName;
use intake::domain::{
    Description, Hardware, Link, MethodName, Modality, Objects, Onboarding, Task, TeamName,
    TrainingData, Visibility, flag, optional,
};
use intake::upload::{MAX_FILES, MAX_TEXT_FIELD, UploadFields, client_file_name};
use libfuzzer_sys::fuzz_target;

/// Bytes of files allowed per body (the server's limit is its upload limit).
const LIMIT: u64 = 1 << 20;

fuzz_target!(|data: &[u8]| {
    let (boundary, body) = match data.iter().position(|&b| b == b'\n') {
        Some(at) => (&data[..at], &data[at + 1..]),
        None => (data, &data[data.len()..]),
    };
    let content_type = [b"multipart/form-data; boundary=".as_slice(), boundary].concat();
    let Ok(content_type) = HeaderValue::from_bytes(&content_type) else {
        return;
    };
    let request = Request::builder()
        .method("POST")
        .uri("/api/v1/submissions")
        .header(header::CONTENT_TYPE, content_type)
        .body(Body::from(body.to_vec()))
        .expect("a request");
    if let Some(fields) = futures_executor::block_on(read(request)) {
        parse(&fields);
    }
});

/// The text fields of a body, `None` where the server would refuse it while reading.
async fn read(request: Request<Body>) -> Option<UploadFields> {
    let mut multipart = Multipart::from_request(request, &()).await.ok()?;
    let mut fields = UploadFields::default();
    let (mut files, mut size) = (0, 0u64);
    while let Some(mut field) = multipart.next_field().await.ok()? {
        let name = field.name().unwrap_or_default().to_string();
        if name == "file" {
            if files == MAX_FILES {
                return None;
            }
            client_file_name(field.file_name());
            while let Some(chunk) = field.chunk().await.ok()? {
                size += chunk.len() as u64;
                if size > LIMIT {
                    return None;
                }
            }
            files += 1;
            continue;
        }
        let mut bytes = Vec::new();
        while let Some(chunk) = field.chunk().await.ok()? {
            bytes.extend_from_slice(&chunk);
            if bytes.len() > MAX_TEXT_FIELD {
                return None;
            }
        }
        let text = String::from_utf8(bytes).ok()?;
        if let Some(slot) = fields.slot(&name) {
            *slot = text;
        }
    }
    Some(fields)
}

/// Every field through its parser, whatever the others give (the server stops at the first
/// refused).
fn parse(f: &UploadFields) {
    let _ = MethodName::parse(&f.method);
    let _ = TeamName::parse("team", &f.team);
    if Task::from_str(f.protocol.trim()).is_err() {
        for name in f.protocol.split(',') {
            let _ = ProtocolName::from_str(name.trim());
        }
    }
    let _ = f.visibility.trim().parse::<Visibility>();
    let _ = Description::parse(&f.description);
    let _ = Link::parse("paper_url", &f.paper_url);
    let _ = Link::parse("code_url", &f.code_url);
    let _ = optional::<TrainingData>(&f.training_data);
    let _ = optional::<Modality>(&f.modality);
    let _ = flag("anonymous", &f.anonymous);
    let _ = optional::<Onboarding>(&f.onboarding);
    let _ = optional::<Objects>(&f.objects);
    let _ = Hardware::parse(&f.hardware);
}
