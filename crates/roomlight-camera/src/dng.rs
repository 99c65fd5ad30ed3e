//! RAW shots as DNG (Adobe's open RAW format, a TIFF) decoded to linear light: the sensor's
//! values through the file's linearisation table, less its black levels, over its white level,
//! as 16-bit linear RGB. It must not know response curves or masks (radiometry.rs flags what
//! is saturated).
//!
//! Hand-written, with a small TIFF directory reader of its own, because no crate does this job
//! under the project's licence: the `tiff` crate refuses a colour-filter-array image
//! (photometric 32803) and does not decode images in SubIFDs, where DNG keeps its RAW data;
//! rawloader and rawler, which do, are LGPL-2.1, which a statically linked MIT/Apache binary
//! cannot simply take.
//!
//! What is decoded: uncompressed DNG (compression 1), 8- or 16-bit samples, in strips or tiles,
//! either a 2×2 Bayer colour filter array (one red, two green, one blue, any phase) or
//! `LinearRaw` RGB; `LinearizationTable`, `BlackLevel` with its repeat pattern and per-row and
//! per-column deltas, `WhiteLevel` and `ActiveArea` are applied. A Bayer image is developed by
//! 2×2 superpixels (red, the mean of the two greens, blue): half the resolution, no
//! interpolation, so every output value is a linear combination of sensor values of one place.
//! Colours are the camera's own primaries, not white-balanced: the same camera measures both the
//! reference lighting and the projectors, so a fixed linear space is all the optimiser needs.
//! Compressed DNG (lossless JPEG, compression 7) and packed 10/12/14-bit samples are refused
//! with the reason; docs/hardware.md says how to save uncompressed DNG.

use crate::error::CameraError;
use crate::exif::Shot;
use crate::frame::{Frame, Samples};
use std::path::Path;

const DNG_VERSION: u16 = 50706;
const NEW_SUBFILE_TYPE: u16 = 254;
const WIDTH: u16 = 256;
const HEIGHT: u16 = 257;
const BITS: u16 = 258;
const COMPRESSION: u16 = 259;
const PHOTOMETRIC: u16 = 262;
const STRIP_OFFSETS: u16 = 273;
const SAMPLES_PER_PIXEL: u16 = 277;
const ROWS_PER_STRIP: u16 = 278;
const STRIP_BYTES: u16 = 279;
const PLANAR: u16 = 284;
const TILE_WIDTH: u16 = 322;
const TILE_LENGTH: u16 = 323;
const TILE_OFFSETS: u16 = 324;
const TILE_BYTES: u16 = 325;
const SUB_IFDS: u16 = 330;
const CFA_REPEAT: u16 = 33421;
const CFA_PATTERN: u16 = 33422;
const CFA_LAYOUT: u16 = 50711;
const LINEARIZATION: u16 = 50712;
const BLACK_REPEAT: u16 = 50713;
const BLACK_LEVEL: u16 = 50714;
const BLACK_DELTA_H: u16 = 50715;
const BLACK_DELTA_V: u16 = 50716;
const WHITE_LEVEL: u16 = 50717;
const ACTIVE_AREA: u16 = 50829;
const EXPOSURE_TIME: u16 = 33434;
const F_NUMBER: u16 = 33437;
const ISO: u16 = 34855;

const PHOTOMETRIC_CFA: u64 = 32803;
const PHOTOMETRIC_LINEAR_RAW: u64 = 34892;
/// Directory entries read per IFD and SubIFDs looked at: far above any real DNG, and a bound
/// on what a hostile file can make us walk.
const MAX_ENTRIES: usize = 4096;
const MAX_SUB_IFDS: usize = 16;
const MAX_TILE: u64 = 1 << 14;

/// Whether `data` is a DNG: a TIFF header whose first directory has a `DNGVersion` tag.
pub(crate) fn is_dng(data: &[u8]) -> bool {
    Tiff::new(data)
        .and_then(|t| t.ifd(t.first_ifd()?))
        .is_ok_and(|ifd| ifd.get(DNG_VERSION).is_some())
}

