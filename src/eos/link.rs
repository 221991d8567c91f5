//! One OSC TCP connection to an Eos console (OSC 1.0 length-prefixed or 1.1 SLIP
//! framing), with blocking sockets and a deadline on every read, so a console that stops
//! answering is an error, never a hang. The live import (`visobjd import eos://`) and the
//! record confirmation both talk to Eos through it.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use rosc::{OscMessage, OscPacket, OscType};
use visobjd_rig::eos::Arg;

use crate::osc::framing::{self, Decoder, Framing, StreamFrame};
use crate::osc::packet;

/// A connection to the console.
pub struct Link {
    to: SocketAddr,
    stream: TcpStream,
    framing: Framing,
    decoder: Decoder,
    /// Messages decoded and not yet taken.
    queue: VecDeque<OscMessage>,
}

impl Link {
    /// Connects within `timeout`; writes may take as long.
    pub fn connect(to: SocketAddr, framing: Framing, timeout: Duration) -> Result<Link, String> {
        let stream = TcpStream::connect_timeout(&to, timeout)
            .map_err(|e| format!("cannot connect to Eos at {to}: {e}"))?;
        stream
            .set_write_timeout(Some(timeout))
            .map_err(|e| format!("Eos at {to}: cannot set a write timeout: {e}"))?;
        let _ = stream.set_nodelay(true);
        Ok(Link {
            to,
            stream,
            framing,
            decoder: Decoder::with_framing(framing, framing::MAX_FRAME),
            queue: VecDeque::new(),
        })
    }

    /// Sends the messages, each in its own frame, in one write.
    pub fn send(&mut self, messages: &[OscMessage]) -> Result<(), String> {
        let bytes: Vec<u8> = packets(messages)?
            .iter()
            .flat_map(|p| framing::encode(self.framing, p))
            .collect();
        self.stream
            .write_all(&bytes)
            .and_then(|()| self.stream.flush())
            .map_err(|e| format!("Eos at {}: cannot send: {e}", self.to))
    }

    /// The next message the console sends, or None once `deadline` passes without one;
    /// Err when the connection fails or the console closes it.
    pub fn next(&mut self, deadline: Instant) -> Result<Option<OscMessage>, String> {
        let mut buf = [0u8; 8192];
        loop {
            if let Some(m) = self.queue.pop_front() {
                return Ok(Some(m));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.stream
                .set_read_timeout(Some(deadline - now))
                .map_err(|e| format!("Eos at {}: cannot set a read timeout: {e}", self.to))?;
            let n = match self.stream.read(&mut buf) {
                Ok(0) => return Err(format!("Eos at {} closed the connection", self.to)),
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    continue;
                }
                Err(e) => return Err(format!("Eos at {}: {e}", self.to)),
            };
            let mut frames = Vec::new();
            self.decoder.feed(&buf[..n], &mut frames);
            for f in frames {
                match f {
                    StreamFrame::Packet(p) => match packet::decode(&p) {
                        Ok(ms) => self.queue.extend(ms),
                        Err(e) => tracing::debug!("Eos at {}: skipped a packet: {e}", self.to),
                    },
                    StreamFrame::Oversize { len, .. } => {
                        tracing::debug!("Eos at {}: skipped a {len}-byte frame", self.to)
                    }
                }
            }
        }
    }
}

/// Each message as one encoded OSC packet.
pub fn packets(messages: &[OscMessage]) -> Result<Vec<Vec<u8>>, String> {
    messages
        .iter()
        .map(|m| {
            rosc::encoder::encode(&OscPacket::Message(m.clone()))
                .map_err(|e| format!("cannot encode {}: {e}", m.addr))
        })
        .collect()
}

/// An OSC argument as the rig crate's Eos replies take it.
pub fn arg(a: &OscType) -> Arg {
    match a {
        OscType::Int(i) => Arg::Int(i64::from(*i)),
        OscType::Long(i) => Arg::Int(*i),
        OscType::Float(f) => Arg::Float(f64::from(*f)),
        OscType::Double(d) => Arg::Float(*d),
        OscType::String(s) => Arg::Str(s.clone()),
        other => Arg::Str(format!("{other:?}")),
    }
}

impl super::palettes::Exchange for Link {
    fn send(&mut self, messages: &[OscMessage]) -> Result<(), String> {
        Link::send(self, messages)
    }

    fn next(&mut self, deadline: Instant) -> Result<Option<OscMessage>, String> {
        Link::next(self, deadline)
    }
}
