//! The control loop: one dedicated thread, ticking on absolute deadlines
//! `t₀ + k·T` of the [`DaemonClock`] (no drift: a late tick does not shift the
//! next one; missed deadlines are skipped and counted as overruns).
//!
//! Per tick ([`ControlLoop::tick`], a short pipeline; every decision that matters
//! for safety is a pure function in [`crate::safety`], unit-tested there):
//! 1. inputs: every waiting pose sample through the [`crate::pose_gate`] (future
//!    stamps, jumps, workspace; a run of rejects is a pose fault), the newest machine
//!    state (fresh and plausible) and the CAN integrity counters; the faults they
//!    show ([`safety::input_faults`]);
//! 2. the goal lifecycle's tick ([`crate::goal_lifecycle`]: the goal to drive, and
//!    whether it ended: succeeded, aborted on a fault ([`safety::goal_abort`]) or for
//!    lack of progress);
//! 3. the decision ([`safety::decide`]): drive, or stop with its cause; while
//!    driving, the controller's step (it owns the fallback on its shifted plan) and
//!    [`safety::after_solve`] (a global-layer abort, or too many ticks without a
//!    fresh solve, stops);
//! 4. the command — the controller's, or the stop ramp ([`envelope::stop_command`]) —
//!    limited to the machine's bounds, to the CAN I/O task, and back to the
//!    controller ([`Controller::sent`]: its delay compensation runs on the daemon's
//!    clock with the commands actually sent);
//! 5. telemetry on `{prefix}/v2/telemetry`, with at most one goal outcome (the oldest
//!    not yet reported); WATCHDOG=1 if the tick was healthy.
//!
//! Safety (DESIGN §6): a controlled stop — velocities ramped to zero at no more
//! than the machine's acceleration limits (β̈_max, a_max) from the last command —
//! on: no goal, goal reached, stale or implausible pose (a run of gate rejects) or
//! machine state, persistent CAN integrity failures (consecutive rejected frames ≥
//! `loop.can_bad_frames_stop`; single ones are counted and flagged), a solve that
//! fails for more than `loop.fallback_ticks` ticks, a stop or cancel request, no
//! progress towards the goal, no route, and shutdown. A fault drops the goal
//! (outcome `aborted`, reason `fault`): the machine stays stopped until a new goal
//! arrives after the fault has cleared.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use control::delay::compensate_pose_age;
use control::envelope::{self, Guarded};
use control::live::LiveSet;
use control::model::pose_error;
use control::pilot::LiveStatus;
use control::{MachineParams, State, VelocityCommand};
use shm_ipc::{fault_flags, AbortReason, DaemonEndpoint, GoalOutcome, Mode, Pose2, Telemetry};
use tokio::sync::mpsc;

use crate::can::{DriveMode, MachineState};
use crate::can_io::{CanShared, CanSnapshot, OutCommand};
use crate::clock::DaemonClock;
use crate::config::Config;
use crate::controller::{Controller, PlanStatus, Step};
use crate::goal_lifecycle::{Abort, AcceptedGoal, TickInput, TickPlan};
use crate::ipc::{wire_state, SharedGoals};
use crate::log_limit::{LogDecision, LogLimiter};
use crate::notify::Notifier;
use crate::pose_gate::{PoseGate, PoseVerdict};
use crate::safety::{self, Decision, InputFaults, InputHealth, Situation, SolveResult, StopCause};
use crate::stats::LoopStats;

mod live;
use live::live_flags;
pub use live::MIN_LIVE_SPACING;

