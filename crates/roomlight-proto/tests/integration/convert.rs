//! Wire conversions round-trip and refuse malformed input with a clear message.

use prost::Message;
use roomlight_core::LinearRgb;
use roomlight_proto::convert::{
    MAX_BATCH_NODES, MAX_DISPLAY_TEXT, ProtoError, check_display_status, display_status,
    from_node_changes, from_node_errors, from_rgb, from_sparse, node_change, node_errors,
    pack_patches, pack_rgb, to_rgb, to_sparse,
};
use roomlight_proto::v1;

#[test]
fn sparse_vectors_and_batches_round_trip_through_bytes() {
    let patches = vec![2u32, 7, 40];
    let values = vec![
        LinearRgb([0.1, 0.2, 0.3]),
        LinearRgb([0.0, 1.0, 0.5]),
        LinearRgb([1e-9, 2.5, 0.25]),
    ];
    let sparse = to_sparse(&patches, &values);
    let back = v1::SparseRgb::decode(sparse.encode_to_vec().as_slice()).expect("decodes");
    let (p, v) = from_sparse("attenuation", &back).expect("valid");
    assert_eq!((p, v.clone()), (patches.clone(), values.clone()));
    // A round's errors: each node's values on its support, without patch ids.
    let msg = v1::Errors {
        round: 12,
        kind: v1::ErrorKind::Measured as i32,
        objective: 0.5,
        restart: true,
        nodes: vec![
            node_errors(3, values.len(), values.iter().copied()),
            node_errors(4, 1, values[..1].iter().copied()),
        ],
    };
    let back = v1::Errors::decode(msg.encode_to_vec().as_slice()).expect("decodes");
    assert_eq!(back, msg);
    let batch = from_node_errors(back.nodes, |_| true).expect("a batch");
    assert!(batch.refused.is_empty(), "{:?}", batch.refused);
    assert_eq!(
        batch.entries,
        vec![(3, values.clone()), (4, vec![values[0]])]
    );
    // A round's changes of value, one triple a node.
    let msg = v1::Contribution {
        round: 12,
        nodes: vec![node_change(3, values[0]), node_change(4, values[1])],
    };
    let back = v1::Contribution::decode(msg.encode_to_vec().as_slice()).expect("decodes");
    let batch = from_node_changes(back.nodes, |_| true).expect("a batch");
    assert!(batch.refused.is_empty(), "{:?}", batch.refused);
    assert_eq!(batch.entries, vec![(3, values[0]), (4, values[1])]);
    assert_eq!(
        from_rgb("x", Some(&to_rgb(LinearRgb([0.25, 0.5, 1.0])))).expect("rgb"),
        LinearRgb([0.25, 0.5, 1.0])
    );
}

#[test]
fn malformed_sparse_vectors_are_refused() {
    let short = v1::SparseRgb {
        patches: pack_patches(&[1, 2]),
        values: vec![0; 47],
    };
    assert!(matches!(
        from_sparse("delta", &short),
        Err(ProtoError::Length {
            bytes: 47,
            patches: 2,
            ..
        })
    ));
    let nan = v1::SparseRgb {
        patches: pack_patches(&[1]),
        values: pack_rgb(1, [LinearRgb([0.0, f64::NAN, 0.0])]),
    };
    let err = from_sparse("delta", &nan).expect_err("nan");
    assert!(
        err.to_string().contains("delta") && err.to_string().contains("finite"),
        "{err}"
    );
    let unsorted = v1::SparseRgb {
        patches: pack_patches(&[4, 4]),
        values: vec![0; 48],
    };
    assert!(matches!(
        from_sparse("delta", &unsorted),
        Err(ProtoError::Unsorted { .. })
    ));
    let ragged = v1::SparseRgb {
        patches: vec![1, 0, 0],
        values: Vec::new(),
    };
    let err = from_sparse("delta", &ragged).expect_err("three bytes");
    assert!(
        matches!(err, ProtoError::PatchBytes { bytes: 3, .. }),
        "{err}"
    );
    assert!(matches!(
        from_rgb("x", None),
        Err(ProtoError::Missing { .. })
    ));
    let status: tonic::Status = ProtoError::Length {
        field: "delta",
        bytes: 47,
        patches: 2,
    }
    .into();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
}

