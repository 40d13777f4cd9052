//! The envelope's assumptions, checked while driving (DESIGN §14, issue 43).
//!
//! The safety envelope ([`crate::envelope`]) holds when its stated tolerances
//! cover the machine. This monitor compares, each tick, what the machine did
//! with what the model predicted, and says which stated tolerance the machine
//! has been seen to exceed, by how much, and what to do about it.
//!
//! # What is measured
//!
//! - **Geometry** (`geometry_tolerance`). Over each tick the measured pose is
//!   predicted from the previous one with the model's kinematics (paper eq. 5)
//!   driven by the machine's own measured β, β̇, v_f (linear between the two
//!   ticks). Velocities measured, the heading change over the tick depends
//!   on L_f and L_r alone; its residual r_θ ≈ a_f ΔL_f + a_r ΔL_r with
//!   a = Δt ∂θ̇/∂L. (ΔL_f, ΔL_r) is a least-squares fit with forgetting and
//!   a small prior at zero; the measured geometry error is |ΔL_f| + |ΔL_r|
//!   (how far the true rear axle can be from the modelled one, the quantity
//!   the tolerance bounds), broken only when it exceeds the tolerance by
//!   [`CONFIDENCE`] standard deviations of the fit (pose noise alone never
//!   breaks it). Pose residual of the rear axle = front residual + lever ×
//!   heading residual: the heading residual is the rear axle's.
//! - **Pose noise** (`pose_noise_xy`, `pose_noise_theta`). The same residual
//!   of the front axle's position and of the heading: with white pose noise
//!   of σ it is n_k − n_{k−1}, variance 2σ², lag-1 covariance −σ²; a smooth
//!   model error adds about the same to both, so σ̂² = (P₀ − P₁) / 3 from the
//!   residual's power P₀ and lag-1 product P₁ (forgetting). Broken above
//!   [`NOISE_RATIO`] × the stated σ plus a floor.
//! - **Delay** (`response_lag`). The MPC's online delay estimate
//!   ([`crate::delay_estimate`], the actuator's response one tick ahead from
//!   the machine's own velocities) against the configured delay: broken when
//!   it exceeds the configured delay by more than `response_lag` (plus half
//!   the estimate's grid).
//! - **Gain** (`actuator_gain_max`). The MPC's online gain estimate
//!   ([`crate::gain`]), the larger channel, against `actuator_gain_max` (plus
//!   the estimate's dead band).
//!
//! The pose's stamp error (`pose_latency`) is not observable from these
//! residuals (a constant stamp error moves the residual by a·Δt·δt, below the
//! noise): check it against the localisation's clock instead.
//!
//! # What is decided
//!
//! A measurement outside its tolerance for `span` seconds in a row breaks the
//! assumption ([`decide`], pure). With `action = "widen"` the envelope's
//! tolerance is raised to what was measured (never lowered again while the
//! monitor runs: the machine does not go back to a model it has just seen to
//! be wrong), as long as that stays within the configured bound
//! (`max_*`); beyond it, or with `action = "stop"`, the decision is a
//! controlled stop. Either way the finding names the assumption and the
//! amount, for the telemetry and the log. Allocation-free after
//! construction.

use serde::{Deserialize, Serialize};

use crate::envelope::EnvelopeSettings;
use crate::model::{clamp_state, f_continuous, ix, wrap_angle, Control, MachineParams, State};

/// Forgetting factor per tick of the residual statistics (≈ 10 s memory at
/// 5 Hz).
pub const FORGETTING: f64 = 0.98;
/// Standard deviations of the geometry fit beyond the tolerance before the
/// geometry is taken as broken.
pub const CONFIDENCE: f64 = 3.0;
/// Measured pose noise is broken above this × the stated σ (plus
/// [`NOISE_FLOOR_XY`], [`NOISE_FLOOR_THETA`]): an estimate from ~50 ticks
/// has a relative spread of ~15 %, so 1.5 × is three of them.
pub const NOISE_RATIO: f64 = 1.5;
pub const NOISE_FLOOR_XY: f64 = 0.005;
pub const NOISE_FLOOR_THETA: f64 = 0.003;
/// Effective ticks of residual before pose noise and geometry are judged.
pub const MIN_WEIGHT: f64 = 15.0;
/// Half the delay estimate's grid ([`crate::delay_estimate::GRID`]).
pub const DELAY_SLACK: f64 = crate::delay_estimate::GRID / 2.0;
/// The gain estimate's dead band ([`crate::gain::DEADBAND`]).
pub const GAIN_SLACK: f64 = crate::gain::DEADBAND;

