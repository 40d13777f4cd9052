//! The DBC file, parsed by an independent parser (`can-dbc`), must describe exactly
//! the layout the codec implements.

use can_dbc::{ByteOrder, Dbc, MessageId, MultiplexIndicator, NumericValue, ValueType};
use wlnavd::can::codec::{MessageSpec, MESSAGES};
use wlnavd::can::{AliveCounter, CanFrame, DriveMode, MachineState, MachineStatus};

const DBC_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/can/wlnav.dbc");

fn load() -> Dbc {
    let text = std::fs::read_to_string(DBC_PATH).expect("read daemon/can/wlnav.dbc");
    Dbc::try_from(text.as_str()).unwrap_or_else(|e| panic!("{DBC_PATH} does not parse: {e:?}"))
}

fn num(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

fn spec_for(id: u16) -> &'static MessageSpec {
    MESSAGES
        .iter()
        .copied()
        .find(|m| m.id == id)
        .unwrap_or_else(|| panic!("DBC message {id:#x} unknown to the codec"))
}

#[test]
fn dbc_matches_codec_layout() {
    let dbc = load();
    assert_eq!(dbc.messages.len(), MESSAGES.len(), "message count");
    for msg in &dbc.messages {
        let id = match msg.id {
            MessageId::Standard(id) => id,
            MessageId::Extended(id) => panic!("{}: extended id {id:#x}", msg.name),
        };
        let spec = spec_for(id);
        assert_eq!(msg.name, spec.name, "name of {id:#x}");
        assert_eq!(msg.size as usize, spec.dlc, "{}: size", msg.name);
        assert_eq!(
            msg.transmitter.as_deref(),
            Some(spec.transmitter),
            "{}: transmitter",
            msg.name
        );
        assert_eq!(
            msg.signals.len(),
            spec.signals.len(),
            "{}: signal count",
            msg.name
        );
        for sig in &msg.signals {
            let s = spec
                .signal(&sig.name)
                .unwrap_or_else(|| panic!("{}.{}: not in the codec", msg.name, sig.name));
            let what = format!("{}.{}", msg.name, sig.name);
            assert_eq!(
                sig.multiplexer_indicator,
                MultiplexIndicator::Plain,
                "{what}"
            );
            assert_eq!(sig.start_bit, u64::from(s.start_bit), "{what}: start bit");
            assert_eq!(sig.size, u64::from(s.size), "{what}: size");
            assert_eq!(
                sig.byte_order,
                if s.little_endian {
                    ByteOrder::LittleEndian
                } else {
                    ByteOrder::BigEndian
                },
                "{what}: byte order"
            );
            assert_eq!(
                sig.value_type,
                if s.signed {
                    ValueType::Signed
                } else {
                    ValueType::Unsigned
                },
                "{what}: signedness"
            );
            assert_eq!(sig.factor, s.factor, "{what}: factor");
            assert_eq!(sig.offset, s.offset, "{what}: offset");
            assert_eq!(num(&sig.min), s.min, "{what}: min");
            assert_eq!(num(&sig.max), s.max, "{what}: max");
            assert_eq!(sig.unit, s.unit, "{what}: unit");
        }
    }
    // Every message is little-endian with the CRC in byte 7 (documented in the DBC).
    for m in MESSAGES {
        assert!(m.signals.iter().all(|s| s.little_endian));
    }
}

#[test]
fn dbc_value_tables_match_enums() {
    let dbc = load();
    let cmd = MessageId::Standard(wlnavd::can::VELOCITY_COMMAND_ID);
    let st = MessageId::Standard(wlnavd::can::MACHINE_STATE_ID);
    let modes: Vec<(i64, String)> = dbc
        .value_descriptions_for_signal(cmd, "mode")
        .expect("VAL_ for mode")
        .iter()
        .map(|v| (v.id, v.description.clone()))
        .collect();
    let want_modes = [
        (DriveMode::Stop, "Stop"),
        (DriveMode::Drive, "Drive"),
        (DriveMode::Hold, "Hold"),
        (DriveMode::Fault, "Fault"),
    ];
    assert_eq!(modes.len(), want_modes.len());
    for (m, name) in want_modes {
        assert!(modes.contains(&(m as i64, name.to_owned())), "{name}");
        assert_eq!(format!("{m:?}"), name);
    }
    let statuses: Vec<(i64, String)> = dbc
        .value_descriptions_for_signal(st, "status")
        .expect("VAL_ for status")
        .iter()
        .map(|v| (v.id, v.description.clone()))
        .collect();
    let want_statuses = [
        (MachineStatus::Manual, "Manual"),
        (MachineStatus::Ready, "Ready"),
        (MachineStatus::Auto, "Auto"),
        (MachineStatus::EStop, "EStop"),
        (MachineStatus::Fault, "Fault"),
    ];
    assert_eq!(statuses.len(), want_statuses.len());
    for (s, name) in want_statuses {
        assert!(statuses.contains(&(s as i64, name.to_owned())), "{name}");
        assert_eq!(format!("{s:?}"), name);
    }
}

/// Decode a frame with nothing but the parsed DBC (generic Intel extraction), as a
/// third-party tool would, and compare with the codec.
#[test]
fn generic_dbc_decoding_agrees_with_codec() {
    let dbc = load();
    let st = MachineState {
        beta: -0.61,
        beta_dot: 0.4321,
        v_f: -2.5,
        status: MachineStatus::EStop,
        alive: AliveCounter::new(9).unwrap(),
    };
    let frame: CanFrame = st.encode().unwrap().frame;
    let word = u64::from_le_bytes(*frame.raw_data());
    let msg = dbc
        .messages
        .iter()
        .find(|m| m.id == MessageId::Standard(frame.id()))
        .unwrap();
    let phys = |name: &str| -> f64 {
        let s = msg.signals.iter().find(|s| s.name == name).unwrap();
        let raw = (word >> s.start_bit) & ((1u64 << s.size) - 1);
        let raw = if s.value_type == ValueType::Signed && raw >> (s.size - 1) == 1 {
            raw as i64 - (1i64 << s.size)
        } else {
            raw as i64
        };
        raw as f64 * s.factor + s.offset
    };
    assert!((phys("beta") - st.beta).abs() < 1e-9);
    assert!((phys("beta_dot") - st.beta_dot).abs() < 1e-9);
    assert!((phys("v_f") - st.v_f).abs() < 1e-9);
    assert_eq!(phys("status"), MachineStatus::EStop as u8 as f64);
    assert_eq!(phys("state_alive"), 9.0);
    assert_eq!(phys("state_crc"), f64::from(frame.raw_data()[7]));
}
