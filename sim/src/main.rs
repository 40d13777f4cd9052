//! `wlnav-sim`: scenario files, evaluation, the baseline and the results report.
//!
//! ```text
//! wlnav-sim eval --scenarios sim/scenarios/paper128.csv --methods mpc,actor,baseline,min-time \
//!     [--horizon N] [--hessian exact|gauss-newton] [--obstacles distance|cbf] \
//!     [--qp-solver clarabel|riccati] \
//!     [--sqp-iterations K] [--step-length A] [--obstacle-margin M] \
//!     [--delay 0.2] [--lag 0.1] [--tolerance 0.1] [--weights critic-weights/avant635] --out out/eval \
//!     [--plant-scale-lf K] [--plant-scale-lr K] [--plant-delay S] [--actuator-gain K] \
//!     [--pose-noise SXY,STHETA] [--pose-latency S]
//! # controller options left out take the daemon's defaults (MpcSettings::default());
//! # the plant is ideal unless --delay / --lag are given (the paper's test); the
//! # perturbations make the plant differ from the MPC's model (DESIGN §12)
//! wlnav-sim paper [--weights critic-weights/avant635] [--out docs]
//! wlnav-sim robustness [--obstacles-per-kind 10] [--out docs]   # docs/robustness.md
//! wlnav-sim scenarios --out sim/scenarios   # paper128, selection64, obstacles200 (seeded)
//! ```

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use control::assumption_check::{CheckSettings, OnBroken};
use control::critic::HessianMode;
use control::envelope::EnvelopeSettings;
use control::mpc::{MpcSettings, ObstacleConstraint, QpSolver};
use control::planner::{NavigatorSettings, PlanDelay};
use control::plant::PlantConfig;
use control::scenario;
use control::site::{Outline, Site, SiteIndex};
use control::MachineParams;
use sim::eval;
use sim::movers::PerceptionSettings;
use sim::robustness::{self, PerturbationOptions};
use sim::runner::{EvalConfig, Method, Networks};
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "wlnav-sim",
    about = "wlnav scenarios, closed-loop evaluation, baseline and report"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// A value of one of control's settings enums, read as its serde name
/// (`gauss-newton`, `riccati`, …): the flag and the daemon's configuration
/// take the same words from the same declaration.
fn serde_value<T: serde::de::DeserializeOwned>(s: &str) -> Result<T, String> {
    T::deserialize(serde::de::value::StrDeserializer::<serde::de::value::Error>::new(s))
        .map_err(|e| e.to_string())
}

