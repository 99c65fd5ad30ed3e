//! A plain HTTP/1.1 request over a `TcpStream`, enough to ask chromedriver whether it is ready
//! and the console's API what the browser should have changed (with the bearer token, as a
//! script would), without a browser in between.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// An answer: its status code and body.
#[derive(Debug)]
pub struct Answer {
    pub status: u16,
    pub body: String,
}

impl Answer {
    /// The body as JSON; panics naming the request when it is not.
    pub fn json(&self, what: &str) -> serde_json::Value {
        serde_json::from_str(&self.body)
            .unwrap_or_else(|e| panic!("{what}: not JSON ({e}): {}", self.body))
    }
}

/// `METHOD path` on `address` (`127.0.0.1:PORT`), with `Authorization: Bearer token` when given
/// and a JSON body when given. One connection per request, read until the answer is whole (by
/// its length, its last chunk, or the connection's end: chromedriver keeps it open).
pub fn request(
    address: &str,
    method: &str,
    path: &str,
    token: Option<&str>,
    body: Option<&serde_json::Value>,
) -> std::io::Result<Answer> {
    let mut stream = TcpStream::connect(address)?;
    stream.set_read_timeout(Some(Duration::from_secs(30)))?;
    let body = body.map(|b| b.to_string()).unwrap_or_default();
    let mut head = format!("{method} {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n");
    if let Some(token) = token {
        head.push_str(&format!("Authorization: Bearer {token}\r\n"));
    }
    if !body.is_empty() {
        head.push_str("Content-Type: application/json\r\n");
    }
    head.push_str(&format!("Content-Length: {}\r\n\r\n", body.len()));
    stream.write_all(head.as_bytes())?;
    stream.write_all(body.as_bytes())?;
    let mut raw = Vec::new();
    let mut buf = [0u8; 16 * 1024];
    loop {
        let n = stream.read(&mut buf)?;
        raw.extend_from_slice(&buf[..n]);
        if n == 0 || whole(&raw) {
            break;
        }
    }
    parse(&raw).ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not an HTTP answer: {:?}",
                String::from_utf8_lossy(&raw[..raw.len().min(200)])
            ),
        )
    })
}

/// How an answer's body ends.
enum Framing {
    Length(usize),
    Chunked,
    /// At the connection's end.
    Close,
}

/// The head of an answer read so far: status, framing, and where the body starts.
fn head(raw: &[u8]) -> Option<(u16, Framing, usize)> {
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&raw[..split]).ok()?;
    let mut lines = head.split("\r\n");
    let status = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let mut framing = Framing::Close;
    for line in lines {
        let line = line.to_ascii_lowercase();
        if let Some(length) = line.strip_prefix("content-length:") {
            framing = Framing::Length(length.trim().parse().ok()?);
        } else if line.starts_with("transfer-encoding:") && line.contains("chunked") {
            framing = Framing::Chunked;
        }
    }
    Some((status, framing, split + 4))
}

/// Whether `raw` holds a whole answer.
fn whole(raw: &[u8]) -> bool {
    match head(raw) {
        Some((_, Framing::Length(n), start)) => raw.len() >= start + n,
        Some((_, Framing::Chunked, start)) => dechunk(&raw[start..]).is_some(),
        _ => false,
    }
}

/// Status line, headers and body (chunked or not) of a whole answer.
fn parse(raw: &[u8]) -> Option<Answer> {
    let (status, framing, start) = head(raw)?;
    let body = match framing {
        Framing::Length(n) => raw.get(start..start + n)?.to_vec(),
        Framing::Chunked => dechunk(&raw[start..])?,
        Framing::Close => raw[start..].to_vec(),
    };
    Some(Answer {
        status,
        body: String::from_utf8_lossy(&body).into_owned(),
    })
}

fn dechunk(mut rest: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let end = rest.windows(2).position(|w| w == b"\r\n")?;
        let size = std::str::from_utf8(&rest[..end]).ok()?;
        let size = usize::from_str_radix(size.split(';').next()?.trim(), 16).ok()?;
        rest = &rest[end + 2..];
        if size == 0 {
            return Some(out);
        }
        out.extend_from_slice(rest.get(..size)?);
        rest = rest.get(size + 2..)?;
    }
}

#[test]
fn answers_are_read_plain_and_chunked() {
    let plain = b"HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\n{}";
    assert!(!whole(&plain[..plain.len() - 1]) && whole(plain));
    let plain = parse(plain).expect("plain");
    assert_eq!((plain.status, plain.body.as_str()), (200, "{}"));
    let chunked = parse(
        b"HTTP/1.1 409 Conflict\r\nTransfer-Encoding: chunked\r\n\r\n3\r\n{\"a\r\n4\r\n\":1}\r\n0\r\n\r\n",
    )
    .expect("chunked");
    assert_eq!((chunked.status, chunked.body.as_str()), (409, "{\"a\":1}"));
}
