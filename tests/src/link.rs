//! A network link that a test can cut and restore: a TCP relay on `127.0.0.1:0` in front of the
//! camera agent, one per node agent, so that partitions happen in one process to the agents'
//! real sockets, TLS and HTTP/2 (keepalive included) with nothing in the agents changed.
//!
//! - [`LinkState::Down`] is a pulled cable: nothing crosses in either direction, the relay's
//!   connections stay open and what was in flight waits in the kernel's buffers; a connection
//!   made meanwhile is held unanswered. Either side notices only by its own timeouts (the camera
//!   agent's heartbeat deadline, the node's HTTP/2 keepalive), as on a real LAN.
//! - [`LinkState::Up`] plugs it back: held bytes flow again, so a side that gave up meanwhile
//!   tells the other (an HTTP/2 reset or goodbye), as after a real reconnection.
//! - [`LinkState::Impaired`] delays every byte and loses some (what `tc netem` does on a real
//!   interface, for the machines whose kernel has no `sch_netem`).
//!
//! Hand-written: turmoil simulates the network instead, but only for code generic over its own
//! socket types, and the camera agent's listener (connection limit, first-byte peek, TLS) and
//! the node's tonic transport take the OS's; a relay leaves the code under test as it ships.

use std::net::SocketAddr;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::task::JoinSet;
use tokio::time::Instant;

/// Whether and how bytes cross the link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LinkState {
    /// Bytes cross.
    Up,
    /// Nothing crosses; connections stay open (a pulled cable, a dead switch port).
    Down,
    /// Bytes cross `delay` late each way; a share `loss` of the chunks is lost once and
    /// resent a retransmission timeout (200 ms, Linux's least) later, holding back what
    /// follows it on that connection as TCP does.
    Impaired {
        /// One-way delay.
        delay: std::time::Duration,
        /// Share of chunks lost once, in [0, 1].
        loss: f64,
    },
}

/// TCP's least retransmission timeout on Linux.
const RETRANSMISSION: std::time::Duration = std::time::Duration::from_millis(200);

/// A relay to `upstream` that can be cut; dropping it closes every connection through it.
#[derive(Debug)]
pub struct Link {
    address: SocketAddr,
    state: watch::Sender<LinkState>,
    tasks: JoinSet<()>,
}

impl Link {
    /// A link (up) on `127.0.0.1:0` to `upstream`.
    pub async fn new(upstream: SocketAddr) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind a relay");
        let address = listener.local_addr().expect("the relay's address");
        let (state, _) = watch::channel(LinkState::Up);
        let mut tasks = JoinSet::new();
        tasks.spawn(accept(listener, upstream, state.subscribe()));
        Self {
            address,
            state,
            tasks,
        }
    }

    /// The address a node agent connects to: `http://127.0.0.1:port`.
    pub fn endpoint(&self) -> String {
        format!("http://{}", self.address)
    }

    /// Cuts (`Down`) or restores (`Up`) the link.
    pub fn set(&self, state: LinkState) {
        self.state.send_replace(state);
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.tasks.abort_all();
    }
}

/// Waits until bytes cross the link; how late they arrive then.
async fn up(state: &mut watch::Receiver<LinkState>) -> (std::time::Duration, f64) {
    // The sender lives as long as the relay's tasks (they are aborted with the link).
    let _ = state.wait_for(|s| *s != LinkState::Down).await;
    match *state.borrow() {
        LinkState::Impaired { delay, loss } => (delay, loss),
        _ => (std::time::Duration::ZERO, 0.0),
    }
}

async fn accept(listener: TcpListener, upstream: SocketAddr, state: watch::Receiver<LinkState>) {
    let mut connections = JoinSet::new();
    while let Ok((client, _)) = listener.accept().await {
        let mut state = state.clone();
        connections.spawn(async move {
            // A connection made while the link is down is held unanswered until it is up.
            up(&mut state).await;
            let Ok(server) = TcpStream::connect(upstream).await else {
                return;
            };
            let (client_read, client_write) = client.into_split();
            let (server_read, server_write) = server.into_split();
            let mut one_way = JoinSet::new();
            one_way.spawn(carry(client_read, server_write, state.clone()));
            one_way.spawn(carry(server_read, client_write, state));
            // Either direction ending (a side closed) ends the connection.
            one_way.join_next().await;
        });
    }
}

/// Copies `from` to `to` while bytes cross the link (each chunk due its delay later, a lost one
/// a retransmission later still, never before the chunk ahead of it); while it is down, reads
/// and writes nothing.
async fn carry(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    mut state: watch::Receiver<LinkState>,
) {
    let (chunks, mut due) = tokio::sync::mpsc::channel::<(Instant, Vec<u8>)>(64);
    let mut writer_state = state.clone();
    let writer = async move {
        while let Some((at, bytes)) = due.recv().await {
            tokio::time::sleep_until(at).await;
            up(&mut writer_state).await;
            if to.write_all(&bytes).await.is_err() {
                return;
            }
        }
    };
    let reader = async move {
        // Loss drawn from a fixed seed (xorshift): a run of the test is a run of the link.
        let mut draw = 0x2545_F491_4F6C_DD1D_u64;
        let mut last = Instant::now();
        let mut buf = vec![0u8; 16 * 1024];
        loop {
            up(&mut state).await;
            let n = tokio::select! {
                read = from.read(&mut buf) => match read {
                    Ok(0) | Err(_) => return,
                    Ok(n) => n,
                },
                // Cut while waiting to read: stop reading, so bytes stay in the sender's buffers.
                _ = state.wait_for(|s| *s == LinkState::Down) => continue,
            };
            let (delay, loss) = up(&mut state).await;
            draw ^= draw << 13;
            draw ^= draw >> 7;
            draw ^= draw << 17;
            let lost = ((draw >> 11) as f64 / (1u64 << 53) as f64) < loss;
            let resent = if lost {
                RETRANSMISSION
            } else {
                std::time::Duration::ZERO
            };
            let at = (Instant::now() + delay + resent).max(last);
            last = at;
            if chunks.send((at, buf[..n].to_vec())).await.is_err() {
                return;
            }
        }
    };
    // The reader ends when its side closes, the writer once it has delivered what was read.
    tokio::join!(writer, reader);
}
