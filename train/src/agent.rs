//! ALAC (paper §IV-D, eq. 13–16; DESIGN §4): critic, Polyak target, tanh-Gaussian
//! actor, entropy and Lyapunov multipliers, and their Adam states.

use std::collections::HashMap;

use candle_core::{backprop::GradStore, DType, Device, Result, Tensor, Var};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use control::encoder::{ACTOR_INPUTS, CRITIC_INPUTS};
use control::mlp::{Layer, Mlp as ControlMlp};
use control::weights::{NetworkMetadata, NetworkRole, ACTOR_OUTPUTS};

use crate::buffer::Batch;
use crate::config::{Kernel, TrainConfig};
use crate::fused::{self, NetGradient};
use crate::nets::{
    actor_mean_action, actor_sample, critic_value, f32_tensor, gradient_penalty, Mlp,
};
use crate::params::{self, ReadParams};

/// Adam on a set of variables, with its moments kept as tensors so they can be
/// checkpointed (candle's own optimiser hides them).
pub struct Adam {
    pub vars: Vec<Var>,
    pub m: Vec<Var>,
    pub v: Vec<Var>,
    pub t: u64,
    pub lr: f64,
}

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const ADAM_EPS: f64 = 1e-8;
/// (β₁, β₂, ε) of every Adam here.
const ADAM: (f64, f64, f64) = (BETA1, BETA2, ADAM_EPS);

impl Adam {
    pub fn new(vars: Vec<Var>, lr: f64) -> Result<Self> {
        let zeros = |v: &Var| Var::zeros(v.shape(), DType::F32, v.device());
        let m = vars.iter().map(zeros).collect::<Result<_>>()?;
        let v = vars.iter().map(zeros).collect::<Result<_>>()?;
        Ok(Self {
            vars,
            m,
            v,
            t: 0,
            lr,
        })
    }

    /// Counts a step; returns its learning rate and bias corrections (lr, c₁, c₂).
    pub fn advance(&mut self) -> (f64, f64, f64) {
        self.t += 1;
        let c1 = 1.0 - BETA1.powi(self.t as i32);
        let c2 = 1.0 - BETA2.powi(self.t as i32);
        (self.lr, c1, c2)
    }

    /// The same step with a flat gradient, in place (the fused kernels).
    pub fn step_flat(&mut self, grad: &NetGradient) -> Result<()> {
        let schedule = self.advance();
        params::adam_step(&self.vars, (&self.m, &self.v), grad, schedule, ADAM)
    }

    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        let (_, c1, c2) = self.advance();
        for ((var, m), v) in self.vars.iter().zip(&self.m).zip(&self.v) {
            let Some(g) = grads.get(var.as_tensor()) else {
                continue;
            };
            let m_new = ((m.as_tensor() * BETA1)? + (g * (1.0 - BETA1))?)?;
            let v_new = ((v.as_tensor() * BETA2)? + (g.sqr()? * (1.0 - BETA2))?)?;
            let denom = ((&v_new / c2)?.sqrt()? + ADAM_EPS)?;
            let update = ((&m_new / c1)?.div(&denom)? * self.lr)?;
            var.set(&(var.as_tensor() - update)?)?;
            m.set(&m_new)?;
            v.set(&v_new)?;
        }
        Ok(())
    }
}

/// Adam for one scalar (the log-multipliers), by gradient ascent.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ScalarAdam {
    pub m: f64,
    pub v: f64,
    pub t: u64,
}

impl ScalarAdam {
    fn ascend(&mut self, value: &mut f64, grad: f64, lr: f64) {
        self.t += 1;
        self.m = BETA1 * self.m + (1.0 - BETA1) * grad;
        self.v = BETA2 * self.v + (1.0 - BETA2) * grad * grad;
        let mh = self.m / (1.0 - BETA1.powi(self.t as i32));
        let vh = self.v / (1.0 - BETA2.powi(self.t as i32));
        *value += lr * mh / (vh.sqrt() + ADAM_EPS);
    }
}

/// Figures from one update, for logs.
#[derive(Debug, Clone, Copy, Default)]
pub struct UpdateStats {
    pub critic_loss: f64,
    pub penalty: f64,
    pub actor_loss: f64,
    pub lambda_l: f64,
    pub lambda_e: f64,
    pub entropy: f64,
    pub delta_l: f64,
    pub mean_l: f64,
}

pub struct Agent {
    pub cfg: TrainConfig,
    pub device: Device,
    pub critic: Mlp,
    pub critic_target: Mlp,
    pub actor: Mlp,
    pub critic_opt: Adam,
    pub actor_opt: Adam,
    pub log_lambda_e: f64,
    pub log_lambda_l: f64,
    pub lambda_e_opt: ScalarAdam,
    pub lambda_l_opt: ScalarAdam,
    pub updates: u64,
    pub env_steps: u64,
    pub rng: ChaCha8Rng,
    /// Buffers of the fused kernels, kept from update to update.
    fused: FusedBuffers,
}

/// Per thread a workspace and a gradient, and the per-row results of a step.
#[derive(Default)]
struct FusedBuffers {
    shares: [(fused::Workspace, NetGradient); 2],
    l_sa: Vec<f32>,
    entropy_term: Vec<f32>,
    delta_l: Vec<f32>,
}

/// What the critic and the actor steps of an update leave for the rest of it.
struct StepParts {
    critic_loss: f64,
    penalty: f64,
    actor_loss: f64,
    /// mean(log π(s) + H).
    mean_entropy_term: f64,
    /// ΔL per row.
    delta_l: Vec<f32>,
    /// mean L(s, a).
    mean_l: f64,
}

