//! `roomlight sim --scene`: the simulated room served as the `RenderedRoom` gRPC service —
//! whole projector images in, noisy camera images out, LED presets switched by name — so that
//! processes can drive the rendered room as they would real projectors and a real camera.

use anyhow::{Context, Result};
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

#[derive(Clone)]
struct Rendered {
    room: Arc<Room>,
    state: Arc<Mutex<State>>,
}

impl Rendered {
    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
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
        }))
    }

    async fn show_image(
        &self,
        request: Request<v1::ShowImageRequest>,
    ) -> Result<Response<v1::ShowReply>, Status> {
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
    let state = State {
        frames: vec![Frame::Black; room.projectors().len()],
        preset: None,
        noise: CameraNoise::with_seed(&room, seed),
    };
    let service = v1::rendered_room_server::RenderedRoomServer::new(Rendered {
        room,
        state: Arc::new(Mutex::new(state)),
    })
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
