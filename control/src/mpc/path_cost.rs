//! Following a planned path (issue 27, design (a); DESIGN §15): the MPC's cost
//! while the goal is far and the way to it is not open.
//!
//! The goal-conditioned critic prices a pose to converge to; handed points
//! along a route it slows down for each, and behind a wall it sits in a local
//! minimum. Model predictive contouring control instead rewards *progress
//! along the path*: its terminal cost is the arc length left, so no point on
//! the way is a minimum. Here, for the front axle's position p and heading θ,
//!
//!   V(x) = c·max(L − s(p), 0) + q_c·e_c(p)² + q_h·(1 − cos(θ − θ_r(s))) + r·Σ (u_i / u_max,i)²
//!
//! with s(p) the arc length of p's projection onto the path, L the path's
//! length (with an open end, where something else takes over at speed, the
//! max goes: progress beyond the last pose still pays), e_c the lateral (contouring) error, θ_r the path's heading there
//! (the machine's heading on the path, so a reversing leg has the heading
//! opposite to its direction of travel) and the last term a small price on
//! the controls (the critic's own control cost is gone with it). c is the
//! critic's price of a metre (calibrated by [`crate::planner`]), so V is in
//! the critic's units and the handover to it near the goal keeps the scale.
//! Every stage (× Δt) and the terminal cost use V; the MPC drops the critic
//! while a path cost is set.
//!
//! The projection is linearised at the linearisation point: s = s̄ + tᵀ(p − p̄)
//! and e_c = nᵀ(p − r̄) on the nearest segment (tangent t, normal n), which is
//! the Gauss–Newton model of contouring and lag (the curvature of the path is
//! left out of the Hessian: 2 q_c n nᵀ on p, q_h·max(cos, 0) on θ).
//!
//! A path here has one direction of travel: the navigator cuts its route at
//! the cusps, where the machine must stop, and hands the critic each cusp and
//! the goal as targets. The projection only moves forwards along the path
//! (from a hint), so a path that passes close to itself is not jumped.
//!
//! The point followed is the leading axle's ([`AxlePoint`]): the front axle
//! (x_f, y_f) with the front body's heading θ driving forwards, the rear
//! axle with the rear body's heading θ − β reversing. A reversing machine
//! steered by its trailing front axle is a trailer pushed backwards: measured,
//! it locked the articulation and stalled. The leading point's position and
//! heading are functions of (x_f, y_f, θ, β) ([`AxlePoint::position`]); V's
//! gradient and Gauss–Newton Hessian over them go through that Jacobian J
//! (∇ = Jᵀ∇_p, ∇² ≈ Jᵀ∇²_p J: the mapping's own curvature is left out, as
//! the path's is).

use crate::model::{ix, Control, MachineParams, State, NU};
use crate::obstacle::AxlePoint;

/// The weights of [`PathCost`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathWeights {
    /// c: price of a metre of path left [cost/m].
    pub per_metre: f64,
    /// q_c: price of the squared lateral error [cost/m²].
    pub lateral: f64,
    /// q_h: price of the heading error (1 − cos).
    pub heading: f64,
    /// r: price of the squared controls, each relative to its bound.
    pub control: f64,
}

impl PathWeights {
    fn is_valid(&self) -> bool {
        [self.per_metre, self.lateral, self.heading, self.control]
            .iter()
            .all(|w| w.is_finite() && *w >= 0.0)
    }
}

impl Default for PathCost {
    fn default() -> Self {
        Self::new()
    }
}

/// A path's cost: its poses (x, y, θ), their arc lengths and the weights.
#[derive(Debug, Clone, PartialEq)]
pub struct PathCost {
    points: Vec<[f64; 3]>,
    arc: Vec<f64>,
    weights: PathWeights,
    /// 1 / u_max per control (the control term's scale).
    control_scale: [f64; NU],
    /// Progress beyond the last pose still pays (along the last segment's
    /// line): the path ends where something else takes over at speed.
    open_end: bool,
    /// The axle point whose positions and body headings `points` are.
    point: AxlePoint,
    params: MachineParams,
}

