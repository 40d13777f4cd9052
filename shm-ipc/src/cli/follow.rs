//! Following one goal through telemetry: when the daemon took it up, when it converged
//! (DESIGN §7 test), when the daemon declared it reached, or why it failed. Used by
//! `wlnav goal --wait`, `wlnav demo` and the end-to-end tests.

use crate::msg::{fault_flags, Mode, Pose2, Telemetry};

use super::view::{fault_text, goal_distance, mode_name};

/// DESIGN §7 success tolerance on ‖(x_f − x_g, y_f − y_g, e_θ)‖.
pub const CONVERGED_TOLERANCE: f64 = 0.1;

/// Fault bits that end a goal when the daemon is stopping or faulted (an overrun alone is
/// reported but does not end a goal).
const ENDING_FAULTS: u32 = !fault_flags::OVERRUN;

/// Where a followed goal stands after a telemetry sample.
#[derive(Debug, Clone, PartialEq)]
pub enum GoalStatus {
    /// The daemon has not reported this goal yet (its telemetry still shows another one).
    Pending,
    /// The daemon drives towards this goal.
    Active,
    /// The daemon reports the goal reached.
    Reached,
    /// The goal ended without being reached; the text says why.
    Failed(String),
}

impl GoalStatus {
    /// True for [`GoalStatus::Reached`] and [`GoalStatus::Failed`].
    pub fn is_final(&self) -> bool {
        matches!(self, Self::Reached | Self::Failed(_))
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
    /// Tick at which the daemon reported the goal reached.
    pub reached_tick: Option<u64>,
    /// Most recent tick seen.
    pub last_tick: Option<u64>,
    /// Overruns (fault bit) seen while following.
    pub overruns: u64,
    /// Largest solve time seen while the goal was active [µs].
    pub max_solve_us: f64,
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
        }
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

    /// Feeds one telemetry sample (samples before the goal appeared are ignored) and
    /// returns the new status. Once final, the status does not change.
    pub fn update(&mut self, t: &Telemetry) -> &GoalStatus {
        if self.status.is_final() {
            return &self.status;
        }
        self.last_tick = Some(t.tick);
        let ours = t.goal_request_id == self.request_id;
        if !ours {
            if self.first_tick.is_some() {
                let why = if t.goal_request_id == 0 || t.goal_active == 0 {
                    format!(
                        "the daemon dropped the goal at tick {} (mode {}, faults {})",
                        t.tick,
                        mode_name(t.mode),
                        fault_text(t.fault_flags)
                    )
                } else {
                    format!(
                        "superseded at tick {} by request {}",
                        t.tick, t.goal_request_id
                    )
                };
                self.status = GoalStatus::Failed(why);
            }
            return &self.status;
        }
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
        match t.mode() {
            Ok(Mode::Reached) => {
                self.reached_tick = Some(t.tick);
                self.status = GoalStatus::Reached;
            }
            Ok(Mode::Fault) => {
                self.status = GoalStatus::Failed(format!(
                    "daemon fault at tick {}: {}",
                    t.tick,
                    fault_text(t.fault_flags)
                ));
            }
            Ok(Mode::Stopping) if t.fault_flags & ENDING_FAULTS != 0 => {
                self.status = GoalStatus::Failed(format!(
                    "controlled stop at tick {}: {}",
                    t.tick,
                    fault_text(t.fault_flags)
                ));
            }
            Ok(Mode::Idle) => {
                self.status = GoalStatus::Failed(format!(
                    "the daemon went idle at tick {} (faults {})",
                    t.tick,
                    fault_text(t.fault_flags)
                ));
            }
            Ok(_) => {}
            Err(code) => {
                self.status =
                    GoalStatus::Failed(format!("unknown mode code {code} at tick {}", t.tick));
            }
        }
        &self.status
    }

    /// Marks the goal failed (timeout, daemon gone) unless it already ended.
    pub fn fail(&mut self, why: impl Into<String>) {
        if !self.status.is_final() {
            self.status = GoalStatus::Failed(why.into());
        }
    }
}
