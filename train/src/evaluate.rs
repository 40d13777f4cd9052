//! Rollouts of the deployed (f64, `control`) actor, and the Lyapunov checks of
//! `verify`.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use control::model::{converged, env_step, Goal, State};
use control::scenario::Scenario;
use control::{Actor, ActorWorkspace, Critic, CriticWorkspace};

use crate::config::TrainConfig;
use crate::env::{sample_goal, sample_start};

/// How one actor rollout went.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollout {
    pub name: String,
    /// First time within tolerance, if any.
    pub t_converge: Option<f64>,
    pub final_distance: f64,
    pub path_length: f64,
}

/// Runs the deterministic actor from `start` to `goal` on the RL transition.
pub fn rollout(
    actor: &Actor,
    cfg: &TrainConfig,
    name: &str,
    start: State,
    goal: Goal,
    tolerance: f64,
) -> Rollout {
    let mut ws = ActorWorkspace::new(actor);
    let mut x = start;
    let mut t_converge = if converged(&x, &goal, tolerance) {
        Some(0.0)
    } else {
        None
    };
    let mut path = 0.0;
    for k in 0..cfg.episode_steps() {
        let u = actor.action(&mut ws, &x, &goal);
        let next = env_step(&cfg.machine, &x, &u, cfg.dt);
        path += (next[0] - x[0]).hypot(next[1] - x[1]);
        x = next;
        if t_converge.is_none() && converged(&x, &goal, tolerance) {
            t_converge = Some((k + 1) as f64 * cfg.dt);
        }
    }
    Rollout {
        name: name.to_string(),
        t_converge,
        final_distance: control::model::goal_distance(&x, &goal),
        path_length: path,
    }
}

/// Held-out goals: a fixed seed no training run uses for its episodes.
pub fn held_out_goals(cfg: &TrainConfig) -> Vec<(State, Goal)> {
    let mut rng = ChaCha8Rng::seed_from_u64(0xE7A1_u64 ^ cfg.seed.rotate_left(17));
    let far = TrainConfig {
        goal: crate::config::GoalSampling {
            near_fraction: 0.0,
            start_jitter: 0.0,
            ..cfg.goal.clone()
        },
        ..cfg.clone()
    };
    (0..cfg.eval_goals)
        .map(|_| {
            (
                sample_start(&far, &mut rng),
                sample_goal(&far, &mut rng, 1.0),
            )
        })
        .collect()
}

/// Success share of the actor on held-out goals at `tolerance`, and the mean final distance.
pub fn success_rate(actor: &Actor, cfg: &TrainConfig, tolerance: f64) -> (f64, f64) {
    let goals = held_out_goals(cfg);
    let runs: Vec<Rollout> = goals
        .iter()
        .map(|(s, g)| rollout(actor, cfg, "", *s, *g, tolerance))
        .collect();
    let ok = runs.iter().filter(|r| r.t_converge.is_some()).count();
    let mean_d = runs.iter().map(|r| r.final_distance).sum::<f64>() / runs.len() as f64;
    (ok as f64 / runs.len() as f64, mean_d)
}

pub fn rollout_scenarios(
    actor: &Actor,
    cfg: &TrainConfig,
    scenarios: &[Scenario],
    tolerance: f64,
) -> Vec<Rollout> {
    scenarios
        .iter()
        .map(|s| rollout(actor, cfg, &s.name, s.start, s.goal, tolerance))
        .collect()
}

/// One sampled state of `verify`.
#[derive(Debug, Clone, Copy)]
pub struct LyapunovSample {
    pub distance: f64,
    pub cost: f64,
    pub l: f64,
    pub l_next: f64,
    /// ΔL of paper eq. 4c with the exported k = 1 − λ_l, λ = min(λ_l, γ); ≤ 0 is met.
    pub delta: f64,
}

/// Samples states along actor rollouts to random goals and evaluates the
/// decrease condition (eq. 4c) and L ≥ c on each.
pub fn lyapunov_samples(
    actor: &Actor,
    critic: &Critic,
    cfg: &TrainConfig,
    episodes: usize,
    seed: u64,
) -> Vec<LyapunovSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut aws, mut cws) = (ActorWorkspace::new(actor), CriticWorkspace::new(critic));
    let lambda_l = critic.metadata().lambda_l.clamp(0.0, 1.0);
    let (k, lam) = (1.0 - lambda_l, lambda_l.min(cfg.gamma));
    let mut out = Vec::new();
    for _ in 0..episodes {
        let (mut x, g) = (sample_start(cfg, &mut rng), sample_goal(cfg, &mut rng, 1.0));
        let steps = cfg.episode_steps();
        let keep = rng.gen_range(0..steps);
        for i in 0..steps {
            let u = actor.action(&mut aws, &x, &g);
            let next = env_step(&cfg.machine, &x, &u, cfg.dt);
            if i % 10 == keep % 10 {
                let u_next = actor.action(&mut aws, &next, &g);
                let l = critic.value(&mut cws, &x, &u, &g);
                let l_next = critic.value(&mut cws, &next, &u_next, &g);
                let cost = cfg.cost.stage_cost(&next, &g);
                out.push(LyapunovSample {
                    distance: control::model::goal_distance(&x, &g),
                    cost,
                    l,
                    l_next,
                    delta: l_next - l + k * (l - lam * l_next),
                });
            }
            x = next;
        }
    }
    out
}
