//! Goal outcomes, goal validation by footprint and the operator stop latch (DESIGN §10,
//! §11), end to end: requests and telemetry through iceoryx2, the daemon against its
//! simulated machine in accelerated time. Every test records all telemetry and checks
//! that each accepted goal is reported exactly once.

use std::f64::consts::FRAC_1_SQRT_2;
use std::time::{Duration, Instant};

use shm_ipc::{
    fault_flags, AbortReason, GoalOutcome, GoalRequest, IpcConfig, Mode, Obstacle, Pose2,
    RejectCode, StopClient, Telemetry,
};

use crate::common::*;

const T: Duration = Duration::from_secs(30);

fn mode(t: &Telemetry) -> Mode {
    t.mode().unwrap()
}

fn at_rest(t: &Telemetry) -> bool {
    t.command.v == 0.0 && t.command.beta_dot == 0.0 && t.at_rest == 1
}

fn accepted(d: &Running, goal: Pose2, obstacles: &[Obstacle]) -> u64 {
    let (id, reply) = d.request_goal(goal, obstacles);
    assert!(
        reply.is_accepted(),
        "goal rejected: {}",
        reply.reason_text()
    );
    id
}

#[test]
fn a_goal_whose_footprint_is_in_an_obstacle_is_rejected_at_once() {
    let d = start(sim_config("footprint"), None);
    let mut log = Vec::new();
    d.record_until(&mut log, T, "idle", |t| mode(t) == Mode::Idle);
    // Goal (5, 0, 0): its front axle is clear, its rear axle (3.8, 0) inside obstacle 1.
    let obstacles = [Obstacle::new(-6.0, 6.0, 1.0), Obstacle::new(3.8, 0.1, 0.4)];
    let sent = Instant::now();
    let (id, reply) = d.request_goal(Pose2::new(5.0, 0.0, 0.0), &obstacles);
    assert!(
        sent.elapsed() < timing_scale::real(Duration::from_secs(1)),
        "not at once"
    );
    assert!(!reply.is_accepted());
    assert_eq!(reply.reject_code(), Ok(RejectCode::GoalInCollision));
    let text = reply.reason_text();
    assert!(
        text.contains("goal-in-collision") && text.contains("obstacle 1") && text.contains("rear"),
        "{text}"
    );
    // An obstacle around the machine itself (at the origin).
    let (id2, reply) = d.request_goal(Pose2::new(5.0, 3.0, 0.0), &[Obstacle::new(0.2, 0.0, 0.5)]);
    assert_eq!(reply.reject_code(), Ok(RejectCode::MachineInCollision));
    assert!(
        reply.reason_text().contains("obstacle 0"),
        "{}",
        reply.reason_text()
    );
    // The same goal without the obstacles is fine; it then ends once (cancelled).
    let ok = accepted(&d, Pose2::new(5.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "tracking", |t| t.goal_request_id == ok);
    assert!(d
        .client
        .cancel(Duration::from_secs(2))
        .unwrap()
        .is_accepted());
    d.record_until(&mut log, T, "at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    let ended = assert_each_ends_once(&log, &[ok]);
    assert_eq!(ended[0].outcome(), Ok(GoalOutcome::Cancelled));
    assert!(log
        .iter()
        .all(|t| t.outcome_request_id != id && t.outcome_request_id != id2));
    d.stop();
}

#[test]
fn a_newer_goal_preempts_the_old_one_reported_once_with_the_old_id() {
    let d = start(sim_config("preempt"), None);
    let mut log = Vec::new();
    let a = accepted(&d, Pose2::new(10.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "driving to A", |t| {
        t.goal_request_id == a && t.command.v > 0.2
    });
    let b = accepted(&d, Pose2::new(8.0, 1.0, 0.0), &[]);
    let switched = d.record_until(&mut log, T, "tracking B", |t| {
        t.goal_request_id == b && mode(t) == Mode::Tracking
    });
    d.record_until(&mut log, T, "10 more ticks", |t| {
        t.tick >= switched.tick + 10
    });
    let ended = assert_each_ends_once(&log, &[a]);
    let o = ended[0];
    assert_eq!(o.outcome(), Ok(GoalOutcome::Preempted));
    assert_eq!(o.abort_reason(), Ok(AbortReason::None));
    assert!(
        o.outcome_text().contains(&b.to_string()),
        "{}",
        o.outcome_text()
    );
    // Preempting does not stop the machine: B is driven from the same tick.
    assert_eq!(o.goal_request_id, b);
    assert!(
        log.iter().all(|t| t.outcome_request_id != b),
        "B has not ended"
    );
    d.stop();
}

#[test]
fn cancel_ends_the_goal_cancelled_and_the_machine_comes_to_rest() {
    let d = start(sim_config("cancel"), None);
    let mut log = Vec::new();
    let a = accepted(&d, Pose2::new(10.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "driving", |t| t.command.v > 0.3);
    let r = d.client.cancel(Duration::from_secs(2)).unwrap();
    assert!(r.is_accepted());
    d.record_until(&mut log, T, "idle at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    let ended = assert_each_ends_once(&log, &[a]);
    assert_eq!(ended[0].outcome(), Ok(GoalOutcome::Cancelled));
    assert!(ended[0].outcome_text().contains("cancelled by request"));
    assert_eq!(
        ended[0].goal_active, 0,
        "the goal is dropped on the outcome's tick"
    );
    d.stop();
}

#[test]
fn a_reached_goal_succeeds_exactly_once() {
    let d = start(sim_config("succeed"), None);
    let mut log = Vec::new();
    let a = accepted(&d, Pose2::new(3.0, 0.0, 0.0), &[]);
    let reached = d.record_until(&mut log, Duration::from_secs(60), "reached", |t| {
        mode(t) == Mode::Reached
    });
    // Holding at the goal for a while reports nothing more.
    d.record_until(&mut log, T, "held 20 ticks at rest", |t| {
        t.tick >= reached.tick + 20 && at_rest(t)
    });
    let ended = assert_each_ends_once(&log, &[a]);
    let o = ended[0];
    assert_eq!(o.outcome(), Ok(GoalOutcome::Succeeded));
    assert_eq!(o.tick, reached.tick, "reported on the tick it was reached");
    assert_eq!(
        (o.goal_request_id, o.goal_active),
        (a, 1),
        "the goal is held"
    );
    assert!(o.pose_error_xy < 0.1, "{}", o.pose_error_xy);
    d.stop();
}

#[test]
fn an_unreachable_goal_aborts_without_progress_and_the_machine_comes_to_rest() {
    // Without the global layer the MPC drives into the ring's local minimum: the goal
    // lifecycle's progress window ends it.
    let mut config = sim_config("no-progress");
    config.controller.planner = wlnavd::config::PlannerChoice::None;
    config.control.progress_timeout = 3.0;
    let d = start(config, None);
    let mut log = Vec::new();
    // The goal inside a closed ring of circles: the machine drives up to the ring and
    // stalls there.
    let goal = Pose2::new(4.2, 0.0, 0.0);
    let a = accepted(&d, goal, &ring(goal.x, goal.y, 2.3, 0.9));
    let first = d.record_until(&mut log, T, "driving", |t| t.goal_request_id == a);
    let ended = d.record_until(&mut log, Duration::from_secs(60), "aborted", |t| {
        t.outcome_request_id == a
    });
    d.record_until(&mut log, T, "idle at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    let o = assert_each_ends_once(&log, &[a])[0];
    assert_eq!(o.outcome(), Ok(GoalOutcome::Aborted));
    assert_eq!(
        o.abort_reason(),
        Ok(AbortReason::NoProgress),
        "{}",
        o.outcome_text()
    );
    assert!(
        o.outcome_text().contains("no approach"),
        "{}",
        o.outcome_text()
    );
    let secs = (ended.tick - first.tick) as f64 * 0.2;
    assert!(secs < 12.0, "aborted after {secs:.1} s");
    assert!(
        log.iter()
            .any(|t| t.goal_request_id == a && t.state.v_f > 0.2),
        "the machine drove towards the goal first"
    );
    let report = d.stop();
    let x = report.sim.as_ref().unwrap().true_state;
    assert!(x[5].abs() < 0.02 && x[4].abs() < 0.02, "not at rest: {x:?}");
}

#[test]
fn an_enclosed_goal_ends_aborted_no_route_with_the_machine_at_rest() {
    // Daemon defaults: the global layer plans at once, finds no way into the ring and
    // the goal ends on its first tick.
    let d = start(sim_config("no-route"), None);
    let mut log = Vec::new();
    let goal = Pose2::new(4.2, 0.0, 0.0);
    let a = accepted(&d, goal, &ring(goal.x, goal.y, 2.3, 0.9));
    let ended = d.record_until(&mut log, T, "aborted", |t| t.outcome_request_id == a);
    d.record_until(&mut log, T, "idle at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    let o = assert_each_ends_once(&log, &[a])[0];
    assert_eq!(o.outcome(), Ok(GoalOutcome::Aborted));
    assert_eq!(
        o.abort_reason(),
        Ok(AbortReason::NoRoute),
        "{}",
        o.outcome_text()
    );
    assert!(o.outcome_text().contains("route"), "{}", o.outcome_text());
    let driven = log
        .iter()
        .filter(|t| t.goal_request_id == a && t.tick <= ended.tick)
        .count();
    assert!(driven <= 2, "the goal was driven for {driven} ticks");
    // (NaN: no machine state yet, on the first ticks.)
    assert!(
        log.iter()
            .all(|t| t.state.v_f.is_nan() || t.state.v_f.abs() < 0.05),
        "the machine moved"
    );
    d.stop();
}

/// `config` with the trained critic and actor of a committed machine directory
/// (relative to the repository), the machine and Δt taken from their metadata.
/// Sends `goal`, records the telemetry until its outcome (at most 60 s) and
/// requires it to be `succeeded`, reported once.
fn drive_to_success(d: &Running, goal: Pose2, obstacles: &[Obstacle]) -> Vec<Telemetry> {
    let mut log = Vec::new();
    let a = accepted(d, goal, obstacles);
    d.record_until(&mut log, Duration::from_secs(60), "an outcome", |t| {
        t.outcome_request_id == a
    });
    let o = assert_each_ends_once(&log, &[a])[0];
    assert_eq!(
        o.outcome(),
        Ok(GoalOutcome::Succeeded),
        "{}",
        o.outcome_text()
    );
    log
}

#[test]
fn a_goal_behind_a_wall_is_reached_around_it_along_the_global_route() {
    // The trained critic (daemon defaults: critic cost, Hybrid A*) against a wall of
    // overlapping circles across the straight path; the MPC alone stops behind it.
    let config = with_committed_weights(sim_config("wall"), control::weights::DEFAULT_DIR);
    let params = config.machine;
    let d = start(config, None);
    let wall: Vec<Obstacle> = (0..6)
        .map(|k| Obstacle::new(4.0, -1.75 + 0.7 * k as f64, 0.5))
        .collect();
    let circles: Vec<control::obstacle::Obstacle> = wall
        .iter()
        .map(|o| control::obstacle::Obstacle::new(o.x, o.y, o.r))
        .collect();
    let log = drive_to_success(&d, Pose2::new(8.0, 0.0, 0.0), &wall);
    // The route's subgoals are the progress markers along the planned path, which
    // the MPC follows (the daemon's default, path following: no tick drives to a
    // subgoal as its target, the path's end is the goal).
    let routed: Vec<&Telemetry> = log.iter().filter(|t| t.route().len() >= 2).collect();
    assert!(!routed.is_empty(), "no tick had a route around the wall");
    assert!(
        routed
            .iter()
            .all(|t| t.route().last() == Some(&Pose2::new(8.0, 0.0, 0.0))),
        "the route is the subgoals ending with the goal"
    );
    let worst = log
        .iter()
        .filter(|t| t.state.x_f.is_finite())
        .map(|t| {
            let s = &t.state;
            let x = control::State::new(s.x_f, s.y_f, s.theta_f, s.beta, s.beta_dot, s.v_f);
            control::obstacle::footprint_clearance(&params, &x, &circles)
        })
        .fold(f64::INFINITY, f64::min);
    assert!(worst > -0.005, "cut {:.3} m into the wall", -worst);
    d.stop();
}

#[test]
fn an_operator_stop_latches_until_resume() {
    let d = start(sim_config("latch"), None);
    let mut log = Vec::new();
    let a = accepted(&d, Pose2::new(10.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "driving", |t| t.command.v > 0.3);
    assert!(d.client.stop(Duration::from_secs(2)).unwrap().is_accepted());
    let stopped_at = d.record_until(&mut log, T, "stop latched", |t| {
        t.fault_flags & fault_flags::STOP_REQUESTED != 0
    });
    let rejected_now = d.request_goal(Pose2::new(5.0, 0.0, 0.0), &[]);
    // 3 s (simulated) later: still latched, the machine at rest.
    d.record_until(&mut log, T, "3 s later, at rest", |t| {
        t.tick >= stopped_at.tick + 15 && at_rest(t)
    });
    let rejected_later = d.request_goal(Pose2::new(5.0, 0.0, 0.0), &[]);
    for (id, reply) in [&rejected_now, &rejected_later] {
        assert!(!reply.is_accepted(), "goal {id} accepted while stopped");
        assert_eq!(reply.reject_code(), Ok(RejectCode::NotReady));
        assert!(
            reply.reason_text().contains("stopped by an operator"),
            "{}",
            reply.reason_text()
        );
    }
    let idle = d.record_until(&mut log, T, "a sample", |_| true);
    assert_ne!(idle.fault_flags & fault_flags::STOP_REQUESTED, 0);
    assert!(d
        .client
        .resume(Duration::from_secs(2))
        .unwrap()
        .is_accepted());
    let b = accepted(&d, Pose2::new(5.0, 2.0, 0.0), &[]);
    let driving = d.record_until(&mut log, T, "tracking after resume", |t| {
        t.goal_request_id == b && mode(t) == Mode::Tracking
    });
    assert_eq!(driving.fault_flags & fault_flags::STOP_REQUESTED, 0);
    let o = assert_each_ends_once(&log, &[a])[0];
    assert_eq!(o.outcome(), Ok(GoalOutcome::Cancelled));
    assert!(
        o.outcome_text().contains("operator"),
        "{}",
        o.outcome_text()
    );
    d.stop();
}

/// The two stop paths (a stop request on the goal service, and one on the reserved stop
/// service, as `wlnav stop` sends it) end the goal `cancelled` and latch alike; a resume
/// on the goal service releases either.
#[test]
fn a_stop_on_either_service_latches_until_resume() {
    let d = start(sim_config("latch-both"), None);
    let stop_client = StopClient::new(&IpcConfig::new(d.config.ipc.prefix.clone())).unwrap();
    let mut log = Vec::new();
    let mut ended = Vec::new();
    for via_stop_service in [false, true] {
        let a = accepted(&d, Pose2::new(10.0, 0.0, 0.0), &[]);
        ended.push(a);
        d.record_until(&mut log, T, "driving", |t| {
            t.goal_request_id == a && t.command.v > 0.3
        });
        let reply = if via_stop_service {
            stop_client.stop(Duration::from_secs(2)).unwrap()
        } else {
            let req = GoalRequest::stop(d.client.next_request_id());
            d.client.request(&req, Duration::from_secs(2)).unwrap()
        };
        assert!(reply.is_accepted(), "{}", reply.reason_text());
        d.record_until(&mut log, T, "stop latched and at rest", |t| {
            t.fault_flags & fault_flags::STOP_REQUESTED != 0 && at_rest(t)
        });
        let (id, reply) = d.request_goal(Pose2::new(5.0, 0.0, 0.0), &[]);
        assert!(!reply.is_accepted(), "goal {id} accepted while stopped");
        assert_eq!(reply.reject_code(), Ok(RejectCode::NotReady));
        assert!(
            reply.reason_text().contains("stopped by an operator"),
            "{}",
            reply.reason_text()
        );
        assert!(d
            .client
            .resume(Duration::from_secs(2))
            .unwrap()
            .is_accepted());
        let b = accepted(&d, Pose2::new(5.0, 2.0, 0.0), &[]);
        ended.push(b);
        let driving = d.record_until(&mut log, T, "tracking after resume", |t| {
            t.goal_request_id == b && mode(t) == Mode::Tracking
        });
        assert_eq!(driving.fault_flags & fault_flags::STOP_REQUESTED, 0);
        // Cancel it so the next round starts from rest without a goal.
        assert!(d
            .client
            .cancel(Duration::from_secs(2))
            .unwrap()
            .is_accepted());
        d.record_until(&mut log, T, "cancelled, at rest", |t| {
            t.goal_active == 0 && at_rest(t)
        });
    }
    let outcomes = assert_each_ends_once(&log, &ended);
    for o in outcomes {
        assert_eq!(
            o.outcome(),
            Ok(GoalOutcome::Cancelled),
            "{}",
            o.outcome_text()
        );
    }
    d.stop();
}

/// The test that fails if an outcome is reported twice or never: a run through every
/// way a goal ends (succeeded, preempted while driving, preempted before it was ever
/// driven, cancelled, cancelled by a stop, aborted by shutdown), with rejected goals and
/// repeated cancels in between, every tick recorded.
#[test]
fn every_accepted_goal_ends_exactly_once() {
    let d = start(sim_config("exactly-once"), None);
    let mut log = Vec::new();
    let mut ids = Vec::new();
    let mut expect = Vec::new();

    // From rest at the origin (β = 0, which the quadratic test cost handles): reached.
    let e = accepted(&d, Pose2::new(3.0, 0.0, 0.0), &[]);
    let reached = d.record_until(&mut log, Duration::from_secs(60), "E reached", |t| {
        t.outcome_request_id == e
    });
    d.record_until(&mut log, T, "held", |t| t.tick >= reached.tick + 10);
    ids.push(e);
    expect.push(GoalOutcome::Succeeded);

    // A new goal after success ends nothing more; it is preempted while driving.
    let a = accepted(&d, Pose2::new(10.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "A driven", |t| t.goal_request_id == a);
    // B and C back to back: B is preempted by C, most likely before any tick took it up.
    let b = accepted(&d, Pose2::new(9.0, 1.0, 0.0), &[]);
    let c = accepted(&d, Pose2::new(9.0, -1.0, 0.0), &[]);
    d.record_until(&mut log, T, "C driven", |t| t.goal_request_id == c);
    // Rejected requests end nothing and have no outcome.
    let (bad, reply) = d.request_goal(Pose2::new(9.0, -1.0, 0.0), &[Obstacle::new(9.0, -1.0, 0.5)]);
    assert!(!reply.is_accepted());
    assert!(d
        .client
        .cancel(Duration::from_secs(2))
        .unwrap()
        .is_accepted());
    d.record_until(&mut log, T, "idle at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    // A second cancel has nothing to end.
    assert!(d
        .client
        .cancel(Duration::from_secs(2))
        .unwrap()
        .is_accepted());
    ids.extend([a, b, c]);
    expect.extend([
        GoalOutcome::Preempted,
        GoalOutcome::Preempted,
        GoalOutcome::Cancelled,
    ]);

    let f = accepted(&d, Pose2::new(-8.0, 0.0, 0.0), &[]);
    d.record_until(&mut log, T, "F driven", |t| t.goal_request_id == f);
    assert!(d.client.stop(Duration::from_secs(2)).unwrap().is_accepted());
    d.record_until(&mut log, T, "stopped at rest", |t| {
        mode(t) == Mode::Idle && at_rest(t)
    });
    assert!(d
        .client
        .resume(Duration::from_secs(2))
        .unwrap()
        .is_accepted());
    ids.push(f);
    expect.push(GoalOutcome::Cancelled);

    let g = accepted(&d, Pose2::new(8.0, 8.0, 0.0), &[]);
    let driven = d.record_until(&mut log, T, "G driven", |t| t.goal_request_id == g);
    d.record_until(&mut log, T, "5 more ticks", |t| t.tick >= driven.tick + 5);
    ids.push(g);

    // Everything up to here; G is still active (no outcome yet).
    let ended = assert_each_ends_once(&log, &ids[..ids.len() - 1]);
    for ((t, want), id) in ended.iter().zip(&expect).zip(&ids) {
        assert_eq!(t.outcome(), Ok(*want), "goal {id}: {}", t.outcome_text());
    }
    assert_eq!(ended[0].outcome_seq, 1, "the first outcome is number 1");
    assert!(log.iter().all(|t| t.outcome_request_id != bad));
    assert!(log.iter().all(|t| t.outcome_request_id != g));
    // Shutdown ends G (aborted, shutdown): the run ends with it reported.
    let shutdown = d.shutdown.clone();
    shutdown.trigger();
    let last = d.record_until(&mut log, T, "G's outcome", |t| t.outcome_request_id == g);
    assert_eq!(last.outcome(), Ok(GoalOutcome::Aborted));
    assert_eq!(last.abort_reason(), Ok(AbortReason::Shutdown));
    assert_each_ends_once(&log, &ids);
    d.stop();
}

#[test]
fn the_large_loader_stopped_beside_its_goal_is_retried_from_the_approach_pose() {
    // Another machine installed by its weights alone (issue 19): the daemon takes
    // the large loader from the critic's metadata, the simulated machine is that
    // machine. It starts where its critic stops on the way to this goal (paper
    // scenario r4.5_b45_h0, `docs/training.md`): at rest at full articulation,
    // 0.11 from the goal, where the MPC alone holds still. The global layer's
    // retry drives to the approach pose 3 m behind the goal and in again.
    // (Started on the way, the stop depends on the ticks' timing under load.)
    let mut config = with_committed_weights(sim_config("retry"), "critic-weights/large-loader");
    assert_eq!((config.machine.l_f, config.machine.l_r), (0.9, 1.1));
    config.sim.plant = control::PlantConfig::ideal();
    config.mpc.delay = 0.0;
    config.sim.initial_state = [3.235, 3.179, 0.098, -config.machine.beta_max, 0.0, 0.0];
    config.validate().unwrap();
    let d = start(config, None);
    let goal = Pose2::new(4.5 * FRAC_1_SQRT_2, 4.5 * FRAC_1_SQRT_2, 0.0);
    let approach = Pose2::new(goal.x - 3.0, goal.y, 0.0);
    let log = drive_to_success(&d, goal, &[]);
    let retried = log
        .iter()
        .filter(|t| t.active_subgoal().is_some())
        .collect::<Vec<_>>();
    assert!(!retried.is_empty(), "no tick drove to the approach pose");
    for t in retried {
        let sub = t.active_subgoal().unwrap();
        assert!(
            (sub.x - approach.x).abs() < 1e-3 && (sub.y - approach.y).abs() < 1e-3,
            "subgoal {sub:?}, expected the approach pose {approach:?}"
        );
        assert_eq!(t.route().last(), Some(&goal));
    }
    d.stop();
}
