//! The prediction model of the MPC (paper eq. 7–8) behind a small trait, so the
//! LQR test can swap in linear dynamics.

use crate::model::{
    rk4_step_with_jacobians, Control, ControlJacobian, MachineParams, State, StateJacobian,
};

/// Discrete dynamics x⁺ = f(x, u) over one stage of length `dt`, with its
/// Jacobians (the linearised dynamics of the QP).
pub trait Dynamics {
    /// x⁺.
    fn step(&self, x: &State, u: &Control, dt: f64) -> State {
        self.step_with_jacobians(x, u, dt).0
    }
    /// x⁺, ∂x⁺/∂x and ∂x⁺/∂u.
    fn step_with_jacobians(
        &self,
        x: &State,
        u: &Control,
        dt: f64,
    ) -> (State, StateJacobian, ControlJacobian);
}

/// The wheel-loader kinematic model integrated by one RK4 step, with the exact
/// Jacobians of the step ([`crate::model::rk4_step_with_jacobians`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rk4Model {
    pub params: MachineParams,
}

impl Dynamics for Rk4Model {
    fn step(&self, x: &State, u: &Control, dt: f64) -> State {
        crate::model::rk4_step(&self.params, x, u, dt)
    }

    fn step_with_jacobians(
        &self,
        x: &State,
        u: &Control,
        dt: f64,
    ) -> (State, StateJacobian, ControlJacobian) {
        rk4_step_with_jacobians(&self.params, x, u, dt)
    }
}

/// x⁺ = A x + B u (the stage length is already in A and B).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearDynamics {
    pub a: StateJacobian,
    pub b: ControlJacobian,
}

impl Dynamics for LinearDynamics {
    fn step_with_jacobians(
        &self,
        x: &State,
        u: &Control,
        _dt: f64,
    ) -> (State, StateJacobian, ControlJacobian) {
        (self.a * x + self.b * u, self.a, self.b)
    }
}
