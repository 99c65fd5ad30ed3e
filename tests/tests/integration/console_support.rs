//! The console tests' helpers: the router over a sandbox's camera agent, and requests to it
//! with the token.

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use http_body_util::BodyExt as _;
use roomlight_console::{ConsoleConfig, router};
use roomlight_tests::{Sandbox, TOKEN};
use serde_json::{Value, json};
use std::time::Duration;
use tokio_util::sync::CancellationToken;
use tower::ServiceExt as _;

pub const WITHIN: Duration = Duration::from_secs(30);

/// The router over `sb`'s camera agent; its tasks stop with the returned token.
pub fn console(
    sb: &Sandbox,
    survey: Option<std::path::PathBuf>,
    snapshots: &std::path::Path,
) -> (axum::Router, CancellationToken) {
    let cancel = CancellationToken::new();
    let config = ConsoleConfig {
        token: TOKEN.into(),
        survey,
        snapshots: snapshots.to_path_buf(),
        model: None,
    };
    (
        router(config, sb.control(), sb.status_watch(), cancel.clone()),
        cancel,
    )
}

/// One request; the status and the body.
pub async fn call(
    app: &axum::Router,
    request: Request<Body>,
) -> (StatusCode, axum::http::HeaderMap, Vec<u8>) {
    let response = app
        .clone()
        .oneshot(request)
        .await
        .expect("the router answers");
    let status = response.status();
    let headers = response.headers().clone();
    let body = response
        .into_body()
        .collect()
        .await
        .expect("the body")
        .to_bytes()
        .to_vec();
    (status, headers, body)
}

pub fn bearer(method: &str, uri: &str, body: Option<Value>) -> Request<Body> {
    let builder = Request::builder()
        .method(method)
        .uri(uri)
        .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"));
    match body {
        Some(v) => builder
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(v.to_string())),
        None => builder.body(Body::empty()),
    }
    .expect("a request")
}

pub async fn json_of(app: &axum::Router, request: Request<Body>) -> (StatusCode, Value) {
    let (status, _, body) = call(app, request).await;
    let value = serde_json::from_slice(&body)
        .unwrap_or_else(|_| json!({"raw": String::from_utf8_lossy(&body)}));
    (status, value)
}

/// Waits until the console's status satisfies `pred`, looking again whenever the room's
/// status changes (and at least every half second: the console's own state, such as the
/// optimum, follows it).
pub async fn status_until(
    app: &axum::Router,
    mut room: tokio::sync::watch::Receiver<roomlight_agent::camera::RoomStatus>,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    let deadline = tokio::time::Instant::now() + WITHIN;
    loop {
        let (code, s) = json_of(app, bearer("GET", "/api/status", None)).await;
        assert_eq!(code, StatusCode::OK, "{s}");
        if pred(&s) {
            return s;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "status never reached the condition: {s}"
        );
        let _ = tokio::time::timeout(Duration::from_millis(500), room.changed()).await;
    }
}
