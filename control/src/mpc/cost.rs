//! The MPC's cost (paper eq. 19–21): the terminal cost L(x_N, 0, g) and the
//! stage costs Δt·L(x_n, u_n, g), each replaced by its second-order Taylor
//! model at the linearisation point, with every Hessian block made positive
//! semidefinite.

use nalgebra::{SMatrix, SymmetricEigen};

use crate::critic::{Critic, CriticWorkspace, Derivatives, HessianMode, TerminalDerivatives};
use crate::model::{wrap_angle, Control, Goal, State, NX};

use super::layout::NZ;

/// A stage cost L(x, u, g) the MPC can differentiate: the critic, or a
/// quadratic for tests. Evaluations write into caller-owned buffers and use a
/// workspace built once, so a tick does not allocate.
pub trait StageCost {
    /// Buffers for one evaluation.
    type Workspace;
    /// Builds the workspace (once, at MPC construction).
    fn workspace(&self) -> Self::Workspace;
    /// L(x, u, g), ∇_z L and ∇²_z L (z = (x, u)); the Hessian may be indefinite.
    fn stage(
        &self,
        ws: &mut Self::Workspace,
        x: &State,
        u: &Control,
        g: &Goal,
        mode: HessianMode,
        out: &mut Derivatives,
    );
    /// L(x, 0, g) with gradient and Hessian in x (paper eq. 19).
    fn terminal(
        &self,
        ws: &mut Self::Workspace,
        x: &State,
        g: &Goal,
        mode: HessianMode,
        out: &mut TerminalDerivatives,
    ) {
        let mut full = Derivatives::default();
        self.stage(ws, x, &Control::zeros(), g, mode, &mut full);
        *out = TerminalDerivatives::state_block(&full);
    }
}

impl StageCost for Critic {
    type Workspace = CriticWorkspace;

    fn workspace(&self) -> CriticWorkspace {
        CriticWorkspace::new(self)
    }

    fn stage(
        &self,
        ws: &mut CriticWorkspace,
        x: &State,
        u: &Control,
        g: &Goal,
        mode: HessianMode,
        out: &mut Derivatives,
    ) {
        self.hessian(ws, x, u, g, mode, out);
    }

    fn terminal(
        &self,
        ws: &mut CriticWorkspace,
        x: &State,
        g: &Goal,
        mode: HessianMode,
        out: &mut TerminalDerivatives,
    ) {
        self.terminal_hessian(ws, x, g, mode, out);
    }
}

/// L = eᵀ Q e + uᵀ R u + q_pos·‖p − p_g‖ with e = x − [x_g, y_g, θ_g, 0, 0, 0]
/// (heading error wrapped). With `q_pos = 0` it is a plain quadratic (the LQR
/// test); a positive `q_pos` adds a distance term that keeps pulling at
/// constant strength far from the goal. The distance term is smoothed as
/// √(d² + ε²) − ε with ε = 0.1 m so its Hessian stays bounded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadraticCost {
    pub q: SMatrix<f64, NX, NX>,
    pub r: SMatrix<f64, 2, 2>,
    pub q_pos: f64,
}

impl QuadraticCost {
    const EPS: f64 = 0.1;

    /// A diagonal quadratic cost.
    pub fn diagonal(q: [f64; NX], r: [f64; 2]) -> Self {
        Self {
            q: SMatrix::from_diagonal(&q.into()),
            r: SMatrix::from_diagonal(&r.into()),
            q_pos: 0.0,
        }
    }

    fn error(x: &State, g: &Goal) -> State {
        let mut e = *x;
        e[0] -= g.x;
        e[1] -= g.y;
        e[2] = wrap_angle(x[2] - g.theta);
        e
    }
}

impl StageCost for QuadraticCost {
    type Workspace = ();

    fn workspace(&self) {}

    fn stage(
        &self,
        _: &mut (),
        x: &State,
        u: &Control,
        g: &Goal,
        _: HessianMode,
        out: &mut Derivatives,
    ) {
        let e = Self::error(x, g);
        let qs = self.q + self.q.transpose();
        let rs = self.r + self.r.transpose();
        let (ge, gu) = (qs * e, rs * u);
        *out = Derivatives {
            value: 0.5 * (e.dot(&ge) + u.dot(&gu)),
            ..Default::default()
        };
        for i in 0..NX {
            out.grad[i] = ge[i];
            for j in 0..NX {
                out.hess[i][j] = qs[(i, j)];
            }
        }
        for i in 0..2 {
            out.grad[NX + i] = gu[i];
            for j in 0..2 {
                out.hess[NX + i][NX + j] = rs[(i, j)];
            }
        }
        if self.q_pos > 0.0 {
            let (dx, dy) = (e[0], e[1]);
            let d2 = dx * dx + dy * dy;
            let s = (d2 + Self::EPS * Self::EPS).sqrt();
            out.value += self.q_pos * (s - Self::EPS);
            let (gx, gy) = (dx / s, dy / s);
            out.grad[0] += self.q_pos * gx;
            out.grad[1] += self.q_pos * gy;
            // ∇² √(d² + ε²) = (I − ĝĝᵀ)/s with ĝ = (dx, dy)/s.
            out.hess[0][0] += self.q_pos * (1.0 - gx * gx) / s;
            out.hess[1][1] += self.q_pos * (1.0 - gy * gy) / s;
            out.hess[0][1] -= self.q_pos * gx * gy / s;
            out.hess[1][0] -= self.q_pos * gx * gy / s;
        }
    }
}

