//! Circular obstacles and the machine's footprint (DESIGN §10).
//!
//! One obstacle type for the whole workspace: the MPC's constraints, scenario
//! files, the planner, the evaluation and the daemon's goal validation all use
//! [`Obstacle`]. The radius is as on the wire: already inflated by the
//! machine's half-width, so the footprint is the two axle points.
//!
//! Footprint: the front axle at (x_f, y_f); the joint L_f behind it along the
//! front body's heading θ; the rear axle L_r further along the rear body's
//! heading θ − β (β > 0 bends the front body to the left, DESIGN §2):
//!
//! ```text
//! p_r = p_f − L_f (cos θ, sin θ) − L_r (cos(θ − β), sin(θ − β))
//! ```

use serde::{Deserialize, Serialize};

use crate::model::{ix, MachineParams, State};

/// How far inside a circle an axle point may be before it counts as
/// penetration [m]: a planned one makes the MPC's plan a failed solve, a driven
/// one fails a run (DESIGN §7, §14).
pub const PENETRATION_TOLERANCE: f64 = 0.005;

/// A circular obstacle around (x, y); the radius includes the machine's own.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Obstacle {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

/// Why an obstacle is not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("obstacle {index}: {reason}")]
pub struct BadObstacle {
    pub index: usize,
    pub reason: &'static str,
}

/// The two points of the machine that must stay outside every circle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxlePoint {
    Front,
    Rear,
}

impl AxlePoint {
    pub const ALL: [AxlePoint; 2] = [AxlePoint::Front, AxlePoint::Rear];

    /// The point's position for state `x`.
    pub fn position(self, p: &MachineParams, x: &State) -> [f64; 2] {
        match self {
            AxlePoint::Front => [x[ix::X], x[ix::Y]],
            AxlePoint::Rear => {
                let (th, rear) = (x[ix::THETA], x[ix::THETA] - x[ix::BETA]);
                [
                    x[ix::X] - p.l_f * th.cos() - p.l_r * rear.cos(),
                    x[ix::Y] - p.l_f * th.sin() - p.l_r * rear.sin(),
                ]
            }
        }
    }

    /// The heading of the point's body: θ for the front, θ − β for the rear.
    pub fn heading(self, x: &State) -> f64 {
        match self {
            AxlePoint::Front => x[ix::THETA],
            AxlePoint::Rear => x[ix::THETA] - x[ix::BETA],
        }
    }

    /// ∂(heading)/∂(x_f, y_f, θ, β).
    pub fn heading_jacobian(self) -> [f64; 4] {
        match self {
            AxlePoint::Front => [0.0, 0.0, 1.0, 0.0],
            AxlePoint::Rear => [0.0, 0.0, 1.0, -1.0],
        }
    }

    /// ∂(position)/∂(x_f, y_f, θ, β): rows are the point's x and y.
    pub fn jacobian(self, p: &MachineParams, x: &State) -> [[f64; 4]; 2] {
        match self {
            AxlePoint::Front => [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]],
            AxlePoint::Rear => {
                let (th, rear) = (x[ix::THETA], x[ix::THETA] - x[ix::BETA]);
                let (s, c) = th.sin_cos();
                let (sr, cr) = rear.sin_cos();
                [
                    [1.0, 0.0, p.l_f * s + p.l_r * sr, -p.l_r * sr],
                    [0.0, 1.0, -p.l_f * c - p.l_r * cr, p.l_r * cr],
                ]
            }
        }
    }
}

impl Obstacle {
    pub const fn new(x: f64, y: f64, radius: f64) -> Self {
        Self { x, y, radius }
    }

    /// Distance of point `q` outside the circle (negative inside).
    pub fn clearance_of(&self, q: [f64; 2]) -> f64 {
        (q[0] - self.x).hypot(q[1] - self.y) - self.radius
    }

    /// h = ‖q − o‖ − R for axle point `point` of state `x`, and
    /// ∂h/∂(x_f, y_f, θ, β). At the centre, where the gradient is undefined,
    /// the direction +x is used.
    pub fn point_clearance(
        &self,
        p: &MachineParams,
        point: AxlePoint,
        x: &State,
    ) -> (f64, [f64; 4]) {
        let q = point.position(p, x);
        let (dx, dy) = (q[0] - self.x, q[1] - self.y);
        let d = dx.hypot(dy);
        let n = if d > 1e-9 {
            [dx / d, dy / d]
        } else {
            [1.0, 0.0]
        };
        let j = point.jacobian(p, x);
        let mut g = [0.0; 4];
        for (k, gk) in g.iter_mut().enumerate() {
            *gk = n[0] * j[0][k] + n[1] * j[1][k];
        }
        (d - self.radius, g)
    }

