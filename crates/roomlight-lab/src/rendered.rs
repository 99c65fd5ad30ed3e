//! `roomlight sim --scene`: the simulated room served as the `RenderedRoom` gRPC service —
//! whole projector images in, noisy camera images out, LED presets switched by name — so that
//! processes can drive the rendered room as they would real projectors and a real camera.

use anyhow::{Context, Result};
use roomlight_agent::hardware::{Assignment, Pattern};
use roomlight_proto::v1;
use roomlight_sim::{CameraNoise, Frame, ProjectorImage, Room};
use std::sync::{Arc, Mutex, PoisonError};
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status};

/// Largest message either way: a 4K camera image of f32 RGB is about 100 MB.
pub const MAX_MESSAGE: usize = 256 << 20;

struct State {
    frames: Vec<Frame>,
    preset: Option<usize>,
    noise: CameraNoise,
}

/// The served room and what it shows; shared with the grab mode (`process::photos`), which
/// takes the projectors' frames from the screen instead of from `ShowImage`.
#[derive(Clone)]
pub struct Rendered {
    room: Arc<Room>,
    state: Arc<Mutex<State>>,
    /// Frames come from the screen: `ShowImage` is refused.
    from_screen: bool,
}

impl std::fmt::Debug for Rendered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rendered")
            .field("room", &self.room.scene().name)
            .field("from_screen", &self.from_screen)
            .finish_non_exhaustive()
    }
}

impl Rendered {
    /// All projectors black, LEDs off, camera noise from `seed`.
    pub fn new(room: Arc<Room>, seed: u64, from_screen: bool) -> Self {
        let state = State {
            frames: vec![Frame::Black; room.projectors().len()],
            preset: None,
            noise: CameraNoise::with_seed(&room, seed),
        };
        Self {
            room,
            state: Arc::new(Mutex::new(state)),
            from_screen,
        }
    }

    /// What each projector shows now (what a test renders the noiseless truth of).
    pub fn frames(&self) -> Vec<Frame> {
        self.state().frames.clone()
    }

    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Shows `frames` (one per projector) and photographs the room under the current LEDs,
    /// with the camera's noise. Blocking: rendering takes a fraction of a second.
    pub(crate) fn photograph(
        &self,
        frames: Vec<Frame>,
    ) -> Result<roomlight_sim::Capture, roomlight_sim::SimError> {
        let preset = {
            let mut s = self.state();
            s.frames = frames.clone();
            s.preset
        };
        let clean = self.room.render(&frames, preset)?;
        Ok(self.state().noise.expose(&clean))
    }
}

#[tonic::async_trait]
impl v1::rendered_room_server::RenderedRoom for Rendered {
    async fn describe(
        &self,
        _request: Request<v1::DescribeRequest>,
    ) -> Result<Response<v1::RoomDescription>, Status> {
        let scene = self.room.scene();
        Ok(Response::new(v1::RoomDescription {
            room: scene.name.clone(),
            projectors: scene
                .projectors
                .iter()
                .map(|p| v1::ProjectorDescription {
                    name: p.name.clone(),
                    width: p.resolution[0],
                    height: p.resolution[1],
                })
                .collect(),
            presets: scene.presets.iter().map(|p| p.name.clone()).collect(),
            camera_width: scene.camera.resolution[0],
            camera_height: scene.camera.resolution[1],
            camera_saturation: scene.camera.saturation as f32,
        }))
    }

