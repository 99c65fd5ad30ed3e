//! Installing and checking a PC: the Debian package's files, the room token from a file or a
//! systemd credential, `roomlight check` and `roomlight node --check`.

use super::*;

/// The Debian package's metadata names files that exist: every asset but the release binary,
/// both systemd units, the example configs, and executable maintainer scripts that parse.
#[test]
fn the_debian_package_names_files_that_exist() {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest: toml::Table = std::fs::read_to_string(here.join("Cargo.toml"))
        .expect("Cargo.toml")
        .parse()
        .expect("Cargo.toml parses");
    let deb = &manifest["package"]["metadata"]["deb"];
    let assets = deb["assets"].as_array().expect("assets");
    let mut installed = Vec::new();
    for asset in assets {
        let [from, to, mode] = &asset.as_array().expect("[from, to, mode]")[..] else {
            panic!("asset {asset}");
        };
        let from = from.as_str().expect("source");
        installed.push(format!(
            "{}{}",
            to.as_str().expect("target"),
            from.rsplit('/').next().expect("name")
        ));
        assert!(matches!(mode.as_str(), Some("644" | "755")), "{asset}");
        if !from.starts_with("target/") {
            assert!(here.join(from).is_file(), "{from} is not a file");
        }
    }
    for wanted in [
        "usr/bin/roomlight",
        "lib/systemd/system/roomlight-camera.service",
        "lib/systemd/system/roomlight-node@.service",
        "usr/share/doc/roomlight/examples/camera.toml",
        "usr/share/doc/roomlight/examples/node.toml",
    ] {
        assert!(
            installed.iter().any(|i| i == wanted),
            "{wanted} not in {installed:?}"
        );
    }
    let scripts = here.join(deb["maintainer-scripts"].as_str().expect("scripts"));
    for script in ["postinst", "postrm"] {
        let path = scripts.join(script);
        let mode = std::os::unix::fs::PermissionsExt::mode(
            &std::fs::metadata(&path).expect("script").permissions(),
        );
        assert!(mode & 0o111 != 0, "{script} is not executable");
        let parsed = Command::new("sh")
            .arg("-n")
            .arg(&path)
            .status()
            .expect("sh -n");
        assert!(parsed.success(), "{script} does not parse");
    }
}

/// The room token can stay out of the config: read from a file, or from a systemd credential
/// (`LoadCredential=`, `$CREDENTIALS_DIRECTORY`); a credential outside systemd, a missing file
/// or an empty token is refused naming the config and where the token was to come from.
#[test]
fn the_token_comes_from_a_file_or_a_systemd_credential() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    std::fs::write(d.join("room-token"), "s3cret-from-a-file\n").expect("token file");
    std::fs::write(d.join("empty-token"), "\n").expect("empty token file");
    let check = |token: &str, credentials: Option<&Path>| {
        let config = d.join("camera.toml");
        std::fs::write(
            &config,
            format!(
                "room = \"lab\"\ntoken = {token}\nlisten = \"127.0.0.1:0\"\n\
                 hardware = {{ sim = \"http://127.0.0.1:1\" }}\nmodel = \"m.json\"\n"
            ),
        )
        .expect("config");
        let mut command = Command::new(env!("CARGO_BIN_EXE_roomlight"));
        command.args([
            "camera",
            "--check",
            "--config",
            config.to_str().expect("utf-8"),
        ]);
        command.env_remove("CREDENTIALS_DIRECTORY");
        if let Some(dir) = credentials {
            command.env("CREDENTIALS_DIRECTORY", dir);
        }
        let out = command.output().expect("run roomlight");
        let said = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.success(), said)
    };
    let file = format!("{{ file = {:?} }}", d.join("room-token"));
    let (ok, said) = check(&file, None);
    assert!(ok, "{said}");
    assert!(!said.contains("s3cret"), "--check prints the token: {said}");
    let (ok, said) = check("{ credential = \"room-token\" }", Some(d));
    assert!(ok, "{said}");
    let (ok, said) = check("{ credential = \"room-token\" }", None);
    assert!(
        !ok && said.contains("camera.toml") && said.contains("CREDENTIALS_DIRECTORY"),
        "{said}"
    );
    let (ok, said) = check("{ file = \"/nonexistent/room-token\" }", None);
    assert!(!ok && said.contains("/nonexistent/room-token"), "{said}");
    let empty = format!("{{ file = {:?} }}", d.join("empty-token"));
    let (ok, said) = check(&empty, None);
    assert!(!ok && said.contains("token is empty"), "{said}");
}

