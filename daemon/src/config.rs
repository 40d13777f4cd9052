//! The daemon's configuration: one TOML file, every section optional, every key
//! with a documented default (the built-in defaults are a complete simulated set-up,
//! so `wlnavd --sim` needs no file at all).
//!
//! Validation happens once, in [`Config::validate`], and every error names the key
//! (`loop.pose_timeout`, `mpc.horizon`, `sim.plant.delay`, …). Unknown keys are errors
//! too (a typo must not silently fall back to a default on a machine).
//!
//! ```toml
//! [machine]            # control::MachineParams: l_f, l_r, beta_max, beta_dot_max, v_max, beta_ddot_max, a_max
//! [mpc]                # control::mpc::MpcSettings: horizon, dt, hessian, delay, time_budget, qp_solver, ...
//! [envelope]           # control::envelope::EnvelopeSettings: the safety envelope (DESIGN §14)
//! margin = 0.01        # m kept beyond the tolerances below
//! geometry_tolerance = 0.06  # m: how far the true rear axle may be from the configured L_f, L_r
//! pose_noise_xy = 0.02 # m, 1 σ;  pose_noise_theta = 0.01  # rad, 1 σ
//! pose_latency = 0.01  # s: uncertainty of the pose's stamp;  response_lag = 0.15  # s
//! actuator_gain_max = 1.2  # the machine may achieve up to this × the commanded velocities
//! # (the shipped defaults are conservative: docs/envelope-tolerances.md says how to narrow them)
//! [envelope.check]     # control::assumption_check::CheckSettings: the assumptions checked while driving
//! span = 1.0           # s outside a tolerance before it counts;  action = "widen"  # or "stop"
//! [controller]
//! cost = "critic"      # "critic" (the trained network) or "quadratic" (no weights; for bring-up)
//! planner = "hybrid-astar"  # the global layer (DESIGN §10): "hybrid-astar" or "none"
//! [navigator]          # control::planner::NavigatorSettings: [navigator.search], [navigator.following], [navigator.stall], max_route_age, trajectory
//! [trajectory]         # trajopt::trajectory::TrajectorySettings: the min-time trajectory's solve (max_solve_seconds, margin, ...)
//! [weights]
//! critic = "critic-weights/avant635/critic.safetensors"   # control::weights::DEFAULT_DIR
//! actor = "critic-weights/avant635/actor.safetensors"     # "" = no actor (zero-control warm start)
//! [loop]              # the tick period is mpc.dt (one MPC stage per command)
//! pose_timeout = 0.5   # s: older pose -> controlled stop
//! progress_timeout = 10.0  # s without approach -> goal aborted (no-progress)
//! ...
//! [loop.realtime]      # tick thread: SCHED_FIFO, mlockall, CPU pinning (crate::realtime)
//! enabled = false
//! priority = 40        # SCHED_FIFO 1..=99
//! lock_memory = true
//! cpu = 1              # absent = no pinning
//! [can]
//! backend = "sim"      # or "socketcan"
//! interface = "can0"
//! log = ""             # candump -L file of every frame ("" = off)
//! [ipc]
//! prefix = "wlnav"
//! workspace = { x_min = -50.0, x_max = 50.0, y_min = -50.0, y_max = 50.0 }
//! [site]
//! file = ""            # a wlnav-site-v1 JSON or a Nav2 map YAML (DESIGN §17); "" = no site
//! [outline]            # the machine's covering circles (DESIGN §17)
//! preset = "axle-circles"  # or avant635, large-loader, large-loader-axles; or circles + half_width
//! [sim]                # the simulated machine (can.backend = "sim")
//! time_scale = 1.0
//! [sim.plant]          # control::PlantConfig: delay, tau_beta_dot, tau_v, noise, seed
//! [sim.faults]         # fault injection for tests and demos
//! ```
//!
//! Relative paths (weights, CAN log) are resolved against the configuration file's
//! directory; without a file, see [`Config::resolve_paths`].

use std::path::{Path, PathBuf};

use control::envelope::EnvelopeSettings;
use control::mpc::MpcSettings;
use control::progress::ProgressSettings;
use control::weights::{self, NetworkRole};
use control::{MachineParams, PlantConfig};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A configuration problem; the message names the key.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// TOML syntax, an unknown key or a value of the wrong type (toml names the key
    /// and the line).
    #[error("config file {path}: {message}")]
    Parse {
        /// The file (or `<built-in>`).
        path: String,
        /// toml's message, with line and key.
        message: String,
    },
    /// A value outside its valid range.
    #[error("config key `{key}`: {message}")]
    Invalid {
        /// Dotted key, e.g. `loop.pose_timeout`.
        key: String,
        /// What is wrong.
        message: String,
    },
}

fn invalid(key: impl Into<String>, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        message: message.into(),
    }
}

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Machine geometry and bounds (paper Table I by default).
    pub machine: MachineParams,
    /// MPC settings.
    pub mpc: MpcSettings,
    /// The safety envelope after the MPC and the tolerances its margins come
    /// from (DESIGN §14). Not in `[machine]`: the weights' metadata names the
    /// machine, and a tolerance is a property of the installation, not of the
    /// trained networks.
    pub envelope: EnvelopeSettings,
    /// Which cost the MPC uses.
    pub controller: ControllerConfig,
    /// The global layer's settings (the measured defaults; DESIGN §10). Its
    /// progress window and reach tolerance are the loop's (`loop.progress_*`,
    /// `loop.reach_tolerance`): one owner each.
    pub navigator: control::planner::NavigatorSettings,
    /// How the planner's min-time trajectory is optimised, where
    /// `navigator.trajectory` asks for one (issue 42).
    pub trajectory: trajopt::trajectory::TrajectorySettings,
    /// Weight files.
    pub weights: WeightsConfig,
    /// Control loop timing and safety thresholds.
    #[serde(rename = "loop")]
    pub control: LoopConfig,
    /// CAN interface.
    pub can: CanConfig,
    /// iceoryx2 services.
    pub ipc: IpcSection,
    /// The simulated machine.
    pub sim: SimConfig,
    /// The site file (DESIGN §17).
    pub site: SiteConfig,
    /// The machine's outline (DESIGN §17).
    pub outline: OutlineConfig,
    /// Live obstacles from perception (DESIGN §18): their stop and slow-down
    /// fields, the freshness rule (`required`: a machine without perception
    /// declares it not required), the hold after a protective stop.
    pub live: control::live::LiveSettings,
    /// Which keys the configuration text set (not a setting).
    #[serde(skip)]
    pub given: KeysGiven,
}

