//! Shared by the fleet tests: a mosquitto broker on a free port, `wlnavd --sim` daemons
//! with private prefixes, `wlnav-fleet` bridges, and a test-side MQTT client that records
//! every message and checks it against the official schemas.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

// The test kit's: the repository root, one test at a time in this binary (daemons,
// bridges and a broker per test on 2 cores), mosquitto on a free port, SIGTERM then
// SIGKILL, the prefixes, the wall-clock factor and the daemon's time scale.
#[allow(unused_imports)] // not every test binary of fleet uses each
pub use wlnav_test_kit::broker::{free_port, Broker};
#[allow(unused_imports)]
pub use wlnav_test_kit::{repo_root, serial, terminate, timing_scale, unique_prefix, FAST};
use wlnav_test_kit::{Daemon, DaemonCommand};

// ------------------------------------------------------------------------------------
// Schemas
// ------------------------------------------------------------------------------------

/// The topics with an official schema (fleet/schemas/).
pub const SCHEMA_TOPICS: [&str; 6] = [
    "connection",
    "factsheet",
    "instantActions",
    "order",
    "state",
    "visualization",
];

/// `npm ci` in `dir` unless its node_modules holds exactly the committed lock file's
/// packages: `npm ci` copies package-lock.json to node_modules/.wlnav-lock (as
/// scripts/test.sh does), and a different or missing copy means missing or stale.
pub fn npm_ci(dir: &Path) {
    static DONE: Mutex<bool> = Mutex::new(false);
    let mut done = DONE.lock().unwrap_or_else(|p| p.into_inner());
    if *done {
        return;
    }
    let lock =
        std::fs::read(dir.join("package-lock.json")).expect("fleet/master/package-lock.json");
    let stamp = dir.join("node_modules/.wlnav-lock");
    if !std::fs::read(&stamp).is_ok_and(|s| s == lock) {
        eprintln!("fleet tests: npm ci in {}", dir.display());
        let status = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--loglevel=error"])
            .current_dir(dir)
            .status()
            .unwrap_or_else(|e| {
                panic!(
                    "npm: {e}: Node.js and npm are needed for the fleet tests' schema check \
                     and the VDA 5050 master (apt-get install nodejs npm; scripts/test.sh \
                     installs them)"
                )
            });
        assert!(status.success(), "npm ci failed in {}", dir.display());
        std::fs::write(&stamp, lock).unwrap();
    }
    *done = true;
}

/// The official schemas (fleet/schemas/, draft 2020-12) checked by Ajv with its formats,
/// the validator the VDA 5050 master test uses too: fleet/master/validate.mjs, one Node.js
/// process per test binary, a JSON line per message each way.
struct SchemaCheck {
    stdin: std::process::ChildStdin,
    stdout: BufReader<std::process::ChildStdout>,
    _child: Child,
}

fn schema_check() -> &'static Mutex<SchemaCheck> {
    static CHECK: OnceLock<Mutex<SchemaCheck>> = OnceLock::new();
    CHECK.get_or_init(|| {
        let master = repo_root().join("fleet/master");
        npm_ci(&master);
        let mut child = Command::new("node")
            .arg(master.join("validate.mjs"))
            .arg(repo_root().join("fleet/schemas"))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("node: {e}: Node.js is needed for the schema check"));
        let stdin = child.stdin.take().unwrap();
        let stdout = BufReader::new(child.stdout.take().unwrap());
        Mutex::new(SchemaCheck {
            stdin,
            stdout,
            _child: child,
        })
    })
}

/// What the schema of `topic` finds wrong with `msg` (empty: valid).
pub fn schema_errors(topic: &str, msg: &Value) -> Vec<String> {
    let mut check = schema_check().lock().unwrap_or_else(|p| p.into_inner());
    let request = json!({ "topic": topic, "msg": msg }).to_string();
    writeln!(check.stdin, "{request}").expect("schema check (node validate.mjs) gone");
    check.stdin.flush().unwrap();
    let mut line = String::new();
    check.stdout.read_line(&mut line).unwrap();
    assert!(
        !line.is_empty(),
        "schema check (node validate.mjs) exited; its error is above"
    );
    serde_json::from_str(&line).unwrap_or_else(|e| panic!("schema check answered {line:?}: {e}"))
}

