//! The node and the goal, pose, telemetry, obstacle and stop services, opened or created with the
//! crate's QoS ([`qos`]); when that fails, who holds them. Also the start-up clean-up of
//! dead nodes, and the port constructors the endpoints share.

use iceoryx2::node::node_name::NodeName;
use iceoryx2::node::{Node, NodeBuilder};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{ServiceName, ZeroCopySend};
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use iceoryx2::signal_handling_mode::SignalHandlingMode;

use super::{boxed, qos, GoalClient, GoalFactory, IpcService};
use crate::config::{IpcConfig, ServiceNames};
use crate::error::IpcError;
use crate::msg::{GoalReply, GoalRequest, LiveObstacleSet, PoseEstimate, Telemetry};

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
pub(super) enum Access {
    /// Open or create with the crate's QoS; refuse a foreign-created service that does
    /// not fit ([`IpcError::ServiceHeld`]).
    Create,
    /// Open only, without requirements (the creator's settings rule); a missing service is
    /// [`IpcError::NotServed`].
    Open,
}

/// The node and the goal, pose, telemetry and obstacle services, opened or created.
/// Shared setup of both endpoints.
pub(super) struct Connection {
    /// Owns the node's registration; ports keep it alive too, this makes it explicit.
    pub(super) node: Node<IpcService>,
    pub(super) names: ServiceNames,
    pub(super) goal: GoalFactory,
    pub(super) goal_event: event::PortFactory<IpcService>,
    pub(super) pose: publish_subscribe::PortFactory<IpcService, PoseEstimate, ()>,
    pub(super) pose_event: event::PortFactory<IpcService>,
    pub(super) telemetry: publish_subscribe::PortFactory<IpcService, Telemetry, ()>,
    pub(super) telemetry_event: event::PortFactory<IpcService>,
    pub(super) obstacles: ObstacleFactory,
    pub(super) obstacles_event: event::PortFactory<IpcService>,
    pub(super) cleanup: CleanupReport,
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

/// The live-obstacle service's port factory.
pub(super) type ObstacleFactory = publish_subscribe::PortFactory<IpcService, LiveObstacleSet, ()>;

/// A publish-subscribe service's limits, as the daemon creates it.
#[derive(Debug, Clone, Copy)]
pub(super) struct PubSubLimits {
    pub(super) max_publishers: usize,
    pub(super) max_subscribers: usize,
    /// The largest buffer a subscriber may ask for.
    pub(super) subscriber_buffer: usize,
}

/// The live-obstacle service's limits ([`qos`]).
pub(super) const OBSTACLE_LIMITS: PubSubLimits = PubSubLimits {
    max_publishers: qos::OBSTACLES_MAX_PUBLISHERS,
    max_subscribers: qos::OBSTACLES_MAX_SUBSCRIBERS,
    subscriber_buffer: qos::OBSTACLES_SUBSCRIBER_BUFFER,
};

/// A publish-subscribe service: created with `limits` and the crate's history and
/// overflow QoS, or opened as it is.
pub(super) fn pubsub<T: std::fmt::Debug + ZeroCopySend>(
    node: &Node<IpcService>,
    name: &str,
    limits: PubSubLimits,
    access: Access,
) -> Result<publish_subscribe::PortFactory<IpcService, T, ()>, IpcError> {
    let PubSubLimits {
        max_publishers,
        max_subscribers,
        subscriber_buffer,
    } = limits;
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
                .subscriber_max_buffer_size(subscriber_buffer)
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

/// The publisher of a service that admits one (poses, live obstacles): the slot taken is
/// `taken(service, holders)`, naming the process that holds it.
pub(super) fn single_publisher<T: std::fmt::Debug + ZeroCopySend>(
    factory: &publish_subscribe::PortFactory<IpcService, T, ()>,
    service: &str,
    taken: impl FnOnce(String, String) -> IpcError,
) -> Result<iceoryx2::port::publisher::Publisher<IpcService, T, ()>, IpcError> {
    factory.publisher_builder().create().map_err(|e| {
        if e == iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers {
            taken(
                service.to_owned(),
                crate::holders::publisher_holders(factory),
            )
        } else {
            IpcError::Port {
                port: "publisher",
                service: service.to_owned(),
                source: boxed(e),
            }
        }
    })
}

/// A request-response service of [`GoalRequest`] → [`GoalReply`] (the goal service and
/// the stop service).
pub(super) fn goal_service(
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
pub(super) fn event_service(
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
pub(super) fn make_node(
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
    pub(super) fn open(
        config: &IpcConfig,
        node_name: &str,
        access: Access,
    ) -> Result<Self, IpcError> {
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
            PubSubLimits {
                max_publishers: qos::POSE_MAX_PUBLISHERS,
                max_subscribers: qos::POSE_MAX_SUBSCRIBERS,
                subscriber_buffer: qos::SUBSCRIBER_BUFFER,
            },
            access,
        )?;
        let telemetry = pubsub::<Telemetry>(
            &node,
            &names.telemetry,
            PubSubLimits {
                max_publishers: qos::TELEMETRY_MAX_PUBLISHERS,
                max_subscribers: qos::TELEMETRY_MAX_SUBSCRIBERS,
                subscriber_buffer: qos::SUBSCRIBER_BUFFER,
            },
            access,
        )?;
        let obstacles =
            pubsub::<LiveObstacleSet>(&node, &names.obstacles, OBSTACLE_LIMITS, access)?;
        let goal_event = event_service(&node, &names.goal, access)?;
        let pose_event = event_service(&node, &names.pose, access)?;
        let telemetry_event = event_service(&node, &names.telemetry, access)?;
        let obstacles_event = event_service(&node, &names.obstacles, access)?;
        Ok(Self {
            node,
            names,
            goal,
            goal_event,
            pose,
            pose_event,
            telemetry,
            telemetry_event,
            obstacles,
            obstacles_event,
            cleanup,
        })
    }

    pub(super) fn notifier(
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

    pub(super) fn listener(
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
pub(super) fn client_port(factory: &GoalFactory, service: &str) -> Result<GoalClient, IpcError> {
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
