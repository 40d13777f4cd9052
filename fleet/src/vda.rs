//! VDA 5050 2.0.0 messages: the project's own serde types.
//!
//! Written from the official JSON schemas (`fleet/schemas/`, see its README for their
//! provenance), not from `vda5050-types`, which gets the wire wrong in several places. What
//! these types get right, and the schema tests (`tests/schemas.rs`) check:
//!
//! * instant actions travel under the key `actions`;
//! * the connection state `CONNECTIONBROKEN` is one word;
//! * `allowedDeviationXY` has a capital `Y`;
//! * an action parameter's `value` is any JSON value (array, boolean, number, string,
//!   object);
//! * optional fields are `Option` and optional arrays default to empty when absent;
//! * `None` is left out of the JSON (never `null`, which the schemas refuse).
//!
//! Field names are the specification's (camelCase); units are metres, radians, seconds.

use serde::{Deserialize, Serialize};

/// The protocol version this bridge speaks (sent in every header).
pub const PROTOCOL_VERSION: &str = "2.0.0";
/// The major version in topic names (`uagv/v2/...`).
pub const TOPIC_VERSION: &str = "v2";

/// The header every message carries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Header {
    /// Per topic and sender, incremented by one per message.
    pub header_id: u64,
    /// ISO 8601 UTC, e.g. `2017-04-15T11:40:03.12Z`.
    pub timestamp: String,
    /// Protocol version `[Major].[Minor].[Patch]`.
    pub version: String,
    /// Manufacturer of the vehicle.
    pub manufacturer: String,
    /// Serial number of the vehicle.
    pub serial_number: String,
}

/// `blockingType` of an action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum BlockingType {
    /// May run while driving and with other actions.
    None,
    /// Other actions may run, driving must not.
    Soft,
    /// Nothing else may run.
    Hard,
}

/// One `actionParameters` entry. `value` is any JSON value, as in the schema.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActionParameter {
    /// The parameter's key.
    pub key: String,
    /// Its value: array, boolean, number, string or object.
    pub value: serde_json::Value,
}

/// An action (on a node, an edge, or instant).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Action {
    /// e.g. `cancelOrder`, `startPause`.
    pub action_type: String,
    /// Unique id, to match the action's state.
    pub action_id: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_description: Option<String>,
    /// Whether the vehicle may drive meanwhile.
    pub blocking_type: BlockingType,
    /// Parameters.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub action_parameters: Vec<ActionParameter>,
}

/// `nodePosition` of an order's node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct NodePosition {
    /// x [m] in the map's frame.
    pub x: f64,
    /// y [m].
    pub y: f64,
    /// Absolute orientation at the node [rad], in [−π, π]; absent: any orientation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<f64>,
    /// How far from the node counts as traversed [m]; 0 or absent: the vehicle's own test.
    #[serde(
        default,
        rename = "allowedDeviationXY",
        skip_serializing_if = "Option::is_none"
    )]
    pub allowed_deviation_xy: Option<f64>,
    /// Orientation tolerance [rad]; 0 or absent: the vehicle's own test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allowed_deviation_theta: Option<f64>,
    /// The map the position is in.
    pub map_id: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_description: Option<String>,
}

/// A node of an order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Node {
    /// Node id.
    pub node_id: String,
    /// Even, increasing by 2 along the order; shared with the edges' odd ids.
    pub sequence_id: u64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_description: Option<String>,
    /// Base (true) or horizon (false).
    pub released: bool,
    /// Where the node is (required by this vehicle; its mapId must be the daemon's site id).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_position: Option<NodePosition>,
    /// Actions at the node (required by the schema, may be empty).
    pub actions: Vec<Action>,
}

/// An edge of an order (the fields this bridge reads; unknown fields are ignored).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Edge {
    /// Edge id.
    pub edge_id: String,
    /// Odd, between its nodes' ids.
    pub sequence_id: u64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_description: Option<String>,
    /// Base (true) or horizon (false).
    pub released: bool,
    /// The node the edge starts at.
    pub start_node_id: String,
    /// The node it ends at.
    pub end_node_id: String,
    /// Speed limit on the edge [m/s] (reported, not enforced: the daemon's limits rule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_speed: Option<f64>,
    /// Actions along the edge (required by the schema, may be empty).
    pub actions: Vec<Action>,
}

/// Which order, and which of its updates, a message is about: `order` names the one it
/// carries, `state` the one the vehicle executes (or executed last).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct OrderIds {
    /// Order id, the same across its updates ("" in a state before the first order).
    pub order_id: String,
    /// 0, 1, 2, … per update of one order.
    pub order_update_id: u64,
    /// Zone set (not used by this vehicle).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zone_set_id: Option<String>,
}

