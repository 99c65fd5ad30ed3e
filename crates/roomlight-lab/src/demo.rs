//! `roomlight demo`: the whole method on the simulated lab (calibration from captures, then the
//! real agents over loopback gRPC; see `crate::pipeline`), or with `--synthetic` the comparison of
//! update rules on a synthetic room against the exact optimum. The report of issue 6 builds on it.

use crate::pipeline::{self, RunOptions};
use crate::report::{self, PresetOutcome, Report, RuleOutcome, mean};
use anyhow::{Context, Result};
use roomlight_core::closed_loop::{self, LoopConfig, Plant, PlantConfig};
use roomlight_core::conventional::conventional_start;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, StepRule};
use std::sync::Arc;
use std::time::Instant;

/// Options of the demo (the binary fills them from its command line).
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// A smaller room (for tests).
    pub quick: bool,
    /// The synthetic-room comparison of update rules instead of the simulated lab.
    pub synthetic: bool,
    /// Seed of the synthetic room and the camera noise.
    pub seed: u64,
    /// Where the report goes.
    pub out: std::path::PathBuf,
    /// Weight of each wall tile in the rounds' model ([`pipeline::Calibrated::wall_weight`];
    /// 0: the charts alone).
    pub wall_weight: f64,
    /// Weight of the light on the target in every preset's rounds, instead of the weight each
    /// preset asks for in the scene (`dark_weight`, 0 when left out).
    pub dark_weight: Option<f64>,
    /// Luminaire nodes shaped to the first LED preset instead of flat over their regions
    /// ([`pipeline::Nodes`]).
    pub shaped_nodes: bool,
    /// Calibration codes up to three groups at once in their primaries
    /// ([`roomlight_calib::procedure::Settings::primaries`], the default), else one at a time
    /// in white.
    pub primaries: bool,
}

