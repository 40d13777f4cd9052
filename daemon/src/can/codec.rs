//! Encoding and decoding of the two wlnav CAN messages, exactly as
//! `daemon/can/wlnav.dbc` defines them.
//!
//! The layout lives in one place, the [`MessageSpec`] tables [`VELOCITY_COMMAND`] and
//! [`MACHINE_STATE`]; the bit packing below is driven by those tables and a test
//! parses the DBC file and compares it against them field by field, so the file and
//! the code cannot drift apart silently.
//!
//! Both messages are 8-byte classic frames with standard 11-bit identifiers and
//! little-endian (Intel) signals. Start bits are DBC Intel start bits, i.e. the bit
//! position of the signal's least significant bit in the frame read as one
//! little-endian `u64`.
//!
//! ```text
//! byte         0      1      2      3      4      5      6            7
//! 0x120 cmd   [beta_dot_cmd ][v_cmd        ][reserved=0 ][alive|mode ][crc]
//! 0x121 state [beta         ][beta_dot     ][v_f        ][alive|status][crc]
//!                                                        low   high
//!                                                        nibble nibble
//! ```
//!
//! * Rates and angles: signed 16 bit, factor 5e-5 (rad or rad/s), range ±1.63835,
//!   which covers the Avant's ±40° = ±0.698 rad articulation and ±33°/s = ±0.576
//!   rad/s with margin for other machines, at 0.003° resolution.
//! * Speed: signed 16 bit, factor 1e-4 m/s, range ±3.2767 m/s.
//! * Raw −32768 (0x8000) is outside the DBC's `[min|max]` and therefore never sent;
//!   on receive it is rejected as out of range. A machine that wants to say "signal
//!   not available" can use it, and we will not mistake it for a full-scale value.
//! * Byte 6: 4-bit alive counter in bits 48..=51 (counts 0..=15 and wraps to 0, one
//!   step per frame sent), mode or status in bits 52..=55.
//! * Byte 7: CRC-8 SAE J1850 ([`crate::can::crc`]) over bytes 0..=6, in that order.
//!   Reserved bits are sent as zero and are covered by the CRC; on receive they are
//!   ignored (a later protocol revision may use them).
//!
//! Encoding saturates out-of-range physical values to the representable range and
//! says which signals it saturated ([`Saturation`]): the controller's output is
//! already bounded, so saturation means a configuration or bug somewhere upstream
//! that the caller should report, but the frame must still go out. Non-finite
//! values are refused: there is no honest number to send for NaN.

use thiserror::Error;

use super::crc::crc8_j1850;
use super::CanFrame;

/// Identifier of the velocity command, daemon → machine.
pub const VELOCITY_COMMAND_ID: u16 = 0x120;
/// Identifier of the machine state, machine → daemon.
pub const MACHINE_STATE_ID: u16 = 0x121;
/// Data length of both messages.
pub const FRAME_LEN: usize = 8;
/// Index of the CRC byte; the CRC covers every byte before it.
pub const CRC_BYTE: usize = 7;

/// Layout of one signal, in DBC terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalSpec {
    /// Signal name as in the DBC file.
    pub name: &'static str,
    /// DBC start bit (Intel: position of the least significant bit).
    pub start_bit: u32,
    /// Width in bits.
    pub size: u32,
    /// Two's-complement signed (`-` in the DBC) or unsigned (`+`).
    pub signed: bool,
    /// Intel (little-endian, `@1` in the DBC). Every wlnav signal is.
    pub little_endian: bool,
    /// physical = raw · factor + offset.
    pub factor: f64,
    /// physical = raw · factor + offset.
    pub offset: f64,
    /// Smallest valid physical value.
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Unit string as in the DBC file.
    pub unit: &'static str,
}

impl SignalSpec {
    const fn int(name: &'static str, start_bit: u32, size: u32, max: f64) -> Self {
        Self {
            name,
            start_bit,
            size,
            signed: false,
            little_endian: true,
            factor: 1.0,
            offset: 0.0,
            min: 0.0,
            max,
            unit: "",
        }
    }

