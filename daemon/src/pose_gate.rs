//! The pose gate (DESIGN §11, "inputs that lie"): which pose samples the control loop may
//! use, and when the pose source is faulted. Pure: the tick feeds it every sample with its
//! time mapped to daemon seconds, and asks it for the fresh pose.
//!
//! A sample is
//! * **ignored** (neither used nor held against the source) when it is not flagged valid
//!   (localization not converged), not newer than the last accepted one (a repeat), or
//!   already older than the pose timeout when it arrives;
//! * **rejected** (counted) when it is non-finite, stamped more than `max_future` ahead of
//!   the daemon's clock, outside the pose region (the goal workspace grown by a margin), or
//!   when it implies a jump the machine cannot make since the last accepted pose: farther
//!   than `max_speed · Δt + position_tolerance`, or a heading change beyond
//!   `max_yaw_rate · Δt + heading_tolerance`;
//! * otherwise **accepted**: it becomes the reference for the next jump test and for age.
//!
//! Age is judged on accepted samples only, so a future timestamp can never make a pose
//! look fresh: the stale-pose stop comes `timeout` after the last good pose whatever is
//! published after it. `reject_run` consecutive rejects are a pose fault
//! ([`PoseGate::faulted`] → controlled stop). The fault clears only when the source has
//! been consistent again: `reject_run` successive samples, each plausible relative to the
//! one before and inside the region, received while faulted and spanning at least the pose
//! timeout; the newest of them becomes the reference (a relocalised machine recovers; a
//! jumping or absurd source never does). The span matters for a fast source: at 50 Hz
//! `reject_run` samples take 0.1 s, so a source jumping every 0.5 s would re-anchor within
//! one 5 Hz tick each time and the loop might never see the fault; with the span a fault
//! lasts at least the timeout (longer than a tick), and a source that jumps more often
//! than that never recovers.

use shm_ipc::Pose2;

/// The gate's thresholds. Times in daemon seconds, lengths in metres, angles in radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseGateConfig {
    /// An accepted pose older than this is stale.
    pub timeout: f64,
    /// A timestamp more than this ahead of the daemon's clock is rejected.
    pub max_future: f64,
    /// Fastest the machine's front axle can move [m/s] (bound plus margin).
    pub max_speed: f64,
    /// Fastest the front body can turn [rad/s] (bound plus margin).
    pub max_yaw_rate: f64,
    /// Position jump tolerated on top of `max_speed · Δt` (localization noise, latency).
    pub position_tolerance: f64,
    /// Heading jump tolerated on top of `max_yaw_rate · Δt`.
    pub heading_tolerance: f64,
    /// Poses must lie in this rectangle: `[x_min, x_max, y_min, y_max]`, inclusive.
    pub region: [f64; 4],
    /// Consecutive rejects that make a pose fault (≥ 1).
    pub reject_run: u32,
}

impl PoseGateConfig {
    /// The largest front-body yaw rate of the model (DESIGN §2) within the machine's
    /// bounds: θ̇ = (L_r β̇ + v sin β) / (L_f cos β + L_r), numerator and denominator
    /// bounded separately (conservative).
    pub fn model_yaw_rate(p: &control::MachineParams) -> f64 {
        let beta = p.beta_max.min(core::f64::consts::FRAC_PI_2);
        (p.l_r * p.beta_dot_max + p.v_max * beta.sin()) / (p.l_f * beta.cos() + p.l_r)
    }
}

/// Why a sample was rejected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseReject {
    /// x, y or heading is NaN or infinite.
    NonFinite,
    /// Stamped `ahead` seconds in the future of the daemon's clock.
    Future {
        /// How far ahead [s]
        ahead: f64,
    },
    /// Outside the pose region.
    OutsideRegion {
        /// x [m]
        x: f64,
        /// y [m]
        y: f64,
    },
    /// Farther from the last accepted pose than the machine can move.
    Jump {
        /// Distance [m]
        distance: f64,
        /// Largest plausible distance [m]
        allowed: f64,
        /// Time since the last accepted pose [s]
        dt: f64,
    },
    /// A heading change the machine cannot make.
    HeadingJump {
        /// Wrapped heading change [rad]
        change: f64,
        /// Largest plausible change [rad]
        allowed: f64,
        /// Time since the last accepted pose [s]
        dt: f64,
    },
}

