//! The installer's web console of a camera agent (DESIGN §11, docs/console.md): served by the
//! camera agent's process on an address of its own, it shows the room as the camera sees it,
//! every projector's state and the objective live, edits the survey, starts calibrations and
//! carries out the actions an installer needs during a show. Every asset is embedded.
//!
//! It only reads what the round loop publishes (the status watch, the latest photograph) and
//! asks through the agent's bounded [`Control`]: serving it costs the rounds nothing. Whatever
//! a browser sends is bounded before it is read: a connection limit, a body limit, a timeout on
//! every request but the event stream, a cap on event streams with the lagging ones dropped,
//! and image rendering two at a time.
//!
//! The parts: `auth` (token, sessions, CSRF), `api` (the JSON API and images), `events` (the
//! Server-Sent Events hub), `survey` (the survey document: validation, rasterising, atomic
//! writes, versions), `images` (PNG rendering), `history` (objective against rounds and time,
//! and the optimum when the room is small enough to compute it), `warnings` (the last warnings
//! of the process, from its log).

mod api;
mod auth;
mod events;
mod history;
mod images;
pub mod survey;
pub mod warnings;

pub use api::PAGE_BYTES;

use axum::Router;
use roomlight_agent::camera::{Control, RoomStatus};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;

/// The largest request body: a survey with its polygons fits many times over.
pub const MAX_BODY: usize = 1 << 20;
/// At most this many connections at once (browsers open about six each).
pub const MAX_CONNECTIONS: usize = 128;
/// A request (the event stream aside) is answered within this or abandoned.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(30);

/// How a console is served.
#[derive(Clone)]
pub struct ConsoleConfig {
    /// The token that logs in (the room token unless the config names another).
    pub token: String,
    /// The survey file the Survey page edits; `None`: the agent runs from a calibrated model.
    pub survey: Option<PathBuf>,
    /// Where snapshots are written (a folder per snapshot).
    pub snapshots: PathBuf,
    /// The model file the agent writes, copied into snapshots.
    pub model: Option<PathBuf>,
}

impl std::fmt::Debug for ConsoleConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConsoleConfig")
            .field("token", &"<secret>")
            .field("survey", &self.survey)
            .field("snapshots", &self.snapshots)
            .field("model", &self.model)
            .finish()
    }
}

/// What every handler shares.
struct Console {
    config: ConsoleConfig,
    control: Control,
    status: watch::Receiver<RoomStatus>,
    overview: watch::Receiver<roomlight_agent::camera::Overview>,
    sessions: auth::Sessions,
    events: events::Hub,
    history: history::History,
    images: images::Images,
    /// Survey edits one at a time: a version check and its write are one step.
    survey_lock: tokio::sync::Mutex<()>,
    started: std::time::Instant,
}

type State = Arc<Console>;

/// The console's routes over a running camera agent (for tests: serve them, or call them with
/// `tower::ServiceExt::oneshot`). Its background tasks (events, history, thumbnails) run until
/// `cancel`.
pub fn router(
    config: ConsoleConfig,
    control: Control,
    status: watch::Receiver<RoomStatus>,
    cancel: CancellationToken,
) -> Router {
    let console = Arc::new(Console {
        events: events::Hub::default(),
        history: history::History::default(),
        images: images::Images::new(control.photos()),
        sessions: auth::Sessions::default(),
        survey_lock: tokio::sync::Mutex::new(()),
        started: std::time::Instant::now(),
        overview: control.overview(),
        config,
        control,
        status,
    });
    tokio::spawn(events::publish(console.clone(), cancel.clone()));
    tokio::spawn(history::follow(console.clone(), cancel.clone()));
    tokio::spawn(images::follow(console.clone(), cancel));
    api::routes(console)
}

/// Serves the console on `listener` until `cancel`, at most [`MAX_CONNECTIONS`] at once.
pub async fn serve(
    listener: tokio::net::TcpListener,
    config: ConsoleConfig,
    control: Control,
    status: watch::Receiver<RoomStatus>,
    cancel: CancellationToken,
) -> std::io::Result<()> {
    let app = router(config, control, status, cancel.clone());
    let listener = Limited {
        inner: listener,
        permits: Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS)),
    };
    axum::serve(listener, app)
        .with_graceful_shutdown(cancel.cancelled_owned())
        .await
}

/// A listener that holds a permit per open connection: beyond the limit, accepting waits (the
/// kernel's backlog holds the rest) and nothing else is slowed.
struct Limited {
    inner: tokio::net::TcpListener,
    permits: Arc<tokio::sync::Semaphore>,
}

/// A connection and its permit.
struct Counted {
    stream: tokio::net::TcpStream,
    _permit: tokio::sync::OwnedSemaphorePermit,
}

impl axum::serve::Listener for Limited {
    type Io = Counted;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            let permit = self
                .permits
                .clone()
                .acquire_owned()
                .await
                .expect("the console's connection semaphore is never closed");
            match self.inner.accept().await {
                Ok((stream, addr)) => {
                    let _ = stream.set_nodelay(true);
                    return (
                        Counted {
                            stream,
                            _permit: permit,
                        },
                        addr,
                    );
                }
                Err(e) => {
                    // Out of file descriptors and the like: wait a little, as axum's own does.
                    tracing::warn!(error = %e, "console: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

impl tokio::io::AsyncRead for Counted {
    fn poll_read(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_read(cx, buf)
    }
}

impl tokio::io::AsyncWrite for Counted {
    fn poll_write(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_write(cx, buf)
    }

    fn poll_flush(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_flush(cx)
    }

    fn poll_shutdown(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_shutdown(cx)
    }
}
