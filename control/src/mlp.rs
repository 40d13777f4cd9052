//! A fully connected network with Softplus hidden layers and a linear output,
//! evaluated in f64 with hand-written loops over preallocated buffers.
//!
//! Hidden layer l: z_l = W_l h_{l−1} + b_l, h_l = softplus(z_l); output
//! y = W_out h_L + b_out. Weights are row-major [out, in] as in PyTorch.

/// Hidden layer widths of the paper's actor and critic (§V-A).
pub const PAPER_HIDDEN: [usize; 5] = [48, 96, 144, 96, 48];

/// One affine layer.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub n_in: usize,
    pub n_out: usize,
    /// Row-major [n_out, n_in].
    pub weight: Vec<f64>,
    pub bias: Vec<f64>,
}

impl Layer {
    pub fn row(&self, i: usize) -> &[f64] {
        &self.weight[i * self.n_in..(i + 1) * self.n_in]
    }
}

/// e^x for x ≤ 0, branch-free so loops over it vectorise: x = n ln 2 + r with
/// |r| ≤ ln2/2 (Cody–Waite split of ln 2), e^r by its Taylor series to r¹²/12!
/// (truncation < 2e-16 relative), times 2ⁿ built in the exponent bits.
/// libm's exp and log1p were half of a forward pass.
#[inline(always)]
fn exp_nonpositive(x: f64) -> f64 {
    const LN2_HI: f64 = 6.931_471_803_691_238_164_9e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
    const SHIFTER: f64 = 6_755_399_441_055_744.0; // 1.5·2⁵², rounds to nearest
                                                  // Below −708 the result (< 1e-307) is irrelevant next to 1 in softplus.
    let x = x.max(-708.0);
    let shifted = x * std::f64::consts::LOG2_E + SHIFTER;
    let n = shifted - SHIFTER;
    let r = n.mul_add(-LN2_LO, n.mul_add(-LN2_HI, x));
    let mut p: f64 = 1.0 / 479_001_600.0; // 1/12!
    for c in [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p.mul_add(r, c);
    }
    // n sits in the low mantissa bits of `shifted`: integer arithmetic only
    // (no float→int conversion, which would not vectorise).
    let n_int = shifted.to_bits().wrapping_sub(SHIFTER.to_bits());
    p * f64::from_bits(n_int.wrapping_add(1023) << 52)
}

/// ln(1 + t) for t ∈ [0, 1] as 2 atanh(s), s = t/(2 + t) ≤ 1/3, by the odd
/// series to s³³ (truncation < 2e-17): relatively exact as t → 0, branch-free.
#[inline(always)]
fn ln_1p_unit(t: f64) -> f64 {
    // 1/(2k+1) for k = 15 … 0; a fixed array so the loop unrolls and the
    // caller's loop over neurons can vectorise.
    const C: [f64; 16] = [
        1.0 / 31.0,
        1.0 / 29.0,
        1.0 / 27.0,
        1.0 / 25.0,
        1.0 / 23.0,
        1.0 / 21.0,
        1.0 / 19.0,
        1.0 / 17.0,
        1.0 / 15.0,
        1.0 / 13.0,
        1.0 / 11.0,
        1.0 / 9.0,
        1.0 / 7.0,
        1.0 / 5.0,
        1.0 / 3.0,
        1.0,
    ];
    let s = t / (2.0 + t);
    let s2 = s * s;
    let mut p: f64 = 1.0 / 33.0;
    for c in C {
        p = p.mul_add(s2, c);
    }
    2.0 * s * p
}

/// Softplus and its first two derivatives, σ(z) = ln(1 + eᶻ), σ' = sigmoid(z),
/// σ'' = σ'(1 − σ'), from a single exp in the overflow-free form
/// σ(z) = max(z, 0) + ln(1 + e^{−|z|}).
#[inline(always)]
pub fn softplus3(z: f64) -> (f64, f64, f64) {
    let e = exp_nonpositive(-z.abs());
    let s = z.max(0.0) + ln_1p_unit(e);
    let r = 1.0 / (1.0 + e);
    let sig = if z >= 0.0 { r } else { e * r };
    (s, sig, sig * (1.0 - sig))
}

/// Softplus alone.
#[inline(always)]
pub fn softplus(z: f64) -> f64 {
    z.max(0.0) + ln_1p_unit(exp_nonpositive(-z.abs()))
}

