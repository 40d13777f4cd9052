//! The control loop: one dedicated thread, ticking on absolute deadlines
//! `t₀ + k·T` of the [`DaemonClock`] (no drift: a late tick does not shift the
//! next one; missed deadlines are skipped and counted as overruns).
//!
//! Per tick:
//! 1. newest pose (from `{prefix}/v2/pose`), newest machine state and CAN integrity
//!    counters (from the CAN I/O task);
//! 2. staleness and plausibility checks: every pose sample passes the
//!    [`crate::pose_gate`] (future stamps, jumps, workspace; a run of rejects is a
//!    pose fault), the machine state its bounds;
//! 3. the goal lifecycle's tick ([`crate::goal_lifecycle`]: the goal to drive, and
//!    whether it ended: succeeded, aborted on a fault or for lack of progress), then
//!    the mode decision (below);
//! 4. while tracking: the MPC step (which propagates the measured state over the
//!    actuator delay, `mpc.delay`, with the commands already sent, then solves);
//! 5. the command, through the stop ramp when stopping, to the CAN I/O task;
//! 6. telemetry on `{prefix}/v2/telemetry`, with at most one goal outcome (the oldest
//!    not yet reported); WATCHDOG=1 if the tick was healthy.
//!
//! Safety (DESIGN §6): a controlled stop — velocities ramped to zero at no more
//! than the machine's acceleration limits (β̈_max, a_max) from the last command —
//! on: no goal, goal reached, stale or implausible pose (a run of gate rejects) or
//! machine state,
//! persistent CAN integrity failures (consecutive rejected frames ≥
//! `loop.can_bad_frames_stop`; single ones are counted and flagged), a failed or
//! non-finite solve that persists beyond `loop.fallback_ticks` ticks on the
//! shifted plan, a stop or cancel request, no progress towards the goal, and
//! shutdown. A fault drops the goal (outcome `aborted`, reason `fault`): the machine
//! stays stopped until a new goal arrives after the fault has cleared.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use control::model::{ix, pose_error};
use control::{Goal, MachineParams, State};
use shm_ipc::{
    fault_flags, AbortReason, DaemonEndpoint, GoalOutcome, MachineState as IpcState, Mode, Pose2,
    Telemetry,
};
use tokio::sync::mpsc;

use crate::can::{DriveMode, MachineStatus};
use crate::can_io::{CanShared, CanSnapshot, OutCommand, RejectKind};
use crate::clock::DaemonClock;
use crate::config::Config;
use crate::controller::{Controller, PlanStatus, Step};
use crate::goal_lifecycle::{Abort, AcceptedGoal, TickInput, TickPlan};
use crate::ipc::{fault_names, SharedGoals};
use crate::log_limit::{LogDecision, LogLimiter};
use crate::notify::Notifier;
use crate::pose_gate::{PoseGate, PoseVerdict};
use crate::stats::LoopStats;

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitReason {
    /// Shutdown requested (signal or handle), machine stopped.
    Shutdown,
    /// `loop.max_ticks` reached, machine stopped.
    MaxTicks,
}

/// What the control thread shares with the rest of the daemon.
pub struct LoopContext {
    /// The configuration.
    pub config: Config,
    /// The clock.
    pub clock: DaemonClock,
    /// iceoryx2 endpoint (poses in, telemetry out).
    pub endpoint: Arc<DaemonEndpoint>,
    /// CAN receive side.
    pub can: Arc<CanShared>,
    /// CAN send side.
    pub commands: mpsc::Sender<OutCommand>,
    /// The goal lifecycle, shared with the IPC task.
    pub goals: Arc<SharedGoals>,
    /// Set to request a controlled stop and exit.
    pub shutdown: Arc<AtomicBool>,
    /// Loop statistics, shared with the reporter.
    pub stats: Arc<std::sync::Mutex<LoopStats>>,
}

