//! Tracking a time-parametrised trajectory (issue 42): the MPC's cost while
//! the navigator's route carries a minimum-time trajectory
//! ([`crate::planner::TrajectoryOptimiser`]), in place of the critic and the
//! path cost. At stage k, with r(t) the trajectory's state at time t (linear
//! between its samples, its last state beyond its end) and t_k = t₀ + k·Δt,
//!
//!   V_k(x, u) = q_p‖p(x) − p(r)‖² + q_θ(1 − cos(θ − θ_r)) + q_β(β − β_r)²
//!             + q_β̇(β̇ − β̇_r)² + q_v(v − v_r)² + r·Σ (u_i / u_max,i)²
//!
//! with p the leading axle's position: the front axle's where the reference
//! drives forwards, the rear axle's where it reverses (as [`super::PathCost`]
//! follows the leading point: tracked by its trailing front axle, a
//! reversing machine is a trailer pushed backwards; measured on obstacles200,
//! the front axle tracked reversing drifted up to 0.7 m off the reference and
//! lost goals). The reference's speed and articulation carry what
//! a path cannot: where the trajectory brakes, stops to reverse (a cusp is
//! v_r passing through 0) and arrives at rest. t₀, the reference time of the
//! first stage, is the navigator's ([`crate::planner::Navigator`]): it runs
//! with the clock and waits while the machine lags behind.
//!
//! Its Gauss–Newton Hessian takes 2q_p·JᵀJ for the position (J the point's
//! Jacobian over (x_f, y_f, θ, β); the front axle's is constant) and
//! q_θ·max(cos, 0) for the heading, as [`super::PathCost`] does. The
//! terminal cost is V at t_N without the controls.

use crate::critic::Derivatives;
use crate::model::{ix, wrap_angle, Control, MachineParams, State, NU, NX};
use crate::obstacle::AxlePoint;

use super::path_cost::POSE_INDEX;

/// The weights of [`TrackCost`], each on its squared error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackWeights {
    /// q_p [1/m²] on the front axle's position.
    pub position: f64,
    /// q_θ on 1 − cos of the heading error.
    pub heading: f64,
    /// q_β [1/rad²].
    pub articulation: f64,
    /// q_β̇ [s²/rad²].
    pub articulation_rate: f64,
    /// q_v [s²/m²].
    pub speed: f64,
    /// r on the squared controls, each relative to its bound.
    pub control: f64,
}

impl Default for TrackWeights {
    fn default() -> Self {
        Self {
            position: 50.0,
            // 1 − cos(e) ≈ e²/2: a radian of heading weighs as a metre, as
            // in the success test (DESIGN §7).
            heading: 100.0,
            articulation: 1.0,
            articulation_rate: 0.1,
            speed: 1.0,
            control: 0.1,
        }
    }
}

impl TrackWeights {
    fn is_valid(&self) -> bool {
        [
            self.position,
            self.heading,
            self.articulation,
            self.articulation_rate,
            self.speed,
            self.control,
        ]
        .iter()
        .all(|w| w.is_finite() && *w >= 0.0)
    }
}

/// States a tracked trajectory holds (allocated once): 4096 samples of
/// 0.1 s are almost seven minutes.
pub const MAX_TRACK_STATES: usize = 4096;

/// A trajectory to track: its states every `dt`, from its start.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackCost {
    states: Vec<State>,
    dt: f64,
    /// t₀: the reference time of the first stage [s from the start].
    time: f64,
    weights: TrackWeights,
    control_scale: [f64; NU],
    params: MachineParams,
}

impl Default for TrackCost {
    fn default() -> Self {
        Self::new()
    }
}

impl TrackCost {
    /// Room for [`MAX_TRACK_STATES`] (setting or copying allocates nothing).
    pub fn new() -> Self {
        Self {
            states: Vec::with_capacity(MAX_TRACK_STATES),
            dt: 0.0,
            time: 0.0,
            weights: TrackWeights::default(),
            control_scale: [0.0; NU],
            params: MachineParams::default(),
        }
    }

