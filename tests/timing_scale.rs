//! The one factor for wall-clock limits in tests: `WLNAV_TIMING_SCALE`.
//!
//! On a slower CPU than the tests were written for, above all under emulation
//! (`scripts/cross-check.sh` runs the arm64 tests under qemu-aarch64 with
//! `WLNAV_TIMING_SCALE=5`; README, "The Jetson"), every wall-clock limit of a test is
//! multiplied by this factor and every faster-than-real-time daemon clock is divided by
//! it. Nothing is skipped: a test that misses its scaled limit fails.
//!
//! This one file is the helper of every crate's tests: the e2e crate exports it
//! (`e2e::timing_scale`), the others include it with
//! `#[path = ".../tests/timing_scale.rs"] mod timing_scale;` (control and daemon cannot
//! depend on the e2e crate). The Rust programs of `examples/` include it the same way for
//! their timeouts (`examples/python_client.py` reads the variable by the same rule), as
//! `scripts/cross-check.sh` runs them against an arm64 daemon under qemu.
#![allow(dead_code)]

use std::time::Duration;

/// `WLNAV_TIMING_SCALE` (default 1, i.e. unset = no scaling). A value that is not a
/// number >= 1 panics: a typo must neither tighten the limits nor leave them unscaled
/// without anyone noticing.
pub fn factor() -> f64 {
    match std::env::var("WLNAV_TIMING_SCALE") {
        Err(std::env::VarError::NotPresent) => 1.0,
        Ok(s) if s.trim().is_empty() => 1.0,
        Ok(s) => match s.trim().parse::<f64>() {
            Ok(f) if f.is_finite() && f >= 1.0 => f,
            _ => panic!(
                "WLNAV_TIMING_SCALE={s:?}: must be a number >= 1 (the slow-down of this CPU)"
            ),
        },
        Err(e) => panic!("WLNAV_TIMING_SCALE: {e}"),
    }
}

/// A wall-clock limit or timeout of a test: `d` times [`factor`].
pub fn real(d: Duration) -> Duration {
    d.mul_f64(factor())
}

/// [`real`] in seconds.
pub fn secs(s: f64) -> f64 {
    s * factor()
}

/// A daemon clock `k` times faster than real time (`wlnavd --time-scale`,
/// `sim.time_scale`) on this CPU: `k` / [`factor`], so the daemon's 5 Hz deadlines leave
/// its solves the same share of a tick as on the CPU the test was written for.
pub fn daemon_time_scale(k: f64) -> f64 {
    k / factor()
}
