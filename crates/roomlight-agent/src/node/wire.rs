//! The node agent's side of the wire contract for what the camera agent asks it to show and
//! how to draw: Show patterns with their masks and Assign weights, checked at the boundary
//! (codes in [0, 1], known axes and codings, a mask of the projector's size, weights in (0, 1]
//! inside the frame) before anything reaches the display; and its display's state on the way
//! out. It knows nothing of sessions or streams.

use crate::AgentError;
use crate::hardware::{Assignment, DisplayReport, Fill, Pattern, validate_assignment};
use roomlight_calib::shading::{BLOCK, Ratios};
use roomlight_proto::convert::{display_status, from_rgb};
use roomlight_proto::v1;
use std::sync::Arc;

/// What the display says of itself, as the camera agent reads it (strings bounded).
pub(super) fn display_status_to_wire(report: &DisplayReport) -> v1::DisplayStatus {
    match report {
        DisplayReport::Showing { output } => display_status(v1::DisplayState::Showing, output, ""),
        DisplayReport::Lost { output, reason } => {
            display_status(v1::DisplayState::Lost, output, reason)
        }
    }
}

/// A Show message's pattern: node values, or a whole frame.
pub(super) enum Wire {
    Nodes(v1::NodeValues),
    Frame(Pattern),
}

/// A Show message's pattern with its `mask` (see [`mask_from_wire`]) for a projector of
/// `resolution` (`None`: a display that draws no pixels, which takes no mask).
pub(super) fn pattern_from_wire(
    p: v1::show::Pattern,
    mask: &[u8],
    resolution: Option<(u32, u32)>,
) -> Result<Wire, String> {
    let fill = match p {
        v1::show::Pattern::Nodes(values) if mask.is_empty() => return Ok(Wire::Nodes(values)),
        v1::show::Pattern::Nodes(_) => {
            return Err(
                "a mask with node values: expected one only with a uniform or Gray pattern".into(),
            );
        }
        v1::show::Pattern::Uniform(u) => uniform_from_wire(&u)?,
        v1::show::Pattern::Gray(g) => gray_from_wire(&g)?,
    };
    // A Gray bit the projector does not have is refused here, not acknowledged and then
    // found undrawable.
    if let (
        Fill::Structured {
            pattern,
            coding,
            cell,
            ..
        },
        Some((width, height)),
    ) = (fill, resolution)
    {
        let manifest = roomlight_calib::graycode::Manifest::with_cell(width, height, coding, cell)
            .map_err(|e| e.to_string())?;
        crate::hardware::check_gray_bit(&manifest, pattern)?;
    }
    Ok(Wire::Frame(Pattern {
        fill,
        mask: mask_from_wire(mask, resolution)?,
    }))
}

/// A Show's mask: empty is everywhere; otherwise one bit per projector pixel, row-major, least
/// significant bit first, exactly `ceil(width · height / 8)` bytes for this projector (a mask
/// drawn for another resolution would show the pattern in the wrong places).
pub(super) fn mask_from_wire(
    mask: &[u8],
    resolution: Option<(u32, u32)>,
) -> Result<Option<Arc<[bool]>>, String> {
    if mask.is_empty() {
        return Ok(None);
    }
    let Some((width, height)) = resolution else {
        return Err(format!(
            "a mask of {} bytes for a display of unknown resolution",
            mask.len()
        ));
    };
    let pixels = width as usize * height as usize;
    let expected = pixels.div_ceil(8);
    if mask.len() != expected {
        return Err(format!(
            "a mask of {} bytes; expected {expected} (one bit per pixel of the {width}×{height} projector)",
            mask.len()
        ));
    }
    Ok(Some(
        (0..pixels)
            .map(|i| mask[i / 8] >> (i % 8) & 1 == 1)
            .collect(),
    ))
}

fn uniform_from_wire(u: &v1::Uniform) -> Result<Fill, String> {
    let code = from_rgb("uniform code", u.code.as_ref()).map_err(|e| e.to_string())?;
    if code.0.iter().any(|v| !(0.0..=1.0).contains(v)) {
        return Err(format!("uniform code {code:?}: expected values in [0, 1]"));
    }
    Ok(Fill::Uniform(code.0.map(|v| v as f32)))
}

