//! wlnavd with its simulated machine, driven through iceoryx2 shared memory by the client
//! library and the `wlnav` CLI. Each test starts its own daemon under its own prefix.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use e2e::{binaries, SimDaemon};
use shm_ipc::{
    fault_flags, AbortReason, Client, GoalOutcome, GoalRequest, Mode, Obstacle, Pose2, RejectCode,
    Telemetry, MAX_OBSTACLES,
};
use wlnav_cli::commands::{follow, FollowEnd, FollowOptions};
use wlnav_cli::follow::GoalTracker;

const REPLY: Duration = Duration::from_secs(2);
/// Ticks per simulated second at the default 5 Hz.
const TICK_S: f64 = 0.2;

fn accepted_goal(d: &SimDaemon, goal: Pose2, obstacles: &[Obstacle]) -> u64 {
    let id = d.client.next_request_id();
    let req = GoalRequest::set_goal(id, goal, obstacles).expect("≤ 8 obstacles");
    let reply = d.client.request(&req, REPLY).expect("reply");
    assert!(
        reply.is_accepted(),
        "goal {goal:?} rejected: {}",
        reply.reason_text()
    );
    id
}

/// Reads telemetry until `pred` holds or `timeout` passes; returns the matching sample.
fn wait_for(d: &SimDaemon, timeout: Duration, pred: impl Fn(&Telemetry) -> bool) -> Telemetry {
    let timeout = e2e::timing_scale::real(timeout);
    let deadline = Instant::now() + timeout;
    let mut last = None;
    while Instant::now() < deadline {
        if let Some(t) = d
            .telemetry
            .recv_timeout(Duration::from_millis(200))
            .expect("recv")
        {
            if pred(&t) {
                return t;
            }
            last = Some(t);
        }
    }
    panic!(
        "condition not met within {timeout:?}; last telemetry: {:?}\ndaemon log:\n{}",
        last.map(|t| (t.tick, t.mode, t.goal_request_id, t.fault_flags)),
        d.process.log_tail(20)
    );
}

#[test]
fn goal_sent_through_the_client_is_reached() {
    let _serial = e2e::serial();
    let scale = e2e::FAST;
    let d = SimDaemon::start("reach", scale);
    let goal = Pose2::new(4.5, 0.0, 0.0);
    let id = accepted_goal(&d, goal, &[]);
    let mut tracker = GoalTracker::new(id, goal);
    let opts = FollowOptions {
        timeout: e2e::timing_scale::real(Duration::from_secs_f64(30.0 / scale * 3.0 + 10.0)),
        max_seconds: Some(30.0),
        ..FollowOptions::default()
    };
    let mut last = None;
    let end = follow(&d.telemetry, &mut tracker, &opts, |t, _| last = Some(*t)).expect("follow");
    assert_eq!(end, FollowEnd::Final);
    assert!(
        tracker.status().is_succeeded(),
        "{:?}, cost {}; daemon log:\n{}",
        tracker.status(),
        e2e::cost(),
        d.process.log_tail(20)
    );
    let t = last.expect("telemetry");
    assert_eq!(t.mode(), Ok(Mode::Reached));
    // Reached when inside the tolerance at rest; the last delay-compensated sample may
    // have rolled a few centimetres further.
    assert!(t.pose_error_xy.hypot(t.pose_error_heading) < 0.15, "{t:?}");
    let converged = tracker.converged_tick.expect("converged") - tracker.first_tick.unwrap();
    eprintln!(
        "reached (4.5, 0, 0) with the {} cost: converged after {:.1} s",
        e2e::cost(),
        converged as f64 * TICK_S
    );
    // The machine comes to rest and stays there.
    let rest = wait_for(&d, Duration::from_secs(10), |t| t.at_rest == 1);
    assert_eq!(rest.mode(), Ok(Mode::Reached));
    assert_eq!(rest.goal_request_id, id);
    d.stop();
}

