//! The pattern set of one projector resolution ([`Manifest`], what `patterns.json` holds):
//! which patterns there are, in display order, over which code cells, and what each shows at a
//! projector pixel. It must not know how captures are decoded.

use super::{Axis, Coding, Pattern, PatternFile, bits_for, gray};
use crate::CalibError;
use crate::image_io::LinearImage;
use serde::{Deserialize, Serialize};

/// The pattern set of one projector resolution: what `patterns.json` holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// Projector width.
    pub width: u32,
    /// Projector height.
    pub height: u32,
    /// How bits become patterns (files without it are plain Gray code).
    #[serde(default = "gray_coding")]
    pub coding: Coding,
    /// Projector pixels per code cell along each axis, a power of two up to [`MAX_CELL`] (files
    /// without it: 1). Every pattern codes `x / cell` and `y / cell`: a camera that sees
    /// several projector pixels in one of its own cannot resolve the finest stripes of a
    /// full-resolution code, and each doubling of the cells saves a bit per axis
    /// ([`Manifest::with_cell`]).
    #[serde(default = "one_pixel")]
    pub cell: u32,
    /// Bits for the columns (of cells).
    pub column_bits: u32,
    /// Bits for the rows.
    pub row_bits: u32,
    /// Every pattern, in display order.
    pub patterns: Vec<PatternFile>,
}

fn gray_coding() -> Coding {
    Coding::Gray
}

fn one_pixel() -> u32 {
    1
}

/// The largest code cell, in projector pixels per side ([`Manifest::cell`]).
pub const MAX_CELL: u32 = 8;

/// The largest projector side a pattern set is made for (8K): one pattern of it as an image is
/// 8192² × 12 bytes = 805 MB, so larger sizes are refused before anything is allocated.
pub const MAX_SIDE: u32 = 8192;

impl Manifest {
    /// The pattern set for a `width × height` projector: white, black, then each column bit and
    /// its inverse from the most significant, then the rows.
    pub fn new(width: u32, height: u32) -> Result<Self, CalibError> {
        Self::with_coding(width, height, Coding::default())
    }

    /// The pattern set with a chosen coding.
    pub fn with_coding(width: u32, height: u32, coding: Coding) -> Result<Self, CalibError> {
        Self::with_cell(width, height, coding, 1)
    }

