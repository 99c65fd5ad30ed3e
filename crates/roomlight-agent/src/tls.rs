//! TLS between the agents (issue 19). This module owns:
//! - the room's certificates: a room CA ([`init_ca`]) and a certificate per camera agent or node
//!   ([`issue`]), made with rcgen (ECDSA P-256; key files written 0600);
//! - a config's `tls = { ... }` table ([`TlsFiles`]) turned into the camera agent's side
//!   ([`ServerTls`]: its certificate, the room CA for client certificates, whether they are
//!   required) or a node agent's ([`ClientTls`]: the room CA the camera agent is verified
//!   against, its own certificate if it has one), with errors naming the config file and field;
//! - the plaintext rule ([`check_plaintext`]): plaintext only on loopback, or with `insecure`;
//! - the names a peer's certificate carries (mTLS binds a node's projector id to them).
//!
//! It knows nothing of the Room service, rounds, or the rest of a config file. rustls runs with
//! the ring provider (no C toolchain beyond ring's own).

use serde::Deserialize;
use std::fmt;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};

/// The CA's files in its folder.
pub const CA_CERT: &str = "ca.pem";
pub const CA_KEY: &str = "ca.key";

/// What went wrong with certificates or keys; the message names the file (and the config field).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct TlsError(String);

fn error(what: impl fmt::Display) -> TlsError {
    TlsError(what.to_string())
}

/// A config's `tls` table, as written: paths of PEM files. The camera agent's needs `cert` and
/// `key` (and `ca` for client certificates); a node's needs `ca`, and `cert` and `key` when the
/// camera agent requires client certificates.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsFiles {
    /// The room CA's certificate (`ca.pem` of `roomlight certs init`).
    #[serde(default)]
    pub ca: Option<PathBuf>,
    /// This agent's certificate (`NAME.pem` of `roomlight certs issue`).
    #[serde(default)]
    pub cert: Option<PathBuf>,
    /// Its key (`NAME.key`).
    #[serde(default)]
    pub key: Option<PathBuf>,
    /// Camera agent: refuse node agents without a certificate of the room CA (mTLS).
    #[serde(default)]
    pub require_client_cert: bool,
    /// Node agent: the name the camera agent's certificate must carry (default: the host of
    /// `camera`, or the room's name for a camera agent found over mDNS).
    #[serde(default)]
    pub camera_name: Option<String>,
}

/// The camera agent's TLS: what its listener accepts connections with.
#[derive(Clone)]
pub struct ServerTls {
    pub(crate) acceptor: tokio_rustls::TlsAcceptor,
    require_client_cert: bool,
}

impl fmt::Debug for ServerTls {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ServerTls")
            .field("require_client_cert", &self.require_client_cert)
            .finish_non_exhaustive()
    }
}

/// A node agent's TLS: tonic's client config (the room CA, its own certificate if any) and the
/// name the camera agent's certificate must carry, when it is not the address's host.
#[derive(Clone, Debug)]
pub struct ClientTls {
    config: tonic::transport::ClientTlsConfig,
    /// As configured; `None`: the endpoint's host (or the room, over mDNS).
    pub camera_name: Option<String>,
}

impl ClientTls {
    /// tonic's config for a camera agent that must be `name` (the host of the endpoint when
    /// `None`).
    pub(crate) fn tonic(&self, name: Option<&str>) -> tonic::transport::ClientTlsConfig {
        match name {
            Some(name) => self.config.clone().domain_name(name),
            None => self.config.clone(),
        }
    }
}

fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// Reads a file a config names, bounded (a PEM file is small), naming the config and field.
fn read(config: &Path, field: &str, path: &Path) -> Result<Vec<u8>, TlsError> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(1 << 20).read_to_end(&mut bytes))
        .map_err(|e| {
            error(format!(
                "{}: {field} = {:?}: {e}",
                config.display(),
                path.display()
            ))
        })?;
    Ok(bytes)
}

fn certs(
    config: &Path,
    field: &str,
    path: &Path,
) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let pem = read(config, field, path)?;
    let certs = CertificateDer::pem_slice_iter(&pem)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| {
            error(format!(
                "{}: {field} = {:?}: {e}",
                config.display(),
                path.display()
            ))
        })?;
    if certs.is_empty() {
        return Err(error(format!(
            "{}: {field} = {:?}: no certificate in it (expected PEM, -----BEGIN CERTIFICATE-----)",
            config.display(),
            path.display()
        )));
    }
    Ok(certs)
}