#[test]
fn bad_goals_are_rejected_with_their_reason_and_the_previous_goal_is_kept() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("reject", 1.0);
    let good = Pose2::new(6.0, 2.0, 0.5);
    let good_id = accepted_goal(&d, good, &[Obstacle::new(3.0, -3.0, 1.0)]);
    wait_for(&d, Duration::from_secs(5), |t| t.goal_request_id == good_id);

    let mut too_many = GoalRequest::set_goal(
        d.client.next_request_id(),
        Pose2::new(5.0, 0.0, 0.0),
        &[Obstacle::new(-10.0, -10.0, 0.5); MAX_OBSTACLES],
    )
    .unwrap();
    too_many.obstacle_count = MAX_OBSTACLES as u32 + 1;
    let cases: Vec<(&str, GoalRequest, RejectCode, &str)> = vec![
        (
            "NaN",
            GoalRequest::set_goal(
                d.client.next_request_id(),
                Pose2::new(f64::NAN, 1.0, 0.0),
                &[],
            )
            .unwrap(),
            RejectCode::NonFinite,
            "not finite",
        ),
        (
            "out of workspace",
            GoalRequest::set_goal(
                d.client.next_request_id(),
                Pose2::new(5000.0, 0.0, 0.0),
                &[],
            )
            .unwrap(),
            RejectCode::OutOfWorkspace,
            "outside the workspace",
        ),
        (
            "too many obstacles",
            too_many,
            RejectCode::TooManyObstacles,
            "at most 8",
        ),
        (
            "goal inside obstacle",
            GoalRequest::set_goal(
                d.client.next_request_id(),
                Pose2::new(5.0, 1.0, 0.0),
                &[Obstacle::new(5.2, 1.1, 1.0)],
            )
            .unwrap(),
            RejectCode::GoalInCollision,
            "goal-in-collision",
        ),
        (
            "negative obstacle radius",
            GoalRequest::set_goal(
                d.client.next_request_id(),
                Pose2::new(5.0, 1.0, 0.0),
                &[Obstacle::new(2.0, 2.0, -1.0)],
            )
            .unwrap(),
            RejectCode::BadObstacle,
            "radius",
        ),
    ];
    for (what, req, code, text) in &cases {
        let reply = d.client.request(req, REPLY).expect("reply");
        assert!(!reply.is_accepted(), "{what}: accepted");
        assert_eq!(
            reply.reject_code(),
            Ok(*code),
            "{what}: {}",
            reply.reason_text()
        );
        assert!(
            reply.reason_text().contains(text),
            "{what}: reason {:?} does not mention {text:?}",
            reply.reason_text()
        );
        assert_eq!(reply.request_id, req.request_id);
    }
    // The daemon still drives to the good goal, several ticks later.
    let first = d.next(Duration::from_secs(2)).tick;
    let t = wait_for(&d, Duration::from_secs(5), |t| t.tick >= first + 3);
    assert_eq!(t.goal_request_id, good_id);
    assert_eq!(t.active_goal(), Some(good));
    assert!(
        matches!(t.mode(), Ok(Mode::Tracking | Mode::Reached)),
        "mode {}",
        t.mode
    );
    d.stop();
}

