//! Following one goal through telemetry until the daemon reports its outcome (DESIGN §10:
//! every accepted goal ends in exactly one outcome, reported once with its request id).
//! Along the way: when the daemon took the goal up and when it converged (DESIGN §7 test).
//! Used by `wlnav goal --wait`, `wlnav demo` and the end-to-end tests.

use shm_ipc::{fault_flags, AbortReason, GoalOutcome, Pose2, Telemetry};

use super::view::goal_distance;

/// DESIGN §7 success tolerance on ‖(x_f − x_g, y_f − y_g, e_θ)‖.
pub const CONVERGED_TOLERANCE: f64 = 0.1;

/// The outcome the daemon reported for a goal.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportedOutcome {
    /// How the goal ended (never [`GoalOutcome::None`]).
    pub outcome: GoalOutcome,
    /// Why, when aborted ([`AbortReason::None`] otherwise).
    pub abort_reason: AbortReason,
    /// The daemon's reason text.
    pub text: String,
    /// The tick that reported it.
    pub tick: u64,
}

impl ReportedOutcome {
    /// `succeeded`, `cancelled`, `preempted`, or `aborted (no-progress)`.
    pub fn name(&self) -> String {
        match self.outcome {
            GoalOutcome::Aborted => format!("aborted ({})", self.abort_reason.name()),
            other => other.name().to_owned(),
        }
    }
}

/// Where a followed goal stands after a telemetry sample.
#[derive(Debug, Clone, PartialEq)]
pub enum GoalStatus {
    /// The daemon has not reported this goal yet (its telemetry still shows another one).
    Pending,
    /// The daemon drives towards this goal.
    Active,
    /// The daemon reported the goal's outcome.
    Ended(ReportedOutcome),
    /// Following stopped without an outcome because telemetry stopped: the daemon is gone.
    NoTelemetry(String),
    /// Following stopped without an outcome because a time limit passed; the goal may
    /// still be active.
    TimedOut(String),
}

impl GoalStatus {
    /// True once the status can no longer change (an outcome, or following gave up).
    pub fn is_final(&self) -> bool {
        !matches!(self, Self::Pending | Self::Active)
    }

    /// True if the daemon reported the goal `succeeded`.
    pub fn is_succeeded(&self) -> bool {
        matches!(self, Self::Ended(o) if o.outcome == GoalOutcome::Succeeded)
    }

    /// The reported outcome, if any.
    pub fn outcome(&self) -> Option<&ReportedOutcome> {
        match self {
            Self::Ended(o) => Some(o),
            _ => None,
        }
    }
}

/// Follows one accepted goal (by request id) through the daemon's telemetry.
#[derive(Debug, Clone)]
pub struct GoalTracker {
    request_id: u64,
    goal: Pose2,
    status: GoalStatus,
    /// First tick whose telemetry carried this goal.
    pub first_tick: Option<u64>,
    /// First tick at which the DESIGN §7 test held.
    pub converged_tick: Option<u64>,
    /// Tick at which the daemon reported the goal succeeded.
    pub reached_tick: Option<u64>,
    /// Most recent tick seen.
    pub last_tick: Option<u64>,
    /// Overruns (fault bit) seen while following.
    pub overruns: u64,
    /// Largest solve time seen while the goal was active [µs].
    pub max_solve_us: f64,
    /// (tick, timestamp [ns]) of the first and the newest telemetry sample: the
    /// daemon's tick period is measured, not configured twice (it is `mpc.dt`).
    stamps: Option<((u64, u64), (u64, u64))>,
    /// Seconds of the daemon's clock per wall-clock second (a simulated machine may
    /// run faster than real time).
    time_scale: f64,
}

impl GoalTracker {
    /// Starts following the goal sent with `request_id`.
    pub fn new(request_id: u64, goal: Pose2) -> Self {
        Self {
            request_id,
            goal,
            status: GoalStatus::Pending,
            first_tick: None,
            converged_tick: None,
            reached_tick: None,
            last_tick: None,
            overruns: 0,
            max_solve_us: 0.0,
            stamps: None,
            time_scale: 1.0,
        }
    }

