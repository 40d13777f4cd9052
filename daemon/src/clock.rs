//! The daemon's clock: monotonic time since start-up, optionally running faster
//! than real time.
//!
//! Everything that is a time in the daemon goes through one [`DaemonClock`]: tick
//! deadlines, staleness of poses and machine states, the simulated machine's
//! physics, the stop timeouts. With `time_scale = 1` (always, on a real machine) it is
//! plain `CLOCK_MONOTONIC`; with `time_scale = k` (simulated machine only) one
//! daemon second lasts `1/k` real seconds, so a test drives a 30 s manoeuvre in
//! 30/k s and every timing rule (5 Hz deadlines, 0.5 s pose timeout, watchdog) still
//! holds in daemon time.
//!
//! Pose estimates carry real `CLOCK_MONOTONIC` timestamps (the shm-ipc contract);
//! [`DaemonClock::from_monotonic_ns`] maps them into daemon time so their age is
//! judged on the same scale.

use std::time::{Duration, Instant};

/// Monotonic, optionally accelerated time; cheap to copy and share between threads.
#[derive(Debug, Clone, Copy)]
pub struct DaemonClock {
    origin: Instant,
    origin_mono_ns: u64,
    scale: f64,
}

impl DaemonClock {
    /// A clock starting now, running `time_scale` times faster than real time
    /// (`time_scale` > 0 and finite, checked by the configuration).
    pub fn new(time_scale: f64) -> Self {
        let scale = if time_scale.is_finite() && time_scale > 0.0 {
            time_scale
        } else {
            1.0
        };
        Self {
            origin: Instant::now(),
            origin_mono_ns: shm_ipc::monotonic_now_ns(),
            scale,
        }
    }

    /// The time scale (daemon seconds per real second).
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Daemon seconds since start-up.
    pub fn now(&self) -> f64 {
        self.origin.elapsed().as_secs_f64() * self.scale
    }

    /// The real instant at which daemon time `t` [s] is reached.
    pub fn instant_at(&self, t: f64) -> Instant {
        self.origin + Duration::from_secs_f64((t / self.scale).max(0.0))
    }

    /// A real duration for a span of `dt` daemon seconds.
    pub fn real_duration(&self, dt: f64) -> Duration {
        Duration::from_secs_f64((dt / self.scale).max(0.0))
    }

    /// Daemon time of a `CLOCK_MONOTONIC` timestamp (may be negative: before start-up).
    pub fn from_monotonic_ns(&self, ns: u64) -> f64 {
        (ns as f64 - self.origin_mono_ns as f64) * 1e-9 * self.scale
    }

    /// `CLOCK_MONOTONIC` timestamp of daemon time `t`.
    pub fn to_monotonic_ns(&self, t: f64) -> u64 {
        let real = (t / self.scale) * 1e9;
        (self.origin_mono_ns as f64 + real).max(0.0) as u64
    }

    /// Sleeps the calling thread until daemon time `t` (returns at once if past).
    pub fn sleep_until(&self, t: f64) {
        let target = self.instant_at(t);
        let now = Instant::now();
        if target > now {
            std::thread::sleep(target - now);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_time_and_monotonic_mapping() {
        let c = DaemonClock::new(10.0);
        std::thread::sleep(Duration::from_millis(20));
        let t = c.now();
        assert!((0.19..1.0).contains(&t), "{t}");
        let ns = c.to_monotonic_ns(2.0);
        assert!((c.from_monotonic_ns(ns) - 2.0).abs() < 1e-6);
        assert_eq!(c.real_duration(1.0), Duration::from_millis(100));
    }
}
