//! `eval`: run an evaluation and write its outputs to a directory:
//! `results.csv` ([`crate::results`]), `summary.md`, `trajectories/<scenario>.svg`
//! (all methods), `overview_<method>.svg` (all scenarios of one method) and
//! `histogram.svg` (convergence times).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use control::scenario::Scenario;

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
        "{header}\n{}\n```\n{}```\n",
        results::summary_markdown(&ev.summaries),
        timing_text(ev)
    );
    std::fs::write(dir.join("summary.md"), summary)?;
    if plots_per_scenario {
        let tdir = dir.join("trajectories");
        std::fs::create_dir_all(&tdir)?;
        for s in &ev.runs {
            scenario_svg(s, &tdir.join(format!("{}.svg", s.scenario.name)))?;
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
pub fn scenario_svg(s: &ScenarioRuns, path: &Path) -> Result<()> {
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
        })
        .collect();
    plots::trajectory_svg(path, &s.scenario.name, &[&s.scenario], &tracks)
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
        })
        .collect();
    plots::trajectory_svg(
        path,
        &format!("{method}: all scenarios"),
        &scenarios,
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
