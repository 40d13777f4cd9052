//! A simulated machine: what the real low-level controller and hydraulics do
//! with a velocity command, for evaluation and for the daemon's simulated
//! backend.
//!
//! It takes (β̇_cmd, v_cmd) like the real machine, holds each command back by
//! an input delay, tracks it with a first-order velocity response limited by the
//! acceleration bounds, integrates the kinematic model (paper eq. 5) at a fine
//! step and reports the state, optionally with seeded Gaussian measurement noise.
//!
//! [`PlantPerturbation`] makes it a machine that is not the MPC's model
//! (DESIGN §12): other axle distances, a true delay other than the compensated
//! one, an actuator gain, pose noise and pose latency. Its default is none,
//! and then the plant computes exactly what it computed without it.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::model::{clamp_state, f_continuous, ix, Control, MachineParams, State, VelocityCommand};

/// Errors in plant settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlantError {
    #[error("plant setting `{name}` must be finite and >= 0 (got {value})")]
    Negative { name: &'static str, value: f64 },
    #[error("plant setting `substep` must be in (0, 0.02] s (got {0})")]
    BadSubstep(f64),
    #[error("plant perturbation `{name}` {requirement} (got {value})")]
    Perturbation {
        name: &'static str,
        requirement: &'static str,
        value: f64,
    },
    #[error("plant command is not finite: beta_dot {beta_dot}, v {v}")]
    NonFiniteCommand { beta_dot: f64, v: f64 },
}

impl PlantError {
    /// The setting (`PlantConfig` or `PlantPerturbation` field name) an error is about.
    pub fn setting(&self) -> Option<&'static str> {
        match self {
            Self::Negative { name, .. } | Self::Perturbation { name, .. } => Some(name),
            Self::BadSubstep(_) => Some("substep"),
            Self::NonFiniteCommand { .. } => None,
        }
    }
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

/// How the real machine differs from the MPC's model (DESIGN §12). The default
/// is no difference; each field is off at its default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantPerturbation {
    /// The plant's L_f is the nominal L_f × this (the MPC keeps the nominal).
    pub scale_lf: f64,
    /// The plant's L_r is the nominal L_r × this.
    pub scale_lr: f64,
    /// The plant's true input delay [s]; `None`: [`PlantConfig::delay`], the
    /// delay the MPC compensates.
    pub delay: Option<f64>,
    /// Achieved β̇ and v are this × the (saturated) command. The plant's own
    /// bounds on β̇ and v grow with a gain above 1, so the achieved rate is
    /// exactly K × command; the acceleration limits stay.
    pub actuator_gain: f64,
    /// Standard deviation of Gaussian noise on the measured x_f and y_f [m].
    pub pose_noise_xy: f64,
    /// Standard deviation of Gaussian noise on the measured θ_f [rad].
    pub pose_noise_theta: f64,
    /// Age of the pose (x_f, y_f, θ_f) when [`Plant::measure`] reads it [s];
    /// β, β̇ and v (the machine's own sensors) stay current.
    pub pose_latency: f64,
    /// Seed of the pose noise.
    pub seed: u64,
}

impl Default for PlantPerturbation {
    fn default() -> Self {
        Self {
            scale_lf: 1.0,
            scale_lr: 1.0,
            delay: None,
            actuator_gain: 1.0,
            pose_noise_xy: 0.0,
            pose_noise_theta: 0.0,
            pose_latency: 0.0,
            seed: 0,
        }
    }
}

impl PlantPerturbation {
    /// No perturbation (the seed aside).
    pub fn is_nominal(&self) -> bool {
        Self {
            seed: self.seed,
            ..Self::default()
        } == *self
    }

