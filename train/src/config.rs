//! Training configuration (TOML), validated once with errors naming the key.

use serde::{Deserialize, Serialize};

use control::{CostWeights, MachineParams};

/// Everything a training run needs; every field has a documented default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    pub seed: u64,
    /// Parallel environments stepped per vector step.
    pub n_envs: usize,
    pub batch_size: usize,
    pub buffer_size: usize,
    /// Transitions collected with random actions before the first update.
    pub warmup_transitions: usize,
    /// Gradient updates in the whole run.
    pub total_updates: u64,
    /// Gradient updates per vector step of the environments.
    pub updates_per_step: usize,
    pub gamma: f64,
    /// Polyak rate τ of the target critic: ψ̄ ← (1 − τ) ψ̄ + τ ψ.
    pub tau: f64,
    pub critic_lr: f64,
    pub actor_lr: f64,
    /// Learning rate of log λ_e and log λ_l.
    pub multiplier_lr: f64,
    pub target_entropy: f64,
    /// Gradient-penalty weight ρ (paper eq. 16).
    pub gradient_penalty: f64,
    /// Critic output size m of Q (L = ‖Q‖²).
    pub critic_outputs: usize,
    pub hidden: Vec<usize>,
    pub init_lambda_e: f64,
    pub init_lambda_l: f64,
    pub machine: MachineParams,
    pub cost: CostWeights,
    /// Weight of ‖a/a_max‖² added to the cost (0 = the paper's cost).
    pub action_cost: f64,
    pub dt: f64,
    pub pos_scale: f64,
    pub episode_seconds: f64,
    pub goal: GoalSampling,
    /// Fraction of sampled transitions whose goal is replaced by a pose reached
    /// later in the same episode (hindsight relabelling).
    pub her_ratio: f64,
    /// Ascend λ_l on E[ΔL] over the rows that keep their episode's own goal
    /// only (eq. 4c's expectation is over the states the policy visits on its
    /// way to its goals, S_π); false: over the whole batch, relabelled rows too.
    pub multiplier_own_goals: bool,
    /// Where an episode ends (`[terminal]`); off by default.
    pub terminal: Termination,
    /// Compute each gradient of an update on the two halves of the batch, one
    /// per thread, and average: the same update on both cores.
    pub two_threads: bool,
    /// Which implementation computes the updates (the same mathematics).
    pub kernel: Kernel,
    /// Minutes between checkpoints.
    pub checkpoint_minutes: f64,
    /// Updates between evaluations of the actor on held-out goals.
    pub eval_every: u64,
    pub eval_goals: usize,
    /// Updates between rows of the CSV log.
    pub log_every: u64,
}

/// The implementation of an update's gradients.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// Hand-written f32 kernels over reused buffers (`crate::fused`).
    #[default]
    Fused,
    /// The candle autograd graph (`crate::nets`), the reference.
    Candle,
}

/// The terminal set of the goal (DESIGN §4's `done`): the machine at rest
/// with its pose within `distance` of the goal ([`control::model::goal_distance`]).
/// A transition into it is terminal: the critic's target is c alone and L = 0
/// beyond, so reaching the goal set and stopping there ends all further cost.
/// Without it, standing still beside the goal costs c/(1 − γ), and for the few
/// centimetres sideways an articulated machine can only fix by a manoeuvre that
/// first raises the cost, standing still is the cheaper choice at γ = 0.99
/// (`wlnav-train stalls`). The authors' recipe ends episodes at c < 0.55 for
/// the same reason.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Termination {
    /// Pose-error radius of the set; 0 turns termination off (the time limit
    /// alone ends episodes, as a truncation).
    pub distance: f64,
    /// At rest: |v_f| below this [m/s] ...
    pub speed: f64,
    /// ... and |β̇| below this [rad/s].
    pub beta_rate: f64,
}

impl Default for Termination {
    fn default() -> Self {
        Self {
            distance: 0.0,
            speed: 0.05,
            beta_rate: 0.05,
        }
    }
}

/// How episode goals are drawn (DESIGN §4), with a near-goal share for precision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GoalSampling {
    pub r_min: f64,
    pub r_max: f64,
    /// Share of episodes whose goal lies between `near_r_min` and `r_min`.
    pub near_fraction: f64,
    pub near_r_min: f64,
    /// Share of episodes whose goal lies beside the start pose: sideways by up
    /// to `offset_max` (m), along the heading and turned by up to a quarter of
    /// it (m, rad). A sideways offset of a few centimetres is where an actor
    /// stalls (moving sideways needs a manoeuvre that first raises the cost),
    /// and random goals rarely ask for one.
    pub offset_fraction: f64,
    pub offset_max: f64,
    /// Start β uniform in ±this share of β_max, v_f likewise of v_max.
    pub start_jitter: f64,
    /// Curriculum: over this many updates the far band's upper radius grows
    /// from `r_min` to `r_max` (0 = the full band from the start). Near goals
    /// teach the precise final approach first; the goal-relative encoder
    /// carries it outwards.
    pub curriculum_updates: u64,
}

