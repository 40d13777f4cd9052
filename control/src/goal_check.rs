//! Goal validation by footprint (DESIGN §10 "Goal validation"): a goal is refused at
//! request time when the machine could never stand there, or could not start from where
//! it stands.
//!
//! * The machine's outline at the goal — the goal pose with the machine straight (β = 0)
//!   — must meet nothing of the world ([`World`]: the site's obstacles and keep-outs,
//!   its bounds, the circles sent with the goal; DESIGN §17).
//! * Nothing may meet the machine's current outline: an overlap there means the world
//!   and the machine disagree (a wrong map, or an obstacle placed on the machine), and
//!   the MPC's soft constraints would make it lurch out.
//!
//! This is the one place the check lives: the daemon calls [`check_goal`] when a goal
//! arrives; a global layer's `set_goal` can call it before its route search.

use crate::model::{Goal, State};
use crate::site::outline::Body;
use crate::world::{Contact, Target, World};

/// Why a goal is refused: which footprint, what it meets (a goal's circle, a
/// site's feature or its bounds), by which circle of the outline and how deep.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GoalConflict {
    /// The machine's outline at the goal (β = 0) meets something.
    #[error(
        "goal-in-collision: at the goal ({:.2}, {:.2}, {:.2} rad) the {circle_name} is {:.2} m \
         inside {what}",
        goal.x, goal.y, goal.theta, -clearance
    )]
    GoalInCollision {
        goal: Goal,
        /// What it meets.
        target: Target,
        /// The outline's circle that meets it.
        circle: usize,
        circle_name: String,
        /// Clearance [m] (negative: overlapping).
        clearance: f64,
        /// The target as a message names it.
        what: String,
    },
    /// Something meets the machine's current outline.
    #[error("machine-in-collision: {what} contains the machine's {circle_name} ({:.2} m inside)", -clearance)]
    MachineInCollision {
        target: Target,
        circle: usize,
        circle_name: String,
        clearance: f64,
        what: String,
    },
}

/// "front axle" / "rear axle" for a circle on an axle (the default
/// outline's), else "front body's circle 2".
fn circle_name(world: &World, i: usize) -> String {
    let c = &world.outline().circles()[i];
    let body = match c.body {
        Body::Front => "front",
        Body::Rear => "rear",
    };
    if c.offset == [0.0, 0.0] {
        format!("{body} axle")
    } else {
        format!("{body} body's circle {i}")
    }
}

/// The deepest overlap of the outline at `x` with anything in `world`
/// (clearance < 0; touching is allowed, as in the MPC's constraint).
fn deepest(world: &World, x: &State) -> Option<Contact> {
    world.excess(x, &[0.0; crate::site::MAX_OUTLINE_CIRCLES], 0.0)
}

/// Checks a goal against the world (the site and the circles sent with the
/// goal): first the outline at the goal (β = 0), then the machine's current
/// outline `current` (skipped when unknown). The error names the deepest
/// overlap: the feature's id and its site, or the circle.
pub fn check_goal(world: &World, current: Option<&State>, goal: &Goal) -> Result<(), GoalConflict> {
    let at_goal = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
    if let Some(c) = deepest(world, &at_goal) {
        return Err(GoalConflict::GoalInCollision {
            goal: *goal,
            target: c.target,
            circle: c.circle,
            circle_name: circle_name(world, c.circle),
            clearance: c.clearance,
            what: world.describe(c.target),
        });
    }
    if let Some(x) = current {
        if let Some(c) = deepest(world, x) {
            return Err(GoalConflict::MachineInCollision {
                target: c.target,
                circle: c.circle,
                circle_name: circle_name(world, c.circle),
                clearance: c.clearance,
                what: world.describe(c.target),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::MachineParams;
    use crate::obstacle::{AxlePoint, Obstacle};

    /// The default outline among `obstacles`.
    fn world(p: &MachineParams, obstacles: &[Obstacle]) -> World {
        let mut w = World::with_axle_circles(*p, 8);
        w.set_circles(obstacles).unwrap();
        w
    }

    fn check_goal(
        p: &MachineParams,
        current: Option<&State>,
        goal: &Goal,
        obstacles: &[Obstacle],
    ) -> Result<(), GoalConflict> {
        super::check_goal(&world(p, obstacles), current, goal)
    }

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
                target,
                circle,
                clearance,
                ..
            } => {
                assert_eq!((target, circle), (Target::Circle(1), 1));
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
                target: Target::Circle(1),
                circle: 0,
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
                target: Target::Circle(1),
                circle: 1,
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
            Err(GoalConflict::GoalInCollision {
                target: Target::Circle(1),
                ..
            })
        ));
    }

    /// A site's keep-out at the goal is named by its id and site; the goal
    /// beside it passes; a truer outline (the bucket ahead) meets it from
    /// farther away.
    #[test]
    fn a_site_feature_is_named() {
        use crate::site::{Outline, Site, SiteIndex};
        let site = Site::parse(
            br#"{"format": "wlnav-site-v1", "id": "yard", "version": 2,
                 "bounds": [[-20, -20], [20, -20], [20, 20], [-20, 20]],
                 "obstacles": [{"id": "pile-1", "circle": [0, 10, 2]}],
                 "keepout": [{"id": "office", "polygon": [[6, -1], [9, -1], [9, 1], [6, 1]]}]}"#,
        )
        .unwrap();
        let p = avant();
        let mut w = World::with_axle_circles(p, 8);
        w.set_site(Some(std::sync::Arc::new(SiteIndex::new(site))));
        let e =
            super::check_goal(&w, Some(&State::zeros()), &Goal::new(7.0, 0.0, 0.0)).unwrap_err();
        assert!(
            e.to_string().contains("keep-out `office` of site `yard`"),
            "{e}"
        );
        // Front axle 4.5 m: its circle (0.65) keeps 0.85 m from the office.
        let beside = Goal::new(4.5, 0.0, 0.0);
        assert_eq!(
            super::check_goal(&w, Some(&State::zeros()), &beside),
            Ok(())
        );
        // The Avant's bucket reaches 1.2 + 0.72 m ahead of the front axle.
        w.set_outline(Outline::avant635());
        let e = super::check_goal(&w, None, &beside).unwrap_err();
        assert!(e.to_string().contains("front body's circle 2"), "{e}");
        // Outside the bounds.
        w.set_outline(crate::world::default_outline());
        let e = super::check_goal(&w, None, &Goal::new(19.8, 0.0, 0.0)).unwrap_err();
        assert!(e.to_string().contains("the bounds of site `yard`"), "{e}");
        // On the machine.
        let e = super::check_goal(&w, Some(&State::new(0.0, 9.0, 0.0, 0.0, 0.0, 0.0)), &beside)
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("machine-in-collision: obstacle `pile-1`"),
            "{e}"
        );
    }
}
