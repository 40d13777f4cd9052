//! The two trajectory optimisations: the paper's baseline (eq. 23–24, DESIGN
//! §8) and the free-final-time `min-time` problem, both transcribed by
//! Hermite–Simpson collocation ([`crate::collocation`]) into an
//! [`ElementNlp`] and solved with IPOPT.
//!
//! Variable layout: z = [x₀, u₀, x₁, u₁, …, x_{K−1}, u_{K−1}, x_K] (8K + 6
//! values), and for min-time the final time T last.

pub use crate::guess::Guess;
use std::f64::consts::PI;
use std::time::Duration;

use control::model::{
    env_step, goal_distance, ix, wrap_angle, Control, Goal, MachineParams, State,
};
use control::obstacle::{AxlePoint, Obstacle};
use control::scenario::Scenario;

use crate::collocation::hermite_simpson;
use crate::ipopt::{self, IpoptStatus, OptValue};
use crate::nlp::{Element, ElementNlp, HessianKind, INF};

/// Index of x_k's first component.
pub fn xi(k: usize) -> usize {
    8 * k
}

/// Index of u_k's first component.
pub fn ui(k: usize) -> usize {
    8 * k + 6
}

/// Constants of the baseline's cost e(t) (paper eq. 24), which the paper does
/// not give. c₁ = 1 makes e^{1/4} ≈ √distance (in m); c₂ = 1 weighs a
/// half-turn heading error like 2 m; ε keeps the fourth root smooth at the goal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaselineSettings {
    /// Horizon T [s] (paper: 25).
    pub horizon: f64,
    /// Collocation step [s] (paper: 0.2).
    pub dt: f64,
    pub c1: f64,
    pub c2: f64,
    pub epsilon: f64,
    pub hessian: HessianKind,
    /// IPOPT's tolerance.
    pub tol: f64,
    pub max_iter: i32,
    /// Fraction of the state bounds (β, β̇, v) the NLP may use. Below 1 so the
    /// replay on the RK4 model, whose clamping rule zeroes β̇ at the β stop,
    /// does not touch the stops between nodes (that made open-loop replays
    /// drift off the plan).
    pub state_margin: f64,
    /// Footprint constraint points inside each interval (besides its nodes).
    pub obstacle_samples: usize,
}

impl Default for BaselineSettings {
    fn default() -> Self {
        Self {
            horizon: 25.0,
            dt: 0.2,
            c1: 1.0,
            c2: 1.0,
            epsilon: 1e-3,
            hessian: HessianKind::FiniteDifference,
            tol: 1e-6,
            max_iter: 1000,
            state_margin: 0.97,
            obstacle_samples: 1,
        }
    }
}

/// An open-loop trajectory optimisation's result.
#[derive(Debug, Clone)]
pub struct Plan {
    pub status: IpoptStatus,
    /// Node states x₀..x_K.
    pub states: Vec<State>,
    /// Controls u₀..u_{K−1}, constant over each interval.
    pub controls: Vec<Control>,
    /// Interval length [s].
    pub dt: f64,
    pub objective: f64,
    /// Largest bound or constraint violation at the solution.
    pub violation: f64,
    /// Time spent inside IPOPT for it (all branches / guesses tried).
    pub solve_time: Duration,
}

/// One collocation interval: defect constraints, and the baseline's running
/// cost when `cost` is set. Variables (x_k, u_k, x_{k+1}) and, with a free
/// final time, T (then h = T / K).
struct Interval {
    vars: Vec<usize>,
    params: MachineParams,
    /// Fixed h, or `None` when h = T / `intervals` with T the last variable.
    h: Option<f64>,
    intervals: usize,
    cost: Option<(BaselineSettings, Goal)>,
}

/// The baseline's state cost s(x) = e^{1/4} + β² and its gradient.
fn baseline_state_cost(s: &BaselineSettings, g: &Goal, x: &[f64], grad: &mut [f64; 6]) -> f64 {
    let (dx, dy) = (x[0] - g.x, x[1] - g.y);
    let w = g.theta - x[ix::THETA];
    let one_minus_cos = 1.0 - w.cos();
    let e = s.c1 * (dx * dx + dy * dy) + s.c2 * one_minus_cos * one_minus_cos + s.epsilon;
    let root = e.powf(0.25);
    let de = 0.25 * root / e;
    *grad = [0.0; 6];
    grad[0] = de * 2.0 * s.c1 * dx;
    grad[1] = de * 2.0 * s.c1 * dy;
    // d/dθ (1 − cos(θ_g − θ)) = −sin(θ_g − θ)
    grad[ix::THETA] = de * 2.0 * s.c2 * one_minus_cos * (-w.sin());
    let beta = x[ix::BETA];
    grad[ix::BETA] = 2.0 * beta;
    root + beta * beta
}

