//! Replay buffer of whole episodes with hindsight goal relabelling.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use control::encoder::{Encoder, ACTOR_INPUTS};
use control::model::{ix, Goal};

use crate::config::TrainConfig;
use crate::env::{is_terminal, transition_cost, Transition};

/// A ring of transitions; each remembers (as absolute insertion counts) where
/// its episode ends, so a later pose of the same episode can stand in as goal.
pub struct ReplayBuffer {
    slots: Vec<Transition>,
    episode_end: Vec<u64>,
    capacity: usize,
    inserted: u64,
}

/// A training batch as flat f32 rows, ready for tensors.
#[derive(Debug, Clone, Default)]
pub struct Batch {
    pub len: usize,
    /// Actor features of s [len × 7].
    pub state: Vec<f32>,
    /// Scaled action [len × 2].
    pub action: Vec<f32>,
    /// Cost c [len].
    pub cost: Vec<f32>,
    /// Actor features of s′ [len × 7].
    pub next_state: Vec<f32>,
    /// 1 − done: 0 where s′ lies in the (possibly relabelled) goal's terminal set.
    pub not_done: Vec<f32>,
    /// 1 where the row keeps its episode's own goal, 0 where relabelled.
    pub own_goal: Vec<f32>,
}

impl ReplayBuffer {
    pub fn new(capacity: usize) -> Self {
        Self {
            slots: Vec::with_capacity(capacity.min(1 << 20)),
            episode_end: Vec::new(),
            capacity,
            inserted: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    pub fn push_episode(&mut self, episode: &[Transition]) {
        let end = self.inserted + episode.len() as u64;
        for t in episode {
            let slot = (self.inserted % self.capacity as u64) as usize;
            if slot < self.slots.len() {
                self.slots[slot] = *t;
                self.episode_end[slot] = end;
            } else {
                self.slots.push(*t);
                self.episode_end.push(end);
            }
            self.inserted += 1;
        }
    }

    /// Draws `n` transitions uniformly, relabels a share `her_ratio` of them
    /// with a future pose of their episode, and encodes them with `encoder`.
    pub fn sample(
        &self,
        cfg: &TrainConfig,
        encoder: &Encoder,
        n: usize,
        rng: &mut ChaCha8Rng,
        out: &mut Batch,
    ) {
        out.len = n;
        out.state.clear();
        out.action.clear();
        out.cost.clear();
        out.next_state.clear();
        out.not_done.clear();
        out.own_goal.clear();
        let oldest = self.inserted.saturating_sub(self.slots.len() as u64);
        let mut f = [0.0; ACTOR_INPUTS];
        for _ in 0..n {
            let abs = rng.gen_range(oldest..self.inserted);
            let slot = (abs % self.capacity as u64) as usize;
            let t = &self.slots[slot];
            let mut goal = t.goal;
            let relabel = rng.gen::<f64>() < cfg.her_ratio;
            out.own_goal.push(if relabel { 0.0 } else { 1.0 });
            if relabel {
                let end = self.episode_end[slot];
                let future = rng.gen_range(abs..end);
                let reached = &self.slots[(future % self.capacity as u64) as usize].next;
                goal = Goal::new(reached[ix::X], reached[ix::Y], reached[ix::THETA]);
            }
            encoder.encode_state(&t.x, &goal, &mut f);
            out.state.extend(f.iter().map(|v| *v as f32));
            encoder.encode_state(&t.next, &goal, &mut f);
            out.next_state.extend(f.iter().map(|v| *v as f32));
            out.action.extend(t.a.iter().map(|v| *v as f32));
            out.cost
                .push(transition_cost(cfg, &t.next, &t.a, &goal) as f32);
            // Recomputed for the goal used: a relabelled goal has its own terminal set.
            out.not_done.push(if is_terminal(cfg, &t.next, &goal) {
                0.0
            } else {
                1.0
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::model::State;
    use rand::SeedableRng;

    fn episode(k: usize, len: usize) -> Vec<Transition> {
        (0..len)
            .map(|i| {
                let x = State::new((k * 100 + i) as f64, 0.0, 0.0, 0.0, 0.0, 0.0);
                let next = State::new((k * 100 + i + 1) as f64, 0.0, 0.0, 0.0, 0.0, 0.0);
                Transition {
                    x,
                    a: [0.0, 0.0],
                    next,
                    goal: Goal::new(-1.0, 0.0, 0.0),
                }
            })
            .collect()
    }

    #[test]
    fn relabelled_goals_come_from_the_same_episodes_future() {
        let cfg = TrainConfig {
            her_ratio: 1.0,
            pos_scale: 1.0,
            ..Default::default()
        };
        let enc = Encoder::new(cfg.machine, 1.0);
        let mut buf = ReplayBuffer::new(25);
        for k in 0..4 {
            buf.push_episode(&episode(k, 10));
        }
        assert_eq!(buf.len(), 25);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut b = Batch::default();
        buf.sample(&cfg, &enc, 500, &mut rng, &mut b);
        for i in 0..b.len {
            // Goal-frame x of s is x − x_goal (heading 0, scale 1): a future pose ⇒ ≤ −1 and > −10.
            let rel = b.state[i * 7] as f64;
            assert!(
                rel <= -1.0 + 1e-6 && rel >= -10.0,
                "relabelled goal not in the episode's future: {rel}"
            );
        }
        // Without relabelling the original goal (x = −1) is kept.
        let cfg = TrainConfig {
            her_ratio: 0.0,
            pos_scale: 1.0,
            ..Default::default()
        };
        buf.sample(&cfg, &enc, 100, &mut rng, &mut b);
        for i in 0..b.len {
            assert!(b.state[i * 7] >= 1.0 - 1e-6);
        }
    }

    #[test]
    fn done_is_recomputed_for_the_goal_the_sample_uses() {
        // An episode standing still at x = 5: every relabelled goal is its own
        // resting pose (done); the original goal at x = −1 is not reached.
        let resting: Vec<Transition> = (0..4)
            .map(|_| {
                let x = State::new(5.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                Transition {
                    x,
                    a: [0.0, 0.0],
                    next: x,
                    goal: Goal::new(-1.0, 0.0, 0.0),
                }
            })
            .collect();
        let mut buf = ReplayBuffer::new(10);
        buf.push_episode(&resting);
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut b = Batch::default();
        let not_done = |her_ratio: f64, distance: f64, rng: &mut ChaCha8Rng, b: &mut Batch| {
            let mut cfg = TrainConfig {
                her_ratio,
                ..Default::default()
            };
            cfg.terminal.distance = distance;
            let enc = Encoder::new(cfg.machine, cfg.pos_scale);
            buf.sample(&cfg, &enc, 50, rng, b);
            assert_eq!(b.not_done.len(), 50);
            b.not_done.iter().sum::<f32>()
        };
        assert_eq!(not_done(1.0, 0.08, &mut rng, &mut b), 0.0);
        assert!(b.own_goal.iter().all(|w| *w == 0.0), "all relabelled");
        assert_eq!(not_done(0.0, 0.08, &mut rng, &mut b), 50.0);
        assert!(b.own_goal.iter().all(|w| *w == 1.0), "none relabelled");
        assert_eq!(
            not_done(1.0, 0.0, &mut rng, &mut b),
            50.0,
            "termination off"
        );
    }
}
