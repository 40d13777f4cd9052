//! The training loop: collect, update, log, evaluate, checkpoint, export.

use std::collections::HashMap;
use std::fs;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use candle_core::{Device, Tensor};
use indicatif::{ProgressBar, ProgressStyle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use safetensors::tensor::{Dtype, TensorView};

use control::encoder::ACTOR_INPUTS;
use control::weights::{self, FileDtype, NetworkRole, NetworkWeights};
use control::Actor;

use crate::agent::{Agent, UpdateStats};
use crate::buffer::{Batch, ReplayBuffer};
use crate::config::TrainConfig;
use crate::env::VecEnv;
use crate::evaluate::success_rate;

pub const CHECKPOINT: &str = "checkpoint.safetensors";
/// Where every checkpoint's networks are kept (`candidates/u000123456/`), for
/// the closed-loop selection after training: later checkpoints are not always
/// the better controllers.
pub const CANDIDATES: &str = "candidates";
pub const CONFIG: &str = "config.toml";
/// One line per `wlnav-train train` on the run directory: the git commit of the
/// working tree and the command (a run resumed by a newer binary says so).
pub const INVOCATIONS: &str = "invocations.log";
const LOG_HEADER: &str =
    "updates,env_steps,wall_s,updates_per_s,critic_loss,penalty,actor_loss,lambda_l,lambda_e,entropy,delta_l,mean_l";
const EVAL_HEADER: &str = "updates,env_steps,wall_s,success_0.1,success_0.3,mean_final_distance";

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub out_dir: PathBuf,
    pub resume: bool,
    /// Stop after this many updates in this invocation (smoke runs, time-boxed sessions).
    pub max_updates: Option<u64>,
    /// Stop when the run's total wall time (across resumes) reaches this [s].
    pub max_wall_s: Option<f64>,
    /// Git commit written into exported metadata.
    pub git_commit: String,
    pub quiet: bool,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct RunSummary {
    pub updates: u64,
    pub env_steps: u64,
    pub first_critic_loss: f64,
    pub last_critic_loss: f64,
    pub lambda_l: f64,
    pub wall_s: f64,
}

/// Checkpoint metadata key of the run's training wall time so far [s].
const WALL_KEY: &str = "wall_s";

/// Saves networks, Adam moments, multipliers, counters and the run's wall time
/// so far (`wall_s`, so that a resumed run reports its total), atomically.
pub fn save_checkpoint(agent: &Agent, dir: &Path, wall_s: f64) -> Result<()> {
    let (tensors, mut meta) = agent.checkpoint_tensors();
    meta.insert(WALL_KEY.into(), format!("{wall_s:.1}"));
    let data: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(n, t)| {
            let v = t.flatten_all()?.to_vec1::<f32>()?;
            Ok((
                n.clone(),
                t.dims().to_vec(),
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ))
        })
        .collect::<Result<_>>()?;
    let views: Vec<(String, TensorView<'_>)> = data
        .iter()
        .map(|(n, s, b)| Ok((n.clone(), TensorView::new(Dtype::F32, s.clone(), b)?)))
        .collect::<Result<_>>()?;
    let bytes = safetensors::serialize(views, &Some(meta))?;
    let tmp = dir.join(format!("{CHECKPOINT}.tmp"));
    fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    fs::rename(&tmp, dir.join(CHECKPOINT)).context("replacing the checkpoint")?;
    Ok(())
}

/// Loads a checkpoint written by [`save_checkpoint`] into `agent`; returns the
/// run's wall time at the checkpoint (`None` for checkpoints written before it
/// was recorded).
pub fn load_checkpoint(agent: &mut Agent, dir: &Path) -> Result<Option<f64>> {
    let path = dir.join(CHECKPOINT);
    let bytes = fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes)
        .with_context(|| format!("{} is not a checkpoint", path.display()))?;
    let meta: HashMap<String, String> = header.metadata().clone().unwrap_or_default();
    let st = safetensors::SafeTensors::deserialize(&bytes)?;
    let mut tensors = HashMap::new();
    for (name, view) in st.tensors() {
        anyhow::ensure!(
            view.dtype() == Dtype::F32,
            "{}: tensor `{name}` is not f32",
            path.display()
        );
        let v: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        tensors.insert(name, Tensor::from_vec(v, view.shape(), &Device::Cpu)?);
    }
    agent
        .restore(&tensors, &meta)
        .with_context(|| format!("restoring {}", path.display()))?;
    meta.get(WALL_KEY)
        .map(|v| {
            v.parse::<f64>()
                .ok()
                .filter(|w| w.is_finite() && *w >= 0.0)
                .with_context(|| {
                    format!(
                        "{}: `{WALL_KEY}` = {v:?} is not a wall time",
                        path.display()
                    )
                })
        })
        .transpose()
}

/// The deployed networks of the agent, as `control` loads them.
pub fn exported(agent: &Agent, git_commit: &str) -> Result<(NetworkWeights, NetworkWeights)> {
    let critic = NetworkWeights {
        source: "training".into(),
        meta: agent.metadata(NetworkRole::Critic, git_commit),
        mlp: Agent::to_control_mlp(&agent.critic)?,
    };
    let actor = NetworkWeights {
        source: "training".into(),
        meta: agent.metadata(NetworkRole::Actor, git_commit),
        mlp: Agent::to_control_mlp(&agent.actor)?,
    };
    Ok((critic, actor))
}