fn key(config: &Path, field: &str, path: &Path) -> Result<PrivateKeyDer<'static>, TlsError> {
    let pem = read(config, field, path)?;
    PrivateKeyDer::from_pem_slice(&pem).map_err(|e| {
        error(format!(
            "{}: {field} = {:?}: no private key in it ({e})",
            config.display(),
            path.display()
        ))
    })
}

fn roots(config: &Path, path: &Path) -> Result<Arc<rustls::RootCertStore>, TlsError> {
    let mut roots = rustls::RootCertStore::empty();
    for cert in certs(config, "tls.ca", path)? {
        roots.add(cert).map_err(|e| {
            error(format!(
                "{}: tls.ca = {:?}: {e}",
                config.display(),
                path.display()
            ))
        })?;
    }
    Ok(Arc::new(roots))
}

fn required<'a>(
    config: &Path,
    field: &str,
    value: Option<&'a PathBuf>,
) -> Result<&'a PathBuf, TlsError> {
    value.ok_or_else(|| error(format!("{}: {field} is missing", config.display())))
}

impl TlsFiles {
    /// The camera agent's side, from the files of `config`'s `tls` table.
    pub fn server(&self, config: &Path) -> Result<ServerTls, TlsError> {
        if self.camera_name.is_some() {
            return Err(error(format!(
                "{}: tls.camera_name belongs in a node agent's config",
                config.display()
            )));
        }
        let cert = required(config, "tls.cert", self.cert.as_ref())?;
        let key_path = required(config, "tls.key", self.key.as_ref())?;
        let chain = certs(config, "tls.cert", cert)?;
        let key = key(config, "tls.key", key_path)?;
        let builder = rustls::ServerConfig::builder_with_provider(provider())
            .with_safe_default_protocol_versions()
            .map_err(error)?;
        let builder = match &self.ca {
            Some(ca) => {
                let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(
                    roots(config, ca)?,
                    provider(),
                );
                let verifier = if self.require_client_cert {
                    verifier
                } else {
                    // A certificate is still checked against the room CA when one is shown.
                    verifier.allow_unauthenticated()
                };
                builder.with_client_cert_verifier(
                    verifier
                        .build()
                        .map_err(|e| error(format!("{}: tls.ca: {e}", config.display())))?,
                )
            }
            None if self.require_client_cert => {
                return Err(error(format!(
                    "{}: tls.require_client_cert needs tls.ca, the room CA client certificates are checked against",
                    config.display()
                )));
            }
            None => builder.with_no_client_auth(),
        };
        let mut server = builder.with_single_cert(chain, key).map_err(|e| {
            error(format!(
                "{}: tls.cert and tls.key do not make a pair: {e}",
                config.display()
            ))
        })?;
        server.alpn_protocols = vec![b"h2".to_vec()];
        Ok(ServerTls {
            acceptor: tokio_rustls::TlsAcceptor::from(Arc::new(server)),
            require_client_cert: self.require_client_cert,
        })
    }

    /// A node agent's side, from the files of `config`'s `tls` table.
    pub fn client(&self, config: &Path) -> Result<ClientTls, TlsError> {
        if self.require_client_cert {
            return Err(error(format!(
                "{}: tls.require_client_cert belongs in the camera agent's config",
                config.display()
            )));
        }
        let ca = required(config, "tls.ca", self.ca.as_ref())?;
        // Parsed here so that a broken file fails at load, not at the first connection.
        roots(config, ca)?;
        let mut tls = tonic::transport::ClientTlsConfig::new().ca_certificate(
            tonic::transport::Certificate::from_pem(read(config, "tls.ca", ca)?),
        );
        match (&self.cert, &self.key) {
            (Some(cert), Some(key_path)) => {
                certs(config, "tls.cert", cert)?;
                key(config, "tls.key", key_path)?;
                tls = tls.identity(tonic::transport::Identity::from_pem(
                    read(config, "tls.cert", cert)?,
                    read(config, "tls.key", key_path)?,
                ));
            }
            (None, None) => {}
            (Some(_), None) => {
                return Err(error(format!(
                    "{}: tls.cert without tls.key",
                    config.display()
                )));
            }
            (None, Some(_)) => {
                return Err(error(format!(
                    "{}: tls.key without tls.cert",
                    config.display()
                )));
            }
        }
        if let Some(name) = &self.camera_name
            && ServerName::try_from(name.as_str()).is_err()
        {
            return Err(error(format!(
                "{}: tls.camera_name = {name:?}: expected a DNS name or an IP address",
                config.display()
            )));
        }
        Ok(ClientTls {
            config: tls,
            camera_name: self.camera_name.clone(),
        })
    }
}

