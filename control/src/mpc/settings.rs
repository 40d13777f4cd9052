//! MPC settings (DESIGN §5) with documented defaults, validated once at
//! construction; errors name the offending field.

use serde::{Deserialize, Serialize};

use crate::critic::HessianMode;
use crate::model::ModelError;

/// Most obstacles one goal can carry (DESIGN §6).
pub const MAX_OBSTACLES: usize = 8;

/// How circular obstacles enter the QP (both soft, with an exact L1 slack).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObstacleConstraint {
    /// h(x_n) ≥ 0 on n = 1..N, with h(x) = ‖p_f − o‖ − R linearised at the
    /// linearisation point (paper eq. 18 in distance form).
    Distance,
    /// Discrete-time control barrier function h(x_{n+1}) ≥ (1 − γ_cbf) h(x_n)
    /// on n = 0..N−1 (the paper's future work), also linearised.
    Cbf,
}

/// The QP solver behind the MPC (issue 30). The default is the Riccati
/// interior point; Clarabel is the reference it is tested against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum QpSolver {
    /// Clarabel's general sparse interior point ([`super::ClarabelBackend`]).
    Clarabel,
    /// The interior point over the horizon's stages with a Riccati recursion
    /// ([`super::RiccatiBackend`]).
    #[default]
    Riccati,
}

/// Everything the MPC can be tuned with. `Default` gives the values below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MpcSettings {
    /// Horizon N (stages). Default 10; 20 and 40 are supported. 1..=200.
    pub horizon: usize,
    /// Stage length Δt [s], also the command period. Default 0.2.
    pub dt: f64,
    /// Hessian of the critic: projected exact (eigenvalue clipping per block)
    /// or Gauss–Newton. Default exact.
    pub hessian: HessianMode,
    /// Levenberg–Marquardt term added to every cost block's diagonal (after the
    /// Δt scaling). Default 1e-4 (the authors' acados set-up). ≥ 0.
    pub levenberg_marquardt: f64,
    /// Eigenvalue floor of the projected exact Hessian blocks. Default 0. ≥ 0.
    pub min_eigenvalue: f64,
    /// Maximum SQP iterations per tick; 1 is real-time iteration (RTI). Default 1.
    pub sqp_iterations: usize,
    /// Step length α of every SQP iteration, in (0, 1]. Default 1.
    pub step_length: f64,
    /// SQP stops early when the step's largest component (∞-norm over all
    /// states and controls) is below this. Default 1e-6. > 0.
    pub sqp_tolerance: f64,
    /// L1 penalty per unit of state-bound violation (β [rad], β̇ [rad/s],
    /// v_f [m/s]). Default 1000. > 0.
    pub state_slack_weight: f64,
    /// L1 penalty per metre of obstacle penetration (per stage, of the
    /// deepest obstacle of either axle point; see [`super::layout`]).
    /// Default 1000: on `obstacles200.csv` 195/200 reached against 191/200
    /// at 100, no run inside a circle with either (README, work sites). > 0.
    pub obstacle_slack_weight: f64,
    /// Obstacle constraint form. Default distance.
    pub obstacle_constraint: ObstacleConstraint,
    /// γ_cbf in (0, 1] of the CBF form. Default 0.3.
    pub cbf_gamma: f64,
    /// Margin [m] by which the planned axle points keep clear of every circle
    /// (h ≥ margin at the ticks), so that the plant between ticks, its lag
    /// and the linearisation error stay outside the circle itself. Default
    /// 0.05. ≥ 0.
    pub obstacle_margin: f64,
    /// Margin [m] of the rear axle's rows. The rear axle's position is
    /// computed from the measured front pose through L_f and L_r, so it also
    /// carries the error of the measured geometry (a few centimetres on a
    /// field machine); the front axle's is measured. Default 0.05, as the
    /// front: 0.08 kept every obstacles200 run out with the plant's L_r 10 %
    /// longer (+0.016 m against −0.028 m) but missed `c_obstacles` and one
    /// more goal of obstacles200 (README, "robustness"). ≥ 0.
    pub obstacle_margin_rear: f64,
    /// Most circles a goal may have, at most 8. Default 8. One QP per count
    /// 0..=max_obstacles is built at start-up; a tick uses the one of the
    /// circles within reach ([`MpcSettings::obstacle_reach`]).
    pub max_obstacles: usize,
    /// Estimate the actuator gain online and divide the commands by it
    /// ([`crate::gain`]; DESIGN §12). Default true. On a machine without gain
    /// error the commands are bit-identical to those without it.
    pub gain_estimation: bool,
    /// Estimate the actuator delay online and compensate the estimate
    /// ([`crate::delay_estimate`]; DESIGN §12). Default true. When the
    /// configured delay is the machine's, the estimate stays on it.
    pub delay_estimation: bool,
    /// Actuator delay compensated before each solve [s], any value ≥ 0
    /// (the initial one with `delay_estimation`).
    /// Default 0.2 (the paper's machine).
    pub delay: f64,
    /// Clarabel's absolute and relative gap and feasibility tolerance. Default
    /// 1e-6 (with refinement off, about half the QP time of 1e-7 with it).
    pub qp_tolerance: f64,
    /// Clarabel's iteration limit. Default 100.
    pub qp_max_iterations: u32,
    /// Clarabel's iterative refinement of each KKT solve. Default false.
    pub qp_iterative_refinement: bool,
    /// Clarabel's Ruiz equilibration (computed once, on nominal data). Default true.
    pub qp_equilibrate: bool,
    /// The QP solver. Default Riccati (issue 30: the same closed loop as
    /// Clarabel, paper128 and obstacles200, with the QP about 3 × and the
    /// tick about 1.6 × faster; README, "Rows that exist").
    pub qp_solver: QpSolver,
    /// Time budget of one tick [s]: Clarabel's time limit, and no further SQP
    /// iteration is started if it would not fit. Default 0.1.
    pub time_budget: f64,
}

