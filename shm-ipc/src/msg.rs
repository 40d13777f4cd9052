//! The `#[repr(C)]` payloads exchanged over shared memory.
//!
//! Every type here is plain old data: fixed size, no pointers, no Rust enums or `bool`s
//! (a peer written in another language, or a buggy one, can put any bit pattern into shared
//! memory, and an invalid `bool`/enum discriminant would be undefined behaviour on read).
//! Discriminants are therefore `u32` codes that are decoded with `TryFrom`, and every
//! struct spells out its padding as `_reserved` fields so the byte layout is identical in
//! every language and contains no uninitialised bytes.
//!
//! The layout is documented in the crate root and frozen by the compile-time assertions at
//! the bottom of this file; changing it requires a new service version (now `v2`: v2 added
//! goal outcomes, the subgoal and route to [`Telemetry`], the resume request and the
//! footprint reject codes).

use core::mem::{align_of, offset_of, size_of};

use iceoryx2::prelude::ZeroCopySend;

/// Maximum number of circular obstacles in one goal request.
pub const MAX_OBSTACLES: usize = 8;
/// Maximum number of states in the planned trajectory of a telemetry sample
/// (x₀..x_N for horizons up to N = 40).
pub const MAX_TRAJECTORY: usize = 41;
/// Capacity in bytes of the UTF-8 reason texts: the reject reason of a [`GoalReply`] and
/// the outcome reason of a [`Telemetry`] sample.
pub const REASON_TEXT_CAPACITY: usize = 128;
/// Maximum number of poses in the global route of a telemetry sample.
pub const MAX_ROUTE: usize = 16;

/// Copies `text` into `buf`, cut at a character boundary to fit, zero-filling the rest;
/// returns the number of bytes stored.
fn write_reason(buf: &mut [u8; REASON_TEXT_CAPACITY], text: &str) -> u32 {
    let mut end = text.len().min(REASON_TEXT_CAPACITY);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    buf.fill(0);
    buf[..end].copy_from_slice(&text.as_bytes()[..end]);
    end as u32
}

/// The UTF-8 text of `len` bytes of `buf`. Never fails: an out-of-range length is clamped
/// and invalid UTF-8 from a foreign peer is cut at the first bad byte.
fn read_reason(buf: &[u8], len: u32) -> &str {
    let bytes = &buf[..(len as usize).min(buf.len())];
    match core::str::from_utf8(bytes) {
        Ok(s) => s,
        // `valid_up_to` is a char boundary by definition, so this cannot fail.
        Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or(""),
    }
}

/// A planar pose: position in metres, heading in radians (world frame, counter-clockwise
/// from the x axis).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::Pose2")]
pub struct Pose2 {
    /// x [m]
    pub x: f64,
    /// y [m]
    pub y: f64,
    /// Heading [rad]
    pub heading: f64,
}

impl Pose2 {
    /// A pose from its components.
    pub const fn new(x: f64, y: f64, heading: f64) -> Self {
        Self { x, y, heading }
    }

    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.heading.is_finite()
    }
}

/// A circular obstacle: centre in metres, radius in metres (already inflated by the
/// machine's own radius, DESIGN §5).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::Obstacle")]
pub struct Obstacle {
    /// Centre x [m]
    pub x: f64,
    /// Centre y [m]
    pub y: f64,
    /// Radius [m], must be positive and finite
    pub r: f64,
}

impl Obstacle {
    /// An obstacle from its centre and radius.
    pub const fn new(x: f64, y: f64, r: f64) -> Self {
        Self { x, y, r }
    }
}

/// The machine state x = [x_f, y_f, θ_f, β, β̇, v_f] (DESIGN §2): front-axle pose, articulation
/// angle and rate, front speed.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::MachineState")]
pub struct MachineState {
    /// Front-axle centre x [m]
    pub x_f: f64,
    /// Front-axle centre y [m]
    pub y_f: f64,
    /// Front-body heading [rad]
    pub theta_f: f64,
    /// Articulation angle β [rad], positive bends the front body to the left
    pub beta: f64,
    /// Articulation rate β̇ [rad/s]
    pub beta_dot: f64,
    /// Front speed v_f [m/s]
    pub v_f: f64,
}

impl MachineState {
    /// All zeros (at rest at the origin).
    pub const ZERO: Self = Self {
        x_f: 0.0,
        y_f: 0.0,
        theta_f: 0.0,
        beta: 0.0,
        beta_dot: 0.0,
        v_f: 0.0,
    };

    /// The state as an array in the order of DESIGN §2.
    pub const fn to_array(&self) -> [f64; 6] {
        [
            self.x_f,
            self.y_f,
            self.theta_f,
            self.beta,
            self.beta_dot,
            self.v_f,
        ]
    }

