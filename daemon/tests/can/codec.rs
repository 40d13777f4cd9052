//! Codec: round trips at the limits and mid-range, saturation, non-finite input,
//! and typed errors for every kind of bad frame.

use wlnavd::can::codec::{
    frame_crc, CanMessage, MessageSpec, ANGLE_FACTOR, ANGLE_LIMIT, MACHINE_STATE, MESSAGES,
    SPEED_FACTOR, SPEED_LIMIT, VELOCITY_COMMAND,
};
use wlnavd::can::{
    AliveCounter, CanFrame, DecodeError, DriveMode, EncodeError, MachineState, MachineStatus,
    VelocityCommandFrame, MACHINE_STATE_ID, VELOCITY_COMMAND_ID,
};

const MODES: [DriveMode; 4] = [
    DriveMode::Stop,
    DriveMode::Drive,
    DriveMode::Hold,
    DriveMode::Fault,
];
const STATUSES: [MachineStatus; 5] = [
    MachineStatus::Manual,
    MachineStatus::Ready,
    MachineStatus::Auto,
    MachineStatus::EStop,
    MachineStatus::Fault,
];

fn alive(v: u8) -> AliveCounter {
    AliveCounter::new(v).expect("test counter in range")
}

/// Values a ±limit signal must carry: both limits, zero, one step either side of
/// zero, one step inside each limit, and assorted mid-range values.
fn probe_values(limit: f64, step: f64) -> Vec<f64> {
    vec![
        -limit,
        -limit + step,
        -limit / 2.0,
        -0.123_45,
        -step,
        0.0,
        step,
        0.3,
        0.577,
        limit / 3.0,
        limit - step,
        limit,
    ]
}

fn assert_close(got: f64, want: f64, step: f64, what: &str) {
    assert!(
        (got - want).abs() <= step / 2.0 + 1e-12,
        "{what}: got {got}, want {want} (± {})",
        step / 2.0
    );
}

#[test]
fn command_round_trip_every_signal() {
    let rates = probe_values(ANGLE_LIMIT, ANGLE_FACTOR);
    let speeds = probe_values(SPEED_LIMIT, SPEED_FACTOR);
    let mut n = 0u32;
    for (i, &rate) in rates.iter().enumerate() {
        for (j, &v) in speeds.iter().enumerate() {
            let cmd = VelocityCommandFrame {
                beta_dot_cmd: rate,
                v_cmd: v,
                mode: MODES[(i + j) % MODES.len()],
                alive: alive(((i * 7 + j) % 16) as u8),
            };
            let enc = cmd.encode().expect("finite command encodes");
            assert!(
                enc.saturated.is_empty(),
                "{cmd:?} saturated {:?}",
                enc.saturated
            );
            assert_eq!(enc.frame.id(), VELOCITY_COMMAND_ID);
            assert_eq!(enc.frame.len(), 8);
            let back = VelocityCommandFrame::decode(&enc.frame).expect("own frame decodes");
            assert_close(back.beta_dot_cmd, rate, ANGLE_FACTOR, "beta_dot_cmd");
            assert_close(back.v_cmd, v, SPEED_FACTOR, "v_cmd");
            assert_eq!(back.mode, cmd.mode);
            assert_eq!(back.alive, cmd.alive);
            // Decoded values are exact grid points: encoding them again is lossless.
            assert_eq!(back.encode().unwrap().frame, enc.frame);
            n += 1;
        }
    }
    assert_eq!(n, 144);
    // All alive counter values and modes on their own.
    for c in 0..16 {
        for m in MODES {
            let cmd = VelocityCommandFrame {
                beta_dot_cmd: 0.0,
                v_cmd: 0.0,
                mode: m,
                alive: alive(c),
            };
            let back = VelocityCommandFrame::decode(&cmd.encode().unwrap().frame).unwrap();
            assert_eq!(back, cmd);
        }
    }
}

