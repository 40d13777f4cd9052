//! `eval`: run an evaluation and write its outputs to a directory:
//! `results.csv` ([`crate::results`]), `summary.md`, `trajectories/<scenario>.svg`
//! (all methods), `overview_<method>.svg` (all scenarios of one method) and
//! `histogram.svg` (convergence times).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use control::planner::{PlanOutcome, TrajectoryOutcome};
use control::scenario::Scenario;
use control::site::{Site, SiteIndex};
use std::sync::Arc;

use crate::plots::{self, method_color, Track};
use crate::results::{self, MethodSummary, ResultRow};
use crate::runner::{run_all, EvalConfig, Method, Networks, ScenarioRuns};

/// The outcome of an evaluation.
pub struct Evaluation {
    pub runs: Vec<ScenarioRuns>,
    pub rows: Vec<ResultRow>,
    pub summaries: Vec<MethodSummary>,
    /// Wall time of the whole evaluation [s].
    pub wall_s: f64,
    pub jobs: usize,
    /// The site the scenarios ran in (drawn under the trajectories).
    pub site: Option<Arc<SiteIndex>>,
}

/// Runs `scenarios` under `cfg` and summarises.
pub fn evaluate(cfg: &EvalConfig, nets: &Networks, scenarios: &[Scenario]) -> Result<Evaluation> {
    let start = Instant::now();
    let runs = run_all(cfg, nets, scenarios)?;
    let wall_s = start.elapsed().as_secs_f64();
    let rows: Vec<ResultRow> = runs
        .iter()
        .flat_map(|s| s.runs.iter().map(|(_, r)| r.row.clone()))
        .collect();
    let summaries = summarize_runs(&cfg.methods, &runs, &rows);
    Ok(Evaluation {
        runs,
        rows,
        summaries,
        wall_s,
        jobs: cfg.jobs,
        site: cfg.site.clone(),
    })
}

/// Summaries of `methods` over `runs`; `rows` may hold more methods' rows (the
/// baseline and min-time of another evaluation of the same scenarios) to compare
/// against.
pub fn summarize_runs(
    methods: &[Method],
    runs: &[ScenarioRuns],
    rows: &[ResultRow],
) -> Vec<MethodSummary> {
    let names: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
    let of_method = |m: Method| {
        runs.iter()
            .flat_map(move |s| s.runs.iter().filter(move |(k, _)| *k == m).map(|(_, r)| r))
    };
    let samples: Vec<Vec<f64>> = methods
        .iter()
        .map(|&m| {
            of_method(m)
                .flat_map(|r| r.solve_ms.iter().copied())
                .collect()
        })
        .collect();
    let wall: Vec<f64> = methods
        .iter()
        .map(|&m| of_method(m).map(|r| r.wall_s).sum())
        .collect();
    results::summarize(rows, &names, &samples, &wall)
}

/// Timing lines for the speed targets (issue 5: 128 scenarios with the MPC at
/// N = 10 in ≤ 60 s; the baseline ≤ 2 s per scenario).
pub fn timing_text(ev: &Evaluation) -> String {
    let mut s = format!(
        "timing: {} scenarios in {:.1} s wall on {} threads\n",
        ev.runs.len(),
        ev.wall_s,
        ev.jobs
    );
    for m in &ev.summaries {
        let per = m.wall_s / m.scenarios.max(1) as f64;
        s.push_str(&format!(
            "timing: {:<9} {:.1} s summed over scenarios ({:.3} s per scenario; ≈ {:.1} s wall at {} threads)\n",
            m.method,
            m.wall_s,
            per,
            m.wall_s / ev.jobs.max(1) as f64,
            ev.jobs
        ));
    }
    s
}

