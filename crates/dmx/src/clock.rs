//! The sender thread: ticks at `rate_hz` with absolute deadlines, takes in the engine's
//! latest state, computes the frame (crossfade, master, blackout) and sends one packet per
//! universe per destination of its [`Wiring`]; a reload hands it a new wiring, which it
//! swaps in between two ticks.

use std::collections::HashSet;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use tokio::sync::watch;
use uuid::Uuid;

use crate::patch::SLOTS;
use crate::wire::{self, SacnSource};
use crate::wiring::{DISCOVERY_EVERY, DISCOVERY_UNIVERSE, NODE_GONE, POLL_EVERY, Wiring, route_to};
use crate::{Counters, Desired, SlotLevels, lock};
use visobjd_scene::look::Look;

/// Keep-alive bookkeeping of one universe.
#[derive(Debug, Clone, Copy, Default)]
struct Idle {
    /// Repeats of unchanged data sent so far (up to 3).
    repeats: u8,
    last_sent: Option<Instant>,
}

/// The sender thread's state.
pub(crate) struct Clock {
    rx: watch::Receiver<Desired>,
    generation: u64,
    from: SlotLevels,
    target: SlotLevels,
    fade_start: Instant,
    fade: Duration,
    master: f32,
    blackout: bool,
    wiring: Wiring,
    /// The [`Desired::rewire`] last taken in.
    rewire: u64,
    /// Where [`crate::Output::rewire`] leaves the next wiring.
    pending: Arc<Mutex<Option<Wiring>>>,
    cid: Uuid,
    /// Per universe, shared by all sACN destinations (one stream per universe per CID).
    sacn_sequence: Vec<u8>,
    /// Per universe, shared by all Art-Net destinations.
    artnet_sequence: Vec<u8>,
    idle: Vec<Idle>,
    /// The bytes last sent per universe.
    last: Vec<[u8; SLOTS]>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    buf: Vec<u8>,
    /// When discovering Art-Net destinations poll next.
    poll_due: Instant,
    /// When E1.31 universe discovery goes out next.
    discovery_due: Instant,
}

impl Clock {
    /// A clock sending `initial` through `wiring` from its first tick.
    pub(crate) fn new(
        rx: watch::Receiver<Desired>,
        wiring: Wiring,
        initial: &Look,
        pending: Arc<Mutex<Option<Wiring>>>,
        cid: Uuid,
        counters: Arc<Counters>,
        stop: Arc<AtomicBool>,
    ) -> Clock {
        let now = Instant::now();
        let target = wiring.patch.unmastered(initial);
        let n = wiring.patch.universes().len();
        Clock {
            rx,
            generation: 0,
            from: target.clone(),
            target,
            fade_start: now,
            fade: Duration::ZERO,
            master: 1.0,
            blackout: false,
            wiring,
            rewire: 0,
            pending,
            cid,
            sacn_sequence: vec![0; n],
            artnet_sequence: vec![0; n],
            idle: vec![Idle::default(); n],
            last: vec![[0; SLOTS]; n],
            counters,
            stop,
            buf: Vec::with_capacity(700),
            poll_due: now,
            discovery_due: now,
        }
    }

    pub(crate) fn run(mut self) {
        let mut next = Instant::now();
        let mut first = true;
        let mut window = (next, 0u64);
        loop {
            // Wait for the deadline; an unpark from shutdown ends the wait early.
            loop {
                if self.stop.load(Ordering::Acquire) {
                    self.terminate();
                    return;
                }
                let now = Instant::now();
                if now >= next {
                    break;
                }
                thread::park_timeout(next - now);
            }
            self.test_hooks();
            let now = Instant::now();
            let late = now.saturating_duration_since(next);
            let c = &*self.counters;
            c.worst_late_us
                .fetch_max(late.as_micros() as u64, Ordering::Relaxed);
            if late > self.wiring.period / 2 {
                c.late_ticks.fetch_add(1, Ordering::Relaxed);
            }
            let ticks = c.ticks.fetch_add(1, Ordering::Relaxed) + 1;
            let span = now.duration_since(window.0);
            if span >= Duration::from_secs(1) {
                let rate = (ticks - window.1) as f64 / span.as_secs_f64();
                c.tick_rate
                    .store((rate as f32).to_bits(), Ordering::Relaxed);
                window = (now, ticks);
            }
            if late > self.wiring.period {
                // Too late to catch up frame by frame: restart the schedule from now.
                next = now;
            }
            self.tick(now, first);
            first = false;
            next += self.wiring.period;
        }
    }

