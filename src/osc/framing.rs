//! OSC over a byte stream (TCP): SLIP (OSC 1.1) and 32-bit length prefix (OSC 1.0).
//!
//! Ours rather than rosc's: rosc 0.11 has no SLIP, and its TCP decoder mis-measures frames.
//! The first byte of a stream picks the framing: 0xC0 (SLIP END) means
//! SLIP, anything else is a big-endian length prefix (whose first byte is 0 for any frame we
//! accept). Memory per connection is bounded by the frame limit: a larger frame is
//! reported by its first bytes and skipped, so its sender can be told why.

/// The largest packet a stream may carry. Larger frames close the connection; the decode
/// buffer never grows past this.
pub const MAX_FRAME: usize = 64 * 1024;

const END: u8 = 0xC0;
const ESC: u8 = 0xDB;
const ESC_END: u8 = 0xDC;
const ESC_ESC: u8 = 0xDD;

/// How a client frames its packets; replies use the same.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// OSC 1.1: RFC 1055 SLIP, packets between END bytes.
    Slip,
    /// OSC 1.0: each packet preceded by its length as a big-endian u32.
    LengthPrefix,
}

/// How many leading bytes of a frame over the limit are kept, so its address can be named
/// in the error (an OSC address is rarely longer).
pub const HEAD: usize = 256;

/// One frame taken off a stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StreamFrame {
    /// A whole packet.
    Packet(Vec<u8>),
    /// A frame over the size limit: reported once its first bytes are in, then skipped
    /// without being buffered (the stream goes on after it).
    Oversize {
        /// Bytes the frame has: the declared length, or (SLIP) at least the limit + 1.
        len: usize,
        /// Its first [`HEAD`] bytes (fewer if the limit is smaller), for naming it.
        head: Vec<u8>,
    },
}

/// Incremental per-connection decoder: feed it whatever each read returned, collect whole
/// packets. Holds at most one partial frame (bounded by `max`); larger frames are skipped.
#[derive(Debug)]
pub struct Decoder {
    framing: Option<Framing>,
    max: usize,
    buf: Vec<u8>,
    /// SLIP: the previous byte was ESC.
    escaped: bool,
    /// Length prefix: bytes of the header seen so far, and the declared length once known.
    header: [u8; 4],
    header_len: usize,
    want: Option<usize>,
    /// Inside a frame over the limit: bytes still to skip (SLIP: until the next END).
    skip: Option<usize>,
}

impl Default for Decoder {
    fn default() -> Self {
        Decoder::new(MAX_FRAME)
    }
}

impl Decoder {
    /// A decoder for a new stream whose frames may be up to `max` bytes.
    pub fn new(max: usize) -> Decoder {
        Decoder {
            framing: None,
            max,
            buf: Vec::new(),
            escaped: false,
            header: [0; 4],
            header_len: 0,
            want: None,
            skip: None,
        }
    }

    /// A decoder for a stream whose framing is known beforehand (a client that chose it),
    /// so a SLIP peer that does not open with END is still read as SLIP.
    pub fn with_framing(framing: Framing, max: usize) -> Decoder {
        Decoder {
            framing: Some(framing),
            ..Decoder::new(max)
        }
    }

    /// The framing the stream turned out to use (None before its first byte).
    pub fn framing(&self) -> Option<Framing> {
        self.framing
    }

    /// Consumes `data` and appends every frame it completes to `out`, in order. Empty
    /// frames are skipped; a frame over the limit is reported once as [`StreamFrame::Oversize`]
    /// and its remaining bytes are dropped as they arrive.
    pub fn feed(&mut self, data: &[u8], out: &mut Vec<StreamFrame>) {
        let framing = match (self.framing, data.first()) {
            (Some(f), _) => f,
            (None, None) => return,
            (None, Some(&first)) => {
                let f = if first == END {
                    Framing::Slip
                } else {
                    Framing::LengthPrefix
                };
                self.framing = Some(f);
                f
            }
        };
        match framing {
            Framing::Slip => self.feed_slip(data, out),
            Framing::LengthPrefix => self.feed_prefixed(data, out),
        }
    }

    fn head_len(&self) -> usize {
        HEAD.min(self.max)
    }

