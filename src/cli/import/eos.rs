//! `visobjd import eos://HOST[:PORT]`: the patch and groups read live from an ETC Eos
//! console over OSC TCP. Blocking sockets: connecting and every read have a deadline, so a
//! console that stops answering is a one-line error naming what was being read.
//!
//! The exchange (ETC's "Eos Integration via OSC"; the reply formats and the list
//! convention are the rig crate's `eos` module): `/eos/get/patch/count`, then
//! `/eos/get/patch/index/<i>` for every index (positions in the patch list, one channel
//! part each, as ETCLabs' EosSyncLib counts them), likewise `/eos/get/group/count` and
//! `/eos/get/group/index/<i>`, then the focus palettes (`crate::eos::palettes`). Requests go out a window ahead of the answers; replies are
//! matched by the index they carry (their first argument), not by arrival order. Everything else the
//! console sends (pings, the active channel, the command line, notes, augment3d) is skipped.

use std::collections::BTreeMap;
use std::net::ToSocketAddrs;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rosc::OscMessage;
use visobjd_rig::eos::{
    self, Arg, EosChannel, EosGroup, EosPalette, EosPatch, Lists, Piece, Reply,
};

use crate::eos::link::{Link, arg};
use crate::osc::framing::Framing;

/// Eos's OSC TCP port for OSC 1.0 (length-prefixed) packets.
const PORT_LENGTH_PREFIX: u16 = 3032;
/// Eos's OSC TCP port for OSC 1.1 (SLIP) packets.
const PORT_SLIP: u16 = 3037;
/// Index requests out at once (a few kB of replies each way).
const WINDOW: usize = 32;
/// The whole read may take this many times `--timeout` (10 minutes by default): a
/// console that keeps answering, but too slowly to finish, is given up on.
const TOTAL_TIMEOUTS: u32 = 120;

/// Where and how to reach a console named by `source`; `None` when `source` is not an
/// `eos://` or `eos+slip://` address.
pub fn target(source: &str) -> Option<anyhow::Result<(String, Framing)>> {
    let (rest, framing, port) = if let Some(r) = source.strip_prefix("eos://") {
        (r, Framing::LengthPrefix, PORT_LENGTH_PREFIX)
    } else if let Some(r) = source.strip_prefix("eos+slip://") {
        (r, Framing::Slip, PORT_SLIP)
    } else {
        return None;
    };
    let rest = rest.trim_end_matches('/');
    if rest.is_empty() || rest.contains('/') {
        return Some(Err(anyhow::anyhow!(
            "{source}: not an Eos address: write eos://HOST or eos://HOST:PORT"
        )));
    }
    // A bare host (or a bracketed IPv6 address) takes the default port.
    let has_port = match rest.rsplit_once(':') {
        Some((host, p)) => {
            !p.is_empty()
                && p.bytes().all(|b| b.is_ascii_digit())
                && (!host.contains(':') || host.ends_with(']'))
        }
        None => false,
    };
    let addr = if has_port {
        rest.to_string()
    } else {
        format!("{rest}:{port}")
    };
    Some(Ok((addr, framing)))
}

/// A connection to the Eos console.
struct EosConnection<'a> {
    source: &'a str,
    link: Link,
    /// The longest the console may be silent.
    quiet: Duration,
    /// When the whole read gives up ([`TOTAL_TIMEOUTS`] times `quiet` from the start).
    give_up: Instant,
}

