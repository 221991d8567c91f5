//! At most one log line per 10 s for a noisy event (a send error, a refused sender, a
//! malformed packet), counting the ones left out: a fault that repeats a thousand times a
//! second must not flood the journal, yet the line that is logged says how much it hid.
//! One type for the DMX output and input and the OSC server, so every such line follows
//! one rule; the caller passes the time, so tests need no sleeps.

use std::time::{Duration, Instant};

/// One kind of noisy event's log lines: when the last one went out, how many were left
/// out since.
#[derive(Debug, Default)]
pub struct Throttle {
    last: Option<Instant>,
    left_out: u64,
}

impl Throttle {
    /// The least time between two lines.
    pub const EVERY: Duration = Duration::from_secs(10);

    /// Counts an event at `now`: `Some(events left out since the last line)` when a line
    /// may be logged for it, `None` (and one more left out) while the last line is recent.
    pub fn allow(&mut self, now: Instant) -> Option<u64> {
        match self.last {
            Some(last) if now.duration_since(last) < Self::EVERY => {
                self.left_out += 1;
                None
            }
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.left_out))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_at_least_ten_seconds_apart() {
        let mut t = Throttle::default();
        let t0 = Instant::now();
        assert_eq!(t.allow(t0), Some(0));
        assert_eq!(t.allow(t0 + Duration::from_secs(1)), None);
        assert_eq!(t.allow(t0 + Duration::from_millis(9_999)), None);
        assert_eq!((t.last, t.left_out), (Some(t0), 2));
        let t1 = t0 + Duration::from_secs(10);
        assert_eq!(t.allow(t1), Some(2));
        assert_eq!((t.last, t.left_out), (Some(t1), 0));
    }

    #[test]
    fn a_line_counts_the_events_left_out_since_the_last() {
        let mut t = Throttle::default();
        let t0 = Instant::now();
        assert_eq!(t.allow(t0), Some(0));
        assert_eq!(t.allow(t0), None);
        assert_eq!(t.allow(t0), None);
        assert_eq!(t.allow(t0 + Throttle::EVERY), Some(2));
        assert_eq!(t.allow(t0 + 2 * Throttle::EVERY), Some(0));
    }
}
