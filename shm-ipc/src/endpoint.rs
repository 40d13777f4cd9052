//! The two ends of the connection: [`DaemonEndpoint`] (used by `wlnavd`) and [`Client`]
//! (used by the CLI, tests, localization bridges).
//!
//! All ports use iceoryx2's `ipc_threadsafe` service flavour, so endpoints are `Send + Sync`
//! and can move between the daemon's tokio I/O tasks and threads; the wire format is the
//! same as the plain `ipc` flavour, so C/C++/Python peers interoperate unchanged.

use core::time::Duration;
use std::os::fd::RawFd;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use iceoryx2::node::node_name::NodeName;
use iceoryx2::node::{Node, NodeBuilder};
use iceoryx2::port::client::Client as IoxClient;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{ipc_threadsafe, EventId, FileDescriptorBased, ServiceName, ZeroCopySend};
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};
use iceoryx2::signal_handling_mode::SignalHandlingMode;

use crate::config::{IpcConfig, ServiceNames};
use crate::error::{ClientError, IpcError};
use crate::msg::{GoalReply, GoalRequest, Obstacle, Pose2, PoseEstimate, Telemetry};

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

// The daemon moves endpoints between its tokio tasks and threads.
const _: () = {
    const fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<DaemonEndpoint>();
    assert_send_sync::<Client>();
    assert_send_sync::<TelemetrySubscriber>();
};

/// What stale-node clean-up found at start-up.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CleanupReport {
    /// Dead nodes seen by `Node::list` before cleaning.
    pub dead_nodes_found: u64,
    /// Dead nodes whose resources were removed.
    pub cleaned: u64,
    /// Dead nodes that could not be removed (other user's files, or another process is
    /// cleaning them right now).
    pub failed: u64,
}

/// How a process attaches to the services: the daemon creates them with the crate's
/// settings (DESIGN §11: "the daemon creates its services"); everyone else only opens
/// what the daemon created, so a client started first can never fix settings the daemon
/// cannot use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    /// Open or create with the crate's QoS; refuse a foreign-created service that does
    /// not fit ([`IpcError::ServiceHeld`]).
    Create,
    /// Open only, without requirements (the creator's settings rule); a missing service is
    /// [`IpcError::NotServed`].
    Open,
}

/// The node and the goal, pose and telemetry services, opened or created. Shared setup of
/// both endpoints.
struct Connection {
    /// Owns the node's registration; ports keep it alive too, this makes it explicit.
    node: Node<IpcService>,
    names: ServiceNames,
    goal: GoalFactory,
    goal_event: event::PortFactory<IpcService>,
    pose: publish_subscribe::PortFactory<IpcService, PoseEstimate, ()>,
    pose_event: event::PortFactory<IpcService>,
    telemetry: publish_subscribe::PortFactory<IpcService, Telemetry, ()>,
    telemetry_event: event::PortFactory<IpcService>,
    cleanup: CleanupReport,
}

fn service_name(name: &str) -> Result<ServiceName, IpcError> {
    ServiceName::new(name).map_err(|e| IpcError::InvalidServiceName {
        name: name.to_owned(),
        source: boxed(e),
    })
}

/// Who is attached to service `name` (any payload type): `node "x" (pid 12, python3)`, …
fn service_holders(name: &ServiceName, pattern: MessagingPattern) -> String {
    use iceoryx2::node::{NodeState, NodeView};
    use iceoryx2::service::Service as _;
    let details =
        match IpcService::details(name, iceoryx2::config::Config::global_config(), pattern) {
            Ok(Some(d)) => d,
            Ok(None) => return "nobody (the service vanished meanwhile)".into(),
            Err(e) => return format!("unknown ({e:?})"),
        };
    let Some(dynamic) = details.dynamic_details else {
        return "unknown".into();
    };
    let describe = |view: &dyn Fn() -> Option<String>, state: &str| {
        view().unwrap_or_else(|| format!("a {state} node without details"))
    };
    let mut holders: Vec<String> = dynamic
        .nodes
        .iter()
        .map(|state| match state {
            NodeState::Alive(v) => describe(
                &|| {
                    v.details().as_ref().map(|d| {
                        format!(
                            "node {:?} (pid {}, {})",
                            d.name().to_string(),
                            d.process_id().value(),
                            d.executable()
                        )
                    })
                },
                "live",
            ),
            NodeState::Dead(v) => describe(
                &|| {
                    v.details().as_ref().map(|d| {
                        format!(
                            "dead node {:?} (pid {}, {})",
                            d.name().to_string(),
                            d.process_id().value(),
                            d.executable()
                        )
                    })
                },
                "dead",
            ),
            NodeState::Inaccessible(_) => "a node of another user".into(),
            NodeState::Undefined(_) => "a node in an undefined state".into(),
        })
        .collect();
    if holders.is_empty() {
        holders.push("no node".into());
    }
    holders.join(", ")
}

