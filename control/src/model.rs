//! The articulated wheel-loader kinematic model (paper eq. 5–8, Table I).
//!
//! State x = [x_f, y_f, θ_f, β, β̇, v_f] (front-axle pose, articulation angle and
//! rate, front speed); control u = [β̈, a_f]. β > 0 bends the front body to the
//! left, so with β̇ = 0 and v_f > 0 the machine turns counter-clockwise.

use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// Number of state components.
pub const NX: usize = 6;
/// Number of control components.
pub const NU: usize = 2;

pub type State = SVector<f64, NX>;
pub type Control = SVector<f64, NU>;
/// ∂f/∂x of the discrete step.
pub type StateJacobian = SMatrix<f64, NX, NX>;
/// ∂f/∂u of the discrete step.
pub type ControlJacobian = SMatrix<f64, NX, NU>;

/// Indices into [`State`], so code reads like the paper.
pub mod ix {
    pub const X: usize = 0;
    pub const Y: usize = 1;
    pub const THETA: usize = 2;
    pub const BETA: usize = 3;
    pub const BETA_DOT: usize = 4;
    pub const V: usize = 5;
}

/// Errors in model parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("machine parameter `{name}` must be finite and > 0 (got {value})")]
    NotPositive { name: &'static str, value: f64 },
    #[error("machine parameter `beta_max` must be below 90° so L_f cos β + L_r stays positive (got {0} rad)")]
    BetaMaxTooLarge(f64),
}

impl ModelError {
    /// The parameter that is wrong (its `MachineParams` field name).
    pub fn setting(&self) -> &'static str {
        match self {
            Self::NotPositive { name, .. } => name,
            Self::BetaMaxTooLarge(_) => "beta_max",
        }
    }
}

/// Machine geometry and motion limits. Defaults are the Avant 635 of the
/// paper's Table I; every field is configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MachineParams {
    /// Centre joint to front axle [m].
    pub l_f: f64,
    /// Centre joint to rear axle [m].
    pub l_r: f64,
    /// |β| bound [rad].
    pub beta_max: f64,
    /// |β̇| bound [rad/s].
    pub beta_dot_max: f64,
    /// |v_f| bound [m/s].
    pub v_max: f64,
    /// |β̈| bound [rad/s²].
    pub beta_ddot_max: f64,
    /// |a_f| bound [m/s²].
    pub a_max: f64,
}

/// "L_f 0.6 m, L_r 0.6 m, |β| ≤ 40°, …": what a report names the machine by.
impl std::fmt::Display for MachineParams {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let deg = |rad: f64| rad.to_degrees();
        write!(
            f,
            "L_f {} m, L_r {} m, |β| ≤ {:.0}°, |β̇| ≤ {:.0}°/s, |v| ≤ {} m/s, |β̈| ≤ {:.0}°/s², |a| ≤ {} m/s²",
            self.l_f,
            self.l_r,
            deg(self.beta_max),
            deg(self.beta_dot_max),
            self.v_max,
            deg(self.beta_ddot_max),
            self.a_max
        )
    }
}

impl Default for MachineParams {
    fn default() -> Self {
        let deg = std::f64::consts::PI / 180.0;
        Self {
            l_f: 0.6,
            l_r: 0.6,
            beta_max: 40.0 * deg,
            beta_dot_max: 33.0 * deg,
            v_max: 1.0,
            beta_ddot_max: 33.0 * deg,
            a_max: 1.0,
        }
    }
}

impl MachineParams {
    /// Named fields, in a fixed order (used by validation, metadata and configs).
    pub fn fields(&self) -> [(&'static str, f64); 7] {
        [
            ("l_f", self.l_f),
            ("l_r", self.l_r),
            ("beta_max", self.beta_max),
            ("beta_dot_max", self.beta_dot_max),
            ("v_max", self.v_max),
            ("beta_ddot_max", self.beta_ddot_max),
            ("a_max", self.a_max),
        ]
    }

    /// Checks every length and bound is finite and positive.
    pub fn validate(&self) -> Result<(), ModelError> {
        for (name, value) in self.fields() {
            if !(value.is_finite() && value > 0.0) {
                return Err(ModelError::NotPositive { name, value });
            }
        }
        if self.beta_max >= std::f64::consts::FRAC_PI_2 {
            return Err(ModelError::BetaMaxTooLarge(self.beta_max));
        }
        Ok(())
    }

    /// Upper bounds of the control [β̈_max, a_max].
    pub fn control_max(&self) -> Control {
        Control::new(self.beta_ddot_max, self.a_max)
    }

    /// Clamps a control to its box.
    pub fn clamp_control(&self, u: &Control) -> Control {
        Control::new(
            u[0].clamp(-self.beta_ddot_max, self.beta_ddot_max),
            u[1].clamp(-self.a_max, self.a_max),
        )
    }
}

/// A velocity command (β̇_cmd, v_cmd) as the machine's low-level controller takes
/// it: what the MPC outputs (the velocities of its x₁), the daemon sends over CAN
/// and the simulated machine executes. One type from the MPC to the CAN encoder.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct VelocityCommand {
    /// Articulation rate β̇_cmd [rad/s].
    pub beta_dot: f64,
    /// Front speed v_cmd [m/s].
    pub v: f64,
}