/// The loop's state between ticks.
pub struct ControlLoop {
    ctx: LoopContext,
    controller: Box<dyn Controller>,
    notifier: Notifier,
    params: MachineParams,
    /// The goal generation the controller plans for, with a consistent command
    /// history (None: re-plan before the next step).
    engaged_generation: Option<u64>,
    /// Outcomes dropped so far (logged when it grows).
    dropped_outcomes: u64,
    /// Faults that hold until a new goal (solver failure).
    latched: u32,
    last_cmd: [f64; 2],
    /// Every pose sample passes this gate (age, future stamps, plausibility).
    pose_gate: PoseGate,
    /// Rejected pose samples are logged at a limited rate.
    pose_log: LogLimiter,
    fallback_count: u32,
    /// The subgoal of the global route driven to on the last tracking tick (None: the
    /// goal itself, or no global layer); the goal lifecycle's progress window runs
    /// towards it.
    subgoal: Option<Goal>,
    fallback_plan: Vec<State>,
    fallback_age: usize,
    prev_counters: crate::can::RxCounters,
    mode: Mode,
    telemetry: Telemetry,
    shutdown_started: Option<f64>,
    tick: u64,
    /// Fresh pose and machine state have been seen at least once (until then the
    /// mode stays `Startup`).
    seen_data: bool,
}

/// Moves `v` towards 0 by at most `step`.
fn towards_zero(v: f64, step: f64) -> f64 {
    if v.abs() <= step {
        0.0
    } else {
        v - step.copysign(v)
    }
}

impl ControlLoop {
    /// A loop around a controller that passed its first solve.
    pub fn new(ctx: LoopContext, controller: Box<dyn Controller>, notifier: Notifier) -> Self {
        let horizon = ctx.config.mpc.horizon;
        let params = ctx.config.machine;
        let pose_gate = PoseGate::new(ctx.config.pose_gate());
        Self {
            ctx,
            controller,
            notifier,
            params,
            engaged_generation: None,
            dropped_outcomes: 0,
            latched: 0,
            last_cmd: [0.0; 2],
            pose_gate,
            pose_log: LogLimiter::new(5, 10.0),
            fallback_count: 0,
            subgoal: None,
            fallback_plan: Vec::with_capacity(horizon + 1),
            fallback_age: 0,
            prev_counters: Default::default(),
            mode: Mode::Startup,
            telemetry: Telemetry::ZERO,
            shutdown_started: None,
            tick: 0,
            seen_data: false,
        }
    }

    /// Runs until shutdown (or `loop.max_ticks`); the last command sent is a stop.
    pub fn run(mut self) -> ExitReason {
        let period = self.ctx.config.control.period();
        let clock = self.ctx.clock;
        let t0 = clock.now();
        let mut k: u64 = 0;
        let reason = loop {
            let deadline = t0 + k as f64 * period;
            clock.sleep_until(deadline);
            let start = clock.now();
            let outcome = self.tick(start);
            let end = clock.now();
            let late_start = start - deadline;
            let overrun = end - deadline > period;
            let healthy = !overrun && late_start < period && outcome.sent;
            {
                let mut s = self.ctx.stats.lock().unwrap_or_else(|p| p.into_inner());
                s.record(late_start, outcome.solve_time, overrun);
            }
            if healthy {
                self.notifier.watchdog();
            }
            if let Some(r) = outcome.exit {
                break r;
            }
            // Next deadline: the next k whose deadline is still ahead (skip missed ones).
            k += 1;
            let now = clock.now();
            let next = t0 + k as f64 * period;
            if now > next {
                let missed = ((now - next) / period).floor() as u64 + 1;
                k += missed;
                let mut s = self.ctx.stats.lock().unwrap_or_else(|p| p.into_inner());
                s.missed_deadlines += missed;
            }
        };
        self.notifier.stopping("stopped: machine at rest");
        reason
    }

