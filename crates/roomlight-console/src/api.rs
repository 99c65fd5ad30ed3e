//! The console's routes: the page and its login, and the JSON API under `/api` with the same
//! powers (docs/console.md). Every route but the assets and the login passes the token check
//! first; every answer that is not an image is JSON, errors as `{"error", "item"}`.

use crate::auth::{self, Denied};
use crate::{Console, State, survey};
use axum::body::Body;
use axum::extract::{DefaultBodyLimit, Path as UrlPath, Request, State as Shared};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum::{Form, Json, Router};
use roomlight_agent::camera::Refused;
use serde_json::{Value, json};
use std::sync::Arc;
use tokio_stream::StreamExt as _;
use tokio_stream::wrappers::ReceiverStream;

const LOGIN: &str = include_str!("../assets/login.html");
const INDEX: &str = include_str!("../assets/index.html");
const APP_JS: &str = include_str!("../assets/app.js");
const APP_CSS: &str = include_str!("../assets/app.css");

/// The assets' total size (the page's weight, with its pictures aside).
pub const PAGE_BYTES: usize = LOGIN.len() + INDEX.len() + APP_JS.len() + APP_CSS.len();
// Issue 18's bound on the page, checked when the console is compiled.
const _: () = assert!(
    PAGE_BYTES <= 300_000,
    "the console's page (HTML, script, style) weighs over 300 kB"
);

/// An API error: its status and message, and the item it names.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    error: String,
    item: Option<String>,
}

impl ApiError {
    fn new(status: StatusCode, error: impl Into<String>) -> Self {
        Self {
            status,
            error: error.into(),
            item: None,
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (
            self.status,
            Json(json!({"error": self.error, "item": self.item})),
        )
            .into_response()
    }
}

impl From<Refused> for ApiError {
    fn from(r: Refused) -> Self {
        let status = match r {
            Refused::UnknownProjector(_) | Refused::UnknownPreset(..) => StatusCode::NOT_FOUND,
            Refused::Busy | Refused::Stopping | Refused::Camera(_) | Refused::Lights(_) => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            Refused::NoLights => StatusCode::CONFLICT,
            Refused::Model(_) => StatusCode::UNPROCESSABLE_ENTITY,
        };
        Self::new(status, r.to_string())
    }
}

type Answer = Result<Response, ApiError>;

/// The routes over `console`.
pub fn routes(console: State) -> Router {
    let api = Router::new()
        .route("/api/session", get(session))
        .route("/api/status", get(status))
        .route("/api/events", get(events))
        .route("/api/history", get(history))
        .route("/api/image.png", get(image))
        .route("/api/capture", post(capture))
        .route("/api/survey", get(survey_get).put(survey_put))
        .route("/api/survey/target.png", get(survey_target))
        .route("/api/calibrate", post(calibrate))
        .route("/api/calibration/{id}/coverage.png", get(coverage))
        .route("/api/calibration/{id}/attenuation.png", get(attenuation))
        .route("/api/projectors/{id}/frame.png", get(frame))
        .route("/api/pause", post(pause))
        .route("/api/resume", post(resume))
        .route("/api/preset", post(preset))
        .route("/api/identify", post(identify))
        .route("/api/snapshot", post(snapshot))
        .route("/api/report", get(report))
        .route("/logout", post(logout))
        .route_layer(middleware::from_fn_with_state(console.clone(), authorise));
    Router::new()
        .route("/", get(index))
        .route("/login", get(login_page).post(login))
        .route("/assets/app.js", get(app_js))
        .route("/assets/app.css", get(app_css))
        .merge(api)
        .layer(middleware::from_fn(bounded))
        .layer(DefaultBodyLimit::max(crate::MAX_BODY))
        .with_state(console)
}

/// Every request but the event stream is answered within [`crate::REQUEST_TIMEOUT`]; every
/// answer says not to be cached or framed.
async fn bounded(request: Request, next: Next) -> Response {
    let streaming = request.uri().path() == "/api/events";
    let mut response = if streaming {
        next.run(request).await
    } else {
        match tokio::time::timeout(crate::REQUEST_TIMEOUT, next.run(request)).await {
            Ok(r) => r,
            Err(_) => ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "timed out").into_response(),
        }
    };
    let h = response.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    response
}