/// Smallest log λ_l: λ_l lives in (0, 1].
const LOG_LAMBDA_MIN: f64 = -9.2;

impl Agent {
    pub fn new(cfg: &TrainConfig) -> Result<Self> {
        let device = Device::Cpu;
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let sizes = |input: usize, output: usize| {
            let mut s = vec![input];
            s.extend(&cfg.hidden);
            s.push(output);
            s
        };
        let critic = Mlp::new(&sizes(CRITIC_INPUTS, cfg.critic_outputs), &mut rng, &device)?;
        let critic_target = Mlp::new(&sizes(CRITIC_INPUTS, cfg.critic_outputs), &mut rng, &device)?;
        critic_target.copy_from(&critic)?;
        let actor = Mlp::new(&sizes(ACTOR_INPUTS, ACTOR_OUTPUTS), &mut rng, &device)?;
        Ok(Self {
            critic_opt: Adam::new(critic.vars(), cfg.critic_lr)?,
            actor_opt: Adam::new(actor.vars(), cfg.actor_lr)?,
            cfg: cfg.clone(),
            device,
            critic,
            critic_target,
            actor,
            log_lambda_e: cfg.init_lambda_e.ln(),
            log_lambda_l: cfg.init_lambda_l.ln(),
            lambda_e_opt: ScalarAdam::default(),
            lambda_l_opt: ScalarAdam::default(),
            updates: 0,
            env_steps: 0,
            rng,
            fused: FusedBuffers::default(),
        })
    }

    pub fn lambda_e(&self) -> f64 {
        self.log_lambda_e.exp()
    }

    pub fn lambda_l(&self) -> f64 {
        self.log_lambda_l.exp()
    }

    /// Standard normal draws, rows × 2.
    fn normal_values(&mut self, rows: usize) -> Vec<f32> {
        (0..rows * 2)
            .map(|_| StandardNormal.sample(&mut self.rng))
            .collect()
    }

    fn normal(&mut self, rows: usize) -> Result<Tensor> {
        let v = self.normal_values(rows);
        f32_tensor(&v, rows, 2, &self.device)
    }

    /// Sampled (exploring) actions for a set of states' actor features.
    pub fn act(&mut self, features: &[f32], rows: usize) -> Result<Vec<[f64; 2]>> {
        let eps = self.normal(rows)?;
        let s = f32_tensor(features, rows, ACTOR_INPUTS, &self.device)?;
        let a = actor_sample(&self.actor, &s, &eps)?
            .action
            .to_vec2::<f32>()?;
        Ok(a.into_iter().map(|r| [r[0] as f64, r[1] as f64]).collect())
    }

    /// Deterministic actions tanh(μ).
    pub fn act_mean(&self, features: &[f32], rows: usize) -> Result<Vec<[f64; 2]>> {
        let s = f32_tensor(features, rows, ACTOR_INPUTS, &self.device)?;
        let a = actor_mean_action(&self.actor, &s)?.to_vec2::<f32>()?;
        Ok(a.into_iter().map(|r| [r[0] as f64, r[1] as f64]).collect())
    }

    fn batch_tensors(&self, batch: &Batch) -> Result<BatchTensors> {
        let n = batch.len;
        let both: Vec<f32> = batch
            .state
            .iter()
            .chain(&batch.next_state)
            .copied()
            .collect();
        let both = f32_tensor(&both, 2 * n, ACTOR_INPUTS, &self.device)?;
        Ok(BatchTensors {
            s: both.narrow(0, 0, n)?,
            s2: both.narrow(0, n, n)?,
            both,
            a: f32_tensor(&batch.action, n, 2, &self.device)?,
            c: Tensor::from_slice(&batch.cost, n, &self.device)?,
            not_done: Tensor::from_slice(&batch.not_done, n, &self.device)?,
        })
    }

    /// One ALAC update: critic, actor, multipliers, Polyak target, by the
    /// configured kernel.
    pub fn update(&mut self, batch: &Batch) -> Result<UpdateStats> {
        let parts = match self.cfg.kernel {
            Kernel::Fused => self.fused_steps(batch)?,
            Kernel::Candle => self.candle_steps(batch)?,
        };
        // Multipliers by gradient ascent on J(λ) in log space.
        let mean_delta = multiplier_delta(
            &parts.delta_l,
            &batch.own_goal,
            self.cfg.multiplier_own_goals,
        );
        let lr = self.cfg.multiplier_lr;
        self.lambda_e_opt
            .ascend(&mut self.log_lambda_e, parts.mean_entropy_term, lr);
        self.lambda_l_opt
            .ascend(&mut self.log_lambda_l, mean_delta, lr);
        self.log_lambda_l = self.log_lambda_l.clamp(LOG_LAMBDA_MIN, 0.0);
        self.log_lambda_e = self.log_lambda_e.clamp(-20.0, 5.0);
        match self.cfg.kernel {
            Kernel::Fused => params::polyak(&self.critic_target, &self.critic, self.cfg.tau)?,
            Kernel::Candle => self.critic_target.polyak_from(&self.critic, self.cfg.tau)?,
        }
        self.updates += 1;
        Ok(UpdateStats {
            critic_loss: parts.critic_loss,
            penalty: parts.penalty,
            actor_loss: parts.actor_loss,
            lambda_l: self.lambda_l(),
            lambda_e: self.lambda_e(),
            entropy: -(parts.mean_entropy_term - self.cfg.target_entropy),
            delta_l: mean_delta,
            mean_l: parts.mean_l,
        })
    }

