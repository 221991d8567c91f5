//! A backup daemon (docs/reliability.md, "Backup"): `[backup] main = "host:port"` makes
//! this daemon mirror a main over one TCP connection and transmit the same universes all
//! the time at a lower sACN priority, so receivers take its identical look when the main
//! stops (E1.31's priority merge, no home-made cluster).
//!
//! The main side is small: `/vo/backup/subscribe` (src/cmd/backup.rs) registers the
//! connection and answers it with the whole session (`/vo/backup/state`); from then on
//! every command the main accepted is forwarded on it, in the order the session took it
//! ([`Pending`]), and a generate as the gallery it installed (`/vo/backup/gallery`). The
//! backup side is [`mirror`]: it connects, subscribes, and runs what arrives through the
//! same command path as any sender's message.

use std::cell::RefCell;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use rosc::{OscMessage, OscPacket};
use serde::Deserialize;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::engine::{Engine, msg};
use crate::osc::Peer;
use crate::osc::args::Request;
use crate::osc::framing::{self, Decoder, Framing, StreamFrame};
use crate::osc::packet::{self, Item};
use visobjd_dmx::OutputConfig;

/// The `[backup]` section: present, this daemon is a backup of `main`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackupConfig {
    /// The main's OSC TCP address (`osc.tcp` of its config), `host:port`.
    pub main: String,
    /// The sACN priority every destination sends at; by default each destination's
    /// configured priority minus 10. Always below the configured one.
    pub priority: Option<u8>,
}

/// How far below the configured (the main's) priority a backup sends by default.
const PRIORITY_STEP: u8 = 10;

/// Checks `[backup]` against `[output]` and lowers every sACN destination to the
/// backup's priority. Err is one sentence naming the key.
pub fn configure(backup: &BackupConfig, output: &mut OutputConfig) -> Result<(), String> {
    let main = backup.main.trim();
    let port_ok = main
        .rsplit_once(':')
        .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p != 0));
    if !port_ok {
        return Err(format!(
            "backup.main `{}`: not host:port such as 10.101.0.10:8000 (the main's osc.tcp address)",
            backup.main
        ));
    }
    if !output.artnet.is_empty() {
        return Err("backup: a backup sends no Art-Net (Art-Net has no priority merge, so its ArtDmx would fight the main's); remove the [[output.artnet]] entries".into());
    }
    if output.sacn.is_empty() {
        return Err("backup: a backup takes over through sACN priority; list the main's [[output.sacn]] destinations".into());
    }
    if let Some(p) = backup.priority.filter(|&p| p > 200) {
        return Err(format!("backup.priority: {p} is out of range (0..=200)"));
    }
    for (i, d) in output.sacn.iter_mut().enumerate() {
        let lower = backup
            .priority
            .unwrap_or(d.priority.saturating_sub(PRIORITY_STEP));
        if lower >= d.priority {
            return Err(format!(
                "backup.priority {lower} is not below output.sacn[{i}].priority {}: a backup must send below the main, or it would fight it",
                d.priority
            ));
        }
        d.priority = lower;
    }
    Ok(())
}

thread_local! {
    /// The accepted command being applied on this thread, to forward to the backups.
    static PENDING: RefCell<Option<OscMessage>> = const { RefCell::new(None) };
}

/// The command a handling thread is applying, forwarded to the backups at the moment the
/// session takes it (under its lock, so backups see changes in the main's order), or once
/// it succeeded if no commit took it. Set by `cmd::run` for commands that change state.
pub struct Pending;

impl Pending {
    /// Marks `m` as the command this thread now applies (None: nothing to forward).
    pub fn set(m: Option<OscMessage>) {
        PENDING.with(|p| *p.borrow_mut() = m);
    }

    /// Takes the command to forward, if it was not forwarded yet.
    pub fn take() -> Option<OscMessage> {
        PENDING.with(|p| p.borrow_mut().take())
    }
}

/// The largest frame the backup takes from its main: the state snapshot is one message
/// (objectives with their palettes, saved looks), far above the 64 KiB a client's frame
/// may have. Only the configured main's connection gets this limit.
const STATE_FRAME: usize = 64 * 1024 * 1024;
/// Reconnection backoff: a restarted main is re-joined within a fraction of a second.
const BACKOFF_MIN: Duration = Duration::from_millis(200);
const BACKOFF_MAX: Duration = Duration::from_secs(2);
const CONNECT: Duration = Duration::from_secs(3);
/// A ping this often keeps the main from closing the quiet connection (its idle timeout
/// is 60 s).
const KEEPALIVE: Duration = Duration::from_secs(20);

