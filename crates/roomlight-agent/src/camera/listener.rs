//! The camera agent's listener: a connection limit and a handshake timeout in front of tonic.
//! Accepted connections hold a permit of a semaphore; when none is left a new connection is
//! closed at once (the kernel's backlog does not fill, and a count is logged at a limited
//! rate). A connection on which no Hello has been admitted within the handshake timeout is
//! closed, so idle or refused peers cannot hold the slots of legitimate node agents.
//!
//! It knows nothing of the Room service: the service marks a connection admitted through the
//! [`Handshake`] tonic puts in each request's extensions.

use crate::throttle;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;

/// A connection's handshake state, as the requests on it see it (tonic's connect info).
#[derive(Debug, Clone)]
pub(super) struct Handshake {
    admitted: Arc<AtomicBool>,
}

impl Handshake {
    /// A node was admitted on this connection: it is no longer closed at the timeout.
    pub(super) fn admitted(&self) {
        self.admitted.store(true, Ordering::Relaxed);
    }
}

/// An accepted connection: its permit, and its handshake deadline until a node is admitted.
pub(super) struct Guarded {
    inner: TcpStream,
    _permit: OwnedSemaphorePermit,
    handshake: Handshake,
    /// Until a node is admitted: closed when it fires.
    deadline: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl tonic::transport::server::Connected for Guarded {
    type ConnectInfo = Handshake;

    fn connect_info(&self) -> Handshake {
        self.handshake.clone()
    }
}

impl Guarded {
    /// Whether the handshake timed out (once a node is admitted, never).
    fn expired(&mut self, cx: &mut Context<'_>) -> bool {
        if self.handshake.admitted.load(Ordering::Relaxed) {
            self.deadline = None;
            return false;
        }
        self.deadline
            .as_mut()
            .is_some_and(|d| d.as_mut().poll(cx).is_ready())
    }
}

fn timed_out() -> io::Error {
    io::Error::new(
        io::ErrorKind::TimedOut,
        "no Hello admitted within the handshake timeout",
    )
}

impl AsyncRead for Guarded {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.expired(cx) {
            return Poll::Ready(Err(timed_out()));
        }
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl AsyncWrite for Guarded {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// Accepts on `listener` until `cancel`, at most `limit` connections open at once, each closed
/// after `handshake` unless a node is admitted on it; the stream to hand to tonic.
pub(super) fn guarded(
    listener: TcpListener,
    limit: usize,
    handshake: Duration,
    cancel: CancellationToken,
) -> ReceiverStream<io::Result<Guarded>> {
    let (tx, rx) = mpsc::channel(16);
    let permits = Arc::new(Semaphore::new(limit.max(1)));
    tokio::spawn(async move {
        let over = throttle::Shared::default();
        let failed = throttle::Shared::default();
        loop {
            let accepted = tokio::select! {
                () = cancel.cancelled() => return,
                () = tx.closed() => return,
                accepted = listener.accept() => accepted,
            };
            let stream = match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    if let Some(count) = failed.hit() {
                        tracing::warn!(error = %e, count, "accept failed (count since the last report)");
                    }
                    // Out of descriptors: give the open ones a moment to close rather than spin.
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            };
            let Ok(permit) = permits.clone().try_acquire_owned() else {
                if let Some(count) = over.hit() {
                    tracing::warn!(
                        limit,
                        count,
                        "connection limit reached: new connections closed (count since the last report)"
                    );
                }
                continue;
            };
            // Small messages both ways every round: Nagle's algorithm would add ~40 ms.
            let _ = stream.set_nodelay(true);
            let guarded = Guarded {
                inner: stream,
                _permit: permit,
                handshake: Handshake {
                    admitted: Arc::new(AtomicBool::new(false)),
                },
                deadline: Some(Box::pin(tokio::time::sleep(handshake))),
            };
            if tx.send(Ok(guarded)).await.is_err() {
                return;
            }
        }
    });
    ReceiverStream::new(rx)
}
