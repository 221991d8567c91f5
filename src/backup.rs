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
//!
//! A backup never applies its main's commands to a session that is not the main's: when it
//! cannot take something the main sent (a frame over the largest state a main of its scene
//! can send, a state that does not restore, a malformed packet, a command that fails here
//! or comes before the state), it ends the connection and subscribes again, for a whole
//! state. Why is logged once for as long as it repeats and shown in `/vo/status` until it
//! follows again, and the subscriptions back off while the same reason repeats.

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

/// Reconnection backoff: a restarted main is re-joined within a fraction of a second.
const BACKOFF_MIN: Duration = Duration::from_millis(200);
/// The longest wait after the connection was lost (the main is down, the network).
const BACKOFF_LOST: Duration = Duration::from_secs(2);
/// The longest wait after this backup could not take what its main sent, while the same
/// reason repeats: a main that sends the same thing again is not asked every 0.2 s.
const BACKOFF_REFUSED: Duration = Duration::from_secs(10);
const CONNECT: Duration = Duration::from_secs(3);
/// A ping this often keeps the main from closing the quiet connection (its idle timeout
/// is 60 s).
const KEEPALIVE: Duration = Duration::from_secs(20);

/// Why a connection to the main ended.
#[derive(Debug, Clone, PartialEq)]
enum End {
    /// The connection went: refused, timed out, closed, an I/O error.
    Lost(String),
    /// This backup could not take something the main sent, so it subscribes again for a
    /// whole state rather than apply later commands to a session that differs: `what` it
    /// was (the same thing again, whatever its details, is the same reason) and why.
    Refused { what: String, why: String },
}

impl End {
    fn refused(what: impl Into<String>, why: String) -> End {
        End::Refused {
            what: what.into(),
            why,
        }
    }

    fn why(&self) -> &str {
        match self {
            End::Lost(why) | End::Refused { why, .. } => why,
        }
    }

    /// Whether `other` ended the connection for the same reason.
    fn same_reason(&self, other: &End) -> bool {
        match (self, other) {
            (End::Lost(a), End::Lost(b)) => a == b,
            (End::Refused { what: a, .. }, End::Refused { what: b, .. }) => a == b,
            _ => false,
        }
    }
}

/// The backup's side: keeps a connection to `main`, subscribes, and applies what the main
/// sends, subscribing again with backoff for ever (the task is aborted at shutdown).
pub async fn follow_main(runner: Runner, main: String) {
    let engine = std::sync::Arc::clone(runner.engine());
    let mut backoff = BACKOFF_MIN;
    let mut last: Option<End> = None;
    loop {
        let (synced, end) = connection(&runner, &main).await;
        let repeated = last.as_ref().is_some_and(|l| l.same_reason(&end));
        let max = match &end {
            End::Lost(_) => BACKOFF_LOST,
            End::Refused { .. } => BACKOFF_REFUSED,
        };
        // A new reason starts the backoff again, and so does a connection lost after it
        // followed (a main restarted); the same refusal again keeps doubling it.
        if !repeated || (synced && matches!(end, End::Lost(_))) {
            backoff = BACKOFF_MIN;
        }
        if !repeated {
            match &end {
                End::Lost(why) => {
                    tracing::warn!("backup: not following the main {main}: {why}; retrying")
                }
                End::Refused { why, .. } => tracing::error!(
                    "backup: not following the main {main}: {why}; subscribing again for its whole state (this message is not repeated while the reason stays the same)"
                ),
            }
        }
        let problem = format!(
            "backup: not following the main {main}: {}; subscribing again",
            end.why()
        );
        set_problem(&engine, Some(problem)).await;
        last = Some(end);
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(max);
    }
}

/// Records why this backup is not following (None: it follows), off the async threads
/// (subscribers are told under the session's lock).
async fn set_problem(engine: &std::sync::Arc<crate::engine::Engine>, problem: Option<String>) {
    let engine = std::sync::Arc::clone(engine);
    let _ = tokio::task::spawn_blocking(move || engine.set_backup_problem(problem)).await;
}

/// One connection to the main: whether its state was taken, and why the connection ended.
async fn connection(runner: &Runner, main: &str) -> (bool, End) {
    let mut synced = false;
    let end = follow(runner, main, &mut synced).await;
    (synced, end)
}

