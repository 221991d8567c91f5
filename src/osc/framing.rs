//! OSC over a byte stream (TCP): SLIP (OSC 1.1) and 32-bit length prefix (OSC 1.0).
//!
//! Ours rather than rosc's: rosc 0.11 has no SLIP, and its TCP decoder mis-measures frames
//! (notes/crates.md). The first byte of a stream picks the framing: 0xC0 (SLIP END) means
//! SLIP, anything else is a big-endian length prefix (whose first byte is 0 for any frame we
//! accept). Memory per connection is bounded by the frame limit.

use std::fmt;

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

/// A stream that cannot be decoded any further; the connection should be closed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// A frame is larger than the limit (`len` is the declared size, or the limit + 1 for a
    /// SLIP frame that ran past it).
    Oversize {
        /// Bytes the frame has (at least).
        len: usize,
        /// The limit it broke.
        limit: usize,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::Oversize { len, limit } => {
                write!(f, "a frame of {len} bytes is over the {limit}-byte limit")
            }
        }
    }
}

impl std::error::Error for FrameError {}

/// Incremental per-connection decoder: feed it whatever each read returned, collect whole
/// packets. Holds at most one partial frame (bounded by `max`).
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
        }
    }

    /// The framing the stream turned out to use (None before its first byte).
    pub fn framing(&self) -> Option<Framing> {
        self.framing
    }

    /// Consumes `data` and appends every packet it completes to `out`, in order. Empty
    /// frames are skipped. After an error the stream is unusable.
    pub fn feed(&mut self, data: &[u8], out: &mut Vec<Vec<u8>>) -> Result<(), FrameError> {
        let framing = match (self.framing, data.first()) {
            (Some(f), _) => f,
            (None, None) => return Ok(()),
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

    fn feed_slip(&mut self, data: &[u8], out: &mut Vec<Vec<u8>>) -> Result<(), FrameError> {
        for &b in data {
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
                            out.push(std::mem::take(&mut self.buf));
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
                return Err(FrameError::Oversize {
                    len: self.max + 1,
                    limit: self.max,
                });
            }
            self.buf.push(byte);
        }
        Ok(())
    }

    fn feed_prefixed(&mut self, mut data: &[u8], out: &mut Vec<Vec<u8>>) -> Result<(), FrameError> {
        while !data.is_empty() {
            let Some(want) = self.want else {
                let n = (4 - self.header_len).min(data.len());
                self.header[self.header_len..self.header_len + n].copy_from_slice(&data[..n]);
                self.header_len += n;
                data = &data[n..];
                if self.header_len == 4 {
                    self.header_len = 0;
                    let len = u32::from_be_bytes(self.header) as usize;
                    if len > self.max {
                        return Err(FrameError::Oversize {
                            len,
                            limit: self.max,
                        });
                    }
                    if len > 0 {
                        self.want = Some(len);
                        self.buf.reserve_exact(len);
                    }
                }
                continue;
            };
            let n = (want - self.buf.len()).min(data.len());
            self.buf.extend_from_slice(&data[..n]);
            data = &data[n..];
            if self.buf.len() == want {
                self.want = None;
                out.push(std::mem::take(&mut self.buf));
            }
        }
        Ok(())
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

    fn decode_in_chunks(stream: &[u8], chunk: usize) -> Result<Vec<Vec<u8>>, FrameError> {
        let mut d = Decoder::default();
        let mut out = Vec::new();
        for c in stream.chunks(chunk) {
            d.feed(c, &mut out)?;
        }
        Ok(out)
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
                let got = decode_in_chunks(&stream, chunk).unwrap();
                assert_eq!(got, packets(), "{framing:?} in chunks of {chunk}");
            }
        }
    }

    #[test]
    fn the_first_byte_picks_the_framing() {
        let mut d = Decoder::default();
        let mut out = Vec::new();
        d.feed(&[], &mut out).unwrap();
        assert_eq!(d.framing(), None);
        d.feed(&[END], &mut out).unwrap();
        assert_eq!(d.framing(), Some(Framing::Slip));
        let mut d = Decoder::default();
        d.feed(&[0], &mut out).unwrap();
        assert_eq!(d.framing(), Some(Framing::LengthPrefix));
        assert!(out.is_empty());
    }

    #[test]
    fn slip_escapes_and_empty_frames() {
        let stream = [
            END, END, b'a', ESC, ESC_END, ESC, ESC_ESC, END, END, END, b'b', END,
        ];
        let got = decode_in_chunks(&stream, stream.len()).unwrap();
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
        assert_eq!(decode_in_chunks(&stream, 3).unwrap(), vec![b"xy".to_vec()]);
    }

    #[test]
    fn oversize_frames_are_errors_without_buffering_them() {
        let limit = 16;
        let mut d = Decoder::new(limit);
        let mut out = Vec::new();
        let err = d.feed(&[0, 0, 0, 17], &mut out).unwrap_err();
        assert_eq!(err, FrameError::Oversize { len: 17, limit });
        assert!(err.to_string().contains("17 bytes"), "{err}");
        // A frame of exactly the limit passes.
        let mut d = Decoder::new(limit);
        d.feed(&encode(Framing::LengthPrefix, &[1; 16]), &mut out)
            .unwrap();
        assert_eq!(out, vec![vec![1; 16]]);

        let mut d = Decoder::new(limit);
        let mut out = Vec::new();
        d.feed(&encode(Framing::Slip, &[2; 16]), &mut out).unwrap();
        assert_eq!(out, vec![vec![2; 16]]);
        let mut endless = vec![END];
        endless.extend([3; 100]);
        let err = d.feed(&endless[1..], &mut out).unwrap_err();
        assert!(matches!(err, FrameError::Oversize { limit: 16, .. }));
        assert!(d.buf.len() <= limit);
    }
}
