//! The gradients of one ALAC update in hand-written f32 kernels (issue 19):
//! the forward passes, the critic's input-gradient sweep, its adjoint (the
//! gradient penalty's double backward) and the weight backward passes over
//! buffers kept from update to update, matrix products by `gemm`, the
//! element-wise work of a layer fused into one pass. The candle graph of
//! [`crate::nets`] and [`crate::agent`] computes the same gradients and stays
//! as the reference (`Kernel::Candle`); the tests compare the two on one batch.
//!
//! Notation (one network of K layers, rows are batch rows): h₀ = x,
//! z_l = h_l W_lᵀ + b_l, h_{l+1} = softplus(z_l), output z_{K−1}. For the
//! critic L = ‖Q‖² with Q = z_{K−1} (paper eq. 13).

use gemm::{gemm, Parallelism};

use control::encoder::{ACTOR_INPUTS, CRITIC_INPUTS};

use crate::buffer::Batch;
use crate::config::TrainConfig;
use crate::nets::{ln_1p_unit, softplus_f32, LOG_STD_MAX, LOG_STD_MIN};

/// One dense layer's parameters as in the weight files: `weight` row-major
/// [n_out × n_in], `bias` [n_out].
#[derive(Debug, Clone, Copy)]
pub struct LayerRef<'a> {
    pub weight: &'a [f32],
    pub bias: &'a [f32],
}

impl LayerRef<'_> {
    fn n_out(&self) -> usize {
        self.bias.len()
    }

    fn n_in(&self) -> usize {
        self.weight.len() / self.bias.len()
    }
}

/// The gradient of one network, shaped like its parameters: (∂W, ∂b) per layer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetGradient {
    pub layers: Vec<(Vec<f32>, Vec<f32>)>,
}

impl NetGradient {
    /// Zeroes it, shaped like `net` (allocates only the first time).
    pub fn reset(&mut self, net: &[LayerRef]) {
        self.layers.resize_with(net.len(), Default::default);
        for ((w, b), layer) in self.layers.iter_mut().zip(net) {
            w.clear();
            w.resize(layer.weight.len(), 0.0);
            b.clear();
            b.resize(layer.bias.len(), 0.0);
        }
    }

    /// self += other.
    pub fn add(&mut self, other: &NetGradient) {
        for ((w, b), (ow, ob)) in self.layers.iter_mut().zip(&other.layers) {
            w.iter_mut().zip(ow).for_each(|(x, y)| *x += y);
            b.iter_mut().zip(ob).for_each(|(x, y)| *x += y);
        }
    }
}

/// C (m × n, row-major) = A·B, or C += A·B with `accumulate`. A is m × k and B
/// k × n, each row-major, or stored transposed with `a_t` (Aᵀ, k × m) or
/// `b_t` (Bᵀ, n × k): a transpose is a choice of strides, never a copy.
fn matmul(
    c: &mut [f32],
    (a, a_t): (&[f32], bool),
    (b, b_t): (&[f32], bool),
    (m, n, k): (usize, usize, usize),
    accumulate: bool,
) {
    assert!(
        c.len() >= m * n && a.len() >= m * k && b.len() >= k * n,
        "matmul: {m}×{k} · {k}×{n} on buffers of {}, {}, {}",
        a.len(),
        b.len(),
        c.len()
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            c[..m * n].fill(0.0);
        }
        return;
    }
    // (row stride, column stride) of each operand as gemm reads it.
    let (a_rs, a_cs) = if a_t { (1, m) } else { (k, 1) };
    let (b_rs, b_cs) = if b_t { (1, k) } else { (n, 1) };
    // SAFETY: gemm reads A at i·a_rs + p·a_cs (i < m, p < k), B at p·b_rs + j·b_cs
    // (p < k, j < n) and writes C at i·n + j: each below m·k, k·n and m·n, which
    // the assert above keeps inside the slices. The slices do not overlap (one
    // is borrowed mutably).
    unsafe {
        gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.as_ptr(),
            a_cs as isize,
            a_rs as isize,
            b.as_ptr(),
            b_cs as isize,
            b_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            Parallelism::None,
        )
    }
}

