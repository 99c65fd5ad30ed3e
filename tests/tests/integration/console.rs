//! The installer's console over a running room (docs/console.md): its API against the router
//! (`tower::ServiceExt::oneshot`) and, for the event stream, on a real port. The room is the
//! sandbox's: a camera agent and node agents over loopback gRPC on a virtual room whose truth
//! the tests compare with what the console says.

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use roomlight_agent::camera::Lights;
use roomlight_agent::hardware::{Camera, VirtualCamera};
use roomlight_core::LinearRgb;
use roomlight_tests::{Sandbox, TOKEN};
use serde_json::{Value, json};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

use crate::console_support::{WITHIN, bearer, call, console, json_of, status_until};

/// Without the token nothing is told; with it the status names every projector live, the
/// round, and the measured objective, equal to the camera agent's own, with its excess over the
/// model's exact optimum; history points follow the rounds.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_status_tells_the_room_as_it_is() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    let (code, body) = json_of(
        &app,
        Request::get("/api/status")
            .body(Body::empty())
            .expect("request"),
    )
    .await;
    assert_eq!(code, StatusCode::UNAUTHORIZED, "{body}");
    let wrong = Request::get("/api/status")
        .header(header::AUTHORIZATION, "Bearer not-the-token")
        .body(Body::empty())
        .expect("request");
    assert_eq!(json_of(&app, wrong).await.0, StatusCode::UNAUTHORIZED);
    let s = status_until(&app, sb.status_watch(), |s| {
        s["captures"].as_u64() >= Some(3)
            && s["projectors"]
                .as_array()
                .is_some_and(|p| p.len() == 3 && p.iter().all(|p| p["state"] == "live"))
    })
    .await;
    let ids: Vec<&str> = s["projectors"]
        .as_array()
        .expect("projectors")
        .iter()
        .map(|p| p["id"].as_str().expect("id"))
        .collect();
    assert_eq!(ids, ["p0", "p1", "p2"]);
    assert!(
        s["projectors"][0]["nodes"] == 4 && s["projectors"][0]["shown"].as_u64().is_some(),
        "{s}"
    );
    assert!(s["round"].as_u64().expect("round") >= 1);
    let objective = s["objective"].as_f64().expect("an objective");
    let optimum = s["optimum"]
        .as_f64()
        .expect("the optimum of a 12-node room");
    assert!(
        objective >= 0.0 && optimum >= 0.0 && s["excess"].as_f64().is_some(),
        "{s}"
    );
    // The captures the objective averages, as the camera agent's round controller counts them.
    let averaged = s["averaged"].as_u64().expect("averaged");
    assert!(
        (1..2 * roomlight_core::round::AVERAGE_CAPTURES as u64).contains(&averaged),
        "{s}"
    );
    // A camera that hands over every frame at once: no capture was refused as late.
    assert_eq!(s["late_frames"].as_u64(), Some(0), "{s}");
    // The optimum is the camera agent's model's, computed independently here.
    let truth = roomlight_core::optimum::optimum(&sb.control().problem()).expect("optimum");
    assert!(
        (truth.objective - optimum).abs() <= 1e-9 * (1.0 + truth.objective),
        "{optimum} vs {}",
        truth.objective
    );
    let (_, history) = json_of(&app, bearer("GET", "/api/history", None)).await;
    let points = history["points"].as_array().expect("points");
    assert!(!points.is_empty());
    let rounds: Vec<u64> = points
        .iter()
        .map(|p| p["round"].as_u64().expect("round"))
        .collect();
    assert!(rounds.windows(2).all(|w| w[0] < w[1]), "{rounds:?}");
    assert!(points.iter().all(|p| p["t"].as_f64().is_some_and(|t| t >= 0.0) && p["objective"].as_f64().is_some()));
    cancel.cancel();
    sb.shutdown().await;
}

