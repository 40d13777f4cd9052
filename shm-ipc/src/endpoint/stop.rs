//! The reserved stop path ([`StopClient`]): a stop gets through whatever other local
//! processes hold (DESIGN §11, §14).

use core::time::Duration;
use std::time::Instant;

use iceoryx2::node::Node;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::service::port_factory::event;

use super::client::{try_reply, wait_reply};
use super::events::notify;
use super::services::{client_port, event_service, goal_service, make_node, Access, Connection};
use super::{boxed, event_ids, GoalFactory, GoalPending, IpcService};
use crate::config::{IpcConfig, ServiceNames};
use crate::error::{ClientError, IpcError};
use crate::msg::{GoalReply, GoalRequest};

/// Which service carried a stop ([`StopReport::path`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopPath {
    /// The reserved stop service `{prefix}/v2/stop` (the normal path).
    StopService,
    /// The goal service `{prefix}/v2/goal` (request kind 3): the fallback when the stop
    /// service has no free client slot (or cannot be opened at all).
    GoalService,
}

/// How a stop was sent and answered ([`StopClient::stop_report`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StopReport {
    /// The daemon's reply.
    pub reply: GoalReply,
    /// The service that carried it.
    pub path: StopPath,
    /// True if the daemon was woken by a notification; false if the request went without
    /// one (no free notifier anywhere), to be picked up by the daemon's periodic pass
    /// (every 50 ms).
    pub notified: bool,
    /// True if the reply was awaited on a listener; false if it was polled for (every
    /// 2 ms) because no listener was free.
    pub listened: bool,
    /// What did not work on the way, in order (the stop service's slots taken, no free
    /// notifier, …), each naming the holders; empty when the first path worked.
    pub detours: Vec<String>,
}

/// A stop attempt on one service that failed: before the request left (try the next
/// path) or after (it may have arrived; report).
pub(super) enum Attempt {
    NotSent(ClientError),
    Sent(ClientError),
}

/// How often a reply is polled for when no listener could be created.
const REPLY_POLL: Duration = Duration::from_millis(2);

/// The reserved stop path (DESIGN §11, §14: "a stop must get through whatever other local
/// processes hold").
///
/// Stops travel on their own request-response service, `{prefix}/v2/stop` (payloads as on
/// the goal service; only kind 3 is accepted there), with its own client slots and paired
/// event service. Neither [`Client::new`] nor anything else holds a port there: a
/// `StopClient` opens only the stop services (not the goal, pose or telemetry ones, whose
/// node and client limits another process may exhaust) and creates its ports per
/// [`StopClient::stop`] call, releasing them with the reply.
///
/// What another local process can hold, and what a stop then does:
///
/// * **All 16 client slots of the stop service** (or its 64 node slots): the stop goes
///   to the goal service instead, as request kind 3 (the daemon handles a stop there
///   the same way). Only a process that holds every client slot of *both* services
///   (16 + 32) keeps it out; the error then names the holders of both.
/// * **All 64 notifiers of the stop event service**: the request is sent anyway, and
///   the daemon is woken through the goal event service's notifier (its request loop
///   serves stops first, whatever woke it); with no notifier free there either, the
///   request goes without a notification and the daemon's periodic pass (every 50 ms)
///   picks it up.
/// * **All 64 listeners**: the reply is polled for every 2 ms instead of awaited.
///
/// [`StopClient::stop_report`] says which path was taken and why. A stop on either
/// service latches the same way: set-goals are rejected until a resume
/// ([`Client::resume`], on the goal service).
///
/// [`Client::new`]: crate::Client::new
/// [`Client::resume`]: crate::Client::resume
pub struct StopClient {
    node: Node<IpcService>,
    names: ServiceNames,
    service: String,
    /// The stop service and its event service; the reason when they could not be opened
    /// (then every stop takes the goal service).
    stop: Result<(GoalFactory, event::PortFactory<IpcService>), StopUnavailable>,
}

/// Why [`StopClient::new`] could not open the stop service (kept to report it per stop).
#[derive(Debug, Clone)]
enum StopUnavailable {
    /// It does not exist (a daemon without it, or one that has gone).
    NotServed,
    /// Anything else (e.g. its node limit), as text.
    Other(String),
}

impl StopUnavailable {
    fn error(&self, service: &str, pattern: &'static str) -> IpcError {
        match self {
            Self::NotServed => IpcError::NotServed {
                service: service.to_owned(),
            },
            Self::Other(why) => IpcError::Service {
                service: service.to_owned(),
                pattern,
                source: why.clone().into(),
            },
        }
    }
}