/// The token check in front of the API.
async fn authorise(Shared(console): Shared<State>, request: Request, next: Next) -> Response {
    match console
        .sessions
        .check(&console.config.token, request.method(), request.headers())
    {
        Ok(_) => next.run(request).await,
        Err(Denied::Unauthenticated) => ApiError::new(
            StatusCode::UNAUTHORIZED,
            "log in: Authorization: Bearer TOKEN, or the session cookie of /login",
        )
        .into_response(),
        Err(Denied::NoCsrf) => ApiError::new(
            StatusCode::FORBIDDEN,
            "a cookie session's change needs its X-Roomlight-CSRF header (GET /api/session)",
        )
        .into_response(),
    }
}

fn asset(text: &'static str, kind: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], text).into_response()
}

async fn app_js() -> Response {
    asset(APP_JS, "text/javascript; charset=utf-8")
}

async fn app_css() -> Response {
    asset(APP_CSS, "text/css; charset=utf-8")
}

fn html(text: &'static str) -> Response {
    asset(text, "text/html; charset=utf-8")
}

async fn index(Shared(console): Shared<State>, headers: HeaderMap) -> Response {
    let logged_in = auth::session_id(&headers).is_some_and(|id| {
        console
            .sessions
            .check(&console.config.token, &axum::http::Method::GET, &headers)
            .is_ok()
            && !id.is_empty()
    });
    if logged_in {
        html(INDEX)
    } else {
        Redirect::to("/login").into_response()
    }
}

async fn login_page() -> Response {
    html(LOGIN)
}

#[derive(serde::Deserialize)]
struct LoginForm {
    token: String,
}

async fn login(Shared(console): Shared<State>, Form(form): Form<LoginForm>) -> Response {
    if !auth::token_matches(&form.token, &console.config.token) {
        tracing::info!("console: a login with a wrong token");
        // The form again, with its status: the page tells the installer (a browser does not
        // follow a redirect that comes with a 401).
        let mut page = html(LOGIN);
        *page.status_mut() = StatusCode::UNAUTHORIZED;
        return page;
    }
    let id = console.sessions.open();
    let mut response = Redirect::to("/").into_response();
    if let Ok(cookie) = HeaderValue::from_str(&auth::cookie(&id)) {
        response.headers_mut().insert(header::SET_COOKIE, cookie);
    }
    response
}

async fn logout(Shared(console): Shared<State>, headers: HeaderMap) -> Response {
    if let Some(id) = auth::session_id(&headers) {
        console.sessions.close(&id);
    }
    let mut response = Json(json!({"logged_out": true})).into_response();
    if let Ok(cookie) = HeaderValue::from_str(&auth::expired_cookie()) {
        response.headers_mut().insert(header::SET_COOKIE, cookie);
    }
    response
}

async fn session(Shared(console): Shared<State>, headers: HeaderMap) -> Json<Value> {
    let csrf =
        match console
            .sessions
            .check(&console.config.token, &axum::http::Method::GET, &headers)
        {
            Ok(auth::Who::Session { csrf }) => Some(csrf),
            _ => None,
        };
    Json(json!({ "csrf": csrf }))
}

