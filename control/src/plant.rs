//! A simulated machine: what the real low-level controller and hydraulics do
//! with a velocity command, for evaluation and for the daemon's simulated
//! backend.
//!
//! It takes (β̇_cmd, v_cmd) like the real machine, holds each command back by
//! an input delay, tracks it with a first-order velocity response limited by the
//! acceleration bounds, integrates the kinematic model (paper eq. 5) at a fine
//! step and reports the state, optionally with seeded Gaussian measurement noise.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::model::{clamp_state, f_continuous, ix, Control, MachineParams, State};

/// Errors in plant settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlantError {
    #[error("plant setting `{name}` must be finite and >= 0 (got {value})")]
    Negative { name: &'static str, value: f64 },
    #[error("plant setting `substep` must be in (0, 0.02] s (got {0})")]
    BadSubstep(f64),
    #[error("plant command is not finite: beta_dot {beta_dot}, v {v}")]
    NonFiniteCommand { beta_dot: f64, v: f64 },
}

/// Standard deviations of the measurement noise added by [`Plant::measure`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeasurementNoise {
    /// Position [m].
    pub position: f64,
    /// Heading θ_f [rad].
    pub heading: f64,
    /// Articulation β [rad].
    pub beta: f64,
    /// Articulation rate β̇ [rad/s].
    pub beta_dot: f64,
    /// Speed v_f [m/s].
    pub speed: f64,
}

/// Plant settings. The default is the paper's real machine: 0.2 s input delay,
/// a fast velocity response, no noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantConfig {
    /// Input delay between a command and its effect [s], any value ≥ 0.
    pub delay: f64,
    /// First-order time constant of the articulation-rate response [s]; 0 means
    /// a linear ramp to each command over `ramp` seconds instead.
    pub tau_beta_dot: f64,
    /// First-order time constant of the speed response [s]; 0 as above.
    pub tau_v: f64,
    /// Duration of the linear ramp used with a zero time constant [s]; the
    /// command period (0.2 s) makes the plant reproduce the MPC's model.
    pub ramp: f64,
    /// Integration step [s], at most 20 ms.
    pub substep: f64,
    pub noise: MeasurementNoise,
    /// Seed of the measurement noise.
    pub seed: u64,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self {
            delay: 0.2,
            tau_beta_dot: 0.1,
            tau_v: 0.2,
            ramp: 0.2,
            substep: 0.01,
            noise: Default::default(),
            seed: 0,
        }
    }
}

impl PlantConfig {
    /// The ideal machine: no delay, no lag, no noise; with commands reachable
    /// within one tick it reproduces the MPC's model.
    pub fn ideal() -> Self {
        Self {
            delay: 0.0,
            tau_beta_dot: 0.0,
            tau_v: 0.0,
            ..Self::default()
        }
    }

    pub fn validate(&self) -> Result<(), PlantError> {
        let n = &self.noise;
        for (name, value) in [
            ("delay", self.delay),
            ("tau_beta_dot", self.tau_beta_dot),
            ("tau_v", self.tau_v),
            ("noise.position", n.position),
            ("noise.heading", n.heading),
            ("noise.beta", n.beta),
            ("noise.beta_dot", n.beta_dot),
            ("noise.speed", n.speed),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(PlantError::Negative { name, value });
            }
        }
        if !(self.ramp.is_finite() && self.ramp > 0.0) {
            return Err(PlantError::Negative {
                name: "ramp",
                value: self.ramp,
            });
        }
        if !(self.substep > 0.0 && self.substep <= 0.02) {
            return Err(PlantError::BadSubstep(self.substep));
        }
        Ok(())
    }
}

/// A velocity command as the low-level controller takes it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct VelocityCommand {
    /// Articulation rate β̇_cmd [rad/s].
    pub beta_dot: f64,
    /// Front speed v_cmd [m/s].
    pub v: f64,
}

