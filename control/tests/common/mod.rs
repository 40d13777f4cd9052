//! Shared helpers for the control crate's integration tests.
#![allow(dead_code)]

use control::mlp::PAPER_HIDDEN;
use control::weights::{random_network, NetworkMetadata, NetworkRole, NetworkWeights};
use control::{Actor, Critic};

/// A random critic of the paper's sizes with `m` outputs.
pub fn random_critic_weights(m: usize, seed: u64) -> NetworkWeights {
    random_network(
        NetworkMetadata::new(NetworkRole::Critic, m),
        &PAPER_HIDDEN,
        seed,
    )
}

pub fn random_critic(m: usize, seed: u64) -> Critic {
    Critic::from_weights(random_critic_weights(m, seed)).expect("random critic is valid")
}

pub fn random_actor(seed: u64) -> Actor {
    let w = random_network(
        NetworkMetadata::new(NetworkRole::Actor, 4),
        &PAPER_HIDDEN,
        seed,
    );
    Actor::from_weights(w).expect("random actor is valid")
}
