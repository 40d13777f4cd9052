//! End to end: mosquitto on a free port, `wlnavd --sim` with a private prefix, `wlnav-fleet`,
//! and a test-side master that records every message and validates it against the official
//! schemas. One test at a time (2 cores).

mod common;

use std::time::{Duration, Instant};

use common::*;
use serde_json::Value;

const LONG: Duration = Duration::from_secs(60);

fn node_count(s: &Value) -> usize {
    s["nodeStates"].as_array().map_or(0, Vec::len)
}

fn action_status(s: &Value, id: &str) -> Option<String> {
    s["actionStates"]
        .as_array()?
        .iter()
        .find(|a| a["actionId"] == id)
        .and_then(|a| a["actionStatus"].as_str())
        .map(str::to_owned)
}

/// Waits until the bridge is online and reports the machine in automatic without errors.
fn wait_ready(master: &Master, serial: &str) {
    master.wait_state(
        serial,
        Instant::now() - Duration::from_secs(600),
        LONG,
        "AUTOMATIC without errors",
        |s| {
            s["operatingMode"] == "AUTOMATIC"
                && errors(s).is_empty()
                && s["agvPosition"]["positionInitialized"] == true
        },
    );
}

#[test]
fn an_order_is_driven_node_by_node_then_updated() {
    let _g = serial();
    let broker = Broker::start();
    let master = Master::connect(broker.port);
    let prefix = unique_prefix("order");
    let _daemon = start_daemon(&prefix);
    let mut bridge = start_bridge(&broker.addr(), "L1", &prefix, None);
    wait_ready(&master, "L1");
    // Retained ONLINE and factsheet, as a master connecting later sees them.
    let c = retained(
        broker.port,
        "uagv/v2/wlnav/L1/connection",
        Duration::from_secs(5),
    )
    .expect("retained connection");
    assert_eq!(c["connectionState"], "ONLINE");
    let f = retained(
        broker.port,
        "uagv/v2/wlnav/L1/factsheet",
        Duration::from_secs(5),
    )
    .expect("retained factsheet");
    assert_valid("factsheet", &f);

    // A → B (passed within 0.5 m) → C (stop) | D (horizon).
    let t0 = Instant::now();
    master.order(
        "L1",
        "o1",
        0,
        0,
        &[
            ("A", 0.0, 0.0, 0.0, true),
            ("B", 3.0, 0.0, 0.5, true),
            ("C", 6.0, 0.0, 0.0, true),
            ("D", 9.0, 0.0, 0.0, false),
        ],
    );
    let s = master.wait_state("L1", t0, LONG, "order o1 accepted", |s| {
        s["orderId"] == "o1"
    });
    assert_eq!(s["lastNodeId"], "A");
    assert_eq!(node_count(&s), 3);
    let b = master.wait_state("L1", t0, LONG, "B traversed", |s| s["lastNodeId"] == "B");
    assert_eq!(b["driving"], true, "B is passed without stopping: {b:#}");
    let c = master.wait_state("L1", t0, LONG, "C traversed", |s| s["lastNodeId"] == "C");
    assert_eq!(
        c["driving"], false,
        "the last released node ends at rest: {c:#}"
    );
    let pos = &c["agvPosition"];
    assert!(
        (pos["x"].as_f64().unwrap() - 6.0).hypot(pos["y"].as_f64().unwrap()) < 0.3,
        "{pos}"
    );
    // Only the horizon is left, and the machine waits there.
    assert_eq!(node_count(&c), 1);
    assert_eq!(c["nodeStates"][0]["released"], false);
    assert_eq!(c["edgeStates"].as_array().unwrap().len(), 1);
    std::thread::sleep(Duration::from_millis(700));
    assert_eq!(master.last_state("L1").unwrap()["lastNodeId"], "C");

    // The update stitches at C and releases D.
    let t1 = Instant::now();
    master.order(
        "L1",
        "o1",
        1,
        4,
        &[("C", 6.0, 0.0, 0.0, true), ("D", 9.0, 0.0, 0.0, true)],
    );
    let d = master.wait_state("L1", t1, LONG, "D traversed", |s| {
        s["lastNodeId"] == "D" && node_count(s) == 0
    });
    assert_eq!(d["orderUpdateId"], 1);
    assert!(errors(&d).is_empty(), "{d:#}");
    // Visualization at the tick rate (the simulated daemon ticks at 5 Hz × FAST).
    let vis = master.messages("L1", "visualization");
    let span = vis.last().unwrap().at - vis.first().unwrap().at;
    assert!(
        vis.len() as f64 > span.as_secs_f64() * 5.0,
        "{} visualizations in {span:?}",
        vis.len()
    );

    // A clean exit publishes OFFLINE (retained).
    assert!(
        bridge.terminate(Duration::from_secs(10)),
        "bridge did not exit cleanly:\n{}",
        bridge.log_tail(20)
    );
    let c = retained(
        broker.port,
        "uagv/v2/wlnav/L1/connection",
        Duration::from_secs(5),
    )
    .unwrap();
    assert_eq!(c["connectionState"], "OFFLINE");
    let n = master.check_valid();
    eprintln!("{n} messages, all valid");
}

