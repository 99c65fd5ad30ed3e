//! What the room bench records of its runs: one [`Record`] per case and rule (medians over
//! the repeats, with ranges), the median curves, the wall-clock model of time to 1%, and the
//! printed table with its note.

use super::floor::Floor;
use comfy_table::{Table, presets::UTF8_FULL_CONDENSED};
use serde::Serialize;

/// One record of the table and of `--json`: medians over the repeats.
#[derive(Debug, Clone, Serialize)]
pub struct Record {
    pub case: String,
    pub rule: String,
    pub captures_to_1pct: Option<u64>,
    pub captures_to_0_1pct: Option<u64>,
    pub final_excess: f64,
    /// Captures to 1% excess of the room as it is (the simulator's noiseless camera on the same
    /// patches) over the best the room can show (the optimum of the true transport), beside the
    /// measured model's figure: the rounds correct the model with every capture, so they
    /// converge towards the room's optimum, not exactly to the model's.
    pub captures_to_1pct_true: Option<u64>,
    /// The same excess at the end.
    pub final_true_excess: f64,
    /// Per colour channel (R, G, B): `(G_c − G*_c)/G*_c`, each channel's objective over its
    /// own optimum, at the end (medians).
    pub final_excess_rgb: [f64; 3],
    pub mean_de00: f64,
    pub max_de00: f64,
    pub compute_us_per_round: f64,
    pub message_ms_per_round: f64,
    pub capture_ms: f64,
    pub bytes_per_round: f64,
    /// True when any repeat diverged (a non-finite value, or ending above where it started).
    pub diverged: bool,
    pub captures: u64,
    pub repeats: usize,
    /// The smallest and largest value over the repeats.
    pub spread: Spread,
    /// The case's noise floor (see [`Floor`]); `None` where it is not computed.
    pub floor: Option<Floor>,
    /// When the floor is above 1%: captures to the floor's level instead (see
    /// [`Floor::level`]).
    pub captures_to_floor: Option<u64>,
    /// Captures of the room's calibration, counted in the wall-clock times.
    pub calibration_captures: usize,
    /// Wall-clock seconds to 1% excess, calibration included, with a video camera at 30 frames
    /// a second (see [`TIME_NOTE`]); `None`: never reached.
    pub seconds_to_1pct_video: Option<f64>,
    /// The same with a DSLR at 9 s per shot.
    pub seconds_to_1pct_dslr: Option<f64>,
}

/// `[min, max]` over the repeats (`None`: never reached).
#[derive(Debug, Clone, Serialize)]
pub struct Spread {
    pub captures_to_1pct: [Option<u64>; 2],
    pub final_excess: [f64; 2],
    pub mean_de00: [f64; 2],
    pub max_de00: [f64; 2],
    pub message_ms_per_round: [f64; 2],
}

/// One point of a run: after `capture` captures' rounds.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Point {
    pub capture: u64,
    pub seconds: f64,
    pub excess: f64,
    /// The room's excess over its true optimum (see [`Record::captures_to_1pct_true`]).
    pub true_excess: f64,
    pub mean_de00: f64,
    /// Wall time of the rounds up to here (the agents' computation and messages, without the
    /// camera's).
    pub rounds_seconds: f64,
}

/// A rule's name and its median curve.
pub type Curve = (String, Vec<Point>);

/// One run of one case and rule.
#[derive(Debug, Clone)]
pub(super) struct Run {
    pub(super) trace: Vec<Point>,
    /// After a leave and a join: the captures taken when the room was whole again (the joining
    /// projector in the rounds: its join, or for a hot join the end of its calibration).
    /// Captures to a level are then the captures after it; otherwise from the start.
    pub(super) joined_after: Option<u64>,
    pub(super) final_excess: f64,
    pub(super) final_true_excess: f64,
    pub(super) final_excess_rgb: [f64; 3],
    pub(super) mean_de00: f64,
    pub(super) max_de00: f64,
    pub(super) compute_us_per_round: f64,
    pub(super) message_ms_per_round: f64,
    pub(super) capture_ms: f64,
    pub(super) bytes_per_round: f64,
    pub(super) captures: u64,
}

impl Run {
    /// The points that count: all, or after a join those after the room was whole again.
    fn counted(&self) -> impl Iterator<Item = &Point> {
        let after = self.joined_after;
        self.trace
            .iter()
            .filter(move |p| after.is_none_or(|j| p.capture > j))
    }

    /// Captures to `point`: from the start, or after the room was whole again.
    fn captures_to(&self, point: &Point) -> u64 {
        point.capture - self.joined_after.unwrap_or(0)
    }

