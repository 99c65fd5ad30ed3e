//! Every refusal survives the trip to a `tonic::Status` and back, through the HTTP/2 headers a
//! status travels in, with the table's code and the same message on both sides.

use roomlight_proto::refusal::Refusal;
use std::collections::HashSet;
use tonic::codegen::http::HeaderMap;
use tonic::{Code, Status};

/// One of each variant, with fields that exercise the text encoding (quotes, non-ASCII, empty).
fn every_refusal() -> Vec<Refusal> {
    let projector = "päin \"p0\"".to_string();
    let room = "lab".to_string();
    vec![
        Refusal::ProtocolVersion { got: 99, speaks: 1 },
        Refusal::OtherRoom {
            asked: "kitchen".into(),
            room: room.clone(),
        },
        Refusal::WrongToken,
        Refusal::UnknownProjector {
            projector: projector.clone(),
            room: room.clone(),
        },
        Refusal::NoResolution {
            projector: projector.clone(),
            room: String::new(),
        },
        Refusal::AlreadyAttached {
            projector,
            room: room.clone(),
        },
        Refusal::NoHello,
        Refusal::FirstNotHello,
        Refusal::EndedBeforeHello,
        Refusal::LeftDuringHandshake,
        Refusal::CertificateName {
            projector: "p2".into(),
            certificate: "p1, node-pc.local".into(),
        },
        Refusal::Lagging { queue: 256 },
        Refusal::Malformed {
            what: "contribution: patches not increasing".into(),
        },
        Refusal::ShuttingDown,
    ]
}

/// The status as the other side reads it: its headers, parsed back.
fn over_the_wire(status: &Status) -> Status {
    let mut headers = HeaderMap::new();
    status.add_header(&mut headers).expect("headers");
    Status::from_header_map(&headers).expect("a status")
}

#[test]
fn the_examples_cover_the_whole_table_once() {
    let keys: Vec<&str> = every_refusal().iter().map(|r| r.row().key).collect();
    let table: Vec<&str> = Refusal::TABLE.iter().map(|row| row.key).collect();
    assert_eq!(keys, table);
    assert_eq!(
        table.iter().collect::<HashSet<_>>().len(),
        table.len(),
        "wire names are unique"
    );
}

#[test]
fn every_refusal_round_trips_through_a_status_and_its_headers() {
    for refusal in every_refusal() {
        let status = refusal.to_status();
        assert_eq!(status.code(), refusal.row().code, "{refusal}");
        assert_eq!(status.message(), refusal.to_string());
        assert_eq!(Refusal::from_status(&status).as_ref(), Some(&refusal));
        let received = over_the_wire(&status);
        assert_eq!(received.code(), status.code(), "{refusal}");
        assert_eq!(received.message(), refusal.to_string());
        assert_eq!(Refusal::from_status(&received), Some(refusal.clone()));
        assert_eq!(Refusal::is_fatal_status(&received), refusal.is_fatal());
        assert_eq!(Status::from(refusal.clone()).code(), refusal.row().code);
    }
}

/// The messages node agents and operators already know stay as they were.
#[test]
fn messages_name_the_reason_and_its_values() {
    assert_eq!(
        Refusal::ProtocolVersion { got: 99, speaks: 1 }.to_string(),
        "protocol version 99, this camera agent speaks 1"
    );
    assert_eq!(
        Refusal::OtherRoom {
            asked: "kitchen".into(),
            room: "lab".into()
        }
        .to_string(),
        "room \"kitchen\", this is room \"lab\""
    );
    assert_eq!(
        Refusal::AlreadyAttached {
            projector: "p0".into(),
            room: "lab".into()
        }
        .to_status()
        .message(),
        "projector \"p0\" is already attached to room \"lab\""
    );
}

/// What retrying cannot fix ends the node agent; the rest is retried with backoff.
#[test]
fn fatality_follows_the_reason() {
    let fatal: Vec<&str> = every_refusal()
        .iter()
        .filter(|r| r.is_fatal())
        .map(|r| r.row().key)
        .collect();
    assert_eq!(
        fatal,
        [
            "protocol-version",
            "other-room",
            "wrong-token",
            "unknown-projector",
            "no-resolution",
            "first-not-hello",
            "ended-before-hello",
            "certificate-name",
            "malformed"
        ]
    );
}

/// A status without a refusal (a camera agent of an older build, a proxy) is judged by its code
/// alone, and the table gives every code one fatality, so that judgement agrees with the
/// refusal's own.
#[test]
fn each_code_has_one_fatality_so_a_bare_code_is_judged_alike() {
    for a in Refusal::TABLE {
        for b in Refusal::TABLE.iter().filter(|b| b.code == a.code) {
            assert_eq!(
                a.fatal, b.fatal,
                "{} and {} share {:?}",
                a.key, b.key, a.code
            );
        }
        let bare = Status::new(a.code, "from an older camera agent");
        assert_eq!(Refusal::from_status(&bare), None);
        assert_eq!(Refusal::is_fatal_status(&bare), a.fatal, "{:?}", a.code);
    }
    for code in [Code::Unknown, Code::Internal, Code::Cancelled] {
        assert!(!Refusal::is_fatal_status(&Status::new(code, "transport")));
    }
}

/// A status whose metadata names an unknown refusal, lacks a field, carries an unreadable one,
/// or comes with another code than the table's is not taken for a refusal.
#[test]
fn statuses_that_do_not_match_the_table_are_not_refusals() {
    let tampered = |edit: &dyn Fn(&mut tonic::metadata::MetadataMap)| {
        let status = Refusal::ProtocolVersion { got: 2, speaks: 1 }.to_status();
        let mut metadata = status.metadata().clone();
        edit(&mut metadata);
        Status::with_metadata(status.code(), status.message(), metadata)
    };
    let unknown = tampered(&|m| {
        m.insert(
            "roomlight-refusal",
            tonic::metadata::AsciiMetadataValue::from_static("no-such-reason"),
        );
    });
    assert_eq!(Refusal::from_status(&unknown), None);
    let missing = tampered(&|m| {
        m.remove_bin("roomlight-refusal-got-bin");
    });
    assert_eq!(Refusal::from_status(&missing), None);
    let unreadable = tampered(&|m| {
        m.insert_bin(
            "roomlight-refusal-got-bin",
            tonic::metadata::BinaryMetadataValue::from_bytes(b"two"),
        );
    });
    assert_eq!(Refusal::from_status(&unreadable), None);
    let status = Refusal::WrongToken.to_status();
    let recoded =
        Status::with_metadata(Code::NotFound, status.message(), status.metadata().clone());
    assert_eq!(Refusal::from_status(&recoded), None);
}
