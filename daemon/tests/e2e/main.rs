//! End-to-end tests: the daemon against the simulated machine in accelerated time,
//! goals and telemetry through iceoryx2, commands checked as the machine received
//! them. Each test has its own service prefix.

mod assumptions;
mod common;
mod faults;
mod live;
mod outcomes;
mod process;
mod realtime;
mod site;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::*;
use control::mpc::Mpc;
use control::{State, VelocityCommand};
use shm_ipc::{fault_flags, Mode, Telemetry};
use wlnav_test_kit::controller::{Forwarding, Hooks};
use wlnavd::can::DriveMode;
use wlnavd::controller::{
    quadratic_cost, Controller, ControllerError, ControllerFactory, PilotController, Plan, Step,
};

fn mode(t: &Telemetry) -> Mode {
    t.mode().unwrap()
}

#[test]
fn goal_reached_and_machine_stopped() {
    let d = start(sim_config("reach"), None);
    d.goal(3.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(60), "tracking", |t| {
        mode(t) == Mode::Tracking
    });
    d.wait_for(Duration::from_secs(60), "reached", |t| {
        mode(t) == Mode::Reached
    });
    let seen = d.wait_for(Duration::from_secs(20), "holding at rest", |t| {
        mode(t) == Mode::Reached
            && t.command.v == 0.0
            && t.command.beta_dot == 0.0
            && t.at_rest == 1
    });
    let last = seen.last().unwrap();
    assert_eq!(last.goal_active, 1);
    assert!(last.pose_error_xy < 0.1, "{}", last.pose_error_xy);
    assert_eq!(last.fault_flags & !fault_flags::CAN_CRC, 0);
    let config = d.config.clone();
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let x = log.true_state;
    let dist = ((x[0] - 3.0).powi(2) + x[1].powi(2) + x[2].powi(2)).sqrt();
    assert!(dist < 0.15, "machine not at the goal: {x:?}");
    assert!(
        x[5].abs() < 0.02 && x[4].abs() < 0.02,
        "machine not at rest: {x:?}"
    );
    // The goal was driven (Drive commands), then held.
    assert!(log
        .commands
        .iter()
        .any(|c| c.command.mode == DriveMode::Drive));
    let last_cmd = log.commands.last().unwrap().command;
    assert_eq!((last_cmd.beta_dot_cmd, last_cmd.v_cmd), (0.0, 0.0));
    assert_eq!(report.stats.overruns, 0, "{}", report.summary());
    let _ = config;
}

#[test]
fn real_critic_mpc_path_runs() {
    use control::weights::{encode, random_network, FileDtype, NetworkMetadata, NetworkRole};
    let dir = tempfile::tempdir().unwrap();
    let hidden = [48, 96, 144, 96, 48];
    for (role, out, name) in [
        (NetworkRole::Critic, 4, "critic.safetensors"),
        (NetworkRole::Actor, 4, "actor.safetensors"),
    ] {
        let w = random_network(NetworkMetadata::new(role, out), &hidden, 7);
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F32).unwrap();
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let mut config = sim_config("critic");
    config.controller.cost = wlnavd::config::CostKind::Critic;
    config.weights.critic = dir.path().join("critic.safetensors");
    config.weights.actor = dir.path().join("actor.safetensors");
    let n = config.mpc.horizon;
    let d = start(config, None);
    d.goal(4.0, 1.0, 0.5);
    // Untrained weights: only that the critic MPC runs (solves, plans, commands).
    let seen = d.wait_for(Duration::from_secs(30), "a critic MPC solve", |t| {
        mode(t) == Mode::Tracking && t.solve_time_us > 0.0 && t.trajectory_len as usize == n + 1
    });
    let t = seen.last().unwrap();
    assert!(t.qp_iterations > 0);
    assert!(t.trajectory().iter().all(|s| s.x_f.is_finite()));
    d.stop();
}

#[test]
fn stale_pose_stops_within_two_ticks_with_fault_flag() {
    let mut config = sim_config("stale");
    let drop_at = 3.0;
    config.sim.faults.pose_dropout_at = drop_at;
    config.sim.faults.pose_dropout_duration = 1000.0;
    let (timeout, period) = (config.control.pose_timeout, config.period());
    let params = config.machine;
    let d = start(config, None);
    d.goal(10.0, 0.0, 0.0);
    let seen = d.wait_for(Duration::from_secs(30), "pose stale fault", |t| {
        t.fault_flags & fault_flags::POSE_STALE != 0 && mode(t) != Mode::Startup
    });
    let flagged = seen.last().unwrap();
    assert_eq!(mode(flagged), Mode::Fault);
    assert_eq!(flagged.goal_active, 0, "the goal is dropped on a fault");
    // Before the dropout the machine was driving.
    assert!(seen
        .iter()
        .any(|t| mode(t) == Mode::Tracking && t.command.v > 0.3));
    d.wait_for(Duration::from_secs(20), "stopped", |t| {
        t.command.v == 0.0 && t.command.beta_dot == 0.0
    });
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = first_command(log, 0.0, DriveMode::Fault).expect("a fault command");
    let stale_since = drop_at + timeout;
    assert!(
        log.commands[i].time <= stale_since + 2.0 * period + 0.02,
        "first fault command at {:.3} s, pose stale since {:.3} s",
        log.commands[i].time,
        stale_since
    );
    assert!(log.commands[i - 1].command.mode == DriveMode::Drive);
    assert!(log.commands[i - 1].command.v_cmd > 0.3, "was not moving");
    check_ramp_down(log, i, &params, period);
}