/// Opening `name` failed because its node limit is reached: who is attached.
fn nodes_exhausted(name: &str, messaging: MessagingPattern) -> IpcError {
    let holders = ServiceName::new(name)
        .map(|n| service_holders(&n, messaging))
        .unwrap_or_else(|_| "the holder could not be found (invalid service name)".into());
    IpcError::PortsExhausted {
        port: "node",
        service: name.to_owned(),
        limit: qos::MAX_NODES,
        holders: format!("attached: {holders}"),
    }
}

/// The error for a service the daemon could not open or create with its settings: if the
/// service exists, who holds it ([`IpcError::ServiceHeld`]); else iceoryx2's reason.
fn create_error<E: std::error::Error + Send + Sync + 'static>(
    name: &str,
    pattern: &'static str,
    messaging: MessagingPattern,
    e: E,
) -> IpcError {
    let exists = ServiceName::new(name).ok().and_then(|n| {
        use iceoryx2::service::Service as _;
        IpcService::details(&n, iceoryx2::config::Config::global_config(), messaging)
            .ok()
            .flatten()
            .map(|_| n)
    });
    match exists {
        Some(n) => IpcError::ServiceHeld {
            service: name.to_owned(),
            pattern,
            problem: format!("{e:?}"),
            holders: service_holders(&n, messaging),
        },
        None => IpcError::Service {
            service: name.to_owned(),
            pattern,
            source: boxed(e),
        },
    }
}

/// The daemon found a foreign-created service whose `setting` is `got` where it needs
/// `want` (the safety-relevant limits are checked exactly, not "at least").
fn check_setting(
    name: &str,
    pattern: &'static str,
    messaging: MessagingPattern,
    setting: &str,
    got: usize,
    want: usize,
) -> Result<(), IpcError> {
    if got == want {
        return Ok(());
    }
    let holders = ServiceName::new(name)
        .map(|n| service_holders(&n, messaging))
        .unwrap_or_else(|_| "unknown".into());
    Err(IpcError::ServiceHeld {
        service: name.to_owned(),
        pattern,
        problem: format!("{setting} is {got}, wlnavd needs {want}"),
        holders,
    })
}

/// A publish-subscribe service: created with the crate's buffer, history and overflow
/// QoS, or opened as it is.
fn pubsub<T: std::fmt::Debug + ZeroCopySend>(
    node: &Node<IpcService>,
    name: &str,
    max_publishers: usize,
    max_subscribers: usize,
    access: Access,
) -> Result<publish_subscribe::PortFactory<IpcService, T, ()>, IpcError> {
    const PATTERN: &str = "publish-subscribe";
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<T>();
    match access {
        Access::Open => builder.open().map_err(|e| {
            use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as E;
            if e == E::DoesNotExist {
                IpcError::NotServed {
                    service: name.to_owned(),
                }
            } else if e == E::ExceedsMaxNumberOfNodes {
                nodes_exhausted(name, MessagingPattern::PublishSubscribe)
            } else {
                IpcError::Service {
                    service: name.to_owned(),
                    pattern: PATTERN,
                    source: boxed(e),
                }
            }
        }),
        Access::Create => {
            let factory = builder
                .max_publishers(max_publishers)
                .max_subscribers(max_subscribers)
                .subscriber_max_buffer_size(qos::SUBSCRIBER_BUFFER)
                .history_size(qos::HISTORY)
                .enable_safe_overflow(true)
                .max_nodes(qos::MAX_NODES)
                .open_or_create()
                .map_err(|e| create_error(name, PATTERN, MessagingPattern::PublishSubscribe, e))?;
            use iceoryx2::service::port_factory::PortFactory as _;
            check_setting(
                name,
                PATTERN,
                MessagingPattern::PublishSubscribe,
                "max_publishers",
                factory.static_config().max_publishers(),
                max_publishers,
            )?;
            Ok(factory)
        }
    }
}

