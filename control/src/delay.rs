//! Actuator-delay compensation (DESIGN §5, paper §V-A): before each solve the
//! measured state is propagated over the delay d with the model and the
//! commands already sent that act in that window, so the MPC plans from the
//! state the machine will be in when the new command takes effect.
//!
//! # From velocity commands to accelerations
//!
//! The machine takes velocity commands (β̇_cmd, v_cmd), one per tick. As in
//! [`crate::plant`] with zero time constants, a command issued at time tᵢ takes
//! effect at tᵢ + d and from then ramps each velocity linearly to its value over
//! `ramp` seconds (the command period Δt), at the acceleration
//! a = clamp((v_cmd − v(tᵢ + d)) / ramp, ±a_max), and holds it when reached;
//! a newer command replaces the ramp when it takes effect. The accelerations are
//! therefore piecewise constant, and the window [t, t + d] is integrated with
//! RK4 on sub-steps (at most `substep`, split at every activation and ramp end),
//! applying the model's clamping rule after each, exactly as the plant does.
//!
//! The ramp in progress at the measurement time t is continued from the
//! *measured* velocity: it reaches its command at its nominal end
//! t_act + ramp, i.e. a = clamp((v_cmd − v_meas) / (t_act + ramp − t), ±a_max)
//! (with an exact measurement this is the plant's own rate); a ramp whose
//! nominal end has passed but which has not reached its command (one that was
//! acceleration-limited) continues at ±a_max. Before the first command the
//! machine holds its measured velocities.
//!
//! A first-order velocity lag (`tau > 0` in the plant) is not modelled: it is a
//! model error the MPC's feedback absorbs. Neither is the plant's articulation
//! stop exactly: there the plant zeroes β̇ after each sub-step while the ramp
//! goes on, whereas the compensator continues the ramp from the measured β̇
//! (errors of order 1e-4 in the pose over a 0.2 s window).

/// Most commands recorded per command period: the tick's, and between
/// ticks at most one slow-down and one protective stop when a live set
/// arrives ([`crate::pilot::Pilot::check_live`]). The history is reserved
/// for this many, so recording never allocates.
pub const MAX_COMMANDS_PER_PERIOD: usize = 3;
use std::collections::VecDeque;

use crate::model::VelocityCommand;
use crate::model::{clamp_state, f_continuous, ix, Control, MachineParams, State};

/// Default integration sub-step [s] (the plant's).
pub const DEFAULT_SUBSTEP: f64 = 0.01;

/// Errors in the compensator's settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DelayError {
    #[error("delay setting `{name}` {requirement} (got {value})")]
    Setting {
        name: &'static str,
        requirement: &'static str,
        value: f64,
    },
}

/// Propagates measured states over the actuator delay with the commands
/// committed in the window. Holds a short history of the commands sent.
#[derive(Debug, Clone)]
pub struct DelayCompensator {
    params: MachineParams,
    delay: f64,
    ramp: f64,
    substep: f64,
    /// Commands may act up to this much later than `delay` in
    /// [`Self::propagate_with`]; the history keeps what that needs.
    late_max: f64,
    /// Commands as (issue time, command), oldest first; only the ones that can
    /// still matter are kept.
    history: VecDeque<(f64, VelocityCommand)>,
}

/// One velocity channel's ramp: constant `rate` until `until`, then hold `target`.
#[derive(Debug, Clone, Copy, Default)]
struct Ramp {
    rate: f64,
    until: f64,
    target: f64,
}

impl Ramp {
    /// Ramp from `now` (velocity `v`) towards `target`, nominally reached after `span`.
    fn start(t: f64, v: f64, target: f64, span: f64, max: f64) -> Self {
        if target == v {
            return Self {
                rate: 0.0,
                until: t,
                target,
            };
        }
        let rate = if span > 0.0 {
            ((target - v) / span).clamp(-max, max)
        } else {
            max.copysign(target - v)
        };
        Self {
            rate,
            until: t + (target - v) / rate,
            target,
        }
    }

    fn acceleration(&self, t: f64) -> f64 {
        if self.until > t + 1e-12 {
            self.rate
        } else {
            0.0
        }
    }
}

const CHANNELS: [usize; 2] = [ix::BETA_DOT, ix::V];

