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
//!
//! Hand-written: turmoil simulates the network instead, but only for code generic over its own
//! socket types, and the camera agent's listener (connection limit, first-byte peek, TLS) and
//! the node's tonic transport take the OS's; a relay leaves the code under test as it ships.

use std::net::SocketAddr;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::task::JoinSet;

/// Whether bytes cross the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// Bytes cross.
    Up,
    /// Nothing crosses; connections stay open (a pulled cable, a dead switch port).
    Down,
}

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

/// Waits until the link is up.
async fn up(state: &mut watch::Receiver<LinkState>) {
    // The sender lives as long as the relay's tasks (they are aborted with the link).
    let _ = state.wait_for(|s| *s == LinkState::Up).await;
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

/// Copies `from` to `to` while the link is up; while it is down, reads nothing.
async fn carry(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    mut state: watch::Receiver<LinkState>,
) {
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
        // Bytes read just before a cut are delivered once the link is up again.
        up(&mut state).await;
        if to.write_all(&buf[..n]).await.is_err() {
            return;
        }
    }
}
