//! The simulated machine: `control::plant::Plant` behind the real CAN frames.
//!
//! [`spawn`] starts a tokio task that plays the machine's low-level controller on
//! one end of a [`LoopbackBus`] and returns the other end for the daemon. The task
//!
//! * decodes every velocity command with the same codec and integrity checks a
//!   real machine would use (CRC, alive counter), and hands it to the plant
//!   (`Drive`/`Stop`: follow the velocities; `Hold`/`Fault`: zero), which adds the
//!   configured delay, velocity lag and acceleration limits;
//! * sends machine-state frames (β, β̇, v_f, status, alive, CRC) at
//!   `sim.state_rate_hz`, with the configured measurement noise;
//! * publishes pose estimates on `{prefix}/v2/pose` at `sim.pose_rate_hz` (the
//!   built-in localization), so the default set-up needs nothing else;
//! * injects the faults of `[sim.faults]` (CRC bursts, frozen alive counter,
//!   pose or state dropouts);
//! * stops the plant by itself when commands stop arriving for 0.5 s (the
//!   machine-side command timeout a real low-level controller has).
//!
//! All its times are daemon times of the shared [`DaemonClock`], so the physics run
//! `sim.time_scale` times faster than real time together with the daemon.
//!
//! A [`SimHandle`] lets tests read what the machine received (every decoded
//! command, with its daemon time) and its true state.

use std::sync::{Arc, Mutex};

use control::model::ix;
use control::movers::{Mover, Perception};
use control::{Plant, State};
use shm_ipc::{pose_flags, Client, IpcConfig, LiveObstacleSet, Pose2, PoseEstimate};
use thiserror::Error;
use tokio::task::JoinHandle;

use crate::can::{
    AliveCounter, CanBus, CanFrame, DriveMode, LoopbackBus, MachineState, MachineStatus, RxTracker,
    VelocityCommandFrame,
};
use crate::clock::DaemonClock;
use crate::config::Config;

/// Without a command for this long [s] the simulated machine stops by itself.
pub const MACHINE_COMMAND_TIMEOUT: f64 = 0.5;

/// A command as the machine received it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceivedCommand {
    /// Daemon time of reception [s].
    pub time: f64,
    /// The decoded command.
    pub command: VelocityCommandFrame,
    /// The machine's true (β̇, v) when it arrived.
    pub velocity: (f64, f64),
}

/// What the simulated machine saw and did.
#[derive(Debug, Clone, Default)]
pub struct SimLog {
    /// Every valid command received, in order (when recording).
    pub commands: Vec<ReceivedCommand>,
    /// Valid commands received.
    pub commands_received: u64,
    /// Command frames rejected by the machine's checks.
    pub rejected_commands: u64,
    /// Machine-state frames sent (including corrupted ones).
    pub state_frames: u64,
    /// State frames sent with a corrupted CRC.
    pub corrupted_frames: u64,
    /// State frames sent with a repeated alive counter.
    pub frozen_frames: u64,
    /// Poses published.
    pub poses: u64,
    /// The plant's true state at the last update.
    pub true_state: [f64; 6],
    /// Daemon time of the last update [s].
    pub time: f64,
    /// Times the machine-side command timeout stopped the plant.
    pub command_timeouts: u64,
}

/// Read access to the simulated machine's log.
#[derive(Debug, Clone, Default)]
pub struct SimHandle(Arc<Mutex<SimLog>>);

