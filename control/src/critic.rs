//! The critic L(s, a, g) = ‖Q(s, a, g)‖² (paper eq. 12) and its derivatives
//! with respect to z = (x, u), hand-written and allocation-free.
//!
//! Why these formulas: with z ↦ f (encoder) ↦ Q (MLP) ↦ L = ‖Q‖², the only
//! nonlinear nodes are the Softplus units, sin/cos e_θ in the encoder and the
//! final square. The exact Hessian of a computational graph is the sum over its
//! nonlinear nodes of (adjoint of the node) × (its local second derivative) ×
//! (outer product of the total gradient of its input):
//!
//!   ∇²L = 2 J_Qᵀ J_Q  +  Σ_l Σ_j h̄_{l,j} σ''(z_{l,j}) ∇z_{l,j} ∇z_{l,j}ᵀ  +  Σ_k f̄_k ∇²f_k
//!
//! where ∇z_{l,j} (rows of the pre-activation Jacobians) come from one forward
//! Jacobian sweep and h̄ (adjoints) from one reverse sweep. Dropping the last two
//! terms gives the Gauss–Newton Hessian 2 J_Qᵀ J_Q, positive semidefinite by
//! construction.

use crate::encoder::{Encoder, CRITIC_INPUTS, NZ};
use crate::mlp::{axpy, Layer, Mlp, MlpWorkspace};
use crate::model::{Control, Goal, State, NX};
use crate::weights::{NetworkMetadata, NetworkRole, NetworkWeights, WeightsError};

/// Which Hessian of L to form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HessianMode {
    /// The exact Hessian (indefinite in general; the MPC projects it).
    Exact,
    /// 2 J_Qᵀ J_Q.
    GaussNewton,
}

/// Value, gradient and Hessian of L with respect to z = (x, u).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Derivatives {
    pub value: f64,
    pub grad: [f64; NZ],
    pub hess: [[f64; NZ]; NZ],
}

impl Default for Derivatives {
    fn default() -> Self {
        Self {
            value: 0.0,
            grad: [0.0; NZ],
            hess: [[0.0; NZ]; NZ],
        }
    }
}

/// Value, gradient and Hessian of the terminal cost L(x, 0, g) with respect to x.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TerminalDerivatives {
    pub value: f64,
    pub grad: [f64; NX],
    pub hess: [[f64; NX]; NX],
}

impl TerminalDerivatives {
    /// The state part of derivatives taken at u = 0.
    pub fn state_block(full: &Derivatives) -> Self {
        let mut out = Self {
            value: full.value,
            ..Self::default()
        };
        out.grad.copy_from_slice(&full.grad[..NX]);
        for (dst, src) in out.hess.iter_mut().zip(&full.hess) {
            dst.copy_from_slice(&src[..NX]);
        }
        out
    }
}

/// The deployed critic.
#[derive(Debug, Clone)]
pub struct Critic {
    mlp: Mlp,
    encoder: Encoder,
    meta: NetworkMetadata,
}

/// Buffers for one critic evaluation; build once with [`CriticWorkspace::new`]
/// and pass `&mut` to every call.
#[derive(Debug, Clone)]
pub struct CriticWorkspace {
    mlp: MlpWorkspace,
    features: [f64; CRITIC_INPUTS],
    /// ∂f/∂z.
    enc_jac: [[f64; NZ]; CRITIC_INPUTS],
    /// ∂L/∂f.
    feature_grad: [f64; CRITIC_INPUTS],
    /// Adjoints ∂L/∂h_l of each hidden layer.
    adjoint: Vec<Vec<f64>>,
    /// Pre-activation Jacobians ∂z_l/∂z, one `[f64; 8]` row per unit.
    jz: Vec<Vec<[f64; NZ]>>,
    /// ∂Q/∂z.
    jq: Vec<[f64; NZ]>,
    /// Post-activation Jacobian of the layer below, scratch for the sweep.
    jh: Vec<[f64; NZ]>,
}