    /// The critic and actor steps in the fused kernels ([`crate::fused`]): the
    /// same objectives, random draws and order as [`Agent::candle_steps`].
    fn fused_steps(&mut self, batch: &Batch) -> Result<StepParts> {
        let n = batch.len;
        let eps_critic = self.normal_values(n);
        let eps_actor = self.normal_values(2 * n);
        let cfg = &self.cfg;
        let set = fused::Settings::new(cfg, n);
        let rows = fused::Rows::from(batch);
        // With two threads the second takes rows split..n.
        let split = if cfg.two_threads { n / 2 } else { n };
        let multipliers = (self.lambda_e() as f32, self.lambda_l() as f32);
        let buf = &mut self.fused;
        buf.l_sa.resize(n, 0.0);
        buf.entropy_term.resize(n, 0.0);
        buf.delta_l.resize(n, 0.0);

        let critic = {
            let read = ReadParams::new(&[&self.critic, &self.critic_target, &self.actor])?;
            let (c, t, a) = (read.layers(0)?, read.layers(1)?, read.layers(2)?);
            let nets = fused::Nets {
                critic: &c,
                target: &t,
                actor: &a,
            };
            let share = |range: std::ops::Range<usize>,
                         ws: &mut fused::Workspace,
                         grad: &mut NetGradient,
                         l_sa: &mut [f32]| {
                grad.reset(nets.critic);
                let eps = &eps_critic[2 * range.start..2 * range.end];
                fused::critic_gradient(ws, nets, rows.range(range), eps, set, l_sa, grad)
            };
            let [(ws0, g0), (ws1, g1)] = &mut buf.shares;
            let (l0, l1) = buf.l_sa.split_at_mut(split);
            let [a, b] = on_shares(
                split < n,
                || share(0..split, ws0, g0, l0),
                || share(split..n, ws1, g1, l1),
            )?;
            if split < n {
                g0.add(g1);
            }
            fused::CriticShare {
                loss: a.loss + b.loss,
                penalty: a.penalty + b.penalty,
            }
        };
        self.critic_opt.step_flat(&buf.shares[0].1)?;

        let actor_loss = {
            let read = ReadParams::new(&[&self.critic, &self.actor])?;
            let (c, a) = (read.layers(0)?, read.layers(1)?);
            // The actor step reads no target critic.
            let nets = fused::Nets {
                critic: &c,
                target: &c,
                actor: &a,
            };
            let l_sa = &buf.l_sa;
            let share = |range: std::ops::Range<usize>,
                         ws: &mut fused::Workspace,
                         grad: &mut NetGradient,
                         outs: (&mut [f32], &mut [f32])| {
                grad.reset(nets.actor);
                // The actor noise of row i of s sits at i, of s′ at n + i.
                let eps = (
                    &eps_actor[2 * range.start..2 * range.end],
                    &eps_actor[2 * (n + range.start)..2 * (n + range.end)],
                );
                let l_sa = &l_sa[range.clone()];
                fused::actor_gradient(
                    ws,
                    nets,
                    rows.range(range),
                    eps,
                    l_sa,
                    set,
                    multipliers,
                    outs,
                    grad,
                )
            };
            let [(ws0, g0), (ws1, g1)] = &mut buf.shares;
            let (e0, e1) = buf.entropy_term.split_at_mut(split);
            let (d0, d1) = buf.delta_l.split_at_mut(split);
            let [a, b] = on_shares(
                split < n,
                || share(0..split, ws0, g0, (e0, d0)),
                || share(split..n, ws1, g1, (e1, d1)),
            )?;
            if split < n {
                g0.add(g1);
            }
            a.loss + b.loss
        };
        self.actor_opt.step_flat(&buf.shares[0].1)?;
        let mean = |v: &[f32]| v.iter().map(|x| f64::from(*x)).sum::<f64>() / n as f64;
        Ok(StepParts {
            critic_loss: critic.loss,
            penalty: critic.penalty,
            actor_loss,
            mean_entropy_term: mean(&buf.entropy_term),
            delta_l: buf.delta_l.clone(),
            mean_l: mean(&buf.l_sa),
        })
    }

