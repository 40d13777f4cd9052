//! Plane geometry of a site's features (DESIGN §17): signed distance, nearest
//! surface point and the clearance of a disc, for circles, simple polygons
//! (convex or not, either winding) and polylines with a width (a chain of
//! capsules).
//!
//! Conventions: metres, the pose frame. The signed distance of a point is
//! negative inside the feature, zero on its outline, positive outside; its
//! gradient (where it exists) is [`Nearest::normal`], a unit vector pointing
//! away from the feature. The clearance of a disc (centre c, radius r) is
//! `signed_distance(c) − r`: positive means apart, negative overlapping.

/// A point or vector of the plane, [x, y] in metres.
pub type P2 = [f64; 2];

/// An axis-aligned box: `min` and `max` corners.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Aabb {
    pub min: P2,
    pub max: P2,
}

impl Aabb {
    /// The smallest box holding every point (an empty box for no points).
    pub fn of_points(points: &[P2]) -> Self {
        let mut b = Aabb {
            min: [f64::INFINITY; 2],
            max: [f64::NEG_INFINITY; 2],
        };
        for q in points {
            b.min = [b.min[0].min(q[0]), b.min[1].min(q[1])];
            b.max = [b.max[0].max(q[0]), b.max[1].max(q[1])];
        }
        b
    }

    /// The box grown by `d` on every side.
    pub fn grown(self, d: f64) -> Self {
        Aabb {
            min: [self.min[0] - d, self.min[1] - d],
            max: [self.max[0] + d, self.max[1] + d],
        }
    }

    /// Euclidean distance from `p` to the box (0 inside): a lower bound of
    /// the distance to anything the box holds.
    pub fn distance(&self, p: P2) -> f64 {
        let dx = (self.min[0] - p[0]).max(p[0] - self.max[0]).max(0.0);
        let dy = (self.min[1] - p[1]).max(p[1] - self.max[1]).max(0.0);
        dx.hypot(dy)
    }

    /// Whether two boxes share a point.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min[0] <= o.max[0]
            && o.min[0] <= self.max[0]
            && self.min[1] <= o.max[1]
            && o.min[1] <= self.max[1]
    }
}

/// The point of a feature's outline nearest to a query point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Nearest {
    /// Signed distance of the query point (negative inside) [m].
    pub distance: f64,
    /// The nearest point of the feature's outline.
    pub point: P2,
    /// Unit gradient of the signed distance at the query point: away from
    /// the feature (outside) or towards its nearest outline point (inside).
    /// On the outline itself, the outline's outward normal.
    pub normal: P2,
    /// The polygon edge (from vertex i to i + 1, cyclic) or polyline segment
    /// the point lies on; `None` for a circle.
    pub edge: Option<usize>,
}

pub(crate) fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

pub(crate) fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn norm(a: P2) -> f64 {
    a[0].hypot(a[1])
}

/// Closest point to `p` on segment a–b and its distance.
pub fn closest_on_segment(p: P2, a: P2, b: P2) -> (P2, f64) {
    let (q, d2) = closest_on_segment_squared(p, a, b);
    (q, d2.sqrt())
}

/// Closest point to `p` on segment a–b and its squared distance: what a
/// search over many segments compares (one square root for the winner; the
/// envelope and the MPC ask every polygon near the machine each tick).
pub fn closest_on_segment_squared(p: P2, a: P2, b: P2) -> (P2, f64) {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 {
        (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * ab[0], a[1] + t * ab[1]];
    let v = sub(p, q);
    (q, dot(v, v))
}

/// Orientation of c relative to the directed line a → b: > 0 left, < 0 right.
pub(crate) fn orient(a: P2, b: P2, c: P2) -> f64 {
    cross(sub(b, a), sub(c, a))
}

fn on_segment_collinear(a: P2, b: P2, c: P2) -> bool {
    c[0] >= a[0].min(b[0])
        && c[0] <= a[0].max(b[0])
        && c[1] >= a[1].min(b[1])
        && c[1] <= a[1].max(b[1])
}

/// Whether segments p1–p2 and q1–q2 share any point (touching included).
pub fn segments_intersect(p1: P2, p2: P2, q1: P2, q2: P2) -> bool {
    let d1 = orient(q1, q2, p1);
    let d2 = orient(q1, q2, p2);
    let d3 = orient(p1, p2, q1);
    let d4 = orient(p1, p2, q2);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment_collinear(q1, q2, p1))
        || (d2 == 0.0 && on_segment_collinear(q1, q2, p2))
        || (d3 == 0.0 && on_segment_collinear(p1, p2, q1))
        || (d4 == 0.0 && on_segment_collinear(p1, p2, q2))
}

