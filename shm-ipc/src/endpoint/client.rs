//! The client's side: [`Client`] sends goals, cancels, stops and resumes, publishes poses
//! (and, through [`Client::obstacle_publisher`], live obstacles) and subscribes to
//! telemetry ([`TelemetrySubscriber`]); [`PendingGoal`] awaits a reply.

use core::time::Duration;
use std::os::fd::RawFd;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;

use super::events::{drain, listener_fd, notify, wait_error};
use super::obstacles::ObstaclePublisher;
use super::services::{client_port, single_publisher, Access, CleanupReport, Connection};
use super::stop::{Attempt, StopClient, StopPath, StopReport};
use super::{
    boxed, event_ids, newest, qos, receive_copy, wait_for_daemon, GoalClient, GoalPending,
    IpcService, PosePublisher,
};
use crate::config::{IpcConfig, ServiceNames};
use crate::error::{ClientError, IpcError};
use crate::msg::{GoalReply, GoalRequest, Obstacle, Pose2, PoseEstimate, Telemetry};

/// The client's side: sends goals, cancels, stops, resumes; publishes poses; subscribes
/// to telemetry.
pub struct Client {
    conn: Connection,
    client: GoalClient,
    goal_notifier: Notifier<IpcService>,
    goal_listener: Listener<IpcService>,
    /// Created on first [`Client::publish_pose`], so read-only clients take no publisher slot.
    pose_pub: std::sync::Mutex<Option<PosePublisher>>,
    next_id: AtomicU64,
    /// For the stop path ([`Client::stop`] opens a [`StopClient`] per stop).
    config: IpcConfig,
}

impl core::fmt::Debug for Client {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Client")
            .field("services", &self.conn.names)
            .finish_non_exhaustive()
    }
}

impl Client {
    /// Opens the services the daemon created for `config.prefix` (a client never creates
    /// a service). Fails with [`IpcError::NotServed`] when no daemon has created them
    /// (not started yet, or another prefix); see [`Client::connect`] to wait for one. The
    /// goal client port is taken here (one of 32 slots); [`Client::stop`] does not need
    /// it.
    pub fn new(config: &IpcConfig) -> Result<Self, IpcError> {
        let conn = Connection::open(config, "wlnav-client", Access::Open)?;
        let names = &conn.names;
        let client = client_port(&conn.goal, &names.goal)?;
        let goal_notifier = Connection::notifier(&conn.goal_event, &names.goal)?;
        let goal_listener = Connection::listener(&conn.goal_event, &names.goal)?;
        // Ids start at the monotonic clock so two clients (or two runs) are unlikely to
        // reuse an id the daemon reports in telemetry.
        let start = crate::monotonic_now_ns().max(1);
        Ok(Self {
            conn,
            client,
            goal_notifier,
            goal_listener,
            pose_pub: std::sync::Mutex::new(None),
            next_id: AtomicU64::new(start),
            config: IpcConfig {
                cleanup_stale_nodes: false,
                ..config.clone()
            },
        })
    }

    /// Like [`Client::new`], but waits up to `timeout` for a daemon to create the services
    /// (polling every 20 ms); other errors return at once.
    pub fn connect(config: &IpcConfig, timeout: Duration) -> Result<Self, IpcError> {
        wait_for_daemon(config, timeout, Self::new)
    }

    /// The service names in use.
    pub fn service_names(&self) -> &ServiceNames {
        &self.conn.names
    }

    /// What the start-up stale-node clean-up did.
    pub fn cleanup_report(&self) -> CleanupReport {
        self.conn.cleanup
    }

    /// A fresh request id (unique within this client, never 0).
    pub fn next_request_id(&self) -> u64 {
        self.next_id.fetch_add(1, Ordering::Relaxed)
    }

