//! Things that move, and the perception that sees them (DESIGN §18).
//!
//! A movers file (`--movers FILE`) is CSV with header
//! `id,radius,t0,x0,y0,vx,vy,t1`: a circle of `radius` [m] (physical)
//! appears at `t0` [s after the goal's start] at (x0, y0), moves at
//! (vx, vy) [m/s] and vanishes at `t1`. Every scenario of a run gets them.
//!
//! The simulated perception measures them every 1 / `rate` seconds (their
//! true positions then, their velocities, stamped with the measurement
//! time), delivers each set `latency` later, and loses a set with
//! probability `dropout` (seeded, per scenario): what the pilot gets through
//! [`control::pilot::Pilot::set_live`], as the daemon gets it from the
//! live-obstacle service.
//!
//! [`MoverMeter`] measures `min_clearance_moving`: the smallest clearance of
//! the machine's true outline to a mover's true disc while the machine's
//! |v| > [`MOVING_SPEED`] (a mover walking into a machine at rest is not the
//! machine's doing).

use std::path::Path;

use anyhow::{bail, Context, Result};
use control::live::{LiveClass, LiveObstacle, LiveSet, LiveShape, MAX_LIVE_OBSTACLES};
use control::model::{ix, State};
use control::world::World;

/// The machine moves above this speed [m/s] (the success test's rest).
pub const MOVING_SPEED: f64 = 0.05;

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
    /// Its centre at `t`, if it is there then.
    pub fn at(&self, t: f64) -> Option<[f64; 2]> {
        (t >= self.t0 && t < self.t1).then(|| {
            let s = t - self.t0;
            [
                self.start[0] + self.velocity[0] * s,
                self.start[1] + self.velocity[1] * s,
            ]
        })
    }
}

/// Parses a movers file; `source` names it in errors.
pub fn parse(text: &str, source: &str) -> Result<Vec<Mover>> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    match lines.next() {
        Some((_, h)) if h.trim().trim_start_matches('\u{feff}') == HEADER => {}
        Some((i, h)) => bail!(
            "{source}:{}: bad header `{}`: expected `{HEADER}`",
            i + 1,
            h.trim()
        ),
        None => bail!("{source}: empty: expected the header `{HEADER}`"),
    }
    let mut movers: Vec<Mover> = Vec::new();
    for (i, line) in lines {
        let at = || format!("{source}:{}", i + 1);
        let fields: Vec<&str> = line.trim_end_matches('\r').split(',').collect();
        if fields.len() != 8 {
            bail!("{}: expected 8 fields, found {}", at(), fields.len());
        }
        let id: u32 = fields[0]
            .trim()
            .parse()
            .with_context(|| format!("{}: `id` `{}` is not a whole number", at(), fields[0]))?;
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
                .with_context(|| format!("{}: `{name}` `{}` is not a finite number", at(), f))?;
        }
        let [radius, t0, x0, y0, vx, vy, t1] = v;
        if radius <= 0.0 {
            bail!("{}: `radius` must be positive (got {radius})", at());
        }
        if t0 < 0.0 || t1 <= t0 {
            bail!("{}: need 0 <= t0 < t1 (got t0 {t0}, t1 {t1})", at());
        }
        if movers.iter().any(|m| m.id == id) {
            bail!("{}: id {id} is given twice", at());
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
        bail!(
            "{source}: {} movers, at most {MAX_LIVE_OBSTACLES}",
            movers.len()
        );
    }
    Ok(movers)
}

/// Reads a movers file.
pub fn load(path: &Path) -> Result<Vec<Mover>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse(&text, &path.display().to_string())
}

/// The simulated perception's settings (`--perception-*`).
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
    pub fn validate(&self) -> Result<()> {
        if !(self.latency.is_finite() && (0.0..=2.0).contains(&self.latency)) {
            bail!(
                "--perception-latency must be in [0, 2] s (got {})",
                self.latency
            );
        }
        if !(self.rate.is_finite() && self.rate >= 1.0 && self.rate <= 100.0) {
            bail!(
                "--perception-rate must be in [1, 100] Hz (got {})",
                self.rate
            );
        }
        if !(self.dropout.is_finite() && (0.0..1.0).contains(&self.dropout)) {
            bail!(
                "--perception-dropout must be in [0, 1) (got {})",
                self.dropout
            );
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

/// `min_clearance_moving` (module docs).
#[derive(Debug, Clone)]
pub struct MoverMeter<'a> {
    movers: &'a [Mover],
    /// The machine's true outline (an empty world: only `place`).
    world: World,
    min: f64,
}

impl<'a> MoverMeter<'a> {
    pub fn new(movers: &'a [Mover], world: World) -> Self {
        Self {
            movers,
            world,
            min: f64::INFINITY,
        }
    }

    /// The true state `x` at time `t`.
    pub fn observe(&mut self, t: f64, x: &State) {
        if x[ix::V].abs() <= MOVING_SPEED {
            return;
        }
        let placed = self.world.place(x);
        for m in self.movers {
            if let Some(c) = m.at(t) {
                for p in &placed[..self.world.outline().len()] {
                    let d = (p.center[0] - c[0]).hypot(p.center[1] - c[1]) - p.radius - m.radius;
                    self.min = self.min.min(d);
                }
            }
        }
    }

    /// The least clearance while moving; `None` if no mover was ever there
    /// while the machine moved.
    pub fn finish(&self) -> Option<f64> {
        self.min.is_finite().then_some(self.min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::model::MachineParams;

    const FILE: &str = "id,radius,t0,x0,y0,vx,vy,t1\n1,0.4,1,5,-3,0,1.4,10\n2,1.5,0,20,0,-3,0,4\n";

    #[test]
    fn a_movers_file_is_read_and_bad_rows_are_named() {
        let m = parse(FILE, "m.csv").unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(m[0].at(2.0), Some([5.0, -1.6]));
        assert_eq!(m[0].at(0.5), None);
        assert_eq!(m[1].at(4.0), None);
        for (bad, says) in [
            ("id,r\n", "bad header"),
            ("", "empty"),
            (
                "id,radius,t0,x0,y0,vx,vy,t1\n1,0,0,0,0,0,0,1\n",
                "m.csv:2: `radius` must be positive",
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
            let e = format!("{:#}", parse(bad, "m.csv").unwrap_err());
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

    #[test]
    fn the_meter_counts_only_while_the_machine_moves() {
        let movers = parse("id,radius,t0,x0,y0,vx,vy,t1\n1,0.5,0,3,0,0,0,10\n", "m").unwrap();
        let world = World::with_axle_circles(MachineParams::default(), 0);
        let mut m = MoverMeter::new(&movers, world);
        // At rest touching it: not counted.
        m.observe(1.0, &State::new(2.0, 0.0, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(m.finish(), None);
        // Moving 1.5 m from its centre: 1.5 − 0.65 − 0.5.
        m.observe(1.0, &State::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.5));
        assert!((m.finish().unwrap() - 0.35).abs() < 1e-12);
        // Gone at t1.
        m.observe(10.0, &State::new(3.0, 0.0, 0.0, 0.0, 0.0, 0.5));
        assert!((m.finish().unwrap() - 0.35).abs() < 1e-12);
    }
}