#[test]
fn bad_orders_and_actions_are_errors_in_state_and_never_reach_the_daemon() {
    let _g = serial();
    let broker = Broker::start();
    let master = Master::connect(broker.port);
    let prefix = unique_prefix("reject");
    let _daemon = start_daemon(&prefix);
    // A site obstacle at (5, 5).
    let mut bridge = start_bridge(
        &broker.addr(),
        "L1",
        &prefix,
        Some("obstacles = [{ x = 5.0, y = 5.0, r = 1.0 }]\n"),
    );
    let telemetry = TelemetryLog::start(&prefix);
    wait_ready(&master, "L1");

    let t0 = Instant::now();
    let good = master
        .order("L1", "probe", 0, 0, &[("A", 0.0, 0.0, 0.0, true)])
        .to_string();
    master.wait_state("L1", t0, LONG, "probe accepted", |s| {
        s["orderId"] == "probe"
    });
    let hostile: Vec<(&str, Vec<u8>, &str)> = vec![
        ("garbage", b"{this is not json".to_vec(), "not valid JSON"),
        (
            "oversized",
            {
                let mut v = good.clone().into_bytes();
                v.extend(std::iter::repeat_n(b' ', 300 * 1024));
                v
            },
            "exceeds the limit",
        ),
        (
            "wrong version",
            good.replace("\"2.0.0\"", "\"3.0.0\"")
                .replace("probe", "h1")
                .into_bytes(),
            "version",
        ),
        (
            "wrong serial",
            good.replace("\"L1\"", "\"L9\"")
                .replace("probe", "h2")
                .into_bytes(),
            "L9",
        ),
        (
            "number beyond f64",
            good.replace("\"x\":0.0", "\"x\":1e999")
                .replace("probe", "h3")
                .into_bytes(),
            "not valid JSON",
        ),
        (
            "NaN",
            good.replace("\"x\":0.0", "\"x\":NaN")
                .replace("probe", "h4")
                .into_bytes(),
            "not valid JSON",
        ),
    ];
    for (what, payload, text) in hostile {
        let t = Instant::now();
        master.publish("L1", "order", payload);
        let s = master.wait_state("L1", t, LONG, what, |s| {
            has_error(s, "validationError", text)
        });
        assert_eq!(s["orderId"], "probe", "{what}");
    }
    // sequenceIds out of order.
    let t = Instant::now();
    master.order("L1", "h5", 0, 1, &[("A", 0.0, 0.0, 0.0, true)]);
    master.wait_state("L1", t, LONG, "sequenceId", |s| {
        has_error(s, "validationError", "out of order")
    });
    // First node out of range.
    let t = Instant::now();
    master.order(
        "L1",
        "far",
        0,
        0,
        &[("F", 20.0, 0.0, 0.0, true), ("G", 22.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t, LONG, "noRouteError", |s| {
        has_error(s, "noRouteError", "not trivially reachable")
    });
    // cancelOrder without an order.
    let t = Instant::now();
    master.instant("L1", &[("cancelOrder", "c0"), ("initPosition", "i0")]);
    let s = master.wait_state("L1", t, LONG, "noOrderToCancel", |s| {
        has_error(s, "noOrderToCancel", "")
    });
    assert_eq!(action_status(&s, "c0").as_deref(), Some("FAILED"));
    let s = master.wait_state("L1", t, LONG, "initPosition failed", |s| {
        action_status(s, "i0").as_deref() == Some("FAILED")
    });
    assert!(s["actionStates"].to_string().contains("localization"));
    // Nothing reached the daemon: no goal in any telemetry sample since the bridge started
    // (every tick seen: no gaps in the tick counter, so no goal can hide between samples).
    // A few more ticks, so a goal sent last would show.
    std::thread::sleep(Duration::from_millis(500));
    let samples = telemetry.samples();
    assert!(samples.len() >= 8, "{} telemetry samples", samples.len());
    for w in samples.windows(2) {
        assert_eq!(w[1].tick, w[0].tick + 1, "telemetry samples missed");
    }
    for tm in &samples {
        assert_eq!(
            (tm.goal_active, tm.goal_request_id),
            (0, 0),
            "a goal reached the daemon at tick {}",
            tm.tick
        );
    }
    let checked = samples.len();
    assert!(bridge.is_running());

    // The daemon's own validation: a node in an obstacle, a node outside the workspace.
    let t = Instant::now();
    master.order(
        "L1",
        "obst",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 5.0, 5.0, 0.0, true)],
    );
    master.wait_state("L1", t, LONG, "goal-in-collision refused", |s| {
        has_error(s, "noRouteError", "wlnavd refused node B")
    });
    let t = Instant::now();
    master.order(
        "L1",
        "ws",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 90000.0, 0.0, 0.0, true)],
    );
    let s = master.wait_state("L1", t, LONG, "out of workspace refused", |s| {
        s["orderId"] == "ws" && has_error(s, "noRouteError", "wlnavd refused node B")
    });
    assert!(s["errors"].to_string().contains("OutOfWorkspace"), "{s:#}");

    // Update rules: another order while one is active, a stale update.
    let t = Instant::now();
    master.order(
        "L1",
        "long",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 8.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t, LONG, "long driving", |s| {
        s["orderId"] == "long" && s["driving"] == true
    });
    // The check above sees goals when there are some.
    assert!(
        telemetry.samples()[checked..]
            .iter()
            .any(|t| t.goal_active == 1 && t.goal_request_id != 0),
        "the telemetry log shows no goal while driving"
    );
    master.order(
        "L1",
        "long",
        2,
        2,
        &[("B", 8.0, 0.0, 0.0, true), ("C", 8.0, 3.0, 0.0, false)],
    );
    let t = Instant::now();
    master.order("L1", "long", 1, 2, &[("B", 8.0, 0.0, 0.0, true)]);
    master.wait_state("L1", t, LONG, "stale update", |s| {
        has_error(s, "orderUpdateError", "older")
    });
    let t = Instant::now();
    master.order("L1", "other", 0, 0, &[("A", 0.0, 0.0, 0.0, true)]);
    master.wait_state("L1", t, LONG, "another order active", |s| {
        has_error(s, "orderUpdateError", "still active")
    });
    // Cancel: RUNNING until at rest, then FINISHED; the nodes are gone.
    let t = Instant::now();
    master.instant("L1", &[("cancelOrder", "c1")]);
    master.wait_state("L1", t, LONG, "cancel running", |s| {
        action_status(s, "c1").is_some()
    });
    let s = master.wait_state("L1", t, LONG, "cancel finished", |s| {
        action_status(s, "c1").as_deref() == Some("FINISHED")
    });
    assert_eq!(s["driving"], false);
    assert_eq!(node_count(&s), 0);
    assert!(master
        .messages("L1", "state")
        .iter()
        .any(|r| r.at >= t && action_status(&r.json, "c1").as_deref() == Some("RUNNING")));
    assert!(bridge.is_running());
    master.check_valid();
}