#[test]
fn a_flood_of_10000_goals_in_10_s_keeps_the_loop_on_time_and_the_last_goal_wins() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("flood", 1.0);
    // Watch every tick on a second subscription while the flood runs.
    let stop = Arc::new(AtomicBool::new(false));
    let watcher = {
        let client = Client::new(&d.config).expect("client");
        let stop = stop.clone();
        thread::spawn(move || {
            let sub = client.subscribe_telemetry().expect("subscribe");
            let mut seen: Vec<Telemetry> = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                if let Some(t) = sub.recv_timeout(Duration::from_millis(100)).expect("recv") {
                    seen.push(t);
                }
            }
            while let Some(t) = sub.try_recv().expect("recv") {
                seen.push(t);
            }
            seen
        })
    };

    const N: usize = 10_000;
    const WINDOW: usize = 12; // < 16 requests in flight per client
    let goal_of = |i: usize| {
        Pose2::new(
            3.0 + (i % 97) as f64 * 0.05,
            -2.0 + (i % 89) as f64 * 0.05,
            0.3,
        )
    };
    let start = Instant::now();
    let mut pending = std::collections::VecDeque::new();
    let (mut accepted, mut other) = (0usize, Vec::new());
    let mut last_id = 0;
    for i in 0..N {
        // Pace to 10,000 in ~9 s so the flood really spans the loop's ticks.
        let due = Duration::from_secs_f64(e2e::timing_scale::secs(9.0) * i as f64 / N as f64);
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            thread::sleep(wait);
        }
        let id = d.client.next_request_id();
        last_id = id;
        let req = GoalRequest::set_goal(id, goal_of(i), &[]).unwrap();
        pending.push_back(d.client.submit(&req).expect("submit"));
        if pending.len() >= WINDOW {
            match pending.pop_front().unwrap().wait(REPLY) {
                Ok(r) if r.is_accepted() => accepted += 1,
                Ok(r) => other.push(format!("rejected: {}", r.reason_text())),
                Err(e) => other.push(e.to_string()),
            }
        }
    }
    for p in pending {
        match p.wait(REPLY) {
            Ok(r) if r.is_accepted() => accepted += 1,
            Ok(r) => other.push(format!("rejected: {}", r.reason_text())),
            Err(e) => other.push(e.to_string()),
        }
    }
    let took = start.elapsed();
    eprintln!(
        "flood: {N} goals in {took:?}, {accepted} accepted, {} other",
        other.len()
    );
    assert!(
        took < e2e::timing_scale::real(Duration::from_secs(10)),
        "flood took {took:?}"
    );
    assert_eq!(
        accepted,
        N,
        "not all accepted: {:?}",
        &other[..other.len().min(5)]
    );

    // The last goal wins.
    let t = wait_for(&d, Duration::from_secs(3), |t| t.goal_request_id == last_id);
    assert_eq!(t.active_goal(), Some(goal_of(N - 1)));
    thread::sleep(e2e::timing_scale::real(Duration::from_millis(600)));
    stop.store(true, Ordering::Relaxed);
    let seen = watcher.join().expect("watcher");

    // On time: no overrun flag on any tick, no tick lost, ≈ 5 Hz.
    assert!(seen.len() >= 45, "only {} ticks seen in ~10 s", seen.len());
    let overruns: Vec<u64> = seen
        .iter()
        .filter(|t| t.fault_flags & fault_flags::OVERRUN != 0)
        .map(|t| t.tick)
        .collect();
    assert!(overruns.is_empty(), "overrun at ticks {overruns:?}");
    for w in seen.windows(2) {
        assert_eq!(
            w[1].tick,
            w[0].tick + 1,
            "tick gap {} → {}",
            w[0].tick,
            w[1].tick
        );
    }
    let span_s = (seen.last().unwrap().timestamp_ns - seen[0].timestamp_ns) as f64 * 1e-9;
    let rate = (seen.len() - 1) as f64 / span_s;
    // 5 Hz in daemon time; in real time 5 Hz x the daemon's time scale (1, or 1 /
    // WLNAV_TIMING_SCALE on a slower CPU).
    let hz = 5.0 * e2e::timing_scale::daemon_time_scale(1.0);
    assert!(
        (0.96 * hz..1.04 * hz).contains(&rate),
        "tick rate {rate:.2} Hz, expected {hz:.2}"
    );
    d.stop();
}

#[test]
fn telemetry_is_seen_by_two_subscribers_at_once() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("two-subs", e2e::FAST);
    let other = Client::new(&d.config).expect("client");
    let a = other.subscribe_telemetry().expect("subscribe a");
    let b = other.subscribe_telemetry().expect("subscribe b");
    accepted_goal(&d, Pose2::new(4.0, 1.0, 0.0), &[]);
    let collect = |sub: &shm_ipc::TelemetrySubscriber| {
        let mut ticks = Vec::new();
        while ticks.len() < 30 {
            let t = sub
                .recv_timeout(e2e::timing_scale::real(Duration::from_secs(2)))
                .expect("recv")
                .expect("telemetry within 2 s (times WLNAV_TIMING_SCALE)");
            ticks.push((t.tick, t.state.x_f.to_bits(), t.goal_request_id));
        }
        ticks
    };
    let (ta, tb) = thread::scope(|s| {
        let ha = s.spawn(|| collect(&a));
        let hb = s.spawn(|| collect(&b));
        (ha.join().unwrap(), hb.join().unwrap())
    });
    let sa: BTreeSet<_> = ta.iter().copied().collect();
    let sb: BTreeSet<_> = tb.iter().copied().collect();
    let common = sa.intersection(&sb).count();
    assert!(common >= 25, "only {common} of 30 samples seen by both");
    for w in ta.windows(2).chain(tb.windows(2)) {
        assert_eq!(w[1].0, w[0].0 + 1, "a subscriber missed a tick");
    }
    d.stop();
}