pub fn run(args: &DemoOptions) -> Result<()> {
    if args.synthetic {
        return synthetic(args);
    }
    let t0 = Instant::now();
    let mut phases = Phases::default();
    let (name, room) = build_room(args.quick)?;
    phases.done("room", t0);
    let mut calibration = vec![format!(
        "simulated room built in {:.1} s ({} projectors, {} charts, camera {}×{})",
        t0.elapsed().as_secs_f64(),
        room.projectors().len(),
        room.geometry().charts.len(),
        room.scene().camera.resolution[0],
        room.scene().camera.resolution[1],
    )];
    println!("{name}: {}", calibration[0]);
    let dir = &args.out;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut noise = roomlight_sim::CameraNoise::with_seed(&room, args.seed);
    let bar = progress_bar()?;
    let t = Instant::now();
    // With patches on the target measured too, for the dark-target trade-off (the chart
    // patches' values, and so every model at weight 0, are the same as without).
    let nodes = if args.shaped_nodes {
        pipeline::Nodes::ShapedTo(0)
    } else {
        pipeline::Nodes::Flat
    };
    let settings = roomlight_calib::procedure::Settings {
        primaries: args.primaries,
        ..Default::default()
    };
    let mut cal =
        pipeline::calibrate_configured(&room, true, settings, nodes, &mut noise, &bar, |line| {
            bar.println(&line);
            if bar.is_hidden() {
                println!("{line}");
            }
            calibration.push(line);
        })?;
    phases.done("calibration", t);
    cal.wall_weight = args.wall_weight;
    let t = Instant::now();
    let transport = pipeline::Transport::new(&room, &cal.regions, cal.setup())?;
    println!(
        "simulated hardware: each node's light rendered once in {:.1} s",
        t.elapsed().as_secs_f64()
    );
    let reach = crate::whole_room::ReachMap::new(&room, &cal.regions)?;
    phases.done("node basis and reach", t);
    let lab = Lab {
        room: &room,
        cal: &cal,
        reach: &reach,
        transport: &transport,
        bar: &bar,
        options: args,
        phases: std::cell::RefCell::new(phases),
    };
    let (presets, rules, lit) = lab.presets(&mut noise, dir)?;
    // One capture per preset measures its target.
    let captures = cal.captures + presets.len();
    let mut dark_target = match &lit {
        Some((preset, lit)) => Some(lab.dark_target(*preset, lit, &presets)?),
        None => None,
    };
    let (hot_join, pm) = match presets.first() {
        Some(first) => {
            let t = Instant::now();
            let hot_join = lab.hot_join(first)?;
            lab.phases.borrow_mut().done("hot join", t);
            let t = Instant::now();
            let pm = lab.pm(&presets, dark_target.as_mut())?;
            lab.phases.borrow_mut().done("projection mapping", t);
            (hot_join, Some(pm))
        }
        None => (None, None),
    };
    let mut phases = lab.phases.into_inner();
    let t = Instant::now();
    let shadows = shadows(&room)?;
    phases.done("shadows", t);
    let report = Report {
        pm,
        dark_target,
        shadows,
        hot_join,
        room: name,
        seed: args.seed,
        chart_names: room.scene().charts.iter().map(|c| c.name.clone()).collect(),
        calibration,
        calibration_captures: captures,
        presets,
        rules,
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    let t = Instant::now();
    report::write(dir, &report)?;
    phases.done("report", t);
    println!("{phases}");
    println!(
        "report: {} (demo finished in {:.1} s)",
        dir.join("index.html").display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The small room (with enough camera pixels per chart patch) or the lab.
fn build_room(quick: bool) -> Result<(String, Arc<roomlight_sim::Room>)> {
    let mut scene = if quick {
        roomlight_sim::scenes::small()?
    } else {
        roomlight_sim::scenes::lab()?
    };
    if quick {
        scene.camera.resolution = [640, 480];
    }
    let name = scene.name.clone();
    let room =
        roomlight_sim::Room::build(scene).with_context(|| format!("building the {name} room"))?;
    Ok((name, Arc::new(room)))
}

/// Progress on stderr, only on a terminal (indicatif hides itself otherwise).
fn progress_bar() -> Result<indicatif::ProgressBar> {
    Ok(indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template("{msg:>16} [{bar:30}] {pos}/{len} {elapsed}")
            .map_err(|e| anyhow::anyhow!("progress style: {e}"))?
            .progress_chars("=> "),
    ))
}

fn print_preset(name: &str, r: &pipeline::RunResult) {
    println!(
        "{}: {} captures{}, mean ΔE00 {:.2} (max {:.2}), conventional start {:.2}, true optimum {:.2}; excess over G* {:.1e} (true {:.1e}), {:.1} s",
        name,
        r.captures,
        if r.settled {
            " until settled"
        } else {
            " (cap)"
        },
        mean(&r.de00),
        r.de00.iter().copied().fold(0.0, f64::max),
        mean(&r.conventional_de00),
        r.best_mean_de00,
        r.final_excess,
        r.true_excess,
        r.seconds
    );
}

fn print_whole_room(name: &str, w: &crate::whole_room::WholeRoom) {
    println!(
        "{name}, whole room: ΔE00 mean {:.2}, 95th percentile {:.2} over reached pixels ({:.1}%); not reached: no node {:.1}%, occluded {:.1}%, outside every luminaire {:.1}%; seam band {}",
        w.de00_mean,
        w.de00_p95,
        100.0 * w.reached_share,
        100.0 * w.no_node_share,
        100.0 * w.occluded_share,
        100.0 * w.outside_share,
        w.seam.map_or("none (no overlap)".into(), |s| format!(
            "{:.2} against {:.2} elsewhere",
            s.band_de00_mean, s.elsewhere_de00_mean
        ))
    );
}

/// The calibrated simulated lab the demo's runs share.
struct Lab<'a> {
    room: &'a Arc<roomlight_sim::Room>,
    cal: &'a pipeline::Calibrated,
    /// Which camera pixels the luminaires can light, for the whole-room figures.
    reach: &'a crate::whole_room::ReachMap,
    transport: &'a pipeline::Transport,
    bar: &'a indicatif::ProgressBar,
    options: &'a DemoOptions,
    /// Wall time per phase, for the closing line.
    phases: std::cell::RefCell<Phases>,
}

impl Lab<'_> {
    /// Every preset: its target measured, the agents from the default rule's start, its
    /// pictures; on the first, every rule compared.
    /// Also the LED capture's samples of the dark-target trade-off's preset
    /// ([`crate::dark_target::preset`]).
    #[allow(clippy::type_complexity)]
    fn presets(
        &self,
        noise: &mut roomlight_sim::CameraNoise,
        dir: &std::path::Path,
    ) -> Result<(
        Vec<PresetOutcome>,
        Vec<RuleOutcome>,
        Option<(usize, Vec<roomlight_calib::charts::PatchSample>)>,
    )> {
        let mut presets = Vec::new();
        let mut rules = Vec::new();
        let mut kept = None;
        let tradeoff = crate::dark_target::preset(self.room.scene());
        let mut shading = crate::shaded::Camera::new(self.room, self.options.seed)?;
        for (preset, spec) in self.room.scene().presets.iter().enumerate() {
            let t = Instant::now();
            let (lit, photograph) = pipeline::photograph_lit(self.room, self.cal, preset, noise)?;
            let weight = self.options.dark_weight.unwrap_or(spec.dark_weight);
            let model = pipeline::Model::for_weight(self.cal, &lit, weight)?;
            if Some(preset) == tradeoff {
                kept = Some((preset, lit.clone()));
            }
            let truth = pipeline::Truth::new(self.room, self.transport, &model, preset)?;
            let result = self.agents(
                &model,
                &truth,
                RunOptions::default_rule(self.options.seed + preset as u64),
            )?;
            print_preset(&spec.name, &result);
            self.phases.borrow_mut().done("preset runs", t);
            let t = Instant::now();
            let pictures = report::pictures::preset_pictures(
                self.room, self.cal, &model, &result, self.reach, preset, &spec.name, dir,
            )?;
            print_whole_room(&spec.name, &pictures.whole_room);
            let model_best =
                crate::whole_room_best::pair(self.room, self.cal, self.reach, preset, &lit)?;
            for b in &model_best {
                println!(
                    "{}: the model's optimum with walls weighed {}: whole room ΔE00 mean {:.2}, p95 {:.2}; charts {:.2}",
                    spec.name,
                    b.wall_weight,
                    b.whole_room_de00_mean,
                    b.whole_room_de00_p95,
                    b.chart_de00_mean
                );
            }
            self.phases.borrow_mut().done("pictures and whole room", t);
            let t = Instant::now();
            let lab = (&**self.room, self.cal, self.reach);
            let mut shaded = shading.shade(lab, preset, &photograph, &result.x)?;
            shaded.write_map(dir, &spec.name)?;
            println!("{}, {}", spec.name, shaded.summary());
            self.phases.borrow_mut().done("per-pixel shading", t);
            if preset == 0 {
                let t = Instant::now();
                rules = self.compare_rules(&model, &truth)?;
                self.phases.borrow_mut().done("rules compared", t);
            }
            presets.push(PresetOutcome {
                name: spec.name.clone(),
                // Target and wall patches (after the charts') belong to no chart.
                chart_of_patch: model
                    .patches
                    .iter()
                    .map(|&i| {
                        (i < self.cal.corners.len() * PATCHES_PER_CHART)
                            .then_some(i / PATCHES_PER_CHART)
                    })
                    .collect(),
                model,
                dark_weight: weight,
                truth: truth.problem,
                result,
                pictures,
                model_best: model_best.to_vec(),
                shaded,
            });
        }
        Ok((presets, rules, kept))
    }

    /// The dark-target trade-off curve on `preset` (its LED capture sampled as `lit`): the
    /// model's optimum at each weight, the whole room under it, and the same for the rounds'
    /// result on it (the board's ANSI contrast is added by [`Self::pm`]).
    fn dark_target(
        &self,
        preset: usize,
        lit: &[roomlight_calib::charts::PatchSample],
        presets: &[PresetOutcome],
    ) -> Result<report::DarkTarget> {
        let t = Instant::now();
        let points = crate::dark_target::curve(
            self.room,
            self.cal,
            self.reach,
            preset,
            lit,
            &crate::dark_target::WEIGHTS,
        )?;
        println!(
            "dark target on {}: the model's optimum at weights {} ({:.1} s)",
            self.room.scene().presets[preset].name,
            points
                .iter()
                .map(|p| format!(
                    "{}: whole-room ΔE00 {:.2}, light on the target {:.0}% of the LEDs'",
                    p.weight,
                    p.room_de00_mean,
                    100.0 * p.target_light_share
                ))
                .collect::<Vec<_>>()
                .join("; "),
            t.elapsed().as_secs_f64()
        );
        let rounds = presets
            .get(preset)
            .map(|p| crate::dark_target::rounds_of(self.room, self.cal, self.reach, preset, p))
            .transpose()?;
        Ok(report::DarkTarget {
            preset: self.room.scene().presets[preset].name.clone(),
            patches: self.cal.target_patch_range().len(),
            points,
            rounds,
        })
    }

    /// The agents on one target, with the live line while they run.
    fn agents(
        &self,
        model: &pipeline::Model,
        truth: &pipeline::Truth,
        options: RunOptions,
    ) -> Result<pipeline::RunResult> {
        self.bar.reset();
        self.bar.set_length(options.max_captures);
        self.bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} capture {pos}/{len} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        let result = pipeline::run_agents(
            self.room,
            self.cal,
            model,
            self.transport,
            truth,
            options,
            self.bar,
        );
        self.bar.finish_and_clear();
        result
    }

    /// The rules of DESIGN §3.2–§3.4 on the same target, from the same start, with the same
    /// capture budget whether or not they would have settled.
    fn compare_rules(
        &self,
        model: &pipeline::Model,
        truth: &pipeline::Truth,
    ) -> Result<Vec<RuleOutcome>> {
        let momentum = StepRule::Momentum { theta: 1.0 };
        let safe = StepRule::Safe { theta: 1.0 };
        let compared = [
            ("paper (fixed ε)", StepRule::paper(), 0),
            ("safe step", safe, 0),
            ("momentum", momentum, 0),
            ("momentum + 5 model rounds", momentum, 5),
            ("momentum + 20 model rounds", momentum, 20),
            (
                "momentum + 100 model rounds (default)",
                momentum,
                roomlight_agent::camera::DEFAULT_MODEL_ROUNDS,
            ),
        ];
        let budget = if self.options.quick { 15 } else { 30 };
        let mut rules = Vec::new();
        for (label, rule, model_rounds) in compared {
            let options = RunOptions {
                rule,
                model_rounds,
                max_captures: budget,
                stop_when_settled: false,
                ..RunOptions::default_rule(self.options.seed)
            };
            let result = self.agents(model, truth, options)?;
            println!(
                "  rule {label}: {} captures, {:.2} s, true excess {:.1e}, mean ΔE00 {:.2}",
                result.captures,
                result.seconds,
                result.true_excess,
                mean(&result.de00)
            );
            rules.push(RuleOutcome {
                label: label.into(),
                result,
            });
        }
        Ok(rules)
    }

    /// A projector leaves, and another that the camera agent has never measured joins: it is
    /// calibrated hot, then the room converges without the leaver (first preset, default rule).
    fn hot_join(&self, first: &PresetOutcome) -> Result<Option<report::HotJoin>> {
        let (leave_at, join_at, after) = if self.options.quick {
            (3, 6, 8)
        } else {
            (5, 10, 12)
        };
        let churn = match pipeline::Churn::pick(self.room, self.cal, leave_at, join_at, true) {
            Ok(churn) => churn,
            Err(e) => {
                println!("no projector to join hot: {e:#}");
                return Ok(None);
            }
        };
        let truth = pipeline::Truth::new(self.room, self.transport, &first.model, 0)?;
        let nodes = self
            .cal
            .regions
            .iter()
            .filter(|r| r.projector == churn.joining)
            .count() as u64;
        let options = RunOptions {
            max_captures: join_at + nodes + 1 + after,
            stop_when_settled: false,
            churn: Some(churn),
            ..RunOptions::default_rule(self.options.seed)
        };
        let result = self.agents(&first.model, &truth, options)?;
        let name = |k: usize| self.room.projectors()[k].name.clone();
        println!(
            "{} leaves after {leave_at} captures, {} joins unmeasured after {join_at}: calibrated hot ({} projector, {} captures), then {} captures in all: excess {:.1e} over the optimum without the leaver (true {:.1e}), mean ΔE00 {:.2}",
            name(churn.leaving),
            name(churn.joining),
            result.calibrated_hot,
            nodes + 1,
            result.captures,
            result.final_excess,
            result.true_excess,
            mean(&result.de00)
        );
        Ok(Some(report::HotJoin {
            leaving: name(churn.leaving),
            joining: name(churn.joining),
            churn,
            calibration_captures: (nodes + 1) * result.calibrated_hot,
            result,
        }))
    }

    /// Projection mapping with the first preset's result; the board's contrast under every
    /// preset's.
    fn pm(
        &self,
        presets: &[PresetOutcome],
        dark_target: Option<&mut report::DarkTarget>,
    ) -> Result<crate::pm::PmResult> {
        let t = Instant::now();
        let tradeoff: Vec<crate::pm::Lighting<'_>> = dark_target
            .as_ref()
            .map(|d| {
                d.points
                    .iter()
                    .map(|p| crate::pm::Lighting {
                        preset: 0,
                        name: "dark-target",
                        x: &p.x,
                        gains: &[],
                    })
                    .collect()
            })
            .unwrap_or_default();
        let lightings: Vec<crate::pm::Lighting<'_>> = presets
            .iter()
            .enumerate()
            .map(|(preset, p)| crate::pm::Lighting {
                preset,
                name: &p.name,
                x: &p.result.x,
                gains: &[],
            })
            .collect();
        // After the trade-off's, each preset's light after per-pixel shading: the board's ANSI
        // contrast under it.
        let extra: Vec<crate::pm::Lighting<'_>> = tradeoff
            .iter()
            .copied()
            .chain(
                lightings
                    .iter()
                    .zip(presets)
                    .map(|(l, p)| crate::pm::Lighting {
                        gains: &p.shaded.final_gains,
                        ..*l
                    }),
            )
            .collect();
        let mut pm = crate::pm::run(
            self.room,
            self.cal,
            &lightings,
            &extra,
            self.options.seed,
            &self.options.out,
            |line| println!("{line}"),
        )?;
        let shaded_ansi = pm.tradeoff_ansi.split_off(tradeoff.len());
        drop(tradeoff);
        println!(
            "ANSI contrast on the board under projector lighting after per-pixel shading: {}",
            presets
                .iter()
                .zip(&shaded_ansi)
                .map(|(p, a)| format!("{} {a:.1}", p.name))
                .collect::<Vec<_>>()
                .join(", ")
        );
        println!(
            "ANSI contrast on the board per preset, dark/LED/projector lighting: {}",
            pm.ansi_by_preset
                .iter()
                .map(|(n, a)| format!("{n} {:.0}/{:.1}/{:.1}", a[0], a[1], a[2]))
                .collect::<Vec<_>>()
                .join(", ")
        );
        if let Some(d) = dark_target {
            crate::dark_target::with_ansi(d, &pm);
        }
        println!(
            "projection mapping and contrast: {:.1} s",
            t.elapsed().as_secs_f64()
        );
        Ok(pm)
    }
}