/// Why a TIFF that is not a DNG must not be read as an image: camera RAW files (NEF, ARW, ...)
/// are TIFFs whose first directory is a reduced-resolution preview or points to SubIFDs;
/// decoding it would silently give a small 8-bit preview instead of the shot.
pub(crate) fn foreign_raw(data: &[u8]) -> Option<String> {
    let tiff = Tiff::new(data).ok()?;
    let first = tiff.ifd(tiff.first_ifd().ok()?).ok()?;
    let preview = tiff
        .uint(&first, NEW_SUBFILE_TYPE)
        .ok()?
        .is_some_and(|t| t & 1 == 1);
    (preview || first.get(SUB_IFDS).is_some()).then(|| {
        "a camera RAW file that is not DNG (its first image is a preview): shoot JPEG or DNG, \
         or develop it linear to a 16-bit PNG or TIFF with a command: camera"
            .into()
    })
}

/// The shot's settings as TIFF/EP writes them, in the first directory (`ExposureTime`,
/// `FNumber`, ISO), for DNGs that keep them there rather than in an EXIF directory.
pub(crate) fn tiff_ep_shot(data: &[u8]) -> Shot {
    let read = || -> Result<Shot, String> {
        let tiff = Tiff::new(data)?;
        let first = tiff.ifd(tiff.first_ifd()?)?;
        let real = |tag| -> Option<f64> {
            let value = tiff.reals(first.get(tag)?).ok()?.first().copied()?;
            value.is_finite().then_some(value)
        };
        Ok(Shot {
            exposure_s: real(EXPOSURE_TIME),
            iso: real(ISO)
                .and_then(|v| (0.0..=f64::from(u32::MAX)).contains(&v).then_some(v as u32)),
            f_number: real(F_NUMBER),
        })
    };
    read().unwrap_or_default()
}

/// Decodes a DNG's RAW image to linear 16-bit RGB (0 = black level, 65535 = white level),
/// refusing it before reading any sample when the developed image has more than `max_pixels`
/// pixels. Errors name the file and what in it was not as expected.
pub(crate) fn decode(path: &Path, data: &[u8], max_pixels: u64) -> Result<Frame, CameraError> {
    decode_raw(data, max_pixels).map_err(|reason| CameraError::Decode {
        path: path.to_path_buf(),
        reason: format!("DNG: {reason}"),
    })
}

fn decode_raw(data: &[u8], max_pixels: u64) -> Result<Frame, String> {
    let tiff = Tiff::new(data)?;
    let raw = raw_ifd(&tiff)?;
    let image = RawImage::read(&tiff, &raw, max_pixels)?;
    let levels = Levels::read(&tiff, &raw, &image)?;
    let (width, height, pixels) = if image.samples == 1 {
        let bayer = Bayer::read(&tiff, &raw)?;
        develop_bayer(&image, &levels, &bayer)?
    } else {
        develop_linear(&image, &levels)?
    };
    Ok(Frame {
        width,
        height,
        samples: Samples::Rgb16(pixels),
        exposure_s: None,
        shot: None,
    })
}

/// The directory holding the full-resolution RAW image: the first directory, or one of its
/// SubIFDs, whose `NewSubfileType` is 0 and whose photometric is CFA or `LinearRaw`.
fn raw_ifd(tiff: &Tiff) -> Result<Ifd, String> {
    let first = tiff.ifd(tiff.first_ifd()?)?;
    if first.get(DNG_VERSION).is_none() {
        return Err("no DNGVersion tag: not a DNG".into());
    }
    let is_raw = |ifd: &Ifd| -> Result<bool, String> {
        let main = tiff.uint(ifd, NEW_SUBFILE_TYPE)?.unwrap_or(0) == 0;
        let photometric = tiff.uint(ifd, PHOTOMETRIC)?;
        Ok(main && matches!(photometric, Some(PHOTOMETRIC_CFA | PHOTOMETRIC_LINEAR_RAW)))
    };
    if is_raw(&first)? {
        return Ok(first);
    }
    let subs = match first.get(SUB_IFDS) {
        Some(e) => tiff.uints(e)?,
        None => Vec::new(),
    };
    for &offset in subs.iter().take(MAX_SUB_IFDS) {
        let sub = tiff.ifd(offset)?;
        if is_raw(&sub)? {
            return Ok(sub);
        }
    }
    Err("no full-resolution RAW image (NewSubfileType 0, photometric CFA or LinearRaw)".into())
}

