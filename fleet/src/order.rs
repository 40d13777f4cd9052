//! Order logic, pure: checking an incoming message, deciding accept / update / reject
//! (VDA 5050 2.0.0 §6.6, "order handling" flow), stitching updates onto the last base
//! node, node traversal, and the map orders must be on ([`VehicleMap`]). No I/O here;
//! `vehicle.rs` drives it.

use shm_ipc::{normalize_angle, Pose2, Telemetry};

use crate::vda::{self, Edge, ErrorLevel, InstantActions, Node, Order, OrderIds};

/// Limits on what the bridge accepts (also reported in the factsheet).
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// Longest message accepted [bytes].
    pub max_message_len: usize,
    /// Most nodes in one order.
    pub max_nodes: usize,
    /// Longest id (orderId, nodeId, edgeId, actionId) [bytes].
    pub max_id_len: usize,
    /// Most instant actions in one message.
    pub max_instant_actions: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_message_len: 256 * 1024,
            max_nodes: 1000,
            max_id_len: 256,
            max_instant_actions: 64,
        }
    }
}

/// Who this vehicle is: messages for another manufacturer or serial number are refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// `manufacturer` in topics and headers.
    pub manufacturer: String,
    /// `serialNumber` in topics and headers.
    pub serial_number: String,
}

/// The map an order's nodes must be on (their `nodePosition.mapId`), and the one
/// `agvPosition.mapId` reports: the daemon's site, read from its newest telemetry sample
/// (DESIGN §17: the site is the daemon's, the bridge has none of its own).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VehicleMap {
    /// The daemon's loaded site: its id and version.
    Site {
        /// The site's `id`.
        id: String,
        /// The site's `version`.
        version: u64,
    },
    /// The daemon has no site (telemetry's `site_id_len` is 0): the configuration's
    /// `map_id` is the fallback, so the bridge works with a site-less daemon.
    Configured(String),
    /// No telemetry has arrived yet: the map is not known, every order is refused.
    Unknown,
}

impl VehicleMap {
    /// The map for the newest telemetry sample `newest` (`None`: none yet) and the
    /// configuration's `map_id` (`configured`, used only while the daemon has no site).
    pub fn from_telemetry(newest: Option<&Telemetry>, configured: &str) -> Self {
        match newest {
            None => Self::Unknown,
            Some(t) if t.site_id_len == 0 => Self::Configured(configured.to_owned()),
            Some(t) => Self::Site {
                id: t.site_id().to_owned(),
                version: t.site_version,
            },
        }
    }

    /// The map's id (`None` before any telemetry).
    pub fn id(&self) -> Option<&str> {
        match self {
            Self::Site { id, .. } | Self::Configured(id) => Some(id),
            Self::Unknown => None,
        }
    }

    /// Whether node `node_id` with `nodePosition.mapId` = `map_id` is on this map; if not,
    /// why (naming both ids). Unknown (no telemetry yet) is never a match.
    pub fn check_node(&self, node_id: &str, map_id: &str) -> Result<(), String> {
        match self {
            Self::Site { id, .. } | Self::Configured(id) if id == map_id => Ok(()),
            Self::Site { id, version } => Err(format!(
                "node {node_id}: mapId {map_id:?}, but the daemon's site is {id:?} \
                 (version {version})"
            )),
            Self::Configured(id) => Err(format!(
                "node {node_id}: mapId {map_id:?}, but the vehicle's map is {id:?} (the \
                 configuration's map_id: wlnavd has no site loaded)"
            )),
            Self::Unknown => Err(NO_TELEMETRY_YET.to_owned()),
        }
    }
}

/// Why an order is refused before the daemon's first telemetry sample.
pub const NO_TELEMETRY_YET: &str = "no telemetry from wlnavd yet: the daemon's site (the map \
     an order's nodes must be on) and the machine's position are not known";

/// A validation error, with `topic` and whatever of the header could be read as references.
fn validation(topic: &str, what: impl Into<String>, refs: &[(&str, &str)]) -> vda::Error {
    let mut all: Vec<(&str, &str)> = vec![("topic", topic)];
    all.extend_from_slice(refs);
    vda::Error::new("validationError", ErrorLevel::Warning, what, &all)
}

/// Parses `payload` as JSON within the size limit, and checks the header: protocol major
/// version 2, this vehicle's manufacturer and serial number. Returns the raw value too so
/// a later error can name the orderId / headerId.
fn parse_checked<T: serde::de::DeserializeOwned>(
    topic: &str,
    payload: &[u8],
    id: &Identity,
    limits: &Limits,
) -> Result<T, vda::Error> {
    if payload.len() > limits.max_message_len {
        return Err(validation(
            topic,
            format!(
                "message of {} bytes exceeds the limit of {} bytes",
                payload.len(),
                limits.max_message_len
            ),
            &[],
        ));
    }
    let value: serde_json::Value = serde_json::from_slice(payload)
        .map_err(|e| validation(topic, format!("not valid JSON: {e}"), &[]))?;
    let header_id = value.get("headerId").map(|v| v.to_string());
    let order_id = value
        .get("orderId")
        .and_then(|v| v.as_str())
        .map(str::to_owned);
    let mut refs: Vec<(&str, &str)> = Vec::new();
    if let Some(h) = &header_id {
        refs.push(("headerId", h));
    }
    if let Some(o) = &order_id {
        refs.push(("orderId", o));
    }
    let version = value.get("version").and_then(|v| v.as_str()).unwrap_or("");
    if version.split('.').next() != Some("2") {
        return Err(validation(
            topic,
            format!("protocol version {version:?} is not supported (2.x.x is)"),
            &refs,
        ));
    }
    let manufacturer = value.get("manufacturer").and_then(|v| v.as_str());
    let serial = value.get("serialNumber").and_then(|v| v.as_str());
    if manufacturer != Some(id.manufacturer.as_str()) || serial != Some(id.serial_number.as_str()) {
        return Err(validation(
            topic,
            format!(
                "message for {}/{} reached {}/{}",
                manufacturer.unwrap_or("?"),
                serial.unwrap_or("?"),
                id.manufacturer,
                id.serial_number
            ),
            &refs,
        ));
    }
    serde_json::from_value(value).map_err(|e| {
        validation(
            topic,
            format!("does not match the {topic} schema: {e}"),
            &refs,
        )
    })
}

