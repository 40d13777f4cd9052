//! Where the deterministic actor stops short of its goal, and whether the
//! training objective asks it to go on.
//!
//! An actor trained on the discounted cost Σ γᵗ c stops for good at a state x
//! when no manoeuvre from x costs less than standing there: c(x)/(1 − γ). To
//! tell a poorly trained actor from an objective that rewards stopping, a
//! cross-entropy search looks for open-loop manoeuvres from each stop that beat
//! standing still under a given γ. A search finds upper bounds only: "none
//! found" is evidence, not proof, that stopping is optimal; a manoeuvre found is
//! proof that it is not.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use control::model::{env_step, goal_distance, ix, Control, Goal, State, SUCCESS_TOLERANCE};
use control::Actor;

use crate::config::TrainConfig;
use crate::env::{is_terminal, sample_goal, sample_start, transition_cost};
use crate::evaluate::rollout;

/// An episode the actor ended outside the goal set: its last state and goal.
#[derive(Debug, Clone, Copy)]
pub struct Stall {
    pub state: State,
    pub goal: Goal,
}

impl Stall {
    /// Position error in the goal's frame: (along its heading, sideways) [m].
    pub fn along_sideways(&self) -> (f64, f64) {
        let (dx, dy) = (
            self.state[ix::X] - self.goal.x,
            self.state[ix::Y] - self.goal.y,
        );
        let (s, c) = self.goal.theta.sin_cos();
        (c * dx + s * dy, -s * dx + c * dy)
    }
}

/// Episodes (from verify's start and goal distribution) in which the
/// deterministic actor never meets the success test within the episode.
pub fn find_stalls(actor: &Actor, cfg: &TrainConfig, episodes: usize, seed: u64) -> Vec<Stall> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..episodes)
        .filter_map(|_| {
            let (x, goal) = (sample_start(cfg, &mut rng), sample_goal(cfg, &mut rng, 1.0));
            let r = rollout(actor, cfg, "", x, goal, SUCCESS_TOLERANCE);
            r.t_converge.is_none().then_some(Stall {
                state: r.final_state,
                goal,
            })
        })
        .collect()
}

/// The manoeuvre search: piecewise-constant scaled actions, then braking to rest.
#[derive(Debug, Clone, Copy)]
pub struct ManoeuvreSearch {
    /// Number of constant pieces of the manoeuvre.
    pub pieces: usize,
    /// Transitions per piece.
    pub piece_steps: usize,
    /// Transitions summed explicitly (manoeuvre, then braking); after them the
    /// machine stands still and the rest is the geometric tail c/(1 − γ).
    pub horizon_steps: usize,
    pub population: usize,
    pub elites: usize,
    pub iterations: usize,
}

impl Default for ManoeuvreSearch {
    /// 20 s of manoeuvre in 1 s pieces, 60 s summed (at Δt = 0.2 s).
    fn default() -> Self {
        Self {
            pieces: 20,
            piece_steps: 5,
            horizon_steps: 300,
            population: 400,
            elites: 40,
            iterations: 60,
        }
    }
}

/// The best manoeuvre found from a stop, against standing still.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ManoeuvreResult {
    /// Σ γᵗ c of standing still.
    pub stay: f64,
    /// Σ γᵗ c of the cheapest manoeuvre found (≤ `stay`: standing still is a candidate).
    pub best: f64,
    /// Goal distance where that manoeuvre ends.
    pub end_distance: f64,
}

/// Runs `actions` (scaled, one per piece) from `x0`, then brakes β̇ and v to zero;
/// returns Σ γᵗ c over the transitions plus the resting tail, and the end state.
/// A transition into the terminal set (config `[terminal]`) ends the sum there.
fn discounted_cost(
    cfg: &TrainConfig,
    search: &ManoeuvreSearch,
    x0: &State,
    goal: &Goal,
    actions: &[[f64; 2]],
    gamma: f64,
) -> (f64, State) {
    let m = &cfg.machine;
    let (mut x, mut sum, mut discount) = (*x0, 0.0, 1.0);
    for k in 0..search.horizon_steps {
        let a = actions
            .get(k / search.piece_steps)
            .copied()
            .unwrap_or_else(|| {
                [
                    (-x[ix::BETA_DOT] / (m.beta_ddot_max * cfg.dt)).clamp(-1.0, 1.0),
                    (-x[ix::V] / (m.a_max * cfg.dt)).clamp(-1.0, 1.0),
                ]
            });
        let next = env_step(
            m,
            &x,
            &Control::new(a[0] * m.beta_ddot_max, a[1] * m.a_max),
            cfg.dt,
        );
        sum += discount * transition_cost(cfg, &next, &a, goal);
        if is_terminal(cfg, &next, goal) {
            return (sum, next);
        }
        discount *= gamma;
        x = next;
    }
    (
        sum + discount * cfg.cost.stage_cost(&x, goal) / (1.0 - gamma),
        x,
    )
}

