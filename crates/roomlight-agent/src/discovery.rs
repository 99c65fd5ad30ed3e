//! Discovery (DESIGN §6): the camera agent advertises `_roomlight._tcp.local.` over mDNS
//! (mdns-sd) with the room's name and the protocol version in its TXT record; a node agent
//! browses for the agent of its room. mDNS only finds candidates: anyone on the LAN can
//! advertise the room, so a node agent tries them in turn and skips one that refuses it or
//! cannot be reached (`node::run`); trust comes from the token (and, with issue 19, TLS).
//! Liveness comes from the stream, HTTP/2 keepalive and heartbeats.

use mdns_sd::{IfKind, ServiceDaemon, ServiceEvent, ServiceInfo};
use roomlight_proto::PROTOCOL_VERSION;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

/// The service type every roomlight camera agent advertises.
pub const SERVICE: &str = "_roomlight._tcp.local.";

/// Where mDNS runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MdnsConfig {
    /// UDP port: 5353 in an installation; tests use their own.
    pub port: u16,
    /// Only the loopback interface (one machine, tests); otherwise every interface.
    pub loopback_only: bool,
}

impl Default for MdnsConfig {
    fn default() -> Self {
        Self {
            port: mdns_sd::MDNS_PORT,
            loopback_only: false,
        }
    }
}

/// What went wrong in discovery.
#[derive(Debug, thiserror::Error)]
pub enum DiscoveryError {
    #[error("mDNS: {0}")]
    Mdns(#[from] mdns_sd::Error),
    #[error("room {room:?}: no camera agent speaking protocol {version} found within {waited:?}")]
    NotFound {
        room: String,
        version: u32,
        waited: Duration,
    },
}

fn daemon(config: &MdnsConfig) -> Result<ServiceDaemon, DiscoveryError> {
    let daemon = ServiceDaemon::new_with_port(config.port)?;
    if config.loopback_only {
        daemon.disable_interface(IfKind::All)?;
        daemon.enable_interface(IfKind::Addr(IpAddr::V4(Ipv4Addr::LOCALHOST)))?;
    }
    Ok(daemon)
}

/// A running advertisement; withdrawn when dropped.
pub struct Advertisement {
    daemon: ServiceDaemon,
    fullname: String,
}

impl std::fmt::Debug for Advertisement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Advertisement")
            .field("fullname", &self.fullname)
            .finish_non_exhaustive()
    }
}

impl Drop for Advertisement {
    fn drop(&mut self) {
        // Best effort: a daemon that is already gone has nothing left to withdraw.
        let _ = self.daemon.unregister(&self.fullname);
        let _ = self.daemon.shutdown();
    }
}

/// Advertises the camera agent of `room` listening on `address`. An unspecified address
/// (0.0.0.0) is advertised with every address of this host.
pub fn advertise(
    room: &str,
    address: std::net::SocketAddr,
    config: &MdnsConfig,
) -> Result<Advertisement, DiscoveryError> {
    let daemon = daemon(config)?;
    let version = PROTOCOL_VERSION.to_string();
    let properties = [("room", room), ("version", version.as_str())];
    let host = format!("roomlight-{}.local.", sanitize(room));
    let ip = address.ip();
    let info = if ip.is_unspecified() {
        ServiceInfo::new(
            SERVICE,
            &sanitize(room),
            &host,
            "",
            address.port(),
            &properties[..],
        )?
        .enable_addr_auto()
    } else {
        ServiceInfo::new(
            SERVICE,
            &sanitize(room),
            &host,
            ip.to_string().as_str(),
            address.port(),
            &properties[..],
        )?
    };
    let fullname = info.get_fullname().to_string();
    daemon.register(info)?;
    tracing::info!(%room, %address, "advertised over mDNS");
    Ok(Advertisement { daemon, fullname })
}

/// An instance name: letters, digits and dashes (mDNS labels).
fn sanitize(room: &str) -> String {
    room.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect()
}

/// Browses until the camera agent of `room` speaking this protocol version is found; returns
/// its endpoint (`http://address:port`). Agents of other rooms or versions are skipped.
pub fn find_camera(
    room: &str,
    config: &MdnsConfig,
    within: Duration,
) -> Result<String, DiscoveryError> {
    find_camera_except(room, config, within, &[])
}

