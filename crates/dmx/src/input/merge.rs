//! The E1.31 receiver's merge, pure: packets in with the time they arrived, merged DMX per
//! universe out. No clock and no socket, so tests drive it packet by packet.
//!
//! The rules (E1.31-2018 and ETC's per-address priority, as consoles use them):
//! - a stream is one source (CID) on one universe; visobjd's own CID, preview data and
//!   universes not listened to are ignored;
//! - sequence numbers per stream: a packet whose number is 0 to 19 behind the last one
//!   taken is dropped as late (6.7.2);
//! - Stream_Terminated drops the stream at once;
//! - a stream is lost [`SOURCE_LOSS`] after its last level (0x00) packet, whatever else it
//!   still sends; its 0xDD priorities lapse the same time after their last packet;
//! - a new stream counts only once it has been seen for [`SAMPLE`] (ETC's receiver samples
//!   a new source for as long): its 0xDD packet (sent about once a second) has then had
//!   time to arrive, so its levels never flash in at the universe priority first, and a
//!   source that only passes through never reaches the stage;
//! - per slot, the highest priority wins and equal priorities merge highest-takes-
//!   precedence; a slot's priority is the stream's 0xDD value for it (0: the stream does
//!   not source that slot) while its 0xDD is current, else the universe priority; slots
//!   past the end of a short level packet are not sourced; a slot nobody sources is 0.
//! - 0xDD slots are only ever priorities and 0x00 slots only ever levels; other start
//!   codes (text, test packets) only advance the sequence.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use uuid::Uuid;

use super::packet::{DataPacket, LEVELS, PER_ADDRESS_PRIORITY};
use crate::patch::SLOTS;

/// A stream is lost this long after its last level packet (E1.31 `E131_NETWORK_DATA_LOSS_TIMEOUT`).
pub const SOURCE_LOSS: Duration = Duration::from_millis(2500);

/// A new stream counts in the merge once it has been seen this long.
pub const SAMPLE: Duration = Duration::from_millis(1500);

/// A packet within this many sequence numbers behind the last one is late (6.7.2).
const SEQUENCE_WINDOW: i8 = -20;

/// What the merge did with a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Levels or priorities taken.
    Taken,
    /// visobjd's own output, looped back.
    Own,
    /// Preview data (not for live output).
    Preview,
    /// A universe the input does not listen to.
    NotListened,
    /// Late: its sequence number is within 20 behind the last one taken.
    OutOfSequence,
    /// Stream_Terminated: the stream was dropped.
    Terminated,
    /// A start code other than 0x00 and 0xDD: only its sequence number counts.
    OtherStartCode,
    /// A new stream while [`MAX_STREAMS`] are tracked: dropped (a flood of made-up CIDs
    /// cannot grow the merge without bound).
    TooMany,
}

/// The most streams (source and universe) tracked at once: a console, a backup console and
/// a few more per universe fit many times over.
pub const MAX_STREAMS: usize = 256;

/// One source on one universe.
#[derive(Debug, Clone)]
struct Stream {
    name: String,
    /// Universe priority of its level packets.
    priority: u8,
    first_seen: Instant,
    last_packet: Instant,
    sequence: u8,
    /// Its latest level slots and when they came.
    levels: Option<(Vec<u8>, Instant)>,
    /// Its latest per-address priorities and when they came.
    priorities: Option<(Vec<u8>, Instant)>,
}

impl Stream {
    /// Whether it counts in the merge at `now`: sampled, with current levels.
    fn active(&self, now: Instant) -> bool {
        now.saturating_duration_since(self.first_seen) >= SAMPLE
            && self
                .levels
                .as_ref()
                .is_some_and(|(_, at)| now.saturating_duration_since(*at) < SOURCE_LOSS)
    }

    /// The priority it sources `slot` at, `None` where it does not source it.
    fn slot_priority(&self, slot: usize, levels: &[u8], now: Instant) -> Option<u8> {
        if slot >= levels.len() {
            return None;
        }
        match &self.priorities {
            Some((p, at)) if now.saturating_duration_since(*at) < SOURCE_LOSS => {
                p.get(slot).copied().filter(|&v| v > 0)
            }
            _ => Some(self.priority),
        }
    }
}

