//! Packet encoding. The `sacn` and `artnet_protocol` crates encode correctly (checked with
//! tshark and in tests/output.rs); we only use their packet types and keep the sockets.

use std::borrow::Cow;

use artnet_protocol::{ArtCommand, Output as ArtDmx, PortAddress};
use sacn::packet::{
    AcnRootLayerProtocol, DataPacketDmpLayer, DataPacketFramingLayer, E131RootLayer,
    E131RootLayerData, SynchronizationPacketFramingLayer,
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
}
