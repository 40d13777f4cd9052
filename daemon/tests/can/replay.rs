//! `candump -L` replay of a hand-written log, and logs written by the logger read
//! back.

use std::path::{Path, PathBuf};
use std::time::Duration;

use socketcan::{EmbeddedFrame, Id};
use wlnavd::can::log::{format_line, LineProblem};
use wlnavd::can::tracker::RxError;
use wlnavd::can::{
    AliveCounter, AliveError, CanBus, CanFrame, CandumpReader, CandumpWriter, DecodeError,
    DriveMode, LogRecord, LoggingBus, LoopbackBus, MachineState, MachineStatus, ReplayError,
    RxTracker, VelocityCommandFrame, MACHINE_STATE_ID, VELOCITY_COMMAND_ID,
};

fn data_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn tmp_file(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("wlnavd-can-tests");
    std::fs::create_dir_all(&dir).expect("create test tmp dir");
    let p = dir.join(format!("{}-{name}", std::process::id()));
    let _ = std::fs::remove_file(&p);
    p
}

fn read_all(path: &Path) -> Vec<LogRecord> {
    CandumpReader::open(path)
        .unwrap_or_else(|e| panic!("{e}"))
        .map(|r| r.unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn hand_written_log_decodes_to_expected_values() {
    let records = read_all(&data_file("machine_session.candump"));
    assert_eq!(records.len(), 11);
    for (i, r) in records.iter().enumerate() {
        assert_eq!(r.iface, "can0");
        assert_eq!(
            r.timestamp,
            Duration::new(1_700_000_000, 0) + Duration::from_micros(i as u64 * 20_000 + 123)
        );
    }

    let mut states = RxTracker::<MachineState>::new(0);
    let mut foreign = 0;
    let mut got_states = Vec::new();
    let mut got_cmds = Vec::new();
    let mut state_errors = Vec::new();
    for (line, r) in records.iter().enumerate().map(|(i, r)| (i + 1, r)) {
        match r.frame.id() {
            MACHINE_STATE_ID => match states.accept(&r.frame) {
                Ok(s) => got_states.push((line, s)),
                Err(e) => state_errors.push((line, e)),
            },
            // The log holds only a few commands (alive 0, 1, 15): decode without the
            // sequence check.
            VELOCITY_COMMAND_ID => {
                got_cmds.push((line, VelocityCommandFrame::decode(&r.frame).unwrap()))
            }
            _ => foreign += 1,
        }
    }
    assert_eq!(foreign, 1);

    let a = |v| AliveCounter::new(v).unwrap();
    let want_states = [
        (1, 0.0, 0.0, 0.0, MachineStatus::Ready, 0),
        (3, 0.5, -0.25, 1.2345, MachineStatus::Auto, 1),
        (5, 1.63835, -1.63835, 3.2767, MachineStatus::Auto, 2),
        (6, -1.63835, 1.63835, -3.2767, MachineStatus::EStop, 3),
        (9, 0.0001, 0.00005, -0.0001, MachineStatus::Fault, 4),
    ];
    assert_eq!(got_states.len(), want_states.len());
    for ((line, s), (wl, beta, beta_dot, v_f, status, alive)) in got_states.iter().zip(want_states)
    {
        assert_eq!(*line, wl);
        assert!(close(s.beta, beta), "line {line}: beta {}", s.beta);
        assert!(
            close(s.beta_dot, beta_dot),
            "line {line}: beta_dot {}",
            s.beta_dot
        );
        assert!(close(s.v_f, v_f), "line {line}: v_f {}", s.v_f);
        assert_eq!(s.status, status, "line {line}");
        assert_eq!(s.alive, a(alive), "line {line}");
    }

    let want_cmds = [
        (2, 0.0, 0.0, DriveMode::Hold, 0),
        (4, 0.1, -0.5, DriveMode::Drive, 1),
        (11, -1.63835, 3.2767, DriveMode::Stop, 15),
    ];
    assert_eq!(got_cmds.len(), want_cmds.len());
    for ((line, c), (wl, rate, v, mode, alive)) in got_cmds.iter().zip(want_cmds) {
        assert_eq!(*line, wl);
        assert!(
            close(c.beta_dot_cmd, rate),
            "line {line}: {}",
            c.beta_dot_cmd
        );
        assert!(close(c.v_cmd, v), "line {line}: {}", c.v_cmd);
        assert_eq!(c.mode, mode, "line {line}");
        assert_eq!(c.alive, a(alive), "line {line}");
    }

    // Line 8: corrupted CRC; line 10: repeated alive counter.
    assert_eq!(state_errors.len(), 2);
    assert_eq!(state_errors[0].0, 8);
    assert_eq!(
        state_errors[0].1,
        RxError::Decode(DecodeError::BadCrc {
            message: "WLNAV_MachineState",
            received: 0xF3,
            computed: 0xF2
        })
    );
    assert_eq!(state_errors[1].0, 10);
    assert_eq!(
        state_errors[1].1,
        RxError::Alive {
            message: "WLNAV_MachineState",
            source: AliveError::Frozen {
                counter: 4,
                repeats: 1
            }
        }
    );
    let c = states.counters();
    assert_eq!((c.accepted, c.bad_crc, c.frozen, c.skipped), (5, 1, 1, 0));
    assert_eq!(c.consecutive_bad, 1);
}

/// Our reader and `socketcan::dump::Reader` (an independent parser) agree on the
/// hand-written log.
#[test]
fn reader_agrees_with_socketcan_dump_reader() {
    let path = data_file("machine_session.candump");
    let ours = read_all(&path);
    let theirs: Vec<_> = socketcan::dump::Reader::from_file(&path)
        .expect("open log")
        .map(|r| r.expect("socketcan parses the log"))
        .collect();
    assert_eq!(ours.len(), theirs.len());
    for (o, t) in ours.iter().zip(&theirs) {
        assert_eq!(o.timestamp.as_micros() as u64, t.t_us);
        assert_eq!(o.iface, t.device);
        let socketcan::CanAnyFrame::Normal(f) = &t.frame else {
            panic!("not a classic data frame: {:?}", t.frame);
        };
        let Id::Standard(id) = f.id() else {
            panic!("extended id")
        };
        assert_eq!(o.frame.id(), id.as_raw());
        assert_eq!(o.frame.data(), f.data());
    }
}

#[test]
fn bad_log_lines_are_named() {
    let path = tmp_file("bad.log");
    std::fs::write(
        &path,
        "(1700000000.000000) can0 121#00000000000010C7\n\
         (1700000000.000001) can0 121#0000000000001\n\
         (1700000000.000002) can0 12345678#00\n\
         garbage\n\
         (1700000000.000003) can0 120#000000000000208D\n",
    )
    .unwrap();
    let got: Vec<_> = CandumpReader::open(&path).unwrap().collect();
    assert_eq!(got.len(), 5);
    assert!(got[0].is_ok() && got[4].is_ok());
    let expect = [
        (2, LineProblem::BadData),
        (3, LineProblem::ExtendedId),
        (4, LineProblem::MissingField),
    ];
    for (r, (line, problem)) in got[1..4].iter().zip(expect) {
        let e = r.as_ref().unwrap_err();
        assert_eq!(e.line(), Some(line));
        assert_eq!(e.problem(), Some(problem));
        let msg = e.to_string();
        assert!(msg.contains(&format!("bad.log line {line}: ")), "{msg}");
    }
    match CandumpReader::open(&tmp_file("missing.log")) {
        Err(ReplayError::Open { source_name, .. }) => assert!(source_name.ends_with("missing.log")),
        other => panic!("expected Open error, got {other:?}"),
    }
}

#[test]
fn writer_output_reads_back() {
    let path = tmp_file("writer.log");
    let mut w = CandumpWriter::append_to(&path, "can0").unwrap();
    let mut frames = Vec::new();
    let mut alive = AliveCounter::ZERO;
    for i in 0..40 {
        let cmd = VelocityCommandFrame {
            beta_dot_cmd: 0.01 * f64::from(i) - 0.2,
            v_cmd: 0.05 * f64::from(i) - 1.0,
            mode: DriveMode::Drive,
            alive,
        };
        alive = alive.next();
        let f = cmd.encode().unwrap().frame;
        let t = std::time::UNIX_EPOCH
            + Duration::from_micros(1_700_000_000_000_000 + 200_000 * u64::from(i as u32));
        w.write(t, &f).unwrap();
        frames.push((t, f, cmd));
    }
    drop(w);
    // Appending, not truncating: a second writer adds after the first.
    let extra = CanFrame::new(0x7E8, &[1, 2, 3]).unwrap();
    CandumpWriter::append_to(&path, "can0")
        .unwrap()
        .write(
            std::time::UNIX_EPOCH + Duration::from_secs(1_700_000_010),
            &extra,
        )
        .unwrap();

    let text = std::fs::read_to_string(&path).unwrap();
    let first = text.lines().next().unwrap();
    assert_eq!(first, format_line(frames[0].0, "can0", &frames[0].1));
    assert!(
        first.starts_with("(1700000000.000000) can0 120#"),
        "{first}"
    );

    let back = read_all(&path);
    assert_eq!(back.len(), frames.len() + 1);
    for (r, (t, f, cmd)) in back.iter().zip(&frames) {
        assert_eq!(r.frame, *f);
        assert_eq!(
            Some(r.timestamp),
            t.duration_since(std::time::UNIX_EPOCH).ok()
        );
        assert_eq!(
            VelocityCommandFrame::decode(&r.frame).unwrap().alive,
            cmd.alive
        );
    }
    assert_eq!(back.last().unwrap().frame, extra);
}

/// The logging wrapper records every frame sent and received, in order.
#[tokio::test]
async fn logging_bus_logs_both_directions() {
    let path = tmp_file("bus.log");
    let (daemon_end, mut machine) = LoopbackBus::pair("sim");
    let mut bus = LoggingBus::new(daemon_end, CandumpWriter::append_to(&path, "can0").unwrap());

    let mut expected = Vec::new();
    let mut c_alive = AliveCounter::ZERO;
    let mut s_alive = AliveCounter::ZERO;
    for i in 0..10 {
        let cmd = VelocityCommandFrame {
            beta_dot_cmd: 0.1,
            v_cmd: 0.02 * f64::from(i),
            mode: DriveMode::Drive,
            alive: c_alive,
        }
        .encode()
        .unwrap()
        .frame;
        c_alive = c_alive.next();
        bus.send(&cmd).await.unwrap();
        expected.push(cmd);
        assert_eq!(machine.recv().await.unwrap(), cmd);

        let st = MachineState {
            beta: 0.01 * f64::from(i),
            beta_dot: 0.1,
            v_f: 0.02 * f64::from(i),
            status: MachineStatus::Auto,
            alive: s_alive,
        }
        .encode()
        .unwrap()
        .frame;
        s_alive = s_alive.next();
        machine.send(&st).await.unwrap();
        assert_eq!(bus.recv().await.unwrap(), st);
        expected.push(st);
    }
    assert_eq!(bus.log_errors(), 0);
    assert_eq!(bus.name(), "sim.a");
    drop(bus);

    let back = read_all(&path);
    assert_eq!(back.iter().map(|r| r.frame).collect::<Vec<_>>(), expected);
    assert!(back.iter().all(|r| r.iface == "can0"));
    assert!(back.windows(2).all(|w| w[0].timestamp <= w[1].timestamp));
    // And the log replays through the receive checks without a single rejection.
    let mut rx = RxTracker::<MachineState>::new(0);
    for r in &back {
        if rx.is_for(&r.frame) {
            rx.accept(&r.frame).unwrap();
        }
    }
    assert_eq!(rx.counters().accepted, 10);
}