/// Whether `msg` validates against the schema of `topic`.
pub fn is_valid(topic: &str, msg: &Value) -> bool {
    schema_errors(topic, msg).is_empty()
}

/// Panics unless `msg` validates against the schema of `topic`.
pub fn assert_valid(topic: &str, msg: &Value) {
    let errors = schema_errors(topic, msg);
    assert!(
        errors.is_empty(),
        "{topic} message fails its schema: {errors:?}\n{msg:#}"
    );
}

// ------------------------------------------------------------------------------------
// Daemon and bridge processes
// ------------------------------------------------------------------------------------

/// A bridge (`wlnav-fleet`) child process with its log in a file (wlnavd is the kit's
/// [`Daemon`]).
pub struct Proc {
    pub child: Option<Child>,
    pub log: PathBuf,
    pub what: String,
}

impl Proc {
    fn spawn(what: &str, bin: &Path, args: &[String]) -> Self {
        let log = wlnav_test_kit::log_path(&format!("fleet-{what}"));
        let out = std::fs::File::create(&log).unwrap();
        let child = Command::new(bin)
            .args(args)
            // wlnavd finds its default weights (critic-weights/avant635/) relative to the
            // working directory, as on the machine; cargo runs the tests in fleet/.
            .current_dir(repo_root())
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .env("NO_COLOR", "1")
            // The tests read the logs (wlnavd's goals with their obstacle counts).
            .env("RUST_LOG", "info")
            .spawn()
            .unwrap_or_else(|e| panic!("start {}: {e}", bin.display()));
        Self {
            child: Some(child),
            log,
            what: what.into(),
        }
    }

    pub fn log_tail(&self, lines: usize) -> String {
        wlnav_test_kit::tail(&self.log, lines)
    }

    /// SIGTERM; true if it exited cleanly within `grace` (times `WLNAV_TIMING_SCALE`).
    pub fn terminate(&mut self, grace: Duration) -> bool {
        match self.child.take() {
            Some(mut c) => {
                let clean = terminate(&mut c, grace);
                clean && c.wait().map(|s| s.success()).unwrap_or(false)
            }
            None => true,
        }
    }

    /// SIGKILL.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub fn is_running(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| c.try_wait().ok().flatten().is_none())
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            terminate(&mut c, Duration::from_secs(5));
        }
    }
}

/// Starts `wlnavd --sim` on `prefix` (the kit's supervised start) and waits until it is
/// ready (telemetry in idle). Its log is at `info` (the tests read its goals with their
/// obstacle counts).
pub fn start_daemon(prefix: &str) -> Daemon {
    start_daemon_with(prefix, None)
}

/// [`start_daemon`] with the site `site` (`wlnavd --site FILE`, DESIGN §17).
pub fn start_daemon_with(prefix: &str, site: Option<&Path>) -> Daemon {
    let scale = timing_scale::daemon_time_scale(FAST);
    let mut command = DaemonCommand::sim(
        &wlnav_test_kit::binaries().wlnavd,
        prefix,
        "fleet-wlnavd",
        Some(scale),
    )
    .args(["--cost".to_owned(), wlnav_test_kit::cost()])
    .env("RUST_LOG", "info");
    if let Some(site) = site {
        command = command.args(["--site".as_ref(), site.as_os_str()]);
    }
    // On a slower CPU the solver's budget (also the start-up self-test's) is scaled too.
    if timing_scale::factor() > 1.0 {
        let budget = command.log.with_extension("toml");
        std::fs::write(
            &budget,
            format!("[mpc]\ntime_budget = {}\n", timing_scale::secs(0.1)),
        )
        .expect("write the budget configuration");
        command = command.args(["--config".as_ref(), budget.as_os_str()]);
    }
    let (daemon, _client, _telemetry, _first) = Daemon::start_ready(command);
    daemon
}