impl VelocityCommand {
    /// Standing still.
    pub const ZERO: Self = Self {
        beta_dot: 0.0,
        v: 0.0,
    };

    /// True if both velocities are finite.
    pub fn is_finite(&self) -> bool {
        self.beta_dot.is_finite() && self.v.is_finite()
    }

    /// The command the machine may be sent: inside the velocity bounds
    /// (|β̇| ≤ β̇_max, |v| ≤ v_max), and zero if either velocity is not finite.
    /// The one place commands are limited; see [`Self::is_within`].
    pub fn limited(self, p: &MachineParams) -> Self {
        if !self.is_finite() {
            return Self::ZERO;
        }
        Self {
            beta_dot: self.beta_dot.clamp(-p.beta_dot_max, p.beta_dot_max),
            v: self.v.clamp(-p.v_max, p.v_max),
        }
    }

    /// True if [`Self::limited`] leaves the command unchanged.
    pub fn is_within(&self, p: &MachineParams) -> bool {
        self.limited(p) == *self
    }
}

/// Continuous dynamics f_c(x, u) (paper eq. 5).
pub fn f_continuous(p: &MachineParams, x: &State, u: &Control) -> State {
    let (theta, beta, beta_dot, v) = (x[ix::THETA], x[ix::BETA], x[ix::BETA_DOT], x[ix::V]);
    let (sb, cb) = beta.sin_cos();
    let denom = p.l_f * cb + p.l_r;
    State::new(
        v * theta.cos(),
        v * theta.sin(),
        (p.l_r * beta_dot + v * sb) / denom,
        beta_dot,
        u[0],
        u[1],
    )
}

/// ∂f_c/∂x of paper eq. 5; ∂f_c/∂u is constant, see [`continuous_b`].
pub fn continuous_a(p: &MachineParams, x: &State) -> StateJacobian {
    let (theta, beta, beta_dot, v) = (x[ix::THETA], x[ix::BETA], x[ix::BETA_DOT], x[ix::V]);
    let (st, ct) = theta.sin_cos();
    let (sb, cb) = beta.sin_cos();
    let denom = p.l_f * cb + p.l_r;
    let num = p.l_r * beta_dot + v * sb;
    let mut a = StateJacobian::zeros();
    a[(0, ix::THETA)] = -v * st;
    a[(0, ix::V)] = ct;
    a[(1, ix::THETA)] = v * ct;
    a[(1, ix::V)] = st;
    // d/dβ of num/denom = (v cos β · denom + num · L_f sin β) / denom²
    a[(2, ix::BETA)] = (v * cb * denom + num * p.l_f * sb) / (denom * denom);
    a[(2, ix::BETA_DOT)] = p.l_r / denom;
    a[(2, ix::V)] = sb / denom;
    a[(3, ix::BETA_DOT)] = 1.0;
    a
}

/// ∂f_c/∂u: rows β̇ and v_f of the identity.
pub fn continuous_b() -> ControlJacobian {
    let mut b = ControlJacobian::zeros();
    b[(4, 0)] = 1.0;
    b[(5, 1)] = 1.0;
    b
}

/// One explicit RK4 step of length `dt` (paper eq. 7–8).
pub fn rk4_step(p: &MachineParams, x: &State, u: &Control, dt: f64) -> State {
    let k1 = f_continuous(p, x, u);
    let k2 = f_continuous(p, &(x + k1 * (0.5 * dt)), u);
    let k3 = f_continuous(p, &(x + k2 * (0.5 * dt)), u);
    let k4 = f_continuous(p, &(x + k3 * dt), u);
    x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (dt / 6.0)
}

