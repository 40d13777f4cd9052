//! The safety envelope after the optimiser (DESIGN §14).
//!
//! The MPC is not the safety function. Before a command leaves the loop, [`guard`]
//! predicts the machine's motion under it: the commands already sent that act
//! within the actuator delay, then this command until the next tick, then a full
//! stop at the machine's braking limits (β̈_max, a_max); with every command
//! acting after the delay and at lags up to `response_lag` later (sampled at
//! most [`LATE_STEP`] apart, the motion between samples added to the margins),
//! at up to `actuator_gain_max` × the commanded velocities. Both axle
//! points are checked on the integration
//! sub-steps ([`DelayCompensator::propagate_with`], the model the delay
//! compensation uses). If the prediction comes closer to a circle than the
//! protective margin — and closer than stopping now would — the command is
//! replaced by the safest one of a small set (a stop at the limits, or braking
//! while keeping the proposed articulation rate: whichever keeps the larger
//! clearance). The daemon and `wlnav-sim` call this same function.
//!
//! # Margins
//!
//! The margins come from stated tolerances, not from scenarios
//! ([`EnvelopeSettings::margins`]): with k = `noise_sigmas`,
//!
//! ```text
//! m_front = margin + k·σ_xy + v_max·δt_pose
//! m_rear  = m_front + δ_geometry + (L_f + L_r)·k·σ_θ
//! ```
//!
//! σ_xy, σ_θ: the pose estimate's noise; δt_pose: how far its timestamp may be
//! off once its age is compensated ([`crate::delay::compensate_pose_age`]);
//! δ_geometry: how far the true rear axle may be from where the configured L_f,
//! L_r put it (≤ |ΔL_f| + |ΔL_r|); the rear axle's heading error acts over its
//! lever L_f + L_r from the measured front axle.
//!
//! # What passes
//!
//! A command passes when its prediction keeps every margin, or is no worse than
//! an immediate stop (the commands already sent cannot be taken back, so a
//! machine already inside a margin may still move away from the circle, never
//! towards it). With every tolerance zero and nothing near, the command passes
//! unchanged: the envelope changes nothing where it does not act.

use serde::{Deserialize, Serialize};

use crate::assumption_check::CheckSettings;
use crate::delay::DelayCompensator;
use crate::live::{LiveSet, LiveSettings, MAX_LIVE_OBSTACLES};
use crate::model::{MachineParams, State, VelocityCommand};
use crate::site::index::Near;
use crate::site::outline::{Body, Outline, MAX_OUTLINE_CIRCLES};
use crate::world::World;

/// Settings of the envelope: what it assumes about the machine and its pose
/// estimate. `Default` gives the values below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvelopeSettings {
    /// Check every command (default true). Off only to measure what the
    /// envelope changes.
    pub enabled: bool,
    /// Protective margin [m] kept beyond the tolerances below. Default 0.01
    /// (the MPC plans 0.05 away: the envelope acts only on commands that leave
    /// the plan's own margin).
    pub margin: f64,
    /// How far the true rear axle may be from where the configured L_f, L_r put
    /// it [m] (≤ |ΔL_f| + |ΔL_r|). Default 0.06 (10 % of L_r = 0.6 m).
    pub geometry_tolerance: f64,
    /// Standard deviation of the pose estimate's position [m]. Default 0.02.
    pub pose_noise_xy: f64,
    /// Standard deviation of the pose estimate's heading [rad]. Default 0.01.
    pub pose_noise_theta: f64,
    /// How many standard deviations of pose noise the margins cover. Default 3.
    pub noise_sigmas: f64,
    /// Uncertainty of the pose's timestamp once its age is compensated [s].
    /// Default 0.01.
    pub pose_latency: f64,
    /// The machine may respond to every command up to this much later than the
    /// compensated delay says [s]: unmodelled velocity lag, an actuator delay
    /// longer than the compensated one. Default 0.15.
    pub response_lag: f64,
    /// The machine may achieve up to this many times the commanded
    /// velocities (an actuator gain above 1; the MPC's online estimate
    /// corrects its plan, not what is already on its way). Default 1.2.
    pub actuator_gain_max: f64,
    /// Prediction sub-step [s], in (0, 0.02]. Default 0.01 (the plant's).
    pub substep: f64,
    /// The check of these assumptions while driving (`[envelope.check]`,
    /// [`crate::assumption_check`]).
    pub check: CheckSettings,
}

impl Default for EnvelopeSettings {
    /// The shipped, conservative tolerances (issue 43; justified in
    /// docs/envelope-tolerances.md): they cover the robustness matrix's
    /// moderate levels (L_r × 1.1, the all-moderate pose noise 0.02 m /
    /// 0.01 rad, a true delay 0.15 s beyond the compensated one, actuator
    /// gain 1.2) and a 10 ms error of the pose's stamp. Noisier poses are
    /// caught by [`crate::assumption_check`]. An integrator narrows them knowingly, after
    /// measuring the machine; [`Self::exact`] states none.
    fn default() -> Self {
        Self {
            geometry_tolerance: 0.06,
            pose_noise_xy: 0.02,
            pose_noise_theta: 0.01,
            pose_latency: 0.01,
            response_lag: 0.15,
            actuator_gain_max: 1.2,
            ..Self::exact()
        }
    }
}

