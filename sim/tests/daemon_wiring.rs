//! The daemon's controller and `wlnav-sim`'s pilot are the same controller
//! (issue 44): built from the same settings, one by `wlnavd`'s own loading
//! (`wlnavd::controller::load_controller` from a `wlnavd::config::Config`, its
//! routes on the planner thread), the other by `sim::runner::pilot` from an
//! `EvalConfig` (routes planned inline, charged one tick), they give
//! bit-identical commands on the same measured states, the route's arrival
//! included. So an evaluation measures what the daemon runs: a setting wired
//! on one side only (the MPC's or the navigator's clearance widening, the
//! envelope, the progress window, the compensated delay) fails here.
//!
//! Deterministic: the MPC's time budget is made large on both sides (no
//! solve is cut by the wall clock), and after each tick the planner thread's
//! plan is waited for, as a plan of milliseconds finishes inside a 200 ms
//! tick in the daemon (the sim charges it one tick).
//!
//! A dev-dependency of `sim` on `daemon` (this file only): the daemon never
//! links `sim`, so the dependencies still point one way (DESIGN §1).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use control::model::{Goal, State};
use control::obstacle::Obstacle;
use control::pilot::PilotDecision;
use control::planner::PlanDelay;
use control::plant::{Plant, PlantConfig};
use control::{weights, VelocityCommand};
use sim::runner::{self, EvalConfig, Networks};
use wlnavd::config::Config;
use wlnavd::controller::{load_controller, Controller, Step};

/// Ticks compared: the hold for the first route, the route's arrival, the
/// drive around the wall (12 s).
const TICKS: usize = 60;

/// Wall-clock limits are multiplied by `WLNAV_TIMING_SCALE` (slow or emulated machines).
#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `wlnavd --sim` without a configuration file: the built-in defaults, the
/// repository's shipped weights (critic-weights/avant635) and their machine.
/// The changes: a time budget no solve reaches, so the comparison does not
/// depend on the wall clock (the same value reaches both sides), and live
/// obstacles not required (no perception in either).
fn daemon_config() -> Config {
    let mut c = Config::default();
    c.resolve_paths(&[repo()]);
    c.adopt_trained_machine();
    c.mpc.time_budget = 10.0;
    // Nor the trajectory's: its iteration budget decides (the CPU backstop
    // would let a loaded machine cut the planner thread's solve only).
    c.trajectory.max_solve_seconds = 60.0;
    // No perception on either side: the sim's pilot runs without movers, and
    // the daemon's, without sets, would stop for stale perception.
    c.live.required = false;
    c.validate().expect("the defaults are valid");
    c
}

/// `wlnav-sim eval`'s configuration with the daemon's settings: its machine,
/// MPC, navigator and envelope; the plant as the MPC knows it compensates the
/// daemon's `mpc.delay` (the sim's pilot takes its delay from the plant); a
/// route is charged one tick, as the planner thread answers.
fn sim_config(c: &Config) -> EvalConfig {
    EvalConfig {
        params: c.machine,
        mpc: c.mpc,
        plant: PlantConfig {
            delay: c.mpc.delay,
            ..c.sim.plant
        },
        navigator: Some(c.navigator.clone()),
        trajectory: c.trajectory,
        plan_delay: PlanDelay::Fixed(c.period()),
        envelope: c.envelope,
        jobs: 1,
        progress: false,
        ..Default::default()
    }
}

/// A wall across the way to a goal 8 m ahead (7 circles of 0.6 m, 0.8 m
/// apart): the straight way is blocked, so the navigator plans a route.
fn wall() -> Vec<Obstacle> {
    (-3..=3)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect()
}

/// A command as bits: identical means identical, -0.0 is not 0.0.
fn bits(c: VelocityCommand) -> (u64, u64) {
    (c.beta_dot.to_bits(), c.v.to_bits())
}

/// What one side decided at a tick: the command and the route followed.
#[derive(Debug, Clone, PartialEq)]
struct Tick {
    command: VelocityCommand,
    route: Vec<Goal>,
    new_plan: bool,
}

fn daemon_tick(c: &mut dyn Controller, x: &State, now: f64) -> Tick {
    match c.step(x, now, Instant::now()).expect("daemon step") {
        Step::Drive(p) => Tick {
            command: p.command,
            route: p.route.to_vec(),
            new_plan: p.new_plan,
        },
        Step::Abort(r) => panic!("the daemon's controller aborted at {now:.1} s: {r:?}"),
        Step::AssumptionBroken { finding, .. } => {
            panic!("the daemon's controller stopped at {now:.1} s: {finding}")
        }
    }
}

