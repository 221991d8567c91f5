//! Packet encoding. The `sacn` and `artnet_protocol` crates encode correctly (checked with
//! tshark and in tests/output.rs); we only use their packet types and keep the sockets.

use std::borrow::Cow;

use std::net::Ipv4Addr;

use artnet_protocol::{ArtCommand, Output as ArtDmx, Poll, PollReply, PortAddress};
use sacn::packet::{
    AcnRootLayerProtocol, DataPacketDmpLayer, DataPacketFramingLayer, E131RootLayer,
    E131RootLayerData, SynchronizationPacketFramingLayer, UniverseDiscoveryPacketFramingLayer,
    UniverseDiscoveryPacketUniverseDiscoveryLayer,
};
use uuid::Uuid;

use crate::patch::SLOTS;

/// What every sACN data packet of one destination shares.
pub(crate) struct SacnSource<'a> {
    pub cid: Uuid,
    pub source_name: &'a str,
    pub priority: u8,
    pub sync_universe: u16,
}

/// Encodes an E1.31 data packet (start code 0 + 512 slots) into `buf`.
pub(crate) fn sacn_data(
    src: &SacnSource<'_>,
    universe: u16,
    sequence: u8,
    terminated: bool,
    dmx: &[u8; SLOTS],
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    let mut values = [0u8; SLOTS + 1];
    values[1..].copy_from_slice(dmx);
    let packet = AcnRootLayerProtocol {
        pdu: E131RootLayer {
            cid: src.cid,
            data: E131RootLayerData::DataPacket(DataPacketFramingLayer {
                source_name: Cow::Borrowed(src.source_name),
                priority: src.priority,
                synchronization_address: src.sync_universe,
                sequence_number: sequence,
                preview_data: false,
                stream_terminated: terminated,
                force_synchronization: false,
                universe,
                data: DataPacketDmpLayer {
                    property_values: Cow::Borrowed(&values),
                },
            }),
        },
    };
    packet.pack_vec(buf).map_err(|e| e.to_string())
}

/// Encodes an E1.31 synchronization packet for `sync_universe` into `buf`.
pub(crate) fn sacn_sync(
    cid: Uuid,
    sync_universe: u16,
    sequence: u8,
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    let packet = AcnRootLayerProtocol {
        pdu: E131RootLayer {
            cid,
            data: E131RootLayerData::SynchronizationPacket(SynchronizationPacketFramingLayer {
                sequence_number: sequence,
                synchronization_address: sync_universe,
            }),
        },
    };
    packet.pack_vec(buf).map_err(|e| e.to_string())
}

/// Encodes an ArtDmx packet (protocol version 14, 512 slots) for a 15-bit port-address.
pub(crate) fn artdmx(
    port_address: u16,
    sequence: u8,
    dmx: &[u8; SLOTS],
) -> Result<Vec<u8>, String> {
    let port_address = PortAddress::try_from(port_address).map_err(|e| e.to_string())?;
    ArtCommand::Output(ArtDmx {
        sequence,
        port_address,
        data: dmx.to_vec().into(),
        ..ArtDmx::default()
    })
    .write_to_buffer()
    .map_err(|e| e.to_string())
}

/// Universes per E1.31 universe discovery page (E1.31-2018 8.5).
pub(crate) const DISCOVERY_PAGE: usize = 512;

/// Encodes page `page` (of `last_page`, from 0) of an E1.31 universe discovery packet
/// listing `universes` (sorted, at most [`DISCOVERY_PAGE`]) into `buf`.
pub(crate) fn sacn_discovery(
    cid: Uuid,
    source_name: &str,
    page: u8,
    last_page: u8,
    universes: &[u16],
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    let packet = AcnRootLayerProtocol {
        pdu: E131RootLayer {
            cid,
            data: E131RootLayerData::UniverseDiscoveryPacket(UniverseDiscoveryPacketFramingLayer {
                source_name: Cow::Borrowed(source_name),
                data: UniverseDiscoveryPacketUniverseDiscoveryLayer {
                    page,
                    last_page,
                    universes: Cow::Borrowed(universes),
                },
            }),
        },
    };
    packet.pack_vec(buf).map_err(|e| e.to_string())
}

