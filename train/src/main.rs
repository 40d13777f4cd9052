//! `wlnav-train`: train, export, evaluate and verify the ALAC actor and critic.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

use control::weights::{self, NetworkRole, NetworkWeights};
use control::{Actor, Critic};
use train::config::{Kernel, TrainConfig};
use train::evaluate::VerifySummary;
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
    /// Train a new run (or continue one with --resume); once it is complete (its
    /// updates or wall hours reached), drive the MPC with every checkpoint on a
    /// selection set and publish the best to OUT/published.
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
        /// Stop when the run's total training wall time (across resumes) reaches
        /// this many hours.
        #[arg(long)]
        max_wall_hours: Option<f64>,
        /// Goals of the closed-loop selection set (seeded, generated for the run's
        /// machine) on which the run's candidates are compared once it is complete.
        #[arg(long, default_value_t = 64)]
        selection_goals: usize,
        /// The run's random seed (default: the config's `seed`); not with --resume.
        #[arg(long, conflicts_with = "resume")]
        seed: Option<u64>,
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
        #[arg(long, default_value_t = control::model::SUCCESS_TOLERANCE)]
        tolerance: f64,
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Measure gradient updates per second (batch 256: critic + penalty + actor
    /// + multipliers + Polyak) of the fused kernels and the candle reference, on
    /// one thread and on two, in the same run; and environment steps per second.
    Bench {
        #[arg(long, default_value_t = 300)]
        updates: u64,
    },
    /// Copy a run's weights, config and learning curves to a machine's directory
    /// (e.g. critic-weights/avant635/) and write its README with the figures: the
    /// candidate its closed-loop selection chose (`selection.csv`), or without one
    /// the run's last export. Refuses weights whose machine or Δt is not the run
    /// config's.
    Publish {
        #[arg(long)]
        run: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// The command that produced the run, for the README.
        #[arg(long)]
        command: String,
    },
    /// Check the Lyapunov decrease condition (eq. 4c) and L ≥ c on states sampled under the actor.
    Verify {
        #[arg(long)]
        actor: PathBuf,
        #[arg(long)]
        critic: PathBuf,
        #[arg(long, default_value_t = 200)]
        episodes: usize,
        /// A training config whose `[terminal]` set the critic was trained with
        /// (e.g. critic-weights/avant635/train-config.toml); default: no terminal
        /// set. Its machine and dt must be the weights'.
        #[arg(long)]
        terminal_from: Option<PathBuf>,
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Where the actor stops outside the goal set (verify's goals), and whether
    /// a manoeuvre from there is cheaper than standing still under each γ.
    Stalls {
        #[arg(long)]
        actor: PathBuf,
        #[arg(long, default_value_t = 200)]
        episodes: usize,
        /// Discount factors to test (comma-separated; default: the actor's own).
        #[arg(long, value_delimiter = ',')]
        gamma: Vec<f64>,
        /// Test at most this many stalls (the search takes a few seconds each).
        #[arg(long, default_value_t = 12)]
        max_stalls: usize,
        /// A training config whose `[terminal]` set the critic was trained with
        /// (e.g. critic-weights/avant635/train-config.toml); default: no terminal
        /// set. Its machine and dt must be the weights'.
        #[arg(long)]
        terminal_from: Option<PathBuf>,
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

/// Appends `commit<TAB>command` to the run directory's [`run::INVOCATIONS`].
fn record_invocation(out: &Path, commit: &str, command: &str) -> Result<()> {
    use std::io::Write;
    fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join(run::INVOCATIONS);
    fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| writeln!(f, "{commit}\t{command}"))
        .with_context(|| format!("appending to {}", path.display()))
}

/// The run's invocations as a Markdown list (empty if it has none recorded).
fn invocations_markdown(run_dir: &Path) -> String {
    let Ok(text) = fs::read_to_string(run_dir.join(run::INVOCATIONS)) else {
        return String::new();
    };
    let lines: Vec<String> = text
        .lines()
        .filter_map(|l| l.split_once('\t'))
        .map(|(commit, command)| format!("- `{command}` (working tree at `{commit}`)\n"))
        .collect();
    if lines.is_empty() {
        return String::new();
    }
    format!(
        "Every invocation on the run directory, in order:\n\n{}\n",
        lines.concat()
    )
}

fn load_config(path: &Path) -> Result<TrainConfig> {
    let text = fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    TrainConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))
}

/// Loads a network file; with `config` (a training config and its file), refuses
/// weights trained for another machine or Δt than the config's, naming both values.
fn load_net(
    path: &Path,
    role: NetworkRole,
    config: Option<(&TrainConfig, &Path)>,
) -> Result<NetworkWeights> {
    Ok(match config {
        None => weights::load(path, role)?,
        Some((cfg, file)) => {
            weights::load_for(path, role, &cfg.machine, cfg.dt).with_context(|| {
                format!(
                    "{} is for another machine or Δt than the weights",
                    file.display()
                )
            })?
        }
    })
}

/// The actor at `path`, refused if it was trained for another machine or Δt
/// than `critic`.
fn load_actor_for(path: &Path, critic: &Critic) -> Result<Actor> {
    let meta = critic.metadata();
    let w = weights::load_for(path, NetworkRole::Actor, &meta.machine, meta.dt)
        .context("the actor and the critic were trained for different machines or Δt")?;
    Ok(Actor::from_weights(w)?)
}

/// The training config at `path` (`--terminal-from`), if given.
fn terminal_config(path: &Option<PathBuf>) -> Result<Option<(TrainConfig, &Path)>> {
    path.as_deref()
        .map(|p| Ok((load_config(p)?, p)))
        .transpose()
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

/// `cfg` with the `[terminal]` set of `from`, if any.
fn with_terminal(cfg: TrainConfig, from: Option<&TrainConfig>) -> TrainConfig {
    match from {
        Some(c) => TrainConfig {
            terminal: c.terminal.clone(),
            ..cfg
        },
        None => cfg,
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
            max_wall_hours,
            selection_goals,
            seed,
        } => {
            if let Some(h) = max_wall_hours {
                anyhow::ensure!(
                    h.is_finite() && h > 0.0,
                    "--max-wall-hours must be a positive number of hours, got {h}"
                );
            }
            let mut cfg = match (&config, resume) {
                (_, true) => load_config(&out.join(run::CONFIG))?,
                (Some(p), false) => load_config(p)?,
                (None, false) => TrainConfig::default(),
            };
            if let Some(s) = seed {
                cfg.seed = s;
            }
            let opts = RunOptions {
                out_dir: out.clone(),
                resume,
                max_updates,
                max_wall_s: max_wall_hours.map(|h| h * 3600.0),
                git_commit: git_commit(),
                quiet: false,
            };
            anyhow::ensure!(selection_goals > 0, "--selection-goals must be at least 1");
            let command = std::env::args().collect::<Vec<_>>().join(" ");
            record_invocation(&out, &opts.git_commit, &command)?;
            let s = run::train(&cfg, &opts)?;
            println!(
                "{} updates, {} env steps in {:.0} s; critic loss {:.4e} -> {:.4e}; lambda_l {:.3}; weights in {}",
                s.updates, s.env_steps, s.wall_s, s.first_critic_loss, s.last_critic_loss, s.lambda_l, out.display()
            );
            let complete =
                s.updates >= cfg.total_updates || opts.max_wall_s.is_some_and(|w| s.wall_s >= w);
            if !complete {
                println!("the run is not complete: the selection runs when it is (--resume)");
                return Ok(());
            }
            let goals =
                train::select::selection_goals(selection_goals, train::select::SELECTION_SEED);
            println!(
                "selection: every candidate's MPC on {} goals (seed {:#x}, {} s each)",
                goals.len(),
                train::select::SELECTION_SEED,
                train::select::DURATION
            );
            let scores = train::select::select(&out, &cfg, &goals, |c| {
                println!(
                    "  update {:>9}: {}/{} reached, mean {:.2} s",
                    c.updates, c.reached, c.goals, c.mean_time
                )
            })?;
            let best = &scores[0];
            publish(
                &out,
                &best.dir,
                &out.join("published"),
                &command,
                Some(&scores),
            )?;
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
            let actor = Actor::from_weights(load_net(&actor, NetworkRole::Actor, None)?)?;
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
        Cmd::Publish {
            run: run_dir,
            out,
            command,
        } => match train::select::read_selection(&run_dir)? {
            // The selection's choice, as `train` publishes it.
            Some(scores) => publish(&run_dir, &scores[0].dir, &out, &command, Some(&scores))?,
            None => publish(&run_dir, &run_dir, &out, &command, None)?,
        },
        Cmd::Bench { updates } => bench(updates)?,
        Cmd::Stalls {
            actor,
            episodes,
            gamma,
            max_stalls,
            terminal_from,
            out,
        } => {
            let terminal = terminal_config(&terminal_from)?;
            let check = terminal.as_ref().map(|(c, p)| (c, *p));
            let actor = Actor::from_weights(load_net(&actor, NetworkRole::Actor, check)?)?;
            let cfg = with_terminal(
                config_from_metadata(actor.metadata()),
                terminal.as_ref().map(|(c, _)| c),
            );
            let gammas = if gamma.is_empty() {
                vec![cfg.gamma]
            } else {
                gamma
            };
            if let Some(g) = gammas.iter().find(|g| !(**g > 0.0 && **g < 1.0)) {
                anyhow::bail!("--gamma {g}: a discount factor must lie in (0, 1)");
            }
            stalls(&actor, &cfg, episodes, &gammas, max_stalls, out.as_deref())?;
        }
        Cmd::Verify {
            actor,
            critic,
            episodes,
            terminal_from,
            out,
        } => {
            let terminal = terminal_config(&terminal_from)?;
            let check = terminal.as_ref().map(|(c, p)| (c, *p));
            let critic = Critic::from_weights(load_net(&critic, NetworkRole::Critic, check)?)?;
            let actor = load_actor_for(&actor, &critic)?;
            let cfg = with_terminal(
                config_from_metadata(critic.metadata()),
                terminal.as_ref().map(|(c, _)| c),
            );
            let samples = train::evaluate::lyapunov_samples(&actor, &critic, &cfg, episodes, 7);
            let v = VerifySummary::of(&samples);
            println!(
                "{} states outside the goal set: decrease condition (eq. 4c) met on {:.1}%, \
                 E[delta L] = {:.3e}, L >= c on {:.1}% (lambda_l {:.3})",
                v.states,
                v.decrease_share * 100.0,
                v.mean_delta,
                v.above_cost_share * 100.0,
                critic.metadata().lambda_l
            );
            println!(
                "decrease condition in episodes that reach the goal set: {:.1}%, \
                 in those that stop short of it: {:.1}% (see `wlnav-train stalls`)",
                v.decrease_share_reaching * 100.0,
                v.decrease_share_stopping * 100.0
            );
            // The same property in closed loop with the MPC, on the selection set.
            let goals = train::select::selection_goals(64, train::select::SELECTION_SEED);
            let (mut pairs, mut decreases, mut reached) = (0, 0, 0);
            for g in &goals {
                let run = train::select::closed_loop(&critic, &actor, &cfg, *g)?;
                pairs += run.tick_pairs;
                decreases += run.critic_decreases;
                reached += usize::from(run.time.is_some());
            }
            println!(
                "the MPC in closed loop on the selection set ({} goals, {reached} reached): the \
                 critic L(x, u0, g) decreases from tick to tick on {:.1}% of {pairs} ticks",
                goals.len(),
                100.0 * decreases as f64 / pairs.max(1) as f64
            );
            let csv = train::evaluate::lyapunov_csv(&samples);
            if let Some(p) = out {
                fs::write(&p, csv).with_context(|| format!("writing {}", p.display()))?;
            }
        }
    }
    Ok(())
}

/// Prints (and writes as CSV) the actor's stalls and, per γ, the manoeuvre search's result.
fn stalls(
    actor: &Actor,
    cfg: &TrainConfig,
    episodes: usize,
    gammas: &[f64],
    max_stalls: usize,
    out: Option<&std::path::Path>,
) -> Result<()> {
    use train::stalls::{best_manoeuvre, find_stalls, ManoeuvreSearch};
    let stalls = find_stalls(actor, cfg, episodes, 7);
    println!(
        "{} of {episodes} episodes end outside the goal set ({}); testing {}",
        stalls.len(),
        control::model::SUCCESS_TOLERANCE,
        stalls.len().min(max_stalls)
    );
    let search = ManoeuvreSearch::default();
    let mut csv = String::from(
        "distance,along,sideways,heading,gamma,stay,best_manoeuvre,change_pct,end_distance\n",
    );
    let mut cheaper = vec![(0usize, 0usize); gammas.len()];
    for (i, s) in stalls.iter().take(max_stalls).enumerate() {
        let (along, sideways) = s.along_sideways();
        let heading = control::model::pose_error(&s.state, &s.goal)[1];
        let distance = control::model::goal_distance(&s.state, &s.goal);
        for (j, &gamma) in gammas.iter().enumerate() {
            let r = best_manoeuvre(cfg, &search, &s.state, &s.goal, gamma, i as u64);
            let change = 100.0 * (r.best / r.stay - 1.0);
            println!(
                "distance {distance:.3} (along {along:+.3}, sideways {sideways:+.3}, \
                 heading {heading:+.3}) gamma {gamma}: standing {:.2}, best manoeuvre {:.2} \
                 ({change:+.1} %), ends at {:.3}",
                r.stay, r.best, r.end_distance
            );
            if r.best < r.stay {
                cheaper[j].0 += 1;
                if r.end_distance < control::model::SUCCESS_TOLERANCE {
                    cheaper[j].1 += 1;
                }
            }
            csv.push_str(&format!(
                "{distance:.4},{along:.4},{sideways:.4},{heading:.4},{gamma},{:.4},{:.4},{change:.2},{:.4}\n",
                r.stay,
                r.best,
                r.end_distance
            ));
        }
    }
    let tested = stalls.len().min(max_stalls);
    for (g, (c, inside)) in gammas.iter().zip(cheaper) {
        println!(
            "gamma {g}: a manoeuvre cheaper than standing still from {c} of {tested} stops \
             ({inside} ending inside the goal set)"
        );
    }
    if let Some(p) = out {
        fs::write(p, csv).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

/// Success of the actor alone on the paper's 128 scenarios: (reached, mean time).
fn actor_on_paper_set(actor: &Actor, cfg: &TrainConfig, tolerance: f64) -> (usize, f64) {
    let set = control::scenario::paper_scenarios();
    let runs = train::evaluate::rollout_scenarios(actor, cfg, &set, tolerance);
    let ok: Vec<f64> = runs.iter().filter_map(|r| r.t_converge).collect();
    (ok.len(), ok.iter().sum::<f64>() / ok.len().max(1) as f64)
}

/// Publishes the networks in `weights_dir` (the run's exports, or its selected
/// candidate) with the run's config, logs and curves and a README with the
/// figures; `selection` is the closed-loop selection that chose them, best first.
fn publish(
    run_dir: &Path,
    weights_dir: &Path,
    out: &Path,
    command: &str,
    selection: Option<&[train::select::CandidateScore]>,
) -> Result<()> {
    // The run's config and its exported weights must be for the same machine and Δt
    // (checked before anything is copied).
    let config_path = run_dir.join(run::CONFIG);
    let run_cfg = load_config(&config_path)?;
    let check = Some((&run_cfg, config_path.as_path()));
    let critic = Critic::from_weights(load_net(
        &weights_dir.join(weights::CRITIC_FILE),
        NetworkRole::Critic,
        check,
    )?)?;
    let actor = Actor::from_weights(load_net(
        &weights_dir.join(weights::ACTOR_FILE),
        NetworkRole::Actor,
        check,
    )?)?;
    fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (dir, name) in [
        (weights_dir, weights::CRITIC_FILE),
        (weights_dir, weights::ACTOR_FILE),
        (run_dir, "log.csv"),
        (run_dir, "eval.csv"),
    ] {
        let src = dir.join(name);
        fs::copy(&src, out.join(name)).with_context(|| format!("copying {}", src.display()))?;
    }
    train::plot::learning_curves(out).context("drawing the learning curves")?;
    fs::copy(&config_path, out.join("train-config.toml")).context("copying the run's config")?;
    let meta = critic.metadata().clone();
    let cfg = with_terminal(config_from_metadata(&meta), Some(&run_cfg));
    let v = VerifySummary::of(&train::evaluate::lyapunov_samples(
        &actor, &critic, &cfg, 200, 7,
    ));
    let (decrease, above) = (v.decrease_share * 100.0, v.above_cost_share * 100.0);
    let (reaching, stopping) = (
        v.decrease_share_reaching * 100.0,
        v.decrease_share_stopping * 100.0,
    );
    let (ok01, t01) = actor_on_paper_set(&actor, &cfg, 0.1);
    let (ok03, t03) = actor_on_paper_set(&actor, &cfg, 0.3);
    let (_, log) = train::plot::read_csv(&run_dir.join("log.csv"))?;
    let wall = log
        .last()
        .and_then(|r| r.get(2))
        .copied()
        .unwrap_or(f64::NAN);
    let (how, selection_table) = match selection {
        None => (
            format!(
                ", then\n`wlnav-train publish --run {} --out {} --command ...`",
                run_dir.display(),
                out.display()
            ),
            String::new(),
        ),
        Some(scores) => {
            let goals = scores.first().map_or(0, |s| s.goals);
            let mut table = format!(
                "\n## Closed-loop selection\n\nEach checkpoint's MPC (daemon settings, ideal plant) \
                 from rest to {goals} goals of the seeded selection set ({:#x}, distances 3–10 m, \
                 bearings and headings uniform; not an acceptance set), {} s each; best first \
                 (`selection.csv` in the run directory):\n\n\
                 | update | reached | mean time to converge [s] |\n|---|---|---|\n",
                train::select::SELECTION_SEED,
                train::select::DURATION
            );
            for s in scores {
                table.push_str(&format!(
                    "| {} | {}/{} | {:.2} |\n",
                    s.updates, s.reached, s.goals, s.mean_time
                ));
            }
            (
                format!(
                    ": the checkpoint at update {}, chosen by the closed-loop selection below \
                     among the run's {} checkpoints",
                    scores.first().map_or(0, |s| s.updates),
                    scores.len()
                ),
                table,
            )
        }
    };
    let readme = format!(
        "# Trained actor and critic\n\n\
         Produced by `{command}` (config: `train-config.toml`){how}.\n\n\
         {invocations}\
         | | |\n|---|---|\n\
         | git commit of the training binary | `{commit}` |\n\
         | gradient updates | {steps} |\n\
         | wall time of the run | {wall:.0} s ({hours:.1} h, 2 CPU cores shared) |\n\
         | final λ_l | {lambda:.3} |\n\
         | γ, cost W, p, form | {gamma}, {w:?}, {p}, {form} |\n\
         | critic outputs m | {m} |\n\n\
         ## Verify (`wlnav-train verify`, {n} states under the actor, outside the goal set)\n\n\
         - decrease condition of the paper's eq. 4c met on {decrease:.1} % of states \
         ({reaching:.1} % in episodes that reach the goal set, {stopping:.1} % in those that \
         stop short of it: `wlnav-train stalls`)\n\
         - its expectation form: E[ΔL] = {mean_delta:.3e}\n\
         - L ≥ c on {above:.1} %\n\n\
         ## The actor alone on the paper's 128 scenarios (ideal model)\n\n\
         - within 0.1: {ok01}/128 (mean time {t01:.2} s)\n\
         - within 0.3: {ok03}/128 (mean time {t03:.2} s)\n\n\
         The MPC with this critic is evaluated in `docs/results.md`.\n\n\
         The Python check (DESIGN §4: a PyTorch/NumPy user opens both files): `scripts/test.sh` runs\n\
         `scripts/check_weights_python.py {out}` in a venv with `safetensors` and `numpy`\n\
         (`safetensors.numpy.load_file`: same tensor names `layers.{{i}}.weight|bias`, chained\n\
         shapes, metadata keys).\n\n\
         ## Learning curves\n\n![learning curves](learning_curves.svg)\n\n\
         `log.csv` and `eval.csv` are the run's logs.\n{selection_table}",
        out = out.display(),
        invocations = invocations_markdown(run_dir),
        commit = meta.git_commit,
        steps = meta.steps,
        hours = wall / 3600.0,
        lambda = meta.lambda_l,
        gamma = meta.gamma,
        w = meta.cost.w,
        p = meta.cost.p,
        form = meta.cost.form.as_str(),
        m = meta.output_size,
        n = v.states,
        mean_delta = v.mean_delta,
    );
    fs::write(out.join("README.md"), readme).context("writing README.md")?;
    println!(
        "published update {} to {}: actor {ok01}/128 within 0.1, decrease met on {decrease:.1} %",
        meta.steps,
        out.display()
    );
    Ok(())
}

fn bench(updates: u64) -> Result<()> {
    use rand::{Rng, SeedableRng};
    use std::time::Instant;
    let cfg = TrainConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut env = train::env::VecEnv::new(&cfg, &mut rng);
    let mut buffer = train::buffer::ReplayBuffer::new(cfg.buffer_size);
    let steps = 2000;
    let t = Instant::now();
    for _ in 0..steps {
        let actions: Vec<[f64; 2]> = (0..cfg.n_envs)
            .map(|_| [rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)])
            .collect();
        env.step(&cfg, &actions, &mut rng, |ep| buffer.push_episode(ep));
    }
    let env_rate = (steps * cfg.n_envs) as f64 / t.elapsed().as_secs_f64();
    let encoder = control::Encoder::new(cfg.machine, cfg.pos_scale);
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all".into());
    println!(
        "environment: {env_rate:.0} transitions/s (RK4 + clamp + episode bookkeeping, {} envs)",
        cfg.n_envs
    );
    // Both implementations and both schedules in the same run, alternated in
    // rounds, so their ratios are robust to a shared machine.
    let variants = [
        (Kernel::Candle, false),
        (Kernel::Candle, true),
        (Kernel::Fused, false),
        (Kernel::Fused, true),
    ];
    let mut agents = variants
        .iter()
        .map(|&(kernel, two_threads)| {
            train::agent::Agent::new(&TrainConfig {
                kernel,
                two_threads,
                ..cfg.clone()
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut batch = train::buffer::Batch::default();
    for agent in &mut agents {
        for _ in 0..20 {
            buffer.sample(&cfg, &encoder, cfg.batch_size, &mut rng, &mut batch);
            agent.update(&batch)?;
        }
    }
    const ROUNDS: u64 = 3;
    let mut seconds = [0.0f64; 4];
    for _ in 0..ROUNDS {
        for (agent, seconds) in agents.iter_mut().zip(&mut seconds) {
            let t = Instant::now();
            for _ in 0..updates.div_ceil(ROUNDS) {
                buffer.sample(&cfg, &encoder, cfg.batch_size, &mut rng, &mut batch);
                agent.update(&batch)?;
            }
            *seconds += t.elapsed().as_secs_f64();
        }
    }
    let timed = (updates.div_ceil(ROUNDS) * ROUNDS) as f64;
    let rates: Vec<f64> = seconds.iter().map(|s| timed / s).collect();
    for ((kernel, two_threads), rate) in variants.iter().zip(&rates) {
        println!(
            "training: {rate:6.1} updates/s  {:<6} {} (batch {}, critic + gradient penalty + actor + multipliers + Polyak; RAYON_NUM_THREADS={threads})",
            format!("{kernel:?}").to_lowercase(),
            if *two_threads { "two threads (each gradient on half the batch)" } else { "one thread" },
            cfg.batch_size
        );
    }
    println!(
        "fused / candle: {:.2} on one thread, {:.2} on two; two threads / one: candle {:.2}, fused {:.2}",
        rates[2] / rates[0],
        rates[3] / rates[1],
        rates[1] / rates[0],
        rates[3] / rates[2]
    );
    Ok(())
}