    /// The critic and actor steps in the candle graph (the reference). With
    /// `two_threads` each step's gradient is computed on the two halves of the
    /// batch at once and averaged: the same update (the losses are batch means),
    /// on both cores.
    fn candle_steps(&mut self, batch: &Batch) -> Result<StepParts> {
        let n = batch.len;
        let t = self.batch_tensors(batch)?;
        let (eps_critic, eps_actor) = (self.normal(n)?, self.normal(2 * n)?);
        // Next actions a′ ∼ π(s′) of the critic target, drawn before the actor moves.
        let a2 = actor_sample(&self.actor, &t.s2, &eps_critic)?
            .action
            .detach();
        let multipliers = (self.lambda_e(), self.lambda_l());
        let cfg = &self.cfg;
        let ((critic_loss, penalty, l_sa), actor) = if cfg.two_threads {
            let ranges = [(0, n / 2), (n / 2, n - n / 2)];
            let halves = [
                t.rows(ranges[0].0, ranges[0].1)?,
                t.rows(ranges[1].0, ranges[1].1)?,
            ];
            let (critic, target) = (&self.critic, &self.critic_target);
            let [((loss0, gp0, l0), grads0), ((loss1, gp1, l1), grads1)] = on_two_threads(|i| {
                let a2 = a2.narrow(0, ranges[i].0, ranges[i].1)?;
                let out = critic_objective(critic, target, cfg, &halves[i], &a2)?;
                let grads = out.0.backward()?;
                Ok((out, grads))
            })?;
            self.critic_opt
                .step(&mean_grads(&self.critic_opt.vars, grads0, &grads1)?)?;
            let critic_out = (
                ((loss0 + loss1)? * 0.5)?,
                0.5 * (gp0 + gp1),
                Tensor::cat(&[&l0, &l1], 0)?,
            );
            let (actor, critic) = (&self.actor, &self.critic);
            let l_sa = &critic_out.2;
            let [a0, a1] = on_two_threads(|i| {
                let (start, len) = ranges[i];
                // The actor noise of a row of s and of s′ sits at i and n + i.
                let eps = Tensor::cat(
                    &[
                        &eps_actor.narrow(0, start, len)?,
                        &eps_actor.narrow(0, n + start, len)?,
                    ],
                    0,
                )?;
                let out = actor_objective(
                    actor,
                    critic,
                    cfg,
                    &halves[i],
                    &eps,
                    &l_sa.narrow(0, start, len)?,
                    multipliers,
                )?;
                let grads = out.loss.backward()?;
                Ok((out, grads))
            })?;
            self.actor_opt
                .step(&mean_grads(&self.actor_opt.vars, a0.1, &a1.1)?)?;
            let actor_out = ActorObjective {
                loss: ((&a0.0.loss + &a1.0.loss)? * 0.5)?,
                entropy_term: Tensor::cat(&[&a0.0.entropy_term, &a1.0.entropy_term], 0)?,
                delta_l: Tensor::cat(&[&a0.0.delta_l, &a1.0.delta_l], 0)?,
            };
            (critic_out, actor_out)
        } else {
            let out = critic_objective(&self.critic, &self.critic_target, cfg, &t, &a2)?;
            self.critic_opt.step(&out.0.backward()?)?;
            // L(s, a) is the value from the critic step (it does not depend on the actor).
            let actor = actor_objective(
                &self.actor,
                &self.critic,
                cfg,
                &t,
                &eps_actor,
                &out.2,
                multipliers,
            )?;
            self.actor_opt.step(&actor.loss.backward()?)?;
            (out, actor)
        };

        Ok(StepParts {
            critic_loss: critic_loss.to_scalar::<f32>()? as f64,
            penalty,
            actor_loss: actor.loss.to_scalar::<f32>()? as f64,
            mean_entropy_term: actor.entropy_term.mean_all()?.to_scalar::<f32>()? as f64,
            delta_l: actor.delta_l.to_vec1::<f32>()?,
            mean_l: l_sa.mean_all()?.to_scalar::<f32>()? as f64,
        })
    }

