//! Online estimate of the actuator gain (DESIGN §12, issue 16).
//!
//! The MPC commands the velocities (β̇, v_f) of its planned x₁, and x₁ is the
//! measured state plus one tick of bounded acceleration. If the machine
//! achieves K × the command, that loop has a pole at K: with K > 1 the
//! velocities grow by K every tick the plan asks to hold them (until the
//! machine's limits), with K < 1 they stall at K·a_max·Δt / (1 − K) — 0.3 m/s
//! at K = 0.6. Measured on the paper's 128 scenarios without this estimate:
//! K = 1.2 reached 25/128, K = 0.6 45/128 (docs/robustness.md).
//!
//! Each tick, per channel, the velocity measured now is compared with the
//! command that has fully acted by now (issued ⌈(d + Δt)/Δt⌉ ticks ago, d the
//! compensated delay): m ≈ K c. Only informative samples are used: |c| large
//! enough, the command steady over its neighbours and the measured velocity
//! steady (so the machine was not acceleration-limited), and for β̇ the joint
//! away from its stop. K is their recursive least-squares ratio with
//! forgetting, Σλⁱ c m / Σλⁱ c², starting from a prior of K = 1, clamped to
//! [`MIN_GAIN`, `MAX_GAIN`]. The command sent is the intended one divided by
//! K̂, saturated at the machine's bounds; the delay compensator is told the
//! velocity that should then be achieved, K̂ × the command sent.
//!
//! An estimate within [`DEADBAND`] of 1 is not applied, so on a machine
//! without gain error (velocity lag and delays off the tick grid included)
//! the commands are bit-identical to those without the estimate; on the ideal
//! plant every informative sample has m = c exactly and K̂ stays exactly 1.

use std::collections::VecDeque;

use crate::model::VelocityCommand;
use crate::model::{ix, MachineParams, State};

/// Smallest and largest gain the estimate may take.
pub const MIN_GAIN: f64 = 0.5;
pub const MAX_GAIN: f64 = 2.0;
/// Forgetting factor per informative sample (≈ 20 samples of memory).
pub const FORGETTING: f64 = 0.95;
/// Estimates within this of 1 are not applied (the commands stay exactly the
/// MPC's): a machine without gain error but with a velocity lag, or a delay
/// that is not a multiple of the command period, gives estimates a hair off 1.
pub const DEADBAND: f64 = 0.03;

/// One velocity channel's estimate.
#[derive(Debug, Clone, Copy)]
struct Channel {
    /// Σλⁱ c m and Σλⁱ c² (the prior included).
    s_cm: f64,
    s_cc: f64,
    gain: f64,
    /// Smallest |c| of an informative sample.
    min_command: f64,
    /// Largest change of the command between neighbours, and of the measured
    /// velocity over a tick, of an informative sample.
    steady: f64,
}

impl Channel {
    fn new(prior: f64, min_command: f64, steady: f64) -> Self {
        Self {
            s_cm: prior,
            s_cc: prior,
            gain: 1.0,
            min_command,
            steady,
        }
    }

    fn sample(&mut self, c: f64, m: f64) {
        self.s_cm = FORGETTING * self.s_cm + c * m;
        self.s_cc = FORGETTING * self.s_cc + c * c;
        self.gain = (self.s_cm / self.s_cc).clamp(MIN_GAIN, MAX_GAIN);
    }
}

/// The actuator-gain estimate of (β̇, v_f) and the command scaling.
#[derive(Debug, Clone)]
pub struct GainEstimator {
    params: MachineParams,
    /// Ticks from a command's issue until it has fully acted.
    lag: usize,
    /// Commands sent, oldest first (the last `lag + 2`).
    sent: VecDeque<VelocityCommand>,
    /// Measured (β̇, v) of the previous tick.
    last: Option<[f64; 2]>,
    channels: [Channel; 2],
}

