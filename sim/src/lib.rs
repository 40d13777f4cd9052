//! Scenario evaluation, the baseline and plots (DESIGN §7–8, issue 5).
//!
//! - [`ipopt`]: a small FFI over IPOPT's C interface, and [`nlp`] to assemble
//!   sparse NLPs from elements; [`collocation`] (Hermite–Simpson) and [`ocp`]:
//!   the paper's baseline trajectory optimisation and the min-time bound
//!   ([`guess`]: their initial guess; [`routes`]: guesses around obstacles).
//! - [`runner`]: closed-loop runs of the MPC and the actor on the simulated
//!   plant, the baseline's replay, min-time; scenarios in parallel.
//! - [`results`]: the results CSV and summary statistics; [`plots`]: SVGs;
//!   [`eval`]: the `eval` command's outputs; [`report`]: the `paper` command;
//!   [`robustness`]: the `robustness` command (DESIGN §12).
//!
//! Scenario files are parsed by [`control::scenario`]; the committed ones are
//! in `sim/scenarios/`.

pub mod clearance;
pub mod collocation;
pub mod eval;
pub mod guess;
pub mod ipopt;
pub mod movers;
pub mod nlp;
pub mod ocp;
pub mod plots;
pub mod report;
pub mod results;
pub mod robustness;
pub mod routes;
pub mod runner;
pub mod trajectory;