impl EnvelopeSettings {
    /// The envelope of a machine that is exactly its model: every tolerance
    /// zero (gain 1), margin 0.01 m. The defaults before issue 43; for tests
    /// and for measuring what the tolerances cost.
    pub const fn exact() -> Self {
        Self {
            enabled: true,
            margin: 0.01,
            geometry_tolerance: 0.0,
            pose_noise_xy: 0.0,
            pose_noise_theta: 0.0,
            noise_sigmas: 3.0,
            pose_latency: 0.0,
            response_lag: 0.0,
            actuator_gain_max: 1.0,
            substep: crate::delay::DEFAULT_SUBSTEP,
            check: CheckSettings::DEFAULT,
        }
    }
}

/// A bad envelope setting.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("envelope setting `{name}` {requirement} (got {value})")]
pub struct EnvelopeError {
    pub name: &'static str,
    pub requirement: &'static str,
    pub value: f64,
}

impl EnvelopeSettings {
    /// Every value finite and ≥ 0, `substep` in (0, 0.02], response lag and
    /// pose latency at most 2 s.
    pub fn validate(&self) -> Result<(), EnvelopeError> {
        let err = |name, requirement, value| {
            Err(EnvelopeError {
                name,
                requirement,
                value,
            })
        };
        for (name, value) in [
            ("margin", self.margin),
            ("geometry_tolerance", self.geometry_tolerance),
            ("pose_noise_xy", self.pose_noise_xy),
            ("pose_noise_theta", self.pose_noise_theta),
            ("noise_sigmas", self.noise_sigmas),
            ("pose_latency", self.pose_latency),
            ("response_lag", self.response_lag),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return err(name, "must be finite and >= 0", value);
            }
        }
        for (name, value) in [
            ("pose_latency", self.pose_latency),
            ("response_lag", self.response_lag),
        ] {
            if value > 2.0 {
                return err(name, "must be at most 2 s", value);
            }
        }
        if !(self.actuator_gain_max >= 1.0 && self.actuator_gain_max <= 2.0) {
            return err(
                "actuator_gain_max",
                "must be in [1, 2]",
                self.actuator_gain_max,
            );
        }
        if !(self.substep > 0.0 && self.substep <= 0.02) {
            return err("substep", "must be in (0, 0.02] s", self.substep);
        }
        if let Err((name, requirement, value)) = self.check.validate() {
            return err(name, requirement, value);
        }
        Ok(())
    }

    /// The margins [front, rear] (in the order of [`AxlePoint::ALL`]) from the
    /// tolerances (module docs).
    pub fn margins(&self, p: &MachineParams) -> [f64; 2] {
        let front =
            self.margin + self.noise_sigmas * self.pose_noise_xy + p.v_max * self.pose_latency;
        let rear = front
            + self.geometry_tolerance
            + (p.l_f + p.l_r) * self.noise_sigmas * self.pose_noise_theta;
        [front, rear]
    }

    /// The margin of each of `outline`'s circles [m]: [`Self::margins`] with
    /// the heading noise acting on the circle's lever arm from the front
    /// axle ([`Outline::lever_arm`]) and the geometry's tolerance on every
    /// circle but one at the front axle itself. For the default outline (a
    /// circle at each axle point) exactly [front, rear].
    pub fn circle_margins(
        &self,
        p: &MachineParams,
        outline: &Outline,
    ) -> [f64; MAX_OUTLINE_CIRCLES] {
        let [front, _] = self.margins(p);
        let mut out = [0.0; MAX_OUTLINE_CIRCLES];
        for (i, (m, c)) in out.iter_mut().zip(outline.circles()).enumerate() {
            let lever = outline.lever_arm(i, p);
            *m = if c.body == Body::Front && lever == 0.0 {
                front
            } else {
                front + self.geometry_tolerance + lever * self.noise_sigmas * self.pose_noise_theta
            };
        }
        out
    }

    /// What the tolerances add to each margin beyond `margin` [front, rear]: the
    /// MPC's planned clearance grows by this too, so that it plans outside the
    /// envelope's reach ([`crate::mpc::MpcSettings::with_tolerances`]).
    pub fn tolerance_widening(&self, p: &MachineParams) -> [f64; 2] {
        let [f, r] = self.margins(p);
        [f - self.margin, r - self.margin]
    }
}

/// The machine's stop at its acceleration limits: each velocity moved towards
/// zero by at most one tick of β̈_max, a_max from the last command sent. Sent
/// every tick while stopping, it brakes at the limits.
pub fn ramp_down(last: VelocityCommand, p: &MachineParams, dt: f64) -> VelocityCommand {
    let towards_zero = |v: f64, step: f64| {
        if v.abs() <= step {
            0.0
        } else {
            v - step.copysign(v)
        }
    };
    VelocityCommand {
        beta_dot: towards_zero(last.beta_dot, p.beta_ddot_max * dt),
        v: towards_zero(last.v, p.a_max * dt),
    }
}