/// The safety envelope's figures (MPC runs): ticks it overrode, in how many
/// runs, and which.
pub fn envelope_text(ev: &Evaluation) -> String {
    let mut runs: Vec<(&str, usize)> = ev
        .runs
        .iter()
        .flat_map(|s| {
            s.runs
                .iter()
                .filter(|(m, _)| *m == crate::runner::Method::Mpc)
                .map(|(_, r)| (s.scenario.name.as_str(), r.envelope_overrides))
        })
        .filter(|(_, n)| *n > 0)
        .collect();
    let ticks: usize = runs.iter().map(|(_, n)| n).sum();
    runs.sort_by(|a, b| b.1.cmp(&a.1));
    let most: Vec<String> = runs
        .iter()
        .take(8)
        .map(|(name, n)| format!("{name} {n}"))
        .collect();
    format!(
        "envelope: {ticks} tick(s) overridden in {} run(s){}{}\n",
        runs.len(),
        if most.is_empty() { "" } else { ": " },
        most.join(", ")
    )
}

/// The envelope's assumptions the machine broke (MPC runs, issue 43): per
/// assumption and decision, in how many runs (each run counted once per
/// pair); "none" when nothing was raised.
pub fn assumptions_text(ev: &Evaluation) -> String {
    let mut counts: std::collections::BTreeMap<(&str, String), usize> = Default::default();
    for r in ev.runs.iter().flat_map(|s| {
        s.runs
            .iter()
            .filter(|(m, _)| *m == crate::runner::Method::Mpc)
            .map(|(_, r)| r)
    }) {
        let mut seen = std::collections::BTreeSet::new();
        for (_, f, d) in &r.assumption_findings {
            seen.insert((f.assumption.setting(), format!("{d:?}").to_lowercase()));
        }
        for key in seen {
            *counts.entry(key).or_default() += 1;
        }
    }
    let parts: Vec<String> = counts
        .iter()
        .map(|((what, decision), n)| format!("{what} {decision} in {n} run(s)"))
        .collect();
    format!(
        "envelope assumptions broken: {}\n",
        if parts.is_empty() {
            "none".to_string()
        } else {
            parts.join(", ")
        }
    )
}

/// The obstacle rows' figures (MPC runs): plans discarded because they
/// penetrated a circle, and the largest stage multiplier sum seen (the L1
/// penalty is exact while `obstacle_slack_weight` exceeds it, DESIGN §14).
pub fn obstacle_rows_text(ev: &Evaluation, weight: f64) -> String {
    let mpc = ev.runs.iter().flat_map(|s| {
        s.runs
            .iter()
            .filter(|(m, _)| *m == crate::runner::Method::Mpc)
            .map(|(_, r)| r)
    });
    let (mut plans, mut runs, mut multiplier, mut at_weight) = (0, 0, 0.0f64, 0);
    for r in mpc {
        plans += r.penetrating_plans;
        runs += usize::from(r.penetrating_plans > 0);
        multiplier = multiplier.max(r.obstacle_multiplier_max);
        at_weight += usize::from(r.obstacle_multiplier_max >= 0.999 * weight);
    }
    let mut worst = (f64::INFINITY, "–");
    let mut below = 0;
    for s in &ev.runs {
        for (_, r) in s
            .runs
            .iter()
            .filter(|(m, _)| *m == crate::runner::Method::Mpc)
        {
            if let Some(c) = r.row.min_clearance {
                below += usize::from(c < -crate::report::PENETRATION_TOLERANCE);
                if c < worst.0 {
                    worst = (c, s.scenario.name.as_str());
                }
            }
        }
    }
    format!(
        "obstacle rows: {plans} penetrating plan(s) discarded in {runs} run(s); largest stage \
         multiplier {multiplier:.1} (weight {weight}; {at_weight} run(s) at the weight)\n\
         clearance: worst {:.3} m ({}), {below} run(s) below -{} m\n",
        worst.0,
        worst.1,
        crate::report::PENETRATION_TOLERANCE
    )
}