impl Default for MpcSettings {
    fn default() -> Self {
        Self {
            horizon: 10,
            dt: 0.2,
            hessian: HessianMode::Exact,
            levenberg_marquardt: 1e-4,
            min_eigenvalue: 0.0,
            sqp_iterations: 1,
            step_length: 1.0,
            sqp_tolerance: 1e-6,
            state_slack_weight: 1000.0,
            obstacle_slack_weight: 1000.0,
            obstacle_constraint: ObstacleConstraint::Distance,
            cbf_gamma: 0.3,
            obstacle_margin: 0.05,
            obstacle_margin_rear: 0.05,
            max_obstacles: MAX_OBSTACLES,
            gain_estimation: true,
            delay_estimation: true,
            delay: 0.2,
            qp_tolerance: 1e-6,
            qp_max_iterations: 100,
            qp_iterative_refinement: false,
            qp_equilibrate: true,
            qp_solver: QpSolver::Riccati,
            time_budget: 0.1,
        }
    }
}

/// Largest supported horizon.
pub const MAX_HORIZON: usize = 200;

/// Errors of the MPC's construction and goal handling.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MpcError {
    #[error("MPC setting `{name}` {requirement} (got {value})")]
    Setting {
        name: &'static str,
        requirement: &'static str,
        value: String,
    },
    #[error("machine parameters: {0}")]
    Model(#[from] ModelError),
    #[error("goal must be finite (got x {x}, y {y}, theta {theta})")]
    BadGoal { x: f64, y: f64, theta: f64 },
    #[error("{given} obstacles given, the MPC was built for at most {max} (`max_obstacles`)")]
    TooManyObstacles { given: usize, max: usize },
    #[error(transparent)]
    BadObstacle(#[from] crate::obstacle::BadObstacle),
    #[error("no goal set: call `set_goal` before `step`")]
    NoGoal,
    #[error("QP solver set-up failed: {0}")]
    QpSetup(String),
}

impl MpcError {
    /// The setting (`MpcSettings` field name) a configuration error is about.
    pub fn setting(&self) -> Option<&'static str> {
        match self {
            Self::Setting { name, .. } => Some(name),
            Self::TooManyObstacles { .. } => Some("max_obstacles"),
            _ => None,
        }
    }
}

fn setting(name: &'static str, requirement: &'static str, value: impl ToString) -> MpcError {
    MpcError::Setting {
        name,
        requirement,
        value: value.to_string(),
    }
}

impl MpcSettings {
    /// The settings with the planned clearances widened by the envelope's
    /// tolerances ([`crate::envelope::EnvelopeSettings::tolerance_widening`],
    /// [front, rear]): the MPC plans outside what the envelope guards, so that
    /// stated pose noise, latency and geometry error do not make it act.
    pub fn widened(self, widening: [f64; 2]) -> Self {
        Self {
            obstacle_margin: self.obstacle_margin + widening[0],
            obstacle_margin_rear: self.obstacle_margin_rear + widening[1],
            ..self
        }
    }