impl DelayCompensator {
    /// `delay` ≥ 0 [s]; `ramp` > 0 is the duration of the velocity ramp after
    /// each command (the command period Δt).
    pub fn new(params: MachineParams, delay: f64, ramp: f64) -> Result<Self, DelayError> {
        if !(delay.is_finite() && delay >= 0.0) {
            return Err(DelayError::Setting {
                name: "delay",
                requirement: "must be finite and >= 0",
                value: delay,
            });
        }
        if !(ramp.is_finite() && ramp > 0.0) {
            return Err(DelayError::Setting {
                name: "ramp",
                requirement: "must be finite and > 0",
                value: ramp,
            });
        }
        // Commands issued one ramp apart: those in the window plus the active one.
        let capacity = MAX_COMMANDS_PER_PERIOD * ((delay / ramp).ceil() as usize + 4);
        Ok(Self {
            params,
            delay,
            ramp,
            substep: DEFAULT_SUBSTEP,
            late_max: 0.0,
            history: VecDeque::with_capacity(capacity),
        })
    }

    /// Sets the integration sub-step (0, 0.02] s.
    pub fn with_substep(mut self, substep: f64) -> Result<Self, DelayError> {
        if !(substep > 0.0 && substep <= 0.02) {
            return Err(DelayError::Setting {
                name: "substep",
                requirement: "must be in (0, 0.02]",
                value: substep,
            });
        }
        self.substep = substep;
        Ok(self)
    }

    pub fn delay(&self) -> f64 {
        self.delay
    }

    /// Changes the compensated delay (e.g. to an online estimate,
    /// [`crate::delay_estimate`]); ≥ 0 and finite, else ignored.
    pub fn set_delay(&mut self, delay: f64) {
        if delay.is_finite() && delay >= 0.0 {
            self.delay = delay;
        }
    }

    /// Makes room for the command history of delays up to `max_delay`, so that
    /// a later [`Self::set_delay`] does not allocate in a tick.
    pub fn reserve_for(&mut self, max_delay: f64) {
        let periods = ((max_delay.max(self.delay) + self.late_max) / self.ramp).ceil() as usize + 4;
        let n = MAX_COMMANDS_PER_PERIOD * periods;
        self.history.reserve(n.saturating_sub(self.history.len()));
    }

    /// Keeps the history a prediction with commands acting up to `late` [s]
    /// after the delay needs ([`Self::propagate_with`]'s `late`); ≥ 0 and
    /// finite, else ignored. Call [`Self::reserve_for`] after it.
    pub fn keep_for_late(&mut self, late: f64) {
        if late.is_finite() && late >= 0.0 {
            self.late_max = late;
        }
    }

    /// Forgets every command.
    pub fn reset(&mut self) {
        self.history.clear();
    }

    /// Records the command sent at `time` (saturated at the machine's bounds, as
    /// the low-level controller does). Times must not decrease; non-finite
    /// commands are ignored (the plant rejects them too).
    pub fn record(&mut self, time: f64, cmd: VelocityCommand) {
        if !(cmd.is_finite() && time.is_finite()) {
            return;
        }
        let cmd = cmd.limited(&self.params);
        // An entry is obsolete once the next one has taken effect by `time`.
        while self.history.len() >= 2 && self.history[1].0 + self.delay + self.late_max <= time {
            self.history.pop_front();
        }
        self.history.push_back((time, cmd));
    }

    /// The state at `time + delay`, from the state measured at `time`.
    /// Returns the measurement itself when the delay is zero.
    pub fn propagate(&self, time: f64, measured: &State) -> State {
        self.propagate_over(time, measured, self.delay)
    }

    /// The state at `time + duration` from the state measured at `time`, with
    /// the commands recorded; commands not yet recorded are taken not to act
    /// in the window (true for duration ≤ the delay, and for duration ≤ delay
    /// + command period once the command sent at `time` is recorded).
    pub fn propagate_over(&self, time: f64, measured: &State, duration: f64) -> State {
        if duration <= 0.0 {
            return *measured;
        }
        self.propagate_with(time, measured, &[], 1.0, 0.0, time + duration, |_, _| {})
    }