fn gray_from_wire(g: &v1::GrayBit) -> Result<Fill, String> {
    use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray, Primary};
    let axis = match v1::Axis::try_from(g.axis) {
        Ok(v1::Axis::Column) => Axis::Column,
        Ok(v1::Axis::Row) => Axis::Row,
        _ => return Err(format!("Gray bit axis {}: expected column or row", g.axis)),
    };
    let coding = match v1::Coding::try_from(g.coding) {
        Ok(v1::Coding::Gray) => Coding::Gray,
        Ok(v1::Coding::Xor04) => Coding::Xor04,
        _ => {
            return Err(format!(
                "Gray bit coding {}: expected gray or xor04",
                g.coding
            ));
        }
    };
    if g.bit >= 32 {
        return Err(format!("Gray bit {}: expected below 32", g.bit));
    }
    // Absent (0) is the full-resolution code of senders from before cells.
    let cell = g.cell.max(1);
    if !cell.is_power_of_two() || cell > roomlight_calib::graycode::MAX_CELL {
        return Err(format!(
            "Gray bit cell {}: expected a power of two up to {}",
            g.cell,
            roomlight_calib::graycode::MAX_CELL
        ));
    }
    let primary = match v1::Primary::try_from(g.primary) {
        Ok(v1::Primary::All) => None,
        Ok(v1::Primary::Red) => Some(Primary::Red),
        Ok(v1::Primary::Green) => Some(Primary::Green),
        Ok(v1::Primary::Blue) => Some(Primary::Blue),
        Err(_) => {
            return Err(format!(
                "Gray bit primary {}: expected all, red, green or blue",
                g.primary
            ));
        }
    };
    Ok(Fill::Structured {
        pattern: Gray::Bit {
            axis,
            bit: g.bit,
            inverse: g.inverse,
        },
        coding,
        cell,
        primary,
    })
}

/// The weights and response of an Assign message, checked.
pub(super) fn assignment_from_wire(a: &v1::Assign) -> Result<Assignment, AgentError> {
    let gamma = match a.gamma.as_slice() {
        [] => [1.0; 3],
        [r, g, b] => [*r, *g, *b],
        other => {
            return Err(AgentError::Protocol(format!(
                "assignment: {} response exponents, expected 3",
                other.len()
            )));
        }
    };
    let mut nodes = Vec::with_capacity(a.nodes.len());
    for n in &a.nodes {
        if n.pixels.len() != n.weights.len() {
            return Err(AgentError::Protocol(format!(
                "assignment of node {}: {} pixels, {} weights",
                n.node,
                n.pixels.len(),
                n.weights.len()
            )));
        }
        nodes.push((
            n.node,
            n.pixels
                .iter()
                .copied()
                .zip(n.weights.iter().copied())
                .collect(),
        ));
    }
    let assignment = Assignment {
        width: a.width,
        height: a.height,
        response: roomlight_calib::response::Response {
            gamma,
            max_residual: [0.0; 3],
        },
        nodes,
    };
    validate_assignment(&assignment, "assignment")?;
    Ok(assignment)
}

/// A Shade message checked for a display of `width`×`height`: the gains to step with and
/// how. `reset` alone (no ratios) carries no step.
#[derive(Debug, PartialEq)]
pub(super) struct ShadeStep {
    pub(super) ratios: Option<Ratios>,
    pub(super) rate: f64,
    pub(super) reset: bool,
}

/// A Shade message's ratios for a display of `width`×`height`: the block size must be ours,
/// the block counts the display's, the bytes 12 a block, each ratio finite within the bounds
/// (all three 0: a block not read), the rate in (0, 1]. The reason, when refused.
pub(super) fn shade_from_wire(
    s: &v1::Shade,
    (width, height): (u32, u32),
) -> Result<ShadeStep, String> {
    if s.ratios.is_empty() && s.reset {
        return Ok(ShadeStep {
            ratios: None,
            rate: 1.0,
            reset: true,
        });
    }
    if s.block != BLOCK {
        return Err(format!("blocks of {} pixels, expected {BLOCK}", s.block));
    }
    let (across, down) = (width.div_ceil(BLOCK), height.div_ceil(BLOCK));
    if (s.across, s.down) != (across, down) {
        return Err(format!(
            "{}×{} blocks, a {width}×{height} display has {across}×{down}",
            s.across, s.down
        ));
    }
    let blocks = across as usize * down as usize;
    if s.ratios.len() != blocks * 12 {
        return Err(format!(
            "{} bytes of ratios, expected {} (12 a block)",
            s.ratios.len(),
            blocks * 12
        ));
    }
    if !(s.rate > 0.0 && s.rate <= 1.0) {
        return Err(format!("rate {}, expected in (0, 1]", s.rate));
    }
    // All zero means unread.
    let blocks: Vec<Option<[f64; 3]>> = per_block(&s.ratios).collect();
    let mut ratios = Ratios::from_blocks(width, height, blocks).map_err(|e| e.to_string())?;
    if !s.light.is_empty() {
        if s.light.len() != ratios.blocks().len() * 24 {
            return Err(format!(
                "{} bytes of light, expected {} (24 a block) or none",
                s.light.len(),
                ratios.blocks().len() * 24
            ));
        }
        // All zero is unknown.
        let light = per_block::<6>(&s.light)
            .map(|b| b.map(|v| [[v[0], v[1], v[2]], [v[3], v[4], v[5]]]))
            .collect();
        ratios = ratios.with_light(light).map_err(|e| e.to_string())?;
    }
    Ok(ShadeStep {
        ratios: Some(ratios),
        rate: s.rate,
        reset: s.reset,
    })
}

