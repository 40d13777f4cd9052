//! The closed-loop runner: every scenario × method, scenarios in parallel on
//! worker threads, with a progress bar.
//!
//! - `mpc`: [`control::mpc::Mpc`] with the critic on [`control::plant::Plant`]
//!   (ideal, or with delay and velocity lag; the MPC compensates the configured
//!   delay). One tick every Δt = 0.2 s for 30 s.
//! - `actor`: the actor's deterministic action, sent as the velocity of the
//!   model's next state, on the same plant (delay compensated the same way).
//! - `baseline`: [`trajopt::ocp::solve_baseline`], its open-loop controls replayed
//!   on the ideal model.
//! - `min-time`: [`trajopt::ocp::solve_min_time`] from several initial guesses
//!   (the other methods' converged trajectories among them).
//!
//! Every trajectory is sampled every 0.2 s (min-time at its own step) and
//! scored the same way ([`score`]).

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use control::assumption_check;
use control::delay::{compensate_pose_age, DelayCompensator};
use control::envelope::EnvelopeSettings;
use control::mlp::PAPER_HIDDEN;
use control::model::{
    converged, env_step, ix, Control, Goal, MachineParams, State, REACH_SPEED, SUCCESS_TOLERANCE,
};
use control::mpc::{FallbackReason, Mpc, MpcSettings, StepStatus};
use control::pilot::{Pilot, PilotDecision};
use control::planner::{
    AbortReason, InlineRoutes, Navigator, NavigatorSettings, PlanDelay, PlanOutcome, RoutePlanner,
    TrajectoryOutcome,
};
use control::plant::{Plant, PlantConfig, PlantPerturbation};
use control::progress::ProgressSettings;
use control::scenario::Scenario;
use control::weights::{self, random_network, NetworkMetadata, NetworkRole};
use control::VelocityCommand;
use control::{Actor, ActorWorkspace, Critic};
use indicatif::{ProgressBar, ProgressStyle};

use crate::clearance::ClearanceMeter;
use crate::movers::{Mover, MoverMeter, Perception, PerceptionSettings};
use crate::results::ResultRow;
use control::live::LiveSettings;
use control::site::{Outline, SiteIndex};
use control::world::{default_outline, World};
use std::sync::Arc;
use trajopt::ocp::{self, BaselineSettings, Guess, MinTimeSettings};
use trajopt::trajectory::{IpoptTrajectory, TrajectorySettings};

/// How long a run with [`EvalConfig::end_at_rest`] must stay converged and at rest [s].
pub const AT_REST_FOR: f64 = 1.0;

/// The plant of one scenario: `cfg.plant` changed by `cfg.perturbation`.
fn scenario_plant(cfg: &EvalConfig, sc: &Scenario) -> Result<Plant> {
    Ok(Plant::perturbed(
        cfg.params,
        cfg.plant,
        cfg.perturbation.seeded_for(&sc.name),
        sc.start,
    )?)
}

/// Counts ticks converged at rest, for [`EvalConfig::end_at_rest`].
struct RestCounter {
    ticks: usize,
    needed: Option<usize>,
}

impl RestCounter {
    fn new(cfg: &EvalConfig, dt: f64) -> Self {
        Self {
            ticks: 0,
            needed: cfg.end_at_rest.then(|| (AT_REST_FOR / dt).round() as usize),
        }
    }

    /// Takes the true state of a tick; true when the run may end.
    fn done(&mut self, x: &State, goal: &Goal, tolerance: f64) -> bool {
        let Some(n) = self.needed else { return false };
        if converged(x, goal, tolerance) && x[ix::V].abs() < REACH_SPEED {
            self.ticks += 1;
        } else {
            self.ticks = 0;
        }
        self.ticks > n
    }
}

/// An evaluated method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Mpc,
    Actor,
    Baseline,
    MinTime,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Mpc => "mpc",
            Method::Actor => "actor",
            Method::Baseline => "baseline",
            Method::MinTime => "min-time",
        }
    }

    pub fn parse(s: &str) -> Result<Self> {
        Ok(match s.trim() {
            "mpc" => Method::Mpc,
            "actor" => Method::Actor,
            "baseline" => Method::Baseline,
            "min-time" | "mintime" => Method::MinTime,
            other => bail!("unknown method `{other}` (expected mpc, actor, baseline, min-time)"),
        })
    }

    /// A comma-separated list; min-time is moved last (it uses the others' trajectories).
    pub fn parse_list(s: &str) -> Result<Vec<Self>> {
        let mut v: Vec<Method> = s
            .split(',')
            .filter(|t| !t.trim().is_empty())
            .map(Method::parse)
            .collect::<Result<_>>()?;
        v.dedup();
        v.sort_by_key(|m| *m == Method::MinTime);
        if v.is_empty() {
            bail!("no method given");
        }
        Ok(v)
    }
}