    /// The faults a test asked for: a panic, or a stall until released (or stopped).
    fn test_hooks(&self) {
        let hooks = &self.counters.hooks;
        if hooks.panic.load(Ordering::Relaxed) {
            panic!("test hook: the DMX output clock panics");
        }
        while hooks.stall.load(Ordering::Relaxed) && !self.stop.load(Ordering::Acquire) {
            thread::park_timeout(Duration::from_millis(10));
        }
    }

    /// The unmastered levels at `now`.
    fn levels_at(&self, now: Instant) -> SlotLevels {
        let elapsed = now.saturating_duration_since(self.fade_start);
        if self.fade.is_zero() || elapsed >= self.fade {
            self.target.clone()
        } else {
            let t = elapsed.as_secs_f32() / self.fade.as_secs_f32();
            self.wiring.patch.crossfade(&self.from, &self.target, t)
        }
    }

    /// Takes in the engine's latest state, if it changed.
    fn update(&mut self, now: Instant) {
        if !self.rx.has_changed().unwrap_or(false) {
            return;
        }
        let d = self.rx.borrow_and_update().clone();
        if d.rewire != self.rewire {
            self.rewire = d.rewire;
            let next = lock(&self.pending).take();
            if let Some(wiring) = next {
                self.swap(wiring);
            }
        }
        if d.generation != self.generation {
            self.from = self.levels_at(now);
            self.target = match &d.frame {
                Some(f) => (**f).clone(),
                None => self.wiring.patch.unmastered(&d.look),
            };
            self.fade_start = d.since;
            self.fade = d.fade;
            self.generation = d.generation;
        }
        self.master = d.master;
        self.blackout = d.blackout;
    }

    fn tick(&mut self, now: Instant, first: bool) {
        self.update(now);
        let wire = if self.blackout {
            self.wiring.patch.blackout()
        } else {
            self.wiring
                .patch
                .mastered(&self.levels_at(now), self.master)
        };
        let bytes = self.wiring.patch.quantise(&wire);
        let mut sent_any = false;
        for (u, data) in bytes.iter().enumerate() {
            if !self.due(u, data, now, first) {
                continue;
            }
            self.send_universe(u, data, false, now);
            self.last[u] = *data;
            self.wiring.traffic.frames[u].fetch_add(1, Ordering::Relaxed);
            sent_any = true;
        }
        if sent_any {
            self.send_syncs(now);
        }
        self.discovery(now);
    }

    /// Art-Net's poll and reply and E1.31's universe discovery: what arrived on the
    /// Art-Net sockets (non-blocking: one call that finds nothing on a quiet network), and
    /// the periodic announcements when due.
    fn discovery(&mut self, now: Instant) {
        self.receive_artnet(now);
        if now >= self.poll_due {
            self.poll_due = now + POLL_EVERY;
            let poll = wire::artpoll();
            for sink in self.wiring.artnet.iter_mut().filter(|s| s.discover) {
                sink.nodes
                    .retain(|n| now.duration_since(n.seen) < NODE_GONE);
                let packet = poll.as_deref().map_err(Clone::clone);
                sink.route.send(
                    &self.wiring.sockets,
                    &self.counters,
                    &self.wiring.traffic,
                    now,
                    sink.to,
                    packet,
                );
            }
        }
        if now >= self.discovery_due {
            self.discovery_due = now + DISCOVERY_EVERY;
            self.send_universe_discovery(now);
        }
    }

    /// Answers ArtPolls and records the nodes' ArtPollReplies, from every socket an
    /// Art-Net destination sends from.
    fn receive_artnet(&mut self, now: Instant) {
        let mut packet = [0u8; 600];
        for k in 0..self.wiring.art_sockets.len() {
            let i = self.wiring.art_sockets[k];
            // A bounded drain: a flood cannot hold the clock.
            for _ in 0..64 {
                let Ok((n, from)) = self.wiring.sockets[i].recv_from(&mut packet) else {
                    break;
                };
                match wire::parse_artnet_in(&packet[..n]) {
                    Some(wire::ArtIn::Poll) => self.answer_poll(i, from, now),
                    Some(wire::ArtIn::Reply {
                        bind_index,
                        outputs,
                    }) => {
                        for sink in self
                            .wiring
                            .artnet
                            .iter_mut()
                            .filter(|s| s.discover && s.route.socket == i)
                        {
                            sink.found(from.ip(), bind_index, &outputs, now);
                        }
                    }
                    None => {}
                }
            }
        }
    }

