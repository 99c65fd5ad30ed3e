//! The virtual hardware over gRPC (DESIGN §6): `roomlight sim` serves a [`VirtualRoom`] as the
//! `VirtualHardware` service; node agents show through [`remote_display`] and the camera agent
//! captures through [`RemoteCamera`], so the same binaries run against simulated hardware in
//! separate processes.

use crate::AgentError;
use crate::hardware::{Assignment, Camera, Display, Gains, Pattern, VirtualRoom};
use roomlight_core::LinearRgb;
use roomlight_proto::convert::{from_rgb, to_rgb};
use roomlight_proto::v1;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status};

#[derive(Clone)]
struct Hardware(VirtualRoom);

#[tonic::async_trait]
impl v1::virtual_hardware_server::VirtualHardware for Hardware {
    async fn show(
        &self,
        request: Request<v1::ShowRequest>,
    ) -> Result<Response<v1::ShowReply>, Status> {
        let mut display = self.0.display();
        for v in &request.get_ref().values {
            let value = from_rgb("show value", v.x.as_ref())?;
            display.show(v.node, value);
        }
        Ok(Response::new(v1::ShowReply {}))
    }

    async fn capture(
        &self,
        _request: Request<v1::CaptureRequest>,
    ) -> Result<Response<v1::CaptureReply>, Status> {
        let values = self.0.camera().capture_now();
        Ok(Response::new(v1::CaptureReply {
            values: values.iter().flat_map(|v| v.0).collect(),
            true_objective: self.0.true_objective(),
        }))
    }
}

/// Serves a virtual room until `cancel`.
pub async fn serve_hardware(
    room: VirtualRoom,
    listener: tokio::net::TcpListener,
    cancel: CancellationToken,
) -> Result<(), AgentError> {
    tonic::transport::Server::builder()
        .add_service(v1::virtual_hardware_server::VirtualHardwareServer::new(
            Hardware(room),
        ))
        .serve_with_incoming_shutdown(
            tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
            cancel.cancelled_owned(),
        )
        .await?;
    Ok(())
}

/// What a [`QueuedDisplay`]'s task applies, in the order it was shown.
#[derive(Debug, Clone)]
pub enum Update {
    Value(u32, LinearRgb),
    Pattern(Pattern),
    Assign(Box<Assignment>),
    /// Per-pixel shading gains to draw node values with (`None`: without).
    Shade(Option<Box<Gains>>),
}

/// What a [`QueuedDisplay`] hands its background task.
#[derive(Debug)]
enum Queued {
    Update(Update),
    /// Answered once every update queued before it has been applied.
    Flush(tokio::sync::oneshot::Sender<()>),
}

/// A display whose updates a background task applies in batches (sent to another process, or
/// drawn into a projector image first); [`Display::flush`] resolves once everything shown before
/// it has been applied.
#[derive(Debug, Clone)]
pub struct QueuedDisplay {
    tx: mpsc::UnboundedSender<Queued>,
    /// The projector's resolution, for displays that draw pixels and show patterns.
    resolution: Option<(u32, u32)>,
}

impl QueuedDisplay {
    /// Spawns the task until `cancel`: `apply` is handed each batch of updates in the order they
    /// were shown (everything queued while the previous batch was applied) and returns a future
    /// that resolves once the display has them. `resolution`: the projector's, when this display
    /// draws pixels (it then shows patterns and takes assignments); `None` for node values only.
    pub fn spawn<F, Fut>(
        cancel: CancellationToken,
        resolution: Option<(u32, u32)>,
        mut apply: F,
    ) -> Self
    where
        F: FnMut(Vec<Update>) -> Fut + Send + 'static,
        Fut: Future<Output = ()> + Send,
    {
        let (tx, mut rx) = mpsc::unbounded_channel::<Queued>();
        tokio::spawn(async move {
            loop {
                let first = tokio::select! {
                    () = cancel.cancelled() => return,
                    q = rx.recv() => q,
                };
                let Some(first) = first else { return };
                let mut updates = Vec::new();
                let mut flushes = Vec::new();
                let mut take = |q: Queued| match q {
                    Queued::Update(u) => updates.push(u),
                    Queued::Flush(done) => flushes.push(done),
                };
                take(first);
                while let Ok(q) = rx.try_recv() {
                    take(q);
                }
                if !updates.is_empty() {
                    apply(updates).await;
                }
                for done in flushes {
                    let _ = done.send(());
                }
            }
        });
        Self { tx, resolution }
    }
}

impl Display for QueuedDisplay {
    fn show(&mut self, node: u32, value: LinearRgb) {
        // The task only stops with the agent.
        let _ = self.tx.send(Queued::Update(Update::Value(node, value)));
    }

    fn show_pattern(&mut self, pattern: Pattern) -> bool {
        self.resolution.is_some()
            && self
                .tx
                .send(Queued::Update(Update::Pattern(pattern)))
                .is_ok()
    }

    fn shade(&mut self, gains: Option<&Gains>) {
        if self.resolution.is_some() {
            let _ = self
                .tx
                .send(Queued::Update(Update::Shade(gains.cloned().map(Box::new))));
        }
    }

    fn assign(&mut self, assignment: &Assignment) {
        if self.resolution.is_some() {
            let _ = self
                .tx
                .send(Queued::Update(Update::Assign(Box::new(assignment.clone()))));
        }
    }