/// Encodes an ArtPoll (protocol version 14): what a controller sends to find the nodes.
pub(crate) fn artpoll() -> Result<Vec<u8>, String> {
    ArtCommand::Poll(Poll::default())
        .write_to_buffer()
        .map_err(|e| e.to_string())
}

/// Encodes visobjd's ArtPollReply packets: a controller whose ports send `port_addresses`
/// onto the network (Art-Net calls them input ports), one reply per four ports that share
/// a net and sub-net, numbered by `BindIndex` from 1 as Art-Net 4 asks of a device with
/// more ports than one reply holds.
pub(crate) fn artpollreplies(ip: Ipv4Addr, port_addresses: &[u16]) -> Result<Vec<Vec<u8>>, String> {
    let mut sorted = port_addresses.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    let mut groups: Vec<Vec<u16>> = Vec::new();
    for pa in sorted {
        match groups.last_mut() {
            Some(g) if g.len() < 4 && g[0] >> 4 == pa >> 4 => g.push(pa),
            _ => groups.push(vec![pa]),
        }
    }
    let text = |s: &str, out: &mut [u8]| {
        let n = s.len().min(out.len() - 1);
        out[..n].copy_from_slice(&s.as_bytes()[..n]);
    };
    groups
        .iter()
        .enumerate()
        .map(|(i, group)| {
            let mut reply = PollReply {
                address: ip,
                version: [0, 1],
                port_address: [(group[0] >> 8) as u8 & 0x7f, (group[0] >> 4) as u8 & 0x0f],
                // OEM "unknown" and an ESTA code from the prototyping range.
                oem: [0x00, 0xff],
                esta_code: 0x7ff0,
                // Indicators normal; port-addresses set over the network (the config).
                status_1: 0b1110_0000,
                num_ports: [0, group.len() as u8],
                // StController: a console (a source of DMX).
                style: 0x01,
                bind_ip: ip.octets(),
                bind_index: (i + 1).min(255) as u8,
                // Supports 15-bit port-addresses (Art-Net 3 and later).
                status_2: 0b0000_1000,
                ..PollReply::default()
            };
            text("visobjd", &mut reply.short_name);
            text(
                "visobjd - looks from visual objectives",
                &mut reply.long_name,
            );
            text(
                &format!("#0001 [{:04}] visobjd sending", group.len()),
                &mut reply.node_report,
            );
            for (k, pa) in group.iter().enumerate() {
                reply.port_types[k] = 0x40; // can send DMX512 onto Art-Net
                reply.good_input[k] = 0x80; // data received
                reply.swin[k] = (pa & 0x0f) as u8;
            }
            ArtCommand::PollReply(Box::new(reply))
                .write_to_buffer()
                .map_err(|e| e.to_string())
        })
        .collect()
}

/// An Art-Net packet visobjd acts on, read from the specification's byte offsets (never
/// through a crate that might panic on what the network sends).
#[derive(Debug, PartialEq)]
pub(crate) enum ArtIn {
    /// An ArtPoll: answer it.
    Poll,
    /// A node's ArtPollReply: its bind index and the port-addresses its output ports take
    /// from the network.
    Reply { bind_index: u8, outputs: Vec<u16> },
}

/// Reads an ArtPoll or ArtPollReply; `None` for anything else or anything malformed.
pub(crate) fn parse_artnet_in(p: &[u8]) -> Option<ArtIn> {
    if p.len() < 14 || &p[..8] != b"Art-Net\0" {
        return None;
    }
    match u16::from_le_bytes([p[8], p[9]]) {
        0x2000 => Some(ArtIn::Poll),
        0x2100 if p.len() >= 212 => {
            let (net, sub) = (u16::from(p[18] & 0x7f), u16::from(p[19] & 0x0f));
            let ports = usize::from(p[173]).min(4);
            let outputs = (0..ports)
                // PortTypes bit 7: the port can output DMX512 from the network.
                .filter(|&i| p[174 + i] & 0x80 != 0)
                .map(|i| net << 8 | sub << 4 | u16::from(p[190 + i] & 0x0f))
                .collect();
            Some(ArtIn::Reply {
                bind_index: p[211],
                outputs,
            })
        }
        _ => None,
    }
}

