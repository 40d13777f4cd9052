//! Receive-side integrity checks: CRC and range (through the codec), alive counter,
//! and counters of everything rejected.
//!
//! Why a tracker and not just a decoder: a single bad frame is noise, but a run of
//! them is a broken link or a hung sender, and the safety logic must stop the
//! machine on the latter. The tracker keeps the counts (total per cause, and the
//! current run of consecutive bad frames) so the control loop can decide
//! "persistent" with one comparison, and telemetry can publish the totals.

use std::marker::PhantomData;

use thiserror::Error;

use super::codec::{AliveCounter, CanMessage, DecodeError};
use super::CanFrame;

/// Alive-counter sequence violations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum AliveError {
    /// The counter did not advance: the sender re-sent an old frame (hung task,
    /// stale buffer). The frame's data must not be used as fresh.
    #[error("alive counter frozen at {counter} ({repeats} repeat(s) in a row)")]
    Frozen {
        /// The repeated counter value.
        counter: u8,
        /// Repeats in a row so far (1 on the first repeat).
        repeats: u32,
    },
    /// The counter jumped further than the allowed number of lost frames.
    #[error("alive counter jumped from {previous} to {got}: {lost} frame(s) lost, at most {max_lost} allowed")]
    Skipped {
        /// Counter of the last accepted frame.
        previous: u8,
        /// Counter received.
        got: u8,
        /// Frames missing in between (modulo 16).
        lost: u8,
        /// The configured tolerance.
        max_lost: u8,
    },
}

/// Follows one sender's 4-bit alive counter.
///
/// The first frame (and the first after [`reset`](Self::reset)) is taken as is. A
/// repeat of the previous value is [`AliveError::Frozen`]; a jump by more than
/// `max_lost + 1` is [`AliveError::Skipped`], after which the tracker re-synchronises
/// on the new value, so one lost burst costs one rejected frame, not all that follow.
/// With a 4-bit counter, 15 lost frames are indistinguishable from a repeat, so
/// `max_lost` is capped at 14.
#[derive(Debug, Clone)]
pub struct AliveTracker {
    last: Option<AliveCounter>,
    max_lost: u8,
    frozen_run: u32,
}

impl AliveTracker {
    /// Largest meaningful tolerance of lost frames.
    pub const MAX_LOST_LIMIT: u8 = 14;

    /// A tracker that accepts up to `max_lost` lost frames between two good ones
    /// (0 = every frame must arrive).
    pub fn new(max_lost: u8) -> Self {
        Self {
            last: None,
            max_lost: max_lost.min(Self::MAX_LOST_LIMIT),
            frozen_run: 0,
        }
    }

    /// Forget the history (after a reconnect, or a long silence where any counter
    /// value is plausible).
    pub fn reset(&mut self) {
        self.last = None;
        self.frozen_run = 0;
    }

    /// The last accepted counter.
    pub fn last(&self) -> Option<AliveCounter> {
        self.last
    }

    /// Check the next counter; on success returns the number of frames lost since
    /// the previous accepted one.
    pub fn check(&mut self, counter: AliveCounter) -> Result<u8, AliveError> {
        let Some(prev) = self.last else {
            self.last = Some(counter);
            self.frozen_run = 0;
            return Ok(0);
        };
        let steps = counter.steps_since(prev);
        if steps == 0 {
            self.frozen_run = self.frozen_run.saturating_add(1);
            return Err(AliveError::Frozen {
                counter: counter.get(),
                repeats: self.frozen_run,
            });
        }
        self.frozen_run = 0;
        self.last = Some(counter);
        let lost = steps - 1;
        if lost > self.max_lost {
            return Err(AliveError::Skipped {
                previous: prev.get(),
                got: counter.get(),
                lost,
                max_lost: self.max_lost,
            });
        }
        Ok(lost)
    }
}

/// Totals kept by an [`RxTracker`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RxCounters {
    /// Frames decoded and accepted.
    pub accepted: u64,
    /// Frames of another message (not an error of this link; not in `consecutive_bad`).
    pub wrong_id: u64,
    /// Frames with the wrong data length.
    pub wrong_length: u64,
    /// Frames whose CRC byte did not match.
    pub bad_crc: u64,
    /// Frames with a signal outside its DBC range.
    pub out_of_range: u64,
    /// Frames with a repeated alive counter.
    pub frozen: u64,
    /// Frames whose alive counter jumped too far.
    pub skipped: u64,
    /// Frames inferred lost from counter gaps (accepted and skipped jumps alike).
    pub lost: u64,
    /// Rejected frames since the last accepted one: the "persistent" measure.
    pub consecutive_bad: u32,
}