impl Element for Interval {
    fn vars(&self) -> &[usize] {
        &self.vars
    }

    /// The model does not depend on the position (x, y): the defects are
    /// linear in both nodes' positions (the baseline's cost is not).
    fn is_linear_in(&self, local: usize) -> bool {
        self.cost.is_none() && matches!(local, 0 | 1 | 8 | 9)
    }

    fn has_objective(&self) -> bool {
        self.cost.is_some()
    }

    fn n_cons(&self) -> usize {
        6
    }

    fn con_bounds(&self, lower: &mut [f64], upper: &mut [f64]) {
        lower.fill(0.0);
        upper.fill(0.0);
    }

    fn eval(&self, z: &[f64], obj: &mut f64, grad: &mut [f64], g: &mut [f64], jac: &mut [f64]) {
        let nv = self.vars.len();
        let x0 = State::from_column_slice(&z[0..6]);
        let u = Control::new(z[6], z[7]);
        let x1 = State::from_column_slice(&z[8..14]);
        let (h, dh_dt) = match self.h {
            Some(h) => (h, 0.0),
            None => (z[14] / self.intervals as f64, 1.0 / self.intervals as f64),
        };
        let d = hermite_simpson(&self.params, &x0, &u, &x1, h);
        for r in 0..6 {
            g[r] = d.d[r];
            let row = &mut jac[r * nv..(r + 1) * nv];
            for c in 0..6 {
                row[c] = d.d_x0[(r, c)];
                row[8 + c] = d.d_x1[(r, c)];
            }
            row[6] = d.d_u[(r, 0)];
            row[7] = d.d_u[(r, 1)];
            if nv == 15 {
                row[14] = d.d_h[r] * dh_dt;
            }
        }
        grad.fill(0.0);
        *obj = 0.0;
        if let Some((s, goal)) = &self.cost {
            let (mut g0, mut g1) = ([0.0; 6], [0.0; 6]);
            let s0 = baseline_state_cost(s, goal, &z[0..6], &mut g0);
            let s1 = baseline_state_cost(s, goal, &z[8..14], &mut g1);
            let uu = z[6] * z[6] + z[7] * z[7];
            *obj = 0.5 * h * (s0 + s1) + h * uu;
            for c in 0..6 {
                grad[c] = 0.5 * h * g0[c];
                grad[8 + c] = 0.5 * h * g1[c];
            }
            grad[6] = 2.0 * h * z[6];
            grad[7] = 2.0 * h * z[7];
            if nv == 15 {
                grad[14] = (0.5 * (s0 + s1) + uu) * dh_dt;
            }
        }
    }
}

/// The footprint (DESIGN §10) on one collocation interval: both axle points
/// outside every circle, ‖q − o‖ − R ≥ 0, at the points τ ∈ (0, 1] of the
/// interval's cubic Hermite interpolant
///   x(τ) = h₀₀ x₀ + h₁₀ h f(x₀,u) + h₀₁ x₁ + h₁₁ h f(x₁,u)
/// (τ = 1 is the node x₁; τ = ½ the Hermite–Simpson midpoint). Variables as
/// [`Interval`]: (x₀, u, x₁) and, with a free final time, T.
struct IntervalFootprint {
    vars: Vec<usize>,
    params: MachineParams,
    h: Option<f64>,
    intervals: usize,
    taus: Vec<f64>,
    obstacles: Vec<Obstacle>,
}

/// The interpolation points of [`IntervalFootprint`]: `interior` evenly spaced
/// points inside the interval, and its end node.
fn footprint_taus(interior: usize) -> Vec<f64> {
    (1..=interior + 1)
        .map(|i| i as f64 / (interior + 1) as f64)
        .collect()
}

impl IntervalFootprint {
    /// The interpolated state at τ and its Jacobian with respect to the
    /// local variables (6 × nv, row-major).
    fn point(&self, z: &[f64], tau: f64, jac: &mut [f64]) -> State {
        interval_point(&self.params, self.h, self.intervals, z, tau, jac)
    }
}