/// RK4 step with its exact Jacobians ∂x⁺/∂x (6×6) and ∂x⁺/∂u (6×2): the
/// hand-derived f_c Jacobians chained through the four stages.
pub fn rk4_step_with_jacobians(
    p: &MachineParams,
    x: &State,
    u: &Control,
    dt: f64,
) -> (State, StateJacobian, ControlJacobian) {
    let id = StateJacobian::identity();
    let b = continuous_b();
    let h2 = 0.5 * dt;

    let k1 = f_continuous(p, x, u);
    let a1 = continuous_a(p, x);
    let (k1x, k1u) = (a1, b);

    let x2 = x + k1 * h2;
    let k2 = f_continuous(p, &x2, u);
    let a2 = continuous_a(p, &x2);
    let k2x = a2 * (id + k1x * h2);
    let k2u = a2 * (k1u * h2) + b;

    let x3 = x + k2 * h2;
    let k3 = f_continuous(p, &x3, u);
    let a3 = continuous_a(p, &x3);
    let k3x = a3 * (id + k2x * h2);
    let k3u = a3 * (k2u * h2) + b;

    let x4 = x + k3 * dt;
    let k4 = f_continuous(p, &x4, u);
    let a4 = continuous_a(p, &x4);
    let k4x = a4 * (id + k3x * dt);
    let k4u = a4 * (k3u * dt) + b;

    let s = dt / 6.0;
    let next = x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * s;
    let jx = id + (k1x + 2.0 * k2x + 2.0 * k3x + k4x) * s;
    let ju = (k1u + 2.0 * k2u + 2.0 * k3u + k4u) * s;
    (next, jx, ju)
}

/// Applies the RL environment's constraint rule (DESIGN §2) in place: β̇ and v_f
/// are clamped to their bounds; a β past ±β_max is clamped and β̇ set to zero.
pub fn clamp_state(p: &MachineParams, x: &mut State) {
    x[ix::BETA_DOT] = x[ix::BETA_DOT].clamp(-p.beta_dot_max, p.beta_dot_max);
    x[ix::V] = x[ix::V].clamp(-p.v_max, p.v_max);
    if x[ix::BETA].abs() > p.beta_max {
        x[ix::BETA] = p.beta_max.copysign(x[ix::BETA]);
        x[ix::BETA_DOT] = 0.0;
    }
}

/// The RL environment transition: RK4 step, then [`clamp_state`]. The control
/// is clamped to its box first, as the actor's tanh already guarantees.
pub fn env_step(p: &MachineParams, x: &State, u: &Control, dt: f64) -> State {
    let mut next = rk4_step(p, x, &p.clamp_control(u), dt);
    clamp_state(p, &mut next);
    next
}

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.sin().atan2(a.cos());
    if w <= -std::f64::consts::PI {
        w + 2.0 * std::f64::consts::PI
    } else {
        w
    }
}

/// A goal pose of the front axle; the target state is [x, y, θ, 0, 0, 0].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Goal {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Goal {
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }
}

/// The error vector e = [e_xy, e_θ, β, β̇, v_f] of paper eq. 10–11 (e_θ wrapped).
pub fn pose_error(x: &State, g: &Goal) -> [f64; 5] {
    let dx = x[ix::X] - g.x;
    let dy = x[ix::Y] - g.y;
    [
        dx.hypot(dy),
        wrap_angle(x[ix::THETA] - g.theta),
        x[ix::BETA],
        x[ix::BETA_DOT],
        x[ix::V],
    ]
}

/// The paper's success measure ‖(x_f − x_g, y_f − y_g, e_θ)‖ (DESIGN §7).
pub fn goal_distance(x: &State, g: &Goal) -> f64 {
    let e = pose_error(x, g);
    e[0].hypot(e[1])
}

/// The paper's success tolerance (DESIGN §7): [`goal_distance`] below it counts
/// as converged in every evaluation, `verify` and the daemon's default.
pub const SUCCESS_TOLERANCE: f64 = 0.1;

/// |v_f| below which a converged machine counts as having reached its goal
/// [m/s]: the evaluations' settling test and the daemon's default "goal
/// reached". Not "at rest" ([`REST_SPEED`]): a goal is reported reached while
/// the machine still settles into it.
pub const REACH_SPEED: f64 = 0.05;