/// eˣ for x ≤ 0, branch-free so that a loop over it can vectorise (libm's expf
/// is a call per element; it was a tenth of the update): x = k ln 2 + r with
/// |r| ≤ ln 2 / 2, eʳ by its degree-7 Taylor polynomial (truncation below
/// 0.35⁸/8! ≈ 6e-9, under f32's resolution), 2ᵏ from the exponent bits.
/// Inputs below −87 give e⁻⁸⁷ (f32's smallest normal is e^−87.3).
#[inline(always)]
fn exp_nonpositive(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let x = x.max(-87.0);
    let k = (x * std::f32::consts::LOG2_E).round();
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (1.0 / 2.0
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r / 5040.0))))));
    p * f32::from_bits(((k as i32 + 127) as u32) << 23)
}

/// softplus(z) and its derivative σ(z) from one exponential.
#[inline(always)]
fn softplus_and_sigmoid(z: f32) -> (f32, f32) {
    let t = exp_nonpositive(-z.abs());
    let sigmoid = if z >= 0.0 {
        1.0 / (1.0 + t)
    } else {
        t / (1.0 + t)
    };
    (z.max(0.0) + ln_1p_unit(t), sigmoid)
}

/// Sizes `v` to `len` (allocating only when it grows past its capacity).
fn sized(v: &mut Vec<f32>, len: usize) -> &mut [f32] {
    v.resize(len, 0.0);
    &mut v[..len]
}

/// The activations of one forward pass, kept for the reverse sweeps.
#[derive(Debug, Default)]
struct Pass {
    rows: usize,
    /// h[l], the input of layer l (h[0] the network's input), rows × n_in.
    h: Vec<Vec<f32>>,
    /// z[l], the pre-activation of layer l; the last is the output.
    z: Vec<Vec<f32>>,
    /// σ(z[l]) = softplus′(z[l]) of each hidden layer.
    sig: Vec<Vec<f32>>,
}

impl Pass {
    /// Sizes the buffers for `rows` rows of `net`; returns the input to fill.
    fn input(&mut self, net: &[LayerRef], rows: usize) -> &mut [f32] {
        self.rows = rows;
        self.h.resize_with(net.len(), Vec::new);
        self.z.resize_with(net.len(), Vec::new);
        self.sig.resize_with(net.len() - 1, Vec::new);
        for (l, layer) in net.iter().enumerate() {
            sized(&mut self.h[l], rows * layer.n_in());
            sized(&mut self.z[l], rows * layer.n_out());
            if l + 1 < net.len() {
                sized(&mut self.sig[l], rows * layer.n_out());
            }
        }
        &mut self.h[0]
    }

    fn forward(&mut self, net: &[LayerRef]) {
        for (l, layer) in net.iter().enumerate() {
            let (n_in, n_out) = (layer.n_in(), layer.n_out());
            let z = &mut self.z[l];
            z.chunks_exact_mut(n_out)
                .for_each(|row| row.copy_from_slice(layer.bias));
            matmul(
                z,
                (&self.h[l], false),
                (layer.weight, true),
                (self.rows, n_out, n_in),
                true,
            );
            if l + 1 < net.len() {
                let (h, sig) = (&mut self.h[l + 1], &mut self.sig[l]);
                for ((z, h), s) in z.iter().zip(h.iter_mut()).zip(sig.iter_mut()) {
                    (*h, *s) = softplus_and_sigmoid(*z);
                }
            }
        }
    }

    fn output(&self) -> &[f32] {
        self.z.last().map_or(&[], Vec::as_slice)
    }
}

/// The critic's reverse sweep ∇ₓ Σ_r w_r L_r (nets::critic_input_gradient):
/// u_{K−1} = 2 w Q, v_l = u_l W_l, u_{l−1} = v_l ⊙ σ(z_{l−1}); v₀ is the gradient.
#[derive(Debug, Default)]
struct InputSweep {
    /// u[l], rows × n_out(l).
    u: Vec<Vec<f32>>,
    /// v[l], rows × n_in(l).
    v: Vec<Vec<f32>>,
}

