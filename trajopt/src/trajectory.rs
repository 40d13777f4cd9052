//! The trajectory optimiser `wlnav-sim` plans with (issue 42): the min-time
//! problem of the bound ([`crate::ocp`], Hermite–Simpson collocation of paper
//! eq. 5 with every bound, solved by IPOPT) from the planner's start to its
//! goal, warm-started from the route (the search's path and shot, or the
//! open way's roll-out), with the world's rows ([`World::row`], the MPC's and
//! the envelope's) as its footprint: each interval keeps its outline circles
//! off the features the warm start passes near, by the route's margins plus
//! [`TrajectorySettings::margin`]. The solution is checked against the whole
//! world before it is used.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use control::model::{ix, wrap_angle, Control, Goal, MachineParams, State};
use control::planner::world::CheckedWorld;
use control::planner::{PathPose, TrajectoryFailure, TrajectoryOptimiser};
use control::site::index::Near;
use control::site::outline::MAX_OUTLINE_CIRCLES;
use control::world::{Target, World};

use crate::guess::Guess;
use crate::ipopt::{self, OptValue};
use crate::nlp::{Element, HessianKind, INF};
use crate::ocp::{self, MinTimeSettings};

/// How the trajectory is optimised (`wlnavd`'s `[trajectory]`; used where
/// `[navigator] trajectory = true`). `Default` gives the measured best.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrajectorySettings {
    /// Collocation intervals.
    pub intervals: usize,
    /// How near the goal the trajectory ends (position and heading, the
    /// success test's norm) [m].
    pub tolerance: f64,
    /// IPOPT's iterations at most: the solve's budget in work, the same on
    /// every machine and load (an evaluation repeats), sized so that plans
    /// stay within 200 ms at p99 here (measured: `docs/decisions.md`). A solve
    /// cut there gives its last iterate if that passes the checks a solution
    /// passes; else the route stays.
    pub max_iterations: u32,
    /// IPOPT's CPU-time limit [s], a backstop on slower or loaded machines
    /// (cut there as at `max_iterations`).
    pub max_solve_seconds: f64,
    /// A feature is a row of an interval when the warm start passes it
    /// within this much beyond the margin [m].
    pub reach: f64,
    /// Rows per interval point at most (the nearest).
    pub max_rows: usize,
    /// The warm start's speed, as a fraction of v_max.
    pub cruise: f64,
    /// What the trajectory keeps beyond the route's margins [m]: the MPC
    /// tracking it at speed and the envelope's stop check need room the
    /// route's followers did not (measured: `docs/global-layer.md`). Less
    /// where the start or the goal lies nearer (a bucket at a pile face):
    /// the trajectory must end there.
    pub margin: f64,
    /// The share of β̇_max the trajectory may use between its ends: planned
    /// at the full rate, the tracking MPC has none left to catch up a lag,
    /// and a machine late into a turn at full articulation ends off the goal
    /// (measured: `docs/decisions.md`).
    pub beta_dot_fraction: f64,
}

impl Default for TrajectorySettings {
    fn default() -> Self {
        Self {
            intervals: 50,
            tolerance: 0.01,
            max_iterations: 60,
            max_solve_seconds: 0.5,
            reach: 1.5,
            max_rows: 6,
            cruise: 0.8,
            margin: 0.2,
            beta_dot_fraction: 0.9,
        }
    }
}

/// Rows per interval point at most a configuration may ask for (each is a
/// constraint per interval point: more only slows the solve).
const MAX_ROWS: usize = 64;

/// A setting out of its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("trajectory.{key}: {message}")]
pub struct SettingsError {
    pub key: &'static str,
    pub message: &'static str,
}