/// |v_f| and |β̇| below which the machine is at rest [m/s, rad/s]: the one
/// definition (the daemon's default `loop.rest_speed`: a stop or shutdown is
/// complete; telemetry's `at_rest`, which clients such as the fleet link read
/// instead of keeping a threshold of their own).
pub const REST_SPEED: f64 = 0.02;

/// Convergence test of DESIGN §7: [`goal_distance`] below `tolerance` ([`SUCCESS_TOLERANCE`] in the paper).
pub fn converged(x: &State, g: &Goal, tolerance: f64) -> bool {
    goal_distance(x, g) < tolerance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_machine_is_named_by_its_parameters_in_the_units_people_use() {
        let deg = std::f64::consts::PI / 180.0;
        let large = MachineParams {
            l_f: 0.9,
            l_r: 1.1,
            beta_max: 42.0 * deg,
            beta_dot_max: 25.0 * deg,
            v_max: 1.5,
            beta_ddot_max: 25.0 * deg,
            a_max: 0.8,
        };
        assert_eq!(
            large.to_string(),
            "L_f 0.9 m, L_r 1.1 m, |β| ≤ 42°, |β̇| ≤ 25°/s, |v| ≤ 1.5 m/s, |β̈| ≤ 25°/s², |a| ≤ 0.8 m/s²"
        );
    }

    fn central_diff_jacobians(
        p: &MachineParams,
        x: &State,
        u: &Control,
        dt: f64,
    ) -> (StateJacobian, ControlJacobian) {
        let mut jx = StateJacobian::zeros();
        let mut ju = ControlJacobian::zeros();
        for j in 0..NX {
            let h = 1e-6 * (1.0 + x[j].abs());
            let (mut xp, mut xm) = (*x, *x);
            xp[j] += h;
            xm[j] -= h;
            let col = (rk4_step(p, &xp, u, dt) - rk4_step(p, &xm, u, dt)) / (2.0 * h);
            jx.set_column(j, &col);
        }
        for j in 0..NU {
            let h = 1e-6 * (1.0 + u[j].abs());
            let (mut up, mut um) = (*u, *u);
            up[j] += h;
            um[j] -= h;
            let col = (rk4_step(p, x, &up, dt) - rk4_step(p, x, &um, dt)) / (2.0 * h);
            ju.set_column(j, &col);
        }
        (jx, ju)
    }

    #[test]
    fn rk4_jacobians_match_central_differences() {
        let p = MachineParams::default();
        let cases = [
            (
                State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                Control::new(0.0, 0.0),
            ),
            (
                State::new(1.0, -2.0, 0.7, 0.3, -0.2, 0.8),
                Control::new(0.4, -0.6),
            ),
            (
                State::new(-3.0, 4.0, -2.9, -0.6, 0.5, -0.9),
                Control::new(-0.5, 1.0),
            ),
            (
                State::new(5.0, 1.0, 3.1, 0.69, 0.57, 1.0),
                Control::new(0.57, 0.3),
            ),
        ];
        for (x, u) in cases {
            for dt in [0.05, 0.2] {
                let (next, jx, ju) = rk4_step_with_jacobians(&p, &x, &u, dt);
                assert!((next - rk4_step(&p, &x, &u, dt)).norm() < 1e-14);
                let (fx, fu) = central_diff_jacobians(&p, &x, &u, dt);
                let rel_x = (jx - fx).norm() / fx.norm();
                let rel_u = (ju - fu).norm() / fu.norm();
                assert!(rel_x <= 1e-6, "∂f/∂x relative error {rel_x} at {x:?}");
                assert!(rel_u <= 1e-6, "∂f/∂u relative error {rel_u} at {x:?}");
            }
        }
    }

    #[test]
    fn straight_line_motion_matches_closed_form() {
        let p = MachineParams::default();
        let theta: f64 = 0.6;
        let mut x = State::new(1.0, 2.0, theta, 0.0, 0.0, 0.5);
        let a = 0.3;
        let dt = 0.2;
        for _ in 0..10 {
            x = rk4_step(&p, &x, &Control::new(0.0, a), dt);
        }
        let t = 2.0;
        let s = 0.5 * t + 0.5 * a * t * t;
        assert!((x[ix::X] - (1.0 + s * theta.cos())).abs() < 1e-12);
        assert!((x[ix::Y] - (2.0 + s * theta.sin())).abs() < 1e-12);
        assert!((x[ix::THETA] - theta).abs() < 1e-15);
        assert!((x[ix::V] - (0.5 + a * t)).abs() < 1e-12);
    }

    #[test]
    fn constant_beta_circle_has_closed_form_radius() {
        let p = MachineParams::default();
        for beta in [0.2_f64, -0.5, 0.69] {
            let v = 0.8;
            let mut x = State::new(0.0, 0.0, 0.0, beta, 0.0, v);
            let dt = 0.01;
            let steps = 3000;
            let mut pts = Vec::with_capacity(steps);
            for _ in 0..steps {
                x = rk4_step(&p, &x, &Control::zeros(), dt);
                pts.push((x[0], x[1]));
            }
            // Radius from the expected centre: on the left (β > 0, CCW) at distance R.
            let r = (p.l_f * beta.cos() + p.l_r) / beta.sin();
            let (ox, oy) = (0.0, r);
            for (px, py) in &pts {
                let d = (px - ox).hypot(py - oy);
                assert!(
                    (d - r.abs()).abs() < 1e-8,
                    "β={beta}: distance {d} vs R {r}"
                );
            }
            // Heading rate sign: CCW for β > 0.
            let omega = x[ix::THETA] / (steps as f64 * dt);
            assert!((omega - v / r).abs() < 1e-10);
        }
    }

    #[test]
    fn clamping_rule() {
        let p = MachineParams::default();
        // β̇ pushes β past the limit: β clamped and β̇ zeroed.
        let x = State::new(0.0, 0.0, 0.0, p.beta_max - 0.01, p.beta_dot_max, 0.0);
        let n = env_step(&p, &x, &Control::new(p.beta_ddot_max, 0.0), 0.2);
        assert_eq!(n[ix::BETA], p.beta_max);
        assert_eq!(n[ix::BETA_DOT], 0.0);
        // Same at the negative limit.
        let x = State::new(0.0, 0.0, 0.0, -p.beta_max + 0.01, -p.beta_dot_max, 0.0);
        let n = env_step(&p, &x, &Control::new(-p.beta_ddot_max, 0.0), 0.2);
        assert_eq!(n[ix::BETA], -p.beta_max);
        assert_eq!(n[ix::BETA_DOT], 0.0);
        // Speed and rate saturate at their bounds, β inside keeps its rate.
        let x = State::new(0.0, 0.0, 0.0, 0.0, p.beta_dot_max, p.v_max);
        let n = env_step(&p, &x, &Control::new(1.0, 1.0), 0.2);
        assert_eq!(n[ix::V], p.v_max);
        assert_eq!(n[ix::BETA_DOT], p.beta_dot_max);
        assert!(n[ix::BETA] > 0.0 && n[ix::BETA] < p.beta_max);
        // An out-of-box control is clamped before integration.
        let x = State::zeros();
        let a = env_step(&p, &x, &Control::new(0.0, 5.0), 0.2);
        let b = env_step(&p, &x, &Control::new(0.0, p.a_max), 0.2);
        assert_eq!(a, b);
    }

    #[test]
    fn pose_error_and_convergence() {
        let g = Goal::new(1.0, 1.0, 3.0);
        let x = State::new(1.03, 0.96, -3.2, 0.1, 0.2, 0.3);
        let e = pose_error(&x, &g);
        assert!((e[0] - 0.05).abs() < 1e-12);
        let expected = -3.2 - 3.0 + 2.0 * std::f64::consts::PI;
        assert!((e[1] - expected).abs() < 1e-12);
        assert_eq!(&e[2..], &[0.1, 0.2, 0.3]);
        assert!(converged(&x, &g, 0.1));
        assert!(!converged(&x, &g, 0.05));
    }

    #[test]
    fn validation_names_the_parameter() {
        let mut p = MachineParams::default();
        assert!(p.validate().is_ok());
        p.l_r = -0.1;
        let e = p.validate().unwrap_err();
        assert!(e.to_string().contains("l_r"), "{e}");
        let mut p = MachineParams::default();
        p.a_max = f64::NAN;
        assert!(p.validate().unwrap_err().to_string().contains("a_max"));
        let mut p = MachineParams::default();
        p.beta_max = 2.0;
        assert!(matches!(p.validate(), Err(ModelError::BetaMaxTooLarge(_))));
    }
}