    fn first_below(&self, level: f64) -> Option<u64> {
        self.point_below(level).map(|p| self.captures_to(p))
    }

    fn first_true_below(&self, level: f64) -> Option<u64> {
        self.counted()
            .find(|p| p.true_excess <= level)
            .map(|p| self.captures_to(p))
    }

    fn point_below(&self, level: f64) -> Option<&Point> {
        self.counted().find(|p| p.excess <= level)
    }

    /// A non-finite value anywhere, an end above the start, or an end far above the best the
    /// run had reached (an oscillation that grew): ten times it and over 10% excess, so that
    /// noise around a small excess does not count.
    fn diverged(&self) -> bool {
        let start = self.trace.first().map_or(f64::INFINITY, |p| p.excess);
        let best = self
            .counted()
            .map(|p| p.excess)
            .fold(f64::INFINITY, f64::min);
        !self.final_excess.is_finite()
            || self
                .trace
                .iter()
                .any(|p| !p.excess.is_finite() || !p.mean_de00.is_finite())
            || self.final_excess > start
            || (self.final_excess > 0.1 && self.final_excess > 10.0 * best)
    }

    /// Wall-clock seconds to 1% with `shot` seconds per capture (see [`TIME_NOTE`]).
    fn seconds_to_1pct(&self, calibration: &Calibration, shot: f64) -> Option<f64> {
        let p = self.point_below(1e-2)?;
        Some(
            (calibration.captures + p.capture as usize) as f64 * shot
                + calibration.compute_seconds
                + p.rounds_seconds,
        )
    }
}

/// The calibration a case's times include: its captures and the computation between them.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Calibration {
    pub(super) captures: usize,
    pub(super) compute_seconds: f64,
}

/// Seconds per shot of a video camera at 30 frames a second.
pub const VIDEO_SHOT: f64 = 1.0 / 30.0;
/// Seconds per shot of the paper's DSLR.
pub const DSLR_SHOT: f64 = 9.0;

pub(super) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn range(v: &[f64]) -> [f64; 2] {
    [
        v.iter().copied().fold(f64::INFINITY, f64::min),
        v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    ]
}

/// Median, min and max of "captures to a level" where never (`None`) counts as infinite.
fn captures_stats(v: &[Option<u64>]) -> (Option<u64>, [Option<u64>; 2]) {
    let mut sorted: Vec<Option<u64>> = v.to_vec();
    sorted.sort_by_key(|c| c.unwrap_or(u64::MAX));
    let pick = |k: usize| sorted.get(k).copied().flatten();
    (
        pick(sorted.len() / 2),
        [pick(0), pick(sorted.len().saturating_sub(1))],
    )
}

/// The median of optional seconds, never (`None`) counting as infinite.
fn median_time(v: &[Option<f64>]) -> Option<f64> {
    let mut sorted: Vec<Option<f64>> = v.to_vec();
    sorted.sort_by(|a, b| {
        a.unwrap_or(f64::INFINITY)
            .total_cmp(&b.unwrap_or(f64::INFINITY))
    });
    sorted.get(sorted.len() / 2).copied().flatten()
}

