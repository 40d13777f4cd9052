//! Rollouts of the deployed (f64, `control`) actor, and the Lyapunov checks of
//! `verify`.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use control::model::{converged, env_step, Goal, State, SUCCESS_TOLERANCE};
use control::scenario::Scenario;
use control::{Actor, ActorWorkspace, Critic, CriticWorkspace};

use crate::config::TrainConfig;
use crate::env::{is_terminal, sample_goal, sample_start};

/// How one actor rollout went.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollout {
    pub name: String,
    /// First time within tolerance, if any.
    pub t_converge: Option<f64>,
    pub final_distance: f64,
    pub final_state: State,
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
        final_state: x,
        path_length: path,
    }
}

/// Held-out goals: a fixed seed no training run uses for its episodes.
pub fn held_out_goals(cfg: &TrainConfig) -> Vec<(State, Goal)> {
    let mut rng = ChaCha8Rng::seed_from_u64(0xE7A1_u64 ^ cfg.seed.rotate_left(17));
    let far = TrainConfig {
        goal: crate::config::GoalSampling {
            near_fraction: 0.0,
            offset_fraction: 0.0,
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
    /// Whether the sample's episode reaches the goal set within the episode.
    pub episode_reached: bool,
}

/// Samples states along actor rollouts to random goals, every tenth step from a
/// random phase, and evaluates the decrease condition (eq. 4c) and L ≥ c on each.
///
/// An episode contributes states only until it first meets the success test: from
/// there the machine rests at its goal, the equilibrium, where L′ = L and no
/// function can decrease (Lyapunov decrease is asked for outside the target set).
pub fn lyapunov_samples(
    actor: &Actor,
    critic: &Critic,
    cfg: &TrainConfig,
    episodes: usize,
    seed: u64,
) -> Vec<LyapunovSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut ws = (ActorWorkspace::new(actor), CriticWorkspace::new(critic));
    let mut out = Vec::new();
    for _ in 0..episodes {
        let (x, g) = (sample_start(cfg, &mut rng), sample_goal(cfg, &mut rng, 1.0));
        let phase = rng.gen_range(0..10);
        episode_samples(actor, critic, cfg, &mut ws, (x, g), phase, &mut out);
    }
    out
}

/// The samples of one episode from `start` to `goal`: every tenth step from
/// `phase`, until the success test first holds.
fn episode_samples(
    actor: &Actor,
    critic: &Critic,
    cfg: &TrainConfig,
    (aws, cws): &mut (ActorWorkspace, CriticWorkspace),
    (mut x, g): (State, Goal),
    phase: usize,
    out: &mut Vec<LyapunovSample>,
) {
    let lambda_l = critic.metadata().lambda_l.clamp(0.0, 1.0);
    let (k, lam) = (1.0 - lambda_l, lambda_l.min(cfg.gamma));
    let first = out.len();
    let mut reached = false;
    for i in 0..cfg.episode_steps() {
        if converged(&x, &g, SUCCESS_TOLERANCE) {
            reached = true;
            break;
        }
        let u = actor.action(aws, &x, &g);
        let next = env_step(&cfg.machine, &x, &u, cfg.dt);
        if i % 10 == phase {
            let u_next = actor.action(aws, &next, &g);
            let l = critic.value(cws, &x, &u, &g);
            // L = 0 beyond a terminal transition (the critic's training target).
            let l_next = if is_terminal(cfg, &next, &g) {
                0.0
            } else {
                critic.value(cws, &next, &u_next, &g)
            };
            out.push(LyapunovSample {
                distance: control::model::goal_distance(&x, &g),
                cost: cfg.cost.stage_cost(&next, &g),
                l,
                l_next,
                delta: l_next - l + k * (l - lam * l_next),
                episode_reached: false,
            });
        }
        x = next;
    }
    reached |= converged(&x, &g, SUCCESS_TOLERANCE);
    for s in &mut out[first..] {
        s.episode_reached = reached;
    }
}

/// What `verify` reports about a set of samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerifySummary {
    pub states: usize,
    /// Share of states with ΔL ≤ 0 (the per-sample form of eq. 4c).
    pub decrease_share: f64,
    /// The same share among states of episodes that reach the goal set, and
    /// among those of episodes that stop short of it (NaN without such states).
    pub decrease_share_reaching: f64,
    pub decrease_share_stopping: f64,
    /// E[ΔL] over the states: eq. 4c itself is this expectation being ≤ 0.
    pub mean_delta: f64,
    /// Share of states with L ≥ c.
    pub above_cost_share: f64,
}

impl VerifySummary {
    pub fn of(samples: &[LyapunovSample]) -> Self {
        let n = samples.len().max(1) as f64;
        let share = |f: &dyn Fn(&LyapunovSample) -> bool| {
            samples.iter().filter(|s| f(s)).count() as f64 / n
        };
        let share_where = |reached: bool| {
            let (met, of) = samples
                .iter()
                .filter(|s| s.episode_reached == reached)
                .fold((0, 0), |(met, of), s| {
                    (met + (s.delta <= 0.0) as usize, of + 1)
                });
            met as f64 / of as f64
        };
        Self {
            states: samples.len(),
            decrease_share: share(&|s| s.delta <= 0.0),
            decrease_share_reaching: share_where(true),
            decrease_share_stopping: share_where(false),
            mean_delta: samples.iter().map(|s| s.delta).sum::<f64>() / n,
            above_cost_share: share(&|s| s.l >= s.cost),
        }
    }
}