/// `order` (master → vehicle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Order {
    /// Header.
    #[serde(flatten)]
    pub header: Header,
    /// orderId, orderUpdateId, zoneSetId.
    #[serde(flatten)]
    pub ids: OrderIds,
    /// Nodes, base then horizon.
    pub nodes: Vec<Node>,
    /// Edges between consecutive nodes.
    pub edges: Vec<Edge>,
}

/// `instantActions` (master → vehicle). The array's key is `actions`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct InstantActions {
    /// Header.
    #[serde(flatten)]
    pub header: Header,
    /// The actions, to start at once.
    pub actions: Vec<Action>,
}

/// `connectionState`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ConnectionState {
    /// Connected.
    Online,
    /// Disconnected in an orderly way.
    Offline,
    /// The broker's last will: the connection broke.
    #[serde(rename = "CONNECTIONBROKEN")]
    ConnectionBroken,
}

/// `connection` (vehicle → master, retained, QoS 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Connection {
    /// Header.
    #[serde(flatten)]
    pub header: Header,
    /// The state.
    pub connection_state: ConnectionState,
}

/// `nodeStates` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct NodeState {
    /// Node id.
    pub node_id: String,
    /// Sequence id.
    pub sequence_id: u64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_description: Option<String>,
    /// Position, as ordered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_position: Option<NodePosition>,
    /// Base or horizon.
    pub released: bool,
}

/// `edgeStates` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct EdgeState {
    /// Edge id.
    pub edge_id: String,
    /// Sequence id.
    pub sequence_id: u64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_description: Option<String>,
    /// Base or horizon.
    pub released: bool,
}

impl From<&Node> for NodeState {
    /// A node of the order as the state lists it while it is still to traverse.
    fn from(n: &Node) -> Self {
        Self {
            node_id: n.node_id.clone(),
            sequence_id: n.sequence_id,
            node_description: n.node_description.clone(),
            node_position: n.node_position.clone(),
            released: n.released,
        }
    }
}

impl From<&Edge> for EdgeState {
    /// An edge of the order as the state lists it while it is still to traverse.
    fn from(e: &Edge) -> Self {
        Self {
            edge_id: e.edge_id.clone(),
            sequence_id: e.sequence_id,
            edge_description: e.edge_description.clone(),
            released: e.released,
        }
    }
}

/// `agvPosition`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct AgvPosition {
    /// x [m] (front-axle centre).
    pub x: f64,
    /// y [m].
    pub y: f64,
    /// Heading of the front body [rad], in (−π, π].
    pub theta: f64,
    /// The map.
    pub map_id: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_description: Option<String>,
    /// False while the daemon has no fresh pose.
    pub position_initialized: bool,
    /// 0..1, optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub localization_score: Option<f64>,
    /// Position uncertainty [m], optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deviation_range: Option<f64>,
}

/// `velocity`, in the vehicle's frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Velocity {
    /// Forward speed [m/s].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vx: Option<f64>,
    /// Sideways speed [m/s].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vy: Option<f64>,
    /// Turn rate [rad/s].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega: Option<f64>,
}

/// `actionStatus`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ActionStatus {
    /// Received, not started.
    Waiting,
    /// Being prepared.
    Initializing,
    /// Running.
    Running,
    /// Paused.
    Paused,
    /// Done.
    Finished,
    /// Could not be done.
    Failed,
}

/// `actionStates` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ActionState {
    /// The action's id.
    pub action_id: String,
    /// Its type.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_type: Option<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_description: Option<String>,
    /// Status.
    pub action_status: ActionStatus,
    /// Why it failed, or its result.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub result_description: Option<String>,
}

/// `batteryState`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct BatteryState {
    /// State of charge [%].
    pub battery_charge: f64,
    /// Voltage [V], optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_voltage: Option<f64>,
    /// Health [%], optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_health: Option<u8>,
    /// Charging.
    pub charging: bool,
    /// Reach [m], optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach: Option<f64>,
}

/// `errorLevel`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ErrorLevel {
    /// The vehicle can go on (e.g. an order was rejected).
    Warning,
    /// The vehicle needs help to go on.
    Fatal,
}

/// `errorReferences` entry.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ErrorReference {
    /// e.g. `orderId`, `nodeId`, `actionId`, `headerId`, `topic`.
    pub reference_key: String,
    /// Its value.
    pub reference_value: String,
}

/// `errors` entry.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Error {
    /// e.g. `validationError`, `orderUpdateError`, `noRouteError`, `noOrderToCancel`.
    pub error_type: String,
    /// What the error refers to.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub error_references: Vec<ErrorReference>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_description: Option<String>,
    /// Level.
    pub error_level: ErrorLevel,
}