    /// The state at `end` from the state measured at `time`, with the commands
    /// recorded and then `pending` ((issue time, command), issue times ≥ the
    /// last recorded one and increasing: commands not sent yet, e.g. a
    /// candidate and the stop after it, [`crate::envelope`]); each takes
    /// effect `delay + late` after its issue (`late` ∈ [0, the history kept
    /// by [`Self::keep_for_late`]]: a machine slower to respond than the
    /// compensated delay). The machine achieves `gain` × every command
    /// saturated at the nominal bounds (1: as commanded; the envelope's bound
    /// on the actuator gain). `observe` sees the state after every
    /// integration sub-step (at most `substep` apart, split at every
    /// activation and ramp end), with its time.
    pub fn propagate_with(
        &self,
        time: f64,
        measured: &State,
        pending: &[(f64, VelocityCommand)],
        gain: f64,
        late: f64,
        end: f64,
        mut observe: impl FnMut(f64, &State),
    ) -> State {
        let mut x = *measured;
        let p = self.params;
        let max = [p.beta_ddot_max, p.a_max];
        // The states a machine with this gain reaches: its velocities go up to
        // gain × the nominal bounds (clamping them at the nominal ones would
        // predict a stop from 1.2 m/s as one from 1 m/s, 0.22 m short).
        let reach = MachineParams {
            beta_dot_max: gain.max(1.0) * p.beta_dot_max,
            v_max: gain.max(1.0) * p.v_max,
            ..p
        };
        let recorded = self.history.len();
        let count = recorded + pending.len();
        // The low-level controller saturates each command at the nominal
        // bounds; a machine with actuator gain K then achieves K × that, which
        // may exceed the nominal bounds (`PlantPerturbation::true_params`).
        let achieved = |c: VelocityCommand| {
            let c = c.limited(&p);
            if gain == 1.0 {
                c
            } else {
                VelocityCommand {
                    beta_dot: gain * c.beta_dot,
                    v: gain * c.v,
                }
            }
        };
        let command = |i: usize| {
            let (t, c) = if i < recorded {
                self.history[i]
            } else {
                pending[i - recorded]
            };
            (t, achieved(c))
        };
        let delay = self.delay + late.clamp(0.0, self.late_max);
        let act = |i: usize| command(i).0 + delay;
        // The command in effect at `time`: the last one activated by then.
        let mut next = (0..count)
            .position(|i| act(i) > time + 1e-12)
            .unwrap_or(count);
        let mut ramps = [Ramp::default(); 2];
        if next > 0 {
            let (t0, cmd) = command(next - 1);
            let remaining = (t0 + delay + self.ramp - time).max(0.0);
            for (c, (&k, target)) in CHANNELS.iter().zip([cmd.beta_dot, cmd.v]).enumerate() {
                ramps[c] = Ramp::start(time, x[k], target, remaining, max[c]);
            }
        }
        let mut t = time;
        while end - t > 1e-12 {
            while next < count && act(next) <= t + 1e-12 {
                let cmd = command(next).1;
                for (c, (&k, target)) in CHANNELS.iter().zip([cmd.beta_dot, cmd.v]).enumerate() {
                    ramps[c] = Ramp::start(t, x[k], target, self.ramp, max[c]);
                }
                next += 1;
            }
            let mut h = self.substep.min(end - t);
            if next < count {
                h = h.min(act(next) - t);
            }
            for r in &ramps {
                if r.until > t {
                    h = h.min(r.until - t);
                }
            }
            let h = h.max(1e-12);
            let u = Control::new(ramps[0].acceleration(t), ramps[1].acceleration(t));
            let k1 = f_continuous(&p, &x, &u);
            let k2 = f_continuous(&p, &(x + k1 * (0.5 * h)), &u);
            let k3 = f_continuous(&p, &(x + k2 * (0.5 * h)), &u);
            let k4 = f_continuous(&p, &(x + k3 * h), &u);
            let mut next_x = x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
            // A finished ramp lands on its command exactly.
            for (r, &k) in ramps.iter().zip(&CHANNELS) {
                if r.rate != 0.0 && (r.until - (t + h)).abs() < 1e-12 {
                    next_x[k] = r.target;
                }
            }
            clamp_state(&reach, &mut next_x);
            x = next_x;
            t += h;
            observe(t, &x);
        }
        x
    }
}