/// The trained networks (or random ones, before training).
#[derive(Debug, Clone)]
pub struct Networks {
    pub critic: Critic,
    pub actor: Actor,
    /// Where they came from (for reports).
    pub source: String,
    pub random: bool,
    /// The machine and Δt they were trained for (their metadata): the evaluation runs
    /// that machine.
    pub machine: MachineParams,
    pub dt: f64,
}

impl Networks {
    /// Loads `dir/critic.safetensors` and `dir/actor.safetensors` (one machine's
    /// directory, e.g. `critic-weights/avant635`); refuses an actor trained for
    /// another machine or Δt than the critic.
    pub fn load(dir: &Path) -> Result<Self> {
        let critic_w = weights::load(&dir.join(weights::CRITIC_FILE), NetworkRole::Critic)?;
        let (machine, dt) = (critic_w.meta.machine, critic_w.meta.dt);
        let actor_w = weights::load_for(
            &dir.join(weights::ACTOR_FILE),
            NetworkRole::Actor,
            &machine,
            dt,
        )
        .with_context(|| {
            format!(
                "{}: actor and critic disagree (the critic's machine and Δt are the configured ones)",
                dir.display()
            )
        })?;
        Ok(Self {
            critic: Critic::from_weights(critic_w)?,
            actor: Actor::from_weights(actor_w)?,
            source: dir.display().to_string(),
            random: false,
            machine,
            dt,
        })
    }

    /// Refuses a machine or Δt other than the networks were trained for (the
    /// encoder scales by the machine's bounds): the message names both values.
    pub fn check_for(&self, machine: &MachineParams, dt: f64) -> Result<()> {
        self.critic
            .metadata()
            .check_compatible(machine, dt)
            .map_err(|p| {
                anyhow::anyhow!(
                    "networks {}: the evaluation's machine or Δt is not theirs: {p}",
                    self.source
                )
            })
    }

    /// Random networks of the paper's sizes (they do not reach goals).
    pub fn random(seed: u64) -> Self {
        let c = random_network(
            NetworkMetadata::new(NetworkRole::Critic, 1),
            &PAPER_HIDDEN,
            seed,
        );
        let a = random_network(
            NetworkMetadata::new(NetworkRole::Actor, 4),
            &PAPER_HIDDEN,
            seed + 1,
        );
        Self {
            critic: Critic::from_weights(c).expect("random critic is valid"),
            actor: Actor::from_weights(a).expect("random actor is valid"),
            source: format!("random weights (seed {seed})"),
            random: true,
            machine: MachineParams::default(),
            dt: MpcSettings::default().dt,
        }
    }
}

