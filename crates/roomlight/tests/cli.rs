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

#[test]
fn demo_quick_converges_and_says_so() {
    let stdout = roomlight(&["demo", "--quick"]);
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