/// `roomlight check` on a PC whose room is not there: every item is reported, the exit is
/// non-zero, and the first failure names what failed (the unreachable camera agent, the missing
/// model); a camera that answers passes.
#[test]
fn check_reports_each_item_and_names_the_first_failure() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let run = |config: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_roomlight"))
            .args(["check", "--config", config])
            .env_remove("RUST_BACKTRACE")
            .env_remove("RUST_LIB_BACKTRACE")
            .current_dir(d)
            .output()
            .expect("run roomlight check");
        let said = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.success(), said)
    };
    std::fs::write(
        d.join("node.toml"),
        "room = \"lab\"\ntoken = \"t\"\ncamera = \"http://127.0.0.1:1\"\n\
         hardware = { sim = \"http://127.0.0.1:1\" }\nprojector = \"p0\"\n\
         state_file = \"p0.state.json\"\n",
    )
    .expect("node config");
    let (ok, said) = run("node.toml");
    assert!(!ok, "{said}");
    assert!(
        said.contains("ok    camera agent: http://127.0.0.1:1 (as configured)"),
        "{said}"
    );
    assert!(
        said.contains("FAIL  display: simulator") || said.contains("FAIL  display"),
        "{said}"
    );
    assert!(
        said.contains("ok    state file p0.state.json: writable"),
        "{said}"
    );
    let last = said
        .lines()
        .find(|l| l.starts_with("Error:"))
        .unwrap_or_default();
    assert!(
        last.contains("node.toml")
            && last.contains("attach as projector")
            && last.contains("127.0.0.1:1"),
        "the first failure is named last: {last}"
    );

    let photo = d.join("photo.png");
    image::RgbImage::from_pixel(4, 3, image::Rgb([90, 90, 90]))
        .save(&photo)
        .expect("png");
    std::fs::write(
        d.join("camera.toml"),
        format!(
            "room = \"lab\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\nmodel = \"missing.json\"\n\
             charts = \"charts.json\"\ncamera = {:?}\n",
            format!("command:cp {} {{out}}", photo.display())
        ),
    )
    .expect("camera config");
    let (ok, said) = run("camera.toml");
    assert!(!ok, "{said}");
    assert!(said.contains("ok    listen on 127.0.0.1:0: free"), "{said}");
    assert!(
        said.contains("ok    camera command:cp") && said.contains("4×3"),
        "{said}"
    );
    let last = said
        .lines()
        .find(|l| l.starts_with("Error:"))
        .unwrap_or_default();
    assert!(last.contains("model missing.json"), "{last}");
}

/// `roomlight node --check` prints the node's setup without its token.
#[test]
fn node_check_prints_the_setup_but_not_the_token() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("node.toml");
    std::fs::write(
        &config,
        "room = \"lab\"\ntoken = \"s3cret-node-token\"\ncamera = \"http://127.0.0.1:1\"\n\
         hardware = { sim = \"http://127.0.0.1:1\" }\nprojector = \"p0\"\n",
    )
    .expect("config");
    let printed = roomlight(&[
        "node",
        "--check",
        "--config",
        config.to_str().expect("utf-8"),
    ]);
    assert!(
        printed.contains("p0") && printed.contains("<secret>"),
        "{printed}"
    );
    assert!(!printed.contains("s3cret-node-token"), "{printed}");
}
