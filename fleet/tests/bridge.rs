//! End to end: mosquitto on a free port, `wlnavd --sim` with a private prefix, `wlnav-fleet`,
//! and a test-side master that records every message and validates it against the official
//! schemas. One test at a time (2 cores).

mod common;

use std::time::{Duration, Instant};

use common::*;
use serde_json::Value;

const LONG: Duration = Duration::from_secs(60);

/// The id of [`SITE`].
const SITE_ID: &str = "e2e-quarry";

/// The daemon's site in the rejection test: bounds around the origin, a pile at (5, 5),
/// and a closed square wall around (-6, 0) (inner side 4.6 m; the machine, 1.2 m between
/// its axles, 0.65 m outline circles, fits inside at its centre).
const SITE: &str = r#"{"format": "wlnav-site-v1", "id": "e2e-quarry", "version": 7,
  "bounds": [[-12, -9], [16, -9], [16, 9], [-12, 9]],
  "obstacles": [
    {"id": "pile", "circle": [5, 5, 0.35]},
    {"id": "wall", "polyline": [[-8.5, -2.5], [-3.5, -2.5], [-3.5, 2.5], [-8.5, 2.5], [-8.5, -2.5]],
     "width": 0.4}]}"#;

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

/// Does `send` and waits for a state of L1 with one more error `ty` whose description
/// contains `text` than the newest state before (errors are kept until the next new order,
/// so an older error of the same kind does not count).
fn new_error(master: &Master, ty: &str, text: &str, send: impl FnOnce()) -> Value {
    let count = |s: &Value| {
        errors(s)
            .iter()
            .filter(|(t, d)| t == ty && d.contains(text))
            .count()
    };
    let before = master.last_state("L1").map_or(0, |s| count(&s));
    let t = Instant::now();
    send();
    master.wait_state("L1", t, LONG, &format!("{ty}: {text}"), |s| {
        count(s) > before
    })
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
    // stateRequest and factsheetRequest: both FINISHED, a factsheet published anew.
    let t = Instant::now();
    master.instant("L1", &[("stateRequest", "s1"), ("factsheetRequest", "f1")]);
    let f = master.wait_msg("L1", "factsheet", t, LONG, |_| true);
    assert_eq!(
        f.json["protocolFeatures"]["agvActions"][0]["actionType"],
        "cancelOrder"
    );
    master.wait_state("L1", t, LONG, "requests finished", |s| {
        action_status(s, "s1").as_deref() == Some("FINISHED")
            && action_status(s, "f1").as_deref() == Some("FINISHED")
    });

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
    // Waiting for an update of its horizon, the machine refuses another order.
    let t = Instant::now();
    master.order("L1", "intruder", 0, 0, &[("X", 6.0, 0.0, 0.0, true)]);
    let s = master.wait_state("L1", t, LONG, "another order refused", |s| {
        has_error(s, "orderUpdateError", "waiting for an update")
    });
    assert_eq!((s["orderId"].as_str(), node_count(&s)), (Some("o1"), 1));

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
    // Errors are kept until the next new order: only the refusal above.
    assert_eq!(errors(&d).len(), 1, "{d:#}");
    // Visualization at the tick rate: the simulated daemon ticks at 5 Hz × FAST (15 per
    // second; divided by WLNAV_TIMING_SCALE on a slower CPU); half of it, not a fixed 5 Hz.
    let vis = master.messages("L1", "visualization");
    let span = vis.last().unwrap().at - vis.first().unwrap().at;
    let rate = vis.len() as f64 / span.as_secs_f64();
    eprintln!("{} visualizations in {span:?}: {rate:.1}/s", vis.len());
    assert!(
        rate > 5.0 * timing_scale::daemon_time_scale(FAST) * 0.5,
        "{rate:.1} visualizations/s"
    );

    // QoS as the specification has it; state and visualization are not retained (the
    // connection and the factsheet are, checked above).
    assert!(master.check_qos("L1") > 50);
    for topic in ["state", "visualization"] {
        let r = retained(
            broker.port,
            &format!("uagv/v2/wlnav/L1/{topic}"),
            Duration::from_secs(2),
        );
        assert!(r.is_none(), "{topic} retained: {r:?}");
    }

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
    // The daemon's site (DESIGN §17; the bridge has none of its own): bounds around the
    // origin (the simulated machine starts there, heading +x), a pile at (5, 5) and a closed
    // square wall around (-6, 0) (the machine's outline fits inside, there is no way in).
    // Its id, not the bridge's configured map_id ("site", the default), is the map orders
    // must be on.
    let site = std::env::temp_dir().join(format!("wlnav-fleet-site-{}.json", std::process::id()));
    std::fs::write(&site, SITE).unwrap();
    let daemon = start_daemon_with(&prefix, Some(&site));
    master.set_map(SITE_ID);
    let mut bridge = start_bridge(&broker.addr(), "L1", &prefix, None);
    let telemetry = TelemetryLog::start(&prefix);
    wait_ready(&master, "L1");

    let t0 = Instant::now();
    let good = master
        .order("L1", "probe", 0, 0, &[("A", 0.0, 0.0, 0.0, true)])
        .to_string();
    let s = master.wait_state("L1", t0, LONG, "probe accepted", |s| {
        s["orderId"] == "probe"
    });
    assert_eq!(s["agvPosition"]["mapId"], SITE_ID, "{s:#}");
    // An order on another map than the daemon's site, even the bridge's configured map_id:
    // refused, naming both ids; nothing reaches the daemon (checked below).
    let s = new_error(
        &master,
        "validationError",
        &format!("node A: mapId \"site\", but the daemon's site is \"{SITE_ID}\" (version 7)"),
        || {
            master.order_on(
                "site",
                "L1",
                "elsewhere",
                0,
                0,
                &[("A", 0.0, 0.0, 0.0, true)],
            );
        },
    );
    assert_eq!(s["orderId"], "probe");
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
        let s = new_error(&master, "validationError", text, || {
            master.publish("L1", "order", payload)
        });
        assert_eq!(s["orderId"], "probe", "{what}");
    }
    // Beyond the MQTT packet limit (16 MiB): refused unread, which drops the connection
    // (the broker publishes the will); the bridge connects again (ONLINE) and says so.
    let t = Instant::now();
    let huge = {
        let mut v = good.clone().into_bytes();
        v.extend(std::iter::repeat_n(b' ', 17 << 20));
        v
    };
    let s = new_error(&master, "validationError", "MQTT packet limit", || {
        master.publish("L1", "order", huge)
    });
    assert_eq!(s["orderId"], "probe");
    master.wait_msg("L1", "connection", t, LONG, |r| {
        r.json["connectionState"] == "ONLINE"
    });
    assert!(bridge.is_running());
    // sequenceIds out of order.
    new_error(&master, "validationError", "out of order", || {
        master.order("L1", "h5", 0, 1, &[("A", 0.0, 0.0, 0.0, true)]);
    });
    // First node out of range.
    let far = [("F", 20.0, 0.0, 0.0, true), ("G", 22.0, 0.0, 0.0, true)];
    new_error(&master, "noRouteError", "not trivially reachable", || {
        master.order("L1", "far", 0, 0, &far);
    });
    // Garbage on instantActions.
    let s = new_error(&master, "validationError", "not valid JSON", || {
        master.publish("L1", "instantActions", b"[1, 2".to_vec())
    });
    assert!(
        s["errors"].to_string().contains("\"instantActions\""),
        "{s:#}"
    );
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

    // The daemon's own validation: a node in the site's pile, a node outside the workspace.
    let obst = [("A", 0.0, 0.0, 0.0, true), ("B", 5.0, 5.0, 0.0, true)];
    let s = new_error(&master, "noRouteError", "wlnavd refused node B", || {
        master.order("L1", "obst", 0, 0, &obst);
    });
    assert!(s["errors"].to_string().contains("GoalInCollision"), "{s:#}");
    assert!(s["errors"].to_string().contains("pile"), "{s:#}");
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
    // A goal the daemon accepts and then aborts as no-route: inside the closed wall.
    let t = Instant::now();
    master.order(
        "L1",
        "ring",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("R", -6.0, 0.0, 0.0, true)],
    );
    let s = master.wait_state("L1", t, LONG, "no-route abort", |s| {
        s["orderId"] == "ring" && has_error(s, "noRouteError", "aborted (no-route)")
    });
    assert_eq!(s["lastNodeId"], "A", "{s:#}");
    // The goals went without circles: the daemon's site is the world.
    let log = daemon.log_text();
    assert!(
        log.lines()
            .any(|l| l.contains("(-6.00, 0.00,") && l.contains("with 0 obstacle(s)")),
        "wlnavd log:\n{log}"
    );
    assert!(
        !log.lines()
            .any(|l| l.contains("goal ") && l.contains("obstacle(s)") && !l.contains("with 0 ")),
        "a goal with circles; wlnavd log:\n{log}"
    );

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
    // Cancel: RUNNING until at rest, then FINISHED; the nodes are gone. An update sent
    // while it runs is refused (it would be dropped with the cancelled order).
    let t = Instant::now();
    let update = [("B", 8.0, 0.0, 0.0, true), ("C", 8.0, 3.0, 0.0, true)];
    new_error(&master, "orderUpdateError", "being cancelled", || {
        master.instant("L1", &[("cancelOrder", "c1")]);
        master.order("L1", "long", 3, 2, &update);
    });
    master.wait_state("L1", t, LONG, "cancel running", |s| {
        action_status(s, "c1").is_some()
    });
    let s = master.wait_state("L1", t, LONG, "cancel finished", |s| {
        action_status(s, "c1").as_deref() == Some("FINISHED")
    });
    assert_eq!(s["driving"], false);
    assert_eq!(node_count(&s), 0);
    assert_eq!(s["orderUpdateId"], 2);
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
    let telemetry = TelemetryLog::start(&prefix);
    wait_ready(&master, "L1");
    let online_before = master
        .messages("L1", "connection")
        .iter()
        .filter(|r| r.json["connectionState"] == "ONLINE")
        .map(|r| r.json["headerId"].as_u64().unwrap())
        .max()
        .unwrap();
    // A -> B (passed within 0.5 m) -> C | D (horizon). The broker goes down as soon as the
    // machine drives and comes back only after it has passed B: the order goes on without
    // the broker, B passed without stopping.
    let t0 = Instant::now();
    master.order(
        "L1",
        "keep",
        0,
        0,
        &[
            ("A", 0.0, 0.0, 0.0, true),
            ("B", 3.0, 0.0, 0.5, true),
            ("C", 6.0, 0.0, 0.0, true),
            ("D", 9.0, 0.0, 0.0, false),
        ],
    );
    master.wait_state("L1", t0, LONG, "driving", |s| {
        s["orderId"] == "keep" && s["driving"] == true
    });
    broker.stop();
    let down_from = telemetry.samples().len();
    let deadline = Instant::now() + LONG;
    while !telemetry.samples().iter().any(|t| t.state.x_f > 3.5) {
        assert!(
            Instant::now() < deadline,
            "B not passed with the broker down"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    let t1 = Instant::now();
    broker.restart(Duration::ZERO);
    let samples = telemetry.samples();
    let passed_at = samples.iter().position(|t| t.state.x_f >= 3.0).unwrap();
    assert!(
        passed_at >= down_from,
        "B was passed before the broker went down"
    );
    let slowest = samples
        .iter()
        .filter(|t| (2.0..=4.0).contains(&t.state.x_f))
        .map(|t| t.state.v_f)
        .fold(f64::INFINITY, f64::min);
    // Where the goal moved on from B to C: within B's 0.5 m, as soon as the bridge saw it.
    let switch = samples
        .iter()
        .find(|t| t.goal_active == 1 && t.goal.x > 5.0)
        .map(|t| t.state.x_f);
    eprintln!(
        "broker down for {} telemetry samples; slowest at B (x in 2..4 m) {slowest:.2} m/s; \
         goal C from x = {switch:?}",
        samples.len() - down_from
    );
    assert!(
        slowest > 0.2,
        "the machine slowed to {slowest:.3} m/s at B while the broker was down"
    );

    let online = master.wait_msg("L1", "connection", t1, LONG, |r| {
        r.json["connectionState"] == "ONLINE"
    });
    assert!(
        online.json["headerId"].as_u64().unwrap() > online_before,
        "a fresh headerId on reconnect"
    );
    // The order is kept: C reached at rest, D left on the horizon.
    let s = master.wait_state("L1", t1, LONG, "C reached after the restart", |s| {
        s["lastNodeId"] == "C" && s["driving"] == false
    });
    assert_eq!(s["orderId"], "keep");
    assert_eq!(node_count(&s), 1, "the horizon node is kept: {s:#}");
    assert!(errors(&s).is_empty(), "{s:#}");
    // The order goes on.
    let t2 = Instant::now();
    master.order(
        "L1",
        "keep",
        1,
        4,
        &[("C", 6.0, 0.0, 0.0, true), ("D", 9.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t2, LONG, "D reached", |s| {
        s["lastNodeId"] == "D" && node_count(s) == 0
    });

    // SIGKILL: the broker publishes the will.
    bridge.kill();
    let deadline = Instant::now() + timing_scale::real(Duration::from_secs(10));
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
    let _bridge = start_bridge(
        &broker.addr(),
        "L1",
        &prefix,
        Some("state_interval = 1.0\n"),
    );
    wait_ready(&master, "L1");
    // At rest with nothing changing the state still comes every state_interval (here 1 s;
    // 30 s by default), and only then: not with every telemetry sample.
    let t = Instant::now();
    std::thread::sleep(Duration::from_millis(3500));
    let times: Vec<Instant> = master
        .messages("L1", "state")
        .iter()
        .map(|r| r.at)
        .filter(|at| *at >= t)
        .collect();
    assert!(
        (3..=5).contains(&times.len()),
        "{} states in 3.5 s",
        times.len()
    );
    for w in times.windows(2) {
        assert!(
            w[1] - w[0] < timing_scale::real(Duration::from_millis(1500)),
            "{:?}",
            w[1] - w[0]
        );
    }
    // The daemon stops while the machine drives an order: an error, the order kept; the
    // restarted daemon (its simulated machine starts at the origin again) gets the goal
    // again and the order ends at B.
    let t0 = Instant::now();
    master.order(
        "L1",
        "across",
        0,
        0,
        &[("A", 0.0, 0.0, 0.0, true), ("B", 6.0, 0.0, 0.0, true)],
    );
    master.wait_state("L1", t0, LONG, "driving", |s| {
        s["orderId"] == "across" && s["driving"] == true
    });
    let t1 = Instant::now();
    assert!(
        daemon.stop_cleanly(),
        "wlnavd exit:\n{}",
        daemon.log_tail(20)
    );
    let s = master.wait_state("L1", t1, LONG, "daemon error", |s| {
        has_error(s, "daemonUnavailableError", "")
    });
    assert_eq!(s["operatingMode"], "SERVICE");
    assert_eq!(s["errors"].as_array().unwrap().len(), 1, "{s:#}");
    assert_eq!(s["errors"][0]["errorLevel"], "FATAL");
    assert_eq!((s["lastNodeId"].as_str(), node_count(&s)), (Some("A"), 1));
    let t2 = Instant::now();
    let _daemon = start_daemon(&prefix);
    master.wait_state("L1", t2, LONG, "recovered", |s| {
        s["operatingMode"] == "AUTOMATIC" && errors(s).is_empty()
    });
    let s = master.wait_state("L1", t2, LONG, "B reached", |s| {
        s["lastNodeId"] == "B" && node_count(s) == 0
    });
    assert_eq!(s["orderId"], "across");
    assert!(errors(&s).is_empty(), "{s:#}");
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
