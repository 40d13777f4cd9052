//! The `wlnav` CLI's library parts without a daemon: argument parsing and its errors, the
//! goal tracker's decisions, the telemetry views, and the MCAP writer (read back with the
//! `mcap` crate). The CLI against a real daemon is tested in `tests/` (package `e2e`).

use clap::Parser;
use shm_ipc::{
    fault_flags, AbortReason, GoalOutcome, MachineState, Mode, Obstacle, Pose2, Telemetry,
};
use wlnav_cli::follow::{GoalStatus, GoalTracker};
use wlnav_cli::record::TelemetryWriter;
use wlnav_cli::{exit, view, Cli, Command};

fn parse(args: &[&str]) -> Result<Cli, String> {
    Cli::try_parse_from(std::iter::once("wlnav").chain(args.iter().copied()))
        .map_err(|e| e.to_string())
}

#[test]
fn goal_arguments_parse_with_negative_numbers_degrees_and_obstacles() {
    let cli = parse(&[
        "--prefix",
        "site-2",
        "goal",
        "-3.5",
        "-1",
        "-90",
        "--deg",
        "--obstacle",
        "-1,2.5,0.8",
        "--obstacle",
        "4,4,1",
        "--wait",
    ])
    .unwrap();
    assert_eq!(cli.ipc_config().prefix, "site-2");
    let Command::Goal(g) = cli.command else {
        panic!("not a goal")
    };
    assert_eq!(
        (g.x, g.y, g.heading, g.deg, g.wait),
        (-3.5, -1.0, -90.0, true, true)
    );
    assert_eq!(
        g.obstacles,
        vec![Obstacle::new(-1.0, 2.5, 0.8), Obstacle::new(4.0, 4.0, 1.0)]
    );
    assert_eq!(parse(&["watch"]).unwrap().ipc_config().prefix, "wlnav");
}