/// The RAW samples of the active area, row-major, `samples` per pixel, as stored.
struct RawImage {
    width: usize,
    height: usize,
    samples: usize,
    bits: u32,
    /// `ActiveArea`'s top-left corner in the stored image: black-level deltas are indexed from
    /// the stored image's origin.
    top: usize,
    left: usize,
    values: Vec<u16>,
}

impl RawImage {
    fn read(tiff: &Tiff, ifd: &Ifd, max_pixels: u64) -> Result<Self, String> {
        // Over 80 lines: every check of the directory (size, layout, depth, compression, the
        // pixel cap) comes before the first sample is read, in the order TIFF lays them out.
        let width = tiff.required(ifd, WIDTH, "ImageWidth")?;
        let height = tiff.required(ifd, HEIGHT, "ImageLength")?;
        let samples = tiff.uint(ifd, SAMPLES_PER_PIXEL)?.unwrap_or(1);
        let photometric = tiff.uint(ifd, PHOTOMETRIC)?;
        match (photometric, samples) {
            (Some(PHOTOMETRIC_CFA), 1) | (Some(PHOTOMETRIC_LINEAR_RAW), 3) => {}
            _ => {
                return Err(format!(
                    "{samples} samples per pixel with photometric {photometric:?}; expected 1 \
                     (colour filter array, 32803) or 3 (LinearRaw, 34892)"
                ));
            }
        }
        let compression = tiff.uint(ifd, COMPRESSION)?.unwrap_or(1);
        if compression != 1 {
            return Err(format!(
                "compression {compression} (7 is lossless JPEG) is not decoded; save the DNG \
                 uncompressed"
            ));
        }
        if tiff.uint(ifd, PLANAR)?.unwrap_or(1) != 1 {
            return Err("planar configuration 2 (separate planes) is not decoded".into());
        }
        let bits = match ifd.get(BITS) {
            Some(e) => tiff.uints(e)?,
            None => vec![1],
        };
        let bits = match bits.as_slice() {
            [b, rest @ ..] if matches!(b, 8 | 16) && rest.iter().all(|r| r == b) => *b as u32,
            _ => {
                return Err(format!(
                    "BitsPerSample {bits:?}; only 8- and 16-bit samples are decoded (packed \
                     10/12/14-bit DNG is not)"
                ));
            }
        };
        let area = match ifd.get(ACTIVE_AREA) {
            Some(e) => tiff.uints(e)?,
            None => vec![0, 0, height, width],
        };
        let [top, left, bottom, right] = area[..] else {
            return Err(format!("ActiveArea {area:?}: expected 4 values"));
        };
        if top >= bottom || left >= right || bottom > height || right > width {
            return Err(format!(
                "ActiveArea {area:?} is not inside the {width}×{height} image"
            ));
        }
        // Both the developed image (a Bayer tile is one pixel) and the samples read are bounded.
        let developed = match samples {
            1 => ((right - left) / 2) * ((bottom - top) / 2),
            _ => (right - left) * (bottom - top),
        };
        if developed > max_pixels || width.saturating_mul(height) > max_pixels.saturating_mul(4) {
            return Err(format!(
                "{width}×{height} sensor values, more than the {max_pixels} pixels allowed; \
                 refused before decoding"
            ));
        }
        let (width, height, samples) = (width as usize, height as usize, samples as usize);
        let mut values = vec![0u16; width * height * samples];
        let layout = Layout::read(tiff, ifd, width, height)?;
        layout.fill(tiff, &mut values, [width, height, samples], bits)?;
        let (top, left, bottom, right) =
            (top as usize, left as usize, bottom as usize, right as usize);
        let active = if (top, left, bottom, right) == (0, 0, height, width) {
            values
        } else {
            (top..bottom)
                .flat_map(|y| {
                    let row = (y * width + left) * samples;
                    values[row..row + (right - left) * samples].to_vec()
                })
                .collect()
        };
        Ok(Self {
            width: right - left,
            height: bottom - top,
            samples,
            bits,
            top,
            left,
            values: active,
        })
    }

