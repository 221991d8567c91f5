//! E1.31 (ANSI E1.31-2018) data packets read from their octets, for the console input.
//!
//! The `sacn` crate's parsers are not used for received packets: they slice the buffer by
//! the PDU length fields without first checking that those lengths cover the fixed
//! headers, so a lying packet from the network panics the receiver instead of being
//! dropped (sacn 0.11.1: a valid data packet with its root-layer length set to 5, or its
//! framing-layer length to 16, panics in `AcnRootLayerProtocol::parse`). A data packet has
//! fixed offsets (Table 4-1), so reading it here is short and checks every field the
//! standard fixes.

use uuid::Uuid;

use crate::patch::SLOTS;

/// ACN packet identifier (Table 4-1, octets 4-15).
const ACN_ID: &[u8; 12] = b"ASC-E1.17\0\0\0";
/// Root layer vector of a data packet (`VECTOR_ROOT_E131_DATA`).
const VECTOR_ROOT_DATA: u32 = 0x0000_0004;
/// Root layer vector of synchronization and discovery packets (`VECTOR_ROOT_E131_EXTENDED`).
const VECTOR_ROOT_EXTENDED: u32 = 0x0000_0008;
/// Framing layer vector of a data packet (`VECTOR_E131_DATA_PACKET`).
const VECTOR_DATA_PACKET: u32 = 0x0000_0002;
/// Octets before the DMX start code.
const HEADER: usize = 125;

/// Start code of level (null start code) data.
pub const LEVELS: u8 = 0x00;
/// Start code of per-address priority data (ETC's 0xDD).
pub const PER_ADDRESS_PRIORITY: u8 = 0xdd;

/// One E1.31 data packet, as received.
#[derive(Debug, Clone, PartialEq)]
pub struct DataPacket {
    /// The sender's component identifier.
    pub cid: Uuid,
    /// The source name (lossy UTF-8, up to its NUL).
    pub source_name: String,
    /// Universe priority, 0..=200.
    pub priority: u8,
    /// Sequence number (per source, per universe).
    pub sequence: u8,
    /// Preview_Data option: not meant for live output.
    pub preview: bool,
    /// Stream_Terminated option: the source leaves this universe now.
    pub terminated: bool,
    /// Universe, 1..=63999.
    pub universe: u16,
    /// The DMX start code (0x00 levels, 0xDD per-address priorities, others ignored).
    pub start_code: u8,
    /// The slots after the start code (0..=512 of them).
    pub slots: Vec<u8>,
}

fn u16_at(p: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([p[at], p[at + 1]])
}

fn u32_at(p: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([p[at], p[at + 1], p[at + 2], p[at + 3]])
}

/// Checks a PDU's flags (0x7) and that its length is `want`.
fn pdu(p: &[u8], at: usize, layer: &str, want: usize) -> Result<(), String> {
    let v = u16_at(p, at);
    if v >> 12 != 0x7 {
        return Err(format!("{layer} flags are {:#x}, not 0x7", v >> 12));
    }
    let length = usize::from(v & 0x0fff);
    if length != want {
        return Err(format!(
            "{layer} length is {length} where the packet's property count makes it {want}"
        ));
    }
    Ok(())
}