/// The value, gradient and (Gauss–Newton) Hessian of [`PathCost`] at a stage,
/// over z = (x, u).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathTerm {
    pub value: f64,
    /// ∂V/∂(x_f, y_f, θ, β).
    pub grad_pose: [f64; POSE],
    /// The Gauss–Newton ∂²V/∂(x_f, y_f, θ, β)²: Jᵀ·diag(2 q_c n nᵀ,
    /// q_h·max(cos, 0))·J over the followed point's position and heading.
    pub hess_pose: [[f64; POSE]; POSE],
    /// ∂V/∂u and the diagonal of ∂²V/∂u².
    pub grad_control: [f64; NU],
    pub hess_control: [f64; NU],
    /// The segment p was projected onto: the next stage's hint.
    pub segment: usize,
}

/// The state components a path term depends on: x_f, y_f, θ, β.
pub const POSE: usize = 4;
/// Their indices in the state.
pub const POSE_INDEX: [usize; POSE] = [ix::X, ix::Y, ix::THETA, ix::BETA];

/// Poses a path cost holds (allocated once): a path of 0.6 m primitives this
/// long is over a kilometre, far beyond a planning square; the poses beyond
/// it are left out.
pub const MAX_PATH_POSES: usize = 2048;

/// How far ahead of the hint the projection looks [m of arc]: more than a
/// stage moves (Δt × top speed) by far, less than a path folding back.
const SEARCH_AHEAD: f64 = 3.0;

impl PathCost {
    /// Room for [`MAX_PATH_POSES`] (setting or copying a path allocates
    /// nothing).
    pub fn new() -> Self {
        Self {
            points: Vec::with_capacity(MAX_PATH_POSES),
            arc: Vec::with_capacity(MAX_PATH_POSES),
            weights: PathWeights {
                per_metre: 0.0,
                lateral: 0.0,
                heading: 0.0,
                control: 0.0,
            },
            control_scale: [0.0; NU],
            open_end: false,
            point: AxlePoint::Front,
            params: MachineParams::default(),
        }
    }

    /// No path: the cost is the critic's.
    pub fn is_empty(&self) -> bool {
        self.points.len() < 2
    }

    pub fn clear(&mut self) {
        self.points.clear();
        self.arc.clear();
    }

    /// Whether progress beyond the last pose still pays.
    pub fn open_end(&self) -> bool {
        self.open_end
    }

    /// The axle point that follows the path.
    pub fn point(&self) -> AxlePoint {
        self.point
    }

    /// The path's length L [m].
    pub fn length(&self) -> f64 {
        self.arc.last().copied().unwrap_or(0.0)
    }

    /// Sets the path: poses (x, y, heading) of `point` and its body, in the
    /// order of travel. Poses closer than a millimetre to the previous one
    /// are dropped (a segment needs a direction). Non-finite poses or
    /// weights, or fewer than two distinct poses, leave it empty: a broken
    /// path must not steer. With `open_end` the arc length left goes on
    /// falling beyond the last pose (the machine is not asked to stop
    /// there); otherwise it stops at 0.
    pub fn set(
        &mut self,
        poses: impl IntoIterator<Item = [f64; 3]>,
        weights: PathWeights,
        params: &MachineParams,
        open_end: bool,
        point: AxlePoint,
    ) {
        self.clear();
        let umax = params.control_max();
        if !weights.is_valid() || umax.iter().any(|u| !(u.is_finite() && *u > 0.0)) {
            return;
        }
        for p in poses {
            if self.points.len() == MAX_PATH_POSES {
                break;
            }
            if !p.iter().all(|v| v.is_finite()) {
                self.clear();
                return;
            }
            match self.points.last() {
                None => self.arc.push(0.0),
                Some(last) => {
                    let d = (p[0] - last[0]).hypot(p[1] - last[1]);
                    if d < 1e-3 {
                        continue;
                    }
                    let s = self.length() + d;
                    self.arc.push(s);
                }
            }
            self.points.push(p);
        }
        if self.points.len() < 2 {
            self.clear();
            return;
        }
        self.weights = weights;
        self.control_scale = [1.0 / umax[0], 1.0 / umax[1]];
        self.open_end = open_end;
        self.point = point;
        self.params = *params;
    }

