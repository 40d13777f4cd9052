//! `goal`, `cancel`, `stop`, `resume` and `watch`, plus the telemetry-following loop that
//! `goal --wait` and `demo` share.

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;

use shm_ipc::{Client, StopClient, StopPath, TelemetrySubscriber};
use shm_ipc::{ClientError, IpcError};
use shm_ipc::{GoalReply, GoalRequest, Pose2, RejectCode, Telemetry};

use super::follow::{GoalStatus, GoalTracker};
use super::view::{self, mode_name};
use super::{exit, signal, Cli, GoalArgs, RequestArgs, SimpleRequest, StatusArgs, WatchArgs};

/// Writes one line to stdout; false if stdout is gone (`wlnav watch | head`), so callers
/// stop quietly instead of panicking on a broken pipe.
pub fn emit(line: &str) -> bool {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}").and_then(|_| out.flush()).is_ok()
}

/// Connects a client, with a message that names the prefix on failure.
pub fn connect(cli: &Cli) -> anyhow::Result<Client> {
    let config = cli.ipc_config();
    Client::new(&config).with_context(|| {
        format!(
            "cannot open the shared-memory services of prefix {:?}",
            config.prefix
        )
    })
}

/// Connects a client, waiting up to `timeout` for a daemon to create the services (the
/// client never creates them) unless Ctrl-C comes first. `Ok(None)` when interrupted.
pub fn connect_waiting(cli: &Cli, timeout: Duration) -> anyhow::Result<Option<Client>> {
    let mut config = cli.ipc_config();
    let deadline = Instant::now() + timeout;
    let mut hinted = false;
    loop {
        if signal::requested() {
            return Ok(None);
        }
        match Client::new(&config) {
            Err(IpcError::NotServed { .. }) if Instant::now() < deadline => {
                if !hinted {
                    eprintln!("wlnav: waiting for wlnavd on prefix {:?} …", config.prefix);
                    hinted = true;
                }
                config.cleanup_stale_nodes = false;
                std::thread::sleep(Duration::from_millis(100));
            }
            other => {
                return other.map(Some).with_context(|| {
                    format!(
                        "cannot open the shared-memory services of prefix {:?}",
                        config.prefix
                    )
                })
            }
        }
    }
}

/// A reject code's short name.
pub fn reject_code_name(code: u32) -> String {
    match RejectCode::try_from(code) {
        Ok(RejectCode::None) => "none".into(),
        Ok(RejectCode::NonFinite) => "non-finite".into(),
        Ok(RejectCode::OutOfWorkspace) => "out-of-workspace".into(),
        Ok(RejectCode::TooManyObstacles) => "too-many-obstacles".into(),
        Ok(RejectCode::BadObstacle) => "bad-obstacle".into(),
        Ok(RejectCode::GoalInCollision) => "goal-in-collision".into(),
        Ok(RejectCode::UnknownKind) => "unknown-kind".into(),
        Ok(RejectCode::NotReady) => "not-ready".into(),
        Ok(RejectCode::Other) => "other".into(),
        Ok(RejectCode::MachineInCollision) => "machine-in-collision".into(),
        Err(c) => format!("code-{c}"),
    }
}

/// `rejected (out-of-workspace): goal (60.000, 0.000) m is outside …`.
pub fn describe_reply(reply: &GoalReply) -> String {
    if reply.is_accepted() {
        format!("accepted (request {})", reply.request_id)
    } else {
        format!(
            "rejected ({}): {}",
            reject_code_name(reply.reason_code),
            reply.reason_text()
        )
    }
}

/// Explains a failed request and picks the exit code.
fn request_error(cli: &Cli, e: ClientError) -> u8 {
    match &e {
        ClientError::NoDaemon { .. } => eprintln!(
            "wlnav: {e} (is wlnavd running{}?)",
            cli.prefix
                .as_deref()
                .map(|p| format!(" with --prefix {p}"))
                .unwrap_or_default()
        ),
        _ => eprintln!("wlnav: {e}"),
    }
    exit::ERROR
}

