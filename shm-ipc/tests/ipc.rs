//! Round trips through real iceoryx2 shared memory. Every test uses its own prefix (process
//! id, test name, clock) so tests running in parallel, or other engineers' runs on the same
//! host, never meet.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread;
use std::time::{Duration, Instant};

use shm_ipc::{
    Client, ClientError, DaemonEndpoint, GoalRequest, GoalValidator, IpcConfig, IpcError,
    MachineState, Mode, Obstacle, Pose2, PoseEstimate, RejectCode, Telemetry,
};

/// The request and wait limit of these tests: 5 s times `WLNAV_TIMING_SCALE`.
fn timeout() -> Duration {
    timing_scale::real(Duration::from_secs(5))
}

/// Wall-clock limits of these tests are timing limits: times `WLNAV_TIMING_SCALE` (the
/// shared helper; emulation: scripts/cross-check.sh).
#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

fn unique_config(test: &str) -> IpcConfig {
    IpcConfig::new(format!(
        "wlnav-test/{}/{}/{}",
        std::process::id(),
        test,
        shm_ipc::monotonic_now_ns()
    ))
}

/// A test daemon on its own thread: validates and answers goals until stopped, returns how
/// many requests it answered.
struct TestServer {
    stop: Arc<AtomicBool>,
    handle: Option<thread::JoinHandle<usize>>,
}

impl TestServer {
    fn start(config: IpcConfig) -> Self {
        Self::start_with_ticks(config, 0)
    }

    /// Also publishes one telemetry sample per answered request, ticks counting up from
    /// `tick_base + 1`, so a subscriber can tell which daemon it hears.
    fn start_with_ticks(config: IpcConfig, tick_base: u64) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = mpsc::channel();
        let stop_flag = stop.clone();
        let handle = thread::spawn(move || {
            let ep = DaemonEndpoint::new(&config).expect("daemon endpoint");
            ready_tx.send(()).expect("ready");
            let validator = GoalValidator::default();
            let mut served = 0;
            while !stop_flag.load(Ordering::Relaxed) {
                ep.wait(Some(Duration::from_millis(50))).expect("wait");
                let n = ep
                    .serve_goals(|req| validator.validate_and_reply(req).1)
                    .expect("serve");
                let n = n + ep
                    .serve_stops(|req| validator.validate_and_reply(req).1)
                    .expect("serve stops");
                for _ in 0..n {
                    served += 1;
                    ep.publish_telemetry(&telemetry(tick_base + served as u64))
                        .expect("telemetry");
                }
            }
            served
        });
        ready_rx.recv_timeout(timeout()).expect("server ready");
        Self {
            stop,
            handle: Some(handle),
        }
    }

    fn finish(mut self) -> usize {
        self.stop.store(true, Ordering::Relaxed);
        self.handle
            .take()
            .expect("handle")
            .join()
            .expect("server thread")
    }
}

#[test]
fn goal_request_is_answered_by_server_thread() {
    let config = unique_config("goal_answered");
    let server = TestServer::start(config.clone());
    let client = Client::new(&config).expect("client");

    let obstacles = [Obstacle::new(2.0, 1.0, 0.5)];
    let reply = client
        .set_goal(Pose2::new(4.5, 0.0, 0.3), &obstacles, timeout())
        .expect("reply");
    assert!(reply.is_accepted(), "{}", reply.reason_text());
    assert_eq!(reply.reject_code(), Ok(RejectCode::None));

    // A request with an explicit id: the reply echoes it.
    let req = GoalRequest::set_goal(4242, Pose2::new(f64::NAN, 0.0, 0.0), &[]).expect("req");
    let reply = client.request(&req, timeout()).expect("reply");
    assert_eq!(reply.request_id, 4242);
    assert!(!reply.is_accepted());
    assert_eq!(reply.reject_code(), Ok(RejectCode::NonFinite));
    assert!(
        reply.reason_text().contains("not finite"),
        "{}",
        reply.reason_text()
    );

    // Each rejection reason survives the trip with its code and text.
    let bad_radius = client
        .set_goal(
            Pose2::new(2.0, 1.0, 0.0),
            &[Obstacle::new(2.0, 1.0, -0.5)],
            timeout(),
        )
        .expect("reply");
    assert_eq!(bad_radius.reject_code(), Ok(RejectCode::BadObstacle));
    let outside = client
        .set_goal(Pose2::new(1e4, 0.0, 0.0), &[], timeout())
        .expect("reply");
    assert_eq!(outside.reject_code(), Ok(RejectCode::OutOfWorkspace));
    assert!(outside.reason_text().contains("workspace"));
    let mut too_many = GoalRequest::set_goal(7, Pose2::new(1.0, 1.0, 0.0), &[]).expect("req");
    too_many.obstacle_count = 9;
    let reply = client.request(&too_many, timeout()).expect("reply");
    assert_eq!(reply.reject_code(), Ok(RejectCode::TooManyObstacles));

    assert!(client.cancel(timeout()).expect("cancel").is_accepted());
    assert!(client.stop(timeout()).expect("stop").is_accepted());

    // Several requests in flight at once, answered in any order.
    let pending: Vec<_> = (0..8)
        .map(|i| {
            let req =
                GoalRequest::set_goal(1000 + i, Pose2::new(i as f64, 0.0, 0.0), &[]).expect("req");
            client.submit(&req).expect("submit")
        })
        .collect();
    for (i, p) in pending.into_iter().enumerate() {
        let reply = p.wait(timeout()).expect("reply");
        assert_eq!(reply.request_id, 1000 + i as u64);
        assert!(reply.is_accepted());
    }

    assert!(client
        .set_goal(Pose2::default(), &[Obstacle::default(); 9], timeout())
        .is_err());
    assert_eq!(server.finish(), 5 + 2 + 8);
}

