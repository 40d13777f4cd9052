//! Goal validation by footprint (DESIGN §10 "Goal validation"): a goal is refused at
//! request time when the machine could never stand there, or could not start from where
//! it stands.
//!
//! * The footprint at the goal — the goal pose with the machine straight (β = 0), both
//!   axle points ([`AxlePoint`]) — must be outside every obstacle circle.
//! * No obstacle may contain the machine's current footprint: an axle point inside a
//!   circle means the obstacle list and the machine disagree (a wrong map, or an obstacle
//!   placed on the machine), and the MPC's soft constraints would make it lurch out.
//!
//! This is the one place the check lives: the daemon calls [`check_goal`] when a goal
//! arrives; a global layer's `set_goal` can call it before its route search.

use crate::model::{Goal, MachineParams, State};
use crate::obstacle::{AxlePoint, Obstacle};

/// Why a goal is refused: which footprint, which obstacle, which axle point and how deep.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GoalConflict {
    /// The machine's footprint at the goal (β = 0) lies inside an obstacle.
    #[error(
        "goal-in-collision: at the goal ({:.2}, {:.2}, {:.2} rad) the {} axle is {:.2} m inside \
         obstacle {index} at ({:.2}, {:.2}) r {:.2} m",
        goal.x, goal.y, goal.theta, axle_name(*point), -clearance,
        obstacle.x, obstacle.y, obstacle.radius
    )]
    GoalInCollision {
        /// The goal.
        goal: Goal,
        /// Index of the obstacle in the request.
        index: usize,
        /// The obstacle.
        obstacle: Obstacle,
        /// The axle point inside it.
        point: AxlePoint,
        /// Signed distance to the circle's edge [m] (negative: inside).
        clearance: f64,
    },
    /// An obstacle contains the machine's current footprint.
    #[error(
        "machine-in-collision: obstacle {index} at ({:.2}, {:.2}) r {:.2} m contains the \
         machine's {} axle ({:.2} m inside)",
        obstacle.x, obstacle.y, obstacle.radius, axle_name(*point), -clearance
    )]
    MachineInCollision {
        /// Index of the obstacle in the request.
        index: usize,
        /// The obstacle.
        obstacle: Obstacle,
        /// The axle point inside it.
        point: AxlePoint,
        /// Signed distance to the circle's edge [m] (negative: inside).
        clearance: f64,
    },
}

fn axle_name(point: AxlePoint) -> &'static str {
    match point {
        AxlePoint::Front => "front",
        AxlePoint::Rear => "rear",
    }
}

/// The deepest (axle point, obstacle) penetration of state `x`, if any point is inside
/// a circle (clearance < 0; touching the edge is allowed, as in the MPC's constraint).
fn deepest_penetration(
    p: &MachineParams,
    x: &State,
    obstacles: &[Obstacle],
) -> Option<(usize, AxlePoint, f64)> {
    let mut worst: Option<(usize, AxlePoint, f64)> = None;
    for point in AxlePoint::ALL {
        let q = point.position(p, x);
        for (index, o) in obstacles.iter().enumerate() {
            let c = o.clearance_of(q);
            if c < 0.0 && !matches!(worst, Some(w) if w.2 <= c) {
                worst = Some((index, point, c));
            }
        }
    }
    worst
}

