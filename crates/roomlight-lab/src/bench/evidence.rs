//! `roomlight bench` without a subcommand: the whole evidence. The optimisation core, the room
//! (presets, hard cases, a synthetic room; its page with `--out`), the distributed runtime's
//! scaling, calibration and the simulator, one after the other; with `--out DIR` also
//! `DIR/results.md` (see [`super::results`]).
//!
//! The room and its scaling run in this process, as `roomlight bench` always ran them, so the
//! page keeps its scaling section. Core, calibration and the simulator run as child processes
//! of the same binary (`roomlight bench core` …): each section's command is then the exact
//! command that produced it, each bench measures its own resident set, and one that fails is
//! reported while the others go on. This module owns that order; it must not know how a bench
//! measures, nor parse a command line.

use super::results::{self, Section, Stamp, fenced};
use super::room::{self, Outcome, Plan};
use anyhow::{Result, bail};
use comfy_table::{Table, presets::ASCII_MARKDOWN};
use std::io::BufRead as _;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Instant;

/// What to run and how to name it.
#[derive(Debug, Clone)]
pub struct Evidence {
    /// The room's plan; `plan.out` also receives results.md. With `plan.case` set only the
    /// room runs (a filter asks for a focused run).
    pub plan: Plan,
    /// The `roomlight` binary that runs the other benches as children.
    pub exe: PathBuf,
    /// The command as typed, for the header and the sections run in this process.
    pub command: String,
}

/// Runs every bench; fails at the end if any of them failed.
pub fn run(evidence: &Evidence) -> Result<()> {
    let plan = &evidence.plan;
    plan.check()?;
    let others = plan.case.is_none();
    let seed = plan.seed.to_string();
    let mut sections = Vec::new();
    let mut failed = Vec::new();
    let mut child = |sections: &mut Vec<Section>, bench: &str, extra: &[&str]| {
        let mut args = vec!["bench", bench];
        if plan.quick {
            args.push("--quick");
        }
        args.extend_from_slice(extra);
        let (section, ok) = run_child(bench, evidence, &args);
        if !ok {
            failed.push(bench.to_string());
        }
        sections.push(section);
    };
    if others {
        child(&mut sections, "core", &["--seed", &seed]);
    }
    sections.extend(room_and_scaling(evidence)?);
    if others {
        child(&mut sections, "calib", &[]);
        child(&mut sections, "sim", &[]);
    }
    if let Some(dir) = &plan.out {
        results::write(dir, &evidence.command, &sections)?;
        println!("results: {}", dir.join("results.md").display());
    }
    if !failed.is_empty() {
        bail!("bench {} failed (see above)", failed.join(", "));
    }
    Ok(())
}

/// The room's cases, then its scaling run, then its table and page: as two sections.
fn room_and_scaling(evidence: &Evidence) -> Result<Vec<Section>> {
    let plan = &evidence.plan;
    let t0 = Instant::now();
    let stamp = Stamp::now();
    let mut outcome = room::measure(plan)?;
    let mut sections = vec![Section {
        bench: "room".into(),
        command: evidence.command.clone(),
        stamp,
        seconds: t0.elapsed().as_secs_f64(),
        body: format!(
            "The default room's presets, the hard cases and a synthetic room, run in the \
             command's own process.\n\n{}",
            room_markdown(&outcome)
        ),
    }];
    if plan.runs_scaling() {
        let t = Instant::now();
        let stamp = Stamp::now();
        let run = super::net::run(plan.quick, None)?;
        sections.push(Section {
            bench: "net".into(),
            command: evidence.command.clone(),
            stamp,
            seconds: t.elapsed().as_secs_f64(),
            body: format!(
                "The scaling part of the command (alone: `roomlight bench net{}`).\n\n{}",
                if plan.quick { " --quick" } else { "" },
                net_markdown(&run)
            ),
        });
        outcome.scaling = Some(run);
    }
    room::finish(plan, &outcome, t0)?;
    Ok(sections)
}

