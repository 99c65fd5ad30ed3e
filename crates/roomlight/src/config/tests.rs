//! Each refusal names the file and the field; the deploy examples load.

use super::*;
use roomlight_lab::process::{CameraSource, NodeDisplay};
use std::path::PathBuf;

const CAMERA: &str = "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n\
                      hardware = { sim = \"http://127.0.0.1:1\" }\nmodel = \"m.json\"\n";
const NODE: &str = "room = \"r\"\ntoken = \"t\"\ncamera = \"http://127.0.0.1:1\"\n\
                    hardware = { sim = \"http://127.0.0.1:1\" }\nprojector = \"p0\"\n";

/// Writes `text` to `name` in a fresh folder (kept alive by the returned guard).
fn file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("config");
    (dir, path)
}

fn camera_err(name: &str, text: &str) -> String {
    let (_dir, path) = file(name, text);
    format!("{:#}", load_camera(&path).expect_err("refused"))
}

fn node_err(name: &str, text: &str) -> String {
    let (_dir, path) = file(name, text);
    format!("{:#}", load_node(&path).expect_err("refused"))
}

fn deploy(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy")
        .join(name)
}

#[test]
fn the_deploy_examples_load() {
    let camera = load_camera(&deploy("camera.toml")).expect("deploy/camera.toml");
    assert_eq!(camera.hardware, "http://127.0.0.1:50050");
    assert_eq!(
        camera.agent.deadline,
        std::time::Duration::from_millis(2000)
    );
    assert!(matches!(
        camera.source,
        CameraSource::Model { charts: None, .. }
    ));
    assert!(camera.advertise.is_some());
    let node = load_node(&deploy("node.toml")).expect("deploy/node.toml");
    assert_eq!(
        node.camera,
        CameraLocation::Address("http://127.0.0.1:50051".into())
    );
    assert!(matches!(node.display, NodeDisplay::Synthetic));
    let agent = node.agent_config("http://x:1".into());
    assert_eq!(agent.projector_id, "p0");
    assert_eq!(
        agent.rule,
        roomlight_core::StepRule::Momentum { theta: 1.0 }
    );
}

#[test]
fn unknown_fields_are_refused() {
    let e = camera_err("cam.toml", &format!("{CAMERA}heartbeat = 5\n"));
    assert!(
        e.contains("cam.toml") && e.contains("unknown field `heartbeat`"),
        "{e}"
    );
    let e = node_err("n.toml", &format!("{NODE}thetaa = 1.0\n"));
    assert!(e.contains("n.toml") && e.contains("thetaa"), "{e}");
}

#[test]
fn bad_enums_are_refused_with_the_choices() {
    let e = node_err("n.toml", &format!("{NODE}rule = \"fast\"\n"));
    assert!(
        e.contains("n.toml") && e.contains("rule") && e.contains("momentum"),
        "{e}"
    );
    let e = node_err("n.toml", &format!("{NODE}kind = \"fresnel\"\n"));
    assert!(e.contains("kind") && e.contains("large-aperture"), "{e}");
    // A bare endpoint is the old form of `hardware`; it now says which backend it is.
    let e = camera_err(
        "cam.toml",
        &CAMERA.replace("{ sim = \"http://127.0.0.1:1\" }", "\"http://127.0.0.1:1\""),
    );
    assert!(e.contains("cam.toml") && e.contains("hardware"), "{e}");
    let e = node_err(
        "n.toml",
        &NODE.replace(
            "\"http://127.0.0.1:1\"\nhardware",
            "{ dns = \"r\" }\nhardware",
        ),
    );
    assert!(
        e.contains("n.toml") && e.contains("camera") && e.contains("dns"),
        "{e}"
    );
}

#[test]
fn out_of_range_numbers_are_refused_naming_file_and_field() {
    // A deadline of u64::MAX panicked in the round's time arithmetic.
    let e = camera_err("cam.toml", &format!("{CAMERA}deadline_ms = {}\n", u64::MAX));
    assert!(
        e.contains("cam.toml") && e.contains("deadline_ms = 18446744073709551615"),
        "{e}"
    );
    assert!(e.contains("expected 10 to 600000 milliseconds"), "{e}");
    let e = camera_err("cam.toml", &format!("{CAMERA}heartbeat_ms = 0\n"));
    assert!(e.contains("heartbeat_ms = 0"), "{e}");
    let e = camera_err("cam.toml", &format!("{CAMERA}stale_frames = 1000000\n"));
    assert!(e.contains("stale_frames"), "{e}");
    let e = camera_err("cam.toml", &format!("{CAMERA}mdns_port = 0\n"));
    assert!(e.contains("mdns_port = 0"), "{e}");
    let e = node_err("n.toml", &format!("{NODE}start = 1.5\n"));
    assert!(e.contains("n.toml") && e.contains("start = 1.5"), "{e}");
    let e = node_err("n.toml", &format!("{NODE}theta = 2.5\n"));
    assert!(e.contains("n.toml") && e.contains("theta = 2.5"), "{e}");
    let e = node_err("n.toml", &format!("{NODE}mdns_wait_s = 0\n"));
    assert!(e.contains("mdns_wait_s = 0"), "{e}");
    let e = node_err("n.toml", &format!("{NODE}theta = nan\n"));
    assert!(e.contains("theta = NaN"), "{e}");
}

#[test]
fn the_camera_is_found_by_address_or_over_mdns() {
    let (_d, path) = file(
        "n.toml",
        &NODE.replace(
            "\"http://127.0.0.1:1\"\nhardware",
            "{ mdns = \"lab\" }\nhardware",
        ),
    );
    let node = load_node(&path).expect("mdns table");
    assert_eq!(node.camera, CameraLocation::Mdns("lab".into()));
    // The old form: the agent of the node's own room.
    let (_d, path) = file(
        "n.toml",
        &NODE.replace("\"http://127.0.0.1:1\"\nhardware", "\"mdns\"\nhardware"),
    );
    let node = load_node(&path).expect("mdns string");
    assert_eq!(node.camera, CameraLocation::Mdns("r".into()));
}

#[test]
fn sources_that_contradict_each_other_are_refused() {
    let e = camera_err("cam.toml", &format!("{CAMERA}survey = \"s.json\"\n"));
    assert!(e.contains("either model"), "{e}");
    let e = node_err(
        "n.toml",
        &format!("{NODE}frame = \"f.json\"\nrendered = true\n"),
    );
    assert!(e.contains("n.toml") && e.contains("not both"), "{e}");
}
