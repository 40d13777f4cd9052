//! The goal-conditioned input encoder shared by actor and critic (DESIGN §3).
//!
//! It is part of the deployed network: training calls these same functions to
//! build its batches, so training and deployment cannot drift.
//!
//! Features (encoder id [`ENCODER_ID`]):
//! 0–1  front-axle position relative to the goal, in the goal frame, / `pos_scale`
//! 2–3  sin e_θ, cos e_θ with e_θ = θ_f − θ_g
//! 4–6  β / β_max, β̇ / β̇_max, v_f / v_max
//! 7–8  (critic only) u₁ / β̈_max, u₂ / a_max

use crate::model::{ix, Control, Goal, MachineParams, State};

/// Identifier written into weight files; bump it whenever the features change.
pub const ENCODER_ID: &str = "wlnav-goal-frame-v1";
/// Features seen by the actor.
pub const ACTOR_INPUTS: usize = 7;
/// Features seen by the critic (actor features + scaled action).
pub const CRITIC_INPUTS: usize = 9;
/// Dimension of z = (x, u), the variables the MPC differentiates with respect to.
pub const NZ: usize = 8;
/// Default position scale [m]: goals lie up to 10 m away.
pub const DEFAULT_POS_SCALE: f64 = 10.0;

/// The encoder with its scales.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoder {
    pub pos_scale: f64,
    pub params: MachineParams,
}

impl Encoder {
    pub fn new(params: MachineParams, pos_scale: f64) -> Self {
        Self { pos_scale, params }
    }

    /// Actor features into `out[..7]`.
    pub fn encode_state(&self, x: &State, g: &Goal, out: &mut [f64]) {
        let (sg, cg) = g.theta.sin_cos();
        let dx = x[ix::X] - g.x;
        let dy = x[ix::Y] - g.y;
        let (se, ce) = (x[ix::THETA] - g.theta).sin_cos();
        let p = &self.params;
        out[0] = (cg * dx + sg * dy) / self.pos_scale;
        out[1] = (-sg * dx + cg * dy) / self.pos_scale;
        out[2] = se;
        out[3] = ce;
        out[4] = x[ix::BETA] / p.beta_max;
        out[5] = x[ix::BETA_DOT] / p.beta_dot_max;
        out[6] = x[ix::V] / p.v_max;
    }

    /// Critic features into `out[..9]`.
    pub fn encode(&self, x: &State, u: &Control, g: &Goal, out: &mut [f64]) {
        self.encode_state(x, g, out);
        out[7] = u[0] / self.params.beta_ddot_max;
        out[8] = u[1] / self.params.a_max;
    }

    /// Jacobian ∂features/∂z (9 × 8, row-major as `[f64; 8]` rows) at `x`.
    ///
    /// Every feature but sin/cos e_θ is affine in z, so the only second
    /// derivatives are ∂²(sin e_θ)/∂θ² = −sin e_θ and ∂²(cos e_θ)/∂θ² = −cos e_θ
    /// (used by [`Encoder::add_curvature`]).
    pub fn jacobian(&self, x: &State, g: &Goal, jac: &mut [[f64; NZ]; CRITIC_INPUTS]) {
        let (sg, cg) = g.theta.sin_cos();
        let (se, ce) = (x[ix::THETA] - g.theta).sin_cos();
        let p = &self.params;
        *jac = [[0.0; NZ]; CRITIC_INPUTS];
        jac[0][ix::X] = cg / self.pos_scale;
        jac[0][ix::Y] = sg / self.pos_scale;
        jac[1][ix::X] = -sg / self.pos_scale;
        jac[1][ix::Y] = cg / self.pos_scale;
        jac[2][ix::THETA] = ce;
        jac[3][ix::THETA] = -se;
        jac[4][ix::BETA] = 1.0 / p.beta_max;
        jac[5][ix::BETA_DOT] = 1.0 / p.beta_dot_max;
        jac[6][ix::V] = 1.0 / p.v_max;
        jac[7][6] = 1.0 / p.beta_ddot_max;
        jac[8][7] = 1.0 / p.a_max;
    }

    /// Adds Σₖ (∂L/∂fₖ) ∂²fₖ/∂z² to `hess`, given the feature gradient and features.
    pub fn add_curvature(
        &self,
        feature_grad: &[f64],
        features: &[f64],
        hess: &mut [[f64; NZ]; NZ],
    ) {
        hess[ix::THETA][ix::THETA] -= feature_grad[2] * features[2] + feature_grad[3] * features[3];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goal_frame_position_and_jacobian() {
        let enc = Encoder::new(MachineParams::default(), 10.0);
        let g = Goal::new(2.0, 1.0, std::f64::consts::FRAC_PI_2);
        // 1 m "in front of" a goal facing +y is at (2, 2).
        let x = State::new(2.0, 2.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0);
        let mut f = [0.0; 9];
        enc.encode(&x, &Control::zeros(), &g, &mut f);
        assert!((f[0] - 0.1).abs() < 1e-15 && f[1].abs() < 1e-15);
        assert!(f[2].abs() < 1e-15 && (f[3] - 1.0).abs() < 1e-15);

        let x = State::new(0.3, -0.7, 2.5, 0.2, -0.1, 0.4);
        let u = Control::new(0.3, -0.5);
        let mut jac = [[0.0; NZ]; CRITIC_INPUTS];
        enc.jacobian(&x, &g, &mut jac);
        for j in 0..NZ {
            let h = 1e-6;
            let (mut xp, mut xm, mut up, mut um) = (x, x, u, u);
            if j < 6 {
                xp[j] += h;
                xm[j] -= h;
            } else {
                up[j - 6] += h;
                um[j - 6] -= h;
            }
            let (mut fp, mut fm) = ([0.0; 9], [0.0; 9]);
            enc.encode(&xp, &up, &g, &mut fp);
            enc.encode(&xm, &um, &g, &mut fm);
            for k in 0..CRITIC_INPUTS {
                let fd = (fp[k] - fm[k]) / (2.0 * h);
                assert!(
                    (fd - jac[k][j]).abs() < 1e-8,
                    "∂f{k}/∂z{j}: {fd} vs {}",
                    jac[k][j]
                );
            }
        }
    }
}