/// The state at τ ∈ [0, 1] inside the interval whose local variables are
/// `z` = (x_k, u_k, x_{k+1}[, T]) (cubic Hermite on the nodes and their
/// derivatives), and its Jacobian with respect to them (6 × nv, row-major;
/// nv = 15 with T, h = T / `intervals`, else h fixed).
pub(crate) fn interval_point(
    p: &MachineParams,
    fixed_h: Option<f64>,
    intervals: usize,
    z: &[f64],
    tau: f64,
    jac: &mut [f64],
) -> State {
    let nv = z.len();
    let x0 = State::from_column_slice(&z[0..6]);
    let u = Control::new(z[6], z[7]);
    let x1 = State::from_column_slice(&z[8..14]);
    let (h, dh_dt) = match fixed_h {
        Some(h) => (h, 0.0),
        None => (z[14] / intervals as f64, 1.0 / intervals as f64),
    };
    let (t2, t3) = (tau * tau, tau * tau * tau);
    let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    let h10 = t3 - 2.0 * t2 + tau;
    let h01 = -2.0 * t3 + 3.0 * t2;
    let h11 = t3 - t2;
    let f0 = control::model::f_continuous(p, &x0, &u);
    let f1 = control::model::f_continuous(p, &x1, &u);
    let x = x0 * h00 + f0 * (h10 * h) + x1 * h01 + f1 * (h11 * h);
    let a0 = crate::collocation::jacobian_x(p, &x0) * (h10 * h);
    let a1 = crate::collocation::jacobian_x(p, &x1) * (h11 * h);
    let b = crate::collocation::jacobian_u() * ((h10 + h11) * h);
    let dh = (f0 * h10 + f1 * h11) * dh_dt;
    jac[..6 * nv].fill(0.0);
    for r in 0..6 {
        let row = &mut jac[r * nv..(r + 1) * nv];
        for c in 0..6 {
            row[c] = a0[(r, c)];
            row[8 + c] = a1[(r, c)];
        }
        row[r] += h00;
        row[8 + r] += h01;
        row[6] = b[(r, 0)];
        row[7] = b[(r, 1)];
        if nv == 15 {
            row[14] = dh[r];
        }
    }
    x
}

impl Element for IntervalFootprint {
    fn vars(&self) -> &[usize] {
        &self.vars
    }

    fn has_objective(&self) -> bool {
        false
    }

    fn n_cons(&self) -> usize {
        self.taus.len() * self.obstacles.len() * AxlePoint::ALL.len()
    }

    fn con_bounds(&self, lower: &mut [f64], upper: &mut [f64]) {
        lower.fill(0.0);
        upper.fill(INF);
    }

    fn eval(&self, z: &[f64], obj: &mut f64, grad: &mut [f64], g: &mut [f64], jac: &mut [f64]) {
        *obj = 0.0;
        grad.fill(0.0);
        let nv = self.vars.len();
        let mut dx = [0.0; 6 * 15];
        let mut row = 0;
        for &tau in &self.taus {
            let x = self.point(z, tau, &mut dx);
            for o in &self.obstacles {
                for point in AxlePoint::ALL {
                    // ∂h/∂(x_f, y_f, θ, β), chained through ∂x(τ)/∂z.
                    let (c, dc) = o.point_clearance(&self.params, point, &x);
                    g[row] = c;
                    let out = &mut jac[row * nv..(row + 1) * nv];
                    for (j, o) in out.iter_mut().enumerate() {
                        *o = (0..4).map(|i| dc[i] * dx[i * nv + j]).sum();
                    }
                    row += 1;
                }
            }
        }
    }
}

/// The success test at the final node: (x − x_g)² + (y − y_g)² + (θ − θ_g')² ≤ tol²
/// with θ_g' the chosen branch of the goal heading.
struct TerminalSet {
    vars: [usize; 3],
    goal: Goal,
    tolerance: f64,
}

impl Element for TerminalSet {
    fn vars(&self) -> &[usize] {
        &self.vars
    }

    fn has_objective(&self) -> bool {
        false
    }

    fn n_cons(&self) -> usize {
        1
    }

    fn con_bounds(&self, lower: &mut [f64], upper: &mut [f64]) {
        lower[0] = -INF;
        upper[0] = self.tolerance * self.tolerance;
    }

    fn eval(&self, z: &[f64], obj: &mut f64, grad: &mut [f64], g: &mut [f64], jac: &mut [f64]) {
        *obj = 0.0;
        grad.fill(0.0);
        let d = [
            z[0] - self.goal.x,
            z[1] - self.goal.y,
            z[2] - self.goal.theta,
        ];
        g[0] = d.iter().map(|v| v * v).sum();
        for i in 0..3 {
            jac[i] = 2.0 * d[i];
        }
    }
}

/// Objective T.
struct FinalTime {
    vars: [usize; 1],
}

