//! Goal validation: the daemon calls [`GoalValidator::validate`] on every request so that
//! nothing malformed ever reaches the MPC, and the sender learns why in plain words.
//!
//! These checks need the request alone. Geometry against the obstacles (the machine's
//! footprint at the goal and now, DESIGN §10) needs the machine's dimensions and state and
//! is the daemon's ([`crate::RejectCode::GoalInCollision`],
//! [`crate::RejectCode::MachineInCollision`]).

use core::fmt;

use crate::msg::{GoalKind, GoalReply, GoalRequest, Pose2, RejectCode, MAX_OBSTACLES};

/// Largest goal heading magnitude accepted \[rad\] (about 1,600 turns). Beyond it a heading
/// is absurd rather than merely unwrapped: at 1e300 the spacing of `f64` values is far
/// larger than a turn, so "the heading modulo 2π" has no meaning.
pub const MAX_HEADING_ABS: f64 = 1.0e4;

/// Largest obstacle centre coordinate or radius magnitude accepted \[m\]. Squares of larger
/// values approach the range where the MPC's distance constraints overflow.
pub const MAX_OBSTACLE_ABS: f64 = 1.0e6;

/// An angle wrapped to (−π, π] (DESIGN §11: goal headings are normalised). NaN stays NaN.
pub fn normalize_angle(a: f64) -> f64 {
    use core::f64::consts::{PI, TAU};
    let r = a.rem_euclid(TAU);
    // `rem_euclid` may round up to exactly 2π for tiny negative inputs; both branches
    // then land in (−π, π].
    if r > PI {
        r - TAU
    } else {
        r
    }
}

/// A number as people read it in a reason text: plain decimals for ordinary magnitudes,
/// scientific notation (4 significant digits) for huge or tiny ones, so `1e308` reads
/// `1.000e308` and not 309 digits. At most ~12 bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num {
    value: f64,
    decimals: usize,
}

impl Num {
    /// `value` with 3 decimals (millimetres, milliradians).
    pub const fn new(value: f64) -> Self {
        Self { value, decimals: 3 }
    }

    /// `value` with `decimals` decimals.
    pub const fn with_decimals(value: f64, decimals: usize) -> Self {
        Self { value, decimals }
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.value;
        let a = v.abs();
        if !v.is_finite() {
            write!(f, "{v}")
        } else if a != 0.0 && !(1e-3..1e6).contains(&a) {
            write!(f, "{v:.3e}")
        } else {
            write!(f, "{v:.*}", self.decimals)
        }
    }
}

/// An axis-aligned rectangle of the world frame inside which goals may lie \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Workspace {
    /// Lower x bound \[m\]
    pub x_min: f64,
    /// Upper x bound \[m\]
    pub x_max: f64,
    /// Lower y bound \[m\]
    pub y_min: f64,
    /// Upper y bound \[m\]
    pub y_max: f64,
}

impl Workspace {
    /// A workspace from its bounds. Returns `None` unless all bounds are finite and
    /// `min < max` on both axes (a daemon misconfiguration must not silently accept or
    /// reject everything).
    pub fn new(x_min: f64, x_max: f64, y_min: f64, y_max: f64) -> Option<Self> {
        let ok = [x_min, x_max, y_min, y_max].iter().all(|v| v.is_finite())
            && x_min < x_max
            && y_min < y_max;
        ok.then_some(Self {
            x_min,
            x_max,
            y_min,
            y_max,
        })
    }

    /// True if the point lies inside or on the boundary.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x_min..=self.x_max).contains(&x) && (self.y_min..=self.y_max).contains(&y)
    }
}

impl Default for Workspace {
    /// ±50 m around the origin: generous for the paper's goals (≤ 10 m) while still
    /// catching unit mistakes (mm instead of m).
    fn default() -> Self {
        Self {
            x_min: -50.0,
            x_max: 50.0,
            y_min: -50.0,
            y_max: 50.0,
        }
    }
}

