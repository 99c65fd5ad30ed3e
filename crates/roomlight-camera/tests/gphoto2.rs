//! The gphoto2 backend's settings and EXIF checks over a fake camera (the `Tether` trait), and
//! the EXIF check of folder/command cameras (`expect_exif`) on JPEG files written here with the
//! EXIF a camera would write. With the cargo feature `gphoto2`, libgphoto2 itself is opened on
//! its "Directory Browse" driver (no camera here): the library loads, the camera opens and its
//! missing controls are refused by name.

use roomlight_camera::exif::{ExpectExif, Shot};
use roomlight_camera::gphoto2::{
    Gphoto2Backend, Tether, Widget, apply_settings, parse_aperture, parse_iso, parse_shutter,
};
use roomlight_camera::spec::{CameraConfig, CameraSpec, Gphoto2Settings};
use roomlight_camera::{Backend, CameraError, open_backend};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A 4×2 JPEG carrying `shot` as its EXIF.
fn jpeg_with_exif(shot: &Shot) -> Vec<u8> {
    use image::ImageEncoder as _;
    let mut out = Vec::new();
    let mut encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95);
    encoder
        .set_exif_metadata(shot.to_tiff().expect("exif"))
        .expect("jpeg takes exif");
    encoder
        .write_image(&[128u8; 4 * 2 * 3], 4, 2, image::ExtendedColorType::Rgb8)
        .expect("jpeg");
    out
}

/// A camera whose widgets are a map; `stuck` widgets ignore writes (a dial the body overrides);
/// each capture waits `delay` and returns a JPEG with the EXIF of the current settings, or
/// `exif_override` when given.
#[derive(Clone, Default)]
struct Fake {
    widgets: Arc<Mutex<BTreeMap<String, Widget>>>,
    stuck: Vec<String>,
    delay: Duration,
    exif_override: Option<Shot>,
}

impl Fake {
    fn dslr() -> Self {
        let menu = |value: &str, choices: &[&str]| Widget {
            value: value.into(),
            choices: choices.iter().map(|c| c.to_string()).collect(),
        };
        let mut w = BTreeMap::new();
        w.insert(
            "shutterspeed".into(),
            menu("1/60", &["bulb", "2", "1", "0.5", "1/30", "1/60", "1/125"]),
        );
        w.insert("iso".into(), menu("Auto", &["Auto", "100", "200", "400"]));
        w.insert("aperture".into(), menu("f/4", &["f/4", "f/5.6", "f/8"]));
        w.insert(
            "imageformat".into(),
            menu("RAW", &["RAW", "RAW + Large Fine JPEG", "Large Fine JPEG"]),
        );
        Self {
            widgets: Arc::new(Mutex::new(w)),
            ..Self::default()
        }
    }

    fn value(&self, name: &str) -> String {
        self.widgets.lock().expect("lock")[name].value.clone()
    }
}

impl Tether for Fake {
    fn widget(&mut self, name: &str) -> Result<Option<Widget>, String> {
        Ok(self.widgets.lock().expect("lock").get(name).cloned())
    }
    fn set(&mut self, name: &str, value: &str) -> Result<(), String> {
        if !self.stuck.iter().any(|s| s == name) {
            let mut w = self.widgets.lock().expect("lock");
            w.get_mut(name).ok_or("no such widget")?.value = value.into();
        }
        Ok(())
    }
    fn capture(&mut self) -> Result<(String, Vec<u8>), String> {
        // The fake camera's shot time (a slow DSLR), not a wait on a condition.
        std::thread::sleep(self.delay);
        let shot = self.exif_override.unwrap_or(Shot {
            exposure_s: parse_shutter(&self.value("shutterspeed")),
            iso: parse_iso(&self.value("iso")).map(|i| i as u32),
            f_number: parse_aperture(&self.value("aperture")),
        });
        Ok(("IMG_0001.JPG".into(), jpeg_with_exif(&shot)))
    }
}

const SETTINGS: Gphoto2Settings = Gphoto2Settings {
    exposure_s: 0.0333,
    iso: 100,
    f_number: Some(5.6),
};