/// A stop at the limits that never speeds the machine up: [`ramp_down`] from,
/// per channel, whichever of the last command and the measured velocity is
/// closer to zero (zero if they differ in sign). `ramp_down` of the last
/// command alone would command −0.8 m/s to a machine still reversing at
/// −0.4 m/s towards a −1 m/s command, i.e. accelerate it (seen at N = 40 in
/// `dock038`). Without a trusted measurement (`None`), from the last command.
pub fn stop_command(
    last: VelocityCommand,
    measured: Option<&State>,
    p: &MachineParams,
    dt: f64,
) -> VelocityCommand {
    let Some(x) = measured else {
        return ramp_down(last, p, dt);
    };
    let nearer_zero = |a: f64, b: f64| {
        if !(a * b > 0.0) {
            0.0
        } else if a.abs() <= b.abs() {
            a
        } else {
            b
        }
    };
    let from = VelocityCommand {
        beta_dot: nearer_zero(last.beta_dot, x[crate::model::ix::BETA_DOT]),
        v: nearer_zero(last.v, x[crate::model::ix::V]),
    };
    ramp_down(from, p, dt)
}

/// The loop's own record of the commands it sent, for [`EnvelopeInput::sent`]:
/// they act after `delay` (or up to `settings.response_lag` later), with room
/// reserved for any delay the online estimate can take
/// ([`crate::delay_estimate::MAX_DELAY`]), so that raising it later does not
/// allocate in a tick.
pub fn command_record(
    p: MachineParams,
    settings: &EnvelopeSettings,
    delay: f64,
    dt: f64,
) -> Result<DelayCompensator, crate::delay::DelayError> {
    let mut sent = DelayCompensator::new(p, delay, dt)?;
    sent.keep_for_late(settings.response_lag);
    sent.reserve_for(crate::delay_estimate::MAX_DELAY);
    Ok(sent)
}

/// What the envelope knows at a tick.
#[derive(Debug, Clone, Copy)]
pub struct EnvelopeInput<'a> {
    /// The nominal machine.
    pub params: &'a MachineParams,
    pub settings: &'a EnvelopeSettings,
    /// The commands already sent and the delay they act after (the loop's own
    /// record, independent of the optimiser's).
    pub sent: &'a DelayCompensator,
    /// The tick's time [s, the clock of `sent`].
    pub now: f64,
    /// The measured state at `now` (the pose's age compensated).
    pub state: &'a State,
    /// Everything the outline must keep off (the site, the goal's circles).
    pub world: &'a World,
    /// The command period Δt [s].
    pub dt: f64,
    /// The last command sent (the stop ramps down from it).
    pub last: VelocityCommand,
    /// The live obstacles perception sees, and the clearance kept to them
    /// (`None`: none are checked).
    pub live: Option<LiveView<'a>>,
}

/// The live obstacles the envelope keeps off ([`crate::live`]).
#[derive(Debug, Clone, Copy)]
pub struct LiveView<'a> {
    pub set: &'a LiveSet,
    pub settings: &'a LiveSettings,
}

/// The live obstacle a prediction came nearest to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveContact {
    /// Perception's id of it.
    pub id: u32,
    /// Smallest predicted clearance to it beyond the margins and its stop
    /// field [m] (negative: inside).
    pub excess: f64,
}

/// What [`predict`] found: the smallest clearance beyond the margins over
/// everything (the site, the goal's circles, the live obstacles' stop
/// fields), and the live obstacle nearest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    pub excess: f64,
    pub live: Option<LiveContact>,
}

/// Which command left the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Choice {
    /// The proposed command: it keeps the margins.
    Proposed,
    /// A stop at the limits ([`stop_command`]).
    Stop,
    /// Braking at the limits while keeping the proposed articulation rate.
    BrakeSteering,
}

impl Choice {
    pub fn name(self) -> &'static str {
        match self {
            Choice::Proposed => "proposed",
            Choice::Stop => "stop",
            Choice::BrakeSteering => "brake-steering",
        }
    }
}

/// The envelope's verdict on one command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guarded {
    /// The command to send.
    pub command: VelocityCommand,
    pub choice: Choice,
    /// Smallest predicted clearance beyond the margins [m] of the proposed
    /// command (negative: it would come closer than a margin; +∞ without
    /// obstacles or with the envelope off).
    pub proposed_excess: f64,
    /// The same for the command sent.
    pub excess: f64,
    /// The live obstacle the command sent comes nearest to, if any is
    /// within [`SITE_REACH`] of its stop field.
    pub live: Option<LiveContact>,
}

impl Guarded {
    /// True if the proposed command was replaced.
    pub fn overridden(&self) -> bool {
        self.choice != Choice::Proposed
    }
}

