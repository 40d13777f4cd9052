//! A machine's trained networks, loaded together: above [`crate::weights`] (the
//! file format) and the networks it builds ([`crate::actor`], [`crate::critic`]),
//! so that neither depends on the other.

use std::path::Path;

use crate::actor::Actor;
use crate::critic::Critic;
use crate::model::MachineParams;
use crate::weights::{load_for, NetworkRole, WeightsError, ACTOR_FILE, CRITIC_FILE};

/// The critic and actor of one machine's weights directory ([`CRITIC_FILE`],
/// [`ACTOR_FILE`]), both checked with [`load_for`] against the machine and Δt.
pub fn load_networks(
    dir: &Path,
    machine: &MachineParams,
    dt: f64,
) -> Result<(Critic, Actor), WeightsError> {
    let critic = load_for(&dir.join(CRITIC_FILE), NetworkRole::Critic, machine, dt)?;
    let actor = load_for(&dir.join(ACTOR_FILE), NetworkRole::Actor, machine, dt)?;
    Ok((Critic::from_weights(critic)?, Actor::from_weights(actor)?))
}
