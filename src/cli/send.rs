//! `visobjd send`: a small OSC client for trying the daemon from a shell, and for tests.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs, UdpSocket};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rosc::{OscMessage, OscPacket, OscType};

use crate::osc::framing::{self, Decoder, Framing, StreamFrame};
use crate::osc::packet;

/// Arguments of `send`.
#[derive(clap::Args)]
pub struct Args {
    /// Where to send: HOST:PORT.
    #[arg(long, default_value = "127.0.0.1:8000")]
    to: String,
    /// Send over TCP (length-prefixed, OSC 1.0) instead of UDP.
    #[arg(long)]
    tcp: bool,
    /// Send over TCP framed with SLIP (OSC 1.1) instead of a length prefix (implies --tcp).
    #[arg(long)]
    slip: bool,
    /// Seconds to wait for replies (each is printed as one line).
    #[arg(long, default_value_t = 1.0)]
    wait: f64,
    /// Send every argument as a string (otherwise: int32, else int64 (an OSC `h`, such as a
    /// 64-bit seed), else float, else string).
    #[arg(short = 's', long = "strings")]
    strings: bool,
    /// The OSC address, e.g. /vo/ping.
    address: String,
    /// Arguments, typed by their spelling.
    #[arg(allow_hyphen_values = true, trailing_var_arg = true)]
    args: Vec<String>,
}

/// Runs `send`: sends one message and prints the replies that arrive within `--wait`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.address.starts_with('/') {
        bail!(
            "`{}` is not an OSC address: it must start with /",
            args.address
        );
    }
    if !(args.wait.is_finite() && (0.0..=3600.0).contains(&args.wait)) {
        bail!("--wait must be 0..=3600 seconds, got {}", args.wait);
    }
    let msg = OscMessage {
        addr: args.address.clone(),
        args: args.args.iter().map(|a| typed(a, args.strings)).collect(),
    };
    let bytes = rosc::encoder::encode(&OscPacket::Message(msg))
        .with_context(|| format!("cannot encode {}", args.address))?;
    let to = resolve(&args.to)?;
    let wait = Duration::from_secs_f64(args.wait);
    let mut out = std::io::stdout().lock();
    let mut replies = 0usize;
    let mut print = |m: OscMessage| {
        replies += 1;
        writeln!(out, "{}", format_message(&m))
    };
    if args.tcp || args.slip {
        let framing = if args.slip {
            Framing::Slip
        } else {
            Framing::LengthPrefix
        };
        let mut stream = TcpStream::connect_timeout(&to, Duration::from_secs(5))
            .with_context(|| format!("cannot connect to {to} over TCP"))?;
        stream
            .write_all(&framing::encode(framing, &bytes))
            .with_context(|| format!("cannot send to {to} over TCP"))?;
        let deadline = Instant::now() + wait;
        let mut decoder = Decoder::default();
        let mut buf = [0u8; 8192];
        let mut frames = Vec::new();
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
                break;
            }
            let n = match stream.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => n,
            };
            decoder.feed(&buf[..n], &mut frames);
            for frame in frames.drain(..) {
                let StreamFrame::Packet(frame) = frame else {
                    anyhow::bail!("reply from {to}: a frame over the size limit");
                };
                for m in packet::decode(&frame).unwrap_or_default() {
                    print(m)?;
                }
            }
        }
    } else {
        let local: SocketAddr = if to.is_ipv4() {
            ([0, 0, 0, 0], 0).into()
        } else {
            (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
        };
        let socket = UdpSocket::bind(local).context("cannot open a UDP socket")?;
        socket
            .send_to(&bytes, to)
            .with_context(|| format!("cannot send to {to}"))?;
        let deadline = Instant::now() + wait;
        let mut buf = vec![0u8; 65536];
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            if left.is_zero() || socket.set_read_timeout(Some(left)).is_err() {
                break;
            }
            let n = match socket.recv_from(&mut buf) {
                Ok((n, _)) => n,
                // A timeout, or an ICMP "port unreachable" reported on a later receive:
                // the message went, nothing came back.
                Err(_) => break,
            };
            for m in packet::decode(&buf[..n]).unwrap_or_default() {
                print(m)?;
            }
        }
    }
    if replies == 0 && !wait.is_zero() {
        let hint = if args.tcp || args.slip {
            "is visobjd listening there (osc.tcp), and is this machine in its osc.allow?"
        } else {
            "is visobjd listening there (osc.udp), and is this machine in its osc.allow? With \
             osc.reply_port set, replies go to that port instead of this one: send with --tcp \
             to get them on the connection"
        };
        bail!(
            "no reply from {to} within {} s: {hint} (--wait gives more time)",
            args.wait
        );
    }
    Ok(())
}