/// Smallest clearance beyond the margins [m] of the outline over the
/// prediction: `command` sent now, a stop sent a tick later, until at rest;
/// with the commands acting after the delay and, if `response_lag` > 0, at
/// lags up to it ([`late_samples`]). Live obstacles are predicted along
/// their velocities to each predicted state's time, their stop field
/// ([`LiveSettings::reach`]) added to the margins.
pub fn predict(input: &EnvelopeInput, command: VelocityCommand) -> Prediction {
    let EnvelopeInput {
        params: p,
        settings: s,
        ..
    } = *input;
    let live = input.live.filter(|l| !l.set.is_empty());
    if input.world.is_empty() && live.is_none() {
        return Prediction {
            excess: f64::INFINITY,
            live: None,
        };
    }
    let margins = s.circle_margins(p, input.world.outline());
    let stop_at = input.now + input.dt;
    let braking = braking_time(p, s, input.dt);
    let pending = [(input.now, command), (stop_at, VelocityCommand::ZERO)];
    // The site's features the prediction can come near: every outline circle
    // stays within the distance the front axle can go (at the fastest the
    // machine goes, until the latest end) plus its lever arm of the front
    // axle; a feature beyond that and its radius, margin and SITE_REACH is
    // SITE_REACH or more away all along. One index query, then exact
    // distances to the few in reach (all of them through the index if more).
    let (late_n, late_step, _) = late_samples(s, p);
    let speed = (s.actuator_gain_max * p.v_max).max(input.state[crate::model::ix::V].abs());
    let horizon = input.dt + input.sent.delay() + late_n as f64 * late_step + braking;
    let outline = input.world.outline();
    let extent = (0..outline.len())
        .map(|i| outline.lever_arm(i, p) + outline.circles()[i].radius + margins[i])
        .fold(0.0, f64::max);
    let front = [
        input.state[crate::model::ix::X],
        input.state[crate::model::ix::Y],
    ];
    let reach = speed * horizon + extent + SITE_REACH;
    let mut near = [Near::default(); NEAR_FEATURES];
    let local = input.world.features_near(front, reach, &mut near);
    let near = local.map(|n| &near[..n]);
    // The live obstacles that can come within reach: their bounding discs'
    // paths from now to the end of the prediction.
    let mut movers = [0u8; MAX_LIVE_OBSTACLES];
    let mut n_movers = 0;
    if let Some(l) = live {
        let end = input.now + horizon;
        for (i, o) in l
            .set
            .obstacles()
            .iter()
            .enumerate()
            .take(MAX_LIVE_OBSTACLES)
        {
            let (c, r) = o.shape.bounding_circle();
            let at = |t: f64| {
                let dt = t - o.stamp;
                [c[0] + o.velocity[0] * dt, c[1] + o.velocity[1] * dt]
            };
            let (_, d) = crate::site::geometry::closest_on_segment(front, at(input.now), at(end));
            if d - r - l.settings.reach(end - o.stamp) < reach {
                movers[n_movers] = i as u8;
                n_movers += 1;
            }
        }
    }
    let mut excess = if input.world.site().is_some() {
        SITE_REACH
    } else {
        f64::INFINITY
    };
    let mut nearest_live: Option<LiveContact> = None;
    let substep = input.settings.substep;
    let mut observe = |t: f64, x: &State| {
        // Below the least so far only: the index prunes everything farther.
        if !input.world.is_empty() {
            if let Some(c) = input.world.excess_among(x, &margins, excess, near) {
                excess = excess.min(c.clearance);
            }
        }
        let Some(l) = live else { return };
        if n_movers == 0 {
            return;
        }
        let placed = input.world.place(x);
        for &i in &movers[..n_movers] {
            let o = &l.set.obstacles()[i as usize];
            // The obstacle moves up to |v|·substep between two samples.
            let grow = l.settings.reach(t - o.stamp) + 0.5 * o.speed() * substep;
            for (c, m) in placed[..outline.len()].iter().zip(&margins) {
                let e = o.clearance_at(c.center, c.radius + m + grow, t);
                if nearest_live.is_none_or(|n| e < n.excess) {
                    nearest_live = Some(LiveContact {
                        id: o.id,
                        excess: e,
                    });
                }
            }
        }
    };
    observe(input.now, input.state);
    // The machine responds after the delay, or up to `response_lag` later.
    // The prediction is not monotone in the delay (a later stop is farther
    // along, a later turn is wider or narrower), so neither end bounds what
    // lies between: the lags in [0, response_lag] are sampled at most
    // LATE_STEP apart, every command (those already sent included) acting
    // that late, and the margins grow by the motion between two samples
    // ([`late_samples`]).
    let (n, step, pad) = late_samples(s, p);
    for i in 0..=n {
        let late = i as f64 * step;
        let end = stop_at + input.sent.delay() + late + braking;
        input.sent.propagate_with(
            input.now,
            input.state,
            &pending,
            s.actuator_gain_max,
            late,
            end,
            &mut observe,
        );
    }
    let live = nearest_live
        .filter(|c| c.excess < SITE_REACH)
        .map(|c| LiveContact {
            excess: c.excess - pad,
            ..c
        });
    Prediction {
        excess: live.map_or(excess, |c| excess.min(c.excess + pad)) - pad,
        live,
    }
}

/// How long [`predict`] follows the machine after its stop acts [s]: from
/// the fastest it can go (gain × the bounds), it is at rest within the
/// longer of the two braking times, plus the ramp of the model's response
/// (the command period `dt`).
pub fn braking_time(p: &MachineParams, s: &EnvelopeSettings, dt: f64) -> f64 {
    s.actuator_gain_max * (p.v_max / p.a_max).max(p.beta_dot_max / p.beta_ddot_max) + dt
}

/// With a site, [`predict`] measures exactly up to this [m] and
/// reports this beyond (a lower bound; every decision compares with 0).
pub const SITE_REACH: f64 = 1.0;

/// Most site features [`predict`] takes from one region query
/// before it asks the index for each predicted state instead.
const NEAR_FEATURES: usize = 48;

/// Largest step between the response lags [`predict`] samples [s]
/// (issue 43: with only the two ends sampled, a true delay between them went
/// unchecked).
pub const LATE_STEP: f64 = 0.02;

