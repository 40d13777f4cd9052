//! Live obstacles: what perception sees move (DESIGN §18, issue 41).
//!
//! A [`LiveSet`] is the newest set perception published: circles and convex
//! polygons, each with an id, a class, a velocity and the time it was seen.
//! Nothing here trusts it to be current: every obstacle is predicted along
//! its velocity from its own stamp to the time asked about
//! ([`LiveObstacle::clearance_at`]), its reach grown by
//! [`LiveSettings::speed_uncertainty`] per second of prediction (a person
//! who changes pace or turns), and a set older than
//! [`LiveSettings::max_age`] is stale ([`Freshness`]).
//!
//! The safety envelope checks its predicted motion against these predictions
//! ([`crate::envelope`]); [`slow_factor`] scales the speed down as the
//! MPC's plan nears one (the slow-down field); the pilot holds after a
//! protective stop until the way has been clear for
//! [`LiveSettings::resume_wait`].
//!
//! # The fields in the form of ISO 13855
//!
//! Head-on, a machine at speed v and an obstacle closing at speed u, the
//! envelope stops the machine when the distance from where the obstacle was
//! seen to the machine's outline is at most
//!
//! ```text
//! S_stop = v·T + v²/(2·a_max) + (u + σ_u)·(T + T_age + T_brake) + C_stop + m
//! T      = T_react + d + T_lag
//! ```
//!
//! T_react: the time until the stop is sent (one tick at most; 0 when the
//! set's arrival triggers the check); d: the actuator delay compensated;
//! T_lag: the envelope's `response_lag` (T: the machine goes on at v, then
//! brakes at a_max); T_age: how old the obstacle's stamp is (perception
//! latency + the set's age; the obstacle moves on meanwhile); T_brake: how
//! long the envelope follows the machine once its stop acts
//! ([`crate::envelope::braking_time`]: the longest braking from the
//! bounds plus the model's ramp; the obstacle closes in all along); σ_u: [`LiveSettings::speed_uncertainty`];
//! C_stop: [`LiveSettings::stop_margin`]; m: the envelope's margin of the
//! outline circle. The envelope does not use this formula: it predicts the
//! machine's motion (the command, then the stop at the limits, over every
//! response lag) and each obstacle's along its velocity, and stops when they
//! come within C_stop + m + σ_u·(t − stamp) at any time t; [`stop_distance`]
//! is the formula for documentation, and a test checks the envelope against
//! it. The slow-down field is the time to collision along the MPC's plan
//! ([`slow_factor`]): below [`LiveSettings::slow_time`] the speed is scaled by
//! τ / T_slow, which settles at v = D / T_slow at distance D from a standing
//! obstacle (S_slow = v·T_slow + C_stop + m).

use serde::{Deserialize, Serialize};

use crate::model::{MachineParams, State};
use crate::site::geometry::{ring_nearest, signed_area2, winding, P2};

/// Most obstacles a set holds (the wire's capacity).
pub const MAX_LIVE_OBSTACLES: usize = 128;
/// Most vertices of a live obstacle's polygon.
pub const MAX_POLYGON_VERTICES: usize = 8;

/// What perception says an obstacle is (unknown when it does not say).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LiveClass {
    #[default]
    Unknown,
    Person,
    Vehicle,
    Machine,
    Static,
}

impl LiveClass {
    pub fn name(self) -> &'static str {
        match self {
            LiveClass::Unknown => "unknown",
            LiveClass::Person => "person",
            LiveClass::Vehicle => "vehicle",
            LiveClass::Machine => "machine",
            LiveClass::Static => "static",
        }
    }
}

/// A live obstacle's shape where it was seen (its stamp).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LiveShape {
    /// A disc: centre and physical radius [m].
    Circle { center: P2, radius: f64 },
    /// A convex polygon: the first `len` of `ring` (either winding).
    Polygon {
        ring: [P2; MAX_POLYGON_VERTICES],
        len: usize,
        winding: f64,
    },
}