/// The camera agent's side of a config: its `tls` table loaded, or plaintext where the rule
/// allows it (`listen` on loopback, or `insecure`).
pub fn server(
    config: &Path,
    files: Option<&TlsFiles>,
    listen: &str,
    insecure: bool,
) -> Result<Option<ServerTls>, TlsError> {
    match files {
        Some(files) => files.server(config).map(Some),
        None => check_plaintext(config, "listen", Some(listen), insecure).map(|()| None),
    }
}

/// A node agent's side of a config: its `tls` table loaded, or plaintext where the rule allows
/// it (`to`: the field and the address it connects to, `None` over mDNS on every interface).
pub fn client(
    config: &Path,
    files: Option<&TlsFiles>,
    to: (&str, Option<&str>),
    insecure: bool,
) -> Result<Option<ClientTls>, TlsError> {
    match files {
        Some(files) => files.client(config).map(Some),
        None => check_plaintext(config, to.0, to.1, insecure).map(|()| None),
    }
}

/// Plaintext is allowed only on loopback, or with `insecure = true` (which warns at every
/// start): `address` is what `field` of `config` listens on or connects to (`host:port`,
/// `http://host:port`, or `None` for a camera agent found over mDNS on every interface).
pub fn check_plaintext(
    config: &Path,
    field: &str,
    address: Option<&str>,
    insecure: bool,
) -> Result<(), TlsError> {
    if address.is_some_and(is_loopback) {
        return Ok(());
    }
    if insecure {
        tracing::warn!(
            config = %config.display(),
            "insecure = true: plaintext on the network, the room token travels in the clear; give tls = {{ ... }} (docs/operations.md, Certificates and TLS)"
        );
        return Ok(());
    }
    let what = address.map_or_else(|| "found over mDNS".to_string(), |a| format!("= {a:?}"));
    Err(error(format!(
        "{}: {field} {what} is not a loopback address and there is no tls = {{ ... }}: plaintext would carry the room token in the clear (give tls, or insecure = true on a network you trust)",
        config.display()
    )))
}

/// Whether `address` (`host:port`, `scheme://host:port[/...]`, or a bare host) is on loopback:
/// `localhost`, 127.0.0.0/8 or ::1.
pub fn is_loopback(address: &str) -> bool {
    let rest = address.split_once("://").map_or(address, |(_, r)| r);
    let authority = rest.split('/').next().unwrap_or(rest);
    let host = if let Some(v6) = authority.strip_prefix('[') {
        v6.split(']').next().unwrap_or(v6)
    } else if authority.matches(':').count() > 1 {
        authority
    } else {
        authority.rsplit_once(':').map_or(authority, |(h, _)| h)
    };
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Whether a peer's certificate (already verified against the room CA) is valid for `name`.
pub(crate) fn certificate_names(cert: &CertificateDer<'_>, name: &str) -> Result<(), String> {
    let Ok(entity) = webpki::EndEntityCert::try_from(cert) else {
        return Err("an unreadable certificate".into());
    };
    if let Ok(server_name) = ServerName::try_from(name)
        && entity
            .verify_is_valid_for_subject_name(&server_name)
            .is_ok()
    {
        return Ok(());
    }
    let names: Vec<&str> = entity.valid_dns_names().take(8).collect();
    Err(if names.is_empty() {
        "a certificate naming no one".into()
    } else {
        names.join(", ")
    })
}

/// Writes `bytes` to a new file (never over an existing one), 0600 for a key.
fn write_new(path: &Path, bytes: &[u8], secret: bool) -> Result<(), TlsError> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if secret {
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
    }
    let _ = secret;
    options
        .open(path)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()))
        .map_err(|e| error(format!("writing {}: {e}", path.display())))
}

