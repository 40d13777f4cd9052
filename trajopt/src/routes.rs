//! Initial guesses for the min-time problem among obstacles: routes of the
//! front axle around each side of the obstacles (issue 14, item 7).
//!
//! Minimum time among circles is non-convex: every way around every obstacle
//! (a homotopy class) has its own local optimum, and a solve started on one
//! side stays there. So the guesses cover the sides: overlapping circles are
//! grouped into clusters (a wall is one cluster); for the clusters near the
//! straight start–goal segment (at most [`MAX_SIDE_CLUSTERS`]) every
//! assignment of a side, left or right of the direction of travel, is searched
//! on a grid. "Pass cluster c on the left" blocks a ray from one of c's
//! centres to the right, perpendicular to start → goal, out to the grid's
//! edge, so a path can only get past c on its left. The shortest grid path of
//! each assignment (Dijkstra, 8-connected, with a cost that keeps it off the
//! circles' edges) is shortened by line of sight, smoothed, and timed with a
//! trapezoidal speed profile; heading and articulation follow from the path's
//! tangent and curvature.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::f64::consts::PI;

use control::model::{ix, wrap_angle, Control, MachineParams, State};
use control::obstacle::Obstacle;
use control::scenario::Scenario;

use crate::guess::Guess;

/// Clusters whose side is chosen (2^n assignments).
pub const MAX_SIDE_CLUSTERS: usize = 3;
/// Grid cell [m].
const CELL: f64 = 0.1;
/// Margin of the grid around start, goal and circles [m].
const BORDER: f64 = 3.0;
/// A cell is blocked within this distance of a circle's edge [m].
const HARD_CLEARANCE: f64 = 0.05;
/// Below this clearance a cell costs more, up to 1 + [`SOFT_WEIGHT`] [m].
const SOFT_CLEARANCE: f64 = 0.6;
const SOFT_WEIGHT: f64 = 2.0;
/// Clusters farther than this from the start–goal segment keep their side
/// free [m].
const NEAR_SEGMENT: f64 = 2.0;
/// Two routes closer than this everywhere are the same [m].
const SAME_ROUTE: f64 = 0.4;

/// A front-axle route from the start to the goal.
#[derive(Debug, Clone)]
pub struct Route {
    pub points: Vec<[f64; 2]>,
    pub length: f64,
}

/// Groups circles that overlap or nearly touch (gap < 2 cells); returns the
/// cluster index of every circle and the count.
pub fn clusters(obstacles: &[Obstacle]) -> (Vec<usize>, usize) {
    let n = obstacles.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for i in 0..n {
        for j in 0..i {
            let (a, b) = (&obstacles[i], &obstacles[j]);
            if (a.x - b.x).hypot(a.y - b.y) < a.radius + b.radius + 2.0 * CELL {
                let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                parent[ri] = rj;
            }
        }
    }
    let mut label = vec![usize::MAX; n];
    let mut out = vec![0; n];
    let mut count = 0;
    for (i, o) in out.iter_mut().enumerate() {
        let r = find(&mut parent, i);
        if label[r] == usize::MAX {
            label[r] = count;
            count += 1;
        }
        *o = label[r];
    }
    (out, count)
}