impl TrajectorySettings {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let err = |key, message| Err(SettingsError { key, message });
        if !(4..=200).contains(&self.intervals) {
            return err("intervals", "must be 4 to 200");
        }
        let positive = [
            ("tolerance", self.tolerance),
            ("max_solve_seconds", self.max_solve_seconds),
            ("reach", self.reach),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return err(key, "must be finite and > 0");
            }
        }
        if !(1..=10_000).contains(&self.max_iterations) {
            return err("max_iterations", "must be 1 to 10000");
        }
        if !(1..=MAX_ROWS).contains(&self.max_rows) {
            return err("max_rows", "must be 1 to 64");
        }
        if !(self.cruise.is_finite() && self.cruise > 0.0 && self.cruise <= 1.0) {
            return err("cruise", "must be in (0, 1]");
        }
        if !(self.margin.is_finite() && self.margin >= 0.0) {
            return err("margin", "must be finite and >= 0");
        }
        if !(self.beta_dot_fraction.is_finite()
            && self.beta_dot_fraction > 0.0
            && self.beta_dot_fraction <= 1.0)
        {
            return err("beta_dot_fraction", "must be in (0, 1]");
        }
        Ok(())
    }
}

/// The options file IPOPT reads: none (an empty name reads nothing and
/// prints nothing; a path, even `/dev/null`, is announced on stdout at every
/// solve).
const NO_OPTIONS_FILE: &str = "";

/// Interval points the footprint is checked at (τ in (0, 1]).
const TAUS: [f64; 2] = [0.5, 1.0];
/// Points per interval written out (evenly spaced in time).
const PATH_POINTS: usize = 3;

/// [`TrajectoryOptimiser`] over IPOPT.
pub struct IpoptTrajectory {
    params: MachineParams,
    settings: TrajectorySettings,
}

impl IpoptTrajectory {
    pub fn new(params: MachineParams, settings: TrajectorySettings) -> Self {
        Self { params, settings }
    }
}

/// One outline circle kept off one target at one point of an interval.
#[derive(Debug, Clone, Copy)]
struct Row {
    tau: f64,
    circle: usize,
    target: Target,
    margin: f64,
}

/// An interval's footprint: its rows, on (x_k, u_k, x_{k+1}, T).
struct WorldFootprint {
    vars: Vec<usize>,
    params: MachineParams,
    intervals: usize,
    world: Arc<World>,
    rows: Vec<Row>,
}

impl Element for WorldFootprint {
    fn vars(&self) -> &[usize] {
        &self.vars
    }

    fn has_objective(&self) -> bool {
        false
    }

    fn n_cons(&self) -> usize {
        self.rows.len()
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
        let mut at = f64::NAN;
        let mut x = State::zeros();
        for (r, row) in self.rows.iter().enumerate() {
            if row.tau != at {
                x = ocp::interval_point(&self.params, None, self.intervals, z, row.tau, &mut dx);
                at = row.tau;
            }
            let (h, dh) = self.world.row(&x, row.circle, row.target);
            g[r] = h - row.margin;
            let out = &mut jac[r * nv..(r + 1) * nv];
            for (j, o) in out.iter_mut().enumerate() {
                *o = (0..4).map(|i| dh[i] * dx[i * nv + j]).sum();
            }
        }
    }
}