impl core::fmt::Debug for StopClient {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("StopClient")
            .field("service", &self.service)
            .field("stop_service_open", &self.stop.is_ok())
            .finish_non_exhaustive()
    }
}

impl StopClient {
    /// Opens the stop service of `config.prefix` (never creates it): [`IpcError::NotServed`]
    /// without a daemon. If the stop service cannot be opened (its node limit reached) but
    /// the goal service can, the client is created and stops take the goal service.
    pub fn new(config: &IpcConfig) -> Result<Self, IpcError> {
        let names = config.service_names()?;
        let (node, _) = make_node(config, "wlnav-stop")?;
        let stop = goal_service(&node, &names.stop, 0, 0, Access::Open).and_then(|factory| {
            event_service(&node, &names.stop, Access::Open).map(|event| (factory, event))
        });
        let stop = match stop {
            Ok(s) => Ok(s),
            Err(e) => {
                // Without a daemon the goal service is missing too: NotServed, as before.
                goal_service(&node, &names.goal, 0, 0, Access::Open)?;
                Err(match e {
                    IpcError::NotServed { .. } => StopUnavailable::NotServed,
                    other => StopUnavailable::Other(other.to_string()),
                })
            }
        };
        Ok(Self {
            node,
            service: names.stop.clone(),
            names,
            stop,
        })
    }

    /// Sends a stop request and waits up to `timeout` for the daemon's reply.
    pub fn stop(&self, timeout: Duration) -> Result<GoalReply, ClientError> {
        self.stop_with_id(crate::monotonic_now_ns().max(1), timeout)
    }

    /// [`StopClient::stop`] with a chosen request id.
    pub fn stop_with_id(
        &self,
        request_id: u64,
        timeout: Duration,
    ) -> Result<GoalReply, ClientError> {
        self.stop_report(request_id, timeout).map(|r| r.reply)
    }

    /// [`StopClient::stop_with_id`], saying which path the stop took and what failed on
    /// the way (see the type's docs).
    pub fn stop_report(
        &self,
        request_id: u64,
        timeout: Duration,
    ) -> Result<StopReport, ClientError> {
        let deadline = Instant::now() + timeout;
        let mut detours = Vec::new();
        let stop_error = match self.via_stop_service(request_id, deadline, &mut detours) {
            Ok(report) => return Ok(report),
            Err(Attempt::Sent(e)) => return Err(e),
            Err(Attempt::NotSent(e)) => e,
        };
        detours.push(format!(
            "stop service {:?}: {stop_error}; sending the stop on the goal service {:?}",
            self.names.stop, self.names.goal
        ));
        match self.via_goal_service(request_id, deadline, &mut detours) {
            Ok(report) => Ok(report),
            Err(Attempt::Sent(e)) => Err(e),
            Err(Attempt::NotSent(goal)) => Err(ClientError::StopNotSent {
                stop: Box::new(stop_error),
                goal: Box::new(goal),
            }),
        }
    }

    /// The stop on the reserved stop service (woken through the goal event service when
    /// the stop event service has no free notifier).
    pub(super) fn via_stop_service(
        &self,
        request_id: u64,
        deadline: Instant,
        detours: &mut Vec<String>,
    ) -> Result<StopReport, Attempt> {
        let (factory, event) = match &self.stop {
            Ok(s) => s,
            Err(why) => {
                return Err(Attempt::NotSent(
                    why.error(&self.names.stop, "request-response").into(),
                ))
            }
        };
        let alt = || {
            event_service(&self.node, &self.names.goal, Access::Open)
                .and_then(|e| Connection::notifier(&e, &self.names.goal))
                .map(|n| (n, self.names.goal.clone()))
        };
        send_stop(
            factory,
            event,
            &self.names.stop,
            event_ids::STOP_REQUEST,
            &alt,
            request_id,
            deadline,
            detours,
        )
        .map(|(reply, notified, listened)| StopReport {
            reply,
            path: StopPath::StopService,
            notified,
            listened,
            detours: std::mem::take(detours),
        })
    }

