//! Roll-outs of the actor's deterministic action on the model (the RL
//! environment's transition, [`env_step`]) against the obstacles.
//!
//! Why the actor: the critic and actor know no obstacles, and the MPC's warm
//! start on every new goal is exactly this roll-out, so it is the best cheap
//! prediction of where the MPC will drive. A roll-out that keeps the margin
//! and reaches its target says "nothing is in the way" (the direct case), is
//! the Hybrid A* search's goal shot, and checks a waypoint-graph edge.

use crate::actor::{Actor, ActorWorkspace};
use crate::model::{env_step, goal_distance, ix, Goal, MachineParams, State};

use super::world::CheckedWorld;

/// When a roll-out counts as arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Arrival {
    /// DESIGN §7's pose error ‖(Δx, Δy, e_θ)‖ below this (the final goal).
    Pose(f64),
    /// Front-axle position within this radius (a subgoal passed through).
    Position(f64),
}

impl Arrival {
    fn reached(self, x: &State, g: &Goal) -> bool {
        match self {
            Arrival::Pose(tol) => goal_distance(x, g) < tol,
            Arrival::Position(r) => (x[ix::X] - g.x).hypot(x[ix::Y] - g.y) < r,
        }
    }
}

/// How a roll-out ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rollout {
    /// Arrived without touching the margin.
    pub reached: bool,
    /// Some state came within the margin of a circle.
    pub collided: bool,
    /// Steps taken (of `dt`).
    pub steps: usize,
    /// The last state.
    pub end: State,
}

impl Rollout {
    pub fn duration(&self, dt: f64) -> f64 {
        self.steps as f64 * dt
    }
}

/// Rolls the actor out from `start` towards `goal` for at most `max_steps`
/// steps of `dt`, stopping at arrival or at the first state within the margin.
/// With `trace`, every state after the start is appended to it (within its
/// capacity). Allocation-free.
#[allow(clippy::too_many_arguments)]
pub fn roll_out(
    params: &MachineParams,
    actor: &Actor,
    ws: &mut ActorWorkspace,
    world: &CheckedWorld,
    start: &State,
    goal: &Goal,
    arrival: Arrival,
    dt: f64,
    max_steps: usize,
    mut trace: Option<&mut Vec<State>>,
) -> Rollout {
    let mut x = *start;
    for k in 0..=max_steps {
        if !world.state_free(&x) {
            return Rollout {
                reached: false,
                collided: true,
                steps: k,
                end: x,
            };
        }
        if arrival.reached(&x, goal) {
            return Rollout {
                reached: true,
                collided: false,
                steps: k,
                end: x,
            };
        }
        if k < max_steps {
            let u = actor.action(ws, &x, goal);
            x = env_step(params, &x, &u, dt);
            if let Some(t) = trace.as_deref_mut() {
                if t.len() < t.capacity() {
                    t.push(x);
                }
            }
        }
    }
    Rollout {
        reached: false,
        collided: false,
        steps: max_steps,
        end: x,
    }
}