/// Everything an evaluation is configured by.
#[derive(Debug, Clone)]
pub struct EvalConfig {
    pub params: MachineParams,
    pub methods: Vec<Method>,
    /// MPC settings; `delay` is overwritten with `plant.delay`.
    pub mpc: MpcSettings,
    /// The plant as the MPC knows it: its `delay` is the one compensated.
    pub plant: PlantConfig,
    /// How the real machine differs (DESIGN §12); its noise seed is mixed with
    /// each scenario's name. Success, times and clearance are judged on the
    /// plant's true state and geometry.
    pub perturbation: PlantPerturbation,
    /// End a closed-loop run once the true state has stayed inside the success
    /// test at rest (|v_f| < [`REACH_SPEED`]) for [`AT_REST_FOR`] (the
    /// robustness sweep; `t_settle` is then not reported).
    pub end_at_rest: bool,
    /// Success-test tolerance (DESIGN §7: 0.1).
    pub tolerance: f64,
    /// Simulated duration of closed-loop runs [s] (DESIGN §7: 30).
    pub duration: f64,
    pub baseline: BaselineSettings,
    pub min_time: MinTimeSettings,
    /// The global layer above the MPC (DESIGN §10); `None` drives the MPC
    /// straight to the goal.
    pub navigator: Option<NavigatorSettings>,
    /// How a route plan's time is charged (the daemon plans on a thread of its
    /// own: an answer at the next tick). Default one tick, so the evaluation is
    /// deterministic and honest.
    pub plan_delay: PlanDelay,
    /// How the planner's trajectory is optimised, where the navigator's
    /// settings ask for one (`NavigatorSettings::trajectory`, issue 42).
    pub trajectory: TrajectorySettings,
    /// The safety envelope after the MPC (DESIGN §14), as the daemon runs it;
    /// its tolerances also widen the MPC's planned clearances.
    pub envelope: EnvelopeSettings,
    /// The site every scenario runs in (DESIGN §17: `--site`), on top of the
    /// scenario's own circles.
    pub site: Option<Arc<SiteIndex>>,
    /// The machine's outline (`--outline`; default: a circle of the
    /// half-width at each axle).
    pub outline: Outline,
    /// Things that move (DESIGN §18, `--movers`): every scenario gets them,
    /// seen through `perception`, kept off by the pilot with `live`.
    pub movers: Option<Arc<Vec<Mover>>>,
    pub perception: PerceptionSettings,
    pub live: LiveSettings,
    /// Worker threads.
    pub jobs: usize,
    pub progress: bool,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            params: MachineParams::default(),
            methods: vec![
                Method::Mpc,
                Method::Actor,
                Method::Baseline,
                Method::MinTime,
            ],
            mpc: MpcSettings {
                delay: 0.0,
                ..Default::default()
            },
            plant: PlantConfig::ideal(),
            perturbation: PlantPerturbation::default(),
            end_at_rest: false,
            tolerance: SUCCESS_TOLERANCE,
            duration: 30.0,
            baseline: BaselineSettings::default(),
            min_time: MinTimeSettings::default(),
            navigator: Some(NavigatorSettings::default()),
            plan_delay: PlanDelay::Fixed(MpcSettings::default().dt),
            // The daemon's, but for the CPU-time backstop: the iteration budget
            // decides, and the evaluation's own load (its jobs, other work on
            // the machine) cannot (on this machine the backstop never binds:
            // `docs/global-layer.md`).
            trajectory: TrajectorySettings {
                max_solve_seconds: 10.0,
                ..TrajectorySettings::default()
            },
            envelope: EnvelopeSettings::default(),
            site: None,
            outline: default_outline(),
            movers: None,
            perception: PerceptionSettings::default(),
            live: LiveSettings::default(),
            jobs: std::thread::available_parallelism().map_or(2, |n| n.get()),
            progress: true,
        }
    }
}

/// One method on one scenario.
#[derive(Debug, Clone)]
pub struct Run {
    pub row: ResultRow,
    /// The trajectory, sampled every `dt`.
    pub states: Vec<State>,
    pub dt: f64,
    /// Individual solve times [ms] (per tick, or per NLP solve).
    pub solve_ms: Vec<f64>,
    /// Wall time of the whole run [s].
    pub wall_s: f64,
    /// What the global layer did (MPC runs with a navigator only).
    pub navigation: Option<Navigation>,
    /// Ticks whose command the safety envelope replaced (MPC runs).
    pub envelope_overrides: usize,
    /// Ticks whose plan penetrated a circle and was discarded (MPC runs).
    pub penetrating_plans: usize,
    /// Largest per-stage sum of obstacle-row multipliers over the run's QPs
    /// (MPC runs): the obstacle slack weight must exceed it (DESIGN §14).
    pub obstacle_multiplier_max: f64,
    /// The envelope's assumptions the machine broke (MPC runs, issue 43):
    /// when, what, and what the pilot did (widened the envelope, or stopped).
    pub assumption_findings: Vec<(f64, assumption_check::Finding, assumption_check::Decision)>,
}