    fn at(&self, x: usize, y: usize, sample: usize) -> u16 {
        self.values[(y * self.width + x) * self.samples + sample]
    }
}

/// Where the samples are: strips of whole rows, or tiles.
enum Layout {
    Strips {
        offsets: Vec<u64>,
        bytes: Vec<u64>,
        rows: usize,
    },
    Tiles {
        offsets: Vec<u64>,
        bytes: Vec<u64>,
        width: usize,
        length: usize,
    },
}

impl Layout {
    fn read(tiff: &Tiff, ifd: &Ifd, width: usize, height: usize) -> Result<Self, String> {
        let list = |tag, name: &str| match ifd.get(tag) {
            Some(e) => tiff.uints(e),
            None => Err(format!("no {name} tag")),
        };
        if ifd.get(TILE_OFFSETS).is_some() {
            let tw = tiff.required(ifd, TILE_WIDTH, "TileWidth")?;
            let tl = tiff.required(ifd, TILE_LENGTH, "TileLength")?;
            if tw > MAX_TILE || tl > MAX_TILE {
                return Err(format!("{tw}×{tl} tiles, more than {MAX_TILE} a side"));
            }
            let (tw, tl) = (tw as usize, tl as usize);
            let layout = Self::Tiles {
                offsets: list(TILE_OFFSETS, "TileOffsets")?,
                bytes: list(TILE_BYTES, "TileByteCounts")?,
                width: tw,
                length: tl,
            };
            let expected = width.div_ceil(tw) * height.div_ceil(tl);
            layout.check_count(expected)?;
            Ok(layout)
        } else {
            let rows = tiff
                .uint(ifd, ROWS_PER_STRIP)?
                .map_or(height, |r| (r as usize).clamp(1, height));
            let layout = Self::Strips {
                offsets: list(STRIP_OFFSETS, "StripOffsets")?,
                bytes: list(STRIP_BYTES, "StripByteCounts")?,
                rows,
            };
            layout.check_count(height.div_ceil(rows))?;
            Ok(layout)
        }
    }

    fn check_count(&self, expected: usize) -> Result<(), String> {
        let (Self::Strips { offsets, bytes, .. } | Self::Tiles { offsets, bytes, .. }) = self;
        if offsets.len() != expected || bytes.len() != expected {
            return Err(format!(
                "{} offsets and {} byte counts for {expected} strips or tiles",
                offsets.len(),
                bytes.len()
            ));
        }
        Ok(())
    }