/// Which keys a configuration text sets: paths it leaves out are found like
/// without a file, and a machine it leaves out is the critic's
/// ([`Config::adopt_trained_machine`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KeysGiven {
    /// `weights.critic`.
    pub critic: bool,
    /// `weights.actor`.
    pub actor: bool,
    /// `can.log`.
    pub can_log: bool,
    /// Any key of `[machine]`.
    pub machine: bool,
    /// `mpc.dt`.
    pub dt: bool,
}

/// `[site]`: the site every goal is driven in (DESIGN §17).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SiteConfig {
    /// A `wlnav-site-v1` JSON file, or a ROS / Nav2 `map_server` YAML (its
    /// image beside it); relative to the configuration file. Empty: no site
    /// (the goals' circles only).
    pub file: PathBuf,
}

impl SiteConfig {
    /// The file, if one is configured.
    pub fn path(&self) -> Option<&Path> {
        (!self.file.as_os_str().is_empty()).then_some(self.file.as_path())
    }
}

/// `[outline]`: the machine's outline as covering circles (DESIGN §17). Either
/// `preset` (`axle-circles`, the default: a circle of the half-width at each
/// axle, today's model; `avant635`; `large-loader`; `large-loader-axles`), or
/// `circles` (`{ body = "front" | "rear", offset = [forward, left], radius }`)
/// with `half_width` (what a goal's wire circles include in their radius).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutlineConfig {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub circles: Option<Vec<control::site::OutlineCircle>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub half_width: Option<f64>,
}

impl OutlineConfig {
    /// The outline this section names.
    pub fn outline(&self) -> Result<control::site::Outline, ConfigError> {
        use control::site::Outline;
        match (&self.preset, &self.circles, self.half_width) {
            (None, None, None) => Ok(control::world::default_outline()),
            (Some(name), None, None) => Outline::named(name).ok_or_else(|| {
                invalid(
                    "outline.preset",
                    format!(
                        "unknown outline {name:?} (one of {})",
                        Outline::NAMES.join(", ")
                    ),
                )
            }),
            (None, Some(circles), Some(hw)) => Outline::new(circles.clone(), hw)
                .map_err(|e| invalid("outline.circles", e.to_string())),
            _ => Err(invalid(
                "outline",
                "give either `preset`, or `circles` and `half_width`",
            )),
        }
    }
}

/// `[controller]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// `critic` (default) or `quadratic`.
    pub cost: CostKind,
    /// The global layer above the MPC: `hybrid-astar` (default;
    /// `docs/global-layer.md`) or `none` (the MPC drives straight to the goal and
    /// stops behind obstacles).
    pub planner: PlannerChoice,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            cost: CostKind::Critic,
            planner: PlannerChoice::HybridAstar,
        }
    }
}

/// `controller.planner`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlannerChoice {
    /// Hybrid A* over (x, y, θ) with the model's motion primitives.
    HybridAstar,
    /// No global layer.
    None,
}

/// The MPC's stage cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CostKind {
    /// The trained critic L(s, a, g) (DESIGN §3), loaded from `weights.critic`.
    Critic,
    /// A hand-tuned quadratic cost with a distance term; needs no weights. For
    /// bring-up and tests before the critic is trained; it reaches goals straight
    /// ahead but is no substitute for the critic on turning manoeuvres.
    Quadratic,
}

/// `[weights]`. Their metadata must name the configured `[machine]` and `mpc.dt`
/// (start-up refuses them otherwise).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WeightsConfig {
    /// The critic's safetensors file.
    pub critic: PathBuf,
    /// The actor's safetensors file; empty = no actor.
    pub actor: PathBuf,
}

impl WeightsConfig {
    /// The critic and actor of a weights directory (one per machine, e.g.
    /// `critic-weights/avant635`).
    pub fn in_dir(dir: &Path) -> Self {
        Self {
            critic: dir.join(weights::CRITIC_FILE),
            actor: dir.join(weights::ACTOR_FILE),
        }
    }
}

impl Default for WeightsConfig {
    /// The default machine's: `critic-weights/avant635/{critic,actor}.safetensors`.
    fn default() -> Self {
        Self::in_dir(Path::new(weights::DEFAULT_DIR))
    }
}

