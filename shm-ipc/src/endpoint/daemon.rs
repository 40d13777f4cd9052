//! The daemon's side: [`DaemonEndpoint`] serves goal and stop requests, publishes
//! telemetry and subscribes to poses and live obstacles; [`IncomingGoal`] is a request awaiting its answer.

use core::time::Duration;
use std::os::fd::RawFd;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::service::port_factory::event;

use super::events::{drain, listener_fd, notify, poll_fds};
use super::services::{event_service, goal_service, Access, CleanupReport, Connection};
use super::{
    boxed, event_ids, newest, qos, receive_copy, GoalActive, GoalFactory, GoalServer, IpcService,
};
use crate::config::{IpcConfig, ServiceNames};
use crate::error::IpcError;
use crate::msg::{GoalReply, GoalRequest, LiveObstacleSet, PoseEstimate, Telemetry};

/// Which event sources woke [`DaemonEndpoint::wait`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Wakeup {
    /// Goal requests may be waiting: call [`DaemonEndpoint::receive_goal`] until `None`.
    pub goal: bool,
    /// Poses may be waiting: call [`DaemonEndpoint::latest_pose`].
    pub pose: bool,
    /// Stop requests may be waiting: call [`DaemonEndpoint::receive_stop`] until `None`.
    pub stop: bool,
    /// A live obstacle set may be waiting: call [`DaemonEndpoint::latest_obstacles`].
    pub obstacles: bool,
}

impl Wakeup {
    /// True if anything woke the wait (false on timeout or a signal).
    pub fn any(&self) -> bool {
        self.goal || self.pose || self.stop || self.obstacles
    }
}

/// The daemon's side: serves goal requests, publishes telemetry, subscribes to poses and
/// live obstacles.
///
/// Typical I/O loop (blocking thread; with tokio wrap [`DaemonEndpoint::goal_event_fd`],
/// [`DaemonEndpoint::pose_event_fd`] and [`DaemonEndpoint::obstacles_event_fd`] in
/// `AsyncFd` instead of calling `wait`):
///
/// ```no_run
/// use shm_ipc::{DaemonEndpoint, GoalValidator, IpcConfig};
/// use std::time::Duration;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let ep = DaemonEndpoint::new(&IpcConfig::default())?;
/// let validator = GoalValidator::default();
/// loop {
///     ep.wait(Some(Duration::from_millis(200)))?;
///     while let Some(goal) = ep.receive_goal()? {
///         let (result, reply) = validator.validate_and_reply(goal.request());
///         goal.reply(reply)?;
///         println!("hand to the control thread: {result:?}");
///     }
///     if let Some(pose) = ep.latest_pose()? {
///         println!("pose: {pose:?}");
///     }
///     if let Some(set) = ep.latest_obstacles()? {
///         println!("{} live obstacles", set.as_slice().len());
///     }
/// }
/// # }
/// ```
pub struct DaemonEndpoint {
    conn: Connection,
    server: GoalServer,
    goal_notifier: Notifier<IpcService>,
    goal_listener: Listener<IpcService>,
    telemetry_pub: Publisher<IpcService, Telemetry, ()>,
    telemetry_notifier: Notifier<IpcService>,
    pose_sub: Subscriber<IpcService, PoseEstimate, ()>,
    pose_listener: Listener<IpcService>,
    obstacles_sub: Subscriber<IpcService, LiveObstacleSet, ()>,
    obstacles_listener: Listener<IpcService>,
    /// The reserved stop path: its own service, so it has its own client slots.
    _stop_factory: GoalFactory,
    _stop_event: event::PortFactory<IpcService>,
    stop_server: GoalServer,
    stop_notifier: Notifier<IpcService>,
    stop_listener: Listener<IpcService>,
}

impl core::fmt::Debug for DaemonEndpoint {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("DaemonEndpoint")
            .field("services", &self.conn.names)
            .finish_non_exhaustive()
    }
}

