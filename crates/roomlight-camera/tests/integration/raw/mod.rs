//! RAW shots as DNG and 16-bit TIFF, decoded to linear light through `decode_file` (the path
//! every backend's files take). The DNGs are written here by a small TIFF writer of the test's
//! own, independent of the decoder's reader, with known sensor values, black and white levels.

mod fuzz;

use roomlight_camera::frame::decode_file;
use roomlight_camera::{CameraError, Samples};
use std::path::Path;

/// A directory entry's values, as TIFF types.
enum V {
    Byte(Vec<u8>),
    Short(Vec<u16>),
    Long(Vec<u32>),
    Rational(Vec<(u32, u32)>),
}

/// A TIFF under construction: sections appended, offsets known as they are written.
struct Writer {
    buf: Vec<u8>,
    big: bool,
}

impl Writer {
    fn new(big: bool) -> Self {
        let mut w = Self {
            buf: Vec::new(),
            big,
        };
        w.buf
            .extend_from_slice(if big { b"MM\0*" } else { b"II*\0" });
        w.u32(0);
        w
    }
    fn u16(&mut self, v: u16) {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.buf.extend_from_slice(&b);
    }
    fn u32(&mut self, v: u32) {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.buf.extend_from_slice(&b);
    }
    fn align(&mut self) {
        if self.buf.len() % 2 == 1 {
            self.buf.push(0);
        }
    }
    /// 16-bit samples (or 8-bit with `eight`) as one blob; its offset.
    fn samples(&mut self, values: &[u16], eight: bool) -> u32 {
        self.align();
        let at = self.buf.len() as u32;
        for &v in values {
            if eight {
                self.buf.push(v as u8);
            } else {
                self.u16(v);
            }
        }
        at
    }
    fn encode(&self, v: &V) -> (u16, u32, Vec<u8>) {
        let mut out = Vec::new();
        let put16 = |x: u16, out: &mut Vec<u8>| {
            out.extend_from_slice(&if self.big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            })
        };
        let put32 = |x: u32, out: &mut Vec<u8>| {
            out.extend_from_slice(&if self.big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            })
        };
        match v {
            V::Byte(b) => (1, b.len() as u32, b.clone()),
            V::Short(s) => {
                s.iter().for_each(|&x| put16(x, &mut out));
                (3, s.len() as u32, out)
            }
            V::Long(l) => {
                l.iter().for_each(|&x| put32(x, &mut out));
                (4, l.len() as u32, out)
            }
            V::Rational(r) => {
                for &(n, d) in r {
                    put32(n, &mut out);
                    put32(d, &mut out);
                }
                (5, r.len() as u32, out)
            }
        }
    }
    /// A directory (entries sorted by tag), its long values after it; its offset.
    fn ifd(&mut self, mut entries: Vec<(u16, V)>) -> u32 {
        entries.sort_by_key(|(t, _)| *t);
        self.align();
        let at = self.buf.len();
        let n = entries.len();
        let mut extra = at + 2 + 12 * n + 4;
        let mut tail = Vec::new();
        self.u16(n as u16);
        for (tag, v) in &entries {
            let (kind, count, bytes) = self.encode(v);
            self.u16(*tag);
            self.u16(kind);
            self.u32(count);
            if bytes.len() <= 4 {
                let mut b = bytes.clone();
                b.resize(4, 0);
                self.buf.extend_from_slice(&b);
            } else {
                self.u32(extra as u32);
                extra += bytes.len() + bytes.len() % 2;
                tail.extend_from_slice(&bytes);
                if bytes.len() % 2 == 1 {
                    tail.push(0);
                }
            }
        }
        self.u32(0);
        self.buf.extend_from_slice(&tail);
        at as u32
    }
    fn finish(mut self, first: u32) -> Vec<u8> {
        let b = if self.big {
            first.to_be_bytes()
        } else {
            first.to_le_bytes()
        };
        self.buf[4..8].copy_from_slice(&b);
        self.buf
    }
}

/// The sensor value that means `linear` between `black` and `white`.
fn sensor(linear: f64, black: f64, white: f64) -> u16 {
    (black + linear * (white - black)).round() as u16
}

