//! The drag rows of `visobjd bench` (issue 23): a daemon in this process (the engine, OSC
//! over UDP on loopback, sACN to a local socket) and a client that drags a region as a
//! finger does, `/vo/explore 1`, region updates at [`UPDATES_HZ`], `/vo/explore 0`, while a
//! subscription counts the galleries pushed, another socket pings, and a listener times
//! the DMX packets. A lockstep client (set the region, wait for `/vo/generate`) runs first
//! on the same daemon as the baseline.

use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use rosc::{OscMessage, OscPacket, OscType};

use super::Row;
use crate::cmd::Runner;
use crate::config::Config;
use crate::engine::session::Session;
use crate::engine::{Engine, Loaded};
use crate::osc::Server;
use visobjd_dmx::{Output, Patch};
use visobjd_method::stage::Stage;
use visobjd_scene::look::Look;

/// Region updates a second, as a tablet sends them while a finger moves.
pub const UPDATES_HZ: u32 = 60;
/// Pings during the drag, one this often.
pub const PING_EVERY: Duration = Duration::from_millis(20);
/// How long any single reply may take before the run is called failed.
const PATIENCE: Duration = Duration::from_secs(30);

/// What one drag run measured.
pub struct Drag {
    /// Galleries pushed per second during the drag.
    galleries_s: f64,
    /// Galleries per second of the lockstep client.
    lockstep_s: f64,
    /// Largest interval between universe 1's packets during the drag, ms.
    gap_ms: f64,
    period_ms: f64,
    /// Ping round trips during the drag, ms (sorted).
    pings: Vec<f64>,
    pings_sent: usize,
    updates: usize,
}

impl Drag {
    /// The report's rows for `lights`, against `target` galleries a second.
    pub(super) fn rows(&self, lights: &str, seconds: f64, target: f64) -> Vec<Row> {
        let at = |q: f64| {
            self.pings
                .get(((self.pings.len() as f64 * q) as usize).min(self.pings.len().max(1) - 1))
                .copied()
                .unwrap_or(f64::NAN)
        };
        vec![
            Row {
                name: format!(
                    "drag, {lights} lights: galleries pushed, {UPDATES_HZ} regions/s for {seconds} s"
                ),
                value: self.galleries_s,
                unit: "/s",
                ratio: self.galleries_s / target,
                target: Some(1.0),
                more: true,
                note: format!(
                    "lockstep client {:.1}/s (x{:.2}); {} updates sent",
                    self.lockstep_s,
                    self.galleries_s / self.lockstep_s,
                    self.updates
                ),
            },
            Row::at_most(
                format!(
                    "  DMX largest gap during the drag (two periods: {:.2} ms)",
                    2.0 * self.period_ms
                ),
                self.gap_ms,
                "ms",
                2.0 * self.period_ms,
            ),
            Row {
                name: format!(
                    "  ping round trip during the drag, p99 (against one update, {:.1} ms)",
                    1000.0 / f64::from(UPDATES_HZ)
                ),
                value: at(0.99),
                unit: "ms",
                ratio: at(0.99) * f64::from(UPDATES_HZ) / 1000.0,
                target: None,
                more: false,
                note: format!(
                    "p50 {:.2} ms, {} of {} answered",
                    at(0.5),
                    self.pings.len(),
                    self.pings_sent
                ),
            },
        ]
    }
}

/// An OSC message packet, encoded.
fn packet(addr: &str, args: Vec<OscType>) -> anyhow::Result<Vec<u8>> {
    Ok(rosc::encoder::encode(&OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    }))?)
}

/// The messages of a datagram (bundles flattened).
fn messages(bytes: &[u8]) -> Vec<OscMessage> {
    fn flatten(p: OscPacket, out: &mut Vec<OscMessage>) {
        match p {
            OscPacket::Message(m) => out.push(m),
            OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| flatten(p, out)),
        }
    }
    let mut out = Vec::new();
    if let Ok((_, p)) = rosc::decoder::decode_udp(bytes) {
        flatten(p, &mut out);
    }
    out
}

/// A client socket connected to the daemon.
struct Client(UdpSocket);

impl Client {
    fn new(to: SocketAddr) -> anyhow::Result<Client> {
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.connect(to)?;
        Ok(Client(sock))
    }

    fn port(&self) -> anyhow::Result<u16> {
        Ok(self.0.local_addr()?.port())
    }

    fn send(&self, addr: &str, args: Vec<OscType>) -> anyhow::Result<()> {
        self.0.send(&packet(addr, args)?)?;
        Ok(())
    }

