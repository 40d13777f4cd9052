//! `wlnav demo`: the whole system in one command. Starts `wlnavd --sim` (the built-in
//! simulated machine, no configuration) under a private prefix, waits until it is ready,
//! drives the short loading cycle in [`LOADING_CYCLE`] and a leg around a pile of the demo's
//! site through the real shared-memory path (goal requests, telemetry), prints progress and
//! each leg's convergence time, writes an SVG of the site, the global route, the driven
//! path and the planned horizons, and stops the daemon with SIGTERM. Exit code 0 only if
//! every leg was reached.

use std::ffi::OsString;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;

use shm_ipc::fault_flags;
use shm_ipc::Client;
use shm_ipc::ClientError;
use shm_ipc::IpcConfig;
use shm_ipc::{GoalReply, Pose2};

use super::commands::{
    describe_reply, emit, follow, outcome_line, FollowEnd, FollowOptions, ProgressPrinter,
};
use super::daemon_process::{locate_wlnavd, unique_prefix, DaemonProcess};
use super::follow::{GoalStatus, GoalTracker};
use super::plot::{write_svg, LegTrace, SiteDrawing};
use super::record::{record, RecordLimits};
use super::{args, exit, signal, Cli};

/// One goal of the demo.
#[derive(Debug, Clone, Copy)]
pub struct Leg {
    /// What the leg does.
    pub name: &'static str,
    /// Goal of the front axle (the site is the daemon's: no circles go with it).
    pub goal: Pose2,
}

/// A short V-pattern loading cycle from the origin (heading 0): forward into the pile face
/// 5 m ahead, back out to the apex of the V while turning the nose 60° to the right, then
/// forward 5 m along the new heading to the dump point (truck); then on to the next face,
/// 8 m on, behind a pile of the demo's site (`sim/sites/demo.json`: the pile a polygon
/// across the way out of the dump point, a wall, an office keep-out; the global layer
/// routes around the pile). Each leg is 4–8 m, inside the goal distances the critic was
/// trained on (2.5–10 m). The demo's own summary prints each leg's result (4/4 at
/// 815c9ab, docs/guide/operating.md).
pub const LOADING_CYCLE: [Leg; 4] = [
    Leg {
        name: "drive to the pile face",
        goal: Pose2::new(5.0, 0.0, 0.0),
    },
    Leg {
        name: "back out while turning",
        goal: Pose2::new(1.5, 1.5, -std::f64::consts::FRAC_PI_3),
    },
    Leg {
        name: "drive to the dump point",
        goal: Pose2::new(4.0, -2.83, -std::f64::consts::FRAC_PI_3),
    },
    Leg {
        name: "around a pile to a face",
        goal: Pose2::new(8.0, -9.758, -std::f64::consts::FRAC_PI_3),
    },
];

/// The demo's site file: `sim/sites/demo.json` of the repository (found from this
/// executable, `target/{debug,release}/wlnav`, or the working directory), or
/// `<prefix>/share/wlnav/sites/demo.json` of an installed package.
pub fn locate_demo_site() -> Option<PathBuf> {
    locate_demo_file("sites/demo.json")
}

/// The demo's movers file, `sim/movers/demo.csv`, found as the site is.
pub fn locate_demo_movers() -> Option<PathBuf> {
    locate_demo_file("movers/demo.csv")
}

/// `sim/<name>` of the repository or `share/wlnav/<name>` of a package (see
/// [`locate_demo_site`]).
fn locate_demo_file(name: &str) -> Option<PathBuf> {
    let mut candidates = Vec::new();
    if let Ok(exe) = std::env::current_exe() {
        let dirs: Vec<&std::path::Path> = exe.ancestors().skip(1).take(3).collect();
        for d in &dirs {
            candidates.push(d.join("sim").join(name));
            candidates.push(d.join("share/wlnav").join(name));
        }
    }
    if let Ok(d) = std::env::current_dir() {
        candidates.push(d.join("sim").join(name));
    }
    candidates.push(PathBuf::from("/usr/share/wlnav").join(name));
    candidates.into_iter().find(|p| p.is_file())
}

