//! Trajectory optimisation by direct collocation, solved by IPOPT (DESIGN §7–8,
//! issue 42): the one place the project calls a nonlinear programming solver.
//!
//! - [`ipopt`]: a small FFI over IPOPT's C interface, and [`nlp`] to assemble
//!   sparse NLPs from elements; [`collocation`]: Hermite–Simpson defects.
//! - [`ocp`]: the paper's baseline trajectory optimisation and the min-time
//!   bound of a scenario ([`guess`]: their initial guess; [`routes`]: guesses
//!   around obstacles).
//! - [`trajectory`]: the planner's min-time trajectory along a route
//!   ([`control::planner::TrajectoryOptimiser`]), on the planner thread of
//!   the daemon and of the simulator.

pub mod collocation;
pub mod guess;
pub mod ipopt;
pub mod nlp;
pub mod ocp;
pub mod routes;
pub mod trajectory;