    const fn scaled(
        name: &'static str,
        start_bit: u32,
        factor: f64,
        limit: f64,
        unit: &'static str,
    ) -> Self {
        Self {
            name,
            start_bit,
            size: 16,
            signed: true,
            little_endian: true,
            factor,
            offset: 0.0,
            min: -limit,
            max: limit,
            unit,
        }
    }

    /// Smallest valid raw value (the DBC `min` converted to raw).
    pub fn raw_min(&self) -> i64 {
        ((self.min - self.offset) / self.factor).round() as i64
    }

    /// Largest valid raw value (the DBC `max` converted to raw).
    pub fn raw_max(&self) -> i64 {
        ((self.max - self.offset) / self.factor).round() as i64
    }

    /// Physical value of a raw value.
    pub fn physical(&self, raw: i64) -> f64 {
        raw as f64 * self.factor + self.offset
    }

    /// Raw value for a finite physical value, and whether it had to be clamped.
    ///
    /// Rounds to the nearest step first, so a value within half a step of a limit
    /// counts as representable (that is ordinary quantisation, not saturation).
    pub fn to_raw_saturating(&self, physical: f64) -> (i64, bool) {
        let (lo, hi) = (self.raw_min(), self.raw_max());
        let exact = ((physical - self.offset) / self.factor).round();
        if exact < lo as f64 {
            (lo, true)
        } else if exact > hi as f64 {
            (hi, true)
        } else {
            (exact as i64, false)
        }
    }

    /// Write `raw` into the frame word (bits outside the signal untouched).
    fn insert(&self, word: &mut u64, raw: i64) {
        let mask = field_mask(self.size);
        *word &= !(mask << self.start_bit);
        *word |= ((raw as u64) & mask) << self.start_bit;
    }

    /// Read the raw value (sign-extended for signed signals) from the frame word.
    pub fn extract(&self, word: u64) -> i64 {
        let bits = (word >> self.start_bit) & field_mask(self.size);
        if self.signed && self.size < 64 && bits & (1 << (self.size - 1)) != 0 {
            (bits | !field_mask(self.size)) as i64
        } else {
            bits as i64
        }
    }
}

fn field_mask(size: u32) -> u64 {
    if size >= 64 {
        u64::MAX
    } else {
        (1u64 << size) - 1
    }
}

/// Layout of one message, in DBC terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageSpec {
    /// Message name as in the DBC file.
    pub name: &'static str,
    /// Standard identifier.
    pub id: u16,
    /// Data length in bytes.
    pub dlc: usize,
    /// Transmitting node as in the DBC file.
    pub transmitter: &'static str,
    /// All signals, including alive counter and CRC.
    pub signals: &'static [SignalSpec],
}

impl MessageSpec {
    /// The signal called `name`.
    pub fn signal(&self, name: &str) -> Option<&'static SignalSpec> {
        self.signals.iter().find(|s| s.name == name)
    }

    fn sig(&self, index: usize) -> &'static SignalSpec {
        &self.signals[index]
    }
}

/// Factor of angles and rates: 5e-5 rad per bit, ±1.63835 in 16 signed bits.
pub const ANGLE_FACTOR: f64 = 5e-5;
/// Physical limit of angles and rates.
pub const ANGLE_LIMIT: f64 = 1.63835;
/// Factor of speeds: 1e-4 m/s per bit, ±3.2767 m/s in 16 signed bits.
pub const SPEED_FACTOR: f64 = 1e-4;
/// Physical limit of speeds.
pub const SPEED_LIMIT: f64 = 3.2767;

// Signal indices into the tables below; the tables and these must agree (tested).
const CMD_BETA_DOT: usize = 0;
const CMD_V: usize = 1;
const CMD_ALIVE: usize = 2;
const CMD_MODE: usize = 3;
const CMD_CRC: usize = 4;
const ST_BETA: usize = 0;
const ST_BETA_DOT: usize = 1;
const ST_V: usize = 2;
const ST_ALIVE: usize = 3;
const ST_STATUS: usize = 4;
const ST_CRC: usize = 5;