/// A request-response service of [`GoalRequest`] → [`GoalReply`] (the goal service and
/// the stop service).
fn goal_service(
    node: &Node<IpcService>,
    name: &str,
    max_clients: usize,
    max_active_requests_per_client: usize,
    access: Access,
) -> Result<GoalFactory, IpcError> {
    const PATTERN: &str = "request-response";
    let builder = node
        .service_builder(&service_name(name)?)
        .request_response::<GoalRequest, GoalReply>();
    match access {
        Access::Open => builder.open().map_err(|e| {
            use iceoryx2::service::builder::request_response::RequestResponseOpenError as E;
            if e == E::DoesNotExist {
                IpcError::NotServed {
                    service: name.to_owned(),
                }
            } else if e == E::ExceedsMaxNumberOfNodes {
                nodes_exhausted(name, MessagingPattern::RequestResponse)
            } else {
                IpcError::Service {
                    service: name.to_owned(),
                    pattern: PATTERN,
                    source: boxed(e),
                }
            }
        }),
        Access::Create => {
            let factory = builder
                .max_servers(qos::GOAL_MAX_SERVERS)
                .max_clients(max_clients)
                .max_active_requests_per_client(max_active_requests_per_client)
                .max_nodes(qos::MAX_NODES)
                .open_or_create()
                .map_err(|e| create_error(name, PATTERN, MessagingPattern::RequestResponse, e))?;
            use iceoryx2::service::port_factory::PortFactory as _;
            check_setting(
                name,
                PATTERN,
                MessagingPattern::RequestResponse,
                "max_servers",
                factory.static_config().max_servers(),
                qos::GOAL_MAX_SERVERS,
            )?;
            Ok(factory)
        }
    }
}

/// An event service paired with a data service of the same name.
fn event_service(
    node: &Node<IpcService>,
    name: &str,
    access: Access,
) -> Result<event::PortFactory<IpcService>, IpcError> {
    const PATTERN: &str = "event";
    let builder = node.service_builder(&service_name(name)?).event();
    match access {
        Access::Open => builder.open().map_err(|e| {
            use iceoryx2::service::builder::event::EventOpenError as E;
            if e == E::DoesNotExist {
                IpcError::NotServed {
                    service: name.to_owned(),
                }
            } else if e == E::ExceedsMaxNumberOfNodes {
                nodes_exhausted(name, MessagingPattern::Event)
            } else {
                IpcError::Service {
                    service: name.to_owned(),
                    pattern: PATTERN,
                    source: boxed(e),
                }
            }
        }),
        Access::Create => builder
            .max_listeners(qos::EVENT_MAX_PORTS)
            .max_notifiers(qos::EVENT_MAX_PORTS)
            .max_nodes(qos::MAX_NODES)
            .open_or_create()
            .map_err(|e| create_error(name, PATTERN, MessagingPattern::Event, e)),
    }
}

/// A node (after the optional stale-node clean-up) and its clean-up report.
fn make_node(
    config: &IpcConfig,
    node_name: &str,
) -> Result<(Node<IpcService>, CleanupReport), IpcError> {
    let node_name = NodeName::new(node_name).map_err(|e| IpcError::Node(boxed(e)))?;
    let cleanup = if config.cleanup_stale_nodes {
        cleanup_stale_nodes()?
    } else {
        CleanupReport::default()
    };
    // Signal handling stays with the application (the daemon uses tokio's signals);
    // iceoryx2 must not install its own SIGINT/SIGTERM handlers.
    let node = NodeBuilder::new()
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<IpcService>()
        .map_err(|e| IpcError::Node(boxed(e)))?;
    Ok((node, cleanup))
}