/// Parses and checks an `order`: header, structure and numbers. Anything that fails is a
/// `validationError` (WARNING) naming what is wrong; the order never reaches the daemon.
pub fn parse_order(
    payload: &[u8],
    id: &Identity,
    limits: &Limits,
    map: &VehicleMap,
) -> Result<Order, vda::Error> {
    let order: Order = parse_checked("order", payload, id, limits)?;
    check_order(&order, limits, map)?;
    Ok(order)
}

/// The structural checks of an order (after parsing), and that its nodes are on `map`.
/// Before any telemetry (`map` unknown) a well-formed order is a `noRouteError`
/// ([`NO_TELEMETRY_YET`]), a node on another map a `validationError` naming both ids.
pub fn check_order(order: &Order, limits: &Limits, map: &VehicleMap) -> Result<(), vda::Error> {
    let header_id = order.header.header_id.to_string();
    let update_id = order.ids.order_update_id.to_string();
    let base_refs = [
        ("headerId", header_id.as_str()),
        ("orderId", order.ids.order_id.as_str()),
        ("orderUpdateId", update_id.as_str()),
    ];
    let fail = |what: String, extra: &[(&str, &str)]| {
        let mut refs = base_refs.to_vec();
        refs.extend_from_slice(extra);
        validation("order", what, &refs)
    };
    let bad_id = |s: &str| s.is_empty() || s.len() > limits.max_id_len;
    if bad_id(&order.ids.order_id) {
        return Err(fail(
            format!("orderId must have 1..={} bytes", limits.max_id_len),
            &[],
        ));
    }
    let nodes = &order.nodes;
    let edges = &order.edges;
    if nodes.is_empty() {
        return Err(fail("an order needs at least one node".into(), &[]));
    }
    if nodes.len() > limits.max_nodes {
        return Err(fail(
            format!(
                "{} nodes exceed the limit of {}",
                nodes.len(),
                limits.max_nodes
            ),
            &[],
        ));
    }
    if edges.len() + 1 != nodes.len() {
        return Err(fail(
            format!(
                "{} nodes need {} edges, the order has {}",
                nodes.len(),
                nodes.len() - 1,
                edges.len()
            ),
            &[],
        ));
    }
    if !nodes[0].released {
        return Err(fail("the first node must be released".into(), &[]));
    }
    let first_seq = nodes[0].sequence_id;
    let mut horizon = false;
    for (i, n) in nodes.iter().enumerate() {
        let refs = [("nodeId", n.node_id.as_str())];
        if bad_id(&n.node_id) {
            return Err(fail(
                format!("node {i}: nodeId must have 1..={} bytes", limits.max_id_len),
                &[],
            ));
        }
        let expected = first_seq + 2 * i as u64;
        if n.sequence_id != expected || n.sequence_id % 2 != 0 {
            return Err(fail(
                format!(
                    "node {}: sequenceId {} out of order (expected {expected}: nodes even, \
                     edges odd, consecutive)",
                    n.node_id, n.sequence_id
                ),
                &refs,
            ));
        }
        if n.released && horizon {
            return Err(fail(
                format!("node {}: released after an unreleased node", n.node_id),
                &refs,
            ));
        }
        horizon |= !n.released;
        let Some(p) = &n.node_position else {
            return Err(fail(
                format!(
                    "node {}: nodePosition is required by this vehicle",
                    n.node_id
                ),
                &refs,
            ));
        };
        let finite = p.x.is_finite()
            && p.y.is_finite()
            && p.theta.is_none_or(f64::is_finite)
            && p.allowed_deviation_xy.is_none_or(f64::is_finite)
            && p.allowed_deviation_theta.is_none_or(f64::is_finite);
        if !finite || p.x.abs() > 1e6 || p.y.abs() > 1e6 {
            return Err(fail(
                format!("node {}: position not finite or absurd", n.node_id),
                &refs,
            ));
        }
        if p.theta
            .is_some_and(|t| t.abs() > std::f64::consts::PI + 1e-9)
        {
            return Err(fail(
                format!("node {}: theta outside [-pi, pi]", n.node_id),
                &refs,
            ));
        }
        if p.allowed_deviation_xy.is_some_and(|d| d < 0.0)
            || p.allowed_deviation_theta
                .is_some_and(|d| !(0.0..=std::f64::consts::PI + 1e-9).contains(&d))
        {
            return Err(fail(
                format!("node {}: allowed deviation out of range", n.node_id),
                &refs,
            ));
        }
        if *map != VehicleMap::Unknown {
            if let Err(why) = map.check_node(&n.node_id, &p.map_id) {
                return Err(fail(
                    why,
                    &[("nodeId", n.node_id.as_str()), ("mapId", p.map_id.as_str())],
                ));
            }
        }
        if let Some(a) = n.actions.first() {
            return Err(fail(
                format!(
                    "node {}: action {:?} is not supported by this vehicle (no node actions)",
                    n.node_id, a.action_type
                ),
                &[("nodeId", &n.node_id), ("actionId", &a.action_id)],
            ));
        }
    }
    for (i, e) in edges.iter().enumerate() {
        let refs = [("edgeId", e.edge_id.as_str())];
        if bad_id(&e.edge_id) {
            return Err(fail(
                format!("edge {i}: edgeId must have 1..={} bytes", limits.max_id_len),
                &[],
            ));
        }
        if e.sequence_id != first_seq + 2 * i as u64 + 1 {
            return Err(fail(
                format!(
                    "edge {}: sequenceId {} out of order (expected {})",
                    e.edge_id,
                    e.sequence_id,
                    first_seq + 2 * i as u64 + 1
                ),
                &refs,
            ));
        }
        if e.start_node_id != nodes[i].node_id || e.end_node_id != nodes[i + 1].node_id {
            return Err(fail(
                format!(
                    "edge {} runs {} -> {}, not between its neighbours {} -> {}",
                    e.edge_id,
                    e.start_node_id,
                    e.end_node_id,
                    nodes[i].node_id,
                    nodes[i + 1].node_id
                ),
                &refs,
            ));
        }
        if e.released != nodes[i + 1].released {
            return Err(fail(
                format!(
                    "edge {}: released must match its end node's (base ends with a node)",
                    e.edge_id
                ),
                &refs,
            ));
        }
        if let Some(a) = e.actions.first() {
            return Err(fail(
                format!(
                    "edge {}: action {:?} is not supported by this vehicle (no edge actions)",
                    e.edge_id, a.action_type
                ),
                &[("edgeId", &e.edge_id), ("actionId", &a.action_id)],
            ));
        }
        if e.max_speed.is_some_and(|v| !v.is_finite() || v < 0.0) {
            return Err(fail(format!("edge {}: bad maxSpeed", e.edge_id), &refs));
        }
    }
    if *map == VehicleMap::Unknown {
        return Err(vda::Error::new(
            "noRouteError",
            ErrorLevel::Warning,
            NO_TELEMETRY_YET,
            &base_refs,
        ));
    }
    Ok(())
}