#[test]
fn no_daemon_is_reported_not_hung() {
    // Without a daemon the services do not exist, and a client does not create them.
    let config = unique_config("no_daemon");
    let start = Instant::now();
    match Client::new(&config) {
        Err(shm_ipc::IpcError::NotServed { service }) => assert!(service.ends_with("/v2/goal")),
        other => panic!("expected NotServed, got {other:?}"),
    }
    assert!(matches!(
        Client::connect(&config, Duration::from_millis(100)),
        Err(shm_ipc::IpcError::NotServed { .. })
    ));
    assert!(start.elapsed() < timing_scale::real(Duration::from_secs(1)));
    // A daemon that has gone (its services kept alive by a client) answers NoDaemon.
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let client = Client::new(&config).expect("client");
    drop(ep);
    match client.set_goal(Pose2::new(1.0, 0.0, 0.0), &[], timeout()) {
        Err(ClientError::NoDaemon { service }) => assert!(service.ends_with("/v2/goal")),
        other => panic!("expected NoDaemon, got {other:?}"),
    }
    // The stop service went with the daemon (no client holds it); the fallback on the
    // goal service finds no server either: both reasons are reported.
    match client.stop(timeout()) {
        Err(ClientError::StopNotSent { stop, goal }) => {
            match *stop {
                ClientError::Ipc(shm_ipc::IpcError::NotServed { service })
                | ClientError::NoDaemon { service } => assert!(service.ends_with("/v2/stop")),
                other => panic!("expected NotServed or NoDaemon, got {other:?}"),
            }
            match *goal {
                ClientError::NoDaemon { service } => assert!(service.ends_with("/v2/goal")),
                other => panic!("expected NoDaemon, got {other:?}"),
            }
        }
        other => panic!("expected StopNotSent, got {other:?}"),
    }
}

#[test]
fn a_stop_gets_through_when_every_goal_client_slot_is_taken() {
    let config = unique_config("stop_slots");
    let server = TestServer::start(config.clone());
    let mut held = Vec::new();
    for _ in 0..40 {
        match Client::new(&config) {
            Ok(c) => held.push(c),
            Err(shm_ipc::IpcError::PortsExhausted {
                port: "client",
                limit: 32,
                ..
            }) => {}
            Err(e) => panic!("unexpected {e}"),
        }
    }
    assert_eq!(
        held.len(),
        shm_ipc::qos::GOAL_MAX_CLIENTS,
        "every goal slot taken"
    );
    assert!(Client::new(&config).is_err(), "no goal slot left");
    let stop = shm_ipc::StopClient::new(&config).expect("stop client");
    for _ in 0..3 {
        assert!(stop.stop(timeout()).expect("stop").is_accepted());
    }
    // Each `Client::stop` also goes the reserved way.
    assert!(held[0].stop(timeout()).expect("stop").is_accepted());
    drop(held);
    assert_eq!(server.finish(), 4);
}