    async fn show_image(
        &self,
        request: Request<v1::ShowImageRequest>,
    ) -> Result<Response<v1::ShowReply>, Status> {
        if self.from_screen {
            return Err(Status::failed_precondition(
                "this room takes its projectors' frames from the screen (grab mode), not from \
                 ShowImage",
            ));
        }
        let r = request.into_inner();
        let scene = self.room.scene();
        let Some(k) = scene.projectors.iter().position(|p| p.name == r.projector) else {
            return Err(Status::not_found(format!(
                "no projector {:?} in room {:?} (it has {})",
                r.projector,
                scene.name,
                scene
                    .projectors
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        };
        let [w, h] = scene.projectors[k].resolution;
        if (r.width, r.height) != (w, h) {
            return Err(Status::invalid_argument(format!(
                "projector {}: image of {}×{}, expected {w}×{h}",
                r.projector, r.width, r.height
            )));
        }
        let expected = w as usize * h as usize * 3;
        if r.rgb8.len() != expected {
            return Err(Status::invalid_argument(format!(
                "projector {}: {} bytes of rgb8, expected {expected} ({w}×{h}×3)",
                r.projector,
                r.rgb8.len()
            )));
        }
        let pixels = r
            .rgb8
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]].map(|v| f32::from(v) / 255.0))
            .collect();
        self.state().frames[k] = Frame::Image(ProjectorImage {
            width: w,
            height: h,
            pixels,
        });
        Ok(Response::new(v1::ShowReply {}))
    }