/// The status as the API and the event stream give it.
pub fn status_json(console: &Console) -> Value {
    let s = console.status.borrow().clone();
    let o = console.overview.borrow().clone();
    let objective =
        (s.captures > 0 && s.measured_objective.is_finite()).then_some(s.measured_objective);
    let optimum = console.history.optimum();
    let excess = objective.and_then(|o| console.history.excess(o));
    let projectors: Vec<Value> = o
        .projectors
        .iter()
        .map(|p| {
            let display = s
                .displays_lost
                .iter()
                .find(|d| d.projector == p.id)
                .map(|d| format!("lost on {}: {}", d.output, d.reason));
            json!({
                "id": p.id, "state": p.state.as_str(), "nodes": p.nodes, "shown": p.shown,
                "width": p.width, "height": p.height, "display": display,
            })
        })
        .collect();
    let running = o.calibrating.as_ref().map(|c| {
        json!({"projectors": c.projectors, "stage": c.stage, "done": c.done, "expected": c.expected})
    });
    let results: Vec<Value> = o
        .calibrations
        .iter()
        .map(|r| {
            json!({
                "projector": r.projector, "decoded": r.decoded, "nodes": r.nodes,
                "captures": r.captures, "at_round": r.at_round, "warnings": r.warnings,
            })
        })
        .collect();
    let camera = match &s.camera {
        roomlight_agent::camera::CameraState::Ok => json!({"state": "working", "error": null}),
        roomlight_agent::camera::CameraState::Failing {
            last_error,
            failures,
            ..
        } => json!({"state": "failing", "error": last_error, "failures": failures}),
    };
    let image = console
        .images
        .latest()
        .map(|e| json!({"width": e.width, "height": e.height, "seq": e.seq}));
    let survey = console
        .config
        .survey
        .as_ref()
        .and_then(|p| std::fs::read(p).ok())
        .map(|bytes| json!({"version": survey::version(&bytes)}));
    json!({
        "room": console.control.room(),
        "round": s.round, "captures": s.captures,
        "objective": objective, "optimum": optimum, "excess": excess,
        // How many captures the errors of `objective` average (the round controller's).
        "averaged": objective.map(|_| s.averaged),
        // The most captures refused in a row as late: the camera's latency in frames.
        "late_frames": s.late_frames,
        "settled": s.settled, "paused": o.paused, "restarts": o.restarts,
        // Per-pixel shading passes sent for the current preset.
        "shading_passes": s.shading_passes,
        "camera": camera,
        "preset": o.preset, "presets": console.control.presets(),
        "projectors": projectors,
        "calibration": {"running": running, "results": results},
        "warnings": crate::warnings::recent(),
        "image": image,
        "survey": survey,
        // The weight of the light on the target in the objective, and its patches measured.
        "dark_target": console.control.dark_target()
            .map(|(weight, patches)| json!({"weight": weight, "patches": patches})),
        "consoles": console.events.len(),
        "t": console.started.elapsed().as_secs_f64(),
    })
}

async fn status(Shared(console): Shared<State>) -> Json<Value> {
    Json(status_json(&console))
}

async fn events(Shared(console): Shared<State>) -> Answer {
    let first: Arc<str> = status_json(&console).to_string().into();
    let Some(rx) = console.events.subscribe(first) else {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{} event streams are open already",
                crate::events::MAX_STREAMS
            ),
        ));
    };
    let stream = ReceiverStream::new(rx).map(|update| {
        Ok::<_, std::convert::Infallible>(Event::default().event("status").data(&*update))
    });
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response())
}

async fn history(Shared(console): Shared<State>) -> Json<Value> {
    Json(json!({"points": console.history.points(), "optimum": console.history.optimum()}))
}

fn png_response(png: Vec<u8>) -> Response {
    ([(header::CONTENT_TYPE, "image/png")], png).into_response()
}

async fn image(Shared(console): Shared<State>) -> Answer {
    let latest = console.images.latest().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "no photograph yet: take one (POST /api/capture)",
        )
    })?;
    Ok((
        [(header::CONTENT_TYPE, "image/png")],
        Body::from(latest.png.as_ref().clone()),
    )
        .into_response())
}

async fn capture(Shared(console): Shared<State>) -> Answer {
    let (seq, width, height) = console.control.photograph().await?;
    // Answered once the page can fetch it: the encoder runs off the round loop.
    let deadline = tokio::time::Instant::now() + crate::REQUEST_TIMEOUT / 2;
    while console.images.latest().is_none_or(|e| e.seq < seq) {
        if tokio::time::Instant::now() > deadline {
            return Err(ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "the photograph was taken but not encoded in time",
            ));
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    Ok(Json(json!({"width": width, "height": height, "seq": seq})).into_response())
}

fn survey_path(console: &Console) -> Result<&std::path::Path, ApiError> {
    console.config.survey.as_deref().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "this camera agent runs from a calibrated model, without a survey",
        )
    })
}

