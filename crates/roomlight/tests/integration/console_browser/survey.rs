//! The Survey page: a capture, a target polygon drawn and saved, and the refusals (a file
//! changed meanwhile, a chart name twice) as the page shows them.

use std::path::Path;
use std::time::Duration;

use fantoccini::Locator;
use fantoccini::actions::{InputSource, MOUSE_BUTTON_LEFT, MouseActions, PointerAction};
use serde_json::Value;

use super::Api;
use super::browser::Browser;
use super::room::Room;

/// A capture is taken and shown; a target polygon clicked on the overlay is saved, and the API
/// and the file on disk have it, in full camera pixels.
pub async fn survey_page(b: &Browser, room: &Room, api: &Api, shots: &Path) {
    b.click("a[href='#survey']").await;
    let before = api.get("/api/survey").await;
    let file_before = std::fs::read(room.dir().join("survey.json")).expect("survey file");
    let polygons_before = before["survey"]["target"].as_array().map_or(0, Vec::len);
    b.click("#capture").await;
    b.until("the capture shown", Duration::from_secs(20), async || {
        let seen = b
            .js("const i = document.getElementById('survey-image'); \
                 return [document.getElementById('survey-message').textContent, \
                 i.complete && i.naturalWidth > 0 && !i.classList.contains('missing')]")
            .await;
        let captured = seen[0].as_str().is_some_and(|m| m.starts_with("captured"));
        (captured && seen[1] == true)
            .then_some(())
            .ok_or(seen.to_string())
    })
    .await;
    // WebDriver moves relative to the centre of the element's part in view; the page converts
    // the click to camera pixels from the overlay's shown size.
    let geometry = b
        .js("const c = document.getElementById('survey-overlay'); \
             c.scrollIntoView({block: 'center'}); \
             const r = c.getBoundingClientRect(); \
             const cx = (Math.max(r.left, 0) + Math.min(r.right, innerWidth)) / 2 - r.left; \
             const cy = (Math.max(r.top, 0) + Math.min(r.bottom, innerHeight)) / 2 - r.top; \
             return [cx, cy, r.width, r.height]")
        .await;
    let number = |k: usize| geometry[k].as_f64().expect("a number");
    let (cx, cy, shown_w, shown_h) = (number(0), number(1), number(2), number(3));
    let offsets = [
        (120.0, -100.0),
        (200.0, -100.0),
        (200.0, -40.0),
        (120.0, -40.0),
    ];
    b.click("#draw-target").await;
    let overlay = b
        .client
        .find(Locator::Css("#survey-overlay"))
        .await
        .expect("the overlay");
    b.client
        .perform_actions(clicks(&overlay, &offsets))
        .await
        .expect("four clicks on the overlay");
    b.click("#close-polygon").await;
    let listed = b
        .js("return document.querySelectorAll('#polygon-list li:not(.empty)').length")
        .await;
    assert_eq!(listed, polygons_before as u64 + 1, "polygons listed");
    b.screenshot(shots, "survey").await;
    b.click("#save-survey").await;
    b.until("the survey saved", Duration::from_secs(15), async || {
        let said = b
            .js("return document.getElementById('survey-message').textContent")
            .await;
        let saved = said.as_str().is_some_and(|s| s.starts_with("saved"));
        saved.then_some(()).ok_or(said.to_string())
    })
    .await;
    let after = api.get("/api/survey").await;
    let survey = &after["survey"];
    let camera = |key: &str| survey[key].as_f64().expect("camera size");
    let (camera_w, camera_h) = (camera("camera_width"), camera("camera_height"));
    let expected: Vec<[f64; 2]> = offsets
        .iter()
        .map(|(dx, dy)| {
            [
                (cx + dx) / shown_w * camera_w,
                (cy + dy) / shown_h * camera_h,
            ]
        })
        .collect();
    let target = survey["target"].as_array().expect("target polygons");
    assert_eq!(target.len(), polygons_before + 1, "{target:?}");
    // Within two camera pixels: WebDriver rounds the element's centre to a CSS pixel (about
    // 0.8 camera pixels here), the page to a tenth of a camera pixel.
    let near = |polygon: &Value| {
        polygon.as_array().is_some_and(|points| {
            points.len() == expected.len()
                && points.iter().zip(&expected).all(|(p, e)| {
                    (0..2).all(|k| p[k].as_f64().is_some_and(|v| (v - e[k]).abs() < 2.0))
                })
        })
    };
    assert!(
        target.iter().any(near),
        "no polygon near {expected:?} in {target:?}"
    );
    assert_ne!(after["version"], before["version"], "a new version");
    let file_after = std::fs::read(room.dir().join("survey.json")).expect("survey file");
    assert_ne!(file_after, file_before, "survey.json on disk unchanged");
}

/// The survey's refusals as the page shows them: a file changed meanwhile (by hand here) is
/// 409 and reloaded; a second chart of the same name is 422 naming it.
pub async fn survey_refusals(b: &Browser, room: &Room, api: &Api) {
    let message = async || {
        b.js("return document.getElementById('survey-message').textContent")
            .await
            .as_str()
            .unwrap_or_default()
            .to_string()
    };
    // An edit here, then the file edited by hand: saving the edit is refused.
    b.type_into("#sample-saturation", "0.97").await;
    let file = room.dir().join("survey.json");
    let mut text = std::fs::read(&file).expect("survey file");
    text.push(b'\n');
    std::fs::write(&file, text).expect("edit the survey by hand");
    b.click("#save-survey").await;
    b.until("changed meanwhile", Duration::from_secs(10), async || {
        let said = message().await;
        said.starts_with("changed meanwhile")
            .then_some(())
            .ok_or(said)
    })
    .await;
    let saturation = b
        .js("return document.getElementById('sample-saturation').value")
        .await;
    assert_ne!(
        saturation, "0.97",
        "the edit is replaced by the file's survey"
    );
    let survey = api.get("/api/survey").await;
    let name = survey["survey"]["charts"][0]["name"]
        .as_str()
        .expect("a chart")
        .to_string();
    b.click("#add-chart").await;
    b.js(
        "document.getElementById('survey-overlay').scrollIntoView({block: 'center'}); return null",
    )
    .await;
    let overlay = b
        .client
        .find(Locator::Css("#survey-overlay"))
        .await
        .expect("the overlay");
    let corners = [
        (-300.0, -220.0),
        (-240.0, -220.0),
        (-240.0, -180.0),
        (-300.0, -180.0),
    ];
    b.client
        .perform_actions(clicks(&overlay, &corners))
        .await
        .expect("four corners");
    b.type_into("#chart-name", &name).await;
    b.click("#confirm-chart").await;
    b.click("#save-survey").await;
    b.until(
        "a second chart of the same name refused",
        Duration::from_secs(10),
        async || {
            let said = message().await;
            said.contains(&name).then_some(()).ok_or(said)
        },
    )
    .await;
    let now = api.get("/api/survey").await;
    assert_eq!(now["version"], survey["version"], "nothing saved");
    b.click("#reload-survey").await;
}

/// A click at each offset from `element`'s centre (CSS pixels).
fn clicks(element: &fantoccini::elements::Element, offsets: &[(f64, f64)]) -> MouseActions {
    let mut mouse = MouseActions::new("mouse".to_string());
    for &(x, y) in offsets {
        mouse = mouse
            .then(PointerAction::MoveToElement {
                element: element.clone(),
                duration: None,
                x,
                y,
            })
            .then(PointerAction::Down {
                button: MOUSE_BUTTON_LEFT,
            })
            .then(PointerAction::Up {
                button: MOUSE_BUTTON_LEFT,
            });
    }
    mouse
}