/// `solve_failures` of a goal the controller refused outright (validated
/// goals cannot be refused; it stops at once, as after too many failed solves).
const GOAL_REFUSED: u32 = u32::MAX;

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
    /// The site in force (DESIGN §17).
    site: Option<std::sync::Arc<control::site::SiteIndex>>,
    /// A replaced site the slot was too busy to take back: handed back at a
    /// later tick, never freed here.
    retiring: Option<std::sync::Arc<control::site::SiteIndex>>,
    ctx: LoopContext,
    controller: Box<dyn Controller>,
    notifier: Notifier,
    params: MachineParams,
    /// The tick period: the MPC's Δt.
    period: f64,
    /// The goal generation the controller plans for (None: set the goal before the
    /// next step).
    engaged_generation: Option<u64>,
    /// Outcomes dropped so far (logged when it grows).
    dropped_outcomes: u64,
    /// Faults that hold until the stop is complete (solver failure).
    latched: u32,
    /// The last command sent (the stop ramp starts from it).
    last_command: VelocityCommand,
    /// Envelope overrides are logged at a limited rate.
    envelope_log: LogLimiter,
    /// Every pose sample passes this gate (age, future stamps, plausibility).
    pose_gate: PoseGate,
    /// Rejected pose samples are logged at a limited rate.
    pose_log: LogLimiter,
    /// Ticks in a row without a fresh solution.
    solve_failures: u32,
    prev_counters: crate::can::RxCounters,
    mode: Mode,
    shutdown_started: Option<f64>,
    tick: u64,
    /// Fresh pose and machine state have been seen at least once (until then the
    /// mode stays `Startup`).
    seen_data: bool,
    /// The newest live-obstacle set in the pilot's terms (a buffer: taking a
    /// set allocates nothing).
    live: LiveSet,
    live_validator: shm_ipc::LiveObstacleValidator,
    /// A set was rejected since the last tick (`live-rejected`).
    live_rejected: bool,
    /// Rejected sets and protective stops are logged at a limited rate.
    live_log: LogLimiter,
    /// When the last set was taken: the next waits [`MIN_LIVE_SPACING`].
    live_taken_at: Option<Instant>,
}

/// What a tick read: the measured state when pose and machine state are fresh,
/// the machine state alone, and the faults the inputs show.
struct Inputs {
    x: Option<State>,
    /// The fresh, plausible machine state.
    machine: Option<MachineState>,
    /// The newest machine state, fresh or not (for telemetry).
    latest: Option<MachineState>,
    faults: InputFaults,
}

/// What the controller's step gave the tick.
struct Solve {
    result: SolveResult,
    /// The command, unless the step failed.
    command: Option<VelocityCommand>,
    solve_time: Option<f64>,
    /// The safety envelope replaced the proposed command.
    envelope_override: bool,
    /// The wall time of a route plan taken this step [s].
    new_plan_time: Option<f64>,
    /// The telemetry bits of the envelope's assumptions broken so far.
    assumption_flags: u32,
    /// What the live obstacles did to the step.
    live: Option<LiveStatus>,
}

impl Solve {
    /// The telemetry flags the step raises: a fallback plan, an envelope override.
    fn flags(&self) -> u32 {
        let mut flags = 0;
        if matches!(self.result, SolveResult::Fallback | SolveResult::Failed) {
            flags |= fault_flags::FALLBACK_PLAN;
        }
        if self.envelope_override {
            flags |= fault_flags::ENVELOPE_OVERRIDE;
        }
        flags |= self.assumption_flags;
        flags |= self.live.map_or(0, live_flags);
        flags
    }
}

impl ControlLoop {
    /// A loop around a controller that passed its first solve.
    pub fn new(ctx: LoopContext, controller: Box<dyn Controller>, notifier: Notifier) -> Self {
        let params = ctx.config.machine;
        let period = ctx.config.period();
        let pose_gate = PoseGate::new(ctx.config.pose_gate());
        Self {
            ctx,
            controller,
            notifier,
            params,
            period,
            engaged_generation: None,
            dropped_outcomes: 0,
            latched: 0,
            last_command: VelocityCommand::ZERO,
            envelope_log: LogLimiter::new(5, 10.0),
            pose_gate,
            pose_log: LogLimiter::new(5, 10.0),
            solve_failures: 0,
            prev_counters: Default::default(),
            mode: Mode::Startup,
            shutdown_started: None,
            tick: 0,
            seen_data: false,
            site: None,
            retiring: None,
            live: LiveSet::new(),
            live_validator: shm_ipc::LiveObstacleValidator::default(),
            live_rejected: false,
            live_log: LogLimiter::new(5, 10.0),
            live_taken_at: None,
        }
    }