/// The route as a time-stamped warm start: the path's poses then the shot's
/// states, driven at `cruise` with the acceleration bound from and into
/// every stop (start, cusps, end), resampled on `k` intervals.
fn route_guess(
    p: &MachineParams,
    start: &State,
    path: &[PathPose],
    shot: &[State],
    cruise: f64,
    k: usize,
) -> Option<Guess> {
    // (x, y, θ, β, direction)
    let mut poses: Vec<[f64; 5]> = Vec::with_capacity(path.len() + shot.len() + 1);
    let dir_of = |v: f64, last: f64| {
        if v.abs() > control::model::REACH_SPEED {
            v.signum()
        } else {
            last
        }
    };
    let mut last_dir = dir_of(start[ix::V], 1.0);
    poses.push([
        start[ix::X],
        start[ix::Y],
        start[ix::THETA],
        start[ix::BETA],
        last_dir,
    ]);
    for q in path {
        last_dir = if q.direction == 0 {
            last_dir
        } else {
            q.direction as f64
        };
        poses.push([q.x, q.y, q.theta, q.beta, last_dir]);
    }
    for (i, x) in shot.iter().enumerate() {
        let v = shot.get(i + 1).unwrap_or(x)[ix::V];
        last_dir = dir_of(v, last_dir);
        poses.push([x[ix::X], x[ix::Y], x[ix::THETA], x[ix::BETA], last_dir]);
    }
    poses.dedup_by(|b, a| (b[0] - a[0]).hypot(b[1] - a[1]) < 1e-6);
    if poses.len() < 2 {
        return None;
    }
    // Arc length, and the stops: where the direction changes.
    let n = poses.len();
    let mut s = vec![0.0; n];
    for i in 1..n {
        s[i] = s[i - 1] + (poses[i][0] - poses[i - 1][0]).hypot(poses[i][1] - poses[i - 1][1]);
    }
    let mut stops = vec![0.0];
    for i in 1..n - 1 {
        if poses[i][4] != poses[i + 1][4] {
            stops.push(s[i]);
        }
    }
    stops.push(s[n - 1]);
    let v_top = cruise * p.v_max;
    let a = 0.8 * p.a_max;
    let speed = |si: f64| {
        let j = stops
            .partition_point(|&b| b <= si)
            .clamp(1, stops.len() - 1);
        let (from, to) = (si - stops[j - 1], stops[j] - si);
        v_top
            .min((2.0 * a * (from + 0.02)).sqrt())
            .min((2.0 * a * (to + 0.02)).sqrt())
    };
    let mut t = vec![0.0; n];
    for i in 1..n {
        let v = 0.5 * (speed(s[i - 1]) + speed(s[i]));
        t[i] = t[i - 1] + (s[i] - s[i - 1]) / v.max(0.05);
    }
    let duration = t[n - 1];
    if !(duration.is_finite() && duration > 0.0) {
        return None;
    }
    let h = duration / k as f64;
    let mut theta_prev = start[ix::THETA];
    let mut states = Vec::with_capacity(k + 1);
    for m in 0..=k {
        let tm = (m as f64 * h).min(duration);
        let i = t.partition_point(|&ti| ti <= tm).clamp(1, n - 1);
        let f = ((tm - t[i - 1]) / (t[i] - t[i - 1]).max(1e-9)).clamp(0.0, 1.0);
        let (a0, a1) = (&poses[i - 1], &poses[i]);
        let lerp = |c: usize| a0[c] + f * (a1[c] - a0[c]);
        // Headings unwrapped along the route.
        let th0 = theta_prev + wrap_angle(a0[2] - theta_prev);
        let th = th0 + f * wrap_angle(a1[2] - a0[2]);
        theta_prev = th;
        let v = a1[4] * speed(s[i - 1] + f * (s[i] - s[i - 1]));
        let beta = lerp(3).clamp(-p.beta_max, p.beta_max);
        states.push(State::new(lerp(0), lerp(1), th, beta, 0.0, v));
    }
    states[0] = *start;
    states[k][ix::V] = 0.0;
    for m in 0..k {
        let bd = (states[m + 1][ix::BETA] - states[m][ix::BETA]) / h;
        states[m][ix::BETA_DOT] = bd.clamp(-p.beta_dot_max, p.beta_dot_max);
    }
    states[0][ix::BETA_DOT] = start[ix::BETA_DOT];
    let controls = (0..k)
        .map(|m| {
            let dbd = (states[m + 1][ix::BETA_DOT] - states[m][ix::BETA_DOT]) / h;
            let dv = (states[m + 1][ix::V] - states[m][ix::V]) / h;
            Control::new(
                dbd.clamp(-p.beta_ddot_max, p.beta_ddot_max),
                dv.clamp(-p.a_max, p.a_max),
            )
        })
        .collect();
    Some(Guess {
        states,
        controls,
        dt: h,
        duration,
    })
}

/// The rows of interval `k` at the warm start `z`: per point and outline
/// circle, the targets it passes within `reach` beyond its margin, the
/// nearest `max_rows` per point.
fn interval_rows(
    p: &MachineParams,
    world: &World,
    margins: &[f64; MAX_OUTLINE_CIRCLES],
    s: &TrajectorySettings,
    z: &[f64],
    near: &mut [Near],
) -> Vec<Row> {
    let mut rows = Vec::new();
    let mut dx = [0.0; 6 * 15];
    for &tau in &TAUS {
        let x = ocp::interval_point(p, None, s.intervals, z, tau, &mut dx);
        let placed = world.place(&x);
        let mut here: Vec<(f64, Row)> = Vec::new();
        for (i, c) in placed[..world.outline().len()].iter().enumerate() {
            let m = margins[i];
            let mut consider = |target: Target| {
                let h = world.row(&x, i, target).0 - m;
                if h < s.reach {
                    here.push((
                        h,
                        Row {
                            tau,
                            circle: i,
                            target,
                            margin: m,
                        },
                    ));
                }
            };
            for j in 0..world.circles().len() {
                consider(Target::Circle(j));
            }
            if world.site().is_some() {
                let k = world
                    .features_near(c.center, s.reach + c.radius + m, near)
                    .unwrap_or(near.len());
                for nr in &near[..k] {
                    consider(Target::Feature(nr.feature));
                }
                consider(Target::Bounds);
            }
        }
        here.sort_by(|a, b| a.0.total_cmp(&b.0));
        rows.extend(here.into_iter().take(s.max_rows).map(|(_, r)| r));
    }
    rows
}

