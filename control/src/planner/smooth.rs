//! Smoothing a Hybrid A* path (issue 27, Deliver 1: "smooth with collision
//! checks"; the method of Nav2's simple smoother).
//!
//! Why: the search's path is a chain of 0.6 m arcs at three articulations, so
//! it wiggles (an arc at β_max, then one at 0, …) and is longer than the way
//! it stands for; the path cost (`Tracking::Path`) follows it faithfully, and
//! each wiggle costs the machine articulation it can only change at β̇_max.
//!
//! Each part of one direction of travel (between cusps) is smoothed on its own
//! with its two first and two last poses fixed, so the start pose, the pose a
//! cusp or the goal shot starts from, and the headings there stay as planned.
//! Gauss–Seidel sweeps over the inner positions p_i with the original o_i:
//!
//!   p_i ← p_i + w_d (o_i − p_i) + w_s (p_{i−1} + p_{i+1} − 2 p_i)
//!
//! (w_s = 0.3 as Nav2; w_d pulls back to the search's path, 0 lets the path
//! straighten as far as the collision check allows), until no position moves
//! or the sweeps run out. A moved position makes the headings around it the
//! path's tangents (reversed on a reversing part: the front axle trails) and
//! β the articulation whose steady-state turn has the path's curvature
//! (κ = sin β / (L_f cos β + L_r), paper eq. 5 at β̇ = 0). The move is kept
//! only if no curvature around it exceeds the larger of the turn at β_max and
//! the largest there before (a move may not make the path less drivable) and
//! both axle points keep the world's margin at every sample of the four
//! segments around it, as the search checked its primitives; otherwise the
//! position stays (per position, as a point against a circle must not stop
//! the rest of the path from straightening).

use crate::model::{wrap_angle, MachineParams};

use super::carrot::direction_end;
use super::world::World;
use super::PathPose;

/// Nav2's smoothing weight (stable with any w_d ≤ 0.4: 1 − w_d − 2 w_s ≥ 0).
const SMOOTH_WEIGHT: f64 = 0.3;

/// A sweep that moves no position by more than this [m] ends the smoothing.
const CONVERGED: f64 = 1e-4;

/// How the path is smoothed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Smoothing {
    /// Sweeps at most (0: no smoothing).
    pub iterations: usize,
    /// w_d: the pull back to the search's path, in [0, 0.4].
    pub data_weight: f64,
    /// Collision samples between poses, at most this far apart [m].
    pub sample_spacing: f64,
}

/// The smoother with its buffer (allocated once; paths longer than the
/// capacity are left as they are).
#[derive(Debug, Clone)]
pub struct PathSmoother {
    original: Vec<[f64; 2]>,
}

impl PathSmoother {
    pub fn new(capacity: usize) -> Self {
        Self {
            original: Vec::with_capacity(capacity),
        }
    }

    /// Smooths `path` in place, part by part; returns the sweeps made
    /// (summed over the parts).
    pub fn smooth(&mut self, path: &mut [PathPose], world: &World, s: &Smoothing) -> usize {
        if s.iterations == 0 || path.len() > self.original.capacity() {
            return 0;
        }
        self.original.clear();
        self.original.extend(path.iter().map(|p| [p.x, p.y]));
        let mut sweeps = 0;
        let mut start = 0;
        while start + 1 < path.len() {
            let end = direction_end(path, start + 1);
            sweeps += self.smooth_part(&mut path[start..=end], start, world, s);
            start = end;
        }
        sweeps
    }