impl Element for FinalTime {
    fn vars(&self) -> &[usize] {
        &self.vars
    }

    fn is_linear_in(&self, _local: usize) -> bool {
        true
    }

    fn n_cons(&self) -> usize {
        0
    }

    fn con_bounds(&self, _: &mut [f64], _: &mut [f64]) {}

    fn eval(&self, z: &[f64], obj: &mut f64, grad: &mut [f64], _: &mut [f64], _: &mut [f64]) {
        *obj = z[0];
        grad[0] = 1.0;
    }
}

/// Sets the model's state and control bounds on every node and interval.
fn set_model_bounds(nlp: &mut ElementNlp, p: &MachineParams, k_intervals: usize, margin: f64) {
    for k in 0..=k_intervals {
        let b = xi(k);
        for (i, max) in [
            (ix::BETA, p.beta_max),
            (ix::BETA_DOT, p.beta_dot_max),
            (ix::V, p.v_max),
        ] {
            let max = max * margin;
            nlp.z_lower[b + i] = -max;
            nlp.z_upper[b + i] = max;
        }
    }
    for k in 0..k_intervals {
        nlp.z_lower[ui(k)] = -p.beta_ddot_max;
        nlp.z_upper[ui(k)] = p.beta_ddot_max;
        nlp.z_lower[ui(k) + 1] = -p.a_max;
        nlp.z_upper[ui(k) + 1] = p.a_max;
    }
}

fn fix_state(nlp: &mut ElementNlp, k: usize, x: &State) {
    for i in 0..6 {
        nlp.z_lower[xi(k) + i] = x[i];
        nlp.z_upper[xi(k) + i] = x[i];
    }
}

/// Footprint constraints on every interval (its end node and `interior`
/// points inside), with the same variables as the interval's defects.
fn footprint_elements(
    elements: &mut Vec<Box<dyn Element>>,
    p: &MachineParams,
    obstacles: &[Obstacle],
    k_intervals: usize,
    h: Option<f64>,
    interior: usize,
) {
    if obstacles.is_empty() {
        return;
    }
    for k in 0..k_intervals {
        let mut vars: Vec<usize> = (xi(k)..xi(k) + 14).collect();
        if h.is_none() {
            vars.push(8 * k_intervals + 6);
        }
        elements.push(Box::new(IntervalFootprint {
            vars,
            params: *p,
            h,
            intervals: k_intervals,
            taus: footprint_taus(interior),
            obstacles: obstacles.to_vec(),
        }));
    }
}

/// The start state inside the model's bounds (what the plant makes of it).
pub(crate) fn admissible_start(p: &MachineParams, x: &State) -> State {
    let mut s = *x;
    control::model::clamp_state(p, &mut s);
    s
}

/// The baseline NLP of a scenario with the goal heading on branch `theta_goal`.
pub fn baseline_nlp(
    p: &MachineParams,
    sc: &Scenario,
    s: &BaselineSettings,
    theta_goal: f64,
) -> ElementNlp {
    let k_intervals = (s.horizon / s.dt).round() as usize;
    let n = 8 * k_intervals + 6;
    let goal = Goal::new(sc.goal.x, sc.goal.y, theta_goal);
    let mut elements: Vec<Box<dyn Element>> = Vec::new();
    for k in 0..k_intervals {
        elements.push(Box::new(Interval {
            vars: (xi(k)..xi(k) + 14).collect(),
            params: *p,
            h: Some(s.dt),
            intervals: k_intervals,
            cost: Some((*s, goal)),
        }));
    }
    footprint_elements(
        &mut elements,
        p,
        &sc.obstacles,
        k_intervals,
        Some(s.dt),
        s.obstacle_samples,
    );
    let mut nlp = ElementNlp::new(n, elements, s.hessian);
    set_model_bounds(&mut nlp, p, k_intervals, s.state_margin);
    fix_state(&mut nlp, 0, &admissible_start(p, &sc.start));
    fix_state(
        &mut nlp,
        k_intervals,
        &State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0),
    );
    nlp
}

