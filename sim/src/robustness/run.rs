//! Runs every case of the sweeps on both scenario sets. Each finished case is
//! kept on disk, so an interrupted run continues where it stopped.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use control::plant::PlantPerturbation;
use control::scenario::Scenario;

use super::figures::{opt, Figures};
use super::{all_moderate, case, describe, Case, Sweep};
use crate::eval;
use crate::report::PENETRATION_TOLERANCE;
use crate::results::ResultRow;
use crate::runner::{EvalConfig, Method, Networks};

/// The run's results of one case.
pub(super) struct Outcome {
    pub(super) paper: Vec<ResultRow>,
    pub(super) obstacles: Vec<ResultRow>,
    /// Obstacle-set ticks the safety envelope overrode, and in how many runs.
    pub(super) overrides: (usize, usize),
    wall_s: f64,
}

/// Everything the command needs.
pub struct Inputs<'a> {
    pub base: EvalConfig,
    pub nets: &'a Networks,
    pub paper: &'a [Scenario],
    pub paper_name: String,
    pub obstacles: &'a [Scenario],
    /// How the obstacle scenarios were chosen (for the page).
    pub obstacles_note: String,
    /// T* per scenario name (min-time rows of a results file).
    pub t_star: HashMap<String, f64>,
    pub t_star_source: String,
    pub command: String,
    pub commit: String,
    /// Base name of the page and its asset directory (`robustness`).
    pub name: String,
    /// Run every case with `base.envelope` as it is (the shipped defaults:
    /// nothing stated, issue 43) instead of the tolerances each case states
    /// ([`Case::stated_envelope`]).
    pub shipped_envelope: bool,
}

impl Inputs<'_> {
    /// The envelope case `c` runs with: the shipped one, or the tolerances
    /// the case states on an otherwise exact envelope (the base's margin,
    /// σ count, sub-step and assumption check).
    pub fn envelope_of(&self, c: &Case) -> control::envelope::EnvelopeSettings {
        let b = self.base.envelope;
        if self.shipped_envelope {
            return b;
        }
        let exact = control::envelope::EnvelopeSettings {
            enabled: b.enabled,
            margin: b.margin,
            noise_sigmas: b.noise_sigmas,
            substep: b.substep,
            check: b.check,
            ..control::envelope::EnvelopeSettings::exact()
        };
        c.stated_envelope(exact, &self.base.params)
    }
}

/// Every case's outcome, and how the CSVs and the page look them up.
pub(super) struct Results<'a> {
    /// Distinct cases, the nominal first, then sweep order, all moderate last.
    pub(super) cases: Vec<Case>,
    outcomes: Vec<Outcome>,
    pub(super) nominal: Case,
    pub(super) moderate: Case,
    /// Wall time of all cases [s].
    pub(super) wall: f64,
    t_star: &'a HashMap<String, f64>,
    /// The nominal MPC's times on the obstacle set.
    t_nominal_obst: HashMap<String, f64>,
}

impl Results<'_> {
    pub(super) fn of(&self, c: &Case) -> &Outcome {
        &self.outcomes[self
            .cases
            .iter()
            .position(|x| x == c)
            .expect("every case ran")]
    }

    /// The figures of case `c` on the paper set and on the obstacle set.
    pub(super) fn figures(&self, c: &Case) -> (Figures, Figures) {
        let o = self.of(c);
        (
            Figures::of(&o.paper, self.t_star),
            Figures::of(&o.obstacles, &self.t_nominal_obst),
        )
    }
}