fn segment_distance(a: [f64; 2], b: [f64; 2], q: [f64; 2]) -> (f64, f64) {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = (d[0] * d[0] + d[1] * d[1]).max(1e-12);
    let t = (((q[0] - a[0]) * d[0] + (q[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0);
    let p = [a[0] + t * d[0], a[1] + t * d[1]];
    ((q[0] - p[0]).hypot(q[1] - p[1]), t)
}

struct Grid {
    x0: f64,
    y0: f64,
    nx: usize,
    ny: usize,
    /// Cost factor per cell; infinite where blocked.
    cost: Vec<f64>,
}

impl Grid {
    fn new(sc: &Scenario) -> Self {
        let s = [sc.start[ix::X], sc.start[ix::Y]];
        let g = [sc.goal.x, sc.goal.y];
        let (mut lo, mut hi) = (
            [s[0].min(g[0]), s[1].min(g[1])],
            [s[0].max(g[0]), s[1].max(g[1])],
        );
        for o in &sc.obstacles {
            lo = [lo[0].min(o.x - o.radius), lo[1].min(o.y - o.radius)];
            hi = [hi[0].max(o.x + o.radius), hi[1].max(o.y + o.radius)];
        }
        let (x0, y0) = (lo[0] - BORDER, lo[1] - BORDER);
        let nx = ((hi[0] + BORDER - x0) / CELL).ceil() as usize + 1;
        let ny = ((hi[1] + BORDER - y0) / CELL).ceil() as usize + 1;
        let mut cost = vec![1.0; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let q = [x0 + i as f64 * CELL, y0 + j as f64 * CELL];
                let c = sc
                    .obstacles
                    .iter()
                    .map(|o| o.clearance_of(q))
                    .fold(f64::INFINITY, f64::min);
                cost[j * nx + i] = if c < HARD_CLEARANCE {
                    f64::INFINITY
                } else {
                    1.0 + SOFT_WEIGHT * ((SOFT_CLEARANCE - c) / SOFT_CLEARANCE).max(0.0)
                };
            }
        }
        Self {
            x0,
            y0,
            nx,
            ny,
            cost,
        }
    }

    fn cell(&self, q: [f64; 2]) -> Option<usize> {
        let i = ((q[0] - self.x0) / CELL).round();
        let j = ((q[1] - self.y0) / CELL).round();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then(|| j as usize * self.nx + i as usize)
    }

    fn point(&self, c: usize) -> [f64; 2] {
        [
            self.x0 + (c % self.nx) as f64 * CELL,
            self.y0 + (c / self.nx) as f64 * CELL,
        ]
    }

    /// Blocks every cell within 0.75 cells of the ray from `from` along `dir`
    /// (unit) to the grid's edge: no 8-connected step crosses it.
    fn block_ray(&self, cost: &mut [f64], from: [f64; 2], dir: [f64; 2]) {
        let reach = (self.nx + self.ny) as f64 * CELL;
        let to = [from[0] + dir[0] * reach, from[1] + dir[1] * reach];
        for (c, v) in cost.iter_mut().enumerate() {
            let q = self.point(c);
            if segment_distance(from, to, q).0 <= 0.75 * CELL {
                *v = f64::INFINITY;
            }
        }
    }

    /// Dijkstra from `s` to `g` on `cost`; the cells of the path.
    fn shortest(&self, cost: &[f64], s: usize, g: usize) -> Option<Vec<usize>> {
        #[derive(PartialEq)]
        struct Item(f64, usize);
        impl Eq for Item {}
        impl PartialOrd for Item {
            fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
                Some(self.cmp(o))
            }
        }
        impl Ord for Item {
            fn cmp(&self, o: &Self) -> Ordering {
                o.0.total_cmp(&self.0)
            }
        }
        let n = cost.len();
        let mut dist = vec![f64::INFINITY; n];
        let mut prev = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        dist[s] = 0.0;
        heap.push(Item(0.0, s));
        while let Some(Item(d, c)) = heap.pop() {
            if c == g {
                break;
            }
            if d > dist[c] {
                continue;
            }
            let (i, j) = ((c % self.nx) as isize, (c / self.nx) as isize);
            for (di, dj) in [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ] {
                let (a, b) = (i + di, j + dj);
                if a < 0 || b < 0 || a >= self.nx as isize || b >= self.ny as isize {
                    continue;
                }
                let nb = b as usize * self.nx + a as usize;
                let step = if di != 0 && dj != 0 { 2f64.sqrt() } else { 1.0 };
                let w = 0.5 * (cost[c] + cost[nb]) * step * CELL;
                if !w.is_finite() {
                    continue;
                }
                if d + w < dist[nb] {
                    dist[nb] = d + w;
                    prev[nb] = c;
                    heap.push(Item(d + w, nb));
                }
            }
        }
        if !dist[g].is_finite() {
            return None;
        }
        let mut path = vec![g];
        while *path.last().expect("non-empty") != s {
            path.push(prev[*path.last().expect("non-empty")]);
        }
        path.reverse();
        Some(path)
    }

    /// Whether the straight segment a → b stays on cells that are not blocked
    /// (in `cost`) and not close to a circle.
    fn visible(&self, cost: &[f64], a: [f64; 2], b: [f64; 2]) -> bool {
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let steps = (len / (0.5 * CELL)).ceil().max(1.0) as usize;
        (0..=steps).all(|k| {
            let t = k as f64 / steps as f64;
            let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            self.cell(q)
                .is_some_and(|c| cost[c] < 1.0 + 0.5 * SOFT_WEIGHT)
        })
    }
}

impl Grid {
    /// A grid path as a route: line-of-sight shortcuts on `cost`, resampled
    /// every 0.2 m, corners rounded by a few passes of neighbour averaging
    /// (moves onto cells blocked in `base` refused).
    fn finish(
        &self,
        cost: &[f64],
        base: &[f64],
        cells: &[usize],
        s: [f64; 2],
        g: [f64; 2],
    ) -> Vec<[f64; 2]> {
        let pts: Vec<[f64; 2]> = cells.iter().map(|&c| self.point(c)).collect();
        let mut short = vec![s];
        let mut i = 0;
        while i + 1 < pts.len() {
            let mut j = pts.len() - 1;
            while j > i + 1 && !self.visible(cost, pts[i], pts[j]) {
                j -= 1;
            }
            short.push(pts[j]);
            i = j;
        }
        if short.len() == 1 {
            short.push(g);
        }
        *short.last_mut().expect("non-empty") = g;
        let mut points = resample(&short, 0.2);
        for _ in 0..4 {
            let prev = points.clone();
            for k in 1..points.len() - 1 {
                let q = [
                    0.25 * prev[k - 1][0] + 0.5 * prev[k][0] + 0.25 * prev[k + 1][0],
                    0.25 * prev[k - 1][1] + 0.5 * prev[k][1] + 0.25 * prev[k + 1][1],
                ];
                if self.cell(q).is_some_and(|c| base[c].is_finite()) {
                    points[k] = q;
                }
            }
        }
        points
    }
}

/// Whether the straight start–goal segment of the front axle comes within
/// `margin` of a circle.
pub fn straight_blocked(sc: &Scenario, margin: f64) -> bool {
    let s = [sc.start[ix::X], sc.start[ix::Y]];
    let g = [sc.goal.x, sc.goal.y];
    sc.obstacles
        .iter()
        .any(|o| segment_distance(s, g, [o.x, o.y]).0 < o.radius + margin)
}

/// The shortest route from the start through the points `via` (in order) to
/// the goal, with no side imposed (for independent checks with random
/// via-points); `None` when a leg has no path or a via-point is blocked.
pub fn via_route(sc: &Scenario, via: &[[f64; 2]]) -> Option<Route> {
    let s = [sc.start[ix::X], sc.start[ix::Y]];
    let g = [sc.goal.x, sc.goal.y];
    let grid = Grid::new(sc);
    let mut cost = grid.cost.clone();
    let ends = [grid.cell(s)?, grid.cell(g)?];
    for c in ends {
        cost[c] = cost[c].min(1.0 + SOFT_WEIGHT);
    }
    let mut stops = vec![s];
    stops.extend_from_slice(via);
    stops.push(g);
    let mut points: Vec<[f64; 2]> = Vec::new();
    for leg in stops.windows(2) {
        let (a, b) = (grid.cell(leg[0])?, grid.cell(leg[1])?);
        let cells = grid.shortest(&cost, a, b)?;
        let part = grid.finish(&cost, &cost, &cells, leg[0], leg[1]);
        if !points.is_empty() {
            points.pop();
        }
        points.extend(part);
    }
    let length = polyline_length(&points);
    Some(Route { points, length })
}

fn polyline_length(p: &[[f64; 2]]) -> f64 {
    p.windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum()
}

/// Points every `step` along a polyline (both ends kept).
fn resample(p: &[[f64; 2]], step: f64) -> Vec<[f64; 2]> {
    let total = polyline_length(p);
    let n = (total / step).ceil().max(1.0) as usize;
    let mut out = Vec::with_capacity(n + 1);
    let (mut seg, mut acc) = (0, 0.0);
    for k in 0..=n {
        let s = total * k as f64 / n as f64;
        while seg + 2 < p.len() {
            let l = (p[seg + 1][0] - p[seg][0]).hypot(p[seg + 1][1] - p[seg][1]);
            if acc + l >= s {
                break;
            }
            acc += l;
            seg += 1;
        }
        let l = (p[seg + 1][0] - p[seg][0])
            .hypot(p[seg + 1][1] - p[seg][1])
            .max(1e-12);
        let t = ((s - acc) / l).clamp(0.0, 1.0);
        out.push([
            p[seg][0] + t * (p[seg + 1][0] - p[seg][0]),
            p[seg][1] + t * (p[seg + 1][1] - p[seg][1]),
        ]);
    }
    out
}

/// Routes around each side of the clusters near the start–goal segment,
/// shortest first, distinct, at most `max_routes`.
pub fn side_routes(sc: &Scenario, max_routes: usize) -> Vec<Route> {
    let s = [sc.start[ix::X], sc.start[ix::Y]];
    let g = [sc.goal.x, sc.goal.y];
    if sc.obstacles.is_empty() || max_routes == 0 {
        return Vec::new();
    }
    let grid = Grid::new(sc);
    let (Some(sc_cell), Some(gc_cell)) = (grid.cell(s), grid.cell(g)) else {
        return Vec::new();
    };
    let d = [g[0] - s[0], g[1] - s[1]];
    let len = d[0].hypot(d[1]).max(1e-9);
    let left = [-d[1] / len, d[0] / len];
    // Per cluster, the circle nearest the segment: where its ray starts.
    let (label, count) = clusters(&sc.obstacles);
    let mut near: Vec<(f64, usize)> = (0..count)
        .filter_map(|c| {
            sc.obstacles
                .iter()
                .enumerate()
                .filter(|(i, _)| label[*i] == c)
                .map(|(i, o)| {
                    let (dist, _) = segment_distance(s, g, [o.x, o.y]);
                    (dist - o.radius, i)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
        })
        .filter(|(dist, _)| *dist < NEAR_SEGMENT)
        .collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0));
    near.truncate(MAX_SIDE_CLUSTERS);
    let mut routes: Vec<Route> = Vec::new();
    let mut cost = grid.cost.clone();
    // Start and goal may sit within the hard clearance (docked by a pile).
    for c in [sc_cell, gc_cell] {
        cost[c] = cost[c].min(1.0 + SOFT_WEIGHT);
    }
    let base = cost.clone();
    for mask in 0..(1usize << near.len()) {
        cost.copy_from_slice(&base);
        for (b, &(_, i)) in near.iter().enumerate() {
            let o = &sc.obstacles[i];
            // Bit set: pass on the left, so the way on the right is blocked.
            let dir = if mask >> b & 1 == 1 {
                [-left[0], -left[1]]
            } else {
                left
            };
            grid.block_ray(&mut cost, [o.x, o.y], dir);
        }
        if !cost[sc_cell].is_finite() || !cost[gc_cell].is_finite() {
            continue;
        }
        let Some(cells) = grid.shortest(&cost, sc_cell, gc_cell) else {
            continue;
        };
        let points = grid.finish(&cost, &base, &cells, s, g);
        let length = polyline_length(&points);
        let same = routes.iter().any(|r| same_route(&r.points, &points));
        if !same {
            routes.push(Route { points, length });
        }
    }
    routes.sort_by(|a, b| a.length.total_cmp(&b.length));
    routes.truncate(max_routes);
    routes
}

fn same_route(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    let (a, b) = (resample(a, 0.1), resample(b, 0.1));
    let dev = |p: &[[f64; 2]], q: &[[f64; 2]]| {
        p.iter()
            .map(|x| {
                q.iter()
                    .map(|y| (x[0] - y[0]).hypot(x[1] - y[1]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    };
    dev(&a, &b).max(dev(&b, &a)) < SAME_ROUTE
}

/// A min-time guess that drives `route` forward (or in reverse) at up to
/// `cruise`, accelerating and braking at `accel`.
pub fn route_guess(
    p: &MachineParams,
    sc: &Scenario,
    route: &Route,
    reverse: bool,
    cruise: f64,
    accel: f64,
) -> Guess {
    let pts = &route.points;
    let total = route.length.max(1e-6);
    // Trapezoidal profile of the arc length.
    let ramp = (cruise / accel).min((total / accel).sqrt());
    let v_top = accel * ramp;
    let t_cruise = ((total - v_top * ramp) / v_top).max(0.0);
    let duration = 2.0 * ramp + t_cruise;
    let arc = |t: f64| -> (f64, f64) {
        if t < ramp {
            (0.5 * accel * t * t, accel * t)
        } else if t < ramp + t_cruise {
            (0.5 * v_top * ramp + v_top * (t - ramp), v_top)
        } else {
            let r = (duration - t).max(0.0);
            (total - 0.5 * accel * r * r, accel * r)
        }
    };
    // Cumulative arc length of the route's points.
    let mut cum = vec![0.0; pts.len()];
    for k in 1..pts.len() {
        cum[k] = cum[k - 1] + (pts[k][0] - pts[k - 1][0]).hypot(pts[k][1] - pts[k - 1][1]);
    }
    let tangent = |k: usize| -> f64 {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(pts.len() - 1));
        let t = (pts[b][1] - pts[a][1]).atan2(pts[b][0] - pts[a][0]);
        if reverse {
            t + PI
        } else {
            t
        }
    };
    // Headings along the route, unwrapped from the start's heading, the last
    // metre blended into the goal heading's nearest branch.
    let mut heading = Vec::with_capacity(pts.len());
    let mut h = sc.start[ix::THETA] + wrap_angle(tangent(0) - sc.start[ix::THETA]);
    for k in 0..pts.len() {
        h += wrap_angle(tangent(k) - h);
        heading.push(h);
    }
    let end = *heading.last().expect("non-empty");
    let goal_theta = end + wrap_angle(sc.goal.theta - end);
    for k in 0..pts.len() {
        let w = (1.0 - (total - cum[k]) / 1.0).clamp(0.0, 1.0);
        heading[k] += w * (goal_theta - heading[k]);
    }
    let dt = 0.1;
    let steps = (duration / dt).ceil().max(1.0) as usize;
    let dt = duration / steps as f64;
    let sign = if reverse { -1.0 } else { 1.0 };
    let wheelbase = p.l_f + p.l_r;
    let mut states = Vec::with_capacity(steps + 1);
    let mut k = 0;
    for n in 0..=steps {
        let (s_arc, v) = arc(n as f64 * dt);
        while k + 2 < pts.len() && cum[k + 1] < s_arc {
            k += 1;
        }
        let seg = (cum[k + 1] - cum[k]).max(1e-9);
        let t = ((s_arc - cum[k]) / seg).clamp(0.0, 1.0);
        let x = pts[k][0] + t * (pts[k + 1][0] - pts[k][0]);
        let y = pts[k][1] + t * (pts[k + 1][1] - pts[k][1]);
        let th = heading[k] + t * (heading[k + 1] - heading[k]);
        // Curvature → articulation (steady turn: κ = sin β / (L_f cos β + L_r)).
        let kappa = (heading[k + 1] - heading[k]) / seg * sign;
        let beta = (kappa * wheelbase)
            .atan()
            .clamp(-0.9 * p.beta_max, 0.9 * p.beta_max);
        states.push(State::new(x, y, th, beta, 0.0, sign * v));
    }
    for n in 0..states.len() {
        let (a, b) = (n.saturating_sub(1), (n + 1).min(states.len() - 1));
        let rate = (states[b][ix::BETA] - states[a][ix::BETA]) / ((b - a).max(1) as f64 * dt);
        states[n][ix::BETA_DOT] = rate.clamp(-p.beta_dot_max, p.beta_dot_max);
    }
    let controls = states
        .windows(2)
        .map(|w| {
            Control::new(
                ((w[1][ix::BETA_DOT] - w[0][ix::BETA_DOT]) / dt)
                    .clamp(-p.beta_ddot_max, p.beta_ddot_max),
                ((w[1][ix::V] - w[0][ix::V]) / dt).clamp(-p.a_max, p.a_max),
            )
        })
        .collect();
    Guess {
        states,
        controls,
        dt,
        duration,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::model::Goal;

    fn blocked(obstacles: Vec<Obstacle>) -> Scenario {
        Scenario {
            name: "t".into(),
            start: State::zeros(),
            goal: Goal::new(8.0, 0.0, 0.0),
            obstacles,
        }
    }

    fn side_of(route: &Route, o: &Obstacle) -> f64 {
        // Signed lateral offset of the route where it passes the obstacle.
        route
            .points
            .iter()
            .min_by(|a, b| (a[0] - o.x).abs().total_cmp(&(b[0] - o.x).abs()))
            .map(|q| q[1] - o.y)
            .unwrap()
    }

    #[test]
    fn one_circle_gives_a_route_on_each_side_clear_of_it() {
        let o = Obstacle::new(4.0, 0.1, 1.0);
        let routes = side_routes(&blocked(vec![o]), 8);
        assert_eq!(routes.len(), 2, "{routes:?}");
        let sides: Vec<f64> = routes.iter().map(|r| side_of(r, &o)).collect();
        assert!(sides.iter().any(|s| *s > 1.0) && sides.iter().any(|s| *s < -1.0));
        // Shortest first: the circle is a little left of the line.
        assert!(sides[0] < 0.0 && routes[0].length < routes[1].length);
        for r in &routes {
            assert!(r.points.iter().all(|q| o.clearance_of(*q) > 0.0));
            assert!(r.length > 8.0 && r.length < 11.0);
        }
    }

    #[test]
    fn two_circles_give_four_routes_and_a_wall_counts_once() {
        let a = Obstacle::new(3.0, 0.0, 0.8);
        let b = Obstacle::new(6.0, 0.3, 0.8);
        let routes = side_routes(&blocked(vec![a, b]), 8);
        assert_eq!(routes.len(), 4);
        let mut combos: Vec<(bool, bool)> = routes
            .iter()
            .map(|r| (side_of(r, &a) > 0.0, side_of(r, &b) > 0.0))
            .collect();
        combos.sort();
        combos.dedup();
        assert_eq!(combos.len(), 4);
        // A wall of overlapping circles is one cluster: two ways round.
        let wall: Vec<Obstacle> = (-3..=3)
            .map(|k| Obstacle::new(4.0, k as f64 * 0.5, 0.4))
            .collect();
        assert_eq!(clusters(&wall).1, 1);
        assert_eq!(side_routes(&blocked(wall), 8).len(), 2);
    }

    #[test]
    fn route_guess_starts_at_the_start_and_ends_at_the_goal_at_rest() {
        let p = MachineParams::default();
        let sc = blocked(vec![Obstacle::new(4.0, 0.0, 1.0)]);
        let r = &side_routes(&sc, 1)[0];
        let g = route_guess(&p, &sc, r, false, 0.9, 1.0);
        let (first, last) = (g.states[0], *g.states.last().unwrap());
        assert!(first[ix::X].abs() < 1e-9 && first[ix::V].abs() < 1e-9);
        assert!((last[ix::X] - 8.0).abs() < 1e-9 && last[ix::V].abs() < 1e-9);
        assert!(wrap_angle(last[ix::THETA]).abs() < 1e-9);
        assert!((g.duration - (r.length / 0.9 + 0.9)).abs() < 1e-6);
        assert!(g.states.iter().all(|x| x[ix::BETA].abs() <= p.beta_max));
    }
}