impl Connection {
    fn open(config: &IpcConfig, node_name: &str, access: Access) -> Result<Self, IpcError> {
        let names = config.service_names()?;
        let (node, cleanup) = make_node(config, node_name)?;
        let goal = goal_service(
            &node,
            &names.goal,
            qos::GOAL_MAX_CLIENTS,
            qos::GOAL_MAX_ACTIVE_REQUESTS_PER_CLIENT,
            access,
        )?;
        let pose = pubsub::<PoseEstimate>(
            &node,
            &names.pose,
            qos::POSE_MAX_PUBLISHERS,
            qos::POSE_MAX_SUBSCRIBERS,
            access,
        )?;
        let telemetry = pubsub::<Telemetry>(
            &node,
            &names.telemetry,
            qos::TELEMETRY_MAX_PUBLISHERS,
            qos::TELEMETRY_MAX_SUBSCRIBERS,
            access,
        )?;
        let goal_event = event_service(&node, &names.goal, access)?;
        let pose_event = event_service(&node, &names.pose, access)?;
        let telemetry_event = event_service(&node, &names.telemetry, access)?;
        Ok(Self {
            node,
            names,
            goal,
            goal_event,
            pose,
            pose_event,
            telemetry,
            telemetry_event,
            cleanup,
        })
    }

    fn notifier(
        factory: &event::PortFactory<IpcService>,
        service: &str,
    ) -> Result<Notifier<IpcService>, IpcError> {
        use iceoryx2::port::notifier::NotifierCreateError as E;
        use iceoryx2::service::port_factory::PortFactory as _;
        factory.notifier_builder().create().map_err(|e| {
            if e == E::ExceedsMaxSupportedNotifiers {
                IpcError::PortsExhausted {
                    port: "notifier",
                    service: service.to_owned(),
                    limit: factory.static_config().max_notifiers(),
                    holders: crate::holders::notifier_holders(factory),
                }
            } else {
                IpcError::Port {
                    port: "notifier",
                    service: service.to_owned(),
                    source: boxed(e),
                }
            }
        })
    }

    fn listener(
        factory: &event::PortFactory<IpcService>,
        service: &str,
    ) -> Result<Listener<IpcService>, IpcError> {
        use iceoryx2::port::listener::ListenerCreateError as E;
        use iceoryx2::service::port_factory::PortFactory as _;
        factory.listener_builder().create().map_err(|e| {
            if e == E::ExceedsMaxSupportedListeners {
                IpcError::PortsExhausted {
                    port: "listener",
                    service: service.to_owned(),
                    limit: factory.static_config().max_listeners(),
                    holders: crate::holders::listener_holders(factory),
                }
            } else {
                IpcError::Port {
                    port: "listener",
                    service: service.to_owned(),
                    source: boxed(e),
                }
            }
        })
    }
}

/// A client port on a request-response service of [`GoalRequest`] → [`GoalReply`]; every
/// slot taken is [`IpcError::PortsExhausted`], naming the holders.
fn client_port(factory: &GoalFactory, service: &str) -> Result<GoalClient, IpcError> {
    factory.client_builder().create().map_err(|e| {
        if e == iceoryx2::service::port_factory::client::ClientCreateError::ExceedsMaxSupportedClients {
            use iceoryx2::service::port_factory::PortFactory as _;
            IpcError::PortsExhausted {
                port: "client",
                service: service.to_owned(),
                limit: factory.static_config().max_clients(),
                holders: crate::holders::client_holders(factory),
            }
        } else {
            IpcError::Port {
                port: "client",
                service: service.to_owned(),
                source: boxed(e),
            }
        }
    })
}