/// `[loop]`: timing and safety thresholds. Times in (daemon) seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Removed: the tick period is `mpc.dt`. Present only to refuse old files
    /// with that explanation instead of "unknown field".
    #[serde(skip_serializing)]
    pub rate_hz: Option<f64>,
    /// A pose older than this is stale → controlled stop. Default 0.5 s.
    pub pose_timeout: f64,
    /// A machine state older than this is stale → controlled stop. Default 0.3 s.
    pub state_timeout: f64,
    /// Ticks in a row without a fresh solve (driving on the controller's shifted
    /// plan, or on the stop ramp when it has none) before the loop stops. Default 2.
    pub fallback_ticks: u32,
    /// Consecutive rejected machine-state frames (bad CRC, frozen or skipping alive
    /// counter, bad length or range) that count as persistent → controlled stop.
    /// Default 5.
    pub can_bad_frames_stop: u32,
    /// Lost frames tolerated between two accepted ones (alive-counter gap). Default 2.
    pub can_max_lost: u8,
    /// Goal reached when ‖(x_f − x_g, y_f − y_g, e_θ)‖ is below this. Default 0.1.
    pub reach_tolerance: f64,
    /// … and |v_f| is below this [m/s]. Default 0.05.
    pub reach_speed: f64,
    /// A goal whose error ‖(x_f − x_g, y_f − y_g, e_θ)‖ has not shrunk by
    /// `progress_min_approach` for this long [s] is aborted (`no-progress`) and the
    /// machine brought to rest (DESIGN §10, Nav2's progress checker). Default 10.
    pub progress_timeout: f64,
    /// How much closer counts as progress [m and rad combined]. Default 0.1.
    pub progress_min_approach: f64,
    /// A machine state beyond its bound by more than this fraction of the bound is
    /// implausible (treated like a stale one). Default 0.2.
    pub plausibility_margin: f64,
    /// On SIGTERM/SIGINT: longest wait for the machine to come to rest before
    /// exiting anyway (the stop command is still the last frame). Default 5 s.
    pub shutdown_timeout: f64,
    /// |v_f| and |β̇| below which the machine counts as at rest. Default 0.02.
    pub rest_speed: f64,
    /// Stop after this many ticks (0 = run until signalled); for soak runs.
    pub max_ticks: u64,
    /// A pose stamped more than this ahead of the daemon's clock is rejected (it could
    /// otherwise never go stale). Default 0.05 s.
    pub pose_max_future: f64,
    /// Position jump tolerated on top of what the machine can drive since the last
    /// accepted pose (v_max·(1 + plausibility_margin)·Δt) [m]. Default 0.5.
    pub pose_jump_tolerance: f64,
    /// Heading jump tolerated on top of the model's largest yaw rate times Δt [rad].
    /// Default 0.3.
    pub pose_heading_tolerance: f64,
    /// Poses must lie inside `ipc.workspace` grown by this margin [m]. Default 10.
    pub pose_workspace_margin: f64,
    /// Consecutive rejected pose samples that make a pose fault → controlled stop; as many
    /// consistent samples, spanning at least `pose_timeout`, clear it. Default 5.
    pub pose_reject_stop: u32,
    /// `[loop.realtime]`: SCHED_FIFO, mlockall and CPU pinning for the tick thread
    /// (off by default; refusals are logged, never fatal). See [`crate::realtime`].
    pub realtime: crate::realtime::RealtimeConfig,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            rate_hz: None,
            pose_timeout: 0.5,
            state_timeout: 0.3,
            fallback_ticks: 2,
            can_bad_frames_stop: 5,
            can_max_lost: 2,
            reach_tolerance: control::model::SUCCESS_TOLERANCE,
            reach_speed: control::model::REACH_SPEED,
            progress_timeout: ProgressSettings::default().timeout,
            progress_min_approach: ProgressSettings::default().min_approach,
            plausibility_margin: 0.2,
            shutdown_timeout: 5.0,
            rest_speed: control::model::REST_SPEED,
            max_ticks: 0,
            pose_max_future: 0.05,
            pose_jump_tolerance: 0.5,
            pose_heading_tolerance: 0.3,
            pose_workspace_margin: 10.0,
            pose_reject_stop: 5,
            realtime: Default::default(),
        }
    }
}

impl LoopConfig {
    /// The progress checker's settings.
    pub fn progress(&self) -> ProgressSettings {
        ProgressSettings {
            timeout: self.progress_timeout,
            min_approach: self.progress_min_approach,
        }
    }
}

/// CAN backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CanBackend {
    /// A real interface through SocketCAN.
    Socketcan,
    /// The built-in simulated machine (`control::plant::Plant` behind the frames).
    Sim,
}

/// `[can]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CanConfig {
    /// `sim` (default) or `socketcan`.
    pub backend: CanBackend,
    /// SocketCAN interface name (socketcan backend). Default `can0`.
    pub interface: String,
    /// Log every frame sent and received to this file in `candump -L` format
    /// (appending); empty = off.
    pub log: PathBuf,
}

impl Default for CanConfig {
    fn default() -> Self {
        Self {
            backend: CanBackend::Sim,
            interface: "can0".into(),
            log: PathBuf::new(),
        }
    }
}

/// `[ipc]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcSection {
    /// Service-name prefix: services are `{prefix}/v2/goal|pose|telemetry`.
    pub prefix: String,
    /// Goals must lie inside this rectangle [m].
    pub workspace: WorkspaceConfig,
}

impl Default for IpcSection {
    fn default() -> Self {
        Self {
            prefix: shm_ipc::DEFAULT_PREFIX.into(),
            workspace: WorkspaceConfig::default(),
        }
    }
}

/// `ipc.workspace`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
#[allow(missing_docs)]
pub struct WorkspaceConfig {
    pub x_min: f64,
    pub x_max: f64,
    pub y_min: f64,
    pub y_max: f64,
}

impl Default for WorkspaceConfig {
    fn default() -> Self {
        let w = shm_ipc::Workspace::default();
        Self {
            x_min: w.x_min,
            x_max: w.x_max,
            y_min: w.y_min,
            y_max: w.y_max,
        }
    }
}

