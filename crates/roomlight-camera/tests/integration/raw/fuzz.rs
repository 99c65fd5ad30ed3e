//! Fuzzing the one decoder every camera's files go through (`frame::decode_bytes`) with bolero:
//! valid images of each kind a camera delivers (DNG in strips and in tiles behind a preview,
//! 8- and 16-bit PNG, JPEG, 16-bit TIFF), each changed by a generated list of byte edits and
//! cut at a generated length. Every outcome is an image whose pixels fill it within the cap, or
//! an error naming the file; never a panic or an allocation beyond the cap (the cap is 4 096
//! pixels here, so an allocation the header asked for would show as an abort).
//!
//! Under `cargo test` each target runs for a second of random inputs (`BOLERO_RANDOM_TEST_TIME_MS`
//! or `BOLERO_RANDOM_ITERATIONS` for longer runs; a failure prints its `BOLERO_RANDOM_SEED`);
//! `cargo bolero test` drives the same target with libFuzzer (docs/operations.md, Security).

use roomlight_camera::Samples;
use roomlight_camera::frame::decode_bytes;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

const MAX_PIXELS: u64 = 4096;

fn encoded(image: image::DynamicImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    image.write_to(&mut out, format).expect("encode");
    out.into_inner()
}

/// One valid file of each kind, a few hundred bytes each.
fn seeds() -> Vec<Vec<u8>> {
    let dir = tempfile::tempdir().expect("temp dir");
    let (strips, _) = super::strips_rggb(dir.path());
    let (tiles, _) = super::tiles_grbg(dir.path());
    let rgb8 = image::RgbImage::from_fn(9, 7, |x, y| image::Rgb([x as u8 * 20, y as u8 * 30, 7]));
    let rgb16 = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(5, 4, |x, y| {
        image::Rgb([x as u16 * 9000, y as u16 * 11000, 300])
    });
    vec![
        std::fs::read(strips).expect("read dng"),
        tiles,
        encoded(rgb8.clone().into(), image::ImageFormat::Png),
        encoded(rgb16.clone().into(), image::ImageFormat::Png),
        encoded(rgb8.into(), image::ImageFormat::Jpeg),
        encoded(rgb16.into(), image::ImageFormat::Tiff),
    ]
}

#[test]
fn fuzz_image_decoding_never_panics_and_stays_within_its_cap() {
    let seeds = seeds();
    let path = Path::new("/cameras/shot.img");
    // Decoded and refused inputs: a target that only ever saw one kind tested little.
    let (decoded, refused) = (AtomicU32::new(0), AtomicU32::new(0));
    bolero::check!()
        .with_type::<(u8, u16, Vec<(u16, u8)>)>()
        .for_each(|(which, cut, edits)| {
            let mut bytes = seeds[usize::from(*which) % seeds.len()].clone();
            for &(at, value) in edits {
                let i = usize::from(at) % bytes.len();
                bytes[i] = value;
            }
            // Most inputs keep their whole length; some are cut anywhere.
            if *cut < 4096 {
                bytes.truncate(usize::from(*cut) % (bytes.len() + 1));
            }
            match decode_bytes(path, bytes, MAX_PIXELS) {
                Ok(frame) => {
                    decoded.fetch_add(1, Relaxed);
                    let pixels = u64::from(frame.width) * u64::from(frame.height);
                    assert!(pixels <= MAX_PIXELS, "{pixels} pixels decoded past the cap");
                    let len = match &frame.samples {
                        Samples::Rgb8(p) => p.len(),
                        Samples::Rgb16(p) => p.len(),
                    };
                    assert_eq!(len as u64, pixels, "pixels that do not fill the frame");
                }
                Err(e) => {
                    refused.fetch_add(1, Relaxed);
                    assert!(e.to_string().contains("shot.img"), "unnamed: {e}");
                }
            }
        });
    assert!(
        decoded.load(Relaxed) > 0 && refused.load(Relaxed) > 0,
        "{decoded:?} decoded, {refused:?} refused"
    );
}