/// The page's login: a wrong token gets 401 and the form again, the right one an HttpOnly,
/// SameSite=Strict cookie; with it the page loads and the API reads, but changes need the
/// session's CSRF header; logging out ends it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_browser_logs_in_with_a_cookie_and_changes_need_csrf() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    let (code, headers, _) = call(
        &app,
        Request::get("/").body(Body::empty()).expect("request"),
    )
    .await;
    assert_eq!(code, StatusCode::SEE_OTHER);
    assert_eq!(headers[header::LOCATION], "/login");
    let login = |token: &str| {
        Request::post("/login")
            .header(header::CONTENT_TYPE, "application/x-www-form-urlencoded")
            .body(Body::from(format!("token={token}")))
            .expect("request")
    };
    let (code, headers, page) = call(&app, login("wrong")).await;
    assert_eq!(code, StatusCode::UNAUTHORIZED);
    assert!(headers.get(header::SET_COOKIE).is_none());
    // The form again (a browser does not follow a redirect that comes with a 401).
    assert!(String::from_utf8_lossy(&page).contains("name=\"token\""));
    let (code, headers, _) = call(&app, login(TOKEN)).await;
    assert_eq!(code, StatusCode::SEE_OTHER);
    let set = headers[header::SET_COOKIE].to_str().expect("cookie");
    assert!(
        set.contains("HttpOnly") && set.contains("SameSite=Strict"),
        "{set}"
    );
    let cookie = set.split(';').next().expect("name=value").to_string();
    let with_cookie = |method: &str, uri: &str, csrf: Option<&str>| {
        let mut b = Request::builder()
            .method(method)
            .uri(uri)
            .header(header::COOKIE, &cookie);
        if let Some(c) = csrf {
            b = b.header("x-roomlight-csrf", c);
        }
        b.body(Body::empty()).expect("request")
    };
    let (code, _, page) = call(&app, with_cookie("GET", "/", None)).await;
    assert_eq!(code, StatusCode::OK);
    assert!(String::from_utf8_lossy(&page).contains("<html"));
    let (code, session) = json_of(&app, with_cookie("GET", "/api/session", None)).await;
    assert_eq!(code, StatusCode::OK);
    let csrf = session["csrf"].as_str().expect("a CSRF token").to_string();
    assert_eq!(
        json_of(&app, with_cookie("POST", "/api/pause", None))
            .await
            .0,
        StatusCode::FORBIDDEN
    );
    assert_eq!(
        json_of(&app, with_cookie("POST", "/api/pause", Some("forged")))
            .await
            .0,
        StatusCode::FORBIDDEN
    );
    assert!(
        !sb.control().overview().borrow().paused,
        "a refused change changed nothing"
    );
    let (code, body) = json_of(&app, with_cookie("POST", "/api/pause", Some(&csrf))).await;
    assert_eq!(
        (code, body["paused"].as_bool()),
        (StatusCode::OK, Some(true))
    );
    assert_eq!(
        json_of(&app, with_cookie("POST", "/logout", Some(&csrf)))
            .await
            .0,
        StatusCode::OK
    );
    assert_eq!(
        json_of(&app, with_cookie("GET", "/api/status", None))
            .await
            .0,
        StatusCode::UNAUTHORIZED
    );
    cancel.cancel();
    sb.shutdown().await;
}

/// Until the camera agent says its rounds are paused.
async fn paused(sb: &Sandbox) {
    let mut overview = sb.control().overview();
    tokio::time::timeout(WITHIN, overview.wait_for(|o| o.paused))
        .await
        .expect("paused in time")
        .expect("the camera agent runs");
}

/// Pausing stops the captures after the current round (the projectors keep their light);
/// resuming starts them again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pause_stops_the_rounds_and_resume_restarts_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    sb.wait_captures(WITHIN, 2).await;
    assert_eq!(
        json_of(&app, bearer("POST", "/api/pause", None)).await.0,
        StatusCode::OK
    );
    paused(&sb).await;
    let paused = sb.status();
    let shown = sb.room.shown();
    // At most the round under way ends; then nothing is captured for as long as we look.
    let after = tokio::time::timeout(
        Duration::from_secs(2),
        sb.wait_captures(Duration::from_secs(60), 2),
    )
    .await;
    assert!(
        after.is_err(),
        "captures went on while paused: from {} to {}",
        paused.captures,
        sb.status().captures
    );
    assert_eq!(sb.room.shown().len(), shown.len());
    assert!(
        sb.room
            .shown()
            .iter()
            .all(|v| v.0.iter().all(|c| c.is_finite())),
        "the light stays"
    );
    assert_eq!(
        json_of(&app, bearer("POST", "/api/resume", None)).await.0,
        StatusCode::OK
    );
    sb.wait_captures(WITHIN, 2).await;
    assert!(!sb.control().overview().borrow().paused);
    cancel.cancel();
    sb.shutdown().await;
}