/// Removes the resources of iceoryx2 nodes whose process died (crash, `kill -9`). Without
/// this, a crashed daemon's goal server would keep its slot (max one server per prefix)
/// and the restarted daemon could not serve goals. Both endpoints call it before creating
/// their own node (iceoryx2 may also clean on node creation, depending on its config file;
/// doing it explicitly makes the behaviour independent of that and reportable).
/// Idempotent and safe to run concurrently from several processes; it covers all dead
/// nodes of this user on the host, not only wlnav's.
pub fn cleanup_stale_nodes() -> Result<CleanupReport, IpcError> {
    let mut report = CleanupReport::default();
    Node::<IpcService>::list(iceoryx2::config::Config::global_config(), |state| {
        if let iceoryx2::node::NodeState::Dead(view) = state {
            report.dead_nodes_found += 1;
            match view.try_remove_stale_resources() {
                Ok(()) | Err(iceoryx2::node::NodeCleanupFailure::ResourcesAlreadyCleanedUp) => {
                    report.cleaned += 1
                }
                Err(_) => report.failed += 1,
            }
        }
        iceoryx2::prelude::CallbackProgression::Continue
    })
    .map_err(|e| IpcError::NodeList(boxed(e)))?;
    Ok(report)
}

/// Which event sources woke [`DaemonEndpoint::wait`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Wakeup {
    /// Goal requests may be waiting: call [`DaemonEndpoint::receive_goal`] until `None`.
    pub goal: bool,
    /// Poses may be waiting: call [`DaemonEndpoint::latest_pose`].
    pub pose: bool,
    /// Stop requests may be waiting: call [`DaemonEndpoint::receive_stop`] until `None`.
    pub stop: bool,
}

impl Wakeup {
    /// True if anything woke the wait (false on timeout or a signal).
    pub fn any(&self) -> bool {
        self.goal || self.pose || self.stop
    }
}

/// Waits until one of the file descriptors is readable or `timeout` passes. Returns which
/// were readable; an interrupting signal counts as a timeout (callers loop anyway).
fn poll_fds(fds: &[RawFd], timeout: Option<Duration>) -> Result<Vec<bool>, std::io::Error> {
    let mut pfds: Vec<libc::pollfd> = fds
        .iter()
        .map(|&fd| libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        })
        .collect();
    let timeout_ms: libc::c_int = match timeout {
        None => -1,
        // Round up so a 0.5 ms timeout does not become a busy 0 ms poll.
        Some(t) => t
            .as_micros()
            .div_ceil(1000)
            .try_into()
            .unwrap_or(libc::c_int::MAX),
    };
    // SAFETY: `pfds` is a valid, exclusively borrowed array of `pfds.len()` pollfd structs.
    let rc = unsafe { libc::poll(pfds.as_mut_ptr(), pfds.len() as libc::nfds_t, timeout_ms) };
    if rc < 0 {
        let err = std::io::Error::last_os_error();
        if err.kind() == std::io::ErrorKind::Interrupted {
            return Ok(vec![false; fds.len()]);
        }
        return Err(err);
    }
    Ok(pfds
        .iter()
        .map(|p| p.revents & (libc::POLLIN | libc::POLLERR | libc::POLLHUP) != 0)
        .collect())
}

fn listener_fd(listener: &Listener<IpcService>) -> RawFd {
    // SAFETY: the descriptor stays valid as long as the listener, which the caller owns;
    // we only hand out the number.
    unsafe { listener.file_descriptor().native_handle() }
}

fn drain(listener: &Listener<IpcService>, service: &str) -> Result<(), IpcError> {
    listener
        .try_wait(|_| {})
        .map(|_| ())
        .map_err(|e| IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        })
}

fn notify(notifier: &Notifier<IpcService>, id: usize, service: &str) -> Result<(), IpcError> {
    notifier
        .notify_with_custom_event_id(EventId::new(id))
        .map(|_| ())
        .map_err(|e| IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        })
}