/// The global layer's figures (MPC runs with a navigator): how many runs
/// planned a route, plan times (median / p99 / max over every plan, the
/// direct decisions included), the pilot's tick times, and aborts by reason.
pub fn navigation_text(ev: &Evaluation) -> String {
    let navs: Vec<&crate::runner::Navigation> = ev
        .runs
        .iter()
        .flat_map(|s| s.runs.iter().filter_map(|(_, r)| r.navigation.as_ref()))
        .collect();
    if navs.is_empty() {
        return String::new();
    }
    let plans: Vec<f64> = navs
        .iter()
        .flat_map(|n| n.plan_ms.iter().copied())
        .collect();
    let ticks: Vec<f64> = navs
        .iter()
        .flat_map(|n| n.tick_ms.iter().copied())
        .collect();
    let routed = navs
        .iter()
        .filter(|n| n.routes.iter().any(|r| r.len() > 1))
        .count();
    let outcomes = |outcome: PlanOutcome| {
        navs.iter()
            .flat_map(|n| n.plan_outcome.iter())
            .filter(|&&o| o == outcome)
            .count()
    };
    let retries = outcomes(PlanOutcome::Retry);
    let replans = navs
        .iter()
        .map(|n| n.plan_ms.len().saturating_sub(1))
        .sum::<usize>()
        - retries;
    let trajectories = navs.iter().flat_map(|n| n.plan_trajectory.iter());
    let shaped = trajectories
        .clone()
        .filter(|t| matches!(t, TrajectoryOutcome::Shaped { .. }))
        .count();
    let unshaped = trajectories
        .filter(|t| matches!(t, TrajectoryOutcome::Failed(_)))
        .count();
    let aborts =
        |r: control::planner::AbortReason| navs.iter().filter(|n| n.abort == Some(r)).count();
    let stats = |v: &[f64]| {
        if v.is_empty() {
            "-".to_string()
        } else {
            format!(
                "median {:.3} / p99 {:.3} / max {:.3} ms",
                results::quantile(v, 0.5),
                results::quantile(v, 0.99),
                v.iter().cloned().fold(0.0, f64::max)
            )
        }
    };
    format!(
        "navigation: {} runs, {routed} with a route, {replans} replans, {retries} retries; aborted no-route {}, no-progress {}\n\
         navigation: plan {} ({} plans, on the planner's side); tick {} (the pilot's step: navigator, MPC, envelope)\n\
         navigation: {shaped} plans shaped into a trajectory, {unshaped} not (their route followed; navigation.csv says why)\n",
        navs.len(),
        aborts(control::planner::AbortReason::NoRoute),
        aborts(control::planner::AbortReason::NoProgress),
        stats(&plans),
        plans.len(),
        stats(&ticks),
    )
}

/// One row per plan of every run with a navigator: when, how long, the
/// route (`x:y:theta` subgoals separated by `;`, the goal last) and how the
/// run's navigation ended.
pub fn navigation_csv(ev: &Evaluation) -> Option<String> {
    let mut out = String::from(
        "name,method,plan,outcome,at,plan_ms,expansions,shots,trajectory,route,abort,aborted_at\n",
    );
    let mut any = false;
    for s in &ev.runs {
        for (m, r) in &s.runs {
            let Some(n) = &r.navigation else { continue };
            any = true;
            for (k, route) in n.routes.iter().enumerate() {
                let goals: Vec<String> = route
                    .iter()
                    .map(|g| format!("{:.3}:{:.3}:{:.3}", g.x, g.y, g.theta))
                    .collect();
                out.push_str(&format!(
                    "{},{},{k},{},{},{:.3},{},{},{},{},{},{}\n",
                    s.scenario.name,
                    m.name(),
                    n.plan_outcome.get(k).map_or("", |o| o.name()),
                    n.plan_at.get(k).copied().unwrap_or(0.0),
                    n.plan_ms.get(k).copied().unwrap_or(0.0),
                    n.plan_work.get(k).map_or(0, |w| w.0),
                    n.plan_work.get(k).map_or(0, |w| w.1),
                    n.plan_trajectory
                        .get(k)
                        .map_or(String::new(), |t| trajectory_cell(t)),
                    goals.join(";"),
                    n.abort.map_or("", |a| a.name()),
                    n.aborted_at.map_or(String::new(), |t| format!("{t:.1}")),
                ));
            }
        }
    }
    any.then_some(out)
}

