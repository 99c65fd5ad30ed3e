//! The demo's page, `index.html`: one function per section.

use super::*;

/// The demo's page: calibration, the lighting reproduction per preset, projection mapping,
/// shadows, the hot join and the convergence of each rule, in that order.
pub(super) fn html(report: &Report) -> String {
    let mut h = String::new();
    html_head(&mut h, report);
    calibration_section(&mut h, report);
    reproduction_section(&mut h, report);
    if let Some(pm) = &report.pm {
        pm_section(&mut h, pm);
    }
    if let Some(d) = &report.dark_target {
        dark_target_section(&mut h, d);
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
.row{{display:flex;gap:8px}}.row figure{{flex:1;margin:0}}figcaption{{font-size:90%;text-align:center}}\
.row img.plot{{flex:1;min-width:0}}.crops img{{max-width:none;image-rendering:pixelated}}\
.crops figure{{flex:0 0 auto}}</style>\
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
        "<h2 id=\"reproduction\">Lighting reproduction</h2><table><tr><th>preset</th><th>captures to 1% (model)</th>\
<th>captures to 1% (true)</th><th>captures until settled</th><th>mean ΔE00</th><th>max ΔE00</th><th>conventional mean ΔE00</th><th>true optimum mean ΔE00</th>\
<th>excess over G* (measured model)</th><th>true excess</th></tr>",
    );
    for p in &report.presets {
        let r = &p.result;
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2e}</td><td>{:.2e}</td></tr>",
            escape(&p.name),
            captures_cell(r, model_excess),
            captures_cell(r, true_excess),
            r.captures,
            if r.settled { "" } else { " (cap)" },
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
slightly non-linear, so that reference can be beaten (negative values). Captures to 1% count \
from the conventional start (capture 0) to the first capture whose excess is at most 1%; \
“&gt; N” means not within the N captures the run took.</p>",
    );
    whole_room_table(h, report);
    for p in &report.presets {
        let _ = write!(
            h,
            "<h3>{name}</h3><div class=\"row\">\
<figure><img src=\"{a}\" alt=\"under the LEDs\"><figcaption>target: the LEDs</figcaption></figure>\
<figure><img src=\"{b}\" alt=\"conventional start\"><figcaption>conventional start, ΔE00 {cb:.2}</figcaption></figure>\
<figure><img src=\"{c}\" alt=\"distributed result\"><figcaption>distributed result, ΔE00 {cc:.2}</figcaption></figure></div>\
<table><tr><th>chart</th><th>result ΔE00</th><th>conventional ΔE00</th></tr>",
            name = escape(&p.name),
            a = escape(&p.pictures.pictures[0]),
            b = escape(&p.pictures.pictures[1]),
            c = escape(&p.pictures.pictures[2]),
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
        whole_room_figures(h, p);
    }
}