/// A navigator setting `group.key=value` (`search.heuristic_weight=1.5`): the
/// value is TOML, read by the settings' own serde declaration.
fn navigator_override(s: &str) -> Result<(String, toml::Value), String> {
    let (key, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: expected KEY=VALUE, e.g. search.heuristic_weight=1.5"))?;
    let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
        .map_err(|e| format!("`{s}`: the value is not TOML: {e}"))?
        .get("v")
        .cloned()
        .ok_or_else(|| format!("`{s}`: no value"))?;
    Ok((key.trim().to_string(), value))
}

/// The default settings `T` with `overrides` applied (each a dotted key of
/// `T`, given with `flag`); unknown keys are errors.
fn with_overrides<T: serde::de::DeserializeOwned>(
    overrides: &[(String, toml::Value)],
    flag: &str,
) -> Result<T> {
    let mut table = toml::Table::new();
    for (key, value) in overrides {
        let mut parts: Vec<&str> = key.split('.').collect();
        let last = parts.pop().unwrap_or_default();
        let mut t = &mut table;
        for p in parts {
            t = t
                .entry(p)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .with_context(|| format!("{flag} {key}: `{p}` is a value, not a group"))?;
        }
        t.insert(last.to_string(), value.clone());
    }
    toml::Value::Table(table)
        .try_into()
        .with_context(|| flag.to_string())
}

/// Overrides as given, `key=value, ...` (for the summary's header).
fn overrides_text(overrides: &[(String, toml::Value)]) -> String {
    overrides
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The default navigator settings with `overrides` applied (each a dotted key
/// of [`NavigatorSettings`]); unknown keys are errors.
fn navigator_settings(overrides: &[(String, toml::Value)]) -> Result<NavigatorSettings> {
    let s: NavigatorSettings = with_overrides(overrides, "--navigator")?;
    s.validate()?;
    Ok(s)
}

/// Things that move (DESIGN §18) and the simulated perception that sees them.
#[derive(clap::Args, Clone)]
struct MoverArgs {
    /// A movers file (CSV `id,radius,t0,x0,y0,vx,vy,t1`): every scenario gets
    /// them, seen through the simulated perception below.
    #[arg(long, value_name = "FILE")]
    movers: Option<PathBuf>,
    /// From a mover's measurement to its delivery to the pilot [s].
    #[arg(long, value_name = "S", default_value_t = PerceptionSettings::default().latency)]
    perception_latency: f64,
    /// Sets perception publishes per second.
    #[arg(long, value_name = "HZ", default_value_t = PerceptionSettings::default().rate)]
    perception_rate: f64,
    /// Probability that a published set is lost (seeded per scenario).
    #[arg(long, value_name = "P", default_value_t = PerceptionSettings::default().dropout)]
    perception_dropout: f64,
    /// A live-obstacle setting, `key=value` (repeatable), e.g. `--live
    /// stop_margin=0.8`; the keys are `control::live::LiveSettings`'.
    #[arg(long = "live", value_name = "KEY=VALUE", value_parser = navigator_override)]
    live: Vec<(String, toml::Value)>,
}

impl MoverArgs {
    /// Puts the movers, the perception and the live settings into `cfg`.
    fn apply(&self, cfg: &mut EvalConfig) -> Result<()> {
        cfg.perception = PerceptionSettings {
            latency: self.perception_latency,
            rate: self.perception_rate,
            dropout: self.perception_dropout,
            // The perturbations' seed (`--seed`), mixed with each scenario's name.
            seed: cfg.perturbation.seed,
        };
        cfg.perception.validate().map_err(anyhow::Error::msg)?;
        cfg.live = with_overrides(&self.live, "--live")?;
        cfg.live.validate()?;
        if let Some(path) = &self.movers {
            cfg.movers = Some(Arc::new(sim::movers::load(path)?));
        } else if !self.live.is_empty() {
            bail!("--live needs --movers");
        }
        Ok(())
    }
}

#[derive(clap::Args, Clone)]
struct Common {
    /// One machine's directory with critic.safetensors and actor.safetensors (the
    /// evaluation runs the machine and Δt of their metadata); random networks
    /// (with a warning) when it has none.
    #[arg(long, default_value = control::weights::DEFAULT_DIR)]
    weights: PathBuf,
    /// Refuse to fall back to random networks.
    #[arg(long)]
    require_weights: bool,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Success-test tolerance (DESIGN §7).
    #[arg(long, default_value_t = control::model::SUCCESS_TOLERANCE)]
    tolerance: f64,
}

/// How the plant differs from the MPC's model (DESIGN §12); all off by default.
#[derive(clap::Args, Clone)]
struct Perturbations {
    /// The plant's L_f is K × the nominal (the MPC keeps the nominal).
    #[arg(long, value_name = "K", value_parser = robustness::parse_factor)]
    plant_scale_lf: Option<f64>,
    /// The plant's L_r is K × the nominal (the MPC keeps the nominal).
    #[arg(long, value_name = "K", value_parser = robustness::parse_factor)]
    plant_scale_lr: Option<f64>,
    /// The plant's true input delay [s]; `--delay` stays the delay the MPC compensates.
    #[arg(long, value_name = "S", value_parser = robustness::parse_seconds)]
    plant_delay: Option<f64>,
    /// Achieved β̇ and v are K × the command.
    #[arg(long, value_name = "K", value_parser = robustness::parse_factor)]
    actuator_gain: Option<f64>,
    /// Gaussian noise on the measured x, y [m] and θ [rad] (seeded per scenario).
    #[arg(long, value_name = "SXY,STHETA", value_parser = robustness::parse_pose_noise)]
    pose_noise: Option<(f64, f64)>,
    /// The pose the tick reads is S seconds old.
    #[arg(long, value_name = "S", value_parser = robustness::parse_seconds)]
    pose_latency: Option<f64>,
    /// Seed of the pose noise (mixed with each scenario's name).
    #[arg(long, default_value_t = 0)]
    noise_seed: u64,
}

impl Perturbations {
    fn options(&self) -> PerturbationOptions {
        PerturbationOptions {
            plant_scale_lf: self.plant_scale_lf,
            plant_scale_lr: self.plant_scale_lr,
            plant_delay: self.plant_delay,
            actuator_gain: self.actuator_gain,
            pose_noise: self.pose_noise,
            pose_latency: self.pose_latency,
            seed: self.noise_seed,
        }
    }
}

/// The safety envelope (DESIGN §14) and the tolerances its margins come from;
/// the tolerances also widen the MPC's planned clearances.
#[derive(clap::Args, Clone)]
struct EnvelopeArgs {
    /// Run without the safety envelope (to measure what it changes).
    #[arg(long)]
    no_envelope: bool,
    /// Protective margin kept beyond the tolerances [m] (default: the daemon's).
    #[arg(long, value_name = "M")]
    envelope_margin: Option<f64>,
    /// How far the true rear axle may be from the configured geometry's [m].
    #[arg(long, value_name = "M")]
    geometry_tolerance: Option<f64>,
    /// Stated pose noise (standard deviations) x, y [m] and θ [rad].
    #[arg(long, value_name = "SXY,STHETA", value_parser = robustness::parse_pose_noise)]
    pose_noise_tolerance: Option<(f64, f64)>,
    /// Stated uncertainty of the pose's timestamp [s].
    #[arg(long, value_name = "S", value_parser = robustness::parse_seconds)]
    pose_latency_tolerance: Option<f64>,
    /// The machine may start a stop this much later than the model says [s].
    #[arg(long, value_name = "S", value_parser = robustness::parse_seconds)]
    response_lag: Option<f64>,
    /// The machine may achieve up to K × the commanded velocities (K in [1, 2]).
    #[arg(long, value_name = "K")]
    actuator_gain_max: Option<f64>,
    /// State no tolerance at all (the envelope of a machine that is exactly
    /// its model; the defaults before issue 43); the flags above still apply.
    #[arg(long)]
    exact_envelope: bool,
    /// What a broken assumption does (issue 43; default: the daemon's).
    #[arg(long, value_name = "ACTION", value_parser = serde_value::<OnBroken>)]
    assumption_action: Option<OnBroken>,
    /// Do not check the envelope's assumptions while driving.
    #[arg(long)]
    no_assumption_check: bool,
}

impl EnvelopeArgs {
    fn settings(&self) -> Result<EnvelopeSettings> {
        let d = if self.exact_envelope {
            EnvelopeSettings::exact()
        } else {
            EnvelopeSettings::default()
        };
        let check = CheckSettings {
            enabled: !self.no_assumption_check,
            action: self.assumption_action.unwrap_or(d.check.action),
            ..d.check
        };
        let (sxy, sth) = self
            .pose_noise_tolerance
            .unwrap_or((d.pose_noise_xy, d.pose_noise_theta));
        let s = EnvelopeSettings {
            enabled: !self.no_envelope,
            margin: self.envelope_margin.unwrap_or(d.margin),
            geometry_tolerance: self.geometry_tolerance.unwrap_or(d.geometry_tolerance),
            pose_noise_xy: sxy,
            pose_noise_theta: sth,
            pose_latency: self.pose_latency_tolerance.unwrap_or(d.pose_latency),
            response_lag: self.response_lag.unwrap_or(d.response_lag),
            actuator_gain_max: self.actuator_gain_max.unwrap_or(d.actuator_gain_max),
            check,
            ..d
        };
        s.validate()?;
        Ok(s)
    }
}

// Parsed once; the size of the `eval` variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Evaluate methods on a scenario file; writes DIR/results.csv, summary.md and SVGs.
    Eval {
        #[arg(long)]
        scenarios: PathBuf,
        /// Comma-separated: mpc, actor, baseline, min-time.
        #[arg(long, default_value = "mpc,actor,baseline,min-time")]
        methods: String,
        /// MPC horizon N (default: the daemon's, `MpcSettings::default()`).
        #[arg(long)]
        horizon: Option<usize>,
        /// Hessian of the critic cost: exact or gauss-newton (default: the daemon's).
        #[arg(long, value_parser = serde_value::<HessianMode>)]
        hessian: Option<HessianMode>,
        /// Obstacle constraint form: distance or cbf (default: the daemon's).
        #[arg(long, value_parser = serde_value::<ObstacleConstraint>)]
        obstacles: Option<ObstacleConstraint>,
        /// The MPC's QP solver: riccati or clarabel (the reference; default: the
        /// daemon's, `MpcSettings::qp_solver`).
        #[arg(long, value_parser = serde_value::<QpSolver>)]
        qp_solver: Option<QpSolver>,
        /// SQP iterations per tick (1 = real-time iteration; default: the daemon's).
        #[arg(long)]
        sqp_iterations: Option<usize>,
        /// Step length of every SQP iteration, in (0, 1] (default: the daemon's).
        #[arg(long)]
        step_length: Option<f64>,
        /// Margin [m] the planned axle points keep from every circle (default: the daemon's).
        #[arg(long)]
        obstacle_margin: Option<f64>,
        /// Margin [m] of the rear axle's rows (default: the daemon's).
        #[arg(long)]
        obstacle_margin_rear: Option<f64>,
        /// L1 penalty per metre of obstacle penetration (default: the daemon's).
        #[arg(long)]
        obstacle_slack_weight: Option<f64>,
        /// Time budget of one tick [s] (default: the daemon's). A larger one makes
        /// an evaluation on a loaded machine measure the method, not the load.
        #[arg(long, value_name = "S")]
        time_budget: Option<f64>,
        /// Plant input delay [s] (compensated by the MPC).
        #[arg(long, default_value_t = 0.0)]
        delay: f64,
        /// Plant velocity-lag time constant of β̇ and v [s] (0: ideal ramp).
        #[arg(long, default_value_t = 0.0)]
        lag: f64,
        /// Simulated duration [s].
        #[arg(long, default_value_t = 30.0)]
        duration: f64,
        /// Turn the MPC's online actuator-gain estimate off (default: the daemon's).
        #[arg(long)]
        no_gain_estimation: bool,
        /// Turn the MPC's online delay estimate off (default: the daemon's).
        #[arg(long)]
        no_delay_estimation: bool,
        /// Skip the per-scenario trajectory plots.
        #[arg(long)]
        no_scenario_plots: bool,
        /// Without the global layer: the MPC drives straight to the goal.
        #[arg(long)]
        no_planner: bool,
        /// A navigator setting, `group.key=value` or `key=value` (repeatable),
        /// e.g. `--navigator search.heuristic_weight=1.5`, `--navigator
        /// trajectory=false` (the route followed, not shaped); the groups and
        /// keys are `control::planner::NavigatorSettings`' (search, following,
        /// stall, max_route_age, trajectory).
        #[arg(long = "navigator", value_name = "KEY=VALUE", value_parser = navigator_override)]
        navigator_overrides: Vec<(String, toml::Value)>,
        /// A setting of the planner's trajectory solve, `key=value` (repeatable),
        /// e.g. `--trajectory max_iterations=40`; the keys are
        /// `trajopt::trajectory::TrajectorySettings`' (`wlnavd`'s `[trajectory]`).
        #[arg(long = "trajectory", value_name = "KEY=VALUE", value_parser = navigator_override)]
        trajectory_overrides: Vec<(String, toml::Value)>,
        /// How a route plan's time is charged: a fixed delay [s] (default one
        /// tick, as the daemon's planner thread answers at the next tick) or
        /// `measured` (its wall time; not deterministic).
        #[arg(long, value_name = "S|measured", value_parser = parse_plan_delay)]
        plan_delay: Option<PlanDelay>,
        /// Results file whose min-time rows give T* (e.g. docs/results/worksite.csv
        /// for obstacles200), so t / T* is reported without solving the bound again.
        #[arg(long, value_name = "FILE")]
        t_star: Option<PathBuf>,
        /// A site file (DESIGN §17): its features and bounds apply to every
        /// scenario, on top of the scenario's own circles.
        #[arg(long, value_name = "FILE")]
        site: Option<PathBuf>,
        /// The machine's outline: axle-circles (default), avant635,
        /// large-loader, large-loader-axles.
        #[arg(long, value_name = "NAME", value_parser = parse_outline)]
        outline: Option<Outline>,
        #[command(flatten)]
        perturbations: Perturbations,
        #[command(flatten)]
        envelope: EnvelopeArgs,
        #[command(flatten)]
        movers: MoverArgs,
        #[command(flatten)]
        common: Common,
        #[arg(long)]
        out: PathBuf,
    },
    /// Each plant perturbation alone over a range of levels and all moderate
    /// ones at once (DESIGN §12); writes OUT/robustness.md and OUT/robustness/*.
    Robustness {
        #[arg(long, default_value = "sim/scenarios/paper128.csv")]
        scenarios: PathBuf,
        /// The obstacle set; a seeded subset of it is run.
        #[arg(long, default_value = "sim/scenarios/obstacles200.csv")]
        obstacles: PathBuf,
        /// Scenarios of each obstacle kind in the subset (0: the whole set).
        #[arg(long, default_value_t = 10)]
        obstacles_per_kind: usize,
        /// Seed of the obstacle subset.
        #[arg(long, default_value_t = 16)]
        subset_seed: u64,
        /// Results file whose min-time rows give T* of the paper set.
        #[arg(long, default_value = "docs/results/paper128.csv")]
        t_star: PathBuf,
        /// Run the MPC without its online gain and delay estimates (for comparison).
        #[arg(long)]
        no_estimation: bool,
        /// Base name of the page (NAME.md) and its asset directory.
        #[arg(long, default_value = "robustness")]
        name: String,
        /// Run every case with the shipped envelope (nothing stated about the
        /// perturbation; issue 43) instead of the tolerances each case states.
        #[arg(long)]
        shipped_envelope: bool,
        #[command(flatten)]
        common: Common,
        #[arg(long, default_value = "docs")]
        out: PathBuf,
    },
    /// The whole study: writes OUT/results.md and OUT/results/*.
    Paper {
        #[arg(long, default_value = "sim/scenarios/paper128.csv")]
        scenarios: PathBuf,
        #[arg(long, default_value = "sim/scenarios/highlighted.csv")]
        highlighted: PathBuf,
        /// Work-site scenario files of section 4, comma-separated (empty: no section 4).
        #[arg(
            long,
            default_value = "sim/scenarios/obstacles.csv,sim/scenarios/obstacles200.csv"
        )]
        worksite: String,
        #[command(flatten)]
        common: Common,
        #[arg(long, default_value = "docs")]
        out: PathBuf,
    },
    /// Writes the paper's 128 scenarios to OUT/paper128.csv, a seeded selection set of 64
    /// (for choosing among trained checkpoints without the paper set) to OUT/selection64.csv,
    /// the work-site set OUT/obstacles200.csv and its tuning twin (another seed)
    /// OUT/obstacles-tuning100.csv.
    Scenarios {
        #[arg(long, default_value = "sim/scenarios")]
        out: PathBuf,
    },
}