/// `[sim]`: the simulated machine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Daemon seconds per real second (> 0). Only the simulated machine may run at
    /// another pace than real time. Default 1.
    pub time_scale: f64,
    /// Machine-state frames per (daemon) second. Default 50.
    pub state_rate_hz: f64,
    /// Pose estimates published on `{prefix}/v2/pose` per second. Default 20.
    pub pose_rate_hz: f64,
    /// Publish pose estimates (the built-in localization). Default true.
    pub publish_pose: bool,
    /// Initial state [x_f, y_f, θ_f, β, β̇, v_f].
    pub initial_state: [f64; 6],
    /// Delay, velocity lag, noise of the simulated machine.
    pub plant: PlantConfig,
    /// Fault injection.
    pub faults: SimFaults,
    /// The simulated perception (`[sim.perception]`, DESIGN §18).
    pub perception: SimPerception,
}

/// `[sim.perception]`: the simulated machine's perception publishes live
/// obstacle sets on `{prefix}/v2/obstacles` through the real service (the
/// one publisher): the movers of `movers` (a movers CSV, DESIGN §18; times
/// after the daemon's start), measured every 1 / `rate_hz`, published
/// `latency` later, a set lost with probability `dropout` (seeded).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimPerception {
    /// Publish sets (default true; false: a test or an external program is
    /// the perception).
    pub publish: bool,
    /// A movers file, relative to the configuration file (empty: none; the
    /// sets are empty, and fresh).
    pub movers: PathBuf,
    pub latency: f64,
    pub rate_hz: f64,
    pub dropout: f64,
    pub seed: u64,
}

impl Default for SimPerception {
    fn default() -> Self {
        let p = control::movers::PerceptionSettings::default();
        Self {
            publish: true,
            movers: PathBuf::new(),
            latency: p.latency,
            rate_hz: p.rate,
            dropout: p.dropout,
            seed: p.seed,
        }
    }
}

impl SimPerception {
    pub fn settings(&self) -> control::movers::PerceptionSettings {
        control::movers::PerceptionSettings {
            latency: self.latency,
            rate: self.rate_hz,
            dropout: self.dropout,
            seed: self.seed,
        }
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            time_scale: 1.0,
            state_rate_hz: 50.0,
            pose_rate_hz: 20.0,
            publish_pose: true,
            initial_state: [0.0; 6],
            plant: PlantConfig::default(),
            faults: SimFaults::default(),
            perception: SimPerception::default(),
        }
    }
}

/// `[sim.faults]`: faults the simulated machine injects, at daemon times [s].
/// A negative start time (the default) disables the fault.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimFaults {
    /// From this time, corrupt the CRC byte of machine-state frames …
    pub crc_burst_at: f64,
    /// … this many in a row (0 = none; a large number = permanently).
    pub crc_burst_frames: u32,
    /// From this time, repeat the alive counter (frozen sender) …
    pub freeze_alive_at: f64,
    /// … for this many frames.
    pub freeze_alive_frames: u32,
    /// From this time, publish no pose …
    pub pose_dropout_at: f64,
    /// … for this long [s].
    pub pose_dropout_duration: f64,
    /// From this time, send no machine-state frame …
    pub state_dropout_at: f64,
    /// … for this long [s].
    pub state_dropout_duration: f64,
}

impl Default for SimFaults {
    fn default() -> Self {
        Self {
            crc_burst_at: -1.0,
            crc_burst_frames: 0,
            freeze_alive_at: -1.0,
            freeze_alive_frames: 0,
            pose_dropout_at: -1.0,
            pose_dropout_duration: 0.0,
            state_dropout_at: -1.0,
            state_dropout_duration: 0.0,
        }
    }
}

fn check_positive(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(key, format!("must be finite and > 0 (got {v})")))
    }
}

fn check_non_negative(key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(key, format!("must be finite and >= 0 (got {v})")))
    }
}

/// A configuration error for the setting `name` of `section` (the section alone
/// when the error names none).
fn invalid_in(section: &str, name: Option<&str>, e: impl std::fmt::Display) -> ConfigError {
    let key = match name {
        Some(name) => format!("{section}.{name}"),
        None => section.to_owned(),
    };
    invalid(key, e.to_string())
}

impl Config {
    /// The MPC's settings as it runs: `[mpc]` with the planned clearances widened
    /// by the envelope's tolerances, so the MPC plans outside what the envelope
    /// guards (DESIGN §14; `wlnav-sim eval` does the same).
    pub fn mpc_settings(&self) -> MpcSettings {
        self.mpc
            .widened(self.envelope.tolerance_widening(&self.machine))
    }

    /// What the envelope's tolerances give (issue 43; `wlnavd --check-config`
    /// prints it): the margins of both axle points and where they come from,
    /// the response lags predicted, the MPC's planned clearances and the
    /// assumption check.
    pub fn envelope_report(&self) -> String {
        let e = &self.envelope;
        let p = &self.machine;
        if !e.enabled {
            return "envelope: OFF (envelope.enabled = false): no command is checked\n".into();
        }
        let [front, rear] = e.margins(p);
        let (n, step, pad) = control::envelope::late_samples(e, p);
        let mpc = self.mpc_settings();
        let c = &e.check;
        let mut out = format!(
            "envelope margins (DESIGN §14; docs/envelope-tolerances.md):\n\
             \x20 front axle {front:.3} m = margin {:.3} + {} × pose_noise_xy {:.3} + v_max {:.2} m/s × pose_latency {:.3} s\n\
             \x20 rear axle  {rear:.3} m = front {front:.3} + geometry_tolerance {:.3} + (l_f + l_r) {:.2} m × {} × pose_noise_theta {:.3}\n\
             \x20 response: after the compensated delay and up to response_lag {:.3} s later ({} lag(s), {:.3} s apart, +{:.3} m for the motion between them), at up to actuator_gain_max {:.2} × the command\n\
             \x20 the MPC plans front {:.3} m, rear {:.3} m from every circle (mpc.obstacle_margin{{,_rear}} + the tolerances)\n",
            e.margin,
            e.noise_sigmas,
            e.pose_noise_xy,
            p.v_max,
            e.pose_latency,
            e.geometry_tolerance,
            p.l_f + p.l_r,
            e.noise_sigmas,
            e.pose_noise_theta,
            e.response_lag,
            n + 1,
            step,
            pad,
            e.actuator_gain_max,
            mpc.obstacle_margin,
            mpc.obstacle_margin_rear,
        );
        if c.enabled {
            out += &format!(
                "assumption check: on; a measurement outside its tolerance for {:.1} s → {}; \
                 widened at most to geometry {:.3} m, delay +{:.2} s, gain {:.2}, pose noise {:.3} m / {:.3} rad (beyond: controlled stop)\n",
                c.span,
                match c.action {
                    control::assumption_check::OnBroken::Widen => "widen the envelope to it",
                    control::assumption_check::OnBroken::Stop => "controlled stop",
                },
                c.max_geometry_tolerance,
                c.max_response_lag,
                c.max_actuator_gain,
                c.max_pose_noise_xy,
                c.max_pose_noise_theta,
            );
        } else {
            out += "assumption check: OFF (envelope.check.enabled = false)\n";
        }
        out
    }