    fn set_mode(&mut self, mode: Mode, detail: &str) {
        if mode != self.mode {
            tracing::info!("mode {:?} -> {:?} {detail}", self.mode, mode);
            self.mode = mode;
            let text = format!(
                "{}{}{detail}",
                mode_name(mode),
                if detail.is_empty() { "" } else { ": " }
            );
            self.notifier.status(&text);
        }
    }

    fn disengage(&mut self) {
        self.engaged_generation = None;
        self.fallback_count = 0;
        self.subgoal = None;
    }

    /// Coming to rest without a goal: the ramp, `Stopping` until the command is zero,
    /// then `Idle`.
    fn come_to_rest(&self) -> (Mode, [f64; 2], DriveMode) {
        let cmd = self.ramp_down();
        if cmd == [0.0, 0.0] {
            (Mode::Idle, cmd, DriveMode::Hold)
        } else {
            (Mode::Stopping, cmd, DriveMode::Stop)
        }
    }

    /// The controlled-stop command: the last command ramped towards zero at the
    /// acceleration limits.
    fn ramp_down(&self) -> [f64; 2] {
        let dt = self.ctx.config.control.period();
        [
            towards_zero(self.last_cmd[0], self.params.beta_ddot_max * dt),
            towards_zero(self.last_cmd[1], self.params.a_max * dt),
        ]
    }

