//! Live-obstacle validation (DESIGN §11, §18): the daemon calls
//! [`LiveObstacleValidator::validate`] on every [`LiveObstacleSet`] it reads, and a
//! publisher may call it before sending to learn what the daemon would say.
//!
//! A set with one bad obstacle is rejected **whole**. Dropping only the bad obstacle would
//! make it invisible while the rest of the set looks fresh; rejecting the set keeps the
//! previous accepted set ageing, so a perception that keeps sending garbage runs into the
//! daemon's staleness rule and the machine stops.
//!
//! Pure and allocation-free: no clock is read here (`now_ns` is the caller's), nothing is
//! allocated, so it runs on the daemon's I/O path for every set of a flood.

use core::fmt;

use crate::msg::{
    LiveObstacle, LiveObstacleSet, ObstacleShape, MAX_LIVE_OBSTACLES, MAX_POLYGON_VERTICES,
};
use crate::validate::{Num, MAX_OBSTACLE_ABS};

/// Smallest polygon area accepted \[m²\] (a square millimetre): below it the vertices are
/// (nearly) collinear and the outline has no inside to keep out of.
pub const MIN_POLYGON_AREA: f64 = 1e-6;

/// Checks live obstacle sets. The limits are public fields with documented defaults
/// ([`LiveObstacleValidator::default`]); [`LiveObstacleValidator::new`] checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveObstacleValidator {
    /// How far a stamp (the set's, or an obstacle's) may lie ahead of the daemon's
    /// `CLOCK_MONOTONIC`, and an obstacle's stamp ahead of its set's \[s\]. Default 0.05 s,
    /// as for poses: the same host, one clock, so only rounding and scheduling put a stamp
    /// ahead; more is a publisher's bug, and a stamp from the future would defeat the age
    /// test.
    pub max_future_s: f64,
    /// Largest circle radius \[m\]. Default 30 m: larger than any machine or pile a
    /// perception tracks as one thing; beyond it a unit or parsing mistake (mm for m).
    pub max_radius_m: f64,
    /// Largest polygon extent (its diameter: the largest distance between two vertices)
    /// \[m\]. Default 60 m, twice the largest radius.
    pub max_extent_m: f64,
    /// Largest speed ‖(vx, vy)‖ \[m/s\]. Default 30 m/s (108 km/h): nothing on a work site
    /// moves faster; beyond it a unit mistake (km/h for m/s) or garbage.
    pub max_speed_mps: f64,
    /// Largest |coordinate| of a circle centre or polygon vertex \[m\]. Default
    /// [`MAX_OBSTACLE_ABS`], as for the obstacles of a goal.
    pub max_abs_coord: f64,
}

impl Default for LiveObstacleValidator {
    fn default() -> Self {
        Self {
            max_future_s: 0.05,
            max_radius_m: 30.0,
            max_extent_m: 60.0,
            max_speed_mps: 30.0,
            max_abs_coord: MAX_OBSTACLE_ABS,
        }
    }
}

/// A limit of [`LiveObstacleValidator::new`] is not a positive finite number.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("live obstacle check: {field} must be a positive finite number, got {}", Num::new(*value))]
pub struct LiveValidatorSettingError {
    /// The field's name (`max_future_s`, …)
    pub field: &'static str,
    /// The value given
    pub value: f64,
}

/// A number of a [`LiveObstacle`], as named in a rejection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// Circle centre x
    X,
    /// Circle centre y
    Y,
    /// Circle radius
    Radius,
    /// Velocity x
    Vx,
    /// Velocity y
    Vy,
    /// x of the polygon vertex of this index
    VertexX(usize),
    /// y of the polygon vertex of this index
    VertexY(usize),
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::X => f.write_str("centre x"),
            Self::Y => f.write_str("centre y"),
            Self::Radius => f.write_str("radius"),
            Self::Vx => f.write_str("velocity x"),
            Self::Vy => f.write_str("velocity y"),
            Self::VertexX(k) => write!(f, "vertex {k} x"),
            Self::VertexY(k) => write!(f, "vertex {k} y"),
        }
    }
}

