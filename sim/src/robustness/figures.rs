//! The figures of one case on one scenario set, and issue 16's acceptance test.

use std::collections::HashMap;

use crate::report::PENETRATION_TOLERANCE;
use crate::results::ResultRow;

/// The figures of one case on one scenario set.
#[derive(Debug, Clone)]
pub struct Figures {
    pub scenarios: usize,
    pub reached: usize,
    /// Mean convergence time of the reached runs [s].
    pub t_mean: Option<f64>,
    /// Mean t / T* over the reached runs with a T*.
    pub t_ratio: Option<f64>,
    /// Largest t / T*.
    pub t_ratio_max: Option<f64>,
    /// Smallest footprint clearance over all runs [m] (None: no obstacles).
    pub worst_clearance: Option<f64>,
    /// Runs deeper than [`PENETRATION_TOLERANCE`] into an obstacle.
    pub penetrations: usize,
}

impl Figures {
    pub fn of(rows: &[ResultRow], t_star: &HashMap<String, f64>) -> Self {
        let reached: Vec<&ResultRow> = rows.iter().filter(|r| r.success).collect();
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        let t: Vec<f64> = reached.iter().filter_map(|r| r.t_converge).collect();
        let ratios: Vec<f64> = reached
            .iter()
            .filter_map(|r| Some(r.t_converge? / t_star.get(&r.name)?.max(1e-9)))
            .collect();
        let cl: Vec<f64> = rows.iter().filter_map(|r| r.min_clearance).collect();
        Self {
            scenarios: rows.len(),
            reached: reached.len(),
            t_mean: mean(&t),
            t_ratio: mean(&ratios),
            t_ratio_max: ratios.iter().cloned().reduce(f64::max),
            worst_clearance: cl.iter().cloned().reduce(f64::min),
            penetrations: cl.iter().filter(|&&c| c < -PENETRATION_TOLERANCE).count(),
        }
    }

    pub fn success_rate(&self) -> f64 {
        self.reached as f64 / self.scenarios.max(1) as f64
    }
}

/// Acceptance of issue 16: on the paper set at least `min_success` reached;
/// on the obstacle set no run deeper than [`PENETRATION_TOLERANCE`].
pub fn accepted(paper: &Figures, obstacles: &Figures, min_success: f64) -> bool {
    paper.success_rate() >= min_success - 1e-12 && obstacles.penetrations == 0
}

/// `v` with `d` decimals, `–` when there is none.
pub(super) fn opt(v: Option<f64>, d: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.d$}"))
}