/// What to do when an assumption is broken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnBroken {
    /// Widen the envelope's tolerance to what was measured, up to its bound;
    /// beyond it, stop.
    Widen,
    /// A controlled stop (a fault: the goal is aborted).
    Stop,
}

/// Settings of the check (`[envelope.check]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckSettings {
    /// Check the assumptions while driving (default true).
    pub enabled: bool,
    /// A measurement must stay outside its tolerance this long [s] before it
    /// counts (default 1 s: five ticks).
    pub span: f64,
    /// Widen or stop (default widen; docs/envelope-tolerances.md).
    pub action: OnBroken,
    /// The widest each tolerance may be widened to; a measurement beyond it
    /// is a controlled stop.
    pub max_geometry_tolerance: f64,
    pub max_response_lag: f64,
    pub max_actuator_gain: f64,
    pub max_pose_noise_xy: f64,
    pub max_pose_noise_theta: f64,
}

impl Default for CheckSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl CheckSettings {
    /// The defaults (a `const` for [`EnvelopeSettings::exact`]).
    pub const DEFAULT: Self = Self {
        enabled: true,
        span: 1.0,
        action: OnBroken::Widen,
        // L_r × 1.25 (0.15 m); a delay 0.8 s beyond the configured one; gain
        // 1.5; twice the default pose noise.
        max_geometry_tolerance: 0.15,
        max_response_lag: 0.8,
        max_actuator_gain: 1.5,
        max_pose_noise_xy: 0.06,
        max_pose_noise_theta: 0.04,
    };

    /// `span` in (0, 60] s, the bounds finite and ≥ 0, the gain bound in
    /// [1, 2], the lag bound at most 2 s (the envelope's own limits).
    pub fn validate(&self) -> Result<(), (&'static str, &'static str, f64)> {
        if !(self.span > 0.0 && self.span <= 60.0) {
            return Err(("check.span", "must be in (0, 60] s", self.span));
        }
        for (name, v) in [
            ("check.max_geometry_tolerance", self.max_geometry_tolerance),
            ("check.max_pose_noise_xy", self.max_pose_noise_xy),
            ("check.max_pose_noise_theta", self.max_pose_noise_theta),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((name, "must be finite and >= 0", v));
            }
        }
        if !(self.max_response_lag >= 0.0 && self.max_response_lag <= 2.0) {
            return Err((
                "check.max_response_lag",
                "must be in [0, 2] s",
                self.max_response_lag,
            ));
        }
        if !(self.max_actuator_gain >= 1.0 && self.max_actuator_gain <= 2.0) {
            return Err((
                "check.max_actuator_gain",
                "must be in [1, 2]",
                self.max_actuator_gain,
            ));
        }
        Ok(())
    }
}

/// An assumption of the envelope (a stated tolerance).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Assumption {
    Geometry,
    Delay,
    Gain,
    PoseNoiseXy,
    PoseNoiseTheta,
}

impl Assumption {
    pub const ALL: [Assumption; 5] = [
        Assumption::Geometry,
        Assumption::Delay,
        Assumption::Gain,
        Assumption::PoseNoiseXy,
        Assumption::PoseNoiseTheta,
    ];

