//! The web page end to end: over plain HTTP (pictures, state, commands, limits, the
//! allow-list, the password, cross-origin and hostile uploads), and in headless Chromium
//! driven through the DevTools protocol: a whole designer's session (upload and add
//! references, draw a region, generate, members, transfer, pick, undo, save, recall), each
//! step checked on the page, in a screenshot, and on the wire.

mod common;

use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::daemon::{Daemon, Osc, PATIENCE, Proto, free_port, int};
use common::{temp_dir, tools};

/// A daemon with the web gallery on; returns it and the gallery's address.
fn start(name: &str) -> (Daemon, SocketAddr) {
    let lo = IpAddr::from([127, 0, 0, 1]);
    let port = free_port(lo, lo);
    let d = Daemon::start_with(name, &format!("\n[http]\nlisten = \"127.0.0.1:{port}\"\n"));
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    // OSC answers before the web listener is up: wait for it (bounded).
    let end = Instant::now() + PATIENCE;
    while get(addr, "/state.json").status != 200 {
        assert!(Instant::now() < end, "the web gallery never answered");
        std::thread::sleep(Duration::from_millis(20));
    }
    (d, addr)
}

struct Response {
    status: u16,
    kind: String,
    body: Vec<u8>,
}

impl Response {
    fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).expect("JSON")
    }
}

