//! `roomlight bench --out DIR`: the bench's plots (SVG), its records (bench.json) and one HTML
//! page that shows them, like the demo's report.

use crate::bench::net::growth_exponent;
use crate::bench::room::{Outcome, captures_cell};
use crate::report::escape;
use crate::report::plot::{Figure, Marker, YScale, plot};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// A file name for a case: letters and digits kept, everything else a dash.
fn slug(case: &str) -> String {
    case.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect()
}

/// The sizes of the scaling run (none without one).
fn scaling_points(outcome: &Outcome) -> &[crate::bench::net::NetPoint] {
    outcome
        .scaling
        .as_ref()
        .map_or(&[], |run| run.sizes.as_slice())
}

/// Writes the page, the plots and bench.json into `dir` (made if missing).
pub fn write(dir: &Path, outcome: &Outcome) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let json = serde_json::json!({
        "records": outcome.records,
        "sparsity": outcome.sparsity,
        "scaling": scaling_points(outcome),
        "failed": outcome.failed,
        "curves": outcome.curves,
        "events": outcome.events,
    });
    let path = dir.join("bench.json");
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", path.display()))?;
    let mut figures = String::new();
    for (case, curves) in &outcome.curves {
        let slug = slug(case);
        let series = |f: &dyn Fn(&crate::bench::room::Point) -> (f64, f64)| {
            curves
                .iter()
                .map(|(rule, points)| (rule.as_str(), points.iter().map(f).collect::<Vec<_>>()))
                .collect::<Vec<_>>()
        };
        let by_capture = format!("{slug}-excess-captures.svg");
        let by_time = format!("{slug}-excess-seconds.svg");
        let de = format!("{slug}-de00-captures.svg");
        // Excess on a symmetric log scale (linear within 1e-4 of zero), so negative values show.
        let excess = YScale::SymLog(1e-4);
        let figures_of_case = [
            (
                &by_capture,
                "excess over G* against captures",
                "captures",
                "(G − G*) / G* (symlog)",
                series(&|p| (p.capture as f64, p.excess)),
                excess,
            ),
            (
                &by_time,
                "excess over G* against wall-clock time",
                "seconds",
                "(G − G*) / G* (symlog)",
                series(&|p| (p.seconds, p.excess)),
                excess,
            ),
            (
                &de,
                "mean ΔE00 against captures",
                "captures",
                "mean ΔE00",
                series(&|p| (p.capture as f64, p.mean_de00)),
                YScale::Linear,
            ),
        ];
        // Churn is scheduled in captures: the capture plots mark it; the wall-clock plot does
        // not, since each rule reaches a capture at its own time.
        let markers: Vec<Marker> = outcome
            .events
            .iter()
            .filter(|(c, _)| c == case)
            .flat_map(|(_, events)| events)
            .map(|(capture, label)| Marker {
                x: *capture as f64,
                label: label.clone(),
            })
            .collect();
        for (file, what, x_label, y_label, series, y) in &figures_of_case {
            plot(
                &dir.join(file),
                &Figure {
                    title: &format!("{case}: {what}"),
                    x_label,
                    y_label,
                    series,
                    y: *y,
                    markers: if *x_label == "captures" {
                        &markers
                    } else {
                        &[]
                    },
                },
            )?;
        }
        let _ = write!(
            figures,
            "<h3>{}</h3><div class=\"row\"><img src=\"{by_capture}\" alt=\"excess against captures\">\
<img src=\"{by_time}\" alt=\"excess against wall time\"><img src=\"{de}\" alt=\"ΔE00 against captures\"></div>",
            escape(case)
        );
    }
    let path = dir.join("index.html");
    std::fs::write(&path, html(outcome, &figures))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

