//! The bridge's messages against the official VDA 5050 2.0.0 JSON schemas (fleet/schemas/),
//! without daemon, bridge or broker: states in every situation the vehicle logic produces,
//! visualization, connection and the factsheet (the schema check is Ajv in one Node.js
//! process, common::schema_errors). The end-to-end tests (bridge.rs) validate every message
//! the running bridge publishes as well.

mod common;

use std::time::Duration;

use serde_json::{json, Value};
use shm_ipc::{fault_flags, AbortReason, GoalOutcome, GoalReply, Mode, RejectCode, Telemetry};
use wlnav_fleet::config::MachineInfo;
use wlnav_fleet::order::{Identity, Limits};
use wlnav_fleet::vda::{self, ConnectionState, Header};
use wlnav_fleet::vehicle::{Effect, Vehicle, VehicleSettings};

use common::assert_valid;

fn header(id: u64) -> Header {
    Header {
        header_id: id,
        timestamp: vda::timestamp_now(),
        version: vda::PROTOCOL_VERSION.into(),
        manufacturer: "wlnav".into(),
        serial_number: "L1".into(),
    }
}

fn vehicle() -> Vehicle {
    Vehicle::new(
        VehicleSettings {
            identity: Identity {
                manufacturer: "wlnav".into(),
                serial_number: "L1".into(),
            },
            limits: Limits::default(),
            map_id: "site".into(),
            first_node_range: 1.0,
            machine: MachineInfo::default(),
        },
        1,
    )
}

fn telemetry(x: f64, v: f64, mode: Mode) -> Telemetry {
    let mut t = Telemetry::ZERO;
    t.mode = mode.code();
    t.state.x_f = x;
    t.state.v_f = v;
    // As the daemon sets it (its default `loop.rest_speed`).
    t.at_rest = u32::from(v.abs() < 0.02);
    t
}

fn state_json(v: &Vehicle) -> Value {
    serde_json::to_value(v.state(header(7))).unwrap()
}

fn order(order_id: &str, update: u64, nodes: &[(&str, u64, f64, bool)]) -> Vec<u8> {
    let ns: Vec<_> = nodes
        .iter()
        .map(|(id, seq, x, rel)| json!({"nodeId": id, "sequenceId": seq, "released": rel, "actions": [],
            "nodePosition": {"x": x, "y": 0.0, "theta": 0.0, "mapId": "site", "allowedDeviationXY": 0.5, "allowedDeviationTheta": 0.5}}))
        .collect();
    let es: Vec<_> = nodes
        .windows(2)
        .map(|w| json!({"edgeId": format!("{}{}", w[0].0, w[1].0), "sequenceId": w[0].1 + 1, "released": w[1].3,
            "startNodeId": w[0].0, "endNodeId": w[1].0, "actions": [], "maxSpeed": 1.0}))
        .collect();
    let o = json!({"headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.0.0", "manufacturer": "wlnav",
           "serialNumber": "L1", "orderId": order_id, "orderUpdateId": update, "nodes": ns, "edges": es});
    assert_valid("order", &o);
    o.to_string().into_bytes()
}

fn instant(actions: &[(&str, &str)]) -> Vec<u8> {
    let a: Vec<_> = actions
        .iter()
        .map(|(ty, id)| {
            json!({"actionType": ty, "actionId": id, "blockingType": "HARD",
            "actionParameters": [{"key": "k", "value": [1, "x", {"o": true}]}]})
        })
        .collect();
    let m = json!({"headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.0.0", "manufacturer": "wlnav",
           "serialNumber": "L1", "actions": a});
    assert_valid("instantActions", &m);
    m.to_string().into_bytes()
}