/// The simulated machine. Deterministic for a given configuration and seed.
#[derive(Debug, Clone)]
pub struct Plant {
    params: MachineParams,
    config: PlantConfig,
    state: State,
    time: f64,
    /// Commands waiting for their delay to pass, as (time they take effect, command).
    pending: VecDeque<(f64, VelocityCommand)>,
    active: VelocityCommand,
    /// Linear ramps of (β̇, v_f) used when the time constant is zero.
    ramps: [Ramp; 2],
    rng: ChaCha8Rng,
}

#[derive(Debug, Clone, Copy, Default)]
struct Ramp {
    /// Acceleration while the ramp lasts.
    rate: f64,
    /// Time at which the target is reached.
    until: f64,
}

impl Plant {
    pub fn new(
        params: MachineParams,
        config: PlantConfig,
        initial: State,
    ) -> Result<Self, PlantError> {
        config.validate()?;
        let mut state = initial;
        clamp_state(&params, &mut state);
        Ok(Self {
            params,
            config,
            state,
            time: 0.0,
            pending: VecDeque::new(),
            active: VelocityCommand {
                beta_dot: state[ix::BETA_DOT],
                v: state[ix::V],
            },
            ramps: [Ramp::default(); 2],
            rng: ChaCha8Rng::seed_from_u64(config.seed),
        })
    }

    pub fn time(&self) -> f64 {
        self.time
    }

    /// The true state.
    pub fn state(&self) -> State {
        self.state
    }

    pub fn config(&self) -> &PlantConfig {
        &self.config
    }

    /// The command currently acting on the machine (after the delay).
    pub fn active_command(&self) -> VelocityCommand {
        self.active
    }

    /// Sends a command now; it takes effect after the configured delay. Values
    /// are saturated at the machine's bounds, as the low-level controller does.
    pub fn command(&mut self, cmd: VelocityCommand) -> Result<(), PlantError> {
        if !(cmd.beta_dot.is_finite() && cmd.v.is_finite()) {
            return Err(PlantError::NonFiniteCommand {
                beta_dot: cmd.beta_dot,
                v: cmd.v,
            });
        }
        let p = &self.params;
        let cmd = VelocityCommand {
            beta_dot: cmd.beta_dot.clamp(-p.beta_dot_max, p.beta_dot_max),
            v: cmd.v.clamp(-p.v_max, p.v_max),
        };
        self.pending.push_back((self.time + self.config.delay, cmd));
        Ok(())
    }

    /// Advances the simulation by `duration` seconds.
    pub fn advance(&mut self, duration: f64) {
        self.advance_observed(duration, |_| {});
    }

    /// Advances like [`Self::advance`] and shows `observe` the state after
    /// every integration sub-step (the evaluation's clearance is checked there,
    /// not only at ticks: DESIGN §10).
    pub fn advance_observed(&mut self, duration: f64, mut observe: impl FnMut(&State)) {
        let end = self.time + duration.max(0.0);
        // Tiny remainders from float round-off are not worth a step.
        while end - self.time > 1e-12 {
            while let Some(&(at, cmd)) = self.pending.front() {
                if at > self.time + 1e-12 {
                    break;
                }
                self.pending.pop_front();
                self.activate(cmd);
            }
            // Step to the next event: substep, a command taking effect, a ramp ending, or the end.
            let mut h = self.config.substep.min(end - self.time);
            if let Some(&(at, _)) = self.pending.front() {
                h = h.min(at - self.time);
            }
            for ramp in &self.ramps {
                if ramp.until > self.time {
                    h = h.min(ramp.until - self.time);
                }
            }
            self.integrate(h.max(1e-12));
            observe(&self.state);
        }
        self.time = end;
    }