/// A plan's trajectory in navigation.csv: its duration [s], `none: why`
/// (the route followed), or empty where none was asked.
fn trajectory_cell(t: &TrajectoryOutcome) -> String {
    match t {
        TrajectoryOutcome::NotAsked => String::new(),
        t => t.to_string(),
    }
}

/// Writes results.csv, summary.md and the plots into `dir`.
pub fn write_outputs(
    ev: &Evaluation,
    dir: &Path,
    header: &str,
    plots_per_scenario: bool,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::write(dir.join("results.csv"), results::to_csv(&ev.rows))?;
    let summary = format!(
        "{header}\n{}\n```\n{}{}```\n",
        results::summary_markdown(&ev.summaries),
        timing_text(ev),
        navigation_text(ev)
    );
    std::fs::write(dir.join("summary.md"), summary)?;
    if let Some(csv) = navigation_csv(ev) {
        std::fs::write(dir.join("navigation.csv"), csv)?;
    }
    if plots_per_scenario {
        let tdir = dir.join("trajectories");
        std::fs::create_dir_all(&tdir)?;
        for s in &ev.runs {
            let site = ev.site.as_ref().map(|i| i.site());
            scenario_svg(s, site, &tdir.join(format!("{}.svg", s.scenario.name)))?;
        }
    }
    let methods: Vec<&str> = ev.summaries.iter().map(|m| m.method.as_str()).collect();
    for m in &methods {
        overview_svg(ev, m, &dir.join(format!("overview_{m}.svg")))?;
    }
    histogram(ev, &dir.join("histogram.svg"), "Convergence times")?;
    Ok(())
}

/// One scenario with every method's path.
pub fn scenario_svg(s: &ScenarioRuns, site: Option<&Site>, path: &Path) -> Result<()> {
    let tracks: Vec<Track> = s
        .runs
        .iter()
        .map(|(m, r)| Track {
            label: match r.row.t_converge {
                Some(t) => format!("{} (t = {t:.1} s)", m.name()),
                None => format!("{} (not converged)", m.name()),
            },
            states: &r.states,
            color: method_color(m.name()),
            routes: r.navigation.as_ref().map_or(&[][..], |n| &n.routes[..]),
        })
        .collect();
    plots::trajectory_svg(path, &s.scenario.name, &[&s.scenario], site, &tracks)
}

/// All scenarios and one method's trajectories in one figure (paper Fig. 6).
pub fn overview_svg(ev: &Evaluation, method: &str, path: &Path) -> Result<()> {
    let scenarios: Vec<&Scenario> = ev.runs.iter().map(|s| &s.scenario).collect();
    let tracks: Vec<Track> = ev
        .runs
        .iter()
        .flat_map(|s| s.runs.iter().filter(|(m, _)| m.name() == method))
        .map(|(m, r)| Track {
            label: m.name().to_string(),
            states: &r.states,
            color: method_color(m.name()),
            routes: r.navigation.as_ref().map_or(&[][..], |n| &n.routes[..]),
        })
        .collect();
    plots::trajectory_svg(
        path,
        &format!("{method}: all scenarios"),
        &scenarios,
        ev.site.as_ref().map(|i| i.site()),
        &tracks,
    )
}

/// Histogram of the successful convergence times per method (paper Fig. 8).
pub fn histogram(ev: &Evaluation, path: &Path, title: &str) -> Result<()> {
    let series: Vec<(String, Vec<f64>)> = ev
        .summaries
        .iter()
        .map(|m| {
            let v = ev
                .rows
                .iter()
                .filter(|r| r.method == m.method && r.success)
                .filter_map(|r| r.t_converge)
                .collect();
            (m.method.clone(), v)
        })
        .collect();
    plots::histogram_svg(path, title, &series)
}
