//! Each shot's EXIF against what was asked: the exposure time, ISO and f-number a photograph
//! says it was taken with (`Shot`, read by kamadak-exif from the raw EXIF block the decoder
//! hands over), the settings a session expects (`ExpectExif`, set by the gphoto2 backend from
//! what it asked the camera, or written in a folder/command camera's config for a tethered
//! DSLR), and the wrapper backend that refuses a shot whose EXIF disagrees, naming the tag, what
//! was asked and what the file says. It must not know how a shot was taken.

use crate::Backend;
use crate::error::CameraError;
use crate::frame::Frame;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Relative tolerance on exposure time and f-number: cameras record nominal values (1/30,
/// 5.6), so a config's 0.0333 or 5.66 must pass, while the next third of a stop (26 %) must not.
pub const TOLERANCE: f64 = 0.03;

/// What a photograph's EXIF says it was taken with; `None` where the tag is absent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Shot {
    /// `ExposureTime`, seconds.
    pub exposure_s: Option<f64>,
    /// `PhotographicSensitivity` (formerly ISOSpeedRatings).
    pub iso: Option<u32>,
    /// `FNumber`.
    pub f_number: Option<f64>,
}

impl Shot {
    /// Reads the three tags from a raw EXIF block (a TIFF structure, as JPEG's APP1 and
    /// PNG's eXIf carry it). A block that does not parse is an error naming why.
    pub fn from_tiff(raw: Vec<u8>) -> Result<Self, String> {
        let exif = exif::Reader::new()
            .read_raw(raw)
            .map_err(|e| format!("EXIF does not parse: {e}"))?;
        let field = |tag| exif.get_field(tag, exif::In::PRIMARY).map(|f| &f.value);
        let rational = |tag| match field(tag) {
            Some(exif::Value::Rational(r)) => r.first().map(exif::Rational::to_f64),
            _ => None,
        };
        Ok(Self {
            exposure_s: rational(exif::Tag::ExposureTime).filter(|t| t.is_finite()),
            iso: field(exif::Tag::PhotographicSensitivity).and_then(|v| v.get_uint(0)),
            f_number: rational(exif::Tag::FNumber).filter(|f| f.is_finite()),
        })
    }

    /// The three tags as a raw EXIF block (little-endian TIFF), for an encoder's
    /// `set_exif_metadata`: the fake cameras of the tests and the bench write it.
    pub fn to_tiff(&self) -> Result<Vec<u8>, String> {
        let rational = |v: f64| {
            // Exposure times below a second as 1/N, as cameras write them; others in 1/1000.
            let (num, denom) = if v > 0.0 && v < 1.0 && (1.0 / v - (1.0 / v).round()).abs() < 1e-6 {
                (1, (1.0 / v).round() as u32)
            } else {
                ((v * 1000.0).round() as u32, 1000)
            };
            exif::Value::Rational(vec![exif::Rational { num, denom }])
        };
        let mut fields = Vec::new();
        let field = |tag, value| exif::Field {
            tag,
            ifd_num: exif::In::PRIMARY,
            value,
        };
        if let Some(t) = self.exposure_s {
            fields.push(field(exif::Tag::ExposureTime, rational(t)));
        }
        if let Some(f) = self.f_number {
            fields.push(field(exif::Tag::FNumber, rational(f)));
        }
        if let Some(iso) = self.iso {
            let iso = u16::try_from(iso).map_err(|_| format!("ISO {iso} above 65535"))?;
            fields.push(field(
                exif::Tag::PhotographicSensitivity,
                exif::Value::Short(vec![iso]),
            ));
        }
        let mut writer = exif::experimental::Writer::new();
        for f in &fields {
            writer.push_field(f);
        }
        let mut out = std::io::Cursor::new(Vec::new());
        writer
            .write(&mut out, true)
            .map_err(|e| format!("writing EXIF: {e}"))?;
        Ok(out.into_inner())
    }
}

/// The settings every shot must carry in its EXIF; a field left out is not checked.
/// `expect_exif = { exposure_s = 0.0333, iso = 100, f_number = 8.0 }`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExpectExif {
    #[serde(default)]
    pub exposure_s: Option<f64>,
    #[serde(default)]
    pub iso: Option<u32>,
    #[serde(default)]
    pub f_number: Option<f64>,
}

