//! `wlnav record FILE.mcap`: telemetry to an [MCAP](https://mcap.dev) file that Foxglove
//! opens directly. One channel, topic `/wlnav/telemetry`, message encoding `json`, schema
//! `wlnav.Telemetry` (encoding `jsonschema`, the JSON Schema in [`TELEMETRY_JSON_SCHEMA`]).
//! Each message is one tick: the [`Telemetry`] fields by the same names, `mode` and
//! `faults` also as text, times as Foxglove `{sec, nsec}` timestamps. Log time is the
//! receive time (wall clock); publish time is the daemon's tick start converted from
//! `CLOCK_MONOTONIC` to wall clock. Non-finite numbers are written as `null`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use serde_json::{json, Value};

use shm_ipc::Client;
use shm_ipc::IpcConfig;
use shm_ipc::{MachineState, Pose2, Telemetry};

use super::view::{fault_names, mode_name};
use super::{exit, signal, Cli, RecordArgs};

/// Topic of the telemetry channel.
pub const TOPIC: &str = "/wlnav/telemetry";
/// Schema name of the telemetry channel.
pub const SCHEMA_NAME: &str = "wlnav.Telemetry";

/// JSON Schema (draft 2020-12) of one recorded telemetry message.
pub const TELEMETRY_JSON_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "wlnav.Telemetry",
  "description": "One wlnavd control tick (shm-ipc Telemetry, wire format v2). Lengths m, angles rad, speeds m/s.",
  "type": "object",
  "$defs": {
    "num": {"type": ["number", "null"]},
    "time": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "state": {"type": "object", "properties": {
      "x_f": {"$ref": "#/$defs/num"}, "y_f": {"$ref": "#/$defs/num"}, "theta_f": {"$ref": "#/$defs/num"},
      "beta": {"$ref": "#/$defs/num"}, "beta_dot": {"$ref": "#/$defs/num"}, "v_f": {"$ref": "#/$defs/num"}}},
    "pose": {"type": "object", "properties": {
      "x": {"$ref": "#/$defs/num"}, "y": {"$ref": "#/$defs/num"}, "heading": {"$ref": "#/$defs/num"}}}
  },
  "properties": {
    "timestamp": {"$ref": "#/$defs/time", "description": "tick start, wall clock"},
    "tick": {"type": "integer"},
    "timestamp_ns": {"type": "integer", "description": "tick start, CLOCK_MONOTONIC ns"},
    "goal_request_id": {"type": "integer"},
    "mode": {"type": "string", "enum": ["startup", "idle", "tracking", "reached", "stopping", "fault"]},
    "mode_code": {"type": "integer"},
    "fault_flags": {"type": "integer"},
    "faults": {"type": "array", "items": {"type": "string"}},
    "goal_active": {"type": "boolean"},
    "qp_iterations": {"type": "integer"},
    "sqp_iterations": {"type": "integer"},
    "solve_time_us": {"$ref": "#/$defs/num"},
    "cost": {"$ref": "#/$defs/num"},
    "pose_error_xy": {"$ref": "#/$defs/num"},
    "pose_error_heading": {"$ref": "#/$defs/num"},
    "state": {"$ref": "#/$defs/state"},
    "goal": {"$ref": "#/$defs/pose"},
    "command": {"type": "object", "properties": {"beta_dot": {"$ref": "#/$defs/num"}, "v": {"$ref": "#/$defs/num"}}},
    "trajectory": {"type": "array", "items": {"$ref": "#/$defs/state"}, "description": "planned x_0..x_N"},
    "outcome": {"type": "string", "enum": ["none", "succeeded", "cancelled", "preempted", "aborted"], "description": "how a goal ended this tick"},
    "outcome_code": {"type": "integer"},
    "abort_reason": {"type": "string", "description": "no-progress, no-route, goal-in-collision, fault, shutdown; none unless aborted"},
    "outcome_request_id": {"type": "integer", "description": "request id of the goal that ended, 0 if none"},
    "outcome_seq": {"type": "integer"},
    "outcome_text": {"type": "string"},
    "subgoal": {"oneOf": [{"$ref": "#/$defs/pose"}, {"type": "null"}], "description": "current subgoal of the global route"},
    "route": {"type": "array", "items": {"$ref": "#/$defs/pose"}, "description": "global route"}
  },
  "required": ["tick", "timestamp_ns", "mode", "state", "trajectory"]
}"##;