    /// Waits for `reply` (other messages are skipped); a `/vo/error` is the run's failure.
    fn wait(&self, reply: &str, what: &str) -> anyhow::Result<OscMessage> {
        let end = Instant::now() + PATIENCE;
        let mut buf = vec![0u8; 65536];
        loop {
            let left = end
                .checked_duration_since(Instant::now())
                .with_context(|| format!("no {reply} for {what} within {PATIENCE:?}"))?;
            self.0.set_read_timeout(Some(left))?;
            let Ok(n) = self.0.recv(&mut buf) else {
                continue;
            };
            for m in messages(&buf[..n]) {
                if m.addr == reply {
                    return Ok(m);
                }
                anyhow::ensure!(m.addr != crate::osc::ERROR, "{what}: {:?}", m.args);
            }
        }
    }

    fn call(&self, addr: &str, args: Vec<OscType>, reply: &str) -> anyhow::Result<OscMessage> {
        self.send(addr, args)?;
        self.wait(reply, addr)
    }

    /// Reads and drops whatever arrived.
    fn drain(&self) -> anyhow::Result<()> {
        self.0.set_nonblocking(true)?;
        let mut buf = vec![0u8; 65536];
        while self.0.recv(&mut buf).is_ok() {}
        self.0.set_nonblocking(false)?;
        Ok(())
    }
}

/// The region at `t` seconds into the drag: a half-stage window circling the stage once
/// every two seconds.
fn region(t: f64) -> Vec<OscType> {
    let a = t * std::f64::consts::PI;
    let (x, y) = (0.25 + 0.2 * a.cos(), 0.25 + 0.2 * a.sin());
    [x, y, x + 0.5, y + 0.5]
        .map(|v| OscType::Float(v as f32))
        .into()
}