/// The virtual room's LEDs: a light added to every capture while they are on.
#[derive(Clone)]
struct Leds {
    on: Arc<Mutex<Option<String>>>,
    light: Vec<LinearRgb>,
}

impl Lights for Leds {
    fn presets(&self) -> Vec<String> {
        vec!["warm".into(), "cool".into()]
    }

    fn switch(
        &self,
        preset: Option<String>,
    ) -> std::pin::Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>> {
        *self.on.lock().unwrap_or_else(PoisonError::into_inner) = preset;
        Box::pin(std::future::ready(Ok(())))
    }
}

/// The virtual camera with the LEDs' light added when they are on.
struct LitCamera {
    inner: VirtualCamera,
    leds: Leds,
}

impl Camera for LitCamera {
    async fn capture(&mut self) -> Result<Vec<LinearRgb>, roomlight_agent::AgentError> {
        let mut y = self.inner.capture().await?;
        if self
            .leds
            .on
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .is_some()
        {
            for (v, l) in y.iter_mut().zip(&self.leds.light) {
                *v += *l;
            }
        }
        Ok(y)
    }
}

/// Switching the preset measures the LEDs' light while the projectors keep theirs, makes the
/// room's black plus it the target, restarts the rounds and switches the LEDs off again; an
/// unknown preset is refused naming the room's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_new_preset_is_measured_and_becomes_the_target() {
    let dir = tempfile::tempdir().expect("temp dir");
    let patches = roomlight_core::synthetic::synthetic_room(
        &roomlight_core::synthetic::SyntheticConfig::new(12, 1),
    )
    .expect("room")
    .problem
    .patches();
    let leds = Leds {
        on: Arc::new(Mutex::new(None)),
        light: (0..patches)
            .map(|i| LinearRgb([0.02 + 0.001 * i as f64, 0.03, 0.01]))
            .collect(),
    };
    let wrap = leds.clone();
    let mut sb = Sandbox::builder()
        .lights(Arc::new(leds.clone()))
        .start_with_camera(move |camera, _, _| LitCamera {
            inner: camera,
            leds: wrap,
        })
        .await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    sb.wait_captures(WITHIN, 2).await;
    let (code, body) = json_of(
        &app,
        bearer("POST", "/api/preset", Some(json!({"preset": "disco"}))),
    )
    .await;
    assert_eq!(code, StatusCode::NOT_FOUND);
    assert!(
        body["error"]
            .as_str()
            .expect("error")
            .contains("warm, cool"),
        "{body}"
    );
    let black = sb.control().problem().black().to_vec();
    let (code, body) = json_of(
        &app,
        bearer("POST", "/api/preset", Some(json!({"preset": "warm"}))),
    )
    .await;
    assert_eq!(code, StatusCode::ACCEPTED, "{body}");
    let s = status_until(&app, sb.status_watch(), |s| s["restarts"] == 1).await;
    assert_eq!(s["preset"], "warm");
    assert!(
        leds.on
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .is_none(),
        "the LEDs are off again"
    );
    let target = sb.control().problem().target().to_vec();
    let noise = sb.problem.noise().to_vec();
    for (i, ((t, b), l)) in target.iter().zip(&black).zip(&leds.light).enumerate() {
        for c in 0..3 {
            // Two captures' difference: within 6σ of the patch's noise.
            let tol = 6.0 * noise[i].0[c] * std::f64::consts::SQRT_2 + 1e-9;
            assert!(
                (t.0[c] - (b.0[c] + l.0[c])).abs() <= tol,
                "patch {i} channel {c}: {} vs {}",
                t.0[c],
                b.0[c] + l.0[c]
            );
        }
    }
    // The rounds go on toward the new target.
    sb.wait_captures(WITHIN, 2).await;
    cancel.cancel();
    sb.shutdown().await;
}

/// A survey file as `roomlight calibrate --survey-only` writes it (pixels only).
fn survey_file(path: &std::path::Path) {
    let file = json!({
        "camera_width": 640, "camera_height": 480,
        "corners": [{"name": "desk", "corners": [[10.0, 10.0], [130.0, 10.0], [130.0, 90.0], [10.0, 90.0]]}],
        "sample": {"saturation": 0.98, "read_noise": 0.001, "shot_noise": 0.004, "max_nonuniformity": 0.03},
        "target_pixels": [100, 101, 102]
    });
    std::fs::write(path, file.to_string()).expect("survey written");
}