#[test]
fn state_round_trip_every_signal() {
    let angles = probe_values(ANGLE_LIMIT, ANGLE_FACTOR);
    let speeds = probe_values(SPEED_LIMIT, SPEED_FACTOR);
    for (i, &beta) in angles.iter().enumerate() {
        for (j, &beta_dot) in angles.iter().enumerate() {
            for (k, &v_f) in speeds.iter().enumerate() {
                let st = MachineState {
                    beta,
                    beta_dot,
                    v_f,
                    status: STATUSES[(i + j + k) % STATUSES.len()],
                    alive: alive(((i + 3 * j + 5 * k) % 16) as u8),
                };
                let enc = st.encode().unwrap();
                assert!(enc.saturated.is_empty());
                assert_eq!(enc.frame.id(), MACHINE_STATE_ID);
                let back = MachineState::decode(&enc.frame).unwrap();
                assert_close(back.beta, beta, ANGLE_FACTOR, "beta");
                assert_close(back.beta_dot, beta_dot, ANGLE_FACTOR, "beta_dot");
                assert_close(back.v_f, v_f, SPEED_FACTOR, "v_f");
                assert_eq!(back.status, st.status);
                assert_eq!(back.alive, st.alive);
            }
        }
    }
    for s in STATUSES {
        for c in 0..16 {
            let st = MachineState {
                beta: 0.0,
                beta_dot: 0.0,
                v_f: 0.0,
                status: s,
                alive: alive(c),
            };
            assert_eq!(MachineState::decode(&st.encode().unwrap().frame), Ok(st));
        }
    }
}

#[test]
fn required_ranges_and_resolution_are_covered() {
    // Issue 6 / task brief: ±1 rad, ±1.5 rad/s, ±3 m/s at about 1e-4 resolution.
    let b = MACHINE_STATE.signal("beta").unwrap();
    assert!(b.min <= -1.0 && b.max >= 1.0 && b.factor <= 1e-4);
    for (m, name) in [
        (&MACHINE_STATE, "beta_dot"),
        (&VELOCITY_COMMAND, "beta_dot_cmd"),
    ] {
        let s = m.signal(name).unwrap();
        assert!(s.min <= -1.5 && s.max >= 1.5 && s.factor <= 1e-4, "{name}");
    }
    for (m, name) in [(&MACHINE_STATE, "v_f"), (&VELOCITY_COMMAND, "v_cmd")] {
        let s = m.signal(name).unwrap();
        assert!(s.min <= -3.0 && s.max >= 3.0 && s.factor <= 1e-4, "{name}");
    }
}

#[test]
fn known_bytes() {
    // β̇ = 0.1 rad/s → 2000 = 0x07D0; v = −0.5 m/s → −5000 = 0xEC78; Drive, alive 1.
    let cmd = VelocityCommandFrame {
        beta_dot_cmd: 0.1,
        v_cmd: -0.5,
        mode: DriveMode::Drive,
        alive: alive(1),
    };
    let f = cmd.encode().unwrap().frame;
    assert_eq!(f.data(), &[0xD0, 0x07, 0x78, 0xEC, 0x00, 0x00, 0x11, 0x2D]);
    assert_eq!(f.to_string(), "120#D00778EC0000112D");
}