/// The samples as CSV, one row per state.
pub fn lyapunov_csv(samples: &[LyapunovSample]) -> String {
    let mut csv =
        String::from("distance,cost,l,l_next,delta,decrease_met,l_ge_c,episode_reached\n");
    for s in samples {
        csv.push_str(&format!(
            "{:.4},{:.6},{:.6},{:.6},{:.6},{},{},{}\n",
            s.distance,
            s.cost,
            s.l,
            s.l_next,
            s.delta,
            s.delta <= 0.0,
            s.l >= s.cost,
            s.episode_reached
        ));
    }
    csv
}

#[cfg(test)]
mod tests {
    use super::*;

    fn networks(cfg: &TrainConfig) -> (Actor, Critic) {
        let agent = crate::agent::Agent::new(cfg).unwrap();
        let (critic, actor) = crate::run::exported(&agent, "test").unwrap();
        (
            Actor::from_weights(actor).unwrap(),
            Critic::from_weights(critic).unwrap(),
        )
    }

    #[test]
    fn verify_samples_only_outside_the_goal_set_with_the_paper_delta() {
        let cfg = TrainConfig::default();
        let (actor, critic) = networks(&cfg);
        let mut ws = (ActorWorkspace::new(&actor), CriticWorkspace::new(&critic));
        let goal = Goal::new(2.0, 1.0, 0.5);
        let at_goal = State::new(2.0, 1.0, 0.5, 0.0, 0.0, 0.0);
        let mut out = Vec::new();
        episode_samples(&actor, &critic, &cfg, &mut ws, (at_goal, goal), 3, &mut out);
        assert!(out.is_empty(), "sampled {} states at the goal", out.len());

        let far = State::new(-6.0, 3.0, 2.0, 0.0, 0.0, 0.0);
        episode_samples(&actor, &critic, &cfg, &mut ws, (far, goal), 3, &mut out);
        assert!(!out.is_empty());
        let lambda_l = critic.metadata().lambda_l;
        let (k, lam) = (1.0 - lambda_l, lambda_l.min(cfg.gamma));
        for s in &out {
            assert!(s.distance >= SUCCESS_TOLERANCE);
            // Paper eq. 4c, per sample: L(s′) − L(s) + k (L(s) − λ L(s′)).
            let expected = s.l_next - s.l + k * s.l - k * lam * s.l_next;
            assert!((s.delta - expected).abs() <= 1e-12 * (1.0 + s.l.abs()));
            // An untrained actor does not get from 8 m away into the goal set.
            assert!(!s.episode_reached);
        }

        // 0.12 m behind the goal at 1 m/s: inside the goal set after one step,
        // whatever the actor does, and the one sample is marked as reaching.
        out.clear();
        let (s, c) = goal.theta.sin_cos();
        let rolling = State::new(
            goal.x - 0.12 * c,
            goal.y - 0.12 * s,
            goal.theta,
            0.0,
            0.0,
            1.0,
        );
        episode_samples(&actor, &critic, &cfg, &mut ws, (rolling, goal), 0, &mut out);
        assert_eq!(out.len(), 1);
        assert!(out[0].episode_reached);
    }

    #[test]
    fn verify_summary_counts_shares_and_the_expectation() {
        let sample = |l: f64, l_next: f64, cost: f64, delta: f64| LyapunovSample {
            distance: 1.0,
            cost,
            l,
            l_next,
            delta,
            episode_reached: l_next < 2.0,
        };
        let v = VerifySummary::of(&[
            sample(2.0, 1.0, 1.0, -0.5),
            sample(2.0, 2.5, 3.0, 0.3),
            sample(1.0, 0.5, 0.5, 0.0),
            sample(1.0, 0.9, 0.2, -0.2),
        ]);
        assert_eq!(v.states, 4);
        assert_eq!(v.decrease_share, 0.75);
        assert_eq!(v.decrease_share_reaching, 1.0);
        assert_eq!(v.decrease_share_stopping, 0.0);
        assert!((v.mean_delta - (-0.1)).abs() < 1e-12);
        assert_eq!(v.above_cost_share, 0.75);
    }

    #[test]
    fn verify_takes_the_value_beyond_a_terminal_transition_as_zero() {
        // A terminal set so large every state is in it: L(s′) = 0 on every sample,
        // and ΔL = −L + k L.
        let mut cfg = TrainConfig::default();
        let (actor, critic) = networks(&cfg);
        cfg.terminal.distance = 1e3;
        cfg.terminal.speed = 1e3;
        cfg.terminal.beta_rate = 1e3;
        let samples = lyapunov_samples(&actor, &critic, &cfg, 10, 1);
        assert!(!samples.is_empty());
        let k = 1.0 - critic.metadata().lambda_l;
        for s in &samples {
            assert_eq!(s.l_next, 0.0);
            assert!((s.delta - (k - 1.0) * s.l).abs() <= 1e-12 * (1.0 + s.l));
        }
    }
}