impl LiveShape {
    /// A convex polygon of 3 to [`MAX_POLYGON_VERTICES`] vertices with an
    /// area.
    pub fn polygon(vertices: &[P2]) -> Result<Self, LiveError> {
        let n = vertices.len();
        if !(3..=MAX_POLYGON_VERTICES).contains(&n) {
            return Err(LiveError::Vertices(n));
        }
        let mut ring = [[0.0; 2]; MAX_POLYGON_VERTICES];
        ring[..n].copy_from_slice(vertices);
        if ring[..n].iter().flatten().any(|v| !v.is_finite()) {
            return Err(LiveError::NotFinite("polygon vertex"));
        }
        if signed_area2(&ring[..n]).abs() < 1e-9 {
            return Err(LiveError::NoArea);
        }
        // Convex: every turn the same way (collinear vertices allowed).
        let w = winding(&ring[..n]);
        let turns_one_way = (0..n).all(|i| {
            let (a, b, c) = (ring[i], ring[(i + 1) % n], ring[(i + 2) % n]);
            let turn = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]);
            w * turn >= -1e-12
        });
        if !turns_one_way {
            return Err(LiveError::NotConvex);
        }
        Ok(LiveShape::Polygon {
            ring,
            len: n,
            winding: w,
        })
    }

    /// A disc of positive, finite radius.
    pub fn circle(center: P2, radius: f64) -> Result<Self, LiveError> {
        if !(center[0].is_finite() && center[1].is_finite()) {
            return Err(LiveError::NotFinite("circle centre"));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(LiveError::Radius(radius));
        }
        Ok(LiveShape::Circle { center, radius })
    }

    /// Signed distance of `p` (negative inside) [m].
    pub fn signed_distance(&self, p: P2) -> f64 {
        match self {
            LiveShape::Circle { center, radius } => {
                (p[0] - center[0]).hypot(p[1] - center[1]) - radius
            }
            LiveShape::Polygon { ring, len, winding } => {
                ring_nearest(p, &ring[..*len], *winding).distance
            }
        }
    }

    /// Signed distance of `p` and its unit gradient (away from the shape
    /// outside; at a circle's centre, +x).
    pub fn nearest(&self, p: P2) -> (f64, P2) {
        match self {
            LiveShape::Circle { center, radius } => {
                let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
                let d = dx.hypot(dy);
                let n = if d > 1e-9 {
                    [dx / d, dy / d]
                } else {
                    [1.0, 0.0]
                };
                (d - radius, n)
            }
            LiveShape::Polygon { ring, len, winding } => {
                let near = ring_nearest(p, &ring[..*len], *winding);
                (near.distance, near.normal)
            }
        }
    }

    /// A disc holding the shape: (centre, radius).
    pub fn bounding_circle(&self) -> (P2, f64) {
        match *self {
            LiveShape::Circle { center, radius } => (center, radius),
            LiveShape::Polygon { ring, len, .. } => {
                let ring = &ring[..len];
                let c = ring
                    .iter()
                    .fold([0.0, 0.0], |s, v| [s[0] + v[0], s[1] + v[1]]);
                let c = [c[0] / len as f64, c[1] / len as f64];
                let r = ring
                    .iter()
                    .map(|v| (v[0] - c[0]).hypot(v[1] - c[1]))
                    .fold(0.0, f64::max);
                (c, r)
            }
        }
    }
}

/// One obstacle perception sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveObstacle {
    /// Perception's id: the same thing keeps its id from set to set.
    pub id: u32,
    pub class: LiveClass,
    /// Where it was at `stamp`.
    pub shape: LiveShape,
    /// Its velocity [m/s], world frame.
    pub velocity: P2,
    /// When it was seen [s, the pilot's clock].
    pub stamp: f64,
}

impl LiveObstacle {
    /// A person, vehicle, … of `shape` moving at `velocity`, seen at `stamp`.
    pub fn new(
        id: u32,
        class: LiveClass,
        shape: LiveShape,
        velocity: P2,
        stamp: f64,
    ) -> Result<Self, LiveError> {
        if !(velocity[0].is_finite() && velocity[1].is_finite()) {
            return Err(LiveError::NotFinite("velocity"));
        }
        if !stamp.is_finite() {
            return Err(LiveError::NotFinite("stamp"));
        }
        Ok(Self {
            id,
            class,
            shape,
            velocity,
            stamp,
        })
    }

    /// Clearance of a disc (centre `c`, radius `r`) at time `t` to this
    /// obstacle moved along its velocity from its stamp.
    #[inline]
    pub fn clearance_at(&self, c: P2, r: f64, t: f64) -> f64 {
        self.shape.signed_distance(self.relative(c, t)) - r
    }