    /// For a daemon whose clock runs `scale` times faster than the wall clock
    /// (`wlnavd --sim --time-scale`): times are reported on the daemon's clock.
    pub fn with_time_scale(mut self, scale: f64) -> Self {
        self.time_scale = scale;
        self
    }

    /// The daemon's tick period [s], measured from the telemetry's timestamps once
    /// two ticks have been seen (a missed deadline makes it longer, as it is).
    pub fn tick_period(&self) -> Option<f64> {
        let ((tick0, ns0), (tick1, ns1)) = self.stamps?;
        (tick1 > tick0 && ns1 > ns0)
            .then(|| (ns1 - ns0) as f64 * 1e-9 / (tick1 - tick0) as f64 * self.time_scale)
    }

    /// Seconds from the goal's first tick to `tick` (with the measured period).
    pub fn seconds_since_start(&self, tick: u64) -> Option<f64> {
        Some(self.ticks_since_start(tick)? as f64 * self.tick_period()?)
    }

    /// The goal followed.
    pub fn goal(&self) -> Pose2 {
        self.goal
    }

    /// The request id followed.
    pub fn request_id(&self) -> u64 {
        self.request_id
    }

    /// The current status.
    pub fn status(&self) -> &GoalStatus {
        &self.status
    }

    /// Ticks from the goal's first tick to `tick`.
    pub fn ticks_since_start(&self, tick: u64) -> Option<u64> {
        self.first_tick.map(|f| tick.saturating_sub(f))
    }

    /// Feeds one telemetry sample and returns the new status. The goal ends only with the
    /// outcome the daemon reports for its request id. Once final, the status does not
    /// change.
    pub fn update(&mut self, t: &Telemetry) -> &GoalStatus {
        if self.status.is_final() {
            return &self.status;
        }
        self.last_tick = Some(t.tick);
        let stamp = (t.tick, t.timestamp_ns);
        self.stamps = Some(match self.stamps {
            Some((first, _)) => (first, stamp),
            None => (stamp, stamp),
        });
        if t.goal_request_id == self.request_id && t.goal_active != 0 {
            if self.first_tick.is_none() {
                self.first_tick = Some(t.tick);
                self.status = GoalStatus::Active;
            }
            if t.fault_flags & fault_flags::OVERRUN != 0 {
                self.overruns += 1;
            }
            if t.solve_time_us.is_finite() {
                self.max_solve_us = self.max_solve_us.max(t.solve_time_us);
            }
            if self.converged_tick.is_none() && goal_distance(t) < CONVERGED_TOLERANCE {
                self.converged_tick = Some(t.tick);
            }
        }
        if t.outcome != GoalOutcome::None.code() && t.outcome_request_id == self.request_id {
            let reported = match t.outcome() {
                Ok(outcome) => ReportedOutcome {
                    outcome,
                    abort_reason: t.abort_reason().unwrap_or(AbortReason::None),
                    text: t.outcome_text().to_owned(),
                    tick: t.tick,
                },
                // A newer daemon's outcome this client does not know: the goal ended, but
                // not as asked for.
                Err(code) => ReportedOutcome {
                    outcome: GoalOutcome::Aborted,
                    abort_reason: AbortReason::None,
                    text: format!("unknown outcome code {code}: {}", t.outcome_text()),
                    tick: t.tick,
                },
            };
            if reported.outcome == GoalOutcome::Succeeded {
                self.reached_tick = Some(t.tick);
            }
            self.status = GoalStatus::Ended(reported);
        }
        &self.status
    }

    /// Marks following as given up by a time limit (unless the goal already ended).
    pub fn time_out(&mut self, why: impl Into<String>) {
        if !self.status.is_final() {
            self.status = GoalStatus::TimedOut(why.into());
        }
    }

    /// Marks following as given up because telemetry stopped (unless the goal already
    /// ended).
    pub fn lose_telemetry(&mut self, why: impl Into<String>) {
        if !self.status.is_final() {
            self.status = GoalStatus::NoTelemetry(why.into());
        }
    }
}