    /// The state from an array in the order of DESIGN §2.
    pub const fn from_array(a: [f64; 6]) -> Self {
        Self {
            x_f: a[0],
            y_f: a[1],
            theta_f: a[2],
            beta: a[3],
            beta_dot: a[4],
            v_f: a[5],
        }
    }
}

/// The velocity command sent to the machine's low-level controller.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::Command")]
pub struct Command {
    /// Commanded articulation rate β̇_cmd [rad/s]
    pub beta_dot: f64,
    /// Commanded front speed v_cmd [m/s]
    pub v: f64,
}

/// What a [`GoalRequest`] asks for. Sent on the wire as a `u32` ([`GoalRequest::kind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum GoalKind {
    /// Drive to [`GoalRequest::goal`] avoiding [`GoalRequest::obstacles`]; replaces any
    /// previous goal (the newest valid goal wins).
    SetGoal = 1,
    /// Drop the current goal (outcome `cancelled`) and come to a controlled stop; new goals
    /// are accepted again.
    Cancel = 2,
    /// Operator stop: drop the current goal (outcome `cancelled`), controlled stop, and
    /// **latch**: later goals are rejected with [`RejectCode::NotReady`] ("stopped by an
    /// operator") until a [`GoalKind::Resume`].
    Stop = 3,
    /// Release the latch of an operator stop; goals are accepted again. Does not start
    /// anything by itself (the dropped goal stays dropped). Accepted when nothing is latched.
    Resume = 4,
    /// Reload the daemon's configured site file (DESIGN §17). Accepted once the new file
    /// is read and valid; it takes effect at the next tick boundary (telemetry's
    /// `site_version` and `site_hash` show it). Rejected, with what is wrong in the
    /// file, when it is not: the old site stays. The goal fields are ignored.
    ReloadSite = 5,
}

impl GoalKind {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }
}

impl TryFrom<u32> for GoalKind {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        match v {
            1 => Ok(Self::SetGoal),
            2 => Ok(Self::Cancel),
            3 => Ok(Self::Stop),
            4 => Ok(Self::Resume),
            5 => Ok(Self::ReloadSite),
            other => Err(other),
        }
    }
}

/// Request on `{prefix}/v2/goal` (request-response). 232 bytes, alignment 8.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::GoalRequest")]
pub struct GoalRequest {
    /// Chosen by the client, echoed in [`GoalReply::request_id`]; also reported in telemetry
    /// as the id of the active goal. 0 is allowed but means "unidentified".
    pub request_id: u64,
    /// A [`GoalKind`] code (1 set goal, 2 cancel, 3 stop, 4 resume); 0 and others are
    /// rejected.
    pub kind: u32,
    /// Number of valid entries at the front of [`GoalRequest::obstacles`]; > 8 is rejected.
    pub obstacle_count: u32,
    /// Goal pose of the front axle (x [m], y [m], heading [rad]); ignored unless set goal.
    pub goal: Pose2,
    /// Circular obstacles; entries at index ≥ `obstacle_count` are ignored (send zeros).
    pub obstacles: [Obstacle; MAX_OBSTACLES],
}

impl GoalRequest {
    /// A set-goal request. Returns `None` if more than [`MAX_OBSTACLES`] obstacles are
    /// given (the wire format cannot carry them).
    pub fn set_goal(request_id: u64, goal: Pose2, obstacles: &[Obstacle]) -> Option<Self> {
        if obstacles.len() > MAX_OBSTACLES {
            return None;
        }
        let mut req = Self::empty(request_id, GoalKind::SetGoal);
        req.goal = goal;
        req.obstacle_count = obstacles.len() as u32;
        req.obstacles[..obstacles.len()].copy_from_slice(obstacles);
        Some(req)
    }

    /// A cancel request.
    pub const fn cancel(request_id: u64) -> Self {
        Self::empty(request_id, GoalKind::Cancel)
    }

    /// A stop request (latches until [`GoalRequest::resume`]).
    pub const fn stop(request_id: u64) -> Self {
        Self::empty(request_id, GoalKind::Stop)
    }

    /// A resume request (releases an operator stop).
    pub const fn resume(request_id: u64) -> Self {
        Self::empty(request_id, GoalKind::Resume)
    }

    /// A request to reload the daemon's site file.
    pub const fn reload_site(request_id: u64) -> Self {
        Self::empty(request_id, GoalKind::ReloadSite)
    }

    const fn empty(request_id: u64, kind: GoalKind) -> Self {
        Self {
            request_id,
            kind: kind.code(),
            obstacle_count: 0,
            goal: Pose2::new(0.0, 0.0, 0.0),
            obstacles: [Obstacle::new(0.0, 0.0, 0.0); MAX_OBSTACLES],
        }
    }

