//! What the camera agent prints about its rounds on stdout. A room runs a hundred rounds a
//! second or more, so by default the rounds are summarised, at most one line a second, with a
//! line at once when the projectors live or calibrated change (issue 22: a human's log, or the
//! journal, is not flooded). Tools that follow every round ask for one machine-readable line
//! per round instead (`roomlight camera --status-lines`).

use std::time::{Duration, Instant};

/// How the camera agent reports its rounds on stdout.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum StatusLines {
    /// At most one summary line a second, and a line at once when the projectors live or
    /// calibrated change:
    /// `rounds 1200–1365 (165/s), captures 40, objective 3.1e-4 (−2%), 5 live` and
    /// `round 1366: 4 live (was 5)`.
    #[default]
    Summary,
    /// One line per round, `round R captures C objective G live L calibrated H averaged K`
    /// (G to seven digits; K the captures its errors average, so a tool can take their noise,
    /// `½ Σ σ²/K`, out of G), for tools that follow the rounds.
    EveryRound,
}

/// The figures of one round the lines are made of: those of its status line, and whether G
/// has settled at its noise (the summary says so).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Round {
    pub line: StatusLine,
    pub settled: bool,
}

/// The shortest time between two summary lines.
pub const SUMMARY_EVERY: Duration = Duration::from_secs(1);

/// Turns the rounds, as they come, into the lines to print. Time is passed in.
#[derive(Debug)]
pub struct StatusPrinter {
    mode: StatusLines,
    /// The round last seen.
    last: Option<Round>,
    /// The first round not yet summarised and when it was seen.
    pending: Option<(Round, Instant)>,
    /// When the last summary was printed, and the objective it showed.
    printed: Option<(Instant, f64)>,
}

impl StatusPrinter {
    pub fn new(mode: StatusLines) -> Self {
        Self {
            mode,
            last: None,
            pending: None,
            printed: None,
        }
    }

    /// The lines to print now that `round` is the room's status: its own line, or an event's
    /// and the summary when one is due.
    pub fn round(&mut self, round: Round, now: Instant) -> Vec<String> {
        let before = self.last.replace(round);
        if self.mode == StatusLines::EveryRound {
            return vec![round.line.to_string()];
        }
        let mut lines = Vec::new();
        if let Some(b) = before {
            if b.line.live != round.line.live {
                lines.push(format!(
                    "round {}: {} live (was {})",
                    round.line.round, round.line.live, b.line.live
                ));
            }
            if b.line.calibrated != round.line.calibrated {
                lines.push(format!(
                    "round {}: {} calibrated over the wire or hot (was {})",
                    round.line.round, round.line.calibrated, b.line.calibrated
                ));
            }
        }
        self.pending.get_or_insert((round, now));
        if self.due().is_some_and(|due| due <= now)
            && let Some(line) = self.flush(now)
        {
            lines.push(line);
        }
        lines
    }

    /// When the rounds not yet summarised are to be printed, if there are any: at once for the
    /// first, then a second after the last summary.
    pub fn due(&self) -> Option<Instant> {
        let (_, seen) = self.pending?;
        Some(self.printed.map_or(seen, |(t, _)| t + SUMMARY_EVERY))
    }

    /// The summary of the rounds not yet summarised, if any, printed at `now`.
    pub fn flush(&mut self, now: Instant) -> Option<String> {
        let (first, seen) = self.pending.take()?;
        let last = self.last?;
        let rounds = last.line.round.saturating_sub(first.line.round) + 1;
        let span = now.saturating_duration_since(self.printed.map_or(seen, |(t, _)| t));
        let mut line = if rounds == 1 {
            format!("round {}", last.line.round)
        } else if span.is_zero() {
            format!("rounds {}–{}", first.line.round, last.line.round)
        } else {
            format!(
                "rounds {}–{} ({:.0}/s)",
                first.line.round,
                last.line.round,
                rounds as f64 / span.as_secs_f64()
            )
        };
        line.push_str(&format!(
            ", captures {}, objective {:.2e}",
            last.line.captures, last.line.objective
        ));
        // The change since the last summary; none from or to zero or a non-finite G.
        if let Some((_, g)) = self.printed
            && g > 0.0
            && g.is_finite()
            && last.line.objective.is_finite()
        {
            line.push_str(&format!(
                " ({:+.0}%)",
                100.0 * (last.line.objective / g - 1.0)
            ));
        }
        line.push_str(&format!(", {} live", last.line.live));
        if last.settled {
            line.push_str(", settled");
        }
        self.printed = Some((now, last.line.objective));
        Some(line)
    }
}

/// The camera agent's status line, `round R captures C objective G live L calibrated H
/// averaged K`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StatusLine {
    pub round: u64,
    pub captures: u64,
    pub objective: f64,
    pub live: usize,
    /// Projectors calibrated over the wire or hot.
    pub calibrated: u64,
    /// How many captures the errors of `objective` average.
    pub averaged: usize,
}

