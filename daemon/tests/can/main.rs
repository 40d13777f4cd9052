//! CAN machine interface tests: codec, CRC, DBC agreement, candump replay and
//! logging, buses and receive tracking.

mod bus;
mod codec;
mod crc;
mod dbc;
mod replay;
#[cfg(feature = "vcan-tests")]
mod vcan;