/// Parses and checks an `instantActions` message.
pub fn parse_instant_actions(
    payload: &[u8],
    id: &Identity,
    limits: &Limits,
) -> Result<InstantActions, vda::Error> {
    let msg: InstantActions = parse_checked("instantActions", payload, id, limits)?;
    let header_id = msg.header.header_id.to_string();
    if msg.actions.len() > limits.max_instant_actions {
        return Err(validation(
            "instantActions",
            format!(
                "{} actions exceed the limit of {}",
                msg.actions.len(),
                limits.max_instant_actions
            ),
            &[("headerId", &header_id)],
        ));
    }
    if let Some(a) = msg
        .actions
        .iter()
        .find(|a| a.action_id.is_empty() || a.action_id.len() > limits.max_id_len)
    {
        return Err(validation(
            "instantActions",
            format!(
                "actionId {:?}: 1..={} bytes",
                a.action_id, limits.max_id_len
            ),
            &[("headerId", &header_id)],
        ));
    }
    Ok(msg)
}

/// What to do with a valid order.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// A new order: replace everything; its first node counts as traversed.
    New,
    /// An update of the current order, stitched onto its last base node.
    Update,
    /// The same orderId and orderUpdateId again: already known, ignore.
    Duplicate,
    /// Refused, with the error for the state.
    Reject(vda::Error),
}

/// The current order and how far along it the machine is. Node and edge lists hold the
/// order as merged from all its updates; what is left to drive is everything with a
/// sequenceId above `last_node_sequence_id`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OrderBook {
    /// The current (or last) order's id and update id (empty and 0 before the first), as
    /// the state reports them.
    pub ids: OrderIds,
    /// The last node traversed; empty before the first order.
    pub last_node_id: String,
    /// Its sequenceId.
    pub last_node_sequence_id: u64,
    /// All nodes of the order (merged over updates).
    pub nodes: Vec<Node>,
    /// All edges.
    pub edges: Vec<Edge>,
    /// The order ended with an error (goal aborted or refused by the daemon): nothing more
    /// is driven until an update or a new order.
    pub failed: bool,
}

/// A node the machine is to reach next.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The node's id.
    pub node_id: String,
    /// Its sequenceId.
    pub sequence_id: u64,
    /// The goal pose handed to the daemon (θ: the node's, else the direction of travel).
    pub goal: Pose2,
    /// Passed without stopping, traversed within `allowed_xy` (and `allowed_theta` when the
    /// node has a θ); false: traversed when the daemon reports the goal succeeded.
    pub pass_through: bool,
    /// Allowed position deviation [m] (pass-through only).
    pub allowed_xy: f64,
    /// Allowed heading deviation [rad], `None` when any heading will do.
    pub allowed_theta: Option<f64>,
    /// The node's map: a goal is sent only while it is the daemon's ([`VehicleMap`]).
    pub map_id: String,
}

impl OrderBook {
    /// Nodes still to traverse (base and horizon).
    pub fn remaining_nodes(&self) -> impl Iterator<Item = &Node> {
        let last = self.last_node_sequence_id;
        self.nodes.iter().filter(move |n| n.sequence_id > last)
    }

