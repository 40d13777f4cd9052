//! Constraint rows of the QP (paper eq. 17–18 and the control bounds of §IV-E):
//! hard control bounds, soft state bounds on n = 1..N, soft circular obstacles
//! (linearised distance, or the discrete-time CBF form), all linearised at
//! the linearisation point (x̄, ū). Rows and entries are those of
//! [`super::layout::QpLayout`].

use serde::{Deserialize, Serialize};

use crate::model::{ix, Control, MachineParams, State};

use super::layout::{QpLayout, SOFT_STATES};
use super::settings::{MpcError, ObstacleConstraint};

/// Most obstacles one goal can carry (DESIGN §6).
pub const MAX_OBSTACLES: usize = 8;

/// A circular obstacle around (x, y) that the front axle must stay out of; the
/// radius already includes the machine's own (DESIGN §5).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Obstacle {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

impl Obstacle {
    pub const fn new(x: f64, y: f64, radius: f64) -> Self {
        Self { x, y, radius }
    }

    /// h(x) = ‖p_f − o‖ − R (metres outside the circle; negative inside) and
    /// ∂h/∂(x_f, y_f). At the centre, where the gradient is undefined, the
    /// direction +x is used.
    pub fn clearance(&self, x: &State) -> (f64, [f64; 2]) {
        let (dx, dy) = (x[ix::X] - self.x, x[ix::Y] - self.y);
        let d = dx.hypot(dy);
        if d > 1e-9 {
            (d - self.radius, [dx / d, dy / d])
        } else {
            (d - self.radius, [1.0, 0.0])
        }
    }

    /// Finite centre and radius > 0.
    pub fn validate(&self, index: usize) -> Result<(), MpcError> {
        if !(self.x.is_finite() && self.y.is_finite()) {
            return Err(MpcError::BadObstacle {
                index,
                reason: "centre must be finite",
            });
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(MpcError::BadObstacle {
                index,
                reason: "radius must be finite and > 0",
            });
        }
        Ok(())
    }
}

/// Right-hand sides of the control and state bounds:
/// ±(ū + Δu) ≤ u_max and ±(x̄_c + Δx_c) − s ≤ max_c.
pub fn fill_bounds(
    layout: &QpLayout,
    p: &MachineParams,
    xbar: &[State],
    ubar: &[Control],
    b: &mut [f64],
) {
    let umax = p.control_max();
    for (n, u) in ubar.iter().enumerate() {
        let r = layout.row_controls(n);
        for i in 0..2 {
            b[r + i] = umax[i] - u[i];
            b[r + 2 + i] = umax[i] + u[i];
        }
    }
    let smax = [p.beta_max, p.beta_dot_max, p.v_max];
    for (n, x) in xbar.iter().enumerate().skip(1) {
        let r = layout.row_states(n);
        for (c, &k) in SOFT_STATES.iter().enumerate() {
            b[r + c] = smax[c] - x[k];
            b[r + 3 + c] = smax[c] + x[k];
        }
    }
}

/// Obstacle rows: for each row k = 0..N−1 and slot j,
///
/// * distance form: h(x̄_{k+1}) + ∇h·Δp_{k+1} + s ≥ 0,
/// * CBF form: h(x̄_{k+1}) + ∇h_{k+1}·Δp_{k+1} − (1 − γ)(h(x̄_k) + ∇h_k·Δp_k) + s ≥ 0,
///
/// written as A w ≤ b. Empty slots get zero coefficients and b = 1 (always
/// satisfied with a zero slack).
pub fn fill_obstacles(
    layout: &QpLayout,
    form: ObstacleConstraint,
    gamma: f64,
    obstacles: &[Obstacle],
    xbar: &[State],
    a: &mut [f64],
    b: &mut [f64],
) {
    let cbf = form == ObstacleConstraint::Cbf;
    for k in 0..layout.horizon {
        for j in 0..layout.n_obs {
            let e = &layout.a_obs[k * layout.n_obs + j];
            let r = layout.row_obstacle(k, j);
            let Some(o) = obstacles.get(j) else {
                a[e[0]] = 0.0;
                a[e[1]] = 0.0;
                if cbf {
                    a[e[2]] = 0.0;
                    a[e[3]] = 0.0;
                }
                b[r] = 1.0;
                continue;
            };
            let (h1, g1) = o.clearance(&xbar[k + 1]);
            a[e[0]] = -g1[0];
            a[e[1]] = -g1[1];
            b[r] = h1;
            if cbf {
                let (h0, g0) = o.clearance(&xbar[k]);
                let keep = 1.0 - gamma;
                a[e[2]] = keep * g0[0];
                a[e[3]] = keep * g0[1];
                b[r] -= keep * h0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clearance_and_gradient() {
        let o = Obstacle::new(1.0, 2.0, 0.5);
        let (h, g) = o.clearance(&State::new(4.0, 6.0, 0.0, 0.0, 0.0, 0.0));
        assert!((h - 4.5).abs() < 1e-15);
        assert!((g[0] - 0.6).abs() < 1e-15 && (g[1] - 0.8).abs() < 1e-15);
        let (h, g) = o.clearance(&State::new(1.0, 2.0, 0.0, 0.0, 0.0, 0.0));
        assert_eq!((h, g), (-0.5, [1.0, 0.0]));
        assert!(Obstacle::new(0.0, 0.0, 0.0)
            .validate(3)
            .unwrap_err()
            .to_string()
            .contains("obstacle 3"));
        assert!(Obstacle::new(f64::NAN, 0.0, 1.0).validate(0).is_err());
    }
}
