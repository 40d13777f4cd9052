//! One full MPC tick (delay compensation, critic derivatives, QP update and
//! solve, output, and the safety envelope's check of the command, DESIGN §14)
//! at N = 10, 20, 40 with the committed critic and actor
//! (`critic-weights/avant635/`; random networks of the paper's sizes when absent, said
//! on stdout), for both Hessian modes, in closed loop on the simulated machine (0.2 s delay) with
//! 0, 2 and 8 circles (issue 30; criterion times the 2-circle case). Besides
//! criterion's estimates it prints the median and p99 of 400 ticks per
//! configuration and the tick's split into the critic's derivatives, the rest
//! of the QP's assembly, and the QP solve (medians), with each QP solver
//! (`MpcSettings::qp_solver`: Clarabel, Riccati); criterion times the default's.

use std::time::{Duration, Instant};

use clarabel::solver::DefaultSettings;
use control::delay::DelayCompensator;
use control::envelope::{self, EnvelopeInput, EnvelopeSettings};
use control::mlp::PAPER_HIDDEN;
use control::model::{MachineParams, State};
use control::mpc::{
    ClarabelBackend, Mpc, MpcSettings, Obstacle, QpSolver, QpSolverBackend, Rk4Model,
};
use control::weights::{self, random_network, NetworkMetadata, NetworkRole, WeightsProblem};
use control::{Actor, Critic, HessianMode, Plant, PlantConfig, VelocityCommand};
use criterion::{criterion_group, criterion_main, Criterion};

mod workload;
use workload::{CIRCLES, GOAL};

/// The committed networks, or random ones of the paper's sizes.
fn networks() -> (Critic, Actor) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(weights::DEFAULT_DIR);
    match control::networks::load_networks(
        &dir,
        &MachineParams::default(),
        MpcSettings::default().dt,
    ) {
        Ok(networks) => networks,
        Err(e) if !matches!(e.problem, WeightsProblem::Read { .. }) => panic!("{e}"),
        Err(e) => {
            println!("{e}: random networks");
            (
                Critic::from_weights(random_network(
                    NetworkMetadata::new(NetworkRole::Critic, 8),
                    &PAPER_HIDDEN,
                    1,
                ))
                .expect("valid critic"),
                Actor::from_weights(random_network(
                    NetworkMetadata::new(NetworkRole::Actor, 4),
                    &PAPER_HIDDEN,
                    2,
                ))
                .expect("valid actor"),
            )
        }
    }
}

/// An MPC and the machine it drives; restarts from the origin every 150 ticks.
struct Loop {
    mpc: Mpc<Critic>,
    obstacles: &'static [Obstacle],
    plant: Plant,
    ticks: usize,
    /// The envelope's record of the commands sent, and the last one.
    sent: DelayCompensator,
    last: VelocityCommand,
    /// Time spent in the envelope over the ticks so far.
    envelope: Duration,
}

impl Loop {
    fn new(horizon: usize, hessian: HessianMode, circles: usize) -> Self {
        Self::with_solver(horizon, hessian, circles, MpcSettings::default().qp_solver)
    }

    fn with_solver(
        horizon: usize,
        hessian: HessianMode,
        circles: usize,
        qp_solver: QpSolver,
    ) -> Self {
        let settings = MpcSettings {
            horizon,
            hessian,
            qp_solver,
            ..MpcSettings::default()
        };
        let (critic, actor) = networks();
        let mpc = Mpc::new(MachineParams::default(), critic, Some(actor), settings)
            .expect("valid settings");
        Self::around(mpc, &CIRCLES[..circles])
    }

    fn around(mpc: Mpc<Critic>, obstacles: &'static [Obstacle]) -> Self {
        let p = *mpc.params();
        let settings = *mpc.settings();
        let plant = Plant::new(p, PlantConfig::default(), State::zeros()).expect("valid plant");
        let sent =
            envelope::command_record(p, &EnvelopeSettings::default(), settings.delay, settings.dt)
                .expect("valid delay");
        let mut l = Self {
            mpc,
            obstacles,
            plant,
            ticks: 0,
            sent,
            last: VelocityCommand::ZERO,
            envelope: Duration::ZERO,
        };
        l.restart();
        l
    }

    fn restart(&mut self) {
        self.mpc.reset();
        self.mpc.set_goal(GOAL, self.obstacles).expect("valid goal");
        let p = *self.mpc.params();
        self.plant = Plant::new(p, PlantConfig::default(), State::zeros()).expect("valid plant");
        self.sent =
            envelope::command_record(p, &EnvelopeSettings::default(), self.sent.delay(), 0.2)
                .expect("valid delay");
        self.last = VelocityCommand::ZERO;
        self.ticks = 0;
    }