impl SimHandle {
    /// A copy of the log now.
    pub fn snapshot(&self) -> SimLog {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn with<R>(&self, f: impl FnOnce(&mut SimLog) -> R) -> R {
        f(&mut self.0.lock().unwrap_or_else(|p| p.into_inner()))
    }
}

/// The simulated machine could not start.
#[derive(Debug, Error)]
pub enum SimError {
    /// Bad plant settings.
    #[error("config key `sim.plant`: {0}")]
    Plant(#[from] control::plant::PlantError),
    /// The pose publisher could not be created.
    #[error("simulated localization: {0}")]
    Ipc(#[from] shm_ipc::IpcError),
    /// The perception's movers file could not be read.
    #[error("config key `sim.perception.movers`: {0}")]
    Movers(String),
}

/// Starts the simulated machine on the current tokio runtime. Returns the daemon's
/// end of the bus, the log handle and the task (it ends when the daemon's end is
/// dropped).
/// With `record`, every received command is kept in the log (tests); without, only
/// counters are (a long-running simulation must not grow).
pub fn spawn(
    config: &Config,
    clock: DaemonClock,
    record: bool,
) -> Result<(LoopbackBus, SimHandle, JoinHandle<()>), SimError> {
    let s = &config.sim;
    let initial = State::from_row_slice(&s.initial_state);
    let plant = Plant::new(config.machine, s.plant, initial)?;
    let pose_client = if s.publish_pose {
        Some(Client::new(&IpcConfig::new(config.ipc.prefix.clone()))?)
    } else {
        None
    };
    let (daemon_end, machine_end) = LoopbackBus::pair("sim");
    let handle = SimHandle::default();
    // A recording run with a tick limit (the soak test) has its log's room from the
    // start (a command a tick), so that the heap does not grow with it while the daemon's
    // own heap is watched.
    if record {
        let ticks = usize::try_from(config.control.max_ticks).unwrap_or(0);
        handle.with(|l| l.commands.reserve(ticks));
    }
    let machine = Machine {
        bus: machine_end,
        plant,
        clock,
        config: config.sim.clone(),
        pose_client,
        log: handle.clone(),
        rx: RxTracker::new(config.control.can_max_lost),
        alive: AliveCounter::ZERO,
        last_command_time: f64::NEG_INFINITY,
        stopped_by_timeout: true,
        pose_seq: 0,
        record,
        burst_sent: 0,
        frozen_sent: 0,
    };
    if s.perception.publish {
        let movers = load_movers(&s.perception.movers)?;
        let ipc = IpcConfig::new(config.ipc.prefix.clone());
        let publisher = shm_ipc::ObstaclePublisher::new(&ipc)?;
        // With movers, their times count from the first goal: its telemetry says when.
        let telemetry = if movers.is_empty() {
            None
        } else {
            let client = Client::new(&ipc)?;
            let subscriber = client.subscribe_telemetry()?;
            Some((client, subscriber))
        };
        tokio::spawn(perceive(
            publisher,
            movers,
            s.perception.settings(),
            clock,
            telemetry,
        ));
    }
    let task = tokio::spawn(machine.run());
    Ok((daemon_end, handle, task))
}

/// The movers of `path` (none for an empty path).
fn load_movers(path: &std::path::Path) -> Result<Vec<Mover>, SimError> {
    if path.as_os_str().is_empty() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| SimError::Movers(format!("{}: {e}", path.display())))?;
    control::movers::parse(&text, &path.display().to_string())
        .map_err(|e| SimError::Movers(e.to_string()))
}

/// The simulated perception (`[sim.perception]`, DESIGN §18): the movers'
/// sets published through the real live-obstacle service as they are
/// delivered (measured, then `latency` later, some lost), stamped with their
/// measurement time. Mover times count from the first goal's first tick
/// (`telemetry` tells it); until then the sets are empty. Ends when the
/// daemon's service is gone.
async fn perceive(
    publisher: shm_ipc::ObstaclePublisher,
    movers: Vec<Mover>,
    settings: control::movers::PerceptionSettings,
    clock: DaemonClock,
    telemetry: Option<(Client, shm_ipc::TelemetrySubscriber)>,
) {
    let mut origin = telemetry.is_none().then_some(0.0);
    let mut perception = Perception::new(&movers, settings, "wlnavd --sim");
    let mut wire = Box::new(LiveObstacleSet::ZERO);
    loop {
        let now = clock.now();
        if origin.is_none() {
            let first_goal = telemetry
                .as_ref()
                .and_then(|(_, s)| s.latest().ok().flatten())
                .filter(|t| t.goal_active == 1);
            origin = first_goal.map(|t| clock.from_monotonic_ns(t.timestamp_ns));
        }
        let next = match origin {
            None => {
                *wire = LiveObstacleSet::empty(
                    clock.to_monotonic_ns(now),
                    wire.sequence.wrapping_add(1),
                );
                now + 1.0 / settings.rate
            }
            Some(o) => {
                let mut newest = None;
                while let Some((_, set)) = perception.next_delivery(now - o) {
                    newest = Some(wire_set(set, &clock, o, &mut wire));
                }
                if newest.is_none() {
                    let next =
                        tokio::time::Instant::from_std(clock.instant_at(o + perception.next_at()));
                    tokio::time::sleep_until(next).await;
                    continue;
                }
                o + perception.next_at()
            }
        };
        if publisher.publish(&wire).is_err() {
            return;
        }
        tokio::time::sleep_until(tokio::time::Instant::from_std(clock.instant_at(next))).await;
    }
}

/// `set` on the wire, its times `origin` later on the daemon's clock
/// (movers are circles of unknown class).
fn wire_set(
    set: &control::live::LiveSet,
    clock: &DaemonClock,
    origin: f64,
    out: &mut LiveObstacleSet,
) {
    let stamp = clock.to_monotonic_ns(origin + set.stamp().unwrap_or(0.0));
    *out = LiveObstacleSet::empty(stamp, out.sequence.wrapping_add(1));
    for o in set.obstacles() {
        if let control::live::LiveShape::Circle { center, radius } = o.shape {
            let _ = out.push(shm_ipc::LiveObstacle::circle(
                o.id,
                shm_ipc::ObstacleClass::Unknown,
                center,
                radius,
                o.velocity,
                clock.to_monotonic_ns(origin + o.stamp),
            ));
        }
    }
}

struct Machine {
    bus: LoopbackBus,
    plant: Plant,
    clock: DaemonClock,
    config: crate::config::SimConfig,
    pose_client: Option<Client>,
    log: SimHandle,
    rx: RxTracker<VelocityCommandFrame>,
    alive: AliveCounter,
    last_command_time: f64,
    stopped_by_timeout: bool,
    pose_seq: u32,
    record: bool,
    burst_sent: u32,
    frozen_sent: u32,
}

fn in_window(t: f64, start: f64, duration: f64) -> bool {
    start >= 0.0 && t >= start && t < start + duration
}

impl Machine {
    async fn run(mut self) {
        let state_period = 1.0 / self.config.state_rate_hz;
        let pose_period = 1.0 / self.config.pose_rate_hz;
        let mut next_state = self.clock.now();
        let mut next_pose = next_state;
        loop {
            let next = if self.pose_client.is_some() {
                next_state.min(next_pose)
            } else {
                next_state
            };
            let deadline = tokio::time::Instant::from_std(self.clock.instant_at(next));
            tokio::select! {
                frame = self.bus.recv() => match frame {
                    Ok(f) => self.on_frame(&f),
                    Err(_) => break, // the daemon is gone
                },
                _ = tokio::time::sleep_until(deadline) => {
                    let now = self.clock.now();
                    self.advance(now);
                    if now >= next_state {
                        if self.send_state(now).await.is_err() {
                            break;
                        }
                        next_state += state_period;
                        if next_state < now {
                            next_state = now + state_period;
                        }
                    }
                    if self.pose_client.is_some() && now >= next_pose {
                        self.publish_pose(now);
                        next_pose += pose_period;
                        if next_pose < now {
                            next_pose = now + pose_period;
                        }
                    }
                }
            }
        }
    }