    /// Edges still to traverse.
    pub fn remaining_edges(&self) -> impl Iterator<Item = &Edge> {
        let last = self.last_node_sequence_id;
        self.edges.iter().filter(move |e| e.sequence_id > last)
    }

    /// True while released nodes remain and the order has not failed: the machine is
    /// executing it.
    pub fn is_active(&self) -> bool {
        !self.failed && self.remaining_nodes().any(|n| n.released)
    }

    /// True if there is anything to cancel: nodes left (base or horizon).
    pub fn has_remaining(&self) -> bool {
        self.remaining_nodes().next().is_some()
    }

    /// The last released node of the order (the end of its base).
    pub fn last_base_node(&self) -> Option<&Node> {
        self.nodes.iter().rev().find(|n| n.released)
    }

    /// The specification's order-handling flow for a valid `order`, given the machine's
    /// pose (`None`: unknown) and how far from the first node a new order may start
    /// (`first_node_range`, or the node's allowedDeviationXY when larger).
    pub fn decide(&self, order: &Order, machine: Option<Pose2>, first_node_range: f64) -> Decision {
        let header_id = order.header.header_id.to_string();
        let update_id = order.ids.order_update_id.to_string();
        let refs = [
            ("headerId", header_id.as_str()),
            ("orderId", order.ids.order_id.as_str()),
            ("orderUpdateId", update_id.as_str()),
        ];
        let first = &order.nodes[0];
        if !self.ids.order_id.is_empty() && order.ids.order_id == self.ids.order_id {
            if order.ids.order_update_id < self.ids.order_update_id {
                return Decision::Reject(vda::Error::new(
                    "orderUpdateError",
                    ErrorLevel::Warning,
                    format!(
                        "orderUpdateId {} is older than the current {}",
                        order.ids.order_update_id, self.ids.order_update_id
                    ),
                    &refs,
                ));
            }
            if order.ids.order_update_id == self.ids.order_update_id {
                return Decision::Duplicate;
            }
            // An update must begin at the current base's last node.
            let stitch_ok = self
                .last_base_node()
                .is_some_and(|b| b.node_id == first.node_id && b.sequence_id == first.sequence_id);
            if !stitch_ok {
                let (id, seq) = self
                    .last_base_node()
                    .map(|b| (b.node_id.clone(), b.sequence_id))
                    .unwrap_or_default();
                return Decision::Reject(vda::Error::new(
                    "orderUpdateError",
                    ErrorLevel::Warning,
                    format!(
                        "the update starts at node {} (sequenceId {}); it must start at the \
                         last base node {id} (sequenceId {seq})",
                        first.node_id, first.sequence_id
                    ),
                    &refs,
                ));
            }
            return Decision::Update;
        }
        // The specification's flow: a new order is refused while the machine still executes
        // one *or waits for an update of its horizon* (base done, horizon left). An order
        // that ended with an error (`failed`) waits for nothing: a new one is welcome.
        if !self.failed && self.has_remaining() {
            let what = if self.is_active() {
                "is still active"
            } else {
                "is still active, waiting for an update of its horizon"
            };
            return Decision::Reject(vda::Error::new(
                "orderUpdateError",
                ErrorLevel::Warning,
                format!(
                    "order {} {what}; cancel it first (cancelOrder) or send an update",
                    self.ids.order_id
                ),
                &refs,
            ));
        }
        let Some(pose) = machine else {
            return Decision::Reject(vda::Error::new(
                "noRouteError",
                ErrorLevel::Warning,
                "the machine's position is not known (no telemetry from wlnavd)",
                &refs,
            ));
        };
        let p = first
            .node_position
            .as_ref()
            .expect("checked: nodes have positions");
        let range = p.allowed_deviation_xy.unwrap_or(0.0).max(first_node_range);
        let d = (p.x - pose.x).hypot(p.y - pose.y);
        if d > range {
            let mut refs = refs.to_vec();
            refs.push(("nodeId", &first.node_id));
            return Decision::Reject(vda::Error::new(
                "noRouteError",
                ErrorLevel::Warning,
                format!(
                    "the first node {} is {d:.2} m from the machine (more than {range:.2} m): \
                     not trivially reachable",
                    first.node_id
                ),
                &refs,
            ));
        }
        Decision::New
    }

    /// Applies an order `decide` accepted.
    pub fn apply(&mut self, order: Order, decision: &Decision) {
        match decision {
            Decision::New => {
                let first = &order.nodes[0];
                self.last_node_id = first.node_id.clone();
                self.last_node_sequence_id = first.sequence_id;
                self.ids = order.ids;
                self.nodes = order.nodes;
                self.edges = order.edges;
                self.failed = false;
            }
            Decision::Update => {
                let stitch = order.nodes[0].sequence_id;
                self.nodes.retain(|n| n.sequence_id < stitch);
                self.edges.retain(|e| e.sequence_id < stitch);
                self.nodes.extend(order.nodes);
                self.edges.extend(order.edges);
                self.ids.order_update_id = order.ids.order_update_id;
                self.failed = false;
            }
            Decision::Duplicate | Decision::Reject(_) => {}
        }
    }