impl InputSweep {
    /// Runs the sweep over `pass` with row weights `w` (1 when `None`).
    fn run(&mut self, net: &[LayerRef], pass: &Pass, w: Option<&[f32]>) {
        let (k, rows) = (net.len(), pass.rows);
        self.u.resize_with(k, Vec::new);
        self.v.resize_with(k, Vec::new);
        let m = net[k - 1].n_out();
        let top = sized(&mut self.u[k - 1], rows * m);
        for (r, (u, q)) in top
            .chunks_exact_mut(m)
            .zip(pass.output().chunks_exact(m))
            .enumerate()
        {
            let scale = 2.0 * w.map_or(1.0, |w| w[r]);
            u.iter_mut().zip(q).for_each(|(u, q)| *u = scale * q);
        }
        for l in (0..k).rev() {
            let (n_in, n_out) = (net[l].n_in(), net[l].n_out());
            let v = sized(&mut self.v[l], rows * n_in);
            matmul(
                v,
                (&self.u[l], false),
                (net[l].weight, false),
                (rows, n_in, n_out),
                false,
            );
            if l > 0 {
                let u = sized(&mut self.u[l - 1], rows * n_in);
                for ((u, v), s) in u.iter_mut().zip(&self.v[l]).zip(&pass.sig[l - 1]) {
                    *u = v * s;
                }
            }
        }
    }

    fn gradient(&self) -> &[f32] {
        &self.v[0]
    }
}

/// Buffers of the backward passes.
#[derive(Debug, Default)]
struct Backward {
    /// Adjoint of each layer's pre-activation, rows × n_out(l).
    zbar: Vec<Vec<f32>>,
    /// Adjoint of a layer's input, rows × n_in.
    hbar: Vec<f32>,
    /// The sweep's adjoints v̄ (this layer's and the next one's) and ū.
    vbar: [Vec<f32>; 2],
    ubar: Vec<f32>,
    /// The penalty's share of each hidden pre-activation's adjoint.
    zbar_sweep: Vec<Vec<f32>>,
}

impl Backward {
    /// Adjoint of [`InputSweep::run`] (w = 1): given ḡ = ∂P/∂v₀, adds P's
    /// gradient through the sweep's weights to `grad.W`, leaves its share of
    /// each hidden pre-activation's adjoint in `zbar_sweep` (through σ(z_l)),
    /// and adds its share of the output's adjoint (through u_{K−1} = 2Q) to
    /// `out_adjoint`. With v̄₀ = ḡ, for l = 0, 1, …: ū_l = v̄_l W_lᵀ,
    /// ∂W_l += u_lᵀ v̄_l, then v̄_{l+1} = ū_l ⊙ σ(z_l) and
    /// z̄_l = ū_l ⊙ v_{l+1} ⊙ σ(z_l)(1 − σ(z_l)); at the top Q̄ += 2 ū_{K−1}.
    fn sweep_adjoint(
        &mut self,
        net: &[LayerRef],
        pass: &Pass,
        sweep: &InputSweep,
        gbar: &[f32],
        out_adjoint: &mut [f32],
        grad: &mut NetGradient,
    ) {
        let (k, rows) = (net.len(), pass.rows);
        self.zbar_sweep.resize_with(k - 1, Vec::new);
        sized(&mut self.vbar[0], gbar.len()).copy_from_slice(gbar);
        for (l, layer) in net.iter().enumerate() {
            let (n_in, n_out) = (layer.n_in(), layer.n_out());
            let [vbar, vbar_next] = &mut self.vbar;
            let ubar = sized(&mut self.ubar, rows * n_out);
            matmul(
                ubar,
                (vbar, false),
                (layer.weight, true),
                (rows, n_out, n_in),
                false,
            );
            matmul(
                &mut grad.layers[l].0,
                (&sweep.u[l], true),
                (vbar, false),
                (n_out, n_in, rows),
                true,
            );
            if l + 1 < k {
                let next = sized(vbar_next, rows * n_out);
                let zbar = sized(&mut self.zbar_sweep[l], rows * n_out);
                for (((next, zbar), (ub, s)), v) in next
                    .iter_mut()
                    .zip(zbar.iter_mut())
                    .zip(ubar.iter().zip(&pass.sig[l]))
                    .zip(&sweep.v[l + 1])
                {
                    *next = ub * s;
                    *zbar = ub * v * s * (1.0 - s);
                }
                self.vbar.swap(0, 1);
            } else {
                out_adjoint
                    .iter_mut()
                    .zip(ubar.iter())
                    .for_each(|(q, u)| *q += 2.0 * u);
            }
        }
    }