    /// Copies every strip or tile into `values` (`width · height` pixels of `spp` samples), each
    /// chunk checked to lie inside the file and to hold the samples it must.
    fn fill(
        &self,
        tiff: &Tiff,
        values: &mut [u16],
        shape: [usize; 3],
        bits: u32,
    ) -> Result<(), String> {
        let [width, height, spp] = shape;
        let row_len = width * spp;
        let bytes_per = (bits / 8) as usize;
        let chunk = |offset: u64, count: u64, len: usize| -> Result<Vec<u16>, String> {
            let need = len * bytes_per;
            if count < need as u64 {
                return Err(format!("a chunk of {count} bytes where {need} are needed"));
            }
            let bytes = usize::try_from(offset)
                .ok()
                .and_then(|start| tiff.data.get(start..start.checked_add(need)?))
                .ok_or_else(|| format!("a chunk at byte {offset} runs past the file's end"))?;
            Ok(match bits {
                8 => bytes.iter().map(|&b| u16::from(b)).collect(),
                _ => bytes
                    .chunks_exact(2)
                    .map(|b| tiff.u16_from([b[0], b[1]]))
                    .collect(),
            })
        };
        match self {
            Self::Strips {
                offsets,
                bytes,
                rows,
            } => {
                for (i, (&offset, &count)) in offsets.iter().zip(bytes).enumerate() {
                    let first = i * rows;
                    let n = (*rows).min(height - first);
                    let src = chunk(offset, count, n * row_len)?;
                    values[first * row_len..(first + n) * row_len].copy_from_slice(&src);
                }
            }
            Self::Tiles {
                offsets,
                bytes,
                width: tw,
                length: tl,
            } => {
                let across = width.div_ceil(*tw);
                for (i, (&offset, &count)) in offsets.iter().zip(bytes).enumerate() {
                    // Edge tiles are stored whole, padded past the image.
                    let src = chunk(offset, count, tw * tl * spp)?;
                    let (x0, y0) = ((i % across) * tw, (i / across) * tl);
                    let w = (*tw).min(width - x0);
                    for dy in 0..(*tl).min(height - y0) {
                        let dst = (y0 + dy) * row_len + x0 * spp;
                        let from = dy * tw * spp;
                        values[dst..dst + w * spp].copy_from_slice(&src[from..from + w * spp]);
                    }
                }
            }
        }
        Ok(())
    }
}

/// Black and white levels: what a sensor value of each place and sample means in linear light.
struct Levels {
    /// `LinearizationTable`, when the file has one: stored value → linear sensor value.
    table: Option<Vec<u16>>,
    /// `BlackLevel`, `repeat[0] × repeat[1]` places of `samples` values each.
    black: Vec<f64>,
    repeat: [usize; 2],
    /// `BlackLevelDeltaH` (per column) and `BlackLevelDeltaV` (per row) of the stored image.
    delta_h: Vec<f64>,
    delta_v: Vec<f64>,
    /// `WhiteLevel` per sample.
    white: Vec<f64>,
}

impl Levels {
    fn read(tiff: &Tiff, ifd: &Ifd, image: &RawImage) -> Result<Self, String> {
        let samples = image.samples;
        let reals = |tag| ifd.get(tag).map(|e| tiff.reals(e)).transpose();
        let table = match ifd.get(LINEARIZATION) {
            Some(e) => {
                let t = tiff.uints(e)?;
                if t.is_empty() || t.len() > 1 << 16 {
                    return Err(format!("a LinearizationTable of {} entries", t.len()));
                }
                Some(
                    t.into_iter()
                        .map(|v| v.min(u64::from(u16::MAX)) as u16)
                        .collect(),
                )
            }
            None => None,
        };
        let repeat = match ifd.get(BLACK_REPEAT) {
            Some(e) => match tiff.uints(e)?[..] {
                [r, c] if (1..=16).contains(&r) && (1..=16).contains(&c) => {
                    [r as usize, c as usize]
                }
                ref other => return Err(format!("BlackLevelRepeatDim {other:?}")),
            },
            None => [1, 1],
        };
        let black = reals(BLACK_LEVEL)?.unwrap_or_else(|| vec![0.0]);
        let places = repeat[0] * repeat[1] * samples;
        let black = match black.len() {
            1 => vec![black[0]; places],
            n if n == places => black,
            n => {
                return Err(format!(
                    "{n} BlackLevel values for {places} places and samples"
                ));
            }
        };
        // Deltas are per column and row of the stored image; a missing one is zero.
        let stored_w = image.left + image.width;
        let stored_h = image.top + image.height;
        let delta = |tag, len: usize, name: &str| -> Result<Vec<f64>, String> {
            match reals(tag)? {
                None => Ok(vec![0.0; len]),
                Some(d) if d.len() == len => Ok(d),
                Some(d) => Err(format!("{} {name} values for {len}", d.len())),
            }
        };
        let default_white = f64::from((1u32 << image.bits) - 1);
        let white = match reals(WHITE_LEVEL)? {
            None => vec![default_white; samples],
            Some(w) if w.len() == 1 => vec![w[0]; samples],
            Some(w) if w.len() == samples => w,
            Some(w) => {
                return Err(format!(
                    "{} WhiteLevel values for {samples} samples",
                    w.len()
                ));
            }
        };
        let levels = Self {
            table,
            black,
            repeat,
            delta_h: delta(BLACK_DELTA_H, stored_w, "BlackLevelDeltaH")?,
            delta_v: delta(BLACK_DELTA_V, stored_h, "BlackLevelDeltaV")?,
            white,
        };
        if levels
            .black
            .iter()
            .chain(&levels.delta_h)
            .chain(&levels.delta_v)
            .chain(&levels.white)
            .any(|v| !v.is_finite())
        {
            return Err("a black or white level that is not a finite number".into());
        }
        Ok(levels)
    }