    /// The decoded kind, or the unknown code.
    pub fn kind(&self) -> Result<GoalKind, u32> {
        GoalKind::try_from(self.kind)
    }

    /// The valid obstacles, or `None` if `obstacle_count` exceeds [`MAX_OBSTACLES`].
    pub fn obstacles(&self) -> Option<&[Obstacle]> {
        self.obstacles.get(..self.obstacle_count as usize)
    }
}

/// Why a goal request was rejected. Sent on the wire as a `u32` ([`GoalReply::reason_code`]).
///
/// Codes 1–4 and 6 are produced by [`crate::GoalValidator`] (the request alone); the others
/// by the daemon, which also knows the machine's geometry and state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum RejectCode {
    /// Accepted: no reason.
    None = 0,
    /// A goal or obstacle number is NaN or infinite.
    NonFinite = 1,
    /// The goal position lies outside the configured workspace rectangle.
    OutOfWorkspace = 2,
    /// `obstacle_count` exceeds [`MAX_OBSTACLES`].
    TooManyObstacles = 3,
    /// An obstacle radius is zero, negative or not finite.
    BadObstacle = 4,
    /// `goal-in-collision`: the machine's footprint at the goal (both axle points, goal pose
    /// with β = 0) lies inside an obstacle; the text names the obstacle.
    GoalInCollision = 5,
    /// The request kind code is unknown.
    UnknownKind = 6,
    /// The daemon is not ready to drive (starting up, faulted, shutting down, or stopped by
    /// an operator until a resume request); the text says which.
    NotReady = 7,
    /// Any other daemon-side reason; see the text.
    Other = 8,
    /// `machine-in-collision`: an obstacle of the request contains the machine's current
    /// footprint (an axle point inside its circle); the text names the obstacle.
    MachineInCollision = 9,
}

impl RejectCode {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }
}

impl TryFrom<u32> for RejectCode {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            0 => Self::None,
            1 => Self::NonFinite,
            2 => Self::OutOfWorkspace,
            3 => Self::TooManyObstacles,
            4 => Self::BadObstacle,
            5 => Self::GoalInCollision,
            6 => Self::UnknownKind,
            7 => Self::NotReady,
            8 => Self::Other,
            9 => Self::MachineInCollision,
            other => return Err(other),
        })
    }
}

/// Reply on `{prefix}/v2/goal`. 152 bytes, alignment 8.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::GoalReply")]
pub struct GoalReply {
    /// The [`GoalRequest::request_id`] this answers.
    pub request_id: u64,
    /// 1 accepted, 0 rejected (any non-zero value reads as accepted).
    pub accepted: u32,
    /// A [`RejectCode`]; 0 when accepted.
    pub reason_code: u32,
    /// Number of valid bytes in [`GoalReply::reason`] (≤ 128).
    pub reason_len: u32,
    /// Zero; keeps `reason` 8-byte aligned and the struct free of implicit padding.
    pub _reserved: u32,
    /// UTF-8 human-readable reason, `reason_len` bytes, rest zero-filled (so it is also
    /// NUL-terminated whenever shorter than 128 bytes).
    pub reason: [u8; REASON_TEXT_CAPACITY],
}

impl GoalReply {
    /// An acceptance of `request_id`.
    pub const fn accept(request_id: u64) -> Self {
        Self {
            request_id,
            accepted: 1,
            reason_code: RejectCode::None.code(),
            reason_len: 0,
            _reserved: 0,
            reason: [0; REASON_TEXT_CAPACITY],
        }
    }

    /// A rejection of `request_id` with a code and a message. A message longer than
    /// [`REASON_TEXT_CAPACITY`] bytes is shortened at a word boundary (never inside a number,
    /// a word or a UTF-8 character) and ends with `…`.
    pub fn reject(request_id: u64, code: RejectCode, message: &str) -> Self {
        let mut reply = Self {
            request_id,
            accepted: 0,
            reason_code: code.code(),
            reason_len: 0,
            _reserved: 0,
            reason: [0; REASON_TEXT_CAPACITY],
        };
        let (kept, ellipsis) = fit_reason(message);
        let mut len = kept.len();
        reply.reason[..len].copy_from_slice(kept.as_bytes());
        if ellipsis {
            reply.reason[len..len + ELLIPSIS.len()].copy_from_slice(ELLIPSIS.as_bytes());
            len += ELLIPSIS.len();
        }
        reply.reason_len = len as u32;
        reply
    }

    /// True if the goal was accepted.
    pub fn is_accepted(&self) -> bool {
        self.accepted != 0
    }

    /// The decoded reject code, or the unknown wire code.
    pub fn reject_code(&self) -> Result<RejectCode, u32> {
        RejectCode::try_from(self.reason_code)
    }