/// Seed of `sim/scenarios/obstacles200.csv` (issue 14).
const OBSTACLES_SEED: u64 = 14;
/// Seed of `sim/scenarios/obstacles-tuning100.csv`: the set the navigator's settings are
/// tuned on, so that obstacles200 stays an acceptance set.
const OBSTACLES_TUNING_SEED: u64 = 114;

fn load_scenarios(path: &Path) -> Result<Vec<scenario::Scenario>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(scenario::parse(&text, &path.display().to_string())?)
}

/// A site file (JSON, DESIGN §17), validated.
fn load_site(path: &Path) -> Result<Site> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Site::parse(&bytes).with_context(|| format!("site file {}", path.display()))
}

fn parse_outline(name: &str) -> Result<Outline, String> {
    Outline::named(name).ok_or_else(|| {
        format!(
            "unknown outline {name:?} (one of {})",
            Outline::NAMES.join(", ")
        )
    })
}

fn networks(c: &Common) -> Result<Networks> {
    match Networks::load(&c.weights) {
        Ok(n) => Ok(n),
        Err(e) if !c.require_weights => {
            eprintln!("warning: {e:#}; using RANDOM networks (they do not reach goals)");
            Ok(Networks::random(0))
        }
        Err(e) => Err(e),
    }
}