#[test]
fn camera_values_parse_as_cameras_write_them() {
    assert_eq!(parse_shutter("1/30"), Some(1.0 / 30.0));
    assert_eq!(parse_shutter("2s"), Some(2.0));
    assert_eq!(parse_shutter("0.5"), Some(0.5));
    assert_eq!(parse_shutter("bulb"), None);
    assert_eq!(parse_aperture("f/5.6"), Some(5.6));
    assert_eq!(parse_aperture("8"), Some(8.0));
    assert_eq!(parse_iso("ISO 200"), Some(200.0));
    assert_eq!(parse_iso("Auto"), None);
}

#[test]
fn settings_take_the_nearest_offered_value_and_read_it_back() {
    let mut cam = Fake::dslr();
    apply_settings(&mut cam, "gphoto2", &SETTINGS).expect("applied");
    assert_eq!(cam.value("shutterspeed"), "1/30");
    assert_eq!(cam.value("iso"), "100");
    assert_eq!(cam.value("aperture"), "f/5.6");
    assert_eq!(
        cam.value("imageformat"),
        "Large Fine JPEG",
        "JPEG only, not RAW+JPEG"
    );
}

#[test]
fn a_setting_not_offered_or_not_taken_is_refused_by_name() {
    let mut cam = Fake::dslr();
    let err = apply_settings(
        &mut cam,
        "gphoto2",
        &Gphoto2Settings {
            iso: 150,
            ..SETTINGS
        },
    )
    .expect_err("150 is not offered");
    let text = err.to_string();
    assert!(
        matches!(err, CameraError::Setting { .. })
            && text.contains("setting ISO: asked 150")
            && text.contains("offers Auto, 100, 200, 400"),
        "{text}"
    );
    let mut cam = Fake {
        stuck: vec!["shutterspeed".into()],
        ..Fake::dslr()
    };
    let err = apply_settings(&mut cam, "gphoto2", &SETTINGS).expect_err("dial overrides");
    assert!(
        err.to_string()
            .contains("shutter speed: asked 0.0333, got shutterspeed reads back \"1/60\""),
        "{err}"
    );
    let mut cam = Fake::dslr();
    cam.widgets.lock().expect("lock").remove("aperture");
    let err = apply_settings(&mut cam, "gphoto2", &SETTINGS).expect_err("no aperture");
    assert!(err.to_string().contains("no such control"), "{err}");
}

#[test]
fn each_shot_is_decoded_and_its_exif_checked() {
    let mut backend =
        Gphoto2Backend::new("gphoto2".into(), Box::new(Fake::dslr()), &SETTINGS, 1 << 20)
            .expect("opens");
    let frame = backend
        .capture(Instant::now() + Duration::from_secs(10))
        .expect("a shot");
    assert_eq!((frame.width, frame.height), (4, 2));
    assert!((frame.exposure_s.expect("from EXIF") - 1.0 / 30.0).abs() < 1e-9);
    // A body that shot at ISO 400 whatever was set.
    let liar = Fake {
        exif_override: Some(Shot {
            exposure_s: Some(1.0 / 30.0),
            iso: Some(400),
            f_number: Some(5.6),
        }),
        ..Fake::dslr()
    };
    let mut backend = Gphoto2Backend::new(
        "gphoto2:usb:001,004".into(),
        Box::new(liar),
        &SETTINGS,
        1 << 20,
    )
    .expect("opens");
    let err = backend
        .capture(Instant::now() + Duration::from_secs(10))
        .expect_err("EXIF disagrees");
    assert!(
        err.to_string()
            == "camera gphoto2:usb:001,004: EXIF PhotographicSensitivity (ISO): asked 100, got 400",
        "{err}"
    );
}

