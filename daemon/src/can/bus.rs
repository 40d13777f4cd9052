//! The [`CanBus`] trait the daemon talks to, and an in-memory [`LoopbackBus`].
//!
//! The trait is the seam between the control loop and the machine: the `socketcan`
//! backend puts frames on a real bus, the simulated machine (a plant behind the
//! same frames) and test doubles implement it in memory. It deals in plain
//! [`CanFrame`]s so implementers need no `socketcan` types.

use async_trait::async_trait;
use thiserror::Error;
use tokio::sync::mpsc;

use super::CanFrame;

/// Failures of a CAN bus backend.
#[derive(Debug, Error)]
pub enum CanError {
    /// The interface could not be opened or configured.
    #[error("CAN interface {iface}: cannot open: {source}")]
    Open {
        /// Interface name, e.g. `can0`.
        iface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Sending or receiving failed at the OS level (bus-off, interface down, …).
    #[error("CAN interface {iface}: {op} failed: {source}")]
    Io {
        /// Interface name.
        iface: String,
        /// `"send"` or `"receive"`.
        op: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// The other end of an in-memory bus is gone (simulation ended or crashed).
    #[error("CAN bus {iface}: peer closed")]
    Closed {
        /// Bus name.
        iface: String,
    },
    /// The backend cannot represent this frame.
    #[error("CAN interface {iface}: unsupported frame: {reason}")]
    Unsupported {
        /// Interface name.
        iface: String,
        /// What is unsupported.
        reason: String,
    },
}

/// A CAN bus as the daemon sees it: send a frame, receive the next frame.
///
/// Contract for implementers:
/// * `recv` must be **cancel-safe**: the daemon's I/O task calls it inside
///   `tokio::select!` next to timers and the command channel, and a cancelled
///   `recv` must not lose a frame (tokio `mpsc::Receiver::recv` and
///   `AsyncFd`-based socket reads are).
/// * `recv` returns frames in bus order, including the ones this node is not
///   interested in only if the backend cannot filter them; callers dispatch by id.
/// * `send` returns once the frame is handed to the bus (queued in the socket or
///   the peer's channel), not when it was acknowledged on the wire.
/// * Errors are per call: after an `Io` error the bus may be usable again (e.g. the
///   interface came back up); after `Closed` it will not be.
///
/// The trait is object-safe (through `async_trait`), so the backend can be chosen
/// from the configuration at run time as a `Box<dyn CanBus>`, and its futures are
/// `Send` so the bus can live in a spawned tokio task.
#[async_trait]
pub trait CanBus: Send {
    /// Put `frame` on the bus.
    async fn send(&mut self, frame: &CanFrame) -> Result<(), CanError>;
    /// Wait for the next frame from the bus.
    async fn recv(&mut self) -> Result<CanFrame, CanError>;
    /// Interface name for logs (`can0`, `sim`, …).
    fn name(&self) -> &str;
}

#[async_trait]
impl<B: CanBus + ?Sized> CanBus for Box<B> {
    async fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        (**self).send(frame).await
    }
    async fn recv(&mut self) -> Result<CanFrame, CanError> {
        (**self).recv().await
    }
    fn name(&self) -> &str {
        (**self).name()
    }
}

/// One end of an in-memory point-to-point bus: what one end sends, the other
/// receives, in order.
///
/// Made with [`LoopbackBus::pair`]. Tests hold one end as "the machine" and give
/// the other to the code under test. Channels are bounded, so a peer that stops
/// reading makes `send` wait instead of growing memory without limit (a real CAN
/// controller's TX queue also fills up).
#[derive(Debug)]
pub struct LoopbackBus {
    name: String,
    tx: mpsc::Sender<CanFrame>,
    rx: mpsc::Receiver<CanFrame>,
}

impl LoopbackBus {
    /// Default channel capacity per direction, in frames.
    pub const DEFAULT_CAPACITY: usize = 1024;

    /// Two connected ends named `"{name}.a"` and `"{name}.b"`.
    pub fn pair(name: &str) -> (Self, Self) {
        Self::pair_with_capacity(name, Self::DEFAULT_CAPACITY)
    }

    /// Two connected ends with `capacity` frames of buffering per direction
    /// (at least 1).
    pub fn pair_with_capacity(name: &str, capacity: usize) -> (Self, Self) {
        let capacity = capacity.max(1);
        let (a_tx, b_rx) = mpsc::channel(capacity);
        let (b_tx, a_rx) = mpsc::channel(capacity);
        (
            Self {
                name: format!("{name}.a"),
                tx: a_tx,
                rx: a_rx,
            },
            Self {
                name: format!("{name}.b"),
                tx: b_tx,
                rx: b_rx,
            },
        )
    }

    /// A frame from the peer if one is waiting, without blocking. `Ok(None)` when
    /// nothing is queued; `Err(Closed)` when the peer is gone and the queue empty.
    /// Lets a synchronous test or a simulator drain everything pending.
    pub fn try_recv(&mut self) -> Result<Option<CanFrame>, CanError> {
        match self.rx.try_recv() {
            Ok(f) => Ok(Some(f)),
            Err(mpsc::error::TryRecvError::Empty) => Ok(None),
            Err(mpsc::error::TryRecvError::Disconnected) => Err(self.closed()),
        }
    }

    fn closed(&self) -> CanError {
        CanError::Closed {
            iface: self.name.clone(),
        }
    }
}

#[async_trait]
impl CanBus for LoopbackBus {
    async fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let frame = *frame;
        if self.tx.send(frame).await.is_err() {
            return Err(self.closed());
        }
        Ok(())
    }

    async fn recv(&mut self) -> Result<CanFrame, CanError> {
        match self.rx.recv().await {
            Some(f) => Ok(f),
            None => Err(self.closed()),
        }
    }

    fn name(&self) -> &str {
        &self.name
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn pair_delivers_in_order_both_ways() {
        let (mut a, mut b) = LoopbackBus::pair("t");
        for i in 0..5u8 {
            a.send(&CanFrame::new(0x10, &[i]).unwrap()).await.unwrap();
        }
        b.send(&CanFrame::new(0x20, &[9]).unwrap()).await.unwrap();
        for i in 0..5u8 {
            assert_eq!(b.recv().await.unwrap().data(), &[i]);
        }
        assert_eq!(a.recv().await.unwrap().id(), 0x20);
        assert!(matches!(a.try_recv(), Ok(None)));
        drop(b);
        assert!(matches!(a.recv().await, Err(CanError::Closed { .. })));
        assert!(matches!(
            a.send(&CanFrame::new(1, &[]).unwrap()).await,
            Err(CanError::Closed { .. })
        ));
    }

    #[tokio::test]
    async fn usable_as_trait_object() {
        let (a, mut b) = LoopbackBus::pair("dyn");
        let mut bus: Box<dyn CanBus> = Box::new(a);
        bus.send(&CanFrame::new(0x1, &[1, 2]).unwrap())
            .await
            .unwrap();
        assert_eq!(b.recv().await.unwrap().data(), &[1, 2]);
        assert_eq!(bus.name(), "dyn.a");
    }
}