/// Runs the daemon over `stage` (its folder `scene`, references in `refs`) and the drag.
pub fn run(stage: Arc<Stage>, scene: &Path, refs: &Path, seconds: f64) -> anyhow::Result<Drag> {
    let dir = std::env::temp_dir().join(format!("visobjd-drag-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let dmx = UdpSocket::bind("127.0.0.1:0")?;
    dmx.set_read_timeout(Some(Duration::from_millis(100)))?;
    let abs = |p: &Path| std::path::absolute(p).map(|p| p.display().to_string());
    let text = format!(
        "scene = {:?}\nreferences = {:?}\nstate_dir = {:?}\n[osc]\nudp = \"127.0.0.1:0\"\ntcp = \"\"\n\
         [[output.sacn]]\ndestination = \"127.0.0.1\"\nport = {}\n",
        abs(scene)?,
        abs(refs)?,
        dir.join("state").display().to_string(),
        dmx.local_addr()?.port()
    );
    let config = Config::parse(&dir.join("visobjd.toml"), &text).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&config.state_dir)?;
    let lights = stage.scene.lights.len();
    let output = Output::start(
        &config.output,
        Patch::new(&stage.scene),
        &config.state_dir,
        Look::off(lights),
    )?;
    let period_ms = 1000.0 / f64::from(config.output.rate_hz);
    let session = Session::new(
        &stage.scene,
        config.generate.count,
        config.generate.clusters,
        config.output.fade_s,
    );
    let engine = Arc::new(Engine::new(
        config.clone(),
        Loaded::running(stage),
        output,
        None,
        session,
    )?);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let server = runtime
        .block_on(async { Server::start(&config.osc, Arc::new(Runner::new(Arc::clone(&engine)))) })
        .map_err(anyhow::Error::msg)?;
    if let Some(sender) = server.sender() {
        engine.set_pusher(sender);
    }
    let to = server
        .udp_addr()
        .context("the bench daemon has no UDP address")?;
    let measured = drive(to, &dmx, refs, seconds, period_ms);
    runtime.block_on(server.stop());
    crate::shutdown::finish(&engine);
    let _ = std::fs::remove_dir_all(&dir);
    measured
}

/// The client's side: an objective, the lockstep baseline, then the drag.
fn drive(
    to: SocketAddr,
    dmx: &UdpSocket,
    refs: &Path,
    seconds: f64,
    period_ms: f64,
) -> anyhow::Result<Drag> {
    let hand = Client::new(to)?;
    let listen = Client::new(to)?;
    let pinger = Client::new(to)?;
    let image = crate::touchosc::reference_images(refs)?
        .into_iter()
        .next()
        .context("no reference image")?;
    hand.call(
        "/vo/objective/add",
        vec![OscType::String(image)],
        "/vo/objective/added",
    )?;
    hand.call(
        "/vo/subscribe",
        vec![OscType::Int(i32::from(listen.port()?))],
        "/vo/subscribed",
    )?;

    // Baseline: a client that sets the region and waits for each generate.
    let started = Instant::now();
    let mut lockstep = 0;
    while started.elapsed().as_secs_f64() < seconds.min(3.0) {
        let t = started.elapsed().as_secs_f64();
        hand.call("/vo/objective/1/region", region(t), "/vo/objective/region")?;
        hand.call("/vo/generate", Vec::new(), "/vo/generated")?;
        lockstep += 1;
    }
    let lockstep_s = f64::from(lockstep) / started.elapsed().as_secs_f64();
    listen.drain()?;

    let stop = AtomicBool::new(false);
    std::thread::scope(|s| -> anyhow::Result<Drag> {
        let arrivals = s.spawn(|| dmx_arrivals(dmx, &stop));
        let pushes = s.spawn(|| {
            let mut buf = vec![0u8; 65536];
            let mut generated = Vec::new();
            let _ = listen.0.set_read_timeout(Some(Duration::from_millis(50)));
            while !stop.load(Ordering::Relaxed) {
                if let Ok(n) = listen.0.recv(&mut buf) {
                    let at = Instant::now();
                    let count = messages(&buf[..n])
                        .iter()
                        .filter(|m| m.addr == "/vo/generated")
                        .count();
                    generated.extend(std::iter::repeat_n(at, count));
                }
            }
            generated
        });
        let pings = s.spawn(|| ping(&pinger, &stop));

        hand.call("/vo/explore", vec![OscType::Int(1)], "/vo/explore")?;
        let began = Instant::now();
        let mut updates = 0;
        let every = Duration::from_secs_f64(1.0 / f64::from(UPDATES_HZ));
        while began.elapsed().as_secs_f64() < seconds {
            hand.send(
                "/vo/objective/1/region",
                region(began.elapsed().as_secs_f64()),
            )?;
            updates += 1;
            hand.drain()?;
            let next = began + every * updates;
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
        }
        hand.call("/vo/explore", vec![OscType::Int(0)], "/vo/explore")?;
        let ended = Instant::now();
        stop.store(true, Ordering::Relaxed);
        let join = |e| anyhow::anyhow!("a bench thread panicked: {e:?}");
        let arrivals = arrivals.join().map_err(join)?;
        let generated = pushes.join().map_err(join)?;
        let (mut pings, pings_sent) = pings.join().map_err(join)?;
        pings.sort_by(f64::total_cmp);
        let gap_ms = arrivals
            .windows(2)
            .filter(|w| w[1] >= began && w[0] <= ended)
            .map(|w| (w[1] - w[0]).as_secs_f64() * 1000.0)
            .fold(0.0, f64::max);
        let galleries = generated
            .iter()
            .filter(|&&t| t >= began && t <= ended)
            .count();
        Ok(Drag {
            galleries_s: galleries as f64 / (ended - began).as_secs_f64(),
            lockstep_s,
            gap_ms,
            period_ms,
            pings,
            pings_sent,
            updates: updates as usize,
        })
    })
}

/// Kernel receive times of universe 1's sACN packets until `stop`.
fn dmx_arrivals(dmx: &UdpSocket, stop: &AtomicBool) -> Vec<Instant> {
    let mut buf = [0u8; 1024];
    let mut arrivals = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        if let Ok(n) = dmx.recv(&mut buf)
            // E1.31 data packets carry the universe at bytes 113..115.
            && n > 115
            && u16::from_be_bytes([buf[113], buf[114]]) == 1
        {
            arrivals.push(visobjd_dmx::kernel_arrival(dmx, Instant::now()));
        }
    }
    arrivals
}

/// Pings every [`PING_EVERY`] until `stop`: the round trips answered (ms) and pings sent.
fn ping(pinger: &Client, stop: &AtomicBool) -> (Vec<f64>, usize) {
    let mut rtts = Vec::new();
    let mut sent = 0;
    let mut buf = vec![0u8; 1024];
    let _ = pinger.0.set_read_timeout(Some(Duration::from_secs(1)));
    while !stop.load(Ordering::Relaxed) {
        let at = Instant::now();
        sent += 1;
        if pinger.send("/vo/ping", vec![OscType::Int(sent)]).is_err() {
            continue;
        }
        // Its own pong: a late one of an earlier ping is skipped.
        while let Ok(n) = pinger.0.recv(&mut buf) {
            if messages(&buf[..n])
                .iter()
                .any(|m| m.addr == "/vo/pong" && m.args == [OscType::Int(sent)])
            {
                rtts.push(at.elapsed().as_secs_f64() * 1000.0);
                break;
            }
        }
        std::thread::sleep(PING_EVERY.saturating_sub(at.elapsed()));
    }
    (rtts, sent as usize)
}
