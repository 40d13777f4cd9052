//! The MPC's rows for live obstacles (DESIGN §18, issue 41): perception's
//! newest set, each obstacle predicted along its velocity from its own stamp
//! to the time of the row's stage, kept outside its stop field there
//! (C_stop plus σ_u per second of prediction, as the envelope and the
//! slow-down field see it) with the envelope's margins and
//! [`PLAN_MARGIN`]. A plan the MPC finds is then one the slow-down field
//! does not slow and the envelope lets through: the MPC steers round what
//! it can and the envelope stops for what it cannot. The rows are soft,
//! like every obstacle row.
//!
//! Measured (docs/decisions.md, "The MPC's live rows"): the reach grown along
//! the whole horizon against grown only as far as the envelope's stop from
//! top speed (1.2 s) or not at all: the whole horizon had the fewest
//! protective stops and the shortest times. It can hold the machine in
//! front of a parked truck whose way round the critic does not take: that
//! is what replanning round what stays is for ([`crate::pilot`]).
//!
//! Allocation-free after [`LiveRows::new`].

use crate::live::{LiveSet, LiveSettings, MAX_LIVE_OBSTACLES};
use crate::model::{ix, State};
use crate::site::geometry::closest_on_segment_squared;
use crate::site::outline::MAX_OUTLINE_CIRCLES;
use crate::world::World;

/// What a live row keeps beyond the envelope's margin [m]: the envelope
/// checks the plan's first command held for a tick and then the stop at the
/// limits, with the response lags, which can come nearer than the plan
/// itself (a plan kept at the field's edge was overridden at a few cm).
pub const PLAN_MARGIN: f64 = 0.2;

/// The set, its settings and margins, and the obstacles near this tick.
#[derive(Debug, Clone)]
pub struct LiveRows {
    settings: LiveSettings,
    set: LiveSet,
    /// Each outline circle's margin to a live obstacle beyond the stop
    /// field's reach: the envelope's, plus [`PLAN_MARGIN`].
    margins: [f64; MAX_OUTLINE_CIRCLES],
    /// The time of the plan's x₀ [s, the clock of the stamps].
    t0: f64,
    dt: f64,
    /// The obstacles a plan from this tick's x̂ can come near (indices into
    /// the set), [`LiveRows::select`].
    near: Vec<usize>,
}

impl LiveRows {
    /// Rows for stages `dt` apart.
    pub fn new(settings: LiveSettings, dt: f64) -> Self {
        Self {
            settings,
            set: LiveSet::new(),
            margins: [PLAN_MARGIN; MAX_OUTLINE_CIRCLES],
            t0: 0.0,
            dt,
            near: Vec::with_capacity(MAX_LIVE_OBSTACLES),
        }
    }

    /// The newest set (no allocation).
    pub fn set_obstacles(&mut self, set: &LiveSet) {
        self.set.copy_from(set);
        self.near.clear();
    }

    /// Each outline circle's envelope margin (missing ones 0).
    pub fn set_margins(&mut self, margins: &[f64]) {
        self.margins = [PLAN_MARGIN; MAX_OUTLINE_CIRCLES];
        for (m, v) in self.margins.iter_mut().zip(margins) {
            *m += *v;
        }
    }

    /// The time of stage k's state [s].
    pub fn stage_time(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    /// The obstacles near this tick.
    pub fn near(&self) -> &[usize] {
        &self.near
    }

    /// Chooses the obstacles a plan of `horizon` stages from `x_hat` (its
    /// front axle), at time `t0`, can come within `reach` of (`reach`
    /// covers the plan's travel and the outline, as for the goal's
    /// circles): those whose swept disc (its bounding disc along its
    /// velocity over the horizon, grown by the prediction's reach and the
    /// largest margin) comes that near.
    pub fn select(&mut self, x_hat: &State, t0: f64, horizon: usize, reach: f64) {
        self.t0 = t0;
        self.near.clear();
        let p = [x_hat[ix::X], x_hat[ix::Y]];
        let t_end = self.stage_time(horizon);
        let margin = self.margins.iter().copied().fold(0.0, f64::max);
        for (i, o) in self.set.obstacles().iter().enumerate() {
            let (c, r) = o.shape.bounding_circle();
            let a = o.moved(c, t0);
            let b = o.moved(c, t_end);
            let grow = self.settings.reach(t_end - o.stamp) + margin + r;
            // A non-finite pose keeps every obstacle: the tick falls back anyway.
            if !(closest_on_segment_squared(p, a, b).1.sqrt() - grow > reach) {
                self.near.push(i);
            }
        }
    }

    /// (h, ∇h) of the row of outline circle `circle` against obstacle `i` at
    /// stage k's state `x`: the clearance less the margin and the reach
    /// ([`World::live_row`]).
    pub fn row(
        &self,
        world: &World,
        x: &State,
        k: usize,
        circle: usize,
        i: usize,
    ) -> (f64, [f64; 4]) {
        let o = &self.set.obstacles()[i];
        let t = self.stage_time(k);
        let grow = self.settings.reach(t - o.stamp) + self.margins[circle];
        world.live_row(x, circle, o, t, grow)
    }
}