impl ExpectExif {
    /// Refuses values no camera can be asked for (checked once, at load).
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: Option<f64>| match v {
            Some(v) if !(v.is_finite() && v > 0.0) => Err(format!(
                "expect_exif.{name} = {v}; expected finite and positive"
            )),
            _ => Ok(()),
        };
        positive("exposure_s", self.exposure_s)?;
        positive("f_number", self.f_number)?;
        match self.iso {
            Some(0) => Err("expect_exif.iso = 0; expected positive".into()),
            _ => Ok(()),
        }
    }

    /// Compares a shot's EXIF with what was asked; the first disagreement is an error naming
    /// the tag, asked and got ("absent" for a tag the file lacks, or a file without EXIF).
    pub fn check(&self, camera: &str, shot: Option<&Shot>) -> Result<(), CameraError> {
        let shot = shot.copied().unwrap_or_default();
        let mismatch = |tag: &str, asked: String, got: Option<String>| CameraError::Exif {
            camera: camera.to_string(),
            tag: tag.to_string(),
            asked,
            got: got.unwrap_or_else(|| "absent".into()),
        };
        let close = |a: f64, b: f64| (a - b).abs() <= TOLERANCE * a.abs().max(b.abs());
        if let Some(asked) = self.exposure_s
            && !shot.exposure_s.is_some_and(|got| close(asked, got))
        {
            return Err(mismatch(
                "ExposureTime",
                format!("{asked} s"),
                shot.exposure_s.map(|g| format!("{g} s")),
            ));
        }
        if let Some(asked) = self.iso
            && shot.iso != Some(asked)
        {
            return Err(mismatch(
                "PhotographicSensitivity (ISO)",
                asked.to_string(),
                shot.iso.map(|g| g.to_string()),
            ));
        }
        if let Some(asked) = self.f_number
            && !shot.f_number.is_some_and(|got| close(asked, got))
        {
            return Err(mismatch(
                "FNumber",
                format!("f/{asked}"),
                shot.f_number.map(|g| format!("f/{g}")),
            ));
        }
        Ok(())
    }
}

/// Any backend whose every frame's EXIF is checked: a folder or command camera behind which a
/// tethered DSLR writes its files.
pub struct Checked {
    inner: Box<dyn Backend>,
    expect: ExpectExif,
}

impl std::fmt::Debug for Checked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checked")
            .field("camera", &self.inner.name())
            .field("expect", &self.expect)
            .finish()
    }
}

impl Checked {
    pub fn new(inner: Box<dyn Backend>, expect: ExpectExif) -> Self {
        Self { inner, expect }
    }
}

impl Backend for Checked {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn capture(&mut self, deadline: Instant) -> Result<Frame, CameraError> {
        let frame = self.inner.capture(deadline)?;
        self.expect.check(self.inner.name(), frame.shot.as_ref())?;
        Ok(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_block_reads_back() {
        let shot = Shot {
            exposure_s: Some(1.0 / 30.0),
            iso: Some(200),
            f_number: Some(5.6),
        };
        let back = Shot::from_tiff(shot.to_tiff().expect("writes")).expect("parses");
        assert_eq!(back.iso, Some(200));
        assert!((back.exposure_s.expect("time") - 1.0 / 30.0).abs() < 1e-9);
        assert!((back.f_number.expect("f") - 5.6).abs() < 1e-9);
        assert!(Shot::from_tiff(b"not a tiff".to_vec()).is_err());
    }

    #[test]
    fn a_mismatch_names_the_tag_asked_and_got() {
        let expect = ExpectExif {
            exposure_s: Some(0.0333),
            iso: Some(100),
            f_number: Some(8.0),
        };
        let shot = Shot {
            exposure_s: Some(1.0 / 30.0),
            iso: Some(100),
            f_number: Some(8.0),
        };
        expect
            .check("cam", Some(&shot))
            .expect("nominal values pass");
        let err = expect
            .check(
                "cam",
                Some(&Shot {
                    iso: Some(400),
                    ..shot
                }),
            )
            .expect_err("iso");
        let text = err.to_string();
        assert!(
            text.contains("cam") && text.contains("ISO") && text.contains("asked 100, got 400"),
            "{text}"
        );
        let err = expect
            .check(
                "cam",
                Some(&Shot {
                    exposure_s: Some(0.05),
                    ..shot
                }),
            )
            .expect_err("a third of a stop and more");
        assert!(err.to_string().contains("ExposureTime"), "{err}");
        let err = expect.check("cam", None).expect_err("no EXIF");
        assert!(err.to_string().contains("got absent"), "{err}");
        ExpectExif::default()
            .check("cam", None)
            .expect("nothing asked");
        assert!(
            ExpectExif {
                iso: Some(0),
                ..expect
            }
            .validate()
            .is_err()
        );
        assert!(
            ExpectExif {
                f_number: Some(f64::NAN),
                ..expect
            }
            .validate()
            .is_err()
        );
    }
}
