//! An exported file loads in `control`, and its value, gradient and action
//! equal candle's on 100 random inputs (relative 1e-6). Candle runs in f64
//! here so the comparison measures the implementations, not f32 rounding.

use candle_core::{DType, Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use control::encoder::{CRITIC_INPUTS, NZ};
use control::model::{Control, Goal, State};
use control::weights::{decode, encode, FileDtype, NetworkRole};
use control::{Actor, ActorWorkspace, Critic, CriticWorkspace};
use train::agent::Agent;
use train::config::TrainConfig;
use train::nets::{actor_mean_action, critic_input_gradient, critic_value, Mlp};

fn to_f64(net: &Mlp) -> Mlp {
    let c = |v: &Var| Var::from_tensor(&v.as_tensor().to_dtype(DType::F64).unwrap()).unwrap();
    Mlp {
        layers: net.layers.iter().map(|(w, b)| (c(w), c(b))).collect(),
    }
}

#[test]
fn exported_networks_match_candle() {
    let cfg = TrainConfig::default();
    let agent = Agent::new(&cfg).unwrap();
    // Through the file format, in f64 so no rounding enters.
    let critic_w = train::run::exported(&agent, "test").unwrap().0;
    let bytes = encode(&critic_w.meta, &critic_w.mlp, FileDtype::F64).unwrap();
    let critic = Critic::from_weights(decode(&bytes, "critic.safetensors").unwrap()).unwrap();
    let actor_w = train::run::exported(&agent, "test").unwrap().1;
    assert_eq!(actor_w.meta.role, NetworkRole::Actor);
    let bytes = encode(&actor_w.meta, &actor_w.mlp, FileDtype::F64).unwrap();
    let actor = Actor::from_weights(decode(&bytes, "actor.safetensors").unwrap()).unwrap();
    let (c64, a64) = (to_f64(&agent.critic), to_f64(&agent.actor));

    let enc = *critic.encoder();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (mut cws, mut aws) = (CriticWorkspace::new(&critic), ActorWorkspace::new(&actor));
    let dev = Device::Cpu;
    for _ in 0..100 {
        let x =
            State::from_fn(|i, _| rng.gen_range(-1.0..1.0) * [8.0, 8.0, 3.1, 0.69, 0.57, 1.0][i]);
        let u = Control::new(rng.gen_range(-0.57..0.57), rng.gen_range(-1.0..1.0));
        let g = Goal::new(
            rng.gen_range(-9.0..9.0),
            rng.gen_range(-9.0..9.0),
            rng.gen_range(-3.1..3.1),
        );
        let mut grad = [0.0; NZ];
        let value = critic.value_gradient(&mut cws, &x, &u, &g, &mut grad);

        let mut f = [0.0; CRITIC_INPUTS];
        enc.encode(&x, &u, &g, &mut f);
        let input = Tensor::from_slice(&f, (1, CRITIC_INPUTS), &dev).unwrap();
        let (l, fwd) = critic_value(&c64, &input).unwrap();
        let l = l.to_vec1::<f64>().unwrap()[0];
        assert!((value - l).abs() <= 1e-6 * l.abs(), "value {value} vs {l}");
        // Candle's input gradient, chained through the encoder Jacobian.
        let gf = critic_input_gradient(&c64, &fwd)
            .unwrap()
            .to_vec2::<f64>()
            .unwrap()[0]
            .clone();
        let mut jac = [[0.0; NZ]; CRITIC_INPUTS];
        enc.jacobian(&x, &g, &mut jac);
        let scale = grad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for j in 0..NZ {
            let expected: f64 = (0..CRITIC_INPUTS).map(|k| gf[k] * jac[k][j]).sum();
            assert!(
                (grad[j] - expected).abs() <= 1e-6 * scale,
                "∂L/∂z{j}: {} vs {expected}",
                grad[j]
            );
        }

        let a = actor.action(&mut aws, &x, &g);
        let mut fs = [0.0; 7];
        enc.encode_state(&x, &g, &mut fs);
        let t = actor_mean_action(&a64, &Tensor::from_slice(&fs, (1, 7), &dev).unwrap()).unwrap();
        let t = t.to_vec2::<f64>().unwrap()[0].clone();
        let p = &cfg.machine;
        for (k, max) in [p.beta_ddot_max, p.a_max].into_iter().enumerate() {
            let expected = t[k] * max;
            assert!(
                (a[k] - expected).abs() <= 1e-6 * expected.abs().max(1e-3),
                "action {k}: {} vs {expected}",
                a[k]
            );
        }
    }
}
