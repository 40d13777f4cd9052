//! Goal requests over iceoryx2: a tokio task serves `{prefix}/v2/goal`, validates
//! each request with [`shm_ipc::GoalValidator`] (finite, inside the configured
//! workspace, ≤ 8 obstacles with positive radius), hands it to the goal lifecycle in
//! [`SharedGoals`] (operator stop latch, faults, footprint check, outcomes of the goals
//! it ends; [`crate::goal_lifecycle`]), and answers at once with accept or a reason. A
//! rejected request leaves the current goal untouched.
//!
//! The task sleeps on the goal event service's file descriptor (tokio `AsyncFd`),
//! with a slow periodic pass as a safety net against a peer that sends without
//! notifying.

use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use shm_ipc::{fault_flags, DaemonEndpoint, GoalReply, GoalValidator};
use tokio::io::unix::AsyncFd;
use tokio::sync::Notify;

use crate::goal_lifecycle::{GoalLifecycle, LifecycleSettings};

/// The goal lifecycle, shared by the IPC task (requests, answered at once) and the
/// control thread (one tick at a time), with request counters.
#[derive(Debug)]
pub struct SharedGoals {
    lifecycle: Mutex<GoalLifecycle>,
    requests: AtomicU64,
    rejected: AtomicU64,
}

/// Names of the fault bits, for reject reasons and logs.
pub fn fault_names(flags: u32) -> String {
    const NAMES: [(u32, &str); 9] = [
        (fault_flags::POSE_STALE, "pose stale"),
        (fault_flags::MACHINE_STATE_STALE, "machine state stale"),
        (fault_flags::CAN_CRC, "CAN CRC"),
        (fault_flags::CAN_ALIVE, "CAN alive counter"),
        (fault_flags::SOLVE_FAILED, "solve failed"),
        (fault_flags::FALLBACK_PLAN, "fallback plan"),
        (fault_flags::OVERRUN, "overrun"),
        (fault_flags::STOP_REQUESTED, "stop requested"),
        (fault_flags::CAN_BUS, "CAN bus"),
    ];
    let names: Vec<&str> = NAMES
        .iter()
        .filter(|(bit, _)| flags & bit != 0)
        .map(|(_, n)| *n)
        .collect();
    names.join(", ")
}

impl SharedGoals {
    /// No goal yet; goals wait for the first fresh pose and machine state.
    pub fn new(settings: LifecycleSettings) -> Self {
        Self {
            lifecycle: Mutex::new(GoalLifecycle::new(settings)),
            requests: AtomicU64::new(0),
            rejected: AtomicU64::new(0),
        }
    }

    /// The lifecycle, locked. Held only for a request or a tick's decisions, never
    /// across I/O; a panic elsewhere does not poison it for the loop.
    pub fn lock(&self) -> MutexGuard<'_, GoalLifecycle> {
        self.lifecycle.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Requests served (accepted + rejected).
    pub fn requests(&self) -> u64 {
        self.requests.load(Ordering::Relaxed)
    }

    /// Requests rejected.
    pub fn rejected(&self) -> u64 {
        self.rejected.load(Ordering::Relaxed)
    }
}

struct Fd(RawFd);

impl AsRawFd for Fd {
    fn as_raw_fd(&self) -> RawFd {
        self.0
    }
}

/// Serves goal requests until `stop` is notified (or `stopping` is set).
pub async fn serve_goals(
    endpoint: Arc<DaemonEndpoint>,
    validator: GoalValidator,
    goals: Arc<SharedGoals>,
    stopping: Arc<AtomicBool>,
    stop: Arc<Notify>,
) {
    // SAFETY: the fd belongs to the endpoint's goal listener, which `endpoint` (held
    // by this task until it returns, after the AsyncFd is dropped) keeps open.
    let registered = unsafe {
        AsyncFd::register_with_interest(Fd(endpoint.goal_event_fd()), tokio::io::Interest::READABLE)
    };
    let fd = match registered {
        Ok(fd) => Some(fd),
        Err(e) => {
            tracing::warn!("cannot watch the goal event fd ({e}); polling every 20 ms");
            None
        }
    };
    let serve = || {
        if let Err(e) = endpoint.drain_events() {
            tracing::warn!("goal events: {e}");
        }
        let shutting_down = stopping.load(Ordering::Relaxed);
        let result = endpoint.serve_goals(|req| {
            goals.requests.fetch_add(1, Ordering::Relaxed);
            let (valid, reply) = validator.validate_and_reply(req);
            let decided = valid.map_err(|reason| (reason.code(), reason.to_string()));
            let decided = decided.and_then(|v| {
                goals
                    .lock()
                    .on_request(&v, shutting_down)
                    .map(|()| v)
                    .map_err(|r| (r.code, r.text))
            });
            match decided {
                Ok(v) => {
                    tracing::debug!("goal request {}: accepted {:?}", req.request_id, v);
                    reply
                }
                Err((code, text)) => {
                    goals.rejected.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("goal request {}: rejected: {text}", req.request_id);
                    GoalReply::reject(req.request_id, code, &text)
                }
            }
        });
        if let Err(e) = result {
            tracing::warn!("serving goals: {e}");
        }
    };
    serve();
    let period = if fd.is_some() {
        Duration::from_millis(200)
    } else {
        Duration::from_millis(20)
    };
    loop {
        tokio::select! {
            _ = stop.notified() => break,
            r = async {
                match &fd {
                    Some(fd) => fd.readable().await.map(Some),
                    None => std::future::pending().await,
                }
            } => {
                serve();
                if let Ok(Some(mut guard)) = r {
                    guard.clear_ready();
                }
                // Requests that arrived while clearing are caught by this pass.
                serve();
            }
            _ = tokio::time::sleep(period) => serve(),
        }
    }
}
