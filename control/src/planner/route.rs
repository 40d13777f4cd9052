//! From a planned path to the MPC's subgoals.
//!
//! The critic is goal-conditioned, so a subgoal is just a [`Goal`]: a pose on
//! the path with the path's heading there. Spacing: far enough that the MPC
//! keeps its speed between them (it is switched to the next one within the
//! subgoal radius, before it slows down), close enough that the obstacle-blind
//! actor's line from one to the next stays near the collision-free path. Cusps
//! (where the path changes between forward and reverse) are always subgoals:
//! the machine must stop there.

use crate::model::Goal;

use super::path_geometry::is_cusp;
use super::PathPose;

/// Writes the subgoals of `path` (start first) followed by `goal` into
/// `route`, and each one's index in `path` into `at` (the goal's is
/// `path.len()`); both are cleared first and stay within their capacity.
/// Subgoals closer than `min_gap` to the start or to the goal are dropped: the
/// first would be passed at once, the last is the goal's job.
pub fn subgoals_from_path(
    path: &[PathPose],
    goal: Goal,
    spacing: f64,
    min_gap: f64,
    route: &mut Vec<Goal>,
    at: &mut Vec<usize>,
) {
    route.clear();
    at.clear();
    let reserve_for_goal = 1;
    let mut push = |route: &mut Vec<Goal>, i: usize| {
        let p = &path[i];
        let near_start = path
            .first()
            .is_some_and(|s| (p.x - s.x).hypot(p.y - s.y) < min_gap);
        let near_goal = (p.x - goal.x).hypot(p.y - goal.y) < min_gap;
        let near_last = route
            .last()
            .is_some_and(|l: &Goal| (p.x - l.x).hypot(p.y - l.y) < min_gap);
        if !(near_start || near_goal || near_last)
            && route.len() + reserve_for_goal < route.capacity()
            && at.len() + reserve_for_goal < at.capacity()
        {
            route.push(Goal::new(p.x, p.y, p.theta));
            at.push(i);
        }
    };
    let mut since = 0.0;
    for i in 1..path.len() {
        let (a, b) = (&path[i - 1], &path[i]);
        since += (b.x - a.x).hypot(b.y - a.y);
        let last = i + 1 == path.len();
        if since >= spacing || is_cusp(path, i) || last {
            push(route, i);
            since = 0.0;
        }
    }
    route.push(goal);
    at.push(path.len());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, direction: i8) -> PathPose {
        PathPose {
            x,
            y: 0.0,
            theta: 0.0,
            beta: 0.0,
            direction,
        }
    }

    #[test]
    fn spacing_cusps_and_the_goal() {
        // Forward 0 → 6 m in 0.5 m steps, then reverse back to 4 m.
        let mut path: Vec<PathPose> = (0..=12).map(|k| pose(0.5 * k as f64, 1)).collect();
        path.extend((1..=4).map(|k| pose(6.0 - 0.5 * k as f64, -1)));
        let goal = Goal::new(0.0, 3.0, 1.0);
        let (mut route, mut at) = (Vec::with_capacity(32), Vec::with_capacity(32));
        subgoals_from_path(&path, goal, 2.5, 0.8, &mut route, &mut at);
        let xs: Vec<f64> = route.iter().map(|g| g.x).collect();
        // 2.5 and 5.0 by spacing, 6.0 the cusp, 4.0 the path's end, then the goal.
        assert_eq!(xs, vec![2.5, 5.0, 6.0, 4.0, 0.0]);
        assert_eq!(*route.last().unwrap(), goal);
        assert_eq!(at, vec![5, 10, 12, 16, 17]);
        // The path's end near the goal is left to the goal.
        let near = Goal::new(4.3, 0.0, 0.0);
        subgoals_from_path(&path, near, 2.5, 0.8, &mut route, &mut at);
        let xs: Vec<f64> = route.iter().map(|g| g.x).collect();
        // (5.0 is within the gap of it.)
        assert_eq!(xs, vec![2.5, 6.0, 4.3]);
        assert_eq!(at, vec![5, 12, 17]);
    }
}
