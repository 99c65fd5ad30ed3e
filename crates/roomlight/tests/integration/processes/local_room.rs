//! `deploy/local-room.sh`: a simulated room with the console from an already built binary; it
//! prints the console's URL and token, the console answers with the room's projectors, and a
//! SIGTERM stops every process it started.

use super::*;
use std::io::{Read as _, Write as _};

/// `GET path` on `addr` with the bearer `token`; the status line and body.
fn get(addr: &str, path: &str, token: &str) -> (String, String) {
    let mut stream = std::net::TcpStream::connect(addr).expect("connect to the console");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {token}\r\nConnection: close\r\n\r\n"
    )
    .expect("request");
    let mut text = String::new();
    stream.read_to_string(&mut text).expect("answer");
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    (
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    )
}

/// The pids of `pid`'s children.
fn children(pid: u32) -> Vec<u32> {
    let path = format!("/proc/{pid}/task/{pid}/children");
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .split_whitespace()
        .filter_map(|p| p.parse().ok())
        .collect()
}

/// A process is gone (or a zombie nobody will reap: its parent is gone too).
fn gone(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_or(true, |s| s.split_whitespace().nth(2) == Some("Z"))
}

#[test]
fn local_room_serves_the_console_and_stops_on_sigterm() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy/local-room.sh");
    let missing = Command::new("bash")
        .arg(script)
        .env("ROOMLIGHT_BIN", "/nonexistent/roomlight")
        .output()
        .expect("run the script");
    assert!(!missing.status.success());
    assert!(
        String::from_utf8_lossy(&missing.stderr).contains("build it first"),
        "{}",
        String::from_utf8_lossy(&missing.stderr)
    );
    let mut child = Command::new("bash")
        .arg(script)
        .env("ROOMLIGHT_BIN", env!("CARGO_BIN_EXE_roomlight"))
        .env("ROOMLIGHT_CONSOLE_PORT", "0")
        .env("ROOMLIGHT_TOKEN", "a-token-for-the-test")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start local-room.sh");
    let script_pid = child.id();
    // Whatever happens, the script is stopped (it stops what it started).
    let _guard = Terminate(script_pid);
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    let (exit_tx, exit_rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = exit_tx.send(child.wait());
    });
    let url = wait_line(&rx, Duration::from_secs(120), |l| {
        l.starts_with("console: ")
    });
    let token = wait_line(&rx, Duration::from_secs(5), |l| l.starts_with("token: "));
    assert_eq!(token, "token: a-token-for-the-test");
    let addr = url
        .trim_start_matches("console: http://")
        .trim_end_matches('/')
        .to_string();
    let spawned = children(script_pid);
    assert_eq!(
        spawned.len(),
        5,
        "sim, camera agent, three node agents: {spawned:?}"
    );
    let (status, _) = get(&addr, "/api/status", "wrong-token");
    assert!(status.contains("401"), "{status}");
    // The console's event stream lists the three projectors as they join and calibrate.
    let mut events = std::net::TcpStream::connect(&addr).expect("connect to the console");
    events
        .set_read_timeout(Some(Duration::from_secs(60)))
        .expect("timeout");
    write!(
        events,
        "GET /api/events HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer a-token-for-the-test\r\n\r\n"
    )
    .expect("request");
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut text = String::new();
    'listed: loop {
        assert!(Instant::now() < deadline, "projectors never listed: {text}");
        let mut buf = [0u8; 16384];
        let n = events.read(&mut buf).expect("events in time");
        assert!(n > 0, "the stream ended");
        text.push_str(&String::from_utf8_lossy(&buf[..n]));
        while let Some(end) = text.find("\n\n") {
            let event: String = text.drain(..end + 2).collect();
            let Some(data) = event.lines().find_map(|l| l.strip_prefix("data: ")) else {
                continue;
            };
            let s: serde_json::Value = serde_json::from_str(data).expect("status JSON");
            let ids: Vec<&str> = s["projectors"]
                .as_array()
                .map(|p| p.iter().filter_map(|p| p["id"].as_str()).collect())
                .unwrap_or_default();
            if ids == ["area", "left", "right"] {
                break 'listed;
            }
        }
    }
    // SIGTERM to the script alone, as systemd or a terminal would: it stops what it started,
    // waits for them, and says so.
    let killed = Command::new("kill")
        .args(["-TERM", &script_pid.to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    exit_rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the script stops")
        .expect("its exit status");
    // The exit can be seen before the reader thread has passed on the script's last lines:
    // read until its stdout closes (every process holding it has stopped), at most 10 s.
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut rest: Vec<String> = Vec::new();
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(line) => rest.push(line),
            Err(_) => break,
        }
    }
    assert!(rest.iter().any(|l| l.starts_with("stopped;")), "{rest:?}");
    // It waited for every process it started: none is left.
    let left: Vec<&u32> = spawned.iter().filter(|&&p| !gone(p)).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Sends SIGTERM to a pid when dropped.
struct Terminate(u32);

impl Drop for Terminate {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.to_string()])
            .status();
    }
}