    /// The linear value, 0 at black and 1 at white (clamped: below black is 0, above white 1,
    /// so a clipped sensor stays saturated). A white level at or below black is refused here,
    /// where the place is known, instead of dividing by zero.
    fn linear(&self, image: &RawImage, x: usize, y: usize, sample: usize) -> Result<f64, String> {
        let stored = image.at(x, y, sample);
        let value = match &self.table {
            Some(t) => t[usize::from(stored).min(t.len() - 1)],
            None => stored,
        };
        let place =
            ((y % self.repeat[0]) * self.repeat[1] + x % self.repeat[1]) * image.samples + sample;
        let black = self.black[place] + self.delta_h[image.left + x] + self.delta_v[image.top + y];
        let white = self.white[sample];
        if white <= black {
            return Err(format!(
                "white level {white} is not above the black level {black}"
            ));
        }
        Ok(((f64::from(value) - black) / (white - black)).clamp(0.0, 1.0))
    }
}

fn to_u16(linear: f64) -> u16 {
    (linear * 65535.0).round() as u16
}

/// The colour filter array: which of red (0), green (1), blue (2) each place of a 2×2 tile
/// sees, relative to the active area's top-left corner.
struct Bayer([[usize; 2]; 2]);

impl Bayer {
    fn read(tiff: &Tiff, ifd: &Ifd) -> Result<Self, String> {
        let dims = match ifd.get(CFA_REPEAT) {
            Some(e) => tiff.uints(e)?,
            None => return Err("no CFARepeatPatternDim tag".into()),
        };
        if dims != [2, 2] {
            return Err(format!(
                "CFARepeatPatternDim {dims:?}; only 2×2 Bayer patterns are decoded"
            ));
        }
        if tiff.uint(ifd, CFA_LAYOUT)?.is_some_and(|l| l != 1) {
            return Err("a CFALayout other than rectangular (1)".into());
        }
        let pattern = match ifd.get(CFA_PATTERN) {
            Some(e) => tiff.uints(e)?,
            None => return Err("no CFAPattern tag".into()),
        };
        let mut count = [0; 3];
        for &c in &pattern {
            if let Some(n) = count.get_mut(c as usize) {
                *n += 1;
            }
        }
        if pattern.len() != 4 || count != [1, 2, 1] {
            return Err(format!(
                "CFAPattern {pattern:?}; expected one red (0), two green (1) and one blue (2)"
            ));
        }
        let at = |i: usize| pattern[i] as usize;
        Ok(Self([[at(0), at(1)], [at(2), at(3)]]))
    }
}

