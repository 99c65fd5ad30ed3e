//! `roomlight bench hw --quick`: the latency table's rows (display under a private Xvfb, the
//! folder and command cameras, v4l2 and gphoto2 measured or "no device") and the time-to-1 %
//! table's rules, every number finite and positive, and the `hw` section of results.md. No
//! timing is asserted.

use std::process::Command;

/// The cells of every table row of `text` (header and separator rows left out).
fn rows(text: &str) -> Vec<Vec<String>> {
    text.lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| ---") && !l.starts_with("| measure"))
        .filter(|l| !l.starts_with("| rule"))
        .map(|l| {
            l.trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect()
}

fn positive(cell: &str) -> bool {
    cell.parse::<f64>().is_ok_and(|v| v.is_finite() && v > 0.0)
}

#[test]
fn bench_hw_quick_prints_every_row_with_finite_positive_numbers() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(["bench", "hw", "--quick", "--frames", "4", "--out"])
        .arg(dir.path())
        // A private Xvfb, whatever the session running the tests has.
        .env_remove("DISPLAY")
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let rows = rows(&stdout);
    let row = |prefix: &str| {
        rows.iter()
            .find(|r| r[0].starts_with(prefix))
            .unwrap_or_else(|| panic!("no row {prefix}: {stdout}"))
    };
    for measured in ["display:", "capture: folder", "capture: command"] {
        let r = row(measured);
        assert!(positive(&r[1]) && positive(&r[2]), "{r:?}");
        assert_eq!(r[3], "4", "{r:?}");
    }
    for maybe in ["capture: v4l2", "capture: gphoto2"] {
        let r = row(maybe);
        assert!(
            (positive(&r[1]) && positive(&r[2])) || r[3].starts_with("no device"),
            "{r:?}"
        );
    }
    let rules = [
        "paper",
        "global-oracle",
        "safe",
        "momentum",
        "model-5",
        "model-20",
    ];
    for rule in rules {
        let r = row(rule);
        assert!(positive(&r[2]), "round cost: {r:?}");
        if r[1].starts_with("not reached in") {
            assert_eq!((r[3].as_str(), r[4].as_str()), ("-", "-"), "{r:?}");
        } else {
            assert!(
                positive(&r[1]) && positive(&r[3]) && positive(&r[4]),
                "{r:?}"
            );
        }
    }
    // Model rounds reach 1 % within the quick budget (bench room's test says so too).
    assert!(positive(&row("model-20")[3]), "{stdout}");
    assert!(
        stdout.contains("T = N × (t_capture + t_display + t_round)"),
        "{stdout}"
    );
    let md = std::fs::read_to_string(dir.path().join("results.md")).expect("results.md");
    assert!(
        md.contains("\n## hw\n") && md.contains("| display: show → pixels in a root-window grab |"),
        "{md}"
    );
}
