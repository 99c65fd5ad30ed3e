//! `roomlight bench console`: what the installer's console costs the rounds. A synthetic room
//! runs through the real agents over loopback gRPC (as `bench net`), first alone, then with
//! five consoles open — each behaving as the page does: the status, history and survey once,
//! the event stream read as it comes, every projector's frame thumbnail every 3 s — then alone
//! again; the median round time of each phase, and their ratio, are printed. The consoles
//! talk HTTP/1.1 over plain sockets (hand-written here: a dozen lines, no client crate for a
//! benchmark).

use super::net::SyntheticAgents;
use anyhow::{Context, Result};
use roomlight_core::StepRule;
use roomlight_core::closed_loop::PlantConfig;
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio_util::sync::CancellationToken;

const TOKEN: &str = "bench-console-token";
/// Consoles open in the middle phase.
pub const CONSOLES: usize = 5;
/// Each phase lasts at least this long (the consoles poll twice a second).
pub const PHASE: Duration = Duration::from_secs(8);

/// The three phases' median round times, in ms.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ConsoleRun {
    pub nodes: usize,
    pub rounds_per_phase: usize,
    pub alone_ms: f64,
    pub with_consoles_ms: f64,
    pub alone_again_ms: f64,
    /// Requests the consoles made, and status events they read, in the middle phase.
    pub requests: u64,
    pub events: u64,
}

/// Runs the bench on a room of `nodes` nodes, `rounds` rounds per phase.
pub fn run(nodes: usize, rounds: usize) -> Result<ConsoleRun> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let run = runtime.block_on(measure(nodes, rounds))?;
    println!(
        "{} nodes, median round of each phase (at least {} rounds, 8 s): alone {:.2} ms, with {CONSOLES} consoles {:.2} ms ({} requests, {} events), alone again {:.2} ms; with/alone = {:.3}",
        run.nodes,
        run.rounds_per_phase,
        run.alone_ms,
        run.with_consoles_ms,
        run.requests,
        run.events,
        run.alone_again_ms,
        run.with_consoles_ms / (0.5 * (run.alone_ms + run.alone_again_ms)),
    );
    Ok(run)
}

async fn measure(nodes: usize, rounds: usize) -> Result<ConsoleRun> {
    let problem = synthetic_room(&SyntheticConfig::new(nodes, 1))?.problem;
    let mut room = SyntheticAgents::camera(&problem, PlantConfig::default(), None, 0).await?;
    room.spawn_nodes(StepRule::Momentum { theta: 1.0 });
    let agents = room.agents;
    tokio::time::timeout(
        Duration::from_secs(120),
        room.status
            .wait_for(|s| s.live_projectors == agents && s.captures >= 3),
    )
    .await
    .context("the node agents did not join within 120 s")??;
    let alone = phase(&mut room, rounds).await?;
    // The console, as the camera agent serves it.
    let cancel = CancellationToken::new();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let config = roomlight_console::ConsoleConfig {
        token: TOKEN.into(),
        survey: None,
        snapshots: std::env::temp_dir(),
        model: None,
    };
    let server = tokio::spawn(roomlight_console::serve(
        listener,
        config,
        room.control.clone(),
        room.status.clone(),
        cancel.clone(),
    ));
    let counts = Arc::new((AtomicU64::new(0), AtomicU64::new(0)));
    let projectors: Vec<String> = (0..room.agents).map(|a| format!("p{a}")).collect();
    let browsers: Vec<_> = (0..CONSOLES)
        .map(|_| {
            tokio::spawn(browser(
                addr,
                projectors.clone(),
                counts.clone(),
                cancel.clone(),
            ))
        })
        .collect();
    // Every console has its stream open before the phase starts.
    let deadline = Instant::now() + Duration::from_secs(30);
    while counts.1.load(Ordering::Relaxed) < CONSOLES as u64 {
        anyhow::ensure!(Instant::now() < deadline, "the consoles did not connect");
        room.status.changed().await?;
    }
    counts.0.store(0, Ordering::Relaxed);
    counts.1.store(0, Ordering::Relaxed);
    let with = phase(&mut room, rounds).await?;
    let (requests, events) = (
        counts.0.load(Ordering::Relaxed),
        counts.1.load(Ordering::Relaxed),
    );
    cancel.cancel();
    for b in browsers {
        let _ = b.await;
    }
    let _ = server.await;
    let again = phase(&mut room, rounds).await?;
    room.stop().await;
    Ok(ConsoleRun {
        nodes,
        rounds_per_phase: rounds,
        alone_ms: alone,
        with_consoles_ms: with,
        alone_again_ms: again,
        requests,
        events,
    })
}

/// The median time between two rounds over a phase of [`PHASE`] and at least `rounds`
/// rounds, in ms.
async fn phase(room: &mut SyntheticAgents, rounds: usize) -> Result<f64> {
    let mut last_round = room.status.borrow_and_update().round;
    let started = Instant::now();
    let mut last = started;
    let mut times = Vec::new();
    while times.len() <= rounds || started.elapsed() < PHASE {
        tokio::time::timeout(
            Duration::from_secs(30),
            room.status.wait_for(|s| s.round > last_round),
        )
        .await
        .context("a round took over 30 s")??;
        let now = Instant::now();
        times.push((now - last).as_secs_f64() * 1e3);
        last = now;
        last_round = room.status.borrow().round;
    }
    // The first interval began before the phase.
    times.remove(0);
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

/// One console as the page behaves: the status, the history and the survey once, the event
/// stream read as it comes, and every projector's frame thumbnail every 3 s.
async fn browser(
    addr: SocketAddr,
    projectors: Vec<String>,
    counts: Arc<(AtomicU64, AtomicU64)>,
    cancel: CancellationToken,
) {
    let stream_counts = counts.clone();
    let events = async move {
        let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
            return;
        };
        let request = format!(
            "GET /api/events HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {TOKEN}\r\n\r\n"
        );
        if s.write_all(request.as_bytes()).await.is_err() {
            return;
        }
        let mut buf = vec![0u8; 1 << 16];
        while let Ok(n) = s.read(&mut buf).await {
            if n == 0 {
                return;
            }
            let seen = buf[..n]
                .windows(13)
                .filter(|w| w == b"event: status")
                .count();
            stream_counts.1.fetch_add(seen as u64, Ordering::Relaxed);
        }
    };
    let polling = async move {
        for path in ["/api/status", "/api/history", "/api/survey"] {
            get(addr, path).await;
            counts.0.fetch_add(1, Ordering::Relaxed);
        }
        let mut tick = tokio::time::interval(Duration::from_secs(3));
        loop {
            tick.tick().await;
            for p in &projectors {
                if get(addr, &format!("/api/projectors/{p}/frame.png")).await {
                    counts.0.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    };
    tokio::select! {
        () = events => {}
        () = polling => {}
        () = cancel.cancelled() => {}
    }
}

/// One GET, read to its end; true when it was answered.
async fn get(addr: SocketAddr, path: &str) -> bool {
    let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
        return false;
    };
    let request = format!(
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {TOKEN}\r\nConnection: close\r\n\r\n"
    );
    if s.write_all(request.as_bytes()).await.is_err() {
        return false;
    }
    let mut answer = Vec::new();
    s.read_to_end(&mut answer).await.is_ok() && answer.starts_with(b"HTTP/1.1 200")
}
