//! The progress checker (DESIGN §10, after Nav2's): a goal whose pose error has
//! not come closer by `min_approach` for `timeout` seconds has stalled. The
//! pilot ends such a goal (`no-progress`: the navigator's window, or the
//! pilot's own without one) and the daemon brings the machine to rest; the
//! global layer replans on a shorter window.
//!
//! The error is DESIGN §7's ‖(x_f − x_g, y_f − y_g, e_θ)‖ towards whatever
//! the machine is driving to (the goal, or a subgoal of the global route: a
//! new target restarts the window).

use crate::model::{goal_distance, Goal, State};

/// Settings of one progress window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProgressSettings {
    /// Seconds without approach after which the goal has stalled. Default 10.
    pub timeout: f64,
    /// How much closer [m, rad combined] counts as approach. Default 0.1.
    pub min_approach: f64,
}

impl Default for ProgressSettings {
    fn default() -> Self {
        Self {
            timeout: 10.0,
            min_approach: 0.1,
        }
    }
}

/// Tracks the best error reached and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProgressChecker {
    settings: ProgressSettings,
    target: Option<Goal>,
    best: f64,
    best_at: f64,
}

impl ProgressChecker {
    pub fn new(settings: ProgressSettings) -> Self {
        Self {
            settings,
            target: None,
            best: f64::INFINITY,
            best_at: 0.0,
        }
    }

    pub fn settings(&self) -> &ProgressSettings {
        &self.settings
    }

    /// Starts a new window (a new goal or subgoal) at time `now`.
    pub fn reset(&mut self, target: Goal, now: f64) {
        self.target = Some(target);
        self.best = f64::INFINITY;
        self.best_at = now;
    }

    /// Takes the state at time `now` (seconds, any monotonic origin) and tells
    /// whether the target has stalled. A different target than the last
    /// `reset` restarts the window.
    pub fn update(&mut self, x: &State, target: &Goal, now: f64) -> bool {
        if self.target != Some(*target) {
            self.reset(*target, now);
        }
        let e = goal_distance(x, target);
        if e <= self.best - self.settings.min_approach || !self.best.is_finite() {
            self.best = e;
            self.best_at = now;
        }
        now - self.best_at >= self.settings.timeout
    }

    /// The machine is held by something outside its plan (a protective
    /// stop, DESIGN §18) at `now`: the window starts again from here, the
    /// best error kept.
    pub fn hold(&mut self, now: f64) {
        if self.target.is_some() {
            self.best_at = self.best_at.max(now);
        }
    }

    /// Seconds since the last approach (0 before the first update).
    pub fn stalled_for(&self, now: f64) -> f64 {
        if self.target.is_some() {
            (now - self.best_at).max(0.0)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64) -> State {
        State::new(x, 0.0, 0.0, 0.0, 0.0, 0.0)
    }

    #[test]
    fn a_hold_restarts_the_window_and_keeps_the_best() {
        let g = Goal::new(10.0, 0.0, 0.0);
        let mut p = ProgressChecker::new(ProgressSettings::default());
        assert!(!p.update(&at(1.0), &g, 0.0));
        // Held from 1 s to 8 s: the window counts from 8 s.
        for k in 1..=8 {
            p.hold(k as f64);
        }
        assert_eq!(p.stalled_for(8.0), 0.0);
        assert!(!p.update(&at(1.0), &g, 17.9));
        assert!(p.update(&at(1.0), &g, 18.0));
        // The best is kept: coming back to where it was is no approach.
        let mut q = ProgressChecker::new(ProgressSettings::default());
        assert!(!q.update(&at(5.0), &g, 0.0));
        assert!(!q.update(&at(1.0), &g, 1.0));
        q.hold(2.0);
        assert!(!q.update(&at(1.0), &g, 3.0));
        assert_eq!(q.stalled_for(3.0), 1.0);
    }

    #[test]
    fn approaching_never_stalls_standing_still_does_after_the_timeout() {
        let g = Goal::new(10.0, 0.0, 0.0);
        let mut p = ProgressChecker::new(ProgressSettings::default());
        // 0.05 m per 0.2 s tick: 0.1 m every 0.4 s.
        for k in 0..150 {
            let t = k as f64 * 0.2;
            assert!(!p.update(&at(0.05 * k as f64), &g, t), "t {t}");
        }
        // Now stand still at 7.45 m: stalled exactly 10 s after the last approach.
        let last = 149.0 * 0.2;
        let best_at = p.best_at;
        assert!(best_at <= last && best_at > last - 0.5);
        let mut k = 150;
        loop {
            let t = k as f64 * 0.2;
            if p.update(&at(7.45), &g, t) {
                assert!((t - best_at - 10.0).abs() < 0.2 + 1e-9, "stalled at {t}");
                break;
            }
            assert!(t < best_at + 10.0 + 1e-9);
            k += 1;
        }
    }

    #[test]
    fn wandering_within_the_threshold_is_not_progress_and_a_new_target_restarts() {
        let g = Goal::new(5.0, 0.0, 0.0);
        let mut p = ProgressChecker::new(ProgressSettings {
            timeout: 2.0,
            min_approach: 0.1,
        });
        assert!(!p.update(&at(0.0), &g, 0.0));
        // Creeping 0.05 m closer then back: no new best by 0.1.
        assert!(!p.update(&at(0.05), &g, 1.0));
        assert!(!p.update(&at(0.0), &g, 1.9));
        assert!(p.update(&at(0.05), &g, 2.0));
        assert!((p.stalled_for(2.5) - 2.5).abs() < 1e-12);
        // A subgoal: the window starts again.
        let sub = Goal::new(1.0, 1.0, 0.0);
        assert!(!p.update(&at(0.05), &sub, 2.2));
        assert!(!p.update(&at(0.05), &sub, 4.1));
        assert!(p.update(&at(0.05), &sub, 4.2));
    }
}