/// The directory of the candidate exported at `updates`.
pub fn candidate_dir(run_dir: &Path, updates: u64) -> PathBuf {
    run_dir.join(CANDIDATES).join(format!("u{updates:09}"))
}

/// Exports the networks into the run directory and keeps them as a candidate.
fn export_checkpoint(agent: &Agent, dir: &Path, git_commit: &str) -> Result<()> {
    export(agent, dir, git_commit)?;
    export(agent, &candidate_dir(dir, agent.updates), git_commit)
}

/// Writes `critic.safetensors` and `actor.safetensors` into `dir`.
pub fn export(agent: &Agent, dir: &Path, git_commit: &str) -> Result<()> {
    fs::create_dir_all(dir)?;
    let (critic, actor) = exported(agent, git_commit)?;
    for (name, w) in [("critic.safetensors", critic), ("actor.safetensors", actor)] {
        let bytes = weights::encode(&w.meta, &w.mlp, FileDtype::F32)?;
        let path = dir.join(name);
        fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn append_line(path: &Path, header: &str, line: &str) -> Result<()> {
    let new = !path.exists();
    let mut f = fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    if new {
        writeln!(f, "{header}")?;
    }
    writeln!(f, "{line}")?;
    Ok(())
}

#[derive(Default)]
struct Mean {
    n: f64,
    sum: [f64; 8],
}

impl Mean {
    fn add(&mut self, s: &UpdateStats) {
        let v = [
            s.critic_loss,
            s.penalty,
            s.actor_loss,
            s.lambda_l,
            s.lambda_e,
            s.entropy,
            s.delta_l,
            s.mean_l,
        ];
        for (a, b) in self.sum.iter_mut().zip(v) {
            *a += b;
        }
        self.n += 1.0;
    }
    fn take(&mut self) -> [f64; 8] {
        let out = self.sum.map(|s| s / self.n.max(1.0));
        *self = Mean::default();
        out
    }
}

/// Removes the rows of a run's CSV log whose update count (first column) is past
/// `updates`; a missing file is left missing.
fn drop_rows_after(path: &Path, updates: u64) -> Result<()> {
    let Ok(text) = fs::read_to_string(path) else {
        return Ok(());
    };
    let mut lines = text.lines();
    let mut kept: Vec<&str> = lines.next().into_iter().collect();
    kept.extend(lines.filter(|l| {
        l.split(',')
            .next()
            .and_then(|u| u.parse::<u64>().ok())
            .is_some_and(|u| u <= updates)
    }));
    if kept.len() < text.lines().count() {
        let tmp = path.with_extension("csv.tmp");
        fs::write(&tmp, kept.join("\n") + "\n")
            .with_context(|| format!("writing {}", tmp.display()))?;
        fs::rename(&tmp, path).with_context(|| format!("replacing {}", path.display()))?;
    }
    Ok(())
}

/// Trains (or resumes) a run in `opts.out_dir`.
pub fn train(cfg: &TrainConfig, opts: &RunOptions) -> Result<RunSummary> {
    cfg.validate()?;
    let dir = &opts.out_dir;
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut agent = Agent::new(cfg)?;
    let wall_before = if opts.resume {
        let wall = load_checkpoint(&mut agent, dir)?.unwrap_or_else(|| {
            eprintln!(
                "the checkpoint predates wall-time recording: wall time counts from this resume"
            );
            0.0
        });
        // Rows logged after the checkpoint belong to work the resume redoes.
        for log in ["log.csv", "eval.csv"] {
            drop_rows_after(&dir.join(log), agent.updates)?;
        }
        wall
    } else {
        anyhow::ensure!(
            !dir.join(CHECKPOINT).exists(),
            "{} already holds a run; pass --resume to continue it or choose another --out",
            dir.display()
        );
        fs::write(dir.join(CONFIG), toml::to_string(cfg)?)?;
        0.0
    };
    let start_updates = agent.updates;
    let stop_at = opts.max_updates.map_or(cfg.total_updates, |m| {
        (start_updates + m).min(cfg.total_updates)
    });
    let encoder = control::Encoder::new(cfg.machine, cfg.pos_scale);
    let mut rng =
        ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(agent.updates).wrapping_add(0x5EED));
    let mut env = VecEnv::new(cfg, &mut rng);
    let mut buffer = ReplayBuffer::new(cfg.buffer_size);
    let mut features = vec![0f32; cfg.n_envs * ACTOR_INPUTS];
    let mut f = [0.0; ACTOR_INPUTS];
    let mut batch = Batch::default();

    let bar = if opts.quiet || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(cfg.total_updates)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {per_sec} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(agent.updates);
    let say = |msg: String| {
        if bar.is_hidden() {
            if !opts.quiet {
                eprintln!("{msg}");
            }
        } else {
            bar.println(msg);
        }
    };

    // Wall time of the whole run, across resumes.
    let t0 = Instant::now();
    let wall = || wall_before + t0.elapsed().as_secs_f64();
    let mut last_ckpt = Instant::now();
    let mut last_log = (Instant::now(), agent.updates);
    let mut mean = Mean::default();
    let (mut first_loss, mut last_loss) = (f64::NAN, f64::NAN);
    let fresh = !opts.resume;
    'training: while agent.updates < stop_at {
        env.progress = match cfg.goal.curriculum_updates {
            0 => 1.0,
            n => agent.updates as f64 / n as f64,
        };
        // Collect one vector step: uniform random actions while a fresh run warms up.
        for (i, (x, g)) in env.states.iter().zip(&env.goals).enumerate() {
            encoder.encode_state(x, g, &mut f);
            for (dst, src) in features[i * ACTOR_INPUTS..(i + 1) * ACTOR_INPUTS]
                .iter_mut()
                .zip(f)
            {
                *dst = src as f32;
            }
        }
        let actions = if fresh && buffer.len() < cfg.warmup_transitions {
            (0..cfg.n_envs)
                .map(|_| [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)])
                .collect()
        } else {
            agent.act(&features, cfg.n_envs)?
        };
        env.step(cfg, &actions, &mut rng, |ep| buffer.push_episode(ep));
        agent.env_steps += cfg.n_envs as u64;
        if buffer.len() < cfg.warmup_transitions.min(cfg.buffer_size) {
            continue;
        }
        for _ in 0..cfg.updates_per_step {
            buffer.sample(cfg, &encoder, cfg.batch_size, &mut rng, &mut batch);
            let stats = agent.update(&batch)?;
            anyhow::ensure!(
                stats.critic_loss.is_finite(),
                "critic loss is not finite at update {}",
                agent.updates
            );
            if first_loss.is_nan() {
                first_loss = stats.critic_loss;
            }
            last_loss = stats.critic_loss;
            mean.add(&stats);
            bar.set_position(agent.updates);
            if agent.updates % cfg.log_every == 0 {
                let m = mean.take();
                let rate = (agent.updates - last_log.1) as f64
                    / last_log.0.elapsed().as_secs_f64().max(1e-9);
                last_log = (Instant::now(), agent.updates);
                append_line(
                    &dir.join("log.csv"),
                    LOG_HEADER,
                    &format!(
                        "{},{},{:.1},{:.1},{:.6e},{:.6e},{:.6e},{:.6},{:.6e},{:.4},{:.6e},{:.6e}",
                        agent.updates,
                        agent.env_steps,
                        wall(),
                        rate,
                        m[0],
                        m[1],
                        m[2],
                        m[3],
                        m[4],
                        m[5],
                        m[6],
                        m[7]
                    ),
                )?;
                bar.set_message(format!(
                    "λl {:.3} λe {:.3} Lc {:.3e} {:.0} upd/s",
                    m[3], m[4], m[0], rate
                ));
            }
            if agent.updates % cfg.eval_every == 0 {
                let (_, actor) = exported(&agent, &opts.git_commit)?;
                let actor = Actor::from_weights(actor)?;
                let (s1, d) = success_rate(&actor, cfg, 0.1);
                let (s3, _) = success_rate(&actor, cfg, 0.3);
                append_line(
                    &dir.join("eval.csv"),
                    EVAL_HEADER,
                    &format!(
                        "{},{},{:.1},{:.4},{:.4},{:.4}",
                        agent.updates,
                        agent.env_steps,
                        wall(),
                        s1,
                        s3,
                        d
                    ),
                )?;
                say(format!(
                    "update {}: actor success {:.0}% (0.1) {:.0}% (0.3), mean final distance {:.3}, λ_l {:.3}",
                    agent.updates,
                    s1 * 100.0,
                    s3 * 100.0,
                    d,
                    agent.lambda_l()
                ));
            }
            if last_ckpt.elapsed().as_secs_f64() > cfg.checkpoint_minutes * 60.0 {
                save_checkpoint(&agent, dir, wall())?;
                export_checkpoint(&agent, dir, &opts.git_commit)?;
                if let Err(e) = crate::plot::learning_curves(dir) {
                    say(format!("learning curves not drawn: {e:#}"));
                }
                last_ckpt = Instant::now();
                say(format!("checkpoint at update {}", agent.updates));
            }
            if agent.updates >= stop_at || opts.max_wall_s.is_some_and(|m| wall() >= m) {
                break 'training;
            }
        }
    }
    save_checkpoint(&agent, dir, wall())?;
    export_checkpoint(&agent, dir, &opts.git_commit)?;
    if dir.join("log.csv").exists() {
        if let Err(e) = crate::plot::learning_curves(dir) {
            say(format!("learning curves not drawn: {e:#}"));
        }
    }
    bar.finish_and_clear();
    Ok(RunSummary {
        updates: agent.updates,
        env_steps: agent.env_steps,
        first_critic_loss: first_loss,
        last_critic_loss: last_loss,
        lambda_l: agent.lambda_l(),
        wall_s: wall(),
    })
}
