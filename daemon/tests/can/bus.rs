//! Buses and receive tracking end to end: a test "machine" on one end of a
//! loopback bus, the receive checks on the other.

use wlnavd::can::codec::frame_crc;
use wlnavd::can::tracker::RxError;
use wlnavd::can::{
    AliveCounter, AliveError, CanBus, CanError, CanFrame, DecodeError, DriveMode, LoopbackBus,
    MachineState, MachineStatus, RxTracker, VelocityCommandFrame,
};

fn state(alive: AliveCounter, v_f: f64) -> MachineState {
    MachineState {
        beta: 0.1,
        beta_dot: 0.0,
        v_f,
        status: MachineStatus::Auto,
        alive,
    }
}

#[tokio::test]
async fn alive_counter_wraps_over_the_bus() {
    let (mut daemon, mut machine) = LoopbackBus::pair("wrap");
    let mut rx = RxTracker::<MachineState>::new(0);
    let mut alive = AliveCounter::ZERO;
    let mut seen = Vec::new();
    for i in 0..50 {
        machine
            .send(&state(alive, f64::from(i) * 0.01).encode().unwrap().frame)
            .await
            .unwrap();
        alive = alive.next();
        let s = rx.accept(&daemon.recv().await.unwrap()).unwrap();
        seen.push(s.alive.get());
    }
    let want: Vec<u8> = (0..50).map(|i| (i % 16) as u8).collect();
    assert_eq!(seen, want, "15 wraps to 0");
    assert_eq!(rx.counters().accepted, 50);
    assert_eq!(rx.counters().rejected(), 0);
}

#[tokio::test]
async fn frozen_counter_detected_and_counted() {
    let (mut daemon, mut machine) = LoopbackBus::pair("frozen");
    let mut rx = RxTracker::<MachineState>::new(0);
    let stuck = state(AliveCounter::new(15).unwrap(), 0.3)
        .encode()
        .unwrap()
        .frame;
    // A hung sender repeats its last frame 5 times.
    for _ in 0..6 {
        machine.send(&stuck).await.unwrap();
    }
    assert!(rx.accept(&daemon.recv().await.unwrap()).is_ok());
    for k in 1..=5u32 {
        let e = rx.accept(&daemon.recv().await.unwrap()).unwrap_err();
        assert_eq!(
            e,
            RxError::Alive {
                message: "WLNAV_MachineState",
                source: AliveError::Frozen {
                    counter: 15,
                    repeats: k
                }
            }
        );
        assert_eq!(rx.counters().consecutive_bad, k);
    }
    assert_eq!(rx.counters().frozen, 5);
    // Recovery: the next counter (0, after the wrap) is accepted and the run resets.
    let next = state(AliveCounter::ZERO, 0.3).encode().unwrap().frame;
    machine.send(&next).await.unwrap();
    assert!(rx.accept(&daemon.recv().await.unwrap()).is_ok());
    let c = rx.counters();
    assert_eq!((c.accepted, c.frozen, c.consecutive_bad), (2, 5, 0));
}

#[tokio::test]
async fn skipped_counter_and_lost_frames() {
    let mut rx = RxTracker::<MachineState>::new(2);
    let f = |c: u8| {
        state(AliveCounter::new(c).unwrap(), 0.0)
            .encode()
            .unwrap()
            .frame
    };
    rx.accept(&f(0)).unwrap();
    rx.accept(&f(3)).unwrap(); // 2 lost: tolerated
    let e = rx.accept(&f(9)).unwrap_err(); // 5 lost: too many
    assert_eq!(
        e,
        RxError::Alive {
            message: "WLNAV_MachineState",
            source: AliveError::Skipped {
                previous: 3,
                got: 9,
                lost: 5,
                max_lost: 2
            }
        }
    );
    assert!(e.to_string().contains("jumped from 3 to 9"), "{e}");
    rx.accept(&f(10)).unwrap(); // re-synchronised
    let c = rx.counters();
    assert_eq!((c.accepted, c.skipped, c.lost), (3, 1, 7));
}

