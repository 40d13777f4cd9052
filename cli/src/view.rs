//! Human-readable renderings of [`Telemetry`]: the one-line-per-tick view and the table view
//! of `wlnav watch`, mode and fault names (shared with `record` and `demo`).

use shm_ipc::{AbortReason, GoalOutcome, Mode, Telemetry};

/// Names of the set fault bits (unknown bits as `bit-N`).
pub use shm_ipc::fault_flags::names as fault_names;

/// Fault names joined with `,`, or `-` when there are none.
pub fn fault_text(flags: u32) -> String {
    if flags == 0 {
        "-".to_owned()
    } else {
        fault_names(flags).join(",")
    }
}

/// Lower-case mode name (`idle`, `tracking`, …), or `mode-N` for an unknown code.
pub fn mode_name(code: u32) -> String {
    match Mode::try_from(code) {
        Ok(Mode::Startup) => "startup".into(),
        Ok(Mode::Idle) => "idle".into(),
        Ok(Mode::Tracking) => "tracking".into(),
        Ok(Mode::Reached) => "reached".into(),
        Ok(Mode::Stopping) => "stopping".into(),
        Ok(Mode::Fault) => "fault".into(),
        Err(c) => format!("mode-{c}"),
    }
}

/// The outcome reported on this sample, as `aborted (no-progress) of request 42: text`, or
/// `None` when no goal ended this tick.
pub fn outcome_text(t: &Telemetry) -> Option<String> {
    if t.outcome == GoalOutcome::None.code() {
        return None;
    }
    let name = match (t.outcome(), t.abort_reason()) {
        (Ok(GoalOutcome::Aborted), Ok(reason)) if reason != AbortReason::None => {
            format!("aborted ({})", reason.name())
        }
        (Ok(GoalOutcome::Aborted), Err(code)) => format!("aborted (reason-{code})"),
        (Ok(outcome), _) => outcome.name().to_owned(),
        (Err(code), _) => format!("outcome-{code}"),
    };
    Some(format!(
        "{name} of request {}: {}",
        t.outcome_request_id,
        t.outcome_text()
    ))
}

/// The distance of DESIGN §7's success test, ‖(x_f − x_g, y_f − y_g, e_θ)‖ (metres and
/// radians mixed, as in the paper).
pub fn goal_distance(t: &Telemetry) -> f64 {
    t.pose_error_xy.hypot(t.pose_error_heading)
}

fn deg(rad: f64) -> f64 {
    rad.to_degrees()
}

/// "site yard version 3 hash 0123456789abcdef", or "site none".
pub fn site_text(t: &Telemetry) -> String {
    if t.site_id_len == 0 {
        return "site none".into();
    }
    format!(
        "site {} version {} hash {:016x}",
        t.site_id(),
        t.site_version,
        t.site_hash
    )
}

/// One line per tick: everything an operator looks at, in a fixed order, and the goal
/// outcome on the tick that reports one.
///
/// `tick 412 tracking  x  3.21 y -0.40 θ  12.5° β   4.1° v  0.82 | goal  6.00  0.00    0.0° err 2.81 m  -12.5° | cmd β̇ -3.0°/s v 0.85 | solve 3.9 ms qp 11 cost 2.35 | faults -`
pub fn line(t: &Telemetry) -> String {
    match outcome_text(t) {
        Some(outcome) => format!("{} | outcome {outcome}", state_line(t)),
        None => state_line(t),
    }
}

fn state_line(t: &Telemetry) -> String {
    let s = &t.state;
    let goal = match t.active_goal() {
        Some(g) => format!(
            "goal {:5.2} {:5.2} {:6.1}° err {:5.2} m {:6.1}°",
            g.x,
            g.y,
            deg(g.heading),
            t.pose_error_xy,
            deg(t.pose_error_heading)
        ),
        None => "goal none".to_owned(),
    };
    format!(
        "tick {} {:<8} x {:6.2} y {:6.2} θ {:6.1}° β {:5.1}° v {:5.2} | {} | cmd β̇ {:5.1}°/s v {:5.2} | solve {:.1} ms qp {} cost {:.3} | faults {}",
        t.tick,
        mode_name(t.mode),
        s.x_f,
        s.y_f,
        deg(s.theta_f),
        deg(s.beta),
        s.v_f,
        goal,
        deg(t.command.beta_dot),
        t.command.v,
        t.solve_time_us / 1000.0,
        t.qp_iterations,
        t.cost,
        fault_text(t.fault_flags),
    )
}

/// Column header of the table view (repeat it every screenful).
pub fn table_header() -> String {
    format!(
        "{:>8} {:<8} {:>7} {:>7} {:>7} {:>6} {:>6} {:>7} {:>7} {:>7} {:>6} {:>6} {:>7} {:>4} {:>8}  {}\n{}",
        "tick",
        "mode",
        "x[m]",
        "y[m]",
        "θ[°]",
        "β[°]",
        "v[m/s]",
        "goal_x",
        "goal_y",
        "goal_θ",
        "e_xy",
        "e_θ[°]",
        "solve",
        "qp",
        "cost",
        "faults",
        "-".repeat(132)
    )
}

/// One row of the table view, aligned under [`table_header`].
pub fn table_row(t: &Telemetry) -> String {
    let s = &t.state;
    let (gx, gy, gh, exy, eh) = match t.active_goal() {
        Some(g) => (
            format!("{:7.2}", g.x),
            format!("{:7.2}", g.y),
            format!("{:7.1}", deg(g.heading)),
            format!("{:6.2}", t.pose_error_xy),
            format!("{:6.1}", deg(t.pose_error_heading)),
        ),
        None => (
            format!("{:>7}", "-"),
            format!("{:>7}", "-"),
            format!("{:>7}", "-"),
            format!("{:>6}", "-"),
            format!("{:>6}", "-"),
        ),
    };
    format!(
        "{:>8} {:<8} {:7.2} {:7.2} {:7.1} {:6.1} {:6.2} {} {} {} {} {} {:>4.1}ms {:>4} {:8.3}  {}",
        t.tick,
        mode_name(t.mode),
        s.x_f,
        s.y_f,
        deg(s.theta_f),
        deg(s.beta),
        s.v_f,
        gx,
        gy,
        gh,
        exy,
        eh,
        t.solve_time_us / 1000.0,
        t.qp_iterations,
        t.cost,
        fault_text(t.fault_flags)
    )
}