    pub fn validate(&self) -> Result<(), PlantError> {
        let err = |name, requirement, value| {
            Err(PlantError::Perturbation {
                name,
                requirement,
                value,
            })
        };
        for (name, value) in [
            ("scale_lf", self.scale_lf),
            ("scale_lr", self.scale_lr),
            ("actuator_gain", self.actuator_gain),
        ] {
            if !(value.is_finite() && value > 0.0 && value <= 10.0) {
                return err(name, "must be in (0, 10]", value);
            }
        }
        for (name, value) in [
            ("delay", self.delay.unwrap_or(0.0)),
            ("pose_noise_xy", self.pose_noise_xy),
            ("pose_noise_theta", self.pose_noise_theta),
            ("pose_latency", self.pose_latency),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return err(name, "must be finite and >= 0", value);
            }
        }
        for (name, value) in [
            ("delay", self.delay.unwrap_or(0.0)),
            ("pose_latency", self.pose_latency),
        ] {
            if value > 10.0 {
                return err(name, "must be at most 10 s", value);
            }
        }
        Ok(())
    }

    /// The plant's true machine: `nominal` with the axle distances scaled and,
    /// with a gain above 1, the β̇ and v bounds grown by it.
    pub fn true_params(&self, nominal: &MachineParams) -> MachineParams {
        let g = self.actuator_gain.max(1.0);
        MachineParams {
            l_f: nominal.l_f * self.scale_lf,
            l_r: nominal.l_r * self.scale_lr,
            beta_dot_max: nominal.beta_dot_max * g,
            v_max: nominal.v_max * g,
            ..*nominal
        }
    }

    /// The same perturbation with its seed mixed with `name` (FNV-1a), so
    /// each scenario gets its own noise, reproducibly.
    pub fn seeded_for(&self, name: &str) -> Self {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in name.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        Self {
            seed: self.seed ^ h,
            ..*self
        }
    }
}