/// The global layer's record of one run.
#[derive(Debug, Clone, Default)]
pub struct Navigation {
    /// Every route it handed the MPC (the goal's plan, then each replan),
    /// subgoals ending with the goal.
    pub routes: Vec<Vec<Goal>>,
    /// Duration of every plan [ms] (the "in the way" test and the search).
    pub plan_ms: Vec<f64>,
    /// When each plan was made [s] (the goal's at 0).
    pub plan_at: Vec<f64>,
    /// Each plan's search: (expansions, shots or edge checks).
    pub plan_work: Vec<(usize, usize)>,
    /// How each plan ended (direct, route, no route, retry).
    pub plan_outcome: Vec<PlanOutcome>,
    /// Whether each plan's route was shaped into a trajectory, or why not.
    pub plan_trajectory: Vec<TrajectoryOutcome>,
    /// Duration of every tick of the pilot [ms] (navigator, MPC, envelope;
    /// plans run beside it and are charged as simulated delay).
    pub tick_ms: Vec<f64>,
    /// Why the navigator ended the run, if it did.
    pub abort: Option<AbortReason>,
    /// Tick at which it aborted.
    pub aborted_at: Option<f64>,
}

impl Navigation {
    /// Records the navigator's latest plan if it is new.
    fn record_plan(&mut self, nav: &Navigator, seen: &mut u64, now: f64) {
        if nav.plans() != *seen {
            *seen = nav.plans();
            if let Some(r) = nav.last_plan() {
                self.plan_ms.push(r.duration.as_secs_f64() * 1e3);
                self.plan_work.push((r.search.expansions, r.search.shots));
                self.plan_outcome.push(r.outcome);
                self.plan_trajectory.push(r.trajectory);
            }
            self.plan_at.push(now);
            self.routes.push(nav.route().to_vec());
        }
    }
}

/// All methods on one scenario.
#[derive(Debug, Clone)]
pub struct ScenarioRuns {
    pub scenario: Scenario,
    pub runs: Vec<(Method, Run)>,
}

/// Scores a trajectory sampled every `dt` (DESIGN §7); `min_clearance` is
/// measured by the caller between the samples ([`ClearanceMeter`]).
pub fn score(
    sc: &Scenario,
    method: &str,
    states: &[State],
    dt: f64,
    tolerance: f64,
    solve_ms: &[f64],
    min_clearance: Option<f64>,
) -> ResultRow {
    let inside = |x: &State| converged(x, &sc.goal, tolerance);
    let first = states.iter().position(inside);
    // Sample instants, free of the round-off of k·Δt.
    let at = |k: usize| (k as f64 * dt * 1e9).round() / 1e9;
    let t_converge = first.map(at);
    let t_settle = first.map(|_| {
        let last_bad = states
            .iter()
            .rposition(|x| !inside(x) || x[ix::V].abs() >= REACH_SPEED);
        last_bad.map_or(0.0, |k| at(k + 1))
    });
    // A run that never stays inside and slow by its end has not settled.
    let t_settle = t_settle.filter(|t| *t < states.len() as f64 * dt - 1e-9 || states.len() == 1);
    let upto = first.map_or(states.len(), |k| k + 1);
    let path_length = states[..upto]
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    let (median, max) = if solve_ms.is_empty() {
        (0.0, 0.0)
    } else {
        (
            crate::results::quantile(solve_ms, 0.5),
            solve_ms.iter().cloned().fold(0.0, f64::max),
        )
    };
    ResultRow {
        name: sc.name.clone(),
        method: method.to_string(),
        success: first.is_some(),
        t_converge,
        t_settle,
        path_length,
        min_clearance,
        solve_ms_median: median,
        solve_ms_max: max,
        min_clearance_moving: None,
        protective_stops: None,
    }
}

/// The pilot `wlnav-sim` runs: the one the daemon runs (navigator, MPC,
/// envelope), its routes planned inline and charged as `cfg.plan_delay`.
pub fn pilot(cfg: &EvalConfig, nets: &Networks) -> Result<Pilot<Critic>> {
    let settings = MpcSettings {
        delay: cfg.plant.delay,
        ..cfg.mpc
    }
    .widened(cfg.envelope.tolerance_widening(&cfg.params));
    let mpc = Mpc::new(
        cfg.params,
        nets.critic.clone(),
        Some(nets.actor.clone()),
        settings,
    )?;
    let navigator = match &cfg.navigator {
        Some(s) => {
            // Widened as the daemon widens it (`Config::navigator_settings`).
            let s = &s
                .clone()
                .widened(cfg.envelope.tolerance_widening(&cfg.params));
            let mut planner = RoutePlanner::new(cfg.params, s, Some(nets.actor.clone()))?;
            if s.trajectory {
                let optimiser = IpoptTrajectory::new(cfg.params, cfg.trajectory);
                planner = planner.with_trajectory(Box::new(optimiser));
            }
            let routes = Box::new(InlineRoutes::new(planner, cfg.plan_delay));
            Some(Navigator::with_routes(
                cfg.params,
                s.clone(),
                Some(&nets.critic),
                routes,
            )?)
        }
        None => None,
    };
    // The goal's progress window: the navigator's (stall.progress), the
    // daemon's default without one.
    let progress = cfg
        .navigator
        .as_ref()
        .map_or_else(ProgressSettings::default, |s| s.stall.progress);
    let mut pilot = Pilot::new(cfg.params, mpc, navigator, cfg.envelope, progress)?;
    pilot.set_outline(cfg.outline.clone());
    pilot.set_site(cfg.site.clone());
    if cfg.movers.is_some() {
        pilot.enable_live(cfg.live)?;
    }
    Ok(pilot)
}