    async fn set_lights(
        &self,
        request: Request<v1::SetLightsRequest>,
    ) -> Result<Response<v1::SetLightsReply>, Status> {
        let name = request.into_inner().preset;
        let preset = if name.is_empty() {
            None
        } else {
            Some(self.room.preset(&name).map_err(|_| {
                Status::not_found(format!(
                    "no LED preset {name:?} in room {:?} (it has {})",
                    self.room.scene().name,
                    self.room
                        .scene()
                        .presets
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?)
        };
        self.state().preset = preset;
        Ok(Response::new(v1::SetLightsReply {}))
    }

    async fn capture_image(
        &self,
        _request: Request<v1::CaptureRequest>,
    ) -> Result<Response<v1::Image>, Status> {
        let this = self.clone();
        // Rendering takes a fraction of a second: off the async threads.
        let capture = tokio::task::spawn_blocking(move || {
            let (frames, preset) = {
                let s = this.state();
                (s.frames.clone(), s.preset)
            };
            let clean = this.room.render(&frames, preset)?;
            Ok::<_, roomlight_sim::SimError>(this.state().noise.expose(&clean))
        })
        .await
        .map_err(|e| Status::internal(format!("render task: {e}")))?
        .map_err(|e| Status::internal(format!("render: {e}")))?;
        let linear_f32le = capture
            .pixels
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
            .collect();
        Ok(Response::new(v1::Image {
            width: capture.width,
            height: capture.height,
            linear_f32le,
        }))
    }
}

/// Serves `room` (all projectors black, LEDs off, camera noise from `seed`) until `cancel`.
pub async fn serve(
    room: Arc<Room>,
    seed: u64,
    listener: tokio::net::TcpListener,
    cancel: CancellationToken,
) -> Result<()> {
    serve_rendered(Rendered::new(room, seed, false), listener, cancel).await
}

/// Serves `rendered` until `cancel`.
pub async fn serve_rendered(
    rendered: Rendered,
    listener: tokio::net::TcpListener,
    cancel: CancellationToken,
) -> Result<()> {
    let service = v1::rendered_room_server::RenderedRoomServer::new(rendered)
        .max_decoding_message_size(MAX_MESSAGE)
        .max_encoding_message_size(MAX_MESSAGE);
    tonic::transport::Server::builder()
        .add_service(service)
        .serve_with_incoming_shutdown(
            tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
            cancel.cancelled_owned(),
        )
        .await
        .context("serving the rendered room")
}

/// A client of the rendered room, with messages large enough for whole camera images.
pub type Client = v1::rendered_room_client::RenderedRoomClient<tonic::transport::Channel>;

/// Connects to a `RenderedRoom` service at `endpoint`.
pub async fn connect(endpoint: String) -> Result<Client, roomlight_agent::AgentError> {
    Ok(
        v1::rendered_room_client::RenderedRoomClient::connect(endpoint)
            .await?
            .max_decoding_message_size(MAX_MESSAGE)
            .max_encoding_message_size(MAX_MESSAGE),
    )
}

/// The camera agent's camera on a rendered room: each capture is a whole image, sampled at the
/// charts (corners, inner-half boxes, trimmed means) and reduced to the model's patches.
#[derive(Clone, Debug)]
pub struct RenderedCamera {
    client: Client,
    corners: Arc<Vec<roomlight_calib::charts::ChartCorners>>,
    /// Room patch index of each model patch.
    patches: Arc<Vec<usize>>,
    sample: roomlight_calib::charts::SampleConfig,
    /// Where a capture clips ([`v1::RoomDescription::camera_saturation`]); NaN: unknown.
    saturation: f32,
    /// Holds each capture until a driver has handled the camera agent's last status.
    gate: Option<Arc<crate::pipeline::gate::Gate>>,
}

impl RenderedCamera {
    pub fn new(
        client: Client,
        corners: Vec<roomlight_calib::charts::ChartCorners>,
        patches: Vec<usize>,
        sample: roomlight_calib::charts::SampleConfig,
    ) -> Self {
        Self {
            client,
            corners: Arc::new(corners),
            patches: Arc::new(patches),
            sample,
            saturation: f32::NAN,
            gate: None,
        }
    }

    /// Each capture held by `gate` (a run reproducible at a fixed seed,
    /// [`crate::pipeline::gate`]).
    pub fn with_gate(self, gate: Arc<crate::pipeline::gate::Gate>) -> Self {
        Self {
            gate: Some(gate),
            ..self
        }
    }

    /// Waits for the gate, when there is one.
    async fn held(&self) {
        if let Some(gate) = &self.gate {
            gate.wait().await;
        }
    }

    /// The camera clipping at `saturation` as the room described it (calibration reads a
    /// single shot's clipped pixels from their own patterns there); a value that is not a
    /// positive finite number (0: the room did not say) leaves it unknown.
    pub fn with_saturation(self, saturation: f32) -> Self {
        Self {
            saturation: if saturation.is_finite() && saturation > 0.0 {
                saturation
            } else {
                f32::NAN
            },
            ..self
        }
    }
}

/// A capture's bytes as an image; refused unless they are `width · height` finite RGB triples.
fn decode_image(image: v1::Image) -> Result<roomlight_calib::image_io::LinearImage, String> {
    let expected = image.width as usize * image.height as usize * 12;
    if image.linear_f32le.len() != expected {
        return Err(format!(
            "capture of {}×{}: {} bytes, expected {expected}",
            image.width,
            image.height,
            image.linear_f32le.len()
        ));
    }
    let values: Vec<f32> = image
        .linear_f32le
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if values.iter().any(|v| !v.is_finite()) {
        return Err("capture holds a value that is not finite".into());
    }
    Ok(roomlight_calib::image_io::LinearImage {
        width: image.width,
        height: image.height,
        pixels: values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    })
}

impl RenderedCamera {
    /// The client it captures through.
    pub fn client(&self) -> Client {
        self.client.clone()
    }

    /// Switches the room's LEDs to `preset` (empty: all off).
    pub async fn set_lights(&self, preset: &str) -> Result<(), roomlight_agent::AgentError> {
        let mut client = self.client.clone();
        client
            .set_lights(v1::SetLightsRequest {
                preset: preset.to_string(),
            })
            .await?;
        Ok(())
    }

    /// One whole image.
    pub async fn image(
        &self,
    ) -> Result<roomlight_calib::image_io::LinearImage, roomlight_agent::AgentError> {
        let mut client = self.client.clone();
        let image = client.capture_image(v1::CaptureRequest {}).await?;
        decode_image(image.into_inner()).map_err(roomlight_agent::AgentError::Protocol)
    }
}

impl roomlight_agent::hardware::Camera for RenderedCamera {
    fn limits(&self) -> roomlight_calib::rig::CameraLimits {
        roomlight_calib::rig::CameraLimits {
            saturation: self.saturation,
            longest_exposure: 1.0,
        }
    }

    fn capture_image(
        &mut self,
    ) -> impl Future<
        Output = Result<roomlight_calib::image_io::LinearImage, roomlight_agent::AgentError>,
    > + Send {
        let this = self.clone();
        async move {
            this.held().await;
            this.image().await
        }
    }

    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<roomlight_core::LinearRgb>, roomlight_agent::AgentError>> + Send
    {
        let this = self.clone();
        async move {
            let protocol = roomlight_agent::AgentError::Protocol;
            this.held().await;
            let mut client = this.client.clone();
            let image = client.capture_image(v1::CaptureRequest {}).await?;
            let image = decode_image(image.into_inner()).map_err(protocol)?;
            let samples =
                roomlight_calib::charts::sample_charts(&image, &this.corners, &this.sample)
                    .map_err(|e| protocol(format!("charts: {e}")))?;
            this.patches
                .iter()
                .map(|&i| {
                    samples.get(i).map(|s| s.mean).ok_or_else(|| {
                        protocol(format!("patch {i}: the charts have {}", samples.len()))
                    })
                })
                .collect()
        }
    }
}

/// What a node agent's host knows of its projector to draw node values: each node's feathered
/// weights (sparse, row-major pixels) and the projector's measured response.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct FrameSpec {
    pub projector: String,
    pub width: u32,
    pub height: u32,
    pub response: roomlight_calib::response::Response,
    /// `(node id, [(pixel, weight)])`.
    pub nodes: Vec<(u32, Vec<(u32, f32)>)>,
}

impl FrameSpec {
    /// What the node agent's display draws with: the assignment the camera agent would send.
    pub fn assignment(self) -> Assignment {
        Assignment {
            width: self.width,
            height: self.height,
            response: self.response,
            nodes: self.nodes,
        }
    }
}

/// The 8-bit image of node values `x` (nodes without a value are black) drawn with
/// `assignment` and shaded by `gains` ([`Assignment::draw_shaded`], as every display that
/// draws pixels).
fn values_image(
    assignment: &Assignment,
    x: &std::collections::HashMap<u32, roomlight_core::LinearRgb>,
    gains: Option<&roomlight_agent::hardware::Gains>,
) -> Vec<u8> {
    let values: Vec<(u32, roomlight_core::LinearRgb)> = x.iter().map(|(&n, &v)| (n, v)).collect();
    assignment
        .draw_shaded(&values, gains)
        .into_iter()
        .flat_map(|c| c.map(byte))
        .collect()
}

/// A code in [0, 1] as an 8-bit value.
fn byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The 8-bit image of a whole-frame calibration pattern at `width`×`height`, black where its
/// mask is false ([`Pattern::codes`], as every display that draws pixels).
fn pattern_image(pattern: &Pattern, width: u32, height: u32) -> Vec<u8> {
    match pattern.codes(width, height) {
        Ok(codes) => codes.into_iter().flat_map(|c| c.map(byte)).collect(),
        // Too large to code, or a mask of another size: dark (the camera agent's decode then
        // finds nothing).
        Err(e) => {
            tracing::warn!(error = %e, "cannot draw the pattern");
            vec![0; (width * height * 3) as usize]
        }
    }
}

/// A node agent's display on a rendered room, for projector `projector` of `width`×`height`:
/// node values drawn with `spec` (a frame file, or the weights and response the camera agent
/// assigns over the wire) into the projector's 8-bit image, or a calibration pattern until the
/// next value; before it has weights it shows black. Shown through `client` until `cancel`; a
/// flush resolves once the room has the image.
pub fn rendered_display(
    client: Client,
    projector: String,
    (width, height): (u32, u32),
    spec: Option<FrameSpec>,
    cancel: CancellationToken,
) -> roomlight_agent::remote::QueuedDisplay {
    use roomlight_agent::remote::Update;
    let mut values = std::collections::HashMap::new();
    let mut pattern: Option<Pattern> = None;
    let mut assignment = spec.map(FrameSpec::assignment);
    let mut gains: Option<roomlight_agent::hardware::Gains> = None;
    roomlight_agent::remote::QueuedDisplay::spawn(cancel, Some((width, height)), move |batch| {
        for update in batch {
            match update {
                Update::Value(node, x) => {
                    values.insert(node, x);
                    pattern = None;
                }
                Update::Pattern(p) => pattern = Some(p),
                Update::Assign(a) if (a.width, a.height) != (width, height) => {
                    tracing::warn!(
                        "assignment for a {}×{} projector, this one is {width}×{height}: ignored",
                        a.width,
                        a.height
                    );
                }
                Update::Assign(a) => assignment = Some(*a),
                Update::Shade(g) => gains = g.map(|g| *g),
            }
        }
        let rgb8 = match (&pattern, &assignment) {
            (Some(p), _) => pattern_image(p, width, height),
            (None, Some(a)) => values_image(a, &values, gains.as_ref()),
            (None, None) => vec![0; (width * height * 3) as usize],
        };
        let request = v1::ShowImageRequest {
            projector: projector.clone(),
            width,
            height,
            rgb8,
        };
        let mut client = client.clone();
        async move {
            if let Err(status) = client.show_image(request).await {
                tracing::warn!(%status, "the projector did not take the image");
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use roomlight_agent::hardware::{Camera, Display};
    use roomlight_core::LinearRgb;

    /// A node agent's display and the camera agent's camera against the served small room: one
    /// node over the whole left projector at linear 0.5 (linear response) is shown as an 8-bit
    /// image, and the captured patches match the simulator's own render of that frame, sampled
    /// the same way, to within the camera noise.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn display_and_camera_adapters_drive_the_rendered_room() {
        let mut scene = roomlight_sim::scenes::small().expect("small");
        scene.camera.resolution = [640, 480];
        let room = Arc::new(Room::build(scene).expect("room"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let endpoint = format!("http://{}", listener.local_addr().expect("address"));
        let cancel = CancellationToken::new();
        tokio::spawn(serve(room.clone(), 7, listener, cancel.clone()));
        let client = connect(endpoint).await.expect("connect");
        let k = room
            .projectors()
            .iter()
            .position(|p| p.name == "left")
            .expect("left");
        let [w, h] = room.scene().projectors[k].resolution;
        let spec = FrameSpec {
            projector: "left".into(),
            width: w,
            height: h,
            response: roomlight_calib::response::Response::linear(),
            nodes: vec![(0, (0..w * h).map(|i| (i, 1.0)).collect())],
        };
        let mut display = rendered_display(
            client.clone(),
            "left".into(),
            (w, h),
            Some(spec),
            cancel.clone(),
        );
        let corners = crate::pipeline::chart_corners(&room).expect("corners");
        let sample = crate::pipeline::sample_config(&room);
        let patches: Vec<usize> = (0..room.patches()).collect();
        // The room says where its camera clips, and calibration plans with it; a room that
        // does not say (0) leaves it unknown.
        let described = client
            .clone()
            .describe(v1::DescribeRequest {})
            .await
            .expect("describe")
            .into_inner()
            .camera_saturation;
        assert!(
            (f64::from(described) - room.scene().camera.saturation).abs() < 1e-6,
            "{described}"
        );
        let unsaid = RenderedCamera::new(client.clone(), Vec::new(), Vec::new(), sample);
        assert!(unsaid.limits().saturation.is_nan());
        assert!(unsaid.with_saturation(0.0).limits().saturation.is_nan());
        let mut camera = RenderedCamera::new(client, corners.clone(), patches, sample)
            .with_saturation(described);
        assert!((camera.limits().saturation - described).abs() < 1e-6);
        display.show(0, LinearRgb::splat(0.5));
        display.flush().await;
        let served = camera.capture().await.expect("capture");
        let mut frames = vec![Frame::Black; room.projectors().len()];
        frames[k] = Frame::Uniform([128.0 / 255.0; 3]);
        let image = room.render(&frames, None).expect("render");
        let local = roomlight_calib::charts::sample_charts(
            &roomlight_calib::image_io::LinearImage {
                width: image.width,
                height: image.height,
                pixels: image.pixels,
            },
            &corners,
            &sample,
        )
        .expect("sample");
        assert_eq!(served.len(), local.len());
        let lit = local.iter().filter(|s| s.mean.max_abs() > 0.01).count();
        assert!(lit > 0, "the left projector lights some patch");
        for (i, (s, l)) in served.iter().zip(&local).enumerate() {
            for c in 0..3 {
                let tolerance = 6.0 * l.std_error[c].max(1e-4) + 0.01 * l.mean[c];
                assert!(
                    (s[c] - l.mean[c]).abs() <= tolerance,
                    "patch {i} channel {c}: served {} vs rendered {} (σ {})",
                    s[c],
                    l.mean[c],
                    l.std_error[c]
                );
            }
        }
        cancel.cancel();
    }
}
