//! Real windows under Xvfb: two outputs on one virtual screen stand for two projectors; what a
//! `WindowDisplay` shows on one is read back pixel for pixel from a grab of the root window.
//! Each test starts its own Xvfb (and fails, saying `.ci/run` installs it, when there is none).

use roomlight_agent::hardware::{Assignment, Display, Fill, Gains, Pattern};
use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray, Primary};
use roomlight_calib::response::Response;
use roomlight_calib::shading::Ratios;
use roomlight_core::LinearRgb;
use roomlight_hw::frame::to_8bit;
use roomlight_hw::grab::Grabber;
use roomlight_hw::xvfb::Xvfb;
use roomlight_hw::{DisplayState, Geometry, OutputSelector, WindowDisplay, WindowSpec};
use std::time::{Duration, Instant};
use x11rb::connection::Connection;

const A: Geometry = Geometry {
    width: 320,
    height: 240,
    x: 0,
    y: 0,
};
const B: Geometry = Geometry {
    width: 320,
    height: 240,
    x: 320,
    y: 0,
};

/// A 640×240 screen with outputs `A` (left) and `B` (right).
fn two_projectors() -> Xvfb {
    let x = Xvfb::start(640, 240).unwrap_or_else(|e| panic!("{e}"));
    x.add_output("A", A).expect("output A");
    x.add_output("B", B).expect("output B");
    x
}

fn spec(x: &Xvfb, output: &str) -> WindowSpec {
    WindowSpec {
        x_display: Some(x.display().to_string()),
        output: output.parse().expect("selector"),
        settle: Duration::from_millis(5),
    }
}

/// Polls `check` until it holds or 10 s pass.
fn wait_for(what: &str, mut check: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !check() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .expect("runtime")
}

/// Waits up to 10 s for a state that `holds`.
fn wait_state(
    rt: &tokio::runtime::Runtime,
    state: &mut tokio::sync::watch::Receiver<DisplayState>,
    what: &str,
    holds: impl FnMut(&DisplayState) -> bool,
) -> DisplayState {
    let found = rt.block_on(async {
        tokio::time::timeout(Duration::from_secs(10), state.wait_for(holds))
            .await
            .map(|s| s.expect("the display's state").clone())
    });
    found.unwrap_or_else(|_| {
        panic!(
            "timed out waiting for the display to be {what}: {:?}",
            *state.borrow()
        )
    })
}

fn as_8bit(codes: &[[f32; 3]]) -> Vec<u8> {
    codes.iter().flat_map(|c| c.map(to_8bit)).collect()
}

#[test]
fn outputs_are_listed_and_chosen() {
    let x = two_projectors();
    let outputs = roomlight_hw::output::outputs(Some(x.display())).expect("outputs");
    for (name, g) in [("A", A), ("B", B)] {
        let o = outputs.iter().find(|o| o.name == name).expect(name);
        assert_eq!(o.geometry(), g);
    }
    let by_geometry: OutputSelector = "320x240+320+0".parse().expect("geometry");
    assert_eq!(by_geometry.pick(&outputs).expect("B").name, "B");
}

#[test]
fn a_pattern_and_node_values_land_on_their_output_pixel_for_pixel() {
    let x = two_projectors();
    let grabber = Grabber::connect(Some(x.display())).expect("grabber");
    let rt = runtime();
    let mut display = WindowDisplay::open(&spec(&x, "B"), "p1").expect("window on B");
    assert_eq!(display.resolution(), Some((320, 240)));

    let pattern = Pattern::everywhere(Fill::Structured {
        pattern: Gray::Bit {
            axis: Axis::Column,
            bit: 3,
            inverse: false,
        },
        coding: Coding::Xor04,
        cell: 2,
        primary: Some(Primary::Green),
    });
    let expected = as_8bit(&pattern.codes(320, 240).expect("codes"));
    // Stripes in green alone (a group coded in colour beside others): red and blue black.
    assert!(expected.chunks(3).all(|px| px[0] == 0 && px[2] == 0));
    assert!(expected.chunks(3).any(|px| px[1] == 255));
    assert!(expected.chunks(3).any(|px| px[1] == 0));
    assert!(display.show_pattern(pattern));
    rt.block_on(display.flush());
    // The frame is on the screen once flush resolves: no waiting here.
    assert_eq!(grabber.grab(B).expect("grab B").into_raw(), expected);
    assert!(
        grabber
            .grab(A)
            .expect("grab A")
            .into_raw()
            .iter()
            .all(|&c| c == 0),
        "A stays black"
    );

    // Two nodes: left half node 7 at full weight, right half node 9 at half weight; a
    // response with gamma 2.2 so that codes are not the values.
    let half = |right: bool| -> Vec<(u32, f32)> {
        (0..240u32)
            .flat_map(|y| {
                (0..160u32).map(move |x| {
                    (
                        y * 320 + x + if right { 160 } else { 0 },
                        if right { 0.5 } else { 1.0 },
                    )
                })
            })
            .collect()
    };
    let assignment = Assignment {
        width: 320,
        height: 240,
        response: Response {
            gamma: [2.2; 3],
            max_residual: [0.0; 3],
        },
        nodes: vec![(7, half(false)), (9, half(true))],
    };
    let values = [
        (7, LinearRgb([0.25, 0.5, 0.75])),
        (9, LinearRgb([1.0, 0.1, 0.3])),
    ];
    display.assign(&assignment);
    for (n, v) in values {
        display.show(n, v);
    }
    rt.block_on(display.flush());
    let expected = as_8bit(&assignment.draw(&values));
    assert_eq!(grabber.grab(B).expect("grab B").into_raw(), expected);
    assert!(
        grabber
            .grab(A)
            .expect("grab A")
            .into_raw()
            .iter()
            .all(|&c| c == 0),
        "A stays black"
    );

    // Per-pixel shading: gains stepped by a Shade's ratios (blue halved on the left blocks,
    // red doubled on the right) are drawn on the screen as `draw_shaded` draws them; none
    // again brings the nodes' own light back.
    let (across, down) = (320usize.div_ceil(16), 240usize.div_ceil(16));
    let blocks = (0..across * down)
        .map(|b| {
            Some(if b % across < across / 2 {
                [1.0, 1.0, 0.5]
            } else {
                [2.0, 1.0, 1.0]
            })
        })
        .collect();
    let ratios = Ratios::from_blocks(320, 240, blocks).expect("ratios");
    let mut gains = Gains::flat(320, 240).expect("gains");
    gains.step(&ratios, 1.0).expect("step");
    display.shade(Some(&gains));
    rt.block_on(display.flush());
    let shaded = as_8bit(&assignment.draw_shaded(&values, Some(&gains)));
    assert_ne!(shaded, expected, "the gains change the frame");
    assert_eq!(grabber.grab(B).expect("grab B").into_raw(), shaded);
    display.shade(None);
    rt.block_on(display.flush());
    assert_eq!(grabber.grab(B).expect("grab B").into_raw(), expected);
    assert!(matches!(display.state(), DisplayState::Showing { output, .. } if output.name == "B"));
}