/// Why a goal request is rejected, with the details a human needs. `Display` is the
/// message sent back in [`GoalReply::reason`]; [`RejectReason::code`] the wire code.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RejectReason {
    /// A goal component is NaN or infinite.
    #[error("goal {field} is not finite ({})", Num::new(*value))]
    NonFiniteGoal {
        /// `x`, `y` or `heading`
        field: &'static str,
        /// The offending value
        value: f64,
    },
    /// An obstacle centre is NaN or infinite.
    #[error("obstacle {index} centre {field} is not finite ({})", Num::new(*value))]
    NonFiniteObstacle {
        /// Obstacle index
        index: usize,
        /// `x` or `y`
        field: &'static str,
        /// The offending value
        value: f64,
    },
    /// The goal lies outside the workspace rectangle.
    #[error(
        "goal ({}, {}) m is outside the workspace x [{}, {}] y [{}, {}] m",
        Num::new(*x), Num::new(*y), Num::with_decimals(workspace.x_min, 1), Num::with_decimals(workspace.x_max, 1),
        Num::with_decimals(workspace.y_min, 1), Num::with_decimals(workspace.y_max, 1)
    )]
    OutOfWorkspace {
        /// Goal x \[m\]
        x: f64,
        /// Goal y \[m\]
        y: f64,
        /// The configured workspace
        workspace: Workspace,
    },
    /// More obstacles than the wire format and the MPC support.
    #[error("{count} obstacles given, at most {MAX_OBSTACLES} are supported")]
    TooManyObstacles {
        /// The `obstacle_count` received
        count: u32,
    },
    /// An obstacle radius is zero, negative or not finite.
    #[error("obstacle {index} radius {} m must be positive and finite", Num::new(*r))]
    BadObstacleRadius {
        /// Obstacle index
        index: usize,
        /// The offending radius \[m\]
        r: f64,
    },
    /// The request kind code is not one of [`GoalKind`].
    #[error("unknown request kind {0}")]
    UnknownKind(u32),
    /// The goal heading is finite but absurd (|heading| > [`MAX_HEADING_ABS`]).
    #[error("goal heading {} rad is out of range (|heading| <= {} rad)", Num::new(*heading), Num::with_decimals(MAX_HEADING_ABS, 0))]
    HeadingOutOfRange {
        /// The heading received \[rad\]
        heading: f64,
    },
    /// An obstacle number is finite but absurd (|x|, |y| or r > [`MAX_OBSTACLE_ABS`]).
    #[error("obstacle {index} {field} {} m is out of range (|{field}| <= {} m)", Num::new(*value), Num::new(MAX_OBSTACLE_ABS))]
    ObstacleOutOfRange {
        /// Obstacle index
        index: usize,
        /// `x`, `y` or `r`
        field: &'static str,
        /// The offending value \[m\]
        value: f64,
    },
}

impl RejectReason {
    /// The wire code of this reason.
    pub fn code(&self) -> RejectCode {
        match self {
            Self::NonFiniteGoal { .. } | Self::NonFiniteObstacle { .. } => RejectCode::NonFinite,
            Self::OutOfWorkspace { .. } | Self::HeadingOutOfRange { .. } => {
                RejectCode::OutOfWorkspace
            }
            Self::TooManyObstacles { .. } => RejectCode::TooManyObstacles,
            Self::BadObstacleRadius { .. } | Self::ObstacleOutOfRange { .. } => {
                RejectCode::BadObstacle
            }
            Self::UnknownKind(_) => RejectCode::UnknownKind,
        }
    }

    /// The reply that rejects `request_id` for this reason.
    pub fn to_reply(&self, request_id: u64) -> GoalReply {
        GoalReply::reject(request_id, self.code(), &self.to_string())
    }
}

/// A request that passed validation, decoded into Rust types.
// SetGoal carries its obstacles inline (≈ 230 bytes): validation runs on the daemon's I/O
// path, a flood of requests included, and must not allocate.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum ValidRequest {
    /// Drive to `goal` avoiding `obstacles` (at most [`MAX_OBSTACLES`], all finite, radii > 0).
    SetGoal {
        /// The request id to report in telemetry
        request_id: u64,
        /// Goal pose
        goal: Pose2,
        /// Obstacles (a copy; no allocation beyond the fixed array)
        obstacles: heapless_obstacles::Obstacles,
    },
    /// Drop the goal, stop.
    Cancel {
        /// The request id
        request_id: u64,
    },
    /// Controlled stop, latched until a resume.
    Stop {
        /// The request id
        request_id: u64,
    },
    /// Release an operator stop.
    Resume {
        /// The request id
        request_id: u64,
    },
    /// Reload the configured site file.
    ReloadSite {
        /// The request id
        request_id: u64,
    },
}

impl ValidRequest {
    /// The request id.
    pub fn request_id(&self) -> u64 {
        match self {
            Self::SetGoal { request_id, .. }
            | Self::Cancel { request_id }
            | Self::Stop { request_id }
            | Self::Resume { request_id }
            | Self::ReloadSite { request_id } => *request_id,
        }
    }
}

/// A fixed-capacity obstacle list so validation never allocates (it runs on the daemon's
/// I/O path, possibly thousands of times a second during a flood).
pub mod heapless_obstacles {
    use crate::msg::{Obstacle, MAX_OBSTACLES};