    /// The envelope setting it is stated in.
    pub fn setting(self) -> &'static str {
        match self {
            Assumption::Geometry => "geometry_tolerance",
            Assumption::Delay => "response_lag",
            Assumption::Gain => "actuator_gain_max",
            Assumption::PoseNoiseXy => "pose_noise_xy",
            Assumption::PoseNoiseTheta => "pose_noise_theta",
        }
    }

    /// What the machine showed, in words.
    pub fn what(self) -> &'static str {
        match self {
            Assumption::Geometry => "rear-axle offset from L_f, L_r [m]",
            Assumption::Delay => "actuator delay beyond the configured one [s]",
            Assumption::Gain => "actuator gain",
            Assumption::PoseNoiseXy => "pose position noise, 1 sigma [m]",
            Assumption::PoseNoiseTheta => "pose heading noise, 1 sigma [rad]",
        }
    }

    fn index(self) -> usize {
        self as usize
    }

    /// The stated tolerance in `s`.
    pub fn stated(self, s: &EnvelopeSettings) -> f64 {
        match self {
            Assumption::Geometry => s.geometry_tolerance,
            Assumption::Delay => s.response_lag,
            Assumption::Gain => s.actuator_gain_max,
            Assumption::PoseNoiseXy => s.pose_noise_xy,
            Assumption::PoseNoiseTheta => s.pose_noise_theta,
        }
    }

    fn set(self, s: &mut EnvelopeSettings, v: f64) {
        match self {
            Assumption::Geometry => s.geometry_tolerance = v,
            // The envelope's record of the commands already acts after the
            // delay estimate (the loop sets it): the measured delay is in its
            // prediction, `response_lag` stays the uncertainty around it.
            Assumption::Delay => {
                let _ = v;
            }
            Assumption::Gain => s.actuator_gain_max = v,
            Assumption::PoseNoiseXy => s.pose_noise_xy = v,
            Assumption::PoseNoiseTheta => s.pose_noise_theta = v,
        }
    }

    /// The widest the check may make it.
    pub fn bound(self, c: &CheckSettings) -> f64 {
        match self {
            Assumption::Geometry => c.max_geometry_tolerance,
            Assumption::Delay => c.max_response_lag,
            Assumption::Gain => c.max_actuator_gain,
            Assumption::PoseNoiseXy => c.max_pose_noise_xy,
            Assumption::PoseNoiseTheta => c.max_pose_noise_theta,
        }
    }
}

/// One assumption the machine was seen to break.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finding {
    pub assumption: Assumption,
    /// What was measured (the units of the setting).
    pub measured: f64,
    /// The tolerance in force when it was measured.
    pub stated: f64,
}

impl Finding {
    /// How far beyond the tolerance.
    pub fn excess(&self) -> f64 {
        self.measured - self.stated
    }
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "envelope assumption `{}` broken: {} {:.3} > {:.3} stated (+{:.3})",
            self.assumption.setting(),
            self.assumption.what(),
            self.measured,
            self.stated,
            self.excess()
        )
    }
}

/// What to do this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Every assumption holds (or was widened before): go on.
    Continue,
    /// An assumption broke this tick; the envelope is widened to cover it.
    Widen,
    /// An assumption broke beyond its bound (or `action = "stop"`): stop.
    Stop,
}

/// The monitor's verdict on one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Assessment {
    pub decision: Decision,
    /// The largest break (relative to its tolerance) found this tick.
    pub finding: Option<Finding>,
    /// Assumptions broken so far (bit `Assumption as usize`), widened or not.
    pub broken: u8,
}

/// What the monitor is told each tick.
#[derive(Debug, Clone, Copy)]
pub struct TickInput<'a> {
    /// The tick's time [s].
    pub now: f64,
    /// The measured state (the pose's age compensated).
    pub measured: &'a State,
    /// The MPC's delay estimate [s] (the configured delay without one).
    pub delay_estimate: f64,
    /// The MPC's gain estimates (β̇, v_f) ([1, 1] without one).
    pub gain_estimate: [f64; 2],
}

/// The pure decision. `measured[i]` is the measurement of `Assumption::ALL[i]`
/// when it is outside its tolerance this tick (`None` inside), `since[i]`
/// when it went outside; `tolerance[i]` the tolerance in force, raised here
/// to what was measured when the envelope is widened. Returns the decision,
/// the largest break (relative to its tolerance) and the assumptions broken
/// this tick (bit `Assumption as usize`).
pub fn decide(
    check: &CheckSettings,
    tolerance: &mut [f64; 5],
    measured: &[Option<f64>; 5],
    since: &[Option<f64>; 5],
    now: f64,
) -> (Decision, Option<Finding>, u8) {
    let mut decision = Decision::Continue;
    let mut worst: Option<(f64, Finding)> = None;
    let mut broken = 0u8;
    for a in Assumption::ALL {
        let i = a.index();
        let (Some(m), Some(t0)) = (measured[i], since[i]) else {
            continue;
        };
        if now - t0 < check.span - 1e-9 {
            continue;
        }
        broken |= 1 << i;
        let finding = Finding {
            assumption: a,
            measured: m,
            stated: tolerance[i],
        };
        let relative = finding.excess() / tolerance[i].abs().max(1e-3);
        if worst.map_or(true, |(r, _)| relative > r) {
            worst = Some((relative, finding));
        }
        if check.action == OnBroken::Stop || m > a.bound(check) {
            decision = Decision::Stop;
        } else {
            tolerance[i] = m;
            if decision == Decision::Continue {
                decision = Decision::Widen;
            }
        }
    }
    (decision, worst.map(|(_, f)| f), broken)
}

