//! One received packet (a datagram or a stream frame) to the messages it carries.
//!
//! Bundles are flattened in order and run at once (time tags are not scheduled, osc.md).
//! The raw bytes are checked for nesting before rosc sees them: rosc decodes bundles
//! recursively and nested arrays drop recursively, so a small hostile packet could otherwise
//! exhaust the stack.

use rosc::{OscMessage, OscPacket};

/// How deep bundles may nest (a bundle of messages is depth 1), and how deep argument
/// arrays may nest inside a message.
pub const MAX_DEPTH: usize = 8;

/// Why a packet carried no messages to handle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PacketError {
    /// Not OSC at all (rosc's reason).
    NotOsc(String),
    /// Bundles or arrays nested deeper than [`MAX_DEPTH`].
    TooDeep,
}

impl std::fmt::Display for PacketError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PacketError::NotOsc(why) => write!(f, "not OSC: {why}"),
            PacketError::TooDeep => {
                write!(f, "bundles or arrays nested deeper than {MAX_DEPTH}")
            }
        }
    }
}

impl std::error::Error for PacketError {}

/// Decodes a packet into its messages, bundles flattened in order.
pub fn decode(bytes: &[u8]) -> Result<Vec<OscMessage>, PacketError> {
    if !within_depth(bytes, 0) {
        return Err(PacketError::TooDeep);
    }
    let (_, packet) =
        rosc::decoder::decode_udp(bytes).map_err(|e| PacketError::NotOsc(e.to_string()))?;
    let mut out = Vec::new();
    flatten(packet, &mut out);
    Ok(out)
}

fn flatten(packet: OscPacket, out: &mut Vec<OscMessage>) {
    match packet {
        OscPacket::Message(m) => out.push(m),
        OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| flatten(p, out)),
    }
}

/// Walks the packet's structure without decoding it: false if bundles (counting from
/// `depth`) or a message's argument arrays nest deeper than [`MAX_DEPTH`]. Malformed
/// structure passes here and is left for rosc to reject.
fn within_depth(bytes: &[u8], depth: usize) -> bool {
    let Some(rest) = bytes.strip_prefix(b"#bundle\0") else {
        return array_depth(bytes) <= MAX_DEPTH;
    };
    if depth >= MAX_DEPTH {
        return false;
    }
    let mut rest = rest.get(8..).unwrap_or_default();
    while let Some((size, tail)) = rest.split_first_chunk::<4>() {
        let size = u32::from_be_bytes(*size) as usize;
        let Some(element) = tail.get(..size) else {
            return true;
        };
        if !within_depth(element, depth + 1) {
            return false;
        }
        rest = &tail[size..];
    }
    true
}

/// The deepest `[` nesting in a message's type tag string (0 if it has none or is not a
/// message).
fn array_depth(message: &[u8]) -> usize {
    let padded = |s: &[u8]| s.iter().position(|&b| b == 0).map(|n| (n + 4) & !3);
    let Some(addr_len) = padded(message) else {
        return 0;
    };
    let tags = message.get(addr_len..).unwrap_or_default();
    let tags = &tags[..tags.iter().position(|&b| b == 0).unwrap_or(tags.len())];
    let (mut depth, mut deepest) = (0usize, 0usize);
    for &t in tags {
        match t {
            b'[' => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    deepest
}

#[cfg(test)]
mod tests {
    use super::*;
    use rosc::{OscArray, OscBundle, OscTime, OscType};

    fn msg(addr: &str) -> OscPacket {
        OscPacket::Message(OscMessage {
            addr: addr.into(),
            args: vec![OscType::Int(1)],
        })
    }

    fn nest(levels: usize) -> OscPacket {
        (0..levels).fold(msg("/deep"), |inner, _| {
            OscPacket::Bundle(OscBundle {
                timetag: OscTime::from((0, 1)),
                content: vec![inner],
            })
        })
    }

    fn bytes(p: &OscPacket) -> Vec<u8> {
        rosc::encoder::encode(p).unwrap()
    }

    #[test]
    fn bundles_flatten_in_order() {
        let p = OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content: vec![msg("/a"), nest(2), msg("/b")],
        });
        let addrs: Vec<String> = decode(&bytes(&p))
            .unwrap()
            .into_iter()
            .map(|m| m.addr)
            .collect();
        assert_eq!(addrs, ["/a", "/deep", "/b"]);
    }

    #[test]
    fn nesting_is_bounded() {
        assert_eq!(decode(&bytes(&nest(MAX_DEPTH))).unwrap().len(), 1);
        assert_eq!(
            decode(&bytes(&nest(MAX_DEPTH + 1))),
            Err(PacketError::TooDeep)
        );
        let array = (0..MAX_DEPTH + 1).fold(vec![OscType::Int(1)], |inner, _| {
            vec![OscType::Array(OscArray { content: inner })]
        });
        let m = OscPacket::Message(OscMessage {
            addr: "/a".into(),
            args: array,
        });
        assert_eq!(decode(&bytes(&m)), Err(PacketError::TooDeep));
    }

    #[test]
    fn garbage_is_not_osc() {
        for junk in [&b"hello world"[..], b"", b"#bundle\0\0\0", b"/a\0\0,q\0\0"] {
            assert!(
                matches!(decode(junk), Err(PacketError::NotOsc(_))),
                "{junk:?}"
            );
        }
    }
}