    /// One tick; returns the time spent in `Mpc::step` and the envelope's
    /// check of its command (the envelope's share is added to `self.envelope`).
    fn tick(&mut self) -> Duration {
        if self.ticks == 150 {
            self.restart();
        }
        let x = self.plant.state();
        let start = Instant::now();
        let now = self.ticks as f64 * 0.2;
        let sol = self.mpc.step(&x, now).expect("goal set");
        let proposed = sol.command;
        let guard_start = Instant::now();
        let settings = EnvelopeSettings::default();
        let cmd = envelope::guard(
            &EnvelopeInput {
                params: self.mpc.params(),
                settings: &settings,
                sent: &self.sent,
                now,
                state: &x,
                world: self.mpc.world(),
                dt: 0.2,
                last: self.last,
                live: None,
            },
            proposed,
        )
        .command;
        self.envelope += guard_start.elapsed();
        let elapsed = start.elapsed();
        self.sent.record(now, cmd);
        self.last = cmd;
        self.mpc.sent(now, cmd);
        self.plant.command(cmd).expect("finite command");
        self.plant.advance(0.2);
        self.ticks += 1;
        elapsed
    }
}

fn percentiles(horizon: usize, hessian: HessianMode, circles: usize, solver: QpSolver) {
    let mut l = Loop::with_solver(horizon, hessian, circles, solver);
    for _ in 0..20 {
        l.tick();
    }
    l.envelope = Duration::ZERO;
    let (mut t, mut derivatives, mut assembly, mut qp) = (vec![], vec![], vec![], vec![]);
    for _ in 0..400 {
        t.push(l.tick().as_secs_f64() * 1e3);
        let sol = l.mpc.solution();
        derivatives.push(sol.derivatives_time.as_secs_f64() * 1e3);
        assembly.push(sol.assembly_time.as_secs_f64() * 1e3);
        qp.push(sol.qp_time.as_secs_f64() * 1e3);
    }
    let total: f64 = t.iter().sum();
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (d, a, q) = (
        median(&mut derivatives),
        median(&mut assembly),
        median(&mut qp),
    );
    t.sort_by(f64::total_cmp);
    println!(
        "mpc tick N={horizon:2} {hessian:?} {circles} circles {solver:?}: median {:.3} ms, p99 {:.3} ms, max {:.3} ms \
         (400 ticks; medians: critic derivatives {d:.3}, assembly {a:.3}, QP {q:.3} ms; \
         the envelope {:.3} ms a tick, {:.1} % of the tick)",
        t[t.len() / 2],
        t[(t.len() * 99) / 100],
        t[t.len() - 1],
        l.envelope.as_secs_f64() * 1e3 / 400.0,
        100.0 * l.envelope.as_secs_f64() * 1e3 / total
    );
}