/// The monitor (module docs).
#[derive(Debug, Clone)]
pub struct AssumptionMonitor {
    params: MachineParams,
    stated: EnvelopeSettings,
    effective: EnvelopeSettings,
    configured_delay: f64,
    prev: Option<(f64, State)>,
    /// The previous tick's residual (x, y, θ), for the lag-1 products.
    prev_residual: Option<[f64; 3]>,
    /// Σλ r², Σλ r_k r_{k−1} (xy per axis, θ), Σλ (weight).
    p0: [f64; 2],
    p1: [f64; 2],
    weight: f64,
    /// Geometry fit: Σλ a aᵀ, Σλ a r_θ.
    aa: [[f64; 2]; 2],
    ar: [f64; 2],
    since: [Option<f64>; 5],
    /// The tolerance each measurement is compared with: the stated one,
    /// raised to what was measured by each widening.
    tolerance: [f64; 5],
    broken: u8,
    stopped: bool,
}

impl AssumptionMonitor {
    /// For a machine `params` whose envelope states `stated` and whose MPC
    /// compensates `configured_delay`.
    pub fn new(params: MachineParams, stated: EnvelopeSettings, configured_delay: f64) -> Self {
        Self {
            params,
            stated,
            effective: stated,
            configured_delay,
            prev: None,
            prev_residual: None,
            p0: [0.0; 2],
            p1: [0.0; 2],
            weight: 0.0,
            aa: [[0.0; 2]; 2],
            ar: [0.0; 2],
            since: [None; 5],
            tolerance: Assumption::ALL.map(|a| a.stated(&stated)),
            broken: 0,
            stopped: false,
        }
    }

    /// The envelope settings to use now: the stated ones, widened by what the
    /// machine showed.
    pub fn effective(&self) -> &EnvelopeSettings {
        &self.effective
    }

    /// The stated settings.
    pub fn stated(&self) -> &EnvelopeSettings {
        &self.stated
    }

    /// True once a break has demanded a stop (it stays: the measurement that
    /// demanded it stops the machine again as long as it holds).
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    /// Forgets the previous measurement (a gap in the ticks: the next
    /// residual would span it). The statistics stay: they are the machine's.
    pub fn gap(&mut self) {
        self.prev = None;
        self.prev_residual = None;
    }

    /// The measured pose noise (σ_xy, σ_θ), once enough ticks were seen.
    pub fn pose_noise(&self) -> Option<[f64; 2]> {
        (self.weight >= MIN_WEIGHT).then(|| {
            [0, 1].map(|k| {
                ((self.p0[k] - self.p1[k]) / (3.0 * self.weight))
                    .max(0.0)
                    .sqrt()
            })
        })
    }

    /// The geometry fit (ΔL_f, ΔL_r) and the standard deviation of
    /// |ΔL_f| + |ΔL_r| (from the heading noise), once enough ticks were seen.
    pub fn geometry(&self) -> Option<([f64; 2], f64)> {
        if self.weight < MIN_WEIGHT {
            return None;
        }
        // Prior: ΔL = 0 with the weight of one well-excited tick
        // (a ≈ 0.05 rad/m), so that an unexcited direction stays at zero.
        let prior = 0.05f64.powi(2);
        let m = [
            [self.aa[0][0] + prior, self.aa[0][1]],
            [self.aa[1][0], self.aa[1][1] + prior],
        ];
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        if !(det > 0.0) {
            return None;
        }
        let inv = [
            [m[1][1] / det, -m[0][1] / det],
            [-m[1][0] / det, m[0][0] / det],
        ];
        let dl = [
            inv[0][0] * self.ar[0] + inv[0][1] * self.ar[1],
            inv[1][0] * self.ar[0] + inv[1][1] * self.ar[1],
        ];
        // Heading residual variance: 2σ_θ² (noise) plus a floor for the
        // model's own integration error.
        let sigma_r2 = 2.0 * self.pose_noise().map_or(0.0, |s| s[1] * s[1]) + 1e-8;
        let sd = (sigma_r2 * inv[0][0]).sqrt() + (sigma_r2 * inv[1][1]).sqrt();
        Some((dl, sd))
    }