/// The response lags [`predict`] samples: `n` + 1 of them, `step`
/// apart from 0 to `response_lag`, and the margin `pad` [m] that covers the
/// lags between two samples: there every command acts at most step / 2
/// earlier or later than at the nearer sample, and the axle points move at
/// most gain × v_max × step / 2 further along their path (to first order;
/// the change of heading over a 10 ms shift is second order). Zero lag: one
/// sample, no pad.
pub fn late_samples(s: &EnvelopeSettings, p: &MachineParams) -> (usize, f64, f64) {
    if !(s.response_lag > 0.0) {
        return (0, 0.0, 0.0);
    }
    let n = (s.response_lag / LATE_STEP - 1e-9).ceil().max(1.0) as usize;
    let step = s.response_lag / n as f64;
    (n, step, s.actuator_gain_max * p.v_max * step / 2.0)
}

/// Checks `proposed` (module docs) and returns what to send. Allocation-free.
pub fn guard(input: &EnvelopeInput, proposed: VelocityCommand) -> Guarded {
    let pass = Guarded {
        command: proposed,
        choice: Choice::Proposed,
        proposed_excess: f64::INFINITY,
        excess: f64::INFINITY,
        live: None,
    };
    let has_live = input.live.is_some_and(|l| !l.set.is_empty());
    if !input.settings.enabled || (input.world.is_empty() && !has_live) {
        return pass;
    }
    let it = predict(input, proposed);
    let passed = Guarded {
        proposed_excess: it.excess,
        excess: it.excess,
        live: it.live,
        ..pass
    };
    if it.excess >= 0.0 {
        return passed;
    }
    let stop = stop_command(input.last, Some(input.state), input.params, input.dt);
    let stopped = predict(input, stop);
    // No worse than stopping now: moving away from (or along) a circle the
    // machine is already too close to.
    if it.excess >= stopped.excess - 1e-9 {
        return passed;
    }
    let steer = VelocityCommand {
        beta_dot: proposed.beta_dot,
        ..stop
    }
    .limited(input.params);
    let steered = predict(input, steer);
    let (command, choice, best) = if steered.excess > stopped.excess {
        (steer, Choice::BrakeSteering, steered)
    } else {
        (stop, Choice::Stop, stopped)
    };
    Guarded {
        command,
        choice,
        proposed_excess: it.excess,
        excess: best.excess,
        live: best.live,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ix;
    use crate::obstacle::Obstacle;

    fn avant() -> MachineParams {
        MachineParams::default()
    }

    /// Driving straight along +x at `v`, its commands sent every tick so far.
    fn driving(v: f64, delay: f64) -> (DelayCompensator, State) {
        let mut sent = DelayCompensator::new(avant(), delay, 0.2).unwrap();
        for k in -5..0 {
            sent.record(0.2 * k as f64, VelocityCommand { beta_dot: 0.0, v });
        }
        (sent, State::new(0.0, 0.0, 0.0, 0.0, 0.0, v))
    }

    fn input<'a>(
        p: &'a MachineParams,
        s: &'a EnvelopeSettings,
        sent: &'a DelayCompensator,
        x: &'a State,
        obstacles: &'a [Obstacle],
        last: VelocityCommand,
    ) -> EnvelopeInput<'a> {
        let mut world = World::with_axle_circles(*p, 8);
        world.set_circles(obstacles).unwrap();
        let world: &'a World = Box::leak(Box::new(world));
        EnvelopeInput {
            params: p,
            settings: s,
            sent,
            now: 0.0,
            state: x,
            world,
            dt: 0.2,
            last,
            live: None,
        }
    }

    #[test]
    fn a_command_that_would_cut_into_a_circle_is_replaced_by_a_stop() {
        let p = avant();
        let s = EnvelopeSettings::exact();
        let (sent, x) = driving(1.0, 0.2);
        let full = VelocityCommand {
            beta_dot: 0.0,
            v: 1.0,
        };
        // At 1 m/s, 0.2 s delay: 0.2 m committed, 0.2 m under the command, then
        // 0.5 m of braking (+ the model's ramp) before rest: a circle whose
        // edge is 0.75 m ahead is hit.
        let wall = [Obstacle::new(1.25, 0.0, 0.5)];
        let g = guard(&input(&p, &s, &sent, &x, &wall, full), full);
        assert!(g.overridden(), "{g:?}");
        assert!(g.proposed_excess < 0.0);
        assert!(g.excess > g.proposed_excess);
        assert!(g.command.v < full.v && g.command.v >= full.v - p.a_max * 0.2 - 1e-12);
        // Its independent check: stopping from 1 m/s after 0.4 m ends
        // 0.4 + 0.5 = 0.9 m ahead (ramp model: the last 0.2 m/s in 0.2 s
        // linearly, same distance): the excess is 0.75 − 0.9 − margin < 0 for
        // the proposed command and the stop gains one tick of braking.
        let expected = 0.75 - (0.2 + 0.2 + 0.5) - s.margin;
        assert!(
            (g.proposed_excess - expected).abs() < 2e-3,
            "{g:?} vs {expected}"
        );
        // Far enough ahead, the same command passes unchanged.
        let far = [Obstacle::new(2.0, 0.0, 0.5)];
        let g = guard(&input(&p, &s, &sent, &x, &far, full), full);
        assert_eq!(g.choice, Choice::Proposed);
        assert_eq!(g.command, full);
        assert!(g.excess > 0.0 && g.excess < 0.6);
    }

    /// The guard's verdict on `command` with `set` as the live obstacles.
    fn guard_live(
        inp: EnvelopeInput,
        set: &LiveSet,
        fields: &LiveSettings,
        command: VelocityCommand,
    ) -> Guarded {
        guard(
            &EnvelopeInput {
                live: Some(LiveView {
                    set,
                    settings: fields,
                }),
                ..inp
            },
            command,
        )
    }

    /// A person of radius 0.3 m, seen at `stamp` with its centre at (x, y),
    /// walking at `velocity`.
    fn person(x: f64, y: f64, velocity: [f64; 2], stamp: f64) -> LiveSet {
        use crate::live::{LiveClass, LiveObstacle, LiveShape};
        let shape = LiveShape::circle([x, y], 0.3).unwrap();
        let o = LiveObstacle::new(42, LiveClass::Person, shape, velocity, stamp).unwrap();
        let mut set = LiveSet::new();
        set.set(stamp, &[o]).unwrap();
        set
    }

    #[test]
    fn a_person_closing_in_is_stopped_for_at_the_formulas_distance() {
        // The envelope's prediction against its closed form (crate::live's
        // S_stop): 1 m/s, 0.2 s delay, a person walking head-on at 0.5 m/s
        // seen 0.1 s ago.
        let p = avant();
        let s = EnvelopeSettings::exact();
        let fields = LiveSettings::default();
        let (sent, x) = driving(1.0, 0.2);
        let full = VelocityCommand {
            beta_dot: 0.0,
            v: 1.0,
        };
        let (u, age) = (0.5, 0.1);
        let response = 0.2 + 0.2; // the stop a tick later, acting a delay after
        let gap = crate::live::stop_distance(
            &p,
            &fields,
            1.0,
            u,
            response,
            age,
            braking_time(&p, &s, 0.2),
            s.margin,
        );
        // The gap runs from the front circle (radius 0.65 about the axle) to
        // the person's edge where it was seen.
        for (offset, stops) in [(0.05, false), (-0.05, true)] {
            let centre = 0.65 + gap + offset + 0.3;
            let set = person(centre, 0.0, [-u, 0.0], -age);
            let g = guard_live(input(&p, &s, &sent, &x, &[], full), &set, &fields, full);
            assert_eq!(g.overridden(), stops, "{offset}: {g:?}");
            // The excess is the offset (the ramp model brakes as the closed
            // form does; the mover's sub-step pad is 2.5 mm).
            assert!((g.proposed_excess - offset).abs() < 5e-3, "{g:?}");
            assert_eq!(g.live.map(|c| c.id), Some(42));
            if stops {
                assert_eq!(g.choice, Choice::Stop);
                assert!(g.excess > g.proposed_excess);
            }
        }
    }

    #[test]
    fn a_person_walking_away_or_crossing_behind_is_no_reason_to_stop() {
        let p = avant();
        let s = EnvelopeSettings::exact();
        let fields = LiveSettings::default();
        let (sent, x) = driving(1.0, 0.2);
        let full = VelocityCommand {
            beta_dot: 0.0,
            v: 1.0,
        };
        let check =
            |set: &LiveSet| guard_live(input(&p, &s, &sent, &x, &[], full), set, &fields, full);
        // 3 m ahead, walking away faster than the machine: passes.
        assert!(!check(&person(3.0, 0.0, [1.5, 0.0], 0.0)).overridden());
        // The same person standing there: the stop field is reached.
        assert!(check(&person(3.0, 0.0, [0.0, 0.0], 0.0)).overridden());
        // Crossing 3 m ahead, already past the path and walking off sideways.
        assert!(!check(&person(3.0, 2.0, [0.0, 1.4], 0.0)).overridden());
        // Crossing towards the path 2 m to the side: it arrives in the stop.
        assert!(check(&person(2.2, -2.0, [0.0, 1.4], 0.0)).overridden());
        // Far off: not even reported.
        let g = check(&person(30.0, 0.0, [0.0, 0.0], 0.0));
        assert_eq!((g.choice, g.live), (Choice::Proposed, None));
    }

    #[test]
    fn the_rear_axle_is_checked_too() {
        // Reversing at 1 m/s towards a circle behind: the rear axle (1.2 m
        // behind the front one when straight) reaches it first.
        let p = avant();
        let s = EnvelopeSettings::exact();
        let (sent, x) = driving(-1.0, 0.0);
        let back = VelocityCommand {
            beta_dot: 0.0,
            v: -1.0,
        };
        // No delay: 0.2 m under the command, then 0.5 m of braking. The front
        // axle ends 0.7 m back, far from the edge at −1.8 m; the rear one
        // starts at −1.2 m and ends at −1.9 m, 0.1 m inside.
        let behind = [Obstacle::new(-2.3, 0.0, 0.5)];
        let g = guard(&input(&p, &s, &sent, &x, &behind, back), back);
        assert!(g.overridden(), "{g:?}");
        let expected = -0.1 - s.margin;
        assert!(
            (g.proposed_excess - expected).abs() < 2e-3,
            "{g:?} vs {expected}"
        );
    }

    #[test]
    fn a_machine_inside_its_margin_may_move_away_but_not_closer() {
        let p = avant();
        let s = EnvelopeSettings {
            margin: 0.1,
            ..EnvelopeSettings::exact()
        };
        // At rest, 0.05 m from a circle ahead (inside the 0.1 m margin).
        let sent = DelayCompensator::new(p, 0.2, 0.2).unwrap();
        let x = State::zeros();
        let ahead = [Obstacle::new(0.55, 0.0, 0.5)];
        let away = VelocityCommand {
            beta_dot: 0.0,
            v: -0.2,
        };
        let towards = VelocityCommand {
            beta_dot: 0.0,
            v: 0.2,
        };
        let inp = input(&p, &s, &sent, &x, &ahead, VelocityCommand::ZERO);
        let g = guard(&inp, away);
        assert_eq!(g.choice, Choice::Proposed, "{g:?}");
        assert!(g.excess < 0.0);
        let g = guard(&inp, towards);
        assert_eq!(g.choice, Choice::Stop, "{g:?}");
        assert_eq!(g.command, VelocityCommand::ZERO);
    }

    #[test]
    fn margins_follow_the_formula_and_widen_the_check() {
        let p = avant();
        let s = EnvelopeSettings {
            margin: 0.01,
            geometry_tolerance: 0.06,
            pose_noise_xy: 0.02,
            pose_noise_theta: 0.01,
            noise_sigmas: 3.0,
            pose_latency: 0.05,
            ..EnvelopeSettings::exact()
        };
        let [f, r] = s.margins(&p);
        assert!((f - (0.01 + 0.06 + 0.05)).abs() < 1e-12, "{f}");
        assert!((r - (f + 0.06 + 1.2 * 0.03)).abs() < 1e-12, "{r}");
        let [wf, wr] = s.tolerance_widening(&p);
        assert!((wf - (f - 0.01)).abs() < 1e-12 && (wr - (r - 0.01)).abs() < 1e-12);
        // A command that passes at zero tolerance fails once they are stated.
        let (sent, x) = driving(1.0, 0.2);
        let full = VelocityCommand {
            beta_dot: 0.0,
            v: 1.0,
        };
        // Edge 0.98 m ahead: the prediction ends 0.08 m before it, more than
        // the 0.01 m margin, less than 0.12 m.
        let o = [Obstacle::new(1.48, 0.0, 0.5)];
        let zero = EnvelopeSettings::exact();
        assert!(!guard(&input(&p, &zero, &sent, &x, &o, full), full).overridden());
        assert!(guard(&input(&p, &s, &sent, &x, &o, full), full).overridden());
        assert!(s.validate().is_ok());
        let bad = EnvelopeSettings {
            pose_latency: -1.0,
            ..s
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("`pose_latency`"));
    }

    #[test]
    fn nothing_near_or_switched_off_passes_unchanged() {
        let p = avant();
        let (sent, x) = driving(1.0, 0.2);
        let full = VelocityCommand {
            beta_dot: 0.3,
            v: 1.0,
        };
        let s = EnvelopeSettings::exact();
        let g = guard(&input(&p, &s, &sent, &x, &[], full), full);
        assert_eq!((g.command, g.choice), (full, Choice::Proposed));
        let off = EnvelopeSettings {
            enabled: false,
            ..s
        };
        let wall = [Obstacle::new(0.8, 0.0, 0.5)];
        let g = guard(&input(&p, &off, &sent, &x, &wall, full), full);
        assert_eq!((g.command, g.choice), (full, Choice::Proposed));
        assert_eq!(x[ix::V], 1.0);
    }

    #[test]
    fn a_machine_faster_than_commanded_is_stopped_earlier() {
        // Commanded 0.8 m/s, achieving 1.2 × that: 0.96 m/s, so it travels
        // 0.2 × 0.96 + 0.96²/2 (+ the ramp) instead of 0.2 × 0.8 + 0.8²/2.
        let p = avant();
        let (sent, x) = driving(0.8, 0.0);
        let cmd = VelocityCommand {
            beta_dot: 0.0,
            v: 0.8,
        };
        let wall = [Obstacle::new(1.2, 0.0, 0.5)];
        let nominal = EnvelopeSettings::exact();
        let fast = EnvelopeSettings {
            actuator_gain_max: 1.2,
            ..nominal
        };
        let a = predict(&input(&p, &nominal, &sent, &x, &wall, cmd), cmd).excess;
        let b = predict(&input(&p, &fast, &sent, &x, &wall, cmd), cmd).excess;
        let expected = (0.2 * 0.96 + 0.96 * 0.96 / 2.0) - (0.2 * 0.8 + 0.8 * 0.8 / 2.0);
        assert!(((a - b) - expected).abs() < 0.03, "{a} {b} vs {expected}");
        // A circle that the nominal prediction clears by 0.1 m (the excess is
        // linear in its distance ahead): the faster machine would not.
        let wall = [Obstacle::new(1.2 + 0.1 - a, 0.0, 0.5)];
        assert!(!guard(&input(&p, &nominal, &sent, &x, &wall, cmd), cmd).overridden());
        let g = guard(&input(&p, &fast, &sent, &x, &wall, cmd), cmd);
        assert!(g.overridden(), "{g:?}");
        let bad = EnvelopeSettings {
            actuator_gain_max: 0.5,
            ..nominal
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("actuator_gain_max"));
    }

    #[test]
    fn a_machine_beyond_its_nominal_speed_is_predicted_to_brake_from_there() {
        // Commanded 1 m/s (v_max), achieving 1.2 m/s: a stop now brakes from
        // 1.2 m/s at a_max = 1 m/s², 1.2²/2 = 0.72 m, not the nominal 0.5 m
        // (clamping the prediction at v_max hid 0.22 m: wall029 at gain 1.2
        // went 0.087 m into a circle).
        let p = avant();
        let (sent, mut x) = driving(1.0, 0.0);
        x[ix::V] = 1.2;
        let wall = [Obstacle::new(1.5, 0.0, 0.5)];
        let fast = EnvelopeSettings {
            actuator_gain_max: 1.2,
            ..EnvelopeSettings::exact()
        };
        let stop = VelocityCommand::ZERO;
        let e = predict(&input(&p, &fast, &sent, &x, &wall, stop), stop).excess;
        let expected = 1.0 - 1.2 * 1.2 / (2.0 * p.a_max) - fast.margin;
        assert!((e - expected).abs() < 2e-3, "{e} vs {expected}");
    }

    #[test]
    fn a_late_response_is_predicted_for_every_command_already_sent() {
        // Driving at 1 m/s with no compensated delay; a stop was sent a tick
        // ago. A machine that responds on time is braking (0.5 m to rest);
        // one that responds up to 0.4 s late still drives at 1 m/s until the
        // stop sent at −0.2 s acts at +0.2 s: 0.2 + 0.5 m.
        let p = avant();
        let late = EnvelopeSettings {
            response_lag: 0.4,
            ..EnvelopeSettings::exact()
        };
        let mut sent = command_record(p, &late, 0.0, 0.2).unwrap();
        for k in -8..-1 {
            sent.record(
                0.2 * k as f64,
                VelocityCommand {
                    beta_dot: 0.0,
                    v: 1.0,
                },
            );
        }
        sent.record(-0.2, VelocityCommand::ZERO);
        let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let wall = [Obstacle::new(1.5, 0.0, 0.5)];
        let stop = VelocityCommand::ZERO;
        let on_time = EnvelopeSettings::exact();
        let a = predict(&input(&p, &on_time, &sent, &x, &wall, stop), stop).excess;
        let b = predict(&input(&p, &late, &sent, &x, &wall, stop), stop).excess;
        assert!((a - (1.0 - 0.5 - on_time.margin)).abs() < 2e-3, "{a}");
        let (_, _, pad) = late_samples(&late, &p);
        assert!((pad - 0.01).abs() < 1e-12, "{pad}");
        assert!((b - (1.0 - 0.7 - late.margin - pad)).abs() < 2e-3, "{b}");
    }

    #[test]
    fn the_stop_never_speeds_up_a_machine_that_lags_its_command() {
        let p = avant();
        // Commanded −1 m/s, still at −0.4 m/s (the ramp under way): the stop
        // brakes from −0.4, not from the command.
        let last = VelocityCommand {
            beta_dot: 0.43,
            v: -1.0,
        };
        let x = State::new(0.0, 0.0, 0.0, 0.6, 0.1, -0.4);
        let stop = stop_command(last, Some(&x), &p, 0.2);
        assert!((stop.v - (-0.2)).abs() < 1e-12, "{stop:?}");
        assert_eq!(stop.beta_dot, 0.0);
        // Opposite signs: the stop is zero; no measurement: from the command.
        let back = State::new(0.0, 0.0, 0.0, 0.0, -0.1, 0.3);
        assert_eq!(
            stop_command(last, Some(&back), &p, 0.2),
            VelocityCommand::ZERO
        );
        assert_eq!(stop_command(last, None, &p, 0.2), ramp_down(last, &p, 0.2));
        // A machine faster than its last command (braking under way): from
        // the command.
        let fast = State::new(0.0, 0.0, 0.0, 0.0, 0.5, -0.9);
        let slow = VelocityCommand {
            beta_dot: 0.2,
            v: -0.5,
        };
        let c = stop_command(slow, Some(&fast), &p, 0.2);
        assert!(
            (c.v - (-0.3)).abs() < 1e-12 && c.beta_dot.abs() < 0.2,
            "{c:?}"
        );
    }

    #[test]
    fn ramp_down_respects_the_acceleration_limits_and_ends_at_zero() {
        let p = avant();
        let dt = 0.2;
        let mut c = VelocityCommand {
            beta_dot: -p.beta_dot_max,
            v: p.v_max,
        };
        let mut ticks = 0;
        while c != VelocityCommand::ZERO {
            let next = ramp_down(c, &p, dt);
            assert!((next.beta_dot - c.beta_dot).abs() <= p.beta_ddot_max * dt + 1e-12);
            assert!((next.v - c.v).abs() <= p.a_max * dt + 1e-12);
            assert!(next.beta_dot.abs() <= c.beta_dot.abs() && next.v.abs() <= c.v.abs());
            c = next;
            ticks += 1;
            assert!(ticks < 100, "the ramp does not end");
        }
        let expected = (p.v_max / (p.a_max * dt))
            .max(p.beta_dot_max / (p.beta_ddot_max * dt))
            .ceil() as usize;
        // Within one tick of the closed form (the repeated subtraction may leave
        // a rounding remainder for one more tick).
        assert!(
            (expected..=expected + 1).contains(&ticks),
            "{ticks} ticks, expected {expected}"
        );
    }
}