/// What each outline circle keeps along the trajectory: the route's margin
/// `route` plus `extra`, the extra cut to what the endpoints leave (the
/// trajectory starts and ends there: a goal at a pile face, a bucket 0.3 m
/// from it, would otherwise make the problem infeasible), less 2 cm for the
/// goal's tolerance. The route's margin itself is never cut.
fn kept_margins(
    world: &World,
    route: &[f64; MAX_OUTLINE_CIRCLES],
    extra: f64,
    endpoints: &[State],
) -> [f64; MAX_OUTLINE_CIRCLES] {
    const ENDPOINT_SLACK: f64 = 0.02;
    let mut margins = *route;
    for (i, m) in margins.iter_mut().enumerate().take(world.outline().len()) {
        let mut e = extra;
        for x in endpoints {
            let c = world.place(x)[i];
            let cutoff = route[i] + extra + ENDPOINT_SLACK;
            let clearance = world.disc_clearance(c.center, c.radius, cutoff);
            e = e.min(clearance - route[i] - ENDPOINT_SLACK);
        }
        *m += e.max(0.0);
    }
    margins
}

/// Whether every point of the trajectory (`PATH_POINTS` per interval and the
/// nodes) keeps the margins, less 1 cm of slack for the solver's tolerance.
fn keeps_margins(
    p: &MachineParams,
    world: &World,
    margins: &[f64; MAX_OUTLINE_CIRCLES],
    z: &[f64],
    k: usize,
) -> bool {
    let mut m = *margins;
    for v in &mut m {
        *v -= 0.01;
    }
    let mut dx = [0.0; 6 * 15];
    (0..k).all(|i| {
        let local = interval_vars(z, i, k);
        (0..=4).all(|j| {
            let x = ocp::interval_point(p, None, k, &local, j as f64 / 4.0, &mut dx);
            world.excess(&x, &m, 0.0).is_none()
        })
    })
}

/// Interval `i`'s local variables (x_i, u_i, x_{i+1}, T) out of z.
fn interval_vars(z: &[f64], i: usize, k: usize) -> [f64; 15] {
    let mut local = [0.0; 15];
    local[..14].copy_from_slice(&z[ocp::xi(i)..ocp::xi(i) + 14]);
    local[14] = z[8 * k + 6];
    local
}

impl TrajectoryOptimiser for IpoptTrajectory {
    fn optimise(
        &mut self,
        checked: &CheckedWorld,
        start: &State,
        goal: &Goal,
        path: &[PathPose],
        shot: &[State],
        out: &mut Vec<State>,
    ) -> Result<f64, TrajectoryFailure> {
        let t = self.solve(checked, start, goal, path, shot, out)?;
        Ok(t / (PATH_POINTS * self.settings.intervals) as f64)
    }
}

