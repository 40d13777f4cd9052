//! Scenario evaluation, the baseline and plots (DESIGN §7–8, issue 5).
//!
//! - The baseline, the min-time bound and the planner's trajectory are
//!   solved by [`trajopt`] (IPOPT).
//! - [`runner`]: closed-loop runs of the MPC and the actor on the simulated
//!   plant, the baseline's replay, min-time; scenarios in parallel.
//! - [`results`]: the results CSV and summary statistics; [`plots`]: SVGs;
//!   [`eval`]: the `eval` command's outputs; [`report`]: the `paper` command;
//!   [`robustness`]: the `robustness` command (DESIGN §12).
//!
//! Scenario files are parsed by [`control::scenario`]; the committed ones are
//! in `sim/scenarios/`.

pub mod clearance;
pub mod eval;
pub mod movers;
pub mod plots;
pub mod report;
pub mod results;
pub mod robustness;
pub mod runner;