/// Sends raw request bytes from a stream and reads one answer (status 0: closed without
/// one). Header names are matched in any case; without a Content-Length the body runs to
/// the end of the connection.
fn exchange(mut s: TcpStream, request: &[u8]) -> Response {
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

fn request(addr: SocketAddr, method: &str, path: &str) -> Response {
    send(addr, method, path, &[], b"")
}

/// A request with extra header lines (`Name: value`) and a body; Host is the address
/// (DevTools answers only a Host that is an address) unless a header sets it.
fn send(addr: SocketAddr, method: &str, path: &str, headers: &[&str], body: &[u8]) -> Response {
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
fn osc(addr: SocketAddr, address: &str, args: serde_json::Value, headers: &[&str]) -> Response {
    let mut all = vec!["Content-Type: application/json"];
    all.extend_from_slice(headers);
    let body = serde_json::json!({ "address": address, "args": args }).to_string();
    send(addr, "POST", "/osc", &all, body.as_bytes())
}

fn get(addr: SocketAddr, path: &str) -> Response {
    request(addr, "GET", path)
}

fn jpeg(r: &Response) -> image::RgbImage {
    assert_eq!((r.status, r.kind.as_str()), (200, "image/jpeg"));
    image::load_from_memory(&r.body).expect("a JPEG").to_rgb8()
}

#[test]
fn the_gallery_over_http() {
    let (mut d, addr) = start("web-http");
    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    let html = String::from_utf8(page.body).expect("UTF-8");
    assert!(
        html.contains("<script>") && html.contains("<style>"),
        "inline JS and CSS"
    );
    // Self-contained: nothing fetched from anywhere else.
    for outside in ["src=\"http", "href=\"http", "@import", "url(http"] {
        assert!(!html.contains(outside), "the page loads {outside}");
    }
    assert_eq!(
        get(addr, "/state.json").json()["gallery"],
        serde_json::Value::Null
    );

    d.add_objective("warm.png", "both");
    d.ok(
        "/vo/objective/1/region",
        vec![
            common::daemon::float(0.0),
            common::daemon::float(0.0),
            common::daemon::float(0.5),
            common::daemon::float(1.0),
        ],
        "/vo/objective/region",
    );
    d.generate();
    let n = d.gallery().len();
    let st = get(addr, "/state.json").json();
    assert_eq!(st["gallery"]["sizes"].as_array().map(Vec::len), Some(n));
    assert_eq!(st["objectives"][0]["image"], "warm.png");
    assert_eq!(st["objectives"][0]["region"][2], 0.5);
    assert!(st["console"].is_null(), "no [input.sacn]: no console part");
    let serial = st["gallery"]["serial"].as_u64().expect("a serial");

    let first = jpeg(&get(addr, &format!("/thumb/{serial}/1.jpg")));
    assert!(first.width() > 0 && first.height() > 0);
    let pics: Vec<Vec<u8>> = (1..=n)
        .map(|k| get(addr, &format!("/thumb/{serial}/{k}.jpg")).body)
        .collect();
    assert!(
        pics.windows(2).any(|w| w[0] != w[1]),
        "the entries look different"
    );
    assert_eq!(
        get(addr, &format!("/thumb/{serial}/{}.jpg", n + 1)).status,
        404
    );
    assert_eq!(
        get(addr, &format!("/thumb/{}/1.jpg", serial + 1)).status,
        404
    );
    jpeg(&get(addr, "/ref/1.jpg"));
    assert_eq!(get(addr, "/ref/9.jpg").status, 404);
    let dark = jpeg(&get(addr, "/live.jpg"));

    // A tap picks through the OSC command path: reply, status, DMX.
    let r = osc(addr, "/vo/pick", serde_json::json!([2]), &[]);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(
        r.json()["replies"],
        serde_json::json!([{ "address": "/vo/picked", "args": [2, 1] }])
    );
    assert_eq!(d.status().entry, 2);
    let look = d.candidate(2, 1);
    d.wire.wait_look(Proto::Sacn, &look);
    assert_ne!(
        jpeg(&get(addr, "/live.jpg")),
        dark,
        "the live picture follows"
    );
    assert_eq!(get(addr, "/state.json").json()["entry"], 2);
    // A refused pick changes nothing and says why.
    let r = osc(addr, "/vo/pick", serde_json::json!([n + 1]), &[]);
    assert_eq!(r.status, 409);
    assert!(
        r.json()["error"]
            .as_str()
            .is_some_and(|e| e.contains("not in the gallery"))
    );
    assert_eq!(d.status().entry, 2);

    // Members on demand, and the other pictures.
    jpeg(&get(addr, &format!("/thumb/{serial}/2/1.jpg")));
    assert_eq!(get(addr, &format!("/thumb/{serial}/2/999.jpg")).status, 404);
    jpeg(&get(addr, "/selected/1.jpg"));
    jpeg(&get(addr, "/history/u1.jpg"));
    assert_eq!(get(addr, "/history/u99.jpg").status, 404);
    jpeg(&get(addr, "/references/grey.png"));
    let refs = get(addr, "/references.json").json();
    let mut on_disk: Vec<String> = std::fs::read_dir(d.refs())
        .expect("refs")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".png") || n.ends_with(".jpg"))
        .collect();
    on_disk.sort();
    assert!(on_disk.len() >= 3, "{on_disk:?}");
    assert_eq!(refs["references"], serde_json::json!(on_disk));

    // Bounded and strict.
    let s = TcpStream::connect(addr).expect("connect");
    let huge = format!("GET / HTTP/1.1\r\nX-Pad: {}\r\n\r\n", "a".repeat(20000));
    assert_eq!(exchange(s, huge.as_bytes()).status, 431);
    let big = format!(
        "{{\"address\":\"/vo/ping\",\"args\":[\"{}\"]}}",
        "a".repeat(5000)
    );
    let r = send(
        addr,
        "POST",
        "/osc",
        &["Content-Type: application/json"],
        big.as_bytes(),
    );
    assert_eq!(r.status, 413);
    let s = TcpStream::connect(addr).expect("connect");
    assert_eq!(exchange(s, b"hello there\r\n\r\n").status, 400);
    assert_eq!(request(addr, "PUT", "/osc").status, 405);
    assert_eq!(request(addr, "GET", "/nothing").status, 404);
    let r = send(
        addr,
        "POST",
        "/osc",
        &["Content-Type: application/json"],
        b"{not json",
    );
    assert_eq!(r.status, 400, "{}", String::from_utf8_lossy(&r.body));
    let r = osc(addr, "/vo/backup/subscribe", serde_json::json!([]), &[]);
    assert_eq!(r.status, 403);
    let r = osc(addr, "/vo/pick", serde_json::json!([[1]]), &[]);
    assert_eq!(r.status, 400);
    assert_eq!(d.status().entry, 2);
}