/// The MPC (the pilot) in closed loop with the plant.
pub fn run_mpc(cfg: &EvalConfig, nets: &Networks, sc: &Scenario) -> Result<Run> {
    let start = Instant::now();
    let mut pilot = pilot(cfg, nets)?;
    let dt = pilot.mpc().settings().dt;
    let mut navigation = cfg.navigator.as_ref().map(|_| Navigation::default());
    let mut plans_seen = 0;
    let mut plant = scenario_plant(cfg, sc)?;
    let steps = (cfg.duration / dt).round() as usize;
    let mut states = Vec::with_capacity(steps + 1);
    let mut solve_ms = Vec::with_capacity(steps);
    let mut clearance = meter(cfg, *plant.params(), sc);
    clearance.observe(&plant.state());
    let no_movers = Vec::new();
    let movers = cfg.movers.as_deref().unwrap_or(&no_movers);
    let mut perception = Perception::new(movers, cfg.perception, &sc.name);
    let mut moving = MoverMeter::new(movers, World::new(*plant.params(), cfg.outline.clone(), 0));
    let mut protective_stops = 0;
    let mut held = false;
    let mut rest = RestCounter::new(cfg, dt);
    let mut aborted = false;
    let mut overrides = 0;
    let mut findings = Vec::new();
    let (mut penetrating_plans, mut multiplier_max) = (0, 0.0f64);
    for k in 0..=steps {
        // The pose is stamped: its age is known and compensated, as in the
        // daemon (DESIGN §14).
        let x = compensate_pose_age(
            &cfg.params,
            &plant.measure(),
            plant.perturbation().pose_latency,
        );
        states.push(plant.state());
        if k == steps || rest.done(&plant.state(), &sc.goal, cfg.tolerance) {
            break;
        }
        let now = k as f64 * dt;
        if k == 0 {
            pilot
                .set_goal(&x, sc.goal, &sc.obstacles, now)
                .with_context(|| format!("scenario {}", sc.name))?;
            // What perception delivered before the goal (its pre-roll).
            while let Some((_, set)) = perception.next_delivery(now) {
                pilot.set_live(set);
            }
        }
        let cmd = if aborted {
            // An aborted goal ends the run: the machine is commanded to rest
            // (the plant ramps down within its limits).
            VelocityCommand::ZERO
        } else {
            let t0 = Instant::now();
            let decision = pilot.step(&x, now, t0)?;
            let elapsed = t0.elapsed();
            let cmd = match decision {
                PilotDecision::Abort(reason) => {
                    if let Some(rec) = navigation.as_mut() {
                        rec.abort = Some(reason);
                        rec.aborted_at = Some(now);
                    }
                    aborted = true;
                    VelocityCommand::ZERO
                }
                PilotDecision::Stop { finding, .. } => {
                    tracing_note(&format!("{} at {now:.1} s: {finding}: stop", sc.name));
                    findings.push((now, finding, assumption_check::Decision::Stop));
                    aborted = true;
                    VelocityCommand::ZERO
                }
                PilotDecision::Drive(p) => {
                    if let (Some(f), assumption_check::Decision::Widen) =
                        (p.assumptions.finding, p.assumptions.decision)
                    {
                        tracing_note(&format!("{} at {now:.1} s: {f}: widened", sc.name));
                        findings.push((now, f, assumption_check::Decision::Widen));
                    }
                    if let Some(sol) = p.solution {
                        solve_ms.push(sol.solve_time.as_secs_f64() * 1e3);
                        penetrating_plans += usize::from(
                            sol.status == StepStatus::Fallback(FallbackReason::PlanPenetrates),
                        );
                        multiplier_max = multiplier_max.max(sol.obstacle_multiplier);
                    }
                    overrides += usize::from(p.guarded.overridden());
                    let holding = p.live.is_some_and(|l| l.holding);
                    protective_stops += usize::from(holding && !held);
                    held = holding;
                    p.command
                }
            };
            // The tick without the route searches the inline planner ran in
            // it (charged as simulated delay; the daemon runs them on the
            // planner thread): what the daemon's tick costs.
            let on_tick = pilot.take_plan_time_on_tick();
            if let Some(rec) = navigation.as_mut() {
                rec.tick_ms
                    .push(elapsed.saturating_sub(on_tick).as_secs_f64() * 1e3);
            }
            cmd
        };
        if let (Some(nav), Some(rec)) = (pilot.navigator(), navigation.as_mut()) {
            rec.record_plan(nav, &mut plans_seen, now);
        }
        plant.command(cmd)?;
        pilot.sent(now, cmd);
        // The sets perception delivers during the tick, each checked when it
        // arrives: a stop it calls for is sent then, not at the next tick.
        let end = now + dt;
        let mut t = now;
        loop {
            let next = if aborted {
                None
            } else {
                perception.next_delivery(end)
            };
            let until = next.as_ref().map_or(end, |(at, _)| at.max(t));
            plant.advance_observed(until - t, |at, x| {
                clearance.observe(x);
                moving.observe(at, x);
            });
            t = until;
            let Some((_, set)) = next else { break };
            pilot.set_live(set);
            let x = compensate_pose_age(
                &cfg.params,
                &plant.measure(),
                plant.perturbation().pose_latency,
            );
            if let Some(g) = pilot.check_live(&x, t) {
                plant.command(g.command)?;
                pilot.sent(t, g.command);
                if g.overridden() {
                    protective_stops += usize::from(!held);
                    held = true;
                }
            }
        }
    }
    let mut row = score(
        sc,
        Method::Mpc.name(),
        &states,
        dt,
        cfg.tolerance,
        &solve_ms,
        clearance.finish(),
    );
    if cfg.movers.is_some() {
        row.min_clearance_moving = moving.finish();
        row.protective_stops = Some(protective_stops);
    }
    Ok(Run {
        row,
        states,
        dt,
        solve_ms,
        wall_s: start.elapsed().as_secs_f64(),
        navigation,
        envelope_overrides: overrides,
        penetrating_plans,
        obstacle_multiplier_max: multiplier_max,
        assumption_findings: findings,
    })
}