/// The window id of the roomlight window titled `title`.
fn find_window(display: &str, title: &str) -> u32 {
    use x11rb::protocol::xproto::{AtomEnum, ConnectionExt};
    let (conn, screen) = x11rb::connect(Some(display)).expect("connect");
    let root = conn.setup().roots[screen].root;
    let children = conn
        .query_tree(root)
        .expect("tree")
        .reply()
        .expect("tree")
        .children;
    children
        .into_iter()
        .find(|&w| {
            conn.get_property(false, w, AtomEnum::WM_NAME, AtomEnum::STRING, 0, 64)
                .ok()
                .and_then(|c| c.reply().ok())
                .is_some_and(|p| p.value == title.as_bytes())
        })
        .unwrap_or_else(|| panic!("no window titled {title}"))
}

fn lost_then_back(close: impl FnOnce(&Xvfb, u32), why: &str, restore: impl FnOnce(&Xvfb)) {
    let x = two_projectors();
    let grabber = Grabber::connect(Some(x.display())).expect("grabber");
    let rt = runtime();
    let mut display = WindowDisplay::open(&spec(&x, "A"), "p2").expect("window on A");
    display.show_pattern(Pattern::everywhere(Fill::Uniform([0.5, 0.25, 1.0])));
    rt.block_on(display.flush());
    let shown = grabber.grab(A).expect("grab").into_raw();
    assert!(shown.chunks(3).all(|p| p == [128, 64, 255]));

    let mut state = display.watch();
    close(&x, find_window(x.display(), "roomlight p2"));
    // Lost, or already back from it (the first reopen comes after 100 ms, which a loaded
    // machine may take to look): either way the reason is kept.
    let lost = wait_state(&rt, &mut state, "lost", |s| match s {
        DisplayState::Lost { .. } => true,
        DisplayState::Showing { losses, .. } => *losses > 0,
    });
    let reason = match lost {
        DisplayState::Lost { reason, .. } => reason,
        DisplayState::Showing { last_loss, .. } => last_loss.unwrap_or_default(),
    };
    assert!(reason.contains(why), "{reason}");
    restore(&x);
    wait_state(&rt, &mut state, "back", |s| {
        matches!(s, DisplayState::Showing { losses: 1, .. })
    });
    wait_for("the frame shown again", || {
        grabber.grab(A).expect("grab").into_raw() == shown
    });
}

#[test]
fn a_window_destroyed_from_outside_is_lost_and_comes_back() {
    lost_then_back(
        |x, window| {
            use x11rb::protocol::xproto::ConnectionExt;
            let (conn, _) = x11rb::connect(Some(x.display())).expect("connect");
            // Checked: a connection closed right after its request may be dropped unread.
            conn.destroy_window(window)
                .expect("destroy")
                .check()
                .expect("destroyed");
        },
        "closed",
        |_| {},
    );
}

#[test]
fn a_killed_client_is_lost_and_comes_back() {
    lost_then_back(
        |x, window| {
            use x11rb::protocol::xproto::ConnectionExt;
            let (conn, _) = x11rb::connect(Some(x.display())).expect("connect");
            conn.kill_client(window)
                .expect("kill")
                .check()
                .expect("killed");
        },
        "connection",
        |_| {},
    );
}

#[test]
fn an_output_that_goes_away_is_lost_and_comes_back() {
    lost_then_back(
        |x, _| x.remove_output("A").expect("remove A"),
        "gone",
        |x| x.add_output("A", A).expect("A again"),
    );
}