/// The record of the repeats of one case and rule, and the median curve.
pub(super) fn summarise(
    (case, rule): (&str, &str),
    runs: &[Run],
    calibration: Calibration,
    floor: Option<Floor>,
) -> (Record, Vec<Point>) {
    let values = |f: fn(&Run) -> f64| runs.iter().map(f).collect::<Vec<f64>>();
    let (to_1, to_1_range) =
        captures_stats(&runs.iter().map(|r| r.first_below(1e-2)).collect::<Vec<_>>());
    let (to_1_true, _) = captures_stats(
        &runs
            .iter()
            .map(|r| r.first_true_below(1e-2))
            .collect::<Vec<_>>(),
    );
    let (to_01, _) = captures_stats(&runs.iter().map(|r| r.first_below(1e-3)).collect::<Vec<_>>());
    let captures_to_floor = floor.filter(Floor::above_goal).and_then(|f| {
        captures_stats(
            &runs
                .iter()
                .map(|r| r.first_below(f.level))
                .collect::<Vec<_>>(),
        )
        .0
    });
    let times = |shot: f64| {
        median_time(
            &runs
                .iter()
                .map(|r| r.seconds_to_1pct(&calibration, shot))
                .collect::<Vec<_>>(),
        )
    };
    let spread = Spread {
        captures_to_1pct: to_1_range,
        final_excess: range(&values(|r| r.final_excess)),
        mean_de00: range(&values(|r| r.mean_de00)),
        max_de00: range(&values(|r| r.max_de00)),
        message_ms_per_round: range(&values(|r| r.message_ms_per_round)),
    };
    let record = Record {
        case: case.into(),
        rule: rule.into(),
        captures_to_1pct: to_1,
        captures_to_0_1pct: to_01,
        final_excess: median(&mut values(|r| r.final_excess)),
        captures_to_1pct_true: to_1_true,
        final_true_excess: median(&mut values(|r| r.final_true_excess)),
        final_excess_rgb: std::array::from_fn(|c| {
            median(
                &mut runs
                    .iter()
                    .map(|r| r.final_excess_rgb[c])
                    .collect::<Vec<_>>(),
            )
        }),
        mean_de00: median(&mut values(|r| r.mean_de00)),
        max_de00: median(&mut values(|r| r.max_de00)),
        compute_us_per_round: median(&mut values(|r| r.compute_us_per_round)),
        message_ms_per_round: median(&mut values(|r| r.message_ms_per_round)),
        capture_ms: median(&mut values(|r| r.capture_ms)),
        bytes_per_round: median(&mut values(|r| r.bytes_per_round)),
        diverged: runs.iter().any(Run::diverged),
        captures: runs.iter().map(|r| r.captures).max().unwrap_or(0),
        repeats: runs.len(),
        spread,
        floor,
        captures_to_floor,
        calibration_captures: calibration.captures,
        seconds_to_1pct_video: times(VIDEO_SHOT),
        seconds_to_1pct_dslr: times(DSLR_SHOT),
    };
    // The median curve: capture by capture over the runs that got that far.
    let longest = runs.iter().map(|r| r.trace.len()).max().unwrap_or(0);
    let curve = (0..longest)
        .map(|k| {
            let at: Vec<&Point> = runs.iter().filter_map(|r| r.trace.get(k)).collect();
            let med =
                |f: fn(&Point) -> f64| median(&mut at.iter().map(|p| f(p)).collect::<Vec<_>>());
            Point {
                capture: k as u64,
                seconds: med(|p| p.seconds),
                excess: med(|p| p.excess),
                true_excess: med(|p| p.true_excess),
                mean_de00: med(|p| p.mean_de00),
                rounds_seconds: med(|p| p.rounds_seconds),
            }
        })
        .collect();
    (record, curve)
}

/// What the table of records shows, printed above it.
pub const CAPTION: &str = "medians over the repeats (range in brackets; repeats differ by their camera noise seed, and at one seed every figure but the timings is the same on every run); captures to 1% / 0.1% excess over the model's G*, from the conventional start (capture 0), through the agents on loopback; after a leave and a join they count the captures after the join (after a hot join, those after its calibration: the room whole again). \"true\": the same for the room as it is (the simulator's noiseless camera on the same patches) over the room's own optimum (the true transport's); the rounds correct the model with every capture, so they head for the room's optimum, which differs from the model's where the model is off (reflections cut off, noise)";

/// How the wall-clock columns are computed, printed under the table.
pub const TIME_NOTE: &str = "time to 1% (video: 30 fps, DSLR: 9 s per shot) = (calibration captures + captures to 1%) x seconds per shot + the calibration's computation (its wall time in the simulator less its captures at the simulated camera's mean capture time) + the rounds' measured wall time up to that capture (agents' computation and loopback messages, without the simulated camera); the synthetic room has no calibration (its transport is written down).";

/// How the floor column is computed, printed under the table.
pub const FLOOR_NOTE: &str = "floor: the excess over G* of where the rounds stop on one capture's noise: the fixed point of the safe step with the model's columns on the errors the camera measures in the room itself (its true transport; the model's target less one capture's camera noise, noisy minus noiseless sampling of the same frame), median over the last 5 captures of the case's first run (the exact optimum of the noisy model alone, which takes the model for the room, is noise_only in --json); † marks a floor above 1%, where 1% cannot be reached and the captures in brackets are those to the largest of the 5 floors. worst ch.: the largest of the three channels' final excess, each over its own optimum (R, G and B in --json).";