    fn feed_slip(&mut self, data: &[u8], out: &mut Vec<StreamFrame>) {
        for &b in data {
            if self.skip.is_some() {
                // Skipping an oversize frame: only its END matters.
                if b == END {
                    self.skip = None;
                    self.escaped = false;
                }
                continue;
            }
            let byte = if self.escaped {
                self.escaped = false;
                match b {
                    ESC_END => END,
                    ESC_ESC => ESC,
                    // RFC 1055: a protocol violation; keep the byte as it is.
                    other => other,
                }
            } else {
                match b {
                    END => {
                        if !self.buf.is_empty() {
                            out.push(StreamFrame::Packet(std::mem::take(&mut self.buf)));
                        }
                        continue;
                    }
                    ESC => {
                        self.escaped = true;
                        continue;
                    }
                    other => other,
                }
            };
            if self.buf.len() >= self.max {
                let mut head = std::mem::take(&mut self.buf);
                head.truncate(self.head_len());
                out.push(StreamFrame::Oversize {
                    len: self.max + 1,
                    head,
                });
                self.skip = Some(usize::MAX);
                continue;
            }
            self.buf.push(byte);
        }
    }

    fn feed_prefixed(&mut self, mut data: &[u8], out: &mut Vec<StreamFrame>) {
        while !data.is_empty() {
            if let Some(left) = self.skip {
                let n = left.min(data.len());
                data = &data[n..];
                self.skip = (left > n).then_some(left - n);
                continue;
            }
            let Some(want) = self.want else {
                let n = (4 - self.header_len).min(data.len());
                self.header[self.header_len..self.header_len + n].copy_from_slice(&data[..n]);
                self.header_len += n;
                data = &data[n..];
                if self.header_len == 4 {
                    self.header_len = 0;
                    let len = u32::from_be_bytes(self.header) as usize;
                    if len > 0 {
                        self.want = Some(len);
                        self.buf.reserve_exact(len.min(self.max));
                    }
                }
                continue;
            };
            if want > self.max {
                // Keep only the head, report it, then skip the rest.
                let head_len = self.head_len();
                let n = (head_len - self.buf.len()).min(data.len());
                self.buf.extend_from_slice(&data[..n]);
                data = &data[n..];
                if self.buf.len() == head_len {
                    self.want = None;
                    out.push(StreamFrame::Oversize {
                        len: want,
                        head: std::mem::take(&mut self.buf),
                    });
                    self.skip = (want > head_len).then_some(want - head_len);
                }
                continue;
            }
            let n = (want - self.buf.len()).min(data.len());
            self.buf.extend_from_slice(&data[..n]);
            data = &data[n..];
            if self.buf.len() == want {
                self.want = None;
                out.push(StreamFrame::Packet(std::mem::take(&mut self.buf)));
            }
        }
    }
}