/// The actor alone in closed loop with the plant.
pub fn run_actor(cfg: &EvalConfig, nets: &Networks, sc: &Scenario) -> Result<Run> {
    let start = Instant::now();
    let dt = cfg.mpc.dt;
    let mut ws = ActorWorkspace::new(&nets.actor);
    let mut delay = DelayCompensator::new(cfg.params, cfg.plant.delay, dt)?;
    let mut plant = scenario_plant(cfg, sc)?;
    let steps = (cfg.duration / dt).round() as usize;
    let mut states = Vec::with_capacity(steps + 1);
    let mut solve_ms = Vec::with_capacity(steps);
    let mut clearance = meter(cfg, *plant.params(), sc);
    clearance.observe(&plant.state());
    let mut rest = RestCounter::new(cfg, dt);
    for k in 0..=steps {
        let x = plant.measure();
        states.push(plant.state());
        if k == steps || rest.done(&plant.state(), &sc.goal, cfg.tolerance) {
            break;
        }
        let t0 = Instant::now();
        let now = k as f64 * dt;
        let x_hat = delay.propagate(now, &x);
        let u = nets.actor.action(&mut ws, &x_hat, &sc.goal);
        let next = env_step(&cfg.params, &x_hat, &u, dt);
        let cmd = VelocityCommand {
            beta_dot: next[ix::BETA_DOT],
            v: next[ix::V],
        };
        delay.record(now, cmd);
        solve_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        plant.command(cmd)?;
        plant.advance_observed(dt, |_, x| clearance.observe(x));
    }
    let row = score(
        sc,
        Method::Actor.name(),
        &states,
        dt,
        cfg.tolerance,
        &solve_ms,
        clearance.finish(),
    );
    Ok(Run {
        row,
        states,
        dt,
        solve_ms,
        wall_s: start.elapsed().as_secs_f64(),
        navigation: None,
        envelope_overrides: 0,
        penetrating_plans: 0,
        obstacle_multiplier_max: 0.0,
        assumption_findings: Vec::new(),
    })
}