/// Per preset: ΔE00 over the whole room, the pixels no luminaire lights and the seam metric.
fn whole_room_table(h: &mut String, report: &Report) {
    h.push_str(
        "<h3 id=\"whole-room\">The whole room</h3><p>ΔE00 per camera pixel between the room under the LEDs and \
with the result (noiseless renders in the room camera's view; Lab with the LED picture's 99th \
percentile luminance as L* = 100). Mean and 95th percentile over the pixels a luminaire lights \
directly through a node (<i>reached</i>); the other pixels that see a surface are counted apart: \
<i>no node</i> (a luminaire lights them, but through projector pixels calibration gave no node: \
the target, beyond the nodes), <i>occluded</i> (inside a luminaire's image but shadowed or facing \
away) and <i>outside</i> every luminaire's image. Seam: the mean ΔE00 within 4 pixels of an edge \
where the set of projectors lighting the room changes, against the other reached pixels.</p>\
<table><tr><th>preset</th><th>mean ΔE00</th><th>p95 ΔE00</th><th>reached</th><th>no node</th>\
<th>occluded</th><th>outside</th><th>seam band ΔE00</th><th>elsewhere</th><th>seam − elsewhere</th></tr>",
    );
    for p in &report.presets {
        let w = &p.pictures.whole_room;
        let pct = |v: f64| format!("{:.1}%", 100.0 * v);
        let (band, rest, excess) =
            w.seam
                .map_or(("no overlap".into(), "".into(), "".into()), |s| {
                    (
                        format!("{:.2} ({} of reached)", s.band_de00_mean, pct(s.band_share)),
                        format!("{:.2}", s.elsewhere_de00_mean),
                        format!("{:+.2}", s.excess_de00),
                    )
                });
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{band}</td><td>{rest}</td><td>{excess}</td></tr>",
            escape(&p.name),
            w.de00_mean,
            w.de00_p95,
            pct(w.reached_share),
            pct(w.no_node_share),
            pct(w.occluded_share),
            pct(w.outside_share)
        );
    }
    h.push_str("</table>");
    h.push_str(
        "<p>The best the measured model could reach, beside what the rounds reached: the model's \
exact optimum rendered the same way, over the charts alone (what the rounds minimise) and with \
tiles of the walls beyond the charts weighed in (each tile's squared error at the weight given, a \
chart patch's at 1; tiles no node reaches left out). ΔE00 at the charts is the model's own \
prediction at its optimum.</p><table><tr><th>preset</th><th>model</th><th>patches</th>\
<th>whole room mean ΔE00</th><th>p95</th><th>seam − elsewhere</th><th>charts ΔE00</th></tr>",
    );
    for p in &report.presets {
        for b in &p.model_best {
            let what = if b.wall_weight > 0.0 {
                format!("charts + walls (weight {})", b.wall_weight)
            } else {
                "charts".to_string()
            };
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{what}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td><td>{:.2}</td></tr>",
                escape(&p.name),
                b.patches,
                b.whole_room_de00_mean,
                b.whole_room_de00_p95,
                b.seam_excess_de00
                    .map_or("no overlap".into(), |s| format!("{s:+.2}")),
                b.chart_de00_mean
            );
        }
    }
    h.push_str("</table>");
    h.push_str(
        "<p>Per-pixel shading after the rounds: each luminaire's light multiplied per block of its \
pixels and per colour channel by gains stepped towards the LEDs' photograph, one capture a pass \
(<code>roomlight_calib::shading</code>). It runs in the demo's process on what a camera gives (the \
preset's photograph, noisy captures, the decodes); no message carries gains to a node agent yet. \
Whole-room ΔE00 mean / p95 after each pass (the first: the rounds' result).</p>\
<table><tr><th>preset</th><th>whole room, pass by pass</th><th>charts ΔE00 before → after</th>\
<th>light on the target, share of the LEDs', before → after</th></tr>",
    );
    let share = |t: Option<f64>| t.map_or("—".to_string(), |t| format!("{:.0}%", 100.0 * t));
    for p in &report.presets {
        let s = &p.shaded;
        let path: Vec<String> = s
            .passes()
            .iter()
            .map(|q| {
                format!(
                    "{:.2} / {:.2}",
                    q.whole_room_de00_mean, q.whole_room_de00_p95
                )
            })
            .collect();
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{:.2} → {:.2}</td><td>{} → {}</td></tr>",
            escape(&p.name),
            path.join(" → "),
            s.first().chart_de00_mean,
            s.last().chart_de00_mean,
            share(s.first().target_light_share),
            share(s.last().target_light_share)
        );
    }
    h.push_str("</table>");
}