#[test]
fn the_allow_list_applies_to_the_web_gallery() {
    let (mut d, addr) = start("web-allow");
    // Only 127.0.0.1 may talk (OSC from the harness still can); 127.0.0.2 is loopback too
    // but not on the list.
    let config = d.dir.join("visobjd.toml");
    let text = std::fs::read_to_string(&config).expect("config");
    std::fs::write(
        &config,
        text.replacen("[osc]\n", "[osc]\nallow = [\"127.0.0.1\"]\n", 1),
    )
    .expect("write");
    d.terminate();
    d.restart();
    let end = Instant::now() + PATIENCE;
    while get(addr, "/state.json").status != 200 {
        assert!(Instant::now() < end, "the web gallery never came back");
        std::thread::sleep(Duration::from_millis(20));
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let other = runtime.block_on(async {
        let socket = tokio::net::TcpSocket::new_v4().expect("socket");
        socket
            .bind("127.0.0.2:0".parse().expect("addr"))
            .expect("bind 127.0.0.2");
        socket
            .connect(addr)
            .await
            .expect("connect")
            .into_std()
            .expect("std")
    });
    other.set_nonblocking(false).expect("blocking");
    let r = exchange(other, b"POST /pick/1 HTTP/1.1\r\n\r\n");
    assert_eq!(r.status, 0, "refused without an answer, got {}", r.status);
    assert_eq!(d.status().entry, 0);
}

// ---- headless Chromium ---------------------------------------------------------------

/// The Chromium binary, if installed.
fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            std::env::var_os("PATH")?
                .to_str()?
                .split(':')
                .map(|dir| Path::new(dir).join(name))
                .find(|p| p.is_file())
        })
}

/// A browser process, killed on drop.
struct Browser {
    child: Child,
    profile: PathBuf,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

/// The DevTools connection to one page.
struct Page {
    ws: tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    next_id: u64,
}

impl Page {
    /// Evaluates `expression` in the page; its value as JSON.
    fn eval(&mut self, expression: &str) -> serde_json::Value {
        self.next_id += 1;
        let id = self.next_id;
        let call = serde_json::json!({
            "id": id,
            "method": "Runtime.evaluate",
            "params": { "expression": expression, "returnByValue": true },
        });
        self.ws
            .send(tungstenite::Message::text(call.to_string()))
            .expect("send to DevTools");
        loop {
            let m = self.ws.read().expect("a DevTools message");
            let Ok(text) = m.to_text() else { continue };
            let v: serde_json::Value = serde_json::from_str(text).expect("DevTools JSON");
            if v["id"] == id {
                assert!(
                    v["result"]["exceptionDetails"].is_null(),
                    "{expression}: {v}"
                );
                return v["result"]["result"]["value"].clone();
            }
        }
    }