    /// Takes one tick's measurement; returns the assessment.
    pub fn observe(&mut self, input: &TickInput) -> Assessment {
        let x = input.measured;
        let finite = x.iter().all(|v| v.is_finite());
        if finite {
            if let Some((t0, x0)) = self.prev {
                let dt = input.now - t0;
                if dt > 1e-6 && dt < 1.0 {
                    self.residual(&x0, x, dt);
                } else {
                    self.prev_residual = None;
                }
            }
            self.prev = Some((input.now, *x));
        } else {
            self.gap();
        }
        let measured = self.outside(input);
        for (since, m) in self.since.iter_mut().zip(&measured) {
            match (m, *since) {
                (Some(_), None) => *since = Some(input.now),
                (None, Some(_)) => *since = None,
                _ => {}
            }
        }
        let (decision, finding, broken) = decide(
            &self.stated.check,
            &mut self.tolerance,
            &measured,
            &self.since,
            input.now,
        );
        self.broken |= broken;
        // A stop of one assumption does not undo the widening of another.
        if decision != Decision::Continue {
            for a in Assumption::ALL {
                a.set(&mut self.effective, self.tolerance[a.index()]);
            }
        }
        if decision == Decision::Stop {
            self.stopped = true;
        }
        Assessment {
            decision,
            finding,
            broken: self.broken,
        }
    }

    /// The measurements outside the tolerances in force this tick.
    fn outside(&self, input: &TickInput) -> [Option<f64>; 5] {
        let t = |a: Assumption| self.tolerance[a.index()];
        let mut out = [None; 5];
        if !self.stated.check.enabled {
            return out;
        }
        let lag = input.delay_estimate - self.configured_delay;
        if lag.is_finite() && lag > t(Assumption::Delay) + DELAY_SLACK {
            out[Assumption::Delay.index()] = Some(lag);
        }
        let gain = input.gain_estimate[0].max(input.gain_estimate[1]);
        if gain.is_finite() && gain > t(Assumption::Gain) + GAIN_SLACK {
            out[Assumption::Gain.index()] = Some(gain.min(2.0));
        }
        if let Some([sxy, sth]) = self.pose_noise() {
            if sxy > NOISE_RATIO * t(Assumption::PoseNoiseXy) + NOISE_FLOOR_XY {
                out[Assumption::PoseNoiseXy.index()] = Some(sxy);
            }
            if sth > NOISE_RATIO * t(Assumption::PoseNoiseTheta) + NOISE_FLOOR_THETA {
                out[Assumption::PoseNoiseTheta.index()] = Some(sth);
            }
        }
        if let Some((dl, sd)) = self.geometry() {
            let g = dl[0].abs() + dl[1].abs();
            if g - CONFIDENCE * sd > t(Assumption::Geometry) {
                out[Assumption::Geometry.index()] = Some(g);
            }
        }
        out
    }