    /// The pattern set with a chosen coding over cells of `cell × cell` projector pixels
    /// (a power of two up to [`MAX_CELL`]): the code of cell `(x / cell, y / cell)`, which
    /// decodes to the pixel after the cell's middle ([`Manifest::pixel`]).
    pub fn with_cell(
        width: u32,
        height: u32,
        coding: Coding,
        cell: u32,
    ) -> Result<Self, CalibError> {
        if !cell.is_power_of_two() || cell > MAX_CELL {
            return Err(CalibError::Invalid {
                field: "code cell",
                problem: format!(
                    "{cell} projector pixels, expected a power of two up to {MAX_CELL}"
                ),
            });
        }
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(CalibError::Invalid {
                field: "projector resolution",
                problem: format!("{width}x{height}, expected 1 to {MAX_SIDE} per side (the cap)"),
            });
        }
        let (column_bits, row_bits) = (
            bits_for(width.div_ceil(cell)),
            bits_for(height.div_ceil(cell)),
        );
        let mut patterns = vec![
            PatternFile {
                file: "white.png".into(),
                pattern: Pattern::White,
            },
            PatternFile {
                file: "black.png".into(),
                pattern: Pattern::Black,
            },
        ];
        for (axis, bits, name) in [
            (Axis::Column, column_bits, "col"),
            (Axis::Row, row_bits, "row"),
        ] {
            for bit in 0..bits {
                for inverse in [false, true] {
                    let suffix = if inverse { "-inv" } else { "" };
                    patterns.push(PatternFile {
                        file: format!("{name}-{bit:02}{suffix}.png"),
                        pattern: Pattern::Bit { axis, bit, inverse },
                    });
                }
            }
        }
        Ok(Self {
            width,
            height,
            coding,
            cell,
            column_bits,
            row_bits,
            patterns,
        })
    }

    /// Checks a manifest read from a file: sizes, bit counts and a complete, unique pattern set.
    pub fn validate(&self, file: &str) -> Result<(), CalibError> {
        let expected =
            Self::with_cell(self.width, self.height, self.coding, self.cell).map_err(|e| {
                CalibError::File {
                    file: file.into(),
                    problem: e.to_string(),
                }
            })?;
        if self.column_bits != expected.column_bits || self.row_bits != expected.row_bits {
            return Err(CalibError::File {
                file: file.into(),
                problem: format!(
                    "column_bits/row_bits are {}/{}, a {}x{} projector needs {}/{}",
                    self.column_bits,
                    self.row_bits,
                    self.width,
                    self.height,
                    expected.column_bits,
                    expected.row_bits
                ),
            });
        }
        for p in &expected.patterns {
            let n = self
                .patterns
                .iter()
                .filter(|q| q.pattern == p.pattern)
                .count();
            if n != 1 {
                return Err(CalibError::File {
                    file: file.into(),
                    problem: format!("lists {:?} {n} times, expected once", p.pattern),
                });
            }
        }
        if self.patterns.len() != expected.patterns.len() {
            return Err(CalibError::File {
                file: file.into(),
                problem: format!(
                    "lists {} patterns, expected {}",
                    self.patterns.len(),
                    expected.patterns.len()
                ),
            });
        }
        let mut names: Vec<&str> = self.patterns.iter().map(|p| p.file.as_str()).collect();
        names.sort_unstable();
        if names.windows(2).any(|w| w[0] == w[1])
            || names
                .iter()
                .any(|n| n.contains('/') || n.contains('\\') || n.is_empty())
        {
            return Err(CalibError::File {
                file: file.into(),
                problem: "file names must be unique plain names".into(),
            });
        }
        Ok(())
    }

    /// The patterns shown, in display order: every one, or without the inverses when `once`
    /// ([`Captures::single_shot`]).
    pub fn shown(&self, once: bool) -> impl Iterator<Item = &PatternFile> {
        self.patterns
            .iter()
            .filter(move |f| !(once && matches!(f.pattern, Pattern::Bit { inverse: true, .. })))
    }

    /// The code value (0 or 1) of every projector pixel for a pattern.
    pub fn pattern_values(&self, pattern: Pattern) -> Vec<f32> {
        let (w, h) = (self.width, self.height);
        (0..w * h)
            .map(|i| {
                let on = match pattern {
                    Pattern::White => true,
                    Pattern::Black => false,
                    Pattern::Bit { axis, bit, inverse } => {
                        let v = match axis {
                            Axis::Column => i % w,
                            Axis::Row => i / w,
                        } / self.cell;
                        self.encoded_bit(axis, bit, v) != inverse
                    }
                };
                f32::from(u8::from(on))
            })
            .collect()
    }

    /// How many code cells `axis` has: the coordinates its code takes.
    pub fn cells(&self, axis: Axis) -> u32 {
        match axis {
            Axis::Column => self.width,
            Axis::Row => self.height,
        }
        .div_ceil(self.cell)
    }

    /// The projector pixel a decoded cell `(x, y)` stands for: the one after its middle
    /// (its own for a cell of one), within `cell / 2` pixels of every pixel of the cell
    /// ([`Manifest::tolerance`]).
    pub fn pixel(&self, (x, y): (u32, u32)) -> (u32, u32) {
        (
            (x * self.cell + self.cell / 2).min(self.width - 1),
            (y * self.cell + self.cell / 2).min(self.height - 1),
        )
    }

    /// How far (projector pixels, per axis) a decode may lie from the true pixel and still
    /// be right: placed in the true code cell or one beside it (a camera pixel on a stripe
    /// edge sees both; `graycode::cells`), `2 · cell − 1`, which is ±1 for cells of one.
    pub fn tolerance(&self) -> u32 {
        2 * self.cell - 1
    }

    /// The value `bit` of `axis` shows at cell coordinate `v` (before the inverse): the
    /// Gray code's bit, XOR-ed with the base bit under XOR coding. A bit beyond the axis's
    /// count (which no pattern of this manifest has) shows dark rather than underflowing.
    pub fn encoded_bit(&self, axis: Axis, bit: u32, v: u32) -> bool {
        let bits = match axis {
            Axis::Column => self.column_bits,
            Axis::Row => self.row_bits,
        };
        if bit >= bits {
            return false;
        }
        let g = |b: u32| (gray(v) >> (bits - 1 - b)) & 1 == 1;
        match self.base_bit(bits) {
            Some(base) if base != bit => g(bit) != g(base),
            _ => g(bit),
        }
    }

    /// The bit every other bit is XOR-ed with, for an axis of `bits` bits.
    pub fn base_bit(&self, bits: u32) -> Option<u32> {
        match self.coding {
            Coding::Xor04 if bits >= 3 => Some(bits - 2),
            _ => None,
        }
    }

    /// The pattern with only the projector pixels `shown` marks lit (the others black): the
    /// second pass of [`Correspondence::second_pass_mask`]. A mask of another size than the
    /// projector is refused.
    pub fn pattern_image_where(
        &self,
        pattern: Pattern,
        shown: &[bool],
    ) -> Result<LinearImage, CalibError> {
        if shown.len() != (self.width * self.height) as usize {
            return Err(CalibError::Invalid {
                field: "pattern mask",
                problem: format!(
                    "{} pixels, the projector has {}x{}",
                    shown.len(),
                    self.width,
                    self.height
                ),
            });
        }
        let mut image = self.pattern_image(pattern);
        for (px, &on) in image.pixels.iter_mut().zip(shown) {
            if !on {
                *px = [0.0; 3];
            }
        }
        Ok(image)
    }

    /// The pattern as an image (white where on).
    pub fn pattern_image(&self, pattern: Pattern) -> LinearImage {
        LinearImage {
            width: self.width,
            height: self.height,
            pixels: self
                .pattern_values(pattern)
                .into_iter()
                .map(|v| [v; 3])
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pattern set over cells of two codes each cell once (every pixel of a cell shows the
    /// same value under every pattern, neighbouring cells differ under some), with a bit fewer
    /// per axis; cells that are not a power of two up to `MAX_CELL` are refused; a file without
    /// a cell reads as cells of one.
    #[test]
    fn a_pattern_set_over_cells_codes_each_cell_once() {
        let full = Manifest::new(10, 6).expect("full");
        let cells = Manifest::with_cell(10, 6, Coding::Xor04, 2).expect("cells");
        assert_eq!((full.column_bits, full.row_bits), (4, 3));
        assert_eq!((cells.column_bits, cells.row_bits), (3, 2));
        assert_eq!((cells.cells(Axis::Column), cells.cells(Axis::Row)), (5, 3));
        let values: Vec<Vec<f32>> = cells
            .patterns
            .iter()
            .map(|f| cells.pattern_values(f.pattern))
            .collect();
        let code = |x: u32, y: u32| -> Vec<u32> {
            values
                .iter()
                .map(|v| v[(y * 10 + x) as usize].to_bits())
                .collect()
        };
        for y in 0..6 {
            for x in 0..10 {
                assert_eq!(code(x, y), code(x / 2 * 2, y / 2 * 2), "({x}, {y})");
                if x % 2 == 0 && x > 0 {
                    assert_ne!(code(x, y), code(x - 1, y), "({x}, {y})");
                }
            }
        }
        assert_eq!(cells.pixel((4, 2)), (9, 5));
        assert_eq!((cells.tolerance(), full.tolerance()), (3, 1));
        for bad in [0, 3, 16] {
            assert!(
                Manifest::with_cell(10, 6, Coding::Xor04, bad).is_err(),
                "{bad}"
            );
        }
        let json = serde_json::to_value(&cells).expect("json");
        let back: Manifest = serde_json::from_value(json).expect("back");
        back.validate("patterns.json").expect("valid");
        assert_eq!(back, cells);
        let mut old = serde_json::to_value(&full).expect("json");
        old.as_object_mut().expect("object").remove("cell");
        let old: Manifest = serde_json::from_value(old).expect("old file");
        assert_eq!(old.cell, 1);
    }
}
