//! Scenario evaluation, the baseline and plots (DESIGN §7–8, issue 5).
//!
//! - [`ipopt`]: a small FFI over IPOPT's C interface, and [`nlp`] to assemble
//!   sparse NLPs from elements; [`collocation`] (Hermite–Simpson) and [`ocp`]:
//!   the paper's baseline trajectory optimisation and the min-time bound.

pub mod collocation;
pub mod ipopt;
pub mod nlp;
pub mod ocp;