/// What is wrong with a polygon's outline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PolygonDefect {
    /// Vertices `vertex` and the next one (cyclically) coincide: a zero-length edge.
    RepeatedVertex {
        /// The first of the two
        vertex: usize,
    },
    /// Two edges that do not share a vertex cross or touch (edge k runs from vertex k to
    /// vertex k + 1, cyclically).
    SelfIntersecting {
        /// The lower edge index
        edge_a: usize,
        /// The higher edge index
        edge_b: usize,
    },
    /// The outline encloses (nearly) nothing: |area| < [`MIN_POLYGON_AREA`].
    ZeroArea {
        /// The signed area \[m²\] (positive counter-clockwise)
        area: f64,
    },
    /// A simple polygon that is not convex: at `vertex` the outline turns against its
    /// winding.
    NotConvex {
        /// The reflex vertex
        vertex: usize,
        /// True if the polygon winds counter-clockwise (either winding is accepted)
        counter_clockwise: bool,
    },
}

impl PolygonDefect {
    /// The defect's rule name (`repeated-vertex`, `self-intersecting`, `zero-area`,
    /// `not-convex`).
    pub const fn rule(&self) -> &'static str {
        match self {
            Self::RepeatedVertex { .. } => "repeated-vertex",
            Self::SelfIntersecting { .. } => "self-intersecting",
            Self::ZeroArea { .. } => "zero-area",
            Self::NotConvex { .. } => "not-convex",
        }
    }
}

impl fmt::Display for PolygonDefect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::RepeatedVertex { vertex } => {
                write!(f, "vertices {vertex} and the next one coincide")
            }
            Self::SelfIntersecting { edge_a, edge_b } => write!(
                f,
                "the outline crosses itself (edges {edge_a} and {edge_b} meet)"
            ),
            Self::ZeroArea { area } => write!(
                f,
                "the outline encloses no area ({} m², at least {} m² needed)",
                Num::with_decimals(area, 6),
                Num::with_decimals(MIN_POLYGON_AREA, 6)
            ),
            Self::NotConvex {
                vertex,
                counter_clockwise,
            } => write!(
                f,
                "it is not convex: the outline winds {} but turns the other way at vertex \
                 {vertex}",
                if counter_clockwise {
                    "counter-clockwise"
                } else {
                    "clockwise"
                }
            ),
        }
    }
}