#[test]
fn states_in_every_situation_match_the_schema() {
    let t0 = Duration::ZERO;
    let mut v = vehicle();
    // Before any daemon: an error, no position; an order refused (no telemetry yet).
    assert_valid("state", &state_json(&v));
    v.on_order(&order("early", 0, &[("A", 0, 0.0, true)]), t0);
    assert_valid("state", &state_json(&v));
    v.on_telemetry(&telemetry(0.0, 0.0, Mode::Idle), t0);
    assert_valid("state", &state_json(&v));
    // Every kind of rejection (a node on another map too).
    let north = String::from_utf8(order("north", 0, &[("A", 0, 0.0, true)]))
        .unwrap()
        .replace("\"mapId\":\"site\"", "\"mapId\":\"north\"");
    v.on_order(north.as_bytes(), t0);
    v.on_order(b"garbage", t0);
    v.on_order(&order("far", 0, &[("X", 0, 30.0, true)]), t0);
    v.on_instant_actions(
        &instant(&[("cancelOrder", "c0"), ("initPosition", "i"), ("dance", "d")]),
        t0,
    );
    let s = state_json(&v);
    assert_valid("state", &s);
    assert!(s["errors"].as_array().unwrap().len() >= 5, "{s:#}");
    assert!(
        s["errors"].to_string().contains("mapId \\\"north\\\""),
        "{s:#}"
    );
    // An order with a horizon, driven.
    let fx = v.on_order(
        &order(
            "o",
            0,
            &[
                ("A", 0, 0.0, true),
                ("B", 2, 3.0, true),
                ("C", 4, 6.0, false),
            ],
        ),
        t0,
    );
    let goal = fx
        .iter()
        .find_map(|e| match e {
            Effect::Daemon(r) => Some(*r),
            _ => None,
        })
        .unwrap();
    v.on_reply(goal.request_id, Ok(GoalReply::accept(goal.request_id)), t0);
    v.on_telemetry(&telemetry(1.0, 0.8, Mode::Tracking), t0);
    let s = state_json(&v);
    assert_valid("state", &s);
    assert_eq!(s["nodeStates"].as_array().unwrap().len(), 2);
    assert_eq!(s["driving"], true);
    // Paused, with the stop latched.
    v.on_instant_actions(&instant(&[("startPause", "p")]), t0);
    let mut t = telemetry(1.2, 0.0, Mode::Idle);
    t.fault_flags = fault_flags::STOP_REQUESTED;
    v.on_telemetry(&t, t0);
    let s = state_json(&v);
    assert_valid("state", &s);
    assert_eq!(s["safetyState"]["eStop"], "REMOTE");
    // A fault and an aborted goal.
    v.on_instant_actions(&instant(&[("stopPause", "r")]), t0);
    let fx = v.on_telemetry(&telemetry(1.2, 0.0, Mode::Idle), t0);
    let goal = fx
        .iter()
        .find_map(|e| match e {
            Effect::Daemon(r) if r.kind == 1 => Some(*r),
            _ => None,
        })
        .unwrap();
    let mut t = telemetry(1.2, 0.0, Mode::Fault);
    t.fault_flags = fault_flags::MACHINE_STATE_STALE | fault_flags::POSE_STALE;
    t.set_outcome(
        goal.request_id,
        GoalOutcome::Aborted,
        AbortReason::Fault,
        3,
        "machine state stale",
    );
    v.on_telemetry(&t, t0);
    let s = state_json(&v);
    assert_valid("state", &s);
    assert_eq!(s["agvPosition"]["positionInitialized"], false);
    // A refused goal, the daemon lost.
    v.on_reply(
        12345,
        Ok(GoalReply::reject(
            12345,
            RejectCode::GoalInCollision,
            "in an obstacle",
        )),
        t0,
    );
    v.on_daemon_lost(t0);
    assert_valid("state", &state_json(&v));
    // Visualization.
    let vis = serde_json::to_value(v.visualization(header(3))).unwrap();
    assert_valid("visualization", &vis);
}

#[test]
fn connection_and_factsheet_match_the_schema() {
    for state in [
        ConnectionState::Online,
        ConnectionState::Offline,
        ConnectionState::ConnectionBroken,
    ] {
        let c = serde_json::to_value(vda::Connection {
            header: header(1),
            connection_state: state,
        })
        .unwrap();
        assert_valid("connection", &c);
    }
    let f = wlnav_fleet::factsheet::factsheet(
        &header(0),
        &MachineInfo::default(),
        &Limits::default(),
        30.0,
        0.2,
    );
    assert_valid("factsheet", &f);
}

#[test]
fn the_schemas_refuse_what_vda5050_types_gets_wrong() {
    // The failures the issue lists, so the schema tests would catch them.
    let ok = json!({"headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.0.0",
        "manufacturer": "m", "serialNumber": "s", "connectionState": "CONNECTIONBROKEN"});
    assert_valid("connection", &ok);
    let mut bad = ok.clone();
    bad["connectionState"] = json!("CONNECTION_BROKEN");
    assert!(!common::is_valid("connection", &bad));
    let ia = json!({"headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.0.0",
        "manufacturer": "m", "serialNumber": "s", "instantActions": []});
    assert!(!common::is_valid("instantActions", &ia));
    // null for an optional field is refused.
    let mut s = serde_json::to_value(vehicle().state(header(1))).unwrap();
    s["paused"] = Value::Null;
    assert!(!common::is_valid("state", &s));
}
