//! The agents' config files through `roomlight camera|node --config FILE --check`, which loads,
//! checks and prints what would run: each refusal names the file and the field; the deploy
//! examples load.

use std::path::{Path, PathBuf};
use std::process::Command;

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

/// `roomlight AGENT --config PATH --check`: what it printed, squashed (no whitespace, no
/// trailing commas) so that tests read the Debug form on one line; or what it said when it
/// refused.
fn check(agent: &str, path: &Path) -> Result<String, String> {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args([agent, "--config"])
        .arg(path)
        .arg("--check")
        .output()
        .expect("running roomlight");
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let text: String = String::from_utf8_lossy(&out.stdout)
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    Ok(text
        .replace(",)", ")")
        .replace(",}", "}")
        .replace(",]", "]"))
}

fn load_camera(path: &Path) -> Result<String, String> {
    check("camera", path)
}

fn load_node(path: &Path) -> Result<String, String> {
    check("node", path)
}

fn camera_err(name: &str, text: &str) -> String {
    let (_dir, path) = file(name, text);
    load_camera(&path).expect_err("refused")
}

fn node_err(name: &str, text: &str) -> String {
    let (_dir, path) = file(name, text);
    load_node(&path).expect_err("refused")
}

fn deploy(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy")
        .join(name)
}