#[test]
fn second_daemon_on_same_prefix_is_refused() {
    let config = unique_config("second_daemon");
    let first = DaemonEndpoint::new(&config).expect("first daemon");
    match DaemonEndpoint::new(&config) {
        // The refusal names the process serving already (README fault table, row 8).
        Err(IpcError::AlreadyServed { holders, .. }) => {
            let pid = format!("node \"wlnavd\" (pid {}", std::process::id());
            assert!(holders.contains(&pid), "{pid:?} missing in {holders:?}");
        }
        other => panic!("expected AlreadyServed, got {other:?}"),
    }
    drop(first);
    // The slot is free again once the first daemon is gone.
    DaemonEndpoint::new(&config).expect("daemon after the first left");
}

#[test]
fn unanswered_requests_time_out_or_report_dropped() {
    let config = unique_config("unanswered");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let client = Client::new(&config).expect("client");

    // Held but not answered: the client times out.
    let pending = client.submit(&GoalRequest::cancel(1)).expect("submit");
    let held = loop {
        if let Some(g) = ep.receive_goal().expect("receive") {
            break g;
        }
        ep.wait(Some(Duration::from_millis(100))).expect("wait");
    };
    assert_eq!(held.request().request_id, 1);
    let start = Instant::now();
    match pending.wait(Duration::from_millis(200)) {
        Err(ClientError::Timeout { request_id: 1, .. }) => {}
        other => panic!("expected timeout, got {other:?}"),
    }
    assert!(start.elapsed() >= Duration::from_millis(200));

    // Dropped without an answer: the client learns it instead of waiting out its timeout.
    drop(held);
    let pending = client.submit(&GoalRequest::stop(2)).expect("submit");
    let start = Instant::now();
    let dropped = thread::scope(|s| {
        s.spawn(|| {
            let g = loop {
                if let Some(g) = ep.receive_goal().expect("receive") {
                    break g;
                }
                ep.wait(Some(Duration::from_millis(100))).expect("wait");
            };
            drop(g);
        });
        pending.wait(timeout())
    });
    match dropped {
        Err(ClientError::Dropped { request_id: 2 }) => {}
        other => panic!("expected dropped, got {other:?}"),
    }
    assert!(start.elapsed() < timeout());
}

fn telemetry(tick: u64) -> Telemetry {
    let mut t = Telemetry::ZERO;
    t.tick = tick;
    t.timestamp_ns = shm_ipc::monotonic_now_ns();
    t.mode = Mode::Tracking.code();
    t.goal_active = 1;
    t.goal = Pose2::new(4.5, 0.0, 0.0);
    t.state = MachineState::from_array([tick as f64, 0.0, 0.0, 0.1, 0.0, 0.5]);
    let plan: Vec<MachineState> = (0..11)
        .map(|i| MachineState::from_array([tick as f64 + i as f64 * 0.1, 0.0, 0.0, 0.0, 0.0, 0.5]))
        .collect();
    t.set_trajectory(&plan);
    t
}

#[test]
fn telemetry_reaches_two_subscribers_at_once() {
    let config = unique_config("telemetry_two_subs");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    // Two separate clients, as two processes would be.
    let a = Client::new(&config).expect("client a");
    let b = Client::new(&config).expect("client b");
    let sub_a = a.subscribe_telemetry().expect("sub a");
    let sub_b = b.subscribe_telemetry().expect("sub b");

    let readers: Vec<_> = [sub_a, sub_b]
        .into_iter()
        .map(|sub| {
            thread::spawn(move || {
                let mut ticks = Vec::new();
                while ticks.len() < 10 {
                    match sub.recv_timeout(timeout()).expect("recv") {
                        Some(t) => {
                            assert_eq!(t.trajectory().len(), 11);
                            assert_eq!(t.mode(), Ok(Mode::Tracking));
                            assert_eq!(t.trajectory()[0].x_f, t.tick as f64);
                            ticks.push(t.tick);
                        }
                        None => break,
                    }
                }
                ticks
            })
        })
        .collect();

    for tick in 1..=10 {
        ep.publish_telemetry(&telemetry(tick)).expect("publish");
        // Slower than the readers so the 16-sample buffer never overflows.
        thread::sleep(Duration::from_millis(5));
    }
    for r in readers {
        assert_eq!(r.join().expect("reader"), (1..=10).collect::<Vec<_>>());
    }
}