fn html(outcome: &Outcome, figures: &str) -> String {
    let rows = record_rows(outcome);
    let failed = failed_section(outcome);
    let sparsity: String = outcome
        .sparsity
        .iter()
        .map(|s| format!("<li>{}</li>", escape(&s.line())))
        .collect();
    let scaling = scaling_section(outcome);
    format!(
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>roomlight bench</title>\
<style>body{{font-family:sans-serif;max-width:1400px;margin:2em auto;color:#222}}\
img{{max-width:100%}}table{{border-collapse:collapse;margin:1em 0;font-size:90%}}\
td,th{{border:1px solid #ccc;padding:3px 6px;text-align:right}}th{{background:#f4f4f4}}\
td:first-child,td:nth-child(2){{text-align:left}}tr.bad{{background:#fdd}}\
.row{{display:flex;gap:6px}}.row img{{flex:1;min-width:0}}</style></head><body>\
<h1>roomlight bench: speed against error</h1>\
<p>Every rule from the conventional start, through the camera agent and the node agents on loopback gRPC. \
Excess is (G − G*)/G* on the model the agents run (its optimum by a convex solver); ΔE00 is against the LED \
target on the simulator's noiseless truth. Figures are medians over repeated runs with different camera noise \
(range in brackets); captures are counted from the start (capture 0); after a projector leaves and another \
joins, captures to a level count from the join. Compute is the node updates timed alone, messages the rest \
of the wall time after the simulated camera. Timings come from one shared machine: compare them as ratios.</p>\
<table><tr><th>case</th><th>rule</th><th>captures to 1%</th><th>to 0.1%</th><th>final excess</th><th>to 1% true</th><th>final true</th>\
<th>mean ΔE00</th><th>max ΔE00</th><th>compute µs/round</th><th>message ms/round</th><th>capture ms</th>\
<th>bytes/round</th><th>diverged</th><th>repeats</th></tr>{rows}</table>{failed}\
<h2>Model only what the scene needs</h2><ul>{sparsity}</ul>{scaling}\
<h2>Curves (medians over the repeats)</h2>{figures}</body></html>"
    )
}

/// One table row per record, diverged runs marked.
fn record_rows(outcome: &Outcome) -> String {
    let mut rows = String::new();
    for r in &outcome.records {
        let _ = write!(
            rows,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.1e} ({:.1e}…{:.1e})</td><td>{}</td><td>{:.1e}</td>\
<td>{:.2} ({:.2}…{:.2})</td><td>{:.2}</td><td>{:.1}</td><td>{:.2}</td><td>{:.0}</td><td>{:.0}</td><td>{}</td><td>{}</td></tr>",
            if r.diverged { " class=\"bad\"" } else { "" },
            escape(&r.case),
            escape(&r.rule),
            captures_cell(r.captures_to_1pct, r.spread.captures_to_1pct, r.captures),
            captures_cell(r.captures_to_0_1pct, [None, None], r.captures),
            r.final_excess,
            r.spread.final_excess[0],
            r.spread.final_excess[1],
            captures_cell(r.captures_to_1pct_true, [None, None], r.captures),
            r.final_true_excess,
            r.mean_de00,
            r.spread.mean_de00[0],
            r.spread.mean_de00[1],
            r.max_de00,
            r.compute_us_per_round,
            r.message_ms_per_round,
            r.capture_ms,
            r.bytes_per_round,
            r.diverged,
            r.repeats,
        );
    }
    rows
}

/// The cases that could not run and why; empty when every case ran.
fn failed_section(outcome: &Outcome) -> String {
    let mut failed = String::new();
    for (case, why) in &outcome.failed {
        let _ = write!(
            failed,
            "<li><b>{}</b>: could not run: {}</li>",
            escape(case),
            escape(why)
        );
    }
    if !failed.is_empty() {
        failed = format!("<h2>Cases that could not run</h2><ul>{failed}</ul>");
    }
    failed
}

/// How cost grows with the nodes (the scaling run's table and exponents); empty without one.
fn scaling_section(outcome: &Outcome) -> String {
    let mut scaling = String::new();
    if !scaling_points(outcome).is_empty() {
        let mut rows = String::new();
        for p in scaling_points(outcome) {
            let _ = write!(
                rows,
                "<tr><td>{}</td><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                p.nodes,
                p.agents,
                p.median_ms,
                p.p99_ms,
                p.compute_ms,
                p.bytes_out_per_round,
                p.bytes_in_per_round,
                p.rss_kb_per_node
                    .map_or_else(|| "n/a".to_string(), |v| format!("{v:.1}")),
                escape(p.note.as_deref().unwrap_or(""))
            );
        }
        let fit = |f: fn(&crate::bench::net::NetPoint) -> f64| {
            let points: Vec<(f64, f64)> = scaling_points(outcome)
                .iter()
                .filter(|p| p.rounds > 0)
                .map(|p| (p.nodes as f64, f(p)))
                .collect();
            growth_exponent(&points).map_or("—".to_string(), |b| format!("{b:.2}"))
        };
        scaling = format!(
            "<h2>How cost grows</h2><p>One round over loopback gRPC (errors out, update, contribution and \
acknowledgement back; a virtual camera), supports of fixed size, ten nodes per node agent; compute is every \
node's update timed alone, the rest of a round is messages and waiting. Round time grows as \
nodes<sup>{}</sup>, its compute as nodes<sup>{}</sup>, the resident memory per node as nodes<sup>{}</sup> \
(least squares on log-log; memory is the process's resident set growth while the node agents join, \
the camera agent's per-node state and the streams included).</p>\
<table><tr><th>nodes</th><th>agents</th><th>median ms</th><th>p99 ms</th><th>compute ms</th><th>bytes out/round</th>\
<th>bytes in/round</th><th>resident KB per node</th><th>note</th></tr>{rows}</table>",
            fit(|p| p.median_ms),
            fit(|p| p.compute_ms),
            fit(|p| p.rss_kb_per_node.unwrap_or(0.0))
        );
    }
    scaling
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::room::Point;

    #[test]
    fn a_churn_case_marks_leave_and_join_on_its_capture_plots() {
        let point = |capture: u64| Point {
            capture,
            seconds: capture as f64 * 0.5,
            excess: 1.0 / (1.0 + capture as f64),
            true_excess: 0.5 / (1.0 + capture as f64),
            mean_de00: 2.0,
            rounds_seconds: 0.1,
        };
        let case = "small/leave-2-join-4";
        let outcome = Outcome {
            curves: vec![(
                case.into(),
                vec![("model-20".into(), (0..8).map(point).collect())],
            )],
            events: vec![(
                case.into(),
                vec![
                    (2, "wall-left leaves".into()),
                    (4, "floor-right joins".into()),
                ],
            )],
            ..Outcome::default()
        };
        let dir = tempfile::tempdir().expect("tempdir");
        write(dir.path(), &outcome).expect("written");
        let read = |f: &str| std::fs::read_to_string(dir.path().join(f)).expect(f);
        let slug = "small-leave-2-join-4";
        for f in ["excess-captures", "de00-captures"] {
            let svg = read(&format!("{slug}-{f}.svg"));
            assert!(
                svg.contains("wall-left leaves") && svg.contains("floor-right joins"),
                "{f}"
            );
        }
        let by_time = read(&format!("{slug}-excess-seconds.svg"));
        assert!(!by_time.contains("leaves"));
        let json: serde_json::Value = serde_json::from_str(&read("bench.json")).expect("json");
        assert_eq!(json["events"][0][1][1][0], 4);
        assert_eq!(json["events"][0][1][1][1], "floor-right joins");
    }
}