#[test]
fn the_deploy_examples_load() {
    let camera = load_camera(&deploy("camera.toml")).expect("deploy/camera.toml");
    for part in [
        "hardware:Sim(\"http://127.0.0.1:50050\")",
        "deadline:2s",
        "source:Model{",
        "charts:None}",
        "advertise:Some(",
    ] {
        assert!(camera.contains(part), "{part} in {camera}");
    }
    let node = load_node(&deploy("node.toml")).expect("deploy/node.toml");
    for part in [
        "camera:Address(\"http://127.0.0.1:50051\")",
        "display:Synthetic",
        "projector:\"p0\"",
        "rule:Momentum{theta:1.0}",
    ] {
        assert!(node.contains(part), "{part} in {node}");
    }
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

/// An empty token would admit anyone who sends none: refused at load, naming file and field
/// (never printing a token); so is one longer than the camera agent compares, and waits that
/// would overflow a Duration's arithmetic.
#[test]
fn empty_or_oversized_tokens_and_overflowing_waits_are_refused() {
    let empty_camera = CAMERA.replace("token = \"t\"", "token = \"\"");
    let e = camera_err("cam.toml", &empty_camera);
    assert!(
        e.contains("cam.toml") && e.contains("token is empty"),
        "{e}"
    );
    let empty_node = NODE.replace("token = \"t\"", "token = \"  \"");
    let e = node_err("n.toml", &empty_node);
    assert!(e.contains("n.toml") && e.contains("token is empty"), "{e}");
    let long = NODE.replace(
        "token = \"t\"",
        &format!("token = \"{}\"", "k".repeat(2000)),
    );
    let e = node_err("n.toml", &long);
    assert!(
        e.contains("token of 2000 bytes") && !e.contains("kkkk"),
        "{e}"
    );
    let e = node_err("n.toml", &format!("{NODE}mdns_wait_s = {}\n", u64::MAX));
    assert!(
        e.contains("n.toml") && e.contains("mdns_wait_s = 18446744073709551615"),
        "{e}"
    );
    let e = camera_err(
        "cam.toml",
        &format!("{CAMERA}heartbeat_ms = {}\n", u64::MAX),
    );
    assert!(e.contains("heartbeat_ms = 18446744073709551615"), "{e}");
}

#[test]
fn the_camera_is_found_by_address_or_over_mdns() {
    let (_d, path) = file(
        "n.toml",
        &NODE.replace(
            "\"http://127.0.0.1:1\"\nhardware",
            // Over mDNS on every interface: plaintext needs insecure (no tls here).
            "{ mdns = \"lab\" }\ninsecure = true\nhardware",
        ),
    );
    let node = load_node(&path).expect("mdns table");
    assert!(node.contains("camera:Mdns(\"lab\")"), "{node}");
    // The old form: the agent of the node's own room.
    let (_d, path) = file(
        "n.toml",
        &NODE.replace(
            "\"http://127.0.0.1:1\"\nhardware",
            "\"mdns\"\ninsecure = true\nhardware",
        ),
    );
    let node = load_node(&path).expect("mdns string");
    assert!(node.contains("camera:Mdns(\"r\")"), "{node}");
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
    for part in [
        "display:Window(WindowSpec{x_display:None",
        "output:Name(\"HDMI-1\")",
        "settle:80ms",
    ] {
        assert!(node.contains(part), "{part} in {node}");
    }

    let (_dir, path) = file(
        "g.toml",
        &format!(
            "{WINDOW_NODE}display = {{ kind = \"window\", output = \"320x240+320+0\", x_display = \":3\" }}\n"
        ),
    );
    let node = load_node(&path).expect("by geometry, settle by default");
    for part in ["x_display:Some(\":3\")", "output:Geometry(", "settle:80ms"] {
        assert!(node.contains(part), "{part} in {node}");
    }

    let (_dir, path) = file(
        "sim.toml",
        &format!("{NODE}display = {{ kind = \"sim\" }}\n"),
    );
    let node = load_node(&path).expect("sim");
    assert!(node.contains("display:Synthetic"), "{node}");
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

/// A camera agent on a real camera, before its `camera`, `lights` and source lines.
const REAL: &str = "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\n";

#[test]
fn a_real_camera_is_read_as_a_spec_or_a_table() {
    let (_dir, path) = file(
        "cam.toml",
        &format!(
            "{REAL}camera = \"folder:/tmp/photos\"\nmodel = \"m.json\"\ncharts = \"c.json\"\n"
        ),
    );
    let camera = load_camera(&path).expect("a spec string");
    for part in [
        "hardware:Real{camera:CameraConfig{spec:Folder(\"/tmp/photos\")",
        "timeout_s:10.0",
        "lights:None}",
    ] {
        assert!(camera.contains(part), "{part} in {camera}");
    }
    let (_dir, path) = file(
        "cam.toml",
        &format!(
            "{REAL}camera = {{ spec = \"command:cp a.png {{out}}\", timeout_s = 3, response = {{ gamma = 2.2 }}, settle_ms = 0 }}\n\
             lights = \"http://127.0.0.1:1\"\nsurvey = \"s.json\"\nmodel_out = \"m.json\"\n"
        ),
    );
    let camera = load_camera(&path).expect("a table");
    for part in [
        "spec:Command(\"cpa.png{out}\")",
        "timeout_s:3.0",
        "response:Gamma(2.2)",
        "settle_ms:0",
        "lights:Some(Rendered(\"http://127.0.0.1:1\"))",
        "source:Survey{",
    ] {
        assert!(camera.contains(part), "{part} in {camera}");
    }
    // A physical room's LEDs, switched by a person asked through a folder that must exist.
    let lights = tempfile::tempdir().expect("temp dir");
    let (_dir, path) = file(
        "cam.toml",
        &format!(
            "{REAL}camera = \"folder:/tmp/photos\"\nlights = \"manual:{}\"\nsurvey = \"s.json\"\nmodel_out = \"m.json\"\n",
            lights.path().display()
        ),
    );
    let camera = load_camera(&path).expect("manual lights");
    let part = format!("lights:Some(Manual({:?}))", lights.path());
    assert!(camera.contains(&part), "{part} in {camera}");
}

#[test]
fn a_real_camera_that_contradicts_its_config_is_refused_naming_file_and_field() {
    let model = "model = \"m.json\"\ncharts = \"c.json\"\n";
    let cases = [
        // Both cameras, and neither.
        (
            format!("{CAMERA}camera = \"folder:/p\"\n"),
            vec!["either hardware", "or camera"],
        ),
        (
            format!("{REAL}{model}"),
            vec!["either hardware", "or camera"],
        ),
        (
            format!("{CAMERA}lights = \"http://x:1\"\n"),
            vec!["lights comes with camera"],
        ),
        (
            format!("{REAL}camera = \"folder:/p\"\nsurvey = \"s.json\"\nmodel_out = \"m.json\"\n"),
            vec!["survey with a real camera needs lights"],
        ),
        (
            format!("{REAL}camera = \"folder:/p\"\nmodel = \"m.json\"\n"),
            vec!["model with a real camera needs charts"],
        ),
        (
            format!("{REAL}camera = \"webcam\"\n{model}"),
            vec!["camera", "expected folder:DIR"],
        ),
        (
            format!("{REAL}camera = {{ spec = \"folder:/p\", exposure = 3 }}\n{model}"),
            vec!["camera", "unknown field `exposure`"],
        ),
        (
            format!("{REAL}camera = {{ spec = \"folder:/p\", timeout_s = 0 }}\n{model}"),
            vec!["camera", "timeout_s = 0"],
        ),
        (
            format!(
                "{REAL}camera = {{ spec = \"folder:/p\", v4l2 = {{ exposure_100us = 5 }} }}\n{model}"
            ),
            vec!["camera", "not v4l2"],
        ),
        (
            format!("{REAL}camera = \"folder:/p\"\nlights = \" \"\n{model}"),
            vec!["lights is empty"],
        ),
        (
            format!(
                "{REAL}camera = \"folder:/p\"\nlights = \"manual:/no/such/folder\"\nsurvey = \"s.json\"\nmodel_out = \"m.json\"\n"
            ),
            vec!["lights = \"manual:/no/such/folder\"", "is not a folder"],
        ),
    ];
    for (text, parts) in cases {
        let e = camera_err("cam.toml", &text);
        assert!(e.contains("cam.toml"), "{text}: {e}");
        for part in parts {
            assert!(e.contains(part), "{text}: {part} in {e}");
        }
    }
}

/// Fuzzing the config files (issue 20): the example configs mutated line by line — values
/// replaced by extremes, lines dropped or repeated, bytes spliced in — from a seeded generator.
/// Every one is loaded or refused with an error (exit 1), never a panic (exit 101). A process
/// per input (~0.3 s each on a loaded CI machine): 8 inputs here, `ROOMLIGHT_FUZZ_ITERS` per
/// agent for a longer run.
#[test]
fn mutated_configs_are_loaded_or_refused_never_a_panic() {
    let mut state = 0x5EED_0005u64;
    let mut next = move || {
        // SplitMix64.
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) as usize
    };
    let extremes = [
        "-1",
        "0",
        "18446744073709551615",
        "18446744073709551616",
        "1e309",
        "nan",
        "-inf",
        "\"\"",
        "\"\\u0000\\n\"",
        "{}",
        "[]",
    ];
    let keys = [
        "deadline_ms",
        "heartbeat_ms",
        "mdns_wait_s",
        "stale_frames",
        "start",
        "token",
    ];
    let iterations = std::env::var("ROOMLIGHT_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    for (agent, seed) in [("camera", CAMERA), ("node", NODE)] {
        for _ in 0..iterations {
            let mut lines: Vec<String> = seed.lines().map(str::to_string).collect();
            for _ in 0..=next() % 3 {
                let at = next() % lines.len().max(1);
                match next() % 5 {
                    0 => {
                        let key = lines[at].split('=').next().unwrap_or("x").to_string();
                        lines[at] = format!("{key}= {}", extremes[next() % extremes.len()]);
                    }
                    1 => {
                        lines.remove(at);
                    }
                    2 => lines.push(lines[at].clone()),
                    3 => lines.push(format!(
                        "{} = {}",
                        keys[next() % keys.len()],
                        extremes[next() % extremes.len()]
                    )),
                    _ => {
                        let byte = char::from((next() % 128) as u8);
                        let line = &mut lines[at];
                        let cut = next() % (line.len() + 1);
                        if line.is_char_boundary(cut) {
                            line.insert(cut, byte);
                        }
                    }
                }
                if lines.is_empty() {
                    break;
                }
            }
            let text = lines.join("\n") + "\n";
            let (_dir, path) = file("fuzz.toml", &text);
            let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
                .args([agent, "--config"])
                .arg(&path)
                .arg("--check")
                .output()
                .expect("running roomlight");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                matches!(out.status.code(), Some(0 | 1)) && !err.contains("panicked"),
                "{agent} config\n{text}\nexited {:?}: {err}",
                out.status.code()
            );
        }
    }
}