#[test]
fn pose_from_client_reaches_daemon_and_wakes_it() {
    let config = unique_config("pose");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let client = Client::new(&config).expect("client");
    assert_eq!(ep.latest_pose().expect("pose"), None);

    for seq in 0..3 {
        let p = PoseEstimate::new(
            shm_ipc::monotonic_now_ns(),
            seq,
            Pose2::new(seq as f64, 2.0, 0.1),
        );
        client.publish_pose(&p).expect("publish");
    }
    let woke = ep.wait(Some(timeout())).expect("wait");
    assert!(woke.pose);
    let latest = ep.latest_pose().expect("pose").expect("some pose");
    assert_eq!(latest.sequence, 2);
    assert_eq!(latest.pose(), Pose2::new(2.0, 2.0, 0.1));
    assert!(latest.is_usable());
    assert!(latest.timestamp_ns <= shm_ipc::monotonic_now_ns());

    // Nothing pending: wait times out with an empty wake-up, promptly.
    let start = Instant::now();
    let woke = ep.wait(Some(Duration::from_millis(50))).expect("wait");
    assert!(!woke.any());
    assert!(start.elapsed() >= Duration::from_millis(45));
}

#[test]
fn two_prefixes_in_parallel_do_not_interfere() {
    let ca = unique_config("prefix_a");
    let cb = unique_config("prefix_b");
    let server_a = TestServer::start_with_ticks(ca.clone(), 1_000);
    let server_b = TestServer::start_with_ticks(cb.clone(), 2_000);

    let run = |config: IpcConfig, goals: usize| {
        thread::spawn(move || {
            let client = Client::new(&config).expect("client");
            let sub = client.subscribe_telemetry().expect("sub");
            for i in 0..goals {
                let reply = client
                    .set_goal(Pose2::new(i as f64 * 0.1, 0.0, 0.0), &[], timeout())
                    .expect("reply");
                assert!(reply.is_accepted());
            }
            let mut seen = Vec::new();
            let quiet = timing_scale::real(Duration::from_millis(300));
            while let Some(t) = sub.recv_timeout(quiet).expect("recv") {
                seen.push(t.tick);
            }
            seen
        })
    };
    let ta = run(ca, 7);
    let tb = run(cb, 4);
    let seen_a = ta.join().expect("a");
    let seen_b = tb.join().expect("b");
    // Each daemon publishes one sample per goal it served, numbered from its own base.
    assert_eq!(seen_a, (1_001..=1_007).collect::<Vec<_>>());
    assert_eq!(seen_b, (2_001..=2_004).collect::<Vec<_>>());
    assert_eq!(server_a.finish(), 7);
    assert_eq!(server_b.finish(), 4);
}

/// A squatter in this process: a plain iceoryx2 node (as a third-party client would use)
/// that holds ports on the services of `config`.
fn squatter() -> shm_ipc::iceoryx2::node::Node<shm_ipc::iceoryx2::prelude::ipc::Service> {
    use shm_ipc::iceoryx2::prelude::*;
    NodeBuilder::new()
        .name(&NodeName::new("squatter").unwrap())
        .create::<ipc::Service>()
        .unwrap()
}

fn service_name(name: &str) -> shm_ipc::iceoryx2::prelude::ServiceName {
    shm_ipc::iceoryx2::prelude::ServiceName::new(name).unwrap()
}

#[test]
fn a_stop_falls_back_to_the_goal_service_when_every_stop_slot_is_taken() {
    let config = unique_config("stop_fallback");
    let server = TestServer::start(config.clone());
    let names = config.service_names().unwrap();
    let node = squatter();
    let stop_service = node
        .service_builder(&service_name(&names.stop))
        .request_response::<GoalRequest, shm_ipc::GoalReply>()
        .open()
        .unwrap();
    let held: Vec<_> = (0..20)
        .filter_map(|_| stop_service.client_builder().create().ok())
        .collect();
    assert_eq!(held.len(), shm_ipc::qos::STOP_MAX_CLIENTS);
    let stop = shm_ipc::StopClient::new(&config).expect("stop client");
    let report = stop
        .stop_report(7, timeout())
        .expect("the stop gets through");
    assert!(report.reply.is_accepted(), "{report:?}");
    assert_eq!(report.reply.request_id, 7);
    assert_eq!(report.path, shm_ipc::StopPath::GoalService);
    assert!(report.notified && report.listened, "{report:?}");
    let detours = report.detours.join("\n");
    for needle in [
        "all 16 client slots are taken".to_owned(),
        format!("16 held by node \"squatter\" (pid {}", std::process::id()),
    ] {
        assert!(detours.contains(&needle), "{needle:?} missing in {detours}");
    }
    // `Client::stop` falls back onto its own goal port.
    let client = Client::new(&config).expect("client");
    let report = client
        .stop_report(timeout())
        .expect("the stop gets through");
    assert!(report.reply.is_accepted());
    assert_eq!(report.path, shm_ipc::StopPath::GoalService);
    // Slots free again: the reserved path.
    drop(held);
    let report = stop.stop_report(8, timeout()).expect("stop");
    assert_eq!(report.path, shm_ipc::StopPath::StopService);
    assert!(report.detours.is_empty(), "{report:?}");
    drop(client);
    assert_eq!(server.finish(), 3);
}