impl Default for GoalSampling {
    fn default() -> Self {
        Self {
            r_min: 2.5,
            r_max: 10.0,
            near_fraction: 0.2,
            near_r_min: 0.2,
            offset_fraction: 0.0,
            offset_max: 0.5,
            start_jitter: 0.1,
            curriculum_updates: 0,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            n_envs: 64,
            batch_size: 256,
            buffer_size: 1_000_000,
            warmup_transitions: 20_000,
            total_updates: 2_000_000,
            updates_per_step: 1,
            gamma: 0.99,
            tau: 0.01,
            critic_lr: 3e-4,
            actor_lr: 1e-4,
            multiplier_lr: 3e-4,
            target_entropy: -2.0,
            gradient_penalty: 1e-4,
            critic_outputs: 16,
            hidden: control::mlp::PAPER_HIDDEN.to_vec(),
            init_lambda_e: 1.0,
            init_lambda_l: 1.0,
            machine: MachineParams::default(),
            cost: CostWeights::default(),
            action_cost: 0.0,
            dt: 0.2,
            pos_scale: control::encoder::DEFAULT_POS_SCALE,
            episode_seconds: 30.0,
            goal: GoalSampling::default(),
            her_ratio: 0.5,
            multiplier_own_goals: false,
            terminal: Termination::default(),
            two_threads: false,
            kernel: Kernel::default(),
            checkpoint_minutes: 5.0,
            eval_every: 10_000,
            eval_goals: 64,
            log_every: 1_000,
        }
    }
}

/// A configuration value that is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("config key `{key}`: {problem}")]
pub struct ConfigError {
    pub key: String,
    pub problem: String,
}

fn err(key: &str, problem: impl Into<String>) -> ConfigError {
    ConfigError {
        key: key.to_string(),
        problem: problem.into(),
    }
}