    /// The fallback: the stop (kind 3) on the goal service (woken through the stop event
    /// service when the goal event service has no free notifier).
    fn via_goal_service(
        &self,
        request_id: u64,
        deadline: Instant,
        detours: &mut Vec<String>,
    ) -> Result<StopReport, Attempt> {
        let goal = &self.names.goal;
        let factory = goal_service(&self.node, goal, 0, 0, Access::Open)
            .map_err(|e| Attempt::NotSent(e.into()))?;
        let event = event_service(&self.node, goal, Access::Open)
            .map_err(|e| Attempt::NotSent(e.into()))?;
        let alt = || match &self.stop {
            Ok((_, e)) => {
                Connection::notifier(e, &self.names.stop).map(|n| (n, self.names.stop.clone()))
            }
            Err(why) => Err(why.error(&self.names.stop, "event")),
        };
        send_stop(
            &factory,
            &event,
            goal,
            event_ids::GOAL_REQUEST,
            &alt,
            request_id,
            deadline,
            detours,
        )
        .map(|(reply, notified, listened)| StopReport {
            reply,
            path: StopPath::GoalService,
            notified,
            listened,
            detours: std::mem::take(detours),
        })
    }
}

/// Sends a stop request on `factory` (service `service`) with ports made for this request
/// only, wakes the daemon (on `event`, else through `alt`'s notifier, else not at all) and
/// waits until `deadline` for the reply (on a listener, else polling). Returns the reply,
/// whether the daemon was notified and whether a listener was used.
#[allow(clippy::too_many_arguments)]
fn send_stop(
    factory: &GoalFactory,
    event: &event::PortFactory<IpcService>,
    service: &str,
    event_id: usize,
    alt: &dyn Fn() -> Result<(Notifier<IpcService>, String), IpcError>,
    request_id: u64,
    deadline: Instant,
    detours: &mut Vec<String>,
) -> Result<(GoalReply, bool, bool), Attempt> {
    let client = client_port(factory, service).map_err(|e| Attempt::NotSent(e.into()))?;
    // The listener before sending, so the reply's notification cannot be missed.
    let listener = match Connection::listener(event, service) {
        Ok(l) => Some(l),
        Err(e) => {
            detours.push(format!("{e}; polling for the reply"));
            None
        }
    };
    let pending = client
        .send_copy(GoalRequest::stop(request_id))
        .map_err(|e| {
            Attempt::NotSent(
                IpcError::Send {
                    service: service.to_owned(),
                    source: boxed(e),
                }
                .into(),
            )
        })?;
    if pending.number_of_server_connections() == 0 {
        return Err(Attempt::NotSent(ClientError::NoDaemon {
            service: service.to_owned(),
        }));
    }
    // A notification is only a wake-up: without one the daemon still finds the request.
    let notified =
        match Connection::notifier(event, service).and_then(|n| notify(&n, event_id, service)) {
            Ok(()) => true,
            Err(e) => match alt().and_then(|(n, alt_service)| {
                notify(&n, event_id, &alt_service).map(|()| alt_service)
            }) {
                Ok(alt_service) => {
                    detours.push(format!("{e}; woke the daemon through {alt_service:?}"));
                    true
                }
                Err(e2) => {
                    detours.push(format!(
                        "{e}; {e2}; sent without a notification (the daemon's periodic pass \
                     picks it up)"
                    ));
                    false
                }
            },
        };
    let service_name = service.to_owned();
    let reply = match &listener {
        Some(l) => wait_reply(
            &pending,
            request_id,
            l,
            &service_name,
            deadline.saturating_duration_since(Instant::now()),
        ),
        None => poll_reply(&pending, request_id, &service_name, deadline),
    };
    match reply {
        Ok(r) => Ok((r, notified, listener.is_some())),
        // Dropped unanswered (e.g. the daemon's request buffer overflowed): a repeated
        // stop is harmless, so the next path may try.
        Err(e @ ClientError::Dropped { .. }) => Err(Attempt::NotSent(e)),
        Err(e) => Err(Attempt::Sent(e)),
    }
}

/// Waits until `deadline` for the reply to `pending` without a listener: polls every
/// [`REPLY_POLL`] (only when no listener slot is free).
fn poll_reply(
    pending: &GoalPending,
    request_id: u64,
    service: &str,
    deadline: Instant,
) -> Result<GoalReply, ClientError> {
    let start = Instant::now();
    loop {
        if let Some(reply) = try_reply(pending, request_id, service)? {
            return Ok(reply);
        }
        if !pending.is_connected() {
            return match try_reply(pending, request_id, service)? {
                Some(reply) => Ok(reply),
                None => Err(ClientError::Dropped { request_id }),
            };
        }
        let now = Instant::now();
        if now >= deadline {
            return Err(ClientError::Timeout {
                request_id,
                timeout: deadline.saturating_duration_since(start),
            });
        }
        std::thread::sleep(REPLY_POLL.min(deadline - now));
    }
}
