//! Scenario files, scoring, the results CSV and the runner end to end (with
//! random networks, which do not reach goals: only the plumbing is tested), and
//! one behaviour of the committed critic.

use control::model::{Goal, State};
use control::scenario::{self, Obstacle, Scenario};
use sim::results::{self, ResultRow};
use sim::runner::{self, EvalConfig, Method, Networks};

fn manifest(path: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

#[test]
fn committed_paper_set_matches_the_generator() {
    let text = std::fs::read_to_string(manifest("scenarios/paper128.csv")).unwrap();
    assert_eq!(text, scenario::to_csv(&scenario::paper_scenarios()));
    assert_eq!(scenario::parse(&text, "paper128.csv").unwrap().len(), 128);
}

#[test]
fn committed_highlighted_scenarios_parse() {
    let all = scenario::parse(
        &std::fs::read_to_string(manifest("scenarios/highlighted.csv")).unwrap(),
        "h",
    )
    .unwrap();
    assert_eq!(all.len(), 5);
    let mut parts = Vec::new();
    for f in ["loading_cycle.csv", "compact_turn.csv", "obstacles.csv"] {
        let p = format!("scenarios/{f}");
        parts.extend(scenario::parse(&std::fs::read_to_string(manifest(&p)).unwrap(), f).unwrap());
    }
    assert_eq!(parts, all);
    // The loading cycle's legs chain: each starts where the previous one ends.
    for w in all[..3].windows(2) {
        assert_eq!(
            (w[1].start[0], w[1].start[1], w[1].start[2]),
            (w[0].goal.x, w[0].goal.y, w[0].goal.theta)
        );
    }
    assert_eq!(all[4].obstacles.len(), 4);
}

#[test]
fn sim_level_parse_errors_name_file_line_and_column() {
    let text = format!(
        "{}\nok,0,0,0,0,0,0,1,1,0,\nbad,0,0,0,0,0,0,1,1,0,2:2\n",
        scenario::HEADER
    );
    let e = scenario::parse(&text, "sim/scenarios/x.csv").unwrap_err();
    assert_eq!(
        e.to_string(),
        "sim/scenarios/x.csv:3:23: obstacle `2:2` is not `x:y:r` with finite numbers"
    );
}

fn row(
    name: &str,
    method: &str,
    success: bool,
    t: Option<f64>,
    clearance: Option<f64>,
) -> ResultRow {
    ResultRow {
        name: name.into(),
        method: method.into(),
        success,
        t_converge: t,
        t_settle: t.map(|t| t + 0.4),
        path_length: 6.123456789012345,
        min_clearance: clearance,
        solve_ms_median: 0.1 + 0.2,
        solve_ms_max: 1e-300,
        min_clearance_moving: None,
        protective_stops: None,
    }
}

#[test]
fn results_csv_round_trips() {
    let rows = vec![
        row("r4.5_b0_h0", "mpc", true, Some(10.6), None),
        row("r4.5_b0_h0", "baseline", true, Some(13.9), Some(-0.25)),
        row("c_obstacles", "min-time", false, None, Some(1.0 / 3.0)),
    ];
    let text = results::to_csv(&rows);
    assert!(text.starts_with(results::HEADER));
    assert_eq!(results::parse(&text, "results.csv").unwrap(), rows);
    let bad = format!("{}\nx,mpc,yes,1,1,1,,1,1\n", results::HEADER);
    let e = results::parse(&bad, "r.csv").unwrap_err();
    assert_eq!((e.line, e.column), (2, 7), "{e}");
    let bad = format!("{}\nx,mpc,true,1,1,oops,,1,1\n", results::HEADER);
    assert_eq!(results::parse(&bad, "r.csv").unwrap_err().column, 16);
    // With movers (DESIGN §18) the two columns follow, and round-trip.
    let mut moving = rows.clone();
    moving[0].protective_stops = Some(2);
    moving[0].min_clearance_moving = Some(0.125);
    moving[1].protective_stops = Some(0);
    moving[2].protective_stops = Some(0);
    let text = results::to_csv(&moving);
    let header = format!("{},{}", results::HEADER, results::MOVING_COLUMNS);
    assert!(text.starts_with(&format!("{header}\n")), "{text}");
    assert_eq!(results::parse(&text, "results.csv").unwrap(), moving);
    let bad = format!("{header}\nx,mpc,true,1,1,1,,1,1,0.5,two\n");
    let e = results::parse(&bad, "r.csv").unwrap_err();
    assert!(e.message.contains("protective_stops"), "{e}");
}

#[test]
fn scoring_follows_design_section_7() {
    let sc = Scenario {
        name: "s".into(),
        start: State::zeros(),
        goal: Goal::new(1.0, 0.0, 0.0),
        obstacles: vec![Obstacle::new(0.5, 1.0, 0.5)],
    };
    // Approach at 0.5 m/s, pass inside at 1.8 s while still moving, stop at 2.4 s.
    let xs: Vec<f64> = vec![
        0.0, 0.2, 0.4, 0.6, 0.75, 0.85, 0.92, 0.96, 0.98, 0.99, 0.995, 0.995, 0.995, 0.995,
    ];
    let vs: Vec<f64> = vec![
        0.5, 0.5, 0.5, 0.5, 0.4, 0.3, 0.2, 0.1, 0.08, 0.06, 0.04, 0.0, 0.0, 0.0,
    ];
    let states: Vec<State> = xs
        .iter()
        .zip(&vs)
        .map(|(&x, &v)| State::new(x, 0.0, 0.0, 0.0, 0.0, v))
        .collect();
    let r = runner::score(&sc, "m", &states, 0.2, 0.1, &[1.0, 3.0, 2.0], Some(0.25));
    assert!(r.success);
    // x = 0.92 (distance 0.08) at k = 6; |v| < 0.05 from k = 10 on.
    assert!((r.t_converge.unwrap() - 1.2).abs() < 1e-12, "{r:?}");
    assert!((r.t_settle.unwrap() - 2.0).abs() < 1e-12, "{r:?}");
    // The clearance is the caller's (measured between the samples).
    assert_eq!(r.min_clearance, Some(0.25));
    assert_eq!((r.solve_ms_median, r.solve_ms_max), (2.0, 3.0));
    // Path length up to convergence.
    assert!((r.path_length - 0.92).abs() < 1e-12);
}

#[test]
fn a_scenario_already_at_its_goal_converges_at_t0() {
    let nets = Networks::random(3);
    let goal = Goal::new(2.0, -1.0, 0.7);
    let sc = Scenario {
        name: "at_goal".into(),
        start: State::new(2.0, -1.0, 0.7, 0.0, 0.0, 0.0),
        goal,
        obstacles: vec![],
    };
    let cfg = EvalConfig {
        duration: 2.0,
        methods: vec![Method::Mpc, Method::Actor, Method::Baseline],
        ..Default::default()
    };
    let runs = runner::run_scenario(&cfg, &nets, &sc).unwrap();
    for (m, r) in &runs.runs {
        assert!(r.row.success, "{}", m.name());
        assert_eq!(r.row.t_converge, Some(0.0), "{}", m.name());
    }
}

#[test]
fn runner_runs_every_method_in_parallel_and_writes_outputs() {
    let nets = Networks::random(1);
    let set: Vec<Scenario> = vec![
        Scenario {
            name: "near".into(),
            start: State::zeros(),
            goal: Goal::new(2.5, 0.0, 0.0),
            obstacles: vec![],
        },
        Scenario {
            name: "obs".into(),
            start: State::zeros(),
            goal: Goal::new(4.0, 0.3, 0.0),
            obstacles: vec![Obstacle::new(2.0, 0.0, 0.6)],
        },
    ];
    let cfg = EvalConfig {
        duration: 12.0,
        jobs: 2,
        progress: false,
        ..Default::default()
    };
    let ev = sim::eval::evaluate(&cfg, &nets, &set).unwrap();
    assert_eq!(ev.rows.len(), 8);
    assert_eq!(ev.runs[1].scenario.name, "obs");
    // The NLP methods do not depend on the networks: both reach the goals.
    for r in ev
        .rows
        .iter()
        .filter(|r| r.method == "baseline" || r.method == "min-time")
    {
        assert!(r.success, "{r:?}");
    }
    let mt = ev
        .rows
        .iter()
        .find(|r| r.name == "obs" && r.method == "min-time")
        .unwrap();
    assert!(mt.min_clearance.unwrap() > -1e-3, "{mt:?}");
    let dir = std::env::temp_dir().join(format!("wlnav-sim-test-{}", std::process::id()));
    sim::eval::write_outputs(&ev, &dir, "# test", true).unwrap();
    let back = results::parse(
        &std::fs::read_to_string(dir.join("results.csv")).unwrap(),
        "results.csv",
    )
    .unwrap();
    assert_eq!(back, ev.rows);
    for f in [
        "summary.md",
        "histogram.svg",
        "overview_mpc.svg",
        "trajectories/obs.svg",
    ] {
        let text = std::fs::read_to_string(dir.join(f)).unwrap();
        assert!(text.len() > 100, "{f}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The committed critic (critic-weights/avant635/) moves the MPC from rest beside its goal:
/// `scenarios/beside16.csv` starts 0.12–0.3 m sideways, where a critic trained
/// without a terminal set holds the machine still (README, training the critic).
#[test]
fn committed_critic_drives_from_beside_the_goal_into_it() {
    let nets = committed();
    let path = manifest("scenarios/beside16.csv");
    let set = scenario::parse(&std::fs::read_to_string(&path).unwrap(), "beside16.csv").unwrap();
    assert_eq!(set.len(), 16);
    let cfg = EvalConfig {
        methods: vec![Method::Mpc],
        jobs: 2,
        progress: false,
        ..Default::default()
    };
    let ev = sim::eval::evaluate(&cfg, &nets, &set).unwrap();
    let reached = ev.rows.iter().filter(|r| r.success).count();
    assert!(
        reached >= 12,
        "the MPC reached {reached} of 16 goals beside its start"
    );
}

/// The MPC with `nets` on the named scenarios of `sim/scenarios/FILE`, alone
/// and under the global layer (DESIGN §10).
/// The named scenarios of obstacles200.csv, in the file's order.
fn obstacles200(names: &[&str]) -> Vec<Scenario> {
    let text = std::fs::read_to_string(manifest("scenarios/obstacles200.csv")).unwrap();
    let set: Vec<Scenario> = scenario::parse(&text, "obstacles200.csv")
        .unwrap()
        .into_iter()
        .filter(|s| names.contains(&s.name.as_str()))
        .collect();
    assert_eq!(set.len(), names.len());
    set
}

fn alone_and_navigated(nets: &Networks, file: &str, names: &[&str]) -> [sim::eval::Evaluation; 2] {
    let text = std::fs::read_to_string(manifest(&format!("scenarios/{file}"))).unwrap();
    let set: Vec<Scenario> = scenario::parse(&text, file)
        .unwrap()
        .into_iter()
        .filter(|s| names.contains(&s.name.as_str()))
        .collect();
    assert_eq!(set.len(), names.len());
    [None, Some(control::planner::NavigatorSettings::default())].map(|navigator| {
        let cfg = EvalConfig {
            params: nets.machine,
            methods: vec![Method::Mpc],
            navigator,
            jobs: 2,
            progress: false,
            ..Default::default()
        };
        sim::eval::evaluate(&cfg, nets, &set).unwrap()
    })
}

/// The global layer in closed loop (DESIGN §10): on walls across the straight
/// path the MPC alone stops in front of the wall; driven through the
/// navigator it goes around, keeps clear of the circles and records the route.
#[test]
fn the_navigator_takes_the_mpc_around_walls() {
    let [alone, navigated] = alone_and_navigated(
        &committed(),
        "obstacles200.csv",
        &["wall000", "wall001", "wall002"],
    );
    assert_eq!(alone.rows.iter().filter(|r| r.success).count(), 0);
    for (s, row) in navigated.runs.iter().zip(&navigated.rows) {
        assert!(row.success, "{} not reached", row.name);
        assert!(row.min_clearance.unwrap() > -0.005, "{row:?}");
        let nav = s.runs[0].1.navigation.as_ref().unwrap();
        assert!(nav.routes[0].len() > 1, "{}: no route", row.name);
        assert_eq!(*nav.routes[0].last().unwrap(), s.scenario.goal);
        assert!(nav.abort.is_none());
    }
}

/// The open way among circles in closed loop: on dock024 and wall008 of
/// obstacles200 the actor's roll-out finds the way open, but the critic left
/// to itself drove elsewhere (dock024: reversing into the piles the roll-out
/// drives round forwards; wall008: reversing into the wall's side) and
/// stalled until its replans ran out of time. Following the roll-out's path
/// (reversing by the rear axle) reaches both on the first plan.
#[test]
fn the_open_way_is_followed_along_the_roll_out_that_found_it_open() {
    let nets = committed();
    let set = obstacles200(&["dock024", "wall008"]);
    let mut cfg = EvalConfig {
        params: nets.machine,
        methods: vec![Method::Mpc],
        navigator: Some(control::planner::NavigatorSettings::default()),
        jobs: 2,
        progress: false,
        ..Default::default()
    };
    // Ample: the same QPs whatever the machine's load.
    cfg.mpc.time_budget = 1.0;
    let eval = sim::eval::evaluate(&cfg, &nets, &set).unwrap();
    for (s, row) in eval.runs.iter().zip(&eval.rows) {
        assert!(row.success, "{} not reached", row.name);
        assert!(row.min_clearance.unwrap() > -0.005, "{row:?}");
        let nav = s.runs[0].1.navigation.as_ref().unwrap();
        assert_eq!(
            nav.plan_outcome,
            [control::planner::PlanOutcome::Direct],
            "{}: replanned",
            row.name
        );
    }
}

/// The safety envelope (DESIGN §14) where the plan cuts in: at horizon 40 the
/// MPC's plans drive through circles on these three scenarios of
/// `obstacles200.csv` (by 0.44–0.55 m, measured); with the envelope after it,
/// the same MPC keeps every run out of them, and the envelope is seen acting.
/// The time budget is ample so that both runs solve the same QPs whatever the
/// machine's load.
#[test]
fn at_horizon_40_the_envelope_keeps_out_of_circles_the_plan_cuts_into() {
    let nets = committed();
    let set = obstacles200(&["gap036", "wall044", "wall045"]);
    let [without, with] = [false, true].map(|enabled| {
        let mut cfg = EvalConfig {
            params: nets.machine,
            methods: vec![Method::Mpc],
            jobs: 2,
            progress: false,
            ..Default::default()
        };
        cfg.mpc.horizon = 40;
        cfg.mpc.time_budget = 10.0;
        cfg.envelope.enabled = enabled;
        sim::eval::evaluate(&cfg, &nets, &set).unwrap()
    });
    for row in &without.rows {
        let c = row.min_clearance.unwrap();
        assert!(
            c < -0.05,
            "{}: without the envelope {c} m: the plan was to cut in",
            row.name
        );
    }
    for (s, row) in with.runs.iter().zip(&with.rows) {
        let c = row.min_clearance.unwrap();
        assert!(c > -0.005, "{}: {c} m with the envelope", row.name);
        assert!(
            s.runs[0].1.envelope_overrides > 0,
            "{}: never acted",
            row.name
        );
    }
}

/// A site (DESIGN §17) is the world of every layer: the goal lies behind a
/// berm polygon (non-convex, an L) and a keep-out the straight path crosses;
/// with the default outline and the Avant's truer one the pilot goes around
/// both, and the clearance measured against the site's features stays
/// outside. Ignoring the site would drive straight through the berm (the
/// straight line meets it).
#[test]
fn the_pilot_drives_around_a_sites_features() {
    use control::site::{Outline, Site, SiteIndex};
    let site = Site::parse(
        br#"{"format": "wlnav-site-v1", "id": "test-berm", "version": 1,
             "bounds": [[-6, -12], [30, -12], [30, 12], [-6, 12]],
             "obstacles": [{"id": "berm", "polygon": [[5, -4], [7, -4], [7, 2], [9, 2], [9, 4], [5, 4]]}],
             "keepout": [{"id": "office", "polygon": [[11, -1.5], [13, -1.5], [13, 1.5], [11, 1.5]]}]}"#,
    )
    .unwrap();
    let index = std::sync::Arc::new(SiteIndex::new(site));
    let sc = Scenario {
        name: "behind-berm".into(),
        start: State::zeros(),
        goal: Goal::new(16.0, 0.0, 0.0),
        obstacles: vec![],
    };
    // The straight path crosses the berm.
    let berm = &index.site().features()[0].shape;
    assert!((0..=160).any(|k| berm.signed_distance([0.1 * k as f64, 0.0]) < 0.0));
    let nets = committed();
    for outline in [control::world::default_outline(), Outline::avant635()] {
        let cfg = EvalConfig {
            params: nets.machine,
            methods: vec![Method::Mpc],
            site: Some(index.clone()),
            outline: outline.clone(),
            duration: 60.0,
            jobs: 1,
            progress: false,
            ..Default::default()
        };
        let ev = sim::eval::evaluate(&cfg, &nets, std::slice::from_ref(&sc)).unwrap();
        let row = &ev.rows[0];
        assert!(row.success, "{outline:?}: not reached: {row:?}");
        let c = row.min_clearance.unwrap();
        assert!(c > -0.005 && c < 2.0, "{outline:?}: clearance {c}");
        let nav = ev.runs[0].runs[0].1.navigation.as_ref().unwrap();
        assert!(nav.routes[0].len() > 1, "no route around the berm");
    }
}

/// The min-time bound with obstacles is a bound (issue 14, item 7): on
/// blocked scenarios (the project's `c_obstacles` and two of
/// `obstacles200.csv`), no method evaluated beside it (MPC and actor with the
/// committed weights, the baseline) converges before T* without touching an
/// obstacle (clearance ≥ −5 mm; the actor does not see obstacles).
#[test]
fn no_method_beats_the_min_time_bound_among_obstacles() {
    let nets = committed();
    let mut set = scenario::parse(
        &std::fs::read_to_string(manifest("scenarios/obstacles.csv")).unwrap(),
        "obstacles.csv",
    )
    .unwrap();
    let more = scenario::parse(
        &std::fs::read_to_string(manifest("scenarios/obstacles200.csv")).unwrap(),
        "obstacles200.csv",
    )
    .unwrap();
    set.extend(
        more.into_iter()
            .filter(|s| s.name == "circles003" || s.name == "gap000"),
    );
    assert_eq!(set.len(), 3);
    let cfg = EvalConfig {
        methods: vec![
            Method::Mpc,
            Method::Actor,
            Method::Baseline,
            Method::MinTime,
        ],
        jobs: 2,
        progress: false,
        ..Default::default()
    };
    let ev = sim::eval::evaluate(&cfg, &nets, &set).unwrap();
    let mut compared = 0;
    for sc in &set {
        let rows: Vec<_> = ev.rows.iter().filter(|r| r.name == sc.name).collect();
        let mt = rows.iter().find(|r| r.method == "min-time").unwrap();
        assert!(mt.success, "min-time solves {}", sc.name);
        let bound = mt.t_converge.unwrap();
        for r in rows.iter().filter(|r| r.method != "min-time" && r.success) {
            let t = r.t_converge.unwrap();
            let clearance = r.min_clearance.unwrap();
            eprintln!(
                "{} {}: {t:.2} s (clearance {clearance:.3} m), T* {bound:.3} s",
                sc.name, r.method
            );
            if clearance < -0.005 {
                continue;
            }
            assert!(
                t >= bound - 1e-3,
                "{} beats T* on {}: {t} < {bound}",
                r.method,
                sc.name
            );
            compared += 1;
        }
    }
    assert!(compared >= 4, "only {compared} runs reached their goals");
}

/// The default machine's committed networks (critic-weights/avant635/).
fn committed() -> Networks {
    Networks::load(&manifest("..").join(control::weights::DEFAULT_DIR)).unwrap()
}

#[test]
fn networks_carry_the_machine_they_were_trained_for() {
    use control::weights::{encode, random_network, FileDtype, NetworkMetadata, NetworkRole};
    use control::MachineParams;
    let dir = std::env::temp_dir().join(format!("wlnav-sim-nets-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let large = MachineParams {
        l_f: 0.9,
        l_r: 1.1,
        ..MachineParams::default()
    };
    let write = |role, outputs, name: &str, machine: MachineParams| {
        let mut meta = NetworkMetadata::new(role, outputs);
        meta.machine = machine;
        let w = random_network(meta, &control::mlp::PAPER_HIDDEN, 5);
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F32).unwrap();
        std::fs::write(dir.join(name), bytes).unwrap();
    };
    write(NetworkRole::Critic, 1, "critic.safetensors", large);
    write(NetworkRole::Actor, 4, "actor.safetensors", large);
    let nets = Networks::load(&dir).unwrap();
    assert_eq!(nets.machine, large);
    assert_eq!(nets.dt, 0.2);
    // An actor trained for another machine than the critic is refused.
    write(
        NetworkRole::Actor,
        4,
        "actor.safetensors",
        MachineParams::default(),
    );
    let e = format!("{:#}", Networks::load(&dir).unwrap_err());
    assert!(e.contains("disagree") && e.contains("l_f"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// An evaluation configured for another machine or Δt than its networks' is
/// refused before anything runs, naming the key and both values.
#[test]
fn an_evaluation_of_another_machine_than_the_networks_is_refused() {
    let nets = Networks::random(2); // trained-for: the default machine, Δt 0.2 s
    let set = control::scenario::paper_scenarios()[..1].to_vec();
    let mut cfg = EvalConfig {
        methods: vec![Method::Actor],
        jobs: 1,
        progress: false,
        ..Default::default()
    };
    cfg.params.l_f = 0.9;
    let e = format!(
        "{:#}",
        sim::eval::evaluate(&cfg, &nets, &set).err().unwrap()
    );
    assert!(
        e.contains("`machine.l_f` = 0.6") && e.contains("configured 0.9"),
        "{e}"
    );
    cfg.params = Default::default();
    cfg.mpc.dt = 0.1;
    let e = format!(
        "{:#}",
        sim::eval::evaluate(&cfg, &nets, &set).err().unwrap()
    );
    assert!(
        e.contains("`dt` = 0.2") && e.contains("configured 0.1"),
        "{e}"
    );
    cfg.mpc.dt = 0.2;
    assert!(sim::eval::evaluate(&cfg, &nets, &set).is_ok());
}

/// The large loader's committed critic (critic-weights/large-loader/) stops
/// beside two of its paper goals with the articulation at its limit (a heading
/// error of 0.1 rad that only driving can remove). Alone the MPC stays there;
/// under the global layer a retry from the approach pose reaches them.
#[test]
fn the_large_loader_stopped_beside_its_goal_is_retried_into_it() {
    let nets = Networks::load(&manifest("../critic-weights/large-loader")).unwrap();
    let [alone, navigated] =
        alone_and_navigated(&nets, "paper128.csv", &["r4.5_b45_h0", "r4.5_b315_h0"]);
    for (s, row) in alone.runs.iter().zip(&alone.rows) {
        assert!(!row.success, "{} reached without a retry", row.name);
        let end = s.runs[0].1.states.last().unwrap();
        let miss = control::model::goal_distance(end, &s.scenario.goal);
        assert!(miss < 0.2, "{}: ends {miss} from the goal", row.name);
    }
    for (s, row) in navigated.runs.iter().zip(&navigated.rows) {
        assert!(row.success, "{} not reached", row.name);
        let nav = s.runs[0].1.navigation.as_ref().unwrap();
        assert_eq!(
            nav.plan_outcome,
            [
                control::planner::PlanOutcome::Direct,
                control::planner::PlanOutcome::Retry
            ],
            "{}",
            row.name
        );
    }
}

/// Issue 43: the envelope's assumptions checked in closed loop. With the
/// shipped envelope and nothing stated, a machine whose delay is 0.8 s
/// against 0.2 s compensated (0.45 s beyond the stated response lag) is named
/// within seconds and driven safely on gap006 (the issue's worst run, 0.367 m
/// into a circle before); a gain of 1.4 (above the stated 1.2) is named and the
/// envelope widened to it; the ideal machine and one within the stated lag
/// (0.3 s) raise nothing.
#[test]
fn the_envelope_names_the_assumption_a_machine_breaks_in_closed_loop() {
    use control::assumption_check::{Assumption, Decision};
    let nets = committed();
    let text = std::fs::read_to_string(manifest("scenarios/obstacles200.csv")).unwrap();
    let set = scenario::parse(&text, "obstacles200.csv").unwrap();
    let sc = set.iter().find(|s| s.name == "gap006").unwrap();
    let config = |delay: Option<f64>, gain: f64| EvalConfig {
        params: nets.machine,
        methods: vec![Method::Mpc],
        plant: control::PlantConfig {
            delay: 0.2,
            ..control::PlantConfig::ideal()
        },
        perturbation: control::PlantPerturbation {
            delay,
            actuator_gain: gain,
            ..Default::default()
        },
        end_at_rest: true,
        // The route followed, not the trajectory tracked: the run long enough
        // for the gain estimate to reach what the machine does (tracked, the
        // goal is reached at 9.4 s with the estimate at 1.32).
        navigator: Some(control::planner::NavigatorSettings {
            trajectory: false,
            ..Default::default()
        }),
        jobs: 1,
        progress: false,
        ..Default::default()
    };
    let run =
        |delay: Option<f64>, gain: f64| runner::run_mpc(&config(delay, gain), &nets, sc).unwrap();
    // Through the evaluation, whose summary counts the findings per run.
    let ev = sim::eval::evaluate(&config(Some(0.8), 1.0), &nets, &[sc.clone()]).unwrap();
    assert_eq!(
        sim::eval::assumptions_text(&ev),
        "envelope assumptions broken: response_lag widen in 1 run(s)\n"
    );
    let late = &ev.runs[0].runs[0].1;
    let (t, f, d) = late.assumption_findings[0];
    assert_eq!(f.assumption, Assumption::Delay, "{f}");
    assert!((f.measured - 0.6).abs() < 0.051, "{f}");
    assert_eq!(d, Decision::Widen);
    assert!(t <= 5.0, "named at {t} s");
    let clearance = late.row.min_clearance.unwrap();
    assert!(clearance > -0.005, "0.8 s delay: {clearance} m");

    let fast = run(None, 1.4);
    // Named as the gain estimate climbs past 1.2 + its dead band, widened
    // each time it climbs further, up to what the machine does.
    let gains: Vec<_> = fast
        .assumption_findings
        .iter()
        .filter(|(_, f, _)| f.assumption == Assumption::Gain)
        .collect();
    assert!(!gains.is_empty(), "{:?}", fast.assumption_findings);
    assert!(
        gains.iter().all(|(_, _, d)| *d == Decision::Widen),
        "{gains:?}"
    );
    let widest = gains.iter().map(|(_, f, _)| f.measured).fold(0.0, f64::max);
    assert!((widest - 1.4).abs() < 0.05, "{gains:?}");

    for (delay, what) in [(None, "ideal"), (Some(0.3), "0.1 s late")] {
        let r = run(delay, 1.0);
        assert!(
            r.assumption_findings.is_empty(),
            "{what}: {:?}",
            r.assumption_findings
        );
    }
}

/// Things that move (DESIGN §18): a person standing in the way from the
/// start for 9 s holds the machine short of it (its clearance while moving
/// stays positive; the MPC's live rows keep its plan out of the person's
/// stop field, so no protective stop is needed), and the goal is reached
/// once the person has gone; the results carry the movers' columns. The
/// same person crossing well behind the machine changes nothing.
#[test]
fn a_person_in_the_way_is_waited_for_and_the_results_say_so() {
    let nets = committed();
    let text = std::fs::read_to_string(manifest("scenarios/paper128.csv")).unwrap();
    let set: Vec<Scenario> = scenario::parse(&text, "paper128.csv")
        .unwrap()
        .into_iter()
        .filter(|s| s.name == "r9_b0_h0")
        .collect();
    let run = |movers: &str| {
        let cfg = EvalConfig {
            methods: vec![Method::Mpc],
            jobs: 1,
            progress: false,
            movers: Some(std::sync::Arc::new(
                sim::movers::parse(movers, "test").unwrap(),
            )),
            ..Default::default()
        };
        sim::eval::evaluate(&cfg, &nets, &set).unwrap().rows[0].clone()
    };
    let alone = {
        let cfg = EvalConfig {
            methods: vec![Method::Mpc],
            jobs: 1,
            progress: false,
            ..Default::default()
        };
        sim::eval::evaluate(&cfg, &nets, &set).unwrap().rows[0].clone()
    };
    assert_eq!(alone.protective_stops, None);
    let waited = run("id,radius,t0,x0,y0,vx,vy,t1\n1,0.3,0,5,0,0,0,9\n");
    assert!(waited.success, "{waited:?}");
    assert_eq!(waited.protective_stops, Some(0), "{waited:?}");
    let c = waited
        .min_clearance_moving
        .expect("the person was there while it moved");
    assert!(c > 0.0, "{waited:?}");
    let (t_alone, t_waited) = (alone.t_converge.unwrap(), waited.t_converge.unwrap());
    assert!(t_waited > t_alone + 3.0, "{t_alone} vs {t_waited}");
    let behind = run("id,radius,t0,x0,y0,vx,vy,t1\n1,0.3,0,-6,-5,0,1.4,9\n");
    assert_eq!(behind.protective_stops, Some(0), "{behind:?}");
    assert_eq!(behind.t_converge, alone.t_converge);
    let csv = sim::results::to_csv(&[waited]);
    assert!(csv.starts_with(&format!(
        "{},{}\n",
        sim::results::HEADER,
        sim::results::MOVING_COLUMNS
    )));
}
