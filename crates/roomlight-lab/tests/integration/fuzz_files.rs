//! Fuzzing the files an installer or a camera agent hands roomlight (the survey and the room
//! model) with bolero, through the one parser each goes through (`SurveyFile::parse`,
//! `ModelFile::parse`). Inputs are valid files changed two ways: JSON values replaced by
//! extremes (huge, negative, fractional, NaN-like strings, empty arrays, null) at generated
//! places, and raw byte edits and cuts of the text. Every outcome is a file that passed its
//! checks (and then holds what they promise) or an error naming the file; never a panic and
//! never an allocation sized by the file before it was checked.
//!
//! Under `cargo test` each target runs for a second of random inputs (`BOLERO_RANDOM_TEST_TIME_MS`
//! or `BOLERO_RANDOM_ITERATIONS` for longer; a failure prints its `BOLERO_RANDOM_SEED`);
//! `cargo bolero test` drives the same targets with libFuzzer (docs/operations.md, Security).

use roomlight_calib::charts::{ChartCorners, SampleConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_lab::process::{ModelFile, SurveyFile};
use serde_json::Value;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

fn survey() -> Value {
    let chart = |name: &str, x: f64| ChartCorners {
        name: name.into(),
        corners: [[x, 10.0], [x + 30.0, 10.0], [x + 30.0, 30.0], [x, 30.0]],
    };
    serde_json::to_value(SurveyFile {
        camera_width: 160,
        camera_height: 120,
        corners: vec![chart("desk", 10.0), chart("wall", 80.0)],
        sample: SampleConfig::default(),
        target_pixels: vec![3, 4, 5, 163, 164, 165],
        target_polygons: Vec::new(),
        preset: None,
    })
    .expect("a survey as JSON")
}

fn model() -> Value {
    let problem = synthetic_room(&SyntheticConfig::new(2, 2))
        .expect("room")
        .problem;
    let nodes = problem.nodes() as u32;
    serde_json::to_value(ModelFile {
        owners: [
            ("p0".to_string(), (0..nodes / 2).collect()),
            ("p1".into(), (nodes / 2..nodes).collect()),
        ]
        .into_iter()
        .collect(),
        start: None,
        patches: Some((0..problem.patches()).collect()),
        dark_target_weight: Some(1.0),
        problem,
    })
    .expect("a model as JSON")
}

/// Every leaf of `v` (numbers, strings, booleans, nulls, empty containers), mutably.
fn leaves(v: &mut Value) -> Vec<&mut Value> {
    let empty = match &*v {
        Value::Array(a) => a.is_empty(),
        Value::Object(o) => o.is_empty(),
        _ => true,
    };
    if empty {
        return vec![v];
    }
    match v {
        Value::Array(a) => a.iter_mut().flat_map(leaves).collect(),
        Value::Object(o) => o.values_mut().flat_map(leaves).collect(),
        _ => Vec::new(),
    }
}

fn extreme(kind: u8) -> Value {
    match kind % 10 {
        0 => Value::from(u64::MAX),
        1 => Value::from(-1),
        2 => Value::from(1e300),
        3 => Value::from(0),
        4 => Value::from(u64::from(u32::MAX)),
        5 => Value::from(0.5),
        6 => Value::from("NaN"),
        7 => Value::Array(vec![]),
        8 => Value::Null,
        _ => Value::from(-1e-300),
    }
}

/// The seed with values replaced at generated leaves (at most three), then (one input in four)
/// its text edited and (one in sixteen) cut.
fn mutated(seed: &Value, (values, mode, bytes, cut): &Input) -> Vec<u8> {
    let mut doc = seed.clone();
    for &(at, kind) in values.iter().take(3) {
        let mut all = leaves(&mut doc);
        let n = all.len();
        *all[usize::from(at) % n] = extreme(kind);
    }
    let mut text = serde_json::to_vec(&doc).expect("JSON");
    if mode % 4 != 0 {
        return text;
    }
    for &(at, value) in bytes.iter().take(4) {
        let i = usize::from(at) % text.len();
        text[i] = value;
    }
    if *cut < 4096 {
        text.truncate(usize::from(*cut) % (text.len() + 1));
    }
    text
}

type Input = (Vec<(u16, u8)>, u8, Vec<(u16, u8)>, u16);

/// Counts of inputs accepted and refused: a target that only ever saw one kind tested little.
#[derive(Default)]
struct Seen {
    accepted: AtomicU32,
    refused: AtomicU32,
}

impl Seen {
    fn note(&self, accepted: bool) {
        let c = if accepted {
            &self.accepted
        } else {
            &self.refused
        };
        c.fetch_add(1, Relaxed);
    }

    fn assert_both(&self, what: &str) {
        let (a, r) = (self.accepted.load(Relaxed), self.refused.load(Relaxed));
        assert!(a > 0 && r > 0, "{what}: {a} accepted, {r} refused");
    }
}

#[test]
fn fuzz_survey_files_are_checked_before_use() {
    let seed = survey();
    let path = Path::new("/etc/roomlight/survey.json");
    let seen = Seen::default();
    bolero::check!().with_type::<Input>().for_each(|input| {
        let text = mutated(&seed, input);
        let parsed = SurveyFile::parse(&String::from_utf8_lossy(&text), path);
        seen.note(parsed.is_ok());
        match parsed {
            Ok(s) => {
                let pixels = u64::from(s.camera_width) * u64::from(s.camera_height);
                assert!(s.target_pixels.iter().all(|&i| u64::from(i) < pixels));
                assert_eq!(s.target_mask().len() as u64, pixels);
                assert!(
                    s.corners
                        .iter()
                        .flat_map(|c| c.corners)
                        .flatten()
                        .all(f64::is_finite)
                );
            }
            Err(e) => assert!(format!("{e:#}").contains("survey.json"), "unnamed: {e:#}"),
        }
    });
    seen.assert_both("surveys");
}

#[test]
fn fuzz_model_files_are_checked_before_use() {
    let seed = model();
    let path = Path::new("/var/lib/roomlight/model.json");
    let seen = Seen::default();
    bolero::check!().with_type::<Input>().for_each(|input| {
        let text = mutated(&seed, input);
        let parsed = ModelFile::parse(&String::from_utf8_lossy(&text), path);
        seen.note(parsed.is_ok());
        match parsed {
            Ok(m) => {
                let nodes = m.problem.nodes();
                assert!(m.owners.values().flatten().all(|&n| (n as usize) < nodes));
                if let Some(start) = &m.start {
                    assert_eq!(start.len(), nodes);
                }
            }
            Err(e) => assert!(format!("{e:#}").contains("model.json"), "unnamed: {e:#}"),
        }
    });
    seen.assert_both("models");
}