async fn survey_get(Shared(console): Shared<State>) -> Answer {
    let path = survey_path(&console)?;
    let (version, survey) =
        survey::read(path).map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
    Ok(Json(json!({"version": version, "survey": survey})).into_response())
}

#[derive(serde::Deserialize)]
struct SurveyPut {
    version: String,
    survey: survey::Survey,
}

async fn survey_put(
    Shared(console): Shared<State>,
    body: Result<Json<SurveyPut>, axum::extract::rejection::JsonRejection>,
) -> Answer {
    let Json(put) = body.map_err(|e| ApiError::new(e.status(), e.body_text()))?;
    let path = survey_path(&console)?;
    let _one_at_a_time = console.survey_lock.lock().await;
    let (version, current) =
        survey::read(path).map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
    if put.version != version {
        return Ok((
            StatusCode::CONFLICT,
            Json(json!({
                "error": "the survey changed since you loaded it: here is the current one",
                "version": version, "survey": current,
            })),
        )
            .into_response());
    }
    survey::validate(&put.survey, &current, &console.control.presets()).map_err(|e| ApiError {
        status: StatusCode::UNPROCESSABLE_ENTITY,
        error: e.to_string(),
        item: Some(e.item.clone()),
    })?;
    let path = path.to_path_buf();
    let new = put.survey;
    let version = tokio::task::spawn_blocking(move || survey::write(&path, &new))
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
    tracing::info!(%version, "console: survey saved (used when the camera agent starts again)");
    Ok(Json(json!({"version": version})).into_response())
}

/// Renders on the blocking pool, [`crate::images::AT_ONCE`] at a time.
async fn render(
    console: &Console,
    work: impl FnOnce() -> Result<Vec<u8>, String> + Send + 'static,
) -> Answer {
    let _permit = console
        .images
        .permits
        .acquire()
        .await
        .map_err(|_| ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "stopping"))?;
    let png = tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
    Ok(png_response(png))
}

async fn survey_target(Shared(console): Shared<State>) -> Answer {
    let path = survey_path(&console)?.to_path_buf();
    render(&console, move || {
        let (w, h, mask) = survey::target_mask(&path)?;
        let share: Vec<f32> = mask.iter().map(|&m| if m { 1.0 } else { 0.0 }).collect();
        crate::images::coverage_png(w, h, &share, None)
    })
    .await
}

#[derive(serde::Deserialize, Default)]
struct Which {
    #[serde(default)]
    projector: Option<String>,
}

async fn calibrate(Shared(console): Shared<State>, body: Option<Json<Which>>) -> Answer {
    let which = body.map(|Json(w)| w).unwrap_or_default();
    let queued = console.control.calibrate(which.projector).await?;
    Ok((StatusCode::ACCEPTED, Json(json!({"queued": queued}))).into_response())
}

/// The latest photograph whole, to draw maps over, when it is the survey camera's size.
fn under(console: &Console) -> Option<Arc<roomlight_calib::image_io::LinearImage>> {
    console
        .control
        .photos()
        .borrow()
        .as_ref()
        .map(|p| p.image.clone())
}

async fn coverage(Shared(console): Shared<State>, UrlPath(id): UrlPath<String>) -> Answer {
    let (w, h, share) = console.control.coverage(&id).ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            format!("no coverage of projector {id:?}: not segmented over the wire (yet)"),
        )
    })?;
    let photo = under(&console);
    render(&console, move || {
        crate::images::coverage_png(w, h, &share, photo.as_deref())
    })
    .await
}