fn rgb16(path: &Path, max_pixels: u64) -> Result<(u32, u32, Vec<[u16; 3]>), CameraError> {
    let frame = decode_file(path, max_pixels)?;
    match frame.samples {
        Samples::Rgb16(p) => Ok((frame.width, frame.height, p)),
        Samples::Rgb8(_) => panic!("a RAW or 16-bit file decoded as 8-bit"),
    }
}

fn assert_close(got: &[[u16; 3]], want: &[[f64; 3]]) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        for c in 0..3 {
            let expected = w[c] * 65535.0;
            // One sensor code of rounding over the white-black range, in 16-bit units.
            assert!(
                (f64::from(g[c]) - expected).abs() <= 8.0,
                "got {g:?}, want {:?}",
                w.map(|v| v * 65535.0)
            );
        }
    }
}

/// Little-endian, RAW in the first directory, two strips, RGGB, a 2×2 black-level pattern as
/// rationals and an active area that crops two columns: 2×2 developed pixels.
fn strips_rggb(dir: &Path) -> (std::path::PathBuf, Vec<[f64; 3]>) {
    let black = [500.0, 510.0, 520.0, 530.0];
    let white = 16383.0;
    // Developed pixels' linear values (red, green, blue); green is the mean of two sites
    // given as g ± 0.05. One red clips above white, one blue sits below black.
    let want = [
        [0.1, 0.2, 0.3],
        [0.9, 0.5, 0.05],
        [0.25, 0.75, 0.0],
        [1.0, 0.4, 0.6],
    ];
    let (w, h) = (6usize, 4usize);
    let mut values = vec![7u16; w * h]; // the cropped columns hold junk
    for (i, px) in want.iter().enumerate() {
        let (tx, ty) = (i % 2, i / 2);
        let site = |dx: usize, dy: usize| (2 * ty + dy) * w + 2 + 2 * tx + dx;
        let b = |dx: usize, dy: usize| black[dy * 2 + dx];
        values[site(0, 0)] = sensor(px[0], b(0, 0), white);
        values[site(1, 0)] = sensor(px[1] + 0.05, b(1, 0), white);
        values[site(0, 1)] = sensor(px[1] - 0.05, b(0, 1), white);
        values[site(1, 1)] = sensor(px[2], b(1, 1), white);
    }
    // Pixel 3's red site above white reads 1, pixel 2's blue site below black reads 0.
    values[2 * w + 4] = white as u16 + 200;
    values[3 * w + 3] = 430;
    let mut t = Writer::new(false);
    let s0 = t.samples(&values[..2 * w], false);
    let s1 = t.samples(&values[2 * w..], false);
    let ifd = t.ifd(vec![
        (50706, V::Byte(vec![1, 4, 0, 0])),
        (254, V::Long(vec![0])),
        (256, V::Long(vec![w as u32])),
        (257, V::Long(vec![h as u32])),
        (258, V::Short(vec![16])),
        (259, V::Short(vec![1])),
        (262, V::Short(vec![32803])),
        (273, V::Long(vec![s0, s1])),
        (277, V::Short(vec![1])),
        (278, V::Short(vec![2])),
        (279, V::Long(vec![(4 * w) as u32; 2])),
        (33421, V::Short(vec![2, 2])),
        (33422, V::Byte(vec![0, 1, 1, 2])),
        (50713, V::Short(vec![2, 2])),
        (
            50714,
            V::Rational(black.iter().map(|&b| ((b * 2.0) as u32, 2)).collect()),
        ),
        (50717, V::Long(vec![white as u32])),
        (50829, V::Long(vec![0, 2, 4, 6])),
        (33434, V::Rational(vec![(1, 30)])),
    ]);
    let path = dir.join("strips.dng");
    std::fs::write(&path, t.finish(ifd)).expect("write dng");
    (path, want.to_vec())
}

#[test]
fn a_dng_is_developed_linear_through_its_black_and_white_levels() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (path, want) = strips_rggb(dir.path());
    let (w, h, got) = rgb16(&path, 1 << 20).expect("decodes");
    assert_eq!((w, h), (2, 2));
    assert_close(&got, &want);
    let frame = decode_file(&path, 1 << 20).expect("decodes");
    let exposure = frame.exposure_s.expect("the DNG's ExposureTime");
    assert!((exposure - 1.0 / 30.0).abs() < 1e-9, "{exposure}");
}