/// A console source as status shows it: one CID over its universes.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceInfo {
    /// Its CID.
    pub cid: Uuid,
    /// Its source name.
    pub name: String,
    /// Its highest universe priority.
    pub priority: u8,
    /// The listened universes it sends, ascending.
    pub universes: Vec<u16>,
    /// Time since its last packet of any kind.
    pub age: Duration,
    /// Whether it counts in the merge now (false while it is sampled).
    pub active: bool,
}

/// The merge state of every stream of the listened universes.
#[derive(Debug, Clone)]
pub struct Merger {
    own: Uuid,
    universes: Vec<u16>,
    /// By (universe, CID).
    streams: BTreeMap<(u16, Uuid), Stream>,
}

impl Merger {
    /// A merge of `universes` that ignores packets from `own` (visobjd's CID).
    pub fn new(own: Uuid, universes: &[u16]) -> Merger {
        Merger {
            own,
            universes: universes.to_vec(),
            streams: BTreeMap::new(),
        }
    }

    /// Takes one packet that arrived at `now`.
    pub fn receive(&mut self, p: &DataPacket, now: Instant) -> Verdict {
        if p.cid == self.own {
            return Verdict::Own;
        }
        if !self.universes.contains(&p.universe) {
            return Verdict::NotListened;
        }
        if p.preview {
            return Verdict::Preview;
        }
        let key = (p.universe, p.cid);
        if let Some(s) = self.streams.get(&key)
            && (SEQUENCE_WINDOW + 1..=0).contains(&(p.sequence.wrapping_sub(s.sequence) as i8))
        {
            return Verdict::OutOfSequence;
        }
        if p.terminated {
            self.streams.remove(&key);
            return Verdict::Terminated;
        }
        if p.start_code != LEVELS && p.start_code != PER_ADDRESS_PRIORITY {
            if let Some(s) = self.streams.get_mut(&key) {
                s.sequence = p.sequence;
                s.last_packet = now;
            }
            return Verdict::OtherStartCode;
        }
        if !self.streams.contains_key(&key) && self.streams.len() >= MAX_STREAMS {
            return Verdict::TooMany;
        }
        let s = self.streams.entry(key).or_insert_with(|| Stream {
            name: p.source_name.clone(),
            priority: p.priority,
            first_seen: now,
            last_packet: now,
            sequence: p.sequence,
            levels: None,
            priorities: None,
        });
        s.sequence = p.sequence;
        s.last_packet = now;
        s.name.clone_from(&p.source_name);
        if p.start_code == LEVELS {
            s.priority = p.priority;
            s.levels = Some((p.slots.clone(), now));
        } else {
            s.priorities = Some((p.slots.clone(), now));
        }
        Verdict::Taken
    }

    /// Drops the streams lost at `now`: no level packet for [`SOURCE_LOSS`] (or none at all
    /// since they were first seen that long ago).
    pub fn expire(&mut self, now: Instant) {
        self.streams.retain(|_, s| {
            let since = s.levels.as_ref().map_or(s.first_seen, |(_, at)| *at);
            now.saturating_duration_since(since) < SOURCE_LOSS
        });
    }

    /// The merged slots of `universe` at `now`, or `None` when no stream counts there.
    pub fn merged(&self, universe: u16, now: Instant) -> Option<[u8; SLOTS]> {
        let active: Vec<(&Stream, &[u8])> = self
            .streams
            .range((universe, Uuid::nil())..=(universe, Uuid::max()))
            .map(|(_, s)| s)
            .filter(|s| s.active(now))
            .filter_map(|s| s.levels.as_ref().map(|(l, _)| (s, l.as_slice())))
            .collect();
        if active.is_empty() {
            return None;
        }
        let mut out = [0u8; SLOTS];
        for (slot, byte) in out.iter_mut().enumerate() {
            let mut best: Option<(u8, u8)> = None;
            for (s, levels) in &active {
                let Some(p) = s.slot_priority(slot, levels, now) else {
                    continue;
                };
                let level = levels[slot];
                best = match best {
                    Some((bp, _)) if p < bp => best,
                    Some((bp, bl)) if p == bp => Some((p, bl.max(level))),
                    _ => Some((p, level)),
                };
            }
            *byte = best.map_or(0, |(_, level)| level);
        }
        Some(out)
    }