/// A straight-line initial guess from the start to `goal` over `k` intervals
/// of `h`: pose interpolated, speed and rates from the differences, moving
/// during the first `fraction` of the horizon, then resting.
fn straight_guess(
    sc: &Scenario,
    goal: &Goal,
    k_intervals: usize,
    h: f64,
    fraction: f64,
    reverse: bool,
) -> Vec<f64> {
    let mut z = vec![0.0; 8 * k_intervals + 6];
    let x0 = sc.start;
    let moving = ((k_intervals as f64 * fraction).round() as usize).max(1);
    let dist = (goal.x - x0[0]).hypot(goal.y - x0[1]);
    let speed = dist / (moving as f64 * h) * if reverse { -1.0 } else { 1.0 };
    for k in 0..=k_intervals {
        let s = (k.min(moving)) as f64 / moving as f64;
        let b = xi(k);
        z[b] = x0[0] + s * (goal.x - x0[0]);
        z[b + 1] = x0[1] + s * (goal.y - x0[1]);
        z[b + 2] = x0[2] + s * (goal.theta - x0[2]);
        z[b + ix::V] = if k < moving && k > 0 {
            speed.clamp(-0.9, 0.9)
        } else {
            0.0
        };
    }
    z
}

/// The goal heading's branch nearest to `theta` and the next nearest.
fn heading_branches(theta: f64, goal_theta: f64) -> [f64; 2] {
    let near = theta + wrap_angle(goal_theta - theta);
    let other = if near > theta {
        near - 2.0 * PI
    } else {
        near + 2.0 * PI
    };
    [near, other]
}

pub(crate) fn ipopt_options(tol: f64, max_iter: i32) -> Vec<(&'static str, OptValue)> {
    vec![
        ("tol", OptValue::Num(tol)),
        ("acceptable_tol", OptValue::Num(tol * 100.0)),
        ("max_iter", OptValue::Int(max_iter)),
        ("mu_strategy", OptValue::Str("adaptive".into())),
        (
            "fixed_variable_treatment",
            OptValue::Str("make_parameter".into()),
        ),
    ]
}

pub(crate) fn plan_from(z: &[f64], k_intervals: usize) -> (Vec<State>, Vec<Control>) {
    let states = (0..=k_intervals)
        .map(|k| State::from_column_slice(&z[xi(k)..xi(k) + 6]))
        .collect();
    let controls = (0..k_intervals)
        .map(|k| Control::new(z[ui(k)], z[ui(k) + 1]))
        .collect();
    (states, controls)
}

/// Solves the baseline (DESIGN §8): from a straight-line guess on the nearest
/// heading branch, and also on the other one when the goal heading is more
/// than 135° away; when a circle blocks the straight line, from routes around
/// the obstacles first. The lower objective among feasible solutions wins.
pub fn solve_baseline(p: &MachineParams, sc: &Scenario, s: &BaselineSettings) -> Plan {
    let mut solve_time = Duration::ZERO;
    let k_intervals = (s.horizon / s.dt).round() as usize;
    let start_state = admissible_start(p, &sc.start);
    // (goal-heading branch, initial guess), tried in order.
    let mut candidates: Vec<(f64, Vec<f64>)> = Vec::new();
    // A straight line through a circle leaves IPOPT infeasible: with the
    // way blocked, start on the two shortest routes around ([`crate::routes`]),
    // driven within the horizon and then resting at the goal.
    if crate::routes::straight_blocked(sc, 0.0) {
        for route in crate::routes::side_routes(sc, 2) {
            let g = crate::routes::route_guess(p, sc, &route, false, 0.6 * p.v_max, 0.5 * p.a_max);
            if g.duration >= s.horizon {
                continue;
            }
            let end = g.states.last().expect("non-empty")[ix::THETA];
            let held = Guess {
                duration: s.horizon,
                ..g
            };
            let mut z0 = guess_vector(&held, k_intervals);
            z0.pop();
            candidates.push((end + wrap_angle(sc.goal.theta - end), z0));
        }
    }
    let branches = heading_branches(sc.start[ix::THETA], sc.goal.theta);
    let far = wrap_angle(sc.goal.theta - sc.start[ix::THETA]).abs() > 0.75 * PI;
    let routes = candidates.len();
    for &theta_goal in branches.iter().take(if far { 2 } else { 1 }) {
        let goal = Goal::new(sc.goal.x, sc.goal.y, theta_goal);
        candidates.push((
            theta_goal,
            straight_guess(sc, &goal, k_intervals, s.dt, 0.6, false),
        ));
    }
    let mut best: Option<Plan> = None;
    for (i, (theta_goal, mut z0)) in candidates.into_iter().enumerate() {
        // Straight guesses only when no route guess gave a feasible plan.
        if i >= routes && routes > 0 && best.as_ref().is_some_and(|b| !rank(b).0) {
            break;
        }
        let mut nlp = baseline_nlp(p, sc, s, theta_goal);
        z0[..6].copy_from_slice(start_state.as_slice());
        let r = ipopt::solve(&mut nlp, &z0, &ipopt_options(s.tol, s.max_iter));
        solve_time += r.solve_time;
        let violation = nlp.max_violation(&r.z);
        let (states, controls) = plan_from(&r.z, k_intervals);
        let plan = Plan {
            status: r.status,
            states,
            controls,
            dt: s.dt,
            objective: r.objective,
            violation,
            solve_time: Duration::ZERO,
        };
        let better = match &best {
            None => true,
            Some(b) => rank(&plan) < rank(b),
        };
        if better {
            best = Some(plan);
        }
    }
    let mut plan = best.expect("at least one guess solved");
    plan.solve_time = solve_time;
    plan
}

