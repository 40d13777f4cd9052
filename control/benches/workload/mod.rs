//! The MPC bench's workload, shared by `benches/mpc.rs` and
//! `examples/tick_ab.rs` (which must also build against older commits, so it
//! uses nothing of the library's beyond these types).

use control::model::Goal;
use control::mpc::Obstacle;

/// The goal the machine drives to from the origin.
pub const GOAL: Goal = Goal::new(6.0, 4.0, 1.2);

/// The bench's two circles, then six more around the way to the goal (each
/// within reach at some point).
pub const CIRCLES: [Obstacle; 8] = [
    Obstacle::new(3.0, 1.0, 0.8),
    Obstacle::new(1.0, 4.0, 0.6),
    Obstacle::new(5.0, 1.5, 0.5),
    Obstacle::new(-1.5, 1.0, 0.5),
    Obstacle::new(2.0, -1.5, 0.5),
    Obstacle::new(4.0, 6.0, 0.5),
    Obstacle::new(7.5, 2.5, 0.4),
    Obstacle::new(-1.0, -2.0, 0.6),
];