impl EosConnection<'_> {
    fn send(&mut self, addresses: &[String]) -> anyhow::Result<()> {
        let messages: Vec<OscMessage> = addresses
            .iter()
            .map(|a| OscMessage {
                addr: a.clone(),
                args: Vec::new(),
            })
            .collect();
        self.link
            .send(&messages)
            .map_err(|e| anyhow::anyhow!("{}: {e}", self.source))
    }

    /// The next message, waiting at most `quiet` for it, and never past `give_up`; `what`
    /// names what is being read.
    fn next(&mut self, what: &dyn Fn() -> String) -> anyhow::Result<OscMessage> {
        let deadline = Instant::now() + self.quiet;
        let m = self
            .link
            .next(deadline.min(self.give_up))
            .map_err(|e| anyhow::anyhow!("{}: {e} while reading {}", self.source, what()))?;
        match m {
            Some(m) => Ok(m),
            None if Instant::now() >= self.give_up => bail!(
                "{}: gave up after {} s ({TOTAL_TIMEOUTS} times --timeout) reading {}: the console answers, but too slowly",
                self.source,
                (self.quiet * TOTAL_TIMEOUTS).as_secs_f64(),
                what()
            ),
            None => bail!(
                "{}: Eos stopped answering while reading {} (nothing for {} s)",
                self.source,
                what(),
                self.quiet.as_secs_f64()
            ),
        }
    }

    /// Sends index requests up to [`WINDOW`] ahead of the `done` answered ones (`sent`: how
    /// many went out), so neither side's socket buffers fill with a large show's replies
    /// while the other is still writing.
    fn request(
        &mut self,
        kind: &str,
        sent: &mut usize,
        done: usize,
        n: usize,
    ) -> anyhow::Result<()> {
        let upto = n.min(done + WINDOW);
        if *sent >= upto {
            return Ok(());
        }
        let batch: Vec<String> = (*sent..upto)
            .map(|i| format!("/eos/get/{kind}/index/{i}"))
            .collect();
        *sent = upto;
        self.send(&batch)
    }

    /// Reads replies, requesting `kind` indices ahead, until one completes a list.
    /// `select` picks the replies that are pieces of such lists (the list's key, the
    /// piece, and what the caller keeps of the address); everything else is skipped.
    /// Returns what was kept, the index the list carries (checked to be below `n`) and the
    /// list; `done` of the `n` indices are in already.
    fn next_list<T>(
        &mut self,
        kind: &str,
        lists: &mut Lists,
        sent: &mut usize,
        done: usize,
        n: usize,
        select: impl Fn(Reply) -> Option<(String, Piece, T)>,
    ) -> anyhow::Result<(T, usize, Vec<Arg>)> {
        loop {
            self.request(kind, sent, done, n)?;
            let m = self.next(&|| format!("the {kind} ({done} of {n} entries in)"))?;
            let Some((key, piece, kept)) = select(eos::reply(&m.addr)) else {
                continue;
            };
            let args = m.args.iter().map(arg).collect();
            let Some(list) = lists
                .add(&key, piece, args)
                .map_err(|e| anyhow::anyhow!("{}: {e}", self.source))?
            else {
                continue;
            };
            let Some(i) = eos::first_number(&list).filter(|&i| i < n) else {
                bail!(
                    "{}: {}: the {kind} list's index is not one of 0..{n}",
                    self.source,
                    m.addr
                );
            };
            return Ok((kept, i, list));
        }
    }

    /// Sends `count` and returns the number the console answers with, at most
    /// [`eos::MAX_ENTRIES`].
    fn count(&mut self, kind: &str) -> anyhow::Result<usize> {
        self.send(&[format!("/eos/get/{kind}/count")])?;
        let want = match kind {
            "patch" => Reply::PatchCount,
            _ => Reply::GroupCount,
        };
        loop {
            let m = self.next(&|| format!("the {kind} count"))?;
            if eos::reply(&m.addr) != want {
                continue;
            }
            let args: Vec<Arg> = m.args.iter().map(arg).collect();
            let n = eos::first_number(&args)
                .with_context(|| format!("{}: {} carries no count", self.source, m.addr))?;
            if n > eos::MAX_ENTRIES {
                let what = if kind == "patch" {
                    "channel parts"
                } else {
                    "groups"
                };
                bail!(
                    "{}: Eos reports {n} {what}; the import reads at most {}",
                    self.source,
                    eos::MAX_ENTRIES
                );
            }
            return Ok(n);
        }
    }
}

