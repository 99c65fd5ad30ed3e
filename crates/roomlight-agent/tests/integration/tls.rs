//! TLS between the agents (issue 19) over loopback, with certificates made at test time by
//! `roomlight_agent::tls` (what `roomlight certs` runs): a node over TLS is admitted and rounds
//! run; a camera agent whose certificate is of another CA is refused by the node; with mTLS a
//! node whose certificate names another projector is refused with that reason; a plaintext node
//! against a TLS camera agent gets a clear error on both sides; a stream whose bearer metadata
//! is wrong is refused before its Hello is read. Every wait has a deadline.

use roomlight_agent::camera::{self, RoomStatus};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node;
use roomlight_agent::tls::{self, ClientTls, ServerTls, Subject, TlsFiles};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_proto::refusal::Refusal;
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio_stream::StreamExt;
use tokio_util::sync::CancellationToken;

use crate::common;
use common::TOKEN;

/// A room CA with the camera agent's certificate (`camera`, for 127.0.0.1) and `p0`'s and `p1`'s.
struct Certs {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

impl Certs {
    fn new() -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let root = dir.path().to_path_buf();
        tls::init_ca(&root.join("ca")).expect("CA");
        let camera = Subject {
            name: "camera".into(),
            ip: vec!["127.0.0.1".parse().expect("ip")],
            ..Default::default()
        };
        tls::issue(&root.join("ca"), &camera, &root.join("camera")).expect("camera cert");
        for p in ["p0", "p1"] {
            let subject = Subject {
                name: p.into(),
                ..Default::default()
            };
            tls::issue(&root.join("ca"), &subject, &root.join(p)).expect("node cert");
        }
        Self { _dir: dir, root }
    }

    fn file(&self, dir: &str, file: &str) -> Option<PathBuf> {
        Some(self.root.join(dir).join(file))
    }

    fn server(&self, require_client_cert: bool) -> ServerTls {
        TlsFiles {
            ca: self.file("ca", "ca.pem"),
            cert: self.file("camera", "camera.pem"),
            key: self.file("camera", "camera.key"),
            require_client_cert,
            camera_name: None,
        }
        .server(Path::new("camera.toml"))
        .expect("server TLS")
    }

    /// A node's TLS: the room CA, and with `cert` the certificate of that name.
    fn client(&self, cert: Option<&str>) -> ClientTls {
        TlsFiles {
            ca: self.file("ca", "ca.pem"),
            cert: cert.and_then(|c| self.file(c, &format!("{c}.pem"))),
            key: cert.and_then(|c| self.file(c, &format!("{c}.key"))),
            require_client_cert: false,
            camera_name: None,
        }
        .client(Path::new("node.toml"))
        .expect("client TLS")
    }
}

struct Room {
    room: VirtualRoom,
    endpoint: String,
    status: watch::Receiver<RoomStatus>,
    cancel: CancellationToken,
}

impl Drop for Room {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

/// A camera agent of two projectors (`p0`, `p1`) over TLS (or plaintext with `None`).
async fn start(tls: Option<ServerTls>) -> Room {
    let (problem, owners) = common::split_room(8, 7, 2);
    let room =
        VirtualRoom::new(Plant::new(problem.clone(), PlantConfig::default()).expect("plant"));
    let (listener, endpoint) = common::listen().await;
    let cancel = CancellationToken::new();
    let config = common::camera_config(Duration::from_millis(200), Duration::from_secs(1), 0);
    let model = common::model(problem, owners);
    let (status, _task) = camera::serve_tls(
        config,
        model,
        room.camera(),
        listener,
        tls,
        cancel.child_token(),
    );
    Room {
        room,
        endpoint,
        status,
        cancel,
    }
}

impl Room {
    fn node(
        &self,
        projector: &str,
        tls: Option<ClientTls>,
    ) -> tokio::task::JoinHandle<Result<(), roomlight_agent::AgentError>> {
        tokio::spawn(node::run_tls(
            common::node_config(&self.endpoint, projector),
            tls,
            self.room.display(),
            self.cancel.child_token(),
        ))
    }

