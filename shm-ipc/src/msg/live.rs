//! The live-obstacle wire types (DESIGN §18): what perception publishes on
//! `{prefix}/v2/obstacles`. Plain old data like the rest of [`super`]; the layout is frozen
//! by the assertions at the bottom (documented in the crate root).

use core::mem::{align_of, offset_of, size_of};

use iceoryx2::prelude::ZeroCopySend;

/// Capacity of a [`LiveObstacleSet`]: at most this many live obstacles per set (DESIGN §18).
pub const MAX_LIVE_OBSTACLES: usize = 128;
/// Capacity of a live polygon: at most this many vertices ([`LiveObstacle::vertices`]).
pub const MAX_POLYGON_VERTICES: usize = 8;

/// The outline of a [`LiveObstacle`]. Sent on the wire as a `u32` ([`LiveObstacle::shape`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ObstacleShape {
    /// A circle: centre ([`LiveObstacle::x`], [`LiveObstacle::y`]) and
    /// [`LiveObstacle::radius`].
    Circle = 0,
    /// A convex polygon: the first [`LiveObstacle::vertex_count`] entries of
    /// [`LiveObstacle::vertices`], either winding.
    Polygon = 1,
}

impl ObstacleShape {
    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The shape's name as used in texts and the CLI (`circle`, `polygon`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Circle => "circle",
            Self::Polygon => "polygon",
        }
    }
}

impl TryFrom<u32> for ObstacleShape {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        match v {
            0 => Ok(Self::Circle),
            1 => Ok(Self::Polygon),
            other => Err(other),
        }
    }
}

/// What perception thinks a [`LiveObstacle`] is. Sent on the wire as a `u32`
/// ([`LiveObstacle::class`]). The daemon may keep more distance from people than from
/// things; an unsure perception sends [`ObstacleClass::Unknown`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ObstacleClass {
    /// Not classified.
    Unknown = 0,
    /// A person.
    Person = 1,
    /// A road vehicle (truck, car).
    Vehicle = 2,
    /// Another machine (loader, excavator, dozer).
    Machine = 3,
    /// Something static or anything else (a pile, a barrier) seen by perception.
    Static = 4,
}

impl ObstacleClass {
    /// Every class, in code order.
    pub const ALL: [Self; 5] = [
        Self::Unknown,
        Self::Person,
        Self::Vehicle,
        Self::Machine,
        Self::Static,
    ];

    /// The wire code.
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The class's name as used in texts and the CLI (`unknown`, `person`, `vehicle`,
    /// `machine`, `static`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Unknown => "unknown",
            Self::Person => "person",
            Self::Vehicle => "vehicle",
            Self::Machine => "machine",
            Self::Static => "static",
        }
    }

    /// The class of a [`ObstacleClass::name`], if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

impl TryFrom<u32> for ObstacleClass {
    type Error = u32;
    /// Decodes a wire code; the unknown code is returned as the error.
    fn try_from(v: u32) -> Result<Self, u32> {
        Self::ALL.get(v as usize).copied().ok_or(v)
    }
}

/// A live obstacle could not be built or added to a set (the wire format cannot carry it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LiveObstacleError {
    /// A polygon needs 3 to [`MAX_POLYGON_VERTICES`] vertices.
    #[error("a live polygon has 3 to {MAX_POLYGON_VERTICES} vertices, {0} given")]
    VertexCount(usize),
    /// The set already holds [`MAX_LIVE_OBSTACLES`] obstacles.
    #[error("a live obstacle set holds at most {MAX_LIVE_OBSTACLES} obstacles")]
    SetFull,
}