    /// A command takes effect. With a zero time constant the actuator ramps
    /// linearly to it over `ramp` seconds (acceleration-limited): with commands
    /// taken from the model's next state this reproduces the model exactly.
    fn activate(&mut self, cmd: VelocityCommand) {
        self.active = cmd;
        let p = &self.params;
        let channels = [
            (cmd.beta_dot, self.state[ix::BETA_DOT], p.beta_ddot_max),
            (cmd.v, self.state[ix::V], p.a_max),
        ];
        for (ramp, (target, now, max)) in self.ramps.iter_mut().zip(channels) {
            let rate = ((target - now) / self.config.ramp).clamp(-max, max);
            let duration = if rate == 0.0 {
                0.0
            } else {
                (target - now) / rate
            };
            *ramp = Ramp {
                rate,
                until: self.time + duration,
            };
        }
    }

    /// Accelerations the actuators produce at state `x` while tracking the active command.
    fn actuator_acceleration(&self, x: &State) -> Control {
        let p = &self.params;
        let track = |i: usize, target: f64, now: f64, tau: f64, max: f64| {
            if tau > 0.0 {
                ((target - now) / tau).clamp(-max, max)
            } else if self.ramps[i].until > self.time + 1e-12 {
                self.ramps[i].rate
            } else {
                0.0
            }
        };
        Control::new(
            track(
                0,
                self.active.beta_dot,
                x[ix::BETA_DOT],
                self.config.tau_beta_dot,
                p.beta_ddot_max,
            ),
            track(1, self.active.v, x[ix::V], self.config.tau_v, p.a_max),
        )
    }

    /// One RK4 step of the model with the actuator response as its input.
    fn integrate(&mut self, h: f64) {
        let p = self.params;
        let rhs = |x: &State| f_continuous(&p, x, &self.actuator_acceleration(x));
        let x = self.state;
        let k1 = rhs(&x);
        let k2 = rhs(&(x + k1 * (0.5 * h)));
        let k3 = rhs(&(x + k2 * (0.5 * h)));
        let k4 = rhs(&(x + k3 * h));
        let mut next = x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
        // A finished ramp lands on its target exactly, free of round-off.
        let channels = [
            (ix::BETA_DOT, self.active.beta_dot, self.config.tau_beta_dot),
            (ix::V, self.active.v, self.config.tau_v),
        ];
        for (ramp, (idx, target, tau)) in self.ramps.iter().zip(channels) {
            if tau == 0.0 && ramp.rate != 0.0 && (ramp.until - (self.time + h)).abs() < 1e-12 {
                next[idx] = target;
            }
        }
        clamp_state(&p, &mut next);
        self.state = next;
        self.time += h;
    }