fn rcgen_error(what: &str) -> impl Fn(rcgen::Error) -> TlsError + '_ {
    move |e| error(format!("{what}: {e}"))
}

/// The room CA's parameters. They are the same every time, so `issue` signs with the CA's key
/// under the CA's name without parsing its certificate (which would need an X.509 parser).
fn ca_params() -> rcgen::CertificateParams {
    let mut params = rcgen::CertificateParams::default();
    params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Constrained(0));
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "roomlight room CA");
    params.key_usages = vec![
        rcgen::KeyUsagePurpose::KeyCertSign,
        rcgen::KeyUsagePurpose::CrlSign,
        rcgen::KeyUsagePurpose::DigitalSignature,
    ];
    params
}

/// `roomlight certs init --out DIR`: a new room CA, `DIR/ca.pem` and `DIR/ca.key` (0600). Refuses
/// to overwrite either. Returns what it wrote.
pub fn init_ca(dir: &Path) -> Result<Vec<PathBuf>, TlsError> {
    std::fs::create_dir_all(dir).map_err(|e| error(format!("creating {}: {e}", dir.display())))?;
    let (cert_path, key_path) = (dir.join(CA_CERT), dir.join(CA_KEY));
    for path in [&cert_path, &key_path] {
        if path.exists() {
            return Err(error(format!(
                "{} exists: a room has one CA (remove it to start a new one, then issue every certificate again)",
                path.display()
            )));
        }
    }
    let key = rcgen::KeyPair::generate().map_err(rcgen_error("generating the CA's key"))?;
    let params = ca_params();
    let cert = params
        .self_signed(&key)
        .map_err(rcgen_error("signing the CA"))?;
    write_new(&key_path, key.serialize_pem().as_bytes(), true)?;
    write_new(&cert_path, cert.pem().as_bytes(), false)?;
    Ok(vec![cert_path, key_path])
}

/// What a certificate is for: its name (a camera agent's, or a node's projector id) and the
/// other names and addresses it may be reached by.
#[derive(Debug, Clone, Default)]
pub struct Subject {
    pub name: String,
    pub dns: Vec<String>,
    pub ip: Vec<IpAddr>,
}