/// Cross-entropy search for the cheapest manoeuvre from `x0` under discount `gamma`.
pub fn best_manoeuvre(
    cfg: &TrainConfig,
    search: &ManoeuvreSearch,
    x0: &State,
    goal: &Goal,
    gamma: f64,
    seed: u64,
) -> ManoeuvreResult {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let still = vec![[0.0; 2]; search.pieces];
    let (stay, x_stay) = discounted_cost(cfg, search, x0, goal, &still, gamma);
    let mut best = (stay, x_stay);
    let mut mean = vec![[0.0f64; 2]; search.pieces];
    let mut sd = vec![[0.6f64; 2]; search.pieces];
    for _ in 0..search.iterations {
        let mut population: Vec<(f64, State, Vec<[f64; 2]>)> = (0..search.population)
            .map(|_| {
                let actions: Vec<[f64; 2]> = mean
                    .iter()
                    .zip(&sd)
                    .map(|(m, s)| {
                        [0, 1].map(|i| {
                            let z: f64 = rng.sample(StandardNormal);
                            (m[i] + s[i] * z).clamp(-1.0, 1.0)
                        })
                    })
                    .collect();
                let (cost, end) = discounted_cost(cfg, search, x0, goal, &actions, gamma);
                (cost, end, actions)
            })
            .collect();
        population.sort_by(|a, b| a.0.total_cmp(&b.0));
        if population[0].0 < best.0 {
            best = (population[0].0, population[0].1);
        }
        let elites = &population[..search.elites.min(population.len())];
        let n = elites.len() as f64;
        for p in 0..search.pieces {
            for i in 0..2 {
                let m = elites.iter().map(|e| e.2[p][i]).sum::<f64>() / n;
                let var = elites.iter().map(|e| (e.2[p][i] - m).powi(2)).sum::<f64>() / n;
                mean[p][i] = m;
                // A floor keeps the search from collapsing onto one manoeuvre early.
                sd[p][i] = var.sqrt().max(0.02);
            }
        }
    }
    ManoeuvreResult {
        stay,
        best: best.0,
        end_distance: goal_distance(&best.1, goal),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::model::converged;

    fn small_search() -> ManoeuvreSearch {
        // 10 s of manoeuvre, 20 s summed.
        ManoeuvreSearch {
            pieces: 10,
            piece_steps: 5,
            horizon_steps: 100,
            population: 200,
            elites: 20,
            iterations: 30,
        }
    }

    #[test]
    fn at_the_goal_nothing_beats_standing_still() {
        let cfg = TrainConfig::default();
        let goal = Goal::new(1.0, -2.0, 0.3);
        let x = State::new(1.0, -2.0, 0.3, 0.0, 0.0, 0.0);
        let r = best_manoeuvre(&cfg, &small_search(), &x, &goal, 0.99, 1);
        assert_eq!(r.stay, 0.0);
        assert_eq!(r.best, 0.0);
        assert!(r.end_distance < 1e-12);
    }

    #[test]
    fn standing_behind_the_goal_the_search_drives_there() {
        // At rest 2 m straight behind the goal: driving forward pays (the
        // published run's cost and γ).
        let cfg = TrainConfig::from_toml(include_str!("../configs/alac-power.toml")).unwrap();
        let goal = Goal::new(2.0, 0.0, 0.0);
        let x = State::zeros();
        let r = best_manoeuvre(&cfg, &small_search(), &x, &goal, cfg.gamma, 2);
        let c = cfg.cost.stage_cost(&x, &goal);
        assert!((r.stay - c / (1.0 - cfg.gamma)).abs() < 1e-9 * r.stay);
        assert!(r.best < 0.75 * r.stay, "best {} stay {}", r.best, r.stay);
        assert!(
            r.end_distance < 0.3,
            "ends {} from the goal",
            r.end_distance
        );
    }

    #[test]
    fn stalls_are_episodes_ending_outside_the_goal_set() {
        // A random actor reaches almost nothing: its stalls are its episodes, each
        // ending outside the goal set; the goal frame splits the position error.
        let cfg = TrainConfig {
            episode_seconds: 2.0,
            ..Default::default()
        };
        let agent = crate::agent::Agent::new(&cfg).unwrap();
        let (_, actor) = crate::run::exported(&agent, "test").unwrap();
        let actor = Actor::from_weights(actor).unwrap();
        let stalls = find_stalls(&actor, &cfg, 20, 3);
        assert!(stalls.len() >= 15, "{} stalls", stalls.len());
        for s in &stalls {
            assert!(!converged(&s.state, &s.goal, SUCCESS_TOLERANCE));
            let (along, sideways) = s.along_sideways();
            let e = control::model::pose_error(&s.state, &s.goal);
            assert!((along.hypot(sideways) - e[0]).abs() < 1e-9);
        }
        let behind = Stall {
            state: State::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
            goal: Goal::new(0.5, 1.2, 0.0),
        };
        let (along, sideways) = behind.along_sideways();
        assert!((along + 0.5).abs() < 1e-12 && (sideways + 0.2).abs() < 1e-12);
    }

    #[test]
    fn standing_in_the_terminal_set_costs_one_transition() {
        // At rest 0.05 m beside the goal: without a terminal set standing still
        // costs c/(1 − γ) (the geometric tail), with one only the first transition.
        let mut cfg = TrainConfig::default();
        let goal = Goal::new(0.0, 0.05, 0.0);
        let x = State::zeros();
        let still = vec![[0.0; 2]; 10];
        let c = transition_cost(&cfg, &x, &[0.0; 2], &goal);
        assert!(c > 0.0);
        let (open, _) = discounted_cost(&cfg, &small_search(), &x, &goal, &still, 0.99);
        assert!((open - c / (1.0 - 0.99)).abs() < 1e-9 * open, "{open}");
        cfg.terminal.distance = 0.1;
        let (ended, end) = discounted_cost(&cfg, &small_search(), &x, &goal, &still, 0.99);
        assert_eq!(ended, c);
        assert_eq!(end, x);
    }
}
