//! Parsing of command-line values: numbers that must be finite, obstacles `x,y,r`, prefixes.
//! Errors name the argument and say what was wrong, so `wlnav goal 1 nan 0` answers
//! "Y must be a finite number, got `nan`" instead of sending garbage to the daemon.

use shm_ipc::Obstacle;

/// Parses a finite `f64`; `what` names the argument in the error.
pub fn finite_f64(what: &str, text: &str) -> Result<f64, String> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{what} must be a number, got `{text}`"))?;
    if !v.is_finite() {
        return Err(format!("{what} must be a finite number, got `{text}`"));
    }
    Ok(v)
}

/// Parses an obstacle given as `x,y,r` (metres; the radius already inflated by the
/// machine's, as the daemon expects). The radius must be positive.
pub fn obstacle(text: &str) -> Result<Obstacle, String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected x,y,r (three numbers separated by commas, metres), got `{text}` \
             ({} part{})",
            parts.len(),
            if parts.len() == 1 { "" } else { "s" }
        ));
    }
    let x = finite_f64("obstacle x", parts[0])?;
    let y = finite_f64("obstacle y", parts[1])?;
    let r = finite_f64("obstacle radius r", parts[2])?;
    if r <= 0.0 {
        return Err(format!(
            "obstacle radius r must be positive, got {r} in `{text}`"
        ));
    }
    Ok(Obstacle::new(x, y, r))
}

/// clap value parser for `--obstacle`.
pub fn parse_obstacle(text: &str) -> Result<Obstacle, String> {
    obstacle(text)
}

/// clap value parser for the goal's X.
pub fn parse_x(text: &str) -> Result<f64, String> {
    finite_f64("X", text)
}

/// clap value parser for the goal's Y.
pub fn parse_y(text: &str) -> Result<f64, String> {
    finite_f64("Y", text)
}

/// clap value parser for the goal's HEADING.
pub fn parse_heading(text: &str) -> Result<f64, String> {
    finite_f64("HEADING", text)
}

/// clap value parser for a positive duration in seconds.
pub fn parse_seconds(text: &str) -> Result<f64, String> {
    let v = finite_f64("the duration", text)?;
    if v <= 0.0 {
        return Err(format!("the duration must be positive, got {v}"));
    }
    Ok(v)
}

/// clap value parser for a rate in Hz: positive, at most 1000 (a perception publishes at
/// 5–20 Hz; beyond 1 kHz a typo).
pub fn parse_rate(text: &str) -> Result<f64, String> {
    let v = finite_f64("the rate", text)?;
    if !(v > 0.0 && v <= 1000.0) {
        return Err(format!(
            "the rate must be above 0 and at most 1000 Hz, got {v}"
        ));
    }
    Ok(v)
}

/// clap value parser for `--prefix`.
pub fn parse_prefix(text: &str) -> Result<String, String> {
    shm_ipc::validate_prefix(text).map_err(|e| e.to_string())?;
    Ok(text.to_owned())
}
