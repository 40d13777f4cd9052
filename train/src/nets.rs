//! Actor and critic networks in candle (f32), with the same layout as the
//! deployed `control::mlp::Mlp`: Softplus hidden layers, linear output, weights
//! `layers.{i}.weight` [out, in] and `layers.{i}.bias`.

use candle_core::{CpuStorage, CustomOp1, DType, Device, Layout, Result, Shape, Tensor, Var, D};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Softplus as one fused CPU op (the element-wise chain of exp, log, relu, abs
/// would be five passes and five allocations). Its backward is
/// grad · sigmoid(x), itself differentiable, so the gradient penalty can be
/// back-propagated through it.
struct Softplus;

/// softplus(z) = max(z, 0) + ln(1 + t), t = e^{−|z|} ∈ (0, 1]. libm's log1pf
/// was a third of the training time; here ln(1 + t) = 2 atanh(s) with
/// s = t / (2 + t) ∈ (0, 1/3], as the odd series 2(s + s³/3 + … + s¹¹/11),
/// whose truncation error (< 2·(1/3)¹³/13 ≈ 1e-7 relative) is below f32's
/// resolution, and which stays relatively exact as t → 0.
#[inline(always)]
pub fn softplus_f32(z: f32) -> f32 {
    z.max(0.0) + ln_1p_unit((-z.abs()).exp())
}

/// ln(1 + t) for t ∈ (0, 1], the series of [`softplus_f32`].
#[inline(always)]
pub fn ln_1p_unit(t: f32) -> f32 {
    let s = t / (2.0 + t);
    let s2 = s * s;
    let poly = 1.0
        + s2 * (1.0 / 3.0
            + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0 + s2 * (1.0 / 11.0)))));
    2.0 * s * poly
}

impl CustomOp1 for Softplus {
    fn name(&self) -> &'static str {
        "softplus"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let (start, end) = layout
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("softplus: input must be contiguous".into()))?;
        let out = match storage {
            CpuStorage::F32(v) => {
                CpuStorage::F32(v[start..end].iter().map(|z| softplus_f32(*z)).collect())
            }
            CpuStorage::F64(v) => CpuStorage::F64(
                v[start..end]
                    .iter()
                    .map(|z| control::mlp::softplus(*z))
                    .collect(),
            ),
            _ => return Err(candle_core::Error::Msg("softplus: only f32 and f64".into())),
        };
        Ok((out, layout.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad_res.mul(&candle_nn::ops::sigmoid(arg)?)?))
    }
}

pub fn softplus(z: &Tensor) -> Result<Tensor> {
    z.contiguous()?.apply_op1(Softplus)
}

/// A trainable MLP.
pub struct Mlp {
    /// (weight [out, in], bias [out]) per layer; the last one is linear.
    pub layers: Vec<(Var, Var)>,
}

/// Activations kept from a forward pass for the input-gradient reverse sweep.
pub struct Forward {
    pub output: Tensor,
    /// Pre-activations of each hidden layer.
    pub pre: Vec<Tensor>,
}