impl DaemonEndpoint {
    /// Creates the services for `config.prefix` (or opens them if they survive from an
    /// earlier daemon run with the same settings) and the daemon's ports. Fails with
    /// [`IpcError::AlreadyServed`] if a live daemon already serves that prefix, and with
    /// [`IpcError::ServiceHeld`] (naming the service and the processes attached to it) if
    /// another process created a service with settings the daemon cannot use.
    pub fn new(config: &IpcConfig) -> Result<Self, IpcError> {
        let conn = Connection::open(config, "wlnavd", Access::Create)?;
        let names = &conn.names;
        let server_of = |factory: &GoalFactory, service: &str| {
            factory.server_builder().create().map_err(|e| {
                if e == iceoryx2::service::port_factory::server::ServerCreateError::ExceedsMaxSupportedServers
                {
                    IpcError::AlreadyServed {
                        service: service.to_owned(),
                        holders: crate::holders::server_holders(factory),
                    }
                } else {
                    IpcError::Port {
                        port: "server",
                        service: service.to_owned(),
                        source: boxed(e),
                    }
                }
            })
        };
        let server = server_of(&conn.goal, &names.goal)?;
        let stop_factory = goal_service(
            &conn.node,
            &names.stop,
            qos::STOP_MAX_CLIENTS,
            qos::STOP_MAX_ACTIVE_REQUESTS_PER_CLIENT,
            Access::Create,
        )?;
        let stop_event = event_service(&conn.node, &names.stop, Access::Create)?;
        let stop_server = server_of(&stop_factory, &names.stop)?;
        let stop_notifier = Connection::notifier(&stop_event, &names.stop)?;
        let stop_listener = Connection::listener(&stop_event, &names.stop)?;
        let goal_notifier = Connection::notifier(&conn.goal_event, &names.goal)?;
        let goal_listener = Connection::listener(&conn.goal_event, &names.goal)?;
        let telemetry_pub =
            conn.telemetry
                .publisher_builder()
                .create()
                .map_err(|e| IpcError::Port {
                    port: "publisher",
                    service: names.telemetry.clone(),
                    source: boxed(e),
                })?;
        let telemetry_notifier = Connection::notifier(&conn.telemetry_event, &names.telemetry)?;
        let pose_sub = conn
            .pose
            .subscriber_builder()
            .buffer_size(qos::SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| IpcError::Port {
                port: "subscriber",
                service: names.pose.clone(),
                source: boxed(e),
            })?;
        let pose_listener = Connection::listener(&conn.pose_event, &names.pose)?;
        // One set: the newest replaces an unread one (qos::OBSTACLES_SUBSCRIBER_BUFFER).
        let obstacles_sub = conn
            .obstacles
            .subscriber_builder()
            .buffer_size(qos::OBSTACLES_SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| IpcError::Port {
                port: "subscriber",
                service: names.obstacles.clone(),
                source: boxed(e),
            })?;
        let obstacles_listener = Connection::listener(&conn.obstacles_event, &names.obstacles)?;
        Ok(Self {
            conn,
            server,
            goal_notifier,
            goal_listener,
            telemetry_pub,
            telemetry_notifier,
            pose_sub,
            pose_listener,
            obstacles_sub,
            obstacles_listener,
            _stop_factory: stop_factory,
            _stop_event: stop_event,
            stop_server,
            stop_notifier,
            stop_listener,
        })
    }

    /// The service names in use.
    pub fn service_names(&self) -> &ServiceNames {
        &self.conn.names
    }

    /// What the start-up stale-node clean-up did.
    pub fn cleanup_report(&self) -> CleanupReport {
        self.conn.cleanup
    }

