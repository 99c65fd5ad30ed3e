//! A physical room's survey: a real camera (`folder:`) and LEDs that only a person can switch
//! (`lights = "manual:DIR"`). The test plays the installer and the room: when the camera agent
//! asks (`DIR/lights-wanted`) it switches the room's "LEDs" and answers (`DIR/lights`), and when
//! the folder camera asks for a shot (`photos/.wanted`) it writes a photograph of the room as it
//! is lit now. The camera agent measures the room's black with the LEDs off and its target with
//! them on, asks for them off again (the projectors replace them), and serves.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;

/// The camera agent, killed and reaped on drop whatever happens in the test.
struct Agent(Child);

impl Drop for Agent {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The first stdout line that `pred` accepts, within `within`.
fn wait_line(rx: &mpsc::Receiver<String>, within: Duration, pred: impl Fn(&str) -> bool) -> String {
    let until = Instant::now() + within;
    let mut last = String::new();
    loop {
        let left = until.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) if pred(&line) => return line,
            Ok(line) => last = line,
            Err(e) => panic!("no such line within {within:?} ({e}); the last: {last}"),
        }
    }
}

/// A 16-bit linear photograph of a room lit uniformly at `level`, renamed into `dir` whole.
fn photograph(dir: &Path, n: u64, level: f64) {
    let code = (level * 65535.0).round() as u16;
    let image = image::ImageBuffer::<image::Rgb<u16>, _>::from_pixel(
        WIDTH,
        HEIGHT,
        image::Rgb([code, code, code]),
    );
    let tmp = dir.join(format!(".photo-{n}.png"));
    image.save(&tmp).expect("write the photograph");
    std::fs::rename(&tmp, dir.join(format!("photo-{n}.png"))).expect("rename the photograph");
}

/// The installer and the room until `stop`: answers each lights request after switching the
/// room (each request sent on `requests`, in order), and shoots each photograph asked for.
fn installer(dir: &Path, stop: &AtomicBool, requests: &mpsc::Sender<String>) {
    let (photos, lights) = (dir.join("photos"), dir.join("lights"));
    let (mut lit, mut handled, mut shot) = (false, String::new(), String::new());
    let deadline = Instant::now() + Duration::from_secs(120);
    while !stop.load(Ordering::Relaxed) && Instant::now() < deadline {
        let wanted = std::fs::read_to_string(lights.join("lights-wanted")).unwrap_or_default();
        // A request is handled once; the agent writes it again only for the next switch, which
        // always asks for the other state.
        if !wanted.is_empty() && wanted != handled {
            lit = wanted.trim() == "on";
            std::fs::write(lights.join("lights"), &wanted).expect("answer");
            let _ = requests.send(wanted.trim().to_string());
            handled = wanted;
        }
        let asked = std::fs::read_to_string(photos.join(".wanted")).unwrap_or_default();
        if !asked.is_empty() && asked != shot {
            let n = asked.trim().parse().unwrap_or(0);
            photograph(&photos, n, if lit { 0.5 } else { 0.01 });
            shot = asked;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_physical_rooms_survey_asks_a_person_for_the_leds_and_measures_the_room() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    std::fs::create_dir(d.join("photos")).expect("photos");
    std::fs::create_dir(d.join("lights")).expect("lights");
    std::fs::write(
        d.join("survey.json"),
        format!(
            r#"{{"camera_width":{WIDTH},"camera_height":{HEIGHT},
               "corners":[{{"name":"desk","corners":[[8,8],[56,8],[56,40],[8,40]]}}],
               "sample":{{"saturation":0.98,"read_noise":0.001,"shot_noise":0.004,"max_nonuniformity":0.2}},
               "target_pixels":[0,1,2]}}"#
        ),
    )
    .expect("survey");
    std::fs::write(
        d.join("camera.toml"),
        "room = \"office\"\ntoken = \"t\"\nlisten = \"127.0.0.1:0\"\nmdns = false\n\
         camera = { spec = \"folder:photos\", settle_ms = 0, timeout_s = 10 }\n\
         lights = \"manual:lights\"\nsurvey = \"survey.json\"\npreset = \"neutral\"\n\
         model_out = \"model.json\"\n",
    )
    .expect("camera config");

    let stop = Arc::new(AtomicBool::new(false));
    let (asked, requests) = mpsc::channel();
    let room = std::thread::spawn({
        let (d, stop) = (d.to_path_buf(), stop.clone());
        move || installer(&d, &stop, &asked)
    });
    let mut child = Command::new(env!("CARGO_BIN_EXE_roomlight"))
        .args(["camera", "--config", "camera.toml"])
        .current_dir(d)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the camera agent");
    let stdout = child.stdout.take().expect("piped stdout");
    let stderr = child.stderr.take().expect("piped stderr");
    let log = Arc::new(Mutex::new(String::new()));
    std::thread::spawn({
        let log = log.clone();
        move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                eprintln!("{line}");
                let mut log = log.lock().expect("log");
                log.push_str(&line);
                log.push('\n');
            }
        }
    });
    let _agent = Agent(child);
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });

    let survey = wait_line(&lines, Duration::from_secs(60), |l| {
        l.starts_with("survey:")
    });
    assert_eq!(
        survey, "survey: 24 of 24 patches measured, target from preset neutral",
        "every patch of the chart measured under both"
    );
    wait_line(&lines, Duration::from_secs(30), |l| {
        l.starts_with("camera listening on")
    });
    // Off for the black, on for the target, off again for the projectors to take over.
    let seen: Vec<String> = (0..3)
        .map(|_| {
            requests
                .recv_timeout(Duration::from_secs(10))
                .expect("a lights request answered")
        })
        .collect();
    stop.store(true, Ordering::Relaxed);
    room.join().expect("the installer thread");
    assert_eq!(seen, ["off", "on", "off"]);
    let shots = std::fs::read_dir(d.join("photos"))
        .expect("photos")
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.file_name().to_string_lossy().starts_with("photo-"))
        })
        .count();
    assert_eq!(
        shots, 2,
        "one photograph with the LEDs off, one with them on"
    );
    // The log says what to do, in plain text (no colour codes into a pipe or a file).
    let log = log.lock().expect("log").clone();
    assert!(
        log.contains("switch the room's LED lighting OFF")
            && log.contains("switch the room's LED lighting ON as for neutral")
            && log.contains("echo on > lights/lights"),
        "{log}"
    );
    assert!(
        !log.contains('\u{1b}'),
        "colour codes in a piped log: {log:?}"
    );
}
