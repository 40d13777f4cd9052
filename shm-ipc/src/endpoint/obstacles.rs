//! The live-obstacle publisher ([`ObstaclePublisher`]): what a perception stack uses to
//! hand the daemon its current set of live obstacles (DESIGN §18).

use core::time::Duration;

use iceoryx2::node::Node;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;

use super::events::notify;
use super::services::{
    event_service, make_node, pubsub, single_publisher, Access, Connection, ObstacleFactory,
    OBSTACLE_LIMITS,
};
use super::{boxed, event_ids, wait_for_daemon, IpcService};
use crate::config::IpcConfig;
use crate::error::IpcError;
use crate::msg::LiveObstacleSet;

/// The one publisher of `{prefix}/v2/obstacles`: publishes [`LiveObstacleSet`]s and wakes
/// the daemon (event id [`event_ids::OBSTACLES`]).
///
/// The service admits **one** publisher, for any perception stack: a second
/// `ObstaclePublisher` on the same prefix is refused with
/// [`IpcError::ObstacleSourceTaken`], naming the process that holds the first. Dropping
/// the publisher frees the slot.
///
/// Each set replaces the previous one as a whole: publish the complete current set, at
/// perception's rate (5–20 Hz), and keep publishing (an empty set when nothing is seen):
/// the daemon stops the machine when the newest set grows too old while it moves. Stamp
/// sets with [`crate::monotonic_now_ns`] at measurement time. The daemon checks every set
/// with [`crate::LiveObstacleValidator`] and drops a set that fails as a whole; check
/// before publishing to learn why.
///
/// ```no_run
/// use shm_ipc::{monotonic_now_ns, IpcConfig, LiveObstacle, LiveObstacleSet, ObstacleClass,
///               ObstaclePublisher};
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let publisher = ObstaclePublisher::new(&IpcConfig::default())?;
/// let now = monotonic_now_ns();
/// let mut set = LiveObstacleSet::empty(now, 0);
/// set.push(LiveObstacle::circle(1, ObstacleClass::Person, [4.0, -2.0], 0.4, [0.0, 1.4], now))?;
/// publisher.publish(&set)?;
/// # Ok(()) }
/// ```
pub struct ObstaclePublisher {
    publisher: Publisher<IpcService, LiveObstacleSet, ()>,
    notifier: Notifier<IpcService>,
    service: String,
    /// The services' factories and the node when standalone ([`ObstaclePublisher::new`]);
    /// the ports keep them alive too, this makes it explicit. `None` when made by a
    /// [`crate::Client`], which holds its own.
    _owned: Option<(
        Node<IpcService>,
        ObstacleFactory,
        iceoryx2::service::port_factory::event::PortFactory<IpcService>,
    )>,
}

impl core::fmt::Debug for ObstaclePublisher {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ObstaclePublisher")
            .field("service", &self.service)
            .finish_non_exhaustive()
    }
}

impl ObstaclePublisher {
    /// Opens the obstacle service the daemon created for `config.prefix` (and nothing
    /// else: no goal client slot is taken) and takes its one publisher slot. Fails with
    /// [`IpcError::NotServed`] when no daemon has created it (see
    /// [`ObstaclePublisher::connect`] to wait for one) and with
    /// [`IpcError::ObstacleSourceTaken`] when another process publishes already.
    pub fn new(config: &IpcConfig) -> Result<Self, IpcError> {
        let names = config.service_names()?;
        let (node, _cleanup) = make_node(config, "wlnav-obstacles")?;
        let factory =
            pubsub::<LiveObstacleSet>(&node, &names.obstacles, OBSTACLE_LIMITS, Access::Open)?;
        let event = event_service(&node, &names.obstacles, Access::Open)?;
        let mut publisher = Self::from_factories(&factory, &event, &names.obstacles)?;
        publisher._owned = Some((node, factory, event));
        Ok(publisher)
    }

    /// Like [`ObstaclePublisher::new`], but waits up to `timeout` for a daemon to create
    /// the service (polling every 20 ms); other errors return at once.
    pub fn connect(config: &IpcConfig, timeout: Duration) -> Result<Self, IpcError> {
        wait_for_daemon(config, timeout, Self::new)
    }

    /// The publisher and its notifier on already opened services.
    pub(super) fn from_factories(
        factory: &ObstacleFactory,
        event: &iceoryx2::service::port_factory::event::PortFactory<IpcService>,
        service: &str,
    ) -> Result<Self, IpcError> {
        let publisher = single_publisher(factory, service, |service, holders| {
            IpcError::ObstacleSourceTaken { service, holders }
        })?;
        let notifier = Connection::notifier(event, service)?;
        Ok(Self {
            publisher,
            notifier,
            service: service.to_owned(),
            _owned: None,
        })
    }

    /// The service name, `{prefix}/v2/obstacles`.
    pub fn service_name(&self) -> &str {
        &self.service
    }

    /// Publishes `set` (a copy; the set is not checked here) and wakes the subscribers
    /// with event id [`event_ids::OBSTACLES`]. Never blocks: an unread older set in a
    /// subscriber's one-set buffer is overwritten.
    pub fn publish(&self, set: &LiveObstacleSet) -> Result<(), IpcError> {
        self.publisher.send_copy(*set).map_err(|e| IpcError::Send {
            service: self.service.clone(),
            source: boxed(e),
        })?;
        notify(&self.notifier, event_ids::OBSTACLES, &self.service)
    }
}