    /// Nothing to track: the cost is another's.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    pub fn clear(&mut self) {
        self.states.clear();
        self.time = 0.0;
    }

    /// Sets the trajectory: `states` every `dt` [s], start first (those
    /// beyond [`MAX_TRACK_STATES`] left out), t₀ = 0. Non-finite states,
    /// weights or `dt`, or fewer than two states, leave it empty: a broken
    /// trajectory must not steer.
    pub fn set(
        &mut self,
        states: &[State],
        dt: f64,
        weights: TrackWeights,
        params: &MachineParams,
    ) {
        self.clear();
        let umax = params.control_max();
        let usable = weights.is_valid()
            && dt.is_finite()
            && dt > 0.0
            && states.len() >= 2
            && umax.iter().all(|u| u.is_finite() && *u > 0.0)
            && states.iter().all(|x| x.iter().all(|v| v.is_finite()));
        if !usable {
            return;
        }
        let n = states.len().min(MAX_TRACK_STATES);
        self.states.extend_from_slice(&states[..n]);
        self.dt = dt;
        self.weights = weights;
        self.control_scale = [1.0 / umax[0], 1.0 / umax[1]];
        self.params = *params;
    }

    /// Copies `other` (no allocation).
    pub fn copy_from(&mut self, other: &TrackCost) {
        self.states.clear();
        self.states.extend_from_slice(&other.states);
        self.dt = other.dt;
        self.time = other.time;
        self.weights = other.weights;
        self.control_scale = other.control_scale;
        self.params = other.params;
    }

    /// t₀, the first stage's reference time [s].
    pub fn time(&self) -> f64 {
        self.time
    }

    pub fn set_time(&mut self, t: f64) {
        self.time = if t.is_finite() { t.max(0.0) } else { 0.0 };
    }

    /// The trajectory's duration [s].
    pub fn duration(&self) -> f64 {
        self.states.len().saturating_sub(1) as f64 * self.dt
    }

    /// The spacing of its states [s].
    pub fn step(&self) -> f64 {
        self.dt
    }

    /// r(t): linear between samples (the heading along the shorter way),
    /// the first before the start and the last beyond the end. Call only on
    /// a non-empty trajectory.
    pub fn reference(&self, t: f64) -> State {
        let last = self.states.len() - 1;
        let s = (t / self.dt).clamp(0.0, last as f64);
        let i = (s.floor() as usize).min(last.saturating_sub(1));
        let f = s - i as f64;
        let (a, b) = (&self.states[i], &self.states[(i + 1).min(last)]);
        let mut r = a + (b - a) * f;
        r[ix::THETA] = a[ix::THETA] + f * wrap_angle(b[ix::THETA] - a[ix::THETA]);
        r
    }

    /// V at stage time t₀ + `offset` for (x, u) with its gradient and
    /// Gauss–Newton Hessian over z = (x, u). Call only on a non-empty
    /// trajectory.
    pub fn eval(&self, x: &State, u: &Control, offset: f64, out: &mut Derivatives) {
        let w = &self.weights;
        let r = self.reference(self.time + offset);
        out.value = 0.0;
        out.grad = [0.0; NX + NU];
        out.hess = [[0.0; NX + NU]; NX + NU];
        let mut square = |i: usize, q: f64| {
            let e = x[i] - r[i];
            out.value += q * e * e;
            out.grad[i] = 2.0 * q * e;
            out.hess[i][i] = 2.0 * q;
        };
        square(ix::BETA, w.articulation);
        square(ix::BETA_DOT, w.articulation_rate);
        square(ix::V, w.speed);
        // The leading axle's position: the front's forwards, the rear's
        // reversing (a machine steered by its trailing axle is a trailer
        // pushed backwards; Gauss–Newton through the point's Jacobian J).
        let point = if r[ix::V] < 0.0 {
            AxlePoint::Rear
        } else {
            AxlePoint::Front
        };
        let (p, pr) = (
            point.position(&self.params, x),
            point.position(&self.params, &r),
        );
        let e = [p[0] - pr[0], p[1] - pr[1]];
        let j = point.jacobian(&self.params, x);
        out.value += w.position * (e[0] * e[0] + e[1] * e[1]);
        for (a, &ia) in POSE_INDEX.iter().enumerate() {
            out.grad[ia] += 2.0 * w.position * (j[0][a] * e[0] + j[1][a] * e[1]);
            for (b, &ib) in POSE_INDEX.iter().enumerate() {
                out.hess[ia][ib] += 2.0 * w.position * (j[0][a] * j[0][b] + j[1][a] * j[1][b]);
            }
        }
        let (sin, cos) = wrap_angle(x[ix::THETA] - r[ix::THETA]).sin_cos();
        out.value += w.heading * (1.0 - cos);
        out.grad[ix::THETA] += w.heading * sin;
        out.hess[ix::THETA][ix::THETA] += w.heading * cos.max(0.0);
        for c in 0..NU {
            let k = self.control_scale[c];
            out.value += w.control * (k * u[c]).powi(2);
            out.grad[NX + c] = 2.0 * w.control * k * k * u[c];
            out.hess[NX + c][NX + c] = 2.0 * w.control * k * k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Along x with a turn, starting at speed `v0` and slowing by `braking`
    /// per second: forwards for v0 > 0, reversing for v0 < 0.
    fn trajectory(v0: f64, braking: f64) -> TrackCost {
        let p = MachineParams::default();
        let states: Vec<State> = (0..=10)
            .map(|k| {
                let t = 0.2 * k as f64;
                let v = v0 - braking * t;
                State::new(t, 0.1 * t * t, 3.0 + 0.2 * t, 0.3 * t - 0.2, 0.3, v)
            })
            .collect();
        let mut c = TrackCost::new();
        c.set(&states, 0.2, TrackWeights::default(), &p);
        c
    }

    #[test]
    fn the_reference_interpolates_and_holds_the_ends() {
        let mut c = trajectory(1.0, 0.4);
        assert_eq!(c.duration(), 2.0);
        let r = c.reference(0.3);
        assert!((r[ix::X] - 0.3).abs() < 1e-12);
        assert!((r[ix::V] - (1.0 - 0.4 * 0.3)).abs() < 1e-12);
        assert_eq!(c.reference(-1.0), c.reference(0.0));
        assert_eq!(c.reference(9.0), c.states[10]);
        // The heading across ±π goes the shorter way.
        c.states[1][ix::THETA] = -3.0;
        c.states[0][ix::THETA] = 3.0;
        let mid = c.reference(0.1)[ix::THETA];
        assert!(
            (wrap_angle(mid - std::f64::consts::PI)).abs() < 0.2,
            "{mid}"
        );
    }

    #[test]
    fn gradient_matches_central_differences_and_is_zero_on_the_reference() {
        // Forwards (the front axle tracked) and reversing (the rear axle).
        for v0 in [1.0, -1.0] {
            gradient_at(v0);
        }
    }

    fn gradient_at(v0: f64) {
        let mut c = trajectory(v0, 0.1);
        c.set_time(0.5);
        let x = State::new(0.9, 0.2, -2.9, 0.1, 0.2, 0.6);
        let u = Control::new(0.3, -0.4);
        let mut d = Derivatives::default();
        c.eval(&x, &u, 0.4, &mut d);
        let z: Vec<f64> = x.iter().chain(u.iter()).copied().collect();
        let value = |z: &[f64]| {
            let mut e = Derivatives::default();
            let x = State::from_column_slice(&z[..NX]);
            let u = Control::new(z[NX], z[NX + 1]);
            c.eval(&x, &u, 0.4, &mut e);
            e.value
        };
        let eps = 1e-6;
        for i in 0..NX + NU {
            let (mut a, mut b) = (z.clone(), z.clone());
            a[i] += eps;
            b[i] -= eps;
            let fd = (value(&a) - value(&b)) / (2.0 * eps);
            assert!(
                (fd - d.grad[i]).abs() < 1e-6,
                "component {i}: {fd} vs {}",
                d.grad[i]
            );
        }
        // On the reference at rest controls: no cost, no gradient.
        let r = c.reference(0.9);
        c.eval(&r, &Control::zeros(), 0.4, &mut d);
        assert!(d.value.abs() < 1e-12 && d.grad.iter().all(|g| g.abs() < 1e-12));
    }

    #[test]
    fn broken_input_leaves_it_empty() {
        let p = MachineParams::default();
        let mut c = TrackCost::new();
        let mut states = vec![State::zeros(); 3];
        c.set(&states, 0.0, TrackWeights::default(), &p);
        assert!(c.is_empty());
        states[1][0] = f64::NAN;
        c.set(&states, 0.1, TrackWeights::default(), &p);
        assert!(c.is_empty());
        c.set(&states[..1], 0.1, TrackWeights::default(), &p);
        assert!(c.is_empty());
    }
}