/// The baseline: solve, then replay its controls on the ideal model.
pub fn run_baseline(cfg: &EvalConfig, sc: &Scenario) -> Result<(Run, ocp::Plan)> {
    let start = Instant::now();
    let plan = ocp::solve_baseline(&cfg.params, sc, &cfg.baseline);
    let states = ocp::replay(
        &cfg.params,
        &plan.states[0],
        &plan.controls,
        plan.dt,
        cfg.duration,
    );
    let solve_ms = vec![plan.solve_time.as_secs_f64() * 1e3];
    let mut row = score(
        sc,
        Method::Baseline.name(),
        &states,
        plan.dt,
        cfg.tolerance,
        &solve_ms,
        plan_clearance(cfg, sc, &states, &plan.controls, plan.dt),
    );
    if !plan.status.success() {
        // A failed solve's controls may still converge; keep the replay's verdict
        // but say so in the log.
        tracing_note(&format!(
            "baseline {}: IPOPT {}",
            sc.name,
            plan.status.name()
        ));
    }
    row.success &= plan.violation < 1e-3;
    Ok((
        Run {
            row,
            states,
            dt: plan.dt,
            solve_ms,
            wall_s: start.elapsed().as_secs_f64(),
            navigation: None,
            envelope_overrides: 0,
            penetrating_plans: 0,
            obstacle_multiplier_max: 0.0,
            assumption_findings: Vec::new(),
        },
        plan,
    ))
}

/// Footprint clearance of an open-loop plan (states every `dt` under
/// piecewise-constant `controls`), each interval sub-divided; past the
/// controls' end (the machine braking at its goal) the samples alone.
fn plan_clearance(
    cfg: &EvalConfig,
    sc: &Scenario,
    states: &[State],
    controls: &[Control],
    dt: f64,
) -> Option<f64> {
    let mut meter = meter(cfg, cfg.params, sc);
    for (k, x) in states.iter().enumerate() {
        match controls.get(k) {
            Some(u) if k + 1 < states.len() => meter.observe_interval(x, u, dt),
            _ => meter.observe(x),
        }
    }
    meter.finish()
}

/// Features farther than this from the start–goal segment are left out of
/// the bound's problem [m] (leaving constraints out keeps it a lower bound).
const BOUND_FEATURE_REACH: f64 = 10.0;

/// The scenario the minimum-time bound is solved for (DESIGN §17): with a
/// site, its features near the start–goal segment added as circles, each
/// its inscribed circle ([`control::site::Shape::inscribed_circle`]) grown
/// by the disc the outline surely covers around each axle. Every point of
/// such a circle is inside the feature or within that disc, so any motion of
/// the machine that keeps its outline off the feature keeps its axle points
/// off the circle: the problem is a relaxation and T* stays a lower bound.
/// The site's bounds are left out (a relaxation too).
pub fn bound_scenario(cfg: &EvalConfig, sc: &Scenario) -> Scenario {
    let mut out = sc.clone();
    let Some(site) = &cfg.site else {
        return out;
    };
    let o = &cfg.outline;
    let axle_disc = o
        .axle_radius(control::site::Body::Front)
        .min(o.axle_radius(control::site::Body::Rear));
    let a = [
        sc.start[control::model::ix::X],
        sc.start[control::model::ix::Y],
    ];
    let b = [sc.goal.x, sc.goal.y];
    for f in site.site().features() {
        let c = f.shape.inscribed_circle();
        let (_, d) = control::site::geometry::closest_on_segment(c.center, a, b);
        if d - c.radius <= BOUND_FEATURE_REACH {
            out.obstacles.push(control::Obstacle::new(
                c.center[0],
                c.center[1],
                c.radius + axle_disc,
            ));
        }
    }
    out
}

/// The clearance meter of a run: the site of `cfg` and the scenario's
/// circles, against the outline on the machine `params`.
fn meter(cfg: &EvalConfig, params: MachineParams, sc: &Scenario) -> ClearanceMeter {
    let mut world = World::new(params, cfg.outline.clone(), sc.obstacles.len());
    world
        .set_circles(&sc.obstacles)
        .expect("a scenario's circles are validated when parsed");
    world.set_site(cfg.site.clone());
    ClearanceMeter::new(world)
}