/// The next sequence number of an 8-bit counter (E1.31: every value is valid).
pub(crate) fn next_sacn_sequence(s: u8) -> u8 {
    s.wrapping_add(1)
}

/// The next ArtDmx sequence number: 1..=255 wrapping, never 0 (0 turns sequencing off).
pub(crate) fn next_artnet_sequence(s: u8) -> u8 {
    if s == 255 { 1 } else { s + 1 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn artnet_sequence_skips_zero() {
        assert_eq!(next_artnet_sequence(0), 1);
        assert_eq!(next_artnet_sequence(254), 255);
        assert_eq!(next_artnet_sequence(255), 1);
    }

    #[test]
    fn artdmx_layout() {
        let mut dmx = [0u8; SLOTS];
        dmx[0] = 9;
        dmx[511] = 7;
        let p = artdmx(0x1234, 5, &dmx).expect("encodes");
        assert_eq!(p.len(), 18 + 512);
        assert_eq!(&p[..8], b"Art-Net\0");
        assert_eq!(
            &p[8..18],
            &[0x00, 0x50, 0, 14, 5, 0, 0x34, 0x12, 0x02, 0x00]
        );
        assert_eq!((p[18], p[529]), (9, 7));
    }

    #[test]
    fn sacn_sync_layout() {
        let mut buf = Vec::new();
        sacn_sync(Uuid::from_bytes([1; 16]), 7, 3, &mut buf).expect("encodes");
        assert_eq!(buf.len(), 49);
        assert_eq!(&buf[18..22], &[0, 0, 0, 8]); // VECTOR_ROOT_E131_EXTENDED
        assert_eq!(&buf[40..44], &[0, 0, 0, 1]); // VECTOR_E131_EXTENDED_SYNCHRONIZATION
        assert_eq!((buf[44], buf[45], buf[46]), (3, 0, 7));
    }

    #[test]
    fn our_pollreply_reads_back_and_groups_by_subnet() {
        let replies =
            artpollreplies(Ipv4Addr::new(10, 0, 0, 7), &[0, 1, 2, 3, 4, 0x13]).expect("encode");
        assert_eq!(
            replies.len(),
            3,
            "four ports, then the rest of sub-net 0, then sub-net 1"
        );
        for r in &replies {
            assert_eq!(r.len(), 239);
            assert_eq!(&r[10..14], &[10, 0, 0, 7]);
            assert_eq!(&r[26..33], b"visobjd");
        }
        // Our ports are inputs (onto the network): none outputs, so none reads as a node's.
        assert_eq!(
            parse_artnet_in(&replies[0]),
            Some(ArtIn::Reply {
                bind_index: 1,
                outputs: vec![]
            })
        );
        assert_eq!(replies[0][173], 4);
        assert_eq!(&replies[0][186..190], &[0, 1, 2, 3]);
        assert_eq!(
            (replies[1][173], replies[1][186], replies[1][211]),
            (1, 4, 2)
        );
        assert_eq!(
            (replies[2][19], replies[2][186], replies[2][211]),
            (1, 3, 3)
        );
    }

    #[test]
    fn a_nodes_reply_gives_its_output_port_addresses() {
        let mut p = vec![0u8; 239];
        p[..8].copy_from_slice(b"Art-Net\0");
        p[8..10].copy_from_slice(&0x2100u16.to_le_bytes());
        p[18] = 1; // net
        p[19] = 2; // sub-net
        p[173] = 3;
        p[174..177].copy_from_slice(&[0x80, 0x40, 0x80]);
        p[190..193].copy_from_slice(&[5, 6, 7]);
        p[211] = 2;
        assert_eq!(
            parse_artnet_in(&p),
            Some(ArtIn::Reply {
                bind_index: 2,
                outputs: vec![0x125, 0x127]
            })
        );
        assert_eq!(parse_artnet_in(&p[..100]), None, "too short for a reply");
        assert_eq!(
            parse_artnet_in(&artpoll().expect("poll")),
            Some(ArtIn::Poll)
        );
        assert_eq!(
            parse_artnet_in(b"Art-Net\0\x00\x50abcdefgh"),
            None,
            "ArtDmx"
        );
    }
}
