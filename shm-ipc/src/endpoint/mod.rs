//! The two ends of the connection: [`DaemonEndpoint`] (used by `wlnavd`) and [`Client`]
//! (used by the CLI, tests, localization bridges), and the reserved stop path
//! ([`StopClient`]).
//!
//! All ports use iceoryx2's `ipc_threadsafe` service flavour, so endpoints are `Send + Sync`
//! and can move between the daemon's tokio I/O tasks and threads; the wire format is the
//! same as the plain `ipc` flavour, so C/C++/Python peers interoperate unchanged.
//!
//! One job per module:
//! - `services`: the node and the services, opened or created with the crate's QoS (this
//!   module's [`qos`]), the holders named when that fails, and the stale-node clean-up;
//! - `events`: the event-service wake-ups (notify, drain, poll the listeners' descriptors);
//! - `daemon`: the daemon's side ([`DaemonEndpoint`], [`IncomingGoal`]);
//! - `client`: the client's side ([`Client`], [`PendingGoal`], [`TelemetrySubscriber`]);
//! - `stop`: the reserved stop path ([`StopClient`]).

use iceoryx2::port::client::Client as IoxClient;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::ipc_threadsafe;
use iceoryx2::service::port_factory::request_response;

use crate::msg::{GoalReply, GoalRequest, PoseEstimate};

mod client;
mod daemon;
mod events;
mod obstacles;
mod services;
mod stop;

pub use client::{Client, PendingGoal, TelemetrySubscriber};
pub use daemon::{DaemonEndpoint, IncomingGoal, Wakeup};
pub use obstacles::ObstaclePublisher;
pub use services::{cleanup_stale_nodes, CleanupReport};
pub use stop::{StopClient, StopPath, StopReport};

/// The iceoryx2 service flavour used for every port (see the module docs).
pub type IpcService = ipc_threadsafe::Service;

/// Event ids sent on the event services paired with each data service. A listener may see
/// ids it does not care about (the goal event service carries both directions); they are
/// only wake-ups, the data is always read from the data service.
pub mod event_ids {
    /// A client sent a [`crate::GoalRequest`] (on `{prefix}/v2/goal`).
    pub const GOAL_REQUEST: usize = 1;
    /// The daemon sent a [`crate::GoalReply`] (on `{prefix}/v2/goal`).
    pub const GOAL_REPLY: usize = 2;
    /// A [`crate::PoseEstimate`] was published (on `{prefix}/v2/pose`).
    pub const POSE: usize = 3;
    /// A [`crate::Telemetry`] sample was published (on `{prefix}/v2/telemetry`).
    pub const TELEMETRY: usize = 4;
    /// A client sent a stop request (on `{prefix}/v2/stop`).
    pub const STOP_REQUEST: usize = 5;
    /// The daemon replied to a stop request (on `{prefix}/v2/stop`).
    pub const STOP_REPLY: usize = 6;
    /// A [`crate::LiveObstacleSet`] was published (on `{prefix}/v2/obstacles`).
    pub const OBSTACLES: usize = 7;
}

