//! The factsheet: the machine's physical parameters, the protocol limits the bridge
//! enforces, and the actions it supports. Built as JSON (it is only ever sent) and checked
//! against `factsheet.schema` in the schema tests.

use serde_json::{json, Value};

use crate::config::MachineInfo;
use crate::order::Limits;
use crate::vda::Header;

/// The instant actions the bridge supports, with what each does here.
pub const INSTANT_ACTIONS: [(&str, &str); 6] = [
    (
        "cancelOrder",
        "Drops the order's remaining nodes and stops the machine; FINISHED once at rest.",
    ),
    (
        "startPause",
        "The daemon's operator stop (latched); FINISHED once at rest. State shows paused.",
    ),
    (
        "stopPause",
        "Releases the stop and drives on to the current node.",
    ),
    ("stateRequest", "Publishes the state at once."),
    ("factsheetRequest", "Publishes this factsheet at once."),
    (
        "initPosition",
        "Not supported: the machine's localization owns the pose (FAILED with a reason).",
    ),
];

/// The factsheet message for `header`.
pub fn factsheet(
    header: &Header,
    machine: &MachineInfo,
    limits: &Limits,
    state_interval: f64,
    visualization_interval: f64,
) -> Value {
    let actions: Vec<Value> = INSTANT_ACTIONS
        .iter()
        .map(|(ty, what)| {
            json!({
                "actionType": ty,
                "actionDescription": what,
                // No `blockingTypes`: the 2.0.0 schema puts its enum on the array itself,
                // so no array validates (fleet/schemas/README.md).
                "actionScopes": ["INSTANT"]
            })
        })
        .collect();
    json!({
        "headerId": header.header_id,
        "timestamp": header.timestamp,
        "version": header.version,
        "manufacturer": header.manufacturer,
        "serialNumber": header.serial_number,
        "typeSpecification": {
            "seriesName": machine.series_name,
            "seriesDescription": "Articulated-frame wheel loader, goal-conditioned actor-critic MPC (wlnavd). Kinematics: articulated steering, nearest enum value THREEWHEEL (steered, not on the spot).",
            "agvKinematic": "THREEWHEEL",
            "agvClass": "CARRIER",
            "maxLoadMass": machine.max_load_mass,
            "localizationTypes": ["NATURAL"],
            "navigationTypes": ["AUTONOMOUS"]
        },
        "physicalParameters": {
            "speedMin": 0.0,
            "speedMax": machine.speed_max,
            "accelerationMax": machine.acceleration_max,
            "decelerationMax": machine.deceleration_max,
            "heightMin": machine.height,
            "heightMax": machine.height,
            "width": machine.width,
            "length": machine.length
        },
        "protocolLimits": {
            "maxStringLens": {
                "msgLen": limits.max_message_len,
                "idLen": limits.max_id_len,
                "idNumericalOnly": false
            },
            "maxArrayLens": {
                "order.nodes": limits.max_nodes,
                "order.edges": limits.max_nodes.saturating_sub(1),
                "node.actions": 0,
                "edge.actions": 0,
                "instantActions": limits.max_instant_actions
            },
            "timing": {
                "minOrderInterval": 0.2,
                "minStateInterval": 0.1,
                "defaultStateInterval": state_interval,
                "visualizationInterval": visualization_interval
            }
        },
        "protocolFeatures": {
            "optionalParameters": [
                {"parameter": "order.nodes.nodePosition", "support": "REQUIRED",
                 "description": "Every node needs a position; its mapId must be the daemon's site id, as agvPosition.mapId reports it."},
                {"parameter": "order.nodes.nodePosition.allowedDeviationXY", "support": "SUPPORTED",
                 "description": "> 0 on an intermediate node: passed without stopping within it. 0 or absent: the daemon's own reach test (the machine stops)."},
                {"parameter": "order.nodes.nodePosition.allowedDeviationTheta", "support": "SUPPORTED"},
                {"parameter": "order.nodes.nodePosition.theta", "support": "SUPPORTED",
                 "description": "Absent: the heading of the way from the previous node."}
            ],
            "agvActions": actions
        },
        "agvGeometry": {},
        "loadSpecification": {}
    })
}
