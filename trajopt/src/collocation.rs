//! Hermite–Simpson direct collocation of the machine model (paper eq. 5) with
//! piecewise-constant controls, and its exact derivatives.
//!
//! On an interval of length h with control u:
//!   x_m = (x₀ + x₁)/2 + h/8 (f(x₀,u) − f(x₁,u)),
//!   d   = x₁ − x₀ − h/6 (f(x₀,u) + 4 f(x_m,u) + f(x₁,u)) = 0.
//! The scheme is fourth order like the RK4 step the controllers use, so the
//! open-loop controls of a collocated trajectory replayed on the RK4 model
//! (Δt = h) follow it closely.

use control::model::{f_continuous, Control, MachineParams, State};
use nalgebra::SMatrix;

pub type Mat6 = SMatrix<f64, 6, 6>;
pub type Mat62 = SMatrix<f64, 6, 2>;

/// ∂f_c/∂x of paper eq. 5 (the model's own, hand-derived).
pub fn jacobian_x(p: &MachineParams, x: &State) -> Mat6 {
    control::model::continuous_a(p, x)
}

/// ∂f_c/∂u.
pub fn jacobian_u() -> Mat62 {
    control::model::continuous_b()
}

/// A Hermite–Simpson defect and its derivatives.
#[derive(Debug, Clone, Copy)]
pub struct Defect {
    pub d: State,
    pub d_x0: Mat6,
    pub d_u: Mat62,
    pub d_x1: Mat6,
    /// ∂d/∂h.
    pub d_h: State,
}

/// The defect of one interval and its exact Jacobians.
pub fn hermite_simpson(p: &MachineParams, x0: &State, u: &Control, x1: &State, h: f64) -> Defect {
    let f0 = f_continuous(p, x0, u);
    let f1 = f_continuous(p, x1, u);
    let xm = (x0 + x1) * 0.5 + (f0 - f1) * (h / 8.0);
    let fm = f_continuous(p, &xm, u);
    let d = x1 - x0 - (f0 + fm * 4.0 + f1) * (h / 6.0);
    let a0 = jacobian_x(p, x0);
    let a1 = jacobian_x(p, x1);
    let am = jacobian_x(p, &xm);
    let id = Mat6::identity();
    let dxm_dx0 = id * 0.5 + a0 * (h / 8.0);
    let dxm_dx1 = id * 0.5 - a1 * (h / 8.0);
    let d_x0 = -id - (a0 + am * dxm_dx0 * 4.0) * (h / 6.0);
    let d_x1 = id - (am * dxm_dx1 * 4.0 + a1) * (h / 6.0);
    // x_m does not depend on u (the B terms cancel), so ∂d/∂u = −h B.
    let d_u = -jacobian_u() * h;
    let d_h = -(f0 + fm * 4.0 + f1) / 6.0 - am * (f0 - f1) * (h / 12.0);
    Defect {
        d,
        d_x0,
        d_u,
        d_x1,
        d_h,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defect_jacobians_match_central_differences() {
        let p = MachineParams::default();
        let x0 = State::new(0.3, -0.2, 0.7, 0.3, -0.2, 0.8);
        let x1 = State::new(0.5, 0.1, 0.9, 0.25, -0.1, 0.6);
        let u = Control::new(0.4, -0.6);
        let h = 0.25;
        let df = hermite_simpson(&p, &x0, &u, &x1, h);
        let eps = 1e-6;
        for j in 0..6 {
            let (mut a, mut b) = (x0, x0);
            a[j] += eps;
            b[j] -= eps;
            let col = (hermite_simpson(&p, &a, &u, &x1, h).d
                - hermite_simpson(&p, &b, &u, &x1, h).d)
                / (2.0 * eps);
            assert!((col - df.d_x0.column(j)).norm() < 1e-8, "x0 column {j}");
            let (mut a, mut b) = (x1, x1);
            a[j] += eps;
            b[j] -= eps;
            let col = (hermite_simpson(&p, &x0, &u, &a, h).d
                - hermite_simpson(&p, &x0, &u, &b, h).d)
                / (2.0 * eps);
            assert!((col - df.d_x1.column(j)).norm() < 1e-8, "x1 column {j}");
        }
        for j in 0..2 {
            let (mut a, mut b) = (u, u);
            a[j] += eps;
            b[j] -= eps;
            let col = (hermite_simpson(&p, &x0, &a, &x1, h).d
                - hermite_simpson(&p, &x0, &b, &x1, h).d)
                / (2.0 * eps);
            assert!((col - df.d_u.column(j)).norm() < 1e-8, "u column {j}");
        }
        let col = (hermite_simpson(&p, &x0, &u, &x1, h + eps).d
            - hermite_simpson(&p, &x0, &u, &x1, h - eps).d)
            / (2.0 * eps);
        assert!((col - df.d_h).norm() < 1e-8);
    }
}