#[test]
fn saturates_out_of_range_and_reports_it() {
    let cases: [(f64, f64, &[&str]); 6] = [
        (2.0, 0.0, &["beta_dot_cmd"]),
        (0.0, -10.0, &["v_cmd"]),
        (-1e9, 1e9, &["beta_dot_cmd", "v_cmd"]),
        (f64::MAX, f64::MIN, &["beta_dot_cmd", "v_cmd"]),
        // Within half a step of the limit is quantisation, not saturation.
        (ANGLE_LIMIT + 0.4 * ANGLE_FACTOR, 0.0, &[]),
        (ANGLE_LIMIT + 0.6 * ANGLE_FACTOR, 0.0, &["beta_dot_cmd"]),
    ];
    for (rate, v, want) in cases {
        let cmd = VelocityCommandFrame {
            beta_dot_cmd: rate,
            v_cmd: v,
            mode: DriveMode::Drive,
            alive: alive(3),
        };
        let enc = cmd.encode().unwrap();
        let got: Vec<_> = enc.saturated.names().collect();
        assert_eq!(got, want, "rate {rate}, v {v}");
        for name in want {
            assert!(enc.saturated.contains(name));
        }
        let back = VelocityCommandFrame::decode(&enc.frame).unwrap();
        assert!(back.beta_dot_cmd.abs() <= ANGLE_LIMIT + 1e-12);
        assert!(back.v_cmd.abs() <= SPEED_LIMIT + 1e-12);
        if rate > ANGLE_LIMIT + ANGLE_FACTOR {
            assert_close(back.beta_dot_cmd, ANGLE_LIMIT, ANGLE_FACTOR, "beta_dot_cmd");
        }
        if rate < -ANGLE_LIMIT - ANGLE_FACTOR {
            assert_close(
                back.beta_dot_cmd,
                -ANGLE_LIMIT,
                ANGLE_FACTOR,
                "beta_dot_cmd",
            );
        }
        if v < -SPEED_LIMIT {
            assert_close(back.v_cmd, -SPEED_LIMIT, SPEED_FACTOR, "v_cmd");
        }
        if v > SPEED_LIMIT {
            assert_close(back.v_cmd, SPEED_LIMIT, SPEED_FACTOR, "v_cmd");
        }
    }
    // Machine state too (the simulated machine encodes these).
    let st = MachineState {
        beta: -3.0,
        beta_dot: 0.0,
        v_f: 5.0,
        status: MachineStatus::Auto,
        alive: alive(0),
    };
    let enc = st.encode().unwrap();
    assert_eq!(enc.saturated.names().collect::<Vec<_>>(), ["beta", "v_f"]);
    let back = MachineState::decode(&enc.frame).unwrap();
    assert_close(back.beta, -ANGLE_LIMIT, ANGLE_FACTOR, "beta");
    assert_close(back.v_f, SPEED_LIMIT, SPEED_FACTOR, "v_f");
}

#[test]
fn rejects_non_finite_input() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let cmd = VelocityCommandFrame {
            beta_dot_cmd: 0.0,
            v_cmd: bad,
            mode: DriveMode::Drive,
            alive: alive(0),
        };
        match cmd.encode() {
            Err(EncodeError::NonFinite {
                message, signal, ..
            }) => {
                assert_eq!(message, "WLNAV_VelocityCommand");
                assert_eq!(signal, "v_cmd");
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
        let st = MachineState {
            beta: bad,
            beta_dot: 0.0,
            v_f: 0.0,
            status: MachineStatus::Ready,
            alive: alive(0),
        };
        let e = st.encode().unwrap_err();
        assert!(e.to_string().contains("WLNAV_MachineState.beta"), "{e}");
    }
}

fn state_frame() -> CanFrame {
    MachineState {
        beta: 0.2,
        beta_dot: -0.1,
        v_f: 0.8,
        status: MachineStatus::Auto,
        alive: alive(7),
    }
    .encode()
    .unwrap()
    .frame
}

/// Rebuild a frame with new bytes and a correct CRC, to reach the checks behind it.
fn with_crc(id: u16, mut data: [u8; 8]) -> CanFrame {
    data[7] = frame_crc(&data);
    CanFrame::new8(id, data).unwrap()
}