#[test]
fn short_crc_burst_is_rejected_and_counted() {
    let mut config = sim_config("crc-short");
    config.sim.faults.crc_burst_at = 2.0;
    config.sim.faults.crc_burst_frames = 3;
    let d = start(config, None);
    d.goal(10.0, 0.0, 0.0);
    let seen = d.wait_for(Duration::from_secs(30), "CAN CRC flag", |t| {
        t.fault_flags & fault_flags::CAN_CRC != 0
    });
    let flagged_tick = seen.last().unwrap().tick;
    let after = d.wait_for(Duration::from_secs(10), "5 more ticks", |t| {
        t.tick > flagged_tick + 5
    });
    for t in seen.iter().chain(&after) {
        assert_ne!(
            mode(t),
            Mode::Fault,
            "a short burst must not stop the machine"
        );
    }
    assert_eq!(mode(after.last().unwrap()), Mode::Tracking);
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    assert_eq!(log.corrupted_frames, 3);
    assert!(first_command(log, 0.0, DriveMode::Fault).is_none());
}

fn persistent_can_fault(name: &str, crc: bool) {
    let mut config = sim_config(name);
    // Late enough that the goal is accepted (and tracking seen) first even when
    // the daemon's start-up is slowed by a loaded machine: it rejects goals while
    // a fault is active.
    let at = 5.0;
    if crc {
        config.sim.faults.crc_burst_at = at;
        config.sim.faults.crc_burst_frames = 1_000_000;
    } else {
        config.sim.faults.freeze_alive_at = at;
        config.sim.faults.freeze_alive_frames = 1_000_000;
    }
    let flag = if crc {
        fault_flags::CAN_CRC
    } else {
        fault_flags::CAN_ALIVE
    };
    let (period, params) = (config.period(), config.machine);
    let frames = f64::from(config.control.can_bad_frames_stop);
    let frame_period = 1.0 / config.sim.state_rate_hz;
    let d = start(config, None);
    d.goal(10.0, 0.0, 0.0);
    let seen = d.wait_for(Duration::from_secs(30), "CAN fault", |t| {
        mode(t) == Mode::Fault && t.fault_flags & flag != 0
    });
    assert!(seen.iter().any(|t| mode(t) == Mode::Tracking));
    d.wait_for(Duration::from_secs(20), "stopped", |t| t.command.v == 0.0);
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = first_command(log, 0.0, DriveMode::Fault).expect("a fault command");
    let persistent_at = at + frames * frame_period;
    assert!(
        log.commands[i].time <= persistent_at + period + 0.05,
        "first fault command at {:.3}, persistent since {:.3}",
        log.commands[i].time,
        persistent_at
    );
    check_ramp_down(log, i, &params, period);
}

#[test]
fn persistent_crc_errors_stop_the_machine() {
    persistent_can_fault("crc-persistent", true);
}

#[test]
fn frozen_alive_counter_stops_the_machine() {
    persistent_can_fault("alive-frozen", false);
}

/// Hooks on the quadratic MPC, failing on demand: alternately an error and a non-finite
/// command. Every other call reaches the MPC (the kit's wrapper forwards it).
struct Failing {
    fail: Arc<AtomicBool>,
    calls: u64,
    nan_states: Vec<State>,
}

impl Hooks for Failing {
    fn step<'a>(
        &'a mut self,
        inner: &'a mut dyn Controller,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'a>, ControllerError> {
        if self.fail.load(Ordering::SeqCst) {
            self.calls += 1;
            if self.calls % 2 == 1 {
                return Err(ControllerError("injected solver failure".into()));
            }
            return Ok(Step::Drive(Plan {
                command: VelocityCommand {
                    beta_dot: f64::NAN,
                    v: f64::NAN,
                },
                proposed: VelocityCommand {
                    beta_dot: f64::NAN,
                    v: f64::NAN,
                },
                guarded: None,
                status: wlnavd::controller::PlanStatus::Solved,
                states: &self.nan_states,
                cost: f64::NAN,
                qp_iterations: 0,
                sqp_iterations: 0,
                solve_time: Duration::ZERO,
                subgoal: None,
                route: &[],
                plan_time: Duration::ZERO,
                new_plan: false,
                route_age: 0.0,
                assumptions_broken: 0,
                widened: None,
                live: None,
            }));
        }
        inner.step(state, now, tick_start)
    }
}

