//! Service names and connection settings.

use crate::error::IpcError;

/// The default service-name prefix.
pub const DEFAULT_PREFIX: &str = "wlnav";
/// The wire-format version embedded in every service name. Bumped whenever a payload
/// layout changes, so an old peer fails to find the service instead of misreading bytes
/// (v2: goal outcomes, subgoal and route in telemetry, resume request, footprint reject
/// codes).
pub const API_VERSION: &str = "v2";

/// The service names for one prefix. Each name is used twice: once for the data
/// service (request-response or publish-subscribe) and once for its paired event service;
/// iceoryx2 tells services apart by name *and* messaging pattern.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    /// `{prefix}/v2/goal`: request-response [`crate::GoalRequest`] → [`crate::GoalReply`],
    /// plus event.
    pub goal: String,
    /// `{prefix}/v2/pose`: publish-subscribe [`crate::PoseEstimate`], plus event.
    pub pose: String,
    /// `{prefix}/v2/telemetry`: publish-subscribe [`crate::Telemetry`], plus event.
    pub telemetry: String,
    /// `{prefix}/v2/stop`: request-response [`crate::GoalRequest`] (kind stop only) →
    /// [`crate::GoalReply`], plus event: the reserved stop path (see
    /// [`crate::StopClient`]).
    pub stop: String,
    /// `{prefix}/v2/obstacles`: publish-subscribe [`crate::LiveObstacleSet`] (one
    /// publisher: perception; the daemon subscribes), plus event.
    pub obstacles: String,
}

impl ServiceNames {
    /// The names for `prefix`, after checking the prefix (see [`validate_prefix`]).
    pub fn new(prefix: &str) -> Result<Self, IpcError> {
        validate_prefix(prefix)?;
        Ok(Self {
            goal: format!("{prefix}/{API_VERSION}/goal"),
            pose: format!("{prefix}/{API_VERSION}/pose"),
            telemetry: format!("{prefix}/{API_VERSION}/telemetry"),
            stop: format!("{prefix}/{API_VERSION}/stop"),
            obstacles: format!("{prefix}/{API_VERSION}/obstacles"),
        })
    }
}

/// Longest accepted prefix; keeps the longest service name well inside iceoryx2's limit.
pub const MAX_PREFIX_LEN: usize = 128;

/// Checks a service-name prefix: 1–128 characters from `[A-Za-z0-9_.-/]`, not starting or
/// ending with `/` and without `//`. The restriction keeps names portable across iceoryx2's
/// file-based backends and unambiguous for other-language peers.
pub fn validate_prefix(prefix: &str) -> Result<(), IpcError> {
    let bad = |why: &'static str| IpcError::InvalidPrefix {
        prefix: prefix.to_owned(),
        why,
    };
    if prefix.is_empty() {
        return Err(bad("it is empty"));
    }
    if prefix.len() > MAX_PREFIX_LEN {
        return Err(bad("it is longer than 128 bytes"));
    }
    if !prefix
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/'))
    {
        return Err(bad("only ASCII letters, digits and _ - . / are allowed"));
    }
    if prefix.starts_with('/') || prefix.ends_with('/') || prefix.contains("//") {
        return Err(bad("it must not start or end with '/' or contain '//'"));
    }
    Ok(())
}

/// How to connect: which prefix, and whether to clean up after crashed processes first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IpcConfig {
    /// Service-name prefix; different prefixes never see each other's messages.
    pub prefix: String,
    /// Remove the shared-memory leftovers of dead iceoryx2 nodes at start-up (iceoryx2 has no
    /// central daemon, so a crashed process's resources stay until someone cleans them).
    pub cleanup_stale_nodes: bool,
}

impl IpcConfig {
    /// Settings for `prefix`, with stale-node clean-up on.
    pub fn new(prefix: impl Into<String>) -> Self {
        Self {
            prefix: prefix.into(),
            cleanup_stale_nodes: true,
        }
    }

    /// The service names of this configuration.
    pub fn service_names(&self) -> Result<ServiceNames, IpcError> {
        ServiceNames::new(&self.prefix)
    }
}

impl Default for IpcConfig {
    fn default() -> Self {
        Self::new(DEFAULT_PREFIX)
    }
}