    /// Adds the weight gradient of Σ ⟨out_adjoint, output⟩ to `grad` by the
    /// reverse sweep z̄_{K−1} = out_adjoint, ∂W_l += z̄_lᵀ h_l, ∂b_l += Σ_rows z̄_l,
    /// z̄_{l−1} = (z̄_l W_l) ⊙ σ(z_{l−1}) (+ `zbar_sweep` with `with_sweep`).
    fn weights(
        &mut self,
        net: &[LayerRef],
        pass: &Pass,
        out_adjoint: &[f32],
        with_sweep: bool,
        grad: &mut NetGradient,
    ) {
        let (k, rows) = (net.len(), pass.rows);
        self.zbar.resize_with(k, Vec::new);
        sized(&mut self.zbar[k - 1], out_adjoint.len()).copy_from_slice(out_adjoint);
        for l in (0..k).rev() {
            let (n_in, n_out) = (net[l].n_in(), net[l].n_out());
            let (below, this) = self.zbar.split_at_mut(l);
            let zbar = &this[0];
            let (gw, gb) = &mut grad.layers[l];
            matmul(
                gw,
                (zbar, true),
                (&pass.h[l], false),
                (n_out, n_in, rows),
                true,
            );
            for row in zbar.chunks_exact(n_out) {
                gb.iter_mut().zip(row).for_each(|(g, z)| *g += z);
            }
            if l == 0 {
                break;
            }
            let hbar = sized(&mut self.hbar, rows * n_in);
            matmul(
                hbar,
                (zbar, false),
                (net[l].weight, false),
                (rows, n_in, n_out),
                false,
            );
            let below = sized(&mut below[l - 1], rows * n_in);
            for ((z, h), s) in below.iter_mut().zip(hbar.iter()).zip(&pass.sig[l - 1]) {
                *z = h * s;
            }
            if with_sweep {
                below
                    .iter_mut()
                    .zip(&self.zbar_sweep[l - 1])
                    .for_each(|(z, e)| *z += e);
            }
        }
    }
}

/// Reusable buffers of one thread's share of an update.
#[derive(Debug, Default)]
pub struct Workspace {
    actor: Pass,
    critic: Pass,
    target: Pass,
    sweep: InputSweep,
    backward: Backward,
    out_adjoint: Vec<f32>,
    gbar: Vec<f32>,
    row_weight: Vec<f32>,
}

/// The networks of an update.
#[derive(Debug, Clone, Copy)]
pub struct Nets<'a> {
    pub critic: &'a [LayerRef<'a>],
    pub target: &'a [LayerRef<'a>],
    pub actor: &'a [LayerRef<'a>],
}

/// Rows of a batch (a share of it when the update is split over threads).
#[derive(Debug, Clone, Copy)]
pub struct Rows<'a> {
    /// Actor features of s and s′, rows × [`ACTOR_INPUTS`].
    pub s: &'a [f32],
    pub s2: &'a [f32],
    /// Action a, rows × 2.
    pub a: &'a [f32],
    pub cost: &'a [f32],
    pub not_done: &'a [f32],
}

impl<'a> From<&'a Batch> for Rows<'a> {
    fn from(b: &'a Batch) -> Self {
        Self {
            s: &b.state,
            s2: &b.next_state,
            a: &b.action,
            cost: &b.cost,
            not_done: &b.not_done,
        }
    }
}

impl Rows<'_> {
    fn len(&self) -> usize {
        self.cost.len()
    }

    /// The rows in `range`.
    pub fn range(&self, range: std::ops::Range<usize>) -> Self {
        let (a, b) = (range.start, range.end);
        Self {
            s: &self.s[a * ACTOR_INPUTS..b * ACTOR_INPUTS],
            s2: &self.s2[a * ACTOR_INPUTS..b * ACTOR_INPUTS],
            a: &self.a[2 * a..2 * b],
            cost: &self.cost[a..b],
            not_done: &self.not_done[a..b],
        }
    }
}