fn tracing_note(msg: &str) {
    eprintln!("note: {msg}");
}

/// Converts a 0.2 s trajectory that converged into a min-time initial guess.
fn guess_from(run: &Run) -> Option<Guess> {
    let t = run.row.t_converge?;
    if t <= 0.0 {
        return None;
    }
    let controls = run
        .states
        .windows(2)
        .map(|w| {
            Control::new(
                (w[1][ix::BETA_DOT] - w[0][ix::BETA_DOT]) / run.dt,
                (w[1][ix::V] - w[0][ix::V]) / run.dt,
            )
        })
        .collect();
    Some(Guess {
        states: run.states.clone(),
        controls,
        dt: run.dt,
        duration: t,
    })
}

/// The min-time bound, seeded with the other methods' converged trajectories.
pub fn run_min_time(cfg: &EvalConfig, sc: &Scenario, others: &[(Method, Run)]) -> Result<Run> {
    let start = Instant::now();
    let guesses: Vec<Guess> = others.iter().filter_map(|(_, r)| guess_from(r)).collect();
    let s = MinTimeSettings {
        tolerance: cfg.tolerance,
        ..cfg.min_time
    };
    let bound_sc = bound_scenario(cfg, sc);
    let r = ocp::solve_min_time(&cfg.params, &bound_sc, &s, &guesses);
    let solve_ms = vec![r.solve_time.as_secs_f64() * 1e3];
    let (states, dt) = match &r.plan {
        Some(p) => (p.states.clone(), p.dt),
        None => (vec![sc.start], cfg.mpc.dt),
    };
    let controls = r.plan.as_ref().map_or(&[][..], |p| &p.controls[..]);
    let mut row = score(
        sc,
        Method::MinTime.name(),
        &states,
        dt,
        cfg.tolerance,
        &solve_ms,
        plan_clearance(cfg, sc, &states, controls, dt),
    );
    // The bound is T*, reached at the last node (the test is held at 0.999 × tol).
    row.success = r.plan.is_some();
    row.t_converge = r.plan.as_ref().map(|_| r.time);
    row.t_settle = None;
    if row.success {
        row.path_length = states
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum();
    }
    Ok(Run {
        row,
        states,
        dt,
        solve_ms,
        wall_s: start.elapsed().as_secs_f64(),
        navigation: None,
        envelope_overrides: 0,
        penetrating_plans: 0,
        obstacle_multiplier_max: 0.0,
        assumption_findings: Vec::new(),
    })
}

/// All configured methods on one scenario.
pub fn run_scenario(cfg: &EvalConfig, nets: &Networks, sc: &Scenario) -> Result<ScenarioRuns> {
    let mut runs: Vec<(Method, Run)> = Vec::new();
    for &m in &cfg.methods {
        let run = match m {
            Method::Mpc => run_mpc(cfg, nets, sc)?,
            Method::Actor => run_actor(cfg, nets, sc)?,
            Method::Baseline => run_baseline(cfg, sc)?.0,
            Method::MinTime => run_min_time(cfg, sc, &runs)?,
        };
        runs.push((m, run));
    }
    Ok(ScenarioRuns {
        scenario: sc.clone(),
        runs,
    })
}

/// Runs every scenario on `cfg.jobs` threads; results in scenario order.
pub fn run_all(
    cfg: &EvalConfig,
    nets: &Networks,
    scenarios: &[Scenario],
) -> Result<Vec<ScenarioRuns>> {
    nets.check_for(&cfg.params, cfg.mpc.dt)?;
    let bar = if cfg.progress {
        ProgressBar::new(scenarios.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} scenarios ({eta}) {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<Result<ScenarioRuns>>>> =
        Mutex::new((0..scenarios.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..cfg.jobs.max(1) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= scenarios.len() {
                    break;
                }
                let r = run_scenario(cfg, nets, &scenarios[i]);
                bar.set_message(scenarios[i].name.clone());
                bar.inc(1);
                out.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
            });
        }
    });
    bar.finish_and_clear();
    out.into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .zip(scenarios)
        .map(|(r, sc)| r.unwrap_or_else(|| bail!("scenario {} was not run", sc.name)))
        .collect()
}