/// The velocity command, daemon → machine.
pub const VELOCITY_COMMAND: MessageSpec = MessageSpec {
    name: "WLNAV_VelocityCommand",
    id: VELOCITY_COMMAND_ID,
    dlc: FRAME_LEN,
    transmitter: "WLNAVD",
    signals: &[
        SignalSpec::scaled("beta_dot_cmd", 0, ANGLE_FACTOR, ANGLE_LIMIT, "rad/s"),
        SignalSpec::scaled("v_cmd", 16, SPEED_FACTOR, SPEED_LIMIT, "m/s"),
        SignalSpec::int("cmd_alive", 48, 4, 15.0),
        SignalSpec::int("mode", 52, 4, DriveMode::MAX as f64),
        SignalSpec::int("cmd_crc", 56, 8, 255.0),
    ],
};

/// The machine state, machine → daemon.
pub const MACHINE_STATE: MessageSpec = MessageSpec {
    name: "WLNAV_MachineState",
    id: MACHINE_STATE_ID,
    dlc: FRAME_LEN,
    transmitter: "MACHINE",
    signals: &[
        SignalSpec::scaled("beta", 0, ANGLE_FACTOR, ANGLE_LIMIT, "rad"),
        SignalSpec::scaled("beta_dot", 16, ANGLE_FACTOR, ANGLE_LIMIT, "rad/s"),
        SignalSpec::scaled("v_f", 32, SPEED_FACTOR, SPEED_LIMIT, "m/s"),
        SignalSpec::int("state_alive", 48, 4, 15.0),
        SignalSpec::int("status", 52, 4, MachineStatus::MAX as f64),
        SignalSpec::int("state_crc", 56, 8, 255.0),
    ],
};

/// Both messages, for tools and tests that walk the whole protocol.
pub const MESSAGES: [&MessageSpec; 2] = [&VELOCITY_COMMAND, &MACHINE_STATE];

/// 4-bit alive (rolling) counter: 0..=15, then back to 0.
///
/// The sender increments it once per frame, so a receiver can tell a fresh frame
/// from a repeated one (a hung sender re-sending its last buffer) and notice lost
/// frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct AliveCounter(u8);

impl AliveCounter {
    /// Counter value 0.
    pub const ZERO: Self = Self(0);
    /// Largest value before the wrap.
    pub const MAX: u8 = 15;

    /// `Some` for 0..=15.
    pub fn new(value: u8) -> Option<Self> {
        (value <= Self::MAX).then_some(Self(value))
    }

    /// The counter value, 0..=15.
    pub fn get(self) -> u8 {
        self.0
    }

    /// The next value: +1, with 15 → 0.
    #[must_use]
    pub fn next(self) -> Self {
        Self((self.0 + 1) & Self::MAX)
    }

    /// Steps forward from `earlier` to `self`, modulo 16 (0 = same value).
    pub fn steps_since(self, earlier: Self) -> u8 {
        self.0.wrapping_sub(earlier.0) & Self::MAX
    }
}

impl std::fmt::Display for AliveCounter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

/// What the daemon asks of the machine (the `mode` signal).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum DriveMode {
    /// Controlled stop: the velocities are the stop ramp, ending at zero.
    Stop = 0,
    /// Follow the commanded velocities.
    Drive = 1,
    /// At rest and holding (goal reached or waiting); velocities are zero.
    Hold = 2,
    /// The daemon detected a fault: the machine should make its own safe stop
    /// whatever the velocities say.
    Fault = 3,
}

impl DriveMode {
    /// Largest defined raw value (the DBC maximum).
    pub const MAX: u8 = 3;
}

impl TryFrom<u8> for DriveMode {
    type Error = u8;
    fn try_from(raw: u8) -> Result<Self, u8> {
        Ok(match raw {
            0 => Self::Stop,
            1 => Self::Drive,
            2 => Self::Hold,
            3 => Self::Fault,
            other => return Err(other),
        })
    }
}

/// What the machine reports about itself (the `status` signal).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MachineStatus {
    /// An operator has control; commands are ignored.
    Manual = 0,
    /// Automatic mode selected, standing by for commands.
    Ready = 1,
    /// Automatic mode, following the velocity commands.
    Auto = 2,
    /// Emergency stop active.
    EStop = 3,
    /// The machine-side controller reports a fault.
    Fault = 4,
}

