//! `roomlight certs` and the configs' TLS keys through the binary (issue 19): the files `certs
//! init|issue` write are what the agents' configs load (keys 0600); a config without tls on a
//! non-loopback address is refused at load, naming the file and the field, and accepted with
//! `insecure = true`. The link itself is tested in crates/roomlight-agent/tests/integration/tls.rs.

use std::path::Path;
use std::process::Command;

/// Runs `roomlight ARGS` in `dir`: success, and stdout with stderr.
fn roomlight(dir: &Path, args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run roomlight");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

fn camera_config(listen: &str, extra: &str) -> String {
    format!(
        "room = \"lab\"\ntoken = \"t\"\nlisten = \"{listen}\"\nhardware = {{ sim = \"http://127.0.0.1:1\" }}\nmodel = \"model.json\"\nmdns = false\n{extra}\n"
    )
}

fn node_config(camera: &str, extra: &str) -> String {
    format!(
        "room = \"lab\"\ntoken = \"t\"\ncamera = {camera}\nhardware = {{ sim = \"http://127.0.0.1:1\" }}\nprojector = \"p0\"\n{extra}\n"
    )
}

#[test]
fn certs_init_and_issue_write_files_the_agents_load() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let (ok, said) = roomlight(d, &["certs", "init", "--out", "ca"]);
    assert!(ok && said.contains("ca.key"), "{said}");
    let (ok, said) = roomlight(d, &["certs", "init", "--out", "ca"]);
    assert!(
        !ok && said.contains("exists"),
        "a second CA over the first: {said}"
    );
    let (ok, said) = roomlight(
        d,
        &[
            "certs",
            "issue",
            "--ca",
            "ca",
            "--name",
            "camera",
            "--ip",
            "10.0.0.5",
            "--dns",
            "camera-pc.local",
            "--out",
            "camera",
        ],
    );
    assert!(ok && said.contains("camera.pem"), "{said}");
    let (ok, said) = roomlight(
        d,
        &[
            "certs", "issue", "--ca", "ca", "--name", "p0", "--out", "p0",
        ],
    );
    assert!(ok && said.contains("p0.key"), "{said}");
    #[cfg(unix)]
    for key in ["ca/ca.key", "camera/camera.key", "p0/p0.key"] {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(d.join(key))
            .expect("key")
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600, "{key}");
    }
    // The camera agent on every interface, mTLS; the node by address.
    let tls = "tls = { cert = \"camera/camera.pem\", key = \"camera/camera.key\", ca = \"camera/ca.pem\", require_client_cert = true }";
    std::fs::write(d.join("camera.toml"), camera_config("0.0.0.0:50051", tls)).expect("write");
    let (ok, said) = roomlight(d, &["camera", "--config", "camera.toml", "--check"]);
    assert!(ok && said.contains("require_client_cert: true"), "{said}");
    let tls = "tls = { ca = \"p0/ca.pem\", cert = \"p0/p0.pem\", key = \"p0/p0.key\" }";
    std::fs::write(
        d.join("node.toml"),
        node_config("\"http://10.0.0.5:50051\"", tls),
    )
    .expect("write");
    let (ok, said) = roomlight(d, &["node", "--config", "node.toml", "--check"]);
    assert!(ok, "{said}");
    // A key that is not there is named, with the file and the field.
    let tls = "tls = { cert = \"camera/camera.pem\", key = \"camera/nothing.key\" }";
    std::fs::write(d.join("camera.toml"), camera_config("0.0.0.0:50051", tls)).expect("write");
    let (ok, said) = roomlight(d, &["camera", "--config", "camera.toml", "--check"]);
    assert!(
        !ok && said.contains("camera.toml") && said.contains("tls.key"),
        "{said}"
    );
    // A misspelt key is refused.
    std::fs::write(
        d.join("node.toml"),
        node_config(
            "\"http://10.0.0.5:1\"",
            "tls = { cert_authority = \"ca.pem\" }",
        ),
    )
    .expect("write");
    let (ok, said) = roomlight(d, &["node", "--config", "node.toml", "--check"]);
    assert!(!ok && said.contains("cert_authority"), "{said}");
}

#[test]
fn plaintext_off_loopback_is_refused_at_load_unless_insecure() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let check = |file: &str, text: String, agent: &str| {
        std::fs::write(d.join(file), text).expect("write");
        roomlight(d, &[agent, "--config", file, "--check"])
    };
    let (ok, said) = check("camera.toml", camera_config("0.0.0.0:50051", ""), "camera");
    assert!(
        !ok && said.contains("camera.toml") && said.contains("listen") && said.contains("tls"),
        "{said}"
    );
    let (ok, said) = check(
        "camera.toml",
        camera_config("0.0.0.0:50051", "insecure = true"),
        "camera",
    );
    assert!(
        ok && said.contains("insecure = true"),
        "accepted, with a warning: {said}"
    );
    let (ok, said) = check("camera.toml", camera_config("127.0.0.1:0", ""), "camera");
    assert!(ok, "loopback: {said}");
    let (ok, said) = check(
        "node.toml",
        node_config("\"http://10.0.0.5:50051\"", ""),
        "node",
    );
    assert!(
        !ok && said.contains("node.toml") && said.contains("camera"),
        "{said}"
    );
    let (ok, said) = check("node.toml", node_config("{ mdns = \"lab\" }", ""), "node");
    assert!(
        !ok && said.contains("camera.mdns"),
        "mDNS on every interface: {said}"
    );
    let (ok, said) = check(
        "node.toml",
        node_config("{ mdns = \"lab\" }", "mdns_loopback_only = true"),
        "node",
    );
    assert!(ok, "mDNS on loopback: {said}");
    let (ok, said) = check(
        "node.toml",
        node_config("\"http://10.0.0.5:50051\"", "insecure = true"),
        "node",
    );
    assert!(ok, "{said}");
}
