//! The folder and command backends against real files and real processes in temp dirs, the
//! bounded decoder, and the V4L2 control checks and format conversions against recorded
//! (fake) devices.

use roomlight_camera::command::CommandBackend;
use roomlight_camera::folder::FolderBackend;
use roomlight_camera::frame::decode_file;
use roomlight_camera::spec::{CameraConfig, CameraSpec, V4l2Controls};
use roomlight_camera::v4l2::{Controls, apply_controls, convert};
use roomlight_camera::{Backend, CameraError, Frame, Samples};
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};

const MAX: u64 = 64 << 20;

/// A small PNG whose pixel (x, y) is (x, y, seed).
fn png_bytes(w: u32, h: u32, seed: u8) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, seed]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("png");
    out.into_inner()
}

fn seed_of(frame: &Frame) -> u8 {
    match &frame.samples {
        Samples::Rgb8(p) => p[0][2],
        Samples::Rgb16(_) => panic!("expected 8-bit"),
    }
}

/// Starts a folder capture on its own thread; its result arrives on the channel.
fn capture_in_thread(dir: &Path, timeout: Duration) -> mpsc::Receiver<Result<Frame, CameraError>> {
    let backend = FolderBackend::new(dir.to_path_buf(), Duration::from_millis(100), MAX);
    // Armed here, before the caller writes anything: what the thread sees is decided now.
    let armed = backend.arm().expect("arm");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(armed.wait(Instant::now() + timeout));
    });
    rx
}

#[test]
fn folder_takes_only_a_file_written_after_the_request() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("old.png"), png_bytes(4, 3, 1)).expect("write");
    let rx = capture_in_thread(dir.path(), Duration::from_secs(10));
    // The old file is complete and decodable: were it taken, it would be within the settle.
    assert!(
        rx.recv_timeout(Duration::from_millis(400)).is_err(),
        "old file taken"
    );
    let tmp = dir.path().join(".new.png.part");
    std::fs::write(&tmp, png_bytes(4, 3, 2)).expect("write");
    std::fs::rename(&tmp, dir.path().join("new.png")).expect("rename");
    let frame = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("a capture")
        .expect("the new file");
    assert_eq!((frame.width, frame.height, seed_of(&frame)), (4, 3, 2));
}

#[test]
fn folder_waits_for_a_slowly_written_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rx = capture_in_thread(dir.path(), Duration::from_secs(10));
    let bytes = png_bytes(64, 64, 7);
    let path = dir.path().join("slow.png");
    let half = bytes.len() / 2;
    std::fs::write(&path, &bytes[..half]).expect("first half");
    assert!(
        rx.recv_timeout(Duration::from_millis(500)).is_err(),
        "a half-written file was returned"
    );
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .expect("open");
    f.write_all(&bytes[half..]).expect("second half");
    drop(f);
    let frame = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("a capture")
        .expect("the whole file");
    assert_eq!((frame.width, frame.height, seed_of(&frame)), (64, 64, 7));
}

#[test]
fn folder_times_out_naming_the_camera() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut backend = FolderBackend::new(dir.path().to_path_buf(), Duration::from_millis(50), MAX);
    let started = Instant::now();
    let err = backend
        .capture(started + Duration::from_millis(300))
        .expect_err("nothing was written");
    assert!(started.elapsed() < Duration::from_secs(5));
    assert!(matches!(err, CameraError::Timeout { .. }), "{err}");
    assert!(
        err.to_string()
            .contains(&format!("folder:{}", dir.path().display())),
        "{err}"
    );
}

#[test]
fn command_copies_a_png() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = dir.path().join("shot it.png");
    std::fs::write(&src, png_bytes(5, 2, 9)).expect("write");
    let cmd = format!("cp '{}' {{out}}", src.display());
    let mut backend = CommandBackend::new(cmd, MAX).expect("backend");
    let frame = backend
        .capture(Instant::now() + Duration::from_secs(10))
        .expect("capture");
    assert_eq!((frame.width, frame.height, seed_of(&frame)), (5, 2, 9));
}

#[test]
fn a_failing_command_says_why() {
    let cmd = "echo 'lens cap is on' >&2; exit 3 # {out}".to_string();
    let mut backend = CommandBackend::new(cmd, MAX).expect("backend");
    let err = backend
        .capture(Instant::now() + Duration::from_secs(10))
        .expect_err("exit 3");
    let text = err.to_string();
    assert!(matches!(err, CameraError::Command { .. }), "{text}");
    assert!(
        text.contains("lens cap is on") && text.contains('3'),
        "{text}"
    );
}