    /// The tick period [s]: the MPC's stage Δt (`mpc.dt`), the command period
    /// the critic was trained with.
    pub fn period(&self) -> f64 {
        self.mpc.dt
    }

    /// Parses TOML text (`source` names it in errors) and validates it.
    pub fn from_toml(text: &str, source: &str) -> Result<Self, ConfigError> {
        let mut config: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: source.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        config.validate()?;
        config.given = Self::keys_given(text);
        Ok(config)
    }

    /// Reads, parses and validates a file; relative paths *given in the file* are
    /// resolved against the file's directory. Keys the file leaves out keep their default
    /// (relative) paths, for the caller to resolve like a run without a file
    /// ([`Config::resolve_paths`] leaves absolute paths alone), so a file without
    /// `[weights]` finds the weights where a run without a file would.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        let mut config = Self::from_toml(&text, &path.display().to_string())?;
        let base = path.parent().unwrap_or(Path::new("."));
        let given = config.given;
        let defaults = (config.weights.clone(), config.can.log.clone());
        config.resolve_paths(&[base.to_path_buf()]);
        if !given.critic {
            config.weights.critic = defaults.0.critic;
        }
        if !given.actor {
            config.weights.actor = defaults.0.actor;
        }
        if !given.can_log {
            config.can.log = defaults.1;
        }
        Ok(config)
    }

    /// Which keys a configuration text sets.
    fn keys_given(text: &str) -> KeysGiven {
        let v: toml::Table = toml::from_str(text).unwrap_or_default();
        let section = |name: &str| v.get(name).and_then(|s| s.as_table());
        let has = |name: &str, key: &str| section(name).is_some_and(|s| s.contains_key(key));
        KeysGiven {
            critic: has("weights", "critic"),
            actor: has("weights", "actor"),
            can_log: has("can", "log"),
            machine: section("machine").is_some_and(|s| !s.is_empty()),
            dt: has("mpc", "dt"),
        }
    }

    /// The machine travels with the weights (DESIGN §4): when the configuration
    /// gives no `[machine]` (or no `mpc.dt`), the critic's metadata does. A machine
    /// the configuration gives is checked against the weights when they are loaded
    /// (and refused if it differs). With the quadratic cost, or a critic that
    /// cannot be read (reported when the controller loads), the configured
    /// machine stays.
    pub fn adopt_trained_machine(&mut self) {
        if self.controller.cost != CostKind::Critic || (self.given.machine && self.given.dt) {
            return;
        }
        let Ok(w) = control::weights::load(&self.weights.critic, NetworkRole::Critic) else {
            return;
        };
        if !self.given.machine {
            self.machine = w.meta.machine;
        }
        if !self.given.dt {
            self.mpc.dt = w.meta.dt;
        }
    }

    /// Makes relative weight and log paths absolute: the first of `bases` under which
    /// the weight file exists wins (the first base if none has it, so the error
    /// names a concrete path).
    pub fn resolve_paths(&mut self, bases: &[PathBuf]) {
        let resolve = |p: &Path| -> PathBuf {
            if p.as_os_str().is_empty() || p.is_absolute() {
                return p.to_path_buf();
            }
            for b in bases {
                let c = b.join(p);
                if c.exists() {
                    return c;
                }
            }
            bases.first().map(|b| b.join(p)).unwrap_or_else(|| p.into())
        };
        self.weights.critic = resolve(&self.weights.critic);
        self.weights.actor = resolve(&self.weights.actor);
        self.site.file = resolve(&self.site.file);
        self.sim.perception.movers = resolve(&self.sim.perception.movers);
        if let Some(b) = bases.first() {
            if !self.can.log.as_os_str().is_empty() && self.can.log.is_relative() {
                self.can.log = b.join(&self.can.log);
            }
        }
    }

    /// Checks every value; the error names the first bad key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.machine
            .validate()
            .map_err(|e| invalid_in("machine", Some(e.setting()), &e))?;
        self.mpc
            .validate()
            .map_err(|e| invalid_in("mpc", e.setting(), &e))?;
        self.envelope
            .validate()
            .map_err(|e| invalid_in("envelope", Some(e.name), &e))?;
        self.live
            .validate()
            .map_err(|e| invalid_in("live", Some(e.name), &e))?;
        self.sim
            .perception
            .settings()
            .validate()
            .map_err(|e| invalid("sim.perception", e))?;
        self.outline.outline()?;
        let l = &self.control;
        if let Some(hz) = l.rate_hz {
            return Err(invalid(
                "loop.rate_hz",
                format!(
                    "no longer a setting (got {hz} Hz): the tick period is mpc.dt ({} s, one \
                     MPC stage per command); remove the key",
                    self.mpc.dt
                ),
            ));
        }
        if self.mpc.dt < 1e-3 {
            return Err(invalid("mpc.dt", "must be at least 1 ms (the tick period)"));
        }
        check_positive("loop.pose_timeout", l.pose_timeout)?;
        check_positive("loop.state_timeout", l.state_timeout)?;
        check_positive("loop.reach_tolerance", l.reach_tolerance)?;
        check_positive("loop.reach_speed", l.reach_speed)?;
        check_positive("loop.progress_timeout", l.progress_timeout)?;
        check_positive("loop.progress_min_approach", l.progress_min_approach)?;
        check_non_negative("loop.plausibility_margin", l.plausibility_margin)?;
        check_non_negative("loop.shutdown_timeout", l.shutdown_timeout)?;
        check_positive("loop.rest_speed", l.rest_speed)?;
        check_non_negative("loop.pose_max_future", l.pose_max_future)?;
        check_non_negative("loop.pose_jump_tolerance", l.pose_jump_tolerance)?;
        check_non_negative("loop.pose_heading_tolerance", l.pose_heading_tolerance)?;
        check_non_negative("loop.pose_workspace_margin", l.pose_workspace_margin)?;
        if l.pose_reject_stop == 0 {
            return Err(invalid("loop.pose_reject_stop", "must be >= 1"));
        }
        l.realtime
            .validate()
            .map_err(|(key, m)| invalid(format!("loop.realtime.{key}"), m))?;
        if l.can_bad_frames_stop == 0 {
            return Err(invalid("loop.can_bad_frames_stop", "must be >= 1"));
        }
        if l.can_max_lost > can_max_lost_limit() {
            return Err(invalid(
                "loop.can_max_lost",
                format!("must be at most {}", can_max_lost_limit()),
            ));
        }
        if self.weights.critic.as_os_str().is_empty() && self.controller.cost == CostKind::Critic {
            return Err(invalid(
                "weights.critic",
                "must name a file when controller.cost = \"critic\"",
            ));
        }
        if let Some(n) = self.navigator_settings() {
            n.validate()
                .map_err(|e| invalid("navigator", e.to_string()))?;
        }
        self.trajectory
            .validate()
            .map_err(|e| invalid(format!("trajectory.{}", e.key), e.message))?;
        if self.can.backend == CanBackend::Socketcan && self.can.interface.trim().is_empty() {
            return Err(invalid("can.interface", "must not be empty"));
        }
        shm_ipc::validate_prefix(&self.ipc.prefix)
            .map_err(|e| invalid("ipc.prefix", e.to_string()))?;
        let w = &self.ipc.workspace;
        if shm_ipc::Workspace::new(w.x_min, w.x_max, w.y_min, w.y_max).is_none() {
            return Err(invalid(
                "ipc.workspace",
                "needs finite bounds with x_min < x_max and y_min < y_max",
            ));
        }
        let s = &self.sim;
        check_positive("sim.time_scale", s.time_scale)?;
        if s.time_scale > 1000.0 {
            return Err(invalid("sim.time_scale", "must be at most 1000"));
        }
        if s.time_scale != 1.0 && self.can.backend != CanBackend::Sim {
            return Err(invalid(
                "sim.time_scale",
                "must be 1 unless can.backend = \"sim\": a real machine runs in real time",
            ));
        }
        check_positive("sim.state_rate_hz", s.state_rate_hz)?;
        check_positive("sim.pose_rate_hz", s.pose_rate_hz)?;
        if s.initial_state.iter().any(|v| !v.is_finite()) {
            return Err(invalid("sim.initial_state", "must be 6 finite numbers"));
        }
        s.plant
            .validate()
            .map_err(|e| invalid_in("sim.plant", e.setting(), &e))?;
        let f = &s.faults;
        for (key, v) in [
            ("sim.faults.crc_burst_at", f.crc_burst_at),
            ("sim.faults.freeze_alive_at", f.freeze_alive_at),
            ("sim.faults.pose_dropout_at", f.pose_dropout_at),
            ("sim.faults.state_dropout_at", f.state_dropout_at),
        ] {
            if !v.is_finite() {
                return Err(invalid(key, "must be finite (negative = off)"));
            }
        }
        check_non_negative("sim.faults.pose_dropout_duration", f.pose_dropout_duration)?;
        check_non_negative(
            "sim.faults.state_dropout_duration",
            f.state_dropout_duration,
        )?;
        Ok(())
    }

    /// The pose gate's thresholds (DESIGN §11) from `[loop]`, `[machine]` and
    /// `ipc.workspace`.
    pub fn pose_gate(&self) -> crate::pose_gate::PoseGateConfig {
        let l = &self.control;
        let m = 1.0 + l.plausibility_margin;
        let w = &self.ipc.workspace;
        let g = l.pose_workspace_margin;
        crate::pose_gate::PoseGateConfig {
            timeout: l.pose_timeout,
            max_future: l.pose_max_future,
            max_speed: self.machine.v_max * m,
            max_yaw_rate: crate::pose_gate::PoseGateConfig::model_yaw_rate(&self.machine) * m,
            position_tolerance: l.pose_jump_tolerance,
            heading_tolerance: l.pose_heading_tolerance,
            region: [w.x_min - g, w.x_max + g, w.y_min - g, w.y_max + g],
            reject_run: l.pose_reject_stop,
        }
    }

    /// The goal validator for the configured workspace.
    pub fn goal_validator(&self) -> shm_ipc::GoalValidator {
        let w = &self.ipc.workspace;
        shm_ipc::GoalValidator::new(
            shm_ipc::Workspace::new(w.x_min, w.x_max, w.y_min, w.y_max).unwrap_or_default(),
        )
    }

    /// What the goal lifecycle decides with: the machine's footprint, the reach test.
    pub fn lifecycle_settings(&self) -> crate::goal_lifecycle::LifecycleSettings {
        crate::goal_lifecycle::LifecycleSettings {
            machine: self.machine,
            reach_tolerance: self.control.reach_tolerance,
            reach_speed: self.control.reach_speed,
        }
    }

    /// The global layer's settings (`None` for `controller.planner = "none"`): the
    /// measured defaults, the configured planner, its route clearance widened by the
    /// envelope's tolerances as the MPC's is, and the loop's progress window (the
    /// pilot's: the navigator's abort window, or the pilot's own without one).
    pub fn navigator_settings(&self) -> Option<control::planner::NavigatorSettings> {
        if self.controller.planner == PlannerChoice::None {
            return None;
        }
        let mut n = self
            .navigator
            .clone()
            .widened(self.envelope.tolerance_widening(&self.machine));
        n.stall.progress = self.control.progress();
        n.stall.reached_tolerance = self.control.reach_tolerance;
        Some(n)
    }

    /// The configuration as TOML (for `--print-config`).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"))
    }
}