    /// The point `c` of the obstacle as seen at its stamp, moved along its
    /// velocity to time `t`.
    #[inline]
    pub fn moved(&self, c: P2, t: f64) -> P2 {
        let dt = t - self.stamp;
        [c[0] + self.velocity[0] * dt, c[1] + self.velocity[1] * dt]
    }

    /// Where the point `c` is at time `t` relative to the obstacle seen at
    /// its stamp: `c` moved back along the obstacle's velocity.
    #[inline]
    pub fn relative(&self, c: P2, t: f64) -> P2 {
        let dt = t - self.stamp;
        [c[0] - self.velocity[0] * dt, c[1] - self.velocity[1] * dt]
    }

    /// Its speed [m/s].
    pub fn speed(&self) -> f64 {
        self.velocity[0].hypot(self.velocity[1])
    }
}

/// Why a live obstacle or set is not taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LiveError {
    #[error("{0} is not finite")]
    NotFinite(&'static str),
    #[error("radius {0} m is not positive and finite")]
    Radius(f64),
    #[error("a polygon needs 3 to {MAX_POLYGON_VERTICES} vertices (got {0})")]
    Vertices(usize),
    #[error("the polygon has no area")]
    NoArea,
    #[error("the polygon is not convex")]
    NotConvex,
    #[error("{0} obstacles in one set, at most {MAX_LIVE_OBSTACLES}")]
    TooMany(usize),
}

/// The newest set perception published. Allocation-free after
/// [`LiveSet::new`].
#[derive(Debug)]
pub struct LiveSet {
    /// When the set was measured [s]; `None` before the first.
    stamp: Option<f64>,
    obstacles: Vec<LiveObstacle>,
}

impl Default for LiveSet {
    fn default() -> Self {
        Self::new()
    }
}

impl Clone for LiveSet {
    fn clone(&self) -> Self {
        let mut c = Self::new();
        c.copy_from(self);
        c
    }
}

impl LiveSet {
    /// No set yet, room for [`MAX_LIVE_OBSTACLES`].
    pub fn new() -> Self {
        Self {
            stamp: None,
            obstacles: Vec::with_capacity(MAX_LIVE_OBSTACLES),
        }
    }

    /// Becomes the set measured at `stamp` holding `obstacles`.
    pub fn set(&mut self, stamp: f64, obstacles: &[LiveObstacle]) -> Result<(), LiveError> {
        if obstacles.len() > MAX_LIVE_OBSTACLES {
            return Err(LiveError::TooMany(obstacles.len()));
        }
        if !stamp.is_finite() {
            return Err(LiveError::NotFinite("set stamp"));
        }
        self.stamp = Some(stamp);
        self.obstacles.clear();
        self.obstacles.extend_from_slice(obstacles);
        Ok(())
    }

    /// Starts the set measured at `stamp`, empty: fill it with
    /// [`Self::push`] (a set converted obstacle by obstacle, no allocation).
    pub fn start(&mut self, stamp: f64) -> Result<(), LiveError> {
        if !stamp.is_finite() {
            return Err(LiveError::NotFinite("set stamp"));
        }
        self.stamp = Some(stamp);
        self.obstacles.clear();
        Ok(())
    }

    /// Adds an obstacle to the set [`Self::start`]ed.
    pub fn push(&mut self, o: LiveObstacle) -> Result<(), LiveError> {
        if self.obstacles.len() == MAX_LIVE_OBSTACLES {
            return Err(LiveError::TooMany(MAX_LIVE_OBSTACLES + 1));
        }
        self.obstacles.push(o);
        Ok(())
    }

    /// Becomes `other` (no allocation).
    pub fn copy_from(&mut self, other: &LiveSet) {
        self.stamp = other.stamp;
        self.obstacles.clear();
        self.obstacles.extend_from_slice(&other.obstacles);
    }

    /// Forgets every set.
    pub fn clear(&mut self) {
        self.stamp = None;
        self.obstacles.clear();
    }

    pub fn stamp(&self) -> Option<f64> {
        self.stamp
    }

    pub fn obstacles(&self) -> &[LiveObstacle] {
        &self.obstacles
    }

    pub fn is_empty(&self) -> bool {
        self.obstacles.is_empty()
    }
}

