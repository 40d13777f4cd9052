//! Who holds a service's ports: the text every "slots taken" and "already served" error
//! carries, so a field engineer knows which process to stop (README fault table, rows 7,
//! 8 and 24–26).
//!
//! iceoryx2 records, for every port of a service, the id of the node that created it
//! (`dynamic_config().list_clients(..)` etc.), and for every node its name, process id and
//! executable (`Node::list`). Matching the two names the holder. A node whose details
//! cannot be read (another user's, or removed meanwhile) is reported as such: "the holder
//! could not be found".

use std::collections::BTreeMap;

use crate::endpoint::IpcService;
use crate::msg::{GoalReply, GoalRequest, PoseEstimate, Telemetry};
use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

type GoalFactory = request_response::PortFactory<IpcService, GoalRequest, (), GoalReply, ()>;

/// The node ids of a service's ports of one kind, with their count.
type Counts = BTreeMap<u128, usize>;

/// One node as a reader needs it: `node "squatter" (pid 4711, squat-helper)`.
fn describe_node(state: &NodeState<IpcService>) -> Option<(u128, String)> {
    let (view_id, details, dead) = match state {
        NodeState::Alive(v) => (v.id().value(), v.details().clone(), false),
        NodeState::Dead(v) => (v.id().value(), v.details().clone(), true),
        NodeState::Inaccessible(id) => {
            return Some((
                id.value(),
                "a node of another user (details not readable)".into(),
            ))
        }
        NodeState::Undefined(id) => {
            return Some((id.value(), "a node in an undefined state".into()))
        }
    };
    let text = match details {
        Some(d) => {
            let pid = d.process_id().value();
            format!(
                "{}node {:?} (pid {pid}, {})",
                if dead { "dead " } else { "" },
                d.name().to_string(),
                executable(pid, &d.executable().to_string())
            )
        }
        None => format!(
            "a {} node without details",
            if dead { "dead" } else { "live" }
        ),
    };
    Some((view_id, text))
}

/// The executable's full path from `/proc` when the process is alive and readable, else
/// the file name iceoryx2 recorded.
fn executable(pid: i32, recorded: &str) -> String {
    match std::fs::read_link(format!("/proc/{pid}/exe")) {
        Ok(path) => path.display().to_string(),
        Err(_) => recorded.to_owned(),
    }
}

/// Names the nodes behind `counts` ("16 held by node … (pid …, …)"), or says that they
/// could not be found.
fn name_holders(counts: &Counts, what: &str) -> String {
    if counts.is_empty() {
        return format!(
            "the holder could not be found (iceoryx2 lists no {what}; they may have been \
             released meanwhile)"
        );
    }
    let mut known: BTreeMap<u128, String> = BTreeMap::new();
    let listed = Node::<IpcService>::list(iceoryx2::config::Config::global_config(), |state| {
        if let Some((id, text)) = describe_node(&state) {
            if counts.contains_key(&id) {
                known.insert(id, text);
            }
        }
        CallbackProgression::Continue
    });
    let mut parts: Vec<String> = counts
        .iter()
        .map(|(id, n)| {
            let who = known
                .get(id)
                .cloned()
                .unwrap_or_else(|| format!("node id {id:x}, whose process could not be found"));
            format!("{n} held by {who}")
        })
        .collect();
    if let Err(e) = listed {
        parts.push(format!("(listing the nodes failed: {e:?})"));
    }
    parts.join("; ")
}

fn count(counts: &mut Counts, id: u128) -> CallbackProgression {
    *counts.entry(id).or_default() += 1;
    CallbackProgression::Continue
}

/// Who holds the client ports of a request-response service.
pub(crate) fn client_holders(factory: &GoalFactory) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_clients(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "client ports")
}

/// Who holds the server port(s) of a request-response service.
pub(crate) fn server_holders(factory: &GoalFactory) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_servers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "server ports")
}

/// Who holds the publishers of a publish-subscribe service.
pub(crate) fn publisher_holders(
    factory: &publish_subscribe::PortFactory<IpcService, PoseEstimate, ()>,
) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_publishers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "publishers")
}

/// Who holds the subscribers of a publish-subscribe service.
pub(crate) fn subscriber_holders(
    factory: &publish_subscribe::PortFactory<IpcService, Telemetry, ()>,
) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_subscribers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "subscribers")
}

/// Who holds the notifiers of an event service.
pub(crate) fn notifier_holders(factory: &event::PortFactory<IpcService>) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_notifiers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "notifiers")
}

/// Who holds the listeners of an event service.
pub(crate) fn listener_holders(factory: &event::PortFactory<IpcService>) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_listeners(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "listeners")
}
