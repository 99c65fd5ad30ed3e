//! The survey as the console edits it (docs/console.md, Survey): chart corners, sampling, the
//! target as polygons, the preset. Checked whole before anything is written, each refusal
//! naming the item; written as the survey file the camera agent reads (`target_pixels`, the
//! polygons rasterised, beside the polygons themselves) through a temporary file that is synced
//! and renamed over the old one. The version is a hash of the file's bytes (FNV-1a, 64 bits:
//! hand-written, six lines, no crate needed to tell two texts apart), so another console's
//! save and an edit by hand are both noticed.
//!
//! Geometry is hand-written too (segment crossing, convexity, polygon overlap of convex
//! quadrilaterals by separating axes, even-odd rasterising): a few dozen lines over a handful
//! of points, where a geometry crate would bring far more than it gives.

use roomlight_calib::charts::{ChartCorners, SampleConfig};
use serde::{Deserialize, Serialize};
use std::io::Write as _;
use std::path::Path;

/// At most this many charts (as the survey file allows).
pub const MAX_CHARTS: usize = 1024;
/// At most this many target polygons, and points in one.
pub const MAX_POLYGONS: usize = 64;
pub const MAX_POINTS: usize = 1024;
/// A chart's name at most this long.
pub const MAX_NAME: usize = 64;

/// A polygon in camera pixels.
pub type Polygon = Vec<[f64; 2]>;

/// The survey as the API carries it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Survey {
    pub camera_width: u32,
    pub camera_height: u32,
    pub charts: Vec<ChartCorners>,
    pub sample: SampleConfig,
    /// The target as polygons; empty with `target_pixels` > 0: the file's target came as
    /// pixels only (`roomlight calibrate --survey-only`), kept as it is unless polygons are
    /// drawn.
    #[serde(default)]
    pub target: Vec<Polygon>,
    /// The target's pixel count (read only).
    #[serde(default)]
    pub target_pixels: usize,
    #[serde(default)]
    pub preset: Option<String>,
}

/// The survey file (the camera agent's `SurveyFile`, with the console's polygons and preset).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct File {
    camera_width: u32,
    camera_height: u32,
    corners: Vec<ChartCorners>,
    sample: SampleConfig,
    target_pixels: Vec<u32>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    target_polygons: Vec<Polygon>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    preset: Option<String>,
}

/// Why a survey was refused; `item` names what (e.g. `charts[2]`, `target[0]`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{item}: {problem}")]
pub struct Invalid {
    pub item: String,
    pub problem: String,
}

fn invalid(item: impl Into<String>, problem: impl Into<String>) -> Invalid {
    Invalid {
        item: item.into(),
        problem: problem.into(),
    }
}

/// The version of a file's bytes.
pub fn version(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Reads the survey file: its version and its content for the API.
pub fn read(path: &Path) -> Result<(String, Survey), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let file: File = serde_json::from_slice(&bytes)
        .map_err(|e| format!("{}: not a survey file: {e}", path.display()))?;
    let survey = Survey {
        camera_width: file.camera_width,
        camera_height: file.camera_height,
        charts: file.corners,
        sample: file.sample,
        target: file.target_polygons,
        target_pixels: file.target_pixels.len(),
        preset: file.preset,
    };
    Ok((version(&bytes), survey))
}

/// The file's target pixels (for the mask picture), checked against its size.
pub fn target_mask(path: &Path) -> Result<(u32, u32, Vec<bool>), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let file: File = serde_json::from_slice(&bytes)
        .map_err(|e| format!("{}: not a survey file: {e}", path.display()))?;
    let (w, h) = (file.camera_width, file.camera_height);
    if !(1..=20_000).contains(&w) || !(1..=20_000).contains(&h) {
        return Err(format!("{}: a {w}×{h} camera", path.display()));
    }
    let mut mask = vec![false; w as usize * h as usize];
    for i in file.target_pixels {
        if let Some(m) = mask.get_mut(i as usize) {
            *m = true;
        }
    }
    Ok((w, h, mask))
}

