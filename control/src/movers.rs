//! Things that move, and the perception that sees them, simulated (DESIGN
//! §18): what `wlnav-sim eval --movers` and `wlnavd --sim` (`[sim.perception]`)
//! both run. Pure: the callers read the files.
//!
//! A movers file is CSV with header `id,radius,t0,x0,y0,vx,vy,t1`: a circle
//! of `radius` [m] (physical) appears at `t0` [s after the goal's start; in
//! `wlnavd --sim`, after the daemon's start] at (x0, y0), moves at (vx, vy)
//! [m/s] and vanishes at `t1`. Every scenario of a run gets them.
//!
//! The simulated perception measures them every 1 / `rate` seconds (their
//! true positions then, their velocities, stamped with the measurement
//! time), delivers each set `latency` later, and loses a set with
//! probability `dropout` (seeded): what the pilot gets through
//! [`crate::pilot::Pilot::set_live`], as the daemon gets it from the
//! live-obstacle service.

use crate::live::{LiveClass, LiveObstacle, LiveSet, LiveShape, MAX_LIVE_OBSTACLES};

/// How long perception has run when a goal starts [s]: the pilot starts
/// with fresh sets, as beside a daemon whose perception runs all along.
pub const PRE_ROLL: f64 = 1.0;

/// The header of a movers file.
pub const HEADER: &str = "id,radius,t0,x0,y0,vx,vy,t1";

/// One mover (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mover {
    pub id: u32,
    pub radius: f64,
    pub t0: f64,
    pub start: [f64; 2],
    pub velocity: [f64; 2],
    pub t1: f64,
}

impl Mover {
    /// Its centre at `t`, if it is there then. A mover of `t0` = 0 was there
    /// before the goal started too (on its line, as perception saw it
    /// during its pre-roll): a person standing in the way from the start is
    /// known from the first tick.
    pub fn at(&self, t: f64) -> Option<[f64; 2]> {
        (t < self.t1 && (t >= self.t0 || self.t0 == 0.0)).then(|| {
            let s = t - self.t0;
            [
                self.start[0] + self.velocity[0] * s,
                self.start[1] + self.velocity[1] * s,
            ]
        })
    }
}

/// A malformed movers file: where, and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{source_name}:{line}: {message}")]
pub struct MoversError {
    pub source_name: String,
    /// 1-based line (0: the file as a whole).
    pub line: usize,
    pub message: String,
}

/// Parses a movers file; `source` names it in errors. Lines starting with
/// `#` are comments.
pub fn parse(text: &str, source: &str) -> Result<Vec<Mover>, MoversError> {
    let fail = |line: usize, message: String| MoversError {
        source_name: source.to_string(),
        line,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    match lines.next() {
        Some((_, h)) if h.trim().trim_start_matches('\u{feff}') == HEADER => {}
        Some((i, h)) => {
            return Err(fail(
                i + 1,
                format!("bad header `{}`: expected `{HEADER}`", h.trim()),
            ))
        }
        None => return Err(fail(0, format!("empty: expected the header `{HEADER}`"))),
    }
    let mut movers: Vec<Mover> = Vec::new();
    for (i, line) in lines {
        let n = i + 1;
        let fields: Vec<&str> = line.trim_end_matches('\r').split(',').collect();
        if fields.len() != 8 {
            return Err(fail(
                n,
                format!("expected 8 fields, found {}", fields.len()),
            ));
        }
        let id: u32 = fields[0].trim().parse().map_err(|_| {
            fail(
                n,
                format!("`id` `{}` is not a whole number", fields[0].trim()),
            )
        })?;
        let mut v = [0.0; 7];
        for (k, (f, name)) in fields[1..]
            .iter()
            .zip(["radius", "t0", "x0", "y0", "vx", "vy", "t1"])
            .enumerate()
        {
            v[k] = f
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    fail(n, format!("`{name}` `{}` is not a finite number", f.trim()))
                })?;
        }
        let [radius, t0, x0, y0, vx, vy, t1] = v;
        if radius <= 0.0 || radius > MAX_RADIUS {
            return Err(fail(
                n,
                format!("`radius` must be in (0, {MAX_RADIUS}] m (got {radius})"),
            ));
        }
        if t0 < 0.0 || t1 <= t0 {
            return Err(fail(n, format!("need 0 <= t0 < t1 (got t0 {t0}, t1 {t1})")));
        }
        if vx.hypot(vy) > MAX_SPEED {
            return Err(fail(n, format!("speed above {MAX_SPEED} m/s")));
        }
        if movers.iter().any(|m| m.id == id) {
            return Err(fail(n, format!("id {id} is given twice")));
        }
        movers.push(Mover {
            id,
            radius,
            t0,
            start: [x0, y0],
            velocity: [vx, vy],
            t1,
        });
    }
    if movers.len() > MAX_LIVE_OBSTACLES {
        return Err(fail(
            0,
            format!("{} movers, at most {MAX_LIVE_OBSTACLES}", movers.len()),
        ));
    }
    Ok(movers)
}

