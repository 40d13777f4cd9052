//! Goal requests over iceoryx2: a tokio task serves `{prefix}/v2/goal`, validates
//! each request with [`shm_ipc::GoalValidator`] (finite, inside the configured
//! workspace, ≤ 8 obstacles with positive radius), hands it to the goal lifecycle in
//! [`SharedGoals`] (operator stop latch, faults, footprint check, outcomes of the goals
//! it ends; [`crate::goal_lifecycle`]), and answers at once with accept or a reason. A
//! rejected request leaves the current goal untouched.
//!
//! Stops also arrive on the reserved stop service (`{prefix}/v2/stop`, its own client
//! slots: a process holding every goal client slot cannot keep a stop out); they are
//! served first in every pass.
//!
//! Rejected requests are logged through a [`LogLimiter`]: the first 5 in each 10 s in
//! full, the rest counted and summarised in one line.
//!
//! The task sleeps on the goal and stop event services' file descriptors (tokio
//! `AsyncFd`), with a periodic pass every 50 ms as a safety net against a peer that sends
//! without notifying (a stop client whose notifiers are all taken does). Whatever woke
//! it, a pass serves the stop service first, so a stop client may wake the daemon through
//! the goal event service.

use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use shm_ipc::{DaemonEndpoint, GoalKind, GoalReply, GoalValidator, RejectCode, ValidRequest};
use tokio::io::unix::{AsyncFd, AsyncFdReadyGuard};
use tokio::sync::Notify;

use crate::goal_lifecycle::{GoalLifecycle, LifecycleSettings};
use crate::log_limit::{LogDecision, LogLimiter};
use crate::site::SiteSlot;
use control::site::Outline;

/// The goal lifecycle, shared by the IPC task (requests, answered at once) and the
/// control thread (one tick at a time), with request counters.
#[derive(Debug)]
pub struct SharedGoals {
    lifecycle: Mutex<GoalLifecycle>,
    /// The site file, and a reloaded site waiting for the next tick.
    site: SiteSlot,
    requests: AtomicU64,
    rejected: AtomicU64,
}

/// The wire form of the model's state (the control layer to the IPC layer).
pub fn wire_state(x: &control::State) -> shm_ipc::MachineState {
    shm_ipc::MachineState::from_array([x[0], x[1], x[2], x[3], x[4], x[5]])
}

impl SharedGoals {
    /// No goal yet; goals wait for the first fresh pose and machine state.
    /// `site`: the site file and the outline goals are checked with.
    pub fn new(settings: LifecycleSettings, site: SiteSlot, outline: Outline) -> Self {
        let mut lifecycle = GoalLifecycle::new(settings);
        lifecycle.set_outline(outline);
        Self {
            lifecycle: Mutex::new(lifecycle),
            site,
            requests: AtomicU64::new(0),
            rejected: AtomicU64::new(0),
        }
    }