impl Mlp {
    /// PyTorch's default initialisation: uniform ±1/√fan_in, seeded.
    pub fn new(sizes: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Self> {
        let layers = sizes
            .windows(2)
            .map(|w| {
                let (n_in, n_out) = (w[0], w[1]);
                let bound = 1.0 / (n_in as f32).sqrt();
                let wv: Vec<f32> = (0..n_in * n_out)
                    .map(|_| rng.gen_range(-bound..bound))
                    .collect();
                let bv: Vec<f32> = (0..n_out).map(|_| rng.gen_range(-bound..bound)).collect();
                Ok((
                    Var::from_vec(wv, (n_out, n_in), device)?,
                    Var::from_vec(bv, n_out, device)?,
                ))
            })
            .collect::<Result<_>>()?;
        Ok(Self { layers })
    }

    pub fn vars(&self) -> Vec<Var> {
        self.layers
            .iter()
            .flat_map(|(w, b)| [w.clone(), b.clone()])
            .collect()
    }

    /// Named tensors in the weight-file layout.
    pub fn named(&self) -> Vec<(String, Tensor)> {
        self.layers
            .iter()
            .enumerate()
            .flat_map(|(i, (w, b))| {
                [
                    (format!("layers.{i}.weight"), w.as_tensor().clone()),
                    (format!("layers.{i}.bias"), b.as_tensor().clone()),
                ]
            })
            .collect()
    }

    pub fn forward(&self, x: &Tensor) -> Result<Forward> {
        let mut h = x.clone();
        let mut pre = Vec::with_capacity(self.layers.len());
        let last = self.layers.len() - 1;
        for (i, (w, b)) in self.layers.iter().enumerate() {
            let z = h
                .matmul(&w.as_tensor().t()?)?
                .broadcast_add(b.as_tensor())?;
            if i == last {
                return Ok(Forward { output: z, pre });
            }
            h = softplus(&z)?;
            pre.push(z);
        }
        unreachable!("an Mlp has at least one layer")
    }

    /// Copies `other`'s parameters into this one scaled: θ ← (1 − τ) θ + τ θ_other.
    pub fn polyak_from(&self, other: &Mlp, tau: f64) -> Result<()> {
        for ((w, b), (ow, ob)) in self.layers.iter().zip(&other.layers) {
            for (dst, src) in [(w, ow), (b, ob)] {
                let mixed = ((dst.as_tensor() * (1.0 - tau))? + (src.as_tensor() * tau)?)?;
                dst.set(&mixed.detach())?;
            }
        }
        Ok(())
    }

    pub fn copy_from(&self, other: &Mlp) -> Result<()> {
        self.polyak_from(other, 1.0)
    }
}

/// L = ‖Q‖² per row, and the forward pass it came from.
pub fn critic_value(critic: &Mlp, input: &Tensor) -> Result<(Tensor, Forward)> {
    let fwd = critic.forward(input)?;
    let l = fwd.output.sqr()?.sum(D::Minus1)?;
    Ok((l, fwd))
}

/// ∇_input L for each row, as a reverse sweep written in ordinary tensor ops
/// (DESIGN §4): g = 2Q, then g ← g W_l and g ← g ⊙ σ'(z_{l−1}) down the layers.
/// Differentiable with respect to the weights, so a penalty on it trains them.
pub fn critic_input_gradient(critic: &Mlp, fwd: &Forward) -> Result<Tensor> {
    let mut g = (&fwd.output * 2.0)?;
    for (i, (w, _)) in critic.layers.iter().enumerate().rev() {
        g = g.matmul(w.as_tensor())?;
        if i > 0 {
            g = g.mul(&candle_nn::ops::sigmoid(&fwd.pre[i - 1])?)?;
        }
    }
    Ok(g)
}

/// Gradient penalty E[(1 − ‖∇L‖₂)²] of paper eq. 16.
pub fn gradient_penalty(critic: &Mlp, fwd: &Forward) -> Result<Tensor> {
    let g = critic_input_gradient(critic, fwd)?;
    let norm = (g.sqr()?.sum(D::Minus1)? + 1e-12)?.sqrt()?;
    norm.affine(-1.0, 1.0)?.sqr()?.mean_all()
}

pub const LOG_STD_MIN: f64 = -5.0;
pub const LOG_STD_MAX: f64 = 2.0;

/// A tanh-Gaussian policy sample: the action in [−1, 1]² and its log-density.
pub struct PolicySample {
    pub action: Tensor,
    pub log_prob: Tensor,
}

/// log(1 − tanh²(u)) = 2 (ln 2 − u − softplus(−2u)), stable for large |u|.
pub fn log_one_minus_tanh_sq(u: &Tensor) -> Result<Tensor> {
    let sp = softplus(&(u * -2.0)?)?;
    ((u.neg()? - sp)? + std::f64::consts::LN_2)? * 2.0
}

/// Reparameterised sample a = tanh(μ + σ ε) with
/// log π(a) = Σ [log N(ε) − log σ − log(1 − tanh²(u))] (change of variables).
pub fn actor_sample(actor: &Mlp, state: &Tensor, eps: &Tensor) -> Result<PolicySample> {
    let out = actor.forward(state)?.output;
    let mean = out.narrow(1, 0, 2)?;
    let log_std = out.narrow(1, 2, 2)?.clamp(LOG_STD_MIN, LOG_STD_MAX)?;
    let u = (&mean + log_std.exp()?.mul(eps)?)?;
    let log_normal = (eps.sqr()? * -0.5)?.affine(1.0, -0.5 * (2.0 * std::f64::consts::PI).ln())?;
    let log_prob = ((log_normal - &log_std)? - log_one_minus_tanh_sq(&u)?)?.sum(D::Minus1)?;
    Ok(PolicySample {
        action: u.tanh()?,
        log_prob,
    })
}

/// Deterministic action tanh(μ).
pub fn actor_mean_action(actor: &Mlp, state: &Tensor) -> Result<Tensor> {
    actor.forward(state)?.output.narrow(1, 0, 2)?.tanh()
}

pub fn f32_tensor(data: &[f32], rows: usize, cols: usize, device: &Device) -> Result<Tensor> {
    Tensor::from_slice(data, (rows, cols), device)
}

pub fn zeros_like_var(v: &Var) -> Result<Var> {
    Var::zeros(v.shape(), DType::F32, v.device())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn fast_softplus_matches_libm() {
        let mut worst = 0.0f64;
        for i in -40000..=40000 {
            let z = i as f32 * 1e-3;
            let exact = control::mlp::softplus(z as f64);
            let rel = ((softplus_f32(z) as f64 - exact) / exact).abs();
            worst = worst.max(rel);
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
    }

    #[test]
    fn softplus_op_matches_definition_and_its_gradient_is_sigmoid() {
        let dev = Device::Cpu;
        let x = Var::from_vec(vec![-30.0f32, -2.0, -0.1, 0.0, 0.5, 3.0, 25.0], 7, &dev).unwrap();
        let y = softplus(x.as_tensor()).unwrap();
        let yv = y.to_vec1::<f32>().unwrap();
        for (xi, yi) in x.as_tensor().to_vec1::<f32>().unwrap().iter().zip(&yv) {
            let naive = (1.0f64 + (*xi as f64).exp()).ln() as f32;
            assert!((yi - naive).abs() <= 1e-6 * naive.max(1.0));
        }
        let grads = y.sum_all().unwrap().backward().unwrap();
        let g = grads.get(x.as_tensor()).unwrap().to_vec1::<f32>().unwrap();
        for (xi, gi) in x.as_tensor().to_vec1::<f32>().unwrap().iter().zip(&g) {
            let s = 1.0 / (1.0 + (-xi).exp());
            assert!((gi - s).abs() < 1e-6);
        }
    }

    #[test]
    fn input_gradient_matches_finite_differences() {
        let dev = Device::Cpu;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let net = Mlp::new(&[9, 16, 12, 3], &mut rng, &dev).unwrap();
        // f64 copy for accurate differences.
        let to64 =
            |v: &Var| Var::from_tensor(&v.as_tensor().to_dtype(DType::F64).unwrap()).unwrap();
        let net64 = Mlp {
            layers: net.layers.iter().map(|(w, b)| (to64(w), to64(b))).collect(),
        };
        let x: Vec<f64> = (0..9).map(|i| (i as f64 * 0.37).sin()).collect();
        let input = Tensor::from_slice(&x, (1, 9), &dev).unwrap();
        let (_, fwd) = critic_value(&net64, &input).unwrap();
        let g = critic_input_gradient(&net64, &fwd)
            .unwrap()
            .to_vec2::<f64>()
            .unwrap();
        let value = |x: &[f64]| {
            let t = Tensor::from_slice(x, (1, 9), &dev).unwrap();
            critic_value(&net64, &t)
                .unwrap()
                .0
                .to_vec1::<f64>()
                .unwrap()[0]
        };
        for j in 0..9 {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += 1e-6;
            xm[j] -= 1e-6;
            let fd = (value(&xp) - value(&xm)) / 2e-6;
            assert!(
                (fd - g[0][j]).abs() < 1e-7 * fd.abs().max(1.0),
                "input {j}: {fd} vs {}",
                g[0][j]
            );
        }
    }

    #[test]
    fn tanh_gaussian_log_prob_matches_numerical_density() {
        // One-dimensional check of the change of variables: integrate the
        // density of a = tanh(μ + σ ε) numerically over (−1, 1): it must be 1,
        // and a histogram of samples must match it.
        let (mu, log_std) = (0.4f64, -0.3f64);
        let sigma = log_std.exp();
        let density = |a: f64| {
            let u = a.atanh();
            let eps = (u - mu) / sigma;
            let log_n = -0.5 * eps * eps - 0.5 * (2.0 * std::f64::consts::PI).ln() - log_std;
            (log_n - (1.0 - a * a).ln()).exp()
        };
        let n = 200_000;
        let integral: f64 = (0..n)
            .map(|i| density(-1.0 + (i as f64 + 0.5) * 2.0 / n as f64) * 2.0 / n as f64)
            .sum();
        assert!((integral - 1.0).abs() < 1e-3, "∫ density = {integral}");
        // Now the implementation, in 2-D with both components equal: log π = 2 × 1-D log density.
        let dev = Device::Cpu;
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let actor = Mlp::new(&[7, 4], &mut rng, &dev).unwrap();
        // Zero weights, bias = (μ, μ, log σ, log σ): the output is independent of the state.
        actor.layers[0]
            .0
            .set(&Tensor::zeros((4, 7), DType::F32, &dev).unwrap())
            .unwrap();
        let b = Tensor::from_slice(
            &[mu as f32, mu as f32, log_std as f32, log_std as f32],
            4,
            &dev,
        )
        .unwrap();
        actor.layers[0].1.set(&b).unwrap();
        for e in [-2.0f32, -0.5, 0.0, 0.7, 1.9] {
            let eps = Tensor::from_slice(&[e, e], (1, 2), &dev).unwrap();
            let s = actor_sample(
                &actor,
                &Tensor::zeros((1, 7), DType::F32, &dev).unwrap(),
                &eps,
            )
            .unwrap();
            let a = s.action.to_vec2::<f32>().unwrap()[0][0] as f64;
            let lp = s.log_prob.to_vec1::<f32>().unwrap()[0] as f64;
            let expected = 2.0 * density(a).ln();
            assert!(
                (lp - expected).abs() < 1e-3 * expected.abs().max(1.0),
                "ε={e}: {lp} vs {expected}"
            );
        }
    }
}