impl GainEstimator {
    /// For a machine with `params`, a compensated delay `delay` ≥ 0 and the
    /// command period `dt` > 0.
    pub fn new(params: MachineParams, delay: f64, dt: f64) -> Self {
        let lag = Self::lag_of(delay, dt);
        let most = Self::lag_of(crate::delay_estimate::MAX_DELAY.max(delay), dt);
        Self {
            params,
            lag,
            sent: VecDeque::with_capacity(most + 3),
            last: None,
            channels: [
                // β̇: commands of 0.05 rad/s and more, steady within 0.03 rad/s.
                Channel::new(0.1, 0.05, 0.03),
                // v_f: 0.1 m/s and more, steady within 0.05 m/s.
                Channel::new(1.0, 0.1, 0.05),
            ],
        }
    }

    fn lag_of(delay: f64, dt: f64) -> usize {
        ((delay + dt) / dt - 1e-9).ceil().max(1.0) as usize
    }

    /// A new compensated delay (e.g. the online estimate).
    pub fn set_delay(&mut self, delay: f64, dt: f64) {
        self.lag = Self::lag_of(delay, dt);
    }

    /// The current estimates (β̇, v_f).
    pub fn gains(&self) -> [f64; 2] {
        [self.channels[0].gain, self.channels[1].gain]
    }

    /// The gains the commands are divided by: the estimates, or 1 within [`DEADBAND`].
    pub fn applied_gains(&self) -> [f64; 2] {
        self.gains()
            .map(|g| if (g - 1.0).abs() > DEADBAND { g } else { 1.0 })
    }

    /// Forgets the commands (not the estimate: the gain is the machine's).
    pub fn reset(&mut self) {
        self.sent.clear();
        self.last = None;
    }

    /// Takes the state measured at the start of a tick into account.
    pub fn observe(&mut self, measured: &State) {
        let m = [measured[ix::BETA_DOT], measured[ix::V]];
        if !(m[0].is_finite() && m[1].is_finite()) {
            self.last = None;
            return;
        }
        let n = self.sent.len();
        if let (Some(last), true) = (self.last, n > self.lag) {
            // The command that has fully acted, its predecessor and successor.
            let j = n - self.lag;
            let c = self.sent[j];
            let before = self.sent[j - 1];
            let after = self.sent.get(j + 1).copied().unwrap_or(c);
            let joint_free = measured[ix::BETA].abs() < self.params.beta_max - 0.02;
            for (k, ch) in self.channels.iter_mut().enumerate() {
                let pick = |v: &VelocityCommand| if k == 0 { v.beta_dot } else { v.v };
                let (cj, cb, ca) = (pick(&c), pick(&before), pick(&after));
                let informative = cj.abs() >= ch.min_command
                    && (cj - cb).abs() <= ch.steady
                    && (ca - cj).abs() <= ch.steady
                    && (m[k] - last[k]).abs() <= ch.steady
                    && (k == 1 || joint_free);
                if informative {
                    ch.sample(cj, m[k]);
                }
            }
        }
        self.last = Some(m);
    }

    /// The command to send for the `intended` achieved velocities: divided by
    /// the gain, limited to the machine's bounds.
    pub fn to_send(&self, intended: VelocityCommand) -> VelocityCommand {
        let [gb, gv] = self.applied_gains();
        VelocityCommand {
            beta_dot: intended.beta_dot / gb,
            v: intended.v / gv,
        }
        .limited(&self.params)
    }