#[test]
fn bad_input_names_what_was_wrong() {
    let cases: [(&[&str], &str); 7] = [
        (
            &["goal", "nan", "0", "0"],
            "X must be a finite number, got `nan`",
        ),
        (&["goal", "1", "inf", "0"], "Y must be a finite number"),
        (
            &["goal", "1", "2", "north"],
            "HEADING must be a number, got `north`",
        ),
        (
            &["goal", "1", "2", "0", "--obstacle", "1,2"],
            "expected x,y,r",
        ),
        (
            &["goal", "1", "2", "0", "--obstacle", "1,x,2"],
            "obstacle y must be a number",
        ),
        (
            &["goal", "1", "2", "0", "--obstacle", "1,2,-0.5"],
            "radius r must be positive",
        ),
        (
            &["--prefix", "/abs", "watch"],
            "must not start or end with '/'",
        ),
    ];
    for (args, want) in cases {
        let err = parse(args).expect_err(&format!("{args:?} parsed"));
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

fn sample(tick: u64, request_id: u64, mode: Mode, err_xy: f64) -> Telemetry {
    let mut t = Telemetry {
        tick,
        goal_request_id: request_id,
        mode: mode.code(),
        goal_active: u32::from(request_id != 0),
        pose_error_xy: err_xy,
        goal: Pose2::new(5.0, 0.0, 0.0),
        ..Telemetry::ZERO
    };
    t.set_trajectory(&[MachineState::ZERO; 11]);
    t
}

fn with_outcome(mut t: Telemetry, id: u64, outcome: GoalOutcome, reason: AbortReason) -> Telemetry {
    t.set_outcome(id, outcome, reason, 1, "because");
    t
}

#[test]
fn tracker_follows_only_its_goal_and_ends_with_its_outcome() {
    let mut tr = GoalTracker::new(7, Pose2::new(5.0, 0.0, 0.0));
    assert_eq!(
        *tr.update(&sample(10, 3, Mode::Reached, 0.0)),
        GoalStatus::Pending
    );
    assert_eq!(
        *tr.update(&sample(11, 7, Mode::Tracking, 5.0)),
        GoalStatus::Active
    );
    tr.update(&sample(20, 7, Mode::Tracking, 0.05));
    // Mode reached alone is not the end: the outcome is.
    assert_eq!(
        *tr.update(&sample(24, 7, Mode::Reached, 0.01)),
        GoalStatus::Active
    );
    let done = with_outcome(
        sample(25, 7, Mode::Reached, 0.01),
        7,
        GoalOutcome::Succeeded,
        AbortReason::None,
    );
    assert!(tr.update(&done).is_succeeded());
    assert_eq!(tr.first_tick, Some(11));
    assert_eq!(tr.converged_tick, Some(20));
    assert_eq!(tr.reached_tick, Some(25));
    assert_eq!(exit::for_status(tr.status()), exit::OK);
    // Final: later samples change nothing.
    tr.update(&sample(26, 0, Mode::Idle, 0.0));
    assert!(tr.status().is_succeeded());
}

#[test]
fn tracker_maps_each_outcome_to_its_exit_code_and_ignores_other_goals_outcomes() {
    for (outcome, reason, code) in [
        (GoalOutcome::Succeeded, AbortReason::None, exit::OK),
        (GoalOutcome::Aborted, AbortReason::NoProgress, exit::ABORTED),
        (GoalOutcome::Aborted, AbortReason::Fault, exit::ABORTED),
        (GoalOutcome::Cancelled, AbortReason::None, exit::CANCELLED),
        (GoalOutcome::Preempted, AbortReason::None, exit::PREEMPTED),
    ] {
        let mut tr = GoalTracker::new(7, Pose2::default());
        tr.update(&sample(1, 7, Mode::Tracking, 3.0));
        // Another goal's outcome on the same tick stream is not ours.
        let other = with_outcome(sample(2, 7, Mode::Tracking, 3.0), 6, outcome, reason);
        assert_eq!(*tr.update(&other), GoalStatus::Active);
        // Ours may come when the telemetry already shows the next goal (preempted).
        let ours = with_outcome(sample(3, 8, Mode::Tracking, 3.0), 7, outcome, reason);
        let status = tr.update(&ours).clone();
        let o = status.outcome().expect("an outcome");
        assert_eq!(
            (o.outcome, o.abort_reason, o.text.as_str()),
            (outcome, reason, "because")
        );
        assert_eq!(exit::for_status(&status), code, "{outcome:?}");
    }
    // A goal that never became active still gets its outcome (superseded at once).
    let mut tr = GoalTracker::new(9, Pose2::default());
    let t = with_outcome(
        sample(5, 10, Mode::Tracking, 3.0),
        9,
        GoalOutcome::Preempted,
        AbortReason::None,
    );
    assert_eq!(exit::for_status(tr.update(&t)), exit::PREEMPTED);
    // Giving up without an outcome.
    let mut tr = GoalTracker::new(9, Pose2::default());
    tr.lose_telemetry("silence");
    assert_eq!(exit::for_status(tr.status()), exit::ERROR);
    let mut tr = GoalTracker::new(9, Pose2::default());
    tr.time_out("too long");
    assert_eq!(exit::for_status(tr.status()), exit::TIMED_OUT);
    // An overrun alone does not end a goal.
    let mut tr = GoalTracker::new(7, Pose2::default());
    let mut o = sample(1, 7, Mode::Tracking, 3.0);
    o.fault_flags = fault_flags::OVERRUN;
    assert_eq!(*tr.update(&o), GoalStatus::Active);
    assert_eq!(tr.overruns, 1);
}

#[test]
fn views_show_mode_goal_and_faults() {
    let mut t = sample(42, 7, Mode::Tracking, 2.5);
    t.fault_flags = fault_flags::OVERRUN | fault_flags::CAN_CRC;
    let line = view::line(&t);
    assert!(line.starts_with("tick 42 tracking"), "{line}");
    assert!(line.contains("goal  5.00  0.00"), "{line}");
    assert!(line.contains("faults can-crc,overrun"), "{line}");
    assert!(!line.contains("outcome"), "{line}");
    let ended = with_outcome(t, 6, GoalOutcome::Aborted, AbortReason::NoProgress);
    let line = view::line(&ended);
    assert!(
        line.ends_with("| outcome aborted (no-progress) of request 6: because"),
        "{line}"
    );
    let header = view::table_header();
    let row = view::table_row(&t);
    assert!(header.contains("mode") && row.contains("tracking"));
    assert_eq!(view::fault_text(0), "-");
    assert_eq!(view::fault_names(1 << 30), vec!["bit-30"]);
    assert_eq!(view::mode_name(99), "mode-99");
}

#[test]
fn mcap_writer_output_reads_back_with_schema_and_every_message() {
    let path = std::env::temp_dir().join(format!("wlnav-cli-test-{}.mcap", std::process::id()));
    let mut w = TelemetryWriter::create(&path, "unit").unwrap();
    for tick in 100..150 {
        let mut t = sample(tick, 7, Mode::Tracking, 1.0);
        t.cost = if tick == 120 { f64::NAN } else { 1.5 };
        t.timestamp_ns = shm_ipc::monotonic_now_ns();
        w.write(&t).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let mut ticks = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("wlnav.Telemetry", "jsonschema")
        );
        assert_eq!(m.channel.message_encoding, "json");
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if v["tick"] == 120 {
            assert!(v["cost"].is_null(), "NaN is written as null");
        }
        assert_eq!(v["trajectory"].as_array().unwrap().len(), 11);
        ticks.push(v["tick"].as_u64().unwrap());
    }
    assert_eq!(ticks, (100..150).collect::<Vec<_>>());
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, 50);
    std::fs::remove_file(&path).unwrap();
}

/// The daemon's tick period is measured from the telemetry's timestamps (it is
/// the daemon's `mpc.dt`, configured there only), on the daemon's clock when a
/// simulated machine runs faster than real time.
#[test]
fn tracker_measures_the_tick_period_from_the_telemetry_stamps() {
    for (scale, wall_period_ns) in [(1.0, 200_000_000u64), (10.0, 20_000_000)] {
        let mut tr = GoalTracker::new(7, Pose2::new(5.0, 0.0, 0.0)).with_time_scale(scale);
        let stamped = |tick: u64| Telemetry {
            timestamp_ns: 5_000_000_000 + tick * wall_period_ns,
            ..sample(tick, 7, Mode::Tracking, 1.0)
        };
        tr.update(&stamped(100));
        assert_eq!(tr.tick_period(), None, "one sample gives no period");
        assert_eq!(tr.seconds_since_start(100), None);
        tr.update(&stamped(101));
        tr.update(&stamped(150));
        let period = tr.tick_period().unwrap();
        assert!((period - 0.2).abs() < 1e-12, "scale {scale}: {period}");
        let s = tr.seconds_since_start(150).unwrap();
        assert!((s - 10.0).abs() < 1e-9, "scale {scale}: {s}");
    }
}