/// How the machine treats live obstacles (`[live]` in the daemon's
/// configuration). `Default` gives the values below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiveSettings {
    /// Perception must be fresh for the machine to move (default true). A
    /// site without perception declares it not required.
    pub required: bool,
    /// Largest age of the newest set while the machine moves [s] (default
    /// 0.5: five periods of a 10 Hz perception).
    pub max_age: f64,
    /// Clearance kept to a live obstacle beyond the envelope's margins [m]
    /// (C_stop, default 0.5).
    pub stop_margin: f64,
    /// How fast an obstacle may leave its straight line [m/s]: its reach
    /// grows by this per second of prediction (default 0.5).
    pub speed_uncertainty: f64,
    /// Time to collision along the plan below which the speed is scaled
    /// down [s] (T_slow, default 2: Nav2's collision monitor's approach).
    pub slow_time: f64,
    /// After a protective stop, the way must be clear this long before the
    /// goal resumes [s] (default 1).
    pub resume_wait: f64,
    /// After staleness, fresh sets must arrive for this long before the
    /// machine moves again [s] (default 0.5).
    pub recover_span: f64,
    /// Waiting for live obstacles (a protective hold, or slowed by their
    /// slow-down field) longer than this ends the goal `no-progress` [s]
    /// (default 30). While it lasts, the goal's progress windows are
    /// paused: a person crossing is no stall.
    pub max_hold: f64,
    /// A live obstacle standing in the way (slower than
    /// [`STANDING_SPEED`]) that has kept the machine waiting this long is
    /// planned around: the route is planned again with it as a circle
    /// [s] (default 10: a truck being loaded stays minutes, a person
    /// stepping aside seconds, and a detour that is not needed costs more
    /// than the wait).
    pub replan_after: f64,
}

impl Default for LiveSettings {
    fn default() -> Self {
        Self {
            required: true,
            max_age: 0.5,
            stop_margin: 0.5,
            speed_uncertainty: 0.5,
            slow_time: 2.0,
            resume_wait: 1.0,
            recover_span: 0.5,
            max_hold: 30.0,
            replan_after: 10.0,
        }
    }
}

/// A bad live setting.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("live setting `{name}` {requirement} (got {value})")]
pub struct LiveSettingsError {
    pub name: &'static str,
    pub requirement: &'static str,
    pub value: f64,
}

impl LiveSettings {
    /// Every value finite, ≥ 0, at most 10 s or m; `max_age` and
    /// `slow_time` > 0; `max_hold` and `replan_after` in (0, 600] s.
    pub fn validate(&self) -> Result<(), LiveSettingsError> {
        for (name, value) in [
            ("stop_margin", self.stop_margin),
            ("speed_uncertainty", self.speed_uncertainty),
            ("resume_wait", self.resume_wait),
            ("recover_span", self.recover_span),
        ] {
            if !(value.is_finite() && (0.0..=10.0).contains(&value)) {
                return Err(LiveSettingsError {
                    name,
                    requirement: "must be in [0, 10]",
                    value,
                });
            }
        }
        for (name, value) in [("max_age", self.max_age), ("slow_time", self.slow_time)] {
            if !(value > 0.0 && value <= 10.0) {
                return Err(LiveSettingsError {
                    name,
                    requirement: "must be in (0, 10] s",
                    value,
                });
            }
        }
        for (name, value) in [
            ("max_hold", self.max_hold),
            ("replan_after", self.replan_after),
        ] {
            if !(value > 0.0 && value <= 600.0) {
                return Err(LiveSettingsError {
                    name,
                    requirement: "must be in (0, 600] s",
                    value,
                });
            }
        }
        Ok(())
    }

    /// How much an obstacle's clearance is reduced when predicted `ahead`
    /// seconds past its stamp: C_stop + σ_u·ahead.
    #[inline]
    pub fn reach(&self, ahead: f64) -> f64 {
        self.stop_margin + self.speed_uncertainty * ahead.max(0.0)
    }
}

/// Slower than this [m/s], a live obstacle stands: one that keeps the
/// machine waiting is planned around ([`LiveSettings::replan_after`]).
pub const STANDING_SPEED: f64 = 0.2;