    /// The next released node to drive to, or `None` when the base is done (or failed).
    /// `from` is where the machine is, for the heading of a node without θ.
    pub fn target(&self, from: Pose2) -> Option<Target> {
        if self.failed {
            return None;
        }
        let mut remaining = self.remaining_nodes().filter(|n| n.released);
        let node = remaining.next()?;
        let is_last_released = remaining.next().is_none();
        let p = node.node_position.as_ref()?;
        // Heading when the node gives none: the direction from the previous node (or the
        // machine, right at the start) to this one.
        let prev = self
            .nodes
            .iter()
            .rev()
            .find(|n| n.sequence_id < node.sequence_id)
            .and_then(|n| n.node_position.as_ref())
            .map(|q| (q.x, q.y))
            .unwrap_or((from.x, from.y));
        let heading = match p.theta {
            Some(t) => t,
            None => {
                let (dx, dy) = (p.x - prev.0, p.y - prev.1);
                if dx.hypot(dy) > 1e-6 {
                    dy.atan2(dx)
                } else {
                    from.heading
                }
            }
        };
        let xy = p.allowed_deviation_xy.unwrap_or(0.0);
        let theta_tol = p.allowed_deviation_theta.unwrap_or(0.0);
        let pass_through = !is_last_released && xy > 0.0 && (p.theta.is_none() || theta_tol > 0.0);
        Some(Target {
            node_id: node.node_id.clone(),
            sequence_id: node.sequence_id,
            goal: Pose2::new(p.x, p.y, normalize_angle(heading)),
            pass_through,
            allowed_xy: xy,
            allowed_theta: p.theta.map(|_| theta_tol),
            map_id: p.map_id.clone(),
        })
    }

    /// Marks `sequence_id` (the current target) traversed.
    pub fn traverse(&mut self, node_id: &str, sequence_id: u64) {
        self.last_node_id = node_id.to_owned();
        self.last_node_sequence_id = sequence_id;
    }

    /// Drops every remaining node and edge (cancelOrder); the order id stays.
    pub fn clear(&mut self) {
        let last = self.last_node_sequence_id;
        self.nodes.retain(|n| n.sequence_id <= last);
        self.edges.retain(|e| e.sequence_id <= last);
        self.failed = false;
    }
}

