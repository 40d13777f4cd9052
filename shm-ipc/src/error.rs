//! Error types. iceoryx2's own errors are small enums; they are kept as the boxed `source`
//! so callers can still downcast, while our variants say *which* step failed.

use core::time::Duration;

/// A boxed iceoryx2 error.
pub type BoxedSource = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Setting up or using the shared-memory transport failed.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// The configured service-name prefix is not acceptable.
    #[error("invalid service-name prefix {prefix:?}: {why}")]
    InvalidPrefix {
        /// The prefix given
        prefix: String,
        /// What is wrong with it
        why: &'static str,
    },
    /// iceoryx2 rejected a service name.
    #[error("invalid service name {name:?}: {source}")]
    InvalidServiceName {
        /// The name
        name: String,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// The iceoryx2 node could not be created (permissions on /dev/shm or /tmp/iceoryx2?).
    #[error("cannot create iceoryx2 node: {0}")]
    Node(BoxedSource),
    /// Opening or creating a service failed (e.g. a peer created it with an incompatible
    /// payload type or settings: an old wire version under the same name).
    #[error("cannot open or create service {service:?} ({pattern}): {source}")]
    Service {
        /// Service name
        service: String,
        /// Messaging pattern
        pattern: &'static str,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// The service does not exist: no daemon has created it (the client library only opens
    /// services; `wlnavd` creates them).
    #[error("no daemon serves {service:?} (no such service; is wlnavd running with this prefix?)")]
    NotServed {
        /// Service name
        service: String,
    },
    /// The daemon cannot use a service that another process created before it started
    /// (with settings other than the daemon's). Names the service and the processes
    /// attached to it, so a field engineer knows what to stop.
    #[error(
        "service {service:?} ({pattern}) was created by another process with settings wlnavd \
         cannot use ({problem}); attached: {holders}. Stop those processes (peers must only \
         open the services, never create them) and start wlnavd again"
    )]
    ServiceHeld {
        /// Service name
        service: String,
        /// Messaging pattern
        pattern: &'static str,
        /// What does not fit (iceoryx2's reason, or the setting that differs)
        problem: String,
        /// The processes attached to the service (node name, pid, executable)
        holders: String,
    },
    /// Another process already publishes poses: the pose service admits one publisher.
    #[error(
        "another process already publishes poses on {service:?} (one pose source only): \
         {holders}"
    )]
    PoseSourceTaken {
        /// Service name
        service: String,
        /// The process holding the publisher (node name, pid, executable), or "the holder
        /// could not be found …"
        holders: String,
    },
    /// Another process already publishes live obstacles: the obstacle service admits one
    /// publisher (one perception stack), so two sets never interleave.
    #[error(
        "another process already publishes live obstacles on {service:?} (one publisher, for \
         any perception stack): {holders}"
    )]
    ObstacleSourceTaken {
        /// Service name
        service: String,
        /// The process holding the publisher (node name, pid, executable), or "the holder
        /// could not be found …"
        holders: String,
    },
    /// Another process already serves goals under this prefix.
    #[error(
        "another daemon already serves {service:?} (its server port: {holders}); stop it or \
         use a different prefix"
    )]
    AlreadyServed {
        /// Service name
        service: String,
        /// The process holding the server port (node name, pid, executable), or "the
        /// holder could not be found …"
        holders: String,
    },
    /// Every slot of one port kind on a service is taken (a squatting or leaking process).
    /// Names the processes holding them.
    #[error("cannot create {port} on {service:?}: all {limit} {port} slots are taken ({holders})")]
    PortsExhausted {
        /// Port kind: `client`, `notifier`, `listener`, `subscriber`, `publisher`, `server`,
        /// or `node` (the service's node limit)
        port: &'static str,
        /// Service name
        service: String,
        /// The service's limit for this port kind
        limit: usize,
        /// Who holds them: "N held by node "x" (pid P, /path/exe)", …, or "the holder could
        /// not be found …"
        holders: String,
    },
    /// Creating a port (publisher, subscriber, client, server, notifier, listener) failed,
    /// most often because the service's port limit is reached.
    #[error("cannot create {port} on {service:?}: {source}")]
    Port {
        /// Port kind
        port: &'static str,
        /// Service name
        service: String,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// Sending a message failed.
    #[error("cannot send on {service:?}: {source}")]
    Send {
        /// Service name
        service: String,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// Receiving a message failed.
    #[error("cannot receive on {service:?}: {source}")]
    Receive {
        /// Service name
        service: String,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// Sending or waiting for an event notification failed.
    #[error("event error on {service:?}: {source}")]
    Event {
        /// Service name
        service: String,
        /// iceoryx2's reason
        source: BoxedSource,
    },
    /// Waiting was interrupted by a signal; the caller decides whether to retry.
    #[error("wait interrupted by a signal")]
    Interrupted,
    /// Listing nodes for stale clean-up failed.
    #[error("cannot list iceoryx2 nodes: {0}")]
    NodeList(BoxedSource),
}

/// A client request did not produce a usable reply.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Transport failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// No daemon is serving goals under this prefix.
    #[error("no daemon is serving goals on {service:?}")]
    NoDaemon {
        /// Service name
        service: String,
    },
    /// No reply within the timeout.
    #[error("no reply to request {request_id} within {timeout:?}")]
    Timeout {
        /// The request
        request_id: u64,
        /// The timeout that expired
        timeout: Duration,
    },
    /// The daemon dropped the request without answering (it shut down, or its request
    /// buffer overflowed during a flood).
    #[error("request {request_id} was dropped without a reply")]
    Dropped {
        /// The request
        request_id: u64,
    },
    /// The reply carries a different request id (a misbehaving server).
    #[error("reply for request {got} received while waiting for {expected}")]
    ReplyMismatch {
        /// The id sent
        expected: u64,
        /// The id received
        got: u64,
    },
    /// A stop could be sent neither on the stop service nor on the goal service (the
    /// fallback). Both reasons are given.
    #[error(
        "the stop could not be sent: on the stop service: {stop}; on the goal service: {goal}"
    )]
    StopNotSent {
        /// Why the stop service failed
        stop: Box<ClientError>,
        /// Why the goal service failed
        goal: Box<ClientError>,
    },
    /// More than [`crate::MAX_OBSTACLES`] obstacles were given.
    #[error("{0} obstacles given, at most {max} fit in a request", max = crate::MAX_OBSTACLES)]
    TooManyObstacles(usize),
}
