//! The CSVs of a run: one row per case and set, one row per run.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use super::figures::opt;
use super::run::Results;
use super::{describe, Case, Sweep};

/// Writes `assets/summary.csv` and `assets/runs.csv`.
pub(super) fn write(results: &Results, sweeps: &[Sweep], assets: &Path) -> Result<()> {
    let figures = |c: &Case| results.figures(c);
    let of = |c: &Case| results.of(c);
    let moderate = results.moderate;
    let mut summary_csv = String::from(
        "sweep,level,perturbation,compensated_delay,set,scenarios,reached,t_mean,t_ratio_mean,t_ratio_max,worst_clearance,penetrations\n",
    );
    let mut runs_csv =
        String::from("sweep,level,set,name,success,t_converge,min_clearance,solve_ms_max\n");
    let mut labelled: Vec<(&str, String, Case)> = Vec::new();
    for s in sweeps {
        for l in &s.levels {
            labelled.push((s.flag, l.label.clone(), l.case));
        }
    }
    labelled.push(("all-moderate", "all".into(), moderate));
    for (flag, label, c) in &labelled {
        let (fp, fo) = figures(c);
        for (set, f) in [("paper", &fp), ("obstacles", &fo)] {
            let _ = writeln!(
                summary_csv,
                "{flag},{label},\"{}\",{},{set},{},{},{},{},{},{},{}",
                describe(&c.perturbation),
                c.compensated,
                f.scenarios,
                f.reached,
                opt(f.t_mean, 3),
                opt(f.t_ratio, 4),
                opt(f.t_ratio_max, 4),
                opt(f.worst_clearance, 4),
                f.penetrations
            );
        }
        let o = of(c);
        for (set, rows) in [("paper", &o.paper), ("obstacles", &o.obstacles)] {
            for r in rows.iter() {
                let _ = writeln!(
                    runs_csv,
                    "{flag},{label},{set},{},{},{},{},{:.2}",
                    r.name,
                    r.success,
                    r.t_converge.map_or(String::new(), |t| format!("{t}")),
                    r.min_clearance.map_or(String::new(), |c| format!("{c:.4}")),
                    r.solve_ms_max
                );
            }
        }
    }
    std::fs::write(assets.join("summary.csv"), summary_csv)?;
    std::fs::write(assets.join("runs.csv"), runs_csv)?;
    Ok(())
}