    /// Feeds every waiting pose sample through the gate (oldest first, bounded per tick);
    /// true if any was rejected.
    fn read_poses(&mut self) -> bool {
        // The subscriber buffer holds 16; the bound only guards against a publisher that
        // refills it faster than we drain.
        const MAX_SAMPLES_PER_TICK: usize = 64;
        let mut rejected = false;
        for _ in 0..MAX_SAMPLES_PER_TICK {
            let sample = match self.ctx.endpoint.receive_pose() {
                Ok(Some(p)) => p,
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!("pose: {e}");
                    break;
                }
            };
            let t = self.ctx.clock.from_monotonic_ns(sample.timestamp_ns);
            let now = self.ctx.clock.now();
            let valid = sample.flags & shm_ipc::pose_flags::VALID != 0;
            if let PoseVerdict::Rejected(why) = self.pose_gate.offer(sample.pose(), valid, t, now) {
                rejected = true;
                if let LogDecision::Log { suppressed } = self.pose_log.check(now) {
                    tracing::warn!(
                        "pose sample {} rejected: {why} ({} in a row{})",
                        sample.sequence,
                        self.pose_gate.reject_run(),
                        if suppressed > 0 {
                            format!("; {suppressed} more rejected since the last report")
                        } else {
                            String::new()
                        }
                    );
                }
            }
        }
        if let Some(n) = self.pose_log.summary(self.ctx.clock.now()) {
            tracing::warn!("{n} more pose samples rejected (not logged one by one)");
        }
        rejected
    }

    fn state_fresh(&self, can: &CanSnapshot, now: f64) -> Option<crate::can::MachineState> {
        let (s, t) = can.latest?;
        if now - t > self.ctx.config.control.state_timeout {
            return None;
        }
        let m = 1.0 + self.ctx.config.control.plausibility_margin;
        let p = &self.params;
        let plausible = s.beta.abs() <= p.beta_max * m
            && s.beta_dot.abs() <= p.beta_dot_max * m
            && s.v_f.abs() <= p.v_max * m;
        plausible.then_some(s)
    }

    fn tick(&mut self, start: f64) -> TickOutcome {
        let cfg = self.ctx.config.control;
        self.tick += 1;
        let mut t = Telemetry::ZERO;
        t.tick = self.tick;
        t.timestamp_ns = shm_ipc::monotonic_now_ns();
        let mut solve_time = None;

        let shutting_down = self.ctx.shutdown.load(Ordering::Relaxed)
            || (cfg.max_ticks > 0 && self.tick > cfg.max_ticks);
        if shutting_down && self.shutdown_started.is_none() {
            self.shutdown_started = Some(start);
            self.notifier
                .stopping("stopping: controlled stop before exit");
            tracing::info!("shutdown: controlled stop");
        }

        // Inputs.
        let pose_rejected = self.read_poses();
        let can = self.ctx.can.snapshot();
        let pose = self.pose_gate.fresh(start);
        let state = self.state_fresh(&can, start);

        let mut flags = 0u32;
        let mut stop_faults = 0u32;
        if pose.is_none() {
            flags |= fault_flags::POSE_STALE;
        }
        if pose_rejected || self.pose_gate.faulted() {
            flags |= fault_flags::POSE_REJECTED;
        }
        if self.pose_gate.faulted() {
            // A run of implausible samples: the pose source is not to be trusted.
            stop_faults |= fault_flags::POSE_REJECTED;
        }
        if state.is_none() {
            flags |= fault_flags::MACHINE_STATE_STALE;
        }
        let c = can.counters;
        let p = self.prev_counters;
        if c.bad_crc + c.wrong_length + c.out_of_range > p.bad_crc + p.wrong_length + p.out_of_range
        {
            flags |= fault_flags::CAN_CRC;
        }
        if c.frozen + c.skipped > p.frozen + p.skipped {
            flags |= fault_flags::CAN_ALIVE;
        }
        self.prev_counters = c;
        let persistent_can = c.consecutive_bad >= cfg.can_bad_frames_stop;
        if persistent_can {
            match can.last_reject {
                Some(RejectKind::Alive) => flags |= fault_flags::CAN_ALIVE,
                _ => flags |= fault_flags::CAN_CRC,
            }
        }
        if can.closed {
            flags |= fault_flags::CAN_BUS;
        }
        // Stale data and persistent integrity failures stop the machine.
        stop_faults |= flags
            & (fault_flags::POSE_STALE | fault_flags::MACHINE_STATE_STALE | fault_flags::CAN_BUS);
        // (A pose-gate fault was added to `stop_faults` above.)
        if persistent_can {
            stop_faults |= flags & (fault_flags::CAN_CRC | fault_flags::CAN_ALIVE);
        }
        let machine_blocked = matches!(
            state.map(|s| s.status),
            Some(MachineStatus::Manual | MachineStatus::EStop | MachineStatus::Fault)
        );

        // The measured state (for telemetry, goal check and the MPC).
        let x = match (pose, state) {
            (Some(p), Some(s)) => Some(State::from_column_slice(&[
                p.x, p.y, p.heading, s.beta, s.beta_dot, s.v_f,
            ])),
            _ => None,
        };
        if let Some(x) = &x {
            t.state = IpcState::from_array([x[0], x[1], x[2], x[3], x[4], x[5]]);
        } else {
            let mut a = [f64::NAN; 6];
            if let Some(p) = self.pose_gate.last() {
                a[0] = p.0.x;
                a[1] = p.0.y;
                a[2] = p.0.heading;
            }
            if let Some((s, _)) = can.latest {
                a[3] = s.beta;
                a[4] = s.beta_dot;
                a[5] = s.v_f;
            }
            t.state = IpcState::from_array(a);
        }

        self.seen_data |= x.is_some();

        // The goal lifecycle: what to drive, and whether the goal ended.
        let abort = if shutting_down {
            Some(Abort::new(AbortReason::Shutdown, "daemon shutting down"))
        } else if stop_faults | self.latched != 0 {
            Some(Abort::new(
                AbortReason::Fault,
                format!("fault: {}", fault_names(stop_faults | self.latched)),
            ))
        } else if machine_blocked {
            Some(Abort::new(
                AbortReason::Fault,
                format!(
                    "fault: machine status {:?}",
                    state.map(|s| s.status).unwrap_or(MachineStatus::Fault)
                ),
            ))
        } else {
            None
        };
        let (plan, operator_stop) = {
            let mut goals = self.ctx.goals.lock();
            let plan = goals.on_tick(TickInput {
                now: start,
                state: x.as_ref(),
                abort,
                blocking_faults: stop_faults | self.latched,
                subgoal: self.subgoal,
            });
            (plan, goals.operator_stop())
        };
        if operator_stop {
            flags |= fault_flags::STOP_REQUESTED;
        }
        // The goal shown in telemetry (dropped again if tracking fails below).
        let mut shown: Option<AcceptedGoal> = match plan {
            TickPlan::NoGoal => None,
            TickPlan::Hold(g) | TickPlan::Track(g) => Some(g),
        };
        if !matches!(plan, TickPlan::Track(_)) {
            self.disengage();
        }

        // Mode decision.
        let (mode, mut cmd, drive_mode);
        if shutting_down {
            mode = Mode::Stopping;
            cmd = self.ramp_down();
            drive_mode = DriveMode::Stop;
        } else if !self.seen_data && x.is_none() {
            // Waiting for the first pose and machine state.
            mode = Mode::Startup;
            cmd = self.ramp_down();
            drive_mode = DriveMode::Hold;
        } else if stop_faults != 0 || self.latched != 0 {
            flags |= self.latched;
            mode = Mode::Fault;
            cmd = self.ramp_down();
            drive_mode = DriveMode::Fault;
            if stop_faults == 0 && cmd == [0.0, 0.0] {
                // The solver fault has been shown through the whole stop; clear it.
                self.latched = 0;
            }
        } else {
            match plan {
                TickPlan::NoGoal => {
                    // No goal (none sent, or it ended) or the machine not in automatic
                    // mode: come to rest.
                    (mode, cmd, drive_mode) = self.come_to_rest();
                }
                TickPlan::Hold(_) => {
                    mode = Mode::Reached;
                    cmd = self.ramp_down();
                    drive_mode = if cmd == [0.0, 0.0] {
                        DriveMode::Hold
                    } else {
                        DriveMode::Stop
                    };
                }
                TickPlan::Track(g) => {
                    // Fresh data and no fault: x is Some here.
                    let x = x.unwrap_or_else(State::zeros);
                    let tracked = self.track(&x, &g, start, &mut t);
                    let (c, f, st) = tracked.unwrap_or(([0.0; 2], 0, None));
                    flags |= f;
                    solve_time = st;
                    if tracked.is_none() {
                        // The global layer ended the goal (no route, no progress).
                        self.disengage();
                        shown = None;
                        (mode, cmd, drive_mode) = self.come_to_rest();
                    } else if self.fallback_count > cfg.fallback_ticks {
                        tracing::error!(
                            "solver failed {} ticks in a row: controlled stop",
                            self.fallback_count
                        );
                        self.latched |= fault_flags::SOLVE_FAILED;
                        // This tick stops instead of driving on the fallback plan.
                        flags = (flags & !fault_flags::FALLBACK_PLAN) | fault_flags::SOLVE_FAILED;
                        self.ctx.goals.lock().abort_active(Abort::new(
                            AbortReason::Fault,
                            format!("fault: solve failed {} ticks in a row", self.fallback_count),
                        ));
                        self.disengage();
                        shown = None;
                        mode = Mode::Fault;
                        cmd = self.ramp_down();
                        drive_mode = DriveMode::Fault;
                    } else {
                        mode = Mode::Tracking;
                        cmd = c;
                        drive_mode = DriveMode::Drive;
                    }
                }
            }
        }

        // Last-line bounds (the CAN task checks again).
        let p = &self.params;
        if !(cmd[0].is_finite() && cmd[1].is_finite()) {
            cmd = self.ramp_down();
        }
        cmd[0] = cmd[0].clamp(-p.beta_dot_max, p.beta_dot_max);
        cmd[1] = cmd[1].clamp(-p.v_max, p.v_max);

        // Shutdown completes once the command is zero and the machine at rest (or
        // its state is unknown, or the timeout passed).
        let mut exit = None;
        if let Some(t_stop) = self.shutdown_started {
            let at_rest = match state {
                Some(s) => s.v_f.abs() < cfg.rest_speed && s.beta_dot.abs() < cfg.rest_speed,
                None => true,
            };
            let timed_out = start - t_stop > cfg.shutdown_timeout;
            if cmd == [0.0, 0.0] && (at_rest || timed_out) {
                exit = Some(if self.ctx.shutdown.load(Ordering::Relaxed) {
                    ExitReason::Shutdown
                } else {
                    ExitReason::MaxTicks
                });
            }
        }

        let out = OutCommand {
            beta_dot: cmd[0],
            v: cmd[1],
            mode: drive_mode,
        };
        let sent = match self.ctx.commands.try_send(out) {
            Ok(()) => true,
            Err(e) => {
                flags |= fault_flags::CAN_BUS;
                tracing::warn!("command not queued: {e}");
                false
            }
        };
        self.last_cmd = cmd;
        let detail = match (&shown, mode) {
            (Some(g), _) => format!(
                "goal ({:.2}, {:.2}, {:.2})",
                g.goal.x, g.goal.y, g.goal.theta
            ),
            (None, Mode::Fault) => format!("faults {flags:#x}"),
            _ => String::new(),
        };
        self.set_mode(mode, &detail);

        // Telemetry.
        t.mode = mode.code();
        t.fault_flags = flags;
        t.command.beta_dot = cmd[0];
        t.command.v = cmd[1];
        if let Some(g) = &shown {
            t.goal_active = 1;
            t.goal = Pose2::new(g.goal.x, g.goal.y, g.goal.theta);
            t.goal_request_id = g.request_id;
            if let Some(x) = &x {
                let e = pose_error(x, &g.goal);
                t.pose_error_xy = e[0];
                t.pose_error_heading = e[1];
            }
        }
        self.report_outcome(&mut t);
        if let Err(e) = self.ctx.endpoint.publish_telemetry(&t) {
            tracing::warn!("telemetry: {e}");
        }
        self.telemetry = t;
        TickOutcome {
            sent,
            solve_time,
            exit,
        }
    }

    /// Puts the oldest goal outcome not yet reported (if any) on this tick's telemetry.
    fn report_outcome(&mut self, t: &mut Telemetry) {
        let (outcome, dropped) = {
            let mut goals = self.ctx.goals.lock();
            (goals.next_outcome(), goals.dropped_outcomes())
        };
        if dropped > self.dropped_outcomes {
            tracing::warn!(
                "{} goal outcome(s) dropped: goals ended faster than one per tick",
                dropped - self.dropped_outcomes
            );
            self.dropped_outcomes = dropped;
        }
        let Some(o) = outcome else {
            return;
        };
        let name = match o.outcome {
            GoalOutcome::Aborted => format!("aborted ({})", o.abort_reason.name()),
            other => other.name().to_owned(),
        };
        tracing::info!("goal {} {name}: {}", o.request_id, o.text);
        t.set_outcome(o.request_id, o.outcome, o.abort_reason, o.seq, &o.text);
    }

    /// One tracking tick: the controller's step, with the fallback on the shifted plan.
    /// `None` when the global layer ended the goal (reported to the goal lifecycle).
    fn track(
        &mut self,
        x: &State,
        g: &AcceptedGoal,
        now: f64,
        t: &mut Telemetry,
    ) -> Option<([f64; 2], u32, Option<f64>)> {
        let mut flags = 0;
        if self.engaged_generation != Some(g.generation) {
            tracing::info!(
                "goal {}: ({:.2}, {:.2}, {:.2}) with {} obstacle(s)",
                g.request_id,
                g.goal.x,
                g.goal.y,
                g.goal.theta,
                g.obstacles().len()
            );
            self.controller.reset();
            self.latched = 0;
            self.fallback_count = 0;
            if let Err(e) = self.controller.set_goal(x, g.goal, g.obstacles()) {
                // Validated goals cannot fail here; treat it as a solver failure.
                tracing::error!("controller refused the goal: {e}");
                self.fallback_count = u32::MAX / 2;
                return Some((self.ramp_down(), fault_flags::SOLVE_FAILED, None));
            }
            self.engaged_generation = Some(g.generation);
            self.fallback_plan.clear();
            self.fallback_age = 0;
        }
        let result = self.controller.step(x, now);
        let mut solve_time = None;
        let good = match result {
            Ok(Step::Abort(reason)) => {
                let (wire, what) = match reason {
                    control::planner::AbortReason::NoRoute => (
                        AbortReason::NoRoute,
                        "the global layer found no collision-free route",
                    ),
                    control::planner::AbortReason::NoProgress => (
                        AbortReason::NoProgress,
                        "no approach to the route's target after replanning",
                    ),
                };
                self.ctx.goals.lock().abort_active(Abort::new(wire, what));
                return None;
            }
            Ok(Step::Drive(plan)) => {
                self.subgoal = plan.subgoal;
                if let Some(s) = plan.subgoal {
                    t.subgoal_active = 1;
                    t.subgoal = Pose2::new(s.x, s.y, s.theta);
                }
                let mut route = [Pose2::new(0.0, 0.0, 0.0); shm_ipc::MAX_ROUTE];
                let n = plan.route.len().min(shm_ipc::MAX_ROUTE);
                for (dst, g) in route.iter_mut().zip(plan.route) {
                    *dst = Pose2::new(g.x, g.y, g.theta);
                }
                t.set_route(&route[..n]);
                solve_time = Some(plan.solve_time.as_secs_f64());
                t.solve_time_us = plan.solve_time.as_secs_f64() * 1e6;
                t.cost = plan.cost;
                t.qp_iterations = plan.qp_iterations;
                t.sqp_iterations = plan.sqp_iterations;
                let finite = plan.command.iter().all(|v| v.is_finite())
                    && plan.states.iter().all(|s| s.iter().all(|v| v.is_finite()));
                let mut traj = [IpcState::ZERO; shm_ipc::MAX_TRAJECTORY];
                let n = plan.states.len().min(shm_ipc::MAX_TRAJECTORY);
                for (dst, s) in traj.iter_mut().zip(plan.states) {
                    *dst = IpcState::from_array([s[0], s[1], s[2], s[3], s[4], s[5]]);
                }
                t.set_trajectory(&traj[..n]);
                if finite {
                    self.fallback_plan.clear();
                    self.fallback_plan.extend_from_slice(plan.states);
                    self.fallback_age = 0;
                    Some((plan.command, plan.status))
                } else {
                    None
                }
            }
            Err(e) => {
                tracing::warn!("solve failed: {e}");
                None
            }
        };
        let cmd = match good {
            Some((c, PlanStatus::Solved)) => {
                self.fallback_count = 0;
                c
            }
            Some((c, PlanStatus::Fallback)) => {
                // The controller already shifted its plan.
                self.fallback_count += 1;
                flags |= fault_flags::FALLBACK_PLAN;
                c
            }
            None => {
                // No usable plan this tick: drive on our copy of the last one, shifted.
                self.fallback_count += 1;
                self.fallback_age += 1;
                flags |= fault_flags::FALLBACK_PLAN;
                match self.fallback_plan.get(self.fallback_age) {
                    Some(s) => [s[ix::BETA_DOT], s[ix::V]],
                    None => self.ramp_down(),
                }
            }
        };
        Some((cmd, flags, solve_time))
    }
}

struct TickOutcome {
    sent: bool,
    solve_time: Option<f64>,
    exit: Option<ExitReason>,
}

/// The mode's name as used in STATUS= and logs.
pub fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Startup => "startup",
        Mode::Idle => "idle",
        Mode::Tracking => "tracking",
        Mode::Reached => "reached",
        Mode::Stopping => "stopping",
        Mode::Fault => "fault",
    }
}
