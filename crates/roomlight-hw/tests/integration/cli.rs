//! `roomlight hw show` and `identify` under Xvfb: an image of the wrong size is refused with
//! both sizes named, one of the right size lands on its output pixel for pixel, and the
//! identify pattern goes on the output named.

use roomlight_hw::grab::Grabber;
use roomlight_hw::xvfb::Xvfb;
use roomlight_hw::{Geometry, OutputSelector, cli};
use std::time::{Duration, Instant};

const A: Geometry = Geometry {
    width: 320,
    height: 240,
    x: 0,
    y: 0,
};
const B: Geometry = Geometry {
    width: 160,
    height: 120,
    x: 320,
    y: 0,
};

fn screen() -> Xvfb {
    let x = Xvfb::start(480, 240).unwrap_or_else(|e| panic!("{e}"));
    x.add_output("A", A).expect("output A");
    x.add_output("B", B).expect("output B");
    x
}

fn wait_for(what: &str, mut check: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !check() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn show_refuses_the_wrong_size_and_shows_the_right_one() {
    let x = screen();
    let dir = tempfile::tempdir().expect("tempdir");
    let image = image::RgbImage::from_fn(160, 120, |i, j| image::Rgb([i as u8, j as u8, 200]));
    let path = dir.path().join("b.png");
    image.save(&path).expect("png");

    let on_a: OutputSelector = "A".parse().expect("A");
    let err = cli::open_image(Some(x.display()), &on_a, &path, false)
        .expect_err("a 160x120 image on a 320x240 output")
        .to_string();
    assert!(err.contains("160x120") && err.contains("320x240"), "{err}");

    let grabber = Grabber::connect(Some(x.display())).expect("grabber");
    let on_b: OutputSelector = "B".parse().expect("B");
    let _window = cli::open_image(Some(x.display()), &on_b, &path, false).expect("shown");
    wait_for("the image on B", || grabber.grab(B).expect("grab") == image);

    let _scaled = cli::open_image(Some(x.display()), &on_a, &path, true).expect("scaled");
    wait_for("the scaled image on A", || {
        grabber
            .grab(A)
            .expect("grab")
            .pixels()
            .any(|p| p.0[2] == 200)
    });
}

#[test]
fn displays_lists_outputs_and_identify_marks_every_one() {
    let x = screen();
    let listed = cli::displays(Some(x.display())).expect("displays");
    assert!(listed.lines().any(|l| l == "A 320x240 +0+0"), "{listed}");
    assert!(listed.lines().any(|l| l == "B 160x120 +320+0"), "{listed}");

    let grabber = Grabber::connect(Some(x.display())).expect("grabber");
    // Xvfb's own whole-screen output would cover both: each is identified by name.
    for (name, g) in [("A", A), ("B", B)] {
        let on: OutputSelector = name.parse().expect("selector");
        let _windows = cli::open_identify(Some(x.display()), Some(&on), "p7").expect("identify");
        let expected = roomlight_hw::identify::frame("p7", name, g.width, g.height);
        wait_for(name, || {
            let shot = grabber.grab(g).expect("grab");
            shot.pixels().map(|p| p.0).eq(expected.rgb.iter().copied())
        });
    }
}