impl TrainConfig {
    /// Parses TOML text; unknown keys and bad values are errors naming the key.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        // toml's own message quotes the offending line and key; keep it whole.
        let cfg: Self = toml::from_str(text).map_err(|e| err("<toml>", e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive = |k: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(err(k, format!("must be > 0 (got {v})")))
            }
        };
        let unit = |k: &str, v: f64, lo_open: bool| {
            let ok = v.is_finite() && v <= 1.0 && if lo_open { v > 0.0 } else { v >= 0.0 };
            if ok {
                Ok(())
            } else {
                Err(err(
                    k,
                    format!(
                        "must be in {}0, 1] (got {v})",
                        if lo_open { "(" } else { "[" }
                    ),
                ))
            }
        };
        for (k, v) in [
            ("n_envs", self.n_envs),
            ("batch_size", self.batch_size),
            ("buffer_size", self.buffer_size),
            ("critic_outputs", self.critic_outputs),
            ("eval_goals", self.eval_goals),
            ("updates_per_step", self.updates_per_step),
        ] {
            if v == 0 {
                return Err(err(k, "must be > 0"));
            }
        }
        if self.two_threads && self.batch_size % 2 != 0 {
            return Err(err(
                "batch_size",
                "must be even with two_threads (two equal halves)",
            ));
        }
        if self.batch_size > self.buffer_size {
            return Err(err("batch_size", "must not exceed buffer_size"));
        }
        if self.warmup_transitions < self.batch_size {
            return Err(err(
                "warmup_transitions",
                format!("must be >= batch_size ({})", self.batch_size),
            ));
        }
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(err("hidden", "needs at least one layer, each of width > 0"));
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0 && self.gamma < 1.0) {
            return Err(err(
                "gamma",
                format!("must be in (0, 1) (got {})", self.gamma),
            ));
        }
        unit("tau", self.tau, true)?;
        unit("her_ratio", self.her_ratio, false)?;
        unit("goal.near_fraction", self.goal.near_fraction, false)?;
        unit("goal.start_jitter", self.goal.start_jitter, false)?;
        unit("goal.offset_fraction", self.goal.offset_fraction, false)?;
        if self.goal.near_fraction + self.goal.offset_fraction > 1.0 {
            return Err(err(
                "goal.offset_fraction",
                "goal.near_fraction + goal.offset_fraction must be <= 1",
            ));
        }
        positive("goal.offset_max", self.goal.offset_max)?;
        if !(self.terminal.distance.is_finite() && self.terminal.distance >= 0.0) {
            return Err(err("terminal.distance", "must be >= 0 (0 = off)"));
        }
        positive("terminal.speed", self.terminal.speed)?;
        positive("terminal.beta_rate", self.terminal.beta_rate)?;
        unit("init_lambda_l", self.init_lambda_l, true)?;
        positive("init_lambda_e", self.init_lambda_e)?;
        positive("critic_lr", self.critic_lr)?;
        positive("actor_lr", self.actor_lr)?;
        positive("multiplier_lr", self.multiplier_lr)?;
        positive("dt", self.dt)?;
        positive("pos_scale", self.pos_scale)?;
        positive("episode_seconds", self.episode_seconds)?;
        positive("checkpoint_minutes", self.checkpoint_minutes)?;
        positive("goal.r_min", self.goal.r_min)?;
        positive("goal.near_r_min", self.goal.near_r_min)?;
        if !(self.goal.r_max >= self.goal.r_min) {
            return Err(err("goal.r_max", "must be >= goal.r_min"));
        }
        if !(self.goal.near_r_min <= self.goal.r_min) {
            return Err(err("goal.near_r_min", "must be <= goal.r_min"));
        }
        if !(self.gradient_penalty.is_finite() && self.gradient_penalty >= 0.0) {
            return Err(err("gradient_penalty", "must be >= 0"));
        }
        if !(self.action_cost.is_finite() && self.action_cost >= 0.0) {
            return Err(err("action_cost", "must be >= 0"));
        }
        if !self.target_entropy.is_finite() {
            return Err(err("target_entropy", "must be finite"));
        }
        for (k, v) in [
            ("eval_every", self.eval_every),
            ("log_every", self.log_every),
            ("total_updates", self.total_updates),
        ] {
            if v == 0 {
                return Err(err(k, "must be > 0"));
            }
        }
        self.machine
            .validate()
            .map_err(|e| err("machine", e.to_string()))?;
        self.cost
            .validate()
            .map_err(|e| err("cost", e.to_string()))?;
        Ok(())
    }

    /// Steps per episode.
    pub fn episode_steps(&self) -> usize {
        (self.episode_seconds / self.dt).round().max(1.0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_values_name_the_key() {
        TrainConfig::default().validate().unwrap();
        let cases = [
            ("gamma = 1.5", "gamma"),
            ("tau = 0.0", "tau"),
            ("batch_size = 0", "batch_size"),
            ("critic_lr = -1.0", "critic_lr"),
            ("hidden = []", "hidden"),
            ("[goal]\nr_min = 5.0\nr_max = 2.0", "goal.r_max"),
            ("[machine]\nv_max = -1.0", "machine"),
            ("[cost]\np = 0.0", "cost"),
            ("her_ratio = 2.0", "her_ratio"),
            (
                "[goal]\nnear_fraction = 0.5\noffset_fraction = 0.6",
                "goal.offset_fraction",
            ),
            ("[goal]\noffset_max = 0.0", "goal.offset_max"),
            ("two_threads = true\nbatch_size = 255", "batch_size"),
            ("[terminal]\ndistance = -0.1", "terminal.distance"),
            ("[terminal]\nspeed = 0.0", "terminal.speed"),
            ("[terminal]\nbeta_rate = nan", "terminal.beta_rate"),
        ];
        for (text, key) in cases {
            let e = TrainConfig::from_toml(text).unwrap_err();
            assert!(e.to_string().contains(&format!("`{key}`")), "{text}: {e}");
        }
        let e = TrainConfig::from_toml("gama = 0.9").unwrap_err();
        assert!(e.to_string().contains("gama"), "{e}");
        let e = TrainConfig::from_toml("n_envs = \"many\"").unwrap_err();
        assert!(e.to_string().contains("n_envs"), "{e}");
        let e = TrainConfig::from_toml("[cost]\nform = \"l2\"").unwrap_err();
        assert!(e.to_string().contains("form"), "{e}");
        let c = TrainConfig::from_toml("[cost]\nform = \"power-of-sum\"").unwrap();
        assert_eq!(c.cost.form, control::CostForm::PowerOfSum);
    }

    #[test]
    fn shipped_configs_are_valid() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap();
            TrainConfig::from_toml(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            n += 1;
        }
        assert!(n >= 2, "configs in {}", dir.display());
    }
}