macro_rules! projection {
    ($name:ident, $d:literal) => {
        /// Symmetrises `h` and clips its eigenvalues at `floor`: the nearest
        /// (Frobenius) symmetric matrix with spectrum ≥ `floor`. Stack only.
        pub fn $name(h: &mut [[f64; $d]; $d], floor: f64) {
            let m = SMatrix::<f64, $d, $d>::from_fn(|i, j| 0.5 * (h[i][j] + h[j][i]));
            let eig = SymmetricEigen::new(m);
            if eig.eigenvalues.iter().all(|&l| l >= floor) {
                for i in 0..$d {
                    for j in 0..$d {
                        h[i][j] = m[(i, j)];
                    }
                }
                return;
            }
            let q = eig.eigenvectors;
            let l = eig.eigenvalues.map(|l| l.max(floor));
            for i in 0..$d {
                for j in 0..=i {
                    let mut acc = 0.0;
                    for k in 0..$d {
                        acc += q[(i, k)] * l[k] * q[(j, k)];
                    }
                    h[i][j] = acc;
                    h[j][i] = acc;
                }
            }
        }
    };
}

projection!(project_psd8, 8);
projection!(project_psd6, 6);

/// The QP's cost block of one stage from the cost's derivatives: Δt·(projected)
/// Hessian + λ_LM·I and Δt·gradient (paper eq. 20–21).
pub fn stage_block(
    d: &Derivatives,
    dt: f64,
    mode: HessianMode,
    floor: f64,
    lm: f64,
    hess: &mut [[f64; NZ]; NZ],
    grad: &mut [f64; NZ],
) {
    *hess = d.hess;
    if mode == HessianMode::Exact {
        project_psd8(hess, floor);
    }
    for i in 0..NZ {
        for j in 0..NZ {
            hess[i][j] *= dt;
        }
        hess[i][i] += lm;
        grad[i] = dt * d.grad[i];
    }
}

/// The QP's terminal cost block: (projected) Hessian + λ_LM·I and gradient.
pub fn terminal_block(
    d: &TerminalDerivatives,
    mode: HessianMode,
    floor: f64,
    lm: f64,
    hess: &mut [[f64; NX]; NX],
    grad: &mut [f64; NX],
) {
    *hess = d.hess;
    if mode == HessianMode::Exact {
        project_psd6(hess, floor);
    }
    for i in 0..NX {
        hess[i][i] += lm;
    }
    *grad = d.grad;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_clips_negative_eigenvalues_only() {
        // diag(2, −1) rotated by 30° in the (0, 1) plane, 1 elsewhere.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let r = SMatrix::<f64, 2, 2>::new(c, -s, s, c);
        let m = r * SMatrix::<f64, 2, 2>::new(2.0, 0.0, 0.0, -1.0) * r.transpose();
        let expected = r * SMatrix::<f64, 2, 2>::new(2.0, 0.0, 0.0, 0.0) * r.transpose();
        let mut h = [[0.0; 6]; 6];
        for i in 2..6 {
            h[i][i] = 1.0;
        }
        for i in 0..2 {
            for j in 0..2 {
                h[i][j] = m[(i, j)];
            }
        }
        project_psd6(&mut h, 0.0);
        for i in 0..6 {
            for j in 0..6 {
                let e = if i < 2 && j < 2 {
                    expected[(i, j)]
                } else if i == j {
                    1.0
                } else {
                    0.0
                };
                assert!((h[i][j] - e).abs() < 1e-12, "({i},{j}) {} vs {e}", h[i][j]);
            }
        }
        // A positive definite matrix is left alone.
        let mut p = [[0.0; 8]; 8];
        for i in 0..8 {
            p[i][i] = 2.0;
            if i > 0 {
                p[i][i - 1] = 0.5;
                p[i - 1][i] = 0.5;
            }
        }
        let before = p;
        project_psd8(&mut p, 0.0);
        assert_eq!(p, before);
    }

    #[test]
    fn quadratic_cost_derivatives_match_finite_differences() {
        let mut c = QuadraticCost::diagonal([1.0, 2.0, 0.5, 0.1, 0.2, 0.3], [0.05, 0.07]);
        c.q[(0, 1)] = 0.3;
        c.q_pos = 0.7;
        let g = Goal::new(1.0, -2.0, 3.0);
        let x = State::new(0.3, 0.4, -3.0, 0.1, -0.2, 0.5);
        let u = Control::new(0.2, -0.1);
        let mut d = Derivatives::default();
        c.stage(&mut (), &x, &u, &g, HessianMode::Exact, &mut d);
        let f = |z: &[f64; 8]| {
            let mut o = Derivatives::default();
            let xs = State::from_column_slice(&z[..6]);
            let us = Control::from_column_slice(&z[6..]);
            c.stage(&mut (), &xs, &us, &g, HessianMode::Exact, &mut o);
            o
        };
        let mut z = [0.0; 8];
        z[..6].copy_from_slice(x.as_slice());
        z[6..].copy_from_slice(u.as_slice());
        for j in 0..8 {
            let h = 1e-6;
            let (mut zp, mut zm) = (z, z);
            zp[j] += h;
            zm[j] -= h;
            let (fp, fm) = (f(&zp), f(&zm));
            assert!(
                ((fp.value - fm.value) / (2.0 * h) - d.grad[j]).abs() < 1e-6,
                "grad {j}"
            );
            for i in 0..8 {
                assert!(
                    ((fp.grad[i] - fm.grad[i]) / (2.0 * h) - d.hess[i][j]).abs() < 1e-5,
                    "hess {i},{j}"
                );
            }
        }
    }
}