/// The survey is read with its version; a bad edit is refused naming the item (nothing
/// written); a good one is written whole with its target rasterised and a new version; an
/// edit made from an old version gets 409 with the current survey.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_survey_is_validated_versioned_and_saved_whole() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("survey.json");
    survey_file(&path);
    let sb = Sandbox::builder().start_camera().await;
    let (app, cancel) = console(&sb, Some(path.clone()), dir.path());
    let (code, got) = json_of(&app, bearer("GET", "/api/survey", None)).await;
    assert_eq!(code, StatusCode::OK, "{got}");
    let v0 = got["version"].as_str().expect("version").to_string();
    assert_eq!(got["survey"]["target_pixels"], 3);
    let mut survey = got["survey"].clone();
    survey["charts"].as_array_mut().expect("charts").push(json!({"name": "wall", "corners": [[100.0, 50.0], [200.0, 50.0], [200.0, 120.0], [100.0, 120.0]]}));
    let before = std::fs::read(&path).expect("file");
    let (code, body) = json_of(
        &app,
        bearer(
            "PUT",
            "/api/survey",
            Some(json!({"version": v0, "survey": survey})),
        ),
    )
    .await;
    assert_eq!(code, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["item"], "charts[0] \"desk\"");
    assert!(
        body["error"]
            .as_str()
            .expect("error")
            .contains("overlaps chart \"wall\""),
        "{body}"
    );
    assert_eq!(
        std::fs::read(&path).expect("file"),
        before,
        "nothing written"
    );
    survey["charts"][1]["corners"] =
        json!([[300.0, 20.0], [400.0, 20.0], [400.0, 80.0], [300.0, 80.0]]);
    survey["target"] = json!([[
        [200.0, 200.0],
        [260.0, 200.0],
        [260.0, 240.0],
        [200.0, 240.0]
    ]]);
    let (code, body) = json_of(
        &app,
        bearer(
            "PUT",
            "/api/survey",
            Some(json!({"version": v0, "survey": survey})),
        ),
    )
    .await;
    assert_eq!(code, StatusCode::OK, "{body}");
    let v1 = body["version"].as_str().expect("version").to_string();
    assert_ne!(v0, v1);
    let written: Value =
        serde_json::from_slice(&std::fs::read(&path).expect("file")).expect("JSON");
    assert_eq!(
        written["target_pixels"].as_array().expect("pixels").len(),
        60 * 40
    );
    assert_eq!(written["corners"].as_array().expect("charts").len(), 2);
    // Someone else saved meanwhile: the old version is refused with the current survey.
    let (code, body) = json_of(
        &app,
        bearer(
            "PUT",
            "/api/survey",
            Some(json!({"version": v0, "survey": survey})),
        ),
    )
    .await;
    assert_eq!(code, StatusCode::CONFLICT, "{body}");
    assert_eq!(body["version"], v1.as_str());
    assert_eq!(
        body["survey"]["charts"].as_array().expect("charts").len(),
        2
    );
    // An edit by hand changes the version too.
    let mut by_hand = std::fs::read_to_string(&path).expect("file");
    by_hand.push('\n');
    std::fs::write(&path, by_hand).expect("edited");
    let (_, got) = json_of(&app, bearer("GET", "/api/survey", None)).await;
    assert_ne!(got["version"], v1.as_str());
    let (code, _, png) = call(&app, bearer("GET", "/api/survey/target.png", None)).await;
    assert_eq!(code, StatusCode::OK);
    let mask = image::load_from_memory(&png).expect("PNG").to_rgb8();
    assert_eq!(mask.dimensions(), (640, 480));
    assert!(mask.get_pixel(230, 220).0[0] > 200 && mask.get_pixel(100, 300).0[0] == 0);
    cancel.cancel();
    sb.shutdown().await;
}