/// Orders plans: feasible before infeasible, then by objective.
fn rank(p: &Plan) -> (bool, f64) {
    let feasible = p.violation < 1e-4 && p.objective.is_finite();
    (
        !feasible,
        if p.objective.is_finite() {
            p.objective
        } else {
            f64::INFINITY
        },
    )
}

/// Replays open-loop controls on the ideal model (RK4 + the clamping rule,
/// Δt = `dt`), then holds zero acceleration until `duration`; returns the
/// states at every step, x(0) first.
pub fn replay(
    p: &MachineParams,
    start: &State,
    controls: &[Control],
    dt: f64,
    duration: f64,
) -> Vec<State> {
    let steps = (duration / dt).round() as usize;
    let mut x = *start;
    let mut out = Vec::with_capacity(steps + 1);
    out.push(x);
    for k in 0..steps {
        let u = controls.get(k).copied().unwrap_or_else(Control::zeros);
        // After the plan ends, brake to rest within the bounds.
        let u = if k >= controls.len() {
            Control::new(
                (-x[ix::BETA_DOT] / dt).clamp(-p.beta_ddot_max, p.beta_ddot_max),
                (-x[ix::V] / dt).clamp(-p.a_max, p.a_max),
            )
        } else {
            u
        };
        x = env_step(p, &x, &u, dt);
        out.push(x);
    }
    out
}

/// Settings of the min-time problem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MinTimeSettings {
    /// Collocation intervals K (h = T / K).
    pub intervals: usize,
    pub tolerance: f64,
    pub hessian: HessianKind,
    pub tol: f64,
    pub max_iter: i32,
    /// Bounds of T [s].
    pub t_min: f64,
    pub t_max: f64,
    /// Footprint constraint points inside each interval (besides its nodes).
    pub obstacle_samples: usize,
    /// Routes around the obstacles tried as initial guesses.
    pub max_routes: usize,
    /// Solves per scenario at most.
    pub max_attempts: usize,
    /// IPOPT's CPU-time limit per solve [s].
    pub max_solve_seconds: f64,
}

impl Default for MinTimeSettings {
    fn default() -> Self {
        Self {
            intervals: 50,
            tolerance: 0.1,
            hessian: HessianKind::FiniteDifference,
            tol: 1e-6,
            max_iter: 1000,
            t_min: 0.2,
            t_max: 60.0,
            obstacle_samples: 1,
            max_routes: 4,
            max_attempts: 12,
            max_solve_seconds: 20.0,
        }
    }
}

/// The min-time NLP: minimise T s.t. the model (collocated with h = T/K), all
/// bounds, obstacles and the success test of DESIGN §7 at T, with the goal
/// heading on branch `theta_goal`. The test is held slightly tighter
/// (0.999 × tolerance) so the replayed trajectory passes it too.
pub fn min_time_nlp(
    p: &MachineParams,
    sc: &Scenario,
    s: &MinTimeSettings,
    theta_goal: f64,
) -> ElementNlp {
    let mut footprint: Vec<Box<dyn Element>> = Vec::new();
    footprint_elements(
        &mut footprint,
        p,
        &sc.obstacles,
        s.intervals,
        None,
        s.obstacle_samples,
    );
    min_time_with(
        p,
        &sc.start,
        &Goal::new(sc.goal.x, sc.goal.y, theta_goal),
        s,
        0.999 * s.tolerance,
        footprint,
    )
}

