//! The camera agent's listener: a connection limit and a handshake timeout in front of tonic.
//! Accepted connections hold a permit of a semaphore; when none is left a new connection is
//! closed at once (the kernel's backlog does not fill, and a count is logged at a limited
//! rate). A connection on which no Hello has been admitted within the handshake timeout is
//! closed, so idle or refused peers cannot hold the slots of legitimate node agents.
//!
//! With TLS the handshake runs here, per connection on a task of its own, holding the
//! connection's permit and within its handshake timeout, so it is behind both limits. The first
//! bytes are peeked first: a TLS record (0x16) on a plaintext listener, or an HTTP/2 preface
//! (`PRI `) on a TLS listener, is closed with a line saying so (rate-limited).
//!
//! It knows nothing of the Room service: the service marks a connection admitted through the
//! [`Handshake`] tonic puts in each request's extensions, where it also finds the client
//! certificate a node showed (mTLS).

use crate::throttle;
use crate::tls::ServerTls;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio_rustls::rustls::pki_types::CertificateDer;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;

/// A connection's handshake state, as the requests on it see it (tonic's connect info).
#[derive(Debug, Clone)]
pub(super) struct Handshake {
    admitted: Arc<AtomicBool>,
    /// The client certificate the node showed over TLS, verified against the room CA.
    client_cert: Option<Arc<CertificateDer<'static>>>,
}

impl Handshake {
    /// A node was admitted on this connection: it is no longer closed at the timeout.
    pub(super) fn admitted(&self) {
        self.admitted.store(true, Ordering::Relaxed);
    }

    /// The node's client certificate, if it showed one (mTLS).
    pub(super) fn client_cert(&self) -> Option<&CertificateDer<'static>> {
        self.client_cert.as_deref()
    }
}

/// A connection as tonic reads it: plaintext, or TLS once its handshake is done.
enum Conn {
    Plain(TcpStream),
    Tls(Box<tokio_rustls::server::TlsStream<TcpStream>>),
}

/// An accepted connection: its permit, and its handshake deadline until a node is admitted.
pub(super) struct Guarded {
    inner: Conn,
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
        match &mut self.inner {
            Conn::Plain(s) => Pin::new(s).poll_read(cx, buf),
            Conn::Tls(s) => Pin::new(s.as_mut()).poll_read(cx, buf),
        }
    }
}

impl AsyncWrite for Guarded {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        match &mut self.inner {
            Conn::Plain(s) => Pin::new(s).poll_write(cx, buf),
            Conn::Tls(s) => Pin::new(s.as_mut()).poll_write(cx, buf),
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match &mut self.inner {
            Conn::Plain(s) => Pin::new(s).poll_flush(cx),
            Conn::Tls(s) => Pin::new(s.as_mut()).poll_flush(cx),
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match &mut self.inner {
            Conn::Plain(s) => Pin::new(s).poll_shutdown(cx),
            Conn::Tls(s) => Pin::new(s.as_mut()).poll_shutdown(cx),
        }
    }
}

/// What the connections' preparation logs, each at a limited rate.
#[derive(Default)]
struct Mismatches {
    plaintext: throttle::Shared,
    tls: throttle::Shared,
    handshake: throttle::Shared,
}

/// The first bytes of a connection, then its TLS handshake if `tls`; `None`: closed (logged).
/// The caller bounds it in time.
async fn prepare(
    stream: TcpStream,
    peer: SocketAddr,
    tls: Option<&ServerTls>,
    logs: &Mismatches,
) -> Option<(Conn, Option<Arc<CertificateDer<'static>>>)> {
    let mut first = [0u8; 1];
    // A TLS record starts 0x16 (handshake); an HTTP/2 client starts with its preface, "PRI ".
    let speaks_tls = match stream.peek(&mut first).await {
        Ok(1) => first[0] == 0x16,
        _ => return None,
    };
    let Some(tls) = tls else {
        if speaks_tls {
            if let Some(count) = logs.tls.hit() {
                tracing::warn!(%peer, count, "TLS connection from {peer}, this camera agent speaks plaintext (no tls in its config); closed (count since the last report)");
            }
            return None;
        }
        return Some((Conn::Plain(stream), None));
    };
    if !speaks_tls {
        if let Some(count) = logs.plaintext.hit() {
            tracing::warn!(%peer, count, "plaintext connection from {peer}, this camera agent speaks TLS; closed (count since the last report)");
        }
        return None;
    }
    match tls.acceptor.accept(stream).await {
        Ok(stream) => {
            let cert = stream
                .get_ref()
                .1
                .peer_certificates()
                .and_then(|c| c.first())
                .map(|c| Arc::new(c.clone().into_owned()));
            Some((Conn::Tls(Box::new(stream)), cert))
        }
        Err(e) => {
            if let Some(count) = logs.handshake.hit() {
                tracing::warn!(%peer, error = %e, count, "TLS handshake with {peer} failed; closed (count since the last report)");
            }
            None
        }
    }
}

/// Accepts on `listener` until `cancel`, at most `limit` connections open at once, each closed
/// after `handshake` unless a node is admitted on it; the stream to hand to tonic. With `tls`
/// each connection's TLS handshake runs on a task of its own within that timeout.
pub(super) fn guarded(
    listener: TcpListener,
    limit: usize,
    handshake: Duration,
    tls: Option<ServerTls>,
    cancel: CancellationToken,
) -> ReceiverStream<io::Result<Guarded>> {
    let (tx, rx) = mpsc::channel(16);
    let permits = Arc::new(Semaphore::new(limit.max(1)));
    let logs = Arc::new(Mismatches::default());
    tokio::spawn(async move {
        let over = throttle::Shared::default();
        let failed = throttle::Shared::default();
        loop {
            let accepted = tokio::select! {
                () = cancel.cancelled() => return,
                () = tx.closed() => return,
                accepted = listener.accept() => accepted,
            };
            let (stream, peer) = match accepted {
                Ok(accepted) => accepted,
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
            let deadline = tokio::time::Instant::now() + handshake;
            let (tx, tls, logs, cancel) = (tx.clone(), tls.clone(), logs.clone(), cancel.clone());
            // One task per connection: a slow peer's first bytes or TLS handshake hold only its
            // own place, until the handshake timeout.
            tokio::spawn(async move {
                let prepared = tokio::select! {
                    () = cancel.cancelled() => return,
                    prepared = tokio::time::timeout_at(deadline, prepare(stream, peer, tls.as_ref(), &logs)) => prepared,
                };
                let Ok(Some((inner, client_cert))) = prepared else {
                    return;
                };
                let guarded = Guarded {
                    inner,
                    _permit: permit,
                    handshake: Handshake {
                        admitted: Arc::new(AtomicBool::new(false)),
                        client_cert,
                    },
                    deadline: Some(Box::pin(tokio::time::sleep_until(deadline))),
                };
                let _ = tx.send(Ok(guarded)).await;
            });
        }
    });
    ReceiverStream::new(rx)
}