    /// How far from the front axle [m] a circle's edge can matter to a plan
    /// over the horizon (issue 30: only those get QP rows): the horizon
    /// driven at 1.25 × the top speed (the speed bounds are soft, and a
    /// machine with an actuator gain above 1 goes faster), the rear axle's
    /// lever L_f + L_r, the larger planned margin, and 0.5 m so that a circle
    /// enters the QP well before its rows could bind.
    pub fn obstacle_reach(&self, p: &crate::model::MachineParams) -> f64 {
        1.25 * p.v_max * self.horizon as f64 * self.dt
            + p.l_f
            + p.l_r
            + self.obstacle_margin.max(self.obstacle_margin_rear)
            + 0.5
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), MpcError> {
        if !(1..=MAX_HORIZON).contains(&self.horizon) {
            return Err(setting("horizon", "must be in 1..=200", self.horizon));
        }
        let positive = [
            ("dt", self.dt),
            ("step_length", self.step_length),
            ("sqp_tolerance", self.sqp_tolerance),
            ("state_slack_weight", self.state_slack_weight),
            ("obstacle_slack_weight", self.obstacle_slack_weight),
            ("cbf_gamma", self.cbf_gamma),
            ("qp_tolerance", self.qp_tolerance),
            ("time_budget", self.time_budget),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(setting(name, "must be finite and > 0", value));
            }
        }
        let non_negative = [
            ("levenberg_marquardt", self.levenberg_marquardt),
            ("min_eigenvalue", self.min_eigenvalue),
            ("delay", self.delay),
            ("obstacle_margin", self.obstacle_margin),
            ("obstacle_margin_rear", self.obstacle_margin_rear),
        ];
        for (name, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(setting(name, "must be finite and >= 0", value));
            }
        }
        if self.step_length > 1.0 {
            return Err(setting(
                "step_length",
                "must be in (0, 1]",
                self.step_length,
            ));
        }
        if self.cbf_gamma > 1.0 {
            return Err(setting("cbf_gamma", "must be in (0, 1]", self.cbf_gamma));
        }
        if self.sqp_iterations == 0 {
            return Err(setting(
                "sqp_iterations",
                "must be >= 1",
                self.sqp_iterations,
            ));
        }
        if self.max_obstacles > MAX_OBSTACLES {
            return Err(setting(
                "max_obstacles",
                "must be at most 8",
                self.max_obstacles,
            ));
        }
        if self.qp_max_iterations == 0 {
            return Err(setting(
                "qp_max_iterations",
                "must be >= 1",
                self.qp_max_iterations,
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_errors_name_the_field() {
        assert!(MpcSettings::default().validate().is_ok());
        let cases: [(MpcSettings, &str); 8] = [
            (
                MpcSettings {
                    horizon: 0,
                    ..Default::default()
                },
                "horizon",
            ),
            (
                MpcSettings {
                    dt: -0.2,
                    ..Default::default()
                },
                "dt",
            ),
            (
                MpcSettings {
                    step_length: 1.5,
                    ..Default::default()
                },
                "step_length",
            ),
            (
                MpcSettings {
                    levenberg_marquardt: f64::NAN,
                    ..Default::default()
                },
                "levenberg_marquardt",
            ),
            (
                MpcSettings {
                    sqp_iterations: 0,
                    ..Default::default()
                },
                "sqp_iterations",
            ),
            (
                MpcSettings {
                    max_obstacles: 9,
                    ..Default::default()
                },
                "max_obstacles",
            ),
            (
                MpcSettings {
                    delay: -0.1,
                    ..Default::default()
                },
                "delay",
            ),
            (
                MpcSettings {
                    time_budget: 0.0,
                    ..Default::default()
                },
                "time_budget",
            ),
        ];
        for (s, name) in cases {
            let e = s.validate().unwrap_err().to_string();
            assert!(e.contains(&format!("`{name}`")), "{e}");
        }
    }

    #[test]
    fn settings_round_trip_through_json_with_defaults() {
        let s: MpcSettings =
            serde_json::from_str(r#"{"horizon": 20, "hessian": "gauss-newton"}"#).unwrap();
        assert_eq!(s.horizon, 20);
        assert_eq!(s.hessian, HessianMode::GaussNewton);
        assert_eq!(s.dt, 0.2);
        assert_eq!(s.qp_solver, QpSolver::Riccati);
        let r: MpcSettings = serde_json::from_str(r#"{"qp_solver": "clarabel"}"#).unwrap();
        assert_eq!(r.qp_solver, QpSolver::Clarabel);
        assert!(serde_json::from_str::<MpcSettings>(r#"{"qp_solver": "qdldl"}"#).is_err());
        assert!(serde_json::from_str::<MpcSettings>(r#"{"horizn": 20}"#).is_err());
    }
}