    /// Advances the physics to daemon time `now`, applying the machine-side
    /// command timeout.
    fn advance(&mut self, now: f64) {
        let dt = now - self.plant.time();
        if dt > 0.0 {
            self.plant.advance(dt);
        }
        if !self.stopped_by_timeout && now - self.last_command_time > MACHINE_COMMAND_TIMEOUT {
            self.stopped_by_timeout = true;
            let _ = self.plant.command(control::VelocityCommand::ZERO);
            self.log.with(|l| l.command_timeouts += 1);
        }
        let x = self.plant.state();
        self.log.with(|l| {
            l.time = now;
            l.true_state.copy_from_slice(x.as_slice());
        });
    }

    fn on_frame(&mut self, frame: &CanFrame) {
        if !self.rx.is_for(frame) {
            return;
        }
        let now = self.clock.now();
        self.advance(now);
        match self.rx.accept(frame) {
            Ok(cmd) => {
                let command = match cmd.mode {
                    DriveMode::Drive | DriveMode::Stop => cmd.command(),
                    DriveMode::Hold | DriveMode::Fault => control::VelocityCommand::ZERO,
                };
                // Finite by decoding; the plant saturates at the machine's bounds.
                let _ = self.plant.command(command);
                self.last_command_time = now;
                self.stopped_by_timeout = false;
                let record = self.record;
                let x = self.plant.state();
                self.log.with(|l| {
                    l.commands_received += 1;
                    if record {
                        l.commands.push(ReceivedCommand {
                            time: now,
                            command: cmd,
                            velocity: (x[control::model::ix::BETA_DOT], x[control::model::ix::V]),
                        });
                    }
                });
            }
            Err(e) => {
                tracing::debug!(target: "wlnavd::sim", "machine rejected a command frame: {e}");
                self.log.with(|l| l.rejected_commands += 1);
            }
        }
    }

