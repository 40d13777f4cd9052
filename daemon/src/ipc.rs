//! Goal requests over iceoryx2: a tokio task serves `{prefix}/v1/goal`, validates
//! each request with [`shm_ipc::GoalValidator`] (finite, inside the configured
//! workspace, ≤ 8 obstacles with positive radius, goal not inside an obstacle),
//! answers at once with accept or a reason, and puts every valid request into the
//! [`GoalSlot`]: the newest valid request wins, an invalid one leaves the slot (the
//! previous goal) untouched.
//!
//! The task sleeps on the goal event service's file descriptor (tokio `AsyncFd`),
//! with a slow periodic pass as a safety net against a peer that sends without
//! notifying.

use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use shm_ipc::{fault_flags, DaemonEndpoint, GoalReply, GoalValidator, RejectCode, ValidRequest};
use tokio::io::unix::AsyncFd;
use tokio::sync::Notify;

/// The newest valid goal request, with a sequence number so the control thread
/// sees every change exactly once.
#[derive(Debug)]
pub struct GoalSlot {
    inner: Mutex<(u64, Option<ValidRequest>)>,
    requests: std::sync::atomic::AtomicU64,
    rejected: std::sync::atomic::AtomicU64,
    blocking_faults: AtomicU32,
}

impl Default for GoalSlot {
    fn default() -> Self {
        Self {
            inner: Mutex::default(),
            requests: Default::default(),
            rejected: Default::default(),
            // Until the first tick has seen fresh data.
            blocking_faults: AtomicU32::new(
                fault_flags::POSE_STALE | fault_flags::MACHINE_STATE_STALE,
            ),
        }
    }
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

impl GoalSlot {
    /// Faults that keep the daemon from accepting goals (set by the control loop
    /// every tick; 0 = goals welcome).
    pub fn set_blocking_faults(&self, flags: u32) {
        self.blocking_faults.store(flags, Ordering::Relaxed);
    }

    /// Stores `req` as the newest.
    pub fn put(&self, req: ValidRequest) {
        let mut g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        g.0 += 1;
        g.1 = Some(req);
    }

    /// The newest request if its sequence number is past `seen`.
    pub fn take_newer(&self, seen: &mut u64) -> Option<ValidRequest> {
        let g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        if g.0 > *seen {
            *seen = g.0;
            g.1.clone()
        } else {
            None
        }
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
    slot: Arc<GoalSlot>,
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
        let blocking = slot.blocking_faults.load(Ordering::Relaxed);
        let result = endpoint.serve_goals(|req| {
            slot.requests.fetch_add(1, Ordering::Relaxed);
            let (valid, reply) = validator.validate_and_reply(req);
            match valid {
                Ok(ValidRequest::SetGoal { .. }) if shutting_down => {
                    slot.rejected.fetch_add(1, Ordering::Relaxed);
                    GoalReply::reject(
                        req.request_id,
                        RejectCode::NotReady,
                        "daemon is shutting down",
                    )
                }
                Ok(ValidRequest::SetGoal { .. }) if blocking != 0 => {
                    slot.rejected.fetch_add(1, Ordering::Relaxed);
                    let text = format!("fault active: {}", fault_names(blocking));
                    tracing::info!("goal request {}: rejected: {text}", req.request_id);
                    GoalReply::reject(req.request_id, RejectCode::NotReady, &text)
                }
                Ok(v) => {
                    tracing::debug!("goal request {}: accepted {:?}", req.request_id, v);
                    slot.put(v);
                    reply
                }
                Err(reason) => {
                    slot.rejected.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("goal request {}: rejected: {reason}", req.request_id);
                    reply
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