/// Service quality-of-service settings. They are requirements when opening an existing
/// service, so every wlnav process must use the same values; documented in the crate root
/// for foreign peers (who may leave them at iceoryx2's defaults when only opening).
pub mod qos {
    /// One goal server per prefix: a second daemon is refused instead of both answering.
    pub const GOAL_MAX_SERVERS: usize = 1;
    /// Clients per goal service (CLI invocations, tests, GUIs).
    pub const GOAL_MAX_CLIENTS: usize = 32;
    /// Requests one client may have in flight.
    pub const GOAL_MAX_ACTIVE_REQUESTS_PER_CLIENT: usize = 16;
    /// Nodes per service.
    pub const MAX_NODES: usize = 64;
    /// Telemetry subscribers (watchers, recorders).
    pub const TELEMETRY_MAX_SUBSCRIBERS: usize = 16;
    /// Telemetry publishers: the daemon (2 leaves room for a replay tool).
    pub const TELEMETRY_MAX_PUBLISHERS: usize = 2;
    /// Pose publishers: one. The daemon trusts one pose source only (DESIGN §11); a second
    /// publisher is refused ([`crate::IpcError::PoseSourceTaken`]) instead of mixing its
    /// samples with the localization's.
    pub const POSE_MAX_PUBLISHERS: usize = 1;
    /// Pose subscribers.
    pub const POSE_MAX_SUBSCRIBERS: usize = 8;
    /// Per-subscriber buffer; older samples are overwritten (safe overflow) so a slow
    /// reader never blocks a publisher.
    pub const SUBSCRIBER_BUFFER: usize = 16;
    /// History delivered to a new subscriber: the latest sample, so `watch` shows something
    /// at once and the daemon gets a pose without waiting a period.
    pub const HISTORY: usize = 1;
    /// Listeners and notifiers per event service.
    pub const EVENT_MAX_PORTS: usize = 64;
    /// Clients of the reserved stop service. A [`crate::StopClient`] holds its port only
    /// while one stop request is in flight, so these slots are free unless stops are being
    /// sent right now.
    pub const STOP_MAX_CLIENTS: usize = 16;
    /// Stop requests one stop client may have in flight.
    pub const STOP_MAX_ACTIVE_REQUESTS_PER_CLIENT: usize = 2;
    /// Live-obstacle publishers: one, for any perception stack (DESIGN §18). A second is
    /// refused ([`crate::IpcError::ObstacleSourceTaken`]): two sets interleaving would make
    /// obstacles blink in and out, each set replacing the other's.
    pub const OBSTACLES_MAX_PUBLISHERS: usize = 1;
    /// Live-obstacle subscribers: the daemon, and room for a viewer or a recorder.
    pub const OBSTACLES_MAX_SUBSCRIBERS: usize = 4;
    /// Per-subscriber buffer of the obstacle service: **one** set. A set replaces the
    /// previous one as a whole, so the daemon only ever needs the newest; with safe
    /// overflow a new set overwrites an unread one. A flood of sets therefore never blocks
    /// the publisher and never grows anything: the shared memory is sized once, at
    /// creation, for one 24 592-byte set per subscriber (plus the history and the
    /// publisher's loans), and a reader always finds the newest.
    pub const OBSTACLES_SUBSCRIBER_BUFFER: usize = 1;
}

/// A pose publisher and the notifier that wakes its subscribers.
type PosePublisher = (
    Publisher<IpcService, PoseEstimate, ()>,
    Notifier<IpcService>,
);
type GoalFactory = request_response::PortFactory<IpcService, GoalRequest, (), GoalReply, ()>;
type GoalServer = Server<IpcService, GoalRequest, (), GoalReply, ()>;
type GoalClient = IoxClient<IpcService, GoalRequest, (), GoalReply, ()>;
type GoalPending =
    iceoryx2::pending_response::PendingResponse<IpcService, GoalRequest, (), GoalReply, ()>;
type GoalActive =
    iceoryx2::active_request::ActiveRequest<IpcService, GoalRequest, (), GoalReply, ()>;

fn boxed<E: std::error::Error + Send + Sync + 'static>(e: E) -> crate::error::BoxedSource {
    Box::new(e)
}

/// The next sample of `subscriber` (oldest first), copied out of shared memory, without
/// blocking.
fn receive_copy<T: core::fmt::Debug + Copy + iceoryx2::prelude::ZeroCopySend>(
    subscriber: &iceoryx2::port::subscriber::Subscriber<IpcService, T, ()>,
    service: &str,
) -> Result<Option<T>, crate::error::IpcError> {
    subscriber
        .receive()
        .map(|s| s.map(|s| *s.payload()))
        .map_err(|e| crate::error::IpcError::Receive {
            service: service.to_owned(),
            source: boxed(e),
        })
}

/// Calls `next` until it has nothing more; the last item it gave.
fn newest<T>(
    mut next: impl FnMut() -> Result<Option<T>, crate::error::IpcError>,
) -> Result<Option<T>, crate::error::IpcError> {
    let mut latest = None;
    while let Some(item) = next()? {
        latest = Some(item);
    }
    Ok(latest)
}

/// Opens with `open`, retrying every 20 ms for up to `timeout` while no daemon has created
/// the services ([`crate::IpcError::NotServed`]); other errors return at once.
fn wait_for_daemon<T>(
    config: &crate::config::IpcConfig,
    timeout: core::time::Duration,
    open: impl Fn(&crate::config::IpcConfig) -> Result<T, crate::error::IpcError>,
) -> Result<T, crate::error::IpcError> {
    let deadline = std::time::Instant::now() + timeout;
    let mut config = config.clone();
    loop {
        match open(&config) {
            Err(crate::error::IpcError::NotServed { .. })
                if std::time::Instant::now() < deadline =>
            {
                // Clean once; the retries need not list the nodes again.
                config.cleanup_stale_nodes = false;
                std::thread::sleep(core::time::Duration::from_millis(20));
            }
            other => return other,
        }
    }
}

// The daemon moves endpoints between its tokio tasks and threads.
const _: () = {
    const fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<DaemonEndpoint>();
    assert_send_sync::<Client>();
    assert_send_sync::<TelemetrySubscriber>();
    assert_send_sync::<ObstaclePublisher>();
};