/// The head-on stop distance S_stop of the module docs [m]: machine speed
/// `v`, obstacle closing at `u`, `response` = T_react + d + T_lag (from now
/// until the machine brakes), `age` = T_age, `brake` = T_brake, `margin` =
/// m.
#[allow(clippy::too_many_arguments)]
pub fn stop_distance(
    p: &MachineParams,
    s: &LiveSettings,
    v: f64,
    u: f64,
    response: f64,
    age: f64,
    brake: f64,
    margin: f64,
) -> f64 {
    v * response
        + v * v / (2.0 * p.a_max)
        + (u + s.speed_uncertainty) * (response + age + brake)
        + s.stop_margin
        + margin
}

/// Farther than this [m] from where the previous set predicted it (plus
/// [`LiveSettings::speed_uncertainty`] per second between the two), an
/// obstacle of the same id has jumped.
pub const JUMP_TOLERANCE: f64 = 1.0;

/// Whether an obstacle of `new` is farther from where `old` predicts it (the
/// same id, moved along its velocity to `new`'s stamp) than
/// [`JUMP_TOLERANCE`] plus the speed uncertainty over the time between: a
/// track that teleported (perception re-initialised, a glitch). Obstacles
/// new or gone are no jump.
pub fn jumped(old: &LiveSet, new: &LiveSet, s: &LiveSettings) -> bool {
    let (Some(t0), Some(t1)) = (old.stamp(), new.stamp()) else {
        return false;
    };
    let allowed = JUMP_TOLERANCE + s.speed_uncertainty * (t1 - t0).abs();
    new.obstacles().iter().any(|n| {
        old.obstacles()
            .iter()
            .find(|o| o.id == n.id)
            .is_some_and(|o| {
                let (c, _) = n.shape.bounding_circle();
                let (p, _) = o.shape.bounding_circle();
                let dt = n.stamp - o.stamp;
                let predicted = [p[0] + o.velocity[0] * dt, p[1] + o.velocity[1] * dt];
                (c[0] - predicted[0]).hypot(c[1] - predicted[1]) > allowed
            })
    })
}

/// Whether the newest set is fresh enough for the machine to move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FreshnessState {
    Fresh,
    /// Too old ([`LiveSettings::max_age`]) or none yet: stop.
    Stale {
        age: f64,
    },
    /// Fresh again, not yet for [`LiveSettings::recover_span`].
    Recovering {
        since: f64,
    },
}

/// The freshness rule (issue 41): a set older than `max_age` while the
/// machine moves stops it; moving again needs sets arriving within
/// `max_age` of each other for `recover_span`. Like the pose gate, a
/// single set never re-arms the machine.
#[derive(Debug, Clone, Copy)]
pub struct Freshness {
    state: FreshnessState,
    /// Stamp of the last set seen.
    last: Option<f64>,
}

impl Default for Freshness {
    fn default() -> Self {
        Self {
            state: FreshnessState::Stale { age: f64::INFINITY },
            last: None,
        }
    }
}

impl Freshness {
    /// A set measured at `stamp` arrived (stamps from the set, in order;
    /// an older or equal one is ignored); `consistent`: its obstacles are
    /// where the previous set's predicted them ([`jumped`] is false). While
    /// recovering, a jump restarts the span, as a pose that teleports does
    /// at the pose gate.
    pub fn arrived(&mut self, stamp: f64, consistent: bool, s: &LiveSettings) {
        if self.last.is_some_and(|l| stamp <= l) {
            return;
        }
        let gap_ok = self.last.is_some_and(|l| stamp - l <= s.max_age);
        self.state = match self.state {
            FreshnessState::Fresh if gap_ok => FreshnessState::Fresh,
            FreshnessState::Recovering { since } if gap_ok && consistent => {
                FreshnessState::Recovering { since }
            }
            _ => FreshnessState::Recovering { since: stamp },
        };
        self.last = Some(stamp);
    }

    /// The state at `now`: stale when the newest set is older than
    /// `max_age`; recovered when fresh sets have spanned `recover_span`.
    pub fn update(&mut self, now: f64, s: &LiveSettings) -> FreshnessState {
        let age = self.last.map_or(f64::INFINITY, |l| now - l);
        if age > s.max_age {
            self.state = FreshnessState::Stale { age };
        } else if let FreshnessState::Recovering { since } = self.state {
            if self.last.is_some_and(|l| l - since >= s.recover_span) {
                self.state = FreshnessState::Fresh;
            }
        }
        self.state
    }

    pub fn state(&self) -> FreshnessState {
        self.state
    }
}