    /// The pose (x, y, heading) of `point` and its body in state `x`.
    pub fn point_pose(point: AxlePoint, params: &MachineParams, x: &State) -> [f64; 3] {
        let [px, py] = point.position(params, x);
        [px, py, point.heading(x)]
    }

    /// Copies `other` (no allocation).
    pub fn copy_from(&mut self, other: &PathCost) {
        self.points.clear();
        self.points.extend_from_slice(&other.points);
        self.arc.clear();
        self.arc.extend_from_slice(&other.arc);
        self.weights = other.weights;
        self.control_scale = other.control_scale;
        self.open_end = other.open_end;
        self.point = other.point;
        self.params = other.params;
    }

    /// The segment nearest to (x, y) among those from `hint` to
    /// [`SEARCH_AHEAD`] metres of arc beyond it (and the one before it).
    pub fn nearest_segment(&self, x: f64, y: f64, hint: usize) -> usize {
        let last = self.points.len().saturating_sub(2);
        let from = hint.min(last).saturating_sub(1);
        let limit = self.arc[hint.min(last)] + SEARCH_AHEAD;
        let (mut best, mut best_d) = (from, f64::INFINITY);
        for i in from..=last {
            if self.arc[i] > limit {
                break;
            }
            let d = self.segment_distance(i, x, y);
            if d < best_d {
                (best, best_d) = (i, d);
            }
        }
        best
    }

    /// The arc length left from the followed point's projection in state
    /// `state` (from segment `hint`) to the path's end (negative beyond it),
    /// and the segment projected onto.
    pub fn arc_left(&self, state: &State, hint: usize) -> (f64, usize) {
        let [x, y, _] = Self::point_pose(self.point, &self.params, state);
        let i = self.nearest_segment(x, y, hint);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = self.arc[i + 1] - self.arc[i];
        let along = ((x - a[0]) * (b[0] - a[0]) + (y - a[1]) * (b[1] - a[1])) / len;
        (self.length() - (self.arc[i] + along), i)
    }