impl RxCounters {
    /// Frames rejected for any integrity reason (everything but `wrong_id`).
    pub fn rejected(&self) -> u64 {
        self.wrong_length + self.bad_crc + self.out_of_range + self.frozen + self.skipped
    }
}

/// Why a received frame was rejected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum RxError {
    /// Not a valid frame of the message (id, length, CRC, range).
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// Valid frame, but out of sequence.
    #[error("{message}: {source}")]
    Alive {
        /// Message name.
        message: &'static str,
        /// The sequence violation.
        source: AliveError,
    },
}

/// Decodes and checks one message stream (e.g. the machine state), counting every
/// rejection by cause.
#[derive(Debug, Clone)]
pub struct RxTracker<M> {
    alive: AliveTracker,
    counters: RxCounters,
    _message: PhantomData<fn() -> M>,
}

impl<M: CanMessage> RxTracker<M> {
    /// A tracker tolerating `max_lost` lost frames between two accepted ones.
    pub fn new(max_lost: u8) -> Self {
        Self {
            alive: AliveTracker::new(max_lost),
            counters: RxCounters::default(),
            _message: PhantomData,
        }
    }

    /// True if `frame` carries this tracker's message.
    pub fn is_for(&self, frame: &CanFrame) -> bool {
        frame.id() == M::SPEC.id
    }

    /// Decode, check CRC, ranges and alive counter; count the outcome.
    pub fn accept(&mut self, frame: &CanFrame) -> Result<M, RxError> {
        let c = &mut self.counters;
        let msg = match M::decode(frame) {
            Ok(m) => m,
            Err(e) => {
                match e {
                    DecodeError::WrongId { .. } => {
                        c.wrong_id += 1;
                        return Err(e.into());
                    }
                    DecodeError::WrongLength { .. } => c.wrong_length += 1,
                    DecodeError::BadCrc { .. } => c.bad_crc += 1,
                    DecodeError::OutOfRange { .. } => c.out_of_range += 1,
                }
                c.consecutive_bad = c.consecutive_bad.saturating_add(1);
                return Err(e.into());
            }
        };
        match self.alive.check(msg.alive()) {
            Ok(lost) => {
                c.lost += u64::from(lost);
                c.accepted += 1;
                c.consecutive_bad = 0;
                Ok(msg)
            }
            Err(e) => {
                match e {
                    AliveError::Frozen { .. } => c.frozen += 1,
                    AliveError::Skipped { lost, .. } => {
                        c.skipped += 1;
                        c.lost += u64::from(lost);
                    }
                }
                c.consecutive_bad = c.consecutive_bad.saturating_add(1);
                Err(RxError::Alive {
                    message: M::SPEC.name,
                    source: e,
                })
            }
        }
    }

    /// The totals so far.
    pub fn counters(&self) -> &RxCounters {
        &self.counters
    }

    /// Forget the alive-counter history (totals are kept).
    pub fn reset_sequence(&mut self) {
        self.alive.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(v: u8) -> AliveCounter {
        AliveCounter::new(v).unwrap()
    }

    #[test]
    fn in_sequence_across_wrap() {
        let mut t = AliveTracker::new(0);
        for i in 0..48u8 {
            assert_eq!(t.check(c(i % 16)), Ok(0), "at {i}");
        }
    }

    #[test]
    fn frozen_then_recovers() {
        let mut t = AliveTracker::new(0);
        assert_eq!(t.check(c(15)), Ok(0));
        assert_eq!(
            t.check(c(15)),
            Err(AliveError::Frozen {
                counter: 15,
                repeats: 1
            })
        );
        assert_eq!(
            t.check(c(15)),
            Err(AliveError::Frozen {
                counter: 15,
                repeats: 2
            })
        );
        assert_eq!(t.check(c(0)), Ok(0));
    }

    #[test]
    fn skip_tolerance_and_resync() {
        let mut t = AliveTracker::new(1);
        t.check(c(14)).unwrap();
        assert_eq!(t.check(c(0)), Ok(1)); // 15 lost, tolerated
        assert_eq!(
            t.check(c(3)),
            Err(AliveError::Skipped {
                previous: 0,
                got: 3,
                lost: 2,
                max_lost: 1
            })
        );
        assert_eq!(t.check(c(4)), Ok(0)); // re-synchronised
    }
}