#[test]
fn broker_restart_keeps_the_order_and_sigkill_leaves_connectionbroken() {
    let _g = serial();
    let mut broker = Broker::start();
    let master = Master::connect(broker.port);
    let prefix = unique_prefix("broker");
    let _daemon = start_daemon(&prefix);
    let mut bridge = start_bridge(&broker.addr(), "L1", &prefix, Some("keep_alive = 2\n"));
    wait_ready(&master, "L1");
    let t0 = Instant::now();
    master.order(
        "L1",
        "keep",
        0,
        0,
        &[
            ("A", 0.0, 0.0, 0.0, true),
            ("B", 2.0, 0.0, 0.0, true),
            ("C", 4.0, 0.0, 0.0, false),
        ],
    );
    master.wait_state("L1", t0, LONG, "B reached", |s| {
        s["lastNodeId"] == "B" && s["driving"] == false
    });
    let online_before = master
        .messages("L1", "connection")
        .iter()
        .filter(|r| r.json["connectionState"] == "ONLINE")
        .map(|r| r.json["headerId"].as_u64().unwrap())
        .max()
        .unwrap();

    let t1 = Instant::now();
    broker.restart(Duration::from_secs(1));
    let online = master.wait_msg("L1", "connection", t1, LONG, |r| {
        r.json["connectionState"] == "ONLINE"
    });
    assert!(
        online.json["headerId"].as_u64().unwrap() > online_before,
        "a fresh headerId on reconnect"
    );
    let s = master.wait_state("L1", t1, LONG, "state after the restart", |_| true);
    assert_eq!(s["orderId"], "keep");
    assert_eq!(s["lastNodeId"], "B");
    assert_eq!(node_count(&s), 1, "the horizon node is kept: {s:#}");
    // The order goes on.
    let t2 = Instant::now();
    master.order(
        "L1",
        "keep",
        1,
        2,
        &[("B", 2.0, 0.0, 0.0, true), ("C", 4.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t2, LONG, "C reached", |s| {
        s["lastNodeId"] == "C" && node_count(s) == 0
    });

    // SIGKILL: the broker publishes the will.
    bridge.kill();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let c = retained(
            broker.port,
            "uagv/v2/wlnav/L1/connection",
            Duration::from_secs(2),
        );
        if c.as_ref()
            .is_some_and(|c| c["connectionState"] == "CONNECTIONBROKEN")
        {
            assert_valid("connection", c.as_ref().unwrap());
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no retained CONNECTIONBROKEN: {c:?}"
        );
    }
    master.check_valid();
}

#[test]
fn a_daemon_restart_is_an_error_then_recovers() {
    let _g = serial();
    let broker = Broker::start();
    let master = Master::connect(broker.port);
    let prefix = unique_prefix("restart");
    let mut daemon = start_daemon(&prefix);
    let _bridge = start_bridge(&broker.addr(), "L1", &prefix, None);
    wait_ready(&master, "L1");
    let t0 = Instant::now();
    assert!(
        daemon.terminate(Duration::from_secs(10)),
        "wlnavd exit:\n{}",
        daemon.log_tail(20)
    );
    let s = master.wait_state("L1", t0, LONG, "daemon error", |s| {
        has_error(s, "daemonUnavailableError", "")
    });
    assert_eq!(s["operatingMode"], "SERVICE");
    let t1 = Instant::now();
    let _daemon = start_daemon(&prefix);
    master.wait_state("L1", t1, LONG, "recovered", |s| {
        s["operatingMode"] == "AUTOMATIC" && errors(s).is_empty()
    });
    let t2 = Instant::now();
    master.order(
        "L1",
        "after",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 2.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t2, LONG, "B reached", |s| {
        s["lastNodeId"] == "B" && node_count(s) == 0
    });
    master.check_valid();
}

#[test]
fn two_machines_on_one_broker() {
    let _g = serial();
    let broker = Broker::start();
    let master = Master::connect(broker.port);
    let (p1, p2) = (unique_prefix("two-a"), unique_prefix("two-b"));
    let _d1 = start_daemon(&p1);
    let _d2 = start_daemon(&p2);
    let _b1 = start_bridge(&broker.addr(), "L1", &p1, None);
    let _b2 = start_bridge(&broker.addr(), "L2", &p2, None);
    wait_ready(&master, "L1");
    wait_ready(&master, "L2");
    let t0 = Instant::now();
    master.order(
        "L1",
        "one",
        0,
        0,
        &[
            ("A", 0.0, 0.0, 0.0, true),
            ("B", 3.0, 0.0, 0.5, true),
            ("C", 5.0, 1.0, 0.0, true),
        ],
    );
    master.order(
        "L2",
        "two",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 2.0, -1.0, 0.0, true)],
    );
    let s1 = master.wait_state("L1", t0, LONG, "L1 done", |s| {
        s["lastNodeId"] == "C" && node_count(s) == 0
    });
    let s2 = master.wait_state("L2", t0, LONG, "L2 done", |s| {
        s["lastNodeId"] == "B" && node_count(s) == 0
    });
    assert_eq!(
        (s1["orderId"].as_str(), s2["orderId"].as_str()),
        (Some("one"), Some("two"))
    );
    // Each ended at its own goal.
    assert!((s1["agvPosition"]["x"].as_f64().unwrap() - 5.0).abs() < 0.3);
    assert!((s2["agvPosition"]["y"].as_f64().unwrap() + 1.0).abs() < 0.3);
    master.check_valid();
}
