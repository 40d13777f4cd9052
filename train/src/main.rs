//! `wlnav-train`: train, export, evaluate and verify the ALAC actor and critic.

use std::fs;
use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

use control::weights::decode;
use control::{Actor, Critic};
use train::config::TrainConfig;
use train::run::{self, RunOptions};

#[derive(Parser)]
#[command(
    name = "wlnav-train",
    about = "Offline ALAC training of wlnav's actor and critic"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a new run, or continue one with --resume.
    Train {
        /// TOML configuration (defaults for missing keys); with --resume the run's own config is used.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Run directory: checkpoint, CSV logs, SVG curves, exported weights.
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        resume: bool,
        /// Stop after this many updates in this invocation.
        #[arg(long)]
        max_updates: Option<u64>,
    },
    /// Write critic.safetensors and actor.safetensors from a run's checkpoint.
    Export {
        #[arg(long)]
        run: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Roll the actor alone out on a scenario CSV (DESIGN §7).
    Eval {
        #[arg(long)]
        actor: PathBuf,
        #[arg(long)]
        scenarios: PathBuf,
        #[arg(long, default_value_t = 0.1)]
        tolerance: f64,
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Check the Lyapunov decrease condition (eq. 4c) and L ≥ c on states sampled under the actor.
    Verify {
        #[arg(long)]
        actor: PathBuf,
        #[arg(long)]
        critic: PathBuf,
        #[arg(long, default_value_t = 200)]
        episodes: usize,
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

fn git_commit() -> String {
    Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

fn load_config(path: &PathBuf) -> Result<TrainConfig> {
    let text = fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    TrainConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))
}

fn load_net(path: &PathBuf) -> Result<control::weights::NetworkWeights> {
    let bytes = fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(decode(&bytes, &path.display().to_string())?)
}

/// The training config matching exported weights (machine, cost, dt from their metadata).
fn config_from_metadata(meta: &control::weights::NetworkMetadata) -> TrainConfig {
    TrainConfig {
        machine: meta.machine,
        cost: meta.cost,
        dt: meta.dt,
        gamma: meta.gamma,
        pos_scale: meta.pos_scale,
        ..Default::default()
    }
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Cmd::Train {
            config,
            out,
            resume,
            max_updates,
        } => {
            let cfg = match (&config, resume) {
                (_, true) => load_config(&out.join(run::CONFIG))?,
                (Some(p), false) => load_config(p)?,
                (None, false) => TrainConfig::default(),
            };
            let opts = RunOptions {
                out_dir: out.clone(),
                resume,
                max_updates,
                git_commit: git_commit(),
                quiet: false,
            };
            let s = run::train(&cfg, &opts)?;
            println!(
                "{} updates, {} env steps in {:.0} s; critic loss {:.4e} -> {:.4e}; lambda_l {:.3}; weights in {}",
                s.updates, s.env_steps, s.wall_s, s.first_critic_loss, s.last_critic_loss, s.lambda_l, out.display()
            );
        }
        Cmd::Export { run, out } => {
            let cfg = load_config(&run.join(run::CONFIG))?;
            let mut agent = train::agent::Agent::new(&cfg)?;
            run::load_checkpoint(&mut agent, &run)?;
            run::export(&agent, &out, &git_commit())?;
            println!("exported update {} to {}", agent.updates, out.display());
        }
        Cmd::Eval {
            actor,
            scenarios,
            tolerance,
            out,
        } => {
            let actor = Actor::from_weights(load_net(&actor)?)?;
            let text = fs::read_to_string(&scenarios)
                .with_context(|| format!("reading {}", scenarios.display()))?;
            let set = control::scenario::parse(&text, &scenarios.display().to_string())?;
            let cfg = config_from_metadata(actor.metadata());
            let runs = train::evaluate::rollout_scenarios(&actor, &cfg, &set, tolerance);
            let mut csv =
                String::from("name,method,success,t_converge,final_distance,path_length\n");
            for r in &runs {
                csv.push_str(&format!(
                    "{},actor,{},{},{:.4},{:.3}\n",
                    r.name,
                    r.t_converge.is_some(),
                    r.t_converge.map_or(String::new(), |t| format!("{t:.1}")),
                    r.final_distance,
                    r.path_length
                ));
            }
            let ok: Vec<f64> = runs.iter().filter_map(|r| r.t_converge).collect();
            let mean = ok.iter().sum::<f64>() / ok.len().max(1) as f64;
            println!(
                "actor: {}/{} reached within {tolerance}; mean convergence time {mean:.2} s",
                ok.len(),
                runs.len()
            );
            match out {
                Some(p) => {
                    fs::write(&p, csv).with_context(|| format!("writing {}", p.display()))?
                }
                None => print!("{csv}"),
            }
        }
        Cmd::Verify {
            actor,
            critic,
            episodes,
            out,
        } => {
            let actor = Actor::from_weights(load_net(&actor)?)?;
            let critic = Critic::from_weights(load_net(&critic)?)?;
            let cfg = config_from_metadata(critic.metadata());
            let samples = train::evaluate::lyapunov_samples(&actor, &critic, &cfg, episodes, 7);
            let n = samples.len() as f64;
            let decrease = samples.iter().filter(|s| s.delta <= 0.0).count() as f64 / n;
            let above_cost = samples.iter().filter(|s| s.l >= s.cost).count() as f64 / n;
            println!(
                "{} states: decrease condition (eq. 4c) met on {:.1}%, L >= c on {:.1}% (lambda_l {:.3})",
                samples.len(),
                decrease * 100.0,
                above_cost * 100.0,
                critic.metadata().lambda_l
            );
            let mut csv = String::from("distance,cost,l,l_next,delta,decrease_met,l_ge_c\n");
            for s in &samples {
                csv.push_str(&format!(
                    "{:.4},{:.6},{:.6},{:.6},{:.6},{},{}\n",
                    s.distance,
                    s.cost,
                    s.l,
                    s.l_next,
                    s.delta,
                    s.delta <= 0.0,
                    s.l >= s.cost
                ));
            }
            if let Some(p) = out {
                fs::write(&p, csv).with_context(|| format!("writing {}", p.display()))?;
            }
        }
    }
    Ok(())
}