/// A burst of corrupted frames: every one is rejected and counted, the run of
/// consecutive bad frames is what the safety logic compares against its limit.
#[tokio::test]
async fn crc_burst_rejected_and_counted() {
    let (mut daemon, mut machine) = LoopbackBus::pair("burst");
    let mut rx = RxTracker::<MachineState>::new(0);
    let mut alive = AliveCounter::ZERO;
    let mut max_run = 0;
    for i in 0..30 {
        let mut d = *state(alive, 0.5).encode().unwrap().frame.raw_data();
        alive = alive.next();
        if (10..20).contains(&i) {
            d[1] ^= 0x40; // corrupted on the wire
        }
        machine
            .send(&CanFrame::new8(0x121, d).unwrap())
            .await
            .unwrap();
        let r = rx.accept(&daemon.recv().await.unwrap());
        if (10..20).contains(&i) {
            assert!(
                matches!(r, Err(RxError::Decode(DecodeError::BadCrc { .. }))),
                "{i}: {r:?}"
            );
        } else if i == 20 {
            // 10 frames lost to corruption: the counter jump is itself flagged.
            assert!(
                matches!(
                    r,
                    Err(RxError::Alive {
                        source: AliveError::Skipped { lost: 10, .. },
                        ..
                    })
                ),
                "{r:?}"
            );
        } else {
            assert!(r.is_ok(), "{i}: {r:?}");
        }
        max_run = max_run.max(rx.counters().consecutive_bad);
    }
    let c = rx.counters();
    assert_eq!(c.bad_crc, 10);
    assert_eq!(c.skipped, 1);
    assert_eq!(max_run, 11);
    assert_eq!(c.consecutive_bad, 0);
    assert_eq!(c.accepted, 19);
}

#[tokio::test]
async fn wrong_length_and_foreign_frames() {
    let mut rx = RxTracker::<MachineState>::new(0);
    let foreign = CanFrame::new(0x7E8, &[0; 8]).unwrap();
    assert!(!rx.is_for(&foreign));
    assert!(matches!(
        rx.accept(&foreign),
        Err(RxError::Decode(DecodeError::WrongId { .. }))
    ));
    let mut d = [0u8; 8];
    d[7] = frame_crc(&d);
    let short = CanFrame::new(0x121, &d[..6]).unwrap();
    assert!(matches!(
        rx.accept(&short),
        Err(RxError::Decode(DecodeError::WrongLength { got: 6, .. }))
    ));
    let c = rx.counters();
    // Foreign traffic is not a fault of this link.
    assert_eq!((c.wrong_id, c.wrong_length, c.consecutive_bad), (1, 1, 1));
}

/// The daemon side as it will be written: a boxed bus chosen at run time, a
/// command sent, the machine (here the test) answering.
#[tokio::test]
async fn command_out_state_in_through_dyn_bus() {
    let (a, mut machine) = LoopbackBus::pair("dyn");
    let mut bus: Box<dyn CanBus> = Box::new(a);
    let cmd = VelocityCommandFrame {
        beta_dot_cmd: -0.3,
        v_cmd: 0.7,
        mode: DriveMode::Drive,
        alive: AliveCounter::new(4).unwrap(),
    };
    bus.send(&cmd.encode().unwrap().frame).await.unwrap();
    let got = VelocityCommandFrame::decode(&machine.recv().await.unwrap()).unwrap();
    assert!(
        (got.v_cmd - cmd.v_cmd).abs() < 1e-9 && (got.beta_dot_cmd - cmd.beta_dot_cmd).abs() < 1e-9
    );
    assert_eq!((got.mode, got.alive), (cmd.mode, cmd.alive));
    let reply = state(AliveCounter::ZERO, got.v_cmd);
    machine.send(&reply.encode().unwrap().frame).await.unwrap();
    let back = MachineState::decode(&bus.recv().await.unwrap()).unwrap();
    assert!((back.v_f - 0.7).abs() < 1e-9);
    // recv is cancel-safe: a timed-out recv loses nothing.
    let timed_out = tokio::time::timeout(std::time::Duration::from_millis(5), bus.recv()).await;
    assert!(timed_out.is_err());
    machine.send(&reply.encode().unwrap().frame).await.unwrap();
    assert!(bus.recv().await.is_ok());
    drop(machine);
    assert!(matches!(bus.recv().await, Err(CanError::Closed { .. })));
}