/// The backup's side: keeps a connection to `main`, subscribes, and applies what the main
/// sends, reconnecting with backoff for ever (the task is aborted at shutdown).
pub async fn mirror(engine: Arc<Engine>, main: String) {
    let mut backoff = BACKOFF_MIN;
    let mut last_why = String::new();
    loop {
        let why = match follow(&engine, &main).await {
            Ok(why) => {
                backoff = BACKOFF_MIN;
                why
            }
            Err(why) => why,
        };
        if why != last_why {
            tracing::warn!("backup: not following the main {main}: {why}; retrying");
            last_why = why;
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(BACKOFF_MAX);
    }
}

/// One connection to the main: Ok(why it ended) once the state arrived, Err before.
async fn follow(engine: &Arc<Engine>, main: &str) -> Result<String, String> {
    let stream = tokio::time::timeout(CONNECT, TcpStream::connect(main))
        .await
        .map_err(|_| format!("no connection within {CONNECT:?}"))?
        .map_err(|e| e.to_string())?;
    let _ = stream.set_nodelay(true);
    let at = stream.peer_addr().map_err(|e| e.to_string())?;
    let (mut rd, mut wr) = stream.into_split();
    let send = |m: OscMessage| {
        rosc::encoder::encode(&OscPacket::Message(m))
            .map(|b| framing::encode(Framing::LengthPrefix, &b))
            .map_err(|e| e.to_string())
    };
    wr.write_all(&send(msg("/vo/backup/subscribe", Vec::new()))?)
        .await
        .map_err(|e| e.to_string())?;
    let mut decoder = Decoder::new(STATE_FRAME);
    let mut frames = Vec::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut keepalive = tokio::time::interval(KEEPALIVE);
    let mut synced = false;
    let ended = loop {
        tokio::select! {
            read = rd.read(&mut buf) => {
                let n = match read {
                    Ok(0) => break "the main closed the connection".to_string(),
                    Ok(n) => n,
                    Err(e) => break e.to_string(),
                };
                decoder.feed(&buf[..n], &mut frames);
                for frame in frames.drain(..) {
                    let bytes = match frame {
                        StreamFrame::Packet(bytes) => bytes,
                        StreamFrame::Oversize { len, .. } => {
                            tracing::error!("backup: a {len}-byte frame from the main is over {STATE_FRAME} bytes; skipped");
                            continue;
                        }
                    };
                    for m in messages(&bytes) {
                        if m.addr == "/vo/backup/state" && !synced {
                            synced = true;
                            tracing::info!("backup: following the main {main}");
                        }
                        let engine = Arc::clone(engine);
                        // In order: each message is applied before the next is read.
                        let _ = tokio::task::spawn_blocking(move || apply(&engine, at, m)).await;
                    }
                }
            }
            _ = keepalive.tick() => {
                if let Err(e) = wr.write_all(&send(msg("/vo/ping", Vec::new()))?).await {
                    break e.to_string();
                }
            }
        }
    };
    if synced { Ok(ended) } else { Err(ended) }
}

/// The messages of a packet (bundles flattened); malformed ones are logged and skipped.
fn messages(bytes: &[u8]) -> Vec<OscMessage> {
    match packet::decode_items(bytes) {
        Ok(items) => items
            .into_iter()
            .filter_map(|item| match item {
                Item::Message(m) => Some(m),
                Item::Malformed { why, .. } => {
                    tracing::error!("backup: a malformed message from the main: {why}");
                    None
                }
            })
            .collect(),
        Err(e) => {
            tracing::error!("backup: a packet from the main is not OSC: {e:?}");
            Vec::new()
        }
    }
}

/// Applies one message from the main through the command path (a generate arrives as the
/// gallery it installed, so nothing here waits for one).
fn apply(engine: &Arc<Engine>, main: SocketAddr, m: OscMessage) {
    match m.addr.as_str() {
        "/vo/pong" => return,
        "/vo/error" => {
            tracing::warn!("backup: the main answered an error: {:?}", m.args);
            return;
        }
        _ => {}
    }
    let (peer, _replies) = Peer::capture(main);
    let req = Request::new(m);
    if let Err(e) = crate::cmd::mirror(engine, &req, &peer) {
        tracing::error!(
            "backup: {} from the main failed here: {e}; this backup may differ from the main until it re-syncs",
            req.addr
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use visobjd_dmx::{ArtnetDest, SacnDest};

    fn output(priorities: &[u8]) -> OutputConfig {
        OutputConfig {
            sacn: priorities
                .iter()
                .map(|&priority| SacnDest {
                    priority,
                    ..SacnDest::default()
                })
                .collect(),
            ..OutputConfig::default()
        }
    }

    fn backup(main: &str, priority: Option<u8>) -> BackupConfig {
        BackupConfig {
            main: main.into(),
            priority,
        }
    }

    #[test]
    fn a_backup_sends_below_each_destination() {
        let mut out = output(&[100, 5]);
        configure(&backup("10.0.0.1:8000", None), &mut out).unwrap();
        assert_eq!(out.sacn[0].priority, 90);
        assert_eq!(out.sacn[1].priority, 0);
        let mut out = output(&[100]);
        configure(&backup("main.local:8000", Some(50)), &mut out).unwrap();
        assert_eq!(out.sacn[0].priority, 50);
    }

    #[test]
    fn bad_backups_are_refused_with_the_key() {
        let e = configure(&backup("10.0.0.1", None), &mut output(&[100])).unwrap_err();
        assert!(e.contains("backup.main"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", Some(100)), &mut output(&[100])).unwrap_err();
        assert!(e.contains("not below output.sacn[0].priority"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", None), &mut output(&[0])).unwrap_err();
        assert!(e.contains("not below"), "{e}");
        let e = configure(&backup("10.0.0.1:8000", None), &mut output(&[])).unwrap_err();
        assert!(e.contains("[[output.sacn]]"), "{e}");
        let mut out = output(&[100]);
        out.artnet.push(ArtnetDest::default());
        let e = configure(&backup("10.0.0.1:8000", None), &mut out).unwrap_err();
        assert!(e.contains("no Art-Net"), "{e}");
    }
}
