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

/// Softplus and its first two derivatives, σ(z) = ln(1 + eᶻ), σ' = sigmoid(z),
/// σ'' = σ'(1 − σ'), from a single exp in the overflow-free form.
#[inline(always)]
pub fn softplus3(z: f64) -> (f64, f64, f64) {
    let e = (-z.abs()).exp();
    let s = z.max(0.0) + e.ln_1p();
    let r = 1.0 / (1.0 + e);
    let sig = if z >= 0.0 { r } else { e * r };
    (s, sig, sig * (1.0 - sig))
}

/// Softplus alone.
#[inline(always)]
pub fn softplus(z: f64) -> f64 {
    z.max(0.0) + (-z.abs()).exp().ln_1p()
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
            for i in 0..layer.n_out {
                let z = layer.bias[i] + dot(layer.row(i), prev);
                let (s, s1, s2) = softplus3(z);
                h[i] = s;
                d1[i] = s1;
                d2[i] = s2;
            }
        }
        let last = self.output_layer();
        let prev: &[f64] = match ws.h.last() {
            Some(h) => h,
            None => input,
        };
        for i in 0..last.n_out {
            ws.out[i] = last.bias[i] + dot(last.row(i), prev);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
