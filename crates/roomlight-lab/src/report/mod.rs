//! The demo's report: `index.html` with its images and plots beside it (readable offline),
//! `metrics.json` with the figures, `problem.json` with each preset's measured problem so anyone
//! can check the optimum with another solver.

mod html;
pub mod pictures;
pub(crate) mod plot;
pub mod png;

use crate::pipeline::{Model, RunResult, TracePoint};
use anyhow::{Context, Result};
use plot::{Figure, Marker, YScale, plot};
use roomlight_core::{LinearRgb, Problem};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::Path;

/// One LED preset reproduced by the agents.
#[derive(Debug)]
pub struct PresetOutcome {
    /// The preset's name.
    pub name: String,
    /// The measured model the agents ran on.
    pub model: Model,
    /// The weight of the light on the target in that model (0: the charts alone).
    pub dark_weight: f64,
    /// The true problem on the model's patches (the noiseless truth's transport, black and
    /// target): what the room could reach, for `problem.json`.
    pub truth: Problem,
    /// What they reached.
    pub result: RunResult,
    /// Room chart of each model patch.
    pub chart_of_patch: Vec<Option<usize>>,
    /// Its pictures (under the LEDs, at the conventional start, with the result; the
    /// whole-room ΔE00 map and crops) and the whole-room figures.
    pub pictures: pictures::PresetPictures,
    /// What the measured model could reach over the whole room: its optimum over the charts
    /// alone, and with the walls weighed in ([`crate::whole_room_best::pair`]).
    pub model_best: Vec<crate::whole_room_best::Best>,
    /// The room after per-pixel shading passes on the rounds' result ([`crate::shaded`]).
    pub shaded: crate::shaded::Shaded,
}

/// One update rule run on the first preset, for the convergence plots.
#[derive(Debug)]
pub struct RuleOutcome {
    /// Its label.
    pub label: String,
    /// What it reached, capture by capture.
    pub result: RunResult,
}

/// Everything the report shows.
#[derive(Debug)]
pub struct Report {
    /// The room's name.
    pub room: String,
    /// Seed of the camera noise.
    pub seed: u64,
    /// Chart names, by room chart index.
    pub chart_names: Vec<String>,
    /// One line per calibration stage.
    pub calibration: Vec<String>,
    /// Captures calibration used.
    pub calibration_captures: usize,
    /// Every preset.
    pub presets: Vec<PresetOutcome>,
    /// The rules compared on the first preset.
    pub rules: Vec<RuleOutcome>,
    /// Wall time of the whole demo.
    pub wall_seconds: f64,
    /// Projection mapping and contrast on the first preset.
    pub pm: Option<crate::pm::PmResult>,
    /// The dark-target trade-off curve.
    pub dark_target: Option<DarkTarget>,
    /// Large aperture against a standard projector (rooms without one: none).
    pub shadows: Option<crate::shadow::ShadowComparison>,
    /// A projector leaving and an unmeasured one joining hot (rooms with one standard
    /// luminaire: none).
    pub hot_join: Option<HotJoin>,
}

/// The dark-target trade-off (issue 22): the model's optimum at each weight of the target's
/// light, whole-room ΔE00 against the board's ANSI contrast under projector lighting.
#[derive(Debug)]
pub struct DarkTarget {
    /// The preset it is measured on.
    pub preset: String,
    /// Target patches in the model (at a weight above 0).
    pub patches: usize,
    pub points: Vec<crate::dark_target::TradeoffPoint>,
    /// What the agents' rounds reached on the same preset, at the weight they ran with.
    pub rounds: Option<crate::dark_target::RoundsPoint>,
}

/// One projector leaves, another joins that the camera agent has never measured: it is
/// calibrated hot while the others keep their values, then the room converges again.
#[derive(Debug)]
pub struct HotJoin {
    pub leaving: String,
    pub joining: String,
    pub churn: crate::pipeline::Churn,
    /// Captures of the hot calibration (black, then each node at white).
    pub calibration_captures: u64,
    pub result: RunResult,
}