    /// Converts a candle network to the deployed f64 form.
    pub fn to_control_mlp(net: &Mlp) -> Result<ControlMlp> {
        let layers = net
            .layers
            .iter()
            .map(|(w, b)| {
                let (n_out, n_in) = w.as_tensor().dims2()?;
                let weight = w
                    .as_tensor()
                    .flatten_all()?
                    .to_dtype(DType::F64)?
                    .to_vec1::<f64>()?;
                let bias = b.as_tensor().to_dtype(DType::F64)?.to_vec1::<f64>()?;
                Ok(Layer {
                    n_in,
                    n_out,
                    weight,
                    bias,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        ControlMlp::new(layers).map_err(|e| candle_core::Error::Msg(e.to_string()))
    }

    /// Metadata for an exported network (DESIGN §4).
    pub fn metadata(&self, role: NetworkRole, git_commit: &str) -> NetworkMetadata {
        let output = match role {
            NetworkRole::Critic => self.cfg.critic_outputs,
            NetworkRole::Actor => ACTOR_OUTPUTS,
        };
        let mut meta = NetworkMetadata::new(role, output);
        meta.pos_scale = self.cfg.pos_scale;
        meta.machine = self.cfg.machine;
        meta.dt = self.cfg.dt;
        meta.cost = self.cfg.cost;
        meta.gamma = self.cfg.gamma;
        meta.steps = self.updates;
        meta.lambda_l = self.lambda_l();
        meta.git_commit = git_commit.to_string();
        meta
    }

    /// All state worth resuming from: networks, Adam moments, multipliers,
    /// counters (not the replay buffer).
    pub fn checkpoint_tensors(&self) -> (Vec<(String, Tensor)>, HashMap<String, String>) {
        let mut tensors = Vec::new();
        for (prefix, net) in [
            ("critic", &self.critic),
            ("critic_target", &self.critic_target),
            ("actor", &self.actor),
        ] {
            for (name, t) in net.named() {
                tensors.push((format!("{prefix}.{name}"), t));
            }
        }
        for (prefix, opt) in [
            ("critic_adam", &self.critic_opt),
            ("actor_adam", &self.actor_opt),
        ] {
            for (i, (m, v)) in opt.m.iter().zip(&opt.v).enumerate() {
                tensors.push((format!("{prefix}.m.{i}"), m.as_tensor().clone()));
                tensors.push((format!("{prefix}.v.{i}"), v.as_tensor().clone()));
            }
        }
        let mut meta = HashMap::new();
        meta.insert("updates".into(), self.updates.to_string());
        meta.insert("env_steps".into(), self.env_steps.to_string());
        meta.insert("critic_adam.t".into(), self.critic_opt.t.to_string());
        meta.insert("actor_adam.t".into(), self.actor_opt.t.to_string());
        meta.insert("log_lambda_e".into(), self.log_lambda_e.to_string());
        meta.insert("log_lambda_l".into(), self.log_lambda_l.to_string());
        for (name, s) in [
            ("lambda_e_adam", self.lambda_e_opt),
            ("lambda_l_adam", self.lambda_l_opt),
        ] {
            meta.insert(name.to_string(), format!("{},{},{}", s.m, s.v, s.t));
        }
        (tensors, meta)
    }

    /// Restores what [`Agent::checkpoint_tensors`] saved.
    pub fn restore(
        &mut self,
        tensors: &HashMap<String, Tensor>,
        meta: &HashMap<String, String>,
    ) -> anyhow::Result<()> {
        use anyhow::Context;
        let get = |name: &str| {
            tensors
                .get(name)
                .with_context(|| format!("checkpoint has no tensor `{name}`"))
        };
        for (prefix, net) in [
            ("critic", &self.critic),
            ("critic_target", &self.critic_target),
            ("actor", &self.actor),
        ] {
            for (i, (w, b)) in net.layers.iter().enumerate() {
                for (var, kind) in [(w, "weight"), (b, "bias")] {
                    let name = format!("{prefix}.layers.{i}.{kind}");
                    let t = get(&name)?;
                    anyhow::ensure!(
                        t.shape() == var.shape(),
                        "checkpoint tensor `{name}` has shape {:?}, expected {:?}",
                        t.shape(),
                        var.shape()
                    );
                    var.set(t)?;
                }
            }
        }
        for (prefix, opt) in [
            ("critic_adam", &mut self.critic_opt),
            ("actor_adam", &mut self.actor_opt),
        ] {
            for (i, (m, v)) in opt.m.iter().zip(&opt.v).enumerate() {
                m.set(get(&format!("{prefix}.m.{i}"))?)?;
                v.set(get(&format!("{prefix}.v.{i}"))?)?;
            }
            opt.t = parse_key(meta, &format!("{prefix}.t"))?;
        }
        self.updates = parse_key(meta, "updates")?;
        self.env_steps = parse_key(meta, "env_steps")?;
        self.log_lambda_e = parse_key(meta, "log_lambda_e")?;
        self.log_lambda_l = parse_key(meta, "log_lambda_l")?;
        for (name, dst) in [
            ("lambda_e_adam", &mut self.lambda_e_opt),
            ("lambda_l_adam", &mut self.lambda_l_opt),
        ] {
            let text = meta
                .get(name)
                .with_context(|| format!("checkpoint metadata has no `{name}`"))?;
            let parts: Vec<&str> = text.split(',').collect();
            anyhow::ensure!(
                parts.len() == 3,
                "checkpoint metadata `{name}` = `{text}` is not m,v,t"
            );
            *dst = ScalarAdam {
                m: parts[0].parse().with_context(|| format!("`{name}`"))?,
                v: parts[1].parse().with_context(|| format!("`{name}`"))?,
                t: parts[2].parse().with_context(|| format!("`{name}`"))?,
            };
        }
        // A resumed run draws new random numbers from its step count.
        self.rng = ChaCha8Rng::seed_from_u64(
            self.cfg.seed ^ self.updates.wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        Ok(())
    }
}

/// A batch as tensors; `both` stacks s over s′ (one actor pass for the two).
struct BatchTensors {
    s: Tensor,
    s2: Tensor,
    both: Tensor,
    a: Tensor,
    c: Tensor,
    /// 1 − done per row.
    not_done: Tensor,
}

impl BatchTensors {
    /// Rows `start..start + len`.
    fn rows(&self, start: usize, len: usize) -> Result<Self> {
        let (s, s2) = (
            self.s.narrow(0, start, len)?,
            self.s2.narrow(0, start, len)?,
        );
        Ok(Self {
            both: Tensor::cat(&[&s, &s2], 0)?,
            s,
            s2,
            a: self.a.narrow(0, start, len)?,
            c: self.c.narrow(0, start, len)?,
            not_done: self.not_done.narrow(0, start, len)?,
        })
    }
}

/// `f(1)` on a second thread and `f(0)` on this one.
fn on_two_threads<T: Send>(f: impl Fn(usize) -> Result<T> + Sync) -> Result<[T; 2]> {
    std::thread::scope(|scope| {
        let second = scope.spawn(|| f(1));
        let first = f(0);
        let second = second
            .join()
            .map_err(|_| candle_core::Error::Msg("a training thread panicked".into()))?;
        Ok([first?, second?])
    })
}

/// `first()` here and, when `two`, `second()` on another thread at the same
/// time (the default in its place otherwise).
fn on_shares<T: Send + Default>(
    two: bool,
    first: impl FnOnce() -> T,
    second: impl FnOnce() -> T + Send,
) -> Result<[T; 2]> {
    if !two {
        return Ok([first(), T::default()]);
    }
    std::thread::scope(|scope| {
        let other = scope.spawn(second);
        let mine = first();
        let other = other
            .join()
            .map_err(|_| candle_core::Error::Msg("a training thread panicked".into()))?;
        Ok([mine, other])
    })
}

/// ½(g_a + g_b) for each of `vars`: the gradient of a mean over two equal halves.
fn mean_grads(vars: &[Var], mut a: GradStore, b: &GradStore) -> Result<GradStore> {
    for v in vars {
        if let (Some(ga), Some(gb)) = (a.remove(v.as_tensor()), b.get(v.as_tensor())) {
            a.insert(v.as_tensor(), ((ga + gb)? * 0.5)?);
        }
    }
    Ok(a)
}

/// ½(L − target)² + ρ·GP (paper eq. 13–16) with target c + γ(1 − done) L̄(s′, a′)
/// (DESIGN §4): done only in the terminal set; the time limit is a truncation.
/// Returns the loss, the penalty and L(s, a) detached.
fn critic_objective(
    critic: &Mlp,
    target: &Mlp,
    cfg: &TrainConfig,
    t: &BatchTensors,
    a2: &Tensor,
) -> Result<(Tensor, f64, Tensor)> {
    let (l_next, _) = critic_value(target, &Tensor::cat(&[&t.s2, a2], 1)?)?;
    let y = (&t.c + ((l_next * &t.not_done)? * cfg.gamma)?)?.detach();
    let (l, fwd) = critic_value(critic, &Tensor::cat(&[&t.s, &t.a], 1)?)?;
    let mse = ((&l - &y)?.sqr()?.mean_all()? * 0.5)?;
    if cfg.gradient_penalty > 0.0 {
        let gp = gradient_penalty(critic, &fwd)?;
        let gp_value = gp.to_scalar::<f32>()? as f64;
        Ok(((mse + (gp * cfg.gradient_penalty)?)?, gp_value, l.detach()))
    } else {
        Ok((mse, 0.0, l.detach()))
    }
}

/// The actor loss and its parts.
struct ActorObjective {
    loss: Tensor,
    /// log π(s) + H per row.
    entropy_term: Tensor,
    /// ΔL per row.
    delta_l: Tensor,
}

/// Actor loss (paper eq. 14–15): λ_e (log π(s) + H) + λ_l ΔL with
/// ΔL = L(s′, π(s′)) − L(s, a) + k (L(s, a) − λ L(s′, π(s′))), k = 1 − λ_l,
/// λ = min(λ_l, γ); s and s′ go through the actor as one batch. Beyond a
/// terminal transition L(s′, ·) = 0, as in the critic's target.
fn actor_objective(
    actor: &Mlp,
    critic: &Mlp,
    cfg: &TrainConfig,
    t: &BatchTensors,
    eps: &Tensor,
    l_sa: &Tensor,
    (lambda_e, lambda_l): (f64, f64),
) -> Result<ActorObjective> {
    let n = l_sa.dim(0)?;
    let (k, lam) = (1.0 - lambda_l, lambda_l.min(cfg.gamma));
    let pi = actor_sample(actor, &t.both, eps)?;
    let log_prob_s = pi.log_prob.narrow(0, 0, n)?;
    let a_s2 = pi.action.narrow(0, n, n)?;
    let (l_s2, _) = critic_value(critic, &Tensor::cat(&[&t.s2, &a_s2], 1)?)?;
    let l_s2 = (l_s2 * &t.not_done)?;
    let delta_l = ((&l_s2 - l_sa)? + ((l_sa - (&l_s2 * lam)?)? * k)?)?;
    let entropy_term = log_prob_s.affine(1.0, cfg.target_entropy)?;
    let loss = ((entropy_term.mean_all()? * lambda_e)? + (delta_l.mean_all()? * lambda_l)?)?;
    Ok(ActorObjective {
        loss,
        entropy_term,
        delta_l,
    })
}

/// The E[ΔL] λ_l ascends on: the batch mean, or with `own_goals` the mean over
/// rows whose `own_goal` is 1 (the batch mean when there are none).
fn multiplier_delta(delta: &[f32], own_goal: &[f32], own_goals: bool) -> f64 {
    let all = delta.iter().map(|d| *d as f64).sum::<f64>() / delta.len().max(1) as f64;
    let (sum, n) = delta
        .iter()
        .zip(own_goal)
        .filter(|(_, w)| **w > 0.0)
        .fold((0.0, 0usize), |(s, n), (d, _)| (s + *d as f64, n + 1));
    if own_goals && n > 0 {
        sum / n as f64
    } else {
        all
    }
}

fn parse_key<T: std::str::FromStr>(meta: &HashMap<String, String>, key: &str) -> anyhow::Result<T> {
    let text = meta
        .get(key)
        .ok_or_else(|| anyhow::anyhow!("checkpoint metadata has no `{key}`"))?;
    text.parse()
        .map_err(|_| anyhow::anyhow!("checkpoint metadata `{key}` = `{text}` is not valid"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A batch of random rows; `not_done` 0 on every third row.
    fn batch(n: usize) -> Batch {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut v = |k: usize| -> Vec<f32> {
            (0..k)
                .map(|_| rand::Rng::gen_range(&mut rng, -1.0..1.0))
                .collect()
        };
        Batch {
            len: n,
            state: v(n * ACTOR_INPUTS),
            action: v(n * 2),
            cost: v(n).iter().map(|c| c.abs()).collect(),
            next_state: v(n * ACTOR_INPUTS),
            not_done: (0..n).map(|i| if i % 3 == 0 { 0.0 } else { 1.0 }).collect(),
            own_goal: vec![1.0; n],
        }
    }

    #[test]
    fn terminal_rows_drop_the_value_beyond_them() {
        let cfg = TrainConfig {
            gradient_penalty: 0.0,
            ..Default::default()
        };
        let mut agent = Agent::new(&cfg).unwrap();
        let n = 12;
        let b = batch(n);
        let t = agent.batch_tensors(&b).unwrap();
        let a2 = agent.act(&b.next_state, n).unwrap();
        let a2: Vec<f32> = a2.iter().flat_map(|a| a.map(|v| v as f32)).collect();
        let a2 = f32_tensor(&a2, n, 2, &agent.device).unwrap();

        // Critic: target c + γ(1 − done) L̄(s′, a′), rebuilt row by row.
        let value = |net: &Mlp, s: &Tensor, a: &Tensor| -> Vec<f32> {
            let (l, _) = critic_value(net, &Tensor::cat(&[s, a], 1).unwrap()).unwrap();
            l.to_vec1().unwrap()
        };
        let l = value(&agent.critic, &t.s, &t.a);
        let l_target = value(&agent.critic_target, &t.s2, &a2);
        let expected = (0..n)
            .map(|i| {
                let y = b.cost[i] as f64 + cfg.gamma * (b.not_done[i] * l_target[i]) as f64;
                0.5 * (l[i] as f64 - y).powi(2)
            })
            .sum::<f64>()
            / n as f64;
        let (loss, _, _) =
            critic_objective(&agent.critic, &agent.critic_target, &cfg, &t, &a2).unwrap();
        let loss = loss.to_scalar::<f32>().unwrap() as f64;
        assert!(
            (loss - expected).abs() < 1e-5 * expected.max(1.0),
            "{loss} vs {expected}"
        );

        // Actor: on a terminal row L(s′, ·) = 0, so ΔL = −L + k L = −λ_l L.
        let lambda_l = 0.7;
        let eps = agent.normal(2 * n).unwrap();
        let l_sa = Tensor::from_slice(&l, n, &agent.device).unwrap();
        let obj = actor_objective(
            &agent.actor,
            &agent.critic,
            &cfg,
            &t,
            &eps,
            &l_sa,
            (1.0, lambda_l),
        )
        .unwrap();
        let delta: Vec<f32> = obj.delta_l.to_vec1().unwrap();
        for i in (0..n).step_by(3) {
            let want = -lambda_l * l[i] as f64;
            assert!(
                (delta[i] as f64 - want).abs() < 1e-5,
                "row {i}: {} vs {want}",
                delta[i]
            );
        }
        // ... and on the others it depends on L(s′, π(s′)).
        assert!((1..n)
            .filter(|i| i % 3 != 0)
            .any(|i| (delta[i] as f64 + lambda_l * l[i] as f64).abs() > 1e-3));
    }

    /// ‖a − b‖∞ / ‖b‖∞.
    fn relative_difference(a: &[f32], b: &[f32]) -> f64 {
        assert_eq!(a.len(), b.len());
        let diff = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        let scale = b.iter().map(|y| y.abs()).fold(0.0f32, f32::max);
        f64::from(diff) / f64::from(scale).max(1e-30)
    }

    /// The candle gradient of each of `net`'s parameters, in the fused layout.
    fn candle_gradient(net: &Mlp, grads: &GradStore) -> Vec<Vec<f32>> {
        net.vars()
            .iter()
            .map(|v| {
                grads
                    .get(v.as_tensor())
                    .expect("a gradient for every parameter")
                    .flatten_all()
                    .unwrap()
                    .to_vec1::<f32>()
                    .unwrap()
            })
            .collect()
    }

    fn fused_flat(grad: &NetGradient) -> Vec<Vec<f32>> {
        grad.layers
            .iter()
            .flat_map(|(w, b)| [w.clone(), b.clone()])
            .collect()
    }

    /// Issue 19: the fused kernels' gradients equal candle's autograd on the
    /// same batch and draws, to 1e-5 relative per parameter tensor: the critic
    /// objective with and without the gradient penalty (ρ = 1 makes the double
    /// backward carry most of it), and the actor objective.
    #[test]
    fn fused_gradients_equal_candles_on_the_same_batch() {
        for rho in [0.0, 1.0] {
            let cfg = TrainConfig {
                gradient_penalty: rho,
                ..Default::default()
            };
            let mut agent = Agent::new(&cfg).unwrap();
            let n = 64;
            let b = batch(n);
            let t = agent.batch_tensors(&b).unwrap();
            let eps_critic = agent.normal_values(n);
            let eps_actor = agent.normal_values(2 * n);
            let set = fused::Settings::new(&cfg, n);
            let rows = fused::Rows::from(&b);

            // Critic.
            let eps = f32_tensor(&eps_critic, n, 2, &agent.device).unwrap();
            let a2 = actor_sample(&agent.actor, &t.s2, &eps)
                .unwrap()
                .action
                .detach();
            let (loss, penalty, l_sa) =
                critic_objective(&agent.critic, &agent.critic_target, &cfg, &t, &a2).unwrap();
            let want = candle_gradient(&agent.critic, &loss.backward().unwrap());
            let read =
                ReadParams::new(&[&agent.critic, &agent.critic_target, &agent.actor]).unwrap();
            let (c, tg, a) = (
                read.layers(0).unwrap(),
                read.layers(1).unwrap(),
                read.layers(2).unwrap(),
            );
            let nets = fused::Nets {
                critic: &c,
                target: &tg,
                actor: &a,
            };
            let mut ws = fused::Workspace::default();
            let mut grad = NetGradient::default();
            grad.reset(&c);
            let mut fused_l_sa = vec![0.0; n];
            let share = fused::critic_gradient(
                &mut ws,
                nets,
                rows,
                &eps_critic,
                set,
                &mut fused_l_sa,
                &mut grad,
            );
            let loss = loss.to_scalar::<f32>().unwrap() as f64;
            assert!(
                (share.loss - loss).abs() <= 1e-5 * loss,
                "ρ {rho}: loss {} vs {loss}",
                share.loss
            );
            assert!((share.penalty - penalty).abs() <= 1e-5 * penalty.max(1e-9));
            assert!(relative_difference(&fused_l_sa, &l_sa.to_vec1::<f32>().unwrap()) < 1e-5);
            for (i, (got, want)) in fused_flat(&grad).iter().zip(&want).enumerate() {
                let d = relative_difference(got, want);
                assert!(
                    d < 1e-5,
                    "ρ {rho}: critic parameter {i}: relative difference {d:e}"
                );
            }

            // Actor, against the same critic.
            let multipliers = (0.05, 0.9);
            let eps = f32_tensor(&eps_actor, 2 * n, 2, &agent.device).unwrap();
            let obj = actor_objective(
                &agent.actor,
                &agent.critic,
                &cfg,
                &t,
                &eps,
                &l_sa,
                multipliers,
            )
            .unwrap();
            let want = candle_gradient(&agent.actor, &obj.loss.backward().unwrap());
            grad.reset(&a);
            let (mut entropy, mut delta) = (vec![0.0; n], vec![0.0; n]);
            let share = fused::actor_gradient(
                &mut ws,
                nets,
                rows,
                (&eps_actor[..2 * n], &eps_actor[2 * n..]),
                &fused_l_sa,
                set,
                (multipliers.0 as f32, multipliers.1 as f32),
                (&mut entropy, &mut delta),
                &mut grad,
            );
            let loss = obj.loss.to_scalar::<f32>().unwrap() as f64;
            assert!(
                (share.loss - loss).abs() <= 1e-5 * loss.abs(),
                "actor loss {} vs {loss}",
                share.loss
            );
            assert!(
                relative_difference(&entropy, &obj.entropy_term.to_vec1::<f32>().unwrap()) < 1e-5
            );
            assert!(relative_difference(&delta, &obj.delta_l.to_vec1::<f32>().unwrap()) < 1e-5);
            for (i, (got, want)) in fused_flat(&grad).iter().zip(&want).enumerate() {
                let d = relative_difference(got, want);
                assert!(
                    d < 1e-5,
                    "ρ {rho}: actor parameter {i}: relative difference {d:e}"
                );
            }
        }
    }

    /// Whole updates (Adam and Polyak in place, two threads or one) follow the
    /// candle updates from the same start.
    #[test]
    fn fused_updates_follow_candle_updates() {
        let b = batch(64);
        let run = |kernel: Kernel, two_threads: bool| {
            let cfg = TrainConfig {
                kernel,
                two_threads,
                ..Default::default()
            };
            let mut agent = Agent::new(&cfg).unwrap();
            let stats: Vec<UpdateStats> = (0..3).map(|_| agent.update(&b).unwrap()).collect();
            let params = |net: &Mlp| -> Vec<f32> {
                net.vars()
                    .iter()
                    .flat_map(|v| {
                        v.as_tensor()
                            .flatten_all()
                            .unwrap()
                            .to_vec1::<f32>()
                            .unwrap()
                    })
                    .collect()
            };
            let p = [
                params(&agent.critic),
                params(&agent.critic_target),
                params(&agent.actor),
                agent
                    .critic_opt
                    .v
                    .iter()
                    .flat_map(|v| {
                        v.as_tensor()
                            .flatten_all()
                            .unwrap()
                            .to_vec1::<f32>()
                            .unwrap()
                    })
                    .collect(),
            ];
            (stats, p, agent.lambda_l())
        };
        let (want_stats, want, want_lambda) = run(Kernel::Candle, false);
        for two_threads in [false, true] {
            let (stats, got, lambda) = run(Kernel::Fused, two_threads);
            for (s, w) in stats.iter().zip(&want_stats) {
                assert!((s.critic_loss - w.critic_loss).abs() <= 1e-4 * w.critic_loss);
                assert!((s.actor_loss - w.actor_loss).abs() <= 1e-4 * w.actor_loss.abs());
            }
            assert!((lambda - want_lambda).abs() < 1e-9);
            for (name, (g, w)) in ["critic", "target", "actor", "critic Adam v"]
                .iter()
                .zip(got.iter().zip(&want))
            {
                // Adam moves each parameter by about lr per step whatever the
                // gradient's size: compare the moves, not the parameters' size.
                let diff = g
                    .iter()
                    .zip(w)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                let bound = if *name == "critic Adam v" {
                    1e-4 * w.iter().fold(0.0f32, |m, x| m.max(*x))
                } else {
                    1e-6
                };
                assert!(
                    diff <= bound,
                    "{name} (two threads {two_threads}): differs by {diff:e}"
                );
            }
        }
    }

    #[test]
    fn the_multiplier_sees_own_goal_rows_when_asked() {
        let delta = [1.0, -3.0, 2.0, 4.0];
        let own = [1.0, 0.0, 1.0, 0.0];
        assert_eq!(multiplier_delta(&delta, &own, false), 1.0);
        assert_eq!(multiplier_delta(&delta, &own, true), 1.5);
        assert_eq!(
            multiplier_delta(&delta, &[0.0; 4], true),
            1.0,
            "no own rows"
        );
    }
}
