//! The room's LED lighting as a survey switches it: a rendered room's through its service, or a
//! physical room's by asking a person. To measure the room's black level and its target, a
//! survey photographs the charts with the LEDs off and then on; in a physical room nothing can
//! switch them but the installer (or whatever the installer wires to this: a relay, a DMX
//! script, the console).
//!
//! The manual handshake is two files in one folder: the camera agent writes `DIR/lights-wanted`
//! (`on` or `off`) and says in its log what to do; it goes on once `DIR/lights` says the same
//! and was written after the request (`echo off > DIR/lights`). It waits as long as it takes,
//! repeating the request every 30 s, and stops waiting when the agent is stopped.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// How the survey switches the LEDs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LightsSpec {
    /// A rendered room (`roomlight sim`) at this endpoint switches its own.
    Rendered(String),
    /// A person switches them, told through files in this folder.
    Manual(PathBuf),
}

impl LightsSpec {
    /// `manual:DIR`, or a rendered room's endpoint.
    pub fn parse(text: &str) -> Self {
        match text.strip_prefix("manual:") {
            Some(dir) => Self::Manual(PathBuf::from(dir)),
            None => Self::Rendered(text.to_string()),
        }
    }
}

/// The longest `DIR/lights` read (it holds one word).
const MAX_ANSWER: u64 = 64;

/// The manual switch: see the module's doc.
#[derive(Debug, Clone)]
pub struct ManualLights {
    dir: PathBuf,
    /// How often the answer is looked for.
    poll: Duration,
    /// How often the request is repeated in the log.
    remind: Duration,
}

impl ManualLights {
    /// The handshake in `dir` (which must exist and be writable).
    pub fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            poll: Duration::from_millis(200),
            remind: Duration::from_secs(30),
        }
    }

    /// Asks for the LEDs `on` (showing `what`, the preset) or off, and waits until the answer
    /// says so.
    pub async fn switch(&self, on: bool, what: &str) -> Result<()> {
        let word = if on { "on" } else { "off" };
        let wanted = self.dir.join("lights-wanted");
        let answer = self.dir.join("lights");
        let tmp = self.dir.join(".lights-wanted.tmp");
        std::fs::write(&tmp, format!("{word}\n"))
            .and_then(|()| std::fs::rename(&tmp, &wanted))
            .with_context(|| format!("writing {}", wanted.display()))?;
        // An answer counts only if written after the request (a stale `on` from the last
        // survey must not pass). File times have coarse resolution on some file systems: a
        // second of slack.
        let asked = SystemTime::now() - Duration::from_secs(1);
        let say = || {
            let what = if on {
                format!("ON as for {what}")
            } else {
                "OFF (and every other light the projectors will replace)".to_string()
            };
            tracing::warn!(
                "survey: switch the room's LED lighting {what}, then `echo {word} > {}`",
                answer.display()
            );
        };
        say();
        let mut last_said = tokio::time::Instant::now();
        loop {
            if answered(&answer, word, asked) {
                tracing::info!("survey: the LED lighting is {word}");
                return Ok(());
            }
            if last_said.elapsed() >= self.remind {
                say();
                last_said = tokio::time::Instant::now();
            }
            tokio::time::sleep(self.poll).await;
        }
    }
}

/// Whether `path` was written after `asked` and says `word` (read bounded; an unreadable or
/// oversized answer is no answer).
fn answered(path: &Path, word: &str, asked: SystemTime) -> bool {
    let Ok(meta) = std::fs::metadata(path) else {
        return false;
    };
    if meta.len() > MAX_ANSWER || meta.modified().map_or(true, |t| t < asked) {
        return false;
    }
    std::fs::read_to_string(path).is_ok_and(|text| text.trim().eq_ignore_ascii_case(word))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_survey_goes_on_only_once_a_person_answers_after_the_request() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut lights = ManualLights::new(dir.path());
        lights.poll = Duration::from_millis(10);
        // A stale answer from an earlier survey, two seconds older than the request.
        let answer = dir.path().join("lights");
        std::fs::write(&answer, "on\n").expect("write");
        let old = SystemTime::now() - Duration::from_secs(5);
        std::fs::File::options()
            .write(true)
            .open(&answer)
            .and_then(|f| f.set_modified(old))
            .expect("age the answer");
        let mut waiting = tokio::spawn({
            let lights = lights.clone();
            async move { lights.switch(true, "neutral").await }
        });
        // The request is there; the stale answer does not count.
        let wanted = dir.path().join("lights-wanted");
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        while std::fs::read_to_string(&wanted).map_or(true, |w| w.trim() != "on") {
            assert!(tokio::time::Instant::now() < deadline, "no request written");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let within = Duration::from_millis(100);
        let still_waiting = tokio::time::timeout(within, &mut waiting).await.is_err();
        assert!(still_waiting, "went on with a stale answer");
        // The wrong word neither.
        std::fs::write(&answer, "off\n").expect("write");
        let still_waiting = tokio::time::timeout(within, &mut waiting).await.is_err();
        assert!(still_waiting, "went on with the wrong answer");
        std::fs::write(&answer, "ON\n").expect("write");
        tokio::time::timeout(Duration::from_secs(10), waiting)
            .await
            .expect("goes on once answered")
            .expect("task")
            .expect("switched");
    }

    #[test]
    fn a_spec_is_manual_or_a_rendered_rooms_endpoint() {
        assert_eq!(
            LightsSpec::parse("manual:/var/lib/roomlight"),
            LightsSpec::Manual("/var/lib/roomlight".into())
        );
        assert_eq!(
            LightsSpec::parse("http://127.0.0.1:50050"),
            LightsSpec::Rendered("http://127.0.0.1:50050".into())
        );
    }
}
