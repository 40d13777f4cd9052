//! Offline ALAC training of wlnav's goal-conditioned actor and critic. Uses
//! `control`'s model, transition, cost and encoder, so training and deployment
//! cannot drift. Never linked by the daemon.

pub mod agent;
pub mod buffer;
pub mod config;
pub mod env;
pub mod evaluate;
pub mod fused;
pub mod nets;
pub mod params;
pub mod plot;
pub mod run;
pub mod select;
pub mod stalls;
