//! The I/O: MQTT (rumqttc) on one side, the daemon's iceoryx2 services on the other, and
//! the [`Vehicle`] in between. Thin on purpose: every decision is the vehicle's.
//!
//! * A thread owns the iceoryx2 [`shm_ipc::Client`] and its telemetry subscription (the
//!   library is blocking); it forwards every telemetry sample and every reply to the async
//!   loop and sends the requests the vehicle asks for. No telemetry for
//!   `daemon_timeout` means the daemon is gone: the thread reports it, drops its ports and
//!   opens them again until a daemon serves the prefix.
//! * The async loop polls the MQTT event loop (which reconnects by itself, tried again
//!   every 0.5 s while the broker is away), the daemon thread's messages, the state timer
//!   and the shutdown signal. The order goes on without the broker: only the MQTT side
//!   waits.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use rumqttc::{AsyncClient, Event, LastWill, MqttOptions, Packet, QoS};
use shm_ipc::{GoalReply, GoalRequest, IpcConfig, Telemetry};
use tokio::sync::mpsc;

use crate::config::Config;
use crate::factsheet;
use crate::order::{Identity, Limits};
use crate::vda::{self, ConnectionState, Header};
use crate::vehicle::{Effect, Vehicle, VehicleSettings};

/// Largest MQTT packet either way: far above any message the bridge accepts
/// ([`Limits::max_message_len`]), so an oversized order is refused with an error in state
/// instead of dropping the connection (rumqttc's default is 10 KiB).
pub const MAX_PACKET: usize = 16 * 1024 * 1024;

/// What `wlnav-fleet` was started with.
#[derive(Debug, Clone)]
pub struct Options {
    /// Broker host.
    pub host: String,
    /// Broker port.
    pub port: u16,
    /// Manufacturer and serial number (topic levels).
    pub identity: Identity,
    /// The daemon's service prefix.
    pub prefix: String,
    /// The configuration file's settings.
    pub config: Config,
}

/// The topics of one vehicle.
#[derive(Debug, Clone)]
pub struct Topics {
    /// `uagv/v2/M/S/order` (subscribed, QoS 0)
    pub order: String,
    /// `…/instantActions` (subscribed, QoS 0)
    pub instant_actions: String,
    /// `…/state` (QoS 0)
    pub state: String,
    /// `…/visualization` (QoS 0)
    pub visualization: String,
    /// `…/connection` (QoS 1, retained; also the last will)
    pub connection: String,
    /// `…/factsheet` (QoS 0, retained)
    pub factsheet: String,
}

impl Topics {
    /// The topics for `interface_name/v2/manufacturer/serial_number/…`.
    pub fn new(interface_name: &str, id: &Identity) -> Self {
        let base = format!(
            "{interface_name}/{}/{}/{}",
            vda::TOPIC_VERSION,
            id.manufacturer,
            id.serial_number
        );
        Self {
            order: format!("{base}/order"),
            instant_actions: format!("{base}/instantActions"),
            state: format!("{base}/state"),
            visualization: format!("{base}/visualization"),
            connection: format!("{base}/connection"),
            factsheet: format!("{base}/factsheet"),
        }
    }
}

/// Messages of the daemon thread.
#[derive(Debug)]
enum FromDaemon {
    Telemetry(Box<Telemetry>),
    Reply(u64, Result<GoalReply, String>),
    Lost,
}

/// Header counters, one per topic (the specification numbers each topic on its own).
#[derive(Debug, Default)]
struct HeaderIds {
    state: u64,
    visualization: u64,
    connection: u64,
    factsheet: u64,
}

fn header(counter: &mut u64, id: &Identity) -> Header {
    let h = Header {
        header_id: *counter,
        timestamp: vda::timestamp_now(),
        version: vda::PROTOCOL_VERSION.into(),
        manufacturer: id.manufacturer.clone(),
        serial_number: id.serial_number.clone(),
    };
    *counter += 1;
    h
}