impl CriticWorkspace {
    pub fn new(critic: &Critic) -> Self {
        let hidden = critic.mlp.hidden();
        Self {
            mlp: MlpWorkspace::new(&critic.mlp),
            features: [0.0; CRITIC_INPUTS],
            enc_jac: [[0.0; NZ]; CRITIC_INPUTS],
            feature_grad: [0.0; CRITIC_INPUTS],
            adjoint: hidden.iter().map(|l| vec![0.0; l.n_out]).collect(),
            jz: hidden.iter().map(|l| vec![[0.0; NZ]; l.n_out]).collect(),
            jq: vec![[0.0; NZ]; critic.mlp.output_size()],
            jh: vec![[0.0; NZ]; critic.mlp.widest()],
        }
    }
}

#[inline(always)]
fn add_outer(hess: &mut [[f64; NZ]; NZ], c: f64, r: &[f64; NZ]) {
    for a in 0..NZ {
        let ca = c * r[a];
        for b in 0..NZ {
            hess[a][b] = ca.mul_add(r[b], hess[a][b]);
        }
    }
}

/// out[i] = Σ_k W[i,k] · prev[k] for rows of width 8. Four output rows at a time
/// give independent FMA chains; one row alone would wait on its own
/// accumulator's latency.
fn jacobian_product(layer: &Layer, prev: &[[f64; NZ]], out: &mut [[f64; NZ]]) {
    let n_in = layer.n_in;
    let mut i = 0;
    while i + 4 <= layer.n_out {
        let w = [
            layer.row(i),
            layer.row(i + 1),
            layer.row(i + 2),
            layer.row(i + 3),
        ];
        let mut acc = [[0.0; NZ]; 4];
        // Rows and inputs cut to n_in up front so the loop has no bounds checks
        // (same FMAs in the same order as indexing them).
        let (w0, w1, w2, w3) = (&w[0][..n_in], &w[1][..n_in], &w[2][..n_in], &w[3][..n_in]);
        for ((((p, &c0), &c1), &c2), &c3) in prev.iter().zip(w0).zip(w1).zip(w2).zip(w3) {
            for (r, c) in [c0, c1, c2, c3].into_iter().enumerate() {
                for j in 0..NZ {
                    acc[r][j] = c.mul_add(p[j], acc[r][j]);
                }
            }
        }
        out[i..i + 4].copy_from_slice(&acc);
        i += 4;
    }
    for (i, row) in out.iter_mut().enumerate().take(layer.n_out).skip(i) {
        let w = layer.row(i);
        let mut acc = [0.0; NZ];
        for (k, p) in prev.iter().enumerate().take(n_in) {
            axpy(w[k], p, &mut acc);
        }
        *row = acc;
    }
}

/// jh[k] = σ'(z_k) · jz[k]: the post-activation Jacobian of a hidden layer.
fn scale_rows(d1: &[f64], jz: &[[f64; NZ]], jh: &mut [[f64; NZ]]) {
    for ((h, z), d) in jh.iter_mut().zip(jz).zip(d1) {
        for j in 0..NZ {
            h[j] = d * z[j];
        }
    }
}

