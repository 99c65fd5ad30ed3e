//! `roomlight check`: the pre-flight of one PC's agent, before a show. Each item is tried in
//! turn with a deadline and reported with what it found and how long it took; an item whose
//! precondition failed (no camera agent found, so none to connect to) is not tried. The config
//! itself was loaded and checked by the caller (the binary's config module).
//!
//! A node's check attaches to the camera agent as its projector for a moment (the only way to
//! know that the room, the token and the projector id are accepted): run it before the node
//! agent starts, or read "already attached" as the running agent holding the place.

use super::camera::{CameraHardware, CameraProcess, CameraSource};
use super::node::NodeDisplay;
use roomlight_agent::discovery::{self, MdnsConfig};
use roomlight_agent::node::NodeConfig;
use roomlight_proto::refusal::Refusal;
use roomlight_proto::{PROTOCOL_VERSION, v1};
use std::fmt;
use std::path::Path;
use std::time::{Duration, Instant};

/// How long a connection or a handshake may take before the item fails.
const NETWORK_DEADLINE: Duration = Duration::from_secs(5);

/// The items checked, in order, with their outcomes.
#[derive(Debug, Default)]
pub struct Checklist(Vec<Item>);

#[derive(Debug)]
struct Item {
    what: String,
    outcome: Result<String, String>,
    took: Duration,
}

impl Checklist {
    /// Runs one item, recording its outcome; true when it passed.
    async fn item<F>(&mut self, what: impl Into<String>, check: F) -> bool
    where
        F: Future<Output = Result<String, String>>,
    {
        let started = Instant::now();
        let outcome = check.await;
        let passed = outcome.is_ok();
        self.0.push(Item {
            what: what.into(),
            outcome,
            took: started.elapsed(),
        });
        passed
    }

    /// An item that was not tried because one it needs failed.
    fn skipped(&mut self, what: impl Into<String>, because: &str) {
        self.0.push(Item {
            what: what.into(),
            outcome: Err(format!("not tried: {because}")),
            took: Duration::ZERO,
        });
    }

    /// The first item that failed, as `what: why`.
    pub fn first_failure(&self) -> Option<String> {
        self.0.iter().find_map(|i| match &i.outcome {
            Err(why) => Some(format!("{}: {why}", i.what)),
            Ok(_) => None,
        })
    }
}

impl fmt::Display for Checklist {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for item in &self.0 {
            let (mark, text) = match &item.outcome {
                Ok(found) => ("ok  ", found),
                Err(why) => ("FAIL", why),
            };
            writeln!(
                f,
                "{mark}  {}: {text} ({} ms)",
                item.what,
                item.took.as_millis()
            )?;
        }
        Ok(())
    }
}

/// Where a node's config says the camera agent is.
#[derive(Debug, Clone)]
pub enum CameraAt {
    Address(String),
    /// Found over mDNS: the room advertised, where mDNS runs, how long to look.
    Mdns(String, MdnsConfig, Duration),
}

/// A node agent's pre-flight: the camera agent found, reached and accepting this projector
/// (protocol version, room, token), its display there, its state file writable.
pub async fn check_node(
    config: &NodeConfig,
    tls: Option<&roomlight_agent::tls::ClientTls>,
    camera: &CameraAt,
    hardware: &str,
    display: &NodeDisplay,
) -> Checklist {
    let mut list = Checklist::default();
    let mut endpoint = None;
    let found = list
        .item("camera agent", async {
            let e = resolve(camera).await?;
            let how = match camera {
                CameraAt::Address(_) => "as configured",
                CameraAt::Mdns(..) => "found over mDNS",
            };
            let said = format!("{e} ({how})");
            endpoint = Some(e);
            Ok(said)
        })
        .await;
    let handshake = format!(
        "attach as projector {:?} to room {:?}",
        config.projector_id, config.room
    );
    match endpoint.filter(|_| found) {
        Some(e) => {
            list.item(handshake, attach(&e, config, tls)).await;
        }
        None => list.skipped(handshake, "no camera agent"),
    }
    list.item("display", check_display(hardware, display)).await;
    if let Some(path) = &config.state_file {
        list.item(format!("state file {}", path.display()), writable(path))
            .await;
    }
    list
}

/// A camera agent's pre-flight: its address free to listen on, its model or survey readable,
/// its camera answering (one capture of a real camera, exposure as asked), where it writes
/// writable.
pub async fn check_camera(process: &CameraProcess) -> Checklist {
    let mut list = Checklist::default();
    let listen = process.listen.clone();
    list.item(format!("listen on {listen}"), async move {
        match tokio::net::TcpListener::bind(&listen).await {
            Ok(l) => Ok(format!(
                "free ({})",
                l.local_addr().map_err(|e| e.to_string())?
            )),
            Err(e) => Err(format!("{e} (is the camera agent already running?)")),
        }
    })
    .await;
    match &process.source {
        CameraSource::Model { model, charts } => {
            list.item(format!("model {}", model.display()), async {
                let m = super::files::load_model(model).map_err(|e| format!("{e:#}"))?;
                Ok(format!(
                    "{} nodes of {} projectors, {} patches",
                    m.problem.nodes(),
                    m.owners.len(),
                    m.problem.patches()
                ))
            })
            .await;
            if let Some(charts) = charts {
                list.item(format!("charts {}", charts.display()), readable(charts))
                    .await;
            }
        }
        CameraSource::Survey {
            survey,
            dark_weight,
            ..
        } => {
            list.item(
                format!(
                    "survey {} (dark target weight {dark_weight})",
                    survey.display()
                ),
                readable(survey),
            )
            .await;
        }
    }
    if let Some(out) = &process.agent.model_out {
        list.item(format!("model_out {}", out.display()), writable(out))
            .await;
    }
    match &process.hardware {
        CameraHardware::Sim(endpoint) => {
            list.item(format!("camera (simulator at {endpoint})"), reach(endpoint))
                .await;
        }
        CameraHardware::Real { camera, .. } => {
            let what = format!("camera {}", camera.spec);
            let camera = (**camera).clone();
            list.item(what, async move {
                // A capture blocks (a DSLR takes seconds): off the runtime's threads.
                tokio::task::spawn_blocking(move || {
                    let out = tempfile::Builder::new()
                        .suffix(".png")
                        .tempfile()
                        .map_err(|e| format!("a scratch file: {e}"))?;
                    roomlight_camera::cli::capture_config(&camera, out.path())
                        .map(|report| report.to_string())
                        .map_err(|e| e.to_string())
                })
                .await
                .map_err(|e| format!("the capture task: {e}"))?
            })
            .await;
        }
    }
    list
}