#[test]
fn two_daemons_with_different_prefixes_do_not_interfere() {
    let _serial = e2e::serial();
    let (a, b) = thread::scope(|s| {
        let ha = s.spawn(|| SimDaemon::start("prefix-a", e2e::FAST));
        let hb = s.spawn(|| SimDaemon::start("prefix-b", e2e::FAST));
        (ha.join().unwrap(), hb.join().unwrap())
    });
    assert_ne!(a.prefix(), b.prefix());
    let ga = Pose2::new(5.0, 0.0, 0.0);
    let gb = Pose2::new(0.0, -5.0, -1.5);
    let ida = accepted_goal(&a, ga, &[]);
    let idb = accepted_goal(&b, gb, &[]);
    let ta = wait_for(&a, Duration::from_secs(5), |t| t.goal_request_id == ida);
    let tb = wait_for(&b, Duration::from_secs(5), |t| t.goal_request_id == idb);
    assert_eq!(ta.active_goal(), Some(ga));
    assert_eq!(tb.active_goal(), Some(gb));
    // Each keeps its own goal for a while: nothing leaks across.
    for _ in 0..15 {
        let t = a.next(Duration::from_secs(2));
        assert_eq!((t.goal_request_id, t.active_goal()), (ida, Some(ga)));
        let t = b.next(Duration::from_secs(2));
        assert_eq!((t.goal_request_id, t.active_goal()), (idb, Some(gb)));
    }
    // The machines drive apart: A along +x, B towards -y.
    let ta = a.next(Duration::from_secs(2));
    let tb = b.next(Duration::from_secs(2));
    assert!(
        ta.state.x_f > 0.2 && ta.state.y_f.abs() < 0.5,
        "A at {:?}",
        ta.state
    );
    assert!(tb.state.y_f < ta.state.y_f, "B at {:?}", tb.state);
    // Stopping one leaves the other running.
    a.stop();
    let t0 = b.next(Duration::from_secs(2)).tick;
    let t1 = b.next(Duration::from_secs(2)).tick;
    assert!(t1 > t0);
    // A prefix nobody serves has no services (clients never create them).
    assert!(matches!(
        Client::new(&shm_ipc::IpcConfig::new(e2e::unique_prefix("nobody"))),
        Err(shm_ipc::IpcError::NotServed { .. })
    ));
    b.stop();
}