    /// ArtPollReply to whoever polled socket `i`, for every destination sending from it,
    /// back to the poller's address and port (6454 for Art-Net gear, which sends from it).
    fn answer_poll(&mut self, i: usize, from: SocketAddr, now: Instant) {
        let ip = match self.wiring.sockets[i].local_addr().map(|a| a.ip()) {
            Ok(IpAddr::V4(ip)) if !ip.is_unspecified() => ip,
            _ => route_to(from),
        };
        for sink in self
            .wiring
            .artnet
            .iter_mut()
            .filter(|s| s.route.socket == i)
        {
            match wire::artpollreplies(ip, &sink.port_addresses) {
                Ok(replies) => {
                    for reply in &replies {
                        sink.route.send(
                            &self.wiring.sockets,
                            &self.counters,
                            &self.wiring.traffic,
                            now,
                            from,
                            Ok(reply),
                        );
                    }
                }
                Err(e) => sink.route.send(
                    &self.wiring.sockets,
                    &self.counters,
                    &self.wiring.traffic,
                    now,
                    from,
                    Err(e),
                ),
            }
        }
    }

    /// E1.31 universe discovery (E1.31-2018 8): every universe this source sends, in
    /// pages of 512, to each sACN destination: the discovery universe's multicast group,
    /// or the unicast receiver.
    fn send_universe_discovery(&mut self, now: Instant) {
        let universes = self.wiring.patch.universes().to_vec();
        let pages: Vec<&[u16]> = universes.chunks(wire::DISCOVERY_PAGE).collect();
        let last = (pages.len().max(1) - 1).min(255) as u8;
        for sink in &mut self.wiring.sacn {
            let to = sink.address(DISCOVERY_UNIVERSE);
            for (page, list) in pages.iter().enumerate().take(256) {
                let packet = wire::sacn_discovery(
                    self.cid,
                    &sink.source_name,
                    page as u8,
                    last,
                    list,
                    &mut self.buf,
                )
                .map(|()| self.buf.as_slice());
                sink.route.send(
                    &self.wiring.sockets,
                    &self.counters,
                    &self.wiring.traffic,
                    now,
                    to,
                    packet,
                );
            }
        }
    }

