//! The identify pattern: what a projector shows so that someone in the room can tell which one
//! it is and whether it is aligned — its projector id, its output's name and resolution, a grid
//! and a mark in each corner. It must not know windows or the wire.

use crate::font;
use crate::frame::Frame;

const GRID: [u8; 3] = [96, 96, 96];
const TEXT: [u8; 3] = [255, 255, 255];
/// Corner marks: top left red, top right green, bottom left blue, bottom right yellow, so that
/// a mirrored or rotated image shows at once.
const CORNERS: [[u8; 3]; 4] = [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]];

/// The identify frame of a `width`×`height` output.
pub fn frame(projector: &str, output: &str, width: u32, height: u32) -> Frame {
    let (w, h) = (width as usize, height as usize);
    let mut rgb = vec![[0u8; 3]; w * h];
    let mut set = |x: u32, y: u32, c: [u8; 3]| {
        if x < width && y < height {
            rgb[y as usize * w + x as usize] = c;
        }
    };
    // A grid of 8×8 cells with the border on the outermost pixels.
    for i in 0..=8u32 {
        let gx = (i * width / 8).min(width - 1);
        let gy = (i * height / 8).min(height - 1);
        for y in 0..height {
            set(gx, y, GRID);
        }
        for x in 0..width {
            set(x, gy, GRID);
        }
    }
    let arm = (width.min(height) / 6).max(4);
    let thick = (arm / 6).max(2);
    let corners = [
        (0, 0, 1i64, 1i64),
        (width - 1, 0, -1, 1),
        (0, height - 1, 1, -1),
        (width - 1, height - 1, -1, -1),
    ];
    for ((cx, cy, sx, sy), colour) in corners.into_iter().zip(CORNERS) {
        for a in 0..arm {
            for t in 0..thick {
                let at = |base: u32, s: i64, d: u32| (i64::from(base) + s * i64::from(d)) as u32;
                set(at(cx, sx, a), at(cy, sy, t), colour);
                set(at(cx, sx, t), at(cy, sy, a), colour);
            }
        }
    }
    let lines = [
        projector.to_string(),
        output.to_string(),
        format!("{width}x{height}"),
    ];
    let longest = lines.iter().map(|l| l.chars().count()).max().unwrap_or(1) as u32;
    // The largest whole scale at which the text fits in the middle half of the frame.
    let scale = (width / 2 / (longest * font::ADVANCE).max(1))
        .min(height / 2 / (3 * (font::HEIGHT + 2)))
        .max(1);
    let line_height = (font::HEIGHT + 2) * scale;
    let top = height.saturating_sub(3 * line_height) / 2;
    for (i, line) in lines.iter().enumerate() {
        let text_width = line.chars().count() as u32 * font::ADVANCE * scale;
        let left = width.saturating_sub(text_width) / 2;
        font::draw(line, left, top + i as u32 * line_height, scale, |x, y| {
            set(x, y, TEXT)
        });
    }
    Frame {
        width,
        height,
        rgb: rgb.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_are_marked_and_text_is_drawn() {
        let f = frame("p1", "HDMI-1", 320, 240);
        let at = |x: usize, y: usize| f.rgb[y * 320 + x];
        assert_eq!(at(0, 0), CORNERS[0]);
        assert_eq!(at(319, 0), CORNERS[1]);
        assert_eq!(at(0, 239), CORNERS[2]);
        assert_eq!(at(319, 239), CORNERS[3]);
        assert!(f.rgb.iter().filter(|&&c| c == TEXT).count() > 100);
    }

    #[test]
    fn tiny_outputs_do_not_panic() {
        for (w, h) in [(1, 1), (3, 2), (16, 9)] {
            assert_eq!(
                frame("a-long-projector-id", "x", w, h).rgb.len(),
                (w * h) as usize
            );
        }
    }
}