/// The min-time NLP from `start` to `goal` (its heading on the branch
/// wanted) within `tolerance`, kept off the world by `footprint` (elements
/// over (x_k, u_k, x_{k+1}, T), as [`footprint_elements`] makes them).
pub(crate) fn min_time_with(
    p: &MachineParams,
    start: &State,
    goal: &Goal,
    s: &MinTimeSettings,
    tolerance: f64,
    footprint: Vec<Box<dyn Element>>,
) -> ElementNlp {
    let k_intervals = s.intervals;
    let n = 8 * k_intervals + 7;
    let t_index = n - 1;
    let mut elements: Vec<Box<dyn Element>> = Vec::new();
    for k in 0..k_intervals {
        let mut vars: Vec<usize> = (xi(k)..xi(k) + 14).collect();
        vars.push(t_index);
        elements.push(Box::new(Interval {
            vars,
            params: *p,
            h: None,
            intervals: k_intervals,
            cost: None,
        }));
    }
    elements.extend(footprint);
    let kk = xi(k_intervals);
    elements.push(Box::new(TerminalSet {
        vars: [kk, kk + 1, kk + 2],
        goal: *goal,
        tolerance,
    }));
    elements.push(Box::new(FinalTime { vars: [t_index] }));
    let mut nlp = ElementNlp::new(n, elements, s.hessian);
    set_model_bounds(&mut nlp, p, k_intervals, 1.0);
    fix_state(&mut nlp, 0, &admissible_start(p, start));
    nlp.z_lower[t_index] = s.t_min;
    nlp.z_upper[t_index] = s.t_max;
    nlp
}

pub(crate) fn guess_vector(g: &Guess, k_intervals: usize) -> Vec<f64> {
    let mut z = vec![0.0; 8 * k_intervals + 7];
    let h = g.duration / k_intervals as f64;
    let sample = |t: f64| -> (State, Control) {
        let s = (t / g.dt).clamp(0.0, (g.states.len() - 1) as f64);
        let i = (s.floor() as usize).min(g.states.len().saturating_sub(2));
        let f = s - i as f64;
        let x = g.states[i] * (1.0 - f) + g.states[(i + 1).min(g.states.len() - 1)] * f;
        let u = g.controls.get(i).copied().unwrap_or_else(Control::zeros);
        (x, u)
    };
    for k in 0..=k_intervals {
        let (x, u) = sample(k as f64 * h);
        z[xi(k)..xi(k) + 6].copy_from_slice(x.as_slice());
        if k < k_intervals {
            z[ui(k)] = u[0];
            z[ui(k) + 1] = u[1];
        }
    }
    z[8 * k_intervals + 6] = g.duration;
    z
}

/// The min-time result: the best feasible plan over all initial guesses.
#[derive(Debug, Clone)]
pub struct MinTime {
    pub plan: Option<Plan>,
    /// T* [s].
    pub time: f64,
    pub solve_time: Duration,
    pub attempts: usize,
}

/// Initial guesses of the min-time problem, most promising first: with
/// obstacles, routes around each side of them ([`crate::routes`]), driven
/// forward and, where the start or goal heading suits it, in reverse; then the
/// callers' guesses (other methods' trajectories); then, unless a circle is
/// in the way, straight lines forward and in reverse on both heading
/// branches. Each route guess carries the
/// route's length over v_max, a lower estimate of its time.
pub fn min_time_guesses(
    p: &MachineParams,
    sc: &Scenario,
    s: &MinTimeSettings,
    guesses: &[Guess],
) -> Vec<(Guess, f64)> {
    let mut all: Vec<(Guess, f64)> = Vec::new();
    for (i, route) in crate::routes::side_routes(sc, s.max_routes)
        .iter()
        .enumerate()
    {
        let estimate = route.length / p.v_max;
        all.push((
            crate::routes::route_guess(p, sc, route, false, 0.8 * p.v_max, 0.8 * p.a_max),
            estimate,
        ));
        // Reverse along the two shortest routes when either end faces backwards.
        let pts = &route.points;
        let (n, m) = (pts.len(), pts.len().saturating_sub(1));
        if i < 2 && n >= 2 {
            let t0 = (pts[1][1] - pts[0][1]).atan2(pts[1][0] - pts[0][0]);
            let t1 = (pts[m][1] - pts[m - 1][1]).atan2(pts[m][0] - pts[m - 1][0]);
            let backwards =
                |heading: f64, tangent: f64| wrap_angle(heading - tangent).abs() > 0.5 * PI;
            if backwards(sc.start[ix::THETA], t0) || backwards(sc.goal.theta, t1) {
                all.push((
                    crate::routes::route_guess(p, sc, route, true, 0.8 * p.v_max, 0.8 * p.a_max),
                    estimate,
                ));
            }
        }
    }
    all.extend(guesses.iter().cloned().map(|g| (g, 0.0)));
    if crate::routes::straight_blocked(sc, 0.0) && all.len() > guesses.len() {
        return all;
    }
    let dist = (sc.goal.x - sc.start[0]).hypot(sc.goal.y - sc.start[1]);
    let t_line = (dist / 0.7).max(3.0);
    for reverse in [false, true] {
        for &theta in &heading_branches(sc.start[ix::THETA], sc.goal.theta) {
            let goal = Goal::new(sc.goal.x, sc.goal.y, theta);
            let k = 50;
            let z = straight_guess(sc, &goal, k, t_line / k as f64, 1.0, reverse);
            let (states, controls) = plan_from(&z, k);
            all.push((
                Guess {
                    states,
                    controls,
                    dt: t_line / k as f64,
                    duration: t_line,
                },
                0.0,
            ));
        }
    }
    all
}

