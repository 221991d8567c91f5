//! Connection slots shared out by host, for the OSC TCP listener and the web page
//! (docs/security.md): one host cannot take every slot, however many connections it opens.
//!
//! The rules, checked when a connection is accepted ([`Slots::admit`]):
//!
//! - A host has at most `per_host` connections open. One more from it takes the place of
//!   its own oldest idle one (a browser keeps idle keep-alive connections, a client that
//!   reconnects leaves dead ones behind); when none of its connections is idle it is
//!   refused.
//! - When every slot is taken, a newcomer from a host with fewer connections than another
//!   takes a slot from the host with the most: that host's oldest idle connection is
//!   closed, or, when none is idle, its oldest stream (the web page's event stream, which
//!   the browser opens again). A connection in the middle of a request is never closed.
//! - A reserved host (the configured backup and `[[osc.peer]]` consoles) is never refused
//!   for want of a free slot while another host has a connection to give up, and its own
//!   connections are never given up for another host.
//! - A host has at most `streams_per_host` streams at once: a further one closes its
//!   oldest ([`Slot::stream`]).
//!
//! "Idle" is a connection that is neither in a request ([`Slot::busy`]) nor a stream; of two,
//! the one whose last request ended (or which connected) longer ago is the older. Hosts are
//! IP addresses as the caller gives them (the web page counts every loopback address as
//! one).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use tokio::sync::Notify;

/// How the slots are shared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Connections open at once, all hosts together.
    pub total: usize,
    /// Connections one host may have open.
    pub per_host: usize,
    /// Streams one host may have open (each also a connection).
    pub streams_per_host: usize,
}

/// Why a connection was refused: a sentence for the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refused {
    /// Its host has its share open, none of them idle.
    HostFull { host: IpAddr, open: usize },
    /// Every slot is taken and no host has one to give up for it.
    Full { open: usize },
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refused::HostFull { host, open } => write!(
                f,
                "{host} already has {open} connections open, none of them idle (each in a request or a stream)"
            ),
            Refused::Full { open } => write!(
                f,
                "all {open} connections are taken and no host has more than this one's, or one to give up"
            ),
        }
    }
}

/// A connection admitted, and the host of the one closed to make room for it, if any.
#[derive(Debug)]
pub struct Admitted {
    pub slot: Arc<Slot>,
    pub made_room: Option<IpAddr>,
}

/// The connections open, by host.
#[derive(Debug)]
pub struct Slots {
    limits: Limits,
    table: Mutex<Table>,
}

#[derive(Debug, Default)]
struct Table {
    next: u64,
    open: HashMap<u64, Entry>,
}

#[derive(Debug)]
struct Entry {
    host: IpAddr,
    reserved: bool,
    /// Requests in progress.
    busy: u32,
    stream: bool,
    /// When it last became idle (its last request ended, it connected), or its stream began.
    since: Instant,
    close: Arc<Notify>,
}

impl Entry {
    /// The order connections are given up in: idle ones first, then streams, oldest first;
    /// `None`: not to be given up (in a request).
    fn rank(&self) -> Option<(u8, Instant)> {
        match (self.busy, self.stream) {
            (0, false) => Some((0, self.since)),
            (_, true) => Some((1, self.since)),
            _ => None,
        }
    }
}

impl Slots {
    pub fn new(limits: Limits) -> Arc<Slots> {
        Arc::new(Slots {
            limits,
            table: Mutex::new(Table::default()),
        })
    }

    pub fn limits(&self) -> Limits {
        self.limits
    }

    fn table(&self) -> MutexGuard<'_, Table> {
        self.table.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Connections open now.
    pub fn open(&self) -> usize {
        self.table().open.len()
    }