#[test]
fn solver_failure_falls_back_then_stops() {
    let config = sim_config("solver");
    let (machine, settings) = (config.machine, config.mpc);
    let fallback_ticks = config.control.fallback_ticks as usize;
    let (period, params) = (config.period(), config.machine);
    let fail = Arc::new(AtomicBool::new(false));
    let f = fail.clone();
    let pilot_config = config.clone();
    let factory: ControllerFactory = Box::new(move || {
        let mpc = Mpc::new(machine, quadratic_cost(), None, settings)
            .map_err(|e| ControllerError(e.to_string()))?;
        Ok(Box::new(Forwarding::new(
            Box::new(PilotController::without_navigator(mpc, &pilot_config)?),
            Failing {
                fail: f,
                calls: 0,
                nan_states: vec![State::from_element(f64::NAN); settings.horizon + 1],
            },
        )) as Box<dyn Controller>)
    });
    let d = start(config, Some(factory));
    d.goal(10.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(30), "driving", |t| {
        mode(t) == Mode::Tracking && t.command.v > 0.4
    });
    fail.store(true, Ordering::SeqCst);
    let seen = d.wait_for(Duration::from_secs(20), "solver fault", |t| {
        t.fault_flags & fault_flags::SOLVE_FAILED != 0
    });
    let fallback: Vec<&Telemetry> = seen
        .iter()
        .filter(|t| t.fault_flags & fault_flags::FALLBACK_PLAN != 0)
        .collect();
    assert_eq!(
        fallback.len(),
        fallback_ticks,
        "ticks on the fallback plan before the stop"
    );
    // A controller without a plan of its own to fall back on: the loop keeps
    // tracking (the next solve may recover) on the stop ramp.
    let mut last_v = f64::INFINITY;
    for t in &fallback {
        assert_eq!(mode(t), Mode::Tracking);
        // Braking from the last command or the machine's own speed, whichever
        // is lower (`control::envelope::stop_command`): it may reach zero.
        assert!(
            t.command.v.is_finite()
                && t.command.v >= 0.0
                && (t.command.v < last_v || t.command.v == 0.0),
            "a failed step ramps the speed down: {} after {last_v}",
            t.command.v
        );
        last_v = t.command.v;
    }
    let faulted = seen.last().unwrap();
    assert_eq!(mode(faulted), Mode::Fault);
    // The stop completes; the fault stays visible while stopping.
    d.wait_for(Duration::from_secs(20), "stopped", |t| {
        t.command.v == 0.0 && t.command.beta_dot == 0.0
    });
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = first_command(log, 0.0, DriveMode::Fault).expect("fault command");
    check_ramp_down(log, i, &params, period);
}

#[test]
fn invalid_goal_keeps_previous_and_newest_wins() {
    use shm_ipc::{Obstacle as IpcObstacle, Pose2, RejectCode};
    let d = start(sim_config("goals"), None);
    d.goal(5.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(20), "tracking goal 1", |t| {
        mode(t) == Mode::Tracking && t.goal.x == 5.0
    });
    let timeout = Duration::from_secs(2);
    let r = d
        .client
        .set_goal(Pose2::new(f64::NAN, 0.0, 0.0), &[], timeout)
        .unwrap();
    assert_eq!(r.reject_code(), Ok(RejectCode::NonFinite));
    let r = d
        .client
        .set_goal(Pose2::new(500.0, 0.0, 0.0), &[], timeout)
        .unwrap();
    assert_eq!(r.reject_code(), Ok(RejectCode::OutOfWorkspace));
    let r = d
        .client
        .set_goal(
            Pose2::new(5.0, 0.0, 0.0),
            &[IpcObstacle::new(5.0, 0.2, 1.0)],
            timeout,
        )
        .unwrap();
    assert_eq!(r.reject_code(), Ok(RejectCode::GoalInCollision));
    let seen = d.wait_for(Duration::from_secs(5), "3 more ticks", |t| t.tick > 0);
    let tick = seen.last().unwrap().tick;
    let later = d.wait_for(Duration::from_secs(5), "3 more ticks", |t| {
        t.tick > tick + 3
    });
    assert_eq!(later.last().unwrap().goal.x, 5.0, "previous goal kept");
    assert_eq!(mode(later.last().unwrap()), Mode::Tracking);
    d.goal(6.0, 1.0, 0.0);
    d.goal(7.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(5), "newest goal", |t| {
        t.goal.x == 7.0 && mode(t) == Mode::Tracking
    });
    // Stop request: controlled stop, flag.
    let r = d.client.stop(timeout).unwrap();
    assert!(r.is_accepted());
    d.wait_for(Duration::from_secs(20), "stopped on request", |t| {
        mode(t) == Mode::Idle && t.fault_flags & fault_flags::STOP_REQUESTED != 0
    });
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = first_command(log, 0.0, DriveMode::Stop).expect("stop command");
    check_ramp_down(log, i, &report_params(), 0.2);
}

fn report_params() -> control::MachineParams {
    control::MachineParams::default()
}
