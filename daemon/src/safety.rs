//! The safety decisions of one tick (DESIGN §6), as pure functions of what the
//! tick observed: which faults the inputs show ([`input_faults`]), whether the
//! goal must end ([`goal_abort`]), whether to drive or stop and why
//! ([`decide`], [`after_solve`]), and the mode and CAN drive mode of a stop
//! ([`StopCause::modes`]). The control loop gathers the inputs and carries the
//! decisions out; every branch here is unit-tested without a daemon.
//!
//! Every stop is a controlled stop: braking at the acceleration limits from the
//! last command or the machine's own velocity, whichever is nearer zero
//! (`control::envelope::stop_command`, one function with the safety envelope's
//! stop).

use shm_ipc::{fault_flags, AbortReason, Mode};

use crate::can::{DriveMode, MachineStatus, RxCounters};
use crate::can_io::{CanSnapshot, RejectKind};
use crate::goal_lifecycle::{Abort, TickPlan};

/// Why the machine is brought to rest (or kept there) this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopCause {
    /// The daemon is shutting down (signal, `loop.max_ticks`).
    Shutdown,
    /// No fresh pose and machine state seen yet since start.
    WaitingForData,
    /// A fault stops the machine (the [`fault_flags`] bits: stale or rejected
    /// pose, stale machine state, CAN bus or persistent integrity failures, a
    /// latched solver failure).
    Fault(u32),
    /// No goal: none was sent, or it ended (cancelled, no progress, aborted).
    NoGoal,
    /// An operator stop is latched (no goal until resume).
    StopRequested,
    /// The goal was reached: hold it.
    Reached,
    /// The global layer ended the goal this tick (no route, no progress
    /// towards its target).
    RouteEnded,
    /// The solver failed more than `loop.fallback_ticks` ticks in a row.
    SolveFailed,
}

/// What a tick does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Step the controller and send its command.
    Track,
    /// Ramp the last command down to zero.
    Stop(StopCause),
}

impl StopCause {
    /// The mode shown and the drive mode sent while stopping for this cause;
    /// `at_zero`: the ramped command has reached zero.
    pub fn modes(self, at_zero: bool) -> (Mode, DriveMode) {
        let ramping = |done| if at_zero { done } else { DriveMode::Stop };
        match self {
            Self::Shutdown => (Mode::Stopping, DriveMode::Stop),
            Self::WaitingForData => (Mode::Startup, DriveMode::Hold),
            Self::Fault(_) | Self::SolveFailed => (Mode::Fault, DriveMode::Fault),
            Self::Reached => (Mode::Reached, ramping(DriveMode::Hold)),
            Self::NoGoal | Self::StopRequested | Self::RouteEnded => {
                if at_zero {
                    (Mode::Idle, DriveMode::Hold)
                } else {
                    (Mode::Stopping, DriveMode::Stop)
                }
            }
        }
    }
}

/// The fault flags of a tick's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InputFaults {
    /// Everything to show in telemetry.
    pub flags: u32,
    /// The subset that stops the machine.
    pub stop: u32,
}

/// What the pose gate and the machine-state check found this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputHealth {
    /// A fresh accepted pose exists.
    pub pose_fresh: bool,
    /// A pose sample was rejected this tick.
    pub pose_rejected: bool,
    /// The gate saw a run of rejects: the pose source is not to be trusted.
    pub pose_faulted: bool,
    /// A fresh, plausible machine state exists.
    pub state_fresh: bool,
}

/// Faults from the inputs: stale data and a pose-gate fault stop the machine;
/// single bad CAN frames are shown, and stop it once `can_bad_frames_stop`
/// arrive in a row; a closed bus stops it. `prev` are the counters of the
/// previous tick (new rejects since then raise the flags).
pub fn input_faults(
    health: InputHealth,
    can: &CanSnapshot,
    prev: &RxCounters,
    can_bad_frames_stop: u32,
) -> InputFaults {
    let mut f = InputFaults::default();
    if !health.pose_fresh {
        f.flags |= fault_flags::POSE_STALE;
    }
    if health.pose_rejected || health.pose_faulted {
        f.flags |= fault_flags::POSE_REJECTED;
    }
    if health.pose_faulted {
        f.stop |= fault_flags::POSE_REJECTED;
    }
    if !health.state_fresh {
        f.flags |= fault_flags::MACHINE_STATE_STALE;
    }
    let (c, p) = (&can.counters, prev);
    if c.bad_crc + c.wrong_length + c.out_of_range > p.bad_crc + p.wrong_length + p.out_of_range {
        f.flags |= fault_flags::CAN_CRC;
    }
    if c.frozen + c.skipped > p.frozen + p.skipped {
        f.flags |= fault_flags::CAN_ALIVE;
    }
    if c.consecutive_bad >= can_bad_frames_stop {
        let bit = match can.last_reject {
            Some(RejectKind::Alive) => fault_flags::CAN_ALIVE,
            _ => fault_flags::CAN_CRC,
        };
        f.flags |= bit;
        f.stop |= f.flags & (fault_flags::CAN_CRC | fault_flags::CAN_ALIVE);
    }
    if can.closed {
        f.flags |= fault_flags::CAN_BUS;
    }
    f.stop |= f.flags
        & (fault_flags::POSE_STALE | fault_flags::MACHINE_STATE_STALE | fault_flags::CAN_BUS);
    f
}

