//! The two-thread update (each gradient on two batch halves, averaged) is the
//! one-thread update: same losses, same parameters after a few updates, with
//! either kernel.

use rand::{Rng, SeedableRng};
use train::agent::Agent;
use train::buffer::Batch;
use train::config::{Kernel, TrainConfig};

fn batch(n: usize, seed: u64) -> Batch {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut v = |k: usize, lo: f32, hi: f32| (0..k).map(|_| rng.gen_range(lo..hi)).collect();
    Batch {
        len: n,
        state: v(n * 7, -1.0, 1.0),
        action: v(n * 2, -1.0, 1.0),
        cost: v(n, 0.0, 1.0),
        next_state: v(n * 7, -1.0, 1.0),
        not_done: (0..n).map(|i| if i % 5 == 0 { 0.0 } else { 1.0 }).collect(),
        own_goal: (0..n).map(|i| if i % 4 == 0 { 1.0 } else { 0.0 }).collect(),
    }
}

fn params(agent: &Agent) -> Vec<f32> {
    [&agent.critic, &agent.actor]
        .iter()
        .flat_map(|net| net.named())
        .flat_map(|(_, t)| t.flatten_all().unwrap().to_vec1::<f32>().unwrap())
        .collect()
}

#[test]
fn two_thread_update_equals_the_one_thread_update() {
    for kernel in [Kernel::Fused, Kernel::Candle] {
        two_threads_equal_one(kernel);
    }
}

fn two_threads_equal_one(kernel: Kernel) {
    let cfg = TrainConfig {
        batch_size: 64,
        hidden: vec![32, 32],
        gradient_penalty: 1e-2,
        kernel,
        ..TrainConfig::default()
    };
    let mut one = Agent::new(&cfg).unwrap();
    let mut two = Agent::new(&TrainConfig {
        two_threads: true,
        ..cfg.clone()
    })
    .unwrap();
    for k in 0..3 {
        let b = batch(64, k);
        let (s1, s2) = (one.update(&b).unwrap(), two.update(&b).unwrap());
        for (name, x, y) in [
            ("critic loss", s1.critic_loss, s2.critic_loss),
            ("penalty", s1.penalty, s2.penalty),
            ("actor loss", s1.actor_loss, s2.actor_loss),
            ("delta L", s1.delta_l, s2.delta_l),
            ("mean L", s1.mean_l, s2.mean_l),
            ("entropy", s1.entropy, s2.entropy),
        ] {
            assert!(
                (x - y).abs() <= 1e-5 * (1.0 + x.abs()),
                "{kernel:?} update {k}: {name} {x} vs {y}"
            );
        }
    }
    let (p1, p2) = (params(&one), params(&two));
    let worst = p1
        .iter()
        .zip(&p2)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let moved = p1
        .iter()
        .zip(params(&Agent::new(&cfg).unwrap()))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    eprintln!("{kernel:?}: max parameter difference {worst:e}, max move {moved:e}");
    assert!(
        moved > 1e-4,
        "{kernel:?}: the updates did not move the parameters"
    );
    assert!(
        worst < 1e-5,
        "{kernel:?}: parameters differ by up to {worst}"
    );
}