/// A batched message: each entry is checked on its own (owned by the receiver or sender, named
/// once, its values present, whole finite triples); a malformed entry is refused with a reason
/// that names the node and what is wrong, and the others are kept.
#[test]
fn malformed_entries_of_a_batch_are_refused_one_by_one() {
    let good = |node: u32| node_change(node, LinearRgb::splat(0.1));
    let inf = v1::NodeChange {
        node: 12,
        change: Some(v1::Rgb {
            r: 0.0,
            g: f64::INFINITY,
            b: 0.0,
        }),
    };
    let absent = v1::NodeChange {
        node: 14,
        change: None,
    };
    // Finite but absurd: a value in [0, 1] never changes by more than 1.
    let huge = node_change(13, LinearRgb([0.0, 0.0, -1e300]));
    let owned = |n: u32| (10..15).contains(&n);
    let batch = from_node_changes(
        vec![good(10), good(99), good(10), inf, huge, absent, good(11)],
        owned,
    )
    .expect("bounded");
    let kept: Vec<u32> = batch.entries.iter().map(|e| e.0).collect();
    assert_eq!(kept, [10, 11]);
    let reasons: Vec<String> = batch.refused.iter().map(ToString::to_string).collect();
    let expected = [
        "node 99: contribution: node 99 is not one of this projector's nodes",
        "node 10: contribution: node 10 appears more than once",
        "node 12: contribution: value 1 is inf, expected a finite number",
        "node 13: contribution: value 2 is -1e300, expected a change within [-1, 1]",
        "node 14: contribution: field rgb is missing",
    ];
    assert_eq!(reasons, expected);
    // Errors: whole triples of finite values for a node it owns.
    let ok = node_errors(10, 2, [LinearRgb::splat(0.1); 2]);
    let ragged = v1::NodeErrors {
        node: 11,
        values: vec![0; 32],
    };
    let nan = node_errors(12, 1, [LinearRgb([0.0, f64::NAN, 0.0])]);
    let foreign = node_errors(99, 1, [LinearRgb::ZERO]);
    let batch = from_node_errors(vec![ok, ragged, nan, foreign], owned).expect("bounded");
    assert_eq!(batch.entries, vec![(10, vec![LinearRgb::splat(0.1); 2])]);
    let reasons: Vec<String> = batch.refused.iter().map(ToString::to_string).collect();
    let expected = [
        "node 11: errors: 32 bytes of values, expected 24 per patch (three little-endian doubles)",
        "node 12: errors: value 1 is NaN, expected a finite number",
        "node 99: errors: node 99 is not one of this projector's nodes",
    ];
    assert_eq!(reasons, expected);
    // Too many entries: the whole message is refused before any is read.
    let flood = vec![v1::NodeChange::default(); MAX_BATCH_NODES + 1];
    assert!(matches!(
        from_node_changes(flood, |_| true),
        Err(ProtoError::TooLarge { .. })
    ));
}

#[test]
fn a_display_status_is_bounded_on_the_way_out_and_checked_on_the_way_in() {
    let lost = display_status(v1::DisplayState::Lost, "HDMI-1", "output HDMI-1 is gone");
    let back = v1::DisplayStatus::decode(lost.encode_to_vec().as_slice()).expect("decodes");
    assert_eq!(check_display_status(&back), Ok(v1::DisplayState::Lost));
    assert_eq!(
        (back.output.as_str(), back.reason.as_str()),
        ("HDMI-1", "output HDMI-1 is gone")
    );
    // A long reason of multi-byte characters is cut at a character boundary, under the bound.
    let long = "é".repeat(MAX_DISPLAY_TEXT);
    let cut = display_status(v1::DisplayState::Lost, "A", &long);
    assert!(cut.reason.len() <= MAX_DISPLAY_TEXT && cut.reason.len() >= MAX_DISPLAY_TEXT - 1);
    assert!(cut.reason.chars().all(|c| c == 'é'));
    assert_eq!(check_display_status(&cut), Ok(v1::DisplayState::Lost));
    // Refused: a string over the bound, the unspecified state, a state of a later version.
    let too_long = v1::DisplayStatus {
        state: v1::DisplayState::Lost as i32,
        output: "x".repeat(MAX_DISPLAY_TEXT + 1),
        reason: String::new(),
    };
    assert!(matches!(
        check_display_status(&too_long),
        Err(ProtoError::TooLarge {
            field: "display_status.output",
            ..
        })
    ));
    for state in [0, 7] {
        let s = v1::DisplayStatus {
            state,
            ..Default::default()
        };
        let e = check_display_status(&s).expect_err("refused");
        assert!(e.to_string().contains("display_status.state"), "{e}");
    }
}

#[test]
fn a_display_status_is_a_message_without_a_body_to_a_camera_agent_that_predates_it() {
    // A NodeMessage as version 3 had it before DisplayStatus: an older camera agent decodes the
    // new message as one without a body, which it ignores.
    #[derive(Clone, PartialEq, prost::Message)]
    struct OldNodeMessage {
        #[prost(oneof = "OldBody", tags = "4")]
        body: Option<OldBody>,
    }
    #[derive(Clone, PartialEq, prost::Oneof)]
    enum OldBody {
        #[prost(message, tag = "4")]
        Heartbeat(v1::Heartbeat),
    }
    let new = v1::NodeMessage {
        body: Some(v1::node_message::Body::DisplayStatus(display_status(
            v1::DisplayState::Lost,
            "A",
            "gone",
        ))),
    };
    let old =
        OldNodeMessage::decode(new.encode_to_vec().as_slice()).expect("an old peer decodes it");
    assert_eq!(old.body, None);
}