/// Checks `new` against the file it replaces (whose camera size it must keep) and the room's
/// presets (none known: any name).
pub fn validate(new: &Survey, current: &Survey, presets: &[String]) -> Result<(), Invalid> {
    let (w, h) = (new.camera_width, new.camera_height);
    if (w, h) != (current.camera_width, current.camera_height) {
        return Err(invalid(
            "camera_width/camera_height",
            format!(
                "{w}×{h}, the survey's camera is {}×{}",
                current.camera_width, current.camera_height
            ),
        ));
    }
    if new.charts.len() > MAX_CHARTS {
        return Err(invalid(
            "charts",
            format!("{} charts, at most {MAX_CHARTS}", new.charts.len()),
        ));
    }
    let inside = |p: &[f64; 2]| {
        p.iter().all(|v| v.is_finite())
            && (0.0..=f64::from(w)).contains(&p[0])
            && (0.0..=f64::from(h)).contains(&p[1])
    };
    let mut names = std::collections::HashSet::new();
    for (i, chart) in new.charts.iter().enumerate() {
        let item = format!("charts[{i}] {:?}", chart.name);
        if chart.name.trim().is_empty() || chart.name.chars().count() > MAX_NAME {
            return Err(invalid(
                item,
                format!("a name of 1 to {MAX_NAME} characters is needed"),
            ));
        }
        if !names.insert(chart.name.as_str()) {
            return Err(invalid(item, "another chart has this name"));
        }
        if let Some((k, p)) = chart.corners.iter().enumerate().find(|(_, p)| !inside(p)) {
            return Err(invalid(
                item,
                format!(
                    "corner {} ({:.1}, {:.1}) is outside the {w}×{h} image",
                    k + 1,
                    p[0],
                    p[1]
                ),
            ));
        }
        let quad = chart.corners.to_vec();
        if crosses_itself(&quad) {
            return Err(invalid(
                item,
                "its outline crosses itself (corners go top-left, top-right, bottom-right, bottom-left)",
            ));
        }
        if !convex(&quad) || area(&quad).abs() < 16.0 {
            return Err(invalid(
                item,
                "its corners do not make a convex chart of at least 4×4 pixels",
            ));
        }
    }
    for (i, a) in new.charts.iter().enumerate() {
        for b in &new.charts[i + 1..] {
            if convex_overlap(&a.corners, &b.corners) {
                return Err(invalid(
                    format!("charts[{i}] {:?}", a.name),
                    format!("it overlaps chart {:?}", b.name),
                ));
            }
        }
    }
    if new.target.len() > MAX_POLYGONS {
        return Err(invalid(
            "target",
            format!("{} polygons, at most {MAX_POLYGONS}", new.target.len()),
        ));
    }
    for (i, polygon) in new.target.iter().enumerate() {
        let item = format!("target[{i}]");
        if !(3..=MAX_POINTS).contains(&polygon.len()) {
            return Err(invalid(
                item,
                format!("{} points, expected 3 to {MAX_POINTS}", polygon.len()),
            ));
        }
        if let Some((k, p)) = polygon.iter().enumerate().find(|(_, p)| !inside(p)) {
            return Err(invalid(
                item,
                format!(
                    "point {} ({:.1}, {:.1}) is outside the {w}×{h} image",
                    k + 1,
                    p[0],
                    p[1]
                ),
            ));
        }
        if crosses_itself(polygon) {
            return Err(invalid(item, "its edges cross"));
        }
        if area(polygon).abs() < 1.0 {
            return Err(invalid(item, "it encloses no area"));
        }
    }
    let s = &new.sample;
    if !(s.saturation > 0.0 && s.saturation <= 1.0) {
        return Err(invalid(
            "sample.saturation",
            format!("{}, expected in (0, 1]", s.saturation),
        ));
    }
    for (field, v) in [
        ("sample.read_noise", f64::from(s.read_noise)),
        ("sample.shot_noise", f64::from(s.shot_noise)),
        ("sample.max_nonuniformity", s.max_nonuniformity),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(invalid(field, format!("{v}, expected a finite value ≥ 0")));
        }
    }
    if let Some(preset) = &new.preset
        && !presets.is_empty()
        && !presets.contains(preset)
    {
        return Err(invalid(
            "preset",
            format!("{preset:?}: the room has {}", presets.join(", ")),
        ));
    }
    Ok(())
}

/// Twice the signed area (shoelace).
fn area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Segments `ab` and `cd` cross at a point inside both (touching ends do not count).
fn segments_cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Two edges that are not neighbours cross (O(n²) over at most [`MAX_POINTS`] points).
fn crosses_itself(p: &[[f64; 2]]) -> bool {
    let n = p.len();
    (0..n).any(|i| {
        ((i + 2)..n).any(|j| {
            // The first and last edges share a point.
            (i, j) != (0, n - 1) && segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n])
        })
    })
}