/// Why the goal being driven must end this tick, if it must: shutdown, a fault
/// (`faults`: stopping and latched bits), or a machine not in automatic mode.
pub fn goal_abort(
    shutting_down: bool,
    faults: u32,
    status: Option<MachineStatus>,
) -> Option<Abort> {
    if shutting_down {
        return Some(Abort::new(AbortReason::Shutdown, "daemon shutting down"));
    }
    if faults != 0 {
        return Some(Abort::new(
            AbortReason::Fault,
            format!("fault: {}", fault_flags::names(faults).join(", ")),
        ));
    }
    match status {
        Some(s @ (MachineStatus::Manual | MachineStatus::EStop | MachineStatus::Fault)) => Some(
            Abort::new(AbortReason::Fault, format!("fault: machine status {s:?}")),
        ),
        _ => None,
    }
}

/// What [`decide`] looks at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Situation {
    /// Shutdown requested.
    pub shutting_down: bool,
    /// Fresh pose and machine state seen at least once (this tick included).
    pub seen_data: bool,
    /// Faults that stop the machine now, and the latched ones.
    pub faults: u32,
    /// An operator stop is latched.
    pub stop_requested: bool,
    /// The goal lifecycle's plan.
    pub goal: GoalPlan,
}

/// The goal lifecycle's plan, without the goal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalPlan {
    /// No goal.
    None,
    /// The goal is reached: hold.
    Hold,
    /// Drive to the goal.
    Track,
}

impl From<&TickPlan> for GoalPlan {
    fn from(p: &TickPlan) -> Self {
        match p {
            TickPlan::NoGoal => Self::None,
            TickPlan::Hold(_) => Self::Hold,
            TickPlan::Track(_) => Self::Track,
        }
    }
}

/// Drive or stop, in priority order: shutdown, waiting for the first data,
/// faults, then the goal's plan.
pub fn decide(s: &Situation) -> Decision {
    let cause = if s.shutting_down {
        StopCause::Shutdown
    } else if !s.seen_data {
        StopCause::WaitingForData
    } else if s.faults != 0 {
        StopCause::Fault(s.faults)
    } else {
        match s.goal {
            GoalPlan::Track => return Decision::Track,
            GoalPlan::Hold => StopCause::Reached,
            GoalPlan::None if s.stop_requested => StopCause::StopRequested,
            GoalPlan::None => StopCause::NoGoal,
        }
    };
    Decision::Stop(cause)
}

/// What the controller's step gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveResult {
    /// A fresh solution.
    Solved,
    /// The controller's own fallback (its shifted previous plan).
    Fallback,
    /// No usable command (an error, a non-finite plan).
    Failed,
    /// The global layer ended the goal.
    RouteEnded,
}