    fn resolution(&self) -> Option<(u32, u32)> {
        self.resolution
    }

    fn flush(&mut self) -> impl Future<Output = ()> + Send {
        let (done, taken) = tokio::sync::oneshot::channel();
        let queued = self.tx.send(Queued::Flush(done)).is_ok();
        async move {
            // A task that is gone (the agent stopping) has nothing left to wait for.
            if queued {
                let _ = taken.await;
            }
        }
    }
}

/// A display in another process (`roomlight sim`'s synthetic room): node values sent in
/// batches; the task ends with `cancel`.
pub async fn remote_display(
    endpoint: String,
    cancel: CancellationToken,
) -> Result<QueuedDisplay, AgentError> {
    let client = v1::virtual_hardware_client::VirtualHardwareClient::connect(endpoint).await?;
    Ok(QueuedDisplay::spawn(cancel, None, move |batch| {
        let values = batch
            .into_iter()
            .filter_map(|u| match u {
                Update::Value(node, x) => Some(v1::NodeState {
                    node,
                    x: Some(to_rgb(x)),
                    attenuation: None,
                }),
                Update::Pattern(_) | Update::Assign(_) | Update::Shade(_) => None,
            })
            .collect();
        let mut client = client.clone();
        async move {
            if let Err(status) = client.show(v1::ShowRequest { values }).await {
                tracing::warn!(%status, "the display did not take the frame");
            }
        }
    }))
}

/// Captures per second of the simulated camera unless told otherwise: a fast video camera's.
/// Unpaced, a synthetic room's rounds ran as fast as the CPU allowed (100% of a core for
/// nothing: the room converges in captures, not in seconds).
pub const SIM_CAPTURE_RATE: f64 = 60.0;

/// A camera in another process, paced to a capture rate as a real camera is by its frame rate.
#[derive(Debug, Clone)]
pub struct RemoteCamera {
    client: v1::virtual_hardware_client::VirtualHardwareClient<tonic::transport::Channel>,
    /// Time between two captures' starts.
    interval: std::time::Duration,
    /// When the next capture may start.
    next: Option<tokio::time::Instant>,
}

impl RemoteCamera {
    /// Connects to `endpoint`; captures at [`SIM_CAPTURE_RATE`].
    pub async fn connect(endpoint: String) -> Result<Self, AgentError> {
        Ok(Self {
            client: v1::virtual_hardware_client::VirtualHardwareClient::connect(endpoint).await?,
            interval: std::time::Duration::ZERO,
            next: None,
        }
        .with_capture_rate(SIM_CAPTURE_RATE))
    }

    /// At most `per_second` captures a second (clamped to 0.1 to 10 000; not a number: the
    /// default rate).
    pub fn with_capture_rate(mut self, per_second: f64) -> Self {
        let rate = if per_second.is_nan() {
            SIM_CAPTURE_RATE
        } else {
            per_second.clamp(0.1, 10_000.0)
        };
        // rate ≥ 0.1: the division is finite.
        self.interval = std::time::Duration::from_secs_f64(1.0 / rate);
        self
    }
}

impl Camera for RemoteCamera {
    fn capture(&mut self) -> impl Future<Output = Result<Vec<LinearRgb>, AgentError>> + Send {
        let mut client = self.client.clone();
        let now = tokio::time::Instant::now();
        let at = self.next.map_or(now, |next| next.max(now));
        self.next = Some(at + self.interval);
        async move {
            tokio::time::sleep_until(at).await;
            let reply = client.capture(v1::CaptureRequest {}).await?.into_inner();
            if reply.values.len() % 3 != 0 || reply.values.iter().any(|v| !v.is_finite()) {
                return Err(AgentError::Protocol(
                    "capture: expected three finite values per patch".into(),
                ));
            }
            tracing::debug!(true_objective = reply.true_objective, "captured");
            Ok(reply
                .values
                .chunks_exact(3)
                .map(|c| LinearRgb([c[0], c[1], c[2]]))
                .collect())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_core::closed_loop::{Plant, PlantConfig};
    use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};

    /// The synthetic room's camera is paced: 13 captures at 60 a second take at least 0.2 s
    /// (unpaced they took a few milliseconds, and rounds spun a core).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_simulated_camera_keeps_its_capture_rate() {
        let problem = synthetic_room(&SyntheticConfig::new(4, 1))
            .expect("room")
            .problem;
        let room = VirtualRoom::new(Plant::new(problem, PlantConfig::default()).expect("plant"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let endpoint = format!("http://{}", listener.local_addr().expect("address"));
        let cancel = CancellationToken::new();
        let _stop = cancel.clone().drop_guard();
        tokio::spawn(serve_hardware(room, listener, cancel.clone()));
        let mut camera = RemoteCamera::connect(endpoint).await.expect("connect");
        let start = tokio::time::Instant::now();
        for _ in 0..13 {
            camera.capture().await.expect("capture");
        }
        let took = start.elapsed();
        let least = std::time::Duration::from_secs_f64(12.0 / SIM_CAPTURE_RATE);
        assert!(
            took >= least,
            "13 captures in {took:?}, expected at least {least:?}"
        );
    }
}