/// Reads one datagram: `Ok(Some)` for a data packet, `Ok(None)` for the E1.31 packets an
/// input has no use for (synchronization, universe discovery), `Err` with a phrase for
/// anything malformed.
pub fn parse(p: &[u8]) -> Result<Option<DataPacket>, String> {
    if p.len() < 22 {
        return Err(format!(
            "{} bytes is too short for an E1.31 packet",
            p.len()
        ));
    }
    if u16_at(p, 0) != 0x0010 || u16_at(p, 2) != 0 || &p[4..16] != ACN_ID {
        return Err("not an ACN packet (preamble, postamble or identifier)".into());
    }
    match u32_at(p, 18) {
        VECTOR_ROOT_DATA => {}
        VECTOR_ROOT_EXTENDED => return Ok(None),
        v => return Err(format!("root vector {v:#010x} is not an E1.31 one")),
    }
    if p.len() < HEADER + 1 {
        return Err(format!(
            "{} bytes is too short for an E1.31 data packet (at least 126)",
            p.len()
        ));
    }
    let count = usize::from(u16_at(p, 123));
    if !(1..=SLOTS + 1).contains(&count) {
        return Err(format!(
            "property value count {count} is outside 1..=513 (a start code and up to 512 slots)"
        ));
    }
    if p.len() < HEADER + count {
        return Err(format!(
            "{} bytes hold fewer than the {count} property values announced",
            p.len()
        ));
    }
    pdu(p, 16, "root layer", HEADER - 16 + count)?;
    pdu(p, 38, "framing layer", HEADER - 38 + count)?;
    pdu(p, 115, "DMP layer", HEADER - 115 + count)?;
    if u32_at(p, 40) != VECTOR_DATA_PACKET {
        return Err(format!(
            "framing vector {:#010x} is not a data packet",
            u32_at(p, 40)
        ));
    }
    if p[117] != 0x02 || p[118] != 0xa1 || u16_at(p, 119) != 0 || u16_at(p, 121) != 1 {
        return Err(
            "DMP layer is not Set Property, 0xa1, first address 0, increment 1".to_string(),
        );
    }
    let priority = p[108];
    if priority > 200 {
        return Err(format!("priority {priority} is outside 0..=200"));
    }
    let universe = u16_at(p, 113);
    if !(1..=63999).contains(&universe) {
        return Err(format!("universe {universe} is outside 1..=63999"));
    }
    let name = &p[44..108];
    let end = name.iter().position(|&b| b == 0).unwrap_or(name.len());
    let mut cid = [0u8; 16];
    cid.copy_from_slice(&p[22..38]);
    Ok(Some(DataPacket {
        cid: Uuid::from_bytes(cid),
        source_name: String::from_utf8_lossy(&name[..end]).into_owned(),
        priority,
        sequence: p[111],
        preview: p[112] & 0x80 != 0,
        terminated: p[112] & 0x40 != 0,
        universe,
        start_code: p[HEADER],
        slots: p[HEADER + 1..HEADER + count].to_vec(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{SacnSource, sacn_data, sacn_sync};

    fn packet(universe: u16, terminated: bool) -> Vec<u8> {
        let mut dmx = [0u8; SLOTS];
        dmx[0] = 7;
        dmx[511] = 9;
        let mut buf = Vec::new();
        let src = SacnSource {
            cid: Uuid::from_bytes([3; 16]),
            source_name: "Eos",
            priority: 120,
            sync_universe: 0,
        };
        sacn_data(&src, universe, 42, terminated, &dmx, &mut buf).expect("encodes");
        buf
    }

    #[test]
    fn reads_what_the_sender_encodes() {
        let p = parse(&packet(5, true)).expect("valid").expect("data");
        assert_eq!(p.cid, Uuid::from_bytes([3; 16]));
        assert_eq!(
            (p.source_name.as_str(), p.priority, p.sequence, p.universe),
            ("Eos", 120, 42, 5)
        );
        assert!(p.terminated && !p.preview);
        assert_eq!(
            (p.start_code, p.slots.len(), p.slots[0], p.slots[511]),
            (0, 512, 7, 9)
        );
    }

    #[test]
    fn start_code_and_short_packets() {
        let mut b = packet(1, false);
        b[125] = PER_ADDRESS_PRIORITY;
        b[112] |= 0x80;
        let p = parse(&b).expect("valid").expect("data");
        assert_eq!(p.start_code, PER_ADDRESS_PRIORITY);
        assert!(p.preview);
        // 24 slots: the layer lengths shrink with the count.
        let mut short = packet(1, false)[..125 + 25].to_vec();
        short[123..125].copy_from_slice(&25u16.to_be_bytes());
        for (at, base) in [
            (16, 0x7000 | (150 - 16)),
            (38, 0x7000 | (150 - 38)),
            (115, 0x7000 | (150 - 115)),
        ] {
            short[at..at + 2].copy_from_slice(&(base as u16).to_be_bytes());
        }
        assert_eq!(parse(&short).expect("valid").expect("data").slots.len(), 24);
    }

    #[test]
    fn no_cut_or_changed_byte_panics() {
        let good = packet(1, false);
        for cut in 0..=good.len() {
            let _ = parse(&good[..cut]);
        }
        for at in 0..good.len() {
            for v in [0x00, 0x01, 0x70, 0x7f, 0xc0, 0xff] {
                let mut b = good.clone();
                b[at] = v;
                if let Ok(Some(p)) = parse(&b) {
                    assert!(p.slots.len() <= SLOTS && p.priority <= 200);
                }
            }
        }
    }

    #[test]
    fn sync_is_not_data_and_garbage_is_an_error() {
        let mut buf = Vec::new();
        sacn_sync(Uuid::from_bytes([1; 16]), 7, 3, &mut buf).expect("encodes");
        assert_eq!(parse(&buf), Ok(None));
        let good = packet(1, false);
        for cut in [0, 10, 21, 60, 125, 300, 637] {
            assert!(parse(&good[..cut]).is_err(), "cut at {cut}");
        }
        let mut lying = good.clone();
        lying[16..18].copy_from_slice(&0x7005u16.to_be_bytes());
        assert!(parse(&lying).unwrap_err().contains("root layer"));
        let mut prio = good.clone();
        prio[108] = 201;
        assert!(parse(&prio).unwrap_err().contains("priority"));
        let mut uni = good;
        uni[113..115].copy_from_slice(&0u16.to_be_bytes());
        assert!(parse(&uni).unwrap_err().contains("universe"));
    }
}
