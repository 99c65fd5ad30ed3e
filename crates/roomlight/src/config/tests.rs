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

const WINDOW_NODE: &str = "room = \"r\"\ntoken = \"t\"\ncamera = \"http://127.0.0.1:1\"\n\
                           projector = \"p0\"\n";

#[test]
fn a_window_display_is_read_and_checked() {
    let (_dir, path) = file(
        "w.toml",
        &format!(
            "{WINDOW_NODE}display = {{ kind = \"window\", output = \"HDMI-1\", settle_ms = 80 }}\n"
        ),
    );
    let node = load_node(&path).expect("a window display");
    let NodeDisplay::Window(spec) = node.display else {
        panic!("{:?}", node.display)
    };
    assert_eq!(
        spec.output,
        roomlight_hw::OutputSelector::Name("HDMI-1".into())
    );
    assert_eq!(spec.settle, std::time::Duration::from_millis(80));
    assert_eq!(spec.x_display, None);

    let (_dir, path) = file(
        "g.toml",
        &format!(
            "{WINDOW_NODE}display = {{ kind = \"window\", output = \"320x240+320+0\", x_display = \":3\" }}\n"
        ),
    );
    let node = load_node(&path).expect("by geometry, settle by default");
    let NodeDisplay::Window(spec) = node.display else {
        panic!("{:?}", node.display)
    };
    assert!(matches!(
        spec.output,
        roomlight_hw::OutputSelector::Geometry(_)
    ));
    assert_eq!(spec.settle, std::time::Duration::from_millis(80));
    assert_eq!(spec.x_display.as_deref(), Some(":3"));

    let (_dir, path) = file(
        "sim.toml",
        &format!("{NODE}display = {{ kind = \"sim\" }}\n"),
    );
    assert!(matches!(
        load_node(&path).expect("sim").display,
        NodeDisplay::Synthetic
    ));
}

#[test]
fn a_bad_window_display_is_refused_naming_file_and_field() {
    let err = node_err(
        "s.toml",
        &format!(
            "{WINDOW_NODE}display = {{ kind = \"window\", output = \"A\", settle_ms = 60000 }}\n"
        ),
    );
    assert!(
        err.contains("s.toml") && err.contains("display.settle_ms = 60000"),
        "{err}"
    );
    let err = node_err(
        "u.toml",
        &format!("{WINDOW_NODE}display = {{ kind = \"window\", output = \"A\", vsync = true }}\n"),
    );
    assert!(err.contains("u.toml") && err.contains("vsync"), "{err}");
    let err = node_err(
        "k.toml",
        &format!("{WINDOW_NODE}display = {{ kind = \"beamer\" }}\n"),
    );
    assert!(err.contains("k.toml") && err.contains("beamer"), "{err}");
    let err = node_err(
        "h.toml",
        &format!(
            "{WINDOW_NODE}hardware = {{ sim = \"http://127.0.0.1:1\" }}\n\
             display = {{ kind = \"window\", output = \"A\" }}\n"
        ),
    );
    assert!(
        err.contains("h.toml") && err.contains("no hardware"),
        "{err}"
    );
    let err = node_err("m.toml", WINDOW_NODE);
    assert!(
        err.contains("m.toml") && err.contains("hardware is missing"),
        "{err}"
    );
    let err = node_err(
        "o.toml",
        &format!("{WINDOW_NODE}display = {{ kind = \"window\", output = \"0x0+1+1\" }}\n"),
    );
    assert!(
        err.contains("o.toml") && err.contains("display.output"),
        "{err}"
    );
}
