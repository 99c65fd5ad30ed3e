//! `DIR/results.md`, what `roomlight bench --out DIR` leaves behind: one section per bench it
//! ran, each with when it started (UTC), the commit, the machine (CPUs, model, load average at
//! its start) and the command, so that a figure quoted in the docs can be traced to a run.
//!
//! It owns the markdown and the metadata. It must not know how a bench measures: a section's
//! body is handed in already written (a table, or the bench's printed output).

use std::fmt::Write as _;
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

/// The machine a section ran on, read when the section started.
#[derive(Debug, Clone, PartialEq)]
pub struct Machine {
    /// `nproc`: the CPUs this process may use.
    pub cpus: usize,
    /// The first `model name` of `/proc/cpuinfo` ("unknown" where there is none).
    pub model: String,
    /// The first three fields of `/proc/loadavg` ("unknown" where there is none).
    pub load: String,
}

impl Machine {
    /// This machine now.
    pub fn probe() -> Self {
        let read = |path: &str| std::fs::read_to_string(path).unwrap_or_default();
        Self {
            cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
            model: cpu_model(&read("/proc/cpuinfo")).unwrap_or_else(|| "unknown".into()),
            load: load_average(&read("/proc/loadavg")).unwrap_or_else(|| "unknown".into()),
        }
    }
}

/// The `model name` line of a `/proc/cpuinfo` text.
fn cpu_model(cpuinfo: &str) -> Option<String> {
    cpuinfo.lines().find_map(|line| {
        let (key, value) = line.split_once(':')?;
        (key.trim() == "model name").then(|| value.trim().to_string())
    })
}

/// The 1, 5 and 15 minute load averages of a `/proc/loadavg` text.
fn load_average(loadavg: &str) -> Option<String> {
    let fields: Vec<&str> = loadavg.split_whitespace().take(3).collect();
    (fields.len() == 3).then(|| fields.join(" "))
}

/// When, on which commit and on what machine a section started.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamp {
    /// `YYYY-MM-DD HH:MM:SS UTC`.
    pub utc: String,
    /// `git rev-parse --short HEAD`, "unknown" outside a checkout or without git.
    pub commit: String,
    pub machine: Machine,
}

impl Stamp {
    /// Now, here.
    pub fn now() -> Self {
        let seconds = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        Self {
            utc: utc(seconds),
            commit: commit(),
            machine: Machine::probe(),
        }
    }
}

