//! The min-time NLP's initial guess, built by [`crate::routes`] and the
//! runner and consumed by [`crate::ocp`] (its own module, so that neither of
//! the two depends on the other).

use control::model::{Control, State};

/// A trajectory sampled every `dt` (states, and the controls between them),
/// used as an initial guess for min-time up to `duration`.
#[derive(Debug, Clone)]
pub struct Guess {
    pub states: Vec<State>,
    pub controls: Vec<Control>,
    pub dt: f64,
    pub duration: f64,
}
