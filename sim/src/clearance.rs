//! The evaluation's `min_clearance` (DESIGN §7, §10): the smallest distance of
//! either axle point to any obstacle's edge over the whole run, checked on the
//! plant's integration sub-steps (closed loop) or on a fine sub-division of
//! each control interval (open-loop plans), never only at ticks.

use control::model::{rk4_step, Control, MachineParams, State};
use control::world::World;

/// Sub-steps per control interval when an open-loop plan is re-integrated.
pub const PLAN_SUBSTEPS: usize = 20;

/// Running minimum of the outline's clearance to the world (the site's
/// features and bounds, the scenario's circles; DESIGN §17).
#[derive(Debug, Clone)]
pub struct ClearanceMeter {
    world: World,
    min: f64,
}

impl ClearanceMeter {
    /// Measures in `world` (its params: the plant's true geometry).
    pub fn new(world: World) -> Self {
        Self {
            world,
            min: f64::INFINITY,
        }
    }

    fn params(&self) -> MachineParams {
        *self.world.params()
    }

    /// Takes one state into account.
    pub fn observe(&mut self, x: &State) {
        if !self.world.is_empty() {
            self.min = self.min.min(self.world.clearance(x));
        }
    }

    /// Takes an open-loop interval into account: from `x` under the constant
    /// control `u` for `dt`, in [`PLAN_SUBSTEPS`] RK4 sub-steps of the model.
    pub fn observe_interval(&mut self, x: &State, u: &Control, dt: f64) {
        if self.world.is_empty() {
            return;
        }
        let p = self.params();
        let h = dt / PLAN_SUBSTEPS as f64;
        let mut x = *x;
        self.observe(&x);
        for _ in 0..PLAN_SUBSTEPS {
            x = rk4_step(&p, &x, u, h);
            self.observe(&x);
        }
    }

    /// The minimum seen; `None` without obstacles.
    pub fn finish(&self) -> Option<f64> {
        (!self.world.is_empty()).then_some(self.min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::obstacle::Obstacle;

    fn meter(p: MachineParams, o: &[Obstacle]) -> ClearanceMeter {
        let mut w = World::with_axle_circles(p, 8);
        w.set_circles(o).unwrap();
        ClearanceMeter::new(w)
    }

    /// A straight pass by a circle: sampled every 0.2 s at 1 m/s the closest
    /// tick misses the closest approach by up to 0.1 m; the sub-divided
    /// interval finds it.
    #[test]
    fn intervals_see_what_ticks_miss() {
        let p = MachineParams::default();
        // The front axle passes x = 1.1 between ticks at x = 1.0 and 1.2.
        let o = [Obstacle::new(1.1, 0.5, 0.3)];
        let x0 = State::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let x1 = rk4_step(&p, &x0, &Control::zeros(), 0.2);
        let mut ticks = meter(p, &o);
        ticks.observe(&x0);
        ticks.observe(&x1);
        let mut fine = meter(p, &o);
        fine.observe_interval(&x0, &Control::zeros(), 0.2);
        let exact = 0.5 - 0.3;
        assert!((fine.finish().unwrap() - exact).abs() < 1e-9);
        assert!(ticks.finish().unwrap() > exact + 0.005);
        assert_eq!(meter(p, &[]).finish(), None);
    }
}
