//! `roomlight soak` at a small scale: a room of processes (sim, camera agent, node agents) runs a
//! few hundred rounds while a node is killed and restarted, a spare projector added, the camera
//! agent restarted and a misbehaving peer attaches; each event must take effect, the room end
//! within 1% of the optimum of the projectors present, and no agent hold more descriptors than
//! its peers explain. Nothing here is timed. No process is left behind (the soak stops its
//! children, and kills them if it fails).

use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

fn soak(out: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .arg("soak")
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run roomlight soak")
}

fn said(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn a_short_soak_applies_every_event_and_ends_at_the_optimum_with_flat_descriptors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let run = soak(
        dir.path(),
        &["--rounds", "240", "--seed", "3", "--events", "6"],
    );
    assert!(run.status.success(), "{}", said(&run));
    let text = std::fs::read_to_string(dir.path().join("soak.json")).expect("soak.json");
    let report: Value = serde_json::from_str(&text).expect("json");
    assert!(
        report["rounds_completed"].as_u64().expect("rounds") >= 240,
        "{text}"
    );
    assert_eq!(
        report["failures"].as_array().map(Vec::len),
        Some(0),
        "{text}"
    );

    let events = report["events"].as_array().expect("events");
    assert_eq!(events.len(), 6, "{text}");
    for kind in ["kill-node", "add-projector", "restart-camera", "misbehave"] {
        assert!(
            events.iter().any(|e| e["kind"] == kind),
            "no {kind}: {text}"
        );
    }
    for e in events {
        assert_eq!(e["took_effect"], true, "{e}");
        let outcome = e["outcome"].as_str().expect("outcome");
        match e["kind"].as_str() {
            Some("kill-node") => assert!(outcome.contains("relit from its state file"), "{e}"),
            Some("misbehave") => assert!(outcome.contains("malformed"), "{e}"),
            _ => {}
        }
    }
    // The misbehaving peer was dropped each time, as the camera agent logged it.
    let peers = events.iter().filter(|e| e["kind"] == "misbehave").count();
    let camera_log = std::fs::read_to_string(dir.path().join("camera.log")).expect("camera log");
    let dropped = camera_log
        .lines()
        .filter(|l| l.contains("left projector=p5"))
        .count();
    assert_eq!(dropped, peers, "{camera_log}");

    let excess = report["excess"]["excess"].as_f64().expect("excess");
    assert!(excess <= 0.01, "{text}");
    // Every agent still running at the end holds no descriptor beyond its peers' sockets that
    // it did not hold after its warm-up.
    for agent in report["agents"].as_array().expect("agents") {
        for run in agent["runs"].as_array().expect("runs") {
            if run["end"] != "stopped" || run["warm"].is_null() {
                continue;
            }
            let net = |s: &Value| s["fds"].as_u64().unwrap_or(0) - s["peers"].as_u64().unwrap_or(0);
            assert!(
                net(&run["last"]) <= net(&run["warm"]),
                "{}: {run}",
                agent["name"]
            );
        }
    }
}

#[test]
fn a_soak_that_misses_a_criterion_fails_naming_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    // No time at all: the first event's round is never reached.
    let run = soak(dir.path(), &["--rounds", "100", "--max-minutes", "0"]);
    let text = said(&run);
    assert!(!run.status.success(), "{text}");
    assert!(
        text.contains("soak failed: the run stopped early"),
        "{text}"
    );
    assert!(text.contains("rounds: "), "{text}");
    assert!(dir.path().join("soak.json").exists(), "{text}");
}