/// What a console holds: its patch and groups, and its focus palettes or why they could
/// not be read (an import without them still imports the patch).
pub struct Console {
    pub patch: EosPatch,
    pub palettes: Result<Vec<EosPalette>, String>,
}

/// Reads the console's patch, groups and focus palettes. `quiet` is the longest the
/// console may be silent.
pub fn read(
    source: &str,
    addr: &str,
    framing: Framing,
    quiet: Duration,
) -> anyhow::Result<Console> {
    let to = addr
        .to_socket_addrs()
        .with_context(|| format!("{source}: `{addr}` is not a HOST:PORT"))?
        .next()
        .with_context(|| format!("{source}: the host has no address"))?;
    let link = Link::connect(to, framing, quiet).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
    let mut c = EosConnection {
        source,
        link,
        quiet,
        give_up: Instant::now() + quiet * TOTAL_TIMEOUTS,
    };

    let n = c.count("patch")?;
    let mut sent = 0;
    let mut lists = Lists::default();
    // By index and part: should a console answer one index with several parts, none is
    // lost; the patch is in once every index has answered.
    let mut parts: BTreeMap<(usize, u32), EosChannel> = BTreeMap::new();
    let mut answered = std::collections::BTreeSet::new();
    while answered.len() < n {
        let done = answered.len();
        let ((channel, part), i, list) =
            c.next_list("patch", &mut lists, &mut sent, done, n, |r| match r {
                Reply::Patch {
                    channel,
                    part,
                    piece,
                } => Some((format!("patch/{channel}/{part}"), piece, (channel, part))),
                _ => None,
            })?;
        let entry =
            eos::patch_entry(channel, part, &list).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        answered.insert(i);
        parts.insert((i, part), entry);
    }

    let g = c.count("group")?;
    let mut sent = 0;
    // By group index: the group's number, its list, its channel list.
    let mut mains: BTreeMap<usize, (String, Vec<Arg>)> = BTreeMap::new();
    let mut members: BTreeMap<usize, Vec<Arg>> = BTreeMap::new();
    // Groups with both their lists in.
    let mut done = 0;
    while done < g {
        let ((number, channels), i, list) =
            c.next_list("group", &mut lists, &mut sent, done, g, |r| match r {
                Reply::Group {
                    number,
                    channels,
                    piece,
                } => Some((
                    format!("group/{number}/{channels}"),
                    piece,
                    (number, channels),
                )),
                _ => None,
            })?;
        let first = if channels {
            members.insert(i, list).is_none()
        } else {
            mains.insert(i, (number, list)).is_none()
        };
        if first && mains.contains_key(&i) && members.contains_key(&i) {
            done += 1;
        }
    }
    let mut groups: Vec<EosGroup> = Vec::new();
    for (i, (number, list)) in &mains {
        let channels = members.get(i).map(Vec::as_slice).unwrap_or_default();
        groups.push(
            eos::group_entry(number, list, channels)
                .map_err(|e| anyhow::anyhow!("{source}: {e}"))?,
        );
    }
    let palettes = crate::eos::palettes::read(&mut c.link, quiet);
    Ok(Console {
        patch: EosPatch {
            channels: parts.into_values().collect(),
            groups,
        },
        palettes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eos_addresses_take_the_default_port_of_their_framing() {
        let t = |s: &str| target(s).map(|r| r.map_err(|e| e.to_string()));
        assert_eq!(
            t("eos://10.0.0.5").and_then(Result::ok),
            Some(("10.0.0.5:3032".to_string(), Framing::LengthPrefix))
        );
        assert_eq!(
            t("eos+slip://desk:4000").and_then(Result::ok),
            Some(("desk:4000".to_string(), Framing::Slip))
        );
        assert_eq!(
            t("eos://[::1]").and_then(Result::ok),
            Some(("[::1]:3032".to_string(), Framing::LengthPrefix))
        );
        assert!(t("eos://").is_some_and(|r| r.is_err()));
        assert!(t("plot.mvr").is_none());
    }
}