/// Runs the sweeps' distinct cases (`start`: when the command started).
pub(super) fn run_cases<'a>(
    inp: &'a Inputs,
    sweeps: &[Sweep],
    out: &Path,
    start: Instant,
) -> Result<Results<'a>> {
    // Distinct cases, the nominal first, then sweep order, all moderate last.
    let nominal = case(PlantPerturbation::default(), 0.0);
    let mut cases: Vec<Case> = vec![nominal];
    for s in sweeps {
        for l in &s.levels {
            if !cases.contains(&l.case) {
                cases.push(l.case);
            }
        }
    }
    let moderate = all_moderate();
    cases.push(moderate);
    let both: Vec<Scenario> = inp.paper.iter().chain(inp.obstacles).cloned().collect();
    // Each finished case is kept in OUT/NAME/cases/ (its rows and a key of
    // everything that determines them), so an interrupted run continues
    // where it stopped: rerun the same command.
    let cache = out.join(&inp.name).join("cases");
    std::fs::create_dir_all(&cache).with_context(|| format!("creating {}", cache.display()))?;
    let mut outcomes: Vec<Outcome> = Vec::new();
    for (k, c) in cases.iter().enumerate() {
        let t0 = Instant::now();
        let key = format!(
            "{:?} | {:?} | {:?} | {} | {} | {}",
            c,
            inp.base.mpc,
            inp.envelope_of(&c),
            inp.paper_name,
            inp.nets.source,
            inp.obstacles
                .iter()
                .map(|s| s.name.as_str())
                .collect::<Vec<_>>()
                .join(",")
        );
        let (rows_file, meta_file) = (
            cache.join(format!("{k:02}.csv")),
            cache.join(format!("{k:02}.key")),
        );
        if let (Ok(text), Ok(meta)) = (
            std::fs::read_to_string(&rows_file),
            std::fs::read_to_string(&meta_file),
        ) {
            let mut lines = meta.lines();
            let stored_key = lines.next().unwrap_or_default();
            let numbers: Vec<f64> = lines
                .next()
                .unwrap_or_default()
                .split(',')
                .filter_map(|v| v.parse().ok())
                .collect();
            let rows = crate::results::parse(&text, &rows_file.display().to_string())?;
            if stored_key == key && numbers.len() == 3 && rows.len() == both.len() {
                let (paper, obstacles) = rows.split_at(inp.paper.len());
                eprintln!(
                    "robustness [{}/{}] {}: kept from {}",
                    k + 1,
                    cases.len(),
                    describe(&c.perturbation),
                    rows_file.display()
                );
                outcomes.push(Outcome {
                    paper: paper.to_vec(),
                    obstacles: obstacles.to_vec(),
                    overrides: (numbers[0] as usize, numbers[1] as usize),
                    wall_s: numbers[2],
                });
                continue;
            }
        }
        let cfg = EvalConfig {
            methods: vec![Method::Mpc],
            plant: control::plant::PlantConfig {
                delay: c.compensated,
                ..control::plant::PlantConfig::ideal()
            },
            perturbation: c.perturbation,
            envelope: inp.envelope_of(&c),
            end_at_rest: true,
            progress: false,
            ..inp.base.clone()
        };
        let ev = eval::evaluate(&cfg, inp.nets, &both)?;
        let (paper, obstacles) = ev.rows.split_at(inp.paper.len());
        let per_run: Vec<usize> = ev.runs[inp.paper.len()..]
            .iter()
            .flat_map(|s| s.runs.iter().map(|(_, r)| r.envelope_overrides))
            .collect();
        let o = Outcome {
            paper: paper.to_vec(),
            obstacles: obstacles.to_vec(),
            overrides: (
                per_run.iter().sum(),
                per_run.iter().filter(|&&n| n > 0).count(),
            ),
            wall_s: t0.elapsed().as_secs_f64(),
        };
        std::fs::write(&rows_file, crate::results::to_csv(&ev.rows))
            .with_context(|| format!("writing {}", rows_file.display()))?;
        std::fs::write(
            &meta_file,
            format!("{key}\n{},{},{}\n", o.overrides.0, o.overrides.1, o.wall_s),
        )
        .with_context(|| format!("writing {}", meta_file.display()))?;
        let fp = Figures::of(&o.paper, &inp.t_star);
        let fo = Figures::of(&o.obstacles, &HashMap::new());
        eprintln!(
            "robustness [{}/{}] {} (delay compensated {} s): paper {}/{}, t/T* {}; obstacles {}/{}, worst clearance {} m, {} below -{} m; {:.1} s (total {:.0} s)",
            k + 1,
            cases.len(),
            describe(&c.perturbation),
            c.compensated,
            fp.reached,
            fp.scenarios,
            opt(fp.t_ratio, 3),
            fo.reached,
            fo.scenarios,
            opt(fo.worst_clearance, 3),
            fo.penetrations,
            PENETRATION_TOLERANCE,
            o.wall_s,
            start.elapsed().as_secs_f64()
        );
        outcomes.push(o);
    }
    let wall = start.elapsed().as_secs_f64();
    let mut results = Results {
        cases,
        outcomes,
        nominal,
        moderate,
        wall,
        t_star: &inp.t_star,
        t_nominal_obst: HashMap::new(),
    };
    // Obstacle-set times are compared with the nominal MPC's on the same scenario.
    results.t_nominal_obst = results
        .of(&nominal)
        .obstacles
        .iter()
        .filter_map(|r| Some((r.name.clone(), r.t_converge?)))
        .collect();
    Ok(results)
}