#[test]
fn a_stop_goes_without_notifier_and_listener_when_none_is_free() {
    let config = unique_config("stop_no_notifier");
    let server = TestServer::start(config.clone());
    let names = config.service_names().unwrap();
    let node = squatter();
    let mut notifiers = Vec::new();
    let mut listeners = Vec::new();
    let mut events = Vec::new();
    // Every notifier and listener of both event services a stop could use.
    for name in [&names.stop, &names.goal] {
        let event = node
            .service_builder(&service_name(name))
            .event()
            .open()
            .unwrap();
        notifiers.extend((0..80).filter_map(|_| event.notifier_builder().create().ok()));
        listeners.extend((0..80).filter_map(|_| event.listener_builder().create().ok()));
        events.push(event);
    }
    // The daemon holds one notifier and one listener on each.
    assert_eq!(notifiers.len(), 2 * (shm_ipc::qos::EVENT_MAX_PORTS - 1));
    assert_eq!(listeners.len(), 2 * (shm_ipc::qos::EVENT_MAX_PORTS - 1));
    let stop = shm_ipc::StopClient::new(&config).expect("stop client");
    let start = Instant::now();
    let report = stop
        .stop_report(9, timeout())
        .expect("the stop gets through");
    let took = start.elapsed();
    assert!(report.reply.is_accepted(), "{report:?}");
    assert_eq!(report.path, shm_ipc::StopPath::StopService);
    assert!(!report.notified && !report.listened, "{report:?}");
    // The test server wakes every 50 ms by itself, as the daemon does.
    assert!(
        took < timing_scale::real(Duration::from_secs(1)),
        "took {took:?}"
    );
    let detours = report.detours.join("\n");
    for needle in [
        "all 64 notifier slots are taken".to_owned(),
        "all 64 listener slots are taken".to_owned(),
        "sent without a notification".to_owned(),
        format!("63 held by node \"squatter\" (pid {}", std::process::id()),
    ] {
        assert!(detours.contains(&needle), "{needle:?} missing in {detours}");
    }
    // The stop event's notifiers alone: the daemon is woken through the goal event service.
    notifiers.truncate(shm_ipc::qos::EVENT_MAX_PORTS - 1);
    listeners.clear();
    let report = stop.stop_report(10, timeout()).expect("stop");
    assert!(report.notified && report.listened, "{report:?}");
    assert!(
        report
            .detours
            .join("\n")
            .contains("woke the daemon through"),
        "{report:?}"
    );
    drop(notifiers);
    assert_eq!(server.finish(), 2);
}

#[test]
fn a_second_pose_source_is_named() {
    let config = unique_config("pose_source_named");
    let _ep = DaemonEndpoint::new(&config).expect("daemon");
    let first = Client::new(&config).expect("client");
    let pose = PoseEstimate::new(shm_ipc::monotonic_now_ns(), 1, Pose2::new(0.0, 0.0, 0.0));
    first.publish_pose(&pose).expect("first source");
    let second = Client::new(&config).expect("client");
    match second.publish_pose(&pose) {
        Err(IpcError::PoseSourceTaken { holders, .. }) => {
            let pid = format!("node \"wlnav-client\" (pid {}", std::process::id());
            assert!(holders.contains(&pid), "{pid:?} missing in {holders:?}");
        }
        other => panic!("expected PoseSourceTaken, got {other:?}"),
    }
}

fn person(id: u32, y: f64, stamp: u64) -> shm_ipc::LiveObstacle {
    shm_ipc::LiveObstacle::circle(
        id,
        shm_ipc::ObstacleClass::Person,
        [4.0, y],
        0.4,
        [0.0, 1.4],
        stamp,
    )
}

