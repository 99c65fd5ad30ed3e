//! The X11 connection and the screen's pixel format: how 8-bit RGB becomes the bytes of a
//! ZPixmap image and back, for windows (PutImage) and grabs (GetImage). It must not know what
//! the pixels mean.

use crate::HwError;
use x11rb::connection::{Connection, RequestConnection};
use x11rb::protocol::xproto::{ImageOrder, Screen, VisualClass};
use x11rb::rust_connection::RustConnection;

/// A connection to an X server and the screen roomlight draws on.
#[derive(Debug)]
pub struct X11 {
    pub conn: RustConnection,
    pub screen: usize,
    pub format: PixelFormat,
}

impl X11 {
    /// Connects to `display` (e.g. `:1`), or to `$DISPLAY` when `None`.
    pub fn connect(display: Option<&str>) -> Result<Self, HwError> {
        let name = display
            .map(str::to_string)
            .or_else(|| std::env::var("DISPLAY").ok())
            .unwrap_or_default();
        let (conn, screen) = RustConnection::connect(display).map_err(|e| HwError::Connect {
            display: name,
            reason: e.to_string(),
        })?;
        let format = PixelFormat::of(&conn, screen)?;
        Ok(Self {
            conn,
            screen,
            format,
        })
    }

    pub fn screen(&self) -> &Screen {
        &self.conn.setup().roots[self.screen]
    }

    pub fn root(&self) -> u32 {
        self.screen().root
    }

    /// The most image bytes one request may carry (BIG-REQUESTS included), less the header.
    pub fn max_image_bytes(&self) -> usize {
        self.conn.maximum_request_bytes().saturating_sub(64)
    }
}

/// How the screen's root visual stores a pixel in a ZPixmap image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelFormat {
    pub depth: u8,
    /// 24 or 32.
    pub bits_per_pixel: u8,
    /// Rows are padded to this many bits.
    pub scanline_pad: u8,
    pub lsb_first: bool,
    pub masks: [u32; 3],
}

impl PixelFormat {
    fn of(conn: &RustConnection, screen: usize) -> Result<Self, HwError> {
        let setup = conn.setup();
        let root = &setup.roots[screen];
        let visual = root
            .allowed_depths
            .iter()
            .flat_map(|d| d.visuals.iter().map(move |v| (d.depth, v)))
            .find(|(_, v)| v.visual_id == root.root_visual);
        let Some((depth, visual)) = visual else {
            return Err(HwError::Unsupported("the root visual is not listed".into()));
        };
        if !matches!(
            visual.class,
            VisualClass::TRUE_COLOR | VisualClass::DIRECT_COLOR
        ) {
            return Err(HwError::Unsupported(format!(
                "a {:?} root visual; roomlight needs true colour",
                visual.class
            )));
        }
        let Some(pixmap) = setup.pixmap_formats.iter().find(|f| f.depth == depth) else {
            return Err(HwError::Unsupported(format!(
                "no pixmap format of depth {depth}"
            )));
        };
        if !matches!(pixmap.bits_per_pixel, 24 | 32) {
            return Err(HwError::Unsupported(format!(
                "{} bits per pixel; roomlight draws 24 or 32",
                pixmap.bits_per_pixel
            )));
        }
        let masks = [visual.red_mask, visual.green_mask, visual.blue_mask];
        if masks.iter().any(|m| m.count_ones() != 8) {
            return Err(HwError::Unsupported(format!(
                "colour masks {masks:08x?}; roomlight needs 8 bits per channel"
            )));
        }
        Ok(Self {
            depth,
            bits_per_pixel: pixmap.bits_per_pixel,
            scanline_pad: pixmap.scanline_pad,
            lsb_first: setup.image_byte_order == ImageOrder::LSB_FIRST,
            masks,
        })
    }

    fn bytes_per_pixel(&self) -> usize {
        usize::from(self.bits_per_pixel / 8)
    }

    /// Bytes of one row of `width` pixels, padding included.
    pub fn stride(&self, width: usize) -> usize {
        let pad = usize::from(self.scanline_pad.max(8));
        (width * usize::from(self.bits_per_pixel)).div_ceil(pad) * pad / 8
    }

    /// The ZPixmap bytes of `rows` rows of `width` pixels from `rgb` (row-major).
    pub fn encode(&self, rgb: &[[u8; 3]], width: usize) -> Vec<u8> {
        let (stride, bpp) = (self.stride(width), self.bytes_per_pixel());
        let rows = rgb.len().checked_div(width).unwrap_or(0);
        let mut out = vec![0u8; stride * rows];
        for (row, pixels) in out.chunks_exact_mut(stride).zip(rgb.chunks_exact(width)) {
            for (dst, px) in row.chunks_exact_mut(bpp).zip(pixels) {
                let mut value = 0u32;
                for (mask, &c) in self.masks.iter().zip(px) {
                    value |= (u32::from(c) << mask.trailing_zeros()) & mask;
                }
                let bytes = if self.lsb_first {
                    value.to_le_bytes()
                } else {
                    value.to_be_bytes()
                };
                if self.lsb_first {
                    dst.copy_from_slice(&bytes[..bpp]);
                } else {
                    dst.copy_from_slice(&bytes[4 - bpp..]);
                }
            }
        }
        out
    }

    /// The 8-bit RGB of a ZPixmap image of `width`×`height` pixels.
    pub fn decode(&self, data: &[u8], width: usize, height: usize) -> Vec<[u8; 3]> {
        let (stride, bpp) = (self.stride(width), self.bytes_per_pixel());
        let mut out = Vec::with_capacity(width * height);
        for row in data.chunks(stride).take(height) {
            for src in row.chunks_exact(bpp).take(width) {
                let mut bytes = [0u8; 4];
                let value = if self.lsb_first {
                    bytes[..bpp].copy_from_slice(src);
                    u32::from_le_bytes(bytes)
                } else {
                    bytes[4 - bpp..].copy_from_slice(src);
                    u32::from_be_bytes(bytes)
                };
                let channel = |m: u32| ((value & m) >> m.trailing_zeros()) as u8;
                out.push([
                    channel(self.masks[0]),
                    channel(self.masks[1]),
                    channel(self.masks[2]),
                ]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn formats() -> Vec<PixelFormat> {
        let masks = [0xff0000, 0xff00, 0xff];
        [(32, true), (32, false), (24, true), (24, false)]
            .into_iter()
            .map(|(bits_per_pixel, lsb_first)| PixelFormat {
                depth: 24,
                bits_per_pixel,
                scanline_pad: 32,
                lsb_first,
                masks,
            })
            .collect()
    }

    #[test]
    fn encode_then_decode_gives_the_codes_back() {
        let rgb: Vec<[u8; 3]> = (0..15u8).map(|i| [i, 255 - i, i * 7]).collect();
        for f in formats() {
            let data = f.encode(&rgb, 5);
            assert_eq!(data.len(), f.stride(5) * 3, "{f:?}");
            assert_eq!(f.decode(&data, 5, 3), rgb, "{f:?}");
        }
    }

    #[test]
    fn rows_are_padded() {
        let f = formats()[2];
        assert_eq!(f.stride(5), 16, "15 bytes padded to 32 bits");
    }
}