/// One live (moving or moveable) obstacle seen by perception (DESIGN §18): a circle or a
/// convex polygon in the world frame, with an id, a class, a velocity and the time it was
/// observed. 192 bytes, alignment 8.
///
/// Shapes are **physical** outlines: the daemon adds the machine's own outline (unlike
/// the circles of a [`super::GoalRequest`], whose radius includes the machine's half-width).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::LiveObstacle")]
pub struct LiveObstacle {
    /// Perception's track id; unique within a set (the same thing keeps its id from set
    /// to set, so the daemon can follow it).
    pub id: u32,
    /// An [`ObstacleShape`] code: 0 circle, 1 convex polygon.
    pub shape: u32,
    /// An [`ObstacleClass`] code: 0 unknown, 1 person, 2 vehicle, 3 machine, 4 static.
    pub class: u32,
    /// Polygon: the number of valid entries at the front of `vertices` (3..=8). Circle: 0.
    pub vertex_count: u32,
    /// When this obstacle was observed, nanoseconds of `CLOCK_MONOTONIC` (like
    /// [`PoseEstimate::timestamp_ns`]); at or before the set's stamp.
    pub timestamp_ns: u64,
    /// Circle centre x \[m\], world frame (polygon: ignored, send 0).
    pub x: f64,
    /// Circle centre y \[m\], world frame (polygon: ignored, send 0).
    pub y: f64,
    /// Circle radius \[m\]: the physical radius, not inflated by the machine (polygon:
    /// ignored, send 0).
    pub radius: f64,
    /// Velocity x \[m/s\], world frame.
    pub vx: f64,
    /// Velocity y \[m/s\], world frame.
    pub vy: f64,
    /// Polygon vertices (x, y) \[m\], world frame, in order around the outline (either
    /// winding); the first `vertex_count` are used, send zeros in the rest.
    pub vertices: [[f64; 2]; MAX_POLYGON_VERTICES],
}

impl LiveObstacle {
    /// All zeros: a circle of radius 0 (invalid until filled in).
    pub const ZERO: Self = Self {
        id: 0,
        shape: ObstacleShape::Circle as u32,
        class: ObstacleClass::Unknown as u32,
        vertex_count: 0,
        timestamp_ns: 0,
        x: 0.0,
        y: 0.0,
        radius: 0.0,
        vx: 0.0,
        vy: 0.0,
        vertices: [[0.0; 2]; MAX_POLYGON_VERTICES],
    };

    /// A circle of physical `radius` \[m\] centred at `centre` \[m\], moving at `velocity`
    /// \[m/s\], observed at `stamp_ns` (`CLOCK_MONOTONIC`).
    pub const fn circle(
        id: u32,
        class: ObstacleClass,
        centre: [f64; 2],
        radius: f64,
        velocity: [f64; 2],
        stamp_ns: u64,
    ) -> Self {
        Self {
            id,
            class: class.code(),
            timestamp_ns: stamp_ns,
            x: centre[0],
            y: centre[1],
            radius,
            vx: velocity[0],
            vy: velocity[1],
            ..Self::ZERO
        }
    }

    /// A convex polygon with `vertices` \[m\] in order around its outline (either winding),
    /// moving at `velocity` \[m/s\], observed at `stamp_ns`. Fails unless 3 to
    /// [`MAX_POLYGON_VERTICES`] vertices are given; convexity is the validator's
    /// ([`crate::LiveObstacleValidator`]).
    pub fn polygon(
        id: u32,
        class: ObstacleClass,
        vertices: &[[f64; 2]],
        velocity: [f64; 2],
        stamp_ns: u64,
    ) -> Result<Self, LiveObstacleError> {
        if !(3..=MAX_POLYGON_VERTICES).contains(&vertices.len()) {
            return Err(LiveObstacleError::VertexCount(vertices.len()));
        }
        let mut o = Self {
            id,
            shape: ObstacleShape::Polygon.code(),
            class: class.code(),
            vertex_count: vertices.len() as u32,
            timestamp_ns: stamp_ns,
            vx: velocity[0],
            vy: velocity[1],
            ..Self::ZERO
        };
        o.vertices[..vertices.len()].copy_from_slice(vertices);
        Ok(o)
    }

    /// The decoded shape, or the unknown wire code.
    pub fn shape(&self) -> Result<ObstacleShape, u32> {
        ObstacleShape::try_from(self.shape)
    }

    /// The decoded class, or the unknown wire code.
    pub fn class(&self) -> Result<ObstacleClass, u32> {
        ObstacleClass::try_from(self.class)
    }

    /// The polygon's valid vertices (`vertex_count` clamped to [`MAX_POLYGON_VERTICES`], so
    /// a corrupt count cannot make this panic); empty for a circle.
    pub fn vertices(&self) -> &[[f64; 2]] {
        &self.vertices[..(self.vertex_count as usize).min(MAX_POLYGON_VERTICES)]
    }