/// Every telemetry sample of a daemon, read by a thread of its own (the subscriber keeps
/// only 16 samples, about a second at the tests' time scale, so a test that must see
/// everything of a longer phase cannot read them at its end).
pub struct TelemetryLog {
    samples: Arc<Mutex<Vec<shm_ipc::Telemetry>>>,
    stop: Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl TelemetryLog {
    /// Starts recording the telemetry of the daemon on `prefix` (which must be running).
    pub fn start(prefix: &str) -> Self {
        let client = shm_ipc::Client::new(&shm_ipc::IpcConfig::new(prefix)).unwrap();
        let sub = client.subscribe_telemetry().unwrap();
        let samples = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (s, st) = (samples.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let _client = client;
            while !st.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(Some(t)) = sub.recv_timeout(Duration::from_millis(50)) {
                    s.lock().unwrap().push(t);
                }
            }
        });
        Self {
            samples,
            stop,
            thread: Some(thread),
        }
    }

    /// The samples so far.
    pub fn samples(&self) -> Vec<shm_ipc::Telemetry> {
        self.samples.lock().unwrap().clone()
    }
}

impl Drop for TelemetryLog {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Starts `wlnav-fleet` for serial `serial` on `prefix`, with an optional config file text.
pub fn start_bridge(broker: &str, serial: &str, prefix: &str, config: Option<&str>) -> Proc {
    let mut args: Vec<String> = vec![
        "--broker".into(),
        broker.into(),
        "--manufacturer".into(),
        MANUFACTURER.into(),
        "--serial-number".into(),
        serial.into(),
        "--prefix".into(),
        prefix.into(),
    ];
    if let Some(text) = config {
        let path = std::env::temp_dir().join(format!(
            "wlnav-fleet-config-{}-{}.toml",
            std::process::id(),
            shm_ipc::monotonic_now_ns()
        ));
        std::fs::write(&path, text).unwrap();
        args.push("--config".into());
        args.push(path.display().to_string());
    }
    Proc::spawn(
        "bridge",
        Path::new(env!("CARGO_BIN_EXE_wlnav-fleet")),
        &args,
    )
}

pub const MANUFACTURER: &str = "wlnav";

// ------------------------------------------------------------------------------------
// A test-side master: records everything, validates everything
// ------------------------------------------------------------------------------------

/// A received message.
#[derive(Debug, Clone)]
pub struct Received {
    pub serial: String,
    pub topic: String,
    pub retained: bool,
    /// The QoS it arrived with: the smaller of the publisher's and the subscription's
    /// (this master subscribes with QoS 1, so a message published with QoS 0 arrives with 0).
    pub qos: u8,
    pub json: Value,
    pub at: Instant,
}

/// Subscribes to `uagv/v2/wlnav/#`, records every message and asserts it matches its
/// schema (a failure is recorded and reported by [`Master::check_valid`]).
pub struct Master {
    client: rumqttc::Client,
    /// The mapId of the nodes [`Master::order`] sends ("site": the bridge's default
    /// `map_id`, the map while wlnavd has no site).
    map_id: Mutex<String>,
    pub received: Arc<Mutex<Vec<Received>>>,
    pub invalid: Arc<Mutex<Vec<String>>>,
    header_id: std::sync::atomic::AtomicU64,
    _thread: std::thread::JoinHandle<()>,
}

impl Master {
    pub fn connect(broker_port: u16) -> Self {
        let mut opts = rumqttc::MqttOptions::new(
            format!(
                "test-master-{}-{}",
                std::process::id(),
                shm_ipc::monotonic_now_ns()
            ),
            "127.0.0.1",
            broker_port,
        );
        opts.set_max_packet_size(32 << 20, 32 << 20);
        opts.set_keep_alive(Duration::from_secs(5));
        let (client, mut connection) = rumqttc::Client::new(opts, 1024);
        let received = Arc::new(Mutex::new(Vec::new()));
        let invalid = Arc::new(Mutex::new(Vec::new()));
        let (r, inv) = (received.clone(), invalid.clone());
        let resubscribe = client.clone();
        let thread = std::thread::spawn(move || {
            for ev in connection.iter() {
                match ev {
                    // A clean session forgets the subscription when the broker restarts.
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                        let _ =
                            resubscribe.try_subscribe("uagv/v2/wlnav/#", rumqttc::QoS::AtLeastOnce);
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p))) => {
                        let parts: Vec<&str> = p.topic.split('/').collect();
                        if parts.len() != 5 {
                            continue;
                        }
                        let (serial, topic) = (parts[3].to_owned(), parts[4].to_owned());
                        if topic == "order" || topic == "instantActions" {
                            continue; // our own
                        }
                        let json: Value = match serde_json::from_slice(&p.payload) {
                            Ok(j) => j,
                            Err(e) => {
                                inv.lock()
                                    .unwrap()
                                    .push(format!("{}: not JSON: {e}", p.topic));
                                continue;
                            }
                        };
                        if SCHEMA_TOPICS.contains(&topic.as_str()) {
                            let errs = schema_errors(&topic, &json);
                            if !errs.is_empty() {
                                inv.lock()
                                    .unwrap()
                                    .push(format!("{}: {errs:?}: {json}", p.topic));
                            }
                        }
                        r.lock().unwrap().push(Received {
                            serial,
                            topic,
                            retained: p.retain,
                            qos: p.qos as u8,
                            json,
                            at: Instant::now(),
                        });
                    }
                    Ok(_) => {}
                    Err(_) => std::thread::sleep(Duration::from_millis(200)),
                }
            }
        });
        Self {
            client,
            map_id: Mutex::new("site".into()),
            received,
            invalid,
            header_id: 0.into(),
            _thread: thread,
        }
    }

    pub fn publish(&self, serial: &str, topic: &str, payload: Vec<u8>) {
        self.client
            .publish(
                format!("uagv/v2/{MANUFACTURER}/{serial}/{topic}"),
                rumqttc::QoS::AtMostOnce,
                false,
                payload,
            )
            .unwrap();
    }

    fn header(&self, serial: &str) -> Value {
        json!({
            "headerId": self.header_id.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            "timestamp": "2026-01-01T00:00:00.000Z",
            "version": "2.0.0",
            "manufacturer": MANUFACTURER,
            "serialNumber": serial,
        })
    }

    /// The mapId of the orders [`Master::order`] sends from now on.
    pub fn set_map(&self, map_id: &str) {
        *self.map_id.lock().unwrap() = map_id.to_owned();
    }

    /// Sends an order built from (nodeId, x, y, allowedDeviationXY, released) nodes,
    /// sequence ids from `first_seq`, on the map set by [`Master::set_map`] ("site" unless
    /// set). The order is checked against its schema first.
    pub fn order(
        &self,
        serial: &str,
        order_id: &str,
        update: u64,
        first_seq: u64,
        nodes: &[(&str, f64, f64, f64, bool)],
    ) -> Value {
        let map = self.map_id.lock().unwrap().clone();
        self.order_on(&map, serial, order_id, update, first_seq, nodes)
    }

    /// [`Master::order`] with every node on map `map_id`.
    pub fn order_on(
        &self,
        map_id: &str,
        serial: &str,
        order_id: &str,
        update: u64,
        first_seq: u64,
        nodes: &[(&str, f64, f64, f64, bool)],
    ) -> Value {
        let mut o = self.header(serial);
        o["orderId"] = json!(order_id);
        o["orderUpdateId"] = json!(update);
        o["nodes"] = nodes
            .iter()
            .enumerate()
            .map(|(i, (id, x, y, dev, rel))| json!({"nodeId": id, "sequenceId": first_seq + 2 * i as u64, "released": rel, "actions": [],
                "nodePosition": {"x": x, "y": y, "mapId": map_id, "allowedDeviationXY": dev}}))
            .collect();
        o["edges"] = nodes
            .windows(2)
            .enumerate()
            .map(|(i, w)| json!({"edgeId": format!("{}-{}", w[0].0, w[1].0), "sequenceId": first_seq + 2 * i as u64 + 1,
                "released": w[1].4, "startNodeId": w[0].0, "endNodeId": w[1].0, "actions": []}))
            .collect();
        assert_valid("order", &o);
        self.publish(serial, "order", o.to_string().into_bytes());
        o
    }

    /// Sends instant actions (type, id).
    pub fn instant(&self, serial: &str, actions: &[(&str, &str)]) {
        let mut m = self.header(serial);
        m["actions"] = actions
            .iter()
            .map(|(ty, id)| json!({"actionType": ty, "actionId": id, "blockingType": "HARD"}))
            .collect();
        assert_valid("instantActions", &m);
        self.publish(serial, "instantActions", m.to_string().into_bytes());
    }

    /// Messages of `serial` on `topic` so far.
    pub fn messages(&self, serial: &str, topic: &str) -> Vec<Received> {
        self.received
            .lock()
            .unwrap()
            .iter()
            .filter(|r| r.serial == serial && r.topic == topic)
            .cloned()
            .collect()
    }

    /// The newest state of `serial`.
    pub fn last_state(&self, serial: &str) -> Option<Value> {
        self.messages(serial, "state")
            .last()
            .map(|r| r.json.clone())
    }

    /// Waits until a state of `serial` received after `since` satisfies `pred`.
    pub fn wait_state(
        &self,
        serial: &str,
        since: Instant,
        timeout: Duration,
        what: &str,
        pred: impl Fn(&Value) -> bool,
    ) -> Value {
        let timeout = timing_scale::real(timeout);
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self
                .messages(serial, "state")
                .into_iter()
                .filter(|r| r.at >= since)
                .map(|r| r.json)
                .find(|j| pred(j))
            {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "{serial}: no state with {what} within {timeout:?}; last: {:#}",
                self.last_state(serial).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for a message on `topic` of `serial` after `since` satisfying `pred`.
    pub fn wait_msg(
        &self,
        serial: &str,
        topic: &str,
        since: Instant,
        timeout: Duration,
        pred: impl Fn(&Received) -> bool,
    ) -> Received {
        let timeout = timing_scale::real(timeout);
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(r) = self
                .messages(serial, topic)
                .into_iter()
                .filter(|r| r.at >= since)
                .find(|r| pred(r))
            {
                return r;
            }
            assert!(
                Instant::now() < deadline,
                "{serial}: no matching {topic} message within {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Asserts the QoS every message of `serial` so far arrived with: the specification's
    /// (`connection` 1, `state`, `visualization`, `factsheet` 0); returns how many.
    pub fn check_qos(&self, serial: &str) -> usize {
        let received = self.received.lock().unwrap();
        let mut n = 0;
        for r in received.iter().filter(|r| r.serial == serial) {
            let want = if r.topic == "connection" { 1 } else { 0 };
            assert_eq!(
                r.qos, want,
                "{} {} arrived with QoS {}",
                r.serial, r.topic, r.qos
            );
            n += 1;
        }
        n
    }

    /// Asserts every message so far matched its schema, and returns how many there were.
    pub fn check_valid(&self) -> usize {
        let inv = self.invalid.lock().unwrap();
        assert!(inv.is_empty(), "messages failing their schema: {inv:#?}");
        self.received.lock().unwrap().len()
    }
}

/// The errors of a state, as (errorType, description).
pub fn errors(state: &Value) -> Vec<(String, String)> {
    state["errors"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|e| {
                    (
                        e["errorType"].as_str().unwrap_or("").to_owned(),
                        e["errorDescription"].as_str().unwrap_or("").to_owned(),
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

pub fn has_error(state: &Value, ty: &str, text: &str) -> bool {
    errors(state)
        .iter()
        .any(|(t, d)| t == ty && d.contains(text))
}

/// Reads a retained message on `topic` with a fresh client (as a master started later
/// would see it); `None` if none arrives within `timeout` (times `WLNAV_TIMING_SCALE`).
pub fn retained(port: u16, topic: &str, timeout: Duration) -> Option<Value> {
    let timeout = timing_scale::real(timeout);
    let mut opts = rumqttc::MqttOptions::new(
        format!("retained-{}", shm_ipc::monotonic_now_ns()),
        "127.0.0.1",
        port,
    );
    opts.set_max_packet_size(32 << 20, 32 << 20);
    let (client, mut conn) = rumqttc::Client::new(opts, 16);
    client.subscribe(topic, rumqttc::QoS::AtLeastOnce).unwrap();
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        match conn.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p)))) if p.retain => {
                let _ = client.disconnect();
                return serde_json::from_slice(&p.payload).ok();
            }
            Ok(Err(_)) => std::thread::sleep(Duration::from_millis(100)),
            _ => {}
        }
    }
    let _ = client.disconnect();
    None
}