    /// Polls `expression` until `want` holds (bounded); returns the last value.
    fn wait(
        &mut self,
        expression: &str,
        what: &str,
        want: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let end = Instant::now() + Duration::from_secs(30);
        loop {
            let v = self.eval(expression);
            if want(&v) {
                return v;
            }
            assert!(Instant::now() < end, "the page never {what}: last {v}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// Starts headless Chromium on `url` and connects to its page.
fn open(browser: &Path, url: &str, name: &str) -> (Browser, Page) {
    let profile = temp_dir(&format!("chromium-{name}"));
    let child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--remote-debugging-port=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(url)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromium starts");
    let b = Browser { child, profile };
    // Chromium writes its DevTools port into the profile once it listens.
    let end = Instant::now() + Duration::from_secs(60);
    let port: u16 = loop {
        if let Some(p) = std::fs::read_to_string(b.profile.join("DevToolsActivePort"))
            .ok()
            .and_then(|t| t.lines().next()?.trim().parse().ok())
        {
            break p;
        }
        assert!(Instant::now() < end, "Chromium never opened DevTools");
        std::thread::sleep(Duration::from_millis(50));
    };
    let devtools = SocketAddr::from(([127, 0, 0, 1], port));
    let ws_url = loop {
        let list = get(devtools, "/json/list");
        let found = (list.status == 200)
            .then(|| list.json())
            .and_then(|targets| {
                targets.as_array()?.iter().find_map(|t| {
                    (t["type"] == "page" && t["url"].as_str()?.starts_with(url))
                        .then(|| t["webSocketDebuggerUrl"].as_str().map(str::to_string))?
                })
            });
        if let Some(u) = found {
            break u;
        }
        assert!(Instant::now() < end, "Chromium never listed the page");
        std::thread::sleep(Duration::from_millis(50));
    };
    let (ws, _) = tungstenite::connect(ws_url.as_str()).expect("DevTools websocket");
    (b, Page { ws, next_id: 0 })
}

#[test]
fn a_tap_in_the_browser_puts_the_entry_live() {
    let Some(browser) = chromium() else {
        return tools::missing("Chromium", "is not installed", "apt-get install chromium");
    };
    let (mut d, addr) = start("web-chromium");
    d.ok(
        "/vo/generate/clusters",
        vec![int(12)],
        "/vo/generate/clusters",
    );
    d.add_objective("cool.png", "both");
    let url = format!("http://{addr}/");
    let (_browser, mut page) = open(&browser, &url, "tap");

    page.wait(
        "document.getElementById('status')?.textContent ?? ''",
        "showed the daemon's status",
        |v| v.as_str().is_some_and(|s| s.contains("no gallery yet")),
    );
    assert_eq!(
        page.eval("document.querySelectorAll('#gallery .thumb').length"),
        0
    );

    d.generate();
    assert_eq!(d.gallery().len(), 12, "12 entries");
    page.wait(
        "[...document.querySelectorAll('#gallery .thumb img')].filter(i => i.complete && i.naturalWidth > 0).length",
        "showed 12 loaded thumbnails",
        |v| v == 12,
    );
    let numbers = page.eval(
        "[...document.querySelectorAll('#gallery .thumb span')].map(s => s.textContent).join(' ')",
    );
    assert_eq!(numbers, "1 2 3 4 5 6 7 8 9 10 11 12");

    let look = d.candidate(5, 1);
    assert_eq!(
        page.eval("document.querySelector('#gallery .thumb[data-k=\"5\"]').click(); true"),
        true
    );
    d.wire.wait_look(Proto::Sacn, &look);
    d.wire.wait_look(Proto::Artnet, &look);
    assert_eq!(d.status().entry, 5);
    page.wait(
        "document.querySelector('#gallery .thumb.live')?.dataset.k ?? ''",
        "marked entry 5 live",
        |v| v == "5",
    );
    page.wait(
        "document.getElementById('status')?.textContent ?? ''",
        "said entry 5 is live",
        |v| v.as_str().is_some_and(|s| s.contains("entry 5 of 12 live")),
    );
    // The objective and its reference image are shown.
    page.wait(
        "[...document.querySelectorAll('#objectives img')].filter(i => i.complete && i.naturalWidth > 0).length",
        "showed the reference image",
        |v| v == 1,
    );
}

/// An 8x8 PNG of one colour, as bytes.
fn png(rgb: [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_pixel(8, 8, image::Rgb(rgb));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("encode");
    out.into_inner()
}

#[test]
fn hostile_requests_change_nothing() {
    let (mut d, addr) = start("web-hostile");
    d.add_objective("warm.png", "both");
    d.generate();
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let live = d.live();
    d.wire.wait_look(Proto::Sacn, &live);
    let listed = || get(addr, "/references.json").json()["references"].clone();
    let before = listed();

    // Uploads: too big (refused before the body is read), not an image, the wrong type
    // for its name, names with paths in them.
    let r = send(
        addr,
        "PUT",
        "/references/huge.png",
        &["Content-Length: 40000000"],
        b"",
    );
    assert_eq!(
        r.status,
        413,
        "{}\n{}",
        String::from_utf8_lossy(&r.body),
        d.log_text()
    );
    for (name, body, status) in [
        ("fake.jpg", b"this is not a jpeg at all".to_vec(), 400),
        ("blue.jpg", png([0, 0, 255]), 400),
        ("notes.txt", png([0, 0, 255]), 400),
        ("..%2F..%2Fescape.png", png([0, 0, 255]), 400),
        ("sub%2Fx.png", png([0, 0, 255]), 400),
        (".hidden.png", png([0, 0, 255]), 400),
        ("warm.png", png([0, 0, 255]), 409),
    ] {
        let r = send(addr, "PUT", &format!("/references/{name}"), &[], &body);
        assert_eq!(
            r.status,
            status,
            "{name}: {}",
            String::from_utf8_lossy(&r.body)
        );
        let e = r.json()["error"].as_str().unwrap_or_default().to_string();
        assert!(
            e.starts_with("upload `"),
            "{name}: a sentence naming it: {e}"
        );
    }
    assert_eq!(listed(), before, "no file was stored");
    assert!(!d.refs().join("../escape.png").exists());
    assert_eq!(get(addr, "/references/..%2Fvisobjd.toml").status, 404);

    // Another site's page, a rebound name, a GET that would change something.
    let evil = osc(
        addr,
        "/vo/pick",
        serde_json::json!([2]),
        &["Origin: http://evil.example"],
    );
    assert_eq!(evil.status, 403, "{}", String::from_utf8_lossy(&evil.body));
    let site = osc(
        addr,
        "/vo/pick",
        serde_json::json!([2]),
        &["Sec-Fetch-Site: cross-site"],
    );
    assert_eq!(site.status, 403);
    let rebound = osc(
        addr,
        "/vo/pick",
        serde_json::json!([2]),
        &["Host: evil.example:8080"],
    );
    assert_eq!(rebound.status, 403);
    assert_eq!(get(addr, "/osc").status, 405);
    let r = send(
        addr,
        "PUT",
        "/references/new.png",
        &["Origin: http://evil.example"],
        &png([0, 255, 0]),
    );
    assert_eq!(r.status, 403);
    assert_eq!(listed(), before);
    assert_eq!(d.status().entry, 1);
    assert_eq!(d.live(), live);
    d.wire.wait_look(Proto::Sacn, &live);

    // A good upload goes through (and shows in the list).
    let r = send(addr, "PUT", "/references/new.png", &[], &png([0, 255, 0]));
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    assert!(d.refs().join("new.png").is_file());
}

#[test]
fn the_password_is_asked_for() {
    let lo = IpAddr::from([127, 0, 0, 1]);
    let port = free_port(lo, lo);
    let mut d = Daemon::start_with(
        "web-password",
        &format!("\n[http]\nlisten = \"127.0.0.1:{port}\"\npassword = \"stage left\"\n"),
    );
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    use base64::Engine as _;
    let b64 = |s: &str| base64::engine::general_purpose::STANDARD.encode(s);
    let good = format!("Authorization: Basic {}", b64("designer:stage left"));
    let end = Instant::now() + PATIENCE;
    while send(addr, "GET", "/state.json", &[&good], b"").status != 200 {
        assert!(Instant::now() < end, "the web page never answered");
        std::thread::sleep(Duration::from_millis(20));
    }
    d.add_objective("warm.png", "both");
    d.generate();
    let live = d.live();
    let r = get(addr, "/");
    assert_eq!(r.status, 401);
    let wrong = format!("Authorization: Basic {}", b64("designer:stage right"));
    for auth in [&[][..], &[wrong.as_str()][..]] {
        let r = osc(addr, "/vo/pick", serde_json::json!([1]), auth);
        assert_eq!(r.status, 401);
        assert!(
            r.json()["error"]
                .as_str()
                .is_some_and(|e| e.contains("password"))
        );
    }
    assert_eq!(d.status().entry, 0);
    assert_eq!(d.live(), live);
    let r = osc(addr, "/vo/pick", serde_json::json!([1]), &[&good]);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(d.status().entry, 1);
}
