//! The one world every layer reads (DESIGN §17): the site's features (through
//! its spatial index, shared and swapped whole on a reload), the circles a
//! goal still carries, and the machine's outline they are measured against.
//! Goal validation, the route planner, the MPC's rows and the safety envelope
//! each hold a [`World`] the pilot keeps equal, and ask it the same questions.
//!
//! A goal's circles keep their wire meaning (DESIGN §10: the radius R
//! includes the machine's half-width w): to an outline circle of radius r
//! such a circle is the physical circle R − w, so the clearance is
//! `‖q − o‖ − R − (r − w)`. With the default outline (a circle of radius w at
//! each axle point, [`Outline::axle_circles`]) that is `‖q − o‖ − R` exactly:
//! every figure measured before the site keeps its meaning.
//!
//! Allocation-free after [`World::new`]: the circles live in a buffer of
//! fixed capacity, the site is an `Arc` built at load.

use std::sync::Arc;

use crate::live::LiveObstacle;
use crate::model::{MachineParams, State};
use crate::obstacle::{BadObstacle, Obstacle};
use crate::site::geometry::P2;
use crate::site::index::{Near, Target as SiteTarget};
use crate::site::outline::{Body, Outline, WorldCircle, MAX_OUTLINE_CIRCLES};
use crate::site::SiteIndex;

/// The default machine's half-width [m]: the Avant 635's published 1.3 m
/// over tyres and bucket. What the default outline's two circles measure.
pub const DEFAULT_HALF_WIDTH: f64 = 0.65;

/// What a clearance was measured to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// The site's feature `i` (`site.features()[i]`).
    Feature(usize),
    /// The outside of the site's bounds.
    Bounds,
    /// The goal's circle `j`.
    Circle(usize),
    /// A live obstacle `i` (`LiveSet::obstacles()[i]`): an MPC row only,
    /// measured by [`World::live_row`] at the row's time, never by the
    /// world's own queries.
    Live(usize),
}

/// The least clearance of the outline: to what, by which of its circles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    pub target: Target,
    /// The outline's circle (index into [`Outline::circles`]).
    pub circle: usize,
    /// Clearance beyond the margin asked for [m] (negative: closer).
    pub clearance: f64,
}

/// One MPC row: an outline circle kept off one target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowPair {
    pub circle: usize,
    pub target: Target,
    /// Its clearance beyond the circle's margin where it was chosen [m].
    pub excess: f64,
}

impl Default for RowPair {
    fn default() -> Self {
        Self {
            circle: 0,
            target: Target::Bounds,
            excess: f64::INFINITY,
        }
    }
}

/// Why a goal's circles are not taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldError {
    #[error("{given} obstacles given, at most {max} are taken (`max_obstacles`)")]
    TooManyObstacles { given: usize, max: usize },
    #[error(transparent)]
    BadObstacle(#[from] BadObstacle),
}

/// Site + a goal's circles + the outline (module docs).
#[derive(Debug)]
pub struct World {
    params: MachineParams,
    outline: Outline,
    /// What each outline circle keeps beyond a check's own margin [m]: the
    /// envelope's per-circle margin beyond its body's (0 for the default
    /// outline), so that the route and the MPC plan outside what the
    /// envelope guards ([`World::set_extra_margins`]).
    extra: [f64; MAX_OUTLINE_CIRCLES],
    site: Option<Arc<SiteIndex>>,
    circles: Vec<Obstacle>,
}

impl Clone for World {
    fn clone(&self) -> Self {
        let mut circles = Vec::with_capacity(self.circles.capacity());
        circles.extend_from_slice(&self.circles);
        Self {
            params: self.params,
            outline: self.outline.clone(),
            extra: self.extra,
            site: self.site.clone(),
            circles,
        }
    }
}

impl World {
    /// An empty world (no site, no circles) for room for `capacity` circles.
    pub fn new(params: MachineParams, outline: Outline, capacity: usize) -> Self {
        Self {
            params,
            outline,
            extra: [0.0; MAX_OUTLINE_CIRCLES],
            site: None,
            circles: Vec::with_capacity(capacity),
        }
    }

