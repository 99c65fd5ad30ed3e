//! A camera agent whose camera cannot be opened at start (not plugged in, powered off) waits
//! for it: one log line per try, with backoff, and it does not exit; told to stop (SIGTERM)
//! while it waits, it exits cleanly.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The child, killed and reaped on drop whatever happens in the test.
struct Reaped(Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn a_camera_agent_waits_for_a_camera_it_cannot_open_and_stops_when_told() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("camera.toml");
    // A V4L2 device that does not exist: opening it fails the way an unplugged camera does.
    let missing = dir.path().join("video9");
    std::fs::write(
        &config,
        format!(
            "room = \"r\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\nmdns = false\n\
             camera = {{ spec = \"v4l2:{}\", v4l2 = {{ exposure_100us = 100 }} }}\n\
             lights = \"http://127.0.0.1:1\"\nsurvey = \"s.json\"\nmodel_out = \"{}\"\n",
            missing.display(),
            dir.path().join("model.json").display()
        ),
    )
    .expect("config");
    let mut camera = Reaped(
        Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(["camera", "--config"])
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("roomlight camera"),
    );
    let stderr = camera.0.stderr.take().expect("stderr");
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });

    // Two tries (1 s apart) logged, naming the camera, and the process still there.
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut tries = Vec::new();
    while tries.len() < 2 {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("two tries logged within 30 s; saw {tries:?}"));
        if line.contains("camera unreachable at start") {
            tries.push(line);
        }
    }
    for line in &tries {
        assert!(line.contains("video9"), "the camera named: {line}");
    }
    assert!(
        camera.0.try_wait().expect("status").is_none(),
        "the camera agent exited instead of waiting for its camera"
    );

    // SIGTERM while it waits: a clean exit.
    let pid = camera.0.id().to_string();
    let killed = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill");
    assert!(killed.success());
    let deadline = Instant::now() + Duration::from_secs(10);
    let status = loop {
        if let Some(status) = camera.0.try_wait().expect("status") {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "the camera agent did not stop within 10 s of SIGTERM"
        );
        // Polling the child's exit: the wait is bounded by the deadline above.
        let _ = lines.recv_timeout(Duration::from_millis(50));
    };
    assert!(status.success(), "exit status {status:?}");
}