/// The slow-down field (module docs): the factor in [0, 1] the speed is
/// scaled by, from the time τ to the first state of `plan` (states `dt`
/// apart from `t0`) whose outline comes within the stop field of a live
/// obstacle: τ / `slow_time` below it, 1 beyond. `clearance(t, x)` is that
/// least clearance beyond the field (negative inside).
pub fn slow_factor(
    plan: &[State],
    t0: f64,
    dt: f64,
    s: &LiveSettings,
    mut clearance: impl FnMut(f64, &State) -> f64,
) -> f64 {
    for (k, x) in plan.iter().enumerate() {
        let t = k as f64 * dt;
        if t > s.slow_time {
            break;
        }
        if clearance(t0 + t, x) < 0.0 {
            return (t / s.slow_time).clamp(0.0, 1.0);
        }
    }
    1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::geometry::Polygon;

    #[test]
    fn a_polygons_distance_is_the_site_polygons() {
        // Second implementation: the site's polygon (its own Vec ring).
        let v = [[0.0, 0.0], [2.0, 0.0], [2.5, 1.0], [1.0, 2.0], [-0.5, 1.0]];
        let live = LiveShape::polygon(&v).unwrap();
        let mut cw = v;
        cw.reverse();
        let live_cw = LiveShape::polygon(&cw).unwrap();
        let site = Polygon::new(v.to_vec());
        for i in 0..40 {
            let p = [-2.0 + 0.17 * i as f64, 3.0 - 0.13 * i as f64];
            let d = site.signed_distance(p);
            assert!((live.signed_distance(p) - d).abs() < 1e-12);
            assert!((live_cw.signed_distance(p) - d).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_shapes_are_refused() {
        assert_eq!(
            LiveShape::polygon(&[[0.0, 0.0], [1.0, 0.0]]),
            Err(LiveError::Vertices(2))
        );
        assert_eq!(
            LiveShape::polygon(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]),
            Err(LiveError::NoArea)
        );
        // A dart: one reflex vertex.
        assert_eq!(
            LiveShape::polygon(&[[0.0, 0.0], [2.0, 1.0], [0.0, 2.0], [0.5, 1.0]]),
            Err(LiveError::NotConvex)
        );
        assert_eq!(
            LiveShape::polygon(&[[0.0, 0.0], [f64::NAN, 0.0], [0.0, 1.0]]),
            Err(LiveError::NotFinite("polygon vertex"))
        );
        assert_eq!(
            LiveShape::circle([0.0, 0.0], 0.0),
            Err(LiveError::Radius(0.0))
        );
        assert_eq!(
            LiveShape::circle([f64::INFINITY, 0.0], 1.0),
            Err(LiveError::NotFinite("circle centre"))
        );
        let c = LiveShape::circle([0.0, 0.0], 1.0).unwrap();
        assert!(LiveObstacle::new(1, LiveClass::Person, c, [f64::NAN, 0.0], 0.0).is_err());
        assert!(LiveObstacle::new(1, LiveClass::Person, c, [0.0, 0.0], f64::NAN).is_err());
        let mut set = LiveSet::new();
        let o = LiveObstacle::new(1, LiveClass::Person, c, [0.0, 0.0], 0.0).unwrap();
        assert_eq!(
            set.set(0.0, &vec![o; MAX_LIVE_OBSTACLES + 1]),
            Err(LiveError::TooMany(MAX_LIVE_OBSTACLES + 1))
        );
        assert!(set.stamp().is_none());
    }

    #[test]
    fn an_obstacle_is_predicted_along_its_velocity_from_its_stamp() {
        let c = LiveShape::circle([10.0, 0.0], 0.5).unwrap();
        let o = LiveObstacle::new(7, LiveClass::Person, c, [-1.0, 0.5], 2.0).unwrap();
        // At t = 4 s it is at (8, 1).
        let d = o.clearance_at([5.0, 5.0], 0.25, 4.0);
        assert!((d - (3.0f64.hypot(4.0) - 0.75)).abs() < 1e-12);
        // Before its stamp it is extrapolated backwards the same way.
        let d = o.clearance_at([12.0, -1.0], 0.0, 0.0);
        assert!((d + 0.5).abs() < 1e-12);
    }

    #[test]
    fn freshness_stops_on_an_old_set_and_recovers_only_over_a_span() {
        let s = LiveSettings::default();
        let mut f = Freshness::default();
        assert!(matches!(f.update(0.0, &s), FreshnessState::Stale { .. }));
        // One set does not re-arm the machine.
        f.arrived(0.0, true, &s);
        assert!(matches!(
            f.update(0.05, &s),
            FreshnessState::Recovering { .. }
        ));
        for k in 1..=5 {
            f.arrived(0.1 * k as f64, true, &s);
        }
        assert_eq!(f.update(0.5, &s), FreshnessState::Fresh);
        // Silence beyond max_age: stale, with the age.
        match f.update(1.01, &s) {
            FreshnessState::Stale { age } => assert!((age - 0.51).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        // A stamp from before the last is ignored and cannot refresh.
        f.arrived(0.4, true, &s);
        assert!(matches!(f.update(1.02, &s), FreshnessState::Stale { .. }));
        // A gap larger than max_age restarts the span.
        f.arrived(1.1, true, &s);
        f.arrived(1.2, true, &s);
        f.arrived(1.8, true, &s);
        assert!(matches!(
            f.update(1.8, &s),
            FreshnessState::Recovering { .. }
        ));
        f.arrived(2.0, true, &s);
        f.arrived(2.35, true, &s);
        assert_eq!(f.update(2.35, &s), FreshnessState::Fresh);
    }

    #[test]
    fn a_track_that_jumps_restarts_the_recovery_span() {
        let s = LiveSettings::default();
        let person = |x: f64, t: f64| {
            let shape = LiveShape::circle([x, 0.0], 0.3).unwrap();
            let mut set = LiveSet::new();
            set.set(
                t,
                &[LiveObstacle::new(4, LiveClass::Person, shape, [1.0, 0.0], t).unwrap()],
            )
            .unwrap();
            set
        };
        // Walking at 1 m/s: 0.1 s later 0.1 m on is no jump; 2 m on is.
        assert!(!jumped(&person(0.0, 0.0), &person(0.1, 0.1), &s));
        assert!(!jumped(&person(0.0, 0.0), &person(1.0, 0.1), &s));
        assert!(jumped(&person(0.0, 0.0), &person(2.0, 0.1), &s));
        // A new id, or no stamp yet, is no jump.
        assert!(!jumped(&LiveSet::new(), &person(5.0, 0.1), &s));
        let mut f = Freshness::default();
        f.arrived(0.0, true, &s);
        f.arrived(0.3, true, &s);
        // A jump at 0.4 s: the span starts again there.
        f.arrived(0.4, false, &s);
        f.arrived(0.6, true, &s);
        assert!(matches!(f.update(0.6, &s), FreshnessState::Recovering { since } if since == 0.4));
        f.arrived(0.9, true, &s);
        assert_eq!(f.update(0.9, &s), FreshnessState::Fresh);
        // Once fresh, a jump is the new truth, not a fault.
        f.arrived(1.0, false, &s);
        assert_eq!(f.update(1.0, &s), FreshnessState::Fresh);
    }

    #[test]
    fn the_slow_factor_is_the_time_to_collision_over_the_slow_time() {
        let s = LiveSettings::default();
        // Straight along +x at 1 m/s, a wall at x = 1.5 (clearance 1.5 − x).
        let plan: Vec<State> = (0..20)
            .map(|k| State::new(0.2 * k as f64, 0.0, 0.0, 0.0, 0.0, 1.0))
            .collect();
        let f = slow_factor(&plan, 0.0, 0.2, &s, |_, x| 1.5 - x[0]);
        // The first state past it is x = 1.6 at t = 1.6 s.
        assert!((f - 0.8).abs() < 1e-12);
        assert_eq!(slow_factor(&plan, 0.0, 0.2, &s, |_, x| 3.0 - x[0]), 1.0);
        assert_eq!(slow_factor(&plan, 0.0, 0.2, &s, |_, _| -1.0), 0.0);
        assert!(LiveSettings::default().validate().is_ok());
        let bad = LiveSettings {
            max_age: 0.0,
            ..LiveSettings::default()
        };
        assert_eq!(bad.validate().unwrap_err().name, "max_age");
        for replan_after in [0.0, 601.0, f64::NAN] {
            let bad = LiveSettings {
                replan_after,
                ..LiveSettings::default()
            };
            assert_eq!(bad.validate().unwrap_err().name, "replan_after");
        }
    }
}