impl Error {
    /// An error with references given as (key, value) pairs.
    pub fn new(
        error_type: &str,
        level: ErrorLevel,
        description: impl Into<String>,
        references: &[(&str, &str)],
    ) -> Self {
        Self {
            error_type: error_type.to_owned(),
            error_references: references
                .iter()
                .map(|(k, v)| ErrorReference {
                    reference_key: (*k).to_owned(),
                    reference_value: (*v).to_owned(),
                })
                .collect(),
            error_description: Some(description.into()),
            error_level: level,
        }
    }
}

/// `safetyState.eStop`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum EStop {
    /// Acknowledged by the vehicle itself.
    Autoack,
    /// Needs a person at the vehicle.
    Manual,
    /// Needs a remote acknowledgement (here: `stopPause`, or `wlnav resume`).
    Remote,
    /// No stop.
    None,
}

/// `safetyState`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct SafetyState {
    /// The stop's acknowledge type.
    pub e_stop: EStop,
    /// A protective field was violated.
    pub field_violation: bool,
}

/// `operatingMode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum OperatingMode {
    /// The master controls the vehicle.
    Automatic,
    /// Partly manual.
    Semiautomatic,
    /// Driven by hand.
    Manual,
    /// Service mode.
    Service,
    /// Teach-in.
    Teachin,
}

/// `state` (vehicle → master).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct State {
    /// Header.
    #[serde(flatten)]
    pub header: Header,
    /// The current or last order and its update ("" and 0 before the first).
    #[serde(flatten)]
    pub ids: OrderIds,
    /// Last node reached ("" if none).
    pub last_node_id: String,
    /// Its sequence id (0 if none).
    pub last_node_sequence_id: u64,
    /// Moving.
    pub driving: bool,
    /// Paused by `startPause` (or an operator stop).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paused: Option<bool>,
    /// Asks for a new base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub new_base_request: Option<bool>,
    /// Distance driven since the last node [m].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_since_last_node: Option<f64>,
    /// Mode.
    pub operating_mode: OperatingMode,
    /// Nodes still to traverse.
    pub node_states: Vec<NodeState>,
    /// Edges still to traverse.
    pub edge_states: Vec<EdgeState>,
    /// Position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_position: Option<AgvPosition>,
    /// Velocity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Velocity>,
    /// Actions and their states.
    pub action_states: Vec<ActionState>,
    /// Battery (see the crate docs: a diesel machine reports a full, non-charging one).
    pub battery_state: BatteryState,
    /// Errors.
    pub errors: Vec<Error>,
    /// Safety.
    pub safety_state: SafetyState,
}

/// `visualization` (vehicle → master, at a high rate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Visualization {
    /// Header.
    #[serde(flatten)]
    pub header: Header,
    /// Position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agv_position: Option<AgvPosition>,
    /// Velocity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Velocity>,
}

/// The current UTC time as the specification writes it: `YYYY-MM-DDTHH:MM:SS.mmmZ`.
pub fn timestamp_now() -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    format_timestamp(now.as_secs() as i64, now.subsec_millis())
}

/// `secs` since the Unix epoch and `millis` as ISO 8601 UTC with milliseconds.
pub fn format_timestamp(secs: i64, millis: u32) -> String {
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    // Civil from days (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_iso8601_utc() {
        assert_eq!(format_timestamp(0, 0), "1970-01-01T00:00:00.000Z");
        assert_eq!(
            format_timestamp(1_492_256_403, 120),
            "2017-04-15T11:40:03.120Z"
        );
        assert_eq!(format_timestamp(951_782_400, 5), "2000-02-29T00:00:00.005Z");
    }

    #[test]
    fn wire_names_follow_the_schema() {
        let c = serde_json::to_value(ConnectionState::ConnectionBroken).unwrap();
        assert_eq!(c, "CONNECTIONBROKEN");
        let p = NodePosition {
            x: 1.0,
            y: 2.0,
            theta: None,
            allowed_deviation_xy: Some(0.5),
            allowed_deviation_theta: None,
            map_id: "m".into(),
            map_description: None,
        };
        let v = serde_json::to_value(&p).unwrap();
        assert_eq!(v["allowedDeviationXY"], 0.5);
        // None is left out, never null.
        assert!(v.get("theta").is_none());
        let ia: InstantActions = serde_json::from_value(serde_json::json!({
            "headerId": 1, "timestamp": "x", "version": "2.0.0", "manufacturer": "m",
            "serialNumber": "s",
            "actions": [{"actionType": "t", "actionId": "a", "blockingType": "HARD",
                         "actionParameters": [{"key": "k", "value": [1, {"a": true}]}]}]
        }))
        .unwrap();
        assert_eq!(ia.actions[0].action_parameters[0].value[1]["a"], true);
    }
}