/// Why a live obstacle set is rejected (whole), naming the rule and, for a rule about one
/// obstacle, the obstacle by index and id. `Display` is the plain-words reason;
/// [`LiveSetRejection::rule`] a short name for logs and counters.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LiveSetRejection {
    /// `count` exceeds [`MAX_LIVE_OBSTACLES`].
    #[error("the set claims {count} obstacles, at most {MAX_LIVE_OBSTACLES} fit")]
    TooManyObstacles {
        /// The `count` received
        count: u32,
    },
    /// The set's stamp lies more than `max_future_s` ahead of now.
    #[error(
        "the set is stamped {} s in the future (at most {} s allowed)",
        Num::new(*ahead_s), Num::new(*max_s)
    )]
    SetStampInFuture {
        /// How far ahead \[s\]
        ahead_s: f64,
        /// The limit \[s\]
        max_s: f64,
    },
    /// The shape code is not one of [`ObstacleShape`].
    #[error("obstacle {index} (id {id}): unknown shape code {code}")]
    UnknownShape {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The code received
        code: u32,
    },
    /// The class code is not one of [`crate::ObstacleClass`].
    #[error("obstacle {index} (id {id}): unknown class code {code}")]
    UnknownClass {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The code received
        code: u32,
    },
    /// A polygon with fewer than 3 or more than [`MAX_POLYGON_VERTICES`] vertices.
    #[error(
        "obstacle {index} (id {id}): a polygon needs 3 to {MAX_POLYGON_VERTICES} vertices, it \
         has {count}"
    )]
    VertexCount {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The `vertex_count` received
        count: u32,
    },
    /// A number the daemon reads is NaN or infinite.
    #[error("obstacle {index} (id {id}): {field} is not finite ({})", Num::new(*value))]
    NonFinite {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// Which number
        field: Field,
        /// The value
        value: f64,
    },
    /// The obstacle's stamp lies more than `max_future_s` ahead of now.
    #[error(
        "obstacle {index} (id {id}) is stamped {} s in the future (at most {} s allowed)",
        Num::new(*ahead_s), Num::new(*max_s)
    )]
    ObstacleStampInFuture {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// How far ahead \[s\]
        ahead_s: f64,
        /// The limit \[s\]
        max_s: f64,
    },
    /// The obstacle's stamp lies more than `max_future_s` after its set's stamp (an
    /// obstacle cannot be seen after the set was measured).
    #[error(
        "obstacle {index} (id {id}) is stamped {} s after its set (at most {} s allowed)",
        Num::new(*after_s), Num::new(*max_s)
    )]
    ObstacleNewerThanSet {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// How far after the set's stamp \[s\]
        after_s: f64,
        /// The limit \[s\]
        max_s: f64,
    },
    /// The speed ‖(vx, vy)‖ is absurd.
    #[error(
        "obstacle {index} (id {id}) moves at {} m/s (at most {} m/s)",
        Num::new(*speed), Num::new(*max)
    )]
    SpeedTooHigh {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// ‖(vx, vy)‖ \[m/s\]
        speed: f64,
        /// The limit \[m/s\]
        max: f64,
    },
    /// A centre or vertex coordinate is absurd.
    #[error(
        "obstacle {index} (id {id}): {field} {} m is out of range (|{field}| <= {} m)",
        Num::new(*value), Num::new(*max)
    )]
    CoordinateOutOfRange {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// Which coordinate
        field: Field,
        /// The value \[m\]
        value: f64,
        /// The limit \[m\]
        max: f64,
    },
    /// A circle radius that is zero or negative.
    #[error("obstacle {index} (id {id}): radius {} m must be positive", Num::new(*radius))]
    RadiusNotPositive {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The radius \[m\]
        radius: f64,
    },
    /// A circle radius that is absurd.
    #[error(
        "obstacle {index} (id {id}): radius {} m is too large (at most {} m)",
        Num::new(*radius), Num::new(*max)
    )]
    RadiusTooLarge {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The radius \[m\]
        radius: f64,
        /// The limit \[m\]
        max: f64,
    },
    /// A polygon whose outline is not a simple convex polygon with an inside.
    #[error("obstacle {index} (id {id}): bad polygon: {defect}")]
    BadPolygon {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// What is wrong
        defect: PolygonDefect,
    },
    /// A polygon whose extent (largest distance between two vertices) is absurd.
    #[error(
        "obstacle {index} (id {id}): the polygon is {} m across (at most {} m)",
        Num::new(*extent), Num::new(*max)
    )]
    ExtentTooLarge {
        /// Index in the set
        index: usize,
        /// Its id
        id: u32,
        /// The extent \[m\]
        extent: f64,
        /// The limit \[m\]
        max: f64,
    },
    /// Two obstacles of the set carry the same id.
    #[error(
        "obstacle {index} has id {id}, as obstacle {first_index} has: ids must be unique in a set"
    )]
    DuplicateId {
        /// Index of the later one
        index: usize,
        /// The id
        id: u32,
        /// Index of the first with this id
        first_index: usize,
    },
}