impl IpoptTrajectory {
    /// The trajectory's duration, or why there is none.
    fn solve(
        &self,
        checked: &CheckedWorld,
        start: &State,
        goal: &Goal,
        path: &[PathPose],
        shot: &[State],
        out: &mut Vec<State>,
    ) -> Result<f64, TrajectoryFailure> {
        let p = &self.params;
        let s = &self.settings;
        let k = s.intervals;
        let start = ocp::admissible_start(p, start);
        let guess = route_guess(p, &start, path, shot, s.cruise, k)
            .ok_or(TrajectoryFailure::NoWarmStart)?;
        let end = guess.states[k];
        let theta_goal = end[ix::THETA] + wrap_angle(goal.theta - end[ix::THETA]);
        let world = Arc::new(checked.world().clone());
        let at_goal = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
        let margins = kept_margins(
            &world,
            &checked.circle_margins(),
            s.margin,
            &[start, at_goal],
        );
        let mut z0 = ocp::guess_vector(&guess, k);
        z0[..6].copy_from_slice(start.as_slice());
        let mt = MinTimeSettings {
            intervals: k,
            hessian: HessianKind::FiniteDifference,
            t_min: 0.2,
            t_max: (3.0 * guess.duration).max(5.0),
            ..MinTimeSettings::default()
        };
        z0[8 * k + 6] = guess.duration.clamp(mt.t_min, mt.t_max);
        let mut near = vec![Near::default(); 64];
        let mut footprint: Vec<Box<dyn Element>> = Vec::new();
        for i in 0..k {
            let rows = interval_rows(p, &world, &margins, s, &interval_vars(&z0, i, k), &mut near);
            if rows.is_empty() {
                continue;
            }
            let mut vars: Vec<usize> = (ocp::xi(i)..ocp::xi(i) + 14).collect();
            vars.push(8 * k + 6);
            footprint.push(Box::new(WorldFootprint {
                vars,
                params: *p,
                intervals: k,
                world: world.clone(),
                rows,
            }));
        }
        let goal = Goal::new(goal.x, goal.y, theta_goal);
        let mut nlp = ocp::min_time_with(p, &start, &goal, &mt, s.tolerance, footprint);
        // At rest at the goal, the articulation still: the machine stops
        // there (the bound's problem only asks for the pose).
        for i in [ix::BETA_DOT, ix::V] {
            nlp.z_lower[ocp::xi(k) + i] = 0.0;
            nlp.z_upper[ocp::xi(k) + i] = 0.0;
        }
        // The articulation rate between the ends within its share (the ends
        // are the start's and the goal's own).
        for i in 1..k {
            nlp.z_lower[ocp::xi(i) + ix::BETA_DOT] *= s.beta_dot_fraction;
            nlp.z_upper[ocp::xi(i) + ix::BETA_DOT] *= s.beta_dot_fraction;
        }
        let mut options = ocp::ipopt_options(1e-6, s.max_iterations as i32);
        // The warm start is near a solution: a small fixed barrier parameter
        // reaches it in fewer iterations than the adaptive rule (measured:
        // `docs/decisions.md`, the same times, solves p90 2/3 of them).
        options.retain(|(name, _)| *name != "mu_strategy");
        options.push(("mu_strategy", OptValue::Str("monotone".into())));
        options.push(("mu_init", OptValue::Num(1e-3)));
        options.push(("max_cpu_time", OptValue::Num(s.max_solve_seconds)));
        // IPOPT reads `ipopt.opt` in the working directory and lets it
        // override these: a file nobody configured would change the daemon's
        // plans. The settings are `TrajectorySettings`, nothing else.
        options.push(("option_file_name", OptValue::Str(NO_OPTIONS_FILE.into())));
        let r = ipopt::solve(&mut nlp, &z0, &options);
        let violation = nlp.max_violation(&r.z);
        // (A NaN violation fails too.)
        if violation.is_nan() || violation >= 1e-5 || !r.objective.is_finite() {
            return Err(TrajectoryFailure::NotSolved {
                status: r.status.name(),
            });
        }
        if !keeps_margins(p, &world, &margins, &r.z, k) {
            return Err(TrajectoryFailure::LeavesMargins);
        }
        out.clear();
        let mut dx = [0.0; 6 * 15];
        for i in 0..k {
            let local = interval_vars(&r.z, i, k);
            for j in 0..PATH_POINTS {
                if out.len() == out.capacity() {
                    return Err(TrajectoryFailure::TooLong);
                }
                let tau = j as f64 / PATH_POINTS as f64;
                // Between the nodes the cubic may overshoot a bound by a
                // hair: the model's own clamp (what the plant does).
                let mut x = ocp::interval_point(p, None, k, &local, tau, &mut dx);
                control::model::clamp_state(p, &mut x);
                out.push(x);
            }
        }
        out.push(State::from_column_slice(&r.z[ocp::xi(k)..ocp::xi(k) + 6]));
        Ok(r.z[8 * k + 6])
    }
}