/// Connects, subscribes and applies what the main sends until something ends it;
/// `synced` is set once the main's state is taken.
async fn follow(runner: &Runner, main: &str, synced: &mut bool) -> End {
    let lost = |e: std::io::Error| End::Lost(e.to_string());
    let stream = match tokio::time::timeout(CONNECT, TcpStream::connect(main)).await {
        Err(_) => return End::Lost(format!("no connection within {CONNECT:?}")),
        Ok(Err(e)) => return lost(e),
        Ok(Ok(stream)) => stream,
    };
    let _ = stream.set_nodelay(true);
    let at = match stream.peer_addr() {
        Ok(at) => at,
        Err(e) => return lost(e),
    };
    let (mut rd, mut wr) = stream.into_split();
    let send = |m: OscMessage| match rosc::encoder::encode(&OscPacket::Message(m)) {
        Ok(b) => Ok(framing::encode(Framing::LengthPrefix, &b)),
        Err(e) => Err(End::Lost(format!("cannot encode a message: {e}"))),
    };
    let subscribe = match send(msg("/vo/backup/subscribe", Vec::new())) {
        Ok(b) => b,
        Err(end) => return end,
    };
    if let Err(e) = wr.write_all(&subscribe).await {
        return lost(e);
    }
    let limit = runner.engine().backup_frame_limit();
    let mut decoder = Decoder::new(limit);
    let mut frames = Vec::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut keepalive = tokio::time::interval(KEEPALIVE);
    let mut answered_error = false;
    loop {
        tokio::select! {
            read = rd.read(&mut buf) => {
                let n = match read {
                    Ok(0) => return End::Lost("the main closed the connection".to_string()),
                    Ok(n) => n,
                    Err(e) => return lost(e),
                };
                decoder.feed(&buf[..n], &mut frames);
                for frame in frames.drain(..) {
                    let bytes = match frame {
                        StreamFrame::Packet(bytes) => bytes,
                        StreamFrame::Oversize { len, head } => {
                            return End::refused("an oversize frame", format!(
                                "a {len}-byte {} from the main is over the {limit} bytes of the largest state a main of this backup's scene can send (is the main's scene this one? its saved looks from a larger rig?)",
                                address(&head).unwrap_or("frame")
                            ));
                        }
                    };
                    let msgs = match messages(&bytes) {
                        Ok(msgs) => msgs,
                        Err(why) => return End::refused("a malformed packet", why),
                    };
                    for m in msgs {
                        match m.addr.as_str() {
                            "/vo/pong" => continue,
                            osc::ERROR if !*synced => {
                                return End::refused("the subscription", format!(
                                    "the main refused the subscription: {}",
                                    sentence(&m)
                                ));
                            }
                            osc::ERROR => {
                                if !std::mem::replace(&mut answered_error, true) {
                                    tracing::warn!("backup: the main answered an error: {}", sentence(&m));
                                }
                                continue;
                            }
                            "/vo/backup/state" => {}
                            addr if !*synced => {
                                return End::refused("a command before the state", format!("the main sent {addr} before its state"));
                            }
                            _ => {}
                        }
                        let is_state = m.addr == "/vo/backup/state";
                        let addr = m.addr.clone();
                        let on = runner.clone();
                        // In order: each message is applied before the next is read.
                        let applied = tokio::task::spawn_blocking(move || apply(&on, at, m))
                            .await
                            .unwrap_or_else(|e| Err(format!("it panicked ({e})")));
                        match applied {
                            Err(why) if is_state => {
                                return End::refused("the state", format!("its state could not be taken here: {why}"));
                            }
                            Err(why) => {
                                return End::refused(addr.clone(), format!("{addr} from the main failed here: {why}"));
                            }
                            Ok(()) if is_state => {
                                *synced = true;
                                set_problem(runner.engine(), None).await;
                                tracing::info!("backup: following the main {main}");
                            }
                            Ok(()) => {}
                        }
                    }
                }
            }
            _ = keepalive.tick() => {
                let ping = match send(msg("/vo/ping", Vec::new())) {
                    Ok(b) => b,
                    Err(end) => return end,
                };
                if let Err(e) = wr.write_all(&ping).await {
                    return lost(e);
                }
            }
        }
    }
}

/// The address an oversize frame's first bytes name, if they hold one.
fn address(head: &[u8]) -> Option<&str> {
    let end = head.iter().position(|&b| b == 0)?;
    std::str::from_utf8(&head[..end])
        .ok()
        .filter(|a| a.starts_with('/'))
}

/// An `/vo/error`'s sentence (its second argument), or its arguments as they are.
fn sentence(m: &OscMessage) -> String {
    match m.args.get(1) {
        Some(rosc::OscType::String(s)) => s.clone(),
        _ => format!("{:?}", m.args),
    }
}

/// The messages of a packet (bundles flattened); Err, naming it, when the packet or a
/// message in it is malformed: a command this backup cannot read is one it would miss.
fn messages(bytes: &[u8]) -> Result<Vec<OscMessage>, String> {
    let items = packet::decode_items(bytes).map_err(|e| {
        format!(
            "a {}-byte packet from the main is not OSC: {e:?}",
            bytes.len()
        )
    })?;
    items
        .into_iter()
        .map(|item| match item {
            Item::Message(m) => Ok(m),
            Item::Malformed { addr, why } => {
                Err(format!("a malformed {addr} from the main: {why}"))
            }
        })
        .collect()
}

/// Applies one message from the main through the command path (a generate arrives as the
/// gallery it installed, so nothing here waits for one); Err is why it failed here.
fn apply(runner: &Runner, main: SocketAddr, m: OscMessage) -> Result<(), String> {
    let (peer, _replies) = Peer::capture(main);
    let req = Request::new(m);
    runner
        .run_from_main(&req, &peer)
        .map(drop)
        .map_err(|e| e.to_string())
}
