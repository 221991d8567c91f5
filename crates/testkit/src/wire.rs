//! Art-Net 4 and E1.31 packets decoded from the specifications' byte offsets, independently
//! of the sending code. Malformed packets fail the test that receives them. Also an E1.31
//! encoder written from the same offsets, for test peers that play a console.

/// ACN packet identifier (E1.31-2018 Table 4-1, octets 4-15).
pub const ACN_ID: &[u8; 12] = b"ASC-E1.17\0\0\0";

/// An E1.31 data packet.
#[derive(Debug, Clone)]
pub struct Sacn {
    pub cid: [u8; 16],
    pub source_name: String,
    pub priority: u8,
    pub sync_universe: u16,
    pub sequence: u8,
    pub terminated: bool,
    pub universe: u16,
    /// The 512 DMX slots after the start code.
    pub dmx: Vec<u8>,
}

/// Checks what every E1.31 packet starts with (E1.31 5 and 6: preamble and postamble
/// sizes, the ACN packet identifier, the root and framing layers' flags and lengths), and
/// returns the reader of a later layer's flags and length.
fn root_and_framing(p: &[u8]) -> impl Fn(usize) -> u16 + '_ {
    assert_eq!(p[0..2], [0x00, 0x10], "preamble size");
    assert_eq!(p[2..4], [0, 0], "postamble size");
    assert_eq!(&p[4..16], ACN_ID, "ACN packet identifier");
    let flags_len = |at: usize| u16::from_be_bytes([p[at], p[at + 1]]);
    assert_eq!(
        flags_len(16),
        0x7000 | (p.len() - 16) as u16,
        "root flags+length"
    );
    assert_eq!(
        flags_len(38),
        0x7000 | (p.len() - 38) as u16,
        "framing flags+length"
    );
    flags_len
}

/// Decodes an E1.31 data packet; `None` for anything else (e.g. a sync packet).
pub fn parse_sacn(p: &[u8]) -> Option<Sacn> {
    if p.len() < 126 || p[18..22] != [0, 0, 0, 4] {
        return None;
    }
    let flags_len = root_and_framing(p);
    assert_eq!(
        p[40..44],
        [0, 0, 0, 2],
        "framing vector VECTOR_E131_DATA_PACKET"
    );
    assert_eq!(
        flags_len(115),
        0x7000 | (p.len() - 115) as u16,
        "DMP flags+length"
    );
    assert_eq!(p[117], 0x02, "DMP vector VECTOR_DMP_SET_PROPERTY");
    assert_eq!(p[118], 0xa1, "address type and data type");
    assert_eq!(p[119..121], [0, 0], "first property address");
    assert_eq!(p[121..123], [0, 1], "address increment");
    let count = u16::from_be_bytes([p[123], p[124]]) as usize;
    assert_eq!(count, 513, "property value count");
    assert_eq!(p.len(), 125 + count);
    assert_eq!(p[125], 0, "start code");
    let name = &p[44..108];
    let end = name
        .iter()
        .position(|&b| b == 0)
        .expect("NUL-terminated name");
    Some(Sacn {
        cid: p[22..38].try_into().expect("16 bytes"),
        source_name: String::from_utf8(name[..end].to_vec()).expect("UTF-8 name"),
        priority: p[108],
        sync_universe: u16::from_be_bytes([p[109], p[110]]),
        sequence: p[111],
        terminated: p[112] & 0x40 != 0,
        universe: u16::from_be_bytes([p[113], p[114]]),
        dmx: p[126..].to_vec(),
    })
}

/// Decodes an E1.31 synchronization packet (Table 4-2) to its sync address.
pub fn parse_sync(p: &[u8]) -> Option<u16> {
    if p.len() < 44 || p[18..22] != [0, 0, 0, 8] || p[40..44] != [0, 0, 0, 1] {
        return None;
    }
    assert_eq!(p.len(), 49, "a sync packet is 49 bytes");
    assert_eq!(p[0..2], [0x00, 0x10], "preamble size");
    assert_eq!(&p[4..16], ACN_ID, "ACN packet identifier");
    assert_eq!(p[16..18], [0x70, 33], "root flags+length");
    assert_eq!(p[38..40], [0x70, 11], "framing flags+length");
    assert_eq!(
        p[40..44],
        [0, 0, 0, 1],
        "VECTOR_E131_EXTENDED_SYNCHRONIZATION"
    );
    assert_eq!(p[47..49], [0, 0], "reserved");
    Some(u16::from_be_bytes([p[45], p[46]]))
}

