//! Rate limiting of repetitive log lines (DESIGN §11: "rejected requests are logged with a
//! rate limit"). A peer sending 5,000 bad goals must not write 5,000 lines to the journal;
//! the first few of each window are logged in full, the rest counted and summarised.
//! Pure: the caller passes the time.

/// What to do with one event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogDecision {
    /// Log it. `suppressed` events were dropped since the last logged one (mention them).
    Log {
        /// Events not logged since the previous logged one
        suppressed: u64,
    },
    /// Count it, do not log.
    Suppress,
}

/// At most `burst` log lines per `window` seconds; the rest are counted.
#[derive(Debug, Clone)]
pub struct LogLimiter {
    burst: u32,
    window: f64,
    window_start: Option<f64>,
    logged_in_window: u32,
    suppressed: u64,
}

impl LogLimiter {
    /// A limiter allowing `burst` lines per `window` seconds (`burst` ≥ 1).
    pub fn new(burst: u32, window: f64) -> Self {
        Self {
            burst: burst.max(1),
            window,
            window_start: None,
            logged_in_window: 0,
            suppressed: 0,
        }
    }

    fn roll(&mut self, now: f64) {
        let expired = match self.window_start {
            None => true,
            // NaN-safe: a window counts as over unless it is provably still open.
            Some(start) => {
                (now - start).partial_cmp(&self.window) != Some(core::cmp::Ordering::Less)
            }
        };
        if expired {
            self.window_start = Some(now);
            self.logged_in_window = 0;
        }
    }

    /// Decides about one event at time `now` [s].
    pub fn check(&mut self, now: f64) -> LogDecision {
        self.roll(now);
        if self.logged_in_window < self.burst {
            self.logged_in_window += 1;
            LogDecision::Log {
                suppressed: core::mem::take(&mut self.suppressed),
            }
        } else {
            self.suppressed += 1;
            LogDecision::Suppress
        }
    }

    /// Called periodically: once the window in which events were suppressed has passed,
    /// returns their number (to log one summary line) and resets it.
    pub fn summary(&mut self, now: f64) -> Option<u64> {
        let window_over = self
            .window_start
            .is_none_or(|s| (now - s).partial_cmp(&self.window) != Some(core::cmp::Ordering::Less));
        if self.suppressed > 0 && window_over {
            self.window_start = Some(now);
            self.logged_in_window = 0;
            Some(core::mem::take(&mut self.suppressed))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_logs_a_burst_per_window_and_counts_the_rest() {
        let mut l = LogLimiter::new(5, 10.0);
        let mut logged = 0;
        // 5,000 events over 5 s: one window.
        for i in 0..5000 {
            if let LogDecision::Log { suppressed } = l.check(i as f64 * 0.001) {
                assert_eq!(suppressed, 0);
                logged += 1;
            }
        }
        assert_eq!(logged, 5);
        assert_eq!(l.summary(5.0), None, "window still open");
        assert_eq!(l.summary(10.0), Some(4995));
        assert_eq!(l.summary(30.0), None, "reported once");
    }

    #[test]
    fn the_next_logged_event_reports_what_was_suppressed() {
        let mut l = LogLimiter::new(2, 1.0);
        assert_eq!(l.check(0.0), LogDecision::Log { suppressed: 0 });
        assert_eq!(l.check(0.1), LogDecision::Log { suppressed: 0 });
        assert_eq!(l.check(0.2), LogDecision::Suppress);
        assert_eq!(l.check(0.3), LogDecision::Suppress);
        assert_eq!(l.check(1.5), LogDecision::Log { suppressed: 2 });
        assert_eq!(l.summary(5.0), None);
    }
}