/// Largest mover radius [m] and speed [m/s] a file may give (what the wire
/// takes).
pub const MAX_RADIUS: f64 = 30.0;
pub const MAX_SPEED: f64 = 30.0;

/// The simulated perception's settings (`--perception-*`, `[sim.perception]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerceptionSettings {
    /// From measurement to delivery [s].
    pub latency: f64,
    /// Sets per second.
    pub rate: f64,
    /// Probability that a set is lost.
    pub dropout: f64,
    pub seed: u64,
}

impl Default for PerceptionSettings {
    /// The reference: 0.1 s, 10 Hz, 5 % lost.
    fn default() -> Self {
        Self {
            latency: 0.1,
            rate: 10.0,
            dropout: 0.05,
            seed: 0,
        }
    }
}

impl PerceptionSettings {
    /// Latency in [0, 2] s, rate in [1, 100] Hz, dropout in [0, 1); the
    /// error names the setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.latency.is_finite() && (0.0..=2.0).contains(&self.latency)) {
            return Err(format!(
                "perception latency must be in [0, 2] s (got {})",
                self.latency
            ));
        }
        if !(self.rate.is_finite() && self.rate >= 1.0 && self.rate <= 100.0) {
            return Err(format!(
                "perception rate must be in [1, 100] Hz (got {})",
                self.rate
            ));
        }
        if !(self.dropout.is_finite() && (0.0..1.0).contains(&self.dropout)) {
            return Err(format!(
                "perception dropout must be in [0, 1) (got {})",
                self.dropout
            ));
        }
        Ok(())
    }
}

/// The perception of one scenario: sets measured every 1 / rate, delivered
/// `latency` later unless lost.
#[derive(Debug, Clone)]
pub struct Perception<'a> {
    movers: &'a [Mover],
    settings: PerceptionSettings,
    /// The seed mixed with the scenario's name.
    seed: u64,
    /// The next measurement's number (0 at the goal's start).
    next: i64,
    set: LiveSet,
    buf: Vec<LiveObstacle>,
}