/// An E1.31 universe discovery packet (E1.31-2018 Table 4-3).
#[derive(Debug, Clone)]
pub struct Discovery {
    pub cid: [u8; 16],
    pub source_name: String,
    pub page: u8,
    pub last_page: u8,
    pub universes: Vec<u16>,
}

/// Decodes an E1.31 universe discovery packet; `None` for anything else.
pub fn parse_discovery(p: &[u8]) -> Option<Discovery> {
    if p.len() < 44 || p[18..22] != [0, 0, 0, 8] || p[40..44] != [0, 0, 0, 2] {
        return None;
    }
    assert!(
        p.len() >= 120 && p.len().is_multiple_of(2),
        "discovery length {}",
        p.len()
    );
    let flags_len = root_and_framing(p);
    assert_eq!(p[108..112], [0; 4], "reserved");
    assert_eq!(
        flags_len(112),
        0x7000 | (p.len() - 112) as u16,
        "discovery flags+length"
    );
    assert_eq!(
        p[114..118],
        [0, 0, 0, 1],
        "VECTOR_UNIVERSE_DISCOVERY_UNIVERSE_LIST"
    );
    let name = &p[44..108];
    let end = name.iter().position(|&b| b == 0).unwrap_or(64);
    let universes: Vec<u16> = p[120..]
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    assert!(
        universes.windows(2).all(|w| w[0] < w[1]),
        "sorted: {universes:?}"
    );
    assert!(p[118] <= p[119], "page within last page");
    Some(Discovery {
        cid: p[22..38].try_into().expect("16 bytes"),
        source_name: String::from_utf8_lossy(&name[..end]).into_owned(),
        page: p[118],
        last_page: p[119],
        universes,
    })
}

/// An Art-Net 4 ArtDmx packet.
#[derive(Debug, Clone)]
pub struct ArtDmx {
    pub sequence: u8,
    pub port_address: u16,
    /// The 512 DMX slots.
    pub dmx: Vec<u8>,
}

/// Decodes an ArtDmx packet (OpCode 0x5000, protocol 14, 512 slots).
pub fn parse_artnet(p: &[u8]) -> ArtDmx {
    assert_eq!(&p[0..8], b"Art-Net\0");
    assert_eq!(u16::from_le_bytes([p[8], p[9]]), 0x5000, "OpDmx");
    assert_eq!(u16::from_be_bytes([p[10], p[11]]), 14, "protocol version");
    let length = u16::from_be_bytes([p[16], p[17]]) as usize;
    assert_eq!(length, 512);
    assert_eq!(p.len(), 18 + length);
    ArtDmx {
        sequence: p[12],
        port_address: u16::from_le_bytes([p[14], p[15]]),
        dmx: p[18..].to_vec(),
    }
}

/// An ArtPoll (Art-Net 4, OpPoll 0x2000): ID, opcode, protocol version 14, flags 0,
/// diagnostics priority.
pub fn encode_artpoll() -> Vec<u8> {
    let mut p = b"Art-Net\0".to_vec();
    p.extend_from_slice(&0x2000u16.to_le_bytes());
    p.extend_from_slice(&[0, 14, 0, 0x10]);
    p
}

/// A node's ArtPollReply (Art-Net 4, OpPollReply 0x2100, 239 bytes) whose output ports
/// take `outputs` (the low nibble of each port-address) in `net`/`sub`.
pub fn encode_node_reply(ip: [u8; 4], net: u8, sub: u8, outputs: &[u8]) -> Vec<u8> {
    let mut p = vec![0u8; 239];
    p[..8].copy_from_slice(b"Art-Net\0");
    p[8..10].copy_from_slice(&0x2100u16.to_le_bytes());
    p[10..14].copy_from_slice(&ip);
    p[14..16].copy_from_slice(&0x1936u16.to_le_bytes());
    p[18] = net;
    p[19] = sub;
    p[26..35].copy_from_slice(b"test node");
    p[173] = outputs.len() as u8;
    for (i, &o) in outputs.iter().enumerate() {
        p[174 + i] = 0x80; // output port, DMX512
        p[190 + i] = o;
    }
    p[200] = 0x00; // StNode
    p[211] = 1;
    p
}

