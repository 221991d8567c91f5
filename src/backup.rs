//! A backup daemon (docs/reliability.md, "Backup"): `[backup] main = "host:port"` makes
//! this daemon mirror a main over one TCP connection and transmit the same universes all
//! the time at a lower sACN priority, so receivers take its identical look when the main
//! stops (E1.31's priority merge, no home-made cluster).
//!
//! The main side is small: `/vo/backup/subscribe` (src/cmd/backup.rs) registers the
//! connection and answers it with the whole session (`/vo/backup/state`); from then on
//! every command the main accepted is forwarded on it, in the order the session took it
//! (src/engine/backups.rs), and a generate as the gallery it installed
//! (`/vo/backup/gallery`). The backup side is [`follow_main`]: it connects, subscribes, and
//! runs what arrives through the same command path as any sender's message
//! ([`Runner::run_from_main`]).

use std::net::SocketAddr;
use std::time::Duration;

use rosc::{OscMessage, OscPacket};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::cmd::Runner;
use crate::engine::msg;
use crate::osc::args::Request;
use crate::osc::framing::{self, Decoder, Framing, StreamFrame};
use crate::osc::packet::{self, Item};
use crate::osc::{self, Peer};

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
pub async fn follow_main(runner: Runner, main: String) {
    let mut backoff = BACKOFF_MIN;
    let mut last_why = String::new();
    loop {
        let why = match connection(&runner, &main).await {
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
async fn connection(runner: &Runner, main: &str) -> Result<String, String> {
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
                        let runner = runner.clone();
                        // In order: each message is applied before the next is read.
                        let _ = tokio::task::spawn_blocking(move || apply(&runner, at, m)).await;
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
fn apply(runner: &Runner, main: SocketAddr, m: OscMessage) {
    match m.addr.as_str() {
        "/vo/pong" => return,
        osc::ERROR => {
            tracing::warn!("backup: the main answered an error: {:?}", m.args);
            return;
        }
        _ => {}
    }
    let (peer, _replies) = Peer::capture(main);
    let req = Request::new(m);
    if let Err(e) = runner.run_from_main(&req, &peer) {
        tracing::error!(
            "backup: {} from the main failed here: {e}; this backup may differ from the main until it re-syncs",
            req.addr
        );
    }
}
