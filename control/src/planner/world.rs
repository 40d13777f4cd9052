//! What a plan is checked against: the one world ([`crate::world::World`]:
//! the site, the goal's circles, the machine's outline) and the clearance
//! margin every check of the route keeps.
//!
//! Why a margin on top of the outline: the route is followed by the MPC, not
//! tracked exactly, and the plan's samples are discrete; the margin is what
//! the MPC's own deviation from the route may use up.

use std::sync::Arc;

use crate::model::{MachineParams, State};
use crate::obstacle::Obstacle;
use crate::site::outline::MAX_OUTLINE_CIRCLES;
use crate::site::{Body, Outline, SiteIndex};
use crate::world::{World, WorldError};

use super::NavError;

/// The world and the clearance margin of every check.
#[derive(Debug, Clone)]
pub struct CheckedWorld {
    world: World,
    margin: f64,
    /// How much of each outline circle's extra margin a plan gives up
    /// ([`CheckedWorld::set_relief`]); 0 but where an endpoint is inside it.
    relief: f64,
}

impl CheckedWorld {
    /// Room for `capacity` circles, allocated once; the default outline.
    pub fn new(params: MachineParams, capacity: usize, margin: f64) -> Self {
        Self {
            world: World::with_axle_circles(params, capacity),
            margin,
            relief: 0.0,
        }
    }

    /// Replaces the goal's circles (validated; within the capacity, so no
    /// allocation).
    pub fn set(&mut self, obstacles: &[Obstacle]) -> Result<(), NavError> {
        self.world.set_circles(obstacles).map_err(|e| match e {
            WorldError::TooManyObstacles { given, max } => {
                NavError::TooManyObstacles { given, max }
            }
            WorldError::BadObstacle(b) => NavError::BadObstacle(b),
        })
    }

    /// Adds one circle to the goal's (within the capacity).
    pub fn push(&mut self, o: Obstacle) -> Result<(), NavError> {
        self.world.push_circle(o).map_err(|e| match e {
            WorldError::TooManyObstacles { given, max } => {
                NavError::TooManyObstacles { given, max }
            }
            WorldError::BadObstacle(b) => NavError::BadObstacle(b),
        })
    }

    /// Keeps the first `n` circles.
    pub fn truncate(&mut self, n: usize) {
        self.world.truncate_circles(n);
    }

    /// Becomes `world` (no allocation while the outline stays).
    pub fn copy_from(&mut self, world: &World) {
        self.world.copy_from(world);
    }

    pub fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.world.set_site(site);
    }

    /// The outline and each circle's extra margin ([`World::set_extra_margins`]).
    pub fn set_outline(&mut self, outline: Outline, extra: &[f64]) {
        self.world.set_outline(outline);
        self.world.set_extra_margins(extra);
    }

    /// Forgets the goal's circles (the site stays).
    pub fn clear(&mut self) {
        self.world.clear_circles();
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// The goal's circles.
    pub fn obstacles(&self) -> &[Obstacle] {
        self.world.circles()
    }

    /// Nothing to keep off (no site, no circles).
    pub fn is_empty(&self) -> bool {
        self.world.is_empty()
    }

    pub fn params(&self) -> &MachineParams {
        self.world.params()
    }

    pub fn margin(&self) -> f64 {
        self.margin
    }

    /// The margin of the following checks (a plan lowers it when an endpoint
    /// already lies closer to something).
    pub fn set_margin(&mut self, margin: f64) {
        self.margin = margin;
    }

    pub fn state_clearance(&self, s: &State) -> f64 {
        self.world.clearance(s)
    }

    /// The outline keeps at least the margin.
    pub fn pose_free(&self, x: f64, y: f64, theta: f64, beta: f64) -> bool {
        self.state_free(&State::new(x, y, theta, beta, 0.0, 0.0))
    }

    /// The least of (clearance − extra margin) over the outline's circles:
    /// the most margin a check of this state could keep (+∞ in an empty world).
    pub fn state_slack(&self, s: &State) -> f64 {
        self.world
            .excess(s, self.world.extra_margins(), f64::INFINITY)
            .map_or(f64::INFINITY, |c| c.clearance)
    }

    /// Lets the following checks give up `relief` ≥ 0 of each circle's extra
    /// margin (never more than the extra: the outline itself stays free). A
    /// machine stopped inside its extras (the envelope stopped it there, or a
    /// reload moved a feature) must be able to plan its way out, or every
    /// search would fail at its first node.
    pub fn set_relief(&mut self, relief: f64) {
        self.relief = relief.max(0.0);
    }

    /// Every outline circle keeps the margin plus its extra, less the relief
    /// (the MPC plans each circle that much wider: a route it could not
    /// follow would stall).
    pub fn state_free(&self, s: &State) -> bool {
        // Only what comes nearer than the margins is searched for.
        self.world.excess(s, &self.circle_margins(), 0.0).is_none()
    }

    /// What each outline circle keeps in every check: the margin plus its
    /// extra, less the relief.
    pub fn circle_margins(&self) -> [f64; MAX_OUTLINE_CIRCLES] {
        let mut margins = *self.world.extra_margins();
        for m in &mut margins {
            *m = (*m - self.relief).max(0.0) + self.margin;
        }
        margins
    }

    /// The disc the outline surely covers around the front axle, swept along
    /// a–b, keeps `extra` from everything (a cheap line-of-sight filter).
    pub fn segment_clear(&self, a: [f64; 2], b: [f64; 2], extra: f64) -> bool {
        let r = self.world.outline().axle_radius(Body::Front);
        self.world.segment_clear(a, b, r, extra)
    }

    /// Whether the front axle's disc at `p` comes nearer than `below` to
    /// anything (what the grid heuristic blocks a cell by).
    pub fn front_axle_blocked(&self, p: [f64; 2], below: f64) -> bool {
        let r = self.world.outline().axle_radius(Body::Front);
        self.world.disc_clearance(p, r, below) < below
    }
}