/// The short hash of the checkout's HEAD, "unknown" when git cannot tell.
fn commit() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .filter(|out| out.status.success())
        .and_then(|out| String::from_utf8(out.stdout).ok())
        .map(|hash| hash.trim().to_string())
        .filter(|hash| !hash.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

/// Seconds since the Unix epoch as `YYYY-MM-DD HH:MM:SS UTC` (proleptic Gregorian calendar;
/// days to a civil date as in Howard Hinnant's `civil_from_days`).
pub fn utc(seconds: u64) -> String {
    let days = seconds / 86_400;
    let rest = seconds % 86_400;
    // Shift the epoch to 0000-03-01 so that a leap day ends the (400-year) era's year.
    let z = days + 719_468;
    let era = z / 146_097;
    let day_of_era = z % 146_097;
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let month_index = (5 * day_of_year + 2) / 153;
    let day = day_of_year - (153 * month_index + 2) / 5 + 1;
    let month = if month_index < 10 {
        month_index + 3
    } else {
        month_index - 9
    };
    let year = year_of_era + era * 400 + u64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}

/// One bench as it ran.
#[derive(Debug, Clone)]
pub struct Section {
    /// `core`, `room`, `calib`, `net` or `sim`.
    pub bench: String,
    /// The command that ran it, as one would type it.
    pub command: String,
    pub stamp: Stamp,
    pub seconds: f64,
    /// Markdown: the bench's tables, or its printed output in a fenced block.
    pub body: String,
}

/// `text` in a fenced block whose fence no line of `text` can close.
pub fn fenced(text: &str) -> String {
    let mut fence = "```".to_string();
    while text.contains(fence.as_str()) {
        fence.push('`');
    }
    format!("{fence}text\n{}\n{fence}\n", text.trim_end())
}

/// The whole file: a header saying where it comes from, then every section in the order run.
pub fn markdown(command: &str, sections: &[Section]) -> String {
    let mut md = format!(
        "# roomlight bench results\n\nWritten by `{command}` (`roomlight bench --out DIR` writes \
         DIR/results.md); re-run the bench rather than editing the figures. Timings come from \
         the machine named in each section: compare them as ratios.\n"
    );
    for s in sections {
        let m = &s.stamp.machine;
        let _ = write!(
            md,
            "\n## {}\n\n- started: {} (ran {:.0} s)\n- commit: {}\n- machine: {} CPUs, {}, load \
             average {} at the start\n- command: `{}`\n\n{}",
            s.bench,
            s.stamp.utc,
            s.seconds,
            s.stamp.commit,
            m.cpus,
            m.model,
            m.load,
            s.command,
            s.body
        );
        if !md.ends_with('\n') {
            md.push('\n');
        }
    }
    md
}

/// Writes `dir/results.md`.
pub fn write(dir: &Path, command: &str, sections: &[Section]) -> anyhow::Result<()> {
    use anyhow::Context as _;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join("results.md");
    std::fs::write(&path, markdown(command, sections))
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section(bench: &str, body: &str) -> Section {
        Section {
            bench: bench.into(),
            command: format!("roomlight bench {bench} --quick"),
            stamp: Stamp {
                utc: "2026-11-25 07:19:52 UTC".into(),
                commit: "c73dcac".into(),
                machine: Machine {
                    cpus: 2,
                    model: "Test CPU @ 2.00GHz".into(),
                    load: "1.74 1.62 1.75".into(),
                },
            },
            seconds: 12.4,
            body: body.into(),
        }
    }

    #[test]
    fn every_section_carries_its_table_and_metadata() {
        let benches = ["core", "room", "net", "calib", "sim"];
        let sections: Vec<Section> = benches
            .iter()
            .map(|b| section(b, &format!("| {b} | table |\n")))
            .collect();
        let md = markdown("roomlight bench --quick --out /tmp/x", &sections);
        assert!(md.starts_with("# roomlight bench results\n"));
        assert!(md.contains("Written by `roomlight bench --quick --out /tmp/x`"));
        let mut from = 0;
        for b in benches {
            // In the order run, each with every piece of metadata before its table.
            let at = from + md[from..].find(&format!("\n## {b}\n")).expect(b);
            let next = md[at + 1..].find("\n## ").map_or(md.len(), |k| at + 1 + k);
            let part = &md[at..next];
            for wanted in [
                "- started: 2026-11-25 07:19:52 UTC (ran 12 s)",
                "- commit: c73dcac",
                "- machine: 2 CPUs, Test CPU @ 2.00GHz, load average 1.74 1.62 1.75 at the start",
                &format!("- command: `roomlight bench {b} --quick`"),
                &format!("| {b} | table |"),
            ] {
                assert!(part.contains(wanted), "{b}: {wanted:?} missing in {part}");
            }
            from = next;
        }
    }

    #[test]
    fn utc_dates_match_the_calendar() {
        assert_eq!(utc(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc(951_782_400), "2000-02-29 00:00:00 UTC");
        assert_eq!(utc(1_795_591_192), "2026-11-25 07:19:52 UTC");
        assert_eq!(utc(4_107_542_399), "2100-02-28 23:59:59 UTC");
    }

    #[test]
    fn machine_fields_come_from_proc_texts() {
        let cpuinfo = "processor\t: 0\nvendor_id\t: X\nmodel name\t: Test CPU @ 2.00GHz\n\
                       processor\t: 1\nmodel name\t: Test CPU @ 2.00GHz\n";
        assert_eq!(cpu_model(cpuinfo).as_deref(), Some("Test CPU @ 2.00GHz"));
        assert_eq!(cpu_model("processor : 0\n"), None);
        assert_eq!(
            load_average("1.74 1.62 1.75 2/345 6789\n").as_deref(),
            Some("1.74 1.62 1.75")
        );
        assert_eq!(load_average(""), None);
        let here = Machine::probe();
        assert!(here.cpus >= 1 && !here.model.is_empty() && !here.load.is_empty());
    }

    #[test]
    fn printed_output_is_fenced_so_it_cannot_close_its_block() {
        assert_eq!(fenced("a\nb\n\n"), "```text\na\nb\n```\n");
        let tricky = fenced("x ``` y");
        assert!(tricky.starts_with("````text\n") && tricky.ends_with("\n````\n"));
    }
}