    /// Distance from (x, y) to segment i (its closed extent).
    fn segment_distance(&self, i: usize, x: f64, y: f64) -> f64 {
        let (a, b) = (self.points[i], self.points[i + 1]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let f = (((x - a[0]) * dx + (y - a[1]) * dy) / len2).clamp(0.0, 1.0);
        (x - a[0] - f * dx).hypot(y - a[1] - f * dy)
    }

    /// V at the stage (x, u) with its derivatives, projecting from segment
    /// `hint`. Call only on a non-empty path.
    pub fn eval(&self, x: &State, u: &Control, hint: usize) -> PathTerm {
        let w = &self.weights;
        let [px, py, theta] = Self::point_pose(self.point, &self.params, x);
        let i = self.nearest_segment(px, py, hint);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = self.arc[i + 1] - self.arc[i];
        let t = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let n = [-t[1], t[0]];
        let (rx, ry) = (px - a[0], py - a[1]);
        // Along the segment, unclamped: beyond the first or last pose the
        // segment's line continues (a smooth model at the path's ends).
        let along = t[0] * rx + t[1] * ry;
        let lateral = n[0] * rx + n[1] * ry;
        let left = self.length() - (self.arc[i] + along);
        let f = (along / len).clamp(0.0, 1.0);
        let turn = crate::model::wrap_angle(b[2] - a[2]);
        let theta_r = a[2] + f * turn;
        // dθ_r/ds on the segment's interior (its heading is interpolated).
        let turn_rate = if f > 0.0 && f < 1.0 { turn / len } else { 0.0 };
        let dtheta = crate::model::wrap_angle(theta - theta_r);
        let (sin, cos) = dtheta.sin_cos();
        let pull = if left > 0.0 || self.open_end {
            w.per_metre
        } else {
            0.0
        };
        let mut value = pull * left + w.lateral * lateral * lateral + w.heading * (1.0 - cos);
        let g_lat = 2.0 * w.lateral * lateral;
        // ∂/∂p of q_h(1 − cos(θ − θ_r(s(p)))): θ_r moves with the projection.
        let g_turn = -w.heading * sin * turn_rate;
        let mut grad_control = [0.0; NU];
        let mut hess_control = [0.0; NU];
        for c in 0..NU {
            let k = self.control_scale[c];
            value += w.control * (k * u[c]).powi(2);
            grad_control[c] = 2.0 * w.control * k * k * u[c];
            hess_control[c] = 2.0 * w.control * k * k;
        }
        // Over the point's (p_x, p_y, heading), then through J.
        let grad_point = [
            (g_turn - pull) * t[0] + g_lat * n[0],
            (g_turn - pull) * t[1] + g_lat * n[1],
            w.heading * sin,
        ];
        let hess_lateral = 2.0 * w.lateral;
        let hess_heading = w.heading * cos.max(0.0);
        let [jx, jy] = self.point.jacobian(&self.params, x);
        let jh = self.point.heading_jacobian();
        // n·J: the lateral error's row.
        let jn: [f64; POSE] = std::array::from_fn(|c| n[0] * jx[c] + n[1] * jy[c]);
        let grad_pose = std::array::from_fn(|c| {
            grad_point[0] * jx[c] + grad_point[1] * jy[c] + grad_point[2] * jh[c]
        });
        let hess_pose = std::array::from_fn(|r| {
            std::array::from_fn(|c| hess_lateral * jn[r] * jn[c] + hess_heading * jh[r] * jh[c])
        });
        PathTerm {
            value,
            grad_pose,
            hess_pose,
            grad_control,
            hess_control,
            segment: i,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weights() -> PathWeights {
        PathWeights {
            per_metre: 3.0,
            lateral: 12.0,
            heading: 9.0,
            control: 0.5,
        }
    }

    /// An L-shaped path: 4 m along x, then 3 m up y.
    fn l_path() -> PathCost {
        let mut p = PathCost::new();
        let h = std::f64::consts::FRAC_PI_2;
        p.set(
            [
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [2.0005, 0.0, 0.0],
                [4.0, 0.0, 0.0],
                [4.0, 3.0, h],
            ],
            weights(),
            &MachineParams::default(),
            false,
            AxlePoint::Front,
        );
        p
    }

    #[test]
    fn value_is_the_arc_left_plus_lateral_and_heading_errors() {
        let p = l_path();
        // The pose 0.5 mm from its predecessor was dropped.
        assert_eq!(p.points.len(), 4);
        assert!((p.length() - 7.0).abs() < 1e-12);
        // On the first leg, 0.3 m to the left, heading 0.2 rad off: closed form.
        let x = State::new(1.0, 0.3, 0.2, 0.0, 0.0, 0.0);
        let term = p.eval(&x, &Control::zeros(), 0);
        let expected = 3.0 * 6.0 + 12.0 * 0.09 + 9.0 * (1.0 - 0.2f64.cos());
        assert!((term.value - expected).abs() < 1e-12, "{}", term.value);
        assert_eq!(term.segment, 0);
        // On the second leg, 0.5 m up it and 0.1 m to its right: its heading
        // turns from 0 to π/2 along it, a sixth of the way there.
        let x = State::new(4.1, 0.5, 1.5, 0.0, 0.0, 0.0);
        let term = p.eval(&x, &Control::zeros(), 1);
        let theta_r = std::f64::consts::FRAC_PI_2 / 6.0;
        let expected = 3.0 * 2.5 + 12.0 * 0.01 + 9.0 * (1.0 - (1.5 - theta_r).cos());
        assert!((term.value - expected).abs() < 1e-12, "{}", term.value);
        assert_eq!(term.segment, 2);
    }

    /// ∂V/∂(x_f, y_f, θ, β) against central differences on the stage's
    /// segment (the model is exact on it).
    fn assert_pose_gradient(p: &PathCost, x: &State, u: &Control, term: &PathTerm) {
        let h = 1e-6;
        for (k, c) in POSE_INDEX.into_iter().enumerate() {
            let (mut xp, mut xm) = (*x, *x);
            xp[c] += h;
            xm[c] -= h;
            let fd = (p.eval(&xp, u, term.segment).value - p.eval(&xm, u, term.segment).value)
                / (2.0 * h);
            assert!(
                (fd - term.grad_pose[k]).abs() < 1e-5,
                "{k}: {fd} vs {:?}",
                term.grad_pose
            );
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let p = l_path();
        let u = Control::new(0.1, -0.2);
        for x in [
            State::new(1.0, 0.3, 0.2, 0.0, 0.0, 0.0),
            State::new(3.3, -0.4, -0.5, 0.1, 0.0, 0.5),
            State::new(4.2, 1.7, 1.2, 0.0, 0.0, 0.5),
        ] {
            // From segment 1 all three are within the search's reach.
            let term = p.eval(&x, &u, 1);
            let h = 1e-6;
            assert_pose_gradient(&p, &x, &u, &term);
            for c in 0..NU {
                let (mut up, mut um) = (u, u);
                up[c] += h;
                um[c] -= h;
                let fd = (p.eval(&x, &up, 1).value - p.eval(&x, &um, 1).value) / (2.0 * h);
                assert!((fd - term.grad_control[c]).abs() < 1e-5);
            }
            // The lateral Hessian is 2 q_c n nᵀ: the second difference across the segment.
            let fd2 = {
                let n = if term.segment == 0 {
                    [0.0, 1.0]
                } else {
                    [-1.0, 0.0]
                };
                let e = 1e-3;
                let at = |s: f64| {
                    let mut y = x;
                    y[ix::X] += s * n[0];
                    y[ix::Y] += s * n[1];
                    p.eval(&y, &u, term.segment).value
                };
                (at(e) - 2.0 * at(0.0) + at(-e)) / (e * e)
            };
            let n_h_n = if term.segment == 0 {
                term.hess_pose[1][1]
            } else {
                term.hess_pose[0][0]
            };
            assert!((fd2 - n_h_n).abs() < 1e-3, "{fd2} vs {n_h_n}");
        }
    }

    #[test]
    fn projection_moves_forwards_from_its_hint_and_never_jumps_ahead() {
        // A hairpin: out along y = 0 and back along y = 1 (4 m each way).
        let mut p = PathCost::new();
        let pi = std::f64::consts::PI;
        p.set(
            [
                [0.0, 0.0, 0.0],
                [4.0, 0.0, 0.0],
                [4.0, 1.0, pi / 2.0],
                [0.0, 1.0, pi],
            ],
            weights(),
            &MachineParams::default(),
            false,
            AxlePoint::Front,
        );
        // A point between the legs near the start, nearer the return leg (0.3 m)
        // than the first (0.7 m): from the start's hint the return leg is beyond
        // the search's reach (its arc starts 5 m on), so it belongs to the first.
        let (x, y) = (0.5, 0.7);
        assert!(p.segment_distance(2, x, y) < p.segment_distance(0, x, y));
        assert_eq!(p.nearest_segment(x, y, 0), 0);
        // From a hint on the return leg, the first leg is behind, though nearer
        // (0.45 m against 0.55 m).
        let (x, y) = (0.5, 0.45);
        assert!(p.segment_distance(0, x, y) < p.segment_distance(2, x, y));
        assert_eq!(p.nearest_segment(x, y, 2), 2);
        // Beyond the end the value stops falling (no pull past the end)...
        let x = State::new(-1.0, 1.0, pi, 0.0, 0.0, 0.0);
        let term = p.eval(&x, &Control::zeros(), 2);
        assert_eq!(term.grad_pose[0], 0.0);
        // ... unless the end is open: then it pulls on along the last segment.
        let poses = p.points.clone();
        p.set(
            poses,
            weights(),
            &MachineParams::default(),
            true,
            AxlePoint::Front,
        );
        let term = p.eval(&x, &Control::zeros(), 2);
        assert_eq!(term.grad_pose[0], weights().per_metre);
    }

    #[test]
    fn reversing_follows_the_rear_axle_and_its_derivatives_match_finite_differences() {
        // The rear axle's path: along y = 0 towards -x, the rear body heading
        // 0 (the machine reverses, its front axle trailing at +x).
        let params = MachineParams::default();
        let mut p = PathCost::new();
        p.set(
            [[0.0, 0.0, 0.0], [-2.0, 0.0, 0.0], [-4.0, 0.5, -0.3]],
            weights(),
            &params,
            false,
            AxlePoint::Rear,
        );
        assert_eq!(p.point(), AxlePoint::Rear);
        // A machine whose rear axle sits on the path at (-1, 0), unarticulated,
        // heading 0: its front axle is L_f + L_r ahead.
        let lever = params.l_f + params.l_r;
        let on = State::new(-1.0 + lever, 0.0, 0.0, 0.0, 0.0, -0.5);
        let term = p.eval(&on, &Control::zeros(), 0);
        let left = p.length() - 1.0;
        assert!((term.value - 3.0 * left).abs() < 1e-9, "{}", term.value);
        let (arc, _) = p.arc_left(&on, 0);
        assert!((arc - left).abs() < 1e-9);
        // Pulled backwards (the way the rear axle travels), not forwards.
        assert!(term.grad_pose[0] > 0.0, "{:?}", term.grad_pose);
        let u = Control::new(0.1, -0.2);
        for x in [
            State::new(-0.5 + lever, 0.3, 0.2, 0.1, 0.0, -0.5),
            State::new(-1.2 + lever, -0.2, -0.4, -0.3, 0.0, -0.5),
            State::new(-2.6 + lever, 0.4, 0.1, 0.4, 0.0, -0.5),
        ] {
            let term = p.eval(&x, &u, 0);
            let h = 1e-6;
            assert_pose_gradient(&p, &x, &u, &term);
            // Gauss–Newton: the Hessian is Jᵀ·diag(2 q_c, q_h cos)·J with J
            // the Jacobian of the residuals (lateral error, heading error) on
            // the stage's segment and with its reference heading held (the
            // path's curvature is left out of the model, as on the front
            // axle): checked against finite differences of the residuals.
            let [px0, py0, _] = PathCost::point_pose(AxlePoint::Rear, &params, &x);
            let (a, b) = (p.points[term.segment], p.points[term.segment + 1]);
            let len = p.arc[term.segment + 1] - p.arc[term.segment];
            let n = [-(b[1] - a[1]) / len, (b[0] - a[0]) / len];
            let along = ((px0 - a[0]) * (b[0] - a[0]) + (py0 - a[1]) * (b[1] - a[1])) / len;
            let f = (along / len).clamp(0.0, 1.0);
            let theta_r = a[2] + f * crate::model::wrap_angle(b[2] - a[2]);
            let residuals = |y: &State| {
                let [px, py, heading] = PathCost::point_pose(AxlePoint::Rear, &params, y);
                [n[0] * (px - a[0]) + n[1] * (py - a[1]), heading - theta_r]
            };
            let mut jac = [[0.0; POSE]; 2];
            for (k, c) in POSE_INDEX.into_iter().enumerate() {
                let (mut xp, mut xm) = (x, x);
                xp[c] += h;
                xm[c] -= h;
                let (rp, rm) = (residuals(&xp), residuals(&xm));
                for r in 0..2 {
                    jac[r][k] = (rp[r] - rm[r]) / (2.0 * h);
                }
            }
            let dtheta = residuals(&x)[1];
            let weight = [2.0 * 12.0, 9.0 * dtheta.cos().max(0.0)];
            for r in 0..POSE {
                for c in 0..POSE {
                    let gn: f64 = (0..2).map(|k| weight[k] * jac[k][r] * jac[k][c]).sum();
                    assert!(
                        (gn - term.hess_pose[r][c]).abs() < 1e-4 * (1.0 + gn.abs()),
                        "({r}, {c}): {gn} vs {}",
                        term.hess_pose[r][c]
                    );
                }
            }
        }
    }

    #[test]
    fn a_broken_path_is_no_path() {
        let mut p = PathCost::new();
        let params = MachineParams::default();
        p.set(
            [[0.0, 0.0, 0.0], [f64::NAN, 1.0, 0.0]],
            weights(),
            &params,
            false,
            AxlePoint::Front,
        );
        assert!(p.is_empty());
        p.set(
            [[0.0, 0.0, 0.0], [0.0, 0.0, 0.1]],
            weights(),
            &params,
            false,
            AxlePoint::Front,
        );
        assert!(p.is_empty(), "one distinct pose");
        let bad = PathWeights {
            lateral: -1.0,
            ..weights()
        };
        p.set(
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
            bad,
            &params,
            false,
            AxlePoint::Front,
        );
        assert!(p.is_empty());
        p.set(
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
            weights(),
            &params,
            false,
            AxlePoint::Front,
        );
        assert!(!p.is_empty());
    }
}