impl Critic {
    /// Builds the critic from validated weights (see [`crate::weights::decode`]).
    pub fn from_weights(w: NetworkWeights) -> Result<Self, WeightsError> {
        let w = w.require_role(NetworkRole::Critic)?;
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

    pub fn encoder(&self) -> &Encoder {
        &self.encoder
    }

    fn forward(&self, ws: &mut CriticWorkspace, x: &State, u: &Control, g: &Goal) -> f64 {
        self.encoder.encode(x, u, g, &mut ws.features);
        self.mlp.forward(&ws.features, &mut ws.mlp);
        ws.mlp.out.iter().map(|q| q * q).sum()
    }

    /// L(x, u, g).
    pub fn value(&self, ws: &mut CriticWorkspace, x: &State, u: &Control, g: &Goal) -> f64 {
        self.forward(ws, x, u, g)
    }

    /// Reverse sweep from q̄ = 2Q: fills the hidden adjoints and ∂L/∂f.
    fn reverse(&self, ws: &mut CriticWorkspace) {
        let hidden = self.mlp.hidden();
        let out = self.mlp.output_layer();
        let n_hidden = hidden.len();
        // Adjoint of the last hidden layer (or of the features with no hidden layer).
        {
            let target: &mut [f64] = if n_hidden == 0 {
                &mut ws.feature_grad
            } else {
                &mut ws.adjoint[n_hidden - 1]
            };
            target.fill(0.0);
            for i in 0..out.n_out {
                axpy(2.0 * ws.mlp.out[i], out.row(i), target);
            }
        }
        for l in (0..n_hidden).rev() {
            let layer = &hidden[l];
            let (below, here) = ws.adjoint.split_at_mut(l);
            let adj = &here[0];
            let target: &mut [f64] = if l == 0 {
                &mut ws.feature_grad
            } else {
                &mut below[l - 1]
            };
            target.fill(0.0);
            let d1 = &ws.mlp.d1[l];
            for i in 0..layer.n_out {
                axpy(adj[i] * d1[i], layer.row(i), target);
            }
        }
    }

    /// L and ∇_z L.
    pub fn value_gradient(
        &self,
        ws: &mut CriticWorkspace,
        x: &State,
        u: &Control,
        g: &Goal,
        grad: &mut [f64; NZ],
    ) -> f64 {
        let value = self.forward(ws, x, u, g);
        self.reverse(ws);
        self.encoder.jacobian(x, g, &mut ws.enc_jac);
        *grad = [0.0; NZ];
        for (k, row) in ws.enc_jac.iter().enumerate() {
            axpy(ws.feature_grad[k], row, grad);
        }
        value
    }

    /// Forward Jacobian sweep: ∂z_l/∂z for each hidden layer and ∂Q/∂z.
    fn jacobian_sweep(&self, ws: &mut CriticWorkspace, x: &State, g: &Goal) {
        self.encoder.jacobian(x, g, &mut ws.enc_jac);
        let hidden = self.mlp.hidden();
        for (l, layer) in hidden.iter().enumerate() {
            let (done, rest) = ws.jz.split_at_mut(l);
            if l == 0 {
                jacobian_product(layer, &ws.enc_jac, &mut rest[0]);
            } else {
                let n = done[l - 1].len();
                scale_rows(&ws.mlp.d1[l - 1], &done[l - 1], &mut ws.jh[..n]);
                jacobian_product(layer, &ws.jh[..n], &mut rest[0]);
            }
        }
        let out = self.mlp.output_layer();
        match hidden.len() {
            0 => jacobian_product(out, &ws.enc_jac, &mut ws.jq),
            n => {
                let m = ws.jz[n - 1].len();
                scale_rows(&ws.mlp.d1[n - 1], &ws.jz[n - 1], &mut ws.jh[..m]);
                jacobian_product(out, &ws.jh[..m], &mut ws.jq);
            }
        }
    }

    /// Value, gradient and the Hessian selected by `mode`, all with respect to z = (x, u).
    pub fn hessian(
        &self,
        ws: &mut CriticWorkspace,
        x: &State,
        u: &Control,
        g: &Goal,
        mode: HessianMode,
        out: &mut Derivatives,
    ) {
        out.value = self.forward(ws, x, u, g);
        self.jacobian_sweep(ws, x, g);
        out.grad = [0.0; NZ];
        out.hess = [[0.0; NZ]; NZ];
        for (q, jq) in ws.mlp.out.iter().zip(&ws.jq) {
            // ∇L = 2 J_Qᵀ Q, ∇²L ⊇ 2 J_Qᵀ J_Q.
            axpy(2.0 * q, jq, &mut out.grad);
            add_outer(&mut out.hess, 2.0, jq);
        }
        if mode == HessianMode::GaussNewton {
            return;
        }
        self.reverse(ws);
        for (l, jz) in ws.jz.iter().enumerate() {
            let (adj, d2) = (&ws.adjoint[l], &ws.mlp.d2[l]);
            for (j, row) in jz.iter().enumerate() {
                add_outer(&mut out.hess, adj[j] * d2[j], row);
            }
        }
        self.encoder
            .add_curvature(&ws.feature_grad, &ws.features, &mut out.hess);
    }

    /// The terminal cost L(x, 0, g) (paper eq. 19) with gradient and Hessian in x.
    pub fn terminal_hessian(
        &self,
        ws: &mut CriticWorkspace,
        x: &State,
        g: &Goal,
        mode: HessianMode,
        out: &mut TerminalDerivatives,
    ) {
        let mut full = Derivatives::default();
        self.hessian(ws, x, &Control::zeros(), g, mode, &mut full);
        *out = TerminalDerivatives::state_block(&full);
    }
}