/// Big-endian; the first directory is an 8-bit RGB preview and the RAW is in a SubIFD, in
/// 4×4 tiles over a 6×6 image (edge tiles padded), GRBG, 8-bit stored values through a
/// linearisation table, the shot's settings in an EXIF directory.
fn tiles_grbg(dir: &Path) -> (Vec<u8>, Vec<[f64; 3]>) {
    let (black, white) = (64.0, 2000.0);
    // Stored value v means 8·v on the sensor: 255 stored values reach 2040 ≥ white.
    let table: Vec<u16> = (0..256).map(|v| 8 * v).collect();
    let (w, h) = (6usize, 6usize);
    let mut want = Vec::new();
    let mut sensor_values = vec![0u16; w * h];
    for ty in 0..3 {
        for tx in 0..3 {
            let px = [
                0.1 + 0.1 * tx as f64,
                0.3 + 0.1 * ty as f64,
                0.8 - 0.2 * tx as f64,
            ];
            // GRBG: green, red / blue, green. Stored values are quantised to the table's step,
            // so the expected linear values are those of the stored codes.
            let stored = |lin: f64| (sensor(lin, black, white) as f64 / 8.0).round() as u16;
            let back = |code: u16| (f64::from(8 * code) - black) / (white - black);
            let (g, r, b) = (stored(px[1]), stored(px[0]), stored(px[2]));
            let at = |dx: usize, dy: usize| (2 * ty + dy) * w + 2 * tx + dx;
            sensor_values[at(0, 0)] = g;
            sensor_values[at(1, 0)] = r;
            sensor_values[at(0, 1)] = b;
            sensor_values[at(1, 1)] = g;
            want.push([back(r), back(g), back(b)]);
        }
    }
    let mut t = Writer::new(true);
    // Tiles of 4×4 in row order; those past the image's edge padded with 255s.
    let mut tile_offsets = Vec::new();
    for (ty, tx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
        let tile: Vec<u16> = (0..16)
            .map(|i| {
                let (x, y) = (4 * tx + i % 4, 4 * ty + i / 4);
                if x < w && y < h {
                    sensor_values[y * w + x]
                } else {
                    255
                }
            })
            .collect();
        tile_offsets.push(t.samples(&tile, true));
    }
    let raw = t.ifd(vec![
        (254, V::Long(vec![0])),
        (256, V::Short(vec![w as u16])),
        (257, V::Short(vec![h as u16])),
        (258, V::Short(vec![8])),
        (259, V::Short(vec![1])),
        (262, V::Short(vec![32803])),
        (277, V::Short(vec![1])),
        (322, V::Short(vec![4])),
        (323, V::Short(vec![4])),
        (324, V::Long(tile_offsets)),
        (325, V::Long(vec![16; 4])),
        (33421, V::Short(vec![2, 2])),
        (33422, V::Byte(vec![1, 0, 2, 1])),
        (50712, V::Short(table)),
        (50714, V::Short(vec![black as u16])),
        (50717, V::Short(vec![white as u16])),
    ]);
    let exif = t.ifd(vec![
        (33434, V::Rational(vec![(1, 125)])),
        (33437, V::Rational(vec![(56, 10)])),
        (34855, V::Short(vec![200])),
    ]);
    let preview = t.samples(&[200; 3 * 4], true);
    let first = t.ifd(vec![
        (254, V::Long(vec![1])),
        (256, V::Short(vec![2])),
        (257, V::Short(vec![2])),
        (258, V::Short(vec![8, 8, 8])),
        (259, V::Short(vec![1])),
        (262, V::Short(vec![2])),
        (273, V::Long(vec![preview])),
        (277, V::Short(vec![3])),
        (279, V::Long(vec![12])),
        (330, V::Long(vec![raw])),
        (34665, V::Long(vec![exif])),
        (50706, V::Byte(vec![1, 6, 0, 0])),
    ]);
    let bytes = t.finish(first);
    std::fs::write(dir.join("tiles.dng"), &bytes).expect("write dng");
    (bytes, want)
}

