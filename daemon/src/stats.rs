//! Loop timing statistics: tick start lateness (jitter), solve time, overruns.
//!
//! Samples go into fixed-size rings allocated once, so a soak run of any length
//! uses constant memory; quantiles are computed over the newest
//! [`LoopStats::WINDOW`] samples. Times are daemon seconds (real seconds × time
//! scale).

/// Quantiles of a sample window.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Summary {
    /// Samples in the window.
    pub count: usize,
    /// Median.
    pub median: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Maximum over the whole run (not only the window).
    pub max: f64,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "median {:.3} ms, p99 {:.3} ms, max {:.3} ms (n = {})",
            self.median * 1e3,
            self.p99 * 1e3,
            self.max * 1e3,
            self.count
        )
    }
}

#[derive(Debug, Clone)]
struct Ring {
    data: Vec<f64>,
    next: usize,
    len: usize,
    max: f64,
}

impl Ring {
    fn new(capacity: usize) -> Self {
        Self {
            data: vec![0.0; capacity],
            next: 0,
            len: 0,
            max: 0.0,
        }
    }

    fn push(&mut self, v: f64) {
        self.data[self.next] = v;
        self.next = (self.next + 1) % self.data.len();
        self.len = (self.len + 1).min(self.data.len());
        self.max = self.max.max(v);
    }

    fn summary(&self) -> Summary {
        let mut v: Vec<f64> = self.data[..self.len].to_vec();
        if v.is_empty() {
            return Summary::default();
        }
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        Summary {
            count: v.len(),
            median: q(0.5),
            p99: q(0.99),
            max: self.max,
        }
    }
}

/// Statistics of the control loop.
#[derive(Debug, Clone)]
pub struct LoopStats {
    /// Ticks run.
    pub ticks: u64,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Deadlines skipped because a tick overran.
    pub missed_deadlines: u64,
    /// Ticks whose command the safety envelope replaced (DESIGN §14).
    pub envelope_overrides: u64,
    /// Commands sent between ticks when a live-obstacle set arrived (DESIGN
    /// §18): protective stops, and slow-downs.
    pub protective_stops: u64,
    pub arrival_slowdowns: u64,
    /// Resident memory after warm-up (tick [`LoopStats::WARM_TICK`]).
    pub rss_warm: Option<u64>,
    jitter: Ring,
    solve: Ring,
    tick: Ring,
    plan: Ring,
}

impl Default for LoopStats {
    fn default() -> Self {
        Self::new()
    }
}

impl LoopStats {
    /// The tick after which memory use counts as settled.
    pub const WARM_TICK: u64 = 100;

    /// Samples kept for quantiles.
    pub const WINDOW: usize = 16384;

    /// Empty statistics (allocates the rings).
    pub fn new() -> Self {
        Self {
            ticks: 0,
            overruns: 0,
            missed_deadlines: 0,
            envelope_overrides: 0,
            protective_stops: 0,
            arrival_slowdowns: 0,
            rss_warm: None,
            jitter: Ring::new(Self::WINDOW),
            solve: Ring::new(Self::WINDOW),
            tick: Ring::new(Self::WINDOW),
            plan: Ring::new(Self::WINDOW),
        }
    }

    /// One tick: lateness of its start [s], solve time if the MPC ran [s], overrun.
    pub fn record(&mut self, late_start: f64, solve_time: Option<f64>, overrun: bool) {
        self.record_tick(late_start, solve_time, overrun, None, None);
    }

    /// [`Self::record`] with the tick's own compute time [s] and the wall time of
    /// a route plan that arrived in it [s] (planned on the planner thread, not in
    /// the tick).
    pub fn record_tick(
        &mut self,
        late_start: f64,
        solve_time: Option<f64>,
        overrun: bool,
        tick_time: Option<f64>,
        plan_time: Option<f64>,
    ) {
        if let Some(t) = tick_time {
            self.tick.push(t);
        }
        if let Some(p) = plan_time {
            self.plan.push(p);
        }
        self.ticks += 1;
        if self.ticks == Self::WARM_TICK {
            self.rss_warm = resident_memory();
        }
        self.overruns += u64::from(overrun);
        self.jitter.push(late_start.max(0.0));
        if let Some(s) = solve_time {
            self.solve.push(s);
        }
    }

    /// Tick start lateness.
    pub fn jitter(&self) -> Summary {
        self.jitter.summary()
    }

    /// Solve time (wall time of the MPC step, not scaled).
    pub fn solve(&self) -> Summary {
        self.solve.summary()
    }

    /// The tick's compute time (inputs to telemetry, no sleep).
    pub fn tick(&self) -> Summary {
        self.tick.summary()
    }

    /// Route plan times (on the planner thread), one per plan taken.
    pub fn plan(&self) -> Summary {
        self.plan.summary()
    }
}

/// Resident memory of this process [bytes], from `/proc/self/statm`.
pub fn resident_memory() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    Some(pages * u64::try_from(page).ok()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_bounded_memory() {
        let mut s = LoopStats::new();
        for i in 0..(LoopStats::WINDOW as u64 + 100) {
            s.record((i % 100) as f64 * 1e-3, Some(1e-3), i == 5);
        }
        let j = s.jitter();
        assert_eq!(j.count, LoopStats::WINDOW);
        assert!((j.median - 0.05).abs() < 2e-3, "{j:?}");
        assert!((j.max - 0.099).abs() < 1e-9);
        assert_eq!(s.overruns, 1);
    }
}
