//! Radiometry round trips: codes through a known curve and back, masks, dark frames, the
//! camera adapter over a fake backend, and a response recovered from synthetic exposures.

use roomlight_calib::image_io::LinearImage;
use roomlight_camera::radiometry::calibrate_response;
use roomlight_camera::{Backend, CameraError, Frame, HwCamera, Radiometry, Response, Samples};
use std::time::{Duration, Instant};

#[test]
fn srgb_codes_round_trip_to_linear() {
    let table = Response::Srgb.table();
    for z in 0..=255u8 {
        let linear = table[usize::from(z)];
        // The forward sRGB curve, written independently.
        let c = if linear <= 0.003_130_8 {
            12.92 * linear
        } else {
            1.055 * linear.powf(1.0 / 2.4) - 0.055
        };
        assert_eq!((c * 255.0).round() as u8, z);
    }
    let g = Response::Gamma(2.0).table();
    assert!((g[128] - (128.0f32 / 255.0).powi(2)).abs() < 1e-6);
}

#[test]
fn saturated_and_underexposed_pixels_are_masked_and_dark_frames_subtracted() {
    let frame = Frame::rgb8(
        4,
        1,
        vec![[0, 10, 10], [10, 10, 10], [250, 10, 10], [249, 20, 30]],
    )
    .expect("frame");
    let r = Radiometry::new(&Response::Gamma(1.0), 250, 0);
    let l = r.linearize(&frame, "test").expect("linear");
    assert_eq!(l.usable, vec![false, true, false, true]);
    assert!((l.saturation - 250.0 / 255.0).abs() < 1e-6);
    let dark = LinearImage {
        width: 4,
        height: 1,
        pixels: vec![[1.0 / 255.0; 3]; 4],
    };
    let l = r
        .clone()
        .with_dark_frame(dark)
        .linearize(&frame, "test")
        .expect("linear");
    assert!((l.image.pixels[1][0] - 9.0 / 255.0).abs() < 1e-6);
    let wrong = LinearImage::new(2, 2);
    let err = r
        .with_dark_frame(wrong)
        .linearize(&frame, "cam")
        .expect_err("size");
    assert!(err.to_string().contains("dark frame of 2×2"), "{err}");
    // 16-bit is linear as it is.
    let deep = Frame {
        width: 1,
        height: 1,
        samples: Samples::Rgb16(vec![[65535 / 2, 0, 1000]]),
        exposure_s: None,
        shot: None,
    };
    let l = Radiometry::new(&Response::Srgb, 250, 0)
        .linearize(&deep, "deep")
        .expect("linear");
    assert!((l.image.pixels[0][0] - 0.5).abs() < 1e-4);
    assert_eq!(l.usable, vec![false], "a channel at zero is clipped black");
}

/// A static scene of radiances spread over three decades, shot through `curve`.
fn exposures(curve: impl Fn(f64) -> f64) -> Vec<(Frame, f64)> {
    let n = 400u32;
    let radiance =
        |i: u32, c: usize| 10f64.powf(-3.0 + 3.0 * f64::from(i) / f64::from(n) + 0.1 * c as f64);
    [0.25, 1.0, 4.0, 16.0, 64.0]
        .iter()
        .map(|&t| {
            let pixels = (0..n)
                .map(|i| {
                    std::array::from_fn(|c| {
                        let x = (radiance(i, c) * t / 64.0).min(1.0);
                        (255.0 * curve(x)).round() as u8
                    })
                })
                .collect();
            (Frame::rgb8(n, 1, pixels).expect("frame"), t)
        })
        .collect()
}

#[test]
fn a_known_response_is_recovered_from_exposures() {
    let gamma = 2.2;
    let shots = exposures(|x| x.powf(1.0 / gamma));
    let frames: Vec<(&Frame, f64)> = shots.iter().map(|(f, t)| (f, *t)).collect();
    let Response::Table(table) = calibrate_response(&frames, 60, 10.0).expect("response") else {
        panic!("a table");
    };
    // The curve's scale is free: compare shapes, relative to code 128. Tolerance: 2 % over
    // codes 20-240 (measured 0.58 %; quantisation alone is up to ±2.5 % on one pixel at code 20).
    let mut worst = 0.0f64;
    for z in 20..=240usize {
        let truth = (z as f64 / 128.0).powf(gamma);
        let got = f64::from(table[z]) / f64::from(table[128]);
        worst = worst.max((got / truth - 1.0).abs());
    }
    eprintln!("response recovered: worst relative error {worst:.4} over codes 20-240");
    assert!(worst < 0.02, "worst relative error {worst}");
}