/// Frames one packet for a stream in the given framing (SLIP frames start and end with END,
/// as OSC 1.1 recommends).
pub fn encode(framing: Framing, packet: &[u8]) -> Vec<u8> {
    match framing {
        Framing::LengthPrefix => {
            let mut v = Vec::with_capacity(packet.len() + 4);
            // Packets we send are far below 4 GiB (rosc messages; MAX_FRAME-sized at most in
            // practice), so the length always fits.
            v.extend_from_slice(
                &u32::try_from(packet.len())
                    .unwrap_or(u32::MAX)
                    .to_be_bytes(),
            );
            v.extend_from_slice(packet);
            v
        }
        Framing::Slip => {
            let mut v = Vec::with_capacity(packet.len() + packet.len() / 16 + 2);
            v.push(END);
            for &b in packet {
                match b {
                    END => v.extend_from_slice(&[ESC, ESC_END]),
                    ESC => v.extend_from_slice(&[ESC, ESC_ESC]),
                    other => v.push(other),
                }
            }
            v.push(END);
            v
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_in_chunks(stream: &[u8], chunk: usize) -> Vec<Vec<u8>> {
        let mut d = Decoder::default();
        let mut out = Vec::new();
        for c in stream.chunks(chunk) {
            d.feed(c, &mut out);
        }
        out.into_iter()
            .map(|f| match f {
                StreamFrame::Packet(p) => p,
                other => panic!("{other:?}"),
            })
            .collect()
    }

    fn packets() -> Vec<Vec<u8>> {
        vec![
            b"/a\0\0,i\0\0\0\0\0\x01".to_vec(),
            vec![END, ESC, 1, ESC_END, ESC_ESC, END, END, 0, ESC],
            (0..=255u8).cycle().take(3000).collect(),
        ]
    }

    #[test]
    fn both_framings_survive_any_chunking() {
        for framing in [Framing::Slip, Framing::LengthPrefix] {
            let stream: Vec<u8> = packets().iter().flat_map(|p| encode(framing, p)).collect();
            for chunk in [1, 2, 3, 4, 5, 7, 13, 64, 1000, stream.len()] {
                let got = decode_in_chunks(&stream, chunk);
                assert_eq!(got, packets(), "{framing:?} in chunks of {chunk}");
            }
        }
    }

    #[test]
    fn the_first_byte_picks_the_framing() {
        let mut d = Decoder::default();
        let mut out = Vec::new();
        d.feed(&[], &mut out);
        assert_eq!(d.framing(), None);
        d.feed(&[END], &mut out);
        assert_eq!(d.framing(), Some(Framing::Slip));
        let mut d = Decoder::default();
        d.feed(&[0], &mut out);
        assert_eq!(d.framing(), Some(Framing::LengthPrefix));
        assert!(out.is_empty());
    }

    #[test]
    fn a_known_framing_does_not_wait_for_the_first_byte() {
        // A SLIP peer that only ends its frames with END (RFC 1055 allows it).
        let mut d = Decoder::with_framing(Framing::Slip, MAX_FRAME);
        let mut out = Vec::new();
        d.feed(&[b'a', b'b', END, 0, 1, END], &mut out);
        assert_eq!(
            out,
            [
                StreamFrame::Packet(b"ab".to_vec()),
                StreamFrame::Packet(vec![0, 1])
            ]
        );
    }

    #[test]
    fn slip_escapes_and_empty_frames() {
        let stream = [
            END, END, b'a', ESC, ESC_END, ESC, ESC_ESC, END, END, END, b'b', END,
        ];
        let got = decode_in_chunks(&stream, stream.len());
        assert_eq!(got, vec![vec![b'a', END, ESC], vec![b'b']]);
        assert_eq!(
            encode(Framing::Slip, &[END, ESC, 7]),
            [END, ESC, ESC_END, ESC, ESC_ESC, 7, END]
        );
    }

    #[test]
    fn zero_length_prefix_frames_are_skipped() {
        let mut stream = vec![0, 0, 0, 0];
        stream.extend(encode(Framing::LengthPrefix, b"xy"));
        stream.extend([0, 0, 0, 0]);
        assert_eq!(decode_in_chunks(&stream, 3), vec![b"xy".to_vec()]);
    }

    #[test]
    fn oversize_frames_are_reported_by_their_head_and_skipped() {
        let limit = 16;
        for framing in [Framing::LengthPrefix, Framing::Slip] {
            let big: Vec<u8> = (0..200u8).map(|b| b % 0xC0).collect();
            let mut stream = encode(framing, &[1; 16]);
            stream.extend(encode(framing, &big));
            stream.extend(encode(framing, b"after"));
            for chunk in [1, 5, 64, stream.len()] {
                let mut d = Decoder::new(limit);
                let mut out = Vec::new();
                for c in stream.chunks(chunk) {
                    d.feed(c, &mut out);
                    assert!(d.buf.len() <= limit, "never buffers past the limit");
                }
                let len = match framing {
                    Framing::LengthPrefix => 200,
                    Framing::Slip => limit + 1,
                };
                assert_eq!(
                    out,
                    [
                        StreamFrame::Packet(vec![1; 16]),
                        StreamFrame::Oversize {
                            len,
                            head: big[..limit].to_vec()
                        },
                        StreamFrame::Packet(b"after".to_vec()),
                    ],
                    "{framing:?} in chunks of {chunk}"
                );
            }
        }
        // A declared length far over the limit is reported once its head is in, long
        // before the frame could end.
        let mut d = Decoder::new(limit);
        let mut out = Vec::new();
        d.feed(&u32::MAX.to_be_bytes(), &mut out);
        d.feed(&[7; 40], &mut out);
        assert_eq!(
            out,
            [StreamFrame::Oversize {
                len: u32::MAX as usize,
                head: vec![7; 16]
            }]
        );
    }
}
