//! The goal-conditioned training environment (DESIGN §4), vectorised: many
//! machines stepped together with `control`'s own transition and cost.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use control::model::{env_step, goal_distance, ix, Control, Goal, State};

use crate::config::TrainConfig;

/// One stored transition: s, a (scaled to [−1, 1]), s′, g, and where it lies in
/// its episode (for hindsight relabelling).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    pub x: State,
    /// Action divided by its bounds, in [−1, 1]².
    pub a: [f64; 2],
    pub next: State,
    pub goal: Goal,
}

/// Cost of reaching `next` with scaled action `a` (the cost is charged on the
/// state the action leads to, so L(s, a) sees the action's effect at once).
pub fn transition_cost(cfg: &TrainConfig, next: &State, a: &[f64; 2], g: &Goal) -> f64 {
    cfg.cost.stage_cost(next, g) + cfg.action_cost * (a[0] * a[0] + a[1] * a[1])
}

/// Whether `x` lies in the goal's terminal set (config `[terminal]`): at rest,
/// pose within `terminal.distance`. Never with termination off.
pub fn is_terminal(cfg: &TrainConfig, x: &State, g: &Goal) -> bool {
    let t = &cfg.terminal;
    t.distance > 0.0
        && x[ix::V].abs() < t.speed
        && x[ix::BETA_DOT].abs() < t.beta_rate
        && goal_distance(x, g) < t.distance
}

/// A goal at distance r ∈ [r_min, r_max] (or the near band), uniform bearing and
/// heading, or beside the start pose (the offset share); `progress` ∈ [0, 1] is
/// the curriculum's position (1 = full band).
pub fn sample_goal(cfg: &TrainConfig, rng: &mut ChaCha8Rng, progress: f64) -> Goal {
    let g = &cfg.goal;
    let far_hi = g.r_min + (g.r_max - g.r_min) * progress.clamp(0.0, 1.0);
    let band = rng.gen::<f64>();
    if band < g.offset_fraction {
        // Beside the start pose (the origin, heading 0).
        let along = g.offset_max / 4.0;
        return Goal::new(
            rng.gen_range(-along..=along),
            rng.gen_range(-g.offset_max..=g.offset_max),
            rng.gen_range(-along..=along),
        );
    }
    let (lo, hi) = if band < g.offset_fraction + g.near_fraction {
        (g.near_r_min, g.r_min)
    } else {
        (g.r_min, far_hi)
    };
    let r = rng.gen_range(lo..=hi);
    let bearing = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
    let heading = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
    Goal::new(r * bearing.cos(), r * bearing.sin(), heading)
}

/// Start at rest at the origin, heading 0, with a little β and v_f jitter.
pub fn sample_start(cfg: &TrainConfig, rng: &mut ChaCha8Rng) -> State {
    let j = cfg.goal.start_jitter;
    let m = &cfg.machine;
    let mut x = State::zeros();
    if j > 0.0 {
        x[ix::BETA] = rng.gen_range(-j..=j) * m.beta_max;
        x[ix::V] = rng.gen_range(-j..=j) * m.v_max;
    }
    x
}

/// Parallel environments. Each keeps its running episode until it ends, then
/// hands it over whole, so relabelling can look at the episode's future.
pub struct VecEnv {
    pub states: Vec<State>,
    pub goals: Vec<Goal>,
    steps: Vec<usize>,
    episodes: Vec<Vec<Transition>>,
    /// Curriculum position in [0, 1], set by the training loop.
    pub progress: f64,
}

impl VecEnv {
    pub fn new(cfg: &TrainConfig, rng: &mut ChaCha8Rng) -> Self {
        let n = cfg.n_envs;
        let mut env = Self {
            states: vec![State::zeros(); n],
            goals: vec![Goal::default(); n],
            steps: vec![0; n],
            episodes: (0..n)
                .map(|_| Vec::with_capacity(cfg.episode_steps()))
                .collect(),
            progress: 1.0,
        };
        for i in 0..n {
            env.reset(cfg, i, rng);
        }
        env
    }

    fn reset(&mut self, cfg: &TrainConfig, i: usize, rng: &mut ChaCha8Rng) {
        self.states[i] = sample_start(cfg, rng);
        self.goals[i] = sample_goal(cfg, rng, self.progress);
        self.steps[i] = 0;
        self.episodes[i].clear();
    }