impl LiveSetRejection {
    /// The rule's short name, for logs and counters (`too-many-obstacles`,
    /// `set-stamp-in-future`, `unknown-shape`, `unknown-class`, `vertex-count`,
    /// `non-finite`, `obstacle-stamp-in-future`, `obstacle-newer-than-set`,
    /// `speed-too-high`, `coordinate-out-of-range`, `radius-not-positive`,
    /// `radius-too-large`, the polygon's [`PolygonDefect::rule`], `extent-too-large`,
    /// `duplicate-id`).
    pub const fn rule(&self) -> &'static str {
        match self {
            Self::TooManyObstacles { .. } => "too-many-obstacles",
            Self::SetStampInFuture { .. } => "set-stamp-in-future",
            Self::UnknownShape { .. } => "unknown-shape",
            Self::UnknownClass { .. } => "unknown-class",
            Self::VertexCount { .. } => "vertex-count",
            Self::NonFinite { .. } => "non-finite",
            Self::ObstacleStampInFuture { .. } => "obstacle-stamp-in-future",
            Self::ObstacleNewerThanSet { .. } => "obstacle-newer-than-set",
            Self::SpeedTooHigh { .. } => "speed-too-high",
            Self::CoordinateOutOfRange { .. } => "coordinate-out-of-range",
            Self::RadiusNotPositive { .. } => "radius-not-positive",
            Self::RadiusTooLarge { .. } => "radius-too-large",
            Self::BadPolygon { defect, .. } => defect.rule(),
            Self::ExtentTooLarge { .. } => "extent-too-large",
            Self::DuplicateId { .. } => "duplicate-id",
        }
    }

    /// The obstacle the rejection is about, as (index in the set, id); `None` for the
    /// rules about the set as a whole.
    pub const fn obstacle(&self) -> Option<(usize, u32)> {
        match *self {
            Self::TooManyObstacles { .. } | Self::SetStampInFuture { .. } => None,
            Self::UnknownShape { index, id, .. }
            | Self::UnknownClass { index, id, .. }
            | Self::VertexCount { index, id, .. }
            | Self::NonFinite { index, id, .. }
            | Self::ObstacleStampInFuture { index, id, .. }
            | Self::ObstacleNewerThanSet { index, id, .. }
            | Self::SpeedTooHigh { index, id, .. }
            | Self::CoordinateOutOfRange { index, id, .. }
            | Self::RadiusNotPositive { index, id, .. }
            | Self::RadiusTooLarge { index, id, .. }
            | Self::BadPolygon { index, id, .. }
            | Self::ExtentTooLarge { index, id, .. }
            | Self::DuplicateId { index, id, .. } => Some((index, id)),
        }
    }
}