    /// The sources seen (not lost) at `now`, by CID: streams that have sent levels (a
    /// stream of 0xDD packets alone sources nothing).
    pub fn sources(&self, now: Instant) -> Vec<SourceInfo> {
        let mut by_cid: BTreeMap<Uuid, SourceInfo> = BTreeMap::new();
        for (&(universe, cid), s) in self.streams.iter().filter(|(_, s)| s.levels.is_some()) {
            let age = now.saturating_duration_since(s.last_packet);
            let info = by_cid.entry(cid).or_insert_with(|| SourceInfo {
                cid,
                name: s.name.clone(),
                priority: s.priority,
                universes: Vec::new(),
                age,
                active: false,
            });
            info.priority = info.priority.max(s.priority);
            info.universes.push(universe);
            if age <= info.age {
                info.age = age;
                info.name.clone_from(&s.name);
            }
            info.active |= s.active(now);
        }
        by_cid.into_values().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONSOLE: Uuid = Uuid::from_bytes([1; 16]);
    const BACKUP: Uuid = Uuid::from_bytes([2; 16]);
    const THIRD: Uuid = Uuid::from_bytes([3; 16]);
    const OWN: Uuid = Uuid::from_bytes([9; 16]);

    fn ms(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    fn packet(
        cid: Uuid,
        universe: u16,
        priority: u8,
        seq: u8,
        start: u8,
        slots: &[u8],
    ) -> DataPacket {
        DataPacket {
            cid,
            source_name: format!("src {}", cid.as_bytes()[0]),
            priority,
            sequence: seq,
            preview: false,
            terminated: false,
            universe,
            start_code: start,
            slots: slots.to_vec(),
        }
    }

    fn levels(cid: Uuid, priority: u8, seq: u8, slots: &[u8]) -> DataPacket {
        packet(cid, 1, priority, seq, LEVELS, slots)
    }

    fn dd(cid: Uuid, seq: u8, slots: &[u8]) -> DataPacket {
        packet(cid, 1, 100, seq, PER_ADDRESS_PRIORITY, slots)
    }

    /// A merger whose sources are past their sample time at `t0 + 2 s`.
    fn merger() -> (Merger, Instant) {
        (Merger::new(OWN, &[1, 2]), Instant::now())
    }

    fn first(m: &Merger, at: Instant, n: usize) -> Vec<u8> {
        m.merged(1, at).expect("a source counts")[..n].to_vec()
    }

    #[test]
    fn highest_priority_wins_and_equal_priorities_merge_htp() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10, 200, 30]), t0);
        m.receive(&levels(BACKUP, 90, 0, &[250, 250, 250]), t0);
        assert_eq!(first(&m, ms(t0, 1600), 3), [10, 200, 30], "100 beats 90");
        m.receive(&levels(BACKUP, 100, 1, &[250, 5, 31]), ms(t0, 1700));
        assert_eq!(first(&m, ms(t0, 1700), 3), [250, 200, 31], "HTP at 100");
        m.receive(&levels(BACKUP, 101, 2, &[1, 2, 3]), ms(t0, 1800));
        assert_eq!(
            first(&m, ms(t0, 1800), 3),
            [1, 2, 3],
            "101 takes every slot"
        );
    }

    #[test]
    fn per_address_priority_is_per_slot_and_zero_is_not_sourced() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10, 20, 30, 40]), t0);
        m.receive(&dd(CONSOLE, 1, &[0, 100, 50, 150]), t0);
        m.receive(&levels(BACKUP, 100, 0, &[99, 99, 99, 99]), t0);
        // slot 0: only the backup sources it; slot 1: HTP at 100; slot 2: backup's 100 beats
        // the console's 50; slot 3: the console's 150 wins.
        // Slot 4: past both level packets, nobody sources it.
        assert_eq!(first(&m, ms(t0, 1600), 5), [99, 99, 99, 40, 0]);
        // The backup now sources slot 0 only: the console's 0xDD values rule the rest.
        m.receive(&levels(BACKUP, 100, 1, &[99]), ms(t0, 1700));
        assert_eq!(first(&m, ms(t0, 1700), 5), [99, 20, 30, 40, 0]);
    }

    #[test]
    fn per_address_priorities_lapse_2_5_s_after_their_last_packet() {
        let (mut m, t0) = merger();
        m.receive(&dd(CONSOLE, 0, &[50]), t0);
        m.receive(&levels(CONSOLE, 100, 1, &[10]), t0);
        m.receive(&levels(BACKUP, 80, 0, &[77]), t0);
        assert_eq!(first(&m, ms(t0, 1600), 1), [77], "0xDD 50 loses to 80");
        m.receive(&levels(CONSOLE, 100, 2, &[10]), ms(t0, 2000));
        m.receive(&levels(BACKUP, 80, 1, &[77]), ms(t0, 2000));
        assert_eq!(first(&m, ms(t0, 2499), 1), [77]);
        assert_eq!(
            first(&m, ms(t0, 2500), 1),
            [10],
            "back at its universe priority 100"
        );
    }

    #[test]
    fn levels_and_priorities_are_never_confused() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10, 20]), t0);
        m.receive(&dd(CONSOLE, 1, &[200, 200]), t0);
        assert_eq!(
            first(&m, ms(t0, 1600), 2),
            [10, 20],
            "0xDD values are not levels"
        );
        // A source that sends only 0xDD never counts, however long it lasts, and is not
        // listed as a source.
        m.receive(&dd(THIRD, 0, &[255, 255]), t0);
        assert_eq!(first(&m, ms(t0, 1600), 2), [10, 20]);
        assert!(m.sources(ms(t0, 1600)).iter().all(|s| s.cid != THIRD));
        // Levels of 1 are not read as priorities: slot priorities stay 200.
        m.receive(&levels(CONSOLE, 100, 2, &[1, 1]), ms(t0, 1700));
        m.receive(&levels(BACKUP, 150, 1, &[7, 7]), ms(t0, 1700));
        assert_eq!(first(&m, ms(t0, 1700), 2), [1, 1], "0xDD 200 beats 150");
    }

    #[test]
    fn a_source_is_lost_after_2_5_s_without_levels_even_with_0xdd() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10]), t0);
        m.receive(&levels(BACKUP, 50, 0, &[77]), t0);
        for (seq, t) in (1..).zip((0..=3000).step_by(500)) {
            m.receive(&dd(CONSOLE, seq, &[200]), ms(t0, t));
            m.receive(&levels(BACKUP, 50, seq, &[77]), ms(t0, t));
        }
        assert_eq!(first(&m, ms(t0, 2499), 1), [10]);
        assert_eq!(first(&m, ms(t0, 2500), 1), [77], "lost at 2.5 s");
        m.expire(ms(t0, 3000));
        let names: Vec<String> = m
            .sources(ms(t0, 3000))
            .into_iter()
            .map(|s| s.name)
            .collect();
        assert_eq!(names, ["src 2"], "dropped from the sources");
        // Back, it is a new stream: sampled again, and without its old 0xDD, at its
        // universe priority 40.
        m.receive(&levels(CONSOLE, 40, 9, &[10]), ms(t0, 3000));
        assert_eq!(first(&m, ms(t0, 4600), 1), [77], "back, sampled, at its 40");
    }

    #[test]
    fn a_new_source_is_sampled_before_it_counts() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10]), t0);
        assert_eq!(m.merged(1, ms(t0, 1499)), None, "sampling");
        assert!(!m.sources(ms(t0, 1499))[0].active);
        assert_eq!(first(&m, ms(t0, 1500), 1), [10]);
        // A higher-priority newcomer takes over only after its own sample time.
        m.receive(&levels(CONSOLE, 100, 1, &[10]), ms(t0, 2000));
        m.receive(&levels(BACKUP, 150, 0, &[200]), ms(t0, 2000));
        m.receive(&levels(CONSOLE, 100, 2, &[10]), ms(t0, 3000));
        m.receive(&levels(BACKUP, 150, 1, &[200]), ms(t0, 3000));
        assert_eq!(first(&m, ms(t0, 3499), 1), [10]);
        assert_eq!(first(&m, ms(t0, 3500), 1), [200]);
    }

    #[test]
    fn late_packets_within_the_window_are_dropped() {
        let (mut m, t0) = merger();
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 250, &[1]), t0),
            Verdict::Taken
        );
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 250, &[2]), t0),
            Verdict::OutOfSequence,
            "a repeat"
        );
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 240, &[3]), t0),
            Verdict::OutOfSequence,
            "10 behind"
        );
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 4, &[4]), t0),
            Verdict::Taken,
            "wraps forward"
        );
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 245, &[5]), t0),
            Verdict::OutOfSequence,
            "15 behind"
        );
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 240, &[6]), t0),
            Verdict::Taken,
            "20 behind is outside the window (a restarted source)"
        );
        assert_eq!(first(&m, ms(t0, 1600), 1), [6]);
        // Sequences are per universe: universe 2's numbers do not matter on universe 1.
        let mut u2 = levels(CONSOLE, 100, 239, &[8]);
        u2.universe = 2;
        assert_eq!(m.receive(&u2, t0), Verdict::Taken);
    }

    #[test]
    fn termination_preview_and_own_cid() {
        let (mut m, t0) = merger();
        m.receive(&levels(CONSOLE, 100, 0, &[10]), t0);
        m.receive(&levels(BACKUP, 90, 0, &[20]), t0);
        assert_eq!(m.receive(&levels(OWN, 200, 0, &[255]), t0), Verdict::Own);
        let mut preview = levels(BACKUP, 200, 1, &[255]);
        preview.preview = true;
        assert_eq!(m.receive(&preview, t0), Verdict::Preview);
        let mut other = levels(CONSOLE, 200, 1, &[255]);
        other.universe = 3;
        assert_eq!(m.receive(&other, t0), Verdict::NotListened);
        assert_eq!(
            m.receive(&packet(CONSOLE, 1, 200, 1, 0x17, &[255]), t0),
            Verdict::OtherStartCode
        );
        assert_eq!(first(&m, ms(t0, 1600), 1), [10]);
        let mut end = levels(CONSOLE, 100, 2, &[10]);
        end.terminated = true;
        assert_eq!(m.receive(&end, ms(t0, 1600)), Verdict::Terminated);
        assert_eq!(first(&m, ms(t0, 1600), 1), [20], "dropped at once");
        let s = m.sources(ms(t0, 1700));
        assert_eq!(
            (s.len(), s[0].cid, s[0].priority, s[0].universes.as_slice()),
            (1, BACKUP, 90, &[1u16][..])
        );
        assert_eq!(s[0].age, Duration::from_millis(1700));
    }

    #[test]
    fn a_flood_of_new_cids_is_bounded_and_known_sources_go_on() {
        let t0 = Instant::now();
        let mut m = Merger::new(OWN, &[1]);
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 1, &[200]), t0),
            Verdict::Taken
        );
        let mut refused = 0;
        for i in 0..1000u32 {
            let mut cid = [0u8; 16];
            cid[..4].copy_from_slice(&(i + 1000).to_be_bytes());
            if m.receive(&levels(Uuid::from_bytes(cid), 100, 1, &[9]), t0) == Verdict::TooMany {
                refused += 1;
            }
        }
        assert_eq!(refused, 1000 - (MAX_STREAMS - 1));
        // The console, already tracked, is still taken.
        assert_eq!(
            m.receive(&levels(CONSOLE, 100, 2, &[201]), t0),
            Verdict::Taken
        );
    }
}