/// Dot product with eight independent accumulators, so the compiler can keep
/// them in vector registers (a strict left-to-right sum cannot be vectorised).
#[inline(always)]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    let mut acc = [0.0; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] = x[k].mul_add(y[k], acc[k]);
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail = x.mul_add(*y, tail);
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// out = W x + b, four rows at a time so the accumulators form independent
/// FMA chains (a single dot product is bound by its accumulator's latency).
pub fn affine(layer: &Layer, x: &[f64], out: &mut [f64]) {
    let n = layer.n_in;
    let chunks = n / 4;
    let mut i = 0;
    while i + 4 <= layer.n_out {
        let rows = [
            layer.row(i),
            layer.row(i + 1),
            layer.row(i + 2),
            layer.row(i + 3),
        ];
        let mut acc = [[0.0; 4]; 4];
        // In chunks of four (no bounds checks in the loop, so it vectorises;
        // the same FMAs in the same order as indexing them).
        let xs = x[..4 * chunks].chunks_exact(4);
        let [w0, w1, w2, w3] = rows.map(|row| row[..4 * chunks].chunks_exact(4));
        for ((((xs, w0), w1), w2), w3) in xs.zip(w0).zip(w1).zip(w2).zip(w3) {
            for (r, w) in [w0, w1, w2, w3].into_iter().enumerate() {
                for j in 0..4 {
                    acc[r][j] = w[j].mul_add(xs[j], acc[r][j]);
                }
            }
        }
        for r in 0..4 {
            let mut s = (acc[r][0] + acc[r][2]) + (acc[r][1] + acc[r][3]);
            for k in 4 * chunks..n {
                s = rows[r][k].mul_add(x[k], s);
            }
            out[i + r] = layer.bias[i + r] + s;
        }
        i += 4;
    }
    for (r, o) in out.iter_mut().enumerate().take(layer.n_out).skip(i) {
        *o = layer.bias[r] + dot(layer.row(r), x);
    }
}

/// y += a·x.
#[inline(always)]
pub fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi = a.mul_add(*xi, *yi);
    }
}

/// Errors in the layer chain.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MlpError {
    #[error("network has no layers")]
    Empty,
    #[error("layer {layer}: weight has {got} values, expected {n_out}×{n_in}")]
    WeightSize {
        layer: usize,
        n_out: usize,
        n_in: usize,
        got: usize,
    },
    #[error("layer {layer}: bias has {got} values, expected {expected}")]
    BiasSize {
        layer: usize,
        expected: usize,
        got: usize,
    },
    #[error("layer {layer} takes {n_in} inputs but layer {prev} gives {prev_out}")]
    Chain {
        layer: usize,
        n_in: usize,
        prev: usize,
        prev_out: usize,
    },
}

/// The network: hidden Softplus layers then one linear output layer.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    layers: Vec<Layer>,
}

impl Mlp {
    pub fn new(layers: Vec<Layer>) -> Result<Self, MlpError> {
        if layers.is_empty() {
            return Err(MlpError::Empty);
        }
        for (i, l) in layers.iter().enumerate() {
            if l.weight.len() != l.n_out * l.n_in {
                return Err(MlpError::WeightSize {
                    layer: i,
                    n_out: l.n_out,
                    n_in: l.n_in,
                    got: l.weight.len(),
                });
            }
            if l.bias.len() != l.n_out {
                return Err(MlpError::BiasSize {
                    layer: i,
                    expected: l.n_out,
                    got: l.bias.len(),
                });
            }
            if i > 0 && layers[i - 1].n_out != l.n_in {
                return Err(MlpError::Chain {
                    layer: i,
                    n_in: l.n_in,
                    prev: i - 1,
                    prev_out: layers[i - 1].n_out,
                });
            }
        }
        Ok(Self { layers })
    }

    pub fn layers(&self) -> &[Layer] {
        &self.layers
    }

    /// Hidden layers (all but the last).
    pub fn hidden(&self) -> &[Layer] {
        &self.layers[..self.layers.len() - 1]
    }

    pub fn output_layer(&self) -> &Layer {
        &self.layers[self.layers.len() - 1]
    }

    pub fn input_size(&self) -> usize {
        self.layers[0].n_in
    }

    pub fn output_size(&self) -> usize {
        self.output_layer().n_out
    }

    pub fn widest(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.n_out.max(l.n_in))
            .max()
            .unwrap_or(0)
    }
}

/// Buffers for one evaluation, allocated once per network.
#[derive(Debug, Clone)]
pub struct MlpWorkspace {
    /// Post-activations h_l of each hidden layer.
    pub h: Vec<Vec<f64>>,
    /// σ'(z_l).
    pub d1: Vec<Vec<f64>>,
    /// σ''(z_l).
    pub d2: Vec<Vec<f64>>,
    /// Network output.
    pub out: Vec<f64>,
}

impl MlpWorkspace {
    pub fn new(mlp: &Mlp) -> Self {
        let hidden = mlp.hidden();
        Self {
            h: hidden.iter().map(|l| vec![0.0; l.n_out]).collect(),
            d1: hidden.iter().map(|l| vec![0.0; l.n_out]).collect(),
            d2: hidden.iter().map(|l| vec![0.0; l.n_out]).collect(),
            out: vec![0.0; mlp.output_size()],
        }
    }
}