/// Seconds from nanoseconds, for the texts.
fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl LiveObstacleValidator {
    /// A validator with these limits; each must be a positive finite number (a NaN or
    /// zero limit would silently reject, or accept, everything).
    pub fn new(
        max_future_s: f64,
        max_radius_m: f64,
        max_extent_m: f64,
        max_speed_mps: f64,
        max_abs_coord: f64,
    ) -> Result<Self, LiveValidatorSettingError> {
        for (field, value) in [
            ("max_future_s", max_future_s),
            ("max_radius_m", max_radius_m),
            ("max_extent_m", max_extent_m),
            ("max_speed_mps", max_speed_mps),
            ("max_abs_coord", max_abs_coord),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(LiveValidatorSettingError { field, value });
            }
        }
        Ok(Self {
            max_future_s,
            max_radius_m,
            max_extent_m,
            max_speed_mps,
            max_abs_coord,
        })
    }

    /// Checks `set` against the rules, with `now_ns` the reader's `CLOCK_MONOTONIC` now.
    ///
    /// The order is fixed, so the reason is deterministic when several rules apply: the
    /// set's `count`, then the set's stamp, then each obstacle in index order, and for each
    /// the first failing of: shape code, class code, vertex count (polygon), finite
    /// numbers (the ones read for its shape: a circle's centre, radius and velocity, a
    /// polygon's velocity and used vertices), its stamp against now, its stamp against the
    /// set's, speed, coordinates, then the circle's radius or the polygon's outline
    /// (repeated vertex, self-intersection, zero area, convexity) and extent, and last its
    /// id against the earlier obstacles'. An empty set is valid ("nothing seen").
    pub fn validate(&self, set: &LiveObstacleSet, now_ns: u64) -> Result<(), LiveSetRejection> {
        if set.count as usize > MAX_LIVE_OBSTACLES {
            return Err(LiveSetRejection::TooManyObstacles { count: set.count });
        }
        let max_future_ns = (self.max_future_s * 1e9) as u64;
        let ahead = set.timestamp_ns.saturating_sub(now_ns);
        if ahead > max_future_ns {
            return Err(LiveSetRejection::SetStampInFuture {
                ahead_s: secs(ahead),
                max_s: self.max_future_s,
            });
        }
        let obstacles = set.as_slice();
        for (index, o) in obstacles.iter().enumerate() {
            self.check_obstacle(index, o, set.timestamp_ns, now_ns, max_future_ns)?;
            if let Some(first_index) = obstacles[..index].iter().position(|p| p.id == o.id) {
                return Err(LiveSetRejection::DuplicateId {
                    index,
                    id: o.id,
                    first_index,
                });
            }
        }
        Ok(())
    }

    /// The rules about one obstacle, in [`LiveObstacleValidator::validate`]'s order, up to
    /// (not including) the duplicate id.
    fn check_obstacle(
        &self,
        index: usize,
        o: &LiveObstacle,
        set_ns: u64,
        now_ns: u64,
        max_future_ns: u64,
    ) -> Result<(), LiveSetRejection> {
        let id = o.id;
        let shape = o
            .shape()
            .map_err(|code| LiveSetRejection::UnknownShape { index, id, code })?;
        o.class()
            .map_err(|code| LiveSetRejection::UnknownClass { index, id, code })?;
        if shape == ObstacleShape::Polygon
            && !(3..=MAX_POLYGON_VERTICES as u32).contains(&o.vertex_count)
        {
            return Err(LiveSetRejection::VertexCount {
                index,
                id,
                count: o.vertex_count,
            });
        }
        // The numbers this shape reads, with their names: (field, value, is a coordinate).
        let mut numbers = [(Field::X, 0.0, false); 3 + 2 * MAX_POLYGON_VERTICES];
        let mut n = 0;
        let mut add = |field, value, coordinate| {
            numbers[n] = (field, value, coordinate);
            n += 1;
        };
        add(Field::Vx, o.vx, false);
        add(Field::Vy, o.vy, false);
        match shape {
            ObstacleShape::Circle => {
                add(Field::X, o.x, true);
                add(Field::Y, o.y, true);
                add(Field::Radius, o.radius, false);
            }
            ObstacleShape::Polygon => {
                for (k, v) in o.vertices().iter().enumerate() {
                    add(Field::VertexX(k), v[0], true);
                    add(Field::VertexY(k), v[1], true);
                }
            }
        }
        let numbers = &numbers[..n];
        if let Some(&(field, value, _)) = numbers.iter().find(|(_, v, _)| !v.is_finite()) {
            return Err(LiveSetRejection::NonFinite {
                index,
                id,
                field,
                value,
            });
        }
        let ahead = o.timestamp_ns.saturating_sub(now_ns);
        if ahead > max_future_ns {
            return Err(LiveSetRejection::ObstacleStampInFuture {
                index,
                id,
                ahead_s: secs(ahead),
                max_s: self.max_future_s,
            });
        }
        let after = o.timestamp_ns.saturating_sub(set_ns);
        if after > max_future_ns {
            return Err(LiveSetRejection::ObstacleNewerThanSet {
                index,
                id,
                after_s: secs(after),
                max_s: self.max_future_s,
            });
        }
        let speed = o.vx.hypot(o.vy);
        if speed > self.max_speed_mps {
            return Err(LiveSetRejection::SpeedTooHigh {
                index,
                id,
                speed,
                max: self.max_speed_mps,
            });
        }
        let far = numbers
            .iter()
            .find(|(_, v, coordinate)| *coordinate && v.abs() > self.max_abs_coord);
        if let Some(&(field, value, _)) = far {
            return Err(LiveSetRejection::CoordinateOutOfRange {
                index,
                id,
                field,
                value,
                max: self.max_abs_coord,
            });
        }
        match shape {
            ObstacleShape::Circle if o.radius <= 0.0 => Err(LiveSetRejection::RadiusNotPositive {
                index,
                id,
                radius: o.radius,
            }),
            ObstacleShape::Circle if o.radius > self.max_radius_m => {
                Err(LiveSetRejection::RadiusTooLarge {
                    index,
                    id,
                    radius: o.radius,
                    max: self.max_radius_m,
                })
            }
            ObstacleShape::Circle => Ok(()),
            ObstacleShape::Polygon => {
                let vertices = o.vertices();
                polygon_defect(vertices).map_or(Ok(()), |defect| {
                    Err(LiveSetRejection::BadPolygon { index, id, defect })
                })?;
                let extent = extent(vertices);
                if extent > self.max_extent_m {
                    return Err(LiveSetRejection::ExtentTooLarge {
                        index,
                        id,
                        extent,
                        max: self.max_extent_m,
                    });
                }
                Ok(())
            }
        }
    }
}