    /// The reason text. Never fails: an out-of-range length is clamped and invalid UTF-8
    /// from a foreign peer is cut at the first bad byte.
    pub fn reason_text(&self) -> &str {
        read_reason(&self.reason, self.reason_len)
    }
}

/// Appended to a shortened reason text.
const ELLIPSIS: &str = "…";

/// The part of `message` that fits in a reason, and whether `…` must follow it. A message
/// that fits is kept whole; a longer one is cut after the last whole word that leaves room
/// for `…` (at a character boundary if a single word is longer than that).
fn fit_reason(message: &str) -> (&str, bool) {
    if message.len() <= REASON_TEXT_CAPACITY {
        return (message, false);
    }
    let budget = REASON_TEXT_CAPACITY - ELLIPSIS.len();
    let mut end = budget;
    while !message.is_char_boundary(end) {
        end -= 1;
    }
    // The cut is clean if the next character starts a new word.
    let next_is_space = message[end..].starts_with(char::is_whitespace);
    if !next_is_space {
        if let Some(space) = message[..end].rfind(char::is_whitespace) {
            end = space;
        }
    }
    let kept = message[..end].trim_end_matches(|c: char| c.is_whitespace() || c == ',');
    (kept, true)
}

/// Bits of [`PoseEstimate::flags`].
pub mod pose_flags {
    /// The pose is valid (localization is converged). A pose without this bit is ignored.
    pub const VALID: u32 = 1 << 0;
    /// [`super::PoseEstimate::covariance`] is filled in.
    pub const COVARIANCE_VALID: u32 = 1 << 1;
}

/// Published on `{prefix}/v2/pose` by localization (or the simulated backend). 112 bytes,
/// alignment 8.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::PoseEstimate")]
pub struct PoseEstimate {
    /// Measurement time in nanoseconds of `CLOCK_MONOTONIC` on this host (shared memory means
    /// same host, so all processes share that clock); see [`crate::monotonic_now_ns`]. The
    /// daemon uses it to detect stale poses and to compensate latency.
    pub timestamp_ns: u64,
    /// Publisher's sequence counter (wraps); lets a reader notice dropped samples.
    pub sequence: u32,
    /// [`pose_flags`] bits.
    pub flags: u32,
    /// Front-axle centre x [m], world frame.
    pub x: f64,
    /// Front-axle centre y [m], world frame.
    pub y: f64,
    /// Front-body heading θ_f [rad].
    pub heading: f64,
    /// Row-major 3×3 covariance of (x, y, heading) [m², m·rad, rad²]; meaningful only with
    /// [`pose_flags::COVARIANCE_VALID`].
    pub covariance: [f64; 9],
}

impl PoseEstimate {
    /// A valid pose without covariance.
    pub const fn new(timestamp_ns: u64, sequence: u32, pose: Pose2) -> Self {
        Self {
            timestamp_ns,
            sequence,
            flags: pose_flags::VALID,
            x: pose.x,
            y: pose.y,
            heading: pose.heading,
            covariance: [0.0; 9],
        }
    }

    /// The pose part.
    pub const fn pose(&self) -> Pose2 {
        Pose2::new(self.x, self.y, self.heading)
    }

    /// True if flagged valid and the pose is finite (the daemon must ignore it otherwise).
    pub fn is_usable(&self) -> bool {
        self.flags & pose_flags::VALID != 0 && self.pose().is_finite()
    }
}

/// The daemon's operating mode. Sent on the wire as a `u32` ([`Telemetry::mode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Mode {
    /// Starting up (weights loading, first solve not done yet).
    Startup = 0,
    /// No goal: holding still.
    Idle = 1,
    /// Driving towards the goal.
    Tracking = 2,
    /// Goal reached (DESIGN §7 success test), holding still.
    Reached = 3,
    /// Controlled stop in progress (cancel, stop request, or a fault).
    Stopping = 4,
    /// A fault is active; see [`Telemetry::fault_flags`].
    Fault = 5,
}

impl Mode {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }
}

impl TryFrom<u32> for Mode {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            0 => Self::Startup,
            1 => Self::Idle,
            2 => Self::Tracking,
            3 => Self::Reached,
            4 => Self::Stopping,
            5 => Self::Fault,
            other => return Err(other),
        })
    }
}

/// How a goal ended (DESIGN §10). Sent on the wire as a `u32` ([`Telemetry::outcome`]).
///
/// Every accepted goal ends in exactly one outcome, reported in exactly one telemetry
/// sample together with the goal's request id and a reason text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum GoalOutcome {
    /// No goal ended this tick.
    None = 0,
    /// `succeeded`: the goal was reached (DESIGN §7 test, at rest); the machine holds.
    Succeeded = 1,
    /// `cancelled`: a cancel or an operator stop request ended the goal.
    Cancelled = 2,
    /// `preempted`: a newer goal replaced it (the newest valid goal wins).
    Preempted = 3,
    /// `aborted`: the daemon gave up; [`Telemetry::abort_reason`] says why.
    Aborted = 4,
}