/// `wlnav demo` options.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Where to write the SVG of the driven path and planned horizons
    #[arg(long, default_value = "wlnav-demo.svg")]
    pub out: PathBuf,
    /// Run the simulated machine this many times faster than real time (wlnavd --time-scale)
    #[arg(long, value_parser = args::parse_seconds)]
    pub time_scale: Option<f64>,
    /// The wlnavd binary [default: next to this executable, then PATH]
    #[arg(long)]
    pub wlnavd: Option<PathBuf>,
    /// MPC stage cost for wlnavd (`critic`, the trained critic in critic-weights/avant635/, or
    /// `quadratic`, a bring-up cost that needs no weights) [default: wlnavd's, the critic]
    #[arg(long, value_name = "COST")]
    pub cost: Option<String>,
    /// Extra argument for wlnavd (repeatable)
    #[arg(long = "daemon-arg", allow_hyphen_values = true)]
    pub daemon_args: Vec<OsString>,
    /// Per-leg limit in simulated seconds (the paper's success test uses 30 s)
    #[arg(long, default_value_t = 30.0, value_parser = args::parse_seconds)]
    pub leg_timeout: f64,
    /// How long the daemon may take to start (load weights, first solve) [s]
    #[arg(long, default_value_t = 60.0, value_parser = args::parse_seconds)]
    pub ready_timeout: f64,
    /// Also record all telemetry of the run to this MCAP file
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// The site wlnavd drives in [default: the demo's, sim/sites/demo.json]
    #[arg(long, value_name = "FILE")]
    pub site: Option<PathBuf>,
    /// Things that move for the simulated perception (wlnavd --movers; times from the
    /// first leg's start) [default: the demo's, sim/movers/demo.csv: a person crossing
    /// the first leg]
    #[arg(long, value_name = "FILE")]
    pub movers: Option<PathBuf>,
}

/// What happened on one leg.
#[derive(Debug, Clone)]
pub struct LegResult {
    /// The leg.
    pub leg: Leg,
    /// The daemon's reply (None if the request itself failed).
    pub reply: Option<GoalReply>,
    /// Final status.
    pub status: GoalStatus,
    /// Seconds (simulated) from the goal's first tick to the DESIGN §7 convergence.
    pub converged_s: Option<f64>,
    /// Seconds (simulated) until the daemon reported the goal reached.
    pub reached_s: Option<f64>,
    /// Driven path length [m].
    pub path_length: f64,
    /// Largest solve time [ms].
    pub max_solve_ms: f64,
    /// Ticks with the overrun flag.
    pub overruns: u64,
    /// Trace for the picture.
    pub trace: LegTrace,
}

fn send_goal(client: &Client, leg: &Leg) -> Result<(u64, GoalReply), ClientError> {
    // The daemon may answer "no server" for a moment after its first telemetry: retry.
    let mut tries = 0;
    loop {
        let id = client.next_request_id();
        let req = shm_ipc::GoalRequest::set_goal(id, leg.goal, &[])
            .expect("no circles are within the wire's limit");
        match client.request(&req, Duration::from_secs(2)) {
            Err(ClientError::NoDaemon { .. }) if tries < 20 => {
                tries += 1;
                std::thread::sleep(Duration::from_millis(100));
            }
            other => return other.map(|r| (id, r)),
        }
    }
}

fn path_length(path: &[(f64, f64)]) -> f64 {
    let length: f64 = path
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum();
    length + 0.0 // an empty sum is -0.0; print 0.0
}