/// The camera agent's endpoint: as configured, or the first mDNS candidate of the room.
async fn resolve(camera: &CameraAt) -> Result<String, String> {
    match camera {
        CameraAt::Address(a) => Ok(a.clone()),
        CameraAt::Mdns(room, mdns, within) => {
            let (room, mdns, within) = (room.clone(), mdns.clone(), *within);
            tokio::task::spawn_blocking(move || discovery::find_camera(&room, &mdns, within))
                .await
                .map_err(|e| format!("the mDNS task: {e}"))?
                .map_err(|e| e.to_string())
        }
    }
}

/// Hello as the node would send it (no state), and the camera agent's first answer: a Welcome
/// (protocol version, room and token accepted) or its refusal, by name.
async fn attach(
    endpoint: &str,
    config: &NodeConfig,
    tls: Option<&roomlight_agent::tls::ClientTls>,
) -> Result<String, String> {
    let work = async {
        let channel = roomlight_agent::node::connect(endpoint, tls)
            .await
            .map_err(|e| format!("{endpoint}: unreachable: {}", causes(&e)))?;
        let mut client = v1::room_client::RoomClient::new(channel);
        let hello = v1::NodeMessage {
            body: Some(v1::node_message::Body::Hello(v1::Hello {
                protocol_version: PROTOCOL_VERSION,
                room: config.room.clone(),
                token: config.token.clone(),
                projector_id: config.projector_id.clone(),
                kind: config.kind as i32,
                ..Default::default()
            })),
        };
        let (tx, rx) = tokio::sync::mpsc::channel(1);
        tx.send(hello)
            .await
            .map_err(|_| "the request stream closed")?;
        let refused = |status: tonic::Status| match Refusal::from_status(&status) {
            Some(refusal) => format!("refused: {refusal}"),
            None => format!("refused: {} ({:?})", status.message(), status.code()),
        };
        let mut stream = client
            .attach(tokio_stream::wrappers::ReceiverStream::new(rx))
            .await
            .map_err(refused)?
            .into_inner();
        let first = stream.message().await.map_err(refused)?;
        // Leaving at once: the camera agent sees this projector go.
        drop(tx);
        match first.and_then(|m| m.body) {
            Some(v1::room_message::Body::Welcome(w)) => Ok(format!(
                "{endpoint}: welcomed (protocol version {}, room {:?}, calibration epoch {})",
                w.protocol_version, w.room, w.calibration_epoch
            )),
            other => Err(format!(
                "{endpoint}: expected a Welcome first, got {other:?}"
            )),
        }
    };
    tokio::time::timeout(NETWORK_DEADLINE * 2, work)
        .await
        .map_err(|_| format!("{endpoint}: no answer within {:?}", NETWORK_DEADLINE * 2))?
}

/// An error with its causes, `outer: inner: ...` (tonic's own says only "transport error").
fn causes(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        text = format!("{text}: {cause}");
        source = cause.source();
    }
    text
}

/// The display the node agent will drive: its output on the X server, or its simulator.
async fn check_display(hardware: &str, display: &NodeDisplay) -> Result<String, String> {
    match display {
        NodeDisplay::Window(spec) => {
            let outputs = roomlight_hw::output::outputs(spec.x_display.as_deref())
                .map_err(|e| e.to_string())?;
            let output = spec.output.pick(&outputs).map_err(|e| e.to_string())?;
            Ok(format!("output {output}"))
        }
        _ => reach(hardware).await.map(|s| format!("simulator: {s}")),
    }
}

/// A TCP connection to an `http://host:port` endpoint, within the deadline.
async fn reach(endpoint: &str) -> Result<String, String> {
    let address = endpoint
        .strip_prefix("http://")
        .unwrap_or(endpoint)
        .trim_end_matches('/');
    match tokio::time::timeout(NETWORK_DEADLINE, tokio::net::TcpStream::connect(address)).await {
        Ok(Ok(_)) => Ok(format!("{address} answers")),
        Ok(Err(e)) => Err(format!("{address}: unreachable: {e}")),
        Err(_) => Err(format!("{address}: no answer within {NETWORK_DEADLINE:?}")),
    }
}

async fn readable(path: &Path) -> Result<String, String> {
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    std::fs::File::open(path).map_err(|e| e.to_string())?;
    Ok(format!("{} bytes", meta.len()))
}

/// That a file can be written where `path` is (a scratch file beside it, removed again),
/// without touching the file itself.
async fn writable(path: &Path) -> Result<String, String> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let probe = tempfile::Builder::new()
        .prefix(".roomlight-check")
        .tempfile_in(dir)
        .map_err(|e| format!("cannot write in {}: {e}", dir.display()))?;
    drop(probe);
    Ok(match std::fs::metadata(path) {
        Ok(m) => format!("writable ({} bytes now)", m.len()),
        Err(_) => "writable (not there yet)".into(),
    })
}
