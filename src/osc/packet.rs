//! One received packet (a datagram or a stream frame) to the messages it carries.
//!
//! Bundles are flattened in order and run at once (time tags are not scheduled, docs/osc.md).
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

/// One element of a packet, as the server hands it on.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A message that decoded.
    Message(OscMessage),
    /// A message whose address is intact but whose type tags or arguments are not (a
    /// truncated or corrupted packet): it is answered with `/vo/error` naming the address.
    Malformed {
        /// The message's address.
        addr: String,
        /// Why it did not decode.
        why: String,
    },
}

/// Decodes a packet into its messages, bundles flattened in order; malformed elements are
/// left out (for reading replies, where there is no one to tell).
pub fn decode(bytes: &[u8]) -> Result<Vec<OscMessage>, PacketError> {
    Ok(decode_items(bytes)?
        .into_iter()
        .filter_map(|i| match i {
            Item::Message(m) => Some(m),
            Item::Malformed { .. } => None,
        })
        .collect())
}

/// Decodes a packet into its elements, bundles flattened in order. A message whose address
/// reads but whose rest does not is an [`Item::Malformed`]; a bundle keeps the elements
/// that decode (a truncated bundle loses only its tail). A packet with nothing that reads
/// as OSC is [`PacketError::NotOsc`].
pub fn decode_items(bytes: &[u8]) -> Result<Vec<Item>, PacketError> {
    if !within_depth(bytes, 0) {
        return Err(PacketError::TooDeep);
    }
    let mut out = Vec::new();
    items(bytes, &mut out)?;
    if out.is_empty() {
        // A bundle with no element that reads is as good as garbage.
        return Err(PacketError::NotOsc("no message in the bundle".into()));
    }
    Ok(out)
}

fn items(bytes: &[u8], out: &mut Vec<Item>) -> Result<(), PacketError> {
    if let Some(rest) = bytes.strip_prefix(b"#bundle\0") {
        // Bundles are walked here, element by element: rosc refuses a bundle whole when one
        // element is bad, and silently drops a truncated last element.
        let mut rest = rest
            .get(8..)
            .ok_or_else(|| PacketError::NotOsc("a bundle without its time tag".into()))?;
        while let Some((size, tail)) = rest.split_first_chunk::<4>() {
            let size = u32::from_be_bytes(*size) as usize;
            let element = tail.get(..size).unwrap_or(tail);
            // An element that is not OSC at all is dropped; the others still run.
            let _ = items(element, out);
            rest = tail.get(size..).unwrap_or_default();
        }
        return Ok(());
    }
    match rosc::decoder::decode_udp(bytes) {
        Ok((_, packet)) => {
            flatten(packet, out);
            Ok(())
        }
        Err(e) => match address(bytes) {
            Some(addr) => {
                out.push(Item::Malformed {
                    addr,
                    why: e.to_string(),
                });
                Ok(())
            }
            None => Err(PacketError::NotOsc(e.to_string())),
        },
    }
}

/// The address of the first message a packet (or the head of one) starts with, if it has
/// an intact one: a `/`-path of printable ASCII ending in NUL. Looks into bundles however
/// deep (iteratively: this names what a too-deep packet was, without decoding it).
pub fn first_address(bytes: &[u8]) -> Option<String> {
    let mut bytes = bytes;
    while let Some(rest) = bytes.strip_prefix(b"#bundle\0") {
        bytes = rest.get(12..)?;
    }
    address(bytes)
}

fn flatten(packet: OscPacket, out: &mut Vec<Item>) {
    match packet {
        OscPacket::Message(m) => out.push(Item::Message(m)),
        OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| flatten(p, out)),
    }
}

/// The address a message starts with, if intact.
fn address(bytes: &[u8]) -> Option<String> {
    let end = bytes.iter().position(|&b| b == 0)?;
    let addr = &bytes[..end];
    (addr.first() == Some(&b'/') && addr.iter().all(|b| b.is_ascii_graphic()))
        .then(|| String::from_utf8_lossy(addr).into_owned())
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
        for junk in [
            &b"hello world"[..],
            b"",
            b"#bundle\0\0\0",
            b"\xc0/a\0\0",
            b"/a b\0,i\0\0",
        ] {
            assert!(
                matches!(decode(junk), Err(PacketError::NotOsc(_))),
                "{junk:?}"
            );
        }
    }

    #[test]
    fn a_broken_message_with_an_intact_address_is_malformed() {
        let whole = bytes(&msg("/vo/light/1/level"));
        for cut in [whole.len() - 1, whole.len() - 4, 20] {
            match decode_items(&whole[..cut]).unwrap().as_slice() {
                [Item::Malformed { addr, why }] => {
                    assert_eq!(addr, "/vo/light/1/level");
                    assert!(!why.is_empty());
                }
                other => panic!("cut at {cut}: {other:?}"),
            }
        }
        assert!(matches!(
            decode_items(b"/a\0\0,q\0\0").unwrap()[..],
            [Item::Malformed { .. }]
        ));
        // Cut inside the address: garbage.
        assert!(matches!(
            decode_items(&whole[..5]),
            Err(PacketError::NotOsc(_))
        ));
    }

    #[test]
    fn a_truncated_bundle_keeps_the_elements_before_the_cut() {
        let p = OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content: vec![msg("/a"), msg("/b")],
        });
        let whole = bytes(&p);
        let got = decode_items(&whole[..whole.len() - 2]).unwrap();
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(matches!(&got[0], Item::Message(m) if m.addr == "/a"));
        assert!(matches!(&got[1], Item::Malformed { addr, .. } if addr == "/b"));
        assert_eq!(decode(&whole[..whole.len() - 2]).unwrap().len(), 1);
        assert_eq!(first_address(&whole), Some("/a".into()));
        assert_eq!(first_address(b"#bundle\0"), None);
    }
}
