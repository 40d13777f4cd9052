//! The CAN I/O task: receives machine-state frames (integrity-checked by an
//! [`RxTracker`]) into a shared snapshot the control thread reads each tick, and
//! sends the velocity commands the control thread hands it, each through the
//! last-line [`CommandGuard`].
//!
//! The task ends when the control thread drops its command sender, after sending
//! every command still queued: so the last frame on the bus is the last command
//! the loop produced (a stop, on shutdown).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use control::{MachineParams, VelocityCommand};
use tokio::sync::mpsc;

use crate::can::{
    AliveCounter, CanBus, DriveMode, MachineState, RxCounters, RxError, RxTracker,
    VelocityCommandFrame,
};
use crate::clock::DaemonClock;

/// A command from the control thread: velocities and mode (alive counter and CRC
/// are added by the I/O task).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutCommand {
    /// (β̇_cmd, v_cmd).
    pub command: VelocityCommand,
    /// Mode signal.
    pub mode: DriveMode,
}

/// Which integrity check rejected the latest bad frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectKind {
    /// CRC, length or range.
    Integrity,
    /// Alive counter frozen or skipping.
    Alive,
}

/// What the control thread reads from the CAN side.
#[derive(Debug, Clone, Default)]
pub struct CanSnapshot {
    /// The newest accepted machine state and its daemon receive time [s].
    pub latest: Option<(MachineState, f64)>,
    /// Totals of the receive checks.
    pub counters: RxCounters,
    /// Cause of the newest rejection.
    pub last_reject: Option<RejectKind>,
    /// Send or receive errors of the bus.
    pub io_errors: u64,
    /// The bus is gone.
    pub closed: bool,
}

/// Shared between the I/O task and the control thread.
#[derive(Debug, Default)]
pub struct CanShared {
    snapshot: Mutex<CanSnapshot>,
    sent: AtomicU64,
    clamped: AtomicU64,
}

impl CanShared {
    /// A copy of the current snapshot.
    pub fn snapshot(&self) -> CanSnapshot {
        self.snapshot
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Command frames sent.
    pub fn sent(&self) -> u64 {
        self.sent.load(Ordering::Relaxed)
    }

    /// Commands the guard had to clamp or replace (should stay 0).
    pub fn clamped(&self) -> u64 {
        self.clamped.load(Ordering::Relaxed)
    }

    fn with<R>(&self, f: impl FnOnce(&mut CanSnapshot) -> R) -> R {
        f(&mut self.snapshot.lock().unwrap_or_else(|p| p.into_inner()))
    }
}

/// The last check before a command leaves the daemon: finite, and inside the
/// configured velocity bounds, whatever happened upstream. The loop sends limited
/// commands ([`VelocityCommand::limited`]); a command this guard has to change
/// is a bug, counted and logged as an error (a non-finite one becomes a fault
/// stop).
#[derive(Debug, Clone, Copy)]
pub struct CommandGuard {
    params: MachineParams,
}

impl CommandGuard {
    /// Bounds from the machine parameters.
    pub fn new(p: &MachineParams) -> Self {
        Self { params: *p }
    }

    /// The command made safe, and whether it had to be changed.
    pub fn apply(&self, c: OutCommand) -> (OutCommand, bool) {
        if !c.command.is_finite() {
            let stop = OutCommand {
                command: VelocityCommand::ZERO,
                mode: DriveMode::Fault,
            };
            return (stop, true);
        }
        let command = c.command.limited(&self.params);
        (OutCommand { command, ..c }, command != c.command)
    }
}

/// Runs the I/O task until the command channel closes (or the bus closes).
pub async fn run(
    mut bus: Box<dyn CanBus>,
    mut commands: mpsc::Receiver<OutCommand>,
    shared: Arc<CanShared>,
    clock: DaemonClock,
    guard: CommandGuard,
    max_lost: u8,
) {
    let mut rx = RxTracker::<MachineState>::new(max_lost);
    let mut alive = AliveCounter::ZERO;
    let mut bus_open = true;
    loop {
        tokio::select! {
            biased;
            cmd = commands.recv() => {
                let Some(cmd) = cmd else { break };
                let (cmd, changed) = guard.apply(cmd);
                if changed {
                    shared.clamped.fetch_add(1, Ordering::Relaxed);
                    tracing::error!("command guard changed a command: {cmd:?}");
                }
                let frame = VelocityCommandFrame::new(cmd.command, cmd.mode, alive).encode();
                alive = alive.next();
                match frame {
                    Ok(enc) => match bus.send(&enc.frame).await {
                        Ok(()) => {
                            shared.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => {
                            shared.with(|s| s.io_errors += 1);
                            tracing::warn!("CAN send failed: {e}");
                        }
                    },
                    Err(e) => tracing::error!("cannot encode command: {e}"),
                }
            }
            frame = bus.recv(), if bus_open => match frame {
                Ok(frame) => {
                    if !rx.is_for(&frame) {
                        continue;
                    }
                    let now = clock.now();
                    let result = rx.accept(&frame);
                    let counters = *rx.counters();
                    shared.with(|s| {
                        s.counters = counters;
                        match result {
                            Ok(state) => s.latest = Some((state, now)),
                            Err(RxError::Decode(_)) => s.last_reject = Some(RejectKind::Integrity),
                            Err(RxError::Alive { .. }) => s.last_reject = Some(RejectKind::Alive),
                        }
                    });
                }
                Err(crate::can::CanError::Closed { .. }) => {
                    bus_open = false;
                    shared.with(|s| s.closed = true);
                    tracing::error!("CAN bus closed");
                }
                Err(e) => {
                    shared.with(|s| s.io_errors += 1);
                    tracing::warn!("CAN receive failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guard_clamps_and_replaces_non_finite() {
        let p = MachineParams::default();
        let g = CommandGuard::new(&p);
        let out = |beta_dot, v| OutCommand {
            command: VelocityCommand { beta_dot, v },
            mode: DriveMode::Drive,
        };
        let (c, changed) = g.apply(out(10.0, -5.0));
        assert!(changed);
        assert_eq!(
            c.command,
            VelocityCommand {
                beta_dot: p.beta_dot_max,
                v: -p.v_max
            }
        );
        let (c, changed) = g.apply(out(f64::NAN, 0.1));
        assert!(changed);
        assert_eq!(
            (c.command, c.mode),
            (VelocityCommand::ZERO, DriveMode::Fault)
        );
        let ok = out(0.1, 0.5);
        assert_eq!(g.apply(ok), (ok, false));
    }
}