/// The large aperture's shadow against a standard projector's, when the room has one.
fn shadows(room: &roomlight_sim::Room) -> Result<Option<crate::shadow::ShadowComparison>> {
    let t = Instant::now();
    let large = roomlight_sim::scene::ProjectorKind::LargeAperture;
    if !room.scene().projectors.iter().any(|p| p.kind == large) {
        return Ok(None);
    }
    let s = crate::shadow::run(room.scene())?;
    println!(
        "shadow of a hand-sized box over the desk: penumbra {} mm; a standard projector needs {:.0}× the large aperture's peak radiance for the same desk irradiance ({:.1} s)",
        s.kinds
            .iter()
            .map(|k| format!("{} {:.0}", k.kind, k.penumbra_mm))
            .collect::<Vec<_>>()
            .join(", "),
        s.peak_radiance_ratio,
        t.elapsed().as_secs_f64()
    );
    Ok(Some(s))
}

/// Patches per colour chart.
const PATCHES_PER_CHART: usize = 24;

/// Wall time per phase of the demo (phases met again add up), in the order first met, and the
/// process's peak memory when each last ended: the closing line.
#[derive(Debug, Default)]
struct Phases(Vec<(&'static str, f64, Option<f64>)>);

impl Phases {
    /// Records a phase's time and the peak so far, then hands back what the phase freed
    /// (`heap::release_free`): the full demo peaked at 747–804 MB without, 683–720 MB with.
    fn done(&mut self, name: &'static str, since: Instant) {
        let s = since.elapsed().as_secs_f64();
        // The process's peak resident memory (VmHWM), in MB of 10⁶ bytes; `None` off Linux.
        let peak = crate::bench::memory::resident().map(|r| r.peak as f64 / 1e6);
        crate::heap::release_free();
        match self.0.iter_mut().find(|(n, ..)| *n == name) {
            Some((_, total, at)) => {
                *total += s;
                *at = peak;
            }
            None => self.0.push((name, s, peak)),
        }
    }
}

impl std::fmt::Display for Phases {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let list: Vec<String> = self
            .0
            .iter()
            .map(|(name, s, peak)| match peak {
                Some(mb) => format!("{name} {s:.1} s (peak {mb:.0} MB)"),
                None => format!("{name} {s:.1} s"),
            })
            .collect();
        write!(f, "phases: {}", list.join(", "))
    }
}

/// The synthetic-room comparison: the in-memory loop against the paper's rule, then the agents.
fn synthetic(args: &DemoOptions) -> Result<()> {
    let t0 = Instant::now();
    let nodes = if args.quick { 25 } else { 100 };
    let room = synthetic_room(&SyntheticConfig::new(nodes, args.seed))
        .context("building the synthetic room")?;
    let problem = &room.problem;
    println!(
        "synthetic room: {nodes} luminaire nodes, {} chart patches, {:.1}% of the attenuation entries above 3σ kept",
        problem.patches(),
        100.0 * problem.columns().iter().map(|c| c.len()).sum::<usize>() as f64
            / (nodes * problem.patches()) as f64
    );
    let best = optimum(problem).context("computing the reference optimum")?;
    let start = conventional_start(problem, &room.charts, LinearRgb::splat(0.5))?;
    let de_start = patch_delta_e(problem.target(), &problem.response(&start))?;
    println!(
        "conventional start (DESIGN §3.1): excess over G* {:.3}, mean ΔE00 {:.2}",
        best.excess(problem.objective(&start)),
        de_start.mean
    );
    let plant_config = PlantConfig {
        noise_scale: 1.0,
        seed: args.seed,
        ..PlantConfig::default()
    };
    let trace = momentum_loop(problem, &best, &start, &plant_config)?;
    // The paper's rule on the same room, for comparison.
    let mut plant = Plant::new(problem.clone(), plant_config)?;
    let paper = closed_loop::run(
        problem,
        &mut plant,
        &start,
        &LoopConfig::new(StepRule::paper(), 60),
    )?;
    let to = |t: &closed_loop::Trace| {
        t.records
            .iter()
            .find(|r| best.excess(r.true_objective) <= 0.01)
            .map_or("never".into(), |r| r.capture.to_string())
    };
    println!(
        "captures to 1% excess: paper's fixed step {}, momentum with model rounds {}",
        to(&paper),
        to(&trace)
    );
    agents_over_grpc(problem, &best, args)?;
    println!("demo finished in {:.2} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The in-memory loop on the synthetic room, printed capture by capture: the camera sees the
/// room with its real noise (`plant_config`); the nodes follow momentum with 5 model rounds
/// between captures and stop when every node moves less than half a code step.
fn momentum_loop(
    problem: &roomlight_core::Problem,
    best: &roomlight_core::optimum::Optimum,
    start: &[LinearRgb],
    plant_config: &PlantConfig,
) -> Result<closed_loop::Trace> {
    let config = LoopConfig {
        model_rounds: 5,
        stop_when_settled: true,
        ..LoopConfig::new(StepRule::Momentum { theta: 1.0 }, 30)
    };
    let mut plant = Plant::new(problem.clone(), plant_config.clone())?;
    println!("capture  model rounds  true G      excess     mean ΔE00");
    let trace =
        closed_loop::run_observed(problem, &mut plant, start, &config, |r, shown, plant| {
            let de = patch_delta_e(problem.target(), &plant.true_response(shown, r.capture))
                .map_or(f64::NAN, |d| d.mean);
            println!(
                "{:>7}  {:>12}  {:>9.3e}  {:>9.2e}  {:>9.3}",
                r.capture,
                r.model_rounds,
                r.true_objective,
                best.excess(r.true_objective),
                de
            );
        })?;
    let last = trace.last().context("no capture")?;
    let de = patch_delta_e(
        problem.target(),
        &plant.true_response(&trace.shown, last.capture),
    )?;
    println!(
        "distributed result after {} captures ({:?}): excess {:.2e}, mean ΔE00 {:.2} (max {:.2}); optimum's mean ΔE00 {:.2}",
        last.capture,
        trace.stop,
        best.excess(last.true_objective),
        de.mean,
        de.max,
        patch_delta_e(problem.target(), &problem.response(&best.x))?.mean
    );
    Ok(trace)
}

/// The same room run by the real agents: a camera agent and one node agent per ten nodes, in
/// this process, talking gRPC over loopback; the virtual room stands in for displays and camera.
fn agents_over_grpc(
    problem: &roomlight_core::Problem,
    best: &roomlight_core::optimum::Optimum,
    args: &DemoOptions,
) -> Result<()> {
    use roomlight_agent::camera::{self, CameraConfig, RoomModel};
    use roomlight_agent::hardware::VirtualRoom;
    use roomlight_agent::node::{self, NodeConfig};
    use std::collections::HashMap;
    use std::time::Duration;
    use tokio_util::sync::CancellationToken;
    let per = 10;
    let agents = problem.nodes().div_ceil(per);
    let owners: HashMap<String, Vec<u32>> = (0..agents)
        .map(|a| {
            (
                format!("p{a}"),
                ((a * per) as u32..((a + 1) * per).min(problem.nodes()) as u32).collect(),
            )
        })
        .collect();
    let plant = Plant::new(
        problem.clone(),
        PlantConfig {
            noise_scale: 1.0,
            seed: args.seed,
            ..PlantConfig::default()
        },
    )?;
    let room = VirtualRoom::new(plant);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        let config = CameraConfig { room: "demo".into(), token: "demo".into(), heartbeat: Duration::from_millis(500), deadline: Duration::from_secs(2), model_rounds: 5, calibration_epoch: 1, stale_frames: 0, model_out: None, primaries: true, shading_passes: 0 };
        let (mut status, _handle) = camera::serve(config, RoomModel { problem: problem.clone(), owners: owners.clone(), start: None, hot: Default::default(), survey: None }, room.camera(), listener, cancel.clone());
        for id in owners.keys() {
            let config = NodeConfig { endpoint: endpoint.clone(), room: "demo".into(), token: "demo".into(), projector_id: id.clone(), kind: roomlight_proto::v1::ProjectorKind::Standard, rule: StepRule::Momentum { theta: 1.0 }, start: LinearRgb::splat(0.5), state_file: None };
            tokio::spawn(node::run(config, room.display(), cancel.child_token()));
        }
        println!("the real agents over loopback gRPC: a camera agent and {agents} node agents (model rounds K = 5, camera noise on)");
        let flat = vec![LinearRgb::splat(0.5); problem.nodes()];
        println!("  start (every node at 0.5): true excess {:.2e}", best.excess(problem.objective(&flat)));
        let started = Instant::now();
        let mut last = 0;
        let outcome = tokio::time::timeout(Duration::from_secs(60), async {
            while last < 6 {
                status.changed().await?;
                let s = status.borrow().clone();
                if s.captures > last && s.live_projectors == agents {
                    last = s.captures;
                    println!("  after capture {:>2} and its model rounds: {} node agents, true excess {:.2e}", s.captures, s.live_projectors, best.excess(room.true_objective()));
                }
            }
            Ok::<_, anyhow::Error>(())
        })
        .await;
        cancel.cancel();
        outcome.context("the agents did not converge within 60 s")??;
        println!("agents: final excess {:.2e} after {last} captures in {:.2} s", best.excess(room.true_objective()), started.elapsed().as_secs_f64());
        Ok(())
    })
}