/// `MPC_BENCH_PROBE=1`: time split and QP iterations for a few QP settings.
fn probe() {
    {
        use control::mpc::cost::project_psd8;
        use control::{CriticWorkspace, Derivatives};
        let (critic, _) = networks();
        let mut ws = CriticWorkspace::new(&critic);
        let mut d = Derivatives::default();
        let x = State::new(1.0, 0.5, 0.3, 0.1, 0.05, 0.5);
        let u = control::Control::new(0.1, 0.2);
        for mode in [HessianMode::Exact, HessianMode::GaussNewton] {
            let t = Instant::now();
            for _ in 0..2000 {
                critic.hessian(&mut ws, &x, &u, &GOAL, mode, &mut d);
            }
            println!(
                "critic {mode:?} hessian: {:.1} us",
                t.elapsed().as_secs_f64() * 1e6 / 2000.0
            );
        }
        critic.hessian(&mut ws, &x, &u, &GOAL, HessianMode::Exact, &mut d);
        let t = Instant::now();
        let mut sink = 0.0;
        for _ in 0..2000 {
            let mut h = d.hess;
            h[0][0] -= 1.0;
            project_psd8(&mut h, 0.0);
            sink += h[1][1];
        }
        println!(
            "project_psd8: {:.1} us ({sink})",
            t.elapsed().as_secs_f64() * 1e6 / 2000.0
        );
    }
    // Clarabel's settings, changed from the MPC's (`ClarabelBackend::settings`).
    type Tweak = fn(&mut DefaultSettings<f64>);
    let tweaks: [(&str, Tweak); 7] = [
        ("default", |_| {}),
        ("tol 1e-7 + refinement", |s| {
            (s.tol_gap_abs, s.tol_gap_rel, s.tol_feas) = (1e-7, 1e-7, 1e-7);
            s.iterative_refinement_enable = true;
        }),
        ("tol 1e-5", |s| {
            (s.tol_gap_abs, s.tol_gap_rel, s.tol_feas) = (1e-5, 1e-5, 1e-5)
        }),
        ("tol 1e-4", |s| {
            (s.tol_gap_abs, s.tol_gap_rel, s.tol_feas) = (1e-4, 1e-4, 1e-4)
        }),
        ("no equilibration", |s| s.equilibrate_enable = false),
        ("max step 0.995", |s| s.max_step_fraction = 0.995),
        ("static regularisation 1e-7", |s| {
            s.static_regularization_constant = 1e-7
        }),
    ];
    for horizon in [10, 20, 40] {
        for (name, tweak) in tweaks {
            let settings = MpcSettings {
                horizon,
                ..MpcSettings::default()
            };
            let p = MachineParams::default();
            let (critic, actor) = networks();
            let mpc = Mpc::with_parts(
                p,
                critic,
                Rk4Model { params: p },
                Some(actor),
                settings,
                |layout, data, settings| {
                    let mut s = ClarabelBackend::settings(settings)?;
                    tweak(&mut s);
                    ClarabelBackend::with_settings(layout, data, s).map(QpSolverBackend::Clarabel)
                },
            )
            .expect("valid settings");
            let mut l = Loop::around(mpc, &CIRCLES[..2]);
            let (mut tot, mut qp, mut it, mut cost) = (vec![], vec![], 0, 0.0);
            for _ in 0..200 {
                let t = l.tick();
                let sol = l.mpc.solution();
                tot.push(t.as_secs_f64() * 1e3);
                qp.push(sol.qp_time.as_secs_f64() * 1e3);
                it += sol.qp_iterations;
                cost += sol.cost;
            }
            tot.sort_by(f64::total_cmp);
            qp.sort_by(f64::total_cmp);
            println!(
                "N={horizon} {name}: tick median {:.3} ms, qp median {:.3} ms, mean QP iterations {:.1}, \
                 mean plan cost {:.3}",
                tot[100],
                qp[100],
                it as f64 / 200.0,
                cost / 200.0
            );
        }
    }
}

fn bench(c: &mut Criterion) {
    if std::env::var_os("MPC_BENCH_PROBE").is_some() {
        probe();
        return;
    }
    // `MPC_BENCH_SPLIT=20/Exact/2,40/Exact/2`: only these cases' percentiles
    // and split, with both solvers, in ROUNDS rounds (`MPC_BENCH_ROUNDS`, 1).
    if let Ok(cases) = std::env::var("MPC_BENCH_SPLIT") {
        let rounds = std::env::var("MPC_BENCH_ROUNDS").map_or(1, |r| r.parse().expect("ROUNDS"));
        for _ in 0..rounds {
            for case in cases.split(',') {
                let mut f = case.split('/');
                let mut next = || f.next().expect("N/HESSIAN/CIRCLES");
                let horizon = next().parse().expect("N");
                let hessian = match next() {
                    "Exact" => HessianMode::Exact,
                    "GaussNewton" => HessianMode::GaussNewton,
                    h => panic!("{h}: Exact or GaussNewton"),
                };
                let circles = next().parse().expect("CIRCLES");
                for solver in [QpSolver::Clarabel, QpSolver::Riccati] {
                    percentiles(horizon, hessian, circles, solver);
                }
            }
        }
        return;
    }
    for hessian in [HessianMode::Exact, HessianMode::GaussNewton] {
        for horizon in [10, 20, 40] {
            for circles in [0, 2, 8] {
                for solver in [QpSolver::Clarabel, QpSolver::Riccati] {
                    percentiles(horizon, hessian, circles, solver);
                }
            }
        }
    }
    let mut group = c.benchmark_group("mpc_tick");
    group
        .sample_size(30)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    for hessian in [HessianMode::Exact, HessianMode::GaussNewton] {
        for horizon in [10, 20, 40] {
            let mut l = Loop::new(horizon, hessian, 2);
            group.bench_function(format!("N{horizon}_{hessian:?}"), |b| {
                b.iter_custom(|iters| (0..iters).map(|_| l.tick()).sum())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