    async fn wait(&mut self, within: Duration, pred: impl Fn(&RoomStatus) -> bool) -> RoomStatus {
        common::wait(&mut self.status, within, pred).await
    }
}

/// One attach as a node agent opens it: a Hello as `projector`, optionally bearer metadata.
async fn attach(
    channel: tonic::transport::Channel,
    projector: &str,
    bearer: Option<&str>,
) -> Result<v1::RoomMessage, tonic::Status> {
    let hello = v1::NodeMessage {
        body: Some(v1::node_message::Body::Hello(v1::Hello {
            protocol_version: PROTOCOL_VERSION,
            room: "lab".into(),
            token: TOKEN.into(),
            projector_id: projector.into(),
            ..Default::default()
        })),
    };
    let mut request =
        tonic::Request::new(tokio_stream::iter([hello]).chain(tokio_stream::pending()));
    if let Some(token) = bearer {
        let value = format!("Bearer {token}").parse().expect("metadata");
        request.metadata_mut().insert("authorization", value);
    }
    let mut client = v1::room_client::RoomClient::new(channel);
    let mut inbound = client.attach(request).await?.into_inner();
    tokio::time::timeout(Duration::from_secs(10), inbound.next())
        .await
        .map_err(|_| tonic::Status::deadline_exceeded("no first message"))?
        .ok_or_else(|| tonic::Status::aborted("ended"))?
}

#[tokio::test]
async fn nodes_over_tls_are_admitted_and_rounds_run() {
    let certs = Certs::new();
    let mut room = start(Some(certs.server(false))).await;
    // One node with only the room CA, one with its own certificate (checked against its id).
    let _p0 = room.node("p0", Some(certs.client(None)));
    let _p1 = room.node("p1", Some(certs.client(Some("p1"))));
    room.wait(Duration::from_secs(30), |s| {
        s.live_projectors == 2 && s.captures >= 3
    })
    .await;
}

#[tokio::test]
async fn a_camera_agent_of_another_ca_is_refused_by_the_node() {
    let certs = Certs::new();
    let other = Certs::new();
    let room = start(Some(certs.server(false))).await;
    let e = node::connect(&room.endpoint, Some(&other.client(None)))
        .await
        .expect_err("a camera agent of another CA");
    let text = format!("{e}: {:?}", std::error::Error::source(&e));
    assert!(text.to_lowercase().contains("certificate"), "{text}");
    // The same CA is accepted: the refusal was the CA's.
    let channel = node::connect(&room.endpoint, Some(&certs.client(None)))
        .await
        .expect("the room's CA");
    let welcome = attach(channel, "p0", Some(TOKEN)).await.expect("welcomed");
    assert!(
        matches!(welcome.body, Some(v1::room_message::Body::Welcome(_))),
        "{welcome:?}"
    );
}

#[tokio::test]
async fn with_mtls_a_certificate_of_another_projector_is_refused() {
    let certs = Certs::new();
    let room = start(Some(certs.server(true))).await;
    let channel = node::connect(&room.endpoint, Some(&certs.client(Some("p1"))))
        .await
        .expect("TLS with p1's certificate");
    let status = attach(channel, "p0", Some(TOKEN))
        .await
        .expect_err("p0 with p1's certificate");
    let refusal = Refusal::from_status(&status);
    assert!(
        matches!(&refusal, Some(Refusal::CertificateName { projector, certificate }) if projector == "p0" && certificate.contains("p1")),
        "{status:?}"
    );
    assert!(Refusal::is_fatal_status(&status));
    // Its own projector is welcomed.
    let channel = node::connect(&room.endpoint, Some(&certs.client(Some("p1"))))
        .await
        .expect("TLS");
    let welcome = attach(channel, "p1", Some(TOKEN)).await.expect("welcomed");
    assert!(matches!(
        welcome.body,
        Some(v1::room_message::Body::Welcome(_))
    ));
    // Without a certificate the handshake itself fails (mTLS required).
    let refused = match node::connect(&room.endpoint, Some(&certs.client(None))).await {
        Err(e) => e.to_string(),
        Ok(channel) => format!("{:?}", attach(channel, "p0", Some(TOKEN)).await),
    };
    assert!(!refused.contains("Welcome"), "{refused}");
}

#[tokio::test]
async fn a_wrong_bearer_token_is_refused_before_the_hello() {
    let room = start(None).await;
    let channel = node::connect(&room.endpoint, None)
        .await
        .expect("plaintext");
    // The Hello carries the right token: the metadata decides, before the Hello is read.
    let status = attach(channel.clone(), "p0", Some("wrong"))
        .await
        .expect_err("wrong bearer");
    assert_eq!(
        Refusal::from_status(&status),
        Some(Refusal::WrongToken),
        "{status:?}"
    );
    let welcome = attach(channel, "p0", Some(TOKEN))
        .await
        .expect("right bearer");
    assert!(matches!(
        welcome.body,
        Some(v1::room_message::Body::Welcome(_))
    ));
}

/// Log lines, as the fmt subscriber would write their message and fields; a waiter is woken
/// by each new line.
#[derive(Clone)]
struct Captured(Arc<watch::Sender<Vec<String>>>);

impl Default for Captured {
    fn default() -> Self {
        Self(Arc::new(watch::channel(Vec::new()).0))
    }
}

struct Line(String);

impl tracing::field::Visit for Line {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        self.0.push_str(&format!(" {}={value:?}", field.name()));
    }
}

impl tracing::Subscriber for Captured {
    fn enabled(&self, _: &tracing::Metadata<'_>) -> bool {
        true
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, event: &tracing::Event<'_>) {
        let mut line = Line(String::new());
        event.record(&mut line);
        self.0.send_modify(|lines| lines.push(line.0));
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

impl Captured {
    /// Waits (at most `within`) for a line containing every one of `words`.
    async fn wait_for(&self, within: Duration, words: &[&str]) {
        let mut lines = self.0.subscribe();
        let found = tokio::time::timeout(
            within,
            lines.wait_for(|lines| lines.iter().any(|l| words.iter().all(|w| l.contains(w)))),
        )
        .await
        .is_ok_and(|r| r.is_ok());
        let lines = self.0.borrow().clone();
        assert!(
            found,
            "no line with {words:?} within {within:?}: {lines:#?}"
        );
    }
}

/// (One thread: the subscriber sees every task.)
#[tokio::test(flavor = "current_thread")]
async fn a_plaintext_node_and_a_tls_camera_agent_both_say_so() {
    let log = Captured::default();
    let _default = tracing::subscriber::set_default(log.clone());
    let certs = Certs::new();
    let mut room = start(Some(certs.server(false))).await;
    let _node = room.node("p0", None);
    log.wait_for(
        Duration::from_secs(20),
        &["plaintext connection from", "this camera agent speaks TLS"],
    )
    .await;
    log.wait_for(
        Duration::from_secs(20),
        &["did not answer in plaintext; does it need tls?"],
    )
    .await;
    assert_eq!(room.status.borrow_and_update().live_projectors, 0);
    // And the other way round: a TLS node against a plaintext camera agent.
    let plain = start(None).await;
    let _node = plain.node("p1", Some(certs.client(None)));
    log.wait_for(
        Duration::from_secs(20),
        &["TLS connection from", "speaks plaintext"],
    )
    .await;
    log.wait_for(Duration::from_secs(20), &["did not answer in TLS"])
        .await;
}
