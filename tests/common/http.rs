//! An HTTP/1.1 client written out here (no HTTP crate of the daemon's), for the tests of the
//! web page: raw requests, `POST /osc` as the page sends it, and a daemon with the page on.

use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use super::daemon::{Daemon, PATIENCE, Setup, free_port};

/// A daemon with the web gallery on; returns it and the gallery's address.
pub fn start(name: &str) -> (Daemon, SocketAddr) {
    start_setup(name, Setup::default())
}

/// [`start`] from a [`Setup`] (another scene, more config), the page added to its config.
pub fn start_setup(name: &str, mut setup: Setup) -> (Daemon, SocketAddr) {
    let lo = IpAddr::from([127, 0, 0, 1]);
    let port = free_port(lo, lo);
    setup.extra += &format!("\n[http]\nlisten = \"127.0.0.1:{port}\"\n");
    let d = Daemon::start_setup(name, setup);
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    // OSC answers before the web listener is up: wait for it (bounded).
    let end = Instant::now() + PATIENCE;
    while get(addr, "/state.json").status != 200 {
        assert!(Instant::now() < end, "the web gallery never answered");
        std::thread::sleep(Duration::from_millis(20));
    }
    (d, addr)
}

/// One HTTP answer.
pub struct Response {
    pub status: u16,
    /// Its Content-Type.
    pub kind: String,
    pub body: Vec<u8>,
}

impl Response {
    /// The body as JSON.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).expect("JSON")
    }
}

/// Sends raw request bytes from a stream and reads one answer (status 0: closed without
/// one). Header names are matched in any case; without a Content-Length the body runs to
/// the end of the connection.
pub fn exchange(mut s: TcpStream, request: &[u8]) -> Response {
    s.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let _ = s.write_all(request);
    let mut raw = Vec::new();
    let mut chunk = [0u8; 4096];
    let split = loop {
        if let Some(i) = raw.windows(4).position(|w| w == b"\r\n\r\n") {
            break i;
        }
        match s.read(&mut chunk) {
            Ok(n) if n > 0 => raw.extend_from_slice(&chunk[..n]),
            _ => {
                return Response {
                    status: 0,
                    kind: String::new(),
                    body: raw,
                };
            }
        }
    };
    let head = String::from_utf8_lossy(&raw[..split]).to_string();
    let header = |name: &str| {
        head.lines().skip(1).find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim()
                .eq_ignore_ascii_case(name)
                .then(|| v.trim().to_string())
        })
    };
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("a status code");
    let kind = header("content-type").unwrap_or_default();
    let mut body = raw[split + 4..].to_vec();
    match header("content-length").and_then(|v| v.parse::<usize>().ok()) {
        Some(length) => {
            while body.len() < length {
                match s.read(&mut chunk) {
                    Ok(n) if n > 0 => body.extend_from_slice(&chunk[..n]),
                    _ => panic!("the body ended at {} of {length} bytes", body.len()),
                }
            }
        }
        None => {
            let _ = s.read_to_end(&mut body);
        }
    }
    Response { status, kind, body }
}

/// A request without headers or body.
pub fn request(addr: SocketAddr, method: &str, path: &str) -> Response {
    send(addr, method, path, &[], b"")
}

/// A request with extra header lines (`Name: value`) and a body; Host is the address
/// (DevTools answers only a Host that is an address) unless a header sets it.
pub fn send(addr: SocketAddr, method: &str, path: &str, headers: &[&str], body: &[u8]) -> Response {
    let Ok(s) = TcpStream::connect(addr) else {
        return Response {
            status: 0,
            kind: String::new(),
            body: Vec::new(),
        };
    };
    let mut head = format!("{method} {path} HTTP/1.1\r\n");
    if !headers
        .iter()
        .any(|h| h.to_ascii_lowercase().starts_with("host:"))
    {
        head.push_str(&format!("Host: {addr}\r\n"));
    }
    for h in headers {
        head.push_str(h);
        head.push_str("\r\n");
    }
    if !headers
        .iter()
        .any(|h| h.to_ascii_lowercase().starts_with("content-length:"))
    {
        head.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    head.push_str("Connection: close\r\n\r\n");
    let mut raw = head.into_bytes();
    raw.extend_from_slice(body);
    exchange(s, &raw)
}

/// `POST /osc` with a JSON command, as the page sends it.
pub fn osc(addr: SocketAddr, address: &str, args: serde_json::Value, headers: &[&str]) -> Response {
    let mut all = vec!["Content-Type: application/json"];
    all.extend_from_slice(headers);
    let body = serde_json::json!({ "address": address, "args": args }).to_string();
    send(addr, "POST", "/osc", &all, body.as_bytes())
}

/// `GET path`.
pub fn get(addr: SocketAddr, path: &str) -> Response {
    request(addr, "GET", path)
}