/// A backend that hands out prepared frames in order, then times out.
struct Fake(Vec<Frame>);

impl Backend for Fake {
    fn name(&self) -> &str {
        "fake:1"
    }
    fn capture(&mut self, _deadline: Instant) -> Result<Frame, CameraError> {
        if !self.0.is_empty() {
            return Ok(self.0.remove(0));
        }
        Err(CameraError::Timeout {
            camera: "fake:1".into(),
            after: Duration::ZERO,
        })
    }
}

#[tokio::test]
async fn the_adapter_hands_the_agent_linear_images_and_timeouts() {
    use roomlight_agent::hardware::Camera;
    let frame = Frame::rgb8(2, 1, vec![[255, 255, 255], [188, 188, 188]]).expect("frame");
    let radiometry = Radiometry::new(&Response::Srgb, 250, 0);
    let mut camera = HwCamera::new(
        Box::new(Fake(vec![frame])),
        radiometry,
        Duration::from_secs(1),
    );
    assert!((camera.limits().saturation - Response::Srgb.table()[250]).abs() < 1e-6);
    let image = camera.capture_image().await.expect("image");
    assert!((image.pixels[1][0] - 0.5).abs() < 0.01);
    let err = camera.capture_image().await.expect_err("timeout");
    assert!(err.to_string().contains("fake:1"), "{err}");
}

#[tokio::test]
async fn patches_are_sampled_at_the_charts_and_clipped_pixels_refuse_theirs() {
    use roomlight_agent::hardware::Camera;
    use roomlight_calib::charts::{ChartCorners, SampleConfig};
    // One 6×4 chart filling a 60×40 image: patch k is the 10×10 block at column k % 6, row
    // k / 6. Code 188 is linear 0.5 in sRGB.
    let (w, h) = (60, 40);
    let grey = Frame::rgb8(w, h, vec![[188; 3]; (w * h) as usize]).expect("frame");
    let mut clipped = grey.clone();
    if let Samples::Rgb8(p) = &mut clipped.samples {
        p[(15 * w + 55) as usize] = [255, 188, 188]; // inside patch 11 (column 5, row 1)
    }
    let charts = roomlight_camera::Charts {
        corners: std::sync::Arc::new(vec![ChartCorners {
            name: "wall".into(),
            corners: [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [0.0, 40.0]],
        }]),
        patches: std::sync::Arc::new(vec![0, 11, 23]),
        sample: SampleConfig::default(),
    };
    let radiometry = Radiometry::new(&Response::Srgb, 250, 0);
    let mut camera = HwCamera::new(
        Box::new(Fake(vec![grey, clipped])),
        radiometry,
        Duration::from_secs(1),
    )
    .with_charts(charts);
    let patches = camera.capture().await.expect("patches");
    assert_eq!(patches.len(), 3);
    let half = Response::Srgb.table()[188];
    for p in &patches {
        assert!((p.0[0] - f64::from(half)).abs() < 1e-6, "{p:?}");
    }
    let err = camera.capture().await.expect_err("a clipped pixel");
    assert!(err.to_string().contains("patch 11"), "{err}");
}

#[test]
fn the_cli_measures_a_response_from_files_and_prints_a_config_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let shots: Vec<(std::path::PathBuf, f64)> = exposures(|x| x.powf(1.0 / 2.2))
        .into_iter()
        .enumerate()
        .map(|(k, (frame, t))| {
            let Samples::Rgb8(p) = frame.samples else {
                panic!("8-bit");
            };
            let raw = p.into_iter().flatten().collect();
            let path = dir.path().join(format!("shot{k}.png"));
            image::RgbImage::from_raw(frame.width, frame.height, raw)
                .expect("image")
                .save(&path)
                .expect("save");
            (path, t)
        })
        .collect();
    let line = roomlight_camera::cli::calibrate_response(&shots, 1 << 20).expect("response");
    #[derive(serde::Deserialize)]
    struct Holder {
        response: Response,
    }
    let parsed: Holder = toml::from_str(&line).expect("a config line");
    parsed.response.validate().expect("valid");
    let Response::Table(t) = parsed.response else {
        panic!("a table");
    };
    let ratio = f64::from(t[200]) / f64::from(t[100]);
    assert!((ratio / 2.0f64.powf(2.2) - 1.0).abs() < 0.02, "{ratio}");
}