/// Calibrating one projector again measures it hot while the others keep their light: its
/// state shows calibrating, then live with a result; an unknown projector is 404.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_projector_is_calibrated_again_on_request() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    sb.wait_captures(WITHIN, 2).await;
    // The rounds may run before every node is attached (a CI run asked for p1 first: 404).
    status_until(&app, sb.status_watch(), |s| {
        s["projectors"]
            .as_array()
            .is_some_and(|p| p.iter().any(|p| p["id"] == "p1" && p["state"] == "live"))
    })
    .await;
    let (code, body) = json_of(
        &app,
        bearer("POST", "/api/calibrate", Some(json!({"projector": "p9"}))),
    )
    .await;
    assert_eq!(code, StatusCode::NOT_FOUND, "{body}");
    let (code, body) = json_of(
        &app,
        bearer("POST", "/api/calibrate", Some(json!({"projector": "p1"}))),
    )
    .await;
    assert_eq!(
        (code, body["queued"].clone()),
        (StatusCode::ACCEPTED, json!(["p1"]))
    );
    let s = status_until(&app, sb.status_watch(), |s| {
        s["calibration"]["results"]
            .as_array()
            .is_some_and(|r| r.iter().any(|r| r["projector"] == "p1"))
            && s["projectors"]
                .as_array()
                .is_some_and(|p| p.iter().all(|p| p["state"] == "live"))
    })
    .await;
    let result = s["calibration"]["results"]
        .as_array()
        .expect("results")
        .iter()
        .find(|r| r["projector"] == "p1")
        .expect("p1")
        .clone();
    assert_eq!(result["nodes"], 4);
    assert_eq!(result["warnings"], json!([]), "{result}");
    assert!(s["calibration"]["running"].is_null());
    // Its measured columns are the truth's (a noise-free virtual room).
    let problem = sb.control().problem();
    for n in sb.nodes_of("p1") {
        let (got, truth) = (&problem.columns()[n], &sb.problem.columns()[n]);
        for (i, p) in truth.iter() {
            let g = got.get(i);
            assert!(
                (0..3).all(|c| (g.0[c] - p.0[c]).abs() <= 1e-6 + 1e-3 * p.0[c]),
                "node {n} patch {i}: {g:?} vs {p:?}"
            );
        }
    }
    sb.wait_captures(WITHIN, 2).await;
    cancel.cancel();
    sb.shutdown().await;
}

/// A projector's frame thumbnail shows its nodes' values as the camera agent follows them
/// (starts plus contributions), which are the values the virtual projectors show.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frame_thumbnails_follow_the_nodes_values() {
    let dir = tempfile::tempdir().expect("temp dir");
    let start: Vec<LinearRgb> = (0..12)
        .map(|n| LinearRgb::splat(0.2 + 0.05 * n as f64))
        .collect();
    let mut sb = Sandbox::builder().start(start).start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    sb.wait_captures(WITHIN, 3).await;
    // Paused, the values hold still while we compare.
    assert_eq!(
        json_of(&app, bearer("POST", "/api/pause", None)).await.0,
        StatusCode::OK
    );
    paused(&sb).await;
    let settled = tokio::time::timeout(
        Duration::from_secs(2),
        sb.wait_captures(Duration::from_secs(60), 2),
    )
    .await;
    assert!(settled.is_err(), "no rounds while paused");
    let (code, _, png) = call(&app, bearer("GET", "/api/projectors/p2/frame.png", None)).await;
    assert_eq!(code, StatusCode::OK);
    let strip = image::load_from_memory(&png).expect("PNG").to_rgb8();
    assert_eq!(strip.dimensions(), (4 * 16, 16));
    for (k, v) in sb.shown_by("p2").iter().enumerate() {
        let px = strip.get_pixel(k as u32 * 16 + 8, 8).0;
        for (c, (code, value)) in px.iter().zip(v.0).enumerate() {
            let x = value.clamp(0.0, 1.0);
            let srgb = if x <= 0.003_130_8 {
                12.92 * x
            } else {
                1.055 * x.powf(1.0 / 2.4) - 0.055
            };
            assert!(
                (f64::from(*code) - srgb * 255.0).abs() <= 1.5,
                "node {k} channel {c}: {code} vs {x}"
            );
        }
    }
    assert_eq!(
        call(&app, bearer("GET", "/api/projectors/p7/frame.png", None))
            .await
            .0,
        StatusCode::NOT_FOUND
    );
    // Identify: accepted for a projector, refused for another.
    assert_eq!(
        json_of(
            &app,
            bearer("POST", "/api/identify", Some(json!({"projector": "p0"})))
        )
        .await
        .0,
        StatusCode::ACCEPTED
    );
    assert_eq!(
        json_of(
            &app,
            bearer("POST", "/api/identify", Some(json!({"projector": "p7"})))
        )
        .await
        .0,
        StatusCode::NOT_FOUND
    );
    // A snapshot is a folder with the report in it; the report downloads as an attachment.
    let (code, body) = json_of(&app, bearer("POST", "/api/snapshot", None)).await;
    assert_eq!(code, StatusCode::OK, "{body}");
    let report: Value = serde_json::from_slice(
        &std::fs::read(
            std::path::Path::new(body["path"].as_str().expect("path")).join("report.json"),
        )
        .expect("report"),
    )
    .expect("JSON");
    assert_eq!(
        report["status"]["projectors"].as_array().map(Vec::len),
        Some(3)
    );
    let (code, headers, _) = call(&app, bearer("GET", "/api/report", None)).await;
    assert_eq!(code, StatusCode::OK);
    assert!(
        headers[header::CONTENT_DISPOSITION]
            .to_str()
            .expect("header")
            .starts_with("attachment")
    );
    cancel.cancel();
    sb.shutdown().await;
}

