//! The `roomlight` binary as a user runs it.

use std::process::Command;

fn roomlight(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(args)
        .output()
        .expect("run roomlight");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "roomlight {args:?} failed: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

#[test]
fn bench_core_quick_writes_every_rule_and_case() {
    let dir = tempfile::tempdir().expect("temp dir");
    let json = dir.path().join("core.json");
    let stdout = roomlight(&[
        "bench",
        "core",
        "--quick",
        "--json",
        json.to_str().expect("utf-8 path"),
    ]);
    assert!(stdout.contains("captures to 1%"), "{stdout}");
    let rows: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
            .expect("valid json");
    let rules = [
        "paper",
        "global-oracle",
        "safe",
        "momentum",
        "model-5",
        "model-20",
    ];
    assert_eq!(rows.len(), 2 * rules.len());
    for row in &rows {
        for key in [
            "case",
            "rule",
            "captures_to_1pct",
            "captures_to_0_1pct",
            "final_excess",
            "mean_de00",
            "us_per_node_update",
        ] {
            assert!(row.get(key).is_some(), "missing {key} in {row}");
        }
        let excess = row["final_excess"].as_f64().expect("number");
        assert!(excess.abs() < 1e-5, "{row}");
        assert!(
            row["captures_to_1pct"].as_u64().is_some(),
            "every rule reaches 1%: {row}"
        );
        assert!(
            row["mean_de00"]
                .as_f64()
                .is_some_and(|d| d.is_finite() && d >= 0.0)
        );
    }
}

/// The whole method on the small simulated room: calibration from captures, then the agents;
/// the result must beat the conventional start in true ΔE00 and come near the true optimum.
#[test]
fn demo_quick_calibrates_and_lights_the_room_better_than_the_conventional_start() {
    let stdout = roomlight(&["demo", "--quick"]);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("agents over loopback gRPC"))
        .unwrap_or_else(|| panic!("no agents line in\n{stdout}"));
    let number_after = |text: &str, key: &str| -> f64 {
        text.split(key)
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .map(|s| s.trim_end_matches([',', ';', ')']))
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no {key:?} in {text}"))
    };
    let de = number_after(line, "true mean ΔE00 ");
    let conventional = number_after(line, "conventional start ");
    assert!(de < 0.5 * conventional, "{line}");
    let truth = stdout
        .lines()
        .find(|l| l.starts_with("against the truth"))
        .unwrap_or_else(|| panic!("no truth line in\n{stdout}"));
    // Typically 1.5e-2; a loaded machine changes the interleaving of rounds and noise draws.
    assert!(number_after(truth, "true optimum ") < 0.25, "{truth}");
}

#[test]
fn demo_synthetic_quick_converges_and_says_so() {
    let stdout = roomlight(&["demo", "--synthetic", "--quick"]);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("distributed result"))
        .unwrap_or_else(|| panic!("no result line in\n{stdout}"));
    let excess: f64 = line
        .split("excess ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no excess in {line}"));
    assert!(excess < 1e-2, "{line}");
    // The same room through the real agents over loopback gRPC.
    let agents = stdout
        .lines()
        .find(|l| l.starts_with("agents: final excess"))
        .unwrap_or_else(|| panic!("no agents line in\n{stdout}"));
    let excess: f64 = agents
        .split_whitespace()
        .nth(3)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no excess in {agents}"));
    assert!(excess < 1e-2, "{agents}");
}

#[test]
fn bad_arguments_are_refused_with_a_message() {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(["bench", "core", "--seed", "not-a-number"])
        .output()
        .expect("run roomlight");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seed"));
}

fn roomlight_err(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(args)
        .output()
        .expect("run roomlight");
    assert!(
        !out.status.success(),
        "roomlight {args:?} should have failed"
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Generates patterns for a 40×24 projector and "photographs" them with a camera that sees the
/// projector image one to one (the files themselves), then decodes: the map is the identity.
#[test]
fn graycode_generate_then_decode_identity_and_refuse_bad_folders() {
    let dir = tempfile::tempdir().expect("temp dir");
    let pat = dir.path().join("patterns");
    let p = pat.to_str().expect("utf-8");
    roomlight(&[
        "graycode", "generate", "--width", "40", "--height", "24", "--out", p,
    ]);
    let json = pat.join("patterns.json");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("valid");
    assert_eq!(
        manifest["patterns"].as_array().expect("list").len(),
        2 + 2 * (6 + 5)
    );
    let map = dir.path().join("map.png");
    let stdout = roomlight(&[
        "graycode",
        "decode",
        "--patterns",
        json.to_str().expect("utf-8"),
        "--captures",
        p,
        "--out",
        map.to_str().expect("utf-8"),
        "--depth",
        "8",
    ]);
    assert!(stdout.contains("decoded 100.0%"), "{stdout}");
    let img = image::open(&map).expect("map").to_rgb16();
    for (x, y, px) in img.enumerate_pixels() {
        assert_eq!((px[0], px[1]), (x as u16 + 1, y as u16 + 1));
        assert!(px[2] > 60_000, "confidence {}", px[2]);
    }
    let jp = json.to_str().expect("utf-8");
    let mp = map.to_str().expect("utf-8");
    // 16 bits promised, 8 delivered.
    let err = roomlight_err(&[
        "graycode",
        "decode",
        "--patterns",
        jp,
        "--captures",
        p,
        "--out",
        mp,
        "--depth",
        "16",
    ]);
    assert!(
        err.contains("white.png") && err.contains("16 bits"),
        "{err}"
    );
    // An extra file.
    std::fs::copy(pat.join("white.png"), pat.join("stray.png")).expect("copy");
    let err = roomlight_err(&[
        "graycode",
        "decode",
        "--patterns",
        jp,
        "--captures",
        p,
        "--out",
        mp,
    ]);
    assert!(err.contains("extra file stray.png"), "{err}");
    std::fs::remove_file(pat.join("stray.png")).expect("remove");
    // A missing file.
    std::fs::rename(pat.join("col-03.png"), dir.path().join("aside.png")).expect("move");
    let err = roomlight_err(&[
        "graycode",
        "decode",
        "--patterns",
        jp,
        "--captures",
        p,
        "--out",
        mp,
    ]);
    assert!(err.contains("missing capture col-03.png"), "{err}");
    std::fs::rename(dir.path().join("aside.png"), pat.join("col-03.png")).expect("move back");
    // A capture of the wrong size.
    image::RgbImage::new(10, 10)
        .save(pat.join("row-01.png"))
        .expect("png");
    let err = roomlight_err(&[
        "graycode",
        "decode",
        "--patterns",
        jp,
        "--captures",
        p,
        "--out",
        mp,
    ]);
    assert!(
        err.contains("row-01.png") && err.contains("expected 40x24"),
        "{err}"
    );
    // A manifest that does not match its resolution.
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        std::fs::read_to_string(&json)
            .expect("json")
            .replace("\"width\": 40", "\"width\": 400"),
    )
    .expect("write");
    let err = roomlight_err(&[
        "graycode",
        "decode",
        "--patterns",
        bad.to_str().expect("utf-8"),
        "--captures",
        p,
        "--out",
        mp,
    ]);
    assert!(
        err.contains("bad.json") && err.contains("column_bits"),
        "{err}"
    );
}