    async fn send_state(&mut self, now: f64) -> Result<(), crate::can::CanError> {
        let f = self.config.faults;
        if in_window(now, f.state_dropout_at, f.state_dropout_duration) {
            return Ok(());
        }
        let x = self.plant.measure();
        let freeze = f.freeze_alive_at >= 0.0
            && now >= f.freeze_alive_at
            && self.frozen_sent < f.freeze_alive_frames;
        if freeze {
            self.frozen_sent += 1;
        } else {
            self.alive = self.alive.next();
        }
        let status = if self.stopped_by_timeout {
            MachineStatus::Ready
        } else {
            MachineStatus::Auto
        };
        let msg = MachineState {
            beta: x[ix::BETA],
            beta_dot: x[ix::BETA_DOT],
            v_f: x[ix::V],
            status,
            alive: self.alive,
        };
        let Ok(encoded) = msg.encode() else {
            return Ok(()); // non-finite state: a real ECU would send nothing either
        };
        let mut frame = encoded.frame;
        let corrupt =
            f.crc_burst_at >= 0.0 && now >= f.crc_burst_at && self.burst_sent < f.crc_burst_frames;
        if corrupt {
            self.burst_sent += 1;
            let mut data = *frame.raw_data();
            data[7] ^= 0x5A;
            frame = CanFrame::new8(frame.id(), data).unwrap_or(frame);
        }
        self.bus.send(&frame).await?;
        self.log.with(|l| {
            l.state_frames += 1;
            l.corrupted_frames += u64::from(corrupt);
            l.frozen_frames += u64::from(freeze);
        });
        Ok(())
    }

    fn publish_pose(&mut self, now: f64) {
        let f = self.config.faults;
        if in_window(now, f.pose_dropout_at, f.pose_dropout_duration) {
            return;
        }
        let Some(client) = &self.pose_client else {
            return;
        };
        let x = self.plant.measure();
        self.pose_seq = self.pose_seq.wrapping_add(1);
        let mut pose = PoseEstimate::new(
            self.clock.to_monotonic_ns(now),
            self.pose_seq,
            Pose2::new(x[ix::X], x[ix::Y], x[ix::THETA]),
        );
        pose.flags |= pose_flags::VALID;
        match client.publish_pose(&pose) {
            Ok(()) => self.log.with(|l| l.poses += 1),
            Err(e) => tracing::warn!(target: "wlnavd::sim", "cannot publish pose: {e}"),
        }
    }
}