impl<'a> Perception<'a> {
    /// Its seed mixed with `scenario` (the name of a run's scenario; the
    /// daemon's simulated machine gives its own).
    pub fn new(movers: &'a [Mover], settings: PerceptionSettings, scenario: &str) -> Self {
        // FNV-1a of the name, as the plant's noise seeds are mixed.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in scenario.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        Self {
            movers,
            settings,
            seed: settings.seed ^ h,
            // Perception runs before the goal (as it does beside the daemon):
            // its first set is measured PRE_ROLL before the start.
            next: -(PRE_ROLL * settings.rate).ceil() as i64,
            set: LiveSet::new(),
            buf: Vec::with_capacity(MAX_LIVE_OBSTACLES),
        }
    }

    /// Whether measurement `k` is lost (splitmix64 of seed and k).
    fn lost(&self, k: i64) -> bool {
        let mut z = self.seed.wrapping_add(
            (k as u64)
                .wrapping_add(1)
                .wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 / (1u64 << 53) as f64) < self.settings.dropout
    }

    /// When the next measurement is delivered, if it is not lost.
    pub fn next_at(&self) -> f64 {
        self.next as f64 / self.settings.rate + self.settings.latency
    }

    /// The next set delivered at or before `until`: (delivery time, set).
    pub fn next_delivery(&mut self, until: f64) -> Option<(f64, &LiveSet)> {
        loop {
            let measured = self.next as f64 / self.settings.rate;
            let delivered = measured + self.settings.latency;
            if delivered > until + 1e-9 {
                return None;
            }
            let k = self.next;
            self.next += 1;
            if self.lost(k) {
                continue;
            }
            self.buf.clear();
            for m in self.movers {
                if let Some(c) = m.at(measured) {
                    let shape = LiveShape::Circle {
                        center: c,
                        radius: m.radius,
                    };
                    self.buf.push(LiveObstacle {
                        id: m.id,
                        class: LiveClass::Unknown,
                        shape,
                        velocity: m.velocity,
                        stamp: measured,
                    });
                }
            }
            // Parsed movers are at most the capacity, all finite.
            self.set
                .set(measured, &self.buf)
                .expect("a movers file holds at most the capacity");
            return Some((delivered, &self.set));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "id,radius,t0,x0,y0,vx,vy,t1\n1,0.4,1,5,-3,0,1.4,10\n2,1.5,0,20,0,-3,0,4\n";

    #[test]
    fn a_movers_file_is_read_and_bad_rows_are_named() {
        let m = parse(FILE, "m.csv").unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(m[0].at(2.0), Some([5.0, -1.6]));
        assert_eq!(m[0].at(0.5), None);
        assert_eq!(m[1].at(4.0), None);
        // A mover of t0 = 0 was there before the start too, on its line.
        assert_eq!(m[1].at(-1.0), Some([23.0, 0.0]));
        assert_eq!(m[0].at(-1.0), None);
        for (bad, says) in [
            ("id,r\n", "bad header"),
            ("", "empty"),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,0,0,0,0,0,0,1\n",
                "m.csv:2: `radius` must be in (0, 30] m",
            ),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,1,0,0,0,40,0,1\n",
                "speed above 30 m/s",
            ),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,1,2,0,0,0,0,1\n",
                "need 0 <= t0 < t1",
            ),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,1,0,0,NaN,0,0,1\n",
                "`y0` `NaN` is not a finite number",
            ),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,1,0,0,0,0,0,1\n1,1,0,0,0,0,0,1\n",
                "id 1 is given twice",
            ),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,1,0,0\n",
                "expected 8 fields",
            ),
        ] {
            let e = parse(bad, "m.csv").unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
    }

    #[test]
    fn perception_delivers_late_stamped_sets_and_loses_some() {
        let movers = parse(FILE, "m.csv").unwrap();
        let s = PerceptionSettings {
            latency: 0.1,
            rate: 10.0,
            dropout: 0.3,
            seed: 7,
        };
        let mut p = Perception::new(&movers, s, "sc");
        let mut delivered = Vec::new();
        while let Some((t, set)) = p.next_delivery(20.0) {
            let stamp = set.stamp().unwrap();
            assert!((t - stamp - 0.1).abs() < 1e-9);
            // What it holds is where the movers were at the stamp.
            for o in set.obstacles() {
                let m = movers.iter().find(|m| m.id == o.id).unwrap();
                let c = m.at(stamp).unwrap();
                assert!(o.clearance_at(c, 0.0, stamp) + m.radius < 1e-9);
            }
            delivered.push(stamp);
        }
        // 210 measurements in [-1, 19.9], about 30 % lost.
        assert!(delivered[0] >= -PRE_ROLL - 1e-9);
        let lost = 210 - delivered.len() as i64;
        assert!((40..=85).contains(&lost), "{lost}");
        // Seeded: the same scenario loses the same sets, another others.
        let again: Vec<f64> = {
            let mut p = Perception::new(&movers, s, "sc");
            std::iter::from_fn(|| p.next_delivery(20.0).map(|(_, s)| s.stamp().unwrap())).collect()
        };
        assert_eq!(again, delivered);
        let other: Vec<f64> = {
            let mut p = Perception::new(&movers, s, "other");
            std::iter::from_fn(|| p.next_delivery(20.0).map(|(_, s)| s.stamp().unwrap())).collect()
        };
        assert_ne!(other, delivered);
    }
}