/// Carries a pose measured `age` seconds before the tick to the tick (DESIGN
/// §14): `x` holds that pose (x_f, y_f, θ_f) with the machine state read at the
/// tick (β, β̇, v_f, the machine's own sensors, current). Over the age window
/// β̇ and v_f are taken constant at their current values (β then was
/// β − β̇·age), and the kinematics (paper eq. 5) integrated forward with RK4;
/// the error is of the order of ½·a_max·age² (5 mm at 0.1 s). An age ≤ 0 or
/// not finite returns `x` unchanged.
pub fn compensate_pose_age(p: &MachineParams, x: &State, age: f64) -> State {
    if !(age.is_finite() && age > 0.0) {
        return *x;
    }
    let mut y = *x;
    y[ix::BETA] = x[ix::BETA] - x[ix::BETA_DOT] * age;
    clamp_state(p, &mut y);
    let steps = (age / DEFAULT_SUBSTEP).ceil().max(1.0);
    let h = age / steps;
    let u = Control::zeros();
    for _ in 0..steps as usize {
        let k1 = f_continuous(p, &y, &u);
        let k2 = f_continuous(p, &(y + k1 * (0.5 * h)), &u);
        let k3 = f_continuous(p, &(y + k2 * (0.5 * h)), &u);
        let k4 = f_continuous(p, &(y + k3 * h), &u);
        y += (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
    }
    for k in [ix::BETA, ix::BETA_DOT, ix::V] {
        y[k] = x[k];
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_delay_is_identity_and_settings_are_checked() {
        let c = DelayCompensator::new(MachineParams::default(), 0.0, 0.2).unwrap();
        let x = State::new(1.0, 2.0, 0.3, 0.1, 0.2, 0.5);
        assert_eq!(c.propagate(0.0, &x), x);
        let e = DelayCompensator::new(MachineParams::default(), -0.1, 0.2).unwrap_err();
        assert!(e.to_string().contains("`delay`"));
        assert!(DelayCompensator::new(MachineParams::default(), 0.2, 0.0)
            .unwrap_err()
            .to_string()
            .contains("`ramp`"));
    }

    #[test]
    fn no_command_holds_velocity_and_history_stays_short() {
        let p = MachineParams::default();
        let mut c = DelayCompensator::new(p, 0.3, 0.2).unwrap();
        let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);
        let y = c.propagate(0.0, &x);
        assert!((y[ix::X] - 0.15).abs() < 1e-12 && y[ix::V] == 0.5);
        for k in 0..100 {
            c.record(
                0.2 * k as f64,
                VelocityCommand {
                    beta_dot: 0.0,
                    v: 0.5,
                },
            );
        }
        assert!(c.history.len() <= 4, "{}", c.history.len());
    }

    #[test]
    fn an_old_pose_is_carried_to_the_tick_along_the_arc_driven() {
        // Straight at 1 m/s: 0.1 s old means 0.1 m behind.
        let p = MachineParams::default();
        let x = State::new(1.0, 2.0, 0.0, 0.0, 0.0, 1.0);
        let y = compensate_pose_age(&p, &x, 0.1);
        assert!((y[ix::X] - 1.1).abs() < 1e-12 && y[ix::Y] == 2.0, "{y:?}");
        assert_eq!(compensate_pose_age(&p, &x, 0.0), x);
        // Turning at constant β and v: the closed form of a circle of radius
        // R = (L_f cos β + L_r) / sin β (paper eq. 5 with β̇ = 0).
        let beta: f64 = 0.3;
        let x = State::new(0.0, 0.0, 0.0, beta, 0.0, 0.8);
        let age = 0.25;
        let y = compensate_pose_age(&p, &x, age);
        let r = (p.l_f * beta.cos() + p.l_r) / beta.sin();
        let phi = 0.8 * age / r;
        assert!((y[ix::X] - r * phi.sin()).abs() < 1e-9, "{y:?}");
        assert!((y[ix::Y] - r * (1.0 - phi.cos())).abs() < 1e-9, "{y:?}");
        assert!((y[ix::THETA] - phi).abs() < 1e-9 && y[ix::BETA] == beta);
        // While articulating, the measured β is kept (it is current).
        let x = State::new(0.0, 0.0, 0.0, 0.2, 0.3, 0.5);
        let y = compensate_pose_age(&p, &x, 0.1);
        assert_eq!(y[ix::BETA], 0.2);
        assert!(y[ix::THETA] > 0.0 && y[ix::X] > 0.049);
    }

    #[test]
    fn pending_commands_act_after_the_recorded_ones() {
        // Recorded: 0.5 m/s at t = 0; pending: a stop issued at 0.2 s. With
        // delay 0.1 and ramp 0.2 the stop starts at 0.3 s and decelerates at
        // a_max (0.5 / 0.2 = 2.5 > 1): at rest at 0.8 s.
        let p = MachineParams::default();
        let mut c = DelayCompensator::new(p, 0.1, 0.2).unwrap();
        c.record(
            0.0,
            VelocityCommand {
                beta_dot: 0.0,
                v: 0.5,
            },
        );
        let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);
        let (mut seen, mut last) = (0, 0.0);
        let y = c.propagate_with(
            0.0,
            &x,
            &[(0.2, VelocityCommand::ZERO)],
            1.0,
            0.0,
            2.0,
            |t, _| {
                assert!(t > last && t <= 2.0 + 1e-12, "{t} after {last}");
                last = t;
                seen += 1;
            },
        );
        assert_eq!(y[ix::V], 0.0);
        // 0.3 s at 0.5 m/s, then 0.5²/2 = 0.125 m of braking.
        assert!((y[ix::X] - 0.275).abs() < 1e-9, "{}", y[ix::X]);
        assert!(seen >= 200, "{seen}");
        // Without pending commands it is propagate_over.
        let a = c.propagate_with(0.0, &x, &[], 1.0, 0.0, 0.3, |_, _| {});
        assert_eq!(a, c.propagate_over(0.0, &x, 0.3));
    }
}