/// Solves min-time from [`min_time_guesses`] (at most `max_attempts` solves;
/// a route whose length alone takes longer than the best time found is
/// skipped) and keeps the shortest feasible T.
pub fn solve_min_time(
    p: &MachineParams,
    sc: &Scenario,
    s: &MinTimeSettings,
    guesses: &[Guess],
) -> MinTime {
    let mut solve_time = Duration::ZERO;
    let all = min_time_guesses(p, sc, s, guesses);
    let mut best: Option<(f64, Plan)> = None;
    let mut attempts = 0;
    for (g, estimate) in &all {
        if g.duration.is_nan() || g.duration <= 0.0 || g.states.len() < 2 {
            continue;
        }
        if attempts >= s.max_attempts || best.as_ref().is_some_and(|(bt, _)| *estimate > *bt) {
            continue;
        }
        attempts += 1;
        let (plan, time) = min_time_attempt(p, sc, s, g);
        solve_time += time;
        let Some(plan) = plan else {
            continue;
        };
        let t = plan.objective;
        if best.as_ref().is_none_or(|(bt, _)| t < *bt) {
            best = Some((t, plan));
        }
    }
    match best {
        Some((t, mut plan)) => {
            plan.solve_time = solve_time;
            MinTime {
                plan: Some(plan),
                time: t,
                solve_time,
                attempts,
            }
        }
        None => MinTime {
            plan: None,
            time: f64::NAN,
            solve_time,
            attempts,
        },
    }
}

/// One min-time solve from guess `g` (goal heading on the branch nearest the
/// guess's final heading): the plan when it is feasible (bound and constraint
/// violation < 1e-5; `objective` is T), and the time spent. With the
/// environment variable `WLNAV_MT_DEBUG` set, each solve is logged to stderr.
pub fn min_time_attempt(
    p: &MachineParams,
    sc: &Scenario,
    s: &MinTimeSettings,
    g: &Guess,
) -> (Option<Plan>, Duration) {
    let end = g.states[((g.duration / g.dt).round() as usize).min(g.states.len() - 1)];
    let theta_goal = end[ix::THETA] + wrap_angle(sc.goal.theta - end[ix::THETA]);
    let mut nlp = min_time_nlp(p, sc, s, theta_goal);
    let mut z0 = guess_vector(g, s.intervals);
    let x0 = admissible_start(p, &sc.start);
    z0[..6].copy_from_slice(x0.as_slice());
    let n = z0.len();
    z0[n - 1] = z0[n - 1].clamp(s.t_min, s.t_max);
    let mut options = ipopt_options(s.tol, s.max_iter);
    options.push(("max_cpu_time", OptValue::Num(s.max_solve_seconds)));
    let r = ipopt::solve(&mut nlp, &z0, &options);
    let violation = nlp.max_violation(&r.z);
    if std::env::var_os("WLNAV_MT_DEBUG").is_some() {
        eprintln!(
            "min-time {}: guess T {:.2} -> {} T {:.3} violation {:.1e} in {:.2} s",
            sc.name,
            g.duration,
            r.status.name(),
            r.z[n - 1],
            violation,
            r.solve_time.as_secs_f64()
        );
    }
    if violation.is_nan() || violation >= 1e-5 || !r.objective.is_finite() {
        return (None, r.solve_time);
    }
    let t = r.z[n - 1];
    let (states, controls) = plan_from(&r.z, s.intervals);
    let plan = Plan {
        status: r.status,
        states,
        controls,
        dt: t / s.intervals as f64,
        objective: t,
        violation,
        solve_time: r.solve_time,
    };
    (Some(plan), r.solve_time)
}

/// Goal distance of the last state of a plan (for tests and diagnostics).
pub fn final_distance(plan: &Plan, goal: &Goal) -> f64 {
    plan.states
        .last()
        .map_or(f64::INFINITY, |x| goal_distance(x, goal))
}