    /// Admits a connection from `host` at `now` by the rules above (module header), closing
    /// another to make room when they say so; Err says why not.
    pub fn admit(
        self: &Arc<Self>,
        host: IpAddr,
        reserved: bool,
        now: Instant,
    ) -> Result<Admitted, Refused> {
        let mut t = self.table();
        let mut counts: HashMap<IpAddr, usize> = HashMap::new();
        for e in t.open.values() {
            *counts.entry(e.host).or_default() += 1;
        }
        let mine = counts.get(&host).copied().unwrap_or(0);
        let victim = if mine >= self.limits.per_host {
            // Its own oldest idle one: never its stream (a page of its own), nor one in a
            // request.
            let own = t
                .open
                .iter()
                .filter(|(_, e)| e.host == host)
                .filter_map(|(id, e)| Some((e.rank().filter(|r| r.0 == 0)?, *id)))
                .min();
            match own {
                Some((_, id)) => Some(id),
                None => return Err(Refused::HostFull { host, open: mine }),
            }
        } else if t.open.len() >= self.limits.total {
            // The host with the most gives up its oldest idle connection (or stream).
            let other = t
                .open
                .iter()
                .filter(|(_, e)| e.host != host && !e.reserved)
                .filter(|(_, e)| reserved || counts[&e.host] > mine)
                .filter_map(|(id, e)| {
                    let rank = e.rank()?;
                    Some((std::cmp::Reverse(counts[&e.host]), rank, *id))
                })
                .min();
            match other {
                Some((_, _, id)) => Some(id),
                None => {
                    return Err(Refused::Full { open: t.open.len() });
                }
            }
        } else {
            None
        };
        let made_room = victim.and_then(|id| t.open.remove(&id)).map(|e| {
            e.close.notify_one();
            e.host
        });
        let id = t.next;
        t.next += 1;
        let close = Arc::new(Notify::new());
        t.open.insert(
            id,
            Entry {
                host,
                reserved,
                busy: 0,
                stream: false,
                since: now,
                close: Arc::clone(&close),
            },
        );
        drop(t);
        Ok(Admitted {
            slot: Arc::new(Slot {
                id,
                host,
                slots: Arc::clone(self),
                close,
            }),
            made_room,
        })
    }
}

/// One admitted connection's slot: it is given back when dropped.
#[derive(Debug)]
pub struct Slot {
    id: u64,
    host: IpAddr,
    slots: Arc<Slots>,
    close: Arc<Notify>,
}

impl Slot {
    /// The host it was admitted for.
    pub fn host(&self) -> IpAddr {
        self.host
    }

    /// Resolves once the connection must close: its slot was given to another.
    pub async fn closed(&self) {
        self.close.notified().await;
    }

    /// Marks a request in progress until the guard is dropped: a connection in a request
    /// is never closed for another.
    pub fn busy(self: &Arc<Self>) -> Busy {
        if let Some(e) = self.slots.table().open.get_mut(&self.id) {
            e.busy += 1;
        }
        Busy(Arc::clone(self))
    }

    /// Marks the connection a stream until the guard is dropped, closing its host's oldest
    /// stream when the host had its share of them already.
    pub fn stream(self: &Arc<Self>, now: Instant) -> Stream {
        let limit = self.slots.limits.streams_per_host;
        let mut t = self.slots.table();
        if let Some(e) = t.open.get_mut(&self.id) {
            e.stream = true;
            e.since = now;
        }
        let mut streams: Vec<(Instant, u64)> = t
            .open
            .iter()
            .filter(|(_, e)| e.host == self.host && e.stream)
            .map(|(id, e)| (e.since, *id))
            .collect();
        streams.sort();
        let over = streams.len().saturating_sub(limit);
        for &(_, id) in streams.iter().filter(|s| s.1 != self.id).take(over) {
            if let Some(e) = t.open.remove(&id) {
                e.close.notify_one();
            }
        }
        drop(t);
        Stream(Arc::clone(self))
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.slots.table().open.remove(&self.id);
    }
}

/// A request in progress ([`Slot::busy`]).
#[derive(Debug)]
pub struct Busy(Arc<Slot>);

impl Drop for Busy {
    fn drop(&mut self) {
        let slot = &self.0;
        if let Some(e) = slot.slots.table().open.get_mut(&slot.id) {
            e.busy = e.busy.saturating_sub(1);
            if e.busy == 0 && !e.stream {
                e.since = Instant::now();
            }
        }
    }
}

/// A stream in progress ([`Slot::stream`]).
#[derive(Debug)]
pub struct Stream(Arc<Slot>);

