//! The web page end to end: over plain HTTP (pictures, state, commands, limits, the
//! allow-list, the password, cross-origin and hostile uploads), and in headless Chromium
//! driven through the DevTools protocol: a whole designer's session (upload and add
//! references, draw a region, generate, members, transfer, pick, undo, save, recall), each
//! step checked on the page, in a screenshot, and on the wire; and the constraints of
//! groups and lights, a pin and a transfer region drawn on the stage, and a history tap
//! of several steps as one command, read back from the daemon and checked on the wire,
//! the page shown at a laptop's and a tablet's width; a mover's focus palette chosen on
//! the page (pan and tilt on the wire) and one set over OSC followed by the page.

use std::net::{IpAddr, SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{Daemon, Osc, PATIENCE, Proto, free_port, int};
use crate::common::http::{Response, exchange, get, osc, request, send, start};
use visobjd_testkit::{temp_dir, tools};

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
    // Links between daemons and UDP subscriptions are not the page's, however the address
    // is spelt (the handler drops empty segments and case).
    for address in [
        "/vo/backup/subscribe",
        "/VO//Backup/subscribe",
        "/vo//subscribe",
        "//vo/unsubscribe",
    ] {
        let r = osc(addr, address, serde_json::json!([9000]), &[]);
        assert_eq!(
            r.status,
            403,
            "{address}: {}",
            String::from_utf8_lossy(&r.body)
        );
    }
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
    d.add_objective("warm.png", "both");
    d.generate();
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
    // A pick the page would send: let through, it would put entry 1 live.
    let body = r#"{"address": "/vo/pick", "args": [1]}"#;
    let pick = format!(
        "POST /osc HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    let r = exchange(other, pick.as_bytes());
    assert_eq!(r.status, 0, "refused without an answer, got {}", r.status);
    assert_eq!(d.status().entry, 0);
}

// ---- headless Chromium ---------------------------------------------------------------

/// The Chromium binary; without one, [`tools::missing`] says so (and fails the test under
/// `CI=true`) and this is None.
fn chromium() -> Option<PathBuf> {
    let found = ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            std::env::var_os("PATH")?
                .to_str()?
                .split(':')
                .map(|dir| Path::new(dir).join(name))
                .find(|p| p.is_file())
        });
    if found.is_none() {
        tools::missing("Chromium", "is not installed", "apt-get install chromium");
    }
    found
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
    /// Calls a DevTools method; its result.
    fn call(&mut self, method: &str, params: serde_json::Value) -> serde_json::Value {
        self.next_id += 1;
        let id = self.next_id;
        let call = serde_json::json!({ "id": id, "method": method, "params": params });
        self.ws
            .send(tungstenite::Message::text(call.to_string()))
            .expect("send to DevTools");
        loop {
            let m = self.ws.read().expect("a DevTools message");
            let Ok(text) = m.to_text() else { continue };
            let v: serde_json::Value = serde_json::from_str(text).expect("DevTools JSON");
            if v["id"] == id {
                assert!(v["error"].is_null(), "{method}: {v}");
                return v["result"].clone();
            }
        }
    }

    /// Evaluates `expression` in the page; its value as JSON.
    fn eval(&mut self, expression: &str) -> serde_json::Value {
        let r = self.call(
            "Runtime.evaluate",
            serde_json::json!({ "expression": expression, "returnByValue": true, "awaitPromise": true }),
        );
        assert!(r["exceptionDetails"].is_null(), "{expression}: {r}");
        r["result"]["value"].clone()
    }

    /// Clicks the element `selector` names (it must exist).
    fn click(&mut self, selector: &str) {
        let js = format!(
            "(() => {{ const e = document.querySelector({selector:?}); if (!e) return false; e.click(); return true; }})()"
        );
        assert_eq!(self.eval(&js), true, "no {selector} on the page");
    }

    /// Saves a screenshot of the page as `name`.png under the test's target folder.
    fn screenshot(&mut self, name: &str) -> PathBuf {
        use base64::Engine as _;
        let r = self.call(
            "Page.captureScreenshot",
            serde_json::json!({ "format": "png", "captureBeyondViewport": true }),
        );
        let png = base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().expect("screenshot data"))
            .expect("base64");
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("web-session");
        std::fs::create_dir_all(&dir).expect("screenshot folder");
        let path = dir.join(format!("{name}.png"));
        std::fs::write(&path, png).expect("write screenshot");
        path
    }

    /// A real mouse drag (DevTools input, as a hand would): from and to in page pixels.
    fn drag(&mut self, from: (f64, f64), to: (f64, f64)) {
        let mouse = |page: &mut Page, kind: &str, (x, y): (f64, f64), buttons: u8| {
            page.call(
                "Input.dispatchMouseEvent",
                serde_json::json!({ "type": kind, "x": x, "y": y, "button": "left", "buttons": buttons, "clickCount": 1 }),
            );
        };
        mouse(self, "mouseMoved", from, 0);
        mouse(self, "mousePressed", from, 1);
        for i in 1..=8 {
            let f = f64::from(i) / 8.0;
            let p = (from.0 + (to.0 - from.0) * f, from.1 + (to.1 - from.1) * f);
            mouse(self, "mouseMoved", p, 1);
        }
        mouse(self, "mouseReleased", to, 0);
    }

    /// A finger on the screen (DevTools touch input, as a tablet sends it): down at the
    /// first point, through the others, up at the last; points in page pixels.
    fn touch(&mut self, points: &[(f64, f64)]) {
        let finger = |page: &mut Page, kind: &str, at: Option<(f64, f64)>| {
            let touching: Vec<serde_json::Value> = at
                .iter()
                .map(|&(x, y)| serde_json::json!({ "x": x, "y": y, "radiusX": 8, "radiusY": 8, "force": 1 }))
                .collect();
            page.call(
                "Input.dispatchTouchEvent",
                serde_json::json!({ "type": kind, "touchPoints": touching }),
            );
        };
        let (Some(&first), Some(_)) = (points.first(), points.last()) else {
            return;
        };
        finger(self, "touchStart", Some(first));
        for &p in &points[1..] {
            finger(self, "touchMove", Some(p));
        }
        finger(self, "touchEnd", None);
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
            "--window-size=1500,1100",
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
        return;
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

#[test]
fn the_page_shows_what_a_generate_notes() {
    let Some(browser) = chromium() else {
        return;
    };
    let (mut d, addr) = start("web-note");
    // Colour only on the dark start: the generate sets intensity too and says so.
    d.add_objective("cool.png", "color");
    let (_browser, mut page) = open(&browser, &format!("http://{addr}/"), "note");
    page.wait(
        "document.getElementById('status')?.textContent ?? ''",
        "showed the daemon's status",
        |v| v.as_str().is_some_and(|s| s.contains("no gallery yet")),
    );
    // The note is pushed: the page must be listening before the generate is asked for.
    page.wait(
        "document.body.dataset.events ?? ''",
        "opened its event stream",
        |v| v.as_str() == Some("open"),
    );
    assert_eq!(
        page.eval("document.getElementById('generate').click(); true"),
        true
    );
    page.wait(
        "document.getElementById('error').textContent",
        "showed the generate's note",
        |v| {
            v.as_str()
                .is_some_and(|s| s.contains("cool.png asks for colour only"))
        },
    );
    assert!(d.status().candidates > 0);
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

    // Guessing at network speed: after ten wrong passwords in a minute the sender is
    // refused for the rest of it, the right password included.
    let mut statuses = Vec::new();
    for _ in 0..12 {
        statuses.push(send(addr, "GET", "/state.json", &[&wrong], b"").status);
    }
    assert_eq!(statuses[..9], [401; 9], "{statuses:?}");
    assert_eq!(statuses[10..], [429; 2], "{statuses:?}");
    let r = send(addr, "GET", "/state.json", &[&good], b"");
    assert_eq!(r.status, 429);
    assert!(
        r.json()["error"]
            .as_str()
            .is_some_and(|e| e.contains("too many wrong passwords")),
        "{}",
        String::from_utf8_lossy(&r.body)
    );
}

/// The look the page shows (its last state: every light's intensity and colour), as the
/// wire decoder compares it; a light without colour reads `1 1 1` as on OSC.
fn page_look(page: &mut Page) -> Vec<common::daemon::LightLevel> {
    let v = page.eval(
        "JSON.stringify(st ? st.lights.map(l => [l.ch, l.intensity, l.colour ? l.color : [1, 1, 1]]) : [])",
    );
    let rows: Vec<(i32, f32, [f32; 3])> =
        serde_json::from_str(v.as_str().expect("text")).expect("lights");
    rows.into_iter()
        .map(|(ch, intensity, color)| common::daemon::LightLevel {
            ch,
            intensity,
            color,
        })
        .collect()
}

/// Waits until the page shows `want` (within float noise), then checks both protocols on
/// the wire carry what the page shows.
fn shows_on_page_and_wire(
    page: &mut Page,
    d: &Daemon,
    want: &[common::daemon::LightLevel],
    step: &str,
) {
    let end = Instant::now() + Duration::from_secs(30);
    loop {
        let shown = page_look(page);
        let same = shown.len() == want.len()
            && shown.iter().zip(want).all(|(a, b)| {
                a.ch == b.ch
                    && (a.intensity - b.intensity).abs() < 1e-5
                    && a.color
                        .iter()
                        .zip(&b.color)
                        .all(|(x, y)| (x - y).abs() < 1e-5)
            });
        if same {
            d.wire.wait_look(Proto::Sacn, &shown);
            d.wire.wait_look(Proto::Artnet, &shown);
            return;
        }
        assert!(
            Instant::now() < end,
            "{step}: the page never showed {want:?}; it shows {shown:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until every image under `selector` has loaded, and that there are `n`.
fn images_loaded(page: &mut Page, selector: &str, n: usize, what: &str) {
    let js = format!(
        "[...document.querySelectorAll({selector:?})].filter(i => i.complete && i.naturalWidth > 0).length"
    );
    page.wait(&js, what, |v| v.as_u64() == Some(n as u64));
}

/// A daemon (6 entries a gallery, no fade) with its web page open in headless Chromium
/// (`web-NAME`), and the page's address; None without Chromium (see [`tools::missing`]).
fn browse(name: &str) -> Option<(Daemon, SocketAddr, Browser, Page)> {
    let browser = chromium()?;
    let (mut d, addr) = start(&format!("web-{name}"));
    d.ok(
        "/vo/generate/clusters",
        vec![int(6)],
        "/vo/generate/clusters",
    );
    d.ok("/vo/fade", vec![common::daemon::float(0.0)], "/vo/fade");
    let (b, page) = open(&browser, &format!("http://{addr}/"), name);
    Some((d, addr, b, page))
}

#[test]
fn a_designer_session_in_the_browser() {
    let Some((mut d, _, _browser, mut page)) = browse("session") else {
        return;
    };
    page.wait(
        "document.getElementById('status')?.textContent ?? ''",
        "showed the daemon's status",
        |v| v.as_str().is_some_and(|s| s.contains("no gallery yet")),
    );

    // 1. Upload a new reference through the file picker, as a designer would.
    let upload = temp_dir("web-session-upload").join("deep blue.png");
    std::fs::write(&upload, png([10, 30, 200])).expect("write the upload");
    let doc = page.call("DOM.getDocument", serde_json::json!({}));
    let input = page.call(
        "DOM.querySelector",
        serde_json::json!({ "nodeId": doc["root"]["nodeId"], "selector": "#upload" }),
    );
    page.call(
        "DOM.setFileInputFiles",
        serde_json::json!({ "nodeId": input["nodeId"], "files": [upload.display().to_string()] }),
    );
    page.wait(
        "[...document.querySelectorAll('#references .ref')].map(b => b.dataset.name).join(',')",
        "listed the uploaded reference",
        |v| {
            v.as_str()
                .is_some_and(|s| s.split(',').any(|n| n == "deep blue.png"))
        },
    );
    assert_eq!(
        std::fs::read(d.refs().join("deep blue.png")).expect("stored"),
        std::fs::read(&upload).expect("upload")
    );

    // 2. Add two references as objectives: one for both aspects, the new one for colour.
    page.click("#references .ref[data-name='warm.png']");
    page.wait(
        "document.querySelectorAll('#objectives .objective').length",
        "added warm.png",
        |v| v == 1,
    );
    page.eval("document.getElementById('aspect').value = 'color'; true");
    page.click("#references .ref[data-name='deep blue.png']");
    page.wait(
        "document.querySelectorAll('#objectives .objective').length",
        "added deep blue.png",
        |v| v == 2,
    );
    assert_eq!(d.status().objectives, 2);
    let listing = d.call("/vo/objectives", vec![], "/vo/objectives/end");
    assert_eq!(common::daemon::text(&listing[1].args[1]), "deep blue.png");
    assert_eq!(common::daemon::text(&listing[1].args[2]), "color");
    images_loaded(
        &mut page,
        "#objectives img",
        2,
        "showed both reference images",
    );
    page.screenshot("1-references");

    // 3. Draw objective 1's region on the stage with the mouse.
    page.click("#objectives .objective[data-id='1']");
    page.wait("chosen", "selected objective 1", |v| v == 1);
    let rect = page.eval(
        "(() => { const b = document.getElementById('stage').getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; })()",
    );
    let r: Vec<f64> = serde_json::from_value(rect).expect("rect");
    let at = |fx: f64, fy: f64| (r[0] + r[2] * fx, r[1] + r[3] * fy);
    page.drag(at(0.1, 0.2), at(0.5, 0.9));
    // The drag explored: once it ends, a gallery drawn from the region is on the page
    // without a generate.
    page.wait("exploring", "ended the drag's explore", |v| v == false);
    page.wait(
        "st.gallery ? st.gallery.sizes.length : 0",
        "showed a gallery explored by the drag",
        |v| v.as_u64().is_some_and(|n| n > 0),
    );
    let region = page.wait("st.objectives[0].region", "took the drawn region", |v| {
        v[2].as_f64().is_some_and(|x1| (x1 - 0.5).abs() < 0.02)
    });
    let listing = d.call("/vo/objectives", vec![], "/vo/objectives/end");
    for (i, want) in [0.1, 0.2, 0.5, 0.9].iter().enumerate() {
        let daemon = match listing[0].args[3 + i] {
            rosc::OscType::Float(f) => f64::from(f),
            ref other => panic!("a float, got {other:?}"),
        };
        assert!(
            (daemon - want).abs() < 0.02,
            "x0 y0 x1 y1 {i}: {daemon} vs {want}"
        );
        assert!((region[i].as_f64().expect("num") - daemon).abs() < 1e-6);
    }
    page.eval("document.getElementById('showsel').click(); true");
    page.wait(
        "document.getElementById('stageimg').getAttribute('src')",
        "showed the lights the region selects",
        |v| v.as_str().is_some_and(|s| s.starts_with("/selected/1.jpg")),
    );
    images_loaded(&mut page, "#stageimg", 1, "drew the selected lights");
    let chosen = page.eval("st.objectives[0].selected.length");
    assert!(
        chosen.as_u64().is_some_and(|n| n > 0),
        "the region selects lights"
    );
    page.screenshot("2-region");
    page.eval("document.getElementById('showsel').click(); true");

    // 4. Generate from the page; the gallery arrives by the event stream (a new one: the
    // drag's is on the page already).
    let explored = page.eval("st.gallery.serial");
    page.click("#generate");
    page.wait("st.gallery.serial", "showed the generated gallery", |v| {
        *v != explored
    });
    let n = page.wait(
        "st.gallery ? st.gallery.sizes.length : 0",
        "showed a gallery",
        |v| v.as_u64().is_some_and(|n| n > 1),
    );
    let n = n.as_u64().expect("n") as usize;
    assert_eq!(d.gallery().len(), n);
    images_loaded(
        &mut page,
        "#gallery .entry > .thumb img",
        n,
        "showed every entry",
    );
    page.screenshot("3-gallery");

    // 5. Open entry 2's members.
    page.click("#gallery .entry[data-k='2'] .members");
    let size = d.gallery()[1] as usize;
    images_loaded(
        &mut page,
        "#gallery .entry[data-k='2'] .member img",
        size,
        "showed entry 2's members",
    );
    page.screenshot("4-members");

    // 6. Transfer a group from entry 3 onto the (dark) stage.
    let group = page
        .eval("st.groups[0].name")
        .as_str()
        .expect("a group")
        .to_string();
    let members: Vec<i32> = page
        .eval("st.groups[0].lights")
        .as_array()
        .expect("lights")
        .iter()
        .map(|v| v.as_i64().expect("ch") as i32)
        .collect();
    page.eval(&format!(
        "document.getElementById('transfergroup').value = {group:?}; true"
    ));
    let before = d.live();
    let third = d.candidate(3, 1);
    page.click("#gallery .entry[data-k='3'] .transfer");
    let transferred: Vec<common::daemon::LightLevel> = before
        .iter()
        .zip(&third)
        .map(|(b, c)| {
            if members.contains(&b.ch) {
                c.clone()
            } else {
                b.clone()
            }
        })
        .collect();
    shows_on_page_and_wire(&mut page, &d, &transferred, "transfer");
    assert_eq!(d.live(), transferred);
    page.screenshot("5-transfer");

    // 7. Pick another entry.
    let fourth = d.candidate(4, 1);
    page.click("#gallery .entry[data-k='4'] .thumb");
    shows_on_page_and_wire(&mut page, &d, &fourth, "pick 4");
    page.wait(
        "document.querySelector('#gallery .thumb.live')?.parentElement.dataset.k ?? ''",
        "marked entry 4 live",
        |v| v == "4",
    );
    assert_eq!(d.status().entry, 4);

    // 8. Undo: back to the transferred look; the history shows thumbnails.
    page.click("#undo");
    shows_on_page_and_wire(&mut page, &d, &transferred, "undo");
    images_loaded(&mut page, "#history .redo img", 1, "showed the redo step");
    page.wait(
        "document.querySelectorAll('#history .undo img').length",
        "showed the undo steps",
        |v| v.as_u64().is_some_and(|n| n >= 1),
    );
    page.screenshot("6-undo");

    // 9. Save it as look 1 "Act 1", then go elsewhere and recall it.
    page.eval("document.getElementById('looknum').value = '1'; document.getElementById('looklabel').value = 'Act 1'; true");
    page.click("#save");
    images_loaded(&mut page, "#looks .look img", 1, "showed the saved look");
    let looks = d.call("/vo/looks", vec![], "/vo/looks/end");
    assert_eq!(common::daemon::text(&looks[0].args[1]), "Act 1");
    page.click("#gallery .entry[data-k='1'] .thumb");
    let first = d.candidate(1, 1);
    shows_on_page_and_wire(&mut page, &d, &first, "pick 1");
    page.click("#looks .look[data-n='1']");
    shows_on_page_and_wire(&mut page, &d, &transferred, "recall look 1");
    assert_eq!(d.live(), transferred);
    page.wait(
        "document.getElementById('status')?.textContent ?? ''",
        "showed the status line with the output's health",
        |v| v.as_str().is_some_and(|s| s.contains("fps")),
    );
    page.screenshot("7-recalled");
    assert_eq!(
        page.eval("document.getElementById('error').textContent"),
        ""
    );
}

/// Installed in the page: records every command it posts (`window.sent`: address, args and
/// the answer's body) and how many `/state.json` reads were in flight at once
/// (`window.reads.most`); each read takes 100 ms longer, as over a slow booth network, so
/// events arrive while one is in flight.
const RECORDER: &str = r#"(() => {
  window.sent = [];
  window.reads = { now: 0, most: 0, all: 0 };
  const plain = window.fetch;
  window.fetch = async (url, opts) => {
    if (url === "/osc") {
      const call = JSON.parse(opts.body);
      window.sent.push(call);
      const r = await plain(url, opts);
      call.answer = await r.clone().json().catch(() => null);
      return r;
    }
    if (String(url).startsWith("/state.json")) {
      window.reads.now++; window.reads.all++;
      window.reads.most = Math.max(window.reads.most, window.reads.now);
      try {
        await new Promise((done) => setTimeout(done, 100));
        return await plain(url, opts);
      } finally { window.reads.now--; }
    }
    return plain(url, opts);
  };
  return true;
})()"#;

/// An OSC message as words: `/vo/constraint /vo/group/side/ratio front 0.5`.
fn words(m: &rosc::OscMessage) -> String {
    let mut out = m.addr.clone();
    for a in &m.args {
        out.push(' ');
        out.push_str(&match a {
            rosc::OscType::String(s) => s.clone(),
            rosc::OscType::Float(f) => f.to_string(),
            rosc::OscType::Int(i) => i.to_string(),
            other => format!("{other:?}"),
        });
    }
    out
}

/// The constraints the daemon lists (`/vo/constraints`), as words, without the end.
fn constraints(d: &mut Daemon) -> Vec<String> {
    let mut listed = d.call("/vo/constraints", vec![], "/vo/constraints/end");
    listed.pop();
    listed.iter().map(words).collect()
}

/// Sets the value of the control `selector` names and fires its `change`, as a hand does.
fn change(page: &mut Page, selector: &str, value: &str) {
    let js = format!(
        "(() => {{ const e = document.querySelector({selector:?}); if (!e) return false; e.value = {value:?}; e.dispatchEvent(new Event('change')); return true; }})()"
    );
    assert_eq!(page.eval(&js), true, "no {selector} on the page");
}

/// The channels in a list of JSON numbers.
fn channels(v: &serde_json::Value) -> Vec<i32> {
    v.as_array()
        .expect("a list")
        .iter()
        .map(|c| c.as_i64().expect("a channel") as i32)
        .collect()
}

/// Waits until every command the page posted is answered.
fn answered(page: &mut Page) {
    page.wait(
        "window.sent.every(c => c.answer !== undefined)",
        "had every command answered",
        |v| v == true,
    );
}

/// The commands the page posted since the last call, in the order it sent them, once
/// each is answered; forgets them.
fn sent(page: &mut Page) -> serde_json::Value {
    answered(page);
    page.eval("(() => { const s = window.sent; window.sent = []; return s; })()")
}

/// A mouse drag on the stage, from and to as fractions of its width and height (where
/// the stage is now: the page above it may have changed).
fn stage_drag(page: &mut Page, from: (f64, f64), to: (f64, f64)) {
    let rect = page.eval(
        "(() => { const b = document.getElementById('stage').getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; })()",
    );
    let r: Vec<f64> = serde_json::from_value(rect).expect("rect");
    let at = |(fx, fy): (f64, f64)| (r[0] + r[2] * fx, r[1] + r[3] * fy);
    page.drag(at(from), at(to));
}

/// Shows the page at a width (and height), as a laptop or a tablet does, and saves a
/// screenshot of it.
fn at_width(page: &mut Page, name: &str, width: u32, height: u32, mobile: bool) {
    page.call(
        "Emulation.setDeviceMetricsOverride",
        serde_json::json!({ "width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile }),
    );
    page.wait("window.innerWidth", "took the new width", |v| {
        v.as_u64() == Some(u64::from(width))
    });
    page.screenshot(name);
    let sizes =
        page.eval("[document.documentElement.scrollWidth, document.documentElement.clientWidth]");
    assert!(
        sizes[0].as_u64() <= sizes[1].as_u64(),
        "{name}: the page is wider than the screen (scroll width, width): {sizes}"
    );
}

#[test]
fn constraints_pins_a_transfer_region_and_history_from_the_browser() {
    let Some((mut d, addr, _browser, mut page)) = browse("rules") else {
        return;
    };
    d.add_objective("warm.png", "both");
    d.generate();
    let n = d.gallery().len();
    assert!(n >= 3, "the test needs three entries, got {n}");
    page.wait(
        "typeof st !== 'undefined' && st && st.gallery ? st.gallery.sizes.length : 0",
        "showed the gallery",
        |v| v.as_u64() == Some(n as u64),
    );
    assert_eq!(page.eval(RECORDER), true);

    // 1. Constraints of groups and lights, set on the page and read back from the daemon.
    change(&mut page, "#rules .rule[data-name='side'] .ratio", "0.5");
    change(
        &mut page,
        "#rules .rule[data-name='side'] .ratioof",
        "front",
    );
    change(&mut page, "#rules .rule[data-name='back'] .satmin", "0.2");
    change(&mut page, "#rules .rule[data-name='back'] .satmax", "0.7");
    change(&mut page, "#rules .rule[data-name='front'] .exclude", "off");
    change(&mut page, "#lightrules .rule[data-name='3'] .satmax", "0.9");
    change(
        &mut page,
        "#lightrules .rule[data-name='5'] .exclude",
        "ignore",
    );
    page.wait(
        "JSON.stringify([st.groups.map(g => [g.name, g.ratio, g.saturation, g.exclude]), st.lights.map(l => [l.ch, l.saturation, l.exclude])])",
        "showed the constraints it set",
        |v| {
            v.as_str() == Some(
                r#"[[["front",null,null,"off"],["side",["front",0.5],null,null],["back",null,[0.2,0.7],null]],[[1,null,null],[2,null,null],[3,[0,0.9],null],[4,null,null],[5,null,"ignore"],[6,null,null]]]"#,
            )
        },
    );
    let want = [
        "/vo/constraint /vo/group/front/exclude off",
        "/vo/constraint /vo/group/side/ratio front 0.5",
        "/vo/constraint /vo/group/back/saturation 0.2 0.7",
        "/vo/constraint /vo/light/3/saturation 0 0.9",
        "/vo/constraint /vo/light/5/exclude ignore",
    ];
    assert_eq!(constraints(&mut d), want);
    // The controls show what the daemon holds; a light without colour has no saturation.
    assert_eq!(
        page.eval("document.querySelector(\"#rules .rule[data-name='side'] .ratioof\").value"),
        "front"
    );
    assert_eq!(
        page.eval("document.querySelectorAll(\"#lightrules .rule[data-name='1'] .satmin, #rules .rule[data-name='front'] .satmin\").length"),
        0
    );
    page.eval("document.querySelector('#lightrules').parentElement.open = true; true");
    page.screenshot("rules-1-constraints");
    // A ratio to "nobody" removes it; a refused range (min over max) says why and keeps
    // the old one.
    change(&mut page, "#rules .rule[data-name='side'] .ratioof", "");
    page.wait(
        "st.groups[1].ratio ?? null",
        "showed the ratio removed",
        serde_json::Value::is_null,
    );
    // (Its answer in, so it does not clear the error below.)
    answered(&mut page);
    change(&mut page, "#rules .rule[data-name='back'] .satmin", "0.8");
    page.wait(
        "document.getElementById('error').textContent",
        "said the range is refused",
        |v| v.as_str().is_some_and(|e| e.contains("above max")),
    );
    page.wait(
        "document.querySelector(\"#rules .rule[data-name='back'] .satmin\").value",
        "showed the range the daemon kept",
        |v| v == "0.2",
    );
    assert_eq!(
        constraints(&mut d),
        [want[0], want[2], want[3], want[4]],
        "the ratio is gone, the range kept"
    );
    let posted = sent(&mut page);
    // Changes to one address are sent one after the other, so the order across
    // addresses is the page's to choose: compare them sorted.
    let mut addresses: Vec<&str> = posted
        .as_array()
        .expect("calls")
        .iter()
        .map(|c| c["address"].as_str().expect("address"))
        .collect();
    addresses.sort_unstable();
    assert_eq!(
        addresses,
        [
            "/vo/group/back/saturation",
            "/vo/group/back/saturation",
            "/vo/group/back/saturation",
            "/vo/group/front/exclude",
            "/vo/group/side/ratio",
            "/vo/group/side/ratio",
            "/vo/light/3/saturation",
            "/vo/light/5/exclude",
        ],
        "one command per change: {posted}"
    );

    // 2. A pin drawn on the stage: its lights reported, shown, then removed.
    page.click("#drawmode input[value='pin']");
    stage_drag(&mut page, (0.36, 0.1), (0.64, 0.9));
    let pin = page.wait("st.pins", "showed the pin", |v| {
        v.as_array().is_some_and(|p| p.len() == 1)
    });
    let pinned = channels(&pin[0]["lights"]);
    assert!(!pinned.is_empty(), "{pin}");
    let listed = d.call("/vo/pins", vec![], "/vo/pins/end");
    assert_eq!(listed.len(), 2, "{listed:?}");
    let on_daemon: Vec<i32> = listed[0].args[5..]
        .iter()
        .map(|a| common::daemon::num(a) as i32)
        .collect();
    assert_eq!(on_daemon, pinned);
    for (i, want) in [0.36, 0.1, 0.64, 0.9].iter().enumerate() {
        let x = common::daemon::num(&listed[0].args[1 + i]);
        assert!((x - want).abs() < 0.02, "pin corner {i}: {x} vs {want}");
    }
    let id = pin[0]["id"].as_u64().expect("an id");
    assert_eq!(
        page.eval(&format!(
            "document.querySelector(\"#pins .pinitem[data-id='{id}']\").textContent"
        )),
        format!(
            "pin {id}: lights {} \u{d7}",
            pinned
                .iter()
                .map(i32::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        )
    );
    assert_eq!(
        page.eval(&format!(
            "document.querySelectorAll(\"#stage .pin[data-id='{id}']\").length"
        )),
        1
    );
    page.screenshot("rules-2-pin");
    page.click(&format!("#stage .pin[data-id='{id}'] .unpin"));
    page.wait("st.pins.length", "removed the pin", |v| v == 0);
    assert_eq!(
        page.eval("document.querySelectorAll('#stage .pin, #pins .pinitem').length"),
        0
    );
    let listed = d.call("/vo/pins", vec![], "/vo/pins/end");
    assert_eq!(words(&listed[0]), "/vo/pins/end 0");

    // 3. A transfer region drawn where the pin was, taken from entry 3: its lights are the
    // pin's (the same rule selects them), the others keep the live look.
    assert_eq!(
        page.eval("document.querySelectorAll('#gallery .takeregion:disabled').length"),
        n
    );
    page.click("#drawmode input[value='transfer']");
    stage_drag(&mut page, (0.36, 0.1), (0.64, 0.9));
    let drawn = page.wait("xfer", "kept the transfer region", |v| v.is_array());
    for i in 0..4 {
        let (a, b) = (drawn[i].as_f64(), pin[0]["region"][i].as_f64());
        assert!(
            a.zip(b).is_some_and(|(a, b)| (a - b).abs() < 1e-6),
            "{drawn} vs {pin}"
        );
    }
    page.wait(
        "document.querySelectorAll('#stage .xfer').length",
        "drew the transfer region",
        |v| v == 1,
    );
    let before = d.live();
    let third = d.candidate(3, 1);
    sent(&mut page);
    page.click("#gallery .entry[data-k='3'] .takeregion");
    let taken: Vec<common::daemon::LightLevel> = before
        .iter()
        .zip(&third)
        .map(|(b, c)| {
            if pinned.contains(&b.ch) {
                c.clone()
            } else {
                b.clone()
            }
        })
        .collect();
    shows_on_page_and_wire(&mut page, &d, &taken, "take region");
    assert_eq!(d.live(), taken);
    let posted = sent(&mut page);
    assert_eq!(posted[0]["address"], "/vo/transfer");
    assert_eq!(posted[0]["args"][0], 3);
    assert_eq!(posted[0]["args"][1], "region");
    let reply = &posted[0]["answer"]["replies"][0];
    assert_eq!(reply["address"], "/vo/transferred");
    let mut want = vec![3];
    want.extend(&pinned);
    assert_eq!(channels(&reply["args"]), want);
    page.screenshot("rules-3-transfer");

    // 4. History: two picks, then a tap two steps back is one command and one change, and
    // a tap two steps forward the same.
    let first = d.candidate(1, 1);
    page.click("#gallery .entry[data-k='1'] .thumb");
    shows_on_page_and_wire(&mut page, &d, &first, "pick 1");
    let second = d.candidate(2, 1);
    page.click("#gallery .entry[data-k='2'] .thumb");
    shows_on_page_and_wire(&mut page, &d, &second, "pick 2");
    images_loaded(
        &mut page,
        "#history .undo img",
        3,
        "showed three undo steps",
    );
    sent(&mut page);
    page.click("#history .undo[data-steps='2']");
    shows_on_page_and_wire(&mut page, &d, &taken, "two steps back");
    page.wait(
        "[st.history.undo.length, st.history.redo.length]",
        "showed the history after two steps back",
        |v| *v == serde_json::json!([1, 2]),
    );
    assert_eq!(
        sent(&mut page),
        serde_json::json!([{ "address": "/vo/undo", "args": [2],
            "answer": { "replies": [{ "address": "/vo/undone", "args": [1] }] } }]),
        "one command for two steps"
    );
    images_loaded(&mut page, "#history .redo img", 2, "showed two redo steps");
    page.screenshot("rules-4-history");
    page.click("#history .redo[data-steps='2']");
    shows_on_page_and_wire(&mut page, &d, &second, "two steps forward");
    assert_eq!(
        sent(&mut page),
        serde_json::json!([{ "address": "/vo/redo", "args": [2],
            "answer": { "replies": [{ "address": "/vo/redone", "args": [0] }] } }])
    );
    // A step count the history does not have is refused from the page too: 0 is never a
    // step count (a wrong message), 4 is more than there are (not now).
    let before = d.live();
    for (bad, status) in [(0, 400), (4, 409)] {
        let r = osc(addr, "/vo/undo", serde_json::json!([bad]), &[]);
        assert_eq!(r.status, status, "{}", String::from_utf8_lossy(&r.body));
    }
    assert_eq!(d.live(), before);
    assert_eq!(
        get(addr, "/state.json").json()["history"]["undo"]
            .as_array()
            .map(Vec::len),
        Some(3)
    );

    // 5. A drag of the objective's region (galleries follow it, each an event): the page
    // reads its state one read at a time.
    page.click("#drawmode input[value='objective']");
    let explored = page.eval("st.gallery.serial");
    stage_drag(&mut page, (0.05, 0.05), (0.6, 0.95));
    page.wait("exploring", "ended the drag's explore", |v| v == false);
    page.wait("st.gallery.serial", "showed an explored gallery", |v| {
        *v != explored
    });
    let reads = page.eval("window.reads");
    eprintln!("state reads over the test, with 100 ms added to each: {reads}");
    assert_eq!(reads["most"], 1, "state reads at once: {reads}");
    assert!(reads["all"].as_u64().is_some_and(|n| n > 0), "{reads}");

    // The page on a laptop and on a tablet.
    at_width(&mut page, "rules-laptop", 1366, 900, false);
    at_width(&mut page, "rules-tablet", 820, 1180, true);
    assert_eq!(
        page.eval("document.getElementById('error').textContent"),
        ""
    );
}

#[test]
fn a_tablet_session_by_touch() {
    let Some((mut d, _, _browser, mut page)) = browse("touch") else {
        return;
    };
    // A tablet in portrait: a touch screen, no mouse.
    page.call(
        "Emulation.setDeviceMetricsOverride",
        serde_json::json!({ "width": 820, "height": 1180, "deviceScaleFactor": 1, "mobile": true }),
    );
    page.call(
        "Emulation.setTouchEmulationEnabled",
        serde_json::json!({ "enabled": true, "maxTouchPoints": 5 }),
    );
    page.wait("window.innerWidth", "took the tablet's width", |v| v == 820);
    page.wait(
        "typeof st !== 'undefined' && st ? st.status : ''",
        "showed the daemon's status",
        |v| v.as_str().is_some_and(|s| s.contains("no gallery yet")),
    );

    // Taps are clicks: headless Chromium makes no gestures of DevTools touch input (no
    // click from a tap, no panning), so what is tested by finger is the page's own part,
    // its pointer-event drags.
    page.click("#references .ref[data-name='warm.png']");
    page.wait(
        "document.querySelectorAll('#objectives .objective').length",
        "added warm.png",
        |v| v == 1,
    );
    assert_eq!(d.status().objectives, 1);

    // A finger draws its region on the stage (touch pointer events): the drag explores,
    // and the daemon has the region.
    let stage = page.eval(
        "(() => { const s = document.getElementById('stage'); s.scrollIntoView({ block: 'center' }); const b = s.getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; })()",
    );
    let r: Vec<f64> = serde_json::from_value(stage).expect("rect");
    let at = |fx: f64, fy: f64| (r[0] + r[2] * fx, r[1] + r[3] * fy);
    let path: Vec<(f64, f64)> = (0..=10)
        .map(|i| {
            let f = f64::from(i) / 10.0;
            at(0.2 + 0.4 * f, 0.1 + 0.7 * f)
        })
        .collect();
    page.touch(&path);
    page.wait("exploring", "ended the finger's explore", |v| v == false);
    let listing = d.call("/vo/objectives", vec![], "/vo/objectives/end");
    for (i, want) in [0.2, 0.1, 0.6, 0.8].iter().enumerate() {
        let got = common::daemon::num(&listing[0].args[3 + i]);
        assert!(
            (got - want).abs() < 0.02,
            "x0 y0 x1 y1 {i}: {got} vs {want}"
        );
    }
    page.wait(
        "st.gallery ? st.gallery.sizes.length : 0",
        "showed the gallery the drag explored",
        |v| v.as_u64().is_some_and(|n| n >= 2),
    );
    images_loaded(
        &mut page,
        "#gallery .thumb img",
        d.gallery().len(),
        "showed the gallery",
    );

    // Entry 2 put live: on the page and on the wire.
    page.click("#gallery .entry[data-k='2'] .thumb");
    page.wait("st.entry", "put entry 2 live", |v| v == 2);
    assert_eq!(d.status().entry, 2);
    let live = common::daemon::lights(&d.ok("/vo/live", vec![], "/vo/live").args);
    shows_on_page_and_wire(&mut page, &d, &live, "entry 2 by touch");

    // A pin drawn with a finger, then removed with a finger: the remove button is big
    // enough for one (44 px, the usual touch target).
    page.click("input[name='drawmode'][value='pin']");
    page.wait(
        "document.querySelector(\"input[name='drawmode'][value='pin']\").checked",
        "chose pins",
        |v| v == true,
    );
    let stage = page.eval(
        "(() => { const s = document.getElementById('stage'); s.scrollIntoView({ block: 'center' }); const b = s.getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; })()",
    );
    let r: Vec<f64> = serde_json::from_value(stage).expect("rect");
    let at = |fx: f64, fy: f64| (r[0] + r[2] * fx, r[1] + r[3] * fy);
    page.touch(&[at(0.05, 0.1), at(0.2, 0.4), at(0.45, 0.9)]);
    page.wait("st.pins.length", "added the pin drawn by a finger", |v| {
        v == 1
    });
    let pins = d.call("/vo/pins", vec![], "/vo/pins/end");
    assert_eq!(pins.len(), 2, "one pin and the end: {pins:?}");
    let size = page.eval(
        "(() => { const b = document.querySelector('#stage .pin .unpin').getBoundingClientRect(); return Math.min(b.width, b.height); })()",
    );
    assert!(
        size.as_f64().is_some_and(|s| s >= 44.0),
        "the pin's remove button is {size} px: too small for a finger"
    );
    page.click("#stage .pin .unpin");
    page.wait("st.pins.length", "removed the pin", |v| v == 0);
    assert_eq!(d.call("/vo/pins", vec![], "/vo/pins/end").len(), 1);
    page.screenshot("touch-tablet");
    assert_eq!(
        page.eval("document.getElementById('error').textContent"),
        ""
    );
}

/// Each select of a focus palette in the groups' and lights' tables, in page order: the
/// table, the row's name, its options' text and the one chosen.
const POSITIONS: &str = r#"JSON.stringify([...document.querySelectorAll('#groups tr, #lights tr')].filter(r => r.querySelector('select.position')).map(r => { const s = r.querySelector('select.position'); return [r.closest('table').id, r.dataset.name, [...s.options].map(o => o.textContent), s.value]; }))"#;

/// The palette each select of [`POSITIONS`] shows (group `movers`, then lights 11 and 12;
/// `""` for a group whose movers differ).
fn chosen_palettes() -> String {
    format!("JSON.stringify(JSON.parse({POSITIONS}).map(r => r[3]))")
}

#[test]
fn a_movers_palette_from_the_page_and_from_elsewhere() {
    use crate::daemon_movers::{mover_stage, palette_on_wire};
    let Some(browser) = chromium() else {
        return;
    };
    let stage = mover_stage(&temp_dir("web-movers-stage"));
    let (mut d, addr) = common::http::start_setup(
        "web-movers",
        common::daemon::Setup {
            scene_from: Some(stage),
            ..common::daemon::Setup::default()
        },
    );
    let (_browser, mut page) = open(&browser, &format!("http://{addr}/"), "movers");
    // Each mover lists its palettes by number and name, in its first; the group its movers
    // share; the washes none.
    let listed = page.wait(POSITIONS, "listed the movers' palettes", |v| {
        v.as_str().is_some_and(|s| s.contains("SR"))
    });
    assert_eq!(
        listed,
        r#"[["groups","movers",["1 SL","2 C","3 SR"],"1"],["lights","11",["1 SL","2 C","3 SR"],"1"],["lights","12",["1 SL","2 C","3 SR"],"1"]]"#
    );
    assert_eq!(page.eval(RECORDER), true);

    // Chosen on the page: the same command OSC takes, on the wire and in /vo/live.
    change(&mut page, "#lights tr[data-name='11'] select.position", "3");
    assert_eq!(
        sent(&mut page),
        serde_json::json!([{
            "address": "/vo/light/11/position",
            "args": [3],
            "answer": { "replies": [{ "address": "/vo/light/position", "args": [11, 3] }] },
        }])
    );
    d.wire.wait_both(1, "mover 11 at SR, 12 at SL", |dmx| {
        palette_on_wire(dmx, 0) == Some(3) && palette_on_wire(dmx, 1) == Some(1)
    });
    assert_eq!(d.live_aimed().1, [(11, 3), (12, 1)]);
    // The group's movers are in different palettes now.
    page.wait(&chosen_palettes(), "showed the group mixed", |v| {
        v == r#"["","3","1"]"#
    });

    // Set over OSC, the page follows.
    d.ok(
        "/vo/group/movers/position",
        vec![int(2)],
        "/vo/group/position",
    );
    page.wait(&chosen_palettes(), "followed the group set over OSC", |v| {
        v == r#"["2","2","2"]"#
    });

    // The group's select from the page moves both movers.
    change(
        &mut page,
        "#groups tr[data-name='movers'] select.position",
        "1",
    );
    assert_eq!(
        sent(&mut page),
        serde_json::json!([{
            "address": "/vo/group/movers/position",
            "args": [1],
            "answer": { "replies": [{ "address": "/vo/group/position", "args": ["movers", 1, 2] }] },
        }])
    );
    d.wire.wait_both(1, "both movers at SL", |dmx| {
        palette_on_wire(dmx, 0) == Some(1) && palette_on_wire(dmx, 1) == Some(1)
    });
    assert_eq!(d.live_aimed().1, [(11, 1), (12, 1)]);
    page.wait(&chosen_palettes(), "showed both movers at 1", |v| {
        v == r#"["1","1","1"]"#
    });
    page.screenshot("movers");
}