/// Runs `exe args…`, echoing its output as it comes and keeping it for the section; the
/// flag is false when it could not start or exited unsuccessfully.
fn run_child(bench: &str, evidence: &Evidence, args: &[&str]) -> (Section, bool) {
    let command = format!("roomlight {}", args.join(" "));
    println!("== {command}");
    let t0 = Instant::now();
    let stamp = Stamp::now();
    let mut text = String::new();
    let status = Command::new(&evidence.exe)
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .and_then(|mut process| {
            if let Some(out) = process.stdout.take() {
                for line in std::io::BufReader::new(out).lines() {
                    let line = line?;
                    println!("{line}");
                    text.push_str(&line);
                    text.push('\n');
                }
            }
            process.wait()
        });
    let (ok, verdict) = match status {
        Ok(s) if s.success() => (true, String::new()),
        Ok(s) => (
            false,
            format!("\n**Failed**: {s} (its errors went to stderr).\n"),
        ),
        Err(e) => (false, format!("\n**Failed** to run: {e}.\n")),
    };
    let section = Section {
        bench: bench.into(),
        command,
        stamp,
        seconds: t0.elapsed().as_secs_f64(),
        body: format!("{}{verdict}", fenced(&text)),
    };
    (section, ok)
}

/// The room's records as a markdown table under the caption the terminal shows, its notes, and
/// the cases that could not run.
fn room_markdown(outcome: &Outcome) -> String {
    let mut table = room::table(&outcome.records);
    super::width::markdown(&mut table);
    let mut md = format!(
        "{}.\n\n{table}\n\n{}\n\n{}\n",
        room::CAPTION,
        room::TIME_NOTE,
        room::FLOOR_NOTE
    );
    for (case, why) in &outcome.failed {
        md.push_str(&format!("\n- {case}: could not run: {why}"));
    }
    if !outcome.failed.is_empty() {
        md.push('\n');
    }
    md
}

/// The scaling run's sizes as a markdown table, and its growth exponents.
fn net_markdown(run: &super::net::NetRun) -> String {
    let mut table = Table::new();
    table.load_preset(ASCII_MARKDOWN).set_header([
        "nodes",
        "agents",
        "median ms",
        "p99 ms",
        "compute ms",
        "bytes out/round",
        "bytes in/round",
        "rounds",
        "resident KB/node",
        "note",
    ]);
    let measured = |p: &super::net::NetPoint, v: String| {
        if p.rounds == 0 { "-".to_string() } else { v }
    };
    for p in &run.sizes {
        table.add_row([
            p.nodes.to_string(),
            p.agents.to_string(),
            measured(p, format!("{:.3}", p.median_ms)),
            measured(p, format!("{:.3}", p.p99_ms)),
            format!("{:.3}", p.compute_ms),
            measured(p, p.bytes_out_per_round.to_string()),
            measured(p, p.bytes_in_per_round.to_string()),
            p.rounds.to_string(),
            p.rss_kb_per_node
                .map_or_else(|| "n/a".to_string(), |v| format!("{v:.1}")),
            p.note.clone().unwrap_or_default(),
        ]);
    }
    let show = |e: Option<f64>| e.map_or_else(|| "n/a".to_string(), |e| format!("{e:.2}"));
    format!(
        "{table}\n\nGrowth: round time as nodes^{}, its compute as nodes^{}, resident memory per \
         node as nodes^{} (least squares on log-log over the sizes measured). Memory: {}.\n",
        show(run.growth_exponent),
        show(run.compute_exponent),
        show(run.memory_exponent),
        run.memory
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::net::{NetPoint, NetRun};

    #[test]
    fn net_section_has_every_size_and_the_exponents() {
        let point = |nodes: usize, rounds: usize| NetPoint {
            nodes,
            agents: nodes / 10,
            median_ms: 1.5,
            p99_ms: 2.5,
            compute_ms: 0.25,
            bytes_out_per_round: 1000,
            bytes_in_per_round: 900,
            rounds,
            rss_kb_per_node: Some(3.0),
            note: (rounds == 0).then(|| "too slow".to_string()),
        };
        let md = net_markdown(&NetRun {
            sizes: vec![point(10, 20), point(10_000, 0)],
            growth_exponent: Some(1.01),
            compute_exponent: None,
            memory_exponent: Some(0.0),
            memory: "resident set",
        });
        assert!(md.contains("| nodes "), "{md}");
        assert!(md.contains("| 10 ") && md.contains("| 1.500 "), "{md}");
        assert!(md.contains("| 10000 ") && md.contains("too slow"), "{md}");
        assert!(
            md.contains("nodes^1.01") && md.contains("nodes^n/a"),
            "{md}"
        );
    }

    #[test]
    fn room_section_lists_failed_cases_under_its_table() {
        let outcome = Outcome {
            failed: vec![("lab/dim".into(), "no projector found".into())],
            ..Outcome::default()
        };
        let md = room_markdown(&outcome);
        assert!(md.starts_with(room::CAPTION));
        assert!(
            md.contains("| case ") && md.contains("- lab/dim: could not run: no projector found")
        );
    }
}