/// Which path keys a configuration file sets (see [`Config::load`]).
fn can_max_lost_limit() -> u8 {
    crate::can::AliveTracker::MAX_LOST_LIMIT
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip() {
        let c = Config::default();
        c.validate().unwrap();
        let mut back = Config::from_toml(&c.to_toml(), "t").unwrap();
        assert!(
            back.given.machine && back.given.dt,
            "a full file gives everything"
        );
        back.given = c.given;
        assert_eq!(back, c);
    }

    /// `[mpc] qp_solver` picks the MPC's QP solver (issue 30): each solver's name gives
    /// that solver, so one of them is not the default and a key that were ignored would
    /// fail here; without the key the default stays; a name it does not know is an error
    /// naming the key.
    #[test]
    fn mpc_qp_solver_is_read() {
        use control::mpc::QpSolver;
        let default = control::mpc::MpcSettings::default().qp_solver;
        let mut differs = false;
        for (name, solver) in [
            ("riccati", QpSolver::Riccati),
            ("clarabel", QpSolver::Clarabel),
        ] {
            let c = Config::from_toml(&format!("[mpc]\nqp_solver = \"{name}\"\n"), "t").unwrap();
            assert_eq!(c.mpc_settings().qp_solver, solver, "{name}");
            differs |= solver != default;
        }
        assert!(differs, "both solvers named: one is not the default");
        let d = Config::from_toml("[mpc]\nhorizon = 20\n", "t").unwrap();
        assert_eq!(d.mpc_settings().qp_solver, default);
        assert!(err("[mpc]\nqp_solver = \"qdldl\"\n").contains("qp_solver"));
    }

    /// Issue 43: the shipped envelope states conservative tolerances; a
    /// file narrows them knowingly, `[envelope.check]` is read and checked,
    /// and the report `--check-config` prints gives the margins they make.
    #[test]
    fn envelope_defaults_are_conservative_and_the_report_gives_the_margins() {
        let c = Config::default();
        let e = &c.envelope;
        assert!(
            e.geometry_tolerance >= 0.06
                && e.pose_noise_xy >= 0.02
                && e.pose_noise_theta >= 0.01
                && e.pose_latency > 0.0
                && e.response_lag >= 0.15
                && e.actuator_gain_max >= 1.2,
            "{e:?}"
        );
        assert!(e.check.enabled);
        let report = c.envelope_report();
        // front 0.01 + 3 × 0.02 + 1 × 0.01 = 0.08; rear + 0.06 + 1.2 × 3 × 0.01.
        assert!(report.contains("front axle 0.080 m"), "{report}");
        assert!(report.contains("rear axle  0.176 m"), "{report}");
        assert!(report.contains("assumption check: on"), "{report}");
        // Narrowed in a file: the report follows.
        let exact = Config::from_toml(
            "[envelope]\ngeometry_tolerance = 0.0\npose_noise_xy = 0.0\npose_noise_theta = 0.0\n\
             pose_latency = 0.0\nresponse_lag = 0.0\nactuator_gain_max = 1.0\n\
             [envelope.check]\naction = \"stop\"\nspan = 2.0\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            exact.envelope.check.action,
            control::assumption_check::OnBroken::Stop
        );
        let report = exact.envelope_report();
        assert!(
            report.contains("front axle 0.010 m") && report.contains("rear axle  0.010 m"),
            "{report}"
        );
        assert!(report.contains("controlled stop"), "{report}");
        // The MPC and the route planner plan outside the tolerances: the
        // MPC's clearances by each axle's widening, the route's one margin by
        // their mean; with nothing stated, as configured.
        let (m, n) = (c.mpc_settings(), c.navigator_settings().unwrap());
        let base = control::planner::NavigatorSettings::default()
            .search
            .clearance_margin;
        assert!((m.obstacle_margin - (c.mpc.obstacle_margin + 0.07)).abs() < 1e-9);
        assert!((m.obstacle_margin_rear - (c.mpc.obstacle_margin_rear + 0.166)).abs() < 1e-9);
        assert!(
            (n.search.clearance_margin - (base + 0.118)).abs() < 1e-9,
            "{n:?}"
        );
        let n = exact.navigator_settings().unwrap();
        assert_eq!(n.search.clearance_margin, base);
        assert_eq!(
            exact.mpc_settings().obstacle_margin,
            exact.mpc.obstacle_margin
        );
        assert!(err("[envelope.check]\nspan = 0\n").contains("`envelope.check.span`"));
        assert!(err("[envelope.check]\nmax_actuator_gain = 3\n").contains("max_actuator_gain"));
        assert!(err("[envelope.check]\naction = \"ignore\"\n").contains("action"));
    }

    fn err(text: &str) -> String {
        Config::from_toml(text, "test.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn errors_name_the_key() {
        // The tick period is mpc.dt; the old key is refused with that explanation.
        let removed = err("[loop]\nrate_hz = 5\n");
        assert!(
            removed.contains("`loop.rate_hz`") && removed.contains("mpc.dt"),
            "{removed}"
        );
        assert!(err("[mpc]\ndt = 0.0001\n").contains("`mpc.dt`"));
        assert!(err("[mpc]\nhorizon = 0\n").contains("`mpc.horizon`"));
        assert!(err("[loop]\nprogress_timeout = 0\n").contains("`loop.progress_timeout`"));
        assert!(err("[machine]\nv_max = 0\n").contains("`machine.v_max`"));
        assert!(err("[sim.plant]\ndelay = -1\n").contains("`sim.plant.delay`"));
        assert!(err("[sim]\ntime_scale = 0\n").contains("`sim.time_scale`"));
        assert!(
            err("[can]\nbackend = \"socketcan\"\n[sim]\ntime_scale = 2\n")
                .contains("`sim.time_scale`")
        );
        assert!(err("[ipc]\nprefix = \"\"\n").contains("`ipc.prefix`"));
        assert!(err("[ipc.workspace]\nx_min = 5\nx_max = 1\n").contains("`ipc.workspace`"));
        let unknown = err("[loop]\npose_timeout = 0.5\ntypo = 1\n");
        assert!(unknown.contains("typo"), "{unknown}");
        let wrong_type = err("[loop]\npose_timeout = \"fast\"\n");
        assert!(wrong_type.contains("pose_timeout"), "{wrong_type}");
        assert!(err("[loop]\npose_reject_stop = 0\n").contains("`loop.pose_reject_stop`"));
        assert!(err("[loop]\npose_max_future = -1\n").contains("`loop.pose_max_future`"));
        assert!(err("[loop.realtime]\nenabled = true\npriority = 0\n")
            .contains("`loop.realtime.priority`"));
        assert!(err("[loop.realtime]\npriority = 100\n").contains("`loop.realtime.priority`"));
        assert!(err("[loop.realtime]\ncpu = 100000\n").contains("`loop.realtime.cpu`"));
        assert!(err("[loop.realtime]\nprio = 10\n").contains("prio"));
        assert!(
            err("[trajectory]\nmax_solve_seconds = 0\n").contains("`trajectory.max_solve_seconds`")
        );
        assert!(err("[trajectory]\nintervals = 1\n").contains("`trajectory.intervals`"));
        assert!(err("[trajectory]\nmax_iterations = 0\n").contains("`trajectory.max_iterations`"));
        assert!(err("[trajectory]\nmargin = -0.1\n").contains("`trajectory.margin`"));
        assert!(err("[trajectory]\nbeta_dot_fraction = 1.5\n")
            .contains("`trajectory.beta_dot_fraction`"));
        assert!(err("[trajectory]\nsolver = \"x\"\n").contains("solver"));
        assert!(Config::default().navigator.trajectory);
        let off = Config::from_toml("[navigator]\ntrajectory = false\n", "t").unwrap();
        assert!(!off.navigator.trajectory);
    }

    #[test]
    fn the_machine_and_dt_come_from_the_critic_unless_the_file_gives_them() {
        use control::weights::{encode, random_network, FileDtype, NetworkMetadata};
        let dir = tempfile::tempdir().unwrap();
        let mut meta = NetworkMetadata::new(NetworkRole::Critic, 4);
        meta.machine.l_f = 0.9;
        meta.machine.v_max = 1.5;
        meta.dt = 0.25;
        let w = random_network(meta, &[8], 1);
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F32).unwrap();
        std::fs::write(dir.path().join("critic.safetensors"), bytes).unwrap();
        let file = dir.path().join("wlnavd.toml");
        let weights = "[weights]\ncritic = \"critic.safetensors\"\nactor = \"\"\n";
        std::fs::write(&file, weights).unwrap();
        let mut c = Config::load(&file).unwrap();
        c.adopt_trained_machine();
        assert_eq!(c.machine, w.meta.machine);
        assert_eq!((c.mpc.dt, c.period()), (0.25, 0.25));
        c.validate().unwrap();
        // The weights load and the MPC builds for the adopted machine.
        let build = crate::controller::load_controller(&c).unwrap();
        build().unwrap();

        // A file that gives the machine keeps it, and loading refuses the mismatch.
        std::fs::write(&file, format!("{weights}[machine]\nl_f = 0.6\n")).unwrap();
        let mut c = Config::load(&file).unwrap();
        c.adopt_trained_machine();
        assert_eq!((c.machine.l_f, c.mpc.dt), (0.6, 0.25));
        let e = crate::controller::load_controller(&c)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("l_f") && e.contains("incompatible"), "{e}");

        // The quadratic cost keeps the configured (default) machine.
        std::fs::write(
            &file,
            format!("{weights}[controller]\ncost = \"quadratic\"\n"),
        )
        .unwrap();
        let mut c = Config::load(&file).unwrap();
        c.adopt_trained_machine();
        assert_eq!(c.machine, MachineParams::default());
    }

    #[test]
    fn a_file_without_weights_keeps_the_default_paths_for_the_caller_to_resolve() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("wlnavd.toml");
        std::fs::write(&file, "[loop]\npose_timeout = 0.5\n").unwrap();
        let c = Config::load(&file).unwrap();
        assert_eq!(
            c.weights,
            WeightsConfig::default(),
            "defaults stay relative"
        );
        // Paths the file gives are relative to the file.
        std::fs::write(&file, "[weights]\ncritic = \"w/c.safetensors\"\n").unwrap();
        let c = Config::load(&file).unwrap();
        assert_eq!(c.weights.critic, dir.path().join("w/c.safetensors"));
        assert_eq!(c.weights.actor, WeightsConfig::default().actor);
    }
}