/// True once `pid` has exited (gone, or a zombie waiting for a reaper).
fn exited(pid: &str) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        Ok(stat) => stat
            .rsplit(')')
            .next()
            .is_some_and(|rest| rest.trim_start().starts_with('Z')),
    }
}

#[test]
fn a_hanging_command_is_killed_at_the_timeout() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pids = dir.path().join("pids");
    let cmd = format!(
        "sleep 600 & echo $$ $! > '{}'; wait # {{out}}",
        pids.display()
    );
    let mut backend = CommandBackend::new(cmd, MAX).expect("backend");
    let started = Instant::now();
    let err = backend
        .capture(started + Duration::from_millis(500))
        .expect_err("it hangs");
    assert!(matches!(err, CameraError::Timeout { .. }), "{err}");
    assert!(err.to_string().contains("command:sleep 600"), "{err}");
    assert!(started.elapsed() < Duration::from_secs(5));
    let pids = std::fs::read_to_string(&pids).expect("the command wrote its pids");
    let deadline = Instant::now() + Duration::from_secs(5);
    for pid in pids.split_whitespace() {
        while !exited(pid) {
            assert!(Instant::now() < deadline, "process {pid} left behind");
            std::thread::yield_now();
        }
    }
}

/// PNG's chunk CRC (ISO 3309), bit by bit: the test's one chunk is 17 bytes.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn an_oversized_image_is_refused_before_decoding() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("huge.png");
    // A valid header claiming 100 000 × 100 000 pixels and no pixel data: decoding would fail
    // differently (or allocate 30 GB); the refusal must come from the header alone.
    let mut png = png_bytes(1, 1, 0);
    png[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    png[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    std::fs::write(&path, &png).expect("write");
    let err = decode_file(&path, MAX).expect_err("too large");
    let text = err.to_string();
    assert!(
        text.contains("huge.png") && text.contains("before decoding"),
        "{text}"
    );
}

#[test]
fn specs_parse_and_configs_refuse_unknown_fields() {
    for s in ["folder:/tmp/x", "command:cp a {out}", "v4l2:/dev/video0"] {
        let spec: CameraSpec = s.parse().expect(s);
        assert_eq!(spec.to_string(), s);
    }
    for bad in ["folder:", "command:cp a b", "usb:1", "v4l2"] {
        assert!(bad.parse::<CameraSpec>().is_err(), "{bad}");
    }
    let gphoto = "gphoto2:usb:001,004".parse::<CameraSpec>();
    if !cfg!(feature = "gphoto2") {
        let err = gphoto.expect_err("not built");
        assert!(err.to_string().contains("feature `gphoto2`"), "{err}");
    }
    let config: CameraConfig = toml::from_str(
        "spec = \"v4l2:/dev/video2\"\ntimeout_s = 3\nresponse = { gamma = 2.2 }\n\
         [v4l2]\nexposure_100us = 100\ngain = 4\n",
    )
    .expect("config");
    config.validate().expect("valid");
    assert!(
        toml::from_str::<CameraConfig>("spec = \"folder:/x\"\nexposure = 3\n").is_err(),
        "unknown field accepted"
    );
    let no_controls = CameraConfig::new("v4l2:/dev/video0".parse().expect("spec"));
    assert!(
        no_controls.validate().is_err(),
        "a v4l2 camera on auto exposure"
    );
}

/// A device whose controls read back what a recording says (`stuck`), else what was written.
struct Recorded {
    written: Vec<(linuxvideo::controls::Cid, i64)>,
    stuck: Vec<(linuxvideo::controls::Cid, i64)>,
}

impl Recorded {
    fn new(stuck: Vec<(linuxvideo::controls::Cid, i64)>) -> Self {
        Self {
            written: Vec::new(),
            stuck,
        }
    }
}

impl Controls for Recorded {
    fn write(&mut self, cid: linuxvideo::controls::Cid, value: i64) -> std::io::Result<()> {
        self.written.push((cid, value));
        Ok(())
    }
    fn read(&self, cid: linuxvideo::controls::Cid) -> std::io::Result<i64> {
        let find = |list: &[(linuxvideo::controls::Cid, i64)]| {
            list.iter().rev().find(|(c, _)| *c == cid).map(|(_, v)| *v)
        };
        Ok(find(&self.stuck)
            .or_else(|| find(&self.written))
            .unwrap_or(0))
    }
}

#[test]
fn a_camera_whose_auto_exposure_stays_on_is_refused_by_name() {
    use linuxvideo::controls::Cid;
    let controls = V4l2Controls {
        exposure_100us: 200,
        gain: Some(8),
        white_balance_k: Some(4600),
        size: [640, 480],
    };
    let mut good = Recorded::new(Vec::new());
    apply_controls(&mut good, &controls, "v4l2:/dev/video9").expect("all took");
    // Recorded from a UVC camera that ignores exposure_auto: it reads back 3 (aperture priority).
    let mut bad = Recorded::new(vec![(Cid::EXPOSURE_AUTO, 3)]);
    let err = apply_controls(&mut bad, &controls, "v4l2:/dev/video9").expect_err("auto on");
    let text = err.to_string();
    assert!(
        text.contains("exposure_auto") && text.contains("/dev/video9"),
        "{text}"
    );
    let mut bad = Recorded::new(vec![(Cid::GAIN, 2)]);
    let err = apply_controls(&mut bad, &controls, "v4l2:/dev/video9").expect_err("gain");
    assert!(err.to_string().contains("control gain"), "{err}");
}

#[test]
fn video_formats_convert_to_rgb() {
    use linuxvideo::format::PixelFormat;
    // YUYV of two pixels: black (Y 16) and white (Y 235), neutral chroma.
    let rgb = convert(PixelFormat::YUYV, 2, 1, &[16, 128, 235, 128]).expect("yuyv");
    assert_eq!(rgb, vec![[0, 0, 0], [255, 255, 255]]);
    let rgb = convert(PixelFormat::RGB3, 1, 1, &[1, 2, 3]).expect("rgb3");
    assert_eq!(rgb, vec![[1, 2, 3]]);
    assert!(
        convert(PixelFormat::YUYV, 2, 2, &[0; 4]).is_none(),
        "short buffer"
    );
    let mut jpeg = std::io::Cursor::new(Vec::new());
    image::RgbImage::from_pixel(8, 8, image::Rgb([200, 100, 50]))
        .write_to(&mut jpeg, image::ImageFormat::Jpeg)
        .expect("jpeg");
    let rgb = convert(PixelFormat::MJPG, 8, 8, jpeg.get_ref()).expect("mjpg");
    assert!(
        rgb.iter()
            .all(|p| p[0].abs_diff(200) <= 3 && p[2].abs_diff(50) <= 3)
    );
}

#[test]
fn the_cli_capture_writes_the_frame_and_reports_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A 16-bit source: written as it came, 16-bit.
    let src = dir.path().join("deep.png");
    image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_pixel(3, 2, image::Rgb([1000, 2, 65535]))
        .save(&src)
        .expect("16-bit png");
    let out = dir.path().join("out.png");
    let spec = format!("command:cp '{}' {{out}}", src.display());
    let report =
        roomlight_camera::cli::capture(&spec, &out, Duration::from_secs(10)).expect("capture");
    assert_eq!((report.width, report.height, report.bits), (3, 2, 16));
    assert!(report.to_string().contains("not reported"), "{report}");
    let back = decode_file(&out, MAX).expect("written");
    assert_eq!(back.samples, Samples::Rgb16(vec![[1000, 2, 65535]; 6]));
    // A capture that times out is an error naming the camera.
    let err = roomlight_camera::cli::capture(
        &format!("folder:{}", dir.path().display()),
        &out,
        Duration::from_millis(200),
    )
    .expect_err("nothing new");
    assert!(matches!(err, CameraError::Timeout { .. }), "{err}");
    assert!(err.to_string().contains("folder:"), "{err}");
    // A folder that does not exist is gone, named.
    let missing = dir.path().join("missing");
    let err = roomlight_camera::cli::capture(
        &format!("folder:{}", missing.display()),
        &out,
        Duration::from_millis(200),
    )
    .expect_err("no folder");
    assert!(
        matches!(err, CameraError::Gone { .. }) && err.to_string().contains("missing"),
        "{err}"
    );
    assert!(
        roomlight_camera::cli::cameras()
            .expect("list")
            .contains("folder:DIR")
    );
}