    /// One part of one direction (`offset`: its first pose's index in the
    /// path); returns its sweeps.
    fn smooth_part(
        &mut self,
        part: &mut [PathPose],
        offset: usize,
        world: &World,
        s: &Smoothing,
    ) -> usize {
        let n = part.len();
        let direction = part[n - 1].direction;
        if n < 5 || direction == 0 {
            return 0;
        }
        let params = world.params();
        let kappa_max = max_curvature(params);
        let mut sweeps = 0;
        for _ in 0..s.iterations {
            let mut moved: f64 = 0.0;
            for i in 2..n - 2 {
                // Moving p_i changes the tangents (headings, β) of i − 1,
                // i, i + 1, hence the poses of the four segments around it.
                let saved = [part[i - 1], part[i], part[i + 1]];
                let worst_before = (i - 1..=i + 1)
                    .map(|j| curvature_at(part, j).abs())
                    .fold(0.0, f64::max);
                let o = self.original[offset + i];
                let (l, r) = (part[i - 1], part[i + 1]);
                let p = &mut part[i];
                let dx = s.data_weight * (o[0] - p.x) + SMOOTH_WEIGHT * (l.x + r.x - 2.0 * p.x);
                let dy = s.data_weight * (o[1] - p.y) + SMOOTH_WEIGHT * (l.y + r.y - 2.0 * p.y);
                p.x += dx;
                p.y += dy;
                for j in (i - 1).max(2)..=(i + 1).min(n - 3) {
                    set_tangent_pose(part, j, direction, params);
                }
                let worst = (i - 1..=i + 1)
                    .map(|j| curvature_at(part, j).abs())
                    .fold(0.0, f64::max);
                let drivable = worst <= worst_before.max(kappa_max) * (1.0 + 1e-9);
                if drivable && part_free(&part[i - 2..=i + 2], world, s.sample_spacing) {
                    moved = moved.max(dx.hypot(dy));
                } else {
                    part[i - 1..=i + 1].copy_from_slice(&saved);
                }
            }
            sweeps += 1;
            if moved < CONVERGED {
                break;
            }
        }
        sweeps
    }
}

/// Sets pose i's heading to the path's tangent there (reversed when
/// `direction` < 0) and β to the articulation of its curvature (at most
/// β_max).
fn set_tangent_pose(part: &mut [PathPose], i: usize, direction: i8, params: &MachineParams) {
    let (a, c) = (part[i - 1], part[i + 1]);
    let tangent = (c.y - a.y).atan2(c.x - a.x);
    // A reversing part is travelled against its heading: the curvature the
    // heading sees has the other sign.
    let (heading, kappa) = if direction < 0 {
        (
            wrap_angle(tangent + std::f64::consts::PI),
            -curvature_at(part, i),
        )
    } else {
        (tangent, curvature_at(part, i))
    };
    part[i].theta = heading;
    part[i].beta = articulation_for_curvature(params, kappa);
}

/// The path's curvature at pose i, in the order of the poses.
fn curvature_at(part: &[PathPose], i: usize) -> f64 {
    let (a, b, c) = (part[i - 1], part[i], part[i + 1]);
    menger_curvature([a.x, a.y], [b.x, b.y], [c.x, c.y])
}

/// Signed curvature of the circle through a, b, c (positive turning left
/// from a to c; 0 for coincident points).
pub fn menger_curvature(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let (ab, bc, ac) = (
        (b[0] - a[0]).hypot(b[1] - a[1]),
        (c[0] - b[0]).hypot(c[1] - b[1]),
        (c[0] - a[0]).hypot(c[1] - a[1]),
    );
    let cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]);
    let denominator = ab * bc * ac;
    if denominator > 0.0 {
        2.0 * cross / denominator
    } else {
        0.0
    }
}

/// The front axle's curvature at β_max, the tightest turn.
pub fn max_curvature(p: &MachineParams) -> f64 {
    let (sin, cos) = p.beta_max.sin_cos();
    sin / (p.l_f * cos + p.l_r)
}

/// The articulation β whose steady-state turn has front-axle curvature κ:
/// κ (L_f cos β + L_r) = sin β, i.e. √(1 + κ²L_f²) sin(β − φ) = κ L_r with
/// φ = atan(κ L_f); held at ±β_max beyond [`max_curvature`] (0 for a
/// non-finite κ).
pub fn articulation_for_curvature(p: &MachineParams, kappa: f64) -> f64 {
    if !kappa.is_finite() {
        return 0.0;
    }
    let phi = (kappa * p.l_f).atan();
    let s = (kappa * p.l_r / (1.0 + (kappa * p.l_f).powi(2)).sqrt()).clamp(-1.0, 1.0);
    (phi + s.asin()).clamp(-p.beta_max, p.beta_max)
}