#[test]
fn a_big_endian_tiled_dng_in_a_sub_ifd_is_found_linearised_and_developed() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, want) = tiles_grbg(dir.path());
    let path = dir.path().join("tiles.dng");
    let (w, h, got) = rgb16(&path, 1 << 20).expect("decodes");
    assert_eq!((w, h), (3, 3), "the RAW, not the 2×2 preview");
    assert_close(&got, &want);
    let shot = decode_file(&path, 1 << 20)
        .expect("decodes")
        .shot
        .expect("EXIF");
    assert!((shot.exposure_s.expect("exposure") - 1.0 / 125.0).abs() < 1e-9);
    assert!((shot.f_number.expect("f-number") - 5.6).abs() < 1e-9);
    assert_eq!(shot.iso, Some(200));
}

/// Writes `bytes` and decodes them: the error's text, or "ok".
fn outcome(path: &Path, bytes: &[u8], max_pixels: u64) -> String {
    std::fs::write(path, bytes).expect("write");
    match decode_file(path, max_pixels) {
        Ok(_) => "ok".into(),
        Err(e) => e.to_string(),
    }
}

/// Replaces the first occurrence of entry `tag`'s (type, count, value) in a little-endian
/// directory with `value` as one SHORT.
fn patch_short(bytes: &mut [u8], tag: u16, value: u16) {
    let at = bytes
        .windows(4)
        .position(|w| w[..2] == tag.to_le_bytes() && w[2..] == 3u16.to_le_bytes())
        .expect("the tag is there as a SHORT");
    bytes[at + 8..at + 10].copy_from_slice(&value.to_le_bytes());
}

#[test]
fn bad_dngs_are_refused_with_the_reason_and_never_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (path, _) = strips_rggb(dir.path());
    let good = std::fs::read(&path).expect("read");
    let probe = dir.path().join("probe.dng");

    let mut compressed = good.clone();
    patch_short(&mut compressed, 259, 7);
    let e = outcome(&probe, &compressed, 1 << 20);
    assert!(e.contains("strips.dng") || e.contains("probe.dng"), "{e}");
    assert!(
        e.contains("compression 7") && e.contains("lossless JPEG"),
        "{e}"
    );

    let mut packed = good.clone();
    patch_short(&mut packed, 258, 12);
    assert!(outcome(&probe, &packed, 1 << 20).contains("BitsPerSample [12]"));

    // Two developed pixels allowed, four there: refused before any sample is read.
    let e = outcome(&probe, &good, 2);
    assert!(e.contains("refused before decoding"), "{e}");

    // Cut anywhere, or any byte changed: an error or an image, never a panic.
    for len in 0..good.len() {
        let _ = outcome(&probe, &good[..len], 1 << 20);
    }
    let truncated = outcome(&probe, &good[..good.len() - 10], 1 << 20);
    assert!(truncated.contains("past the file's end"), "{truncated}");
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    for _ in 0..3000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let mut bytes = good.clone();
        let i = (state % bytes.len() as u64) as usize;
        bytes[i] = (state >> 32) as u8;
        let _ = outcome(&probe, &bytes, 1 << 20);
    }
}

#[test]
fn a_camera_raw_that_is_not_dng_is_refused_not_read_as_its_preview() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (mut bytes, _) = tiles_grbg(dir.path());
    // Without its DNGVersion the file is a NEF-like TIFF: a preview first, the RAW in a SubIFD.
    let tag = bytes
        .windows(2)
        .rposition(|w| w == 50706u16.to_be_bytes())
        .expect("DNGVersion entry");
    bytes[tag..tag + 2].copy_from_slice(&50000u16.to_be_bytes());
    let e = outcome(&dir.path().join("shot.nef"), &bytes, 1 << 20);
    assert!(e.contains("shot.nef") && e.contains("not DNG"), "{e}");
}

#[test]
fn a_16_bit_tiff_is_read_linear_as_it_is() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("linear.tif");
    let values: Vec<u16> = (0..4 * 3 * 3).map(|i| (i * 1800) as u16).collect();
    image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(4, 3, values.clone())
        .expect("buffer")
        .save(&path)
        .expect("write tiff");
    let (w, h, got) = rgb16(&path, 1 << 20).expect("decodes");
    assert_eq!((w, h), (4, 3));
    assert_eq!(got.into_iter().flatten().collect::<Vec<_>>(), values);
}