impl core::fmt::Display for PoseReject {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use shm_ipc::Num;
        match *self {
            Self::NonFinite => write!(f, "non-finite pose"),
            Self::Future { ahead } => {
                write!(f, "timestamp {} s in the future", Num::new(ahead))
            }
            Self::OutsideRegion { x, y } => write!(
                f,
                "position ({}, {}) m outside the workspace",
                Num::new(x),
                Num::new(y)
            ),
            Self::Jump {
                distance,
                allowed,
                dt,
            } => write!(
                f,
                "jump of {} m in {} s (at most {} m plausible)",
                Num::new(distance),
                Num::new(dt),
                Num::new(allowed)
            ),
            Self::HeadingJump {
                change,
                allowed,
                dt,
            } => write!(
                f,
                "heading change of {} rad in {} s (at most {} rad plausible)",
                Num::new(change),
                Num::new(dt),
                Num::new(allowed)
            ),
        }
    }
}

/// Why a sample was ignored (not used, not counted against the source).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseIgnore {
    /// The valid flag is not set.
    NotValid,
    /// Not newer than the last accepted sample.
    NotNewer,
    /// Already older than the timeout.
    Stale,
}

/// What the gate did with a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseVerdict {
    /// Used: the new reference pose.
    Accepted,
    /// Neither used nor counted.
    Ignored(PoseIgnore),
    /// Counted against the source.
    Rejected(PoseReject),
}

/// The gate's state between samples.
#[derive(Debug, Clone)]
pub struct PoseGate {
    cfg: PoseGateConfig,
    /// The last accepted pose and its time.
    last: Option<(Pose2, f64)>,
    /// Consecutive rejects.
    run: u32,
    /// All rejects since start.
    rejected_total: u64,
    /// While faulted: the newest sane sample, how many consistent ones led to it, and
    /// the time of the first of them.
    chain: Option<(Pose2, f64, u32, f64)>,
}

/// Heading difference wrapped to (−π, π].
fn heading_change(a: f64, b: f64) -> f64 {
    shm_ipc::normalize_angle(a - b)
}

impl PoseGate {
    /// A gate without any accepted pose.
    pub fn new(cfg: PoseGateConfig) -> Self {
        Self {
            cfg,
            last: None,
            run: 0,
            rejected_total: 0,
            chain: None,
        }
    }

    /// `None` if `pose` at `t` is a plausible successor of `prev` at `t_prev`, else why not.
    fn implausible(&self, prev: (Pose2, f64), pose: Pose2, t: f64) -> Option<PoseReject> {
        let dt = t - prev.1;
        let distance = (pose.x - prev.0.x).hypot(pose.y - prev.0.y);
        let allowed = self.cfg.max_speed * dt + self.cfg.position_tolerance;
        // NaN-safe: anything not provably within the bound is a jump.
        if distance
            .partial_cmp(&allowed)
            .is_none_or(|o| o == core::cmp::Ordering::Greater)
        {
            return Some(PoseReject::Jump {
                distance,
                allowed,
                dt,
            });
        }
        let change = heading_change(pose.heading, prev.0.heading).abs();
        let allowed = self.cfg.max_yaw_rate * dt + self.cfg.heading_tolerance;
        if change
            .partial_cmp(&allowed)
            .is_none_or(|o| o == core::cmp::Ordering::Greater)
        {
            return Some(PoseReject::HeadingJump {
                change,
                allowed,
                dt,
            });
        }
        None
    }

    /// Judges one sample: `pose` flagged `valid`, measured at daemon time `t`, seen at
    /// daemon time `now`.
    pub fn offer(&mut self, pose: Pose2, valid: bool, t: f64, now: f64) -> PoseVerdict {
        if !valid {
            return PoseVerdict::Ignored(PoseIgnore::NotValid);
        }
        let verdict = self.judge(pose, t, now);
        match verdict {
            PoseVerdict::Accepted => {
                self.last = Some((pose, t));
                self.run = 0;
                self.chain = None;
            }
            PoseVerdict::Rejected(_) => {
                self.run = self.run.saturating_add(1);
                self.rejected_total += 1;
            }
            PoseVerdict::Ignored(_) => {}
        }
        verdict
    }

    fn judge(&mut self, pose: Pose2, t: f64, now: f64) -> PoseVerdict {
        if !pose.is_finite() || !t.is_finite() {
            return PoseVerdict::Rejected(PoseReject::NonFinite);
        }
        if t - now > self.cfg.max_future {
            return PoseVerdict::Rejected(PoseReject::Future { ahead: t - now });
        }
        let [x_min, x_max, y_min, y_max] = self.cfg.region;
        if !((x_min..=x_max).contains(&pose.x) && (y_min..=y_max).contains(&pose.y)) {
            return PoseVerdict::Rejected(PoseReject::OutsideRegion {
                x: pose.x,
                y: pose.y,
            });
        }
        if now - t > self.cfg.timeout {
            return PoseVerdict::Ignored(PoseIgnore::Stale);
        }
        let Some(last) = self.last else {
            return PoseVerdict::Accepted;
        };
        if t <= last.1 {
            return PoseVerdict::Ignored(PoseIgnore::NotNewer);
        }
        let Some(why) = self.implausible(last, pose, t) else {
            return PoseVerdict::Accepted;
        };
        if self.faulted() {
            // Re-anchoring: count successive samples consistent with each other, and
            // how long they have been (module docs: at least the pose timeout).
            let (len, since) = match self.chain {
                Some((p, tp, n, t0)) if t > tp && self.implausible((p, tp), pose, t).is_none() => {
                    (n + 1, t0)
                }
                _ => (1, t),
            };
            self.chain = Some((pose, t, len, since));
            // 1 µs: sample times summed in floating point.
            if len >= self.cfg.reject_run.max(1) && t - since >= self.cfg.timeout - 1e-6 {
                return PoseVerdict::Accepted;
            }
        }
        PoseVerdict::Rejected(why)
    }