/// Whether segments cross at a single point interior to both (touching and
/// collinear overlap excluded).
pub fn segments_cross_properly(p1: P2, p2: P2, q1: P2, q2: P2) -> bool {
    let d1 = orient(q1, q2, p1);
    let d2 = orient(q1, q2, p2);
    let d3 = orient(p1, p2, q1);
    let d4 = orient(p1, p2, q2);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Distance between segments p1–p2 and q1–q2 (0 if they meet).
pub fn segment_distance(p1: P2, p2: P2, q1: P2, q2: P2) -> f64 {
    if segments_intersect(p1, p2, q1, q2) {
        return 0.0;
    }
    closest_on_segment(p1, q1, q2)
        .1
        .min(closest_on_segment(p2, q1, q2).1)
        .min(closest_on_segment(q1, p1, p2).1)
        .min(closest_on_segment(q2, p1, p2).1)
}

/// Even-odd (crossing-number) point-in-polygon test; the ring is implicitly
/// closed. A point exactly on the outline may go either way (its signed
/// distance is 0 regardless).
pub fn point_in_polygon(p: P2, ring: &[P2]) -> bool {
    let mut inside = false;
    let n = ring.len();
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let (a, b) = (ring[i], ring[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// Twice the signed area of a ring (> 0 counter-clockwise).
pub fn signed_area2(ring: &[P2]) -> f64 {
    let n = ring.len();
    (0..n).map(|i| cross(ring[i], ring[(i + 1) % n])).sum()
}

/// The winding of a ring: +1 counter-clockwise, −1 clockwise (from its
/// signed area; turns an edge's left normal outward).
pub fn winding(ring: &[P2]) -> f64 {
    if signed_area2(ring) >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// Unit outward normal of the edge a → b of a ring of `winding`.
fn edge_outward_normal(a: P2, b: P2, winding: f64) -> P2 {
    let e = sub(b, a);
    let l = norm(e).max(f64::MIN_POSITIVE);
    // Left normal (−e_y, e_x) points inside a counter-clockwise ring.
    [winding * e[1] / l, -winding * e[0] / l]
}

/// Nearest outline point of the simple polygon `ring` (implicitly closed,
/// of [`winding`] `winding`) to `p`; the distance is negative inside. O(n).
/// What [`Polygon::nearest`] and a live obstacle's polygon (a ring of fixed
/// capacity, [`crate::live`]) both use.
pub fn ring_nearest(p: P2, ring: &[P2], winding: f64) -> Nearest {
    let n = ring.len();
    let edge = |i: usize| (ring[i], ring[(i + 1) % n]);
    let (mut best_q, mut best_d2, mut best_i) = (ring[0], f64::INFINITY, 0);
    for i in 0..n {
        let (a, b) = edge(i);
        let (q, d2) = closest_on_segment_squared(p, a, b);
        if d2 < best_d2 {
            (best_q, best_d2, best_i) = (q, d2, i);
        }
    }
    let best_d = best_d2.sqrt();
    let inside = point_in_polygon(p, ring);
    let normal = if best_d > 0.0 {
        let v = sub(p, best_q);
        let s = if inside { -1.0 } else { 1.0 };
        [s * v[0] / best_d, s * v[1] / best_d]
    } else {
        let (a, b) = edge(best_i);
        edge_outward_normal(a, b, winding)
    };
    Nearest {
        distance: if inside { -best_d } else { best_d },
        point: best_q,
        normal,
        edge: Some(best_i),
    }
}

/// A disc: centre and radius [m].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Circle {
    pub center: P2,
    pub radius: f64,
}

impl Circle {
    pub fn nearest(&self, p: P2) -> Nearest {
        let d = sub(p, self.center);
        let l = norm(d);
        let n = if l > 0.0 {
            [d[0] / l, d[1] / l]
        } else {
            [1.0, 0.0]
        };
        Nearest {
            distance: l - self.radius,
            point: [
                self.center[0] + self.radius * n[0],
                self.center[1] + self.radius * n[1],
            ],
            normal: n,
            edge: None,
        }
    }

    pub fn signed_distance(&self, p: P2) -> f64 {
        norm(sub(p, self.center)) - self.radius
    }

    pub fn aabb(&self) -> Aabb {
        Aabb {
            min: [self.center[0] - self.radius, self.center[1] - self.radius],
            max: [self.center[0] + self.radius, self.center[1] + self.radius],
        }
    }
}

/// A simple polygon (no self-intersection; validated by [`super::Site`]'s
/// loader), either winding, convex or not. The ring is implicitly closed.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    vertices: Vec<P2>,
    /// +1 counter-clockwise, −1 clockwise: turns an edge's left normal outward.
    winding: f64,
    aabb: Aabb,
}

impl Polygon {
    /// A polygon of these vertices, not checked for simplicity (the site
    /// loader checks; a caller building one must); the winding is taken from
    /// the signed area.
    pub fn new(vertices: Vec<P2>) -> Self {
        let winding = winding(&vertices);
        let aabb = Aabb::of_points(&vertices);
        Self {
            vertices,
            winding,
            aabb,
        }
    }

    pub fn vertices(&self) -> &[P2] {
        &self.vertices
    }

    pub fn aabb(&self) -> Aabb {
        self.aabb
    }

    /// Edge i: from vertex i to vertex i + 1 (cyclic).
    pub fn edge(&self, i: usize) -> (P2, P2) {
        let n = self.vertices.len();
        (self.vertices[i], self.vertices[(i + 1) % n])
    }

    pub fn contains(&self, p: P2) -> bool {
        point_in_polygon(p, &self.vertices)
    }

    /// Nearest outline point; the distance is negative inside. O(n).
    pub fn nearest(&self, p: P2) -> Nearest {
        ring_nearest(p, &self.vertices, self.winding)
    }

    /// Unit outward normal of edge i.
    pub fn outward_normal(&self, i: usize) -> P2 {
        let (a, b) = self.edge(i);
        edge_outward_normal(a, b, self.winding)
    }

    pub fn signed_distance(&self, p: P2) -> f64 {
        self.nearest(p).distance
    }
}

/// A polyline with a width: the set of points within `width / 2` of its
/// centre line (a chain of capsules), e.g. a wall or a berm's crest.
#[derive(Debug, Clone, PartialEq)]
pub struct Polyline {
    vertices: Vec<P2>,
    half_width: f64,
    aabb: Aabb,
}

impl Polyline {
    pub fn new(vertices: Vec<P2>, width: f64) -> Self {
        let half_width = 0.5 * width;
        let aabb = Aabb::of_points(&vertices).grown(half_width);
        Self {
            vertices,
            half_width,
            aabb,
        }
    }

    pub fn vertices(&self) -> &[P2] {
        &self.vertices
    }

    pub fn half_width(&self) -> f64 {
        self.half_width
    }

    pub fn aabb(&self) -> Aabb {
        self.aabb
    }

    /// Nearest point of the capsule chain's outline; negative inside. O(n).
    pub fn nearest(&self, p: P2) -> Nearest {
        let (mut best_c, mut best_d2, mut best_i) = (self.vertices[0], f64::INFINITY, 0);
        for (i, w) in self.vertices.windows(2).enumerate() {
            let (q, d2) = closest_on_segment_squared(p, w[0], w[1]);
            if d2 < best_d2 {
                (best_c, best_d2, best_i) = (q, d2, i);
            }
        }
        let best_d = best_d2.sqrt();
        let normal = if best_d > 0.0 {
            let v = sub(p, best_c);
            [v[0] / best_d, v[1] / best_d]
        } else {
            // On the centre line: the segment's left normal (either side is
            // a gradient of the distance there).
            let e = sub(self.vertices[best_i + 1], self.vertices[best_i]);
            let l = norm(e).max(f64::MIN_POSITIVE);
            [-e[1] / l, e[0] / l]
        };
        Nearest {
            distance: best_d - self.half_width,
            point: [
                best_c[0] + self.half_width * normal[0],
                best_c[1] + self.half_width * normal[1],
            ],
            normal,
            edge: Some(best_i),
        }
    }

    pub fn signed_distance(&self, p: P2) -> f64 {
        self.nearest(p).distance
    }
}

/// One feature's shape.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    Circle(Circle),
    Polygon(Polygon),
    Polyline(Polyline),
}

impl Shape {
    /// Nearest outline point to `p` (signed distance negative inside).
    pub fn nearest(&self, p: P2) -> Nearest {
        match self {
            Shape::Circle(c) => c.nearest(p),
            Shape::Polygon(g) => g.nearest(p),
            Shape::Polyline(l) => l.nearest(p),
        }
    }

    /// Signed distance of `p` (negative inside) [m].
    pub fn signed_distance(&self, p: P2) -> f64 {
        match self {
            Shape::Circle(c) => c.signed_distance(p),
            Shape::Polygon(g) => g.signed_distance(p),
            Shape::Polyline(l) => l.signed_distance(p),
        }
    }

    /// Clearance of a disc of `radius` around `center`: the distance between
    /// the disc and the shape when apart, negative when they overlap.
    pub fn clearance(&self, center: P2, radius: f64) -> f64 {
        self.signed_distance(center) - radius
    }

    /// The shape's bounding box.
    pub fn aabb(&self) -> Aabb {
        match self {
            Shape::Circle(c) => c.aabb(),
            Shape::Polygon(g) => g.aabb(),
            Shape::Polyline(l) => l.aabb(),
        }
    }

    /// A disc inside the shape, as large as a search finds: the shape
    /// itself for a circle; for a polygon the best of a 32 × 32 grid over its
    /// box, refined by a shrinking pattern search (the pole of
    /// inaccessibility, to about 1e-4 of the box); for a polyline a disc of
    /// its half-width on its centre line. Every point of the disc is in the
    /// shape, so a problem with each shape replaced by its disc is a
    /// relaxation (e.g. a valid lower bound on a minimum time).
    pub fn inscribed_circle(&self) -> Circle {
        match self {
            Shape::Circle(c) => *c,
            Shape::Polyline(l) => Circle {
                center: l.vertices()[0],
                radius: l.half_width(),
            },
            Shape::Polygon(g) => {
                let b = g.aabb();
                let depth = |q: P2| -g.signed_distance(q);
                let n = 32;
                let mut step = [
                    (b.max[0] - b.min[0]) / n as f64,
                    (b.max[1] - b.min[1]) / n as f64,
                ];
                let mut best = (f64::NEG_INFINITY, g.vertices()[0]);
                for i in 0..n {
                    for j in 0..n {
                        let q = [
                            b.min[0] + (i as f64 + 0.5) * step[0],
                            b.min[1] + (j as f64 + 0.5) * step[1],
                        ];
                        let d = depth(q);
                        if d > best.0 {
                            best = (d, q);
                        }
                    }
                }
                for _ in 0..40 {
                    let c = best.1;
                    for (dx, dy) in [
                        (1.0, 0.0),
                        (-1.0, 0.0),
                        (0.0, 1.0),
                        (0.0, -1.0),
                        (1.0, 1.0),
                        (-1.0, -1.0),
                        (1.0, -1.0),
                        (-1.0, 1.0),
                    ] {
                        let q = [c[0] + dx * step[0], c[1] + dy * step[1]];
                        let d = depth(q);
                        if d > best.0 {
                            best = (d, q);
                        }
                    }
                    if best.1 == c {
                        step = [step[0] * 0.5, step[1] * 0.5];
                    }
                }
                Circle {
                    center: best.1,
                    radius: best.0.max(0.0),
                }
            }
        }
    }

    /// Vertex count (1 for a circle), what the loader's limits count.
    pub fn vertex_count(&self) -> usize {
        match self {
            Shape::Circle(_) => 1,
            Shape::Polygon(g) => g.vertices().len(),
            Shape::Polyline(l) => l.vertices().len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// An independent inside test: the winding number by summed angles.
    fn winding_number(p: P2, ring: &[P2]) -> f64 {
        let n = ring.len();
        let mut total = 0.0;
        for i in 0..n {
            let a = sub(ring[i], p);
            let b = sub(ring[(i + 1) % n], p);
            total += cross(a, b).atan2(dot(a, b));
        }
        total / (2.0 * std::f64::consts::PI)
    }

    /// Distance to the outline by dense sampling of its edges: within
    /// `step / 2` of the true distance.
    fn sampled_outline_distance(p: P2, ring: &[P2], closed: bool, step: f64) -> f64 {
        let n = ring.len();
        let edges = if closed { n } else { n - 1 };
        let mut best = f64::INFINITY;
        for i in 0..edges {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            let l = norm(sub(b, a));
            let k = (l / step).ceil().max(1.0) as usize;
            for s in 0..=k {
                let t = s as f64 / k as f64;
                let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                best = best.min(norm(sub(p, q)));
            }
        }
        best
    }

    /// A non-convex, clockwise "C" shape.
    fn c_shape() -> Vec<P2> {
        let ccw = vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 1.0],
            [1.0, 1.0],
            [1.0, 3.0],
            [4.0, 3.0],
            [4.0, 4.0],
            [0.0, 4.0],
        ];
        ccw.into_iter().rev().collect()
    }

    #[test]
    fn polygon_signed_distance_matches_sampling_and_winding_number() {
        let ring = c_shape();
        let g = Polygon::new(ring.clone());
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let step = 1e-3;
        let (mut inside_seen, mut gradient_ok) = (0, 0);
        for _ in 0..2000 {
            let p = [rng.gen_range(-1.5..5.5), rng.gen_range(-1.5..5.5)];
            let n = g.nearest(p);
            let brute = sampled_outline_distance(p, &ring, true, step);
            assert!(
                (n.distance.abs() - brute).abs() <= step,
                "{p:?}: {} vs {brute}",
                n.distance
            );
            let wn = winding_number(p, &ring);
            // |wn| is 1 inside, 0 outside (either winding).
            let inside = wn.abs() > 0.5;
            if n.distance.abs() > 1e-9 {
                assert_eq!(n.distance < 0.0, inside, "{p:?}");
            }
            inside_seen += inside as usize;
            // The nearest point is on the outline at the stated distance.
            assert!((norm(sub(p, n.point)) - n.distance.abs()).abs() < 1e-12);
            // The normal is the gradient: a small step along it raises the
            // signed distance by the step (by less only on the medial axis,
            // where the distance has no gradient).
            let h = 1e-6;
            let q = [p[0] + h * n.normal[0], p[1] + h * n.normal[1]];
            let rise = g.signed_distance(q) - n.distance;
            assert!(rise <= h * (1.0 + 1e-6), "{p:?}");
            gradient_ok += ((rise - h).abs() <= 1e-3 * h) as usize;
        }
        assert!(inside_seen > 200, "the test must see inside points");
        assert!(gradient_ok >= 1950, "{gradient_ok} of 2000");
    }

    #[test]
    fn outward_normal_points_out_for_either_winding() {
        for ring in [c_shape(), c_shape().into_iter().rev().collect()] {
            let g = Polygon::new(ring);
            for i in 0..g.vertices().len() {
                let (a, b) = g.edge(i);
                let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
                let nrm = g.outward_normal(i);
                let out = [m[0] + 1e-3 * nrm[0], m[1] + 1e-3 * nrm[1]];
                assert!(!g.contains(out), "edge {i}");
            }
        }
    }

    #[test]
    fn circle_distance_is_closed_form() {
        let c = Circle {
            center: [1.0, -2.0],
            radius: 0.5,
        };
        let n = c.nearest([4.0, 2.0]);
        assert!((n.distance - 4.5).abs() < 1e-12);
        assert!((n.point[0] - 1.3).abs() < 1e-12 && (n.point[1] + 1.6).abs() < 1e-12);
        assert!((c.signed_distance([1.0, -2.0]) + 0.5).abs() < 1e-12);
    }

    #[test]
    fn capsule_chain_matches_sampling() {
        let line = vec![[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [0.5, 3.5]];
        let l = Polyline::new(line.clone(), 0.6);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let step = 1e-3;
        let mut inside_seen = 0;
        for _ in 0..2000 {
            let p = [rng.gen_range(-1.0..4.5), rng.gen_range(-1.0..4.5)];
            let brute = sampled_outline_distance(p, &line, false, step) - 0.3;
            let n = l.nearest(p);
            assert!((n.distance - brute).abs() <= step, "{p:?}");
            inside_seen += (n.distance < 0.0) as usize;
            assert!((norm(sub(p, n.point)) - n.distance.abs()).abs() < 1e-9);
        }
        assert!(inside_seen > 50);
    }

    #[test]
    fn disc_clearance_is_negative_exactly_when_the_disc_meets_the_shape() {
        // Independent check: sample the disc's area and ask the winding
        // number whether any sample lies inside the polygon.
        let ring = c_shape();
        let shape = Shape::Polygon(Polygon::new(ring.clone()));
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..300 {
            let c = [rng.gen_range(-1.0..5.0), rng.gen_range(-1.0..5.0)];
            let r = rng.gen_range(0.1..0.8);
            let cl = shape.clearance(c, r);
            if cl.abs() < 0.02 {
                continue; // too close to call by sampling
            }
            let mut meets = false;
            for i in 0..40 {
                for j in 0..16 {
                    let rr = r * (i as f64 + 0.5) / 40.0;
                    let a = j as f64 / 16.0 * std::f64::consts::TAU;
                    let q = [c[0] + rr * a.cos(), c[1] + rr * a.sin()];
                    meets |= winding_number(q, &ring).abs() > 0.5;
                }
            }
            meets |= winding_number(c, &ring).abs() > 0.5;
            assert_eq!(cl < 0.0, meets, "{c:?} r {r}: clearance {cl}");
        }
    }

    #[test]
    fn inscribed_circles_lie_inside_and_are_large() {
        // A 4 × 2 rectangle: the largest inscribed disc has radius 1.
        let rect = Shape::Polygon(Polygon::new(vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 2.0],
            [0.0, 2.0],
        ]));
        let c = rect.inscribed_circle();
        assert!((c.radius - 1.0).abs() < 1e-3, "{c:?}");
        // The C shape: bars 1 wide; the largest disc sits in a corner where
        // two bars meet, touching both outer edges and the inner corner
        // (1, 1): centre (t, t) with t = √2 (1 − t), r = t = 2 − √2.
        let cs = Shape::Polygon(Polygon::new(c_shape()));
        let c = cs.inscribed_circle();
        assert!((c.radius - (2.0 - 2f64.sqrt())).abs() < 1e-3, "{c:?}");
        // Inside: samples of the disc are all in the shape.
        for k in 0..64 {
            let a = k as f64 / 64.0 * std::f64::consts::TAU;
            let q = [
                c.center[0] + 0.999 * c.radius * a.cos(),
                c.center[1] + 0.999 * c.radius * a.sin(),
            ];
            assert!(winding_number(q, &c_shape()).abs() > 0.5);
        }
        let wall = Shape::Polyline(Polyline::new(vec![[0.0, 0.0], [3.0, 0.0]], 0.4));
        let c = wall.inscribed_circle();
        assert!(wall.signed_distance(c.center) <= -0.2 + 1e-12 && (c.radius - 0.2).abs() < 1e-12);
    }

    #[test]
    fn segment_predicates() {
        assert!(segments_intersect(
            [0.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [2.0, 0.0]
        ));
        assert!(segments_intersect(
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0]
        ));
        assert!(!segments_cross_properly(
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0]
        ));
        assert!(!segments_intersect(
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [1.0, 1.0]
        ));
        assert!(
            (segment_distance([0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]) - 1.0).abs() < 1e-12
        );
    }
}