/// What the critic and the actor objectives need beside the batch.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    pub gamma: f32,
    /// ρ of the gradient penalty (paper eq. 16).
    pub gradient_penalty: f32,
    pub target_entropy: f32,
    /// 1 / rows of the whole batch: every loss is a batch mean, so shares of
    /// it add up.
    pub scale: f32,
}

impl Settings {
    /// The configuration's settings for a batch of `rows` rows.
    pub fn new(cfg: &TrainConfig, rows: usize) -> Self {
        Self {
            gamma: cfg.gamma as f32,
            gradient_penalty: cfg.gradient_penalty as f32,
            target_entropy: cfg.target_entropy as f32,
            scale: 1.0 / rows as f32,
        }
    }
}

/// A share of the critic objective (each part already × 1/rows).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CriticShare {
    /// ½ mean (L − y)² + ρ · penalty.
    pub loss: f64,
    /// mean (1 − ‖∇ₓL‖)².
    pub penalty: f64,
}

/// One tanh-Gaussian draw per row of the actor's output [μ₁ μ₂ log σ₁ log σ₂]
/// (nets::actor_sample): calls `each(row, j, u, log σ_j, passes)` per component,
/// u = μ_j + σ_j ε_j with log σ clamped to [LOG_STD_MIN, LOG_STD_MAX]; `passes`
/// says the clamp let the raw value through (else its gradient is 0).
fn for_each_draw(out: &[f32], eps: &[f32], mut each: impl FnMut(usize, usize, f32, f32, bool)) {
    for (r, (o, e)) in out.chunks_exact(4).zip(eps.chunks_exact(2)).enumerate() {
        for j in 0..2 {
            let raw = o[2 + j];
            let log_std = raw.clamp(LOG_STD_MIN as f32, LOG_STD_MAX as f32);
            let passes = raw > LOG_STD_MIN as f32 && raw < LOG_STD_MAX as f32;
            each(r, j, o[j] + log_std.exp() * e[j], log_std, passes);
        }
    }
}

/// Writes `values` (rows × `width`) into the critic input's columns from `column` on.
fn put_columns(input: &mut [f32], column: usize, values: &[f32], width: usize) {
    for (row, v) in input
        .chunks_exact_mut(CRITIC_INPUTS)
        .zip(values.chunks_exact(width))
    {
        row[column..column + width].copy_from_slice(v);
    }
}

/// L = ‖Q‖² of each row of a critic pass.
fn values<'a>(pass: &'a Pass, m: usize) -> impl Iterator<Item = f32> + 'a {
    pass.output()
        .chunks_exact(m)
        .map(|q| q.iter().map(|q| q * q).sum())
}