impl GoalOutcome {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The outcome's name as used in logs, texts and the CLI (`succeeded`, `cancelled`, …).
    pub const fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Succeeded => "succeeded",
            Self::Cancelled => "cancelled",
            Self::Preempted => "preempted",
            Self::Aborted => "aborted",
        }
    }
}

impl TryFrom<u32> for GoalOutcome {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            0 => Self::None,
            1 => Self::Succeeded,
            2 => Self::Cancelled,
            3 => Self::Preempted,
            4 => Self::Aborted,
            other => return Err(other),
        })
    }
}

/// Why a goal was aborted. Sent on the wire as a `u32` ([`Telemetry::abort_reason`]); 0
/// unless the outcome is [`GoalOutcome::Aborted`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum AbortReason {
    /// Not aborted.
    None = 0,
    /// `no-progress`: the error to the goal did not shrink for the configured time
    /// (`loop.progress_timeout`, default 10 s; Nav2's progress checker).
    NoProgress = 1,
    /// `no-route`: the global layer found no collision-free route.
    NoRoute = 2,
    /// `goal-in-collision`: the goal turned out to be in collision after it was accepted.
    GoalInCollision = 3,
    /// `fault`: a fault stopped the machine (stale pose or machine state, CAN integrity,
    /// solver failure, machine not in automatic mode); the text names it.
    Fault = 4,
    /// `shutdown`: the daemon is shutting down (SIGTERM, SIGINT).
    Shutdown = 5,
}

impl AbortReason {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The reason's name as used in logs, texts and the CLI (`no-progress`, …).
    pub const fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::NoProgress => "no-progress",
            Self::NoRoute => "no-route",
            Self::GoalInCollision => "goal-in-collision",
            Self::Fault => "fault",
            Self::Shutdown => "shutdown",
        }
    }
}

impl TryFrom<u32> for AbortReason {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        Ok(match v {
            0 => Self::None,
            1 => Self::NoProgress,
            2 => Self::NoRoute,
            3 => Self::GoalInCollision,
            4 => Self::Fault,
            5 => Self::Shutdown,
            other => return Err(other),
        })
    }
}

/// Bits of [`Telemetry::fault_flags`].
pub mod fault_flags;
mod live;
pub use live::*;

/// Published on `{prefix}/v2/telemetry` by the daemon once per control tick. 2816 bytes,
/// alignment 8.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::Telemetry")]
pub struct Telemetry {
    /// Control tick counter since daemon start.
    pub tick: u64,
    /// Tick start time, nanoseconds of `CLOCK_MONOTONIC`.
    pub timestamp_ns: u64,
    /// [`GoalRequest::request_id`] of the active goal (0 when there is none).
    pub goal_request_id: u64,
    /// A [`Mode`] code.
    pub mode: u32,
    /// [`fault_flags`] bits.
    pub fault_flags: u32,
    /// 1 if [`Telemetry::goal`] holds an active goal, else 0.
    pub goal_active: u32,
    /// Number of valid states at the front of [`Telemetry::trajectory`] (N + 1, ≤ 41).
    pub trajectory_len: u32,
    /// QP (interior-point) iterations spent this tick.
    pub qp_iterations: u32,
    /// SQP iterations spent this tick (1 for plain RTI).
    pub sqp_iterations: u32,
    /// Wall time of this tick's solve [µs].
    pub solve_time_us: f64,
    /// Optimal cost of this tick's solution (dimensionless).
    pub cost: f64,
    /// Position error ‖(x_f − x_g, y_f − y_g)‖ [m].
    pub pose_error_xy: f64,
    /// Wrapped heading error θ_f − θ_g [rad].
    pub pose_error_heading: f64,
    /// Measured (delay-compensated) state x at this tick.
    pub state: MachineState,
    /// Active goal (meaningful only if `goal_active` = 1).
    pub goal: Pose2,
    /// Command sent to the machine this tick.
    pub command: Command,
    /// Planned trajectory x₀..x_N, `trajectory_len` valid entries, rest zero.
    pub trajectory: [MachineState; MAX_TRAJECTORY],
    /// The request id of the goal that ended this tick (0 when `outcome` is 0).
    pub outcome_request_id: u64,
    /// A [`GoalOutcome`] code: non-zero on exactly one tick per accepted goal.
    pub outcome: u32,
    /// An [`AbortReason`] code when `outcome` is aborted, else 0.
    pub abort_reason: u32,
    /// Sequence number of this outcome (1, 2, … since daemon start; 0 when `outcome` is 0).
    /// A reader that sees a gap missed an outcome.
    pub outcome_seq: u32,
    /// Number of valid bytes in `outcome_text` (≤ 128).
    pub outcome_text_len: u32,
    /// UTF-8 reason text of the outcome, `outcome_text_len` bytes, rest zero.
    pub outcome_text: [u8; REASON_TEXT_CAPACITY],
    /// 1 if `subgoal` holds the intermediate goal the MPC drives to (global layer), else 0.
    pub subgoal_active: u32,
    /// Number of valid poses at the front of `route` (≤ 16); 0 without a global route.
    pub route_len: u32,
    /// The current subgoal of the global route (meaningful only if `subgoal_active` = 1).
    pub subgoal: Pose2,
    /// The global route: `route_len` poses from the machine towards the goal, rest zero.
    pub route: [Pose2; MAX_ROUTE],
    /// Wall time of the last route plan, on the planner thread, not in the tick [µs].
    pub plan_time_us: f64,
    /// How old the route followed was when it arrived from the planner [s].
    pub route_age_s: f64,
    /// 1 when the machine is at rest: |v_f| and |β̇| below the daemon's
    /// `loop.rest_speed` (the one definition; clients read it, they do not
    /// keep a threshold of their own). 0 while moving or with no machine state.
    pub at_rest: u32,
    /// Perception's id of the live obstacle the command comes nearest to, with
    /// [`fault_flags::LIVE_NEAR`] (DESIGN §18); 0 without it.
    pub live_id: u32,
    /// The loaded site's `version` (DESIGN §17; 0 with no site).
    pub site_version: u64,
    /// The loaded site file's content hash (64-bit FNV-1a of its bytes; 0 with no site).
    pub site_hash: u64,
    /// Valid bytes in [`Telemetry::site_id`] (≤ 64; 0 with no site).
    pub site_id_len: u32,
    /// Zero (keeps `site_id` 8-byte aligned).
    pub _reserved_site: u32,
    /// The loaded site's `id`, UTF-8, `site_id_len` bytes, rest zero.
    pub site_id: [u8; SITE_ID_CAPACITY],
}