    /// Takes the next pending goal request without blocking. Answer it with
    /// [`IncomingGoal::reply`]; dropping it unanswered makes the client see
    /// [`ClientError::Dropped`](crate::ClientError::Dropped).
    pub fn receive_goal(&self) -> Result<Option<IncomingGoal<'_>>, IpcError> {
        let active = self.server.receive().map_err(|e| IpcError::Receive {
            service: self.conn.names.goal.clone(),
            source: boxed(e),
        })?;
        Ok(active.map(|active| IncomingGoal {
            request: *active.payload(),
            active: Some(active),
            endpoint: self,
            via_stop_service: false,
        }))
    }

    /// Takes the next pending request of the reserved stop service without blocking.
    /// Serve these before goals. Answer with [`IncomingGoal::reply`].
    pub fn receive_stop(&self) -> Result<Option<IncomingGoal<'_>>, IpcError> {
        let active = self.stop_server.receive().map_err(|e| IpcError::Receive {
            service: self.conn.names.stop.clone(),
            source: boxed(e),
        })?;
        Ok(active.map(|active| IncomingGoal {
            request: *active.payload(),
            active: Some(active),
            endpoint: self,
            via_stop_service: true,
        }))
    }

    /// Answers every pending request of the stop service with `handler`'s reply; returns
    /// how many were served.
    pub fn serve_stops(
        &self,
        mut handler: impl FnMut(&GoalRequest) -> GoalReply,
    ) -> Result<usize, IpcError> {
        let mut n = 0;
        while let Some(stop) = self.receive_stop()? {
            let reply = handler(stop.request());
            stop.reply(reply)?;
            n += 1;
        }
        Ok(n)
    }

    /// Answers every pending request with `handler`'s reply; returns how many were served.
    /// The reply's `request_id` is set to the request's.
    pub fn serve_goals(
        &self,
        mut handler: impl FnMut(&GoalRequest) -> GoalReply,
    ) -> Result<usize, IpcError> {
        let mut n = 0;
        while let Some(goal) = self.receive_goal()? {
            let reply = handler(goal.request());
            goal.reply(reply)?;
            n += 1;
        }
        Ok(n)
    }

    /// Publishes one telemetry sample and wakes the subscribers.
    pub fn publish_telemetry(&self, telemetry: &Telemetry) -> Result<(), IpcError> {
        let service = &self.conn.names.telemetry;
        self.telemetry_pub
            .send_copy(*telemetry)
            .map_err(|e| IpcError::Send {
                service: service.clone(),
                source: boxed(e),
            })?;
        notify(&self.telemetry_notifier, event_ids::TELEMETRY, service)
    }

    /// Takes the next pose sample without blocking (oldest first).
    pub fn receive_pose(&self) -> Result<Option<PoseEstimate>, IpcError> {
        receive_copy(&self.pose_sub, &self.conn.names.pose)
    }

    /// Drains all pending pose samples and returns the newest, if any. Validity is not
    /// judged here: check [`PoseEstimate::is_usable`] and the timestamp.
    pub fn latest_pose(&self) -> Result<Option<PoseEstimate>, IpcError> {
        newest(|| self.receive_pose())
    }

    /// Takes the next live obstacle set without blocking (the subscriber keeps one set,
    /// the newest, so this is also the latest).
    pub fn receive_obstacles(&self) -> Result<Option<LiveObstacleSet>, IpcError> {
        receive_copy(&self.obstacles_sub, &self.conn.names.obstacles)
    }

    /// Drains the pending live obstacle sets and returns the newest, if any (a copy out of
    /// shared memory). Nothing is judged here: check it with
    /// [`crate::LiveObstacleValidator::validate`] and judge its age on
    /// [`LiveObstacleSet::timestamp_ns`].
    pub fn latest_obstacles(&self) -> Result<Option<LiveObstacleSet>, IpcError> {
        newest(|| self.receive_obstacles())
    }

    /// Blocks until a goal, stop, pose or live-obstacle notification arrives, or `timeout`
    /// passes (`None`: forever). Consumes the notifications, so read the data afterwards
    /// until empty. Spurious wake-ups are possible (e.g. the goal event service also carries the
    /// daemon's own reply notifications); a signal returns an empty [`Wakeup`].
    pub fn wait(&self, timeout: Option<Duration>) -> Result<Wakeup, IpcError> {
        let ready = poll_fds(
            &[
                listener_fd(&self.goal_listener),
                listener_fd(&self.pose_listener),
                listener_fd(&self.stop_listener),
                listener_fd(&self.obstacles_listener),
            ],
            timeout,
        )
        .map_err(|e| IpcError::Event {
            service: self.conn.names.goal.clone(),
            source: boxed(e),
        })?;
        self.drain_events()?;
        self.drain_obstacle_events()?;
        Ok(Wakeup {
            goal: ready.first().copied().unwrap_or(false),
            pose: ready.get(1).copied().unwrap_or(false),
            stop: ready.get(2).copied().unwrap_or(false),
            obstacles: ready.get(3).copied().unwrap_or(false),
        })
    }

    /// Consumes pending notifications on the goal, pose and stop listeners (call after an
    /// `AsyncFd` readiness before reading the data, so the descriptors stop being
    /// readable). Not the obstacle listener's: a task that serves goals must not swallow
    /// the wake-up another task waits for on [`DaemonEndpoint::obstacles_event_fd`]
    /// (see [`DaemonEndpoint::drain_obstacle_events`]).
    pub fn drain_events(&self) -> Result<(), IpcError> {
        drain(&self.goal_listener, &self.conn.names.goal)?;
        drain(&self.pose_listener, &self.conn.names.pose)?;
        drain(&self.stop_listener, &self.conn.names.stop)
    }

    /// File descriptor that becomes readable when a stop request may be waiting on the
    /// reserved stop service.
    pub fn stop_event_fd(&self) -> RawFd {
        listener_fd(&self.stop_listener)
    }

    /// File descriptor that becomes readable when a goal request may be waiting.
    pub fn goal_event_fd(&self) -> RawFd {
        listener_fd(&self.goal_listener)
    }

    /// File descriptor that becomes readable when a pose may be waiting.
    pub fn pose_event_fd(&self) -> RawFd {
        listener_fd(&self.pose_listener)
    }

    /// File descriptor that becomes readable when a live obstacle set may be waiting
    /// (event id [`event_ids::OBSTACLES`]). After it is readable, call
    /// [`DaemonEndpoint::drain_obstacle_events`], then
    /// [`DaemonEndpoint::latest_obstacles`].
    pub fn obstacles_event_fd(&self) -> RawFd {
        listener_fd(&self.obstacles_listener)
    }

    /// Consumes pending notifications on the obstacle listener (call after an `AsyncFd`
    /// readiness of [`DaemonEndpoint::obstacles_event_fd`], before reading the set).
    pub fn drain_obstacle_events(&self) -> Result<(), IpcError> {
        drain(&self.obstacles_listener, &self.conn.names.obstacles)
    }
}

