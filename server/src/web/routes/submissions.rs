//! Receiving an upload over HTTP, from the browser form or the REST API alike: the multipart
//! body is streamed (each file to a temporary file under the size bound of the whole upload,
//! hashed on the way), then its fields are parsed into a `submissions::Upload` for the
//! submissions service.

use std::str::FromStr;

use axum::extract::Multipart;
use axum::extract::multipart::Field;
use evaluator::protocol::ProtocolName;
use intake::upload::{MAX_FILES, MAX_TEXT_FIELD, UploadFields, client_file_name};
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;

use crate::app::App;
use crate::domain::{
    Description, Hardware, Link, MethodName, Task, TeamName, UploadTask, Visibility, flag, optional,
};
use crate::error::{AppError, AppResult};
use crate::service::submissions::{Protocols, Upload, UploadedFile};
use crate::store::methods::MethodMeta;

/// Checks every field and makes the upload the submissions service takes.
pub fn parse_fields(fields: &UploadFields, files: Vec<UploadedFile>) -> AppResult<Upload> {
    let method = MethodName::parse(&fields.method)?;
    let team = match fields.team.trim() {
        "" => None,
        t => Some(TeamName::parse("team", t)?),
    };
    let (protocols, task) = match fields.protocol.trim() {
        "" => (Protocols::asked(&[]), None),
        p => match Task::from_str(p) {
            Ok(task) => (Protocols::default(), Some(task)),
            Err(_) => {
                // One protocol, or both as `bop19,eccv18`.
                let mut asked = Vec::new();
                for name in p.split(',').map(str::trim) {
                    let name = ProtocolName::from_str(name).map_err(|_| {
                        AppError::BadRequest(format!(
                            "unknown protocol `{name}` ({})",
                            UploadTask::values()
                        ))
                    })?;
                    if !asked.contains(&name) {
                        asked.push(name);
                    }
                }
                (Protocols::asked(&asked), None)
            }
        },
    };
    let visibility = match fields.visibility.trim() {
        "" => None,
        v => Some(v.parse::<Visibility>()?),
    };
    let meta = MethodMeta {
        description: Description::parse(&fields.description)?,
        paper_url: Link::parse("paper_url", &fields.paper_url)?,
        code_url: Link::parse("code_url", &fields.code_url)?,
        training_data: optional(&fields.training_data)?,
        modality: optional(&fields.modality)?,
        anonymous: match fields.anonymous.trim() {
            "" => None,
            sent => Some(flag("anonymous", sent)?),
        },
        onboarding: optional(&fields.onboarding)?,
        objects: optional(&fields.objects)?,
    };
    if files.is_empty() {
        return Err(AppError::BadRequest(
            "field `file` (the result file) is required".into(),
        ));
    }
    let dataset = fields.dataset.trim();
    Ok(Upload {
        method,
        team,
        dataset: (!dataset.is_empty()).then(|| dataset.to_string()),
        protocols,
        task,
        meta,
        hardware: Hardware::parse(&fields.hardware)?,
        visibility,
        files,
    })
}

/// Reads a multipart upload, streaming each file (every `file` field) to a temporary file in
/// the submissions folder; `limit` bounds the files' total size.
pub async fn read_upload(
    app: &App,
    mut multipart: Multipart,
    limit: u64,
) -> AppResult<(UploadFields, Vec<UploadedFile>)> {
    let mut fields = UploadFields::default();
    let mut files: Vec<UploadedFile> = Vec::new();
    while let Some(field) = multipart.next_field().await.map_err(multipart_error)? {
        let name = field.name().unwrap_or_default().to_string();
        if name == "file" {
            if files.len() == MAX_FILES {
                return Err(AppError::BadRequest(format!(
                    "at most {MAX_FILES} files in one upload"
                )));
            }
            let used: u64 = files.iter().map(|f| f.size).sum();
            let file = match save_file(app, field, limit - used, limit).await {
                Ok(file) => file,
                Err(e) if e.is_storage_full() => {
                    drain(multipart).await;
                    return Err(e);
                }
                Err(e) => return Err(e),
            };
            // A browser sends an empty file field when no file is chosen.
            if !(file.size == 0 && file.name.is_empty()) {
                files.push(file);
            }
            continue;
        }
        let text = field_text(field).await?;
        // Unknown fields are drained and ignored.
        if let Some(slot) = fields.slot(&name) {
            *slot = text;
        }
    }
    Ok((fields, files))
}

/// Reads the rest of a multipart body and drops it. An answer given while the client still
/// sends makes the server close the connection on unread bytes, which the client sees as a
/// reset instead of the answer: an upload refused for want of disk space (a fault of the
/// service, within the size limit) is read to its end, so its sender learns why.
async fn drain(mut multipart: Multipart) {
    while let Ok(Some(mut field)) = multipart.next_field().await {
        while let Ok(Some(_)) = field.chunk().await {}
    }
}

/// A malformed or oversized multipart body as the answer it gets.
pub fn multipart_error(e: axum::extract::multipart::MultipartError) -> AppError {
    if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        AppError::TooLarge { limit: 0 }
    } else {
        AppError::BadRequest(format!("malformed upload: {}", e.body_text()))
    }
}

/// A text field of a multipart body, at most `MAX_TEXT_FIELD` bytes of UTF-8.
pub async fn field_text(mut field: Field<'_>) -> AppResult<String> {
    let mut bytes = Vec::new();
    while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
        bytes.extend_from_slice(&chunk);
        if bytes.len() > MAX_TEXT_FIELD {
            return Err(AppError::BadRequest(format!(
                "field `{}` is longer than {MAX_TEXT_FIELD} bytes",
                field.name().unwrap_or_default()
            )));
        }
    }
    String::from_utf8(bytes)
        .map_err(|_| AppError::BadRequest("a text field is not valid UTF-8".into()))
}

/// Streams one file to a temporary file; `room` is what is left of the upload's `limit`.
async fn save_file(
    app: &App,
    mut field: Field<'_>,
    room: u64,
    limit: u64,
) -> AppResult<UploadedFile> {
    // Only the last path component of the client's file name is kept, for display.
    let name = client_file_name(field.file_name());
    let tmp = tempfile::Builder::new()
        .prefix("upload-")
        .tempfile_in(app.config.submissions_dir())?
        .into_temp_path();
    let mut out = tokio::fs::File::create(&tmp).await?;
    let mut hasher = Sha256::new();
    let mut size = 0u64;
    while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
        size += chunk.len() as u64;
        if size > room {
            return Err(AppError::TooLarge { limit });
        }
        hasher.update(&chunk);
        out.write_all(&chunk).await?;
    }
    out.flush().await?;
    Ok(UploadedFile {
        name,
        tmp,
        sha256: hex::encode(hasher.finalize()),
        size,
    })
}
