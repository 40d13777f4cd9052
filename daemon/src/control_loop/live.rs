//! The control thread's part of live obstacles (DESIGN §18): it waits for its
//! next tick on the obstacles' event, takes each set as it arrives (validated,
//! converted at the edge) and sends a stop or slow-down it calls for at once;
//! and the telemetry bits of a step's live status.

use std::time::Instant;

use control::delay::compensate_pose_age;
use control::pilot::LiveStatus;
use control::State;
use shm_ipc::fault_flags;

use super::ControlLoop;
use crate::can::DriveMode;
use crate::live_input;
use crate::log_limit::LogDecision;

/// Between ticks, live-obstacle sets are taken at most this often: a flood
/// (10,000 sets a second) costs the thread a few per cent, and an
/// obstacle's stop still leaves within this of its set's arrival.
pub const MIN_LIVE_SPACING: std::time::Duration = std::time::Duration::from_millis(5);

impl ControlLoop {
    /// Waits for the tick at daemon time `deadline`, taking live-obstacle sets
    /// as they arrive (DESIGN §18): a stop a set calls for leaves then, not at
    /// the tick. At most one set per [`MIN_LIVE_SPACING`].
    pub(super) fn wait_for_tick(&mut self, deadline: f64) {
        let target = self.ctx.clock.instant_at(deadline);
        let fd = self.ctx.endpoint.obstacles_event_fd();
        loop {
            let now = Instant::now();
            if now >= target {
                return;
            }
            if let Some(next) = self.live_taken_at.map(|at| at + MIN_LIVE_SPACING) {
                if next > now {
                    std::thread::sleep(next.min(target) - now);
                    continue;
                }
            }
            if readable(fd, target - now) {
                self.take_live(true);
            }
        }
    }

    /// Takes the newest live-obstacle set, if one came: validated (a rejected
    /// set is counted and named, the one before it stays and ages), converted
    /// and handed to the controller; with `check`, between ticks while a goal
    /// is driven, the command last sent is checked against it and a stop it
    /// calls for is sent at once.
    pub(super) fn take_live(&mut self, check: bool) {
        self.live_taken_at = Some(Instant::now());
        let endpoint = &self.ctx.endpoint;
        if let Err(e) = endpoint.drain_obstacle_events() {
            tracing::warn!("live obstacles: {e}");
        }
        let wire = match endpoint.latest_obstacles() {
            Ok(Some(set)) => set,
            Ok(None) => return,
            Err(e) => {
                tracing::warn!("live obstacles: {e}");
                return;
            }
        };
        let now = self.ctx.clock.now();
        let refused = match self
            .live_validator
            .validate(&wire, shm_ipc::monotonic_now_ns())
        {
            Err(why) => Some(why.to_string()),
            Ok(()) => live_input::convert(&wire, &self.ctx.clock, &mut self.live)
                .err()
                .map(|(i, id, e)| format!("obstacle {i} (id {id}): {e}")),
        };
        if let Some(why) = refused {
            self.live_rejected = true;
            if let LogDecision::Log { .. } = self.live_log.check(now) {
                tracing::warn!("live-obstacle set {} rejected: {why}", wire.sequence);
            }
            return;
        }
        self.controller.set_live(&self.live);
        if !check || self.engaged_generation.is_none() {
            return;
        }
        let Some(x) = self.measured(now) else {
            return;
        };
        if let Some(g) = self.controller.check_live(&x, now) {
            let mut flags = 0;
            self.send(now, g.command, DriveMode::Drive, &mut flags);
            let stop = g.overridden();
            {
                let stats = &mut self.ctx.stats.lock().unwrap_or_else(|p| p.into_inner());
                if stop {
                    stats.protective_stops += 1;
                } else {
                    stats.arrival_slowdowns += 1;
                }
            }
            if let (true, LogDecision::Log { .. }) = (stop, self.live_log.check(now)) {
                tracing::warn!(
                    "protective stop: live obstacle {} ({:+.2} m from its stop field)",
                    g.live.map_or(0, |c| c.id),
                    g.live.map_or(f64::NAN, |c| c.excess),
                );
            }
        }
    }

    /// The measured state at `now` between ticks: the gate's fresh pose
    /// (carried over its age) with the fresh machine state.
    fn measured(&self, now: f64) -> Option<State> {
        let can = self.ctx.can.snapshot();
        let pose = self.pose_gate.fresh(now)?;
        let machine = self.state_fresh(&can, now)?;
        let age = self.pose_gate.last().map_or(0.0, |(_, t)| now - t);
        Some(compensate_pose_age(
            &self.params,
            &machine.with_pose(&pose),
            age,
        ))
    }
}

/// Whether `fd` becomes readable within `timeout`.
fn readable(fd: std::os::fd::RawFd, timeout: std::time::Duration) -> bool {
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask.
    let n = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    n > 0 && pfd.revents & libc::POLLIN != 0
}

/// The telemetry bits of a step's live status (DESIGN §18).
pub(super) fn live_flags(l: LiveStatus) -> u32 {
    let mut flags = 0;
    if l.stale_stop {
        flags |= fault_flags::PERCEPTION_STALE;
    }
    if l.holding {
        flags |= fault_flags::PROTECTIVE_STOP;
    }
    if l.slow < 1.0 {
        flags |= fault_flags::LIVE_SLOWING;
    }
    if l.contact.is_some() {
        flags |= fault_flags::LIVE_NEAR;
    }
    flags
}