fn num(v: f64) -> Value {
    // serde_json maps non-finite floats to null.
    Value::from(v)
}

fn state_json(s: &MachineState) -> Value {
    json!({
        "x_f": num(s.x_f), "y_f": num(s.y_f), "theta_f": num(s.theta_f),
        "beta": num(s.beta), "beta_dot": num(s.beta_dot), "v_f": num(s.v_f),
    })
}

fn pose_json(p: &Pose2) -> Value {
    json!({"x": num(p.x), "y": num(p.y), "heading": num(p.heading)})
}

fn time_json(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// The JSON message for one tick; `wall_ns` is the tick start on the wall clock.
pub fn telemetry_json(t: &Telemetry, wall_ns: u64) -> Value {
    json!({
        "timestamp": time_json(wall_ns),
        "tick": t.tick,
        "timestamp_ns": t.timestamp_ns,
        "goal_request_id": t.goal_request_id,
        "mode": mode_name(t.mode),
        "mode_code": t.mode,
        "fault_flags": t.fault_flags,
        "faults": fault_names(t.fault_flags),
        "goal_active": t.goal_active != 0,
        "qp_iterations": t.qp_iterations,
        "sqp_iterations": t.sqp_iterations,
        "solve_time_us": num(t.solve_time_us),
        "cost": num(t.cost),
        "pose_error_xy": num(t.pose_error_xy),
        "pose_error_heading": num(t.pose_error_heading),
        "state": state_json(&t.state),
        "goal": pose_json(&t.goal),
        "command": {"beta_dot": num(t.command.beta_dot), "v": num(t.command.v)},
        "trajectory": t.trajectory().iter().map(state_json).collect::<Vec<_>>(),
        "outcome": t.outcome().map_or_else(|c| format!("outcome-{c}"), |o| o.name().to_owned()),
        "outcome_code": t.outcome,
        "abort_reason": t.abort_reason().map_or_else(|c| format!("reason-{c}"), |r| r.name().to_owned()),
        "outcome_request_id": t.outcome_request_id,
        "outcome_seq": t.outcome_seq,
        "outcome_text": t.outcome_text(),
        "subgoal": t.active_subgoal().map(|p| pose_json(&p)),
        "route": t.route().iter().map(pose_json).collect::<Vec<_>>(),
    })
}

fn wall_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// Writes telemetry messages to an MCAP file.
pub struct TelemetryWriter {
    writer: mcap::Writer<BufWriter<File>>,
    channel: u16,
    sequence: u32,
    /// wall − monotonic [ns], measured at creation.
    wall_offset_ns: i128,
}

impl TelemetryWriter {
    /// Creates `path` (truncating it) and writes the header, schema and channel.
    pub fn create(path: &Path, prefix: &str) -> anyhow::Result<Self> {
        let file =
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("wlnav ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .context("cannot start the MCAP file")?;
        let schema =
            writer.add_schema(SCHEMA_NAME, "jsonschema", TELEMETRY_JSON_SCHEMA.as_bytes())?;
        let mut meta = BTreeMap::new();
        meta.insert("prefix".to_owned(), prefix.to_owned());
        meta.insert("wire_format".to_owned(), shm_ipc::API_VERSION.to_owned());
        let channel = writer.add_channel(schema, TOPIC, "json", &meta)?;
        let wall_offset_ns = wall_now_ns() as i128 - shm_ipc::monotonic_now_ns() as i128;
        Ok(Self {
            writer,
            channel,
            sequence: 0,
            wall_offset_ns,
        })
    }

    /// Appends one tick.
    pub fn write(&mut self, t: &Telemetry) -> anyhow::Result<()> {
        let publish = (t.timestamp_ns as i128 + self.wall_offset_ns).max(0) as u64;
        let data = serde_json::to_vec(&telemetry_json(t, publish))?;
        let header = mcap::records::MessageHeader {
            channel_id: self.channel,
            sequence: self.sequence,
            log_time: wall_now_ns(),
            publish_time: publish,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, &data)?;
        Ok(())
    }

    /// Writes the summary and closes the file.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.writer
            .finish()
            .context("cannot finish the MCAP file")?;
        Ok(())
    }
}

/// When a recording stops.
#[derive(Debug, Clone, Default)]
pub struct RecordLimits {
    /// Wall-clock duration.
    pub duration: Option<Duration>,
    /// Number of ticks.
    pub ticks: Option<u64>,
}

/// What a recording holds.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordSummary {
    /// Messages written.
    pub messages: u64,
    /// First and last tick recorded.
    pub first_tick: Option<u64>,
    /// Last tick recorded.
    pub last_tick: Option<u64>,
    /// Ticks between first and last that never arrived (subscriber buffer overflow).
    pub missing_ticks: u64,
}