/// After the controller's step: drive on, or stop. `failures` counts the
/// ticks in a row without a fresh solution (this one included); beyond
/// `fallback_ticks` the machine stops. A failed tick within that allowance
/// ramps down but keeps tracking (the next solve may recover).
pub fn after_solve(result: SolveResult, failures: u32, fallback_ticks: u32) -> Decision {
    match result {
        SolveResult::RouteEnded => Decision::Stop(StopCause::RouteEnded),
        SolveResult::Fallback | SolveResult::Failed if failures > fallback_ticks => {
            Decision::Stop(StopCause::SolveFailed)
        }
        _ => Decision::Track,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can_io::CanSnapshot;

    const HEALTHY: InputHealth = InputHealth {
        pose_fresh: true,
        pose_rejected: false,
        pose_faulted: false,
        state_fresh: true,
    };

    fn situation(goal: GoalPlan) -> Situation {
        Situation {
            shutting_down: false,
            seen_data: true,
            faults: 0,
            stop_requested: false,
            goal,
        }
    }

    fn faults(health: InputHealth, can: &CanSnapshot) -> InputFaults {
        input_faults(health, can, &RxCounters::default(), 5)
    }

    /// The stop cause a tick with these input faults decides on.
    fn cause_of(f: InputFaults) -> Decision {
        decide(&Situation {
            faults: f.stop,
            ..situation(GoalPlan::Track)
        })
    }

    #[test]
    fn healthy_inputs_with_a_goal_drive() {
        let f = faults(HEALTHY, &CanSnapshot::default());
        assert_eq!(f, InputFaults::default());
        assert_eq!(cause_of(f), Decision::Track);
        assert_eq!(goal_abort(false, 0, Some(MachineStatus::Auto)), None);
    }

    #[test]
    fn stop_cause_shutdown() {
        let s = Situation {
            shutting_down: true,
            ..situation(GoalPlan::Track)
        };
        assert_eq!(decide(&s), Decision::Stop(StopCause::Shutdown));
        let abort = goal_abort(true, 0, Some(MachineStatus::Auto)).unwrap();
        assert_eq!(abort.reason, AbortReason::Shutdown);
        assert_eq!(
            StopCause::Shutdown.modes(true),
            (Mode::Stopping, DriveMode::Stop)
        );
    }

    #[test]
    fn stop_cause_waiting_for_the_first_data() {
        let s = Situation {
            seen_data: false,
            ..situation(GoalPlan::Track)
        };
        assert_eq!(decide(&s), Decision::Stop(StopCause::WaitingForData));
        assert_eq!(
            StopCause::WaitingForData.modes(false),
            (Mode::Startup, DriveMode::Hold)
        );
    }

    #[test]
    fn stop_cause_stale_pose() {
        let f = faults(
            InputHealth {
                pose_fresh: false,
                ..HEALTHY
            },
            &CanSnapshot::default(),
        );
        assert_eq!(f.stop, fault_flags::POSE_STALE);
        assert_eq!(
            cause_of(f),
            Decision::Stop(StopCause::Fault(fault_flags::POSE_STALE))
        );
        assert_eq!(
            StopCause::Fault(f.stop).modes(false),
            (Mode::Fault, DriveMode::Fault)
        );
    }

    #[test]
    fn stop_cause_a_run_of_rejected_poses_but_not_a_single_one() {
        let single = faults(
            InputHealth {
                pose_rejected: true,
                ..HEALTHY
            },
            &CanSnapshot::default(),
        );
        assert_eq!(single.flags, fault_flags::POSE_REJECTED);
        assert_eq!(cause_of(single), Decision::Track);
        let run = faults(
            InputHealth {
                pose_faulted: true,
                ..HEALTHY
            },
            &CanSnapshot::default(),
        );
        assert_eq!(
            cause_of(run),
            Decision::Stop(StopCause::Fault(fault_flags::POSE_REJECTED))
        );
    }

    #[test]
    fn stop_cause_stale_machine_state() {
        let f = faults(
            InputHealth {
                state_fresh: false,
                ..HEALTHY
            },
            &CanSnapshot::default(),
        );
        assert_eq!(
            cause_of(f),
            Decision::Stop(StopCause::Fault(fault_flags::MACHINE_STATE_STALE))
        );
    }

    #[test]
    fn stop_cause_can_bus_closed() {
        let can = CanSnapshot {
            closed: true,
            ..Default::default()
        };
        assert_eq!(
            cause_of(faults(HEALTHY, &can)),
            Decision::Stop(StopCause::Fault(fault_flags::CAN_BUS))
        );
    }

    #[test]
    fn stop_cause_persistent_can_integrity_and_alive_failures_but_not_single_frames() {
        let mut can = CanSnapshot::default();
        can.counters.bad_crc = 1;
        can.counters.consecutive_bad = 1;
        let single = faults(HEALTHY, &can);
        assert_eq!(single.flags, fault_flags::CAN_CRC);
        assert_eq!(cause_of(single), Decision::Track);
        // The counters of this tick are the previous ones: nothing new to flag.
        assert_eq!(input_faults(HEALTHY, &can, &can.counters, 5).flags, 0);

        can.counters.consecutive_bad = 5;
        can.last_reject = Some(RejectKind::Integrity);
        assert_eq!(
            cause_of(faults(HEALTHY, &can)),
            Decision::Stop(StopCause::Fault(fault_flags::CAN_CRC))
        );
        let mut alive = CanSnapshot::default();
        alive.counters.frozen = 5;
        alive.counters.consecutive_bad = 5;
        alive.last_reject = Some(RejectKind::Alive);
        assert_eq!(
            cause_of(faults(HEALTHY, &alive)),
            Decision::Stop(StopCause::Fault(fault_flags::CAN_ALIVE))
        );
    }

    #[test]
    fn stop_cause_latched_solver_fault_holds_until_cleared() {
        let s = Situation {
            faults: fault_flags::SOLVE_FAILED,
            ..situation(GoalPlan::Track)
        };
        assert_eq!(
            decide(&s),
            Decision::Stop(StopCause::Fault(fault_flags::SOLVE_FAILED))
        );
        let abort = goal_abort(false, fault_flags::SOLVE_FAILED, None).unwrap();
        assert_eq!(abort.reason, AbortReason::Fault);
        assert!(abort.text.contains("fault"), "{}", abort.text);
    }

    #[test]
    fn stop_cause_machine_not_in_automatic_mode_ends_the_goal() {
        for status in [
            MachineStatus::Manual,
            MachineStatus::EStop,
            MachineStatus::Fault,
        ] {
            let abort = goal_abort(false, 0, Some(status)).unwrap();
            assert_eq!(abort.reason, AbortReason::Fault);
            assert!(
                abort.text.contains(&format!("{status:?}")),
                "{}",
                abort.text
            );
        }
        for status in [MachineStatus::Ready, MachineStatus::Auto] {
            assert_eq!(goal_abort(false, 0, Some(status)), None);
        }
        // Ended, the goal is gone: the lifecycle's next plan is no goal.
        assert_eq!(
            decide(&situation(GoalPlan::None)),
            Decision::Stop(StopCause::NoGoal)
        );
    }

    #[test]
    fn stop_cause_no_goal_ramps_then_idles() {
        assert_eq!(
            decide(&situation(GoalPlan::None)),
            Decision::Stop(StopCause::NoGoal)
        );
        assert_eq!(
            StopCause::NoGoal.modes(false),
            (Mode::Stopping, DriveMode::Stop)
        );
        assert_eq!(StopCause::NoGoal.modes(true), (Mode::Idle, DriveMode::Hold));
    }

    #[test]
    fn stop_cause_operator_stop() {
        let s = Situation {
            stop_requested: true,
            ..situation(GoalPlan::None)
        };
        assert_eq!(decide(&s), Decision::Stop(StopCause::StopRequested));
        assert_eq!(
            StopCause::StopRequested.modes(true),
            (Mode::Idle, DriveMode::Hold)
        );
    }

    #[test]
    fn stop_cause_goal_reached_holds() {
        assert_eq!(
            decide(&situation(GoalPlan::Hold)),
            Decision::Stop(StopCause::Reached)
        );
        assert_eq!(
            StopCause::Reached.modes(false),
            (Mode::Reached, DriveMode::Stop)
        );
        assert_eq!(
            StopCause::Reached.modes(true),
            (Mode::Reached, DriveMode::Hold)
        );
    }

    #[test]
    fn stop_cause_route_ended_by_the_global_layer() {
        assert_eq!(
            after_solve(SolveResult::RouteEnded, 0, 3),
            Decision::Stop(StopCause::RouteEnded)
        );
        assert_eq!(
            StopCause::RouteEnded.modes(true),
            (Mode::Idle, DriveMode::Hold)
        );
    }

    #[test]
    fn stop_cause_solve_failed_beyond_the_fallback_allowance() {
        for result in [SolveResult::Fallback, SolveResult::Failed] {
            for failures in 1..=3 {
                assert_eq!(after_solve(result, failures, 3), Decision::Track);
            }
            assert_eq!(
                after_solve(result, 4, 3),
                Decision::Stop(StopCause::SolveFailed)
            );
        }
        assert_eq!(after_solve(SolveResult::Solved, 0, 3), Decision::Track);
        assert_eq!(
            StopCause::SolveFailed.modes(true),
            (Mode::Fault, DriveMode::Fault)
        );
    }

    #[test]
    fn priorities_shutdown_then_startup_then_faults_then_goal() {
        let all = Situation {
            shutting_down: true,
            seen_data: false,
            faults: fault_flags::POSE_STALE,
            stop_requested: true,
            goal: GoalPlan::Track,
        };
        assert_eq!(decide(&all), Decision::Stop(StopCause::Shutdown));
        let s = Situation {
            shutting_down: false,
            ..all
        };
        assert_eq!(decide(&s), Decision::Stop(StopCause::WaitingForData));
        let s = Situation {
            seen_data: true,
            ..s
        };
        assert_eq!(
            decide(&s),
            Decision::Stop(StopCause::Fault(fault_flags::POSE_STALE))
        );
    }
}