/// Every turn goes the same way.
fn convex(p: &[[f64; 2]]) -> bool {
    let n = p.len();
    let turns: Vec<f64> = (0..n)
        .map(|i| cross(p[i], p[(i + 1) % n], p[(i + 2) % n]))
        .collect();
    turns.iter().all(|&t| t >= 0.0) || turns.iter().all(|&t| t <= 0.0)
}

/// Two convex polygons share some area (separating axes: none of their edges' normals
/// separates them; touching edges do not count).
fn convex_overlap(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    let separated = |p: &[[f64; 2]], q: &[[f64; 2]]| {
        (0..p.len()).any(|i| {
            let (s, e) = (p[i], p[(i + 1) % p.len()]);
            let normal = [s[1] - e[1], e[0] - s[0]];
            let project = |v: &[f64; 2]| v[0] * normal[0] + v[1] * normal[1];
            let (pmin, pmax) = p
                .iter()
                .map(project)
                .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            let (qmin, qmax) = q
                .iter()
                .map(project)
                .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            pmax <= qmin || qmax <= pmin
        })
    };
    !separated(a, b) && !separated(b, a)
}

/// The pixels (row-major indices) whose centres lie inside any polygon (even-odd rule per
/// polygon), increasing.
pub fn rasterise(width: u32, height: u32, polygons: &[Polygon]) -> Vec<u32> {
    let mut inside = vec![false; width as usize * height as usize];
    for polygon in polygons {
        let n = polygon.len();
        for y in 0..height {
            let cy = f64::from(y) + 0.5;
            // Where the row's centre line crosses the edges.
            let mut xs: Vec<f64> = (0..n)
                .filter_map(|i| {
                    let (a, b) = (polygon[i], polygon[(i + 1) % n]);
                    let crosses = (a[1] <= cy) != (b[1] <= cy);
                    // A horizontal edge never crosses (a[1] == b[1] fails the test above).
                    crosses.then(|| a[0] + (cy - a[1]) / (b[1] - a[1]) * (b[0] - a[0]))
                })
                .collect();
            xs.sort_by(f64::total_cmp);
            for pair in xs.chunks_exact(2) {
                let from = (pair[0] - 0.5).ceil().max(0.0) as u32;
                let to = ((pair[1] - 0.5).floor().min(f64::from(width) - 1.0)).max(-1.0);
                if to < 0.0 {
                    continue;
                }
                for x in from..=(to as u32) {
                    inside[(y * width + x) as usize] = true;
                }
            }
        }
    }
    inside
        .iter()
        .enumerate()
        .filter(|(_, m)| **m)
        .map(|(i, _)| i as u32)
        .collect()
}