/// A goal request taken from the service, waiting for its answer. Dropping it unanswered
/// tells the client at once ([`ClientError::Dropped`]) rather than after its timeout.
///
/// [`ClientError::Dropped`]: crate::ClientError::Dropped
pub struct IncomingGoal<'a> {
    request: GoalRequest,
    active: Option<GoalActive>,
    endpoint: &'a DaemonEndpoint,
    /// Came through the reserved stop service (reply notifications go there).
    via_stop_service: bool,
}

impl core::fmt::Debug for IncomingGoal<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("IncomingGoal")
            .field("request", &self.request)
            .finish_non_exhaustive()
    }
}

impl IncomingGoal<'_> {
    /// The request as received (a copy out of shared memory; validate before use).
    pub fn request(&self) -> &GoalRequest {
        &self.request
    }

    /// True if the request came through the reserved stop service.
    pub fn via_stop_service(&self) -> bool {
        self.via_stop_service
    }

    /// The service name, notifier and reply event id of the service this came from.
    fn reply_path(&self) -> (&String, &Notifier<IpcService>, usize) {
        let ep = self.endpoint;
        if self.via_stop_service {
            (
                &ep.conn.names.stop,
                &ep.stop_notifier,
                event_ids::STOP_REPLY,
            )
        } else {
            (
                &ep.conn.names.goal,
                &ep.goal_notifier,
                event_ids::GOAL_REPLY,
            )
        }
    }

    /// Sends `reply` (its `request_id` is overwritten with the request's) and wakes the
    /// client. A client that already gave up is not an error.
    pub fn reply(mut self, mut reply: GoalReply) -> Result<(), IpcError> {
        reply.request_id = self.request.request_id;
        let active = self.active.take();
        let (service, notifier, id) = self.reply_path();
        if let Some(active) = active {
            if active.is_connected() {
                active.send_copy(reply).map_err(|e| IpcError::Send {
                    service: service.clone(),
                    source: boxed(e),
                })?;
            }
        }
        notify(notifier, id, service)
    }
}

impl Drop for IncomingGoal<'_> {
    fn drop(&mut self) {
        if let Some(active) = self.active.take() {
            // Disconnect first, then wake the client so it sees the disconnect. A failed
            // notification only delays the client until its timeout: nothing to report.
            drop(active);
            let (service, notifier, id) = self.reply_path();
            let _ = notify(notifier, id, service);
        }
    }
}