/// The simulated machine. Deterministic for a given configuration and seed.
#[derive(Debug, Clone)]
pub struct Plant {
    /// The true machine ([`PlantPerturbation::true_params`]).
    params: MachineParams,
    /// The nominal machine: the command saturation of the low-level controller.
    nominal: MachineParams,
    /// The settings, `delay` the true one.
    config: PlantConfig,
    perturbation: PlantPerturbation,
    state: State,
    time: f64,
    /// Commands waiting for their delay to pass, as (time they take effect, command).
    pending: VecDeque<(f64, VelocityCommand)>,
    active: VelocityCommand,
    /// Linear ramps of (β̇, v_f) used when the time constant is zero.
    ramps: [Ramp; 2],
    rng: ChaCha8Rng,
    /// Noise of the perturbation's pose noise (its own stream, so that
    /// `PlantConfig::noise` draws what it drew without it).
    pose_rng: ChaCha8Rng,
    /// True states after each integration step, as (time, state), kept for
    /// the pose latency only (empty without it).
    history: VecDeque<(f64, State)>,
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
        Self::perturbed(params, config, PlantPerturbation::default(), initial)
    }

    /// A plant that differs from `params` (the MPC's model) by `perturbation`.
    pub fn perturbed(
        params: MachineParams,
        config: PlantConfig,
        perturbation: PlantPerturbation,
        initial: State,
    ) -> Result<Self, PlantError> {
        config.validate()?;
        perturbation.validate()?;
        let nominal = params;
        let params = perturbation.true_params(&nominal);
        let config = PlantConfig {
            delay: perturbation.delay.unwrap_or(config.delay),
            ..config
        };
        let mut state = initial;
        clamp_state(&params, &mut state);
        let mut history = VecDeque::new();
        if perturbation.pose_latency > 0.0 {
            history.push_back((0.0, state));
        }
        Ok(Self {
            params,
            nominal,
            config,
            perturbation,
            state,
            time: 0.0,
            pending: VecDeque::new(),
            active: VelocityCommand {
                beta_dot: state[ix::BETA_DOT],
                v: state[ix::V],
            },
            ramps: [Ramp::default(); 2],
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            pose_rng: ChaCha8Rng::seed_from_u64(perturbation.seed),
            history,
        })
    }

    /// The true machine (the nominal one changed by the perturbation).
    pub fn params(&self) -> &MachineParams {
        &self.params
    }

    pub fn perturbation(&self) -> &PlantPerturbation {
        &self.perturbation
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
    /// are saturated at the machine's bounds, as the low-level controller does,
    /// and the actuators achieve the actuator gain × that.
    pub fn command(&mut self, cmd: VelocityCommand) -> Result<(), PlantError> {
        if !cmd.is_finite() {
            return Err(PlantError::NonFiniteCommand {
                beta_dot: cmd.beta_dot,
                v: cmd.v,
            });
        }
        // The low-level controller saturates at the nominal bounds; a gain error
        // scales what it achieves.
        let k = self.perturbation.actuator_gain;
        let cmd = cmd.limited(&self.nominal);
        let cmd = VelocityCommand {
            beta_dot: k * cmd.beta_dot,
            v: k * cmd.v,
        };
        self.pending.push_back((self.time + self.config.delay, cmd));
        Ok(())
    }

    /// Advances the simulation by `duration` seconds.
    pub fn advance(&mut self, duration: f64) {
        self.advance_observed(duration, |_, _| {});
    }

    /// Advances like [`Self::advance`] and shows `observe` the time and state after
    /// every integration sub-step (the evaluation's clearance is checked there,
    /// not only at ticks: DESIGN §10).
    pub fn advance_observed(&mut self, duration: f64, mut observe: impl FnMut(f64, &State)) {
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
            observe(self.time, &self.state);
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
        if self.perturbation.pose_latency > 0.0 {
            self.history.push_back((self.time, next));
            // Keep one entry at or before the oldest instant still read.
            let oldest = self.time - self.perturbation.pose_latency;
            while self.history.len() > 2 && self.history[1].0 <= oldest - 1e-9 {
                self.history.pop_front();
            }
        }
    }

    /// The true pose (x_f, y_f, θ_f) `age` seconds ago, linear between the
    /// stored integration steps (θ along the shorter arc); before the start,
    /// the initial pose.
    fn pose_at_age(&self, age: f64) -> [f64; 3] {
        let pose = |x: &State| [x[ix::X], x[ix::Y], x[ix::THETA]];
        let t = self.time - age;
        let Some(&(t0, x0)) = self.history.front() else {
            return pose(&self.state);
        };
        if t <= t0 + 1e-9 {
            return pose(&x0);
        }
        for w in self.history.iter().zip(self.history.iter().skip(1)) {
            let (&(ta, xa), &(tb, xb)) = w;
            if (t - tb).abs() <= 1e-9 {
                return pose(&xb);
            }
            if t < tb {
                let s = (t - ta) / (tb - ta);
                let dth = crate::model::wrap_angle(xb[ix::THETA] - xa[ix::THETA]);
                return [
                    xa[ix::X] + s * (xb[ix::X] - xa[ix::X]),
                    xa[ix::Y] + s * (xb[ix::Y] - xa[ix::Y]),
                    xa[ix::THETA] + s * dth,
                ];
            }
        }
        pose(&self.state)
    }

    /// The state as a sensor reports it: the true state plus seeded Gaussian
    /// noise; with the perturbation, the pose `pose_latency` old and with its
    /// own noise on top.
    pub fn measure(&mut self) -> State {
        let n = self.config.noise;
        let mut x = self.state;
        if self.perturbation.pose_latency > 0.0 {
            let [px, py, pth] = self.pose_at_age(self.perturbation.pose_latency);
            x[ix::X] = px;
            x[ix::Y] = py;
            x[ix::THETA] = pth;
        }
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
        let pn = self.perturbation;
        for (i, sd) in [
            (ix::X, pn.pose_noise_xy),
            (ix::Y, pn.pose_noise_xy),
            (ix::THETA, pn.pose_noise_theta),
        ] {
            if sd > 0.0 {
                if let Ok(dist) = Normal::new(0.0, sd) {
                    x[i] += dist.sample(&mut self.pose_rng);
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

    /// A scripted run: commands that change every tick; every true and
    /// measured state hashed bit by bit (FNV-1a).
    fn scripted_hash(config: PlantConfig, perturbation: Option<PlantPerturbation>) -> u64 {
        let p = MachineParams::default();
        let x0 = State::new(0.5, -0.3, 0.4, 0.1, 0.0, 0.2);
        let mut plant = match perturbation {
            None => Plant::new(p, config, x0).unwrap(),
            Some(d) => Plant::perturbed(p, config, d, x0).unwrap(),
        };
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |v: f64| {
            for b in v.to_bits().to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        };
        for k in 0..120 {
            let t = k as f64 * 0.2;
            plant
                .command(VelocityCommand {
                    beta_dot: 0.5 * (0.7 * t).sin(),
                    v: 1.2 * (0.3 * t).cos(),
                })
                .unwrap();
            plant.advance(0.2);
            for v in plant.state().iter().chain(plant.measure().iter()) {
                eat(*v);
            }
        }
        h
    }

    #[test]
    fn no_perturbation_is_bit_identical_to_the_plant_before_it() {
        // Hashes recorded with the plant of a335e36 (before PlantPerturbation).
        let noisy = PlantConfig {
            noise: MeasurementNoise {
                position: 0.02,
                heading: 0.01,
                beta: 0.01,
                beta_dot: 0.01,
                speed: 0.01,
            },
            seed: 3,
            ..Default::default()
        };
        let golden = [
            (PlantConfig::ideal(), 0x8236976177032575_u64),
            (PlantConfig::default(), 0xe7faa3e575100341),
            (noisy, 0x207cd72974a99589),
        ];
        let none = PlantPerturbation {
            seed: 99, // the seed alone changes nothing
            ..Default::default()
        };
        assert!(none.is_nominal());
        for (c, h) in golden {
            assert_eq!(scripted_hash(c, None), h);
            assert_eq!(scripted_hash(c, Some(none)), h);
            assert_eq!(scripted_hash(c, Some(none.seeded_for("r4.5_b0_h0"))), h);
        }
        // And a perturbation does change it.
        let gain = PlantPerturbation {
            actuator_gain: 0.9,
            ..Default::default()
        };
        assert_ne!(scripted_hash(PlantConfig::ideal(), Some(gain)), golden[0].1);
    }

    /// Drives `plant` with a constant command for `t` seconds (ticks of 0.2 s).
    fn hold(plant: &mut Plant, cmd: VelocityCommand, t: f64) {
        let ticks = (t / 0.2).round() as usize;
        for _ in 0..ticks {
            plant.command(cmd).unwrap();
            plant.advance(0.2);
        }
    }

    #[test]
    fn actuator_gain_scales_achieved_rates_and_distance() {
        let p = MachineParams::default();
        for k in [0.8, 1.2] {
            let pert = PlantPerturbation {
                actuator_gain: k,
                ..Default::default()
            };
            // Straight: the same command and time, k × the distance (the ramp
            // accelerations stay under the limits, so the whole profile scales).
            let cmd = VelocityCommand {
                beta_dot: 0.0,
                v: 0.15,
            };
            let mut nominal = Plant::new(p, PlantConfig::ideal(), State::zeros()).unwrap();
            let mut real = Plant::perturbed(p, PlantConfig::ideal(), pert, State::zeros()).unwrap();
            hold(&mut nominal, cmd, 5.0);
            hold(&mut real, cmd, 5.0);
            let (d0, d) = (nominal.state()[ix::X], real.state()[ix::X]);
            assert!((d / d0 - k).abs() < 1e-12, "gain {k}: {d} vs {d0}");
            assert!((real.state()[ix::V] - k * 0.15).abs() < 1e-12);
            // Articulation at rest: k × the angle.
            let cmd = VelocityCommand {
                beta_dot: 0.08,
                v: 0.0,
            };
            let mut nominal = Plant::new(p, PlantConfig::ideal(), State::zeros()).unwrap();
            let mut real = Plant::perturbed(p, PlantConfig::ideal(), pert, State::zeros()).unwrap();
            hold(&mut nominal, cmd, 1.0);
            hold(&mut real, cmd, 1.0);
            let (b0, b) = (nominal.state()[ix::BETA], real.state()[ix::BETA]);
            assert!((b / b0 - k).abs() < 1e-12, "gain {k}: beta {b} vs {b0}");
        }
        // A saturated command: k × the bound (above 1 the machine exceeds the model's bound).
        let pert = PlantPerturbation {
            actuator_gain: 1.2,
            ..Default::default()
        };
        let mut real = Plant::perturbed(p, PlantConfig::ideal(), pert, State::zeros()).unwrap();
        hold(
            &mut real,
            VelocityCommand {
                beta_dot: 0.0,
                v: 5.0,
            },
            3.0,
        );
        assert!((real.state()[ix::V] - 1.2 * p.v_max).abs() < 1e-12);
    }

    #[test]
    fn scaled_geometry_turns_on_the_kinematic_radius() {
        // Constant β and v: the front axle runs on a circle of radius
        // R = (L_f cos β + L_r) / sin β (paper eq. 5 with β̇ = 0).
        let p = MachineParams::default();
        let (beta, v) = (0.3, 0.5);
        for (slf, slr) in [(1.0, 1.0), (0.9, 1.0), (1.2, 1.0), (1.0, 0.9), (1.0, 1.1)] {
            let pert = PlantPerturbation {
                scale_lf: slf,
                scale_lr: slr,
                ..Default::default()
            };
            let x0 = State::new(0.0, 0.0, 0.0, beta, 0.0, v);
            let mut plant = Plant::perturbed(p, PlantConfig::ideal(), pert, x0).unwrap();
            hold(&mut plant, VelocityCommand { beta_dot: 0.0, v }, 4.0);
            let x = plant.state();
            let (lf, lr) = (p.l_f * slf, p.l_r * slr);
            let r = (lf * beta.cos() + lr) / beta.sin();
            // Heading gained: v t / R; the axle on the circle about (0, R).
            assert!((x[ix::THETA] - v * 4.0 / r).abs() < 1e-9, "{slf},{slr}");
            assert!(((x[ix::X]).hypot(x[ix::Y] - r) - r).abs() < 1e-9);
            assert_eq!(plant.params().l_f, lf);
            assert_eq!(plant.params().l_r, lr);
        }
    }

    #[test]
    fn plant_delay_shifts_the_response_by_its_difference() {
        let p = MachineParams::default();
        let config = PlantConfig {
            delay: 0.2,
            ..Default::default()
        };
        let cmd = VelocityCommand {
            beta_dot: 0.3,
            v: 0.6,
        };
        for s in [0.1, 0.35] {
            let pert = PlantPerturbation {
                delay: Some(s),
                ..Default::default()
            };
            let mut nominal = Plant::new(p, config, State::zeros()).unwrap();
            let mut real = Plant::perturbed(p, config, pert, State::zeros()).unwrap();
            assert_eq!(real.config().delay, s);
            nominal.command(cmd).unwrap();
            real.command(cmd).unwrap();
            // Sample both every 0.05 s; the real one at t equals the nominal at t − (s − 0.2).
            let step = 0.05;
            let shift = ((s - 0.2) / step).round() as i64;
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for _ in 0..60 {
                nominal.advance(step);
                real.advance(step);
                a.push(nominal.state());
                b.push(real.state());
            }
            for (k, x) in b.iter().enumerate() {
                let j = k as i64 - shift;
                let expected = if j < 0 {
                    State::zeros()
                } else if (j as usize) < a.len() {
                    a[j as usize]
                } else {
                    continue;
                };
                assert!(
                    (x - expected).norm() < 1e-9,
                    "delay {s}, sample {k}: {x:?} vs {expected:?}"
                );
            }
            assert!(b[5][ix::V] != a[5][ix::V]);
        }
    }

    #[test]
    fn pose_latency_reads_an_old_pose_and_current_machine_state() {
        let p = MachineParams::default();
        let pert = PlantPerturbation {
            pose_latency: 0.2,
            ..Default::default()
        };
        let x0 = State::new(1.0, 2.0, 0.5, 0.0, 0.0, 0.0);
        let mut plant = Plant::perturbed(p, PlantConfig::default(), pert, x0).unwrap();
        let mut reference = Plant::new(p, PlantConfig::default(), x0).unwrap();
        let mut previous = plant.state();
        for k in 0..40 {
            let t = k as f64 * 0.2;
            let cmd = VelocityCommand {
                beta_dot: 0.4 * (0.9 * t).sin(),
                v: 0.8 * (0.4 * t).cos(),
            };
            plant.command(cmd).unwrap();
            reference.command(cmd).unwrap();
            plant.advance(0.2);
            reference.advance(0.2);
            // The latency changes what is read, never the machine.
            assert_eq!(plant.state(), reference.state());
            let m = plant.measure();
            let x = plant.state();
            for i in [ix::X, ix::Y, ix::THETA] {
                assert_eq!(m[i], previous[i], "tick {k}: the pose of one tick before");
            }
            for i in [ix::BETA, ix::BETA_DOT, ix::V] {
                assert_eq!(m[i], x[i]);
            }
            assert!(k < 3 || m[ix::X] != x[ix::X]);
            previous = x;
        }
        // Before the start: the initial pose.
        let mut fresh = Plant::perturbed(p, PlantConfig::default(), pert, x0).unwrap();
        assert_eq!(fresh.measure(), x0);
        // Half a tick: between the true poses (linear within a 10 ms sub-step).
        let half = PlantPerturbation {
            pose_latency: 0.1,
            ..Default::default()
        };
        let mut a = Plant::perturbed(p, PlantConfig::ideal(), half, x0).unwrap();
        let cmd = VelocityCommand {
            beta_dot: 0.2,
            v: 0.8,
        };
        a.command(cmd).unwrap();
        a.advance(0.9);
        let mut b = Plant::new(p, PlantConfig::ideal(), x0).unwrap();
        b.command(cmd).unwrap();
        b.advance(0.8);
        let (ma, xb) = (a.measure(), b.state());
        assert!(
            (ma[ix::X] - xb[ix::X]).abs() < 1e-12 && (ma[ix::THETA] - xb[ix::THETA]).abs() < 1e-12
        );
    }

    #[test]
    fn pose_noise_has_the_requested_spread_and_is_seeded() {
        let p = MachineParams::default();
        let pert = PlantPerturbation {
            pose_noise_xy: 0.03,
            pose_noise_theta: 0.02,
            seed: 5,
            ..Default::default()
        };
        let x0 = State::new(1.0, -1.0, 0.3, 0.1, 0.0, 0.0);
        let samples = |pert: PlantPerturbation| {
            let mut plant = Plant::perturbed(p, PlantConfig::ideal(), pert, x0).unwrap();
            (0..20_000).map(|_| plant.measure()).collect::<Vec<_>>()
        };
        let a = samples(pert);
        for (i, sd) in [(ix::X, 0.03), (ix::Y, 0.03), (ix::THETA, 0.02)] {
            let n = a.len() as f64;
            let mean = a.iter().map(|m| m[i] - x0[i]).sum::<f64>() / n;
            let var = a.iter().map(|m| (m[i] - x0[i] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            // Standard error of the std over 20 000 samples ≈ 0.5 %.
            assert!(
                (var.sqrt() / sd - 1.0).abs() < 0.03,
                "index {i}: std {}",
                var.sqrt()
            );
            assert!(mean.abs() < 4.0 * sd / n.sqrt(), "index {i}: mean {mean}");
        }
        for m in &a {
            assert_eq!(m[ix::BETA], x0[ix::BETA]);
            assert_eq!(m[ix::V], x0[ix::V]);
        }
        assert_eq!(samples(pert), a, "same seed, same noise");
        assert_ne!(samples(PlantPerturbation { seed: 6, ..pert }), a);
        let (s1, s2) = (
            pert.seeded_for("r4.5_b0_h0"),
            pert.seeded_for("r4.5_b0_h45"),
        );
        assert_ne!(s1.seed, s2.seed);
        assert_eq!(s1, pert.seeded_for("r4.5_b0_h0"));
    }

    #[test]
    fn bad_perturbations_are_rejected_naming_the_field() {
        let p = MachineParams::default();
        let cases = [
            (
                "scale_lf",
                PlantPerturbation {
                    scale_lf: 0.0,
                    ..Default::default()
                },
            ),
            (
                "scale_lr",
                PlantPerturbation {
                    scale_lr: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "delay",
                PlantPerturbation {
                    delay: Some(-0.1),
                    ..Default::default()
                },
            ),
            (
                "actuator_gain",
                PlantPerturbation {
                    actuator_gain: -1.0,
                    ..Default::default()
                },
            ),
            (
                "pose_noise_xy",
                PlantPerturbation {
                    pose_noise_xy: -0.01,
                    ..Default::default()
                },
            ),
            (
                "pose_noise_theta",
                PlantPerturbation {
                    pose_noise_theta: f64::INFINITY,
                    ..Default::default()
                },
            ),
            (
                "pose_latency",
                PlantPerturbation {
                    pose_latency: -0.2,
                    ..Default::default()
                },
            ),
        ];
        for (name, pert) in cases {
            let e = Plant::perturbed(p, PlantConfig::ideal(), pert, State::zeros()).unwrap_err();
            assert!(
                matches!(&e, PlantError::Perturbation { name: n, .. } if *n == name),
                "{name}: {e}"
            );
        }
    }
}