/// A browser cannot overwhelm the console: a body over the limit is 413, a capture from a
/// camera without images is 503 (and the rounds go on), and a stream of events arrives on a
/// real port, round after round.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bounds_and_the_event_stream() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut sb = Sandbox::builder().start_camera().await;
    sb.add_all_nodes();
    let (app, cancel) = console(&sb, None, dir.path());
    let huge = "x".repeat(roomlight_console::MAX_BODY + 10);
    let request = Request::post("/api/preset")
        .header(header::AUTHORIZATION, format!("Bearer {TOKEN}"))
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(format!("{{\"preset\": \"{huge}\"}}")))
        .expect("request");
    assert_eq!(call(&app, request).await.0, StatusCode::PAYLOAD_TOO_LARGE);
    // A flood of requests (2 000: status, history, thumbnails) does not hold the rounds up:
    // captures go on while it is served, and every request is answered. It starts once every
    // projector has its nodes (two captures alone did not promise that on a loaded machine:
    // a late p1 had no frame yet, and its thumbnail was a 404).
    sb.wait_captures(WITHIN, 2).await;
    status_until(&app, sb.status_watch(), |s| {
        s["projectors"].as_array().is_some_and(|p| {
            p.len() == 3 && p.iter().all(|p| p["nodes"].as_u64().is_some_and(|n| n > 0))
        })
    })
    .await;
    let flood: Vec<_> = (0..2000)
        .map(|i| {
            let app = app.clone();
            let path = [
                "/api/status",
                "/api/history",
                "/api/projectors/p1/frame.png",
            ][i % 3];
            tokio::spawn(async move { call(&app, bearer("GET", path, None)).await.0 })
        })
        .collect();
    sb.wait_captures(WITHIN, 3).await;
    for request in flood {
        assert_eq!(request.await.expect("answered"), StatusCode::OK);
    }
    let (code, body) = json_of(&app, bearer("POST", "/api/capture", None)).await;
    assert_eq!(code, StatusCode::SERVICE_UNAVAILABLE, "{body}");
    assert_eq!(
        sb.status().camera,
        roomlight_agent::camera::CameraState::Ok,
        "the camera's health is untouched"
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("address");
    let served = tokio::spawn(axum::serve(listener, app).into_future());
    let mut stream = tokio::net::TcpStream::connect(addr).await.expect("connect");
    stream
        .write_all(
            format!("GET /api/events HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n\r\n")
                .as_bytes(),
        )
        .await
        .expect("request");
    let mut text = String::new();
    let mut rounds = Vec::new();
    let deadline = tokio::time::Instant::now() + WITHIN;
    while rounds.len() < 4 {
        let mut buf = [0u8; 8192];
        let n = tokio::time::timeout_at(deadline, stream.read(&mut buf))
            .await
            .expect("events in time")
            .expect("read");
        assert!(n > 0, "the stream ended: {text}");
        text.push_str(&String::from_utf8_lossy(&buf[..n]));
        while let Some(end) = text.find("\n\n") {
            let event: String = text.drain(..end + 2).collect();
            if let Some(data) = event.lines().find_map(|l| l.strip_prefix("data: ")) {
                assert!(event.contains("event: status"), "{event}");
                let s: Value = serde_json::from_str(data).expect("status JSON");
                let round = s["round"].as_u64().expect("round");
                if rounds.last() != Some(&round) {
                    rounds.push(round);
                }
            }
        }
    }
    assert!(rounds.windows(2).all(|w| w[0] < w[1]), "{rounds:?}");
    served.abort();
    cancel.cancel();
    sb.shutdown().await;
}