#[test]
fn live_obstacles_reach_the_daemon_newest_first_and_wake_it() {
    use shm_ipc::{LiveObstacleSet, ObstaclePublisher};
    let config = unique_config("obstacles");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let publisher = ObstaclePublisher::new(&config).expect("publisher");
    assert_eq!(
        publisher.service_name(),
        format!("{}/v2/obstacles", config.prefix)
    );
    assert_eq!(ep.latest_obstacles().expect("obstacles"), None);

    for seq in 0..3u32 {
        let now = shm_ipc::monotonic_now_ns();
        let mut set = LiveObstacleSet::empty(now, seq);
        set.push(person(7, f64::from(seq), now)).expect("room");
        publisher.publish(&set).expect("publish");
    }
    let woke = ep.wait(Some(timeout())).expect("wait");
    assert!(woke.obstacles && woke.any(), "{woke:?}");
    assert!(!woke.goal && !woke.stop);
    let latest = ep.latest_obstacles().expect("read").expect("a set");
    assert_eq!(
        latest.sequence, 2,
        "the newest set, the older ones replaced"
    );
    assert_eq!(latest.as_slice().len(), 1);
    assert_eq!((latest.as_slice()[0].id, latest.as_slice()[0].y), (7, 2.0));
    assert_eq!(ep.latest_obstacles().expect("read"), None, "drained");
}

#[test]
fn a_flood_of_obstacle_sets_neither_blocks_nor_queues() {
    use shm_ipc::{LiveObstacleSet, ObstaclePublisher};
    let config = unique_config("obstacle_flood");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let publisher = ObstaclePublisher::new(&config).expect("publisher");
    let start = Instant::now();
    for seq in 0..2000u32 {
        publisher
            .publish(&LiveObstacleSet::empty(shm_ipc::monotonic_now_ns(), seq))
            .expect("a flood never blocks nor fails");
    }
    assert!(start.elapsed() < timeout(), "{:?}", start.elapsed());
    // One set is buffered: the first read is the newest, the next finds nothing.
    let first = ep.receive_obstacles().expect("read").expect("a set");
    assert_eq!(first.sequence, 1999);
    assert_eq!(ep.receive_obstacles().expect("read"), None);
}

#[test]
fn draining_the_goal_events_leaves_the_obstacle_wakeup() {
    use shm_ipc::{LiveObstacleSet, ObstaclePublisher};
    let config = unique_config("obstacle_wakeup");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let publisher = ObstaclePublisher::new(&config).expect("publisher");
    publisher
        .publish(&LiveObstacleSet::empty(shm_ipc::monotonic_now_ns(), 1))
        .expect("publish");
    // The goal task drains its events; the obstacle task's descriptor stays readable.
    ep.drain_events().expect("drain");
    let mut pfd = libc::pollfd {
        fd: ep.obstacles_event_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd.
    let ready = unsafe { libc::poll(&mut pfd, 1, 2000) };
    assert_eq!(ready, 1, "the obstacle event fd is readable");
    ep.drain_obstacle_events().expect("drain obstacles");
    // SAFETY: as above.
    let ready = unsafe { libc::poll(&mut pfd, 1, 0) };
    assert_eq!(ready, 0, "drained");
    assert!(ep.latest_obstacles().expect("read").is_some());
}

#[test]
fn a_second_obstacle_publisher_is_refused_naming_the_first() {
    use shm_ipc::ObstaclePublisher;
    let config = unique_config("obstacle_source");
    // Without a daemon there is nothing to open: a publisher never creates the service.
    match ObstaclePublisher::new(&config) {
        Err(IpcError::NotServed { service }) => assert!(service.ends_with("/v2/obstacles")),
        other => panic!("expected NotServed, got {other:?}"),
    }
    let _ep = DaemonEndpoint::new(&config).expect("daemon");
    let client = Client::new(&config).expect("client");
    let first = client.obstacle_publisher().expect("first source");
    for second in [ObstaclePublisher::new(&config), client.obstacle_publisher()] {
        match second {
            Err(e @ IpcError::ObstacleSourceTaken { .. }) => {
                let text = e.to_string();
                let pid = format!("node \"wlnav-client\" (pid {}", std::process::id());
                assert!(text.contains(&pid), "{pid:?} missing in {text:?}");
                assert!(text.contains("/v2/obstacles"), "{text}");
                assert!(text.contains("one publisher"), "{text}");
            }
            other => panic!("expected ObstacleSourceTaken, got {other:?}"),
        }
    }
    // Dropping the first frees the slot.
    drop(first);
    ObstaclePublisher::new(&config).expect("the slot is free again");
}