    /// The state as a sensor reports it: the true state plus seeded Gaussian noise.
    pub fn measure(&mut self) -> State {
        let n = self.config.noise;
        let mut x = self.state;
        for (i, sd) in [
            (ix::X, n.position),
            (ix::Y, n.position),
            (ix::THETA, n.heading),
            (ix::BETA, n.beta),
            (ix::BETA_DOT, n.beta_dot),
            (ix::V, n.speed),
        ] {
            if sd > 0.0 {
                // sd > 0 and finite was validated, so Normal::new cannot fail.
                if let Ok(dist) = Normal::new(0.0, sd) {
                    x[i] += dist.sample(&mut self.rng);
                }
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::rk4_step;

    #[test]
    fn step_command_respects_delay_then_first_order_curve() {
        let p = MachineParams::default();
        let tau = 0.1;
        let cfg = PlantConfig {
            delay: 0.23,
            tau_beta_dot: tau,
            tau_v: tau,
            substep: 0.005,
            ..Default::default()
        };
        let mut plant = Plant::new(p, cfg, State::zeros()).unwrap();
        // Small steps so that the initial acceleration 0.05/0.1 = 0.5 stays under the limits.
        let (bd, v) = (0.05, 0.05);
        plant.command(VelocityCommand { beta_dot: bd, v }).unwrap();
        let dt = 0.01;
        let mut t = 0.0;
        while t < 1.2 {
            plant.advance(dt);
            t += dt;
            let x = plant.state();
            if t < cfg.delay - 1e-9 {
                assert_eq!(x[ix::V], 0.0, "moved before the delay at t={t}");
                assert_eq!(x[ix::BETA_DOT], 0.0);
            } else {
                let expected = 1.0 - (-(t - cfg.delay) / tau).exp();
                assert!(
                    (x[ix::V] - v * expected).abs() < 1e-3,
                    "t={t}: v {} vs {}",
                    x[ix::V],
                    v * expected
                );
                assert!((x[ix::BETA_DOT] - bd * expected).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn acceleration_limit_bounds_the_response() {
        let p = MachineParams::default();
        let cfg = PlantConfig {
            delay: 0.0,
            tau_v: 0.01,
            ..Default::default()
        };
        let mut plant = Plant::new(p, cfg, State::zeros()).unwrap();
        plant
            .command(VelocityCommand {
                beta_dot: 0.0,
                v: 1.0,
            })
            .unwrap();
        plant.advance(0.5);
        assert!((plant.state()[ix::V] - 0.5 * p.a_max).abs() < 1e-9);
    }

    #[test]
    fn ideal_plant_reproduces_model_for_reachable_commands() {
        let p = MachineParams::default();
        let x0 = State::new(0.0, 0.0, 0.3, 0.1, 0.0, 0.2);
        let mut plant = Plant::new(p, PlantConfig::ideal(), x0).unwrap();
        // Model: constant acceleration a over 0.2 s reaches v + 0.2 a.
        let u = Control::new(0.2, 0.5);
        let target = VelocityCommand {
            beta_dot: 0.2 * u[0],
            v: 0.2 + 0.2 * u[1],
        };
        plant.command(target).unwrap();
        plant.advance(0.2);
        let model = rk4_step(&p, &x0, &u, 0.2);
        let x = plant.state();
        // A linear ramp over the tick is the model's constant acceleration: equal
        // velocities, positions up to the RK4 error of the model's one 0.2 s step.
        assert_eq!(x[ix::V], model[ix::V]);
        assert!((x[ix::BETA_DOT] - model[ix::BETA_DOT]).abs() < 1e-15);
        assert!((x - model).norm() < 1e-7, "{x:?} vs {model:?}");
        // The ramp ends at the command and the machine holds it.
        plant.advance(0.3);
        assert_eq!(plant.state()[ix::V], target.v);
        assert_eq!(plant.state()[ix::BETA_DOT], target.beta_dot);
    }

    #[test]
    fn noise_is_seeded_and_bounds_hold() {
        let p = MachineParams::default();
        let cfg = PlantConfig {
            noise: MeasurementNoise {
                position: 0.05,
                heading: 0.01,
                ..Default::default()
            },
            seed: 7,
            ..Default::default()
        };
        let mut a = Plant::new(p, cfg, State::zeros()).unwrap();
        let mut b = Plant::new(p, cfg, State::zeros()).unwrap();
        a.command(VelocityCommand {
            beta_dot: 10.0,
            v: -10.0,
        })
        .unwrap();
        b.command(VelocityCommand {
            beta_dot: 10.0,
            v: -10.0,
        })
        .unwrap();
        for _ in 0..50 {
            a.advance(0.2);
            b.advance(0.2);
            assert_eq!(a.measure(), b.measure());
            let x = a.state();
            assert!(x[ix::BETA].abs() <= p.beta_max && x[ix::V].abs() <= p.v_max);
        }
        assert_ne!(a.measure(), a.state());
        assert!(a
            .command(VelocityCommand {
                beta_dot: f64::NAN,
                v: 0.0
            })
            .is_err());
        let bad = PlantConfig {
            substep: 0.05,
            ..Default::default()
        };
        assert!(matches!(
            Plant::new(p, bad, State::zeros()),
            Err(PlantError::BadSubstep(_))
        ));
        let bad = PlantConfig {
            delay: -1.0,
            ..Default::default()
        };
        assert!(Plant::new(p, bad, State::zeros())
            .unwrap_err()
            .to_string()
            .contains("delay"));
    }
}
