//! Wire conversions round-trip and refuse malformed input with a clear message.

use prost::Message;
use roomlight_core::LinearRgb;
use roomlight_proto::convert::{ProtoError, from_rgb, from_sparse, to_rgb, to_sparse};
use roomlight_proto::v1;

#[test]
fn sparse_vectors_round_trip_through_bytes() {
    let patches = vec![2u32, 7, 40];
    let values = vec![
        LinearRgb([0.1, 0.2, 0.3]),
        LinearRgb([0.0, 1.0, 0.5]),
        LinearRgb([1e-9, 2.5, 0.25]),
    ];
    let msg = v1::Errors {
        round: 12,
        kind: v1::ErrorKind::Measured as i32,
        objective: 0.5,
        restart: true,
        node: 3,
        errors: Some(to_sparse(&patches, &values)),
    };
    let bytes = msg.encode_to_vec();
    let back = v1::Errors::decode(bytes.as_slice()).expect("decodes");
    assert_eq!(back, msg);
    let (p, v) = from_sparse("errors", back.errors.as_ref().expect("errors")).expect("valid");
    assert_eq!((p, v), (patches, values));
    assert_eq!(
        from_rgb("x", Some(&to_rgb(LinearRgb([0.25, 0.5, 1.0])))).expect("rgb"),
        LinearRgb([0.25, 0.5, 1.0])
    );
}

#[test]
fn malformed_sparse_vectors_are_refused() {
    let short = v1::SparseRgb {
        patches: vec![1, 2],
        values: vec![0.0; 5],
    };
    assert!(matches!(
        from_sparse("delta", &short),
        Err(ProtoError::Length {
            values: 5,
            patches: 2,
            ..
        })
    ));
    let nan = v1::SparseRgb {
        patches: vec![1],
        values: vec![0.0, f64::NAN, 0.0],
    };
    let err = from_sparse("delta", &nan).expect_err("nan");
    assert!(
        err.to_string().contains("delta") && err.to_string().contains("finite"),
        "{err}"
    );
    let unsorted = v1::SparseRgb {
        patches: vec![4, 4],
        values: vec![0.0; 6],
    };
    assert!(matches!(
        from_sparse("delta", &unsorted),
        Err(ProtoError::Unsorted { .. })
    ));
    assert!(matches!(
        from_rgb("x", None),
        Err(ProtoError::Missing { .. })
    ));
    let status: tonic::Status = ProtoError::Length {
        field: "delta",
        values: 5,
        patches: 2,
    }
    .into();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
}
