//! Grabs of the screen: what is on a region of the root window now, as 8-bit RGB (GetImage,
//! ZPixmap, 24 or 32 bits per pixel). Tests read back what a display showed with it, and later
//! the simulator chain and `bench hw`. It must not know who drew the pixels.

use crate::HwError;
use crate::output::Geometry;
use crate::x11::X11;
use image::RgbImage;
use x11rb::protocol::xproto::{ConnectionExt as _, ImageFormat};

/// A connection kept for repeated grabs (a test polling until a frame appears).
#[derive(Debug)]
pub struct Grabber {
    x: X11,
}

impl Grabber {
    /// Connects to `display`, or to `$DISPLAY` when `None`.
    pub fn connect(display: Option<&str>) -> Result<Self, HwError> {
        Ok(Self {
            x: X11::connect(display)?,
        })
    }

    /// The pixels of `region` of the root window now; a region outside the screen is refused.
    pub fn grab(&self, region: Geometry) -> Result<RgbImage, HwError> {
        let screen = self.x.screen();
        let (sw, sh) = (
            i64::from(screen.width_in_pixels),
            i64::from(screen.height_in_pixels),
        );
        let inside = region.x >= 0
            && region.y >= 0
            && i64::from(region.x) + i64::from(region.width) <= sw
            && i64::from(region.y) + i64::from(region.height) <= sh;
        if !inside {
            return Err(HwError::Request(format!(
                "grabbing {region}: outside the {sw}x{sh} screen"
            )));
        }
        let f = self.x.format;
        let width = region.width as usize;
        // A reply is bounded like a request: grab in bands of rows that fit.
        let band = (self.x.max_image_bytes() / f.stride(width)).max(1);
        let mut rgb = Vec::with_capacity(width * region.height as usize);
        let mut row = 0usize;
        while row < region.height as usize {
            let rows = band.min(region.height as usize - row);
            let reply = self
                .x
                .conn
                .get_image(
                    ImageFormat::Z_PIXMAP,
                    self.x.root(),
                    region.x as i16,
                    (region.y as usize + row) as i16,
                    region.width as u16,
                    rows as u16,
                    u32::MAX,
                )
                .map_err(|e| HwError::Request(format!("grabbing {region}: {e}")))?
                .reply()
                .map_err(|e| HwError::Request(format!("grabbing {region}: {e}")))?;
            rgb.extend(f.decode(&reply.data, width, rows));
            row += rows;
        }
        let bytes = rgb.into_iter().flatten().collect();
        RgbImage::from_raw(region.width, region.height, bytes)
            .ok_or_else(|| HwError::Request(format!("grabbing {region}: a short reply")))
    }
}

/// One grab of `region` on `display` (or `$DISPLAY`).
pub fn grab(display: Option<&str>, region: Geometry) -> Result<RgbImage, HwError> {
    Grabber::connect(display)?.grab(region)
}
