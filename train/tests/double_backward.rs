//! The gradient penalty's gradient, back-propagated once through the
//! hand-written input-gradient sweep, equals candle's own double backward
//! (CANDLE_GRAD_DO_NOT_DETACH=1 keeps the graph of the first backward).
//! Own test binary: the flag is read once per thread from the environment.

use candle_core::{DType, Device, Tensor, Var, D};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use train::nets::{critic_value, gradient_penalty, Mlp};

#[test]
fn penalty_gradient_equals_double_backward() {
    // Set before any backward pass runs on this thread.
    std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1");
    let dev = Device::Cpu;
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let net = Mlp::new(&[9, 12, 10, 3], &mut rng, &dev).unwrap();
    let to64 = |v: &Var| Var::from_tensor(&v.as_tensor().to_dtype(DType::F64).unwrap()).unwrap();
    let net = Mlp {
        layers: net.layers.iter().map(|(w, b)| (to64(w), to64(b))).collect(),
    };
    let xs: Vec<f64> = (0..5 * 9)
        .map(|i| ((i * 7 % 13) as f64 * 0.31).sin())
        .collect();

    // Ours: reverse sweep as tensor ops, one backward.
    let input = Tensor::from_slice(&xs, (5, 9), &dev).unwrap();
    let (_, fwd) = critic_value(&net, &input).unwrap();
    let ours = gradient_penalty(&net, &fwd).unwrap().backward().unwrap();

    // Candle's: input gradient by autograd (graph kept), then a second backward.
    let x_var = Var::from_tensor(&input).unwrap();
    let (l, _) = critic_value(&net, x_var.as_tensor()).unwrap();
    let g1 = l.sum_all().unwrap().backward().unwrap();
    let grad_x = g1.get(x_var.as_tensor()).unwrap();
    let norm = (grad_x.sqr().unwrap().sum(D::Minus1).unwrap() + 1e-12)
        .unwrap()
        .sqrt()
        .unwrap();
    let penalty = norm
        .affine(-1.0, 1.0)
        .unwrap()
        .sqr()
        .unwrap()
        .mean_all()
        .unwrap();
    let theirs = penalty.backward().unwrap();

    let mut compared = 0;
    for (w, b) in &net.layers {
        for v in [w, b] {
            let a = ours
                .get(v.as_tensor())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap();
            let t = theirs
                .get(v.as_tensor())
                .expect("double backward reached the weights");
            let t = t.flatten_all().unwrap().to_vec1::<f64>().unwrap();
            let scale = t.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-12);
            for (x, y) in a.iter().zip(&t) {
                assert!((x - y).abs() <= 1e-5 * scale, "{x} vs {y}");
                compared += 1;
            }
        }
    }
    assert!(compared > 200);
}