    /// The lifecycle, locked. Held only for a request or a tick's decisions, never
    /// across I/O; a panic elsewhere does not poison it for the loop.
    pub fn lock(&self) -> MutexGuard<'_, GoalLifecycle> {
        self.lifecycle.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The site file and a reload waiting for the tick.
    pub fn site(&self) -> &SiteSlot {
        &self.site
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
    let register = |fd: RawFd, what: &str| {
        // SAFETY: the fd belongs to one of the endpoint's listeners, which `endpoint`
        // (held by this task until it returns, after the AsyncFd is dropped) keeps open.
        match unsafe { AsyncFd::register_with_interest(Fd(fd), tokio::io::Interest::READABLE) } {
            Ok(fd) => Some(fd),
            Err(e) => {
                tracing::warn!("cannot watch the {what} event fd ({e}); polling every 20 ms");
                None
            }
        }
    };
    let fd = register(endpoint.goal_event_fd(), "goal");
    let stop_fd = register(endpoint.stop_event_fd(), "stop");
    let origin = std::time::Instant::now();
    let reject_log = Mutex::new(LogLimiter::new(5, 10.0));
    let log_reject = |request_id: u64, text: &dyn std::fmt::Display| {
        let now = origin.elapsed().as_secs_f64();
        let mut limiter = reject_log.lock().unwrap_or_else(|p| p.into_inner());
        if let LogDecision::Log { suppressed } = limiter.check(now) {
            if suppressed > 0 {
                tracing::info!(
                    "goal request {request_id}: rejected: {text} ({suppressed} more rejected \
                     requests not logged)"
                );
            } else {
                tracing::info!("goal request {request_id}: rejected: {text}");
            }
        }
    };
    let serve = || {
        if let Err(e) = endpoint.drain_events() {
            tracing::warn!("goal events: {e}");
        }
        // The reserved stop path first.
        let shutting_down = stopping.load(Ordering::Relaxed);
        let result = endpoint.serve_stops(|req| {
            goals.requests.fetch_add(1, Ordering::Relaxed);
            if req.kind() == Ok(GoalKind::Stop) {
                tracing::info!("stop request {} (stop service)", req.request_id);
                // The same lifecycle path as a stop on the goal service: ends the goal
                // (cancelled) and latches until a resume.
                let stop = ValidRequest::Stop {
                    request_id: req.request_id,
                };
                match goals.lock().on_request(&stop, shutting_down) {
                    Ok(()) => GoalReply::accept(req.request_id),
                    Err(r) => {
                        goals.rejected.fetch_add(1, Ordering::Relaxed);
                        log_reject(req.request_id, &r.text);
                        GoalReply::reject(req.request_id, r.code, &r.text)
                    }
                }
            } else {
                goals.rejected.fetch_add(1, Ordering::Relaxed);
                let text = format!(
                    "the stop service takes only stop requests (kind 3), got kind {}",
                    req.kind
                );
                log_reject(req.request_id, &text);
                GoalReply::reject(req.request_id, RejectCode::UnknownKind, &text)
            }
        });
        if let Err(e) = result {
            tracing::warn!("serving stops: {e}");
        }
        let result = endpoint.serve_goals(|req| {
            goals.requests.fetch_add(1, Ordering::Relaxed);
            let (valid, reply) = validator.validate_and_reply(req);
            let decided = valid.map_err(|reason| (reason.code(), reason.to_string()));
            let decided = decided.and_then(|v| match v {
                // Read and validated here, off the tick; in force from the next tick.
                ValidRequest::ReloadSite { request_id } => match goals.site.reload(shutting_down) {
                    Ok(text) => {
                        tracing::info!("request {request_id}: {text} loaded, in force next tick");
                        Ok(v)
                    }
                    Err(e) => Err((RejectCode::Other, format!("site not reloaded: {e}"))),
                },
                _ => goals
                    .lock()
                    .on_request(&v, shutting_down)
                    .map(|()| v)
                    .map_err(|r| (r.code, r.text)),
            });
            match decided {
                Ok(v) => {
                    tracing::debug!("goal request {}: accepted {:?}", req.request_id, v);
                    reply
                }
                Err((code, text)) => {
                    goals.rejected.fetch_add(1, Ordering::Relaxed);
                    log_reject(req.request_id, &text);
                    GoalReply::reject(req.request_id, code, &text)
                }
            }
        });
        if let Err(e) = result {
            tracing::warn!("serving goals: {e}");
        }
        let now = origin.elapsed().as_secs_f64();
        let summary = reject_log
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .summary(now);
        if let Some(n) = summary {
            tracing::info!("{n} more goal requests rejected (not logged one by one)");
        }
    };
    serve();
    // The periodic pass catches requests sent without a notification: a stop client
    // finds every notifier taken (a squatting process) and sends anyway, so this bounds
    // how late such a stop is seen (shm-ipc docs: 50 ms). A pass over empty services
    // costs a few microseconds.
    let period = if fd.is_some() && stop_fd.is_some() {
        Duration::from_millis(50)
    } else {
        Duration::from_millis(20)
    };
    async fn readable(
        fd: &Option<AsyncFd<Fd>>,
    ) -> std::io::Result<Option<AsyncFdReadyGuard<'_, Fd>>> {
        match fd {
            Some(fd) => fd.readable().await.map(Some),
            None => std::future::pending().await,
        }
    }
    loop {
        tokio::select! {
            _ = stop.notified() => break,
            r = readable(&stop_fd) => {
                serve();
                if let Ok(Some(mut guard)) = r {
                    guard.clear_ready();
                }
                serve();
            }
            r = readable(&fd) => {
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