impl MachineStatus {
    /// Largest defined raw value (the DBC maximum).
    pub const MAX: u8 = 4;
}

impl TryFrom<u8> for MachineStatus {
    type Error = u8;
    fn try_from(raw: u8) -> Result<Self, u8> {
        Ok(match raw {
            0 => Self::Manual,
            1 => Self::Ready,
            2 => Self::Auto,
            3 => Self::EStop,
            4 => Self::Fault,
            other => return Err(other),
        })
    }
}

/// The velocity command (message [`VELOCITY_COMMAND`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityCommandFrame {
    /// Articulation rate command β̇_cmd (rad/s), positive bends the front left.
    pub beta_dot_cmd: f64,
    /// Front speed command v_cmd (m/s), positive forward.
    pub v_cmd: f64,
    /// What the machine should do.
    pub mode: DriveMode,
    /// Alive counter of this frame.
    pub alive: AliveCounter,
}

/// The machine state (message [`MACHINE_STATE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineState {
    /// Articulation angle β (rad), positive = front bent left.
    pub beta: f64,
    /// Articulation rate β̇ (rad/s).
    pub beta_dot: f64,
    /// Front speed v_f (m/s).
    pub v_f: f64,
    /// Machine status.
    pub status: MachineStatus,
    /// Alive counter of this frame.
    pub alive: AliveCounter,
}

/// Which signals an encode had to clamp to their DBC range.
#[derive(Clone, Copy)]
pub struct Saturation {
    spec: &'static MessageSpec,
    mask: u32,
}

impl PartialEq for Saturation {
    fn eq(&self, other: &Self) -> bool {
        self.spec.id == other.spec.id && self.mask == other.mask
    }
}

impl Eq for Saturation {}

impl Saturation {
    fn none(spec: &'static MessageSpec) -> Self {
        Self { spec, mask: 0 }
    }

    fn add(&mut self, index: usize) {
        self.mask |= 1 << index;
    }

    /// True when nothing was clamped.
    pub fn is_empty(&self) -> bool {
        self.mask == 0
    }

    /// True when signal `name` was clamped.
    pub fn contains(&self, name: &str) -> bool {
        self.names().any(|n| n == name)
    }

    /// Names of the clamped signals, in layout order.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.spec
            .signals
            .iter()
            .enumerate()
            .filter(|(i, _)| self.mask & (1 << i) != 0)
            .map(|(_, s)| s.name)
    }
}

impl std::fmt::Debug for Saturation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.names()).finish()
    }
}

/// A frame ready to send, and what had to be clamped to build it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[must_use = "check `saturated`: a clamped command means something upstream is wrong"]
pub struct Encoded {
    /// The frame, CRC included.
    pub frame: CanFrame,
    /// Signals clamped to their range.
    pub saturated: Saturation,
}

/// Why a value could not be encoded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EncodeError {
    /// NaN or ±∞: there is no meaningful raw value, so nothing is sent.
    #[error("{message}.{signal}: non-finite value {value}")]
    NonFinite {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The offending value.
        value: f64,
    },
}

/// Why received bytes are not a valid message. Every variant names the message and,
/// where it applies, the signal.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// The frame carries another message.
    #[error("{message}: wrong CAN id {got:#05x}, expected {expected:#05x}")]
    WrongId {
        /// Message name.
        message: &'static str,
        /// Expected identifier.
        expected: u16,
        /// Received identifier.
        got: u16,
    },
    /// Not 8 data bytes.
    #[error("{message}: wrong length {got} bytes, expected {expected}")]
    WrongLength {
        /// Message name.
        message: &'static str,
        /// Expected length.
        expected: usize,
        /// Received length.
        got: usize,
    },
    /// The CRC byte does not match the other bytes.
    #[error(
        "{message}: CRC mismatch, byte 7 is {received:#04x} but bytes 0..=6 give {computed:#04x}"
    )]
    BadCrc {
        /// Message name.
        message: &'static str,
        /// CRC byte received.
        received: u8,
        /// CRC computed over bytes 0..=6.
        computed: u8,
    },
    /// A signal's raw value is outside its DBC range (or not a defined enum value).
    #[error("{message}.{signal}: raw value {raw} outside the valid range {min}..={max}")]
    OutOfRange {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// Raw value received.
        raw: i64,
        /// Smallest valid raw value.
        min: i64,
        /// Largest valid raw value.
        max: i64,
    },
}

