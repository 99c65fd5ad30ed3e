//! Every `roomlight … --help` as a user reads it: each command has one, none names a document
//! that is not in the repository, and the facts that go stale (sizes, counts, flags) are the
//! ones the code runs with.

use super::roomlight;
use roomlight_lab::bench;

/// The subcommands a help text lists under `Commands:` (`help` left out).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        // A command's line starts with two spaces; a wrapped description, with more.
        .filter(|l| !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(String::from)
        .collect()
}

/// `roomlight PATH --help` for every command path, depth first.
fn every_help() -> Vec<(Vec<String>, String)> {
    let mut todo = vec![Vec::<String>::new()];
    let mut seen = Vec::new();
    while let Some(path) = todo.pop() {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let help = roomlight(&args);
        for c in subcommands(&help) {
            let mut next = path.clone();
            next.push(c);
            todo.push(next);
        }
        seen.push((path, help));
    }
    seen
}

#[test]
fn every_command_has_a_help_that_names_only_what_exists() {
    let helps = every_help();
    let names: Vec<String> = helps.iter().map(|(p, _)| p.join(" ")).collect();
    for expected in [
        "demo",
        "sim",
        "calibrate",
        "camera",
        "node",
        "check",
        "optimum",
        "soak",
        "bench",
        "bench core",
        "bench room",
        "bench net",
        "bench console",
        "bench calib",
        "bench sim",
        "bench hw",
        "hw capture",
        "graycode",
        "certs",
    ] {
        assert!(
            names.iter().any(|n| n == expected),
            "{expected} in {names:?}"
        );
    }
    for (path, help) in &helps {
        // Every option says what it is (clap leaves the text empty otherwise).
        for line in help.lines().filter(|l| l.trim_start().starts_with("--")) {
            let said = line.trim().split_once("  ").map_or("", |(_, h)| h.trim());
            let next = help
                .lines()
                .skip_while(|l| *l != line)
                .nth(1)
                .unwrap_or("")
                .trim();
            assert!(
                !said.is_empty() || !next.is_empty() && !next.starts_with('-'),
                "roomlight {} --help: {line:?} has no help",
                path.join(" ")
            );
        }
        let first = help.lines().next().unwrap_or("");
        assert!(
            first.split_whitespace().count() >= 3,
            "roomlight {} --help says what it does first: {help}",
            path.join(" ")
        );
        // A design document the repository does not hold, and the demo as it was.
        for stale in ["DESIGN", "a synthetic room instead", "old sizes"] {
            assert!(
                !help.contains(stale),
                "roomlight {} --help: {stale:?} in {help}",
                path.join(" ")
            );
        }
    }
}

/// The sizes `bench net` runs are the ones its help says (both come from the same constants),
/// with and without `--quick`.
#[test]
fn bench_net_help_says_the_sizes_it_runs() {
    let help = roomlight(&["bench", "net", "--help"]);
    let flat = help.split_whitespace().collect::<Vec<_>>().join(" ");
    let all = bench::net::said(&bench::net::SIZES);
    assert!(all.ends_with("10 000"), "{all}");
    assert!(flat.contains(&format!("for {all} nodes")), "{help}");
    assert!(
        flat.contains(&format!(
            "{} nodes per node agent",
            bench::net::NODES_PER_AGENT
        )),
        "{help}"
    );
    let quick = bench::net::said(&bench::net::QUICK_SIZES);
    assert!(
        flat.contains(&format!("--quick {quick} nodes only")),
        "{help}"
    );
    // The summary `roomlight bench --help` lists says them too.
    let bench_help = roomlight(&["bench", "--help"]);
    assert!(
        bench_help
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .contains(&all),
        "{bench_help}"
    );
}

#[test]
fn bench_console_help_says_its_consoles_and_phases() {
    let help = roomlight(&["bench", "console", "--help"]);
    let flat = help.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        flat.contains(&format!("with {} consoles open", bench::console::CONSOLES)),
        "{help}"
    );
    assert!(
        flat.contains(&format!("at least {} s", bench::console::PHASE.as_secs())),
        "{help}"
    );
}

/// What the demo and the camera agent print, as their help says.
#[test]
fn demo_and_camera_help_say_what_they_run_and_print() {
    let demo = roomlight(&["demo", "--help"]);
    // clap wraps at the terminal's width (100 columns without one): compare words.
    let flat = demo.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(flat.contains("embedded lab"), "{demo}");
    assert!(flat.contains("per-pixel shading passes"), "{demo}");
    assert!(
        flat.contains("15 captures per preset instead of 30"),
        "{demo}"
    );
    let camera = roomlight(&["camera", "--help"]);
    let flat = camera.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(flat.contains("at most a line a second"), "{camera}");
    assert!(
        flat.contains("--status-lines")
            && flat.contains("round R captures C objective G live L calibrated H averaged K"),
        "{camera}"
    );
    let sim = roomlight(&["sim", "--help"]);
    assert!(
        sim.split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .contains("synthetic room's camera noise"),
        "{sim}"
    );
}