/// 2×2 superpixels: red, the mean of the two greens, blue, each from one tile of the active
/// area (an odd last row or column is dropped).
fn develop_bayer(
    image: &RawImage,
    levels: &Levels,
    bayer: &Bayer,
) -> Result<(u32, u32, Vec<[u16; 3]>), String> {
    let (w, h) = (image.width / 2, image.height / 2);
    if w == 0 || h == 0 {
        return Err(format!(
            "an active area of {}×{}: no 2×2 tile",
            image.width, image.height
        ));
    }
    let mut pixels = Vec::with_capacity(w * h);
    for ty in 0..h {
        for tx in 0..w {
            let mut sum = [0.0; 3];
            for (dy, row) in bayer.0.iter().enumerate() {
                for (dx, &colour) in row.iter().enumerate() {
                    sum[colour] += levels.linear(image, 2 * tx + dx, 2 * ty + dy, 0)?;
                }
            }
            pixels.push([to_u16(sum[0]), to_u16(sum[1] / 2.0), to_u16(sum[2])]);
        }
    }
    Ok((w as u32, h as u32, pixels))
}

/// `LinearRaw` RGB: each pixel through its levels.
fn develop_linear(image: &RawImage, levels: &Levels) -> Result<(u32, u32, Vec<[u16; 3]>), String> {
    let mut pixels = Vec::with_capacity(image.width * image.height);
    for y in 0..image.height {
        for x in 0..image.width {
            let mut px = [0; 3];
            for (s, v) in px.iter_mut().enumerate() {
                *v = to_u16(levels.linear(image, x, y, s)?);
            }
            pixels.push(px);
        }
    }
    Ok((image.width as u32, image.height as u32, pixels))
}

/// A TIFF file in memory: its byte order and directories, every read bounds-checked.
struct Tiff<'a> {
    data: &'a [u8],
    big_endian: bool,
}

/// One directory entry: tag, field type, count, and where its values start.
struct Entry {
    tag: u16,
    kind: u16,
    count: u64,
    at: usize,
}

struct Ifd(Vec<Entry>);

impl Ifd {
    fn get(&self, tag: u16) -> Option<&Entry> {
        self.0.iter().find(|e| e.tag == tag)
    }
}

impl<'a> Tiff<'a> {
    fn new(data: &'a [u8]) -> Result<Self, String> {
        let big_endian = match data.get(..4) {
            Some([b'I', b'I', 42, 0]) => false,
            Some([b'M', b'M', 0, 42]) => true,
            _ => return Err("not a TIFF (no II*/MM* header)".into()),
        };
        Ok(Self { data, big_endian })
    }

    fn first_ifd(&self) -> Result<u64, String> {
        self.u32_at(4).map(u64::from)
    }

    fn bytes<const N: usize>(&self, at: usize) -> Result<[u8; N], String> {
        at.checked_add(N)
            .and_then(|end| self.data.get(at..end))
            .and_then(|b| b.try_into().ok())
            .ok_or_else(|| format!("a read at byte {at} past the file's end"))
    }

