//! How long a request may take. Every request has a plain timeout, except uploads: a wall
//! clock short enough to matter would cut a large file on a slow link (120 s cut a 64 MB
//! upload below 0.55 MB/s), so an upload route lifts it and bounds its body by progress
//! instead: the body must keep delivering at least `min_bytes` every `window`, however long
//! the whole upload takes, and one that falls behind is refused with 408.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body::{Frame, SizeHint};
use tokio::time::{Instant, Sleep};

use crate::config::{HttpConfig, ProgressRule};
use crate::error::AppError;

/// The time bounds of every request.
#[derive(Clone, Copy, Debug)]
pub struct Deadlines {
    /// The plain timeout of every request but uploads.
    pub request: Duration,
    /// What an upload's body must keep delivering.
    pub upload: ProgressRule,
}

impl Deadlines {
    pub fn of(http: &HttpConfig) -> Deadlines {
        Deadlines {
            request: http.request_timeout(),
            upload: http.upload_progress(),
        }
    }
}

/// Put on each request by [`plain_timeout`], for [`by_progress`] to take over.
#[derive(Clone)]
struct Timing {
    lifted: Arc<AtomicBool>,
    upload: ProgressRule,
}

/// Answers 408 when a request is not answered within the plain timeout, unless its route
/// bounds it by progress instead ([`by_progress`]).
pub async fn plain_timeout(
    State(deadlines): State<Deadlines>,
    mut request: Request,
    next: Next,
) -> Response {
    let lifted = Arc::new(AtomicBool::new(false));
    request.extensions_mut().insert(Timing {
        lifted: lifted.clone(),
        upload: deadlines.upload,
    });
    let expired = async {
        tokio::time::sleep(deadlines.request).await;
        if lifted.load(Ordering::Acquire) {
            std::future::pending::<()>().await;
        }
    };
    tokio::select! {
        response = next.run(request) => response,
        () = expired => AppError::TimedOut(format!(
            "no answer within {} s: the request was given up",
            deadlines.request.as_secs()
        ))
        .into_response(),
    }
}

/// For upload routes: lifts the plain timeout and makes the body keep progressing; an upload
/// that stalls is answered 408 saying what pace it must keep.
pub async fn by_progress(request: Request, next: Next) -> Response {
    // Without `plain_timeout` around the route there is no timeout to replace.
    let Some(timing) = request.extensions().get::<Timing>().cloned() else {
        return next.run(request).await;
    };
    timing.lifted.store(true, Ordering::Release);
    let rule = timing.upload;
    let stalled = Arc::new(AtomicBool::new(false));
    let (parts, body) = request.into_parts();
    let body = Body::new(Progressing {
        inner: body,
        rule,
        got: 0,
        deadline: Box::pin(tokio::time::sleep(rule.window)),
        stalled: stalled.clone(),
    });
    let response = next.run(Request::from_parts(parts, body)).await;
    if stalled.load(Ordering::Acquire) {
        // Whatever the handler made of the broken body, the reason is the pace.
        return AppError::TimedOut(stall_message(rule)).into_response();
    }
    response
}

fn stall_message(rule: ProgressRule) -> String {
    let kib = rule.min_bytes.div_ceil(1024);
    let secs = rule.window.as_secs();
    format!(
        "the upload stalled: less than {kib} KiB arrived in {secs} s, and an upload must keep \
         delivering at least {kib} KiB every {secs} s"
    )
}

/// The body's error when it stalls.
#[derive(Debug, thiserror::Error)]
#[error("the upload stalled")]
struct Stalled;

/// A request body that fails once `rule.min_bytes` have not arrived within `rule.window` of
/// the previous `min_bytes` (or of the start). Only time spent waiting for the client counts:
/// data that was already there when the handler came back for it starts a new window.
struct Progressing {
    inner: Body,
    rule: ProgressRule,
    /// Bytes received in the current window.
    got: u64,
    deadline: Pin<Box<Sleep>>,
    stalled: Arc<AtomicBool>,
}

impl http_body::Body for Progressing {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let this = &mut *self;
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => {
                if let Some(data) = frame.data_ref() {
                    this.got += data.len() as u64;
                    if this.got >= this.rule.min_bytes || this.deadline.is_elapsed() {
                        this.got = 0;
                        let next = Instant::now() + this.rule.window;
                        this.deadline.as_mut().reset(next);
                    }
                }
                Poll::Ready(Some(Ok(frame)))
            }
            Poll::Pending => {
                if this.deadline.as_mut().poll(cx).is_ready() {
                    this.stalled.store(true, Ordering::Release);
                    return Poll::Ready(Some(Err(axum::Error::new(Stalled))));
                }
                Poll::Pending
            }
            other => other,
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}