/// Bytes of [`Telemetry::site_id`] (a site id is at most 64 bytes, DESIGN §17).
pub const SITE_ID_CAPACITY: usize = 64;

impl Telemetry {
    /// All zeros, mode [`Mode::Startup`].
    pub const ZERO: Self = Self {
        tick: 0,
        timestamp_ns: 0,
        goal_request_id: 0,
        mode: Mode::Startup as u32,
        fault_flags: 0,
        goal_active: 0,
        trajectory_len: 0,
        qp_iterations: 0,
        sqp_iterations: 0,
        solve_time_us: 0.0,
        cost: 0.0,
        pose_error_xy: 0.0,
        pose_error_heading: 0.0,
        state: MachineState::ZERO,
        goal: Pose2::new(0.0, 0.0, 0.0),
        command: Command {
            beta_dot: 0.0,
            v: 0.0,
        },
        trajectory: [MachineState::ZERO; MAX_TRAJECTORY],
        outcome_request_id: 0,
        outcome: GoalOutcome::None as u32,
        abort_reason: AbortReason::None as u32,
        outcome_seq: 0,
        outcome_text_len: 0,
        outcome_text: [0; REASON_TEXT_CAPACITY],
        subgoal_active: 0,
        route_len: 0,
        subgoal: Pose2::new(0.0, 0.0, 0.0),
        route: [Pose2::new(0.0, 0.0, 0.0); MAX_ROUTE],
        plan_time_us: 0.0,
        route_age_s: 0.0,
        at_rest: 0,
        live_id: 0,
        site_version: 0,
        site_hash: 0,
        site_id_len: 0,
        _reserved_site: 0,
        site_id: [0; SITE_ID_CAPACITY],
    };

    /// Sets the site fields (`None`: no site). An id longer than
    /// [`SITE_ID_CAPACITY`] bytes is cut at a character boundary.
    pub fn set_site(&mut self, site: Option<(&str, u64, u64)>) {
        self.site_id = [0; SITE_ID_CAPACITY];
        let (id, version, hash) = site.unwrap_or(("", 0, 0));
        let mut end = id.len().min(SITE_ID_CAPACITY);
        while !id.is_char_boundary(end) {
            end -= 1;
        }
        self.site_id[..end].copy_from_slice(&id.as_bytes()[..end]);
        self.site_id_len = end as u32;
        self.site_version = version;
        self.site_hash = hash;
    }

    /// The site's id ("" with no site). Never fails: see [`GoalReply::reason_text`].
    pub fn site_id(&self) -> &str {
        read_reason(&self.site_id, self.site_id_len)
    }

    /// The decoded mode, or the unknown wire code.
    pub fn mode(&self) -> Result<Mode, u32> {
        Mode::try_from(self.mode)
    }

