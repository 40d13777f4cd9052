//! wlnavd library: configuration, CAN, control loop.

pub mod can;
