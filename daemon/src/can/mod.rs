//! The CAN machine interface: frames, the codec that matches `daemon/can/wlnav.dbc`,
//! receive-side integrity tracking, the [`CanBus`] trait with its backends, and
//! `candump -L` logging and replay.
//!
//! Layering, and why: [`CanFrame`] is a plain value type that knows nothing about
//! sockets, so the codec, the simulated machine and the log replay all work on the
//! same frames without linking `socketcan`; only [`socketcan_bus`] touches the
//! kernel API.

pub mod bus;
pub mod codec;
pub mod crc;
pub mod log;
pub mod socketcan_bus;
pub mod tracker;

pub use bus::{CanBus, CanError, LoopbackBus};
pub use codec::{
    AliveCounter, DecodeError, DriveMode, EncodeError, Encoded, MachineState, MachineStatus,
    Saturation, VelocityCommandFrame, MACHINE_STATE_ID, VELOCITY_COMMAND_ID,
};
pub use log::{CandumpReader, CandumpWriter, LogRecord, LoggingBus, ReplayError};
pub use socketcan_bus::SocketCanBus;
pub use tracker::{AliveError, AliveTracker, RxCounters, RxError, RxTracker};

use thiserror::Error;

/// Largest standard (11-bit) identifier.
pub const MAX_STANDARD_ID: u16 = 0x7FF;

/// One classic CAN data frame with a standard 11-bit identifier.
///
/// The wlnav protocol uses only standard-ID data frames of up to 8 bytes, so this
/// type can be a small `Copy` value. Fields are private so that every frame in the
/// program is valid by construction (id ≤ 0x7FF, len ≤ 8, bytes past `len` zero);
/// the logger and the socket backend can then format and send it without
/// re-checking.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: u16,
    len: u8,
    data: [u8; 8],
}

/// Why a [`CanFrame`] could not be built.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// The identifier needs more than 11 bits.
    #[error("CAN id {0:#x} is not a standard 11-bit identifier (max 0x7FF)")]
    IdOutOfRange(u32),
    /// More than 8 data bytes for a classic frame.
    #[error("{0} data bytes do not fit a classic CAN frame (max 8)")]
    TooLong(usize),
}

impl CanFrame {
    /// A frame with identifier `id` carrying `payload` (0 to 8 bytes).
    pub fn new(id: u16, payload: &[u8]) -> Result<Self, FrameError> {
        if id > MAX_STANDARD_ID {
            return Err(FrameError::IdOutOfRange(u32::from(id)));
        }
        if payload.len() > 8 {
            return Err(FrameError::TooLong(payload.len()));
        }
        let mut data = [0u8; 8];
        data[..payload.len()].copy_from_slice(payload);
        Ok(Self {
            id,
            // Cannot truncate: checked ≤ 8 above.
            len: payload.len() as u8,
            data,
        })
    }

    /// A full 8-byte frame, the only length the wlnav messages use.
    pub fn new8(id: u16, data: [u8; 8]) -> Result<Self, FrameError> {
        if id > MAX_STANDARD_ID {
            return Err(FrameError::IdOutOfRange(u32::from(id)));
        }
        Ok(Self { id, len: 8, data })
    }

    /// The 11-bit identifier.
    pub fn id(&self) -> u16 {
        self.id
    }

    /// Number of data bytes (the DLC), 0 to 8.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// True for a frame without data bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The data bytes actually carried (`len` of them).
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len()]
    }

    /// All eight data-byte slots; those past [`len`](Self::len) are zero.
    pub fn raw_data(&self) -> &[u8; 8] {
        &self.data
    }
}

impl std::fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The candump notation is what people compare against bus traces.
        write!(f, "CanFrame({self})")
    }
}

impl std::fmt::Display for CanFrame {
    /// `candump` notation: `123#0011223344556677`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:03X}#", self.id)?;
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_invariants() {
        assert_eq!(
            CanFrame::new(0x800, &[]),
            Err(FrameError::IdOutOfRange(0x800))
        );
        assert_eq!(CanFrame::new(1, &[0; 9]), Err(FrameError::TooLong(9)));
        let f = CanFrame::new(0x7FF, &[1, 2, 3]).unwrap();
        assert_eq!(f.len(), 3);
        assert_eq!(f.data(), &[1, 2, 3]);
        assert_eq!(f.raw_data(), &[1, 2, 3, 0, 0, 0, 0, 0]);
        assert_eq!(f.to_string(), "7FF#010203");
        assert_eq!(CanFrame::new(0x12, &[]).unwrap().to_string(), "012#");
    }
}
