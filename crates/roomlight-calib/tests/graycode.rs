//! Gray-code decoding against the simulator's true correspondence.

mod common;

use common::pattern_captures;

use roomlight_calib::graycode::{
    DecodeConfig, Manifest, bits_for, decode, gray, gray_inverse, group_disjoint,
};
use roomlight_sim::{Room, scenes};

#[test]
fn gray_code_round_trips_and_neighbours_differ_in_one_bit() {
    use roomlight_calib::graycode::{Axis, Coding, Pattern};
    for v in 0..5000u32 {
        assert_eq!(gray_inverse(gray(v)), v);
        assert_eq!((gray(v) ^ gray(v + 1)).count_ones(), 1);
    }
    assert_eq!(
        (
            bits_for(1),
            bits_for(2),
            bits_for(1024),
            bits_for(1025),
            bits_for(768)
        ),
        (1, 1, 10, 11, 10)
    );
    for coding in [Coding::Gray, Coding::Xor04] {
        let m = Manifest::with_coding(100, 30, coding).expect("manifest");
        assert_eq!(m.patterns.len(), 2 + 2 * (7 + 5));
        // Each column's bits, read back from the patterns (and XOR-ed with the base bit when the
        // coding says so), give its Gray code; every inverse is the complement.
        let base = m.base_bit(m.column_bits);
        for x in [0u32, 1, 37, 99] {
            let read = |bit: u32, inverse: bool| {
                m.pattern_values(Pattern::Bit {
                    axis: Axis::Column,
                    bit,
                    inverse,
                })[(5 * 100 + x) as usize] as u32
            };
            let mut code = 0;
            for bit in 0..m.column_bits {
                let v = match base {
                    Some(b) if b != bit => read(bit, false) ^ read(b, false),
                    _ => read(bit, false),
                };
                code = (code << 1) | v;
                assert_eq!(read(bit, true), 1 - read(bit, false));
            }
            assert_eq!(gray_inverse(code), x, "{coding:?}");
        }
    }
    // XOR-04 patterns are all high-frequency: no stripe wider than 4 pixels.
    let m = Manifest::new(256, 4).expect("manifest");
    for bit in 0..m.column_bits {
        let v = m.pattern_values(Pattern::Bit {
            axis: Axis::Column,
            bit,
            inverse: false,
        });
        let longest = v[..256]
            .chunk_by(|a, b| (a > &0.5) == (b > &0.5))
            .map(<[f32]>::len)
            .max()
            .unwrap_or(0);
        assert!(longest <= 4, "bit {bit}: a stripe of {longest} pixels");
    }
}

/// (share of reached pixels decoded within ±1, share of decoded pixels off by more than 2).
fn accuracy(
    room: &Room,
    k: usize,
    decoded: &roomlight_calib::graycode::Correspondence,
) -> (f64, f64, usize) {
    let truth = room.true_correspondence(k);
    let pw = room.projectors()[k].pinhole.width;
    let (mut reached, mut close, mut decoded_n, mut far) = (0usize, 0usize, 0usize, 0usize);
    for (t, d) in truth.iter().zip(&decoded.map) {
        let off = |t: u32, (x, y): (u32, u32)| {
            (i64::from(x) - i64::from(t % pw))
                .abs()
                .max((i64::from(y) - i64::from(t / pw)).abs())
        };
        if let Some(t) = t {
            reached += 1;
            if d.is_some_and(|d| off(*t, d) <= 1) {
                close += 1;
            }
        }
        if let Some(d) = d {
            decoded_n += 1;
            if t.is_none_or(|t| off(t, *d) > 2) {
                far += 1;
            }
        }
    }
    (
        close as f64 / reached.max(1) as f64,
        far as f64 / decoded_n.max(1) as f64,
        reached,
    )
}

#[test]
fn standard_projectors_decode_within_a_pixel_under_interreflection_noise_and_ambient_light() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let ambient = Some(room.preset("on").expect("preset"));
    use roomlight_calib::graycode::Coding;
    for (k, coding) in [(0, Coding::Xor04), (1, Coding::Xor04), (0, Coding::Gray)] {
        let p = &room.projectors()[k].pinhole;
        let manifest = Manifest::with_coding(p.width, p.height, coding).expect("manifest");
        let caps = pattern_captures(&room, k, &manifest, ambient, 1);
        let decoded = decode(&manifest, &DecodeConfig::default(), |f| {
            let i = manifest
                .patterns
                .iter()
                .position(|p| p.file == f.file)
                .expect("pattern");
            Ok(&caps[i])
        })
        .expect("decode");
        let (close, far, reached) = accuracy(&room, k, &decoded);
        assert!(reached > 1000, "projector {k} reaches {reached} pixels");
        assert!(
            close >= 0.98,
            "projector {k}: {:.2}% within ±1",
            100.0 * close
        );
        assert!(
            far <= 0.001,
            "projector {k}: {:.3}% off by more than 2",
            100.0 * far
        );
    }
}

#[test]
fn disjoint_footprints_share_captures() {
    let a = vec![true, true, false, false];
    let b = vec![false, false, true, false];
    let c = vec![false, true, false, true];
    assert_eq!(group_disjoint(&[a, b, c]), vec![vec![0, 1], vec![2]]);
}