/// Records telemetry of `config`'s daemon into `path` until a limit is hit, `stop` is set,
/// or SIGINT/SIGTERM arrives. The file is always finished (summary written).
pub fn record(
    config: &IpcConfig,
    path: &Path,
    limits: &RecordLimits,
    stop: &AtomicBool,
) -> anyhow::Result<RecordSummary> {
    let start_wait = Instant::now();
    // The client never creates services: wait for the daemon (or a stop) to appear.
    let client = loop {
        match Client::new(config) {
            Err(shm_ipc::IpcError::NotServed { .. })
                if !(stop.load(Ordering::SeqCst) || signal::requested())
                    && limits
                        .duration
                        .is_none_or(|d| Instant::now() < start_wait + d) =>
            {
                std::thread::sleep(Duration::from_millis(100));
            }
            other => break other?,
        }
    };
    let sub = client.subscribe_telemetry()?;
    let mut out = TelemetryWriter::create(path, &config.prefix)?;
    let start = Instant::now();
    let mut summary = RecordSummary::default();
    let result = (|| -> anyhow::Result<()> {
        loop {
            if stop.load(Ordering::SeqCst) || signal::requested() {
                return Ok(());
            }
            if limits.duration.is_some_and(|d| start.elapsed() >= d) {
                return Ok(());
            }
            if limits.ticks.is_some_and(|n| summary.messages >= n) {
                return Ok(());
            }
            let sample = match sub.recv_timeout(Duration::from_millis(100)) {
                // A signal woke the wait: the check at the top of the loop decides.
                Err(shm_ipc::IpcError::Interrupted) => continue,
                other => other?,
            };
            let Some(t) = sample else {
                continue;
            };
            if let Some(last) = summary.last_tick {
                if t.tick <= last {
                    // A restarted daemon (tick counter reset) or a duplicate: keep it, but
                    // do not count a gap.
                } else {
                    summary.missing_ticks += t.tick - last - 1;
                }
            }
            out.write(&t)?;
            summary.first_tick.get_or_insert(t.tick);
            summary.last_tick = Some(t.tick);
            summary.messages += 1;
        }
    })();
    let finished = out.finish();
    result?;
    finished?;
    Ok(summary)
}

/// `wlnav record FILE.mcap`.
pub fn run(cli: &Cli, a: &RecordArgs) -> anyhow::Result<u8> {
    let config = cli.ipc_config();
    let limits = RecordLimits {
        duration: a.duration.map(Duration::from_secs_f64),
        ticks: a.ticks,
    };
    eprintln!(
        "recording {:?} telemetry to {} (Ctrl-C to stop)",
        config.prefix,
        a.file.display()
    );
    let never = AtomicBool::new(false);
    let s = record(&config, &a.file, &limits, &never)?;
    let range = match (s.first_tick, s.last_tick) {
        (Some(f), Some(l)) => format!(", ticks {f}..={l}"),
        _ => String::new(),
    };
    let interrupted = signal::requested();
    println!(
        "wrote {} ticks to {}{}{}",
        s.messages,
        a.file.display(),
        range,
        if s.missing_ticks > 0 {
            format!(", {} ticks missed", s.missing_ticks)
        } else {
            String::new()
        }
    );
    Ok(if interrupted {
        exit::INTERRUPTED
    } else {
        exit::OK
    })
}