    /// Sends `request` as is (the caller chose its `request_id`) and returns a handle to
    /// await the reply. Dropping the handle abandons the reply and frees the slot (at most
    /// 16 requests in flight per client).
    pub fn submit(&self, request: &GoalRequest) -> Result<PendingGoal<'_>, ClientError> {
        let service = &self.conn.names.goal;
        let pending = self
            .client
            .send_copy(*request)
            .map_err(|e| IpcError::Send {
                service: service.clone(),
                source: boxed(e),
            })?;
        if pending.number_of_server_connections() == 0 {
            return Err(ClientError::NoDaemon {
                service: service.clone(),
            });
        }
        notify(&self.goal_notifier, event_ids::GOAL_REQUEST, service)?;
        Ok(PendingGoal {
            pending,
            request_id: request.request_id,
            client: self,
        })
    }

    /// Sends `request` and waits up to `timeout` for the reply. A rejection is a successful
    /// call: inspect [`GoalReply::is_accepted`], [`GoalReply::reject_code`] and
    /// [`GoalReply::reason_text`].
    pub fn request(
        &self,
        request: &GoalRequest,
        timeout: Duration,
    ) -> Result<GoalReply, ClientError> {
        self.submit(request)?.wait(timeout)
    }

    /// Asks the daemon to drive to `goal` around `obstacles` (≤ 8).
    pub fn set_goal(
        &self,
        goal: Pose2,
        obstacles: &[Obstacle],
        timeout: Duration,
    ) -> Result<GoalReply, ClientError> {
        let req = GoalRequest::set_goal(self.next_request_id(), goal, obstacles)
            .ok_or(ClientError::TooManyObstacles(obstacles.len()))?;
        self.request(&req, timeout)
    }

    /// Asks the daemon to drop its goal and stop.
    pub fn cancel(&self, timeout: Duration) -> Result<GoalReply, ClientError> {
        self.request(&GoalRequest::cancel(self.next_request_id()), timeout)
    }

    /// Asks the daemon for a controlled stop through the reserved stop service (see
    /// [`StopClient`]): it gets through even when every goal client slot is taken, and
    /// when the stop service has no free slot it goes on this client's own goal port
    /// (kind 3). The stop latches: goals are rejected until [`Client::resume`].
    pub fn stop(&self, timeout: Duration) -> Result<GoalReply, ClientError> {
        self.stop_report(timeout).map(|r| r.reply)
    }

    /// [`Client::stop`], saying which path the stop took and what failed on the way.
    pub fn stop_report(&self, timeout: Duration) -> Result<StopReport, ClientError> {
        let request_id = self.next_request_id();
        let deadline = Instant::now() + timeout;
        let mut detours = Vec::new();
        let stop_error = match StopClient::new(&self.config) {
            Ok(sc) => match sc.via_stop_service(request_id, deadline, &mut detours) {
                Ok(report) => return Ok(report),
                Err(Attempt::Sent(e)) => return Err(e),
                Err(Attempt::NotSent(e)) => e,
            },
            Err(e) => e.into(),
        };
        detours.push(format!(
            "stop service {:?}: {stop_error}; sending the stop on this client's goal port",
            self.conn.names.stop
        ));
        // This client already holds a goal port, its notifier and its listener.
        let pending = self
            .submit(&GoalRequest::stop(request_id))
            .map_err(|goal| ClientError::StopNotSent {
                stop: Box::new(stop_error),
                goal: Box::new(goal),
            })?;
        let reply = pending.wait(deadline.saturating_duration_since(Instant::now()))?;
        Ok(StopReport {
            reply,
            path: StopPath::GoalService,
            notified: true,
            listened: true,
            detours,
        })
    }

    /// Releases an operator stop: goals are accepted again.
    pub fn resume(&self, timeout: Duration) -> Result<GoalReply, ClientError> {
        self.request(&GoalRequest::resume(self.next_request_id()), timeout)
    }

    /// Asks the daemon to reload its site file: accepted once the new file is
    /// read and valid (in force from the daemon's next tick), rejected with
    /// what is wrong while the old site stays.
    pub fn reload_site(&self, timeout: Duration) -> Result<GoalReply, ClientError> {
        self.request(&GoalRequest::reload_site(self.next_request_id()), timeout)
    }

    /// Publishes a pose estimate (the publisher is created on first use) and wakes the
    /// daemon.
    pub fn publish_pose(&self, pose: &PoseEstimate) -> Result<(), IpcError> {
        let service = &self.conn.names.pose;
        // A poisoned lock only means another thread panicked mid-send; the ports are fine.
        let mut guard = self
            .pose_pub
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if guard.is_none() {
            let publisher = single_publisher(&self.conn.pose, service, |service, holders| {
                IpcError::PoseSourceTaken { service, holders }
            })?;
            let notifier = Connection::notifier(&self.conn.pose_event, service)?;
            *guard = Some((publisher, notifier));
        }
        let Some((publisher, notifier)) = guard.as_ref() else {
            return Ok(());
        };
        publisher.send_copy(*pose).map_err(|e| IpcError::Send {
            service: service.clone(),
            source: boxed(e),
        })?;
        notify(notifier, event_ids::POSE, service)
    }

    /// The one publisher of live obstacles (`{prefix}/v2/obstacles`), on this client's
    /// connection: see [`ObstaclePublisher`]. Fails with
    /// [`IpcError::ObstacleSourceTaken`] when another process (or another
    /// `ObstaclePublisher` of this one) holds it. A perception process that needs nothing
    /// else should use [`ObstaclePublisher::new`], which takes no goal client slot.
    pub fn obstacle_publisher(&self) -> Result<ObstaclePublisher, IpcError> {
        ObstaclePublisher::from_factories(
            &self.conn.obstacles,
            &self.conn.obstacles_event,
            &self.conn.names.obstacles,
        )
    }

    /// A new telemetry subscription. It receives the latest sample already published (if
    /// any) and everything after; up to 16 unread samples are kept, older ones dropped.
    pub fn subscribe_telemetry(&self) -> Result<TelemetrySubscriber, IpcError> {
        let service = self.conn.names.telemetry.clone();
        let subscriber = self
            .conn
            .telemetry
            .subscriber_builder()
            .buffer_size(qos::SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| {
                if e == iceoryx2::port::subscriber::SubscriberCreateError::ExceedsMaxSupportedSubscribers {
                    use iceoryx2::service::port_factory::PortFactory as _;
                    IpcError::PortsExhausted {
                        port: "subscriber",
                        service: service.clone(),
                        limit: self.conn.telemetry.static_config().max_subscribers(),
                        holders: crate::holders::subscriber_holders(&self.conn.telemetry),
                    }
                } else {
                    IpcError::Port {
                        port: "subscriber",
                        service: service.clone(),
                        source: boxed(e),
                    }
                }
            })?;
        let listener = Connection::listener(&self.conn.telemetry_event, &service)?;
        Ok(TelemetrySubscriber {
            subscriber,
            listener,
            service,
        })
    }
}

