//! The evaluation's view of things that move (DESIGN §18): the movers file
//! read from disk ([`load`]) and `min_clearance_moving` ([`MoverMeter`]): the
//! smallest clearance of the machine's true outline to a mover's true disc
//! while the machine's |v| > [`MOVING_SPEED`] (a mover walking into a machine
//! at rest is not the machine's doing). The movers and the simulated
//! perception are [`control::movers`].

use std::path::Path;

use anyhow::{Context, Result};
use control::model::{ix, State};
pub use control::movers::{parse, Mover, Perception, PerceptionSettings, HEADER, PRE_ROLL};
use control::world::World;

/// The machine moves above this speed [m/s] (the success test's rest).
pub const MOVING_SPEED: f64 = 0.05;

/// Reads a movers file.
pub fn load(path: &Path) -> Result<Vec<Mover>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(parse(&text, &path.display().to_string())?)
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
