//! Online estimate of the actuator delay (DESIGN §12, issue 16).
//!
//! The MPC compensates a configured delay ([`crate::delay`]); when the
//! machine's true delay differs, the state it plans from is wrong by the
//! commands of the difference, and near obstacles that costs clearance
//! (measured: 0.35 s true against 0.2 s compensated put two obstacle-set runs
//! 0.07 and 0.17 m into a circle, docs/robustness.md).
//!
//! A bank of [`DelayCompensator`]s, one per candidate delay on a grid (the
//! configured one included), is fed the same commands. Each tick, each
//! predicts the velocities (β̇, v_f) one command period ahead from the
//! measurement; the next measurement scores it (squared error in units of one
//! tick's largest velocity change, summed with forgetting). The estimate
//! moves to the best candidate only when its score is clearly better than
//! the current one's ([`SWITCH_RATIO`]); it starts at the configured delay.
//! The velocities respond to the commands alone, so the pose sensors' noise
//! and latency do not enter it.
//!
//! On a machine whose delay is the configured one the configured candidate
//! predicts exactly (zero error on the ideal plant), so the estimate never
//! leaves it and the MPC computes exactly what it computed without it.

use crate::delay::DelayCompensator;
use crate::model::VelocityCommand;
use crate::model::{ix, MachineParams, State};

/// Candidate grid step and largest candidate [s].
pub const GRID: f64 = 0.05;
/// 1 s: the robustness matrix's longest delay (0.8 s) with room; the envelope
/// acts after the estimate, so a delay beyond the grid is one the envelope
/// cannot see (issue 43).
pub const MAX_DELAY: f64 = 1.0;
/// Forgetting factor of the scores per tick (≈ 6 s of memory).
pub const FORGETTING: f64 = 0.97;
/// The best candidate replaces the current one when its score is below this
/// fraction of the current one's.
pub const SWITCH_RATIO: f64 = 0.5;

/// The delay estimate.
#[derive(Debug, Clone)]
pub struct DelayEstimator {
    params: MachineParams,
    dt: f64,
    candidates: Vec<f64>,
    models: Vec<DelayCompensator>,
    scores: Vec<f64>,
    /// Each candidate's prediction of (β̇, v_f) at the next tick.
    predictions: Vec<Option<[f64; 2]>>,
    current: usize,
}

impl DelayEstimator {
    /// Candidates 0, GRID, …, MAX_DELAY and `configured` (≥ 0, finite), the
    /// estimate starting at `configured`; `dt` the command period.
    pub fn new(params: MachineParams, configured: f64, dt: f64) -> Self {
        let n = (MAX_DELAY / GRID).round() as usize;
        let mut candidates: Vec<f64> = (0..=n).map(|k| k as f64 * GRID).collect();
        let configured = if configured.is_finite() && configured >= 0.0 {
            configured
        } else {
            0.0
        };
        let current = match candidates
            .iter()
            .position(|&c| (c - configured).abs() < 1e-9)
        {
            Some(i) => {
                candidates[i] = configured;
                i
            }
            None => {
                candidates.push(configured);
                candidates.len() - 1
            }
        };
        let models = candidates
            .iter()
            .map(|&d| DelayCompensator::new(params, d, dt).expect("d >= 0, dt > 0"))
            .collect();
        let k = candidates.len();
        Self {
            params,
            dt,
            candidates,
            models,
            scores: vec![0.0; k],
            predictions: vec![None; k],
            current,
        }
    }

    /// The estimated delay [s].
    pub fn delay(&self) -> f64 {
        self.candidates[self.current]
    }

    /// The largest delay the estimate can take [s].
    pub fn max_delay(&self) -> f64 {
        self.candidates.iter().cloned().fold(0.0, f64::max)
    }

    /// Forgets the commands and predictions (not the estimate).
    pub fn reset(&mut self) {
        for m in &mut self.models {
            m.reset();
        }
        self.predictions.iter_mut().for_each(|p| *p = None);
    }

    /// Scores the predictions against the state measured at the start of a tick.
    pub fn observe(&mut self, measured: &State) {
        let m = [measured[ix::BETA_DOT], measured[ix::V]];
        if !(m[0].is_finite() && m[1].is_finite()) {
            return;
        }
        let scale = [
            self.params.beta_ddot_max * self.dt,
            self.params.a_max * self.dt,
        ];
        for (s, p) in self.scores.iter_mut().zip(&self.predictions) {
            if let Some(p) = p {
                let e: f64 = (0..2).map(|k| ((m[k] - p[k]) / scale[k]).powi(2)).sum();
                *s = FORGETTING * *s + e;
            }
        }
        let best = (0..self.scores.len())
            .min_by(|&a, &b| self.scores[a].total_cmp(&self.scores[b]))
            .unwrap_or(self.current);
        if self.scores[best] < SWITCH_RATIO * self.scores[self.current] {
            self.current = best;
        }
    }

    /// Records the command sent at `time` (the velocities it should achieve)
    /// and predicts the next tick's velocities from the state `measured` at
    /// `time` (no prediction without one, e.g. a stop ramp sent while the MPC
    /// was not stepped).
    pub fn record(&mut self, time: f64, measured: Option<&State>, achieved: VelocityCommand) {
        let measured = measured.filter(|x| x.iter().all(|v| v.is_finite()));
        for (model, p) in self.models.iter_mut().zip(&mut self.predictions) {
            model.record(time, achieved);
            *p = measured.map(|measured| {
                let x = model.propagate_over(time, measured, self.dt);
                [x[ix::BETA_DOT], x[ix::V]]
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{Plant, PlantConfig, PlantPerturbation};

    /// Drives a plant whose true delay is `true_delay` with commands that
    /// change now and then; the estimator configured with `configured`.
    fn estimate(true_delay: f64, configured: f64) -> f64 {
        let p = MachineParams::default();
        let config = PlantConfig {
            delay: configured,
            ..PlantConfig::ideal()
        };
        let pert = PlantPerturbation {
            delay: Some(true_delay),
            ..Default::default()
        };
        let mut plant = Plant::perturbed(p, config, pert, State::zeros()).unwrap();
        let mut est = DelayEstimator::new(p, configured, 0.2);
        for tick in 0..100 {
            let t = tick as f64 * 0.2;
            let x = plant.measure();
            est.observe(&x);
            let cmd = VelocityCommand {
                beta_dot: 0.3 * (0.8 * t).sin(),
                v: 0.5 * (0.5 * t).cos(),
            };
            est.record(t, Some(&x), cmd);
            plant.command(cmd).unwrap();
            plant.advance(0.2);
        }
        est.delay()
    }

    #[test]
    fn finds_the_true_delay() {
        for (truth, configured) in [(0.35, 0.2), (0.1, 0.2), (0.5, 0.2), (0.2, 0.0), (0.25, 0.2)] {
            let d = estimate(truth, configured);
            assert!(
                (d - truth).abs() < 1e-9,
                "true {truth}, configured {configured}: {d}"
            );
        }
    }

    #[test]
    fn stays_at_the_configured_delay_when_it_is_right() {
        for d in [0.0, 0.2, 0.23] {
            assert_eq!(estimate(d, d), d);
        }
    }
}
