//! `roomlight bench …` as a user runs it: tables that fit 120 columns, records in `--json`,
//! and the figures the issues bar.

use super::roomlight;

/// Runs `roomlight bench WHICH --quick --json FILE [EXTRA…]`, checks its table, returns the
/// records.
fn bench_quick_rows(which: &str, extra: &[&str]) -> Vec<serde_json::Value> {
    let dir = tempfile::tempdir().expect("temp dir");
    let json = dir.path().join(format!("{which}.json"));
    let mut args = vec![
        "bench",
        which,
        "--quick",
        "--json",
        json.to_str().expect("utf-8 path"),
    ];
    args.extend_from_slice(extra);
    let stdout = roomlight(&args);
    // Its header may wrap between words.
    assert!(stdout.contains("captures to"), "{stdout}");
    // The table fits 120 columns (characters, not bytes: `│`, `Δ`, `µ`, `…`).
    let table = stdout
        .lines()
        .filter(|l| l.starts_with(['┌', '│', '├', '╞', '└']));
    for line in table {
        assert!(line.chars().count() <= 120, "{line}\n{stdout}");
    }
    serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
        .expect("valid json")
}

#[test]
fn bench_core_quick_writes_every_rule_and_case() {
    let rows = bench_quick_rows("core", &[]);
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

/// Speed against error through the agents on the small room: every rule, the JSON keys, no
/// divergence, and model rounds reaching 1% of G* within the budget where the paper's rule
/// does not; two repeats, so the figures are medians with a range.
#[test]
fn bench_room_quick_records_every_rule_through_the_agents() {
    let rows = bench_quick_rows("room", &["--repeats", "2"]);
    assert_eq!(rows.len(), 7, "{rows:?}");
    let by_rule = |rule: &str| {
        rows.iter()
            .find(|r| r["rule"] == rule)
            .unwrap_or_else(|| panic!("no {rule}"))
    };
    for row in &rows {
        for key in [
            "case",
            "rule",
            "captures_to_1pct",
            "captures_to_0_1pct",
            "final_excess",
            "captures_to_1pct_true",
            "final_true_excess",
            "mean_de00",
            "max_de00",
            "compute_us_per_round",
            "message_ms_per_round",
            "bytes_per_round",
            "diverged",
        ] {
            assert!(row.get(key).is_some(), "missing {key} in {row}");
        }
        assert_eq!(row["diverged"], false, "{row}");
        assert!(
            row["final_excess"].as_f64().is_some_and(f64::is_finite),
            "{row}"
        );
        assert_eq!(row["repeats"], 2, "{row}");
        let [lo, hi] = [0, 1].map(|k| {
            row["spread"]["final_excess"][k]
                .as_f64()
                .unwrap_or(f64::NAN)
        });
        let median = row["final_excess"].as_f64().unwrap_or(f64::NAN);
        assert!(
            lo <= median && median <= hi,
            "median outside its range: {row}"
        );
    }
    let model = by_rule("model-20");
    assert!(
        model["captures_to_1pct"].as_u64().is_some_and(|c| c <= 5),
        "{model}"
    );
    let paper = by_rule("paper");
    assert!(
        paper["final_excess"].as_f64() > model["final_excess"].as_f64(),
        "{paper} vs {model}"
    );
}

/// The hard cases of DESIGN §9 scaled down (the small room's variants, stale errors, a
/// projector leaving and another joining, 100 synthetic nodes), through the agents: nothing
/// non-finite, no divergence for the rules meant to cope, convergence where the room allows
/// it, and the page with its plots.
#[test]
fn bench_room_quick_hard_cases_stay_stable_and_converge() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("bench");
    let rows = bench_quick_rows(
        "room",
        &["--hard", "--out", out.to_str().expect("utf-8 path")],
    );
    let row = |case: &str, rule: &str| {
        rows.iter()
            .find(|r| r["case"] == case && r["rule"] == rule)
            .unwrap_or_else(|| panic!("no {case} / {rule} in {rows:?}"))
    };
    let cases = [
        "small/stale-1",
        "small/stale-2",
        "small/leave-2-join-4",
        "small/leave-2-join-4-hot",
        "small-reflective",
        "small-two-on-one-wall",
        "small-dim-projector",
        "small-node-without-chart",
        "small-heavy-noise",
        "small-uncorrected-gamma",
        "small-bright-target",
        "synthetic-100",
    ];
    for case in cases {
        assert!(rows.iter().any(|r| r["case"] == case), "{case} missing");
    }
    for r in &rows {
        assert!(
            r["final_excess"].as_f64().is_some_and(f64::is_finite)
                && r["mean_de00"].as_f64().is_some_and(f64::is_finite),
            "{r}"
        );
        // Stale errors break the rules that assume fresh ones (the table says so); every other
        // rule and case must not diverge. The default rule copes without being told the
        // latency: the camera agent refuses the captures that show the room before the step
        // (before it did, stale-2 diverged to 1.3e2).
        let stale = r["case"].as_str().is_some_and(|c| c.contains("stale"));
        let coping = !stale
            || matches!(
                r["rule"].as_str(),
                Some("safe-delay" | "model-100" | "model-100-discard")
            );
        if coping {
            assert_eq!(r["diverged"], false, "{r}");
        }
    }
    // Enough model rounds between captures: 1% within three captures where the room allows it,
    // after a join counted from the join (a hot one: from its calibration's end); 3 or fewer at
    // 2026-11-27 19:22 UTC, and the bench is deterministic at a seed. Where the rounds' floor
    // lies above 1% (†: the model's columns on the room's own errors stop there), that floor
    // within three captures instead (issue 21 item 5): node-without-chart, coded in primaries,
    // 1.6%† in 3 (2026-12-07; 1% in 2 coded in white).
    for (case, rule) in [
        ("small/leave-2-join-4", "model-100"),
        ("small/leave-2-join-4-hot", "model-100"),
        ("synthetic-100", "model-100"),
        ("small-reflective", "model-100"),
        ("small-two-on-one-wall", "model-100"),
        ("small-dim-projector", "model-100"),
        ("small-node-without-chart", "model-100"),
        ("small-uncorrected-gamma", "model-100"),
        ("small-bright-target", "model-100"),
        ("small/stale-1", "model-100-discard"),
        ("small/stale-2", "model-100-discard"),
        ("small/stale-1", "model-100"),
        ("small/stale-2", "model-100"),
    ] {
        let to_1pct = row(case, rule)["captures_to_1pct"].as_u64();
        let to_floor = row(case, rule)["captures_to_floor"].as_u64();
        assert!(
            to_1pct.is_some_and(|c| c <= 3) || to_floor.is_some_and(|c| c <= 3),
            "{case} {rule}: to 1% {to_1pct:?}, to its floor above 1% {to_floor:?}"
        );
    }
    // Heavy noise: 1% is below its floor (where the rounds stop in the room); the floor's
    // level within three captures (2 at 19:22 UTC).
    let heavy = row("small-heavy-noise", "model-100")["captures_to_floor"].as_u64();
    assert!(heavy.is_some_and(|c| c <= 3), "{heavy:?}");
    let excess =
        |case: &str, rule: &str| row(case, rule)["final_excess"].as_f64().unwrap_or(f64::NAN);
    for case in [
        "small-dim-projector",
        "small-node-without-chart",
        "small-heavy-noise",
    ] {
        assert!(excess(case, "model-100") < excess(case, "paper"), "{case}");
        assert!(excess(case, "model-100") < 0.5, "{case}");
    }
    // Late frames refused, the default rule ends within 1% as with fresh ones.
    for case in ["small/stale-1", "small/stale-2"] {
        assert!(excess(case, "model-100") < 0.01, "{case}");
    }
    // The damped step survives two stale captures and ends below where it started.
    assert!(excess("small/stale-2", "safe-delay") < excess("small/stale-2", "paper"));

    let page = std::fs::read_to_string(out.join("index.html")).expect("index.html");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("bench.json")).expect("bench.json"))
            .expect("valid json");
    assert_eq!(json["records"].as_array().map(Vec::len), Some(rows.len()));
    let sparsity = json["sparsity"].as_array().expect("sparsity");
    let synthetic = sparsity
        .iter()
        .find(|s| s["case"] == "synthetic-100")
        .expect("synthetic sparsity");
    let (kept, nonzero) = (synthetic["kept"].as_u64(), synthetic["nonzero"].as_u64());
    assert!(kept > Some(0) && kept < nonzero, "{synthetic}");
    assert!(synthetic["sparse_bytes"].as_u64() < synthetic["dense_bytes"].as_u64());
    // The camera sees every entry: the closed loop on the cut model recovers most of what the
    // cut-off costs open-loop.
    assert!(
        synthetic["loop_excess_cut"].as_f64() < synthetic["cutoff_cost"].as_f64(),
        "{synthetic}"
    );
    for case in cases {
        assert!(page.contains(case), "{case} not on the page");
        let slug: String = case
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect();
        for plot in ["excess-captures", "excess-seconds", "de00-captures"] {
            let svg = out.join(format!("{slug}-{plot}.svg"));
            let text =
                std::fs::read_to_string(&svg).unwrap_or_else(|e| panic!("{}: {e}", svg.display()));
            assert!(
                text.contains("<svg") && text.contains("model-100"),
                "{}",
                svg.display()
            );
        }
    }
}