    /// The residual of the pose measured at `x1` against its prediction from
    /// `x0`, `dt` earlier, with the measured velocities; updates the
    /// statistics.
    fn residual(&mut self, x0: &State, x1: &State, dt: f64) {
        let p = &self.params;
        // At the articulation stop the measured β̇ is not the rate β moved
        // at (the stop zeroes it): no residual there.
        let free = p.beta_max - 0.02;
        if x0[ix::BETA].abs() > free || x1[ix::BETA].abs() > free {
            self.prev_residual = None;
            return;
        }
        // Velocities linear between the two measurements.
        let u = Control::new(
            (x1[ix::BETA_DOT] - x0[ix::BETA_DOT]) / dt,
            (x1[ix::V] - x0[ix::V]) / dt,
        );
        // The machine's own bounds may be exceeded by a machine with a gain
        // above 1: clamp at twice them only (the clamp guards the model,
        // not the measurement).
        let reach = MachineParams {
            beta_dot_max: 2.0 * p.beta_dot_max,
            v_max: 2.0 * p.v_max,
            ..*p
        };
        const STEPS: usize = 4;
        let h = dt / STEPS as f64;
        let mut x = *x0;
        // Sensitivity of the heading change to (L_f, L_r), integrated.
        let mut a = [0.0; 2];
        for _ in 0..STEPS {
            let s = heading_sensitivity(p, &x);
            let k1 = f_continuous(p, &x, &u);
            let k2 = f_continuous(p, &(x + k1 * (0.5 * h)), &u);
            let k3 = f_continuous(p, &(x + k2 * (0.5 * h)), &u);
            let k4 = f_continuous(p, &(x + k3 * h), &u);
            x += (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (h / 6.0);
            clamp_state(&reach, &mut x);
            let s2 = heading_sensitivity(p, &x);
            a[0] += 0.5 * (s[0] + s2[0]) * h;
            a[1] += 0.5 * (s[1] + s2[1]) * h;
        }
        let r = [
            x1[ix::X] - x[ix::X],
            x1[ix::Y] - x[ix::Y],
            wrap_angle(x1[ix::THETA] - x[ix::THETA]),
        ];
        let l = FORGETTING;
        let r2 = [0.5 * (r[0] * r[0] + r[1] * r[1]), r[2] * r[2]];
        let r1 = match self.prev_residual {
            Some(q) => [0.5 * (r[0] * q[0] + r[1] * q[1]), r[2] * q[2]],
            // Without a previous residual: the expected lag-1 product of
            // white noise (−P₀/2), so that the estimate is unbiased.
            None => [-0.5 * r2[0], -0.5 * r2[1]],
        };
        for k in 0..2 {
            self.p0[k] = l * self.p0[k] + r2[k];
            self.p1[k] = l * self.p1[k] + r1[k];
        }
        self.weight = l * self.weight + 1.0;
        for i in 0..2 {
            for j in 0..2 {
                self.aa[i][j] = l * self.aa[i][j] + a[i] * a[j];
            }
            self.ar[i] = l * self.ar[i] + a[i] * r[2];
        }
        self.prev_residual = Some(r);
    }
}

/// ∂θ̇/∂(L_f, L_r) of paper eq. 5 at `x`.
fn heading_sensitivity(p: &MachineParams, x: &State) -> [f64; 2] {
    let (b, bd, v) = (x[ix::BETA], x[ix::BETA_DOT], x[ix::V]);
    let d = p.l_f * b.cos() + p.l_r;
    let n = p.l_r * bd + v * b.sin();
    [
        -n * b.cos() / (d * d),
        (bd * p.l_f * b.cos() - v * b.sin()) / (d * d),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::VelocityCommand;
    use crate::plant::{Plant, PlantConfig, PlantPerturbation};

    const DT: f64 = 0.2;

    fn avant() -> MachineParams {
        MachineParams::default()
    }

    /// Each tick of a monitor fed by a plant driven with exciting commands
    /// (articulation and speed both varying), the estimates given by
    /// `estimates(t)`: (time, assessment).
    fn drive(
        stated: EnvelopeSettings,
        pert: PlantPerturbation,
        seconds: f64,
        estimates: impl Fn(f64) -> (f64, [f64; 2]),
    ) -> (AssumptionMonitor, Vec<(f64, Assessment)>) {
        let p = avant();
        let mut plant = Plant::perturbed(p, PlantConfig::ideal(), pert, State::zeros()).unwrap();
        let mut m = AssumptionMonitor::new(p, stated, 0.0);
        let mut out = Vec::new();
        for k in 0..(seconds / DT).round() as usize {
            let t = k as f64 * DT;
            let x = plant.measure();
            let (d, g) = estimates(t);
            let a = m.observe(&TickInput {
                now: t,
                measured: &x,
                delay_estimate: d,
                gain_estimate: g,
            });
            out.push((t, a));
            let cmd = VelocityCommand {
                // β = 0.57 sin(0.7 t): the joint stays off its stop.
                beta_dot: 0.4 * (0.7 * t).cos(),
                v: 0.6 + 0.3 * (0.31 * t).sin(),
            };
            plant.command(cmd).unwrap();
            plant.advance(DT);
        }
        (m, out)
    }

    fn nominal(_: f64) -> (f64, [f64; 2]) {
        (0.0, [1.0, 1.0])
    }

    /// The first tick whose decision is not `Continue`.
    fn first_action(ticks: &[(f64, Assessment)]) -> Option<(f64, Assessment)> {
        ticks
            .iter()
            .find(|(_, a)| a.decision != Decision::Continue)
            .copied()
    }

    #[test]
    fn decide_waits_for_the_span_widens_within_the_bound_and_stops_beyond() {
        let c = CheckSettings::DEFAULT;
        let mut tol = [0.06, 0.15, 1.2, 0.03, 0.02];
        let mut m = [None; 5];
        m[Assumption::Gain as usize] = Some(1.4);
        let mut since = [None; 5];
        since[Assumption::Gain as usize] = Some(10.0);
        // Outside for less than the span: nothing yet.
        let (d, f, b) = decide(&c, &mut tol, &m, &since, 10.0 + c.span - 0.2);
        assert_eq!((d, f, b), (Decision::Continue, None, 0));
        // For the span: widened to what was measured, named.
        let (d, f, b) = decide(&c, &mut tol, &m, &since, 10.0 + c.span);
        assert_eq!(d, Decision::Widen);
        let f = f.unwrap();
        assert_eq!(f.assumption, Assumption::Gain);
        assert!((f.excess() - 0.2).abs() < 1e-12, "{f}");
        assert!(f.to_string().contains("`actuator_gain_max`"), "{f}");
        assert_eq!(b, 1 << Assumption::Gain as usize);
        assert_eq!(tol[Assumption::Gain as usize], 1.4);
        // Beyond the bound (1.5): a stop, the tolerance unchanged.
        m[Assumption::Gain as usize] = Some(1.7);
        let (d, _, _) = decide(&c, &mut tol, &m, &since, 20.0);
        assert_eq!(d, Decision::Stop);
        assert_eq!(tol[Assumption::Gain as usize], 1.4);
        // With action = stop, any break stops.
        let stop = CheckSettings {
            action: OnBroken::Stop,
            ..c
        };
        m[Assumption::Gain as usize] = Some(1.3);
        let (d, _, _) = decide(&stop, &mut tol, &m, &since, 20.0);
        assert_eq!(d, Decision::Stop);
    }

    #[test]
    fn a_delay_beyond_the_response_lag_is_named_after_the_span() {
        let stated = EnvelopeSettings::default();
        let span = stated.check.span;
        // The delay estimate moves from 0 to 0.5 s at t = 4 s (stated lag 0.15).
        let (_, ticks) = drive(stated, PlantPerturbation::default(), 12.0, |t| {
            (if t >= 4.0 { 0.5 } else { 0.0 }, [1.0, 1.0])
        });
        let (t, a) = first_action(&ticks).expect("detected");
        assert!((t - (4.0 + span)).abs() < 1e-9, "at {t}");
        let f = a.finding.unwrap();
        assert_eq!(f.assumption, Assumption::Delay);
        assert!((f.measured - 0.5).abs() < 1e-12 && (f.stated - 0.15).abs() < 1e-12);
        assert_eq!(a.decision, Decision::Widen);
        // Beyond the bound (0.8 s beyond the configured delay): a stop.
        let (m, ticks) = drive(stated, PlantPerturbation::default(), 8.0, |t| {
            (if t >= 2.0 { 0.95 } else { 0.0 }, [1.0, 1.0])
        });
        assert_eq!(first_action(&ticks).unwrap().1.decision, Decision::Stop);
        assert!(m.stopped());
        // Within the lag (0.15 s, on the grid): nothing.
        let (_, ticks) = drive(stated, PlantPerturbation::default(), 12.0, |t| {
            (if t >= 4.0 { 0.15 } else { 0.0 }, [1.0, 1.0])
        });
        assert_eq!(first_action(&ticks), None);
    }

    #[test]
    fn a_gain_above_its_bound_is_widened_to_once_and_named() {
        let stated = EnvelopeSettings::default();
        let (m, ticks) = drive(stated, PlantPerturbation::default(), 12.0, |t| {
            (0.0, if t >= 3.0 { [1.0, 1.4] } else { [1.0, 1.0] })
        });
        let (t, a) = first_action(&ticks).expect("detected");
        assert!((t - (3.0 + stated.check.span)).abs() < 1e-9, "at {t}");
        assert_eq!(a.finding.unwrap().assumption, Assumption::Gain);
        assert_eq!(a.decision, Decision::Widen);
        assert_eq!(m.effective().actuator_gain_max, 1.4);
        // Widened once: the same measurement raises nothing more.
        let later: Vec<_> = ticks
            .iter()
            .filter(|(s, a)| *s > t && a.decision != Decision::Continue)
            .collect();
        assert!(later.is_empty(), "{later:?}");
        assert!(a.broken & (1 << Assumption::Gain as usize) != 0);
        // At the stated bound: nothing.
        let (_, ticks) = drive(stated, PlantPerturbation::default(), 12.0, |_| {
            (0.0, [1.2, 1.2])
        });
        assert_eq!(first_action(&ticks), None);
    }

    #[test]
    fn a_longer_rear_body_is_found_from_the_heading_and_widens_the_geometry() {
        let stated = EnvelopeSettings::default();
        let pert = PlantPerturbation {
            scale_lr: 1.2,
            ..Default::default()
        };
        let (m, ticks) = drive(stated, pert, 40.0, nominal);
        let (t, a) = first_action(&ticks).expect("L_r × 1.2 (0.12 m) detected");
        let f = a.finding.unwrap();
        assert_eq!(f.assumption, Assumption::Geometry, "{f}");
        assert_eq!(a.decision, Decision::Widen);
        // What was measured: the rear axle 0.12 m from the modelled one.
        assert!((f.measured - 0.12).abs() < 0.03, "{f}");
        assert!((m.effective().geometry_tolerance - f.measured).abs() < 1e-12);
        assert!(t < 20.0, "at {t}");
        // Within the tolerance (L_r × 1.05 = 0.03 m < 0.06 m): nothing, and
        // the fit finds it.
        let pert = PlantPerturbation {
            scale_lr: 1.05,
            ..Default::default()
        };
        let (m, ticks) = drive(stated, pert, 40.0, nominal);
        assert_eq!(first_action(&ticks), None);
        let (dl, _) = m.geometry().unwrap();
        assert!((dl[1] - 0.03).abs() < 0.01 && dl[0].abs() < 0.01, "{dl:?}");
    }

    #[test]
    fn pose_noise_beyond_the_stated_one_is_measured_and_named() {
        let stated = EnvelopeSettings::default();
        let noisy = PlantPerturbation {
            pose_noise_xy: 0.08,
            pose_noise_theta: 0.06,
            seed: 7,
            ..Default::default()
        };
        let (m, ticks) = drive(stated, noisy, 30.0, nominal);
        let (_, a) = first_action(&ticks).expect("detected");
        let f = a.finding.unwrap();
        assert!(
            matches!(
                f.assumption,
                Assumption::PoseNoiseXy | Assumption::PoseNoiseTheta
            ),
            "{f}"
        );
        // 0.08 m is beyond the bound (0.06 m): a stop.
        assert_eq!(a.decision, Decision::Stop);
        let [sxy, sth] = m.pose_noise().unwrap();
        assert!(
            (sxy - 0.08).abs() < 0.025 && (sth - 0.06).abs() < 0.02,
            "{sxy} {sth}"
        );
        // The matrix's pose-noise level (0.03 m / 0.02 rad) against the
        // stated 0.02 m / 0.01 rad: the heading noise is found and the
        // envelope widened to it (within the bound 0.04 rad).
        let level = PlantPerturbation {
            pose_noise_xy: 0.03,
            pose_noise_theta: 0.02,
            seed: 3,
            ..Default::default()
        };
        let (m, ticks) = drive(stated, level, 30.0, nominal);
        let (_, a) = first_action(&ticks).expect("detected");
        let f = a.finding.unwrap();
        assert_eq!(f.assumption, Assumption::PoseNoiseTheta, "{f}");
        assert_eq!(a.decision, Decision::Widen);
        assert!((m.effective().pose_noise_theta - 0.02).abs() < 0.006, "{f}");
        // The stated noise over a minute, several seeds: nothing raised, not
        // the geometry either.
        for seed in 0..4 {
            let inside = PlantPerturbation {
                pose_noise_xy: stated.pose_noise_xy,
                pose_noise_theta: stated.pose_noise_theta,
                seed,
                ..Default::default()
            };
            let (_, ticks) = drive(stated, inside, 60.0, nominal);
            assert_eq!(first_action(&ticks), None, "seed {seed}");
        }
    }

    #[test]
    fn the_exact_machine_raises_nothing_even_with_nothing_stated() {
        let (m, ticks) = drive(
            EnvelopeSettings::exact(),
            PlantPerturbation::default(),
            60.0,
            nominal,
        );
        assert_eq!(first_action(&ticks), None);
        let [sxy, sth] = m.pose_noise().unwrap();
        assert!(sxy < 1e-3 && sth < 1e-3, "{sxy} {sth}");
        let (dl, _) = m.geometry().unwrap();
        assert!(dl[0].abs() < 1e-3 && dl[1].abs() < 1e-3, "{dl:?}");
    }
}
