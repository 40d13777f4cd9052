//! [`CanBus`] on a Linux SocketCAN interface (`can0`, `vcan0`, …), through the
//! `socketcan` crate's tokio socket.
//!
//! Only classic data frames with standard identifiers are part of the wlnav
//! protocol. Everything else the kernel delivers (extended-id, remote and error
//! frames) is skipped and counted rather than returned as an error, so unrelated
//! traffic on a shared machine bus cannot make the daemon think its link failed.
//! With [`SocketCanBus::open_filtered`] the kernel drops such frames before they
//! reach us at all.

use async_trait::async_trait;
use socketcan::{
    tokio::CanSocket, CanDataFrame, CanFilter, EmbeddedFrame, Id, SocketOptions, StandardId,
};

use super::{CanBus, CanError, CanFrame};

/// A SocketCAN interface as a [`CanBus`].
#[derive(Debug)]
pub struct SocketCanBus {
    iface: String,
    socket: CanSocket,
    skipped: u64,
}

impl SocketCanBus {
    /// Open `iface` and receive every frame on it.
    pub fn open(iface: &str) -> Result<Self, CanError> {
        let socket = CanSocket::open(iface).map_err(|source| CanError::Open {
            iface: iface.to_owned(),
            source,
        })?;
        Ok(Self {
            iface: iface.to_owned(),
            socket,
            skipped: 0,
        })
    }

    /// Open `iface` and let the kernel pass only standard-id data frames with one
    /// of `ids` (the daemon passes the machine-state id). Saves waking up for the
    /// rest of the machine's bus traffic.
    pub fn open_filtered(iface: &str, ids: &[u16]) -> Result<Self, CanError> {
        let bus = Self::open(iface)?;
        // Match id bits, and require EFF and RTR flags clear: standard data frames only.
        let mask =
            libc_consts::CAN_SFF_MASK | libc_consts::CAN_EFF_FLAG | libc_consts::CAN_RTR_FLAG;
        let filters: Vec<CanFilter> = ids
            .iter()
            .map(|&id| CanFilter::new(u32::from(id) & libc_consts::CAN_SFF_MASK, mask))
            .collect();
        bus.socket
            .set_filters(&filters)
            .map_err(|source| CanError::Open {
                iface: iface.to_owned(),
                source,
            })?;
        Ok(bus)
    }

    /// Frames received and skipped because they are not standard-id data frames.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    fn io(&self, op: &'static str, source: std::io::Error) -> CanError {
        CanError::Io {
            iface: self.iface.clone(),
            op,
            source,
        }
    }
}

/// The three `linux/can.h` constants we need, spelled out so this module does not
/// depend on `libc` directly (their values are kernel ABI and never change).
mod libc_consts {
    pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
    pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
    pub const CAN_SFF_MASK: u32 = 0x0000_07FF;
}

/// Our frame as a socketcan data frame.
fn to_socketcan(frame: &CanFrame) -> Option<CanDataFrame> {
    let id = StandardId::new(frame.id())?;
    CanDataFrame::new(id, frame.data())
}

/// A socketcan frame as ours, if it is a standard-id classic data frame.
fn from_socketcan(frame: &socketcan::CanFrame) -> Option<CanFrame> {
    let socketcan::CanFrame::Data(data) = frame else {
        return None;
    };
    match data.id() {
        Id::Standard(id) => CanFrame::new(id.as_raw(), data.data()).ok(),
        Id::Extended(_) => None,
    }
}

#[async_trait]
impl CanBus for SocketCanBus {
    async fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        // Cannot fail for a valid `CanFrame` (id ≤ 0x7FF, ≤ 8 bytes); handled anyway.
        let out = to_socketcan(frame).ok_or_else(|| CanError::Unsupported {
            iface: self.iface.clone(),
            reason: format!("frame {frame} not representable"),
        })?;
        self.socket
            .write_frame(socketcan::CanFrame::Data(out))
            .await
            .map_err(|e| self.io("send", e))
    }

    async fn recv(&mut self) -> Result<CanFrame, CanError> {
        loop {
            // `read_frame` is AsyncFd-based and cancel-safe: a frame is only taken
            // from the socket in the poll that returns it.
            let raw = self
                .socket
                .read_frame()
                .await
                .map_err(|e| self.io("receive", e))?;
            match from_socketcan(&raw) {
                Some(f) => return Ok(f),
                None => {
                    self.skipped += 1;
                    tracing::trace!(iface = %self.iface, "skipping non-standard CAN frame");
                }
            }
        }
    }

    fn name(&self) -> &str {
        &self.iface
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversion_round_trip() {
        let f = CanFrame::new(0x121, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let s = to_socketcan(&f).unwrap();
        assert_eq!(from_socketcan(&socketcan::CanFrame::Data(s)), Some(f));
        let empty = CanFrame::new(0x7FF, &[]).unwrap();
        let s = to_socketcan(&empty).unwrap();
        assert_eq!(from_socketcan(&socketcan::CanFrame::Data(s)), Some(empty));
    }

    #[test]
    fn extended_frames_are_not_ours() {
        let ext = socketcan::ExtendedId::new(0x121).unwrap();
        let s = CanDataFrame::new(ext, &[0; 8]).unwrap();
        assert_eq!(from_socketcan(&socketcan::CanFrame::Data(s)), None);
    }

    #[tokio::test]
    async fn open_missing_interface_is_a_typed_error() {
        // No such interface here (and no AF_CAN in CI sandboxes): must be an
        // error naming the interface, not a panic.
        match SocketCanBus::open("wlnavnosuch0") {
            Err(CanError::Open { iface, .. }) => assert_eq!(iface, "wlnavnosuch0"),
            other => panic!("expected Open error, got {other:?}"),
        }
    }
}