    /// Whether universe `u` goes out this tick (always, unless keep-alive is idling it).
    fn due(&mut self, u: usize, data: &[u8; SLOTS], now: Instant, first: bool) -> bool {
        let idle = &mut self.idle[u];
        let send = if !self.wiring.keepalive || first || *data != self.last[u] {
            idle.repeats = 0;
            true
        } else if idle.repeats < 3 {
            idle.repeats += 1;
            true
        } else {
            idle.last_sent
                .is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1))
        };
        if send {
            idle.last_sent = Some(now);
        }
        send
    }

    fn send_universe(&mut self, u: usize, data: &[u8; SLOTS], terminated: bool, now: Instant) {
        self.send_sacn(u, data, terminated, now, |_| true);
        if terminated || self.wiring.artnet.is_empty() {
            return;
        }
        self.artnet_sequence[u] = wire::next_artnet_sequence(self.artnet_sequence[u]);
        let seq = self.artnet_sequence[u];
        for sink in &mut self.wiring.artnet {
            let pa = sink.port_addresses[u];
            let packet = wire::artdmx(pa, seq, data);
            let packet = packet.as_deref().map_err(Clone::clone);
            let mut to_node = |to| {
                sink.route.send(
                    &self.wiring.sockets,
                    &self.counters,
                    &self.wiring.traffic,
                    now,
                    to,
                    packet.clone(),
                )
            };
            if sink.discover {
                for node in sink.nodes.iter().filter(|n| n.outputs.contains(&pa)) {
                    to_node(SocketAddr::new(node.ip, sink.to.port()));
                }
            } else {
                to_node(sink.to);
            }
        }
    }

    /// Universe `u`'s sACN packet to every destination whose address `to` wants.
    fn send_sacn(
        &mut self,
        u: usize,
        data: &[u8; SLOTS],
        terminated: bool,
        now: Instant,
        to: impl Fn(SocketAddr) -> bool,
    ) {
        let universe = self.wiring.patch.universes()[u];
        self.sacn_sequence[u] = wire::next_sacn_sequence(self.sacn_sequence[u]);
        let seq = self.sacn_sequence[u];
        for sink in self
            .wiring
            .sacn
            .iter_mut()
            .filter(|s| to(s.address(universe)))
        {
            let dest = sink.address(universe);
            let src = SacnSource {
                cid: self.cid,
                source_name: &sink.source_name,
                priority: sink.priority,
                sync_universe: sink.sync_universe,
            };
            let packet = wire::sacn_data(&src, universe, seq, terminated, data, &mut self.buf)
                .map(|()| self.buf.as_slice());
            sink.route.send(
                &self.wiring.sockets,
                &self.counters,
                &self.wiring.traffic,
                now,
                dest,
                packet,
            );
        }
    }

    /// One synchronization packet per sACN destination with a sync universe, after a frame.
    fn send_syncs(&mut self, now: Instant) {
        for sink in self.wiring.sacn.iter_mut().filter(|s| s.sync_universe != 0) {
            sink.sync_sequence = wire::next_sacn_sequence(sink.sync_sequence);
            let to = sink.address(sink.sync_universe);
            let packet = wire::sacn_sync(
                self.cid,
                sink.sync_universe,
                sink.sync_sequence,
                &mut self.buf,
            )
            .map(|()| self.buf.as_slice());
            sink.route.send(
                &self.wiring.sockets,
                &self.counters,
                &self.wiring.traffic,
                now,
                to,
                packet,
            );
        }
    }

    /// Sends through `new` from now on (a reload). The streams both send (an sACN
    /// destination and universe, an Art-Net universe) go on with their sequence numbers and
    /// last data, so receivers see one source throughout; those `new` no longer sends end
    /// with Stream_Terminated as at shutdown; discovering Art-Net destinations keep the
    /// nodes they found.
    fn swap(&mut self, mut new: Wiring) {
        let now = Instant::now();
        new.traffic.carry(&self.wiring.traffic);
        let kept: HashSet<(SocketAddr, u16)> = new
            .sacn
            .iter()
            .flat_map(|s| {
                new.patch
                    .universes()
                    .iter()
                    .map(move |&u| (s.address(u), u))
            })
            .collect();
        for _ in 0..3 {
            for u in 0..self.last.len() {
                let universe = self.wiring.patch.universes()[u];
                let data = self.last[u];
                self.send_sacn(u, &data, true, now, |to| !kept.contains(&(to, universe)));
            }
        }
        let old = self.wiring.patch.universes().to_vec();
        let carry = |i: Option<usize>, from: &[u8]| i.map_or(0, |i| from[i]);
        let index: Vec<Option<usize>> = new
            .patch
            .universes()
            .iter()
            .map(|u| old.iter().position(|o| o == u))
            .collect();
        self.sacn_sequence = index
            .iter()
            .map(|&i| carry(i, &self.sacn_sequence))
            .collect();
        self.artnet_sequence = index
            .iter()
            .map(|&i| carry(i, &self.artnet_sequence))
            .collect();
        self.last = index
            .iter()
            .map(|&i| i.map_or([0; SLOTS], |i| self.last[i]))
            .collect();
        self.idle = vec![Idle::default(); index.len()];
        for sink in new.artnet.iter_mut().filter(|s| s.discover) {
            if let Some(old) = self
                .wiring
                .artnet
                .iter_mut()
                .find(|o| o.discover && o.to == sink.to)
            {
                sink.nodes = std::mem::take(&mut old.nodes);
            }
        }
        self.wiring = new;
        // Announce the new universes at once rather than within 10 s.
        self.discovery_due = now;
    }

    /// E1.31 6.2.6: three packets with Stream_Terminated per universe, so receivers
    /// release the universe at once instead of holding the last look for 2.5 s.
    fn terminate(&mut self) {
        let now = Instant::now();
        for _ in 0..3 {
            for u in 0..self.last.len() {
                let data = self.last[u];
                self.send_universe(u, &data, true, now);
            }
        }
    }
}