/// `roomlight certs issue`: a certificate for `subject` signed by the CA in `ca_dir`, written as
/// `OUT/NAME.pem` and `OUT/NAME.key` (0600), with the CA's certificate copied to `OUT/ca.pem`
/// when it is not there (what a PC needs, in one folder). Returns what it wrote.
pub fn issue(ca_dir: &Path, subject: &Subject, out: &Path) -> Result<Vec<PathBuf>, TlsError> {
    let name = &subject.name;
    for dns in std::iter::once(name).chain(&subject.dns) {
        if !matches!(
            ServerName::try_from(dns.as_str()),
            Ok(ServerName::DnsName(_))
        ) {
            return Err(error(format!(
                "{dns:?}: expected a DNS name (letters, digits, '-' and '.'; a projector id used as a name must be one)"
            )));
        }
    }
    let read_text = |file: &str| {
        let path = ca_dir.join(file);
        std::fs::read_to_string(&path)
            .map_err(|e| error(format!("reading {}: {e}", path.display())))
    };
    let ca_pem = read_text(CA_CERT)?;
    let ca_key = rcgen::KeyPair::from_pem(&read_text(CA_KEY)?)
        .map_err(rcgen_error(&format!("{}", ca_dir.join(CA_KEY).display())))?;
    let issuer = rcgen::Issuer::new(ca_params(), ca_key);
    let names: Vec<String> = std::iter::once(name)
        .chain(&subject.dns)
        .cloned()
        .chain(subject.ip.iter().map(IpAddr::to_string))
        .collect();
    let mut params = rcgen::CertificateParams::new(names).map_err(rcgen_error(name))?;
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, name.clone());
    params.key_usages = vec![rcgen::KeyUsagePurpose::DigitalSignature];
    // A camera agent serves, a node agent is a client: one certificate may be either.
    params.extended_key_usages = vec![
        rcgen::ExtendedKeyUsagePurpose::ServerAuth,
        rcgen::ExtendedKeyUsagePurpose::ClientAuth,
    ];
    params.use_authority_key_identifier_extension = true;
    let key = rcgen::KeyPair::generate().map_err(rcgen_error("generating a key"))?;
    let cert = params
        .signed_by(&key, &issuer)
        .map_err(rcgen_error("signing the certificate"))?;
    std::fs::create_dir_all(out).map_err(|e| error(format!("creating {}: {e}", out.display())))?;
    let (cert_path, key_path) = (
        out.join(format!("{name}.pem")),
        out.join(format!("{name}.key")),
    );
    for path in [&cert_path, &key_path] {
        if path.exists() {
            return Err(error(format!("{} exists: not overwritten", path.display())));
        }
    }
    write_new(&key_path, key.serialize_pem().as_bytes(), true)?;
    write_new(&cert_path, cert.pem().as_bytes(), false)?;
    let mut wrote = vec![cert_path, key_path];
    let ca_copy = out.join(CA_CERT);
    if !ca_copy.exists() {
        write_new(&ca_copy, ca_pem.as_bytes(), false)?;
        wrote.push(ca_copy);
    }
    Ok(wrote)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_addresses() {
        for a in [
            "127.0.0.1:50051",
            "http://127.0.0.1:1",
            "localhost:9",
            "[::1]:50051",
            "https://[::1]:5/x",
            "127.2.3.4",
        ] {
            assert!(is_loopback(a), "{a}");
        }
        for a in [
            "0.0.0.0:50051",
            "http://10.0.0.5:50051",
            "camera.local:1",
            "[::]:1",
            "",
        ] {
            assert!(!is_loopback(a), "{a}");
        }
    }

    #[test]
    fn plaintext_is_refused_off_loopback_unless_insecure() {
        let config = Path::new("/etc/roomlight/camera.toml");
        check_plaintext(config, "listen", Some("127.0.0.1:0"), false).expect("loopback");
        let e = check_plaintext(config, "listen", Some("0.0.0.0:50051"), false)
            .expect_err("refused")
            .to_string();
        assert!(e.contains("camera.toml") && e.contains("listen"), "{e}");
        let e = check_plaintext(config, "camera.mdns", None, false)
            .expect_err("refused")
            .to_string();
        assert!(e.contains("camera.mdns"), "{e}");
        check_plaintext(config, "listen", Some("0.0.0.0:50051"), true).expect("insecure");
    }

    #[test]
    fn issued_certificates_load_and_carry_their_names() {
        let dir = tempfile::tempdir().expect("temp dir");
        let ca = dir.path().join("ca");
        init_ca(&ca).expect("CA");
        assert!(init_ca(&ca).is_err(), "a second CA over the first");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(ca.join(CA_KEY))
                .expect("key")
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let subject = Subject {
            name: "p1".into(),
            dns: vec!["node-pc.local".into()],
            ip: vec!["10.0.0.7".parse().expect("ip")],
        };
        let out = dir.path().join("p1");
        issue(&ca, &subject, &out).expect("issued");
        assert!(
            issue(
                &ca,
                &Subject {
                    name: "bad/name".into(),
                    ..Default::default()
                },
                &out
            )
            .is_err()
        );
        let pem = std::fs::read(out.join("p1.pem")).expect("cert");
        let cert = CertificateDer::from_pem_slice(&pem).expect("pem");
        certificate_names(&cert, "p1").expect("its name");
        certificate_names(&cert, "node-pc.local").expect("its DNS name");
        let other = certificate_names(&cert, "p2").expect_err("another projector");
        assert!(other.contains("p1"), "{other}");
        let files = TlsFiles {
            ca: Some(out.join(CA_CERT)),
            cert: Some(out.join("p1.pem")),
            key: Some(out.join("p1.key")),
            require_client_cert: true,
            camera_name: None,
        };
        let config = Path::new("camera.toml");
        files.server(config).expect("server side");
        let e = files
            .client(config)
            .expect_err("require_client_cert in a node")
            .to_string();
        assert!(e.contains("tls.require_client_cert"), "{e}");
        let missing = TlsFiles {
            key: Some(dir.path().join("none.key")),
            ..files
        };
        let e = missing.server(config).expect_err("no key").to_string();
        assert!(e.contains("camera.toml") && e.contains("tls.key"), "{e}");
    }
}