/// A sent goal request awaiting its reply.
pub struct PendingGoal<'a> {
    pending: GoalPending,
    request_id: u64,
    client: &'a Client,
}

impl core::fmt::Debug for PendingGoal<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PendingGoal")
            .field("request_id", &self.request_id)
            .finish_non_exhaustive()
    }
}

impl PendingGoal<'_> {
    /// The id of the request.
    pub fn request_id(&self) -> u64 {
        self.request_id
    }

    /// The reply if it has arrived, without blocking.
    pub fn try_reply(&self) -> Result<Option<GoalReply>, ClientError> {
        try_reply(&self.pending, self.request_id, &self.client.conn.names.goal)
    }

    /// Waits up to `timeout` for the reply, sleeping on the goal event service. A signal
    /// interrupting the wait is [`IpcError::Interrupted`].
    pub fn wait(self, timeout: Duration) -> Result<GoalReply, ClientError> {
        wait_reply(
            &self.pending,
            self.request_id,
            &self.client.goal_listener,
            &self.client.conn.names.goal,
            timeout,
        )
    }
}

/// The reply to `pending`, if it has arrived (checked against `request_id`).
pub(super) fn try_reply(
    pending: &GoalPending,
    request_id: u64,
    service: &str,
) -> Result<Option<GoalReply>, ClientError> {
    let response = pending.receive().map_err(|e| IpcError::Receive {
        service: service.to_owned(),
        source: boxed(e),
    })?;
    match response {
        None => Ok(None),
        Some(r) => {
            let reply = *r.payload();
            if reply.request_id != request_id {
                return Err(ClientError::ReplyMismatch {
                    expected: request_id,
                    got: reply.request_id,
                });
            }
            Ok(Some(reply))
        }
    }
}

/// Waits up to `timeout` for the reply to `pending`, sleeping on `listener`.
pub(super) fn wait_reply(
    pending: &GoalPending,
    request_id: u64,
    listener: &Listener<IpcService>,
    service: &str,
    timeout: Duration,
) -> Result<GoalReply, ClientError> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(reply) = try_reply(pending, request_id, service)? {
            return Ok(reply);
        }
        if !pending.is_connected() {
            // The server may have replied and dropped the request between the two
            // checks; look once more before giving up.
            return match try_reply(pending, request_id, service)? {
                Some(reply) => Ok(reply),
                None => Err(ClientError::Dropped { request_id }),
            };
        }
        let now = Instant::now();
        if now >= deadline {
            return Err(ClientError::Timeout {
                request_id,
                timeout,
            });
        }
        listener
            .timed_wait(|_| {}, deadline - now)
            .map_err(|e| wait_error(e, service))?;
    }
}

/// A telemetry subscription (see [`Client::subscribe_telemetry`]).
pub struct TelemetrySubscriber {
    subscriber: Subscriber<IpcService, Telemetry, ()>,
    listener: Listener<IpcService>,
    service: String,
}

impl core::fmt::Debug for TelemetrySubscriber {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TelemetrySubscriber")
            .field("service", &self.service)
            .finish_non_exhaustive()
    }
}

impl TelemetrySubscriber {
    /// The next unread sample (oldest first), without blocking.
    pub fn try_recv(&self) -> Result<Option<Telemetry>, IpcError> {
        receive_copy(&self.subscriber, &self.service)
    }

    /// The next sample, waiting up to `timeout` for one to be published (`Ok(None)` on
    /// timeout, [`IpcError::Interrupted`] if a signal interrupts the wait).
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<Telemetry>, IpcError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(t) = self.try_recv()? {
                return Ok(Some(t));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.listener
                .timed_wait(|_| {}, deadline - now)
                .map_err(|e| wait_error(e, &self.service))?;
        }
    }

    /// Drains everything unread and returns the newest sample.
    pub fn latest(&self) -> Result<Option<Telemetry>, IpcError> {
        newest(|| self.try_recv())
    }

    /// Consumes pending notifications (after an `AsyncFd` readiness, before reading).
    pub fn drain_events(&self) -> Result<(), IpcError> {
        drain(&self.listener, &self.service)
    }

    /// File descriptor that becomes readable when a sample is published.
    pub fn event_fd(&self) -> RawFd {
        listener_fd(&self.listener)
    }
}