/// An argument typed by its spelling: int if it is an int32, int64 if it is a larger
/// whole number, float if it is a finite float32, else a string (always a string with
/// `-s`).
fn typed(arg: &str, strings: bool) -> OscType {
    if strings {
        return OscType::String(arg.into());
    }
    if let Ok(i) = arg.parse::<i32>() {
        return OscType::Int(i);
    }
    if let Ok(i) = arg.parse::<i64>() {
        return OscType::Long(i);
    }
    match arg.parse::<f32>() {
        Ok(f) if f.is_finite() => OscType::Float(f),
        _ => OscType::String(arg.into()),
    }
}

fn resolve(to: &str) -> anyhow::Result<SocketAddr> {
    to.to_socket_addrs()
        .with_context(|| format!("--to `{to}` is not a HOST:PORT"))?
        .next()
        .with_context(|| format!("--to `{to}`: the host has no address"))
}

/// One reply as one line: the address, then each argument (strings quoted only when they
/// hold whitespace or are empty).
fn format_message(m: &OscMessage) -> String {
    let mut line = m.addr.clone();
    for a in &m.args {
        line.push(' ');
        line.push_str(&format_arg(a));
    }
    line
}

fn format_arg(a: &OscType) -> String {
    match a {
        OscType::Int(i) => i.to_string(),
        OscType::Long(i) => i.to_string(),
        OscType::Float(f) => f.to_string(),
        OscType::Double(d) => d.to_string(),
        OscType::String(s) if s.is_empty() || s.chars().any(char::is_whitespace) => {
            format!("{s:?}")
        }
        OscType::String(s) => s.clone(),
        OscType::Bool(b) => b.to_string(),
        OscType::Char(c) => c.to_string(),
        OscType::Nil => "nil".into(),
        OscType::Inf => "inf".into(),
        OscType::Blob(b) => format!("blob({} bytes)", b.len()),
        OscType::Time(t) => format!("time({}.{})", t.seconds, t.fractional),
        OscType::Color(c) => format!("#{:02x}{:02x}{:02x}{:02x}", c.red, c.green, c.blue, c.alpha),
        OscType::Midi(m) => format!("midi({} {} {} {})", m.port, m.status, m.data1, m.data2),
        OscType::Array(arr) => format!(
            "[{}]",
            arr.content
                .iter()
                .map(format_arg)
                .collect::<Vec<_>>()
                .join(" ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arguments_are_typed_by_spelling() {
        assert_eq!(typed("3", false), OscType::Int(3));
        assert_eq!(typed("-1.5", false), OscType::Float(-1.5));
        assert_eq!(typed("1e3", false), OscType::Float(1000.0));
        assert_eq!(typed("inf", false), OscType::String("inf".into()));
        assert_eq!(typed("fast", false), OscType::String("fast".into()));
        assert_eq!(typed("3", true), OscType::String("3".into()));
        assert_eq!(typed("99999999999", false), OscType::Long(99_999_999_999));
        assert_eq!(typed("1e20", false), OscType::Float(1e20));
    }

    #[test]
    fn replies_print_as_one_line() {
        let m = OscMessage {
            addr: crate::osc::ERROR.into(),
            args: vec![
                OscType::String("/vo/pick".into()),
                OscType::String("no gallery yet".into()),
                OscType::Int(3),
                OscType::Float(0.5),
                OscType::String("x".into()),
            ],
        };
        assert_eq!(
            format_message(&m),
            "/vo/error /vo/pick \"no gallery yet\" 3 0.5 x"
        );
    }
}