/// The evaluation's defaults for the machine the networks were trained for.
fn base_config(c: &Common, nets: &Networks) -> Result<EvalConfig> {
    let mut cfg = EvalConfig {
        tolerance: c.tolerance,
        params: nets.machine,
        ..Default::default()
    };
    nets.check_for(&cfg.params, cfg.mpc.dt)?;
    cfg.min_time.tolerance = c.tolerance;
    if let Some(j) = c.jobs {
        cfg.jobs = j.max(1);
    }
    Ok(cfg)
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Eval {
            scenarios,
            methods,
            horizon,
            hessian,
            obstacles,
            qp_solver,
            sqp_iterations,
            step_length,
            obstacle_margin,
            obstacle_margin_rear,
            obstacle_slack_weight,
            time_budget,
            delay,
            lag,
            duration,
            no_gain_estimation,
            no_delay_estimation,
            no_scenario_plots,
            no_planner,
            navigator_overrides,
            trajectory_overrides,
            plan_delay,
            t_star,
            site,
            outline,
            perturbations,
            envelope,
            movers,
            common,
            out,
        } => {
            if !(delay >= 0.0 && lag >= 0.0 && duration > 0.0 && common.tolerance > 0.0) {
                bail!("--delay and --lag must be >= 0, --duration and --tolerance > 0");
            }
            let set = load_scenarios(&scenarios)?;
            let nets = networks(&common)?;
            let mut cfg = base_config(&common, &nets)?;
            cfg.methods = Method::parse_list(&methods)?;
            cfg.duration = duration;
            if let Some(path) = &site {
                cfg.site = Some(Arc::new(SiteIndex::new(load_site(path)?)));
            }
            if let Some(o) = outline {
                cfg.outline = o;
            }
            // Unset options keep the daemon's defaults (the same `MpcSettings::default()`).
            let d = MpcSettings::default();
            cfg.mpc = MpcSettings {
                horizon: horizon.unwrap_or(d.horizon),
                hessian: hessian.unwrap_or(d.hessian),
                obstacle_constraint: obstacles.unwrap_or(d.obstacle_constraint),
                qp_solver: qp_solver.unwrap_or(d.qp_solver),
                sqp_iterations: sqp_iterations.unwrap_or(d.sqp_iterations),
                step_length: step_length.unwrap_or(d.step_length),
                obstacle_margin: obstacle_margin.unwrap_or(d.obstacle_margin),
                obstacle_margin_rear: obstacle_margin_rear.unwrap_or(d.obstacle_margin_rear),
                obstacle_slack_weight: obstacle_slack_weight.unwrap_or(d.obstacle_slack_weight),
                time_budget: time_budget.unwrap_or(d.time_budget),
                gain_estimation: d.gain_estimation && !no_gain_estimation,
                delay_estimation: d.delay_estimation && !no_delay_estimation,
                ..cfg.mpc
            };
            cfg.mpc.validate()?;
            cfg.navigator = if no_planner {
                None
            } else {
                Some(navigator_settings(&navigator_overrides)?)
            };
            if !trajectory_overrides.is_empty() {
                let mut t: trajopt::trajectory::TrajectorySettings =
                    with_overrides(&trajectory_overrides, "--trajectory")?;
                // The evaluation's CPU backstop unless given: the iteration
                // budget decides (`EvalConfig::default`).
                if trajectory_overrides
                    .iter()
                    .all(|(k, _)| k != "max_solve_seconds")
                {
                    t.max_solve_seconds = cfg.trajectory.max_solve_seconds;
                }
                t.validate()?;
                cfg.trajectory = t;
            }
            if let Some(d) = plan_delay {
                cfg.plan_delay = d;
            }
            cfg.plant = PlantConfig {
                delay,
                tau_beta_dot: lag,
                tau_v: lag,
                ..PlantConfig::ideal()
            };
            cfg.plant.validate()?;
            cfg.perturbation = perturbations.options().perturbation()?;
            cfg.envelope = envelope.settings()?;
            movers.apply(&mut cfg)?;
            let mut ev = eval::evaluate(&cfg, &nets, &set)?;
            if let Some(path) = &t_star {
                if cfg.methods.contains(&Method::MinTime) {
                    bail!("--t-star and the method min-time exclude each other");
                }
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?;
                let names: std::collections::HashSet<&str> =
                    set.iter().map(|s| s.name.as_str()).collect();
                let mut rows = ev.rows.clone();
                rows.extend(
                    sim::results::parse(&text, &path.display().to_string())?
                        .into_iter()
                        .filter(|r| r.method == "min-time" && names.contains(r.name.as_str())),
                );
                ev.summaries = eval::summarize_runs(&cfg.methods, &ev.runs, &rows);
            }
            let nd = NavigatorSettings::default();
            let navigation = match &cfg.navigator {
                None => "none".to_string(),
                Some(n) if *n == nd => "hybrid-astar (defaults)".to_string(),
                Some(_) => format!("hybrid-astar ({})", overrides_text(&navigator_overrides)),
            };
            let navigation = if trajectory_overrides.is_empty() {
                navigation
            } else {
                format!(
                    "{navigation}, trajectory ({})",
                    overrides_text(&trajectory_overrides)
                )
            };
            let header = format!(
                "# eval: {}\n\nmethods {methods}, planner {navigation}, plan delay {:?}, time budget {} s, N = {}, Hessian {:?}, obstacles {:?} with margin {} m, SQP iterations {} × step {}, gain estimation {}, delay estimation {}, delay {delay} s, lag {lag} s, plant perturbation: {}, tolerance {}, networks: {}, machine (MPC, plant and min-time bound): {}\n",
                scenarios.display(),
                cfg.plan_delay,
                cfg.mpc.time_budget,
                cfg.mpc.horizon,
                cfg.mpc.hessian,
                cfg.mpc.obstacle_constraint,
                cfg.mpc.obstacle_margin,
                cfg.mpc.sqp_iterations,
                cfg.mpc.step_length,
                cfg.mpc.gain_estimation,
                cfg.mpc.delay_estimation,
                robustness::describe(&cfg.perturbation),
                common.tolerance,
                nets.source,
                cfg.params
            );
            eval::write_outputs(&ev, &out, &header, !no_scenario_plots)?;
            print!("{}", sim::results::summary_markdown(&ev.summaries));
            print!("{}", eval::timing_text(&ev));
            print!("{}", eval::navigation_text(&ev));
            print!("{}", eval::envelope_text(&ev));
            print!("{}", eval::assumptions_text(&ev));
            print!(
                "{}",
                eval::obstacle_rows_text(&ev, cfg.mpc.obstacle_slack_weight)
            );
            println!("wrote {}", out.join("results.csv").display());
        }
        Command::Paper {
            scenarios,
            highlighted,
            worksite,
            common,
            out,
        } => {
            let set = load_scenarios(&scenarios)?;
            let hl = load_scenarios(&highlighted)?;
            let mut site = Vec::new();
            for f in worksite.split(',').filter(|f| !f.trim().is_empty()) {
                site.extend(load_scenarios(Path::new(f.trim()))?);
            }
            let nets = networks(&common)?;
            let cfg = base_config(&common, &nets)?;
            let cmd = "cargo run --release -p sim --bin wlnav-sim -- paper";
            sim::report::paper(&cfg, &nets, &set, &hl, &site, &out, cmd)?;
        }
        Command::Robustness {
            scenarios,
            obstacles,
            obstacles_per_kind,
            subset_seed,
            t_star,
            no_estimation,
            name,
            shipped_envelope,
            common,
            out,
        } => {
            let paper = load_scenarios(&scenarios)?;
            let all_obstacles = load_scenarios(&obstacles)?;
            let (obst, note) = if obstacles_per_kind == 0 {
                let n = format!(
                    "`{}` ({} scenarios)",
                    obstacles.display(),
                    all_obstacles.len()
                );
                (all_obstacles, n)
            } else {
                let sub = robustness::subset(&all_obstacles, obstacles_per_kind, subset_seed);
                let n = format!(
                    "a seeded fixed subset of `{}`: {obstacles_per_kind} scenarios of each kind (seed {subset_seed}; {} of {}), \
                     the whole set being too slow for the 10-minute budget with every level",
                    obstacles.display(),
                    sub.len(),
                    all_obstacles.len()
                );
                (sub, n)
            };
            let text = std::fs::read_to_string(&t_star)
                .with_context(|| format!("reading {}", t_star.display()))?;
            let rows = sim::results::parse(&text, &t_star.display().to_string())?;
            let t_star_map = rows
                .iter()
                .filter(|r| r.method == "min-time" && r.success)
                .filter_map(|r| Some((r.name.clone(), r.t_converge?)))
                .collect();
            let nets = networks(&common)?;
            let commit = std::process::Command::new("git")
                .args(["rev-parse", "--short", "HEAD"])
                .output()
                .ok()
                .filter(|o| o.status.success())
                .map_or("unknown".into(), |o| {
                    String::from_utf8_lossy(&o.stdout).trim().to_string()
                });
            let mut command =
                String::from("cargo run --release -p sim --bin wlnav-sim -- robustness");
            for a in std::env::args().skip(2) {
                command.push(' ');
                command.push_str(&a);
            }
            let mut base = base_config(&common, &nets)?;
            base.mpc.gain_estimation &= !no_estimation;
            base.mpc.delay_estimation &= !no_estimation;
            let inputs = robustness::Inputs {
                base,
                name,
                nets: &nets,
                paper: &paper,
                paper_name: format!("`{}`", scenarios.display()),
                obstacles: &obst,
                obstacles_note: note,
                t_star: t_star_map,
                t_star_source: t_star.display().to_string(),
                command,
                commit,
                shipped_envelope,
            };
            robustness::robustness(&inputs, &robustness::standard_sweeps(), &out)?;
        }
        Command::Scenarios { out } => {
            std::fs::create_dir_all(&out)?;
            for (name, set) in [
                ("paper128.csv", scenario::paper_scenarios()),
                ("selection64.csv", scenario::selection_scenarios(64, 1)),
                (
                    "obstacles200.csv",
                    scenario::obstacle_scenarios(50, OBSTACLES_SEED, &MachineParams::default()),
                ),
                (
                    "obstacles-tuning100.csv",
                    scenario::obstacle_scenarios(
                        25,
                        OBSTACLES_TUNING_SEED,
                        &MachineParams::default(),
                    ),
                ),
            ] {
                let path = out.join(name);
                std::fs::write(&path, scenario::to_csv(&set))?;
                println!("wrote {}", path.display());
            }
        }
    }
    Ok(())
}

/// `--plan-delay`: seconds, or `measured`.
fn parse_plan_delay(s: &str) -> Result<PlanDelay, String> {
    if s == "measured" {
        return Ok(PlanDelay::Measured);
    }
    robustness::parse_seconds(s).map(PlanDelay::Fixed)
}
