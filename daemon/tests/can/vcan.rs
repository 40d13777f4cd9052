//! SocketCAN backend on a real virtual interface. Needs `vcan0`:
//!
//! ```sh
//! modprobe vcan && ip link add dev vcan0 type vcan && ip link set up vcan0
//! cargo test -p daemon --features vcan-tests
//! ```
//!
//! Off by default because sandboxes and CI containers have no AF_CAN. The interface
//! name can be overridden with `WLNAV_VCAN`.

use std::time::Duration;

use wlnavd::can::{
    AliveCounter, CanBus, DriveMode, MachineState, MachineStatus, SocketCanBus,
    VelocityCommandFrame, MACHINE_STATE_ID, VELOCITY_COMMAND_ID,
};

fn iface() -> String {
    std::env::var("WLNAV_VCAN").unwrap_or_else(|_| "vcan0".to_owned())
}

#[tokio::test]
async fn frames_cross_vcan_both_ways() {
    let name = iface();
    let mut daemon = SocketCanBus::open_filtered(&name, &[MACHINE_STATE_ID]).expect("open vcan");
    let mut machine =
        SocketCanBus::open_filtered(&name, &[VELOCITY_COMMAND_ID]).expect("open vcan");
    let cmd = VelocityCommandFrame {
        beta_dot_cmd: 0.25,
        v_cmd: -1.0,
        mode: DriveMode::Drive,
        alive: AliveCounter::new(12).unwrap(),
    };
    daemon.send(&cmd.encode().unwrap().frame).await.unwrap();
    let got = tokio::time::timeout(Duration::from_secs(2), machine.recv())
        .await
        .expect("command arrives")
        .unwrap();
    assert_eq!(VelocityCommandFrame::decode(&got), Ok(cmd));

    let st = MachineState {
        beta: -0.4,
        beta_dot: 0.1,
        v_f: 0.9,
        status: MachineStatus::Auto,
        alive: AliveCounter::ZERO,
    };
    machine.send(&st.encode().unwrap().frame).await.unwrap();
    let got = tokio::time::timeout(Duration::from_secs(2), daemon.recv())
        .await
        .expect("state arrives")
        .unwrap();
    let back = MachineState::decode(&got).unwrap();
    assert!((back.beta + 0.4).abs() < 1e-9);
}