/// `wlnav goal X Y HEADING [--obstacle x,y,r]... [--wait]`.
pub fn goal(cli: &Cli, a: &GoalArgs) -> anyhow::Result<u8> {
    let heading = if a.deg {
        a.heading.to_radians()
    } else {
        a.heading
    };
    let goal = Pose2::new(a.x, a.y, heading);
    if a.obstacles.len() > shm_ipc::MAX_OBSTACLES {
        eprintln!(
            "wlnav: {} obstacles given, at most {} fit in a request",
            a.obstacles.len(),
            shm_ipc::MAX_OBSTACLES
        );
        return Ok(exit::USAGE);
    }
    let client = connect(cli)?;
    // Subscribe before sending so no tick after the acceptance is missed.
    let sub = if a.wait {
        Some(client.subscribe_telemetry()?)
    } else {
        None
    };
    let id = client.next_request_id();
    let req = GoalRequest::set_goal(id, goal, &a.obstacles)
        .context("too many obstacles for one request")?;
    let reply = match client.request(&req, Duration::from_secs_f64(a.reply_timeout)) {
        Ok(r) => r,
        Err(e) => return Ok(request_error(cli, e)),
    };
    emit(&format!(
        "goal ({:.3}, {:.3}) m heading {:.1}°, {} obstacle{}: {}",
        goal.x,
        goal.y,
        goal.heading.to_degrees(),
        a.obstacles.len(),
        if a.obstacles.len() == 1 { "" } else { "s" },
        describe_reply(&reply)
    ));
    if !reply.is_accepted() {
        return Ok(exit::REJECTED);
    }
    let Some(sub) = sub else {
        return Ok(exit::OK);
    };
    let mut tracker = GoalTracker::new(id, goal);
    let opts = FollowOptions {
        timeout: Duration::from_secs_f64(a.timeout),
        ..FollowOptions::default()
    };
    let mut printer = ProgressPrinter::default();
    let end = follow(&sub, &mut tracker, &opts, |t, tr| {
        if let Some(line) = printer.line(t, tr) {
            emit(&line);
        }
    })?;
    match end {
        FollowEnd::Interrupted => {
            emit("interrupted: the goal stays active (`wlnav cancel` drops it)");
            return Ok(exit::INTERRUPTED);
        }
        FollowEnd::DaemonLost => {
            emit(&outcome_line(&tracker));
            return Ok(exit::ERROR);
        }
        FollowEnd::Final => {}
    }
    emit(&outcome_line(&tracker));
    Ok(exit::for_status(tracker.status()))
}

/// `succeeded: converged after 9.8 s, reported after 10.2 s (51 ticks)`,
/// `aborted (no-progress): no approach to the goal for 10.0 s`, …
pub fn outcome_line(tracker: &GoalTracker) -> String {
    let secs = |tick: Option<u64>| tick.and_then(|t| tracker.seconds_since_start(t));
    let fmt_s = |s: Option<f64>| {
        s.map(|s| format!("{s:.1} s"))
            .unwrap_or_else(|| "? s".into())
    };
    match tracker.status() {
        GoalStatus::Ended(o) if tracker.status().is_succeeded() => format!(
            "succeeded: converged (DESIGN §7, < 0.1) after {}, reported after {} ({} ticks): {}",
            fmt_s(secs(tracker.converged_tick)),
            fmt_s(secs(tracker.reached_tick)),
            tracker
                .reached_tick
                .and_then(|t| tracker.ticks_since_start(t))
                .unwrap_or(0),
            o.text
        ),
        GoalStatus::Ended(o) => format!("{}: {}", o.name(), o.text),
        GoalStatus::NoTelemetry(why) => format!("no outcome: {why}"),
        GoalStatus::TimedOut(why) => format!("no outcome yet: {why}"),
        GoalStatus::Pending => "no telemetry for this goal".into(),
        GoalStatus::Active => "still driving".into(),
    }
}

/// One progress line: time since the goal started, mode, pose, remaining error, speed.
pub fn progress_line(t: &Telemetry, tracker: &GoalTracker) -> String {
    let since = tracker.seconds_since_start(t.tick).unwrap_or(0.0);
    let s = &t.state;
    format!(
        "  t {:5.1} s  {:<8} at ({:6.2}, {:6.2}) θ {:6.1}°  to go {:5.2} m {:6.1}°  v {:5.2} m/s  solve {:5.1} ms",
        since,
        mode_name(t.mode),
        s.x_f,
        s.y_f,
        s.theta_f.to_degrees(),
        t.pose_error_xy,
        t.pose_error_heading.to_degrees(),
        s.v_f,
        t.solve_time_us / 1000.0
    )
}

/// Decides which samples get a progress line: one per second (of the daemon's clock)
/// while the machine moves, one every 5 s while it stands still (a stalled goal does
/// not flood the screen), and the final one.
#[derive(Debug, Clone, Default)]
pub struct ProgressPrinter {
    /// Whole seconds since the start, and the pose, of the last line shown.
    last: Option<(u64, f64, f64, f64)>,
}