/// True if a pass-through `target` counts as traversed with the machine at `pose`:
/// within its allowed position deviation, and heading deviation when it has a θ.
pub fn passed(target: &Target, pose: Pose2) -> bool {
    if !target.pass_through {
        return false;
    }
    let d = (pose.x - target.goal.x).hypot(pose.y - target.goal.y);
    let heading_ok = match target.allowed_theta {
        Some(tol) => normalize_angle(pose.heading - target.goal.heading).abs() <= tol,
        None => true,
    };
    d <= target.allowed_xy && heading_ok
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// A node: (nodeId, sequenceId, released, x, y, allowedDeviationXY).
    type N<'a> = (&'a str, u64, bool, f64, f64, f64);

    fn id() -> Identity {
        Identity {
            manufacturer: "wlnav".into(),
            serial_number: "L1".into(),
        }
    }

    /// An order's JSON: `nodes`, and an edge between each two (released as its end node).
    fn order_json(order_id: &str, update: u64, nodes: &[N]) -> serde_json::Value {
        let ns: Vec<_> = nodes
            .iter()
            .map(|(id, seq, released, x, y, dev)| {
                json!({"nodeId": id, "sequenceId": seq, "released": released, "actions": [],
                       "nodePosition": {"x": x, "y": y, "mapId": "site", "allowedDeviationXY": dev}})
            })
            .collect();
        let es: Vec<_> = nodes
            .windows(2)
            .map(|w| {
                json!({"edgeId": format!("{}-{}", w[0].0, w[1].0), "sequenceId": w[0].1 + 1,
                       "released": w[1].2, "startNodeId": w[0].0, "endNodeId": w[1].0,
                       "actions": []})
            })
            .collect();
        json!({"headerId": 1, "timestamp": "2024-01-01T00:00:00.000Z", "version": "2.0.0",
               "manufacturer": "wlnav", "serialNumber": "L1", "orderId": order_id,
               "orderUpdateId": update, "nodes": ns, "edges": es})
    }

    /// The map of a daemon without a site: the configuration's default `map_id`.
    fn fallback() -> VehicleMap {
        VehicleMap::Configured("site".into())
    }

    /// A telemetry sample of a daemon with site `id` version `version` (`None`: no site).
    fn sample(site: Option<(&str, u64)>) -> Telemetry {
        let mut t = Telemetry::ZERO;
        t.set_site(site.map(|(id, version)| (id, version, 0xfeed)));
        t
    }

    fn parse(v: &serde_json::Value) -> Result<Order, vda::Error> {
        parse_order(
            v.to_string().as_bytes(),
            &id(),
            &Limits::default(),
            &fallback(),
        )
    }

    /// A valid order.
    fn order(order_id: &str, update: u64, nodes: &[N]) -> Order {
        parse(&order_json(order_id, update, nodes)).unwrap()
    }

    /// A book holding `nodes` as a new order "o".
    fn book_with(nodes: &[N]) -> OrderBook {
        let mut book = OrderBook::default();
        book.apply(order("o", 0, nodes), &Decision::New);
        book
    }

    fn three_nodes() -> Order {
        order(
            "o1",
            0,
            &[
                ("A", 0, true, 0.0, 0.0, 0.5),
                ("B", 2, true, 3.0, 0.0, 0.5),
                ("C", 4, true, 6.0, 0.0, 0.0),
            ],
        )
    }

    fn err_type(r: Result<Order, vda::Error>) -> (String, String) {
        let e = r.unwrap_err();
        (e.error_type, e.error_description.unwrap_or_default())
    }

    fn rejected_as(d: Decision) -> String {
        match d {
            Decision::Reject(e) => e.error_type,
            d => panic!("not rejected: {d:?}"),
        }
    }

    const A: N = ("A", 0, true, 0.0, 0.0, 0.0);

    #[test]
    fn hostile_orders_are_validation_errors() {
        let limits = Limits::default();
        let p = |b: &[u8]| parse_order(b, &id(), &limits, &fallback());
        assert_eq!(err_type(p(b"{nonsense")).0, "validationError");
        assert_eq!(err_type(p(b"")).0, "validationError");
        // NaN is not JSON; a number beyond f64 is refused by the parser.
        let good = order_json("o", 0, &[A]).to_string();
        assert!(p(good.as_bytes()).is_ok());
        assert!(p(good.replace("\"x\":0.0", "\"x\":NaN").as_bytes()).is_err());
        assert!(p(good.replace("\"x\":0.0", "\"x\":1e999").as_bytes()).is_err());
        let big = vec![b' '; limits.max_message_len + 1];
        assert!(err_type(p(&big)).1.contains("exceeds"));
        let with = |key: &str, value: serde_json::Value| {
            let mut v = order_json("o", 0, &[A]);
            v[key] = value;
            err_type(parse(&v)).1
        };
        assert!(with("version", json!("1.1.0")).contains("version"));
        assert!(with("serialNumber", json!("L2")).contains("L2"));
        // Missing required array.
        let mut v = order_json("o", 0, &[A]);
        v.as_object_mut().unwrap().remove("edges");
        assert!(err_type(parse(&v)).1.contains("schema"));
        // More nodes than the limit.
        let many: Vec<N> = (0..=limits.max_nodes as u64)
            .map(|i| ("n", 2 * i, true, i as f64, 0.0, 0.0))
            .collect();
        assert!(err_type(parse(&order_json("o", 0, &many)))
            .1
            .contains("limit"));
    }

    #[test]
    fn structure_is_checked() {
        let fails = |nodes: &[N], edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v = order_json("o", 0, nodes);
            edit(&mut v);
            let (ty, text) = err_type(parse(&v));
            assert_eq!(ty, "validationError", "{text}");
            text
        };
        let none = |_: &mut serde_json::Value| {};
        // sequenceIds out of order.
        let ab: [N; 2] = [A, ("B", 4, true, 1.0, 0.0, 0.0)];
        assert!(fails(&ab, &none).contains("out of order"));
        // Released after horizon.
        let abc: [N; 3] = [
            A,
            ("B", 2, false, 1.0, 0.0, 0.0),
            ("C", 4, true, 2.0, 0.0, 0.0),
        ];
        assert!(fails(&abc, &none).contains("released after"));
        // Wrong map.
        let map = |v: &mut serde_json::Value| v["nodes"][0]["nodePosition"]["mapId"] = json!("x");
        assert!(fails(&[A], &map).contains("mapId"));
        // Theta out of range, negative deviation.
        let theta = |v: &mut serde_json::Value| v["nodes"][0]["nodePosition"]["theta"] = json!(4.0);
        assert!(fails(&[A], &theta).contains("theta"));
        assert!(fails(&[("A", 0, true, 0.0, 0.0, -1.0)], &none).contains("deviation"));
        // Node actions are not supported.
        let pick = |v: &mut serde_json::Value| {
            v["nodes"][0]["actions"] =
                json!([{"actionType": "pick", "actionId": "p1", "blockingType": "HARD"}])
        };
        assert!(fails(&[A], &pick).contains("pick"));
        // Edge that does not connect its neighbours.
        let ab: [N; 2] = [A, ("B", 2, true, 1.0, 0.0, 0.0)];
        let z = |v: &mut serde_json::Value| v["edges"][0]["endNodeId"] = json!("Z");
        assert!(fails(&ab, &z).contains("not between"));
        // Empty order.
        assert!(fails(&[], &none).contains("at least one node"));
    }

    #[test]
    fn a_new_order_starts_at_a_reachable_first_node() {
        let book = OrderBook::default();
        let o = three_nodes();
        assert_eq!(
            book.decide(&o, Some(Pose2::new(0.3, 0.0, 0.0)), 1.0),
            Decision::New
        );
        let far = book.decide(&o, Some(Pose2::new(5.0, 0.0, 0.0)), 1.0);
        assert_eq!(rejected_as(far), "noRouteError");
        assert_eq!(rejected_as(book.decide(&o, None, 1.0)), "noRouteError");
    }

    #[test]
    fn nodes_are_traversed_in_order_and_the_last_released_one_stops() {
        let mut book = OrderBook::default();
        let o = three_nodes();
        let d = book.decide(&o, Some(Pose2::new(0.0, 0.0, 0.0)), 1.0);
        book.apply(o, &d);
        assert_eq!(book.last_node_id, "A");
        let t = book.target(Pose2::default()).unwrap();
        assert_eq!((t.node_id.as_str(), t.pass_through), ("B", true));
        assert!(!passed(&t, Pose2::new(2.0, 0.0, 0.0)));
        assert!(passed(&t, Pose2::new(2.6, 0.1, 1.0)));
        book.traverse(&t.node_id, t.sequence_id);
        let t = book.target(Pose2::default()).unwrap();
        // The last released node ends at rest: the daemon's success decides.
        assert_eq!((t.node_id.as_str(), t.pass_through), ("C", false));
        assert!(!passed(&t, Pose2::new(6.0, 0.0, 0.0)));
        assert_eq!(book.remaining_edges().count(), 1);
        book.traverse(&t.node_id, t.sequence_id);
        assert!(book.target(Pose2::default()).is_none());
        assert!(!book.is_active());
        assert_eq!(book.remaining_edges().count(), 0);
    }

    #[test]
    fn heading_deviation_counts_only_for_a_node_with_theta() {
        let with_theta = |dev_theta: Option<f64>| {
            let mut v = order_json(
                "o",
                0,
                &[
                    A,
                    ("B", 2, true, 3.0, 0.0, 0.5),
                    ("C", 4, true, 6.0, 0.0, 0.0),
                ],
            );
            v["nodes"][1]["nodePosition"]["theta"] = json!(0.5);
            if let Some(d) = dev_theta {
                v["nodes"][1]["nodePosition"]["allowedDeviationTheta"] = json!(d);
            }
            let mut book = OrderBook::default();
            book.apply(parse(&v).unwrap(), &Decision::New);
            book.target(Pose2::default()).unwrap()
        };
        // θ = 0.5 within 0.2 rad: passed only with the heading within it too.
        let t = with_theta(Some(0.2));
        assert_eq!((t.pass_through, t.allowed_theta), (true, Some(0.2)));
        assert!((t.goal.heading - 0.5).abs() < 1e-12);
        assert!(passed(&t, Pose2::new(2.8, 0.0, 0.6)));
        assert!(!passed(&t, Pose2::new(2.8, 0.0, 0.0)));
        assert!(!passed(&t, Pose2::new(2.8, 0.0, 0.8)));
        // A θ without an allowed heading deviation (absent or 0): the daemon's own test,
        // at rest.
        assert!(!with_theta(None).pass_through);
        assert!(!with_theta(Some(0.0)).pass_through);
    }

    #[test]
    fn heading_without_theta_follows_the_way() {
        let book = book_with(&[A, ("B", 2, true, 0.0, 2.0, 0.0)]);
        let t = book.target(Pose2::default()).unwrap();
        assert!((t.goal.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn a_zero_deviation_node_is_not_passed_through() {
        let book = book_with(&[
            A,
            ("B", 2, true, 2.0, 0.0, 0.0),
            ("C", 4, true, 4.0, 0.0, 0.0),
        ]);
        assert!(!book.target(Pose2::default()).unwrap().pass_through);
    }

    #[test]
    fn horizon_nodes_are_not_driven_and_updates_stitch() {
        let mut book = book_with(&[
            A,
            ("B", 2, true, 3.0, 0.0, 0.5),
            ("C", 4, false, 6.0, 0.0, 0.0),
        ]);
        let t = book.target(Pose2::default()).unwrap();
        // B is the last released node: the machine stops there, C is horizon.
        assert_eq!((t.node_id.as_str(), t.pass_through), ("B", false));
        assert_eq!(book.remaining_nodes().count(), 2);

        // An update that does not start at the last base node is refused.
        let bad = order("o", 1, &[A, ("B", 2, true, 3.0, 0.0, 0.0)]);
        assert_eq!(
            rejected_as(book.decide(&bad, None, 1.0)),
            "orderUpdateError"
        );
        // Stitched at B (still untraversed): B becomes intermediate, passed within 0.5 m.
        let up = order(
            "o",
            1,
            &[
                ("B", 2, true, 3.0, 0.0, 0.5),
                ("C", 4, true, 6.0, 0.0, 0.0),
                ("D", 6, true, 9.0, 0.0, 0.0),
            ],
        );
        assert_eq!(book.decide(&up, None, 1.0), Decision::Update);
        book.apply(up.clone(), &Decision::Update);
        let t = book.target(Pose2::default()).unwrap();
        assert_eq!((t.node_id.as_str(), t.pass_through), ("B", true));
        assert_eq!(book.remaining_nodes().count(), 3);
        assert_eq!(book.remaining_edges().count(), 3);
        // The same update again is a duplicate; an older one an error.
        assert_eq!(book.decide(&up, None, 1.0), Decision::Duplicate);
        let mut old = up.clone();
        old.ids.order_update_id = 0;
        assert_eq!(
            rejected_as(book.decide(&old, None, 1.0)),
            "orderUpdateError"
        );
        // Another order while this one is active.
        let other = order("o2", 0, &[("B", 0, true, 3.0, 0.0, 0.0)]);
        let at_b = Some(Pose2::new(3.0, 0.0, 0.0));
        assert_eq!(
            rejected_as(book.decide(&other, at_b, 1.0)),
            "orderUpdateError"
        );
        // After cancel nothing remains; a new order is welcome.
        book.clear();
        assert!(!book.has_remaining());
        assert_eq!(book.decide(&other, at_b, 1.0), Decision::New);
    }

    #[test]
    fn a_machine_waiting_for_an_update_refuses_another_order() {
        // Base A -> B done, C on the horizon: the machine waits at B for an update.
        let mut book = book_with(&[
            A,
            ("B", 2, true, 3.0, 0.0, 0.0),
            ("C", 4, false, 6.0, 0.0, 0.0),
        ]);
        book.traverse("B", 2);
        assert!(!book.is_active());
        let at_b = Some(Pose2::new(3.0, 0.0, 0.0));
        let other = order("o2", 0, &[("B", 0, true, 3.0, 0.0, 0.0)]);
        let Decision::Reject(e) = book.decide(&other, at_b, 1.0) else {
            panic!("accepted while waiting for an update")
        };
        assert_eq!(e.error_type, "orderUpdateError");
        assert!(e
            .error_description
            .unwrap()
            .contains("waiting for an update"));
        // An order that ended with an error waits for nothing.
        book.failed = true;
        assert_eq!(book.decide(&other, at_b, 1.0), Decision::New);
    }

    #[test]
    fn update_after_the_base_is_done_stitches_at_the_last_node() {
        let mut book = book_with(&[A, ("B", 2, true, 3.0, 0.0, 0.0)]);
        book.traverse("B", 2);
        assert!(!book.is_active());
        let up = order(
            "o",
            1,
            &[("B", 2, true, 3.0, 0.0, 0.0), ("C", 4, true, 6.0, 0.0, 0.0)],
        );
        assert_eq!(book.decide(&up, None, 1.0), Decision::Update);
        book.apply(up, &Decision::Update);
        assert_eq!(book.target(Pose2::default()).unwrap().node_id, "C");
    }

    #[test]
    fn the_map_is_the_daemons_site_else_the_configured_one_else_unknown() {
        // A site loaded: its id, whatever the configuration says.
        let quarry = sample(Some(("quarry", 3)));
        let map = VehicleMap::from_telemetry(Some(&quarry), "site");
        assert_eq!(
            map,
            VehicleMap::Site {
                id: "quarry".into(),
                version: 3
            }
        );
        assert_eq!(map.id(), Some("quarry"));
        // No site (site_id_len 0): the configuration's map_id.
        let bare = sample(None);
        assert_eq!(bare.site_id_len, 0);
        let map = VehicleMap::from_telemetry(Some(&bare), "site");
        assert_eq!(map, VehicleMap::Configured("site".into()));
        assert_eq!(map.id(), Some("site"));
        // No telemetry yet.
        let map = VehicleMap::from_telemetry(None, "site");
        assert_eq!((map.clone(), map.id()), (VehicleMap::Unknown, None));
    }

    #[test]
    fn a_node_must_be_on_the_daemons_site() {
        let quarry = VehicleMap::from_telemetry(Some(&sample(Some(("quarry", 3)))), "site");
        assert_eq!(quarry.check_node("n1", "quarry"), Ok(()));
        assert_eq!(
            quarry.check_node("n2", "north").unwrap_err(),
            "node n2: mapId \"north\", but the daemon's site is \"quarry\" (version 3)"
        );
        // The configured map_id is not a way around the site.
        assert!(quarry
            .check_node("n3", "site")
            .unwrap_err()
            .contains("the daemon's site is \"quarry\""));
        // Without a site: the configured map_id, and the text says so.
        let bare = VehicleMap::from_telemetry(Some(&sample(None)), "site");
        assert_eq!(bare.check_node("n1", "site"), Ok(()));
        let e = bare.check_node("n2", "quarry").unwrap_err();
        assert!(
            e.contains("mapId \"quarry\"")
                && e.contains("\"site\"")
                && e.contains("wlnavd has no site"),
            "{e}"
        );
        // Before telemetry nothing matches.
        assert!(VehicleMap::Unknown
            .check_node("n1", "site")
            .unwrap_err()
            .contains("no telemetry"));
    }

    #[test]
    fn orders_are_checked_against_the_map() {
        let limits = Limits::default();
        let nodes: [N; 3] = [
            A,
            ("n2", 2, true, 3.0, 0.0, 0.0),
            ("n3", 4, false, 6.0, 0.0, 0.0),
        ];
        let on = |maps: [&str; 3]| {
            let mut v = order_json("o", 0, &nodes);
            for (i, m) in maps.iter().enumerate() {
                v["nodes"][i]["nodePosition"]["mapId"] = json!(m);
            }
            v.to_string().into_bytes()
        };
        let quarry = VehicleMap::from_telemetry(Some(&sample(Some(("quarry", 3)))), "site");
        let check = |payload: &[u8], map: &VehicleMap| parse_order(payload, &id(), &limits, map);
        assert!(check(&on(["quarry"; 3]), &quarry).is_ok());
        // One node elsewhere, a horizon node too: refused, naming the node and both ids.
        let e = check(&on(["quarry", "quarry", "north"]), &quarry).unwrap_err();
        assert_eq!(e.error_type, "validationError");
        assert_eq!(
            e.error_description.as_deref(),
            Some("node n3: mapId \"north\", but the daemon's site is \"quarry\" (version 3)")
        );
        assert!(e
            .error_references
            .iter()
            .any(|r| r.reference_key == "nodeId" && r.reference_value == "n3"));
        // The configuration's map_id counts only without a site.
        assert!(check(&on(["site"; 3]), &quarry).is_err());
        assert!(check(&on(["site"; 3]), &fallback()).is_ok());
        assert!(check(&on(["quarry"; 3]), &fallback()).is_err());
        // Before any telemetry: a well-formed order is refused as such; a malformed one is
        // still a validationError.
        let e = check(&on(["quarry"; 3]), &VehicleMap::Unknown).unwrap_err();
        assert_eq!(e.error_type, "noRouteError");
        assert!(e
            .error_description
            .unwrap()
            .contains("no telemetry from wlnavd yet"));
        let e = check(b"{", &VehicleMap::Unknown).unwrap_err();
        assert_eq!(e.error_type, "validationError");
    }
}