    /// Finite centre and radius > 0.
    pub fn validate(&self, index: usize) -> Result<(), BadObstacle> {
        if !(self.x.is_finite() && self.y.is_finite()) {
            return Err(BadObstacle {
                index,
                reason: "centre must be finite",
            });
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(BadObstacle {
                index,
                reason: "radius must be finite and > 0",
            });
        }
        Ok(())
    }
}

/// Smallest clearance of either axle point of `x` to any obstacle's edge
/// (+∞ without obstacles).
pub fn footprint_clearance(p: &MachineParams, x: &State, obstacles: &[Obstacle]) -> f64 {
    AxlePoint::ALL
        .iter()
        .map(|a| a.position(p, x))
        .flat_map(|q| obstacles.iter().map(move |o| o.clearance_of(q)))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn avant() -> MachineParams {
        MachineParams::default()
    }

    #[test]
    fn rear_axle_of_a_straight_and_a_bent_machine() {
        let p = avant();
        // Straight, heading +y: the rear axle is L_f + L_r behind.
        let x = State::new(1.0, 2.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0);
        let r = AxlePoint::Rear.position(&p, &x);
        assert!((r[0] - 1.0).abs() < 1e-12 && (r[1] - (2.0 - p.l_f - p.l_r)).abs() < 1e-12);
        // Heading 0, bent left by 90°: the rear body points along −90°, so the
        // rear axle is L_r to the right of the joint... i.e. rear = joint − L_r(cos(−90°), sin(−90°)).
        let x = State::new(0.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        let r = AxlePoint::Rear.position(&p, &x);
        assert!((r[0] + p.l_f).abs() < 1e-12 && (r[1] - p.l_r).abs() < 1e-12);
    }

    #[test]
    fn clearance_gradient_matches_finite_differences() {
        let p = MachineParams {
            l_f: 0.9,
            l_r: 1.1,
            ..avant()
        };
        let o = Obstacle::new(-1.3, 0.7, 0.4);
        let x = State::new(0.3, -0.2, 0.7, -0.4, 0.1, 0.5);
        for point in AxlePoint::ALL {
            let (h, g) = o.point_clearance(&p, point, &x);
            for (k, i) in [ix::X, ix::Y, ix::THETA, ix::BETA].into_iter().enumerate() {
                let e = 1e-6;
                let (mut a, mut b) = (x, x);
                a[i] += e;
                b[i] -= e;
                let fd = (o.point_clearance(&p, point, &a).0 - o.point_clearance(&p, point, &b).0)
                    / (2.0 * e);
                assert!(
                    (fd - g[k]).abs() < 1e-7,
                    "{point:?} d/d{i}: {fd} vs {}",
                    g[k]
                );
            }
            let q = point.position(&p, &x);
            assert!((h - o.clearance_of(q)).abs() < 1e-15);
        }
    }

    #[test]
    fn footprint_sees_an_obstacle_only_the_rear_axle_touches() {
        let p = avant();
        let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        // A circle around the rear axle (−1.2, 0), well clear of the front axle.
        let o = [Obstacle::new(-1.2, 0.0, 0.3)];
        let front_only = o[0].clearance_of(AxlePoint::Front.position(&p, &x));
        assert!(front_only > 0.5);
        assert!((footprint_clearance(&p, &x, &o) + 0.3).abs() < 1e-12);
        assert_eq!(footprint_clearance(&p, &x, &[]), f64::INFINITY);
    }

    #[test]
    fn validation_names_the_obstacle() {
        let e = Obstacle::new(0.0, 0.0, 0.0).validate(3).unwrap_err();
        assert!(e.to_string().contains("obstacle 3"));
        assert!(Obstacle::new(f64::NAN, 0.0, 1.0).validate(0).is_err());
        assert!(Obstacle::new(0.0, 0.0, f64::INFINITY).validate(0).is_err());
    }
}