/// CRC of an 8-byte payload as the protocol defines it: over bytes 0..=6.
pub fn frame_crc(data: &[u8; 8]) -> u8 {
    crc8_j1850(&data[..CRC_BYTE])
}

/// A message of the wlnav protocol. Lets [`crate::can::RxTracker`] check either
/// direction (the daemon receives states; the simulated machine receives commands).
pub trait CanMessage: Sized {
    /// The layout.
    const SPEC: &'static MessageSpec;
    /// Decode and check a received frame.
    fn decode(frame: &CanFrame) -> Result<Self, DecodeError>;
    /// Encode into a frame, clamping to the DBC ranges.
    fn encode(&self) -> Result<Encoded, EncodeError>;
    /// The frame's alive counter.
    fn alive(&self) -> AliveCounter;
}

/// Packs physical values into a frame according to a spec.
struct Packer {
    spec: &'static MessageSpec,
    word: u64,
    saturated: Saturation,
}

impl Packer {
    fn new(spec: &'static MessageSpec) -> Self {
        Self {
            spec,
            word: 0,
            saturated: Saturation::none(spec),
        }
    }

    fn physical(&mut self, index: usize, value: f64) -> Result<(), EncodeError> {
        let sig = self.spec.sig(index);
        if !value.is_finite() {
            return Err(EncodeError::NonFinite {
                message: self.spec.name,
                signal: sig.name,
                value,
            });
        }
        let (raw, clamped) = sig.to_raw_saturating(value);
        if clamped {
            self.saturated.add(index);
        }
        sig.insert(&mut self.word, raw);
        Ok(())
    }

    /// Integer signals whose values are valid by their Rust type.
    fn raw(&mut self, index: usize, raw: u8) {
        self.spec.sig(index).insert(&mut self.word, i64::from(raw));
    }

    fn finish(self, crc_index: usize) -> Encoded {
        let mut data = self.word.to_le_bytes();
        let crc = frame_crc(&data);
        let mut word = u64::from_le_bytes(data);
        self.spec.sig(crc_index).insert(&mut word, i64::from(crc));
        data = word.to_le_bytes();
        // Built directly: spec ids are constants ≤ 0x7FF (tested in
        // `layouts_are_sound`), so the frame invariants hold without a fallible path.
        debug_assert!(self.spec.id <= super::MAX_STANDARD_ID);
        let frame = CanFrame {
            id: self.spec.id,
            len: 8,
            data,
        };
        Encoded {
            frame,
            saturated: self.saturated,
        }
    }
}

/// Unpacks and checks a received frame according to a spec.
struct Unpacker {
    spec: &'static MessageSpec,
    word: u64,
}

impl Unpacker {
    fn new(spec: &'static MessageSpec, frame: &CanFrame) -> Result<Self, DecodeError> {
        if frame.id() != spec.id {
            return Err(DecodeError::WrongId {
                message: spec.name,
                expected: spec.id,
                got: frame.id(),
            });
        }
        if frame.len() != spec.dlc {
            return Err(DecodeError::WrongLength {
                message: spec.name,
                expected: spec.dlc,
                got: frame.len(),
            });
        }
        let data = frame.raw_data();
        let computed = frame_crc(data);
        if data[CRC_BYTE] != computed {
            return Err(DecodeError::BadCrc {
                message: spec.name,
                received: data[CRC_BYTE],
                computed,
            });
        }
        Ok(Self {
            spec,
            word: u64::from_le_bytes(*data),
        })
    }

    /// The raw value of signal `index`, checked against its DBC range.
    fn raw(&self, index: usize) -> Result<i64, DecodeError> {
        let sig = self.spec.sig(index);
        let raw = sig.extract(self.word);
        let (min, max) = (sig.raw_min(), sig.raw_max());
        if raw < min || raw > max {
            return Err(DecodeError::OutOfRange {
                message: self.spec.name,
                signal: sig.name,
                raw,
                min,
                max,
            });
        }
        Ok(raw)
    }