impl ProgressPrinter {
    /// The progress line for `t`, if it should be shown.
    pub fn line(&mut self, t: &Telemetry, tracker: &GoalTracker) -> Option<String> {
        tracker.ticks_since_start(t.tick)?;
        let second = tracker.seconds_since_start(t.tick).unwrap_or(0.0).floor() as u64;
        let s = &t.state;
        let show = tracker.status().is_final()
            || match self.last {
                None => true,
                Some((last, x, y, th)) => {
                    let moved =
                        (s.x_f - x).hypot(s.y_f - y) > 0.01 || (s.theta_f - th).abs() > 0.004;
                    second > last && (moved || second >= last + 5)
                }
            };
        if !show {
            return None;
        }
        self.last = Some((second, s.x_f, s.y_f, s.theta_f));
        Some(progress_line(t, tracker))
    }
}

/// Limits of [`follow`].
#[derive(Debug, Clone)]
pub struct FollowOptions {
    /// Wall-clock limit for the whole follow.
    pub timeout: Duration,
    /// Fail if no telemetry arrives for this long.
    pub silence: Duration,
    /// Fail if the goal is not reached within this many seconds (of the daemon's
    /// clock) of its first tick (the paper's test is 30 s).
    pub max_seconds: Option<f64>,
    /// Fail if the daemon has not taken the goal up within this many samples.
    pub max_pending_samples: u64,
}

impl Default for FollowOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(120),
            silence: Duration::from_secs(3),
            max_seconds: None,
            max_pending_samples: 50,
        }
    }
}

/// How [`follow`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FollowEnd {
    /// The tracker reached a final status (an outcome, or a time limit).
    Final,
    /// Ctrl-C / SIGTERM.
    Interrupted,
    /// No telemetry for [`FollowOptions::silence`]: the daemon is gone (the tracker is
    /// marked failed with the reason too).
    DaemonLost,
}

/// Feeds telemetry to `tracker` until its status is final (the goal's outcome, silence, a
/// time limit), calling `on_sample` after each sample.
pub fn follow(
    sub: &TelemetrySubscriber,
    tracker: &mut GoalTracker,
    opts: &FollowOptions,
    mut on_sample: impl FnMut(&Telemetry, &GoalTracker),
) -> Result<FollowEnd, IpcError> {
    let start = Instant::now();
    let mut last_sample = Instant::now();
    let mut pending_samples = 0u64;
    loop {
        if signal::requested() {
            return Ok(FollowEnd::Interrupted);
        }
        let sample = match sub.recv_timeout(Duration::from_millis(100)) {
            // A signal woke the wait: the check at the top of the loop decides.
            Err(IpcError::Interrupted) => continue,
            other => other?,
        };
        if let Some(t) = sample {
            last_sample = Instant::now();
            tracker.update(&t);
            if *tracker.status() == GoalStatus::Pending {
                pending_samples += 1;
                if pending_samples > opts.max_pending_samples {
                    tracker.time_out(format!(
                        "the daemon did not take the goal up within {} ticks",
                        opts.max_pending_samples
                    ));
                }
            }
            if let (Some(max), Some(s)) = (opts.max_seconds, tracker.seconds_since_start(t.tick)) {
                if s >= max && !tracker.status().is_final() {
                    tracker.time_out(format!("not reached within {max} s"));
                }
            }
            on_sample(&t, tracker);
        } else if last_sample.elapsed() >= opts.silence {
            tracker.lose_telemetry(format!(
                "no telemetry for {:.1} s: is the daemon still running?",
                opts.silence.as_secs_f64()
            ));
            return Ok(FollowEnd::DaemonLost);
        }
        if !tracker.status().is_final() && start.elapsed() >= opts.timeout {
            tracker.time_out(format!(
                "no result within {:.0} s",
                opts.timeout.as_secs_f64()
            ));
        }
        if tracker.status().is_final() {
            return Ok(FollowEnd::Final);
        }
    }
}