/// The line as the camera agent prints it (G to seven digits); [`StatusLine::parse`] reads it.
impl std::fmt::Display for StatusLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "round {} captures {} objective {:.6e} live {} calibrated {} averaged {}",
            self.round, self.captures, self.objective, self.live, self.calibrated, self.averaged
        )
    }
}

impl StatusLine {
    /// The figures of a status line, or `None` for any other line.
    pub fn parse(line: &str) -> Option<Self> {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            [
                "round",
                r,
                "captures",
                c,
                "objective",
                g,
                "live",
                l,
                "calibrated",
                h,
                "averaged",
                k,
            ] => Some(Self {
                round: r.parse().ok()?,
                captures: c.parse().ok()?,
                objective: g.parse().ok()?,
                live: l.parse().ok()?,
                calibrated: h.parse().ok()?,
                averaged: k.parse().ok()?,
            }),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_line_is_read_and_anything_else_is_not() {
        let s = StatusLine::parse(
            "round 42 captures 7 objective 1.250000e-2 live 3 calibrated 0 averaged 4",
        );
        assert_eq!(
            s,
            Some(StatusLine {
                round: 42,
                captures: 7,
                objective: 0.0125,
                live: 3,
                calibrated: 0,
                averaged: 4,
            })
        );
        assert_eq!(StatusLine::parse("camera listening on 127.0.0.1:5"), None);
        // What the printer writes is what the parser reads (G to seven digits).
        let r = at(10, 3).line;
        let read = StatusLine::parse(&r.to_string()).expect("a status line");
        assert_eq!(
            StatusLine {
                objective: r.objective,
                ..read
            },
            r
        );
        assert!((read.objective - r.objective).abs() <= 1e-6 * r.objective);
    }

    fn at(round: u64, live: usize) -> Round {
        Round {
            line: StatusLine {
                round,
                captures: round / 4,
                objective: 1.0 / (round as f64 + 1.0),
                live,
                calibrated: 0,
                averaged: 1,
            },
            settled: false,
        }
    }

    /// 165 rounds a second for ten seconds, a projector leaving at round 800.
    fn run(mode: StatusLines) -> (Vec<String>, StatusPrinter, Instant) {
        let t0 = Instant::now();
        let mut printer = StatusPrinter::new(mode);
        let mut lines = Vec::new();
        let mut now = t0;
        for r in 1..=1650 {
            now = t0 + Duration::from_secs_f64(r as f64 / 165.0);
            lines.extend(printer.round(at(r, if r < 800 { 3 } else { 2 }), now));
        }
        (lines, printer, now)
    }

    #[test]
    fn every_round_is_one_line_a_parser_reads() {
        let (lines, ..) = run(StatusLines::EveryRound);
        assert_eq!(lines.len(), 1650);
        assert_eq!(
            lines[9],
            "round 10 captures 2 objective 9.090909e-2 live 3 calibrated 0 averaged 1"
        );
    }

    #[test]
    fn rounds_are_summarised_once_a_second_and_events_said_at_once() {
        let (lines, mut printer, now) = run(StatusLines::Summary);
        let summaries: Vec<&String> = lines.iter().filter(|l| l.starts_with("round")).collect();
        let events: Vec<&String> = lines.iter().filter(|l| l.contains(": ")).collect();
        assert_eq!(events, ["round 800: 2 live (was 3)"], "{lines:#?}");
        // The first round at once, then one a second over ten seconds.
        assert!(
            (10..=12).contains(&(summaries.len() - events.len())),
            "{lines:#?}"
        );
        assert!(
            lines[0].starts_with("round 1, captures 0, objective 5.00e-1, 3 live"),
            "{lines:#?}"
        );
        assert!(
            lines[1].starts_with("rounds 2–16") && lines[1].contains("/s), captures 4"),
            "{lines:#?}"
        );
        assert!(lines[1].ends_with("(-99%), 3 live"), "{lines:#?}");
        // The rounds since the last summary wait for the next one, or for a flush.
        let due = printer.due().expect("rounds pending");
        assert!(due > now && due <= now + SUMMARY_EVERY);
        let last = printer.flush(due).expect("a summary");
        assert!(last.contains("–1650"), "{last}");
        assert_eq!(printer.due(), None);
        assert_eq!(printer.flush(due), None);
    }

    #[test]
    fn a_settled_room_says_so_and_a_zero_objective_has_no_change() {
        let t0 = Instant::now();
        let mut printer = StatusPrinter::new(StatusLines::Summary);
        let mut r = at(1, 1);
        r.line.objective = 0.0;
        assert_eq!(
            printer.round(r, t0),
            ["round 1, captures 0, objective 0.00e0, 1 live"]
        );
        r.line.round = 2;
        r.settled = true;
        r.line.calibrated = 1;
        let lines = printer.round(r, t0 + SUMMARY_EVERY);
        assert_eq!(
            lines,
            [
                "round 2: 1 calibrated over the wire or hot (was 0)",
                "round 2, captures 0, objective 0.00e0, 1 live, settled"
            ]
        );
    }
}