    /// The default outline (two axle circles of [`DEFAULT_HALF_WIDTH`]).
    pub fn with_axle_circles(params: MachineParams, capacity: usize) -> Self {
        Self::new(params, default_outline(), capacity)
    }

    pub fn params(&self) -> &MachineParams {
        &self.params
    }

    pub fn outline(&self) -> &Outline {
        &self.outline
    }

    pub fn site(&self) -> Option<&Arc<SiteIndex>> {
        self.site.as_ref()
    }

    /// The goal's circles (wire radii).
    pub fn circles(&self) -> &[Obstacle] {
        &self.circles
    }

    pub fn capacity(&self) -> usize {
        self.circles.capacity()
    }

    /// Nothing to keep off: no site and no circles.
    pub fn is_empty(&self) -> bool {
        self.site.is_none() && self.circles.is_empty()
    }

    pub fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.site = site;
    }

    /// The outline (its extra margins back to 0).
    pub fn set_outline(&mut self, outline: Outline) {
        self.outline.clone_from(&outline);
        self.extra = [0.0; MAX_OUTLINE_CIRCLES];
    }

    /// Each outline circle's extra margin (module docs of the field; one
    /// entry per circle, missing ones 0).
    pub fn set_extra_margins(&mut self, extra: &[f64]) {
        self.extra = [0.0; MAX_OUTLINE_CIRCLES];
        for (e, x) in self.extra.iter_mut().zip(extra) {
            *e = *x;
        }
    }

    pub fn extra_margins(&self) -> &[f64; MAX_OUTLINE_CIRCLES] {
        &self.extra
    }

    /// Replaces the goal's circles (validated; within the capacity, so no
    /// allocation).
    pub fn set_circles(&mut self, circles: &[Obstacle]) -> Result<(), WorldError> {
        if circles.len() > self.circles.capacity() {
            return Err(WorldError::TooManyObstacles {
                given: circles.len(),
                max: self.circles.capacity(),
            });
        }
        for (i, o) in circles.iter().enumerate() {
            o.validate(i)?;
        }
        self.circles.clear();
        self.circles.extend_from_slice(circles);
        Ok(())
    }

    /// Adds one circle (validated; `TooManyObstacles` when full, so no
    /// allocation).
    pub fn push_circle(&mut self, o: Obstacle) -> Result<(), WorldError> {
        if self.circles.len() == self.circles.capacity() {
            return Err(WorldError::TooManyObstacles {
                given: self.circles.len() + 1,
                max: self.circles.capacity(),
            });
        }
        o.validate(self.circles.len())?;
        self.circles.push(o);
        Ok(())
    }

    /// Keeps the first `n` circles.
    pub fn truncate_circles(&mut self, n: usize) {
        self.circles.truncate(n);
    }

    pub fn clear_circles(&mut self) {
        self.circles.clear();
    }

    /// Becomes `other` (site, circles, outline; no allocation: an outline's
    /// buffer holds any outline, and circles beyond the capacity are dropped,
    /// which `set_circles` never lets in).
    pub fn copy_from(&mut self, other: &World) {
        self.params = other.params;
        self.outline.clone_from(&other.outline);
        self.extra = other.extra;
        self.site = other.site.clone();
        self.circles.clear();
        let n = other.circles.len().min(self.circles.capacity());
        self.circles.extend_from_slice(&other.circles[..n]);
    }

    /// The outline's circles placed at state `x` (the first [`Outline::len`]
    /// of the array).
    pub fn place(&self, x: &State) -> [WorldCircle; MAX_OUTLINE_CIRCLES] {
        let mut buf = [WorldCircle::default(); MAX_OUTLINE_CIRCLES];
        self.outline.place(&self.params, x, &mut buf);
        buf
    }

    /// Clearance of a disc (centre `c`, radius `r`) to the goal's circle `o`
    /// (module docs: the wire radius includes the half-width).
    #[inline]
    pub fn circle_clearance(&self, c: P2, r: f64, o: &Obstacle) -> f64 {
        (c[0] - o.x).hypot(c[1] - o.y) - o.radius - (r - self.outline.half_width())
    }

    /// The least of (clearance − `margins[i]`) over the outline's circles i
    /// at state `x` and every target (the site's features and bounds, the
    /// goal's circles), among those below `cutoff`; `None` if none is. Ties:
    /// the site before the circles, then by number. `margins` has one entry
    /// per outline circle.
    pub fn excess(&self, x: &State, margins: &[f64], cutoff: f64) -> Option<Contact> {
        let n = self.outline.len();
        debug_assert!(margins.len() >= n);
        let mut placed = self.place(x);
        let mut best: Option<Contact> = None;
        let mut bound = cutoff;
        for (j, o) in self.circles.iter().enumerate() {
            for (i, c) in placed[..n].iter().enumerate() {
                let e = self.circle_clearance(c.center, c.radius, o) - margins[i];
                if e < bound {
                    bound = e;
                    best = Some(Contact {
                        target: Target::Circle(j),
                        circle: i,
                        clearance: e,
                    });
                }
            }
        }
        if let Some(site) = &self.site {
            // A margin is a larger disc: the index's clearance of circles
            // grown by their margins is the excess.
            for (c, m) in placed[..n].iter_mut().zip(margins) {
                c.radius += m;
            }
            // Ties go to the site: it is asked with a bound just above.
            let above = if bound.is_finite() {
                bound + 1e-12 * (1.0 + bound.abs())
            } else {
                bound
            };
            if let Some(hit) = site.clearance(&placed[..n], above) {
                if best.is_none_or(|b| hit.clearance <= b.clearance) {
                    best = Some(Contact {
                        target: match hit.target {
                            SiteTarget::Feature(f) => Target::Feature(f),
                            SiteTarget::Bounds => Target::Bounds,
                        },
                        circle: hit.circle,
                        clearance: hit.clearance,
                    });
                }
            }
        }
        best
    }

    /// The site's features whose signed distance from `p` is at most
    /// `radius`, written into `buf`: `Some(n)` when they are all there
    /// (fewer than `buf.len()`), `None` when there may be more (or no site).
    /// What [`World::excess_among`] takes: one index query for a region,
    /// then exact distances to the few features in it.
    pub fn features_near(&self, p: P2, radius: f64, buf: &mut [Near]) -> Option<usize> {
        let site = self.site.as_ref()?;
        let n = site.nearest(p, radius, buf);
        (n < buf.len()).then_some(n)
    }

    /// [`World::excess`] with the site's features limited to `near` (from
    /// [`World::features_near`]; `None`: all of them, through the index).
    /// The bounds and the goal's circles are always checked.
    pub fn excess_among(
        &self,
        x: &State,
        margins: &[f64],
        cutoff: f64,
        near: Option<&[Near]>,
    ) -> Option<Contact> {
        let (Some(near), Some(site)) = (near, &self.site) else {
            return self.excess(x, margins, cutoff);
        };
        let n = self.outline.len();
        let placed = self.place(x);
        let mut best: Option<Contact> = None;
        let mut bound = cutoff;
        let mut consider = |target: Target, circle: usize, e: f64| {
            if e < bound {
                bound = e;
                best = Some(Contact {
                    target,
                    circle,
                    clearance: e,
                });
            }
        };
        for (i, c) in placed[..n].iter().enumerate() {
            let m = margins[i];
            for nr in near {
                let shape = &site.site().features()[nr.feature].shape;
                consider(
                    Target::Feature(nr.feature),
                    i,
                    shape.clearance(c.center, c.radius) - m,
                );
            }
            let inside = -site.site().bounds().signed_distance(c.center) - c.radius - m;
            consider(Target::Bounds, i, inside);
            for (j, o) in self.circles.iter().enumerate() {
                consider(
                    Target::Circle(j),
                    i,
                    self.circle_clearance(c.center, c.radius, o) - m,
                );
            }
        }
        best
    }

    /// The outline's least clearance at `x` to anything (+∞ in an empty world).
    pub fn clearance(&self, x: &State) -> f64 {
        let zeros = [0.0; MAX_OUTLINE_CIRCLES];
        self.excess(x, &zeros, f64::INFINITY)
            .map_or(f64::INFINITY, |c| c.clearance)
    }

    /// The least clearance of a disc (centre `p`, radius `r`) to anything,
    /// among those below `cutoff` (`cutoff` itself if none is).
    pub fn disc_clearance(&self, p: P2, r: f64, cutoff: f64) -> f64 {
        let mut best = cutoff;
        for o in &self.circles {
            best = best.min(self.circle_clearance(p, r, o));
        }
        if let Some(site) = &self.site {
            if let Some(hit) = site.clearance(
                &[WorldCircle {
                    center: p,
                    radius: r,
                }],
                best,
            ) {
                best = best.min(hit.clearance);
            }
        }
        best
    }

    /// Whether a disc of radius `r` swept along the segment a–b keeps
    /// `extra` from everything. Exact for the goal's circles; the site is
    /// sampled at most `extra.max(0.05)` apart with the gap's half covered
    /// by the radius (a filter before a finer check, never the check).
    pub fn segment_clear(&self, a: P2, b: P2, r: f64, extra: f64) -> bool {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let circles_clear = self.circles.iter().all(|o| {
            let t = if len2 > 0.0 {
                (((o.x - a[0]) * dx + (o.y - a[1]) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            self.circle_clearance([a[0] + t * dx, a[1] + t * dy], r, o) >= extra
        });
        if !circles_clear {
            return false;
        }
        if self.site.is_none() {
            return true;
        }
        let step = extra.max(0.05);
        let n = (len2.sqrt() / step).ceil().max(1.0) as usize;
        (0..=n).all(|k| {
            let t = k as f64 / n as f64;
            let p = [a[0] + t * dx, a[1] + t * dy];
            self.disc_clearance(p, r + 0.5 * step, extra) >= extra
        })
    }

    /// What `target` is called in a message ("feature pile-1 (obstacle)",
    /// "the site's bounds", "obstacle 2 at (…) r … m").
    pub fn describe(&self, target: Target) -> String {
        match (target, &self.site) {
            (Target::Feature(f), Some(site)) => match site.site().features().get(f) {
                Some(feat) => format!("{} `{}` of site `{}`", feat.kind, feat.id, site.site().id()),
                None => format!("feature {f}"),
            },
            (Target::Feature(f), None) => format!("feature {f}"),
            (Target::Bounds, Some(site)) => format!("the bounds of site `{}`", site.site().id()),
            (Target::Bounds, None) => "the site's bounds".to_string(),
            (Target::Live(i), _) => format!("live obstacle {i}"),
            (Target::Circle(j), _) => match self.circles.get(j) {
                Some(o) => format!(
                    "obstacle {j} at ({:.2}, {:.2}) r {:.2} m",
                    o.x, o.y, o.radius
                ),
                None => format!("obstacle {j}"),
            },
        }
    }

    /// The clearance h of outline circle `circle` to `target` at state `x`
    /// and its gradient over (x_f, y_f, θ, β): what an MPC row linearises
    /// (paper eq. 18 on a general feature: its nearest edge is the row's
    /// half-plane at the linearisation point). Beyond a polygon's corner the
    /// direction is the corner's; at a circle's centre, +x.
    pub fn row(&self, x: &State, circle: usize, target: Target) -> (f64, [f64; 4]) {
        let oc = &self.outline.circles()[circle];
        let q = oc.center(&self.params, x);
        let (h, n) = match target {
            Target::Circle(j) => {
                let o = &self.circles[j];
                let (dx, dy) = (q[0] - o.x, q[1] - o.y);
                let d = dx.hypot(dy);
                let n = if d > 1e-9 {
                    [dx / d, dy / d]
                } else {
                    [1.0, 0.0]
                };
                (d - o.radius - (oc.radius - self.outline.half_width()), n)
            }
            Target::Feature(f) => match &self.site {
                Some(site) => {
                    let near = site.site().features()[f].shape.nearest(q);
                    (near.distance - oc.radius, near.normal)
                }
                None => (f64::INFINITY, [0.0, 0.0]),
            },
            Target::Bounds => match &self.site {
                Some(site) => {
                    // The outside of the bounds: distance to it is minus the
                    // bounds' signed distance, its gradient the opposite.
                    let near = site.site().bounds().nearest(q);
                    (
                        -near.distance - oc.radius,
                        [-near.normal[0], -near.normal[1]],
                    )
                }
                None => (f64::INFINITY, [0.0, 0.0]),
            },
            // Not the world's: [`World::live_row`] measures it.
            Target::Live(_) => (f64::INFINITY, [0.0, 0.0]),
        };
        self.row_gradient(x, circle, n, h)
    }

    /// [`World::row`] for the live obstacle `o` predicted to time `t` (its
    /// shape moved along its velocity from its stamp, DESIGN §18), less
    /// `grow` (the prediction's reach, [`crate::live::LiveSettings::reach`]):
    /// the obstacle's position is the row's constant, so the gradient is
    /// the outline circle's alone (paper eq. 18 on a moving obstacle).
    pub fn live_row(
        &self,
        x: &State,
        circle: usize,
        o: &LiveObstacle,
        t: f64,
        grow: f64,
    ) -> (f64, [f64; 4]) {
        let oc = &self.outline.circles()[circle];
        let q = oc.center(&self.params, x);
        let (d, n) = o.shape.nearest(o.relative(q, t));
        self.row_gradient(x, circle, n, d - oc.radius - grow)
    }

    /// (h, ∇h) of outline circle `circle` for a clearance h whose gradient
    /// in the plane at the circle's centre is `n`.
    fn row_gradient(&self, x: &State, circle: usize, n: P2, h: f64) -> (f64, [f64; 4]) {
        let oc = &self.outline.circles()[circle];
        let j = oc.jacobian(&self.params, x);
        let mut g = [0.0; 4];
        for (k, gk) in g.iter_mut().enumerate() {
            *gk = n[0] * j[0][k] + n[1] * j[1][k];
        }
        (h, g)
    }

    /// The site's rows for state `x`: for each outline circle, the features
    /// within `reach` of it and the bounds, appended to `out[*len..]` as
    /// pairs with their excess over `margins[body]` (front, rear); when `out`
    /// is full, a pair replaces the pair of largest excess if it is smaller.
    /// Allocation-free (`near` is the caller's scratch).
    pub fn site_rows(
        &self,
        x: &State,
        margins: [f64; 2],
        reach: f64,
        near: &mut [Near],
        out: &mut [RowPair],
        len: &mut usize,
    ) {
        let Some(site) = &self.site else {
            return;
        };
        let placed = self.place(x);
        for (i, c) in placed[..self.outline.len()].iter().enumerate() {
            let m = match self.outline.circles()[i].body {
                Body::Front => margins[0],
                Body::Rear => margins[1],
            };
            let k = site.nearest(c.center, reach + c.radius + m, near);
            for nr in &near[..k] {
                push_smallest(
                    out,
                    len,
                    RowPair {
                        circle: i,
                        target: Target::Feature(nr.feature),
                        excess: nr.nearest.distance - c.radius - m,
                    },
                );
            }
            let inside = -site.site().bounds().signed_distance(c.center) - c.radius - m;
            if inside < reach {
                push_smallest(
                    out,
                    len,
                    RowPair {
                        circle: i,
                        target: Target::Bounds,
                        excess: inside,
                    },
                );
            }
        }
    }
}

/// Appends `pair` to `out[..*len]`, or, when full, puts it in place of the
/// pair of largest excess if its own is smaller.
pub(crate) fn push_smallest(out: &mut [RowPair], len: &mut usize, pair: RowPair) {
    if *len < out.len() {
        out[*len] = pair;
        *len += 1;
        return;
    }
    if let Some(worst) = out.iter_mut().max_by(|a, b| a.excess.total_cmp(&b.excess)) {
        if pair.excess < worst.excess {
            *worst = pair;
        }
    }
}

/// Today's outline (DESIGN §10, §17): a circle of [`DEFAULT_HALF_WIDTH`] at
/// each axle point.
pub fn default_outline() -> Outline {
    Outline::axle_circles(DEFAULT_HALF_WIDTH).expect("a positive half-width is a valid outline")
}

#[cfg(test)]
mod tests;