/// `wlnav demo`.
pub fn run(cli: &Cli, a: &DemoArgs) -> anyhow::Result<u8> {
    let binary = locate_wlnavd(a.wlnavd.as_deref())?;
    let prefix = cli
        .prefix
        .clone()
        .unwrap_or_else(|| unique_prefix("wlnav-demo"));
    let log = std::env::temp_dir().join(format!("wlnav-demo-{}.log", std::process::id()));
    emit("wlnav demo: a loading cycle on the simulated machine, through shared memory");
    let config = IpcConfig::new(prefix.clone());
    let started = Instant::now();
    let mut cost = a.cost.clone();
    let site = a.site.clone().or_else(locate_demo_site);
    let movers = a.movers.clone().or_else(locate_demo_movers);
    let drawn_site = match &site {
        // The daemon validates the site; one this drawing cannot read (a Nav2 map) is
        // driven in, not drawn.
        Some(path) => match SiteDrawing::load(path) {
            Ok(d) => Some(d),
            Err(e) => {
                emit(&format!("  NOTE     the site is not drawn: {e}"));
                None
            }
        },
        None => {
            emit("  NOTE     the demo's site file (sim/sites/demo.json) was not found: no site");
            None
        }
    };
    let (mut daemon, first, client, sub) = loop {
        let mut extra: Vec<OsString> = Vec::new();
        if let Some(path) = &site {
            extra.push("--site".into());
            extra.push(path.into());
        }
        if let Some(path) = &movers {
            extra.push("--movers".into());
            extra.push(path.into());
        }
        if let Some(cost) = &cost {
            extra.push("--cost".into());
            extra.push(cost.into());
        }
        extra.extend(a.daemon_args.iter().cloned());
        let mut daemon =
            DaemonProcess::spawn_sim(&binary, &prefix, a.time_scale, &extra, Some(&log))?;
        emit(&format!(
            "  daemon   {} --sim --prefix {}{}{} (pid {}, log {})",
            binary.display(),
            prefix,
            a.time_scale
                .map(|s| format!(" --time-scale {s}"))
                .unwrap_or_default(),
            extra
                .iter()
                .map(|x| format!(" {}", x.to_string_lossy()))
                .collect::<String>(),
            daemon.pid().unwrap_or(0),
            log.display()
        ));
        let ready_timeout = Duration::from_secs_f64(a.ready_timeout);
        let connected = daemon.connect(&config, ready_timeout).and_then(|client| {
            let sub = client
                .subscribe_telemetry()
                .context("cannot subscribe to telemetry")?;
            Ok((client, sub))
        });
        let ready = connected.and_then(|(client, sub)| {
            let t = daemon.wait_ready(&sub, ready_timeout)?;
            Ok((client, sub, t))
        });
        match ready {
            Ok((client, sub, t)) => break (daemon, t, client, sub),
            Err(e) => {
                let tail = daemon.log_tail(50);
                let no_weights = tail.contains("weights file") && tail.contains("cannot read");
                if cost.is_none() && no_weights {
                    // A fresh checkout before the trained critic is committed: say so
                    // plainly and run with the bring-up cost rather than not at all.
                    emit(
                        "  NOTE     no trained weights in critic-weights/avant635/: the daemon cannot \
                         use the critic. Running with the quadratic bring-up cost instead \
                         (reaches goals ahead of the machine; manoeuvres need the critic).",
                    );
                    cost = Some("quadratic".into());
                    continue;
                }
                eprintln!("wlnav demo: {e:#}");
                return Ok(exit::ERROR);
            }
        }
    };
    let cost_text = match cost.as_deref() {
        None | Some("critic") => "critic (trained weights from critic-weights/avant635/)",
        Some("quadratic") => "quadratic bring-up cost (no trained weights)",
        Some(other) => other,
    };
    let start = Pose2::new(first.state.x_f, first.state.y_f, first.state.theta_f);
    emit(&format!(
        "  ready    after {:.1} s: mode {}, machine at ({:.2}, {:.2}) heading {:.1}°",
        started.elapsed().as_secs_f64(),
        super::view::mode_name(first.mode),
        start.x,
        start.y,
        start.heading.to_degrees()
    ));
    emit(&format!("  cost     {cost_text}"));
    if let Some(path) = &site {
        // What wlnavd loaded, as its telemetry says (not this program's parse).
        let drawn = drawn_site.as_ref().map_or(String::new(), |d| {
            format!("; {} features drawn", d.features)
        });
        emit(&format!(
            "  site     {} (wlnavd --site {}{drawn})",
            super::view::site_text(&first),
            path.display(),
        ));
    }

    // Optional recording on its own thread, with its own subscription.
    let rec_stop = Arc::new(AtomicBool::new(false));
    let recorder = a.record.clone().map(|path| {
        let stop = rec_stop.clone();
        let config = config.clone();
        std::thread::spawn(move || record(&config, &path, &RecordLimits::default(), &stop))
    });

    let scale = a.time_scale.unwrap_or(1.0);
    let opts = FollowOptions {
        timeout: Duration::from_secs_f64(a.leg_timeout / scale * 2.0 + 15.0),
        silence: Duration::from_secs(3),
        max_seconds: Some(a.leg_timeout),
        max_pending_samples: 50,
    };
    let mut results: Vec<LegResult> = Vec::new();
    let mut interrupted = false;
    for (i, leg) in LOADING_CYCLE.iter().enumerate() {
        let g = leg.goal;
        let head = format!(
            "\nleg {}/{} {}: goal ({:.2}, {:.2}) heading {:.0}°",
            i + 1,
            LOADING_CYCLE.len(),
            leg.name,
            g.x,
            g.y,
            g.heading.to_degrees()
        );
        let mut trace = LegTrace {
            name: leg.name.to_owned(),
            goal: g,
            ..LegTrace::default()
        };
        if i > 0 && !results.last().is_some_and(|r| r.status.is_succeeded()) {
            // After a failed leg the daemon may still be stopping or faulted: give it time to
            // come back (a fault clears once the machine stands still) before the next goal.
            if let Err(e) = daemon.wait_ready(&sub, Duration::from_secs(10)) {
                emit(&format!("  the daemon did not recover: {e:#}"));
            }
        }
        let (id, reply) = match send_goal(&client, leg) {
            Ok(r) => r,
            Err(e) => {
                emit(&format!("{head}: request failed: {e}"));
                results.push(LegResult {
                    leg: *leg,
                    reply: None,
                    status: GoalStatus::NoTelemetry(format!("request failed: {e}")),
                    converged_s: None,
                    reached_s: None,
                    path_length: 0.0,
                    max_solve_ms: 0.0,
                    overruns: 0,
                    trace,
                });
                continue;
            }
        };
        emit(&format!("{head}: {}", describe_reply(&reply)));
        let mut tracker = GoalTracker::new(id, g).with_time_scale(scale);
        if !reply.is_accepted() {
            tracker.time_out(format!("rejected: {}", reply.reason_text()));
        } else {
            let mut printer = ProgressPrinter::default();
            // The planned horizon is drawn once per second.
            let mut drawn_second = None;
            let end = follow(&sub, &mut tracker, &opts, |t, tr| {
                if tr.first_tick.is_none() {
                    return;
                }
                trace.path.push((t.state.x_f, t.state.y_f));
                let at = (t.state.x_f, t.state.y_f);
                if t.fault_flags & fault_flags::PROTECTIVE_STOP != 0 {
                    trace.held.push(at);
                } else if t.fault_flags & fault_flags::LIVE_SLOWING != 0 {
                    trace.slowed.push(at);
                }
                trace.end = Some([t.state.x_f, t.state.y_f, t.state.theta_f, t.state.beta]);
                if trace.route.is_empty() && t.route().len() > 1 {
                    trace.route = t.route().iter().map(|p| (p.x, p.y)).collect();
                    let via: String = t.route()[..t.route().len() - 1]
                        .iter()
                        .map(|p| format!(" ({:.2}, {:.2})", p.x, p.y))
                        .collect();
                    emit(&format!(
                        "  route    around the obstacles via{via}, then the goal"
                    ));
                }
                let second = tr.seconds_since_start(t.tick).unwrap_or(0.0).floor() as u64;
                if drawn_second != Some(second) && !tr.status().is_final() {
                    drawn_second = Some(second);
                    trace
                        .horizons
                        .push(t.trajectory().iter().map(|s| (s.x_f, s.y_f)).collect());
                }
                if let Some(line) = printer.line(t, tr) {
                    emit(&line);
                }
            })?;
            if end == FollowEnd::Interrupted {
                tracker.time_out("interrupted");
                interrupted = true;
            }
        }
        if !(trace.slowed.is_empty() && trace.held.is_empty()) {
            emit(&format!(
                "  live     slowed for a live obstacle {} tick(s), held after a protective stop {} tick(s) (marked in the picture)",
                trace.slowed.len(),
                trace.held.len()
            ));
        }
        emit(&format!("  {}", outcome_line(&tracker)));
        let secs = |tick: Option<u64>| tick.and_then(|t| tracker.seconds_since_start(t));
        trace.reached = tracker.status().is_succeeded();
        results.push(LegResult {
            leg: *leg,
            reply: Some(reply),
            status: tracker.status().clone(),
            converged_s: secs(tracker.converged_tick),
            reached_s: secs(tracker.reached_tick),
            path_length: path_length(&trace.path),
            max_solve_ms: tracker.max_solve_us / 1000.0,
            overruns: tracker.overruns,
            trace,
        });
        if interrupted {
            break;
        }
    }

    rec_stop.store(true, Ordering::SeqCst);
    let rec_result = recorder.map(|h| h.join());

    emit("\nsummary (times in simulated seconds from the goal's first tick; converged = DESIGN §7 test < 0.1)");
    emit(&format!(
        "  {:<3} {:<26} {:<24} {:<12} {:>9} {:>8} {:>7} {:>9} {:>8}",
        "leg",
        "what",
        "goal (x, y, heading)",
        "result",
        "converged",
        "reached",
        "path",
        "max solve",
        "overruns"
    ));
    for (i, r) in results.iter().enumerate() {
        let g = r.leg.goal;
        let fmt_s = |s: Option<f64>| s.map(|s| format!("{s:.1} s")).unwrap_or_else(|| "-".into());
        emit(&format!(
            "  {:<3} {:<26} {:<24} {:<12} {:>9} {:>8} {:>5.1} m {:>6.1} ms {:>8}",
            i + 1,
            r.leg.name,
            format!("({:.2}, {:.2}, {:.0}°)", g.x, g.y, g.heading.to_degrees()),
            if r.status.is_succeeded() {
                "reached"
            } else {
                "NOT reached"
            },
            fmt_s(r.converged_s),
            fmt_s(r.reached_s),
            r.path_length,
            r.max_solve_ms,
            r.overruns
        ));
    }
    let reached = results.iter().filter(|r| r.status.is_succeeded()).count();
    let total: f64 = results.iter().filter_map(|r| r.reached_s).sum();
    emit(&format!(
        "  {reached}/{} legs reached{}",
        LOADING_CYCLE.len(),
        if reached == LOADING_CYCLE.len() {
            format!(", cycle time {total:.1} s")
        } else {
            String::new()
        }
    ));

    let traces: Vec<LegTrace> = results.iter().map(|r| r.trace.clone()).collect();
    match write_svg(
        &a.out,
        &format!(
            "wlnav demo: loading cycle, {reached}/{} legs reached",
            LOADING_CYCLE.len()
        ),
        start,
        &traces,
        drawn_site.as_ref(),
    ) {
        Ok(()) => {
            emit(&format!(
                "  picture  {} (the site, driven path, planned horizons every 1 s, the machine's \
                 outline where each leg ended, route)",
                a.out.display()
            ));
        }
        Err(e) => eprintln!("wlnav demo: cannot write the SVG: {e:#}"),
    }
    if let (Some(Ok(Ok(s))), Some(path)) = (&rec_result, &a.record) {
        emit(&format!(
            "  recording {} ({} ticks, {} missed)",
            path.display(),
            s.messages,
            s.missing_ticks
        ));
    } else if let Some(Ok(Err(e))) = &rec_result {
        eprintln!("wlnav demo: recording failed: {e:#}");
    }

    let code = match daemon.terminate(Duration::from_secs(10)) {
        Ok((status, killed)) => {
            emit(&format!(
                "  daemon   stopped with SIGTERM{}: {status}",
                if killed {
                    ", then SIGKILL (it did not exit within 10 s)"
                } else {
                    ""
                }
            ));
            if killed || !status.success() {
                eprintln!(
                    "wlnav demo: the daemon did not stop cleanly; log tail:\n{}",
                    daemon.log_tail(15)
                );
            }
            if interrupted || signal::requested() {
                exit::INTERRUPTED
            } else if reached == LOADING_CYCLE.len() {
                exit::OK
            } else {
                exit::ABORTED
            }
        }
        Err(e) => {
            eprintln!("wlnav demo: cannot stop the daemon: {e:#}");
            exit::ERROR
        }
    };
    Ok(code)
}