impl Mlp {
    /// Forward pass; fills the activations and their derivatives in `ws`, the
    /// output in `ws.out`.
    pub fn forward(&self, input: &[f64], ws: &mut MlpWorkspace) {
        debug_assert_eq!(input.len(), self.input_size());
        for (l, layer) in self.hidden().iter().enumerate() {
            let (done, rest) = ws.h.split_at_mut(l);
            let prev: &[f64] = if l == 0 { input } else { &done[l - 1] };
            let h = &mut rest[0];
            let (d1, d2) = (&mut ws.d1[l], &mut ws.d2[l]);
            affine(layer, prev, h);
            // Two simple passes (e = e^{−|z|}, then softplus and its derivatives)
            // vectorise where one pass through `softplus3` stayed scalar.
            for (e, z) in d2.iter_mut().zip(h.iter()) {
                *e = exp_nonpositive(-z.abs());
            }
            for ((z, s1), s2) in h.iter_mut().zip(d1.iter_mut()).zip(d2.iter_mut()) {
                let e = *s2;
                let r = 1.0 / (1.0 + e);
                let sig = if *z >= 0.0 { r } else { e * r };
                *z = z.max(0.0) + ln_1p_unit(e);
                *s1 = sig;
                *s2 = sig * (1.0 - sig);
            }
        }
        let last = self.output_layer();
        let prev: &[f64] = match ws.h.last() {
            Some(h) => h,
            None => input,
        };
        affine(last, prev, &mut ws.out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_exp_and_log1p_match_libm() {
        let mut worst: f64 = 0.0;
        for i in 0..=200_000 {
            let x = -(i as f64) * 3.6e-3; // 0 … −720
            let (a, b) = (exp_nonpositive(x), x.exp());
            if b > 1e-300 {
                worst = worst.max(((a - b) / b).abs());
            }
            let t = i as f64 / 200_000.0;
            let (c, d) = (ln_1p_unit(t), t.ln_1p());
            if d > 0.0 {
                worst = worst.max(((c - d) / d).abs());
            }
        }
        assert!(worst < 2e-15, "worst relative error {worst}");
        let tiny = exp_nonpositive(-1000.0);
        assert!((0.0..1e-300).contains(&tiny));
    }

    #[test]
    fn softplus_matches_definition_and_derivatives() {
        for z in [-40.0, -5.0, -0.3, 0.0, 0.7, 3.0, 30.0] {
            let (s, s1, s2) = softplus3(z);
            let naive: f64 = (1.0 + f64::exp(z)).ln();
            assert!((s - naive).abs() <= 1e-15 * naive.max(1.0), "z={z}");
            let h = 1e-5;
            let fd1 = (softplus(z + h) - softplus(z - h)) / (2.0 * h);
            assert!((s1 - fd1).abs() < 1e-9);
            let fd2 = (softplus3(z + h).1 - softplus3(z - h).1) / (2.0 * h);
            assert!((s2 - fd2).abs() < 1e-9);
        }
    }

    #[test]
    fn affine_matches_naive_product() {
        for (n_in, n_out) in [(9, 48), (37, 7), (3, 2), (144, 96)] {
            let weight: Vec<f64> = (0..n_in * n_out).map(|i| (i as f64 * 0.7).sin()).collect();
            let bias: Vec<f64> = (0..n_out).map(|i| i as f64 * 0.1).collect();
            let layer = Layer {
                n_in,
                n_out,
                weight,
                bias,
            };
            let x: Vec<f64> = (0..n_in).map(|i| (i as f64).cos()).collect();
            let mut out = vec![0.0; n_out];
            affine(&layer, &x, &mut out);
            for i in 0..n_out {
                let naive: f64 =
                    layer.bias[i] + layer.row(i).iter().zip(&x).map(|(w, x)| w * x).sum::<f64>();
                assert!((out[i] - naive).abs() < 1e-12, "{n_in}x{n_out} row {i}");
            }
        }
    }

    #[test]
    fn dot_matches_naive_sum() {
        let a: Vec<f64> = (0..37).map(|i| (i as f64).sin()).collect();
        let b: Vec<f64> = (0..37).map(|i| (i as f64 * 0.3).cos()).collect();
        let naive: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - naive).abs() < 1e-13);
    }

    #[test]
    fn chain_errors_name_the_layer() {
        let l = |n_in, n_out| Layer {
            n_in,
            n_out,
            weight: vec![0.0; n_in * n_out],
            bias: vec![0.0; n_out],
        };
        assert!(Mlp::new(vec![l(3, 4), l(4, 2)]).is_ok());
        let e = Mlp::new(vec![l(3, 4), l(5, 2)]).unwrap_err();
        assert_eq!(
            e,
            MlpError::Chain {
                layer: 1,
                n_in: 5,
                prev: 0,
                prev_out: 4
            }
        );
        let mut bad = l(3, 4);
        bad.bias.pop();
        assert!(matches!(
            Mlp::new(vec![bad]),
            Err(MlpError::BiasSize { layer: 0, .. })
        ));
        assert_eq!(Mlp::new(vec![]), Err(MlpError::Empty));
    }
}