    fn u16_from(&self, b: [u8; 2]) -> u16 {
        if self.big_endian {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    }

    fn u16_at(&self, at: usize) -> Result<u16, String> {
        self.bytes(at).map(|b| self.u16_from(b))
    }

    fn u32_at(&self, at: usize) -> Result<u32, String> {
        self.bytes(at).map(|b| {
            if self.big_endian {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            }
        })
    }

    fn ifd(&self, offset: u64) -> Result<Ifd, String> {
        let at = usize::try_from(offset).map_err(|_| "a directory past the file's end")?;
        let n = usize::from(self.u16_at(at)?);
        if n > MAX_ENTRIES {
            return Err(format!(
                "a directory of {n} entries (at most {MAX_ENTRIES})"
            ));
        }
        (0..n)
            .map(|i| {
                let e = at + 2 + 12 * i;
                let kind = self.u16_at(e + 2)?;
                let count = u64::from(self.u32_at(e + 4)?);
                let size = match kind {
                    1 | 2 | 6 | 7 => 1,
                    3 | 8 => 2,
                    4 | 9 | 11 | 13 => 4,
                    _ => 8,
                };
                // Values of four bytes or fewer sit in the entry; the rest at an offset.
                let inline = count.saturating_mul(size) <= 4;
                let at = if inline {
                    e + 8
                } else {
                    self.u32_at(e + 8)? as usize
                };
                Ok(Entry {
                    tag: self.u16_at(e)?,
                    kind,
                    count,
                    at,
                })
            })
            .collect::<Result<_, String>>()
            .map(Ifd)
    }

    /// An entry's values as unsigned integers (BYTE, SHORT, LONG, IFD).
    fn uints(&self, e: &Entry) -> Result<Vec<u64>, String> {
        let (size, read): (usize, &dyn Fn(usize) -> Result<u64, String>) = match e.kind {
            1 | 7 => (1, &|at| self.bytes::<1>(at).map(|b| u64::from(b[0]))),
            3 => (2, &|at| self.u16_at(at).map(u64::from)),
            4 | 13 => (4, &|at| self.u32_at(at).map(u64::from)),
            k => {
                return Err(format!(
                    "tag {} of type {k} where an integer is expected",
                    e.tag
                ));
            }
        };
        self.each(e, size, read)
    }

    /// An entry's values as numbers (integers, rationals, floats).
    fn reals(&self, e: &Entry) -> Result<Vec<f64>, String> {
        let rational = |at: usize, signed: bool| -> Result<f64, String> {
            let (n, d) = (self.u32_at(at)?, self.u32_at(at + 4)?);
            let (n, d) = if signed {
                (f64::from(n as i32), f64::from(d as i32))
            } else {
                (f64::from(n), f64::from(d))
            };
            // A zero denominator makes no number: refused rather than infinite.
            if d == 0.0 {
                Err(format!("tag {} has a rational over zero", e.tag))
            } else {
                Ok(n / d)
            }
        };
        match e.kind {
            5 => self.each(e, 8, &|at| rational(at, false)),
            10 => self.each(e, 8, &|at| rational(at, true)),
            11 => self.each(e, 4, &|at| {
                self.u32_at(at).map(|b| f64::from(f32::from_bits(b)))
            }),
            12 => self.each(e, 8, &|at| {
                let (a, b) = (u64::from(self.u32_at(at)?), u64::from(self.u32_at(at + 4)?));
                Ok(f64::from_bits(if self.big_endian {
                    a << 32 | b
                } else {
                    b << 32 | a
                }))
            }),
            _ => Ok(self.uints(e)?.into_iter().map(|v| v as f64).collect()),
        }
    }

    fn each<T>(
        &self,
        e: &Entry,
        size: usize,
        read: &dyn Fn(usize) -> Result<T, String>,
    ) -> Result<Vec<T>, String> {
        // The count is the file's word: bounded by what the file can hold before allocating.
        let count = usize::try_from(e.count).unwrap_or(usize::MAX);
        if count.saturating_mul(size) > self.data.len() {
            return Err(format!(
                "tag {} claims {} values, more than the file holds",
                e.tag, e.count
            ));
        }
        (0..count).map(|i| read(e.at + i * size)).collect()
    }

    fn uint(&self, ifd: &Ifd, tag: u16) -> Result<Option<u64>, String> {
        ifd.get(tag)
            .map(|e| self.uints(e).map(|v| v.first().copied().unwrap_or(0)))
            .transpose()
    }

    /// A dimension that must be there and be at least 1.
    fn required(&self, ifd: &Ifd, tag: u16, name: &str) -> Result<u64, String> {
        match self.uint(ifd, tag)? {
            Some(v) if v >= 1 => Ok(v),
            Some(v) => Err(format!("{name} {v}")),
            None => Err(format!("no {name} tag")),
        }
    }
}
