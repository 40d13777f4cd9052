//! The fault-injection suite (DESIGN §11 "inputs that lie", issue 15): each test injects
//! one fault from outside, through the iceoryx2 services or the simulated machine's CAN
//! frames, and checks what the daemon does. The table in the README lists them with the
//! tests of the faults handled before (CAN, floods, crashes, ...).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::common::*;
use shm_ipc::{fault_flags, Client, IpcConfig, IpcError, Mode, Pose2, PoseEstimate, RejectCode};
use wlnavd::can::DriveMode;

fn mode(t: &shm_ipc::Telemetry) -> Mode {
    t.mode().unwrap()
}

/// What the external localization publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Inject {
    /// The true pose.
    Truth,
    /// One sample stamped 8 s (real) in the future, then nothing.
    FutureThenSilence,
    /// The pose at (1e6, −1e6) from now on.
    Absurd,
    /// The true pose shifted by a further 10 m every 0.5 s (daemon time).
    Jumping,
}

/// Drives towards (10, 0) on poses from an external localization, then switches it to
/// `inject`. Checks, in daemon time of the commands the machine received over CAN: the
/// first non-drive command within 1.2 s of the last good pose, |v| < 0.05 m/s within 4 s,
/// the stop ramp within the acceleration limits, and the telemetry's fault bits.
fn pose_fault_stops_the_machine(name: &str, inject: Inject, expect_flag: u32) {
    let config = sim_config_external_pose(name);
    let (period, params) = (config.period(), config.machine);
    let prefix = config.ipc.prefix.clone();
    let d = start(config, None);
    let phase = Arc::new(Mutex::new(Inject::Truth));
    // Daemon time of the last good pose published, as f64 bits.
    let last_good = Arc::new(AtomicU64::new(0));
    let injected_at = Arc::new(Mutex::new(None::<f64>));
    let loc = {
        let (phase, last_good, injected_at) =
            (phase.clone(), last_good.clone(), injected_at.clone());
        Localization::start(&prefix, d.sim.clone(), move |log, now| {
            let p = *phase.lock().unwrap();
            match p {
                Inject::Truth => {
                    last_good.store(log.time.to_bits(), Ordering::SeqCst);
                    Sample::Publish(true_pose(log, now))
                }
                Inject::FutureThenSilence => {
                    let mut at = injected_at.lock().unwrap();
                    if at.is_some() {
                        return Sample::Skip;
                    }
                    *at = Some(log.time);
                    Sample::Publish(true_pose(log, now + 8_000_000_000))
                }
                Inject::Absurd => {
                    Sample::Publish(PoseEstimate::new(now, 0, Pose2::new(1e6, -1e6, 0.0)))
                }
                Inject::Jumping => {
                    let t0 = *injected_at.lock().unwrap().get_or_insert(log.time);
                    let jumps = ((log.time - t0) / 0.5).floor() + 1.0;
                    let mut p = true_pose(log, now);
                    p.x += 10.0 * jumps;
                    Sample::Publish(p)
                }
            }
        })
    };
    d.goal(10.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(30), "driving", |t| {
        mode(t) == Mode::Tracking && t.command.v > 0.5
    });
    *phase.lock().unwrap() = inject;
    let seen = d.wait_for(Duration::from_secs(20), "pose fault", |t| {
        mode(t) == Mode::Fault
    });
    let fault = seen.last().unwrap();
    assert_ne!(
        fault.fault_flags & expect_flag,
        0,
        "flags {:#x}",
        fault.fault_flags
    );
    assert_eq!(
        fault.fault_flags & fault_flags::SOLVE_FAILED,
        0,
        "not a solver fault"
    );
    assert_eq!(fault.goal_active, 0, "the goal is dropped on a fault");
    d.wait_for(Duration::from_secs(20), "stopped", |t| {
        t.command.v.abs() < 1e-9 && t.command.beta_dot.abs() < 1e-9
    });
    drop(loc);
    let t_good = f64::from_bits(last_good.load(Ordering::SeqCst));
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = log
        .commands
        .iter()
        .position(|c| c.time >= t_good && c.command.mode != DriveMode::Drive)
        .expect("a stop command");
    assert!(
        log.commands[i].time <= t_good + 1.2,
        "stopping began at {:.2} s, last good pose at {t_good:.2} s",
        log.commands[i].time
    );
    let slow = log.commands[i..]
        .iter()
        .find(|c| c.command.v_cmd.abs() < 0.05)
        .expect("slowed down");
    assert!(
        slow.time <= t_good + 4.0,
        "speed < 0.05 m/s only at {:.2} s, last good pose at {t_good:.2} s",
        slow.time
    );
    check_ramp_down(log, i, &params, period);
}

#[test]
fn future_stamped_pose_then_silence_stops_the_machine() {
    pose_fault_stops_the_machine("future", Inject::FutureThenSilence, fault_flags::POSE_STALE);
}

#[test]
fn pose_jumping_to_an_absurd_position_stops_the_machine() {
    pose_fault_stops_the_machine("absurd", Inject::Absurd, fault_flags::POSE_REJECTED);
}

#[test]
fn pose_jumping_10_m_every_half_second_stops_the_machine() {
    pose_fault_stops_the_machine("jumping", Inject::Jumping, fault_flags::POSE_REJECTED);
}