async fn attenuation(Shared(console): Shared<State>, UrlPath(id): UrlPath<String>) -> Answer {
    let patches = console.control.attenuation(&id).ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            format!("projector {id:?} has no nodes in the model"),
        )
    })?;
    let path = survey_path(&console)?;
    let (_, survey) =
        survey::read(path).map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
    let photo = under(&console);
    render(&console, move || {
        crate::images::attenuation_png(
            survey.camera_width,
            survey.camera_height,
            &survey.charts,
            &patches,
            photo.as_deref(),
        )
    })
    .await
}

async fn frame(Shared(console): Shared<State>, UrlPath(id): UrlPath<String>) -> Answer {
    let frame = console.control.frame(&id).ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            format!("no projector {id:?} is attached"),
        )
    })?;
    if frame.pixels.is_empty() {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!("projector {id:?} has no nodes yet"),
        ));
    }
    render(&console, move || {
        crate::images::frame_png(frame.width, frame.height, &frame.pixels)
    })
    .await
}

async fn pause(Shared(console): Shared<State>) -> Answer {
    console.control.pause(true)?;
    Ok(Json(json!({"paused": true})).into_response())
}

async fn resume(Shared(console): Shared<State>) -> Answer {
    console.control.pause(false)?;
    Ok(Json(json!({"paused": false})).into_response())
}

#[derive(serde::Deserialize)]
struct Preset {
    preset: String,
}

async fn preset(
    Shared(console): Shared<State>,
    body: Result<Json<Preset>, axum::extract::rejection::JsonRejection>,
) -> Answer {
    let Json(p) = body.map_err(|e| ApiError::new(e.status(), e.body_text()))?;
    console.control.preset(p.preset.clone()).await?;
    Ok((StatusCode::ACCEPTED, Json(json!({"preset": p.preset}))).into_response())
}

#[derive(serde::Deserialize)]
struct Identify {
    projector: String,
    #[serde(default = "five")]
    seconds: u32,
}

fn five() -> u32 {
    5
}

async fn identify(
    Shared(console): Shared<State>,
    body: Result<Json<Identify>, axum::extract::rejection::JsonRejection>,
) -> Answer {
    let Json(i) = body.map_err(|e| ApiError::new(e.status(), e.body_text()))?;
    console.control.identify(&i.projector, i.seconds)?;
    Ok((
        StatusCode::ACCEPTED,
        Json(json!({"projector": i.projector})),
    )
        .into_response())
}

/// The report: status, history, calibration results.
fn report_json(console: &Console) -> Value {
    json!({
        "status": status_json(console),
        "history": console.history.points(),
        "optimum": console.history.optimum(),
    })
}

async fn report(Shared(console): Shared<State>) -> Response {
    let body = serde_json::to_string_pretty(&report_json(&console)).unwrap_or_default();
    (
        [
            (header::CONTENT_TYPE, "application/json"),
            (
                header::CONTENT_DISPOSITION,
                "attachment; filename=\"roomlight-report.json\"",
            ),
        ],
        body,
    )
        .into_response()
}

async fn snapshot(Shared(console): Shared<State>) -> Answer {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    let dir = console.config.snapshots.join(format!("snapshot-{stamp}"));
    // Said whole: a relative path means nothing in a browser.
    let dir = std::path::absolute(&dir).unwrap_or(dir);
    let report = serde_json::to_vec_pretty(&report_json(&console)).unwrap_or_default();
    let image = console.images.latest().map(|e| e.png);
    let model = console.config.model.clone();
    let target = dir.clone();
    tokio::task::spawn_blocking(move || -> std::io::Result<()> {
        std::fs::create_dir_all(&target)?;
        std::fs::write(target.join("report.json"), report)?;
        if let Some(png) = image {
            std::fs::write(target.join("camera.png"), png.as_slice())?;
        }
        if let Some(model) = model.filter(|m| m.exists()) {
            std::fs::copy(&model, target.join("model.json"))?;
        }
        Ok(())
    })
    .await
    .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
    .map_err(|e| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("{}: {e}", dir.display()),
        )
    })?;
    tracing::info!(path = %dir.display(), "console: snapshot saved");
    Ok(Json(json!({"path": dir.display().to_string()})).into_response())
}