    fn physical(&self, index: usize) -> Result<f64, DecodeError> {
        Ok(self.spec.sig(index).physical(self.raw(index)?))
    }

    /// A small unsigned signal converted with `conv`; a failed conversion is
    /// reported as out of range.
    fn small<T>(&self, index: usize, conv: impl FnOnce(u8) -> Option<T>) -> Result<T, DecodeError> {
        let raw = self.raw(index)?;
        u8::try_from(raw).ok().and_then(conv).ok_or_else(|| {
            let sig = self.spec.sig(index);
            DecodeError::OutOfRange {
                message: self.spec.name,
                signal: sig.name,
                raw,
                min: sig.raw_min(),
                max: sig.raw_max(),
            }
        })
    }
}

impl CanMessage for VelocityCommandFrame {
    const SPEC: &'static MessageSpec = &VELOCITY_COMMAND;

    fn encode(&self) -> Result<Encoded, EncodeError> {
        let mut p = Packer::new(Self::SPEC);
        p.physical(CMD_BETA_DOT, self.beta_dot_cmd)?;
        p.physical(CMD_V, self.v_cmd)?;
        p.raw(CMD_ALIVE, self.alive.get());
        p.raw(CMD_MODE, self.mode as u8);
        Ok(p.finish(CMD_CRC))
    }

    fn decode(frame: &CanFrame) -> Result<Self, DecodeError> {
        let u = Unpacker::new(Self::SPEC, frame)?;
        Ok(Self {
            beta_dot_cmd: u.physical(CMD_BETA_DOT)?,
            v_cmd: u.physical(CMD_V)?,
            mode: u.small(CMD_MODE, |r| DriveMode::try_from(r).ok())?,
            alive: u.small(CMD_ALIVE, AliveCounter::new)?,
        })
    }

    fn alive(&self) -> AliveCounter {
        self.alive
    }
}

impl CanMessage for MachineState {
    const SPEC: &'static MessageSpec = &MACHINE_STATE;

    fn encode(&self) -> Result<Encoded, EncodeError> {
        let mut p = Packer::new(Self::SPEC);
        p.physical(ST_BETA, self.beta)?;
        p.physical(ST_BETA_DOT, self.beta_dot)?;
        p.physical(ST_V, self.v_f)?;
        p.raw(ST_ALIVE, self.alive.get());
        p.raw(ST_STATUS, self.status as u8);
        Ok(p.finish(ST_CRC))
    }

    fn decode(frame: &CanFrame) -> Result<Self, DecodeError> {
        let u = Unpacker::new(Self::SPEC, frame)?;
        Ok(Self {
            beta: u.physical(ST_BETA)?,
            beta_dot: u.physical(ST_BETA_DOT)?,
            v_f: u.physical(ST_V)?,
            status: u.small(ST_STATUS, |r| MachineStatus::try_from(r).ok())?,
            alive: u.small(ST_ALIVE, AliveCounter::new)?,
        })
    }

    fn alive(&self) -> AliveCounter {
        self.alive
    }
}

impl VelocityCommandFrame {
    /// The frame carrying `command` (the edge from the control layer to the DBC
    /// message).
    pub fn new(command: control::VelocityCommand, mode: DriveMode, alive: AliveCounter) -> Self {
        Self {
            beta_dot_cmd: command.beta_dot,
            v_cmd: command.v,
            mode,
            alive,
        }
    }

    /// The velocities it carries.
    pub fn command(&self) -> control::VelocityCommand {
        control::VelocityCommand {
            beta_dot: self.beta_dot_cmd,
            v: self.v_cmd,
        }
    }

    /// Encode into a frame (see [`CanMessage::encode`]).
    pub fn encode(&self) -> Result<Encoded, EncodeError> {
        <Self as CanMessage>::encode(self)
    }

    /// Decode a received frame (see [`CanMessage::decode`]).
    pub fn decode(frame: &CanFrame) -> Result<Self, DecodeError> {
        <Self as CanMessage>::decode(frame)
    }
}