/// Writes `new` over the file at `path` (whose current content is `current`): the target
/// pixels from the polygons (or the file's own, when it had pixels only and none are drawn),
/// through a synced temporary file renamed over it. Returns the new version.
pub fn write(path: &Path, new: &Survey) -> Result<String, String> {
    let old: File = serde_json::from_slice(
        &std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?,
    )
    .map_err(|e| format!("{}: not a survey file: {e}", path.display()))?;
    let target_pixels = if new.target.is_empty() && old.target_polygons.is_empty() {
        old.target_pixels
    } else {
        rasterise(new.camera_width, new.camera_height, &new.target)
    };
    let file = File {
        camera_width: new.camera_width,
        camera_height: new.camera_height,
        corners: new.charts.clone(),
        sample: new.sample,
        target_pixels,
        target_polygons: new.target.clone(),
        preset: new.preset.clone(),
    };
    let bytes = serde_json::to_vec(&file).map_err(|e| e.to_string())?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("survey.json");
    let tmp = dir.join(format!(".{name}.console-{}", std::process::id()));
    let written = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        // The rename itself survives a crash once the folder is synced.
        std::fs::File::open(dir)?.sync_all()
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(format!("writing {}: {e}", path.display()));
    }
    Ok(version(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(name: &str, x: f64, y: f64) -> ChartCorners {
        ChartCorners {
            name: name.into(),
            corners: [[x, y], [x + 60.0, y], [x + 60.0, y + 40.0], [x, y + 40.0]],
        }
    }

    fn survey() -> Survey {
        Survey {
            camera_width: 640,
            camera_height: 480,
            charts: vec![chart("A", 10.0, 10.0), chart("B", 100.0, 10.0)],
            sample: SampleConfig::default(),
            target: vec![vec![
                [300.0, 200.0],
                [360.0, 200.0],
                [360.0, 300.0],
                [300.0, 300.0],
            ]],
            target_pixels: 0,
            preset: None,
        }
    }

    /// Each kind of bad survey is refused naming its item; a good one passes.
    #[test]
    fn bad_surveys_are_refused_by_item() {
        let good = survey();
        assert_eq!(validate(&good, &good, &[]), Ok(()));
        let refused = |edit: &dyn Fn(&mut Survey)| {
            let mut s = survey();
            edit(&mut s);
            validate(&s, &good, &["on".to_string()]).expect_err("refused")
        };
        let e = refused(&|s| s.charts[1].corners[2] = [700.0, 50.0]);
        assert_eq!(e.item, "charts[1] \"B\"");
        assert!(
            e.problem
                .contains("corner 3 (700.0, 50.0) is outside the 640×480 image"),
            "{e}"
        );
        let e = refused(&|s| s.charts[0].corners.swap(1, 2));
        assert!(e.problem.contains("crosses itself"), "{e}");
        let e = refused(&|s| s.charts[1] = chart("B", 40.0, 20.0));
        assert_eq!(e.item, "charts[0] \"A\"");
        assert!(e.problem.contains("overlaps chart \"B\""), "{e}");
        let e = refused(&|s| s.charts[1].name = "A".into());
        assert!(e.problem.contains("another chart has this name"), "{e}");
        let e = refused(&|s| {
            s.target[0] = vec![
                [300.0, 200.0],
                [360.0, 300.0],
                [360.0, 200.0],
                [300.0, 300.0],
            ]
        });
        assert_eq!(e.item, "target[0]");
        assert!(e.problem.contains("edges cross"), "{e}");
        let e = refused(&|s| s.target[0].truncate(2));
        assert!(e.problem.contains("2 points"), "{e}");
        let e = refused(&|s| s.target[0][1] = [f64::NAN, 1.0]);
        assert!(e.problem.contains("outside"), "{e}");
        let e = refused(&|s| s.sample.saturation = 0.0);
        assert_eq!(e.item, "sample.saturation");
        let e = refused(&|s| s.preset = Some("disco".into()));
        assert_eq!(e.item, "preset");
        let e = refused(&|s| s.camera_width = 320);
        assert!(e.problem.contains("the survey's camera is 640×480"), "{e}");
        // Charts that only touch do not overlap.
        let mut touching = survey();
        touching.charts[1] = chart("B", 70.0, 10.0);
        assert_eq!(validate(&touching, &good, &[]), Ok(()));
    }

    /// Rasterising a rectangle gives exactly the pixels whose centres it holds, and a triangle
    /// about half its box; nothing outside the image.
    #[test]
    fn polygons_rasterise_to_their_pixels() {
        let square = vec![vec![[2.0, 1.0], [6.0, 1.0], [6.0, 4.0], [2.0, 4.0]]];
        let px = rasterise(10, 8, &square);
        let expected: Vec<u32> = (1..4)
            .flat_map(|y| (2..6).map(move |x| y * 10 + x))
            .collect();
        assert_eq!(px, expected);
        let triangle = vec![vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]];
        let n = rasterise(100, 100, &triangle).len();
        assert!((4900..=5100).contains(&n), "{n}");
        let past = vec![vec![
            [-5.0, -5.0],
            [500.0, -5.0],
            [500.0, 500.0],
            [-5.0, 500.0],
        ]];
        assert_eq!(rasterise(4, 3, &past).len(), 12);
    }

    /// A write replaces the file whole, with pixels from the polygons and a new version; a
    /// file with pixels only keeps them when no polygon is drawn.
    #[test]
    fn writes_are_whole_and_versioned() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("survey.json");
        let pixels_only = serde_json::json!({
            "camera_width": 640, "camera_height": 480,
            "corners": [], "sample": SampleConfig::default(), "target_pixels": [5, 6, 7]
        });
        std::fs::write(&path, pixels_only.to_string()).expect("write");
        let (v0, current) = read(&path).expect("read");
        assert_eq!(current.target_pixels, 3);
        let mut kept = current.clone();
        kept.charts.push(chart("A", 10.0, 10.0));
        let v1 = write(&path, &kept).expect("written");
        assert_ne!(v0, v1);
        let (v1_read, after) = read(&path).expect("read");
        assert_eq!(v1, v1_read);
        assert_eq!(after.target_pixels, 3);
        assert_eq!(after.charts.len(), 1);
        let v2 = write(&path, &survey()).expect("written");
        let (_, drawn) = read(&path).expect("read");
        assert_eq!(drawn.target, survey().target);
        assert_eq!(drawn.target_pixels, 60 * 100);
        assert_ne!(v1, v2);
        // Nothing is left beside it.
        let names: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
        assert_eq!(names.len(), 1);
    }
}