    /// The velocity (vx, vy) \[m/s\].
    pub const fn velocity(&self) -> [f64; 2] {
        [self.vx, self.vy]
    }
}

impl Default for LiveObstacle {
    fn default() -> Self {
        Self::ZERO
    }
}

/// Published on `{prefix}/v2/obstacles` by perception (one publisher): the current set of
/// live obstacles, replacing the previous set as a whole (an obstacle missing from the
/// newest set is gone). 24 592 bytes, alignment 8.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("wlnav::v2::LiveObstacleSet")]
pub struct LiveObstacleSet {
    /// The set's measurement time, nanoseconds of `CLOCK_MONOTONIC`: the daemon judges the
    /// set's freshness on it (DESIGN §18).
    pub timestamp_ns: u64,
    /// Publisher's sequence counter (wraps); lets a reader notice dropped sets.
    pub sequence: u32,
    /// Number of valid entries at the front of `obstacles` (≤ 128; a larger count is
    /// rejected, never trusted).
    pub count: u32,
    /// The obstacles; entries at index ≥ `count` are ignored (send zeros).
    pub obstacles: [LiveObstacle; MAX_LIVE_OBSTACLES],
}

impl LiveObstacleSet {
    /// All zeros: an empty set stamped 0.
    pub const ZERO: Self = Self {
        timestamp_ns: 0,
        sequence: 0,
        count: 0,
        obstacles: [LiveObstacle::ZERO; MAX_LIVE_OBSTACLES],
    };

    /// An empty set measured at `timestamp_ns` with publisher counter `sequence`. An empty
    /// set is a real message: "nothing is there" (and keeps the daemon's freshness check
    /// satisfied).
    pub const fn empty(timestamp_ns: u64, sequence: u32) -> Self {
        Self {
            timestamp_ns,
            sequence,
            ..Self::ZERO
        }
    }

    /// Appends `obstacle`; fails when the set holds [`MAX_LIVE_OBSTACLES`] already (or its
    /// `count` is corrupt, beyond the capacity).
    pub fn push(&mut self, obstacle: LiveObstacle) -> Result<(), LiveObstacleError> {
        let slot = self
            .obstacles
            .get_mut(self.count as usize)
            .ok_or(LiveObstacleError::SetFull)?;
        *slot = obstacle;
        self.count += 1;
        Ok(())
    }

    /// The valid obstacles (`count` clamped to [`MAX_LIVE_OBSTACLES`]: a count from shared
    /// memory is never trusted, so this cannot panic; the validator rejects such a set).
    pub fn as_slice(&self) -> &[LiveObstacle] {
        &self.obstacles[..(self.count as usize).min(MAX_LIVE_OBSTACLES)]
    }
}

impl Default for LiveObstacleSet {
    fn default() -> Self {
        Self::ZERO
    }
}

// Layout freeze (see `super`): a changed number is a changed wire format.

const _: () = assert!(size_of::<LiveObstacle>() == 192 && align_of::<LiveObstacle>() == 8);
const _: () = assert!(offset_of!(LiveObstacle, id) == 0);
const _: () = assert!(offset_of!(LiveObstacle, shape) == 4);
const _: () = assert!(offset_of!(LiveObstacle, class) == 8);
const _: () = assert!(offset_of!(LiveObstacle, vertex_count) == 12);
const _: () = assert!(offset_of!(LiveObstacle, timestamp_ns) == 16);
const _: () = assert!(offset_of!(LiveObstacle, x) == 24);
const _: () = assert!(offset_of!(LiveObstacle, y) == 32);
const _: () = assert!(offset_of!(LiveObstacle, radius) == 40);
const _: () = assert!(offset_of!(LiveObstacle, vx) == 48);
const _: () = assert!(offset_of!(LiveObstacle, vy) == 56);
const _: () = assert!(offset_of!(LiveObstacle, vertices) == 64);

const _: () = assert!(size_of::<LiveObstacleSet>() == 24592 && align_of::<LiveObstacleSet>() == 8);
const _: () = assert!(offset_of!(LiveObstacleSet, timestamp_ns) == 0);
const _: () = assert!(offset_of!(LiveObstacleSet, sequence) == 8);
const _: () = assert!(offset_of!(LiveObstacleSet, count) == 12);
const _: () = assert!(offset_of!(LiveObstacleSet, obstacles) == 16);