#[test]
fn a_second_pose_publisher_is_refused_and_the_good_poses_keep_coming() {
    let d = start(sim_config("second-publisher"), None);
    d.goal(8.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(30), "tracking", |t| {
        mode(t) == Mode::Tracking
    });
    let rogue = Client::new(&IpcConfig::new(d.config.ipc.prefix.clone())).unwrap();
    let now = shm_ipc::monotonic_now_ns();
    let mut invalid = PoseEstimate::new(now, 1, Pose2::new(1.0, 1.0, 0.0));
    invalid.flags = 0;
    for sample in [
        PoseEstimate::new(now, 1, Pose2::new(f64::NAN, 0.0, 0.0)),
        PoseEstimate::new(
            now.saturating_sub(5_000_000_000),
            2,
            Pose2::new(0.0, 0.0, 0.0),
        ),
        invalid,
    ] {
        match rogue.publish_pose(&sample) {
            Err(IpcError::PoseSourceTaken { .. }) => {}
            other => panic!("a second pose publisher was not refused: {other:?}"),
        }
    }
    // The machine keeps driving on the simulated localization's poses.
    let seen = d.wait_for(Duration::from_secs(10), "10 more ticks", {
        let mut n = 0;
        move |_| {
            n += 1;
            n > 10
        }
    });
    for t in &seen {
        assert_eq!(mode(t), Mode::Tracking, "flags {:#x}", t.fault_flags);
        assert_eq!(
            t.fault_flags & (fault_flags::POSE_STALE | fault_flags::POSE_REJECTED),
            0
        );
    }
    d.stop();
}

#[test]
fn absurd_headings_are_rejected_and_headings_normalised() {
    use std::f64::consts::PI;
    let d = start(sim_config("heading"), None);
    d.goal(3.0, 0.0, 0.0);
    let timeout = Duration::from_secs(2);
    let r = d
        .client
        .set_goal(Pose2::new(3.0, 0.0, 1e300), &[], timeout)
        .unwrap();
    assert!(!r.is_accepted());
    assert_eq!(r.reject_code(), Ok(RejectCode::OutOfWorkspace));
    assert!(r.reason_text().contains("1.000e300"), "{}", r.reason_text());
    d.goal(3.0, 0.0, 2.0 * PI + 0.5);
    d.wait_for(Duration::from_secs(5), "normalised heading", |t| {
        t.goal_active == 1 && (t.goal.heading - 0.5).abs() < 1e-9
    });
    d.goal(3.0, 0.0, -PI);
    d.wait_for(Duration::from_secs(5), "-π as π", |t| {
        t.goal_active == 1 && t.goal.heading == PI
    });
    d.stop();
}

#[test]
fn machine_state_dropout_stops_the_machine() {
    let mut config = sim_config("state-dropout");
    let at = 4.0;
    config.sim.faults.state_dropout_at = at;
    config.sim.faults.state_dropout_duration = 1000.0;
    let (timeout, period, params) = (
        config.control.state_timeout,
        config.period(),
        config.machine,
    );
    let d = start(config, None);
    d.goal(10.0, 0.0, 0.0);
    let seen = d.wait_for(Duration::from_secs(30), "state stale fault", |t| {
        mode(t) == Mode::Fault && t.fault_flags & fault_flags::MACHINE_STATE_STALE != 0
    });
    assert!(seen.iter().any(|t| mode(t) == Mode::Tracking));
    d.wait_for(Duration::from_secs(20), "stopped", |t| t.command.v == 0.0);
    let report = d.stop();
    let log = report.sim.as_ref().unwrap();
    let i = first_command(log, 0.0, DriveMode::Fault).expect("a fault command");
    assert!(
        log.commands[i].time <= at + timeout + 2.0 * period + 0.02,
        "first fault command at {:.3} s, state stale since {:.3} s",
        log.commands[i].time,
        at + timeout
    );
    check_ramp_down(log, i, &params, period);
}

#[test]
fn a_peer_that_created_a_service_first_is_named_in_the_refusal() {
    use shm_ipc::iceoryx2::prelude::*;
    let config = sim_config("foreign-creator");
    let names = shm_ipc::ServiceNames::new(&config.ipc.prefix).unwrap();
    // A peer that opens-or-creates the goal service with iceoryx2's defaults, as a
    // careless Python client would, before the daemon starts.
    let node = NodeBuilder::new()
        .name(&NodeName::new("careless-peer").unwrap())
        .create::<ipc::Service>()
        .unwrap();
    let _service = node
        .service_builder(&ServiceName::new(&names.goal).unwrap())
        .request_response::<shm_ipc::GoalRequest, shm_ipc::GoalReply>()
        .open_or_create()
        .unwrap();
    let err = wlnavd::run(config, wlnavd::RunOptions::default())
        .expect_err("the daemon cannot use that service");
    let text = err.to_string();
    eprintln!("wlnavd refused: {text}");
    assert!(
        matches!(err, wlnavd::DaemonError::Ipc(IpcError::ServiceHeld { .. })),
        "{text}"
    );
    for needle in [
        names.goal.clone(),
        "careless-peer".to_owned(),
        format!("pid {}", std::process::id()),
    ] {
        assert!(text.contains(&needle), "{needle:?} missing in: {text}");
    }
}

#[test]
fn the_client_library_never_creates_a_service() {
    let prefix = unique_prefix("never-create");
    match Client::new(&IpcConfig::new(prefix.clone())) {
        Err(IpcError::NotServed { .. }) => {}
        other => panic!("expected NotServed, got {other:?}"),
    }
    match shm_ipc::StopClient::new(&IpcConfig::new(prefix.clone())) {
        Err(IpcError::NotServed { .. }) => {}
        other => panic!("expected NotServed, got {other:?}"),
    }
    // The daemon then starts with its own settings.
    let d = start(sim_config_with_prefix(&prefix), None);
    d.goal(2.0, 0.0, 0.0);
    d.stop();
}
