//! The route shaped by time (issue 42, design (d) of `docs/global-layer.md`):
//! a minimum-time trajectory on the machine model, warm-started from the
//! route (the search's path, or the open way's roll-out), that the MPC
//! tracks ([`crate::mpc::TrackCost`]) in place of following the path.
//!
//! Why: Hybrid A*'s lattice (0.6 m arcs at three articulations) and the
//! actor's goal shot from rest reach the goal's heading by loops the time
//! bound does not make; its path changes β in steps at the nodes, so its rear
//! axle's path jumps. A trajectory of the model with its bounds is smooth in
//! β and as short in time as the optimiser finds.
//!
//! The optimiser is a trait so that the planner (pure, in `control`) does not
//! depend on the solver: `trajopt::trajectory` implements it over IPOPT, the
//! bound's own collocation, for `wlnavd` and `wlnav-sim` (`[navigator]
//! trajectory`, on by default). It runs where the route is planned, after
//! the search; a failed or rejected
//! solve leaves the route as the search made it, followed as before.

use crate::model::{ix, Goal, State, REACH_SPEED};

use super::world::CheckedWorld;
use super::PathPose;

/// Why a route was not shaped (the route stays and is followed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TrajectoryFailure {
    /// The route gives no warm start (empty, or shorter than a step).
    #[error("no warm start")]
    NoWarmStart,
    /// The optimiser stopped without a feasible solution (its status).
    #[error("not solved ({status})")]
    NotSolved { status: &'static str },
    /// The solution comes nearer than the margins to something among none
    /// of its rows.
    #[error("leaves the margins")]
    LeavesMargins,
    /// More states than the buffer holds.
    #[error("too long")]
    TooLong,
}

/// What shaping did with a plan's route ([`super::PlanReport::trajectory`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TrajectoryOutcome {
    /// Not asked: no optimiser, no path (open ground driven by the critic),
    /// a retry, or no route.
    #[default]
    NotAsked,
    /// Shaped: the trajectory's duration [s].
    Shaped { duration: f64 },
    /// Asked and failed: the route is followed.
    Failed(TrajectoryFailure),
}

impl std::fmt::Display for TrajectoryOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TrajectoryOutcome::NotAsked => f.write_str("not asked"),
            TrajectoryOutcome::Shaped { duration } => write!(f, "{duration:.2} s"),
            TrajectoryOutcome::Failed(why) => write!(f, "none: {why}"),
        }
    }
}

/// A minimum-time trajectory from a route.
pub trait TrajectoryOptimiser: Send {
    /// A trajectory from `start` to `goal` that keeps `world`'s margins (the
    /// route's margin plus each outline circle's extra), warm-started from
    /// the route: the search's `path`, then its goal `shot` (may be empty).
    /// Writes the trajectory's states, start first, evenly spaced in time,
    /// into `out` (cleared first, within its capacity) and returns their
    /// spacing [s]; why there is none otherwise (the route stays).
    fn optimise(
        &mut self,
        world: &CheckedWorld,
        start: &State,
        goal: &Goal,
        path: &[PathPose],
        shot: &[State],
        out: &mut Vec<State>,
    ) -> Result<f64, TrajectoryFailure>;
}

/// Appends states (a roll-out's or a trajectory's, start first) to `path`
/// as poses, each with the direction of the motion leaving it (the last
/// keeps the one before), within `path`'s capacity. A pose nearer than
/// `min_spacing` to the last one kept is left out unless the direction
/// changes at it or the path ends there: where a trajectory stops to reverse
/// it articulates at rest and its front axle swings sideways, segments the
/// path's tangent must not be taken from.
pub fn push_states_as_path(states: &[State], min_spacing: f64, path: &mut Vec<PathPose>) {
    let direction_at = |i: usize, last: i8| {
        let v = states.get(i + 1).unwrap_or(&states[i])[ix::V];
        if v.abs() > REACH_SPEED {
            if v < 0.0 {
                -1
            } else {
                1
            }
        } else {
            last
        }
    };
    let mut direction = 1;
    for (i, x) in states.iter().enumerate() {
        if path.len() == path.capacity() {
            break;
        }
        direction = direction_at(i, direction);
        let turning = i + 1 < states.len() && direction_at(i + 1, direction) != direction;
        let spaced = path.last().is_none_or(|p: &PathPose| {
            p.direction != direction || (p.x - x[ix::X]).hypot(p.y - x[ix::Y]) >= min_spacing
        });
        if spaced || turning || i + 1 == states.len() {
            path.push(PathPose {
                x: x[ix::X],
                y: x[ix::Y],
                theta: x[ix::THETA],
                beta: x[ix::BETA],
                direction,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_follow_the_motion_leaving_each_state() {
        let s = |x: f64, v: f64| State::new(x, 0.0, 0.0, 0.0, 0.0, v);
        // Forward, a stop (v below the reach speed keeps the last direction), reverse.
        let states = [
            s(0.0, 0.0),
            s(0.5, 1.0),
            s(1.0, 0.01),
            s(0.8, -0.5),
            s(0.6, -0.5),
        ];
        let mut path = Vec::with_capacity(4);
        push_states_as_path(&states, 0.0, &mut path);
        let dirs: Vec<i8> = path.iter().map(|p| p.direction).collect();
        // Within capacity (4 of 5), each the motion leaving it.
        assert_eq!(dirs, vec![1, 1, -1, -1]);
        assert_eq!(path[2].x, 1.0);
    }

    #[test]
    fn thinning_keeps_the_cusp_and_the_end() {
        // Forward 0 → 2 m in 5 cm steps, then back to 1 m.
        let mut states: Vec<State> = (0..=40)
            .map(|k| {
                State::new(
                    0.05 * k as f64,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    if k == 0 { 0.0 } else { 1.0 },
                )
            })
            .collect();
        states
            .extend((1..=20).map(|k| State::new(2.0 - 0.05 * k as f64, 0.0, 0.0, 0.0, 0.0, -1.0)));
        let mut path = Vec::with_capacity(100);
        push_states_as_path(&states, 0.5, &mut path);
        let xs: Vec<f64> = path.iter().map(|p| (p.x * 100.0).round() / 100.0).collect();
        // Every 0.5 m, the cusp at 2.0 (and the pose before it, where the
        // direction leaving it turns), then back every 0.5 m to the end.
        assert_eq!(xs, vec![0.0, 0.5, 1.0, 1.5, 1.95, 2.0, 1.5, 1.0]);
        let cusps: Vec<usize> = (0..path.len())
            .filter(|&i| super::super::path_geometry::is_cusp(&path, i))
            .collect();
        // The cusp is the last pose left forwards (directions are the motion
        // leaving a pose), one step before the turn.
        assert_eq!(cusps.len(), 1);
        assert!((path[cusps[0]].x - 1.95).abs() < 1e-9);
    }
}