impl Drop for Stream {
    fn drop(&mut self) {
        let slot = &self.0;
        if let Some(e) = slot.slots.table().open.get_mut(&slot.id) {
            e.stream = false;
            e.since = Instant::now();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn ip(last: u8) -> IpAddr {
        IpAddr::from([10, 0, 0, last])
    }

    const LIMITS: Limits = Limits {
        total: 6,
        per_host: 3,
        streams_per_host: 2,
    };

    /// Admits `n` connections from `host`, a millisecond apart from `t`.
    fn fill(s: &Arc<Slots>, host: IpAddr, n: usize, t: &mut Instant) -> Vec<Arc<Slot>> {
        (0..n)
            .map(|_| {
                *t += Duration::from_millis(1);
                s.admit(host, false, *t).expect("admitted").slot
            })
            .collect()
    }

    fn closed(slot: &Slot) -> bool {
        !slot.slots.table().open.contains_key(&slot.id)
    }

    #[test]
    fn a_host_over_its_share_gives_up_its_own_oldest_idle_connection() {
        let s = Slots::new(LIMITS);
        let mut t = Instant::now();
        let a = fill(&s, ip(1), 3, &mut t);
        let _in_a_request = a[0].busy();
        let more = s.admit(ip(1), false, t).expect("admitted");
        assert_eq!(more.made_room, Some(ip(1)));
        // Not the oldest, which is in a request: the next oldest.
        assert!(!closed(&a[0]) && closed(&a[1]) && !closed(&a[2]));
        assert_eq!(s.open(), 3);
        // The others busy or streams: refused.
        let _b = a[2].busy();
        let _s = more.slot.stream(t);
        assert_eq!(
            s.admit(ip(1), false, t).unwrap_err(),
            Refused::HostFull {
                host: ip(1),
                open: 3
            }
        );
    }

    #[test]
    fn when_full_the_host_with_the_most_makes_room() {
        let s = Slots::new(LIMITS);
        let mut t = Instant::now();
        let a = fill(&s, ip(1), 3, &mut t);
        let b = fill(&s, ip(2), 2, &mut t);
        let _c = fill(&s, ip(3), 1, &mut t);
        // A newcomer: host 1 (3 open) gives up its oldest idle one.
        let d = s.admit(ip(4), false, t).expect("admitted");
        assert_eq!(d.made_room, Some(ip(1)));
        assert!(closed(&a[0]) && !closed(&a[1]));
        // Hosts 1 and 2 now have 2 each: the older idle connection of the two goes.
        let e = s.admit(ip(5), false, t).expect("admitted");
        assert_eq!(e.made_room, Some(ip(1)));
        assert!(closed(&a[1]) && !closed(&b[0]));
        let f = s.admit(ip(6), false, t).expect("admitted");
        assert_eq!(f.made_room, Some(ip(2)));
        assert!(closed(&b[0]));
        // Every host has one: a second from any of them is refused, nobody has more.
        assert_eq!(
            s.admit(ip(3), false, t).unwrap_err(),
            Refused::Full { open: 6 }
        );
    }

    #[test]
    fn idle_connections_go_first_then_streams_never_requests() {
        let s = Slots::new(LIMITS);
        let mut t = Instant::now();
        let a = fill(&s, ip(1), 3, &mut t);
        let b = fill(&s, ip(2), 2, &mut t);
        let _c = fill(&s, ip(3), 1, &mut t);
        let _stream = a[0].stream(t);
        let _busy = a[1].busy();
        // Host 1 has the most: its idle connection goes.
        let d = s.admit(ip(4), false, t).unwrap();
        assert_eq!(d.made_room, Some(ip(1)));
        assert!(closed(&a[2]));
        // Hosts 1 and 2 have two each: host 2's idle one goes before host 1's stream.
        let _e = s.admit(ip(5), false, t).unwrap();
        assert!(closed(&b[0]) && !closed(&a[0]));
        // Host 1 has the most: its stream goes, never the connection in a request.
        let _f = s.admit(ip(6), false, t).unwrap();
        assert!(closed(&a[0]) && !closed(&a[1]));
    }

    #[test]
    fn a_hosts_streams_beyond_its_share_close_its_oldest() {
        let s = Slots::new(LIMITS);
        let mut t = Instant::now();
        let a = fill(&s, ip(1), 3, &mut t);
        let _s0 = a[0].stream(t);
        let _s1 = a[1].stream(t + Duration::from_millis(1));
        assert!(!closed(&a[0]));
        let _s2 = a[2].stream(t + Duration::from_millis(2));
        assert!(closed(&a[0]) && !closed(&a[1]) && !closed(&a[2]));
    }

    #[test]
    fn reserved_hosts_are_let_in_and_never_give_up_their_connections() {
        let s = Slots::new(LIMITS);
        let mut t = Instant::now();
        // The backup connects first and idles: the oldest idle connection of all.
        let backup = s.admit(ip(9), true, t).expect("admitted").slot;
        let _others: Vec<_> = (1..=5).flat_map(|h| fill(&s, ip(h), 1, &mut t)).collect();
        // Every host has one: a newcomer from host 1 is refused, the backup's second is
        // let in, and no newcomer ever closes the backup's.
        assert!(s.admit(ip(1), false, t).is_err());
        let second = s.admit(ip(9), true, t).expect("the backup is let in");
        assert_eq!(second.made_room, Some(ip(1)));
        let newcomer = s.admit(ip(7), false, t).expect("admitted");
        assert_ne!(newcomer.made_room, Some(ip(9)));
        assert!(!closed(&backup));
    }

    #[test]
    fn a_dropped_slot_is_given_back() {
        let s = Slots::new(LIMITS);
        let a = s.admit(ip(1), false, Instant::now()).unwrap().slot;
        assert_eq!(s.open(), 1);
        drop(a);
        assert_eq!(s.open(), 0);
    }
}