/// `--case` runs only the cases whose name contains the text (here one stale case: the quick
/// subset of rules plus the two answers to a late camera).
#[test]
fn bench_case_filter_runs_only_the_matching_cases() {
    let rows = bench_quick_rows("room", &["--hard", "--case", "stale-1"]);
    let rules: Vec<&str> = rows.iter().filter_map(|r| r["rule"].as_str()).collect();
    assert!(
        rows.iter().all(|r| r["case"] == "small/stale-1"),
        "{rows:?}"
    );
    assert_eq!(
        rules,
        [
            "paper",
            "momentum",
            "model-100",
            "safe-delay",
            "model-100-discard"
        ]
    );
}

/// `bench net --quick` measures 10 and 100 nodes through the real agents and writes every size,
/// the growth exponent and how memory was measured into `--json`.
#[test]
fn bench_net_quick_writes_its_table() {
    let dir = tempfile::tempdir().expect("temp dir");
    let json = dir.path().join("net.json");
    let stdout = roomlight(&[
        "bench",
        "net",
        "--quick",
        "--json",
        json.to_str().expect("utf-8 path"),
    ]);
    assert!(stdout.contains("growth exponent"), "{stdout}");
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
            .expect("valid json");
    let sizes = run["sizes"].as_array().expect("sizes");
    let nodes: Vec<u64> = sizes.iter().filter_map(|s| s["nodes"].as_u64()).collect();
    let quick: Vec<u64> = roomlight_lab::bench::net::QUICK_SIZES
        .iter()
        .map(|&n| n as u64)
        .collect();
    assert_eq!(nodes, quick, "{run}");
    for s in sizes {
        assert!(s["rounds"].as_u64().is_some_and(|r| r > 0), "{s}");
        assert!(s["median_ms"].as_f64().is_some_and(|m| m > 0.0), "{s}");
        assert!(
            s["bytes_out_per_round"].as_u64().is_some_and(|b| b > 0),
            "{s}"
        );
    }
    assert!(run["growth_exponent"].as_f64().is_some(), "{run}");
    assert!(
        run["memory"].as_str().is_some_and(|m| m.contains("VmRSS")),
        "{run}"
    );
}