/// As [`find_camera`], skipping the endpoints in `skip` (candidates tried and refused).
pub fn find_camera_except(
    room: &str,
    config: &MdnsConfig,
    within: Duration,
    skip: &[String],
) -> Result<String, DiscoveryError> {
    let daemon = daemon(config)?;
    let events = daemon.browse(SERVICE)?;
    let until = Instant::now() + within;
    let version = PROTOCOL_VERSION.to_string();
    let found = loop {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break None;
        }
        match events.recv_timeout(left) {
            Ok(ServiceEvent::ServiceResolved(service)) => {
                let txt = |key: &str| service.get_property_val_str(key).map(str::to_string);
                if txt("room").as_deref() != Some(room) || txt("version") != Some(version.clone()) {
                    tracing::debug!(name = %service.fullname, "another room or version: skipped");
                    continue;
                }
                // Prefer IPv4 (loopback in tests), else whatever is advertised.
                let mut addresses: Vec<IpAddr> = service
                    .get_addresses()
                    .iter()
                    .map(|a| a.to_ip_addr())
                    .collect();
                addresses.sort_by_key(|a| !a.is_ipv4());
                let endpoints = addresses.iter().map(|ip| {
                    let host = match ip {
                        IpAddr::V4(v4) => v4.to_string(),
                        IpAddr::V6(v6) => format!("[{v6}]"),
                    };
                    format!("http://{host}:{}", service.get_port())
                });
                if let Some(endpoint) = endpoints.into_iter().find(|e| !skip.contains(e)) {
                    break Some(endpoint);
                }
            }
            Ok(_) => {}
            Err(_) => break None,
        }
    };
    let _ = daemon.stop_browse(SERVICE);
    let _ = daemon.shutdown();
    found.ok_or_else(|| DiscoveryError::NotFound {
        room: room.to_string(),
        version: PROTOCOL_VERSION,
        waited: within,
    })
}

/// The prefix of a node agent's endpoint that means "find the camera agent over mDNS".
const MDNS_SCHEME: &str = "mdns:";

/// Where to look for the camera agent of `room`, as a node agent's endpoint: the node agent
/// browses for candidates itself and skips those that refuse it or cannot be reached.
pub fn mdns_endpoint(room: &str, config: &MdnsConfig, within: Duration) -> String {
    format!(
        "{MDNS_SCHEME}port={};loopback={};wait_ms={};room={room}",
        config.port,
        u8::from(config.loopback_only),
        within.as_millis()
    )
}

/// What [`mdns_endpoint`] wrote: the room, where mDNS runs, how long each search lasts.
/// `None` when `endpoint` is not an mDNS one (or malformed).
pub fn parse_mdns_endpoint(endpoint: &str) -> Option<(String, MdnsConfig, Duration)> {
    let rest = endpoint.strip_prefix(MDNS_SCHEME)?;
    let mut fields = rest.splitn(4, ';');
    let mut field = |key: &str| fields.next()?.strip_prefix(key)?.strip_prefix('=');
    let port = field("port")?.parse().ok()?;
    let loopback_only = field("loopback")? == "1";
    let wait = Duration::from_millis(field("wait_ms")?.parse().ok()?);
    let room = field("room")?.to_string();
    Some((
        room,
        MdnsConfig {
            port,
            loopback_only,
        },
        wait,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_mdns_endpoint_reads_back_as_written() {
        let config = MdnsConfig {
            port: 5399,
            loopback_only: true,
        };
        let written = mdns_endpoint("lab;2=x", &config, Duration::from_secs(30));
        assert_eq!(
            parse_mdns_endpoint(&written),
            Some(("lab;2=x".to_string(), config, Duration::from_secs(30)))
        );
        assert_eq!(parse_mdns_endpoint("http://127.0.0.1:5"), None);
        assert_eq!(
            parse_mdns_endpoint("mdns:port=x;loopback=1;wait_ms=1;room=r"),
            None
        );
    }
}
