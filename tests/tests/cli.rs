//! The `wlnav` CLI against a real `wlnavd --sim`: goal (accept, reject, --wait), cancel,
//! watch, and the `demo` main job.

use std::process::{Command, Output};
use std::time::Duration;

use e2e::{binaries, SimDaemon};
use shm_ipc::Mode;

fn wlnav(args: &[&str]) -> Output {
    Command::new(&binaries().wlnav)
        .args(args)
        .output()
        .expect("run wlnav")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn bad_input_is_refused_before_anything_is_sent() {
    let o = wlnav(&["goal", "1", "nan", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("Y must be a finite number"),
        "{}",
        text(&o)
    );
    let o = wlnav(&["goal", "1", "2", "0", "--obstacle", "1,2"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("expected x,y,r"), "{}", text(&o));
    let o = wlnav(&["goal", "1", "2", "0", "--obstacle", "1,2,0"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o).contains("radius r must be positive"),
        "{}",
        text(&o)
    );
    let o = wlnav(&["--prefix", "bad prefix", "watch"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o).contains("invalid service-name prefix"),
        "{}",
        text(&o)
    );
    // No daemon under a fresh prefix: exit 4 with a hint.
    let prefix = e2e::unique_prefix("cli-nodaemon");
    let o = wlnav(&["--prefix", &prefix, "goal", "1", "2", "0"]);
    assert_eq!(o.status.code(), Some(4), "{}", text(&o));
    assert!(text(&o).contains("no daemon"), "{}", text(&o));
}

#[test]
fn goal_cancel_and_watch_through_the_cli() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("cli", e2e::FAST);
    let p = d.prefix().to_owned();

    let o = wlnav(&["--prefix", &p, "goal", "60", "0", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("rejected (out-of-workspace)"),
        "{}",
        text(&o)
    );

    let o = wlnav(&[
        "--prefix",
        &p,
        "goal",
        "3",
        "-1",
        "-20",
        "--deg",
        "--obstacle",
        "10,10,1",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("accepted"), "{}", text(&o));

    let o = wlnav(&["--prefix", &p, "watch", "--count", "5"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 5, "{out}");
    // The first line may be the sample published just before the goal was taken up.
    assert!(lines.iter().all(|l| l.starts_with("tick ")), "{out}");
    assert!(
        lines[1..].iter().all(|l| l.contains("goal  3.00 -1.00")),
        "{out}"
    );

    let o = wlnav(&["--prefix", &p, "watch", "--table", "--count", "3"]);
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        out.lines()
            .next()
            .is_some_and(|l| l.contains("tick") && l.contains("mode")),
        "{out}"
    );
    assert_eq!(out.lines().count(), 5, "header, rule, 3 rows:\n{out}");

    // Skip the samples buffered while the CLI ran (some predate the goal).
    let before_cancel = d
        .telemetry
        .latest()
        .expect("telemetry")
        .map_or(0, |t| t.tick);
    let o = wlnav(&["--prefix", &p, "cancel"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("cancel: accepted"), "{}", text(&o));
    // The goal is dropped and the machine comes to rest.
    let deadline = std::time::Instant::now() + e2e::timing_scale::real(Duration::from_secs(10));
    loop {
        let t = d.next(Duration::from_secs(2));
        if t.tick > before_cancel
            && t.goal_active == 0
            && t.mode() == Ok(Mode::Idle)
            && t.state.v_f.abs() < 0.02
        {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "goal still active after cancel: {t:?}"
        );
    }

    d.stop();

    // `goal --wait` on a fresh daemon: the machine at rest at the origin with β = 0, so the
    // goal 3 m straight ahead is reachable by the quadratic bring-up cost used without
    // trained weights (after the cancel above the machine may rest with β ≠ 0, which that
    // cost cannot always straighten out within the horizon).
    let d = SimDaemon::start("cli-wait", e2e::FAST);
    let p = d.prefix().to_owned();
    let s = d.next(Duration::from_secs(5)).state;
    let (gx, gy) = (s.x_f + 3.0 * s.theta_f.cos(), s.y_f + 3.0 * s.theta_f.sin());
    let (gx, gy, gh) = (
        format!("{gx:.3}"),
        format!("{gy:.3}"),
        format!("{:.4}", s.theta_f),
    );
    let o = wlnav(&[
        "--prefix",
        &p,
        "goal",
        &gx,
        &gy,
        &gh,
        "--wait",
        "--timeout",
        "30",
    ]);
    let out = text(&o);
    assert!(out.contains("accepted") && out.contains("  t "), "{out}");
    assert_eq!(
        o.status.code(),
        Some(0),
        "goal --wait did not reach (cost {}):\n{out}",
        e2e::cost()
    );
    assert!(out.contains("succeeded: converged"), "{out}");
    d.stop();
}

#[test]
fn demo_drives_the_loading_cycle_and_stops_the_daemon() {
    let _serial = e2e::serial();
    let dir = std::env::temp_dir().join(format!("wlnav-e2e-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let svg = dir.join("demo.svg");
    let rec = dir.join("demo.mcap");
    let o = Command::new(&binaries().wlnav)
        .args(["demo", "--time-scale"])
        .arg(e2e::timing_scale::daemon_time_scale(4.0).to_string())
        .args(["--cost", &e2e::cost()])
        .arg("--out")
        .arg(&svg)
        .arg("--record")
        .arg(&rec)
        .output()
        .expect("run wlnav demo");
    let out = text(&o);
    eprintln!("{out}");
    assert!(out.contains("summary"), "{out}");
    assert!(
        out.contains("stopped with SIGTERM: exit status: 0"),
        "{out}"
    );
    let picture = std::fs::read_to_string(&svg).expect("svg written");
    assert!(
        picture.contains("<svg") && picture.contains("<polyline"),
        "not a plot"
    );
    // The demo's site (sim/sites/demo.json): wlnavd reports it loaded (its
    // telemetry's site id and version), and the picture draws its pile, wall
    // and keep-out.
    assert!(
        out.contains("site demo version 1 hash "),
        "wlnavd did not load the demo's site: {out}"
    );
    assert!(out.contains("3 features drawn"), "{out}");
    assert!(picture.matches("<polygon").count() >= 3, "no site drawn");
    // The demo's person (sim/movers/demo.csv) crosses the first leg: wlnavd's
    // simulated perception publishes it, the machine holds for it, and the
    // picture marks where (DESIGN §18).
    assert!(
        out.contains("--movers") && out.contains("held after a protective stop"),
        "the machine did not hold for the demo's person: {out}"
    );
    assert!(
        picture.contains("held after a protective stop"),
        "not marked"
    );
    assert!(std::fs::metadata(&rec).expect("recording").len() > 1000);
    // 0 = every leg reached, 3 = a leg not reached (reported honestly); never a crash.
    assert!(matches!(o.status.code(), Some(0) | Some(3)), "{out}");
    if o.status.code() == Some(0) {
        assert!(out.contains("4/4 legs reached"), "{out}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Starts `wlnav --prefix P goal … --wait` in the background.
fn wait_in_background(prefix: &str, goal: &[&str], obstacles: &[&str]) -> std::process::Child {
    let mut cmd = Command::new(&binaries().wlnav);
    cmd.args(["--prefix", prefix, "goal"]).args(goal);
    for o in obstacles {
        cmd.args(["--obstacle", o]);
    }
    cmd.args(["--wait", "--timeout", "60"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn wlnav goal --wait")
}

/// Waits until the daemon's telemetry shows the goal at (`x`, `y`) being tracked (so a
/// goal still active from before is not mistaken for the one just sent).
fn wait_tracking(d: &SimDaemon, x: f64, y: f64) {
    let deadline = std::time::Instant::now() + e2e::timing_scale::real(Duration::from_secs(20));
    loop {
        let t = d.next(Duration::from_secs(2));
        let ours = t
            .active_goal()
            .is_some_and(|g| (g.x - x).abs() < 1e-6 && (g.y - y).abs() < 1e-6);
        if ours && t.mode() == Ok(Mode::Tracking) && t.command.v > 0.1 {
            return;
        }
        assert!(std::time::Instant::now() < deadline, "never tracking");
    }
}

#[test]
fn goal_wait_exit_codes_follow_the_outcome_and_stop_latches_until_resume() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("cli-outcomes", e2e::FAST);
    let p = d.prefix().to_owned();

    // Goals far enough (~20 s of driving) that none is reached before the next command,
    // even on a loaded machine. Preempted by a newer goal: exit 6.
    let first = wait_in_background(&p, &["20", "0", "0"], &[]);
    wait_tracking(&d, 20.0, 0.0);
    let o = wlnav(&["--prefix", &p, "goal", "9", "1", "0"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = first.wait_with_output().expect("wait");
    assert_eq!(o.status.code(), Some(6), "{}", text(&o));
    assert!(
        text(&o).contains("preempted: preempted by request"),
        "{}",
        text(&o)
    );

    // Cancelled by an operator stop: exit 5; the stop latches.
    let second = wait_in_background(&p, &["20", "-2", "0"], &[]);
    wait_tracking(&d, 20.0, -2.0);
    let o = wlnav(&["--prefix", &p, "stop"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = second.wait_with_output().expect("wait");
    assert_eq!(o.status.code(), Some(5), "{}", text(&o));
    assert!(
        text(&o).contains("cancelled: stopped by an operator"),
        "{}",
        text(&o)
    );
    let o = wlnav(&["--prefix", &p, "goal", "5", "0", "0"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("rejected (not-ready): stopped by an operator"),
        "{}",
        text(&o)
    );
    let o = wlnav(&["--prefix", &p, "resume"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("resume: accepted"), "{}", text(&o));

    // A goal whose footprint is in an obstacle: rejected at once, exit 1.
    let o = wlnav(&[
        "--prefix",
        &p,
        "goal",
        "5",
        "0",
        "0",
        "--obstacle",
        "3.8,0,0.4",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("rejected (goal-in-collision)"),
        "{}",
        text(&o)
    );

    // After resume a goal is accepted again; cancel it: exit 5.
    let third = wait_in_background(&p, &["20", "3", "0"], &[]);
    wait_tracking(&d, 20.0, 3.0);
    let o = wlnav(&["--prefix", &p, "cancel"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = third.wait_with_output().expect("wait");
    assert_eq!(o.status.code(), Some(5), "{}", text(&o));
    assert!(
        text(&o).contains("cancelled: cancelled by request"),
        "{}",
        text(&o)
    );
    d.stop();
}