    /// The valid part of the planned trajectory (clamped to [`MAX_TRAJECTORY`], so a corrupt
    /// length cannot make this panic).
    pub fn trajectory(&self) -> &[MachineState] {
        &self.trajectory[..(self.trajectory_len as usize).min(MAX_TRAJECTORY)]
    }

    /// Copies `states` into the trajectory (at most [`MAX_TRAJECTORY`], the rest is
    /// zeroed) and sets the length. Returns how many were stored.
    pub fn set_trajectory(&mut self, states: &[MachineState]) -> usize {
        let n = states.len().min(MAX_TRAJECTORY);
        self.trajectory[..n].copy_from_slice(&states[..n]);
        self.trajectory[n..].fill(MachineState::ZERO);
        self.trajectory_len = n as u32;
        n
    }

    /// The active goal, if any.
    pub fn active_goal(&self) -> Option<Pose2> {
        (self.goal_active != 0).then_some(self.goal)
    }

    /// Reports the end of goal `request_id` on this sample: outcome, abort reason (give
    /// [`AbortReason::None`] unless aborted), sequence number and reason text (cut at a
    /// character boundary to [`REASON_TEXT_CAPACITY`] bytes).
    pub fn set_outcome(
        &mut self,
        request_id: u64,
        outcome: GoalOutcome,
        abort_reason: AbortReason,
        seq: u32,
        text: &str,
    ) {
        self.outcome_request_id = request_id;
        self.outcome = outcome.code();
        self.abort_reason = abort_reason.code();
        self.outcome_seq = seq;
        self.outcome_text_len = write_reason(&mut self.outcome_text, text);
    }

    /// The decoded outcome of this sample, or the unknown wire code.
    pub fn outcome(&self) -> Result<GoalOutcome, u32> {
        GoalOutcome::try_from(self.outcome)
    }

    /// The decoded abort reason, or the unknown wire code.
    pub fn abort_reason(&self) -> Result<AbortReason, u32> {
        AbortReason::try_from(self.abort_reason)
    }

    /// The outcome's reason text (clamped and UTF-8-safe like [`GoalReply::reason_text`]).
    pub fn outcome_text(&self) -> &str {
        read_reason(&self.outcome_text, self.outcome_text_len)
    }

    /// The current subgoal of the global route, if any.
    pub fn active_subgoal(&self) -> Option<Pose2> {
        (self.subgoal_active != 0).then_some(self.subgoal)
    }

    /// The valid part of the global route (clamped to [`MAX_ROUTE`]).
    pub fn route(&self) -> &[Pose2] {
        &self.route[..(self.route_len as usize).min(MAX_ROUTE)]
    }

    /// Copies `poses` into the route (at most [`MAX_ROUTE`], the rest zeroed) and sets the
    /// length. Returns how many were stored.
    pub fn set_route(&mut self, poses: &[Pose2]) -> usize {
        let n = poses.len().min(MAX_ROUTE);
        self.route[..n].copy_from_slice(&poses[..n]);
        self.route[n..].fill(Pose2::new(0.0, 0.0, 0.0));
        self.route_len = n as u32;
        n
    }
}

impl Default for Telemetry {
    fn default() -> Self {
        Self::ZERO
    }
}

// ---------------------------------------------------------------------------------------
// Layout freeze. These are the numbers documented in the crate root; a C/C++/Python peer
// relies on them. If one fails, you changed the wire format: bump the service version.
// ---------------------------------------------------------------------------------------

const _: () = assert!(size_of::<Pose2>() == 24 && align_of::<Pose2>() == 8);
const _: () = assert!(offset_of!(Pose2, x) == 0);
const _: () = assert!(offset_of!(Pose2, y) == 8);
const _: () = assert!(offset_of!(Pose2, heading) == 16);

const _: () = assert!(size_of::<Obstacle>() == 24 && align_of::<Obstacle>() == 8);
const _: () = assert!(offset_of!(Obstacle, x) == 0);
const _: () = assert!(offset_of!(Obstacle, y) == 8);
const _: () = assert!(offset_of!(Obstacle, r) == 16);

const _: () = assert!(size_of::<MachineState>() == 48 && align_of::<MachineState>() == 8);
const _: () = assert!(offset_of!(MachineState, x_f) == 0);
const _: () = assert!(offset_of!(MachineState, y_f) == 8);
const _: () = assert!(offset_of!(MachineState, theta_f) == 16);
const _: () = assert!(offset_of!(MachineState, beta) == 24);
const _: () = assert!(offset_of!(MachineState, beta_dot) == 32);
const _: () = assert!(offset_of!(MachineState, v_f) == 40);

const _: () = assert!(size_of::<Command>() == 16 && align_of::<Command>() == 8);
const _: () = assert!(offset_of!(Command, beta_dot) == 0);
const _: () = assert!(offset_of!(Command, v) == 8);