    /// The last accepted pose if it is fresh at `now` (age ≤ timeout).
    pub fn fresh(&self, now: f64) -> Option<Pose2> {
        let (p, t) = self.last?;
        let age = now - t;
        // Accepted samples are never more than `max_future` ahead, so a negative age is
        // bounded; the lower bound guards against a clock that went backwards.
        (age <= self.cfg.timeout && age >= -self.cfg.max_future).then_some(p)
    }

    /// The last accepted pose and its time, fresh or not.
    pub fn last(&self) -> Option<(Pose2, f64)> {
        self.last
    }

    /// True while a run of `reject_run` or more consecutive rejects holds.
    pub fn faulted(&self) -> bool {
        self.run >= self.cfg.reject_run.max(1)
    }

    /// Consecutive rejects now.
    pub fn reject_run(&self) -> u32 {
        self.run
    }

    /// Rejected samples since start.
    pub fn rejected_total(&self) -> u64 {
        self.rejected_total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> PoseGateConfig {
        PoseGateConfig {
            timeout: 0.5,
            max_future: 0.05,
            max_speed: 1.2,
            max_yaw_rate: 1.0,
            position_tolerance: 0.3,
            heading_tolerance: 0.2,
            region: [-60.0, 60.0, -60.0, 60.0],
            reject_run: 3,
        }
    }

    fn p(x: f64, y: f64, h: f64) -> Pose2 {
        Pose2::new(x, y, h)
    }

    /// Fresh poses along x at 1 m/s, 20 Hz, from t = 0 to `until`.
    fn drive(g: &mut PoseGate, until: f64) {
        let mut t = 0.0;
        while t <= until + 1e-9 {
            assert_eq!(g.offer(p(t, 0.0, 0.0), true, t, t), PoseVerdict::Accepted);
            t += 0.05;
        }
    }

    #[test]
    fn a_future_stamp_is_rejected_and_cannot_keep_the_pose_fresh() {
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 2.0);
        // 8 s ahead, then silence.
        let v = g.offer(p(2.05, 0.0, 0.0), true, 10.0, 2.02);
        assert!(
            matches!(v, PoseVerdict::Rejected(PoseReject::Future { .. })),
            "{v:?}"
        );
        assert!(g.fresh(2.4).is_some());
        assert!(
            g.fresh(2.51).is_none(),
            "stale 0.5 s after the last good pose"
        );
        assert!(g.fresh(9.0).is_none());
        // Within the 50 ms tolerance a stamp is fine.
        let mut g = PoseGate::new(cfg());
        assert_eq!(
            g.offer(p(0.0, 0.0, 0.0), true, 1.04, 1.0),
            PoseVerdict::Accepted
        );
    }

    #[test]
    fn jumps_beyond_the_machine_and_absurd_positions_are_rejected_then_fault() {
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        let v = g.offer(p(1e6, -1e6, 0.0), true, 1.1, 1.1);
        assert!(matches!(
            v,
            PoseVerdict::Rejected(PoseReject::OutsideRegion { .. })
        ));
        // 10 m in 0.5 s: far more than 1.2 m/s allows.
        let v = g.offer(p(11.0, 0.0, 0.0), true, 1.5, 1.5);
        assert!(
            matches!(v, PoseVerdict::Rejected(PoseReject::Jump { .. })),
            "{v:?}"
        );
        assert!(!g.faulted());
        let v = g.offer(p(1.0, 0.0, 2.5), true, 1.55, 1.55);
        assert!(
            matches!(v, PoseVerdict::Rejected(PoseReject::HeadingJump { .. })),
            "{v:?}"
        );
        assert!(g.faulted(), "three in a row");
        assert_eq!(g.rejected_total(), 3);
        // The last good pose is kept as the reference, and goes stale.
        assert!(g.last().is_some_and(|l| (l.0.x - 1.0).abs() < 1e-9));
        assert!(g.fresh(1.6).is_none());
    }