#[test]
fn a_hung_capture_times_out_and_its_late_shot_is_discarded() {
    let slow = Fake {
        delay: Duration::from_millis(600),
        ..Fake::dslr()
    };
    let mut backend =
        Gphoto2Backend::new("gphoto2".into(), Box::new(slow), &SETTINGS, 1 << 20).expect("opens");
    let t0 = Instant::now();
    let err = backend
        .capture(t0 + Duration::from_millis(100))
        .expect_err("too slow");
    assert!(matches!(err, CameraError::Timeout { ref camera, .. } if camera == "gphoto2"));
    assert!(
        t0.elapsed() < Duration::from_millis(500),
        "ended at its deadline"
    );
    // The next capture waits the late shot out, drops it, and takes a new one.
    let frame = backend
        .capture(Instant::now() + Duration::from_secs(10))
        .expect("the next shot");
    assert!(
        t0.elapsed() >= Duration::from_millis(1200),
        "two shots, not the stale one"
    );
    assert_eq!(frame.width, 4);
}

#[test]
fn folder_and_command_cameras_check_expect_exif() {
    let dir = tempfile::tempdir().expect("tmp");
    let shot = Shot {
        exposure_s: Some(1.0 / 125.0),
        iso: Some(200),
        f_number: Some(8.0),
    };
    let file = dir.path().join("shot.jpg");
    std::fs::write(&file, jpeg_with_exif(&shot)).expect("write");
    let mut config = CameraConfig::new(
        format!("command:cp '{}' {{out}}", file.display())
            .parse::<CameraSpec>()
            .expect("spec"),
    );
    config.expect_exif = Some(ExpectExif {
        exposure_s: Some(0.008),
        iso: Some(200),
        f_number: Some(8.0),
    });
    config.validate().expect("valid");
    let deadline = || Instant::now() + Duration::from_secs(10);
    let frame = open_backend(&config)
        .expect("opens")
        .capture(deadline())
        .expect("matches");
    assert_eq!(frame.shot, Some(shot));
    config.expect_exif = Some(ExpectExif {
        f_number: Some(5.6),
        ..ExpectExif::default()
    });
    let err = open_backend(&config)
        .expect("opens")
        .capture(deadline())
        .expect_err("f/8 is not f/5.6");
    assert!(
        err.to_string()
            .contains("EXIF FNumber: asked f/5.6, got f/8"),
        "{err}"
    );
    // Settings belong to their kind of camera.
    let toml_text = "spec = \"folder:/tmp\"\ngphoto2 = { exposure_s = 0.01, iso = 100 }\n";
    let config: CameraConfig = toml::from_str(toml_text).expect("parses");
    assert!(config.validate().is_err());
}

#[cfg(not(feature = "gphoto2"))]
#[test]
fn without_the_feature_a_gphoto2_spec_names_it() {
    let err = "gphoto2".parse::<CameraSpec>().expect_err("no feature");
    assert!(err.to_string().contains("cargo feature `gphoto2`"), "{err}");
}

/// libgphoto2's "Directory Browse" driver on `disk:DIR`: a real library, a real camera
/// handle, but a driver without controls or capture, so the settings are refused by name.
#[cfg(feature = "gphoto2")]
#[test]
fn libgphoto2_opens_a_directory_camera_and_refuses_its_missing_controls() {
    let dir = tempfile::tempdir().expect("tmp");
    let spec = format!("gphoto2:disk:{}", dir.path().display());
    let mut config = CameraConfig::new(spec.parse().expect("spec"));
    config.gphoto2 = Some(SETTINGS);
    config.validate().expect("valid");
    let Err(err) = open_backend(&config) else {
        panic!("a camera without controls opened");
    };
    let text = err.to_string();
    assert!(
        text.contains(&spec)
            && text.contains("setting shutter speed")
            && text.contains("no such control"),
        "{text}"
    );
    let mut tether = roomlight_camera::gphoto2::ffi::Libgphoto2::open(Some(&format!(
        "disk:{}",
        dir.path().display()
    )))
    .expect("libgphoto2 opens the directory camera");
    assert_eq!(tether.widget("shutterspeed"), Ok(None));
    let err = tether.capture().expect_err("this driver cannot capture");
    assert!(err.contains("gp_camera_capture"), "{err}");
    let err = roomlight_camera::gphoto2::ffi::Libgphoto2::open(Some("nosuchport:x"))
        .expect_err("unknown port");
    assert!(err.contains("no port nosuchport:x"), "{err}");
}
