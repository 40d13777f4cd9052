//! The obstacles a plan is checked against: both axle points of the footprint
//! ([`footprint_clearance`], DESIGN §10) outside every circle by a margin.
//!
//! Why a margin on top of the already inflated radii: the route is followed by
//! the MPC, not tracked exactly, and the plan's samples are discrete; the
//! margin is what the MPC's own deviation from the route may use up.

use crate::model::{MachineParams, State};
use crate::obstacle::{footprint_clearance, Obstacle};

use super::NavError;

/// A fixed-capacity set of circles and the clearance margin of every check.
#[derive(Debug, Clone)]
pub struct World {
    params: MachineParams,
    obstacles: Vec<Obstacle>,
    capacity: usize,
    margin: f64,
}

impl World {
    /// Room for `capacity` circles, allocated once.
    pub fn new(params: MachineParams, capacity: usize, margin: f64) -> Self {
        Self {
            params,
            obstacles: Vec::with_capacity(capacity),
            capacity,
            margin,
        }
    }

    /// Replaces the circles (validated; within the capacity, so no allocation).
    pub fn set(&mut self, obstacles: &[Obstacle]) -> Result<(), NavError> {
        if obstacles.len() > self.capacity {
            return Err(NavError::TooManyObstacles {
                given: obstacles.len(),
                max: self.capacity,
            });
        }
        for (i, o) in obstacles.iter().enumerate() {
            o.validate(i).map_err(NavError::BadObstacle)?;
        }
        self.obstacles.clear();
        self.obstacles.extend_from_slice(obstacles);
        Ok(())
    }

    pub fn clear(&mut self) {
        self.obstacles.clear();
    }

    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    pub fn is_empty(&self) -> bool {
        self.obstacles.is_empty()
    }

    pub fn params(&self) -> &MachineParams {
        &self.params
    }

    pub fn margin(&self) -> f64 {
        self.margin
    }

    /// The margin of the following checks (a plan lowers it when an endpoint
    /// already lies closer to a circle).
    pub fn set_margin(&mut self, margin: f64) {
        self.margin = margin;
    }

    /// Smallest distance of either axle point to a circle's edge for the
    /// front-axle pose (x, y, θ) at articulation β (+∞ without circles).
    pub fn pose_clearance(&self, x: f64, y: f64, theta: f64, beta: f64) -> f64 {
        self.state_clearance(&State::new(x, y, theta, beta, 0.0, 0.0))
    }

    pub fn state_clearance(&self, s: &State) -> f64 {
        footprint_clearance(&self.params, s, &self.obstacles)
    }

    /// Both axle points keep at least the margin.
    pub fn pose_free(&self, x: f64, y: f64, theta: f64, beta: f64) -> bool {
        self.pose_clearance(x, y, theta, beta) >= self.margin
    }

    pub fn state_free(&self, s: &State) -> bool {
        self.state_clearance(s) >= self.margin
    }

    /// The straight segment between two points keeps `extra` from every
    /// circle (a point test, for cheap line-of-sight filters).
    pub fn segment_clear(&self, a: [f64; 2], b: [f64; 2], extra: f64) -> bool {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        self.obstacles.iter().all(|o| {
            let t = if len2 > 0.0 {
                (((o.x - a[0]) * dx + (o.y - a[1]) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (cx, cy) = (a[0] + t * dx, a[1] + t * dy);
            (cx - o.x).hypot(cy - o.y) >= o.radius + extra
        })
    }
}