    /// Steps every environment with its scaled action; calls `finished` with
    /// each episode that ended: in the terminal set ([`is_terminal`]) or at the
    /// 30 s time limit (a truncation, not a terminal).
    pub fn step(
        &mut self,
        cfg: &TrainConfig,
        actions: &[[f64; 2]],
        rng: &mut ChaCha8Rng,
        mut finished: impl FnMut(&[Transition]),
    ) {
        let m = &cfg.machine;
        for i in 0..self.states.len() {
            let a = [
                actions[i][0].clamp(-1.0, 1.0),
                actions[i][1].clamp(-1.0, 1.0),
            ];
            let u = Control::new(a[0] * m.beta_ddot_max, a[1] * m.a_max);
            let next = env_step(m, &self.states[i], &u, cfg.dt);
            self.episodes[i].push(Transition {
                x: self.states[i],
                a,
                next,
                goal: self.goals[i],
            });
            self.states[i] = next;
            self.steps[i] += 1;
            if self.steps[i] >= cfg.episode_steps() || is_terminal(cfg, &next, &self.goals[i]) {
                finished(&self.episodes[i]);
                self.reset(cfg, i, rng);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn goals_lie_in_their_band_and_episodes_have_full_length() {
        let cfg = TrainConfig {
            n_envs: 3,
            episode_seconds: 2.0,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..1000 {
            let g = sample_goal(&cfg, &mut rng, 1.0);
            let r = g.x.hypot(g.y);
            assert!(r >= cfg.goal.near_r_min - 1e-12 && r <= cfg.goal.r_max + 1e-12);
            // At the curriculum's start the far band has collapsed to r_min.
            let g = sample_goal(&cfg, &mut rng, 0.0);
            assert!(g.x.hypot(g.y) <= cfg.goal.r_min + 1e-12);
        }
        let mut env = VecEnv::new(&cfg, &mut rng);
        let mut ended = Vec::new();
        for _ in 0..25 {
            env.step(&cfg, &[[1.0, 1.0]; 3], &mut rng, |ep| {
                ended.push(ep.to_vec())
            });
        }
        assert_eq!(ended.len(), 6);
        for ep in &ended {
            assert_eq!(ep.len(), 10);
            for w in ep.windows(2) {
                assert_eq!(w[0].next, w[1].x, "episode is contiguous");
                assert_eq!(w[0].goal, w[1].goal);
            }
            assert!(ep.iter().all(|t| t.next[ix::V] <= cfg.machine.v_max));
        }
    }

    #[test]
    fn offset_goals_lie_beside_the_start_in_their_share() {
        let mut cfg = TrainConfig::default();
        cfg.goal.offset_max = 0.4;
        let in_box = |g: &Goal| g.x.abs() <= 0.1 && g.y.abs() <= 0.4 && g.theta.abs() <= 0.1;
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        cfg.goal.offset_fraction = 1.0 - cfg.goal.near_fraction;
        let goals: Vec<Goal> = (0..2000)
            .map(|_| sample_goal(&cfg, &mut rng, 1.0))
            .collect();
        let beside: Vec<&Goal> = goals.iter().filter(|g| in_box(g)).collect();
        // Sideways offsets of both signs, out to the band's edge.
        assert!(beside.iter().any(|g| g.y > 0.3) && beside.iter().any(|g| g.y < -0.3));
        assert!(beside
            .iter()
            .any(|g| g.x.abs() > 0.08 && g.theta.abs() > 0.08));

        // The share: near/far goals almost never fall in this box.
        cfg.goal.offset_fraction = 0.3;
        let n = 4000;
        let share = (0..n)
            .filter(|_| in_box(&sample_goal(&cfg, &mut rng, 1.0)))
            .count() as f64
            / n as f64;
        assert!((share - 0.3).abs() < 0.03, "share {share}");
    }

    #[test]
    fn an_episode_ends_at_rest_in_the_terminal_set_only_with_termination_on() {
        let mut cfg = TrainConfig {
            n_envs: 2,
            ..Default::default()
        };
        cfg.goal.start_jitter = 0.0;
        let lengths = |cfg: &TrainConfig, speed: f64| {
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let mut env = VecEnv::new(cfg, &mut rng);
            // Env 0's goal 0.05 m ahead of the start, env 1's far away.
            env.goals[0] = Goal::new(0.05, 0.0, 0.0);
            env.goals[1] = Goal::new(8.0, 0.0, 0.0);
            env.states[0][ix::V] = speed;
            let mut ended = Vec::new();
            env.step(cfg, &[[0.0, 0.0]; 2], &mut rng, |ep| ended.push(ep.len()));
            ended
        };
        assert!(
            lengths(&cfg, 0.0).is_empty(),
            "termination is off by default"
        );
        cfg.terminal.distance = 0.1;
        assert_eq!(lengths(&cfg, 0.0), vec![1], "at rest inside: ends");
        // Rolling at 0.3 m/s with zero acceleration: inside, but not at rest.
        assert!(lengths(&cfg, 0.3).is_empty());
        let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        assert!(is_terminal(&cfg, &x, &Goal::new(0.05, 0.0, 0.0)));
        assert!(!is_terminal(&cfg, &x, &Goal::new(0.0, 0.12, 0.0)));
        let mut turning = x;
        turning[ix::BETA_DOT] = 0.2;
        assert!(!is_terminal(&cfg, &turning, &Goal::new(0.05, 0.0, 0.0)));
    }
}