/// Both axle points of every pose of `part`, and of samples at most
/// `spacing` apart between them (position, heading and β interpolated), keep
/// the world's margin.
fn part_free(part: &[PathPose], world: &World, spacing: f64) -> bool {
    part.windows(2).all(|w| {
        let (a, b) = (w[0], w[1]);
        let steps = ((b.x - a.x).hypot(b.y - a.y) / spacing).ceil().max(1.0) as usize;
        let turn = wrap_angle(b.theta - a.theta);
        (0..steps).all(|k| {
            let f = k as f64 / steps as f64;
            world.pose_free(
                a.x + f * (b.x - a.x),
                a.y + f * (b.y - a.y),
                a.theta + f * turn,
                a.beta + f * (b.beta - a.beta),
            )
        })
    }) && part
        .last()
        .is_some_and(|p| world.pose_free(p.x, p.y, p.theta, p.beta))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ix, rk4_step, Control, State};
    use crate::obstacle::{footprint_clearance, Obstacle};

    fn pose(x: f64, y: f64, theta: f64, beta: f64, direction: i8) -> PathPose {
        PathPose {
            x,
            y,
            theta,
            beta,
            direction,
        }
    }

    /// The model's front axle driven at constant β has the curvature the
    /// closed form inverts (paper eq. 5 integrated, not the formula again).
    #[test]
    fn articulation_for_curvature_inverts_the_models_steady_turn() {
        let p = MachineParams::default();
        for beta in [-0.6, -0.3, -0.05, 0.0, 0.1, 0.4, p.beta_max] {
            let mut x = State::new(0.0, 0.0, 0.0, beta, 0.0, 0.0);
            let u = Control::zeros();
            let mut pts = Vec::new();
            for _ in 0..30 {
                let mut s = x;
                s[ix::V] = 1.0;
                x = rk4_step(&p, &s, &u, 0.02);
                x[ix::V] = 0.0;
                pts.push([x[ix::X], x[ix::Y]]);
            }
            let kappa = menger_curvature(pts[0], pts[14], pts[29]);
            let got = articulation_for_curvature(&p, kappa);
            assert!((got - beta).abs() < 1e-6, "β {beta}: got {got}");
        }
        assert!(
            (max_curvature(&p) - 1.0 / 1.6485).abs() < 1e-3,
            "R at 40° for 0.6 + 0.6 m"
        );
        assert_eq!(
            articulation_for_curvature(&p, 2.0 * max_curvature(&p)),
            p.beta_max
        );
        assert_eq!(articulation_for_curvature(&p, f64::NAN), 0.0);
    }

    #[test]
    fn menger_curvature_of_points_on_a_circle_is_its_inverse_radius() {
        let r = 4.0;
        let on = |a: f64| [r * a.cos(), r * a.sin()];
        assert!((menger_curvature(on(0.1), on(0.4), on(0.9)) - 1.0 / r).abs() < 1e-12);
        assert!((menger_curvature(on(0.9), on(0.4), on(0.1)) + 1.0 / r).abs() < 1e-12);
        assert_eq!(menger_curvature([0.0, 0.0], [1.0, 0.0], [2.0, 0.0]), 0.0);
    }

    /// A zigzag of 0.6 m steps along the x axis, forward.
    fn zigzag(n: usize, amplitude: f64) -> Vec<PathPose> {
        (0..n)
            .map(|i| {
                let y = if i < 2 || i + 2 >= n {
                    0.0
                } else {
                    amplitude * if i % 2 == 0 { 1.0 } else { -1.0 }
                };
                pose(0.6 * i as f64, y, 0.0, 0.0, if i == 0 { 0 } else { 1 })
            })
            .collect()
    }

    fn length(path: &[PathPose]) -> f64 {
        path.windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum()
    }

    fn settings(data_weight: f64) -> Smoothing {
        Smoothing {
            iterations: 200,
            data_weight,
            sample_spacing: 0.15,
        }
    }

    #[test]
    fn a_wiggle_in_open_ground_is_straightened_and_the_ends_stay() {
        let p = MachineParams::default();
        let world = World::new(p, 4, 0.15);
        let mut path = zigzag(20, 0.05);
        let before = path.clone();
        let sweeps = PathSmoother::new(64).smooth(&mut path, &world, &settings(0.0));
        assert!(sweeps > 0);
        assert!(
            length(&path) < length(&before) - 0.01,
            "{} vs {}",
            length(&path),
            length(&before)
        );
        let worst = path.iter().map(|q| q.y.abs()).fold(0.0, f64::max);
        assert!(worst < 0.01, "still {worst} m off the line");
        for i in [0, 1, 18, 19] {
            assert_eq!(path[i], before[i], "pose {i} moved");
        }
        assert!(path.iter().all(|q| q.theta.abs() < 0.05));
        assert!(path
            .iter()
            .zip(&before)
            .all(|(a, b)| a.direction == b.direction));
    }

    /// The least clearance of either axle point along the path, sampled every
    /// 2 cm (finer than the smoother's check), from the footprint directly.
    fn least_clearance(path: &[PathPose], obstacles: &[Obstacle]) -> f64 {
        let p = MachineParams::default();
        let mut least = f64::INFINITY;
        for w in path.windows(2) {
            let (a, b) = (w[0], w[1]);
            let steps = ((b.x - a.x).hypot(b.y - a.y) / 0.02).ceil() as usize;
            for k in 0..=steps {
                let f = k as f64 / steps as f64;
                let x = State::new(
                    a.x + f * (b.x - a.x),
                    a.y + f * (b.y - a.y),
                    a.theta + f * wrap_angle(b.theta - a.theta),
                    a.beta + f * (b.beta - a.beta),
                    0.0,
                    0.0,
                );
                least = least.min(footprint_clearance(&p, &x, obstacles));
            }
        }
        least
    }

    /// A circle under the straight line: the path bends over it (y = 0.4
    /// from x = 3.6 to 8.4). Smoothing shortens it but never takes either
    /// axle point into the margin, where straightening would (the line y = 0
    /// passes the circle's edge at 0.1 m).
    #[test]
    fn smoothing_never_takes_the_path_into_the_margin() {
        let p = MachineParams::default();
        let circle = [Obstacle {
            x: 6.0,
            y: -0.3,
            radius: 0.2,
        }];
        let mut world = World::new(p, 4, 0.15);
        world.set(&circle).expect("a valid circle");
        let mut path = zigzag(20, 0.0);
        for q in &mut path[6..15] {
            q.y = 0.4;
        }
        let before = path.clone();
        assert!(
            least_clearance(&path, &circle) >= 0.15,
            "the test's path must start free"
        );
        let sweeps = PathSmoother::new(64).smooth(&mut path, &world, &settings(0.0));
        assert!(sweeps > 0, "the corners can be rounded");
        assert!(length(&path) < length(&before));
        let least = least_clearance(&path, &circle);
        // The smoother samples every 0.15 m: between samples a little less.
        assert!(least >= 0.14, "clearance {least} m");
        assert!(
            path[10].y > 0.05,
            "the path went through the circle: {}",
            path[10].y
        );
    }

    /// A reversing part keeps its headings opposite to its travel, and a cusp
    /// pose (where the machine stops) does not move.
    #[test]
    fn parts_are_smoothed_each_with_its_direction_and_cusps_stay() {
        let p = MachineParams::default();
        let world = World::new(p, 4, 0.15);
        let mut path = zigzag(10, 0.05);
        let cusp = path[9];
        let back = zigzag(10, 0.05);
        path.extend(back[..9].iter().rev().map(|q| PathPose {
            direction: -1,
            ..*q
        }));
        let sweeps = PathSmoother::new(64).smooth(&mut path, &world, &settings(0.0));
        assert!(sweeps > 0);
        assert_eq!(path[9], cusp);
        for q in &path[10..] {
            assert_eq!(q.direction, -1);
            assert!(
                wrap_angle(q.theta).abs() < 0.05,
                "reversing heading {}",
                q.theta
            );
        }
    }

    #[test]
    fn a_path_longer_than_the_buffers_is_left_alone() {
        let world = World::new(MachineParams::default(), 4, 0.15);
        let mut path = zigzag(20, 0.05);
        let before = path.clone();
        assert_eq!(
            PathSmoother::new(8).smooth(&mut path, &world, &settings(0.0)),
            0
        );
        assert_eq!(path, before);
    }
}