/// What an ArtPollReply says of a device.
#[derive(Debug, Clone)]
pub struct PollReply {
    pub ip: [u8; 4],
    pub short_name: String,
    pub net: u8,
    pub sub: u8,
    /// Per port: (port type, SwIn, SwOut).
    pub ports: Vec<(u8, u8, u8)>,
    pub style: u8,
    pub bind_index: u8,
}

/// Decodes an ArtPollReply; `None` for any other Art-Net packet.
pub fn parse_pollreply(p: &[u8]) -> Option<PollReply> {
    if p.len() < 10 || &p[0..8] != b"Art-Net\0" || u16::from_le_bytes([p[8], p[9]]) != 0x2100 {
        return None;
    }
    assert!(p.len() >= 213, "ArtPollReply of {} bytes", p.len());
    assert_eq!(u16::from_le_bytes([p[14], p[15]]), 0x1936, "port 6454");
    let name = &p[26..44];
    let end = name
        .iter()
        .position(|&b| b == 0)
        .expect("a NUL-terminated short name");
    let n = usize::from(p[173]);
    assert!(n <= 4, "at most four ports per reply");
    Some(PollReply {
        ip: p[10..14].try_into().expect("4 bytes"),
        short_name: String::from_utf8_lossy(&name[..end]).into_owned(),
        net: p[18],
        sub: p[19],
        ports: (0..n)
            .map(|i| (p[174 + i], p[186 + i], p[190 + i]))
            .collect(),
        style: p[200],
        bind_index: p[211],
    })
}

/// Option bits of an E1.31 data packet (Table 6-1, octet 112).
pub const PREVIEW_DATA: u8 = 0x80;
pub const STREAM_TERMINATED: u8 = 0x40;

/// Encodes an E1.31 data packet from the standard's octets (Table 4-1), for a test peer
/// playing a console: `slots` after the start code (0..=512 of them).
#[allow(clippy::too_many_arguments)]
pub fn encode_sacn(
    cid: [u8; 16],
    source_name: &str,
    priority: u8,
    sequence: u8,
    options: u8,
    universe: u16,
    start_code: u8,
    slots: &[u8],
) -> Vec<u8> {
    assert!(slots.len() <= 512 && source_name.len() < 64);
    let count = slots.len() + 1;
    let mut p = Vec::with_capacity(125 + count);
    p.extend_from_slice(&[0x00, 0x10, 0x00, 0x00]); // preamble, postamble size
    p.extend_from_slice(ACN_ID);
    let flags_len = |len: usize| (0x7000 | len as u16).to_be_bytes();
    p.extend_from_slice(&flags_len(125 + count - 16)); // root layer
    p.extend_from_slice(&[0, 0, 0, 4]); // VECTOR_ROOT_E131_DATA
    p.extend_from_slice(&cid);
    p.extend_from_slice(&flags_len(125 + count - 38)); // framing layer
    p.extend_from_slice(&[0, 0, 0, 2]); // VECTOR_E131_DATA_PACKET
    let mut name = [0u8; 64];
    name[..source_name.len()].copy_from_slice(source_name.as_bytes());
    p.extend_from_slice(&name);
    p.push(priority);
    p.extend_from_slice(&[0, 0]); // synchronization address: none
    p.push(sequence);
    p.push(options);
    p.extend_from_slice(&universe.to_be_bytes());
    p.extend_from_slice(&flags_len(125 + count - 115)); // DMP layer
    p.push(0x02); // VECTOR_DMP_SET_PROPERTY
    p.push(0xa1); // address type and data type
    p.extend_from_slice(&[0, 0, 0, 1]); // first property address 0, increment 1
    p.extend_from_slice(&(count as u16).to_be_bytes());
    p.push(start_code);
    p.extend_from_slice(slots);
    assert_eq!(p.len(), 125 + count);
    p
}