/// One preset's ΔE00 map and its crops where it is worst, at the camera's full resolution.
fn whole_room_figures(h: &mut String, p: &PresetOutcome) {
    let pic = &p.pictures;
    let (x, y, w, hh) = pic.crop;
    // Twice their size when three fit side by side on the page (1100 px), else 1:1.
    let zoom = if 6 * w + 16 <= 1100 { 2 } else { 1 };
    let shown = if zoom == 2 {
        "shown twice their size"
    } else {
        "shown at their size"
    };
    let _ = write!(
        h,
        "<figure style=\"margin:1em 0\"><img src=\"{map}\" alt=\"ΔE00 map\"><figcaption>ΔE00 of the \
result against the LEDs per camera pixel (mean {mean:.2}, 95th percentile {p95:.2} over reached pixels); \
greys: not reached, black: no surface</figcaption></figure>{shaded}\
<p>Where the map is worst: the {w}×{hh} window at ({x}, {y}), the camera's own pixels, not resampled ({shown}).</p>\
<div class=\"row crops\">",
        map = escape(&pic.de00_map),
        mean = pic.whole_room.de00_mean,
        p95 = pic.whole_room.de00_p95,
        shaded = p.shaded.map_file.as_ref().map_or(String::new(), |f| {
            let last = p.shaded.last();
            format!(
                "<figure style=\"margin:1em 0\"><img src=\"{}\" alt=\"ΔE00 map after shading\">\
<figcaption>The same after {} passes of per-pixel shading (mean {:.2}, 95th percentile {:.2})\
</figcaption></figure>",
                escape(f),
                last.captures,
                last.whole_room_de00_mean,
                last.whole_room_de00_p95
            )
        }),
    );
    for (file, caption) in pic.crops.iter().zip(["the LEDs", "the result", "ΔE00"]) {
        let _ = write!(
            h,
            "<figure><img src=\"{}\" width=\"{}\" alt=\"{caption}\"><figcaption>{caption}</figcaption></figure>",
            escape(file),
            zoom * w
        );
    }
    let linear: Vec<String> = pic
        .linear
        .iter()
        .map(|(f, s)| {
            format!(
                "<a href=\"{}\">{}</a> (value = code × {s:.3e})",
                escape(f),
                escape(f)
            )
        })
        .collect();
    let _ = write!(
        h,
        "</div><p>Linear 16-bit PNGs (gAMA 1.0, cHRM sRGB/D65, scale also in their tEXt chunk; the \
largest value at 65535, nothing clipped): {}.</p>",
        linear.join(", ")
    );
}

/// The texture projector under three lightings: contrast and pictures.
fn pm_section(h: &mut String, pm: &crate::pm::PmResult) {
    let _ = write!(
        h,
        "<h2 id=\"projection-mapping\">Projection mapping</h2><p>The texture projector under three lightings: a dark \
room, the LED preset, and the projectors' lighting (first preset). ANSI contrast of a 4×4 checker \
on a 200 mm board in place of the bust: dark {:.0}:1, LED {:.0}:1, projector lighting {:.0}:1 \
(the paper measured 180:1, 30:1 and 65:1).</p>",
        pm.ansi_contrast[0], pm.ansi_contrast[1], pm.ansi_contrast[2]
    );
    if pm.ansi_by_preset.len() > 1 {
        h.push_str("<table><tr><th>preset</th><th>ANSI dark</th><th>ANSI LED</th><th>ANSI projector lighting</th></tr>");
        for (name, a) in &pm.ansi_by_preset {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{:.0}:1</td><td>{:.0}:1</td><td>{:.0}:1</td></tr>",
                escape(name),
                a[0],
                a[1],
                a[2]
            );
        }
        h.push_str("</table>");
    }
    h.push_str(
        "<table><tr><th>texture</th><th>RMS dark</th><th>RMS LED</th><th>RMS projector</th></tr>",
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

/// The dark-target trade-off: per weight, the room's ΔE00 against the board's contrast.
fn dark_target_section(h: &mut String, d: &DarkTarget) {
    let _ = write!(
        h,
        "<h2 id=\"dark-target\">A dark target: the trade-off</h2><p>The light the luminaires throw on the \
projection-mapping target enters the objective with weight w: {} patches on the target, measured through the \
same attenuation captures as the charts, asked to stay at the black level, their squared errors weighed by w. \
Per weight, on preset {}: the model's exact optimum (not rounds of the agents) rendered noiselessly, the \
whole-room ΔE00 against the LEDs, the light left on the target, and the board's ANSI contrast under that \
projector lighting. The last row is the agents' rounds on that preset at the weight the preset asks for \
(<code>dark_weight</code> in the scene, or <code>demo --dark-weight</code>); {} is the weight suggested for a dark target.</p>\
<table><tr><th>weight w</th><th>whole-room ΔE00 mean</th><th>95th percentile</th>\
<th>light on the target (share of the LEDs')</th><th>ANSI contrast, projector lighting</th></tr>",
        d.patches,
        escape(&d.preset),
        crate::dark_target::DEFAULT_WEIGHT
    );
    for p in &d.points {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.0}%</td><td>{:.0}:1</td></tr>",
            p.weight,
            p.room_de00_mean,
            p.room_de00_p95,
            100.0 * p.target_light_share,
            p.ansi_contrast
        );
    }
    if let Some(r) = &d.rounds {
        let _ = write!(
            h,
            "<tr><td>the rounds, w = {} ({} captures; charts ΔE00 {:.2})</td><td>{:.2}</td><td>{:.2}</td><td>{:.0}%</td><td>{:.1}:1</td></tr>",
            r.point.weight,
            r.captures,
            r.charts_de00_mean,
            r.point.room_de00_mean,
            r.point.room_de00_p95,
            100.0 * r.point.target_light_share,
            r.point.ansi_contrast
        );
    }
    h.push_str("</table>");
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
        "<h2 id=\"hot-join\">A projector leaves, an unmeasured one joins</h2><p>On the first preset, default rule: \
{} is switched off after {} captures; {}, dark until then and unknown to the camera agent, joins after {}. \
The camera agent measures it hot ({} captures: its nodes at black, then each alone at white, while the \
others keep their values), sends everyone <i>s</i> anew, and the room converges without the leaver: \
after {} captures in all, excess {:.1e} over the measured model's optimum (true {:.1e}), mean ΔE00 {:.2}.</p>\
<p>The dashed lines mark the capture after which the projector left and the one after which \
the new one joined.</p><img src=\"hot-join.svg\" alt=\"excess through the leave and the hot join\">",
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