fn connection_message(counter: &mut u64, id: &Identity, state: ConnectionState) -> Vec<u8> {
    let msg = vda::Connection {
        header: header(counter, id),
        connection_state: state,
    };
    serde_json::to_vec(&msg).expect("serialisable")
}

/// Runs the bridge until `shutdown` completes; then publishes `OFFLINE` and disconnects.
pub async fn run(options: Options, shutdown: impl Future<Output = ()>) -> anyhow::Result<()> {
    let config = &options.config;
    let id = options.identity.clone();
    let topics = Topics::new(&config.interface_name, &id);
    let limits = Limits::default();
    let mut ids = HeaderIds::default();

    let client_id = config
        .client_id
        .clone()
        .unwrap_or_else(|| format!("wlnav-fleet-{}-{}", id.manufacturer, id.serial_number));
    let mut mqtt = MqttOptions::new(client_id, options.host.clone(), options.port);
    mqtt.set_keep_alive(Duration::from_secs(config.keep_alive));
    mqtt.set_max_packet_size(MAX_PACKET, MAX_PACKET);
    mqtt.set_clean_session(true);
    let will = |ids: &mut HeaderIds| {
        LastWill::new(
            topics.connection.clone(),
            connection_message(&mut ids.connection, &id, ConnectionState::ConnectionBroken),
            QoS::AtLeastOnce,
            true,
        )
    };
    mqtt.set_last_will(will(&mut ids));
    let (client, mut eventloop) = AsyncClient::new(mqtt, 256);

    // The daemon side.
    let (cmd_tx, cmd_rx) = std::sync::mpsc::channel::<GoalRequest>();
    let (daemon_tx, mut daemon_rx) = mpsc::unbounded_channel();
    let stop = Arc::new(AtomicBool::new(false));
    let daemon_thread = {
        let stop = stop.clone();
        let ipc = IpcConfig::new(options.prefix.clone());
        let timeout = Duration::from_secs_f64(config.daemon_timeout);
        std::thread::Builder::new()
            .name("daemon-link".into())
            .spawn(move || daemon_link(ipc, timeout, cmd_rx, daemon_tx, stop))
            .context("spawn the daemon thread")?
    };

    let settings = VehicleSettings {
        identity: id.clone(),
        limits: limits.clone(),
        map_id: config.map_id.clone(),
        first_node_range: config.first_node_range,
        machine: config.machine.clone(),
    };
    let mut vehicle = Vehicle::new(settings, shm_ipc::monotonic_now_ns());
    let start = Instant::now();
    let mut state_timer = tokio::time::interval(Duration::from_secs_f64(config.state_interval));
    state_timer.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut connected = false;
    let mut last_state_key = String::new();
    let mut last_error_log: Option<Instant> = None;
    let mut last_tick = 0u64;
    let visualization_interval = 0.2;
    // While the broker is away: when to try again. The event loop is not polled meanwhile,
    // and everything else (telemetry, goals, the order) goes on.
    let mut reconnect_at: Option<tokio::time::Instant> = None;

    tokio::pin!(shutdown);
    loop {
        let mut effects = Vec::new();
        let mut publish_visualization = false;
        tokio::select! {
            _ = &mut shutdown => break,
            _ = tokio::time::sleep_until(reconnect_at.unwrap_or_else(tokio::time::Instant::now)),
                if reconnect_at.is_some() => reconnect_at = None,
            ev = eventloop.poll(), if reconnect_at.is_none() => match ev {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    tracing::info!(broker = %format!("{}:{}", options.host, options.port), "connected to the broker");
                    connected = true;
                    let online = connection_message(&mut ids.connection, &id, ConnectionState::Online);
                    let queued = client
                        .try_subscribe(&topics.order, QoS::AtMostOnce)
                        .and_then(|_| client.try_subscribe(&topics.instant_actions, QoS::AtMostOnce))
                        .and_then(|_| client.try_publish(&topics.connection, QoS::AtLeastOnce, true, online));
                    if let Err(e) = queued {
                        tracing::error!("cannot queue the subscriptions and ONLINE: {e}");
                    }
                    effects.push(Effect::PublishFactsheet);
                    effects.push(Effect::PublishState);
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    let now = start.elapsed();
                    if p.topic == topics.order {
                        effects = vehicle.on_order(&p.payload, now);
                    } else if p.topic == topics.instant_actions {
                        effects = vehicle.on_instant_actions(&p.payload, now);
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    // A message beyond MAX_PACKET: refused before it is read, which drops
                    // the connection; the vehicle reports it in the state.
                    if let rumqttc::ConnectionError::MqttState(rumqttc::StateError::Deserialization(
                        rumqttc::mqttbytes::Error::PayloadSizeLimitExceeded(len),
                    )) = &e
                    {
                        effects = vehicle.on_oversized_message(*len, MAX_PACKET, start.elapsed());
                    }
                    if connected || last_error_log.is_none_or(|t| t.elapsed() > Duration::from_secs(30)) {
                        tracing::warn!("broker {}:{}: {e}; reconnecting", options.host, options.port);
                        last_error_log = Some(Instant::now());
                    }
                    connected = false;
                    // The will goes with the next CONNECT: give it a fresh header.
                    eventloop.mqtt_options.set_last_will(will(&mut ids));
                    // Not a sleep here: the daemon's telemetry must go on being handled (a
                    // pass-through node, an outcome) while the broker is away.
                    reconnect_at = Some(tokio::time::Instant::now() + Duration::from_millis(500));
                }
            },
            msg = daemon_rx.recv() => {
                let now = start.elapsed();
                match msg {
                    Some(FromDaemon::Telemetry(t)) => {
                        effects = vehicle.on_telemetry(&t, now);
                        // One visualization per control tick (not per repeated sample).
                        publish_visualization = t.tick != last_tick;
                        last_tick = t.tick;
                    }
                    Some(FromDaemon::Reply(rid, r)) => effects = vehicle.on_reply(rid, r, now),
                    Some(FromDaemon::Lost) => effects = vehicle.on_daemon_lost(now),
                    None => anyhow::bail!("the daemon thread ended"),
                }
            }
            _ = state_timer.tick() => effects.push(Effect::PublishState),
        }

        let mut publish_state = false;
        for effect in effects {
            match effect {
                Effect::Daemon(req) => {
                    cmd_tx.send(req).context("the daemon thread ended")?;
                }
                Effect::PublishState => publish_state = true,
                Effect::PublishFactsheet if connected => {
                    let h = header(&mut ids.factsheet, &id);
                    let f = factsheet::factsheet(
                        &h,
                        &config.machine,
                        &limits,
                        config.state_interval,
                        visualization_interval,
                    );
                    let _ =
                        client.try_publish(&topics.factsheet, QoS::AtMostOnce, true, f.to_string());
                }
                Effect::PublishFactsheet => {}
            }
        }
        if !connected {
            continue;
        }
        // Every change the specification lists (order, nodes, actions, errors, driving,
        // paused, operating mode …) changes the state without its header and motion fields.
        let key = {
            let mut s = vehicle.state(Header {
                header_id: 0,
                timestamp: String::new(),
                version: String::new(),
                manufacturer: String::new(),
                serial_number: String::new(),
            });
            s.agv_position = None;
            s.velocity = None;
            s.distance_since_last_node = None;
            serde_json::to_string(&s).expect("serialisable")
        };
        if publish_state || key != last_state_key {
            last_state_key = key;
            let s = vehicle.state(header(&mut ids.state, &id));
            let _ = client.try_publish(
                &topics.state,
                QoS::AtMostOnce,
                false,
                serde_json::to_vec(&s).expect("serialisable"),
            );
            state_timer.reset();
        }
        if publish_visualization {
            let v = vehicle.visualization(header(&mut ids.visualization, &id));
            let _ = client.try_publish(
                &topics.visualization,
                QoS::AtMostOnce,
                false,
                serde_json::to_vec(&v).expect("serialisable"),
            );
        }
    }

    // Clean exit: OFFLINE (retained, QoS 1, acknowledged), then an orderly disconnect so the
    // broker does not send the will.
    tracing::info!("shutting down: OFFLINE");
    stop.store(true, Ordering::Relaxed);
    if connected {
        let offline = connection_message(&mut ids.connection, &id, ConnectionState::Offline);
        client.try_publish(&topics.connection, QoS::AtLeastOnce, true, offline)?;
        let deadline = tokio::time::Instant::now() + Duration::from_secs(3);
        let mut disconnect_sent = false;
        while let Ok(ev) = tokio::time::timeout_at(deadline, eventloop.poll()).await {
            match ev {
                Ok(Event::Incoming(Packet::PubAck(_))) if !disconnect_sent => {
                    client.try_disconnect()?;
                    disconnect_sent = true;
                }
                Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => break,
                Ok(_) => {}
                Err(_) => break,
            }
        }
    }
    drop(cmd_tx);
    let _ = daemon_thread.join();
    Ok(())
}