/// The records as a table (a terminal's preset; the caller may load another).
pub fn table(records: &[Record]) -> Table {
    let mut table = Table::new();
    super::super::width::fit(&mut table);
    table.load_preset(UTF8_FULL_CONDENSED).set_header([
        "case",
        "rule",
        "to 1%",
        "to 0.1%",
        "final excess (range)",
        "to 1% true",
        "final true",
        "worst ch.",
        "floor",
        "1% video s",
        "1% DSLR min",
        "mean ΔE00 (range)",
        "max ΔE00",
        "compute µs/round",
        "message ms/round",
        "capture ms",
        "bytes/round",
        "diverged",
    ]);
    for r in records {
        table.add_row([
            r.case.clone(),
            r.rule.clone(),
            captures_cell(r.captures_to_1pct, r.spread.captures_to_1pct, r.captures),
            captures_cell(r.captures_to_0_1pct, [None, None], r.captures),
            format!(
                "{:.1e} ({:.1e}…{:.1e})",
                r.final_excess, r.spread.final_excess[0], r.spread.final_excess[1]
            ),
            captures_cell(r.captures_to_1pct_true, [None, None], r.captures),
            format!("{:.1e}", r.final_true_excess),
            worst_channel(r.final_excess_rgb),
            floor_cell(r),
            r.seconds_to_1pct_video
                .map_or("never".into(), |s| format!("{s:.1}")),
            r.seconds_to_1pct_dslr
                .map_or("never".into(), |s| format!("{:.1}", s / 60.0)),
            format!(
                "{:.2} ({:.2}…{:.2})",
                r.mean_de00, r.spread.mean_de00[0], r.spread.mean_de00[1]
            ),
            format!("{:.2}", r.max_de00),
            format!("{:.1}", r.compute_us_per_round),
            format!("{:.2}", r.message_ms_per_round),
            format!("{:.0}", r.capture_ms),
            format!("{:.0}", r.bytes_per_round),
            r.diverged.to_string(),
        ]);
    }
    table
}

/// "8.1e-3 B": the channel with the largest final excess.
fn worst_channel(rgb: [f64; 3]) -> String {
    let (c, v) = rgb
        .iter()
        .enumerate()
        .fold((0, f64::NEG_INFINITY), |(bc, bv), (c, &v)| {
            if v > bv { (c, v) } else { (bc, bv) }
        });
    format!("{v:.1e} {}", ["R", "G", "B"][c])
}

/// "4.2e-4", or "2.1e-2† (3)" for a floor above 1% with the captures to it; empty when none.
fn floor_cell(r: &Record) -> String {
    match r.floor {
        None => String::new(),
        Some(f) if f.above_goal() => format!(
            "{:.1e}† ({})",
            f.median,
            r.captures_to_floor
                .map_or(format!("> {}", r.captures), |c| c.to_string())
        ),
        Some(f) => format!("{:.1e}", f.median),
    }
}

/// "3" or "3 (2…5)" or "> 30".
pub fn captures_cell(median: Option<u64>, range: [Option<u64>; 2], budget: u64) -> String {
    let one = |c: Option<u64>| c.map_or(format!("> {budget}"), |c| c.to_string());
    if range[0] == range[1] || range == [None, None] {
        one(median)
    } else {
        format!("{} ({}…{})", one(median), one(range[0]), one(range[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run whose model excess falls below 1% at capture 2 and the room's own at capture 4.
    fn run(joined_after: Option<u64>) -> Run {
        let model = [0.5, 0.05, 0.005, 0.004, 0.003, 0.002];
        let truth = [0.6, 0.2, 0.05, 0.02, 0.008, 0.006];
        Run {
            trace: (0..6)
                .map(|k| Point {
                    capture: k as u64,
                    seconds: k as f64,
                    excess: model[k],
                    true_excess: truth[k],
                    mean_de00: 2.0,
                    rounds_seconds: 0.0,
                })
                .collect(),
            joined_after,
            final_excess: model[5],
            final_true_excess: truth[5],
            final_excess_rgb: [model[5]; 3],
            mean_de00: 2.0,
            max_de00: 4.0,
            compute_us_per_round: 1.0,
            message_ms_per_round: 1.0,
            capture_ms: 1.0,
            bytes_per_round: 1.0,
            captures: 5,
        }
    }

    #[test]
    fn the_true_columns_come_from_the_rooms_own_excess() {
        let (r, curve) = summarise(("c", "r"), &[run(None)], Calibration::default(), None);
        assert_eq!(r.captures_to_1pct, Some(2));
        assert_eq!(r.captures_to_1pct_true, Some(4));
        assert_eq!(r.final_true_excess.to_bits(), 0.006_f64.to_bits());
        assert_eq!(curve[3].true_excess.to_bits(), 0.02_f64.to_bits());
        // After a join, both count the captures after it (the model's capture 2 is before).
        let (r, _) = summarise(("c", "r"), &[run(Some(2))], Calibration::default(), None);
        assert_eq!(
            (r.captures_to_1pct, r.captures_to_1pct_true),
            (Some(1), Some(2))
        );
    }
}
