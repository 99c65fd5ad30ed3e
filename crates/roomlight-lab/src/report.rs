//! The demo's report: `index.html` with its images and plots beside it (readable offline),
//! `metrics.json` with the figures, `problem.json` with each preset's measured problem so anyone
//! can check the optimum with another solver.

use crate::pipeline::{Model, RunResult, TracePoint};
use anyhow::{Context, Result};
use plotters::prelude::*;
use roomlight_core::LinearRgb;
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
    /// What they reached.
    pub result: RunResult,
    /// Room chart of each model patch.
    pub chart_of_patch: Vec<usize>,
    /// File names (in the report folder) of the room under the LEDs, at the conventional start
    /// and with the distributed result, tone-mapped sRGB.
    pub images: [String; 3],
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
    /// Large aperture against a standard projector (rooms without one: none).
    pub shadows: Option<crate::shadow::ShadowComparison>,
    /// A projector leaving and an unmeasured one joining hot (rooms with one standard
    /// luminaire: none).
    pub hot_join: Option<HotJoin>,
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

impl PresetOutcome {
    /// Mean ΔE00 per room chart (charts without a usable patch left out): (chart, result,
    /// conventional).
    fn per_chart(&self) -> Vec<(usize, f64, f64)> {
        let charts = self
            .chart_of_patch
            .iter()
            .copied()
            .max()
            .map_or(0, |m| m + 1);
        (0..charts)
            .filter_map(|c| {
                let pick = |v: &[f64]| -> Vec<f64> {
                    v.iter()
                        .zip(&self.chart_of_patch)
                        .filter(|(_, k)| **k == c)
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
        .map(|p| (p.name.clone(), preset_metrics(report, p)))
        .collect();
    let rules: serde_json::Map<String, Value> = report
        .rules
        .iter()
        .map(|r| {
            (
                r.label.clone(),
                json!({
                    "captures": r.result.captures,
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
    m
}

/// One preset's figures, and its mean ΔE00 per chart.
fn preset_metrics(report: &Report, p: &PresetOutcome) -> Value {
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
    json!({
        "captures": r.captures,
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

/// `problem.json`: per preset and channel the measured attenuation (sparse), `d`, `r`, `s`,
/// the final `x`, `G` and `G*` (`G = ½ Σ_i e_i²` on that channel).
pub fn problem(report: &Report) -> Value {
    let presets: serde_json::Map<String, Value> = report
        .presets
        .iter()
        .map(|p| {
            let problem = &p.model.problem;
            let s = problem.white_response();
            let errors = problem.errors(&p.result.x);
            let best = roomlight_core::optimum::optimum(problem).ok();
            let channels: Vec<Value> = ["r", "g", "b"]
                .iter()
                .enumerate()
                .map(|(c, name)| {
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
                    json!({
                        "channel": name,
                        "attenuation": columns,
                        "d": channel(problem.black(), c),
                        "r": channel(problem.target(), c),
                        "s": channel(&s, c),
                        "x": channel(&p.result.x, c),
                        "G": 0.5 * errors.iter().map(|e| e[c] * e[c]).sum::<f64>(),
                        "G_star": best.as_ref().map(|b| b.objective_per_channel[c]),
                    })
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

/// A log-scale plot of `y(point)` against `x(point)` for each rule, as SVG.
pub(crate) fn plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(&str, Vec<(f64, f64)>)],
    log_y: bool,
) -> Result<()> {
    let area = SVGBackend::new(path, (720, 400)).into_drawing_area();
    let fail = |e: &dyn std::fmt::Display| anyhow::anyhow!("plot {}: {e}", path.display());
    area.fill(&WHITE).map_err(|e| fail(&e))?;
    let x_max = series
        .iter()
        .flat_map(|(_, s)| s.iter().map(|p| p.0))
        .fold(1e-3, f64::max);
    let ys = || series.iter().flat_map(|(_, s)| s.iter().map(|p| p.1));
    let colours = [RED, BLUE, GREEN, MAGENTA, BLACK, CYAN];
    let mut chart = ChartBuilder::on(&area);
    chart
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60);
    if log_y {
        // Values below 1e-6 are drawn at 1e-6 (the plot's floor).
        let floor = 1e-6;
        let top = ys().fold(floor * 10.0, f64::max) * 2.0;
        let mut c = chart
            .build_cartesian_2d(0.0..x_max, (floor..top).log_scale())
            .map_err(|e| fail(&e))?;
        c.configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(|e| fail(&e))?;
        for ((label, s), colour) in series.iter().zip(colours.iter().cycle()) {
            let colour = *colour;
            c.draw_series(LineSeries::new(
                s.iter().map(|&(x, y)| (x, y.max(floor))),
                colour.stroke_width(2),
            ))
            .map_err(|e| fail(&e))?
            .label(*label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour));
        }
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| fail(&e))?;
    } else {
        let top = ys().fold(1e-3, f64::max) * 1.1;
        let mut c = chart
            .build_cartesian_2d(0.0..x_max, 0.0..top)
            .map_err(|e| fail(&e))?;
        c.configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(|e| fail(&e))?;
        for ((label, s), colour) in series.iter().zip(colours.iter().cycle()) {
            let colour = *colour;
            c.draw_series(LineSeries::new(s.iter().copied(), colour.stroke_width(2)))
                .map_err(|e| fail(&e))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour));
        }
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| fail(&e))?;
    }
    area.present().map_err(|e| fail(&e))?;
    Ok(())
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
    std::fs::write(&path, html(report)).with_context(|| format!("writing {}", path.display()))
}

/// The convergence plots of every rule, the hot join's and the shadow profiles.
fn write_plots(dir: &Path, report: &Report) -> Result<()> {
    let series = |f: fn(&TracePoint) -> (f64, f64)| -> Vec<(&str, Vec<(f64, f64)>)> {
        report
            .rules
            .iter()
            .map(|r| (r.label.as_str(), r.result.trace.iter().map(f).collect()))
            .collect()
    };
    plot(
        &dir.join("excess-captures.svg"),
        "true excess (G − G*)/G* against captures",
        "captures",
        "true excess",
        &series(|p| (p.capture as f64, p.true_excess)),
        true,
    )?;
    plot(
        &dir.join("excess-time.svg"),
        "true excess (G − G*)/G* against wall time",
        "seconds",
        "true excess",
        &series(|p| (p.seconds, p.true_excess)),
        true,
    )?;
    plot(
        &dir.join("de00-captures.svg"),
        "mean ΔE00 against captures",
        "captures",
        "mean ΔE00",
        &series(|p| (p.capture as f64, p.mean_de00)),
        false,
    )?;
    if let Some(h) = &report.hot_join {
        let trace = |f: fn(&TracePoint) -> f64| -> Vec<(f64, f64)> {
            h.result
                .trace
                .iter()
                .map(|p| (p.capture as f64, f(p)))
                .collect()
        };
        plot(
            &dir.join("hot-join.svg"),
            "a projector leaves, an unmeasured one joins hot",
            "captures",
            "excess over the optimum without the leaver",
            &[
                ("model excess", trace(|p| p.model_excess)),
                ("true excess", trace(|p| p.true_excess)),
            ],
            true,
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
            "desk irradiance across the shadow's edge (occluded / open)",
            "mm across the edge (+160 = the geometric edge)",
            "ratio",
            &series,
            false,
        )?;
    }
    Ok(())
}

/// The demo's page: calibration, the lighting reproduction per preset, projection mapping,
/// shadows, the hot join and the convergence of each rule, in that order.
fn html(report: &Report) -> String {
    let mut h = String::new();
    html_head(&mut h, report);
    calibration_section(&mut h, report);
    reproduction_section(&mut h, report);
    if let Some(pm) = &report.pm {
        pm_section(&mut h, pm);
    }
    if let Some(s) = &report.shadows {
        shadow_section(&mut h, s);
    }
    if let Some(j) = &report.hot_join {
        hot_join_section(&mut h, j);
    }
    convergence_section(&mut h, report);
    h
}

/// The page's head, style and introduction.
fn html_head(h: &mut String, report: &Report) {
    let _ = write!(
        h,
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>roomlight: {room}</title>\
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}\
img{{max-width:100%}}table{{border-collapse:collapse;margin:1em 0}}\
td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}th{{background:#f4f4f4}}\
.row{{display:flex;gap:8px}}.row figure{{flex:1;margin:0}}figcaption{{font-size:90%;text-align:center}}</style>\
</head><body><h1>roomlight on the simulated room “{room}”</h1>\
<p>Projectors replace the room's LED lights: the camera measures the charts under each LED preset, \
the LEDs go off, and the projectors' node agents reproduce that light from the per-patch errors \
the camera agent broadcasts. All numbers are against the simulator's ground truth; the whole demo \
took {wall:.1} s (seed {seed}).</p>",
        room = escape(&report.room),
        wall = report.wall_seconds,
        seed = report.seed
    );
}

/// What calibration did, line by line, and its captures.
fn calibration_section(h: &mut String, report: &Report) {
    h.push_str("<h2>Calibration</h2><ul>");
    for line in &report.calibration {
        let _ = write!(h, "<li>{}</li>", escape(line));
    }
    let _ = write!(
        h,
        "</ul><p>{} captures in all.</p>",
        report.calibration_captures
    );
}

/// Per preset: the figures against the simulator's truth, the three pictures and each chart.
fn reproduction_section(h: &mut String, report: &Report) {
    h.push_str(
        "<h2>Lighting reproduction</h2><table><tr><th>preset</th><th>captures</th>\
<th>mean ΔE00</th><th>max ΔE00</th><th>conventional mean ΔE00</th><th>true optimum mean ΔE00</th>\
<th>excess over G* (measured model)</th><th>true excess</th></tr>",
    );
    for p in &report.presets {
        let r = &p.result;
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2e}</td><td>{:.2e}</td></tr>",
            escape(&p.name),
            r.captures,
            mean(&r.de00),
            max(&r.de00),
            mean(&r.conventional_de00),
            r.best_mean_de00,
            r.final_excess,
            r.true_excess
        );
    }
    h.push_str(
        "</table><p>ΔE00 is measured by a noiseless camera sampling the charts as calibration \
does. The excess over G* is on the measured model (what an installation can know). The true \
excess is against the optimum of a linear model of the same nodes built from noiseless renders; \
the charts' trimmed-mean sampling over patches crossed by soft light gradients makes the real room \
slightly non-linear, so that reference can be beaten (negative values).</p>",
    );
    for p in &report.presets {
        let _ = write!(
            h,
            "<h3>{name}</h3><div class=\"row\">\
<figure><img src=\"{a}\" alt=\"under the LEDs\"><figcaption>target: the LEDs</figcaption></figure>\
<figure><img src=\"{b}\" alt=\"conventional start\"><figcaption>conventional start, ΔE00 {cb:.2}</figcaption></figure>\
<figure><img src=\"{c}\" alt=\"distributed result\"><figcaption>distributed result, ΔE00 {cc:.2}</figcaption></figure></div>\
<table><tr><th>chart</th><th>result ΔE00</th><th>conventional ΔE00</th></tr>",
            name = escape(&p.name),
            a = escape(&p.images[0]),
            b = escape(&p.images[1]),
            c = escape(&p.images[2]),
            cb = mean(&p.result.conventional_de00),
            cc = mean(&p.result.de00)
        );
        for (c, de, conv) in p.per_chart() {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{de:.2}</td><td>{conv:.2}</td></tr>",
                escape(report.chart_names.get(c).map_or("?", String::as_str))
            );
        }
        h.push_str("</table>");
    }
}

/// The texture projector under three lightings: contrast and pictures.
fn pm_section(h: &mut String, pm: &crate::pm::PmResult) {
    let _ = write!(
        h,
        "<h2>Projection mapping</h2><p>The texture projector under three lightings: a dark \
room, the LED preset, and the projectors' lighting (first preset). ANSI contrast of a 4×4 checker \
on a 200 mm board in place of the bust: dark {:.0}:1, LED {:.0}:1, projector lighting {:.0}:1 \
(the paper measured 180:1, 30:1 and 65:1).</p><table><tr><th>texture</th><th>RMS dark</th>\
<th>RMS LED</th><th>RMS projector</th></tr>",
        pm.ansi_contrast[0], pm.ansi_contrast[1], pm.ansi_contrast[2]
    );
    for (t, v) in &pm.rms_contrast {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td></tr>",
            escape(t),
            v[0],
            v[1],
            v[2]
        );
    }
    h.push_str("</table><div class=\"row\" style=\"flex-wrap:wrap\">");
    for (file, caption) in &pm.images {
        let _ = write!(
            h,
            "<figure style=\"flex:0 0 24%\"><img src=\"{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>",
            escape(file),
            c = escape(caption)
        );
    }
    h.push_str("</div>");
}

/// The large aperture's penumbra against a standard projector's, and the glare.
fn shadow_section(h: &mut String, s: &crate::shadow::ShadowComparison) {
    let _ = write!(
        h,
        "<h2>Large aperture against a standard projector</h2><p>A hand-sized box 200 mm over \
the desk under the large-aperture projector, then under a standard (pinhole) projector in the \
same place. Penumbra (10% to 90% of the open desk's direct irradiance): {}. For the same desk \
irradiance a standard projector with a {:.0} mm exit pupil emits {:.0}× the peak radiance of the \
large aperture (glare).</p><img src=\"shadow.svg\" alt=\"shadow profiles\">",
        s.kinds
            .iter()
            .map(|k| format!("{} {:.0} mm", escape(&k.kind), k.penumbra_mm))
            .collect::<Vec<_>>()
            .join(", "),
        crate::shadow::STANDARD_PUPIL_MM,
        s.peak_radiance_ratio
    );
}

/// A projector leaves, an unmeasured one joins hot.
fn hot_join_section(h: &mut String, j: &HotJoin) {
    let _ = write!(
        h,
        "<h2>A projector leaves, an unmeasured one joins</h2><p>On the first preset, default rule: \
{} is switched off after {} captures; {}, dark until then and unknown to the camera agent, joins after {}. \
The camera agent measures it hot ({} captures: its nodes at black, then each alone at white, while the \
others keep their values), sends everyone <i>s</i> anew, and the room converges without the leaver: \
after {} captures in all, excess {:.1e} over the measured model's optimum (true {:.1e}), mean ΔE00 {:.2}.</p>\
<img src=\"hot-join.svg\" alt=\"excess through the leave and the hot join\">",
        escape(&j.leaving),
        j.churn.leave_at,
        escape(&j.joining),
        j.churn.join_at,
        j.calibration_captures,
        j.result.captures,
        j.result.final_excess,
        j.result.true_excess,
        mean(&j.result.de00)
    );
}

/// Each rule from the conventional start until the camera agent reports it settled; the plots
/// and the data files.
fn convergence_section(h: &mut String, report: &Report) {
    h.push_str("<h2>Convergence</h2><p>On the first preset, from the conventional start, each rule until the \
camera agent reports that G no longer moves beyond its noise (or the capture cap).</p>\
<table><tr><th>rule</th><th>captures</th><th>seconds</th><th>true excess</th><th>mean ΔE00</th></tr>");
    for r in &report.rules {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2e}</td><td>{:.2}</td></tr>",
            escape(&r.label),
            r.result.captures,
            r.result.seconds,
            r.result.true_excess,
            mean(&r.result.de00)
        );
    }
    h.push_str(
        "</table><img src=\"excess-captures.svg\" alt=\"excess against captures\">\
<img src=\"excess-time.svg\" alt=\"excess against time\">\
<img src=\"de00-captures.svg\" alt=\"ΔE00 against captures\">\
<p>Data: <a href=\"metrics.json\">metrics.json</a>, <a href=\"problem.json\">problem.json</a>.</p></body></html>",
    );
}
