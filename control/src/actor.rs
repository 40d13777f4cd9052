//! The deployed actor: deterministic (mean) action a = tanh(μ(s, g)) ⊙ (β̈_max, a_max)
//! (paper §IV-C), used to initialise the MPC's horizon on a new goal.

use crate::encoder::{Encoder, ACTOR_INPUTS};
use crate::mlp::{Mlp, MlpWorkspace};
use crate::model::{Control, Goal, State};
use crate::weights::{NetworkMetadata, NetworkRole, NetworkWeights, WeightsError};

#[derive(Debug, Clone)]
pub struct Actor {
    mlp: Mlp,
    encoder: Encoder,
    meta: NetworkMetadata,
}

/// Buffers for one actor evaluation.
#[derive(Debug, Clone)]
pub struct ActorWorkspace {
    mlp: MlpWorkspace,
    features: [f64; ACTOR_INPUTS],
}

impl ActorWorkspace {
    pub fn new(actor: &Actor) -> Self {
        Self {
            mlp: MlpWorkspace::new(&actor.mlp),
            features: [0.0; ACTOR_INPUTS],
        }
    }
}

impl Actor {
    pub fn from_weights(w: NetworkWeights) -> Result<Self, WeightsError> {
        let w = w.require_role(NetworkRole::Actor)?;
        let encoder = w.meta.encoder();
        Ok(Self {
            mlp: w.mlp,
            encoder,
            meta: w.meta,
        })
    }

    pub fn metadata(&self) -> &NetworkMetadata {
        &self.meta
    }

    pub fn mlp(&self) -> &Mlp {
        &self.mlp
    }

    /// The Gaussian's mean before tanh (outputs 0–1; 2–3 are its log-std).
    pub fn mean(&self, ws: &mut ActorWorkspace, x: &State, g: &Goal) -> [f64; 2] {
        self.encoder.encode_state(x, g, &mut ws.features);
        self.mlp.forward(&ws.features, &mut ws.mlp);
        [ws.mlp.out[0], ws.mlp.out[1]]
    }

    /// Deterministic action: tanh of the mean, scaled by the control bounds.
    pub fn action(&self, ws: &mut ActorWorkspace, x: &State, g: &Goal) -> Control {
        let m = self.mean(ws, x, g);
        let p = &self.encoder.params;
        Control::new(m[0].tanh() * p.beta_ddot_max, m[1].tanh() * p.a_max)
    }
}