/// The daemon thread (see the module docs).
fn daemon_link(
    ipc: IpcConfig,
    timeout: Duration,
    commands: std::sync::mpsc::Receiver<GoalRequest>,
    tx: mpsc::UnboundedSender<FromDaemon>,
    stop: Arc<AtomicBool>,
) {
    let mut config = ipc;
    let mut logged_absent = false;
    while !stop.load(Ordering::Relaxed) {
        let client = match shm_ipc::Client::new(&config) {
            Ok(c) => c,
            Err(e) => {
                if !logged_absent {
                    tracing::warn!("wlnavd on prefix {:?}: {e}", config.prefix);
                    logged_absent = true;
                }
                // Requests meanwhile fail at once; the vehicle sends them again later.
                while let Ok(req) = commands.try_recv() {
                    let _ = tx.send(FromDaemon::Reply(
                        req.request_id,
                        Err(format!("no wlnavd: {e}")),
                    ));
                }
                std::thread::sleep(Duration::from_millis(200));
                continue;
            }
        };
        // Clean up after a crashed daemon once; later attempts need not list the nodes.
        config.cleanup_stale_nodes = false;
        let subscriber = match client.subscribe_telemetry() {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!("telemetry subscription: {e}");
                std::thread::sleep(Duration::from_millis(200));
                continue;
            }
        };
        let mut last = Instant::now();
        let mut seen = false;
        let mut broken = false;
        loop {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            loop {
                match commands.try_recv() {
                    Ok(req) => {
                        let reply = client
                            .request(&req, Duration::from_secs(1))
                            .map_err(|e| e.to_string());
                        if tx.send(FromDaemon::Reply(req.request_id, reply)).is_err() {
                            return;
                        }
                    }
                    Err(std::sync::mpsc::TryRecvError::Empty) => break,
                    Err(std::sync::mpsc::TryRecvError::Disconnected) => return,
                }
            }
            match subscriber.recv_timeout(Duration::from_millis(50)) {
                Ok(Some(t)) => {
                    last = Instant::now();
                    if !seen {
                        tracing::info!("wlnavd on prefix {:?}: telemetry", config.prefix);
                        seen = true;
                        logged_absent = false;
                    }
                    if tx.send(FromDaemon::Telemetry(Box::new(t))).is_err() {
                        return;
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!("telemetry: {e}");
                    broken = true;
                }
            }
            if broken || last.elapsed() > timeout {
                if tx.send(FromDaemon::Lost).is_err() {
                    return;
                }
                break;
            }
        }
        // Ports dropped here; opened again on the next round.
    }
}