/// `wlnav cancel`, `wlnav stop`, `wlnav resume`. A stop goes through the reserved stop
/// service ([`StopClient`]): it needs none of the goal service's client slots, and it
/// latches like a stop on the goal service (`wlnav resume` releases it). When another
/// process holds the stop service's slots it falls back to the goal service, and when no
/// notifier is free it is sent without one; the detours are printed on stderr, naming
/// the holders, and the exit code is the reply's (0 accepted).
pub fn simple_request(cli: &Cli, a: &RequestArgs, what: SimpleRequest) -> anyhow::Result<u8> {
    let timeout = Duration::from_secs_f64(a.reply_timeout);
    let result = match what {
        SimpleRequest::Stop => {
            let config = cli.ipc_config();
            let client = StopClient::new(&config).with_context(|| {
                format!("cannot open the stop service of prefix {:?}", config.prefix)
            })?;
            // The request id is the monotonic clock: unique across processes in practice.
            let id = shm_ipc::monotonic_now_ns().max(1);
            client.stop_report(id, timeout).map(|report| {
                // What another process held and which way the stop went instead: the
                // operator learns whom to stop, the stop itself still counts.
                for detour in &report.detours {
                    eprintln!("wlnav: {detour}");
                }
                if report.path == StopPath::GoalService {
                    eprintln!("wlnav: the stop went on the goal service (kind 3)");
                }
                report.reply
            })
        }
        SimpleRequest::Cancel => connect(cli)?.cancel(timeout),
        SimpleRequest::Resume => connect(cli)?.resume(timeout),
        SimpleRequest::ReloadSite => connect(cli)?.reload_site(timeout),
    };
    let reply = match result {
        Ok(r) => r,
        Err(e) => return Ok(request_error(cli, e)),
    };
    emit(&format!("{}: {}", what.name(), describe_reply(&reply)));
    Ok(if reply.is_accepted() {
        exit::OK
    } else {
        exit::REJECTED
    })
}

/// `wlnav status`: the next telemetry sample as one line, then the site in force.
pub fn status(cli: &Cli, a: &StatusArgs) -> anyhow::Result<u8> {
    let timeout = Duration::from_secs_f64(a.timeout);
    let Some(client) = connect_waiting(cli, timeout)? else {
        return Ok(exit::INTERRUPTED);
    };
    let sub = client.subscribe_telemetry()?;
    let start = Instant::now();
    while start.elapsed() < timeout && !signal::requested() {
        match sub.recv_timeout(Duration::from_millis(200)) {
            Ok(Some(t)) => {
                emit(&view::line(&t));
                emit(&view::site_text(&t));
                return Ok(exit::OK);
            }
            Ok(None) | Err(IpcError::Interrupted) => continue,
            Err(e) => return Err(e.into()),
        }
    }
    eprintln!(
        "wlnav: no telemetry for {:.0} s (is wlnavd running?)",
        a.timeout
    );
    Ok(exit::ERROR)
}

/// `wlnav watch [--table] [--count N]`.
pub fn watch(cli: &Cli, a: &WatchArgs) -> anyhow::Result<u8> {
    let silence = Duration::from_secs_f64(a.silence_timeout);
    let Some(client) = connect_waiting(cli, silence)? else {
        return Ok(exit::INTERRUPTED);
    };
    let sub = client.subscribe_telemetry()?;
    let mut last_sample = Instant::now();
    let mut last_tick: Option<u64> = None;
    let mut shown = 0u64;
    let mut hinted = false;
    while !signal::requested() {
        if a.count.is_some_and(|c| shown >= c) {
            break;
        }
        let sample = match sub.recv_timeout(Duration::from_millis(200)) {
            Err(IpcError::Interrupted) => continue,
            other => other?,
        };
        let Some(t) = sample else {
            if !hinted && last_sample.elapsed() > Duration::from_secs(1) {
                eprintln!(
                    "wlnav: waiting for telemetry on {:?} …",
                    client.service_names().telemetry
                );
                hinted = true;
            }
            if last_sample.elapsed() >= silence {
                eprintln!(
                    "wlnav: no telemetry for {:.0} s (is wlnavd running{}?)",
                    silence.as_secs_f64(),
                    cli.prefix
                        .as_deref()
                        .map(|p| format!(" with --prefix {p}"))
                        .unwrap_or_default()
                );
                return Ok(exit::ERROR);
            }
            continue;
        };
        last_sample = Instant::now();
        if let Some(prev) = last_tick {
            if t.tick > prev + 1 {
                eprintln!("wlnav: ({} ticks not seen)", t.tick - prev - 1);
            }
        }
        last_tick = Some(t.tick);
        // The header every 20 rows (`is_multiple_of` needs Rust 1.87; the MSRV is 1.80).
        #[allow(clippy::manual_is_multiple_of)]
        let header_due = shown % 20 == 0;
        let ok = if a.table {
            (!header_due || emit(&view::table_header())) && emit(&view::table_row(&t))
        } else {
            emit(&view::line(&t))
        };
        if !ok {
            break;
        }
        shown += 1;
    }
    Ok(if signal::requested() {
        exit::INTERRUPTED
    } else {
        exit::OK
    })
}