/// The run: a plant (the daemon's simulated machine) driven by the daemon's
/// commands, limited as its loop sends them; both controllers see each
/// measured state and learn each command sent. Returns both sides' ticks.
fn run(config: &Config, eval: &EvalConfig) -> (Vec<Tick>, Vec<Tick>) {
    let factory = load_controller(config).expect("the daemon loads its controller");
    let mut daemon = factory().expect("the daemon builds its controller");
    let nets = Networks::load(&repo().join(weights::DEFAULT_DIR)).expect("the shipped weights");
    nets.check_for(&eval.params, eval.mpc.dt)
        .expect("the weights' machine");
    let mut pilot = runner::pilot(eval, &nets).expect("wlnav-sim builds its pilot");

    let params = config.machine;
    let dt = config.period();
    let mut plant = Plant::new(params, eval.plant, State::zeros()).unwrap();
    let goal = Goal::new(8.0, 0.0, 0.0);
    let wait = timing_scale::real(Duration::from_secs(60));
    let (mut ours, mut theirs) = (Vec::new(), Vec::new());
    for k in 0..TICKS {
        let now = k as f64 * dt;
        let x = plant.state();
        if k == 0 {
            // As the daemon's loop takes a new goal (control_loop.rs).
            daemon.reset();
            daemon.set_goal(&x, goal, &wall(), now).unwrap();
            pilot.set_goal(&x, goal, &wall(), now).unwrap();
        }
        let d = daemon_tick(daemon.as_mut(), &x, now);
        let s = match pilot.step(&x, now, Instant::now()).expect("sim step") {
            PilotDecision::Drive(p) => Tick {
                command: p.command,
                route: p.route.to_vec(),
                new_plan: p.new_plan,
            },
            PilotDecision::Abort(r) => panic!("wlnav-sim's pilot aborted at {now:.1} s: {r:?}"),
            PilotDecision::Stop { finding, .. } => {
                panic!("wlnav-sim's pilot stopped at {now:.1} s: {finding}")
            }
        };
        // What the daemon's loop sends (limited to the machine's bounds); the
        // sim sends its own command (the same, unless the wiring differs).
        let sent = d.command.limited(&params);
        daemon.sent(now, sent);
        pilot.sent(now, s.command);
        plant.command(sent).unwrap();
        plant.advance(dt);
        ours.push(d);
        theirs.push(s);
        // The rest of the tick: the planner thread's plan, asked for in this
        // tick, is back before the next (the daemon's 200 ms against a plan's
        // milliseconds; here waited for, so a slow machine cannot change it).
        let t0 = Instant::now();
        while daemon.planner_working() {
            assert!(t0.elapsed() < wait, "the planner thread took {wait:?}");
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    (ours, theirs)
}

/// The first tick at which the two sides differ, described.
fn first_difference(ours: &[Tick], theirs: &[Tick]) -> Option<String> {
    ours.iter().zip(theirs).enumerate().find_map(|(k, (d, s))| {
        (bits(d.command) != bits(s.command) || d.route != s.route || d.new_plan != s.new_plan)
            .then(|| {
                format!(
                    "tick {k}: daemon {:?} (route of {}, new plan {}), wlnav-sim {:?} (route of {}, new plan {})",
                    d.command,
                    d.route.len(),
                    d.new_plan,
                    s.command,
                    s.route.len(),
                    s.new_plan
                )
            })
    })
}

#[test]
fn the_daemons_controller_and_the_sims_pilot_give_identical_commands() {
    let config = daemon_config();
    let eval = sim_config(&config);
    let (ours, theirs) = run(&config, &eval);
    assert_eq!(ours.len(), TICKS);
    if let Some(diff) = first_difference(&ours, &theirs) {
        panic!("the daemon's controller and wlnav-sim's pilot differ at {diff}");
    }
    // What was compared: the hold while the first route is planned, the
    // route around the wall arriving at the next tick (the planner thread's
    // answer; the sim's one-tick charge), then driving on it.
    assert_eq!(ours[0].command, VelocityCommand::ZERO, "held for the route");
    assert!(ours[0].route.is_empty());
    assert!(ours[1].new_plan, "the route arrived at tick 1");
    assert!(
        ours[1].route.len() > 1,
        "a route around the wall, not the goal alone: {:?}",
        ours[1].route
    );
    assert!(
        ours.iter().any(|t| t.command.v > 0.3),
        "it drives: {:?}",
        ours.iter().map(|t| t.command.v).collect::<Vec<_>>()
    );
}

/// The same without the planner's min-time trajectory (`[navigator]
/// trajectory = false`; on by default, issue 42): the route followed. The
/// trajectory changes the drive, so a wiring that dropped it on both sides
/// fails the last assertion.
#[test]
fn without_the_trajectory_the_daemon_and_the_sim_follow_the_same_route() {
    let mut config = daemon_config();
    config.navigator.trajectory = false;
    config.validate().expect("valid");
    let eval = sim_config(&config);
    let (ours, theirs) = run(&config, &eval);
    if let Some(diff) = first_difference(&ours, &theirs) {
        panic!("without the trajectory, the daemon and wlnav-sim differ at {diff}");
    }
    assert!(ours[1].new_plan, "the route arrived at tick 1");
    let tracked = daemon_config();
    assert!(tracked.navigator.trajectory, "on by default");
    let (with, _) = run(&tracked, &sim_config(&tracked));
    assert!(
        ours.iter()
            .zip(&with)
            .any(|(a, b)| bits(a.command) != bits(b.command)),
        "the trajectory changed nothing: is it wired?"
    );
}