/// `bytes` as blocks of `N` little-endian f32 (a length not a multiple of `4 N` is checked by
/// the caller; a rest is dropped): `None` for a block of zeros, else its values, a NaN kept
/// for the caller to refuse (not `== 0.0`: clippy's float_cmp).
fn per_block<const N: usize>(bytes: &[u8]) -> impl Iterator<Item = Option<[f64; N]>> + '_ {
    bytes.chunks_exact(4 * N).map(|b| {
        let v: [f64; N] = std::array::from_fn(|c| {
            let bytes = [b[4 * c], b[4 * c + 1], b[4 * c + 2], b[4 * c + 3]];
            f64::from(f32::from_le_bytes(bytes))
        });
        v.iter().any(|x| x.abs() > 0.0 || x.is_nan()).then_some(v)
    })
}

/// The Shade message that carries `ratios` (see [`shade_from_wire`]).
pub(crate) fn shade_to_wire(seq: u64, ratios: &Ratios, rate: f64, reset: bool) -> v1::Shade {
    let (width, height) = ratios.size();
    let mut bytes = Vec::with_capacity(ratios.blocks().len() * 12);
    for b in ratios.blocks() {
        let v = b.unwrap_or([0.0; 3]);
        for c in v {
            bytes.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    let mut light = Vec::new();
    if ratios.light().iter().any(Option::is_some) {
        light.reserve(ratios.light().len() * 24);
        for l in ratios.light() {
            for c in l.unwrap_or([[0.0; 3]; 2]).into_iter().flatten() {
                light.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
    }
    v1::Shade {
        seq,
        block: BLOCK,
        across: width.div_ceil(BLOCK),
        down: height.div_ceil(BLOCK),
        ratios: bytes,
        rate,
        reset,
        light,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_core::LinearRgb;
    use roomlight_proto::convert::to_rgb;

    /// Shade messages: a pass's ratios round-trip (to f32), a reset alone carries none, and a
    /// wrong block size, block count, byte count, rate or ratio is refused with what was
    /// expected.
    #[test]
    fn shade_messages_round_trip_and_are_checked() {
        let (w, h) = (40, 20); // 3 × 2 blocks
        let blocks = vec![
            Some([2.0, 1.0, 0.5]),
            None,
            Some([1.0, 1.0, 1.0]),
            Some([0.25, 4.0, 1.5]),
            None,
            Some([1.25, 0.75, 3.0]),
        ];
        let ratios = Ratios::from_blocks(w, h, blocks).expect("ratios");
        let msg = shade_to_wire(7, &ratios, 0.8, true);
        assert_eq!(msg.ratios.len(), 6 * 12);
        let step = shade_from_wire(&msg, (w, h)).expect("valid");
        assert_eq!(step.ratios.as_ref(), Some(&ratios), "exact in f32");
        assert!(step.reset && (step.rate - 0.8).abs() < 1e-12);
        let reset = v1::Shade {
            reset: true,
            ..Default::default()
        };
        assert_eq!(
            shade_from_wire(&reset, (w, h)).expect("reset"),
            ShadeStep {
                ratios: None,
                rate: 1.0,
                reset: true
            }
        );
        let refused = |edit: &dyn Fn(&mut v1::Shade), size: (u32, u32), says: &str| {
            let mut m = msg.clone();
            edit(&mut m);
            let e = shade_from_wire(&m, size).expect_err(says);
            assert!(e.contains(says), "{e}");
        };
        refused(&|m| m.block = 8, (w, h), "expected 16");
        refused(&|_| {}, (w + 16, h), "has 4×2");
        refused(&|m| m.ratios.truncate(70), (w, h), "expected 72");
        refused(&|m| m.rate = 0.0, (w, h), "rate 0");
        refused(&|m| m.rate = f64::NAN, (w, h), "rate NaN");
        refused(
            &|m| m.ratios[0..4].copy_from_slice(&f32::NAN.to_le_bytes()),
            (w, h),
            "block 0",
        );
        refused(
            &|m| m.ratios[12..16].copy_from_slice(&9.0f32.to_le_bytes()),
            (w, h),
            "block 1",
        );
        refused(
            &|m| m.ratios[24..28].copy_from_slice(&f32::INFINITY.to_le_bytes()),
            (w, h),
            "block 2",
        );
        // No light known: none sent, none taken.
        assert!(msg.light.is_empty());
        // Each read block's light goes with its ratios, exact in f32; an unread one is zeros.
        let light = vec![
            Some([[0.5, 0.25, 0.125], [0.25, 0.25, 0.25]]),
            None,
            Some([[1.0, 2.0, 0.0], [1.0, 1.0, 64.0]]),
            None,
            None,
            Some([[0.75; 3], [0.5; 3]]),
        ];
        let lit = ratios.clone().with_light(light).expect("light");
        let msg = shade_to_wire(8, &lit, 0.8, false);
        assert_eq!(msg.light.len(), 6 * 24);
        let step = shade_from_wire(&msg, (w, h)).expect("valid");
        assert_eq!(step.ratios.as_ref(), Some(&lit), "exact in f32");
        refused(
            &|m| m.light = vec![0; 100],
            (w, h),
            "expected 144 (24 a block)",
        );
        let mut bad = msg.clone();
        bad.light[48..52].copy_from_slice(&(-1.0f32).to_le_bytes());
        let e = shade_from_wire(&bad, (w, h)).expect_err("negative light");
        assert!(e.contains("block 2"), "{e}");
        bad.light[48..52].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = shade_from_wire(&bad, (w, h)).expect_err("light not a number");
        assert!(e.contains("block 2"), "{e}");
    }

    fn assign(pixels: Vec<u32>, weights: Vec<f32>, gamma: Vec<f64>) -> v1::Assign {
        v1::Assign {
            nodes: vec![v1::NodeAssignment {
                node: 3,
                chart: 3,
                pixels,
                weights,
            }],
            width: 4,
            height: 2,
            gamma,
        }
    }

    /// A well-formed assignment is taken as sent; every malformed one is refused with a message
    /// that names the node or the field, never drawn.
    #[test]
    fn assignments_over_the_wire_are_checked() {
        let ok = assignment_from_wire(&assign(vec![0, 5, 7], vec![1.0, 0.5, 0.25], vec![]))
            .expect("well formed");
        assert_eq!(ok.nodes, vec![(3, vec![(0, 1.0), (5, 0.5), (7, 0.25)])]);
        assert!(
            ok.response.gamma.iter().all(|g| (g - 1.0).abs() < 1e-12),
            "no exponents: linear"
        );
        let refused = |a: v1::Assign, says: &str| {
            let e = assignment_from_wire(&a).expect_err("malformed").to_string();
            assert!(e.contains(says), "{e:?} should say {says:?}");
        };
        refused(
            assign(vec![0, 1], vec![1.0], vec![]),
            "node 3: 2 pixels, 1 weights",
        );
        refused(
            assign(vec![0, 8], vec![1.0, 1.0], vec![]),
            "outside the 4×2 frame",
        );
        refused(assign(vec![5, 2], vec![1.0, 1.0], vec![]), "not increasing");
        refused(assign(vec![0], vec![1.5], vec![]), "outside (0, 1]");
        refused(assign(vec![0], vec![f32::NAN], vec![]), "outside (0, 1]");
        refused(
            assign(vec![0], vec![1.0], vec![2.2, 2.2]),
            "2 response exponents",
        );
        refused(
            assign(vec![0], vec![1.0], vec![2.2, f64::INFINITY, 2.2]),
            "finite and positive",
        );
        let mut empty = assign(vec![0], vec![1.0], vec![]);
        empty.height = 0;
        refused(empty, "a 4×0 projector");
    }

    /// Whole-frame patterns are read as sent; codes outside [0, 1], unknown axes or codings and
    /// impossible bits are refused.
    #[test]
    fn show_patterns_over_the_wire_are_checked() {
        use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray};
        let read = |p| pattern_from_wire(p, &[], None);
        let uniform = |v: f64| {
            v1::show::Pattern::Uniform(v1::Uniform {
                code: Some(to_rgb(LinearRgb::splat(v))),
            })
        };
        assert!(matches!(
            read(uniform(0.25)),
            Ok(Wire::Frame(Pattern {
                fill: Fill::Uniform([0.25, 0.25, 0.25]),
                mask: None
            }))
        ));
        for bad in [-0.1, 1.5, f64::NAN] {
            assert!(read(uniform(bad)).is_err(), "code {bad}");
        }
        let gray = |axis: i32, bit: u32, coding: i32| {
            v1::show::Pattern::Gray(v1::GrayBit {
                axis,
                bit,
                inverse: true,
                coding,
                cell: 0,
                primary: 0,
            })
        };
        let row = v1::Axis::Row as i32;
        let xor = v1::Coding::Xor04 as i32;
        assert!(matches!(
            read(gray(row, 3, xor)),
            Ok(Wire::Frame(Pattern {
                fill: Fill::Structured {
                    pattern: Gray::Bit {
                        axis: Axis::Row,
                        bit: 3,
                        inverse: true
                    },
                    coding: Coding::Xor04,
                    cell: 1,
                    primary: None
                },
                mask: None
            }))
        ));
        assert!(read(gray(0, 3, xor)).is_err(), "unspecified axis");
        assert!(read(gray(9, 3, xor)).is_err(), "unknown axis");
        assert!(read(gray(row, 3, 0)).is_err(), "unspecified coding");
        assert!(read(gray(row, 40, xor)).is_err(), "bit 40");
        // Code cells: absent is 1, a power of two up to MAX_CELL travels, anything else is
        // refused.
        let cell = |cell: u32| {
            read(v1::show::Pattern::Gray(v1::GrayBit {
                axis: row,
                bit: 3,
                inverse: false,
                coding: xor,
                cell,
                primary: 0,
            }))
        };
        assert!(matches!(
            cell(2),
            Ok(Wire::Frame(Pattern {
                fill: Fill::Structured { cell: 2, .. },
                ..
            }))
        ));
        for bad in [3, 16, u32::MAX] {
            assert!(cell(bad).is_err_and(|e| e.contains("cell")), "cell {bad}");
        }
        // Primaries: absent is white stripes, red, green and blue travel and tint the codes,
        // anything else is refused.
        let primary = |primary: i32| {
            pattern_from_wire(
                v1::show::Pattern::Gray(v1::GrayBit {
                    axis: row,
                    bit: 0,
                    inverse: false,
                    coding: xor,
                    cell: 1,
                    primary,
                }),
                &[],
                Some((8, 8)),
            )
        };
        use roomlight_calib::graycode::Primary;
        for (wire, expected) in [
            (v1::Primary::All, None),
            (v1::Primary::Red, Some(Primary::Red)),
            (v1::Primary::Green, Some(Primary::Green)),
            (v1::Primary::Blue, Some(Primary::Blue)),
        ] {
            let Ok(Wire::Frame(p)) = primary(wire as i32) else {
                panic!("primary {wire:?}");
            };
            assert!(matches!(p.fill, Fill::Structured { primary, .. } if primary == expected));
            let codes = p.codes(8, 8).expect("codes");
            assert!(
                codes.iter().any(|c| c.iter().any(|&v| v > 0.0)),
                "{wire:?} lit"
            );
            for c in codes {
                for (channel, v) in c.into_iter().enumerate() {
                    let lit = expected.is_none_or(|e| e.channel() == channel);
                    assert!(lit || v == 0.0, "{wire:?}: channel {channel} at {v}");
                }
            }
        }
        for bad in [4, -1, i32::MAX] {
            assert!(
                primary(bad).is_err_and(|e| e.contains("primary")),
                "primary {bad}"
            );
        }
        // A 5×2 projector has 3 column bits and 1 row bit (found by fuzzing: roomlight-calib's
        // coder underflowed on bit 3 of its columns).
        let sized = |p| pattern_from_wire(p, &[], Some((5, 2)));
        let column = v1::Axis::Column as i32;
        assert!(sized(gray(column, 2, xor)).is_ok());
        assert!(
            sized(gray(column, 3, xor)).is_err_and(|e| e.contains("has 3")),
            "bit 3 of 3"
        );
        assert!(sized(gray(row, 1, xor)).is_err(), "bit 1 of 1");
    }

    /// A 5×2 projector's mask: 10 pixels, two bytes; pixels 0, 3 and 9 shown.
    const MASK: [u8; 2] = [0b0000_1001, 0b0000_0010];
    const SHOWN: [usize; 3] = [0, 3, 9];

    fn white() -> v1::show::Pattern {
        v1::show::Pattern::Uniform(v1::Uniform {
            code: Some(to_rgb(LinearRgb::splat(1.0))),
        })
    }

    /// Codes compared exactly, as bits: white is 1.0 and black 0.0, nothing in between.
    fn bits(codes: Vec<[f32; 3]>) -> Vec<[u32; 3]> {
        codes.into_iter().map(|c| c.map(f32::to_bits)).collect()
    }

    const BLACK: [f32; 3] = [0.0; 3];

    /// A mask is one bit per projector pixel, least significant first, and reaches the display
    /// as sent: the pattern shows where its bit is 1 and black elsewhere, and only on a display
    /// of its own size.
    #[test]
    fn a_masked_pattern_reaches_the_display_masked() {
        let Ok(Wire::Frame(pattern)) = pattern_from_wire(white(), &MASK, Some((5, 2))) else {
            panic!("a well-formed mask is taken");
        };
        let (white_px, black_px) = ([1.0f32; 3].map(f32::to_bits), BLACK.map(f32::to_bits));
        let codes = bits(pattern.codes(5, 2).expect("codes"));
        let lit: Vec<usize> = (0..10).filter(|&i| codes[i] == white_px).collect();
        assert_eq!(lit, SHOWN);
        assert!(
            codes
                .iter()
                .enumerate()
                .all(|(i, c)| lit.contains(&i) || *c == black_px),
            "black where the mask is 0: {codes:?}"
        );
        // The display draws the mask for its own size only.
        assert!(pattern.codes(4, 2).is_err(), "a 10-pixel mask on 8 pixels");
    }

    /// A structured pattern keeps its stripes where its mask shows it and is black elsewhere.
    #[test]
    fn a_masked_structured_pattern_keeps_its_stripes_where_shown() {
        use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray};
        let black_px = BLACK.map(f32::to_bits);
        let bit = v1::show::Pattern::Gray(v1::GrayBit {
            axis: v1::Axis::Column as i32,
            bit: 0,
            inverse: false,
            coding: v1::Coding::Gray as i32,
            cell: 0,
            primary: 0,
        });
        let Ok(Wire::Frame(masked)) = pattern_from_wire(bit.clone(), &MASK, Some((5, 2))) else {
            panic!("a masked Gray bit");
        };
        let Ok(Wire::Frame(whole)) = pattern_from_wire(bit, &[], Some((5, 2))) else {
            panic!("a Gray bit");
        };
        assert_eq!(
            whole.fill,
            Fill::Structured {
                pattern: Gray::Bit {
                    axis: Axis::Column,
                    bit: 0,
                    inverse: false
                },
                coding: Coding::Gray,
                cell: 1,
                primary: None
            }
        );
        let (m, w) = (
            bits(masked.codes(5, 2).expect("masked")),
            bits(whole.codes(5, 2).expect("whole")),
        );
        for i in 0..10 {
            let expected = if SHOWN.contains(&i) { w[i] } else { black_px };
            assert_eq!(m[i], expected, "pixel {i}");
        }
    }

    /// A mask of another length, one for a display of unknown size, and one with node values
    /// are refused with a message that says what was expected.
    #[test]
    fn malformed_masks_are_refused() {
        let refused = |mask: &[u8], resolution, says: &str| {
            let e = match pattern_from_wire(white(), mask, resolution) {
                Err(e) => e,
                Ok(_) => panic!("{mask:?} for {resolution:?} should be refused"),
            };
            assert!(e.contains(says), "{e:?} should say {says:?}");
        };
        refused(
            &[0xff],
            Some((5, 2)),
            "expected 2 (one bit per pixel of the 5×2 projector)",
        );
        refused(&[0xff; 3], Some((5, 2)), "a mask of 3 bytes; expected 2");
        refused(&MASK, None, "unknown resolution");
        let nodes = v1::show::Pattern::Nodes(v1::NodeValues::default());
        assert!(
            pattern_from_wire(nodes, &MASK, Some((5, 2)))
                .is_err_and(|e| e.contains("with node values")),
            "a mask with node values"
        );
    }
}