/// Adds to `grad` the critic objective's gradient over `rows` (agent::critic_objective):
/// ½ (L − y)² with y = c + γ (1 − done) L̄(s′, a′), a′ = tanh(μ + σ ε) of the
/// actor at s′ with `eps` (rows × 2), plus ρ (1 − ‖∇ₓL‖)². Writes L(s, a) to `l_sa`.
pub fn critic_gradient(
    ws: &mut Workspace,
    nets: Nets,
    rows: Rows,
    eps: &[f32],
    set: Settings,
    l_sa: &mut [f32],
    grad: &mut NetGradient,
) -> CriticShare {
    let n = rows.len();
    if n == 0 {
        return CriticShare::default();
    }
    let m = nets.critic[nets.critic.len() - 1].n_out();
    // a′ ∼ π(s′), into the target's input.
    ws.actor.input(nets.actor, n).copy_from_slice(rows.s2);
    ws.actor.forward(nets.actor);
    let target_in = ws.target.input(nets.target, n);
    put_columns(target_in, 0, rows.s2, ACTOR_INPUTS);
    for_each_draw(ws.actor.output(), eps, |r, j, u, _, _| {
        target_in[r * CRITIC_INPUTS + ACTOR_INPUTS + j] = u.tanh();
    });
    ws.target.forward(nets.target);

    let critic_in = ws.critic.input(nets.critic, n);
    put_columns(critic_in, 0, rows.s, ACTOR_INPUTS);
    put_columns(critic_in, ACTOR_INPUTS, rows.a, 2);
    ws.critic.forward(nets.critic);

    // ∂/∂Q of ½ scale (L − y)² is scale (L − y) 2Q.
    let adjoint = sized(&mut ws.out_adjoint, n * m);
    let mut share = CriticShare::default();
    let targets = values(&ws.target, m);
    for (r, (l_next, l)) in targets.zip(values(&ws.critic, m)).enumerate() {
        let y = rows.cost[r] + set.gamma * rows.not_done[r] * l_next;
        l_sa[r] = l;
        share.loss += 0.5 * f64::from(set.scale) * f64::from(l - y).powi(2);
        let k = set.scale * (l - y) * 2.0;
        let q = &ws.critic.output()[r * m..(r + 1) * m];
        adjoint[r * m..(r + 1) * m]
            .iter_mut()
            .zip(q)
            .for_each(|(a, q)| *a = k * q);
    }
    let with_penalty = set.gradient_penalty > 0.0;
    if with_penalty {
        // P = scale Σ (1 − ‖g‖)², ‖g‖ = √(g·g + 1e-12) (nets::gradient_penalty).
        ws.sweep.run(nets.critic, &ws.critic, None);
        let g = ws.sweep.gradient();
        let d = g.len() / n;
        let gbar = sized(&mut ws.gbar, g.len());
        for (gb, g) in gbar.chunks_exact_mut(d).zip(g.chunks_exact(d)) {
            let norm = (g.iter().map(|g| g * g).sum::<f32>() + 1e-12).sqrt();
            share.penalty += f64::from(set.scale) * f64::from(1.0 - norm).powi(2);
            let k = set.gradient_penalty * set.scale * -2.0 * (1.0 - norm) / norm;
            gb.iter_mut().zip(g).for_each(|(b, g)| *b = k * g);
        }
        share.loss += f64::from(set.gradient_penalty) * share.penalty;
        ws.backward.sweep_adjoint(
            nets.critic,
            &ws.critic,
            &ws.sweep,
            &ws.gbar,
            &mut ws.out_adjoint,
            grad,
        );
    }
    ws.backward
        .weights(nets.critic, &ws.critic, &ws.out_adjoint, with_penalty, grad);
    share
}

/// A share of the actor objective.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ActorShare {
    /// λ_e mean(log π(s) + H) + λ_l mean ΔL over the share's rows (× 1/rows of the batch).
    pub loss: f64,
}