#[test]
fn a_recording_made_with_wlnav_record_reads_back_and_holds_every_tick() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("record", e2e::FAST);
    accepted_goal(&d, Pose2::new(4.0, 0.0, 0.0), &[]);
    let dir = std::env::temp_dir().join(format!("wlnav-e2e-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("telemetry.mcap");
    let out = std::process::Command::new(&binaries().wlnav)
        .args(["--prefix", d.prefix(), "record"])
        .arg(&file)
        .args(["--ticks", "60"])
        .output()
        .expect("run wlnav record");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "wlnav record failed: {}\n{stdout}{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("wrote 60 ticks"), "{stdout}");

    let bytes = std::fs::read(&file).expect("read recording");
    let mut ticks = Vec::new();
    let mut planned = 0;
    for message in mcap::MessageStream::new(&bytes).expect("mcap") {
        let m = message.expect("message");
        assert_eq!(m.channel.topic, "/wlnav/telemetry");
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().expect("schema");
        assert_eq!(schema.name, "wlnav.Telemetry");
        assert_eq!(schema.encoding, "jsonschema");
        let _: serde_json::Value = serde_json::from_slice(&schema.data).expect("schema is JSON");
        let v: serde_json::Value = serde_json::from_slice(&m.data).expect("message is JSON");
        let tick = v["tick"].as_u64().expect("tick");
        assert!(v["state"]["x_f"].is_number(), "{v}");
        assert!(v["mode"].is_string());
        let plan = v["trajectory"].as_array().expect("trajectory array");
        if v["mode"] == "tracking" {
            planned += 1;
            assert!(plan.len() >= 2, "tracking without a plan: {v}");
            assert!(plan[1]["x_f"].is_number(), "{v}");
        }
        assert!(m.publish_time > 0 && m.log_time >= m.publish_time.saturating_sub(1_000_000_000));
        ticks.push(tick);
    }
    assert_eq!(ticks.len(), 60, "messages in the file");
    assert!(planned >= 10, "only {planned} ticks with a plan");
    for w in ticks.windows(2) {
        assert_eq!(w[1], w[0] + 1, "tick missing between {} and {}", w[0], w[1]);
    }
    // The summary section is there too (the file was finished, as Foxglove needs).
    let summary = mcap::Summary::read(&bytes)
        .expect("summary")
        .expect("has a summary");
    assert_eq!(summary.stats.expect("statistics").message_count, 60);
    let _ = std::fs::remove_dir_all(&dir);
    d.stop();
}

/// A ring of 8 overlapping circles (radius 0.9 m on a circle of 2.3 m) around `goal`: the
/// goal's footprint is clear (1.4 m free around it), but no way leads in.
fn ring_around(goal: Pose2) -> Vec<Obstacle> {
    (0..8)
        .map(|k| {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            Obstacle::new(goal.x + 2.3 * a.cos(), goal.y + 2.3 * a.sin(), 0.9)
        })
        .collect()
}

/// DESIGN §10 acceptance, with the daemon's defaults (progress timeout 10 s, the default
/// cost): an enclosed goal ends `aborted` within 15 s of simulated time with the machine
/// at rest, reported exactly once; `wlnav goal --wait` exits 3 for it.
#[test]
fn an_enclosed_goal_ends_aborted_within_15_s_with_the_machine_at_rest() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("enclosed", e2e::FAST);
    let goal = Pose2::new(4.2, 0.0, 0.0);
    let obstacles: Vec<String> = ring_around(goal)
        .iter()
        .map(|o| format!("{},{},{}", o.x, o.y, o.r))
        .collect();
    let mut cli = std::process::Command::new(&binaries().wlnav);
    cli.args(["--prefix", d.prefix(), "goal", "4.2", "0", "0", "--wait"]);
    for o in &obstacles {
        cli.args(["--obstacle", o]);
    }
    let child = cli
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("spawn wlnav");
    // Every tick until the machine rests after the goal's outcome.
    let mut log: Vec<Telemetry> = Vec::new();
    let deadline =
        Instant::now() + e2e::timing_scale::real(Duration::from_secs_f64(40.0 / e2e::FAST + 10.0));
    let mut ended_tick = None;
    let mut id = None;
    loop {
        assert!(
            Instant::now() < deadline,
            "no outcome and rest in time; daemon log:\n{}",
            d.process.log_tail(30)
        );
        let t = d.next(Duration::from_secs(3));
        // The goal's id: from its first tick, or (the global layer ends a goal without a
        // route on the tick that takes it) from its outcome, the only one of this daemon.
        if id.is_none() && t.goal_active != 0 {
            id = Some(t.goal_request_id);
        } else if id.is_none() && t.outcome != 0 {
            id = Some(t.outcome_request_id);
        }
        if t.outcome != 0 && Some(t.outcome_request_id) == id {
            ended_tick = Some(t.tick);
        }
        let rest = t.at_rest == 1 && t.command.v == 0.0 && t.command.beta_dot == 0.0;
        log.push(t);
        if ended_tick.is_some() && rest && t.mode() == Ok(Mode::Idle) {
            break;
        }
    }
    let out = child.wait_with_output().expect("wlnav");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(3), "{stdout}");
    assert!(stdout.contains("aborted ("), "{stdout}");

    let id = id.expect("the goal was seen");
    let first = log
        .iter()
        .find(|t| t.goal_active != 0 || t.outcome != 0)
        .map(|t| t.tick)
        .unwrap_or_default();
    for w in log.windows(2) {
        assert_eq!(w[1].tick, w[0].tick + 1, "telemetry lost");
    }
    let outcomes: Vec<&Telemetry> = log.iter().filter(|t| t.outcome != 0).collect();
    assert_eq!(outcomes.len(), 1, "exactly one outcome");
    let o = outcomes[0];
    assert_eq!(o.outcome_request_id, id);
    assert_eq!(
        o.outcome(),
        Ok(GoalOutcome::Aborted),
        "{}",
        o.outcome_text()
    );
    assert!(
        matches!(
            o.abort_reason(),
            Ok(AbortReason::NoProgress | AbortReason::NoRoute)
        ),
        "{}",
        o.outcome_text()
    );
    let rest = log.last().unwrap();
    let secs = |tick: u64| (tick - first) as f64 * TICK_S;
    eprintln!(
        "enclosed goal ({} cost): aborted after {:.1} s ({}), at rest after {:.1} s",
        e2e::cost(),
        secs(o.tick),
        o.outcome_text(),
        secs(rest.tick)
    );
    assert!(
        secs(rest.tick) <= 15.0,
        "at rest only after {:.1} s",
        secs(rest.tick)
    );
    d.stop();
}