/// The daemon's side: serves goal requests, publishes telemetry, subscribes to poses.
///
/// Typical I/O loop (blocking thread; with tokio wrap [`DaemonEndpoint::goal_event_fd`] and
/// [`DaemonEndpoint::pose_event_fd`] in `AsyncFd` instead of calling `wait`):
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
        Ok(Self {
            conn,
            server,
            goal_notifier,
            goal_listener,
            telemetry_pub,
            telemetry_notifier,
            pose_sub,
            pose_listener,
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
    /// [`ClientError::Dropped`].
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
        self.pose_sub
            .receive()
            .map(|s| s.map(|s| *s.payload()))
            .map_err(|e| IpcError::Receive {
                service: self.conn.names.pose.clone(),
                source: boxed(e),
            })
    }

    /// Drains all pending pose samples and returns the newest, if any. Validity is not
    /// judged here: check [`PoseEstimate::is_usable`] and the timestamp.
    pub fn latest_pose(&self) -> Result<Option<PoseEstimate>, IpcError> {
        let mut latest = None;
        while let Some(p) = self.receive_pose()? {
            latest = Some(p);
        }
        Ok(latest)
    }

    /// Blocks until a goal request or pose notification arrives, or `timeout` passes
    /// (`None`: forever). Consumes the notifications, so read the data afterwards until
    /// empty. Spurious wake-ups are possible (e.g. the goal event service also carries the
    /// daemon's own reply notifications); a signal returns an empty [`Wakeup`].
    pub fn wait(&self, timeout: Option<Duration>) -> Result<Wakeup, IpcError> {
        let ready = poll_fds(
            &[
                listener_fd(&self.goal_listener),
                listener_fd(&self.pose_listener),
                listener_fd(&self.stop_listener),
            ],
            timeout,
        )
        .map_err(|e| IpcError::Event {
            service: self.conn.names.goal.clone(),
            source: boxed(e),
        })?;
        self.drain_events()?;
        Ok(Wakeup {
            goal: ready.first().copied().unwrap_or(false),
            pose: ready.get(1).copied().unwrap_or(false),
            stop: ready.get(2).copied().unwrap_or(false),
        })
    }

    /// Consumes pending notifications on both listeners (call after an `AsyncFd` readiness
    /// before reading the data, so the descriptors stop being readable).
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
}

/// A goal request taken from the service, waiting for its answer. Dropping it unanswered
/// tells the client at once ([`ClientError::Dropped`]) rather than after its timeout.
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
        let deadline = Instant::now() + timeout;
        let mut config = config.clone();
        loop {
            match Self::new(&config) {
                Err(IpcError::NotServed { .. }) if Instant::now() < deadline => {
                    // Clean once; the retries need not list the nodes again.
                    config.cleanup_stale_nodes = false;
                    std::thread::sleep(Duration::from_millis(20));
                }
                other => return other,
            }
        }
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
            let publisher = self.conn.pose.publisher_builder().create().map_err(|e| {
                if e == iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers {
                    IpcError::PoseSourceTaken {
                        service: service.clone(),
                        holders: crate::holders::publisher_holders(&self.conn.pose),
                    }
                } else {
                    IpcError::Port {
                        port: "publisher",
                        service: service.clone(),
                        source: boxed(e),
                    }
                }
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

/// Maps a listener wait error: a signal is [`IpcError::Interrupted`] (the caller decides),
/// anything else an event error on `service`.
fn wait_error(e: iceoryx2::port::listener::ListenerWaitError, service: &str) -> IpcError {
    if e == iceoryx2::port::listener::ListenerWaitError::InterruptSignal {
        IpcError::Interrupted
    } else {
        IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        }
    }
}

/// The reply to `pending`, if it has arrived (checked against `request_id`).
fn try_reply(
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
fn wait_reply(
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
enum Attempt {
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
    fn via_stop_service(
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
        self.subscriber
            .receive()
            .map(|s| s.map(|s| *s.payload()))
            .map_err(|e| IpcError::Receive {
                service: self.service.clone(),
                source: boxed(e),
            })
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
        let mut latest = None;
        while let Some(t) = self.try_recv()? {
            latest = Some(t);
        }
        Ok(latest)
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