const _: () = assert!(size_of::<GoalRequest>() == 232 && align_of::<GoalRequest>() == 8);
const _: () = assert!(offset_of!(GoalRequest, request_id) == 0);
const _: () = assert!(offset_of!(GoalRequest, kind) == 8);
const _: () = assert!(offset_of!(GoalRequest, obstacle_count) == 12);
const _: () = assert!(offset_of!(GoalRequest, goal) == 16);
const _: () = assert!(offset_of!(GoalRequest, obstacles) == 40);

const _: () = assert!(size_of::<GoalReply>() == 152 && align_of::<GoalReply>() == 8);
const _: () = assert!(offset_of!(GoalReply, request_id) == 0);
const _: () = assert!(offset_of!(GoalReply, accepted) == 8);
const _: () = assert!(offset_of!(GoalReply, reason_code) == 12);
const _: () = assert!(offset_of!(GoalReply, reason_len) == 16);
const _: () = assert!(offset_of!(GoalReply, _reserved) == 20);
const _: () = assert!(offset_of!(GoalReply, reason) == 24);

const _: () = assert!(size_of::<PoseEstimate>() == 112 && align_of::<PoseEstimate>() == 8);
const _: () = assert!(offset_of!(PoseEstimate, timestamp_ns) == 0);
const _: () = assert!(offset_of!(PoseEstimate, sequence) == 8);
const _: () = assert!(offset_of!(PoseEstimate, flags) == 12);
const _: () = assert!(offset_of!(PoseEstimate, x) == 16);
const _: () = assert!(offset_of!(PoseEstimate, y) == 24);
const _: () = assert!(offset_of!(PoseEstimate, heading) == 32);
const _: () = assert!(offset_of!(PoseEstimate, covariance) == 40);

const _: () = assert!(size_of::<Telemetry>() == 2816 && align_of::<Telemetry>() == 8);
const _: () = assert!(offset_of!(Telemetry, tick) == 0);
const _: () = assert!(offset_of!(Telemetry, timestamp_ns) == 8);
const _: () = assert!(offset_of!(Telemetry, goal_request_id) == 16);
const _: () = assert!(offset_of!(Telemetry, mode) == 24);
const _: () = assert!(offset_of!(Telemetry, fault_flags) == 28);
const _: () = assert!(offset_of!(Telemetry, goal_active) == 32);
const _: () = assert!(offset_of!(Telemetry, trajectory_len) == 36);
const _: () = assert!(offset_of!(Telemetry, qp_iterations) == 40);
const _: () = assert!(offset_of!(Telemetry, sqp_iterations) == 44);
const _: () = assert!(offset_of!(Telemetry, solve_time_us) == 48);
const _: () = assert!(offset_of!(Telemetry, cost) == 56);
const _: () = assert!(offset_of!(Telemetry, pose_error_xy) == 64);
const _: () = assert!(offset_of!(Telemetry, pose_error_heading) == 72);
const _: () = assert!(offset_of!(Telemetry, state) == 80);
const _: () = assert!(offset_of!(Telemetry, goal) == 128);
const _: () = assert!(offset_of!(Telemetry, command) == 152);
const _: () = assert!(offset_of!(Telemetry, trajectory) == 168);
const _: () = assert!(offset_of!(Telemetry, outcome_request_id) == 2136);
const _: () = assert!(offset_of!(Telemetry, outcome) == 2144);
const _: () = assert!(offset_of!(Telemetry, abort_reason) == 2148);
const _: () = assert!(offset_of!(Telemetry, outcome_seq) == 2152);
const _: () = assert!(offset_of!(Telemetry, outcome_text_len) == 2156);
const _: () = assert!(offset_of!(Telemetry, outcome_text) == 2160);
const _: () = assert!(offset_of!(Telemetry, subgoal_active) == 2288);
const _: () = assert!(offset_of!(Telemetry, route_len) == 2292);
const _: () = assert!(offset_of!(Telemetry, subgoal) == 2296);
const _: () = assert!(offset_of!(Telemetry, route) == 2320);
const _: () = assert!(offset_of!(Telemetry, plan_time_us) == 2704);
const _: () = assert!(offset_of!(Telemetry, route_age_s) == 2712);
const _: () = assert!(offset_of!(Telemetry, at_rest) == 2720);
const _: () = assert!(offset_of!(Telemetry, live_id) == 2724);
const _: () = assert!(offset_of!(Telemetry, site_version) == 2728);
const _: () = assert!(offset_of!(Telemetry, site_hash) == 2736);
const _: () = assert!(offset_of!(Telemetry, site_id_len) == 2744);
const _: () = assert!(offset_of!(Telemetry, site_id) == 2752);
