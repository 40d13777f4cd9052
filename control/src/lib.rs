//! wlnav's numerical core: the wheel-loader model, a simulated machine, the
//! critic and actor kernels and the MPC. Pure computation: no I/O (the one
//! exception: [`weights`] reads weight files, the one loader every program uses),
//! no async, no global state; functions take buffers and return results.

pub mod actor;
pub mod assumption_check;
pub mod cost;
pub mod critic;
pub mod delay;
pub mod delay_estimate;
pub mod encoder;
pub mod envelope;
pub mod gain;
pub mod goal_check;
pub mod live;
pub mod mlp;
pub mod model;
pub mod movers;
pub mod mpc;
pub mod networks;
pub mod obstacle;
pub mod pilot;
pub mod planner;
pub mod plant;
pub mod progress;
pub mod scenario;
pub mod site;
pub mod weights;
pub mod world;

pub use actor::{Actor, ActorWorkspace};
pub use cost::{CostForm, CostWeights};
pub use critic::{Critic, CriticWorkspace, Derivatives, HessianMode, TerminalDerivatives};
pub use encoder::Encoder;
pub use model::{Control, Goal, MachineParams, State, VelocityCommand};
pub use obstacle::Obstacle;
pub use plant::{Plant, PlantConfig, PlantPerturbation};