/// Adds to `grad` the actor objective's gradient over `rows`
/// (agent::actor_objective, paper eq. 14–15): λ_e (log π(s) + H) + λ_l ΔL,
/// ΔL = L(s′, π(s′)) − L(s, a) + k (L(s, a) − λ L(s′, π(s′))), k = 1 − λ_l,
/// λ = min(λ_l, γ), L(s′, ·) = 0 beyond a terminal transition. `eps_s` and
/// `eps_s2` (rows × 2) draw the actions at s and s′; writes log π(s) + H and ΔL per row.
#[allow(clippy::too_many_arguments)]
pub fn actor_gradient(
    ws: &mut Workspace,
    nets: Nets,
    rows: Rows,
    (eps_s, eps_s2): (&[f32], &[f32]),
    l_sa: &[f32],
    set: Settings,
    (lambda_e, lambda_l): (f32, f32),
    (entropy_term, delta_l): (&mut [f32], &mut [f32]),
    grad: &mut NetGradient,
) -> ActorShare {
    let n = rows.len();
    if n == 0 {
        return ActorShare::default();
    }
    let m = nets.critic[nets.critic.len() - 1].n_out();
    let (k, lam) = (1.0 - lambda_l, lambda_l.min(set.gamma));
    // s over s′ through the actor as one pass.
    let input = ws.actor.input(nets.actor, 2 * n);
    input[..n * ACTOR_INPUTS].copy_from_slice(rows.s);
    input[n * ACTOR_INPUTS..].copy_from_slice(rows.s2);
    ws.actor.forward(nets.actor);
    let (out_s, out_s2) = ws.actor.output().split_at(n * 4);
    let adjoint = sized(&mut ws.out_adjoint, 2 * n * 4);
    let (adj_s, adj_s2) = adjoint.split_at_mut(n * 4);

    // log π(s) = Σ_j [log N(ε_j) − log σ_j − log(1 − tanh² u_j)]; ∂/∂u = 2 tanh u,
    // u = μ + σ ε, so ∂/∂μ = 2 tanh u and ∂/∂log σ = −1 + 2 tanh u σ ε.
    let mut share = ActorShare::default();
    let log_normal_const = -0.5 * (2.0 * std::f32::consts::PI).ln();
    entropy_term.fill(set.target_entropy);
    let ke = lambda_e * set.scale;
    for_each_draw(out_s, eps_s, |r, j, u, log_std, passes| {
        let e = eps_s[2 * r + j];
        // log(1 − tanh² u) = 2 (ln 2 − u − softplus(−2u)).
        let log_one_minus_tanh_sq = 2.0 * (std::f32::consts::LN_2 - u - softplus_f32(-2.0 * u));
        entropy_term[r] += -0.5 * e * e + log_normal_const - log_std - log_one_minus_tanh_sq;
        let du = 2.0 * u.tanh();
        adj_s[4 * r + j] = ke * du;
        adj_s[4 * r + 2 + j] = if passes {
            ke * (-1.0 + du * log_std.exp() * e)
        } else {
            0.0
        };
    });
    share.loss += f64::from(ke) * entropy_term.iter().map(|t| f64::from(*t)).sum::<f64>();

    // a = tanh(u) at s′ into the critic.
    let input = ws.critic.input(nets.critic, n);
    put_columns(input, 0, rows.s2, ACTOR_INPUTS);
    for_each_draw(out_s2, eps_s2, |r, j, u, _, _| {
        input[r * CRITIC_INPUTS + ACTOR_INPUTS + j] = u.tanh();
    });
    ws.critic.forward(nets.critic);
    let kl = lambda_l * set.scale;
    let weight = sized(&mut ws.row_weight, n);
    for (r, l) in values(&ws.critic, m).enumerate() {
        let l_s2 = l * rows.not_done[r];
        delta_l[r] = (l_s2 - l_sa[r]) + k * (l_sa[r] - lam * l_s2);
        share.loss += f64::from(kl) * f64::from(delta_l[r]);
        // ∂ loss / ∂ L(s′, a′) of this row.
        weight[r] = kl * (1.0 - k * lam) * rows.not_done[r];
    }
    ws.sweep.run(nets.critic, &ws.critic, Some(&ws.row_weight));
    let g = ws.sweep.gradient();
    let d = CRITIC_INPUTS;
    for_each_draw(out_s2, eps_s2, |r, j, u, log_std, passes| {
        let a = u.tanh();
        let ubar = g[r * d + ACTOR_INPUTS + j] * (1.0 - a * a);
        adj_s2[4 * r + j] = ubar;
        adj_s2[4 * r + 2 + j] = if passes {
            ubar * log_std.exp() * eps_s2[2 * r + j]
        } else {
            0.0
        };
    });
    ws.backward
        .weights(nets.actor, &ws.actor, &ws.out_adjoint, false, grad);
    share
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_nonpositive_matches_f64_exp() {
        let mut worst = 0.0f64;
        for i in 0..=870_000 {
            let x = -(i as f32) * 1e-4;
            let exact = f64::from(x).exp();
            worst = worst.max(((f64::from(exp_nonpositive(x)) - exact) / exact).abs());
        }
        assert!(worst < 3e-7, "worst relative error {worst:e}");
    }

    #[test]
    fn softplus_and_sigmoid_match_their_definitions() {
        for i in -30_000..=30_000 {
            let z = i as f32 * 1e-3;
            let (sp, sig) = softplus_and_sigmoid(z);
            let z64 = f64::from(z);
            let sp_exact = z64.max(0.0) + (-z64.abs()).exp().ln_1p();
            let sig_exact = 1.0 / (1.0 + (-z64).exp());
            assert!(
                (f64::from(sp) - sp_exact).abs() <= 5e-7 * sp_exact,
                "softplus({z})"
            );
            assert!(
                (f64::from(sig) - sig_exact).abs() <= 5e-7 * sig_exact,
                "σ({z})"
            );
        }
    }
}