    /// Runs until shutdown (or `loop.max_ticks`); the last command sent is a stop.
    pub fn run(mut self) -> ExitReason {
        let period = self.period;
        let clock = self.ctx.clock;
        let t0 = clock.now();
        let mut k: u64 = 0;
        let reason = loop {
            let deadline = t0 + k as f64 * period;
            self.wait_for_tick(deadline);
            let start = clock.now();
            let compute = Instant::now();
            let outcome = self.tick(start);
            let tick_time = compute.elapsed().as_secs_f64();
            let end = clock.now();
            let late_start = start - deadline;
            let overrun = end - deadline > period;
            let healthy = !overrun && late_start < period && outcome.sent;
            {
                let mut s = self.ctx.stats.lock().unwrap_or_else(|p| p.into_inner());
                s.record_tick(
                    late_start,
                    outcome.solve_time,
                    overrun,
                    Some(tick_time),
                    outcome.plan_time,
                );
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

    /// One tick: inputs → goal lifecycle → safety decision ([`crate::safety`]) →
    /// controller step when driving → command → telemetry.
    fn tick(&mut self, start: f64) -> TickOutcome {
        let tick_start = Instant::now();
        self.tick += 1;
        let mut t = Telemetry::ZERO;
        t.tick = self.tick;
        t.timestamp_ns = shm_ipc::monotonic_now_ns();
        self.swap_site(&mut t);
        let shutting_down = self.shutting_down(start);
        self.take_live(false);
        let inputs = self.read_inputs(start);
        t.state = self.telemetry_state(&inputs);
        t.at_rest = u32::from(
            inputs
                .machine
                .is_some_and(|s| s.at_rest(self.ctx.config.control.rest_speed)),
        );
        self.seen_data |= inputs.x.is_some();

        let faults = inputs.faults.stop | self.latched;
        let abort = safety::goal_abort(shutting_down, faults, inputs.machine.map(|s| s.status));
        let (plan, stop_requested) = self.goal_tick(start, inputs.x.as_ref(), abort, faults);
        let mut flags = inputs.faults.flags;
        if std::mem::take(&mut self.live_rejected) {
            flags |= fault_flags::LIVE_REJECTED;
        }
        if stop_requested {
            flags |= fault_flags::STOP_REQUESTED;
        }
        let mut shown = match plan {
            TickPlan::NoGoal => None,
            TickPlan::Hold(g) | TickPlan::Track(g) => Some(g),
        };
        let mut decision = safety::decide(&Situation {
            shutting_down,
            seen_data: self.seen_data,
            faults,
            stop_requested,
            goal: (&plan).into(),
        });

        let mut solve = None;
        if let (Decision::Track, TickPlan::Track(g), Some(x)) = (decision, &plan, &inputs.x) {
            let s = self.solve(x, g, start, tick_start, &mut t);
            flags |= s.flags();
            decision = safety::after_solve(s.result, self.solve_failures, self.fallback_ticks());
            if let Decision::Stop(cause) = decision {
                flags = self.goal_ended_while_tracking(cause, flags);
                shown = None;
            }
            solve = Some(s);
        }
        if decision != Decision::Track {
            self.disengage();
        }

        let (mode, drive, command) = self.command_for(decision, &plan, &inputs, solve.as_ref());
        if let Decision::Stop(StopCause::Fault(_)) = decision {
            flags |= self.latched;
            if inputs.faults.stop == 0 && command == VelocityCommand::ZERO {
                // The solver fault has been shown through the whole stop; clear it.
                self.latched = 0;
            }
        }

        let exit = self.exit_after(start, command, inputs.machine.as_ref());
        let (command, sent) = self.send(start, command, drive, &mut flags);
        self.set_mode(mode, &mode_detail(shown.as_ref(), mode, flags));
        self.publish(t, mode, flags, command, shown.as_ref(), inputs.x.as_ref());
        TickOutcome {
            sent,
            solve_time: solve.as_ref().and_then(|s| s.solve_time),
            plan_time: solve.and_then(|s| s.new_plan_time),
            exit,
        }
    }

    /// A reloaded site, if one waits, goes into force at this tick boundary: the
    /// goal check and the controller together (DESIGN §17); telemetry names the
    /// site in force. The replaced site goes back to the slot, which frees it
    /// off the tick (this loop holds the last reference until then).
    fn swap_site(&mut self, t: &mut Telemetry) {
        let slot = self.ctx.goals.site();
        if let Some(old) = self.retiring.take() {
            self.retiring = slot.retire(old).err();
        }
        // While a replaced site waits to be handed back (a reload was freeing
        // the one before), the next one waits in the slot.
        if self.retiring.is_none() {
            if let Some((site, text)) = slot.take() {
                tracing::info!("{text} in force");
                self.controller.set_site(Some(site.clone()));
                self.ctx.goals.lock().set_site(Some(site.clone()));
                if let Some(old) = self.site.replace(site) {
                    self.retiring = slot.retire(old).err();
                }
            }
        }
        t.set_site(
            self.site
                .as_ref()
                .map(|i| (i.site().id(), i.site().version(), i.site().hash())),
        );
    }

    /// Counts and logs (rate-limited) an override by the safety envelope
    /// (DESIGN §14; the pilot runs it on every proposal).
    fn note_override(&mut self, now: f64, proposed: VelocityCommand, g: &Guarded) {
        self.ctx
            .stats
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .envelope_overrides += 1;
        if let LogDecision::Log { suppressed } = self.envelope_log.check(now) {
            tracing::warn!(
                "envelope: command (β̇ {:.3}, v {:.3}) would come {:.3} m inside the \
                 margin: sent {} (β̇ {:.3}, v {:.3}){}",
                proposed.beta_dot,
                proposed.v,
                -g.proposed_excess,
                g.choice.name(),
                g.command.beta_dot,
                g.command.v,
                if suppressed > 0 {
                    format!("; {suppressed} more overrides since the last report")
                } else {
                    String::new()
                }
            );
        }
    }

    /// The tick's mode and command: the controller's while tracking (it has
    /// passed the pilot's envelope), else a stop at the limits from the
    /// machine's own velocity where it is trusted (never faster than it goes).
    fn command_for(
        &self,
        decision: Decision,
        plan: &TickPlan,
        inputs: &Inputs,
        solve: Option<&Solve>,
    ) -> (Mode, DriveMode, VelocityCommand) {
        let ramp = envelope::stop_command(
            self.last_command,
            inputs.x.as_ref(),
            &self.params,
            self.period,
        );
        match (decision, plan, &inputs.x) {
            (Decision::Track, TickPlan::Track(_), Some(_)) => {
                let c = solve.and_then(|s| s.command).unwrap_or(ramp);
                (Mode::Tracking, DriveMode::Drive, c)
            }
            (Decision::Track, _, _) => (Mode::Tracking, DriveMode::Drive, ramp),
            (Decision::Stop(cause), _, _) => {
                let (mode, drive) = cause.modes(ramp == VelocityCommand::ZERO);
                (mode, drive, ramp)
            }
        }
    }

    fn fallback_ticks(&self) -> u32 {
        self.ctx.config.control.fallback_ticks
    }

    /// True once shutdown is requested (signal or `loop.max_ticks`); the first such
    /// tick starts the controlled stop.
    fn shutting_down(&mut self, start: f64) -> bool {
        let max_ticks = self.ctx.config.control.max_ticks;
        let shutting_down =
            self.ctx.shutdown.load(Ordering::Relaxed) || (max_ticks > 0 && self.tick > max_ticks);
        if shutting_down && self.shutdown_started.is_none() {
            self.shutdown_started = Some(start);
            self.notifier
                .stopping("stopping: controlled stop before exit");
            tracing::info!("shutdown: controlled stop");
        }
        shutting_down
    }

    /// Poses through the gate, the machine state and the CAN counters, and the
    /// faults they show.
    fn read_inputs(&mut self, start: f64) -> Inputs {
        let pose_rejected = self.read_poses();
        let can = self.ctx.can.snapshot();
        let pose = self.pose_gate.fresh(start);
        let machine = self.state_fresh(&can, start);
        // The pose is stamped: carried to the tick over its age with the
        // machine's current velocities (DESIGN §14).
        let age = self.pose_gate.last().map_or(0.0, |(_, t)| start - t);
        let health = InputHealth {
            pose_fresh: pose.is_some(),
            pose_rejected,
            pose_faulted: self.pose_gate.faulted(),
            state_fresh: machine.is_some(),
        };
        let faults = safety::input_faults(
            health,
            &can,
            &self.prev_counters,
            self.ctx.config.control.can_bad_frames_stop,
        );
        self.prev_counters = can.counters;
        Inputs {
            x: pose
                .zip(machine)
                .map(|(p, s)| compensate_pose_age(&self.params, &s.with_pose(&p), age)),
            machine,
            latest: can.latest.map(|(s, _)| s),
            faults,
        }
    }

    /// The state shown in telemetry: the measured one, or what is known of it
    /// (NaN for the rest).
    fn telemetry_state(&self, inputs: &Inputs) -> shm_ipc::MachineState {
        if let Some(x) = &inputs.x {
            return wire_state(x);
        }
        let mut a = [f64::NAN; 6];
        if let Some(p) = self.pose_gate.last() {
            a[..3].copy_from_slice(&[p.0.x, p.0.y, p.0.heading]);
        }
        if let Some(s) = inputs.latest {
            a[3..].copy_from_slice(&[s.beta, s.beta_dot, s.v_f]);
        }
        shm_ipc::MachineState::from_array(a)
    }

    /// The goal lifecycle's tick: what to drive, and whether an operator stop is
    /// latched.
    fn goal_tick(
        &mut self,
        now: f64,
        state: Option<&State>,
        abort: Option<Abort>,
        blocking_faults: u32,
    ) -> (TickPlan, bool) {
        let mut goals = self.ctx.goals.lock();
        let plan = goals.on_tick(TickInput {
            now,
            state,
            abort,
            blocking_faults,
        });
        (plan, goals.operator_stop())
    }

    /// A goal ended while tracking (`cause`): the solver failed for too long
    /// (latched fault, goal aborted) or the global layer ended it (already
    /// reported by [`Self::solve`]). Returns the tick's flags.
    fn goal_ended_while_tracking(&mut self, cause: StopCause, flags: u32) -> u32 {
        if cause != StopCause::SolveFailed {
            return flags;
        }
        let what = match self.solve_failures {
            GOAL_REFUSED => "the controller refused the goal".to_string(),
            n => format!("solve failed {n} ticks in a row"),
        };
        tracing::error!("{what}: controlled stop");
        self.latched |= fault_flags::SOLVE_FAILED;
        self.ctx
            .goals
            .lock()
            .abort_active(Abort::new(AbortReason::Fault, format!("fault: {what}")));
        // This tick stops instead of driving on the fallback plan.
        (flags & !fault_flags::FALLBACK_PLAN) | fault_flags::SOLVE_FAILED
    }

    /// Shutdown completes once the command is zero and the machine at rest (or its
    /// state is unknown, or the timeout passed).
    fn exit_after(
        &self,
        now: f64,
        command: VelocityCommand,
        machine: Option<&MachineState>,
    ) -> Option<ExitReason> {
        let t_stop = self.shutdown_started?;
        let cfg = &self.ctx.config.control;
        let at_rest = machine.map_or(true, |s| s.at_rest(cfg.rest_speed));
        let timed_out = now - t_stop > cfg.shutdown_timeout;
        (command == VelocityCommand::ZERO && (at_rest || timed_out)).then(|| {
            if self.ctx.shutdown.load(Ordering::Relaxed) {
                ExitReason::Shutdown
            } else {
                ExitReason::MaxTicks
            }
        })
    }

    /// Hands the command to the CAN task, limited to the machine's bounds: the one
    /// place a command leaving the loop is limited (the CAN task's guard only
    /// verifies). The controller learns what was sent (its delay compensation).
    fn send(
        &mut self,
        now: f64,
        command: VelocityCommand,
        mode: DriveMode,
        flags: &mut u32,
    ) -> (VelocityCommand, bool) {
        let command = command.limited(&self.params);
        let sent = match self.ctx.commands.try_send(OutCommand { command, mode }) {
            Ok(()) => {
                self.controller.sent(now, command);
                true
            }
            Err(e) => {
                *flags |= fault_flags::CAN_BUS;
                tracing::warn!("command not queued: {e}");
                false
            }
        };
        self.last_command = command;
        (command, sent)
    }

    /// Fills and publishes the tick's telemetry.
    fn publish(
        &mut self,
        mut t: Telemetry,
        mode: Mode,
        flags: u32,
        command: VelocityCommand,
        shown: Option<&AcceptedGoal>,
        x: Option<&State>,
    ) {
        t.mode = mode.code();
        t.fault_flags = flags;
        t.command.beta_dot = command.beta_dot;
        t.command.v = command.v;
        if let Some(g) = shown {
            t.goal_active = 1;
            t.goal = Pose2::new(g.goal.x, g.goal.y, g.goal.theta);
            t.goal_request_id = g.request_id;
            if let Some(x) = x {
                let e = pose_error(x, &g.goal);
                t.pose_error_xy = e[0];
                t.pose_error_heading = e[1];
            }
        }
        self.report_outcome(&mut t);
        if let Err(e) = self.ctx.endpoint.publish_telemetry(&t) {
            tracing::warn!("telemetry: {e}");
        }
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
        self.solve_failures = 0;
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

    fn state_fresh(&self, can: &CanSnapshot, now: f64) -> Option<MachineState> {
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

    /// One tracking step of the controller (setting the goal first when it is new).
    /// The controller owns the fallback: it returns its shifted plan when a solve
    /// fails; a step without any usable command is `Failed` (the tick ramps down).
    /// An end by the global layer is reported to the goal lifecycle here.
    fn solve(
        &mut self,
        x: &State,
        g: &AcceptedGoal,
        now: f64,
        tick_start: Instant,
        t: &mut Telemetry,
    ) -> Solve {
        let failed = |solve_time| Solve {
            result: SolveResult::Failed,
            command: None,
            solve_time,
            envelope_override: false,
            new_plan_time: None,
            assumption_flags: 0,
            live: None,
        };
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
            self.solve_failures = 0;
            if let Err(e) = self.controller.set_goal(x, g.goal, g.obstacles(), now) {
                // Validated goals cannot fail here; stop at once as on a solver failure.
                tracing::error!("controller refused the goal: {e}");
                self.solve_failures = GOAL_REFUSED;
                return failed(None);
            }
            self.engaged_generation = Some(g.generation);
        }
        let solve = match self.controller.step(x, now, tick_start) {
            Ok(Step::Abort(reason)) => {
                let (wire, what) = match reason {
                    control::planner::AbortReason::NoRoute => (
                        AbortReason::NoRoute,
                        "the global layer found no collision-free route".to_string(),
                    ),
                    control::planner::AbortReason::NoProgress => {
                        let p = self.ctx.config.control.progress();
                        (
                            AbortReason::NoProgress,
                            format!(
                                "no approach to its target by {} for {:.1} s",
                                p.min_approach, p.timeout
                            ),
                        )
                    }
                };
                self.ctx.goals.lock().abort_active(Abort::new(wire, what));
                return Solve {
                    result: SolveResult::RouteEnded,
                    command: None,
                    solve_time: None,
                    envelope_override: false,
                    new_plan_time: None,
                    assumption_flags: 0,
                    live: None,
                };
            }
            Ok(Step::AssumptionBroken { finding, broken }) => {
                // Beyond what the envelope may be widened to: a fault, the
                // goal aborted with the measurement in its reason.
                tracing::error!(
                    "{finding}: beyond what the envelope may widen to: controlled stop"
                );
                let bits = assumption_flags(broken);
                self.latched |= bits;
                self.ctx
                    .goals
                    .lock()
                    .abort_active(Abort::new(AbortReason::Fault, format!("fault: {finding}")));
                return Solve {
                    result: SolveResult::RouteEnded,
                    command: None,
                    solve_time: None,
                    envelope_override: false,
                    new_plan_time: None,
                    assumption_flags: bits,
                    live: None,
                };
            }
            Ok(Step::Drive(plan)) => {
                if let Some(f) = plan.widened {
                    tracing::warn!("{f}: envelope widened to it");
                }
                plan.fill_telemetry(t);
                if let Some(c) = plan.live.and_then(|l| l.contact) {
                    t.live_id = c.id;
                }
                let solve_time = Some(plan.solve_time.as_secs_f64());
                let finite = plan.command.is_finite()
                    && plan.states.iter().all(|s| s.iter().all(|v| v.is_finite()));
                let overridden = plan
                    .guarded
                    .filter(|g| g.overridden())
                    .map(|g| (plan.proposed, g));
                let solve = match (finite, plan.status) {
                    (false, _) => failed(solve_time),
                    (true, status) => Solve {
                        result: match status {
                            // Holding for the first route is no failure.
                            PlanStatus::Solved | PlanStatus::Holding => SolveResult::Solved,
                            PlanStatus::Fallback => SolveResult::Fallback,
                        },
                        command: Some(plan.command),
                        solve_time,
                        envelope_override: overridden.is_some(),
                        new_plan_time: plan.new_plan.then(|| plan.plan_time.as_secs_f64()),
                        assumption_flags: assumption_flags(plan.assumptions_broken),
                        live: plan.live,
                    },
                };
                if let Some((proposed, g)) = overridden {
                    self.note_override(now, proposed, &g);
                }
                solve
            }
            Err(e) => {
                tracing::warn!("solve failed: {e}");
                failed(None)
            }
        };
        self.solve_failures = match solve.result {
            SolveResult::Solved => 0,
            _ => self.solve_failures.saturating_add(1),
        };
        solve
    }
}

/// The telemetry bits of the envelope's assumptions in `broken` (bit
/// `Assumption as usize`), with [`fault_flags::ASSUMPTION_BROKEN`] if any
/// (issue 43).
fn assumption_flags(broken: u8) -> u32 {
    use control::assumption_check::Assumption as A;
    A::ALL
        .iter()
        .filter(|a| broken & (1 << **a as usize) != 0)
        .fold(0, |acc, a| {
            acc | fault_flags::ASSUMPTION_BROKEN
                | match a {
                    A::Geometry => fault_flags::ASSUMPTION_GEOMETRY,
                    A::Delay => fault_flags::ASSUMPTION_DELAY,
                    A::Gain => fault_flags::ASSUMPTION_GAIN,
                    A::PoseNoiseXy | A::PoseNoiseTheta => fault_flags::ASSUMPTION_POSE_NOISE,
                }
        })
}

/// The detail of a mode change in logs and STATUS=.
fn mode_detail(shown: Option<&AcceptedGoal>, mode: Mode, flags: u32) -> String {
    match (shown, mode) {
        (Some(g), _) => format!(
            "goal ({:.2}, {:.2}, {:.2})",
            g.goal.x, g.goal.y, g.goal.theta
        ),
        (None, Mode::Fault) => format!("faults {flags:#x}"),
        _ => String::new(),
    }
}

struct TickOutcome {
    sent: bool,
    solve_time: Option<f64>,
    /// The wall time of a route plan taken this tick [s].
    plan_time: Option<f64>,
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

#[cfg(test)]
mod tests {
    use super::*;
    use control::assumption_check::Assumption;

    #[test]
    fn each_broken_assumption_is_named_by_its_own_telemetry_bit() {
        assert_eq!(assumption_flags(0), 0, "nothing broken raises nothing");
        for (a, name) in [
            (Assumption::Geometry, "assumption-geometry"),
            (Assumption::Delay, "assumption-delay"),
            (Assumption::Gain, "assumption-gain"),
            (Assumption::PoseNoiseXy, "assumption-pose-noise"),
            (Assumption::PoseNoiseTheta, "assumption-pose-noise"),
        ] {
            let names = fault_flags::names(assumption_flags(1 << a as usize));
            assert_eq!(names, ["assumption-broken", name], "{a:?}");
        }
        let both = 1 << Assumption::Delay as usize | 1 << Assumption::Gain as usize;
        let names = fault_flags::names(assumption_flags(both));
        assert_eq!(
            names,
            ["assumption-broken", "assumption-delay", "assumption-gain"]
        );
    }
}
