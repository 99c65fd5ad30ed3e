//! The node agent's side of the wire contract for what the camera agent asks it to show and
//! how to draw: Show patterns and Assign weights, checked at the boundary (codes in [0, 1],
//! known axes and codings, weights in (0, 1] inside the frame) before anything reaches the
//! display. It knows nothing of sessions or streams.

use crate::AgentError;
use crate::hardware::{Assignment, Pattern};
use roomlight_proto::convert::from_rgb;
use roomlight_proto::v1;

/// A Show message's pattern: node values, or a whole frame.
pub(super) enum Wire {
    Nodes(v1::NodeValues),
    Frame(Pattern),
}

pub(super) fn pattern_from_wire(p: v1::show::Pattern) -> Result<Wire, String> {
    use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray};
    Ok(match p {
        v1::show::Pattern::Nodes(values) => Wire::Nodes(values),
        v1::show::Pattern::Uniform(u) => {
            let code = from_rgb("uniform code", u.code.as_ref()).map_err(|e| e.to_string())?;
            if code.0.iter().any(|v| !(0.0..=1.0).contains(v)) {
                return Err(format!("uniform code {code:?}: expected values in [0, 1]"));
            }
            Wire::Frame(Pattern::Uniform(code.0.map(|v| v as f32)))
        }
        v1::show::Pattern::Gray(g) => {
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
            Wire::Frame(Pattern::Structured {
                pattern: Gray::Bit {
                    axis,
                    bit: g.bit,
                    inverse: g.inverse,
                },
                coding,
            })
        }
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
    assignment.validate("assignment")?;
    Ok(assignment)
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_core::LinearRgb;
    use roomlight_proto::convert::to_rgb;

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
        let uniform = |v: f64| {
            v1::show::Pattern::Uniform(v1::Uniform {
                code: Some(to_rgb(LinearRgb::splat(v))),
            })
        };
        assert!(matches!(
            pattern_from_wire(uniform(0.25)),
            Ok(Wire::Frame(Pattern::Uniform([0.25, 0.25, 0.25])))
        ));
        for bad in [-0.1, 1.5, f64::NAN] {
            assert!(pattern_from_wire(uniform(bad)).is_err(), "code {bad}");
        }
        let gray = |axis: i32, bit: u32, coding: i32| {
            v1::show::Pattern::Gray(v1::GrayBit {
                axis,
                bit,
                inverse: true,
                coding,
            })
        };
        let row = v1::Axis::Row as i32;
        let xor = v1::Coding::Xor04 as i32;
        assert!(matches!(
            pattern_from_wire(gray(row, 3, xor)),
            Ok(Wire::Frame(Pattern::Structured {
                pattern: Gray::Bit {
                    axis: Axis::Row,
                    bit: 3,
                    inverse: true
                },
                coding: Coding::Xor04
            }))
        ));
        assert!(
            pattern_from_wire(gray(0, 3, xor)).is_err(),
            "unspecified axis"
        );
        assert!(pattern_from_wire(gray(9, 3, xor)).is_err(), "unknown axis");
        assert!(
            pattern_from_wire(gray(row, 3, 0)).is_err(),
            "unspecified coding"
        );
        assert!(pattern_from_wire(gray(row, 40, xor)).is_err(), "bit 40");
    }
}