    /// Records a command sent; returns the velocities it is expected to
    /// achieve (gain × sent).
    pub fn record(&mut self, sent: VelocityCommand) -> VelocityCommand {
        let [gb, gv] = self.applied_gains();
        if self.sent.len() > self.lag + 2 {
            self.sent.pop_front();
        }
        self.sent.push_back(sent);
        VelocityCommand {
            beta_dot: gb * sent.beta_dot,
            v: gv * sent.v,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{Plant, PlantConfig, PlantPerturbation};

    /// Sends through the estimator: (sent, expected achieved).
    fn send(
        est: &mut GainEstimator,
        intended: VelocityCommand,
    ) -> (VelocityCommand, VelocityCommand) {
        let sent = est.to_send(intended);
        (sent, est.record(sent))
    }

    /// Drives a plant with gain `k` through a speed and articulation profile,
    /// commanding through the estimator; returns the final estimates.
    fn estimate(k: f64, config: PlantConfig, delay: f64) -> [f64; 2] {
        let p = MachineParams::default();
        let pert = PlantPerturbation {
            actuator_gain: k,
            ..Default::default()
        };
        let mut plant = Plant::perturbed(p, config, pert, State::zeros()).unwrap();
        let mut est = GainEstimator::new(p, delay, 0.2);
        for tick in 0..150 {
            let t = tick as f64 * 0.2;
            est.observe(&plant.measure());
            // Slow changes: the command is steady over neighbours most of the time.
            let intended = VelocityCommand {
                beta_dot: 0.2 * (0.15 * t).sin(),
                v: 0.6 + 0.3 * (0.1 * t).sin(),
            };
            let (sent, _) = send(&mut est, intended);
            plant.command(sent).unwrap();
            plant.advance(0.2);
        }
        est.gains()
    }

    #[test]
    fn estimates_the_gain_of_the_plant() {
        for k in [0.6, 0.8, 1.2, 1.4] {
            for (config, delay) in [
                (PlantConfig::ideal(), 0.0),
                (
                    PlantConfig {
                        delay: 0.2,
                        ..PlantConfig::ideal()
                    },
                    0.2,
                ),
            ] {
                let g = estimate(k, config, delay);
                assert!(
                    (g[0] - k).abs() < 0.01 * k && (g[1] - k).abs() < 0.01 * k,
                    "K {k}, delay {delay}: {g:?}"
                );
            }
        }
    }

    #[test]
    fn stays_exactly_one_without_gain_error() {
        assert_eq!(estimate(1.0, PlantConfig::ideal(), 0.0), [1.0, 1.0]);
        let d = PlantConfig {
            delay: 0.2,
            ..PlantConfig::ideal()
        };
        assert_eq!(estimate(1.0, d, 0.2), [1.0, 1.0]);
    }

    #[test]
    fn small_estimates_are_not_applied() {
        let p = MachineParams::default();
        let mut est = GainEstimator::new(p, 0.0, 0.2);
        est.channels[1].gain = 1.0 + 0.5 * DEADBAND;
        let cmd = VelocityCommand {
            beta_dot: 0.1,
            v: 0.4,
        };
        assert_eq!(send(&mut est, cmd), (cmd, cmd));
        // A lagging machine without gain error: the estimate stays in the deadband.
        let lag = PlantConfig {
            delay: 0.3,
            tau_beta_dot: 0.1,
            tau_v: 0.2,
            ..PlantConfig::default()
        };
        let g = estimate(1.0, lag, 0.3);
        assert!(g.iter().all(|g| (g - 1.0).abs() < DEADBAND), "{g:?}");
    }

    #[test]
    fn scales_and_saturates_the_command() {
        let p = MachineParams::default();
        let mut est = GainEstimator::new(p, 0.0, 0.2);
        est.channels[1].gain = 0.8;
        let (sent, achieved) = send(
            &mut est,
            VelocityCommand {
                beta_dot: 0.1,
                v: 0.4,
            },
        );
        assert_eq!(sent.beta_dot, 0.1);
        assert!((sent.v - 0.5).abs() < 1e-15 && (achieved.v - 0.4).abs() < 1e-15);
        let (sent, achieved) = send(
            &mut est,
            VelocityCommand {
                beta_dot: 0.0,
                v: 1.0,
            },
        );
        assert_eq!(sent.v, p.v_max);
        assert!((achieved.v - 0.8).abs() < 1e-15);
    }
}