#[test]
fn typed_decode_errors() {
    let good = state_frame();
    // Wrong message.
    assert_eq!(
        MachineState::decode(&CanFrame::new8(VELOCITY_COMMAND_ID, *good.raw_data()).unwrap()),
        Err(DecodeError::WrongId {
            message: "WLNAV_MachineState",
            expected: MACHINE_STATE_ID,
            got: VELOCITY_COMMAND_ID
        })
    );
    // Short frame.
    let short = CanFrame::new(MACHINE_STATE_ID, &good.data()[..7]).unwrap();
    assert_eq!(
        MachineState::decode(&short),
        Err(DecodeError::WrongLength {
            message: "WLNAV_MachineState",
            expected: 8,
            got: 7
        })
    );
    // Every single-bit flip anywhere in the frame is a CRC error.
    for bit in 0..64 {
        let mut d = *good.raw_data();
        d[bit / 8] ^= 1 << (bit % 8);
        let e = MachineState::decode(&CanFrame::new8(MACHINE_STATE_ID, d).unwrap()).unwrap_err();
        assert!(matches!(e, DecodeError::BadCrc { .. }), "bit {bit}: {e:?}");
    }
    let mut d = *good.raw_data();
    d[7] ^= 0xFF;
    let e = MachineState::decode(&CanFrame::new8(MACHINE_STATE_ID, d).unwrap()).unwrap_err();
    assert!(e.to_string().contains("CRC mismatch"), "{e}");
    // Raw −32768 (0x8000) is outside [min|max].
    let mut d = *good.raw_data();
    d[2] = 0x00;
    d[3] = 0x80;
    assert_eq!(
        MachineState::decode(&with_crc(MACHINE_STATE_ID, d)),
        Err(DecodeError::OutOfRange {
            message: "WLNAV_MachineState",
            signal: "beta_dot",
            raw: -32768,
            min: -32767,
            max: 32767
        })
    );
    // Undefined status 5..=15.
    for s in 5..16u8 {
        let mut d = *good.raw_data();
        d[6] = (d[6] & 0x0F) | (s << 4);
        let e = MachineState::decode(&with_crc(MACHINE_STATE_ID, d)).unwrap_err();
        assert!(
            matches!(e, DecodeError::OutOfRange { signal: "status", raw, .. } if raw == i64::from(s)),
            "{e:?}"
        );
    }
    // Undefined mode 4..=15 in a command.
    let cmd = VelocityCommandFrame {
        beta_dot_cmd: 0.0,
        v_cmd: 0.0,
        mode: DriveMode::Stop,
        alive: alive(0),
    };
    for m in 4..16u8 {
        let mut d = *cmd.encode().unwrap().frame.raw_data();
        d[6] |= m << 4;
        let e = VelocityCommandFrame::decode(&with_crc(VELOCITY_COMMAND_ID, d)).unwrap_err();
        assert!(e.to_string().contains("WLNAV_VelocityCommand.mode"), "{e}");
    }
    // Reserved bytes 4 and 5 of the command are ignored (but CRC-protected).
    let mut d = *cmd.encode().unwrap().frame.raw_data();
    d[4] = 0xAB;
    d[5] = 0xCD;
    assert_eq!(
        VelocityCommandFrame::decode(&with_crc(VELOCITY_COMMAND_ID, d)),
        Ok(cmd)
    );
}

#[test]
fn arbitrary_bytes_never_panic() {
    // Any id, length and payload: decode returns Ok or a typed error.
    let mut x: u64 = 0x0123_4567_89AB_CDEF;
    let mut ok = 0;
    for i in 0..200_000u32 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let len = (i % 9) as usize;
        let id = if i % 3 == 0 {
            MACHINE_STATE_ID
        } else {
            VELOCITY_COMMAND_ID
        };
        let mut d = x.to_le_bytes();
        if i % 2 == 0 {
            // Half the inputs get a valid CRC so range checks are exercised too.
            d[7] = frame_crc(&d);
        }
        let f = CanFrame::new(id, &d[..len]).unwrap();
        if MachineState::decode(&f).is_ok() {
            ok += 1;
        }
        if VelocityCommandFrame::decode(&f).is_ok() {
            ok += 1;
        }
    }
    assert!(ok > 0, "some random frames with valid CRC should decode");
}

#[test]
fn spec_tables_list_every_byte() {
    // Everything except the command's reserved bytes 4..=5 and nothing else is used.
    fn used_bits(m: &MessageSpec) -> u64 {
        m.signals
            .iter()
            .map(|s| ((1u64 << s.size) - 1) << s.start_bit)
            .fold(0, |a, b| a | b)
    }
    assert_eq!(used_bits(&MACHINE_STATE), u64::MAX);
    assert_eq!(used_bits(&VELOCITY_COMMAND), !0x0000_FFFF_0000_0000);
    assert_eq!(MESSAGES.len(), 2);
    assert_eq!(
        <VelocityCommandFrame as CanMessage>::SPEC.id,
        VELOCITY_COMMAND_ID
    );
    assert_eq!(<MachineState as CanMessage>::SPEC.id, MACHINE_STATE_ID);
}