/// Each rule from the conventional start for the same number of captures: captures and time
/// to 1% excess, the plots against captures and against wall-clock time side by side.
fn convergence_section(h: &mut String, report: &Report) {
    h.push_str(
        "<h2 id=\"convergence\">Convergence</h2><p>On the first preset, from the conventional start, each rule \
for the same number of captures whether or not it would have settled. Captures to 1%: the first \
capture (0 is the start) whose excess is at most 1%, on the measured model (what the rules \
minimise) and on the truth; seconds: wall-clock time of the agents to that capture.</p>\
<table><tr><th>rule</th><th>captures to 1% (model)</th><th>seconds to 1% (model)</th>\
<th>captures to 1% (true)</th><th>captures run</th><th>seconds</th><th>final true excess</th>\
<th>mean ΔE00</th></tr>",
    );
    for r in &report.rules {
        let res = &r.result;
        let seconds = captures_to(&res.trace, model_excess, EXCESS_LEVEL)
            .and_then(|c| res.trace.iter().find(|p| p.capture == c))
            .map_or("–".into(), |p| format!("{:.2}", p.seconds));
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{seconds}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2e}</td><td>{:.2}</td></tr>",
            escape(&r.label),
            captures_cell(res, model_excess),
            captures_cell(res, true_excess),
            res.captures,
            res.seconds,
            res.true_excess,
            mean(&res.de00)
        );
    }
    h.push_str(
        "</table><p>Excess on a symmetric log scale: logarithmic above 10<sup>−4</sup> in size, \
linear below, so that negative values (the true reference beaten) show below the zero line.</p>\
<div class=\"row\"><img class=\"plot\" src=\"excess-captures.svg\" alt=\"excess against captures\">\
<img class=\"plot\" src=\"excess-time.svg\" alt=\"excess against wall-clock time\"></div>\
<img src=\"de00-captures.svg\" alt=\"ΔE00 against captures\">\
<p>Data: <a href=\"metrics.json\">metrics.json</a>, <a href=\"problem.json\">problem.json</a>.</p></body></html>",
    );
}