impl MachineState {
    /// The model's state (DESIGN §2) from this machine state and a pose of the
    /// front axle: the conversion from the CAN and pose layers to the control layer.
    pub fn with_pose(&self, pose: &shm_ipc::Pose2) -> control::State {
        control::State::from_column_slice(&[
            pose.x,
            pose.y,
            pose.heading,
            self.beta,
            self.beta_dot,
            self.v_f,
        ])
    }

    /// |v_f| and |β̇| both below `speed`.
    pub fn at_rest(&self, speed: f64) -> bool {
        self.v_f.abs() < speed && self.beta_dot.abs() < speed
    }

    /// Encode into a frame (see [`CanMessage::encode`]).
    pub fn encode(&self) -> Result<Encoded, EncodeError> {
        <Self as CanMessage>::encode(self)
    }

    /// Decode a received frame (see [`CanMessage::decode`]).
    pub fn decode(frame: &CanFrame) -> Result<Self, DecodeError> {
        <Self as CanMessage>::decode(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_constants_match_tables() {
        let c = &VELOCITY_COMMAND;
        assert_eq!(c.sig(CMD_BETA_DOT).name, "beta_dot_cmd");
        assert_eq!(c.sig(CMD_V).name, "v_cmd");
        assert_eq!(c.sig(CMD_ALIVE).name, "cmd_alive");
        assert_eq!(c.sig(CMD_MODE).name, "mode");
        assert_eq!(c.sig(CMD_CRC).name, "cmd_crc");
        let s = &MACHINE_STATE;
        assert_eq!(s.sig(ST_BETA).name, "beta");
        assert_eq!(s.sig(ST_BETA_DOT).name, "beta_dot");
        assert_eq!(s.sig(ST_V).name, "v_f");
        assert_eq!(s.sig(ST_ALIVE).name, "state_alive");
        assert_eq!(s.sig(ST_STATUS).name, "status");
        assert_eq!(s.sig(ST_CRC).name, "state_crc");
        assert_eq!(c.sig(CMD_CRC).start_bit as usize, CRC_BYTE * 8);
        assert_eq!(s.sig(ST_CRC).start_bit as usize, CRC_BYTE * 8);
    }

    #[test]
    fn layouts_are_sound() {
        for m in MESSAGES {
            assert!(m.id <= super::super::MAX_STANDARD_ID, "{}", m.name);
            let mut used = 0u64;
            for s in m.signals {
                assert!(s.start_bit + s.size <= 8 * m.dlc as u32, "{}", s.name);
                let bits = field_mask(s.size) << s.start_bit;
                assert_eq!(used & bits, 0, "{} overlaps", s.name);
                used |= bits;
                // The DBC range must be representable in the bit width.
                let (lo, hi) = if s.signed {
                    (-(1i64 << (s.size - 1)), (1i64 << (s.size - 1)) - 1)
                } else {
                    (0, (1i64 << s.size) - 1)
                };
                assert!(s.raw_min() >= lo && s.raw_max() <= hi, "{}", s.name);
                // min and max are exact multiples of the factor.
                assert!(
                    (s.physical(s.raw_max()) - s.max).abs() < 1e-12,
                    "{}",
                    s.name
                );
                assert!(
                    (s.physical(s.raw_min()) - s.min).abs() < 1e-12,
                    "{}",
                    s.name
                );
            }
        }
    }

    #[test]
    fn alive_counter_wraps() {
        let mut c = AliveCounter::ZERO;
        for i in 0..40u8 {
            assert_eq!(c.get(), i % 16);
            c = c.next();
        }
        assert_eq!(
            AliveCounter::new(15).map(AliveCounter::next),
            AliveCounter::new(0)
        );
        assert_eq!(AliveCounter::new(16), None);
        let (a, b) = (AliveCounter(14), AliveCounter(2));
        assert_eq!(b.steps_since(a), 4);
        assert_eq!(a.steps_since(a), 0);
    }

    #[test]
    fn sign_extension() {
        let s = &MACHINE_STATE.signals[ST_BETA];
        let mut w = 0u64;
        s.insert(&mut w, -1);
        assert_eq!(w, 0xFFFF);
        assert_eq!(s.extract(w), -1);
        s.insert(&mut w, -32767);
        assert_eq!(s.extract(w), -32767);
    }
}