/// Checks a goal against the obstacles sent with it: first the footprint at the goal
/// (β = 0), then the machine's current footprint `current` (skipped when unknown). The
/// error names the obstacle with the deepest penetration.
pub fn check_goal(
    p: &MachineParams,
    current: Option<&State>,
    goal: &Goal,
    obstacles: &[Obstacle],
) -> Result<(), GoalConflict> {
    let at_goal = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
    if let Some((index, point, clearance)) = deepest_penetration(p, &at_goal, obstacles) {
        return Err(GoalConflict::GoalInCollision {
            goal: *goal,
            index,
            obstacle: obstacles[index],
            point,
            clearance,
        });
    }
    if let Some(x) = current {
        if let Some((index, point, clearance)) = deepest_penetration(p, x, obstacles) {
            return Err(GoalConflict::MachineInCollision {
                index,
                obstacle: obstacles[index],
                point,
                clearance,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn avant() -> MachineParams {
        MachineParams::default()
    }

    #[test]
    fn a_free_goal_from_a_free_machine_passes() {
        let p = avant();
        let obstacles = [Obstacle::new(3.0, 3.0, 1.0)];
        let here = State::zeros();
        assert_eq!(
            check_goal(&p, Some(&here), &Goal::new(5.0, 0.0, 0.0), &obstacles),
            Ok(())
        );
        assert_eq!(check_goal(&p, None, &Goal::new(5.0, 0.0, 0.0), &[]), Ok(()));
    }

    #[test]
    fn the_rear_axle_at_the_goal_counts() {
        let p = avant();
        // Goal (5, 0, 0): front axle at (5, 0), rear axle at (5 − l_f − l_r, 0) = (3.8, 0).
        // The circle holds the rear axle only.
        let o = Obstacle::new(3.8, 0.1, 0.3);
        assert!(o.clearance_of([5.0, 0.0]) > 0.5);
        let e = check_goal(
            &p,
            None,
            &Goal::new(5.0, 0.0, 0.0),
            &[Obstacle::new(-9.0, 0.0, 1.0), o],
        )
        .unwrap_err();
        match e {
            GoalConflict::GoalInCollision {
                index,
                point,
                clearance,
                ..
            } => {
                assert_eq!((index, point), (1, AxlePoint::Rear));
                assert!((clearance - (0.1 - 0.3)).abs() < 1e-12, "{clearance}");
            }
            other => panic!("{other:?}"),
        }
        let text = e.to_string();
        assert!(text.starts_with("goal-in-collision"), "{text}");
        assert!(
            text.contains("obstacle 1") && text.contains("rear axle"),
            "{text}"
        );
        // Turned around, the same goal position puts the rear axle on the other side.
        assert_eq!(
            check_goal(&p, None, &Goal::new(5.0, 0.0, std::f64::consts::PI), &[o]),
            Ok(())
        );
    }

    #[test]
    fn the_front_axle_at_the_goal_counts_and_the_deepest_obstacle_is_named() {
        let p = avant();
        let shallow = Obstacle::new(5.0, 0.45, 0.5);
        let deep = Obstacle::new(5.1, 0.0, 0.5);
        let e = check_goal(&p, None, &Goal::new(5.0, 0.0, 0.0), &[shallow, deep]).unwrap_err();
        assert!(matches!(
            e,
            GoalConflict::GoalInCollision {
                index: 1,
                point: AxlePoint::Front,
                ..
            }
        ));
        // On the edge is allowed (the MPC's constraint is distance ≥ r).
        let edge = Obstacle::new(5.5, 0.0, 0.5);
        assert_eq!(
            check_goal(&p, None, &Goal::new(5.0, 0.0, 0.0), &[edge]),
            Ok(())
        );
    }

    #[test]
    fn an_obstacle_containing_the_machine_is_refused() {
        let p = avant();
        let here = State::new(0.0, 0.0, 0.0, 0.3, 0.0, 0.0);
        let rear = AxlePoint::Rear.position(&p, &here);
        let on_machine = Obstacle::new(rear[0], rear[1] + 0.1, 0.4);
        let e = check_goal(
            &p,
            Some(&here),
            &Goal::new(5.0, 0.0, 0.0),
            &[Obstacle::new(3.0, 3.0, 1.0), on_machine],
        )
        .unwrap_err();
        assert!(matches!(
            e,
            GoalConflict::MachineInCollision {
                index: 1,
                point: AxlePoint::Rear,
                ..
            }
        ));
        assert!(e.to_string().contains("obstacle 1"), "{e}");
        // Unknown current state: only the goal is checked.
        assert_eq!(
            check_goal(&p, None, &Goal::new(5.0, 0.0, 0.0), &[on_machine]),
            Ok(())
        );
    }

    #[test]
    fn a_goal_in_collision_is_reported_before_the_machine() {
        let p = avant();
        let here = State::zeros();
        let both = [Obstacle::new(0.0, 0.0, 0.5), Obstacle::new(5.0, 0.0, 0.5)];
        assert!(matches!(
            check_goal(&p, Some(&here), &Goal::new(5.0, 0.0, 0.0), &both),
            Err(GoalConflict::GoalInCollision { index: 1, .. })
        ));
    }
}