    /// Up to [`MAX_OBSTACLES`] obstacles.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Obstacles {
        items: [Obstacle; MAX_OBSTACLES],
        len: usize,
    }

    impl Obstacles {
        /// Copies `src`; `None` if it is longer than [`MAX_OBSTACLES`].
        pub fn from_slice(src: &[Obstacle]) -> Option<Self> {
            if src.len() > MAX_OBSTACLES {
                return None;
            }
            let mut items = [Obstacle::default(); MAX_OBSTACLES];
            items[..src.len()].copy_from_slice(src);
            Some(Self {
                items,
                len: src.len(),
            })
        }

        /// The obstacles as a slice.
        pub fn as_slice(&self) -> &[Obstacle] {
            &self.items[..self.len]
        }
    }

    impl core::ops::Deref for Obstacles {
        type Target = [Obstacle];
        fn deref(&self) -> &[Obstacle] {
            self.as_slice()
        }
    }
}

/// Checks goal requests against the configured workspace. Cheap and allocation-free on the
/// success path.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GoalValidator {
    /// Goals must lie inside this rectangle.
    pub workspace: Workspace,
}

impl GoalValidator {
    /// A validator for `workspace`.
    pub const fn new(workspace: Workspace) -> Self {
        Self { workspace }
    }

    /// Validates one request. Checks run in a fixed order (kind, obstacle count, finiteness,
    /// workspace (inclusive bounds), heading range, obstacle radii and ranges) so the
    /// reported reason is deterministic when several apply. Cancel, stop and resume are
    /// always valid: the goal fields of such a request are ignored, and refusing to stop
    /// over garbage there would be unsafe. An accepted goal's heading is normalised to
    /// (−π, π] ([`normalize_angle`]).
    pub fn validate(&self, req: &GoalRequest) -> Result<ValidRequest, RejectReason> {
        let request_id = req.request_id;
        let kind = req.kind().map_err(RejectReason::UnknownKind)?;
        match kind {
            GoalKind::Cancel => return Ok(ValidRequest::Cancel { request_id }),
            GoalKind::Stop => return Ok(ValidRequest::Stop { request_id }),
            GoalKind::Resume => return Ok(ValidRequest::Resume { request_id }),
            GoalKind::ReloadSite => return Ok(ValidRequest::ReloadSite { request_id }),
            GoalKind::SetGoal => {}
        }
        let obstacles = req.obstacles().ok_or(RejectReason::TooManyObstacles {
            count: req.obstacle_count,
        })?;
        let g = req.goal;
        for (field, value) in [("x", g.x), ("y", g.y), ("heading", g.heading)] {
            if !value.is_finite() {
                return Err(RejectReason::NonFiniteGoal { field, value });
            }
        }
        for (index, o) in obstacles.iter().enumerate() {
            for (field, value) in [("x", o.x), ("y", o.y)] {
                if !value.is_finite() {
                    return Err(RejectReason::NonFiniteObstacle {
                        index,
                        field,
                        value,
                    });
                }
            }
        }
        if !self.workspace.contains(g.x, g.y) {
            return Err(RejectReason::OutOfWorkspace {
                x: g.x,
                y: g.y,
                workspace: self.workspace,
            });
        }
        if g.heading.abs() > MAX_HEADING_ABS {
            return Err(RejectReason::HeadingOutOfRange { heading: g.heading });
        }
        for (index, o) in obstacles.iter().enumerate() {
            // `!(r > 0)` also catches NaN.
            if !(o.r > 0.0 && o.r.is_finite()) {
                return Err(RejectReason::BadObstacleRadius { index, r: o.r });
            }
            for (field, value) in [("x", o.x), ("y", o.y), ("r", o.r)] {
                if value.abs() > MAX_OBSTACLE_ABS {
                    return Err(RejectReason::ObstacleOutOfRange {
                        index,
                        field,
                        value,
                    });
                }
            }
        }
        let obstacles = heapless_obstacles::Obstacles::from_slice(obstacles).ok_or(
            RejectReason::TooManyObstacles {
                count: req.obstacle_count,
            },
        )?;
        Ok(ValidRequest::SetGoal {
            request_id,
            goal: Pose2::new(g.x, g.y, normalize_angle(g.heading)),
            obstacles,
        })
    }

    /// Validates and builds the matching reply in one go: accept, or reject with code and
    /// message.
    pub fn validate_and_reply(
        &self,
        req: &GoalRequest,
    ) -> (Result<ValidRequest, RejectReason>, GoalReply) {
        let result = self.validate(req);
        let reply = match &result {
            Ok(_) => GoalReply::accept(req.request_id),
            Err(reason) => reason.to_reply(req.request_id),
        };
        (result, reply)
    }
}