/// (b − a) × (c − a): positive when a → b → c turns counter-clockwise.
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// True if `p`, known to be collinear with segment a–b, lies on it (ends included).
fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// True if the closed segments p1–p2 and q1–q2 share a point (crossing, touching or
/// overlapping). The same test as `control`'s site geometry (`segments_intersect`): kept
/// here because this client library must not depend on the controller's crate.
fn segments_meet(p1: [f64; 2], p2: [f64; 2], q1: [f64; 2], q2: [f64; 2]) -> bool {
    let d1 = orient(q1, q2, p1);
    let d2 = orient(q1, q2, p2);
    let d3 = orient(p1, p2, q1);
    let d4 = orient(p1, p2, q2);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(q1, q2, p1))
        || (d2 == 0.0 && on_segment(q1, q2, p2))
        || (d3 == 0.0 && on_segment(p1, p2, q1))
        || (d4 == 0.0 && on_segment(p1, p2, q2))
}

/// Twice the signed area (shoelace), positive counter-clockwise.
fn twice_signed_area(v: &[[f64; 2]]) -> f64 {
    let n = v.len();
    (0..n)
        .map(|i| {
            let (a, b) = (v[i], v[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum()
}

/// The largest distance between two vertices \[m\].
fn extent(v: &[[f64; 2]]) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in v.iter().enumerate() {
        for b in &v[i + 1..] {
            d = d.max((a[0] - b[0]).hypot(a[1] - b[1]));
        }
    }
    d
}

/// What keeps `v` (3 to 8 finite vertices, in order) from being a simple convex polygon
/// with an inside, if anything. Either winding is accepted. A polygon with no two
/// non-adjacent edges meeting is simple; a simple polygon whose every turn goes the way
/// of its winding is convex (collinear vertices are accepted: the outline stays convex).
/// Checked in this order: a repeated vertex, a self-intersection, zero area, a reflex
/// vertex, so a bow tie reads "crosses itself" and not "not convex".
pub fn polygon_defect(v: &[[f64; 2]]) -> Option<PolygonDefect> {
    let n = v.len();
    let next = |i: usize| (i + 1) % n;
    if let Some(vertex) = (0..n).find(|&i| v[i] == v[next(i)]) {
        return Some(PolygonDefect::RepeatedVertex { vertex });
    }
    for a in 0..n {
        // Edges a and b share a vertex when b = a + 1, or a = 0 and b = n − 1.
        for b in a + 2..n {
            if a == 0 && b == n - 1 {
                continue;
            }
            if segments_meet(v[a], v[next(a)], v[b], v[next(b)]) {
                return Some(PolygonDefect::SelfIntersecting {
                    edge_a: a,
                    edge_b: b,
                });
            }
        }
    }
    let area = 0.5 * twice_signed_area(v);
    if area.abs() < MIN_POLYGON_AREA {
        return Some(PolygonDefect::ZeroArea { area });
    }
    let counter_clockwise = area > 0.0;
    for k in 0..n {
        let prev = v[(k + n - 1) % n];
        let (here, after) = (v[k], v[next(k)]);
        let turn = orient(prev, here, after);
        // Rounding can make a straight vertex turn by a hair either way: a turn counts
        // as reflex only beyond 1e-12 of the two edges' lengths' product.
        let scale = (here[0] - prev[0]).hypot(here[1] - prev[1])
            * (after[0] - here[0]).hypot(after[1] - here[1]);
        let against = if counter_clockwise { -turn } else { turn };
        if against > 1e-12 * scale {
            return Some(PolygonDefect::NotConvex {
                vertex: k,
                counter_clockwise,
            });
        }
    }
    None
}