    #[test]
    fn a_good_sample_between_bad_ones_resets_the_run() {
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        for k in 0..10 {
            let t = 1.05 + 0.1 * k as f64;
            let bad = g.offer(p(1e6, -1e6, 0.0), true, t, t);
            assert!(matches!(bad, PoseVerdict::Rejected(_)));
            let good = g.offer(p(t, 0.0, 0.0), true, t + 0.05, t + 0.05);
            assert_eq!(good, PoseVerdict::Accepted);
        }
        assert!(!g.faulted());
        assert!(g.fresh(2.0).is_some());
    }

    #[test]
    fn non_finite_invalid_repeated_and_stale_samples() {
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        let v = g.offer(p(f64::NAN, 0.0, 0.0), true, 1.05, 1.05);
        assert_eq!(v, PoseVerdict::Rejected(PoseReject::NonFinite));
        let v = g.offer(p(f64::NAN, 0.0, 0.0), false, 1.05, 1.05);
        assert_eq!(v, PoseVerdict::Ignored(PoseIgnore::NotValid));
        let v = g.offer(p(1.0, 0.0, 0.0), true, 1.0, 1.05);
        assert_eq!(v, PoseVerdict::Ignored(PoseIgnore::NotNewer));
        let v = g.offer(p(1.0, 0.0, 0.0), true, 0.2, 1.05);
        assert_eq!(v, PoseVerdict::Ignored(PoseIgnore::Stale));
        assert_eq!(g.reject_run(), 1, "only the NaN counts");
        // A heading just across ±π is a small change, not a jump.
        let mut g = PoseGate::new(cfg());
        assert_eq!(
            g.offer(p(0.0, 0.0, 3.1), true, 0.0, 0.0),
            PoseVerdict::Accepted
        );
        assert_eq!(
            g.offer(p(0.0, 0.0, -3.1), true, 0.05, 0.05),
            PoseVerdict::Accepted
        );
    }

    #[test]
    fn a_consistent_relocalised_source_re_anchors_only_after_a_fault() {
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        // The localization now reports the machine 5 m to the side, consistently.
        let mut verdicts = Vec::new();
        for k in 0..20 {
            let t = 1.05 + 0.05 * k as f64;
            verdicts.push(g.offer(p(1.0, 5.0, 0.0), true, t, t));
        }
        let accepted = verdicts
            .iter()
            .position(|v| *v == PoseVerdict::Accepted)
            .expect("re-anchored");
        // Three rejects make the fault (k = 2); consistent samples while faulted from k = 3
        // on re-anchor once there are three spanning the 0.5 s timeout (k = 13).
        assert_eq!(accepted, 13, "{verdicts:?}");
        assert!(!g.faulted());
        assert_eq!(g.last().map(|l| l.0.y), Some(5.0));
        // A source jumping 10 m each sample never re-anchors.
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        for k in 0..20 {
            let t = 1.05 + 0.05 * k as f64;
            let v = g.offer(p(1.0 + 10.0 * (k % 2) as f64, 10.0, 0.0), true, t, t);
            assert!(matches!(v, PoseVerdict::Rejected(_)), "{k}: {v:?}");
        }
        assert!(g.faulted());
    }

    #[test]
    fn a_fast_source_jumping_to_another_place_every_half_second_never_re_anchors() {
        // 50 Hz, alternating every 0.5 s between the machine's place and 3 m beside it.
        // Each half-second beside is self-consistent, but never for the 0.5 s timeout,
        // so the gate never takes the other place (before the span it did after six
        // samples, 0.12 s, and the pose teleported every half second), and the fault
        // holds at every 5 Hz tick of those halves once it has begun.
        let mut g = PoseGate::new(cfg());
        drive(&mut g, 1.0);
        let mut faulted_ticks = 0;
        for k in 1..=200 {
            let t = 1.0 + 0.02 * k as f64;
            let beside = ((t - 1.0 + 1e-9) / 0.5).floor() as i64 % 2 == 0;
            let v = g.offer(p(1.0, if beside { 3.0 } else { 0.0 }, 0.0), true, t, t);
            assert_eq!(v == PoseVerdict::Accepted, !beside, "t = {t}: {v:?}");
            let half = (t - 1.0) % 0.5;
            if beside && k % 10 == 0 && half > 0.1 {
                assert!(g.faulted(), "t = {t}: no fault");
                faulted_ticks += 1;
            }
        }
        assert!(faulted_ticks >= 8, "{faulted_ticks}");
        assert!(g.last().is_some_and(|l| l.0.y == 0.0));
    }

    #[test]
    fn model_yaw_rate_bound() {
        let p = control::MachineParams::default();
        let w = PoseGateConfig::model_yaw_rate(&p);
        // Straight at full speed the rate is 0; the bound covers full articulation.
        assert!((0.5..2.0).contains(&w), "{w}");
    }
}