/// Mean of `v`.
pub fn mean(v: &[f64]) -> f64 {
    // Empty: 0, so an empty chart shows as "no patch" rather than NaN.
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// The level of excess the tables count captures to: 1%.
pub const EXCESS_LEVEL: f64 = 0.01;

/// The first capture at which `excess` of a trace point is at or below `level` (none: not
/// within the run). Capture 0 is the conventional start.
pub fn captures_to(
    trace: &[TracePoint],
    excess: fn(&TracePoint) -> f64,
    level: f64,
) -> Option<u64> {
    trace.iter().find(|p| excess(p) <= level).map(|p| p.capture)
}

/// A table cell for [`captures_to`]: the capture, or "> N" with N the captures the run had.
pub fn captures_cell(r: &RunResult, excess: fn(&TracePoint) -> f64) -> String {
    captures_to(&r.trace, excess, EXCESS_LEVEL)
        .map_or(format!("> {}", r.captures), |c| c.to_string())
}

/// The model excess of a trace point (what the rules minimise, on the measured model).
pub fn model_excess(p: &TracePoint) -> f64 {
    p.model_excess
}

/// The true excess of a trace point (against the noiseless truth's optimum; may be negative).
pub fn true_excess(p: &TracePoint) -> f64 {
    p.true_excess
}

impl PresetOutcome {
    /// Mean ΔE00 per room chart (charts without a usable patch left out): (chart, result,
    /// conventional).
    fn per_chart(&self) -> Vec<(usize, f64, f64)> {
        let charts = self
            .chart_of_patch
            .iter()
            .flatten()
            .copied()
            .max()
            .map_or(0, |m| m + 1);
        (0..charts)
            .filter_map(|c| {
                let pick = |v: &[f64]| -> Vec<f64> {
                    v.iter()
                        .zip(&self.chart_of_patch)
                        .filter(|(_, k)| **k == Some(c))
                        .map(|(d, _)| *d)
                        .collect()
                };
                let result = pick(&self.result.de00);
                (!result.is_empty()).then(|| {
                    (
                        c,
                        mean(&result),
                        mean(&pick(&self.result.conventional_de00)),
                    )
                })
            })
            .collect()
    }
}

/// `metrics.json`.
pub fn metrics(report: &Report) -> Value {
    let presets: serde_json::Map<String, Value> = report
        .presets
        .iter()
        .enumerate()
        .map(|(i, p)| (p.name.clone(), preset_metrics(report, i, p)))
        .collect();
    let rules: serde_json::Map<String, Value> = report
        .rules
        .iter()
        .map(|r| {
            (
                r.label.clone(),
                json!({
                    "captures": r.result.captures,
                    "captures_to_1pct_model_excess": captures_to(&r.result.trace, model_excess, EXCESS_LEVEL),
                    "captures_to_1pct_true_excess": captures_to(&r.result.trace, true_excess, EXCESS_LEVEL),
                    "settled": r.result.settled,
                    "final_excess": r.result.final_excess,
                    "true_excess": r.result.true_excess,
                    "mean_de00": mean(&r.result.de00),
                    "seconds": r.result.seconds,
                    "trace": r.result.trace,
                }),
            )
        })
        .collect();
    let mut m = json!({
        "room": report.room,
        "seed": report.seed,
        "calibration_captures": report.calibration_captures,
        "presets": presets,
        "rules": rules,
        "wall_seconds": report.wall_seconds,
    });
    if let Some(h) = &report.hot_join {
        m["hot_join"] = hot_join_metrics(h);
    }
    if let Some(pm) = &report.pm {
        pm_metrics(pm, &mut m);
    }
    if let Some(s) = &report.shadows {
        shadow_metrics(s, &mut m);
    }
    if let Some(d) = &report.dark_target {
        m["dark_target_tradeoff"] = json!(d.points);
        m["dark_target_tradeoff_preset"] = json!(d.preset);
        m["dark_target_patches"] = json!(d.patches);
        m["dark_target_default_weight"] = json!(crate::dark_target::DEFAULT_WEIGHT);
        m["dark_target_rounds"] = json!(d.rounds);
    }
    m
}

/// One preset's figures: on the charts (and per chart), over the whole room (ΔE00 over the
/// reached pixels, the shares no luminaire can light and why, the seam metric), and the ANSI
/// contrast on the projection-mapping board under its three lightings (dark, LED, projectors).
fn preset_metrics(report: &Report, index: usize, p: &PresetOutcome) -> Value {
    let r = &p.result;
    let charts: serde_json::Map<String, Value> = p
        .per_chart()
        .into_iter()
        .map(|(c, de, conv)| {
            (
                report.chart_names.get(c).cloned().unwrap_or(c.to_string()),
                json!({ "mean_de00": de, "conventional_mean_de00": conv }),
            )
        })
        .collect();
    let w = &p.pictures.whole_room;
    let ansi = report
        .pm
        .as_ref()
        .and_then(|pm| pm.ansi_by_preset.get(index))
        .map(|(_, a)| {
            crate::pm::CONDITIONS
                .iter()
                .zip(a)
                .map(|(c, x)| ((*c).to_string(), json!(x)))
                .collect::<serde_json::Map<_, _>>()
        });
    json!({
        "captures": r.captures,
        "captures_to_1pct_model_excess": captures_to(&r.trace, model_excess, EXCESS_LEVEL),
        "captures_to_1pct_true_excess": captures_to(&r.trace, true_excess, EXCESS_LEVEL),
        "whole_room_de00_mean": w.de00_mean,
        "whole_room_de00_p95": w.de00_p95,
        "whole_room_unreachable_share": w.occluded_share + w.outside_share,
        "whole_room_occluded_share": w.occluded_share,
        "whole_room_outside_share": w.outside_share,
        "whole_room_no_node_share": w.no_node_share,
        "whole_room_reached_share": w.reached_share,
        "whole_room_seam": w.seam,
        "whole_room": w,
        "whole_room_model_best": p.model_best,
        "whole_room_shaded": p.shaded,
        "ansi_contrast": ansi,
        "dark_weight": p.dark_weight,
        "linear_png_scale": p.pictures.linear.iter().map(|(f, s)| (f.clone(), json!(s))).collect::<serde_json::Map<_, _>>(),
        "settled": r.settled,
        "final_excess": r.final_excess,
        "G": r.g,
        "G_star": r.g_star,
        "true_excess": r.true_excess,
        "mean_de00": mean(&r.de00),
        "max_de00": max(&r.de00),
        "conventional_mean_de00": mean(&r.conventional_de00),
        "conventional_max_de00": max(&r.conventional_de00),
        "true_optimum_mean_de00": r.best_mean_de00,
        "patches": r.de00.len(),
        "seconds": r.seconds,
        "charts": charts,
    })
}

/// The hot join: who left and joined when, and how the room recovered.
fn hot_join_metrics(h: &HotJoin) -> Value {
    json!({
        "leaving": h.leaving,
        "joining": h.joining,
        "leave_at": h.churn.leave_at,
        "join_at": h.churn.join_at,
        "calibration_captures": h.calibration_captures,
        "captures": h.result.captures,
        "final_excess": h.result.final_excess,
        "true_excess": h.result.true_excess,
        "mean_de00": mean(&h.result.de00),
        "trace": h.result.trace,
    })
}

/// Projection mapping: ANSI and RMS contrast per condition, and the decoded share.
fn pm_metrics(pm: &crate::pm::PmResult, m: &mut Value) {
    let by_condition = |v: &[f64; 3]| -> Value {
        crate::pm::CONDITIONS
            .iter()
            .zip(v)
            .map(|(c, x)| ((*c).to_string(), json!(x)))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    m["ansi_contrast"] = by_condition(&pm.ansi_contrast);
    m["rms_contrast"] = pm
        .rms_contrast
        .iter()
        .map(|(t, v)| (t.clone(), by_condition(v)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    m["pm_decoded_share"] = json!(pm.decoded_share);
}

/// Shadows: penumbra per projector kind and the peak radiance each needs.
fn shadow_metrics(s: &crate::shadow::ShadowComparison, m: &mut Value) {
    m["penumbra_mm"] = s
        .kinds
        .iter()
        .map(|k| (k.kind.clone(), json!(k.penumbra_mm)))
        .collect::<serde_json::Map<_, _>>()
        .into();
    m["peak_radiance_ratio"] = json!({
        "standard_over_large_aperture": s.peak_radiance_ratio,
        "standard_pupil_mm": crate::shadow::STANDARD_PUPIL_MM,
    });
    // Peak emitted radiance per unit desk irradiance (sr⁻¹ · m²/m²), each kind.
    m["peak_radiance_per_irradiance"] = s
        .kinds
        .iter()
        .map(|k| (k.kind.clone(), json!(k.radiance_per_irradiance)))
        .collect::<serde_json::Map<_, _>>()
        .into();
}

fn channel(v: &[LinearRgb], c: usize) -> Vec<f64> {
    v.iter().map(|x| x[c]).collect()
}

/// One channel `c` of `problem` at `x`: the attenuation (sparse), `d`, `r`, `G` of `x` and `G*`
/// (`best`, the optimum's `G` per channel, when it was found).
fn channel_problem(problem: &Problem, x: &[LinearRgb], best: Option<[f64; 3]>, c: usize) -> Value {
    let columns: Vec<Value> = problem
        .columns()
        .iter()
        .enumerate()
        .map(|(n, col)| {
            let (patches, values): (Vec<u32>, Vec<f64>) =
                col.iter().map(|(i, v)| (i, v[c])).unzip();
            json!({ "node": n, "patches": patches, "values": values })
        })
        .collect();
    let errors = problem.errors(x);
    json!({
        "attenuation": columns,
        "d": channel(problem.black(), c),
        "r": channel(problem.target(), c),
        "G": 0.5 * errors.iter().map(|e| e[c] * e[c]).sum::<f64>(),
        "G_star": best.map(|b| b[c]),
    })
}

/// `problem.json`: per preset and channel the measured attenuation (sparse), `d`, `r`, `s`,
/// the final `x`, `G` and `G*` (`G = ½ Σ_i e_i²` on that channel), and under `truth` the same
/// for the true problem on the same patches (the noiseless truth's columns, black and target;
/// `G` of the same final `x` and the true `G*`): the rounds measure the room, so where they
/// stop is judged against both.
pub fn problem(report: &Report) -> Value {
    let presets: serde_json::Map<String, Value> = report
        .presets
        .iter()
        .map(|p| {
            let problem = &p.model.problem;
            let s = problem.white_response();
            let x = &p.result.x;
            let best = roomlight_core::optimum::optimum(problem)
                .ok()
                .map(|b| b.objective_per_channel);
            let true_best = roomlight_core::optimum::optimum(&p.truth)
                .ok()
                .map(|b| b.objective_per_channel);
            let channels: Vec<Value> = ["r", "g", "b"]
                .iter()
                .enumerate()
                .map(|(c, name)| {
                    let mut v = channel_problem(problem, x, best, c);
                    let o = v.as_object_mut().expect("an object");
                    o.insert("channel".into(), json!(name));
                    o.insert("s".into(), json!(channel(&s, c)));
                    o.insert("x".into(), json!(channel(x, c)));
                    o.insert("truth".into(), channel_problem(&p.truth, x, true_best, c));
                    v
                })
                .collect();
            (
                p.name.clone(),
                json!({
                    "nodes": problem.nodes(),
                    "patches": problem.patches(),
                    "bounds": [0.0, 1.0],
                    "objective": "G = 1/2 sum_i (r_i - d_i - sum_n A_in x_n)^2 per channel, 0 <= x_n <= 1",
                    "channels": channels,
                }),
            )
        })
        .collect();
    json!({ "room": report.room, "presets": presets })
}

pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Writes the report into `dir` (the images must already be there).
pub fn write(dir: &Path, report: &Report) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let save = |name: &str, value: &Value| -> Result<()> {
        let path = dir.join(name);
        std::fs::write(&path, serde_json::to_string_pretty(value)?)
            .with_context(|| format!("writing {}", path.display()))
    };
    save("metrics.json", &metrics(report))?;
    save("problem.json", &problem(report))?;
    write_plots(dir, report)?;
    let path = dir.join("index.html");
    std::fs::write(&path, html::html(report)).with_context(|| format!("writing {}", path.display()))
}

/// Below this the excess plots are linear (symmetric log scale): about the camera noise's floor.
const EXCESS_LINEAR_BELOW: f64 = 1e-4;

/// The convergence plots of every rule (true excess against captures and against wall time,
/// mean ΔE00 against captures), the hot join's (with its leave and join marked) and the shadow
/// profiles.
fn write_plots(dir: &Path, report: &Report) -> Result<()> {
    let series = |f: fn(&TracePoint) -> (f64, f64)| -> Vec<(&str, Vec<(f64, f64)>)> {
        report
            .rules
            .iter()
            .map(|r| (r.label.as_str(), r.result.trace.iter().map(f).collect()))
            .collect()
    };
    let excess = YScale::SymLog(EXCESS_LINEAR_BELOW);
    let figures = [
        (
            "excess-captures.svg",
            "true excess (G − G*)/G* against captures",
            "captures",
            "true excess (symlog)",
            series(|p| (p.capture as f64, p.true_excess)),
            excess,
        ),
        (
            "excess-time.svg",
            "true excess (G − G*)/G* against wall-clock time",
            "seconds",
            "true excess (symlog)",
            series(|p| (p.seconds, p.true_excess)),
            excess,
        ),
        (
            "de00-captures.svg",
            "mean ΔE00 on the charts against captures",
            "captures",
            "mean ΔE00",
            series(|p| (p.capture as f64, p.mean_de00)),
            YScale::Linear,
        ),
    ];
    for (file, title, x_label, y_label, series, y) in &figures {
        plot(
            &dir.join(file),
            &Figure {
                title,
                x_label,
                y_label,
                series,
                y: *y,
                markers: &[],
            },
        )?;
    }
    if let Some(h) = &report.hot_join {
        let trace = |f: fn(&TracePoint) -> f64| -> Vec<(f64, f64)> {
            h.result
                .trace
                .iter()
                .map(|p| (p.capture as f64, f(p)))
                .collect()
        };
        let markers = [
            Marker {
                x: h.churn.leave_at as f64,
                label: format!("{} leaves", h.leaving),
            },
            Marker {
                x: h.churn.join_at as f64,
                label: format!("{} joins", h.joining),
            },
        ];
        plot(
            &dir.join("hot-join.svg"),
            &Figure {
                title: "a projector leaves, an unmeasured one joins hot",
                x_label: "captures",
                y_label: "excess over the optimum without the leaver (symlog)",
                series: &[
                    ("model excess", trace(|p| p.model_excess)),
                    ("true excess", trace(|p| p.true_excess)),
                ],
                y: excess,
                markers: &markers,
            },
        )?;
    }
    if let Some(s) = &report.shadows {
        let series: Vec<(&str, Vec<(f64, f64)>)> = s
            .kinds
            .iter()
            .map(|k| {
                (
                    k.kind.as_str(),
                    k.profile.iter().map(|&(d, r)| (d + 160.0, r)).collect(),
                )
            })
            .collect();
        plot(
            &dir.join("shadow.svg"),
            &Figure {
                title: "desk irradiance across the shadow's edge (occluded / open)",
                x_label: "mm across the edge (+160 = the geometric edge)",
                y_label: "ratio",
                series: &series,
                y: YScale::Linear,
                markers: &[],
            },
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run of 30 captures whose model excess halves each capture from 0.5: below 1% first at
    /// capture 6 (0.5/64 ≈ 0.0078); the true excess dips below zero at the end.
    fn run() -> RunResult {
        let trace: Vec<TracePoint> = (0..=30u64)
            .map(|c| TracePoint {
                capture: c,
                seconds: 0.1 * c as f64,
                measured_excess: None,
                model_excess: 0.5 / 2f64.powi(c as i32),
                true_excess: 0.6 / 2f64.powi(c as i32) - 1e-3,
                mean_de00: 2.0,
            })
            .collect();
        RunResult {
            captures: 30,
            settled: false,
            trace,
            x: Vec::new(),
            g: 1.0,
            g_star: 1.0,
            final_excess: 0.0,
            true_excess: -1e-3,
            de00: vec![2.0],
            conventional_de00: vec![5.0],
            best_mean_de00: 1.5,
            seconds: 3.0,
            capture_seconds: 1.0,
            rounds: 600,
            calibrated_hot: 0,
            late_frames: 0,
            bytes_per_round: 0.0,
        }
    }

    fn report() -> Report {
        Report {
            room: "test".into(),
            seed: 1,
            chart_names: Vec::new(),
            calibration: Vec::new(),
            calibration_captures: 0,
            presets: Vec::new(),
            rules: vec![RuleOutcome {
                label: "momentum".into(),
                result: run(),
            }],
            wall_seconds: 1.0,
            pm: None,
            dark_target: None,
            shadows: None,
            hot_join: None,
        }
    }

    /// One channel of a problem as `problem.json` writes it: the column's entries of that
    /// channel at their patches, `d` and `r` of that channel, `G = ½ Σ_i e_i²` of `x` on it and
    /// `G*` of that channel (or null when no optimum was found).
    #[test]
    fn a_channel_of_the_problem_is_its_columns_and_its_objective() {
        let rgb = |r, g, b| LinearRgb([r, g, b]);
        let problem = Problem::new(
            vec![
                roomlight_core::AttenuationColumn::new(
                    vec![0, 2],
                    vec![rgb(0.5, 0.25, 0.125), rgb(0.1, 0.2, 0.3)],
                )
                .expect("column"),
                roomlight_core::AttenuationColumn::new(vec![1], vec![rgb(0.4, 0.6, 0.8)])
                    .expect("column"),
            ],
            vec![rgb(0.01, 0.02, 0.03); 3],
            vec![rgb(0.3, 0.2, 0.1), rgb(0.5, 0.5, 0.5), rgb(0.2, 0.4, 0.6)],
            vec![LinearRgb::ZERO; 3],
        )
        .expect("problem");
        let x = vec![rgb(0.5, 1.0, 0.0), rgb(0.25, 0.5, 1.0)];
        let v = channel_problem(&problem, &x, Some([1.0, 2.0, 3.0]), 1);
        assert_eq!(v["attenuation"][0]["patches"], json!([0, 2]));
        assert_eq!(v["attenuation"][0]["values"], json!([0.25, 0.2]));
        assert_eq!(v["attenuation"][1]["node"], json!(1));
        assert_eq!(v["attenuation"][1]["values"], json!([0.6]));
        assert_eq!(v["d"], json!([0.02, 0.02, 0.02]));
        assert_eq!(v["r"], json!([0.2, 0.5, 0.4]));
        // Green: e = r − d − A x with x = (1.0, 0.5).
        let e = [0.2 - 0.02 - 0.25, 0.5 - 0.02 - 0.6 * 0.5, 0.4 - 0.02 - 0.2];
        let g = 0.5 * e.iter().map(|e| e * e).sum::<f64>();
        assert!((v["G"].as_f64().expect("G") - g).abs() < 1e-15);
        assert_eq!(v["G_star"], json!(2.0));
        assert!(channel_problem(&problem, &x, None, 1)["G_star"].is_null());
    }

    #[test]
    fn captures_to_one_percent_is_the_first_capture_below_not_the_cap() {
        let r = run();
        assert_eq!(captures_to(&r.trace, model_excess, EXCESS_LEVEL), Some(6));
        // 0.6/2^c − 0.001 ≤ 0.01 first at c = 6 (0.0084).
        assert_eq!(captures_to(&r.trace, true_excess, EXCESS_LEVEL), Some(6));
        assert_eq!(captures_to(&r.trace, model_excess, 1e-12), None);
        assert_eq!(captures_cell(&r, model_excess), "6");
        let mut never = r.clone();
        never.trace.truncate(3);
        assert_eq!(captures_cell(&never, model_excess), "> 30");
        let m = metrics(&report());
        assert_eq!(m["rules"]["momentum"]["captures_to_1pct_model_excess"], 6);
        assert_eq!(m["rules"]["momentum"]["captures"], 30);
        let page = html::html(&report());
        assert!(
            page.contains("<td>momentum</td><td>6</td><td>0.60</td><td>6</td><td>30</td>"),
            "the convergence row: {page}"
        );
    }

    #[test]
    fn the_convergence_plots_show_negative_excess() {
        let dir = tempfile::tempdir().expect("temp dir");
        write(dir.path(), &report()).expect("report");
        let svg = std::fs::read_to_string(dir.path().join("excess-captures.svg")).expect("svg");
        assert!(svg.contains("-1e-4"), "a negative tick on the excess axis");
        assert!(dir.path().join("excess-time.svg").exists());
        let page = std::fs::read_to_string(dir.path().join("index.html")).expect("page");
        assert!(page.contains("excess-time.svg") && page.contains("excess-captures.svg"));
    }
}
