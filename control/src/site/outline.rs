//! The machine's outline: covering circles per body (DESIGN §17).
//!
//! Each circle sits in one body's frame: the front body's frame has its
//! origin at the front axle (x_f, y_f), x along the front body's heading θ;
//! the rear body's frame has its origin at the rear axle, x along the rear
//! body's heading θ − β (both x forward, y to the left). With the model's
//! geometry (DESIGN §2, §10; `obstacle.rs`):
//!
//! ```text
//! joint  = p_f − L_f (cos θ, sin θ)
//! p_r    = joint − L_r (cos(θ − β), sin(θ − β))
//! front circle (a, b): p_f + R(θ)     (a, b)
//! rear circle  (a, b): p_r + R(θ − β) (a, b)
//! ```
//!
//! The outline is physical: a site's shapes carry no machine width, and the
//! clearance of the machine to a feature is the least clearance of its
//! circles ([`super::geometry::Shape::clearance`]).

use serde::{Deserialize, Serialize};

use super::geometry::P2;
use crate::model::{ix, MachineParams, State};
use crate::obstacle::AxlePoint;

/// Most circles an outline may have (a fixed bound, so that a caller can
/// place an outline into a stack array: `[WorldCircle; MAX_OUTLINE_CIRCLES]`).
pub const MAX_OUTLINE_CIRCLES: usize = 16;

/// Which body a circle is fixed to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Body {
    Front,
    Rear,
}

/// One covering circle: offset in its body's frame and radius [m].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutlineCircle {
    pub body: Body,
    /// [forward, left] of the body's axle [m].
    pub offset: P2,
    pub radius: f64,
}

/// A circle in the world (pose) frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WorldCircle {
    pub center: P2,
    pub radius: f64,
}

/// Why an outline is not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OutlineError {
    #[error("outline has no circles")]
    Empty,
    #[error("outline has {0} circles, more than the limit of {MAX_OUTLINE_CIRCLES}")]
    TooMany(usize),
    #[error("outline circle {0}: offset must be finite and radius finite and > 0")]
    BadCircle(usize),
    #[error("outline half_width must be finite and > 0, got {0}")]
    BadHalfWidth(f64),
}

/// The machine's outline as covering circles. Its buffer always has room
/// for [`MAX_OUTLINE_CIRCLES`], so that `clone_from` (a world taking another
/// world's outline, e.g. on the planner thread) never allocates.
#[derive(Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, try_from = "OutlineDoc", into = "OutlineDoc")]
pub struct Outline {
    circles: Vec<OutlineCircle>,
    /// The machine's half-width [m]: what a circle on the v2 wire includes
    /// in its radius (DESIGN §10), so that such a circle of radius R is the
    /// physical circle R − half_width ([`crate::world`] converts it).
    half_width: f64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct OutlineDoc {
    circles: Vec<OutlineCircle>,
    half_width: f64,
}

fn full_capacity(circles: &[OutlineCircle]) -> Vec<OutlineCircle> {
    let mut v = Vec::with_capacity(MAX_OUTLINE_CIRCLES.max(circles.len()));
    v.extend_from_slice(circles);
    v
}

impl Clone for Outline {
    fn clone(&self) -> Self {
        Self {
            circles: full_capacity(&self.circles),
            half_width: self.half_width,
        }
    }

    /// No allocation (the buffer has room for every outline).
    fn clone_from(&mut self, source: &Self) {
        self.circles.clear();
        self.circles.extend_from_slice(&source.circles);
        self.half_width = source.half_width;
    }
}

impl TryFrom<OutlineDoc> for Outline {
    type Error = OutlineError;
    fn try_from(d: OutlineDoc) -> Result<Self, Self::Error> {
        Outline::new(d.circles, d.half_width)
    }
}

impl From<Outline> for OutlineDoc {
    fn from(o: Outline) -> Self {
        OutlineDoc {
            circles: o.circles,
            half_width: o.half_width,
        }
    }
}

impl OutlineCircle {
    /// The circle's centre in the world for state `x`.
    pub fn center(&self, p: &MachineParams, x: &State) -> P2 {
        let (origin, heading) = body_frame(self.body, p, x);
        let (s, c) = heading.sin_cos();
        [
            origin[0] + c * self.offset[0] - s * self.offset[1],
            origin[1] + s * self.offset[0] + c * self.offset[1],
        ]
    }

    /// ∂(centre)/∂(x_f, y_f, θ, β): rows are the centre's x and y (what an
    /// MPC row on this circle needs, like `Obstacle::point_clearance`).
    pub fn jacobian(&self, p: &MachineParams, x: &State) -> [[f64; 4]; 2] {
        let (_, heading) = body_frame(self.body, p, x);
        let (s, c) = heading.sin_cos();
        let (a, b) = (self.offset[0], self.offset[1]);
        // d/dφ of R(φ)(a, b) = (−s a − c b, c a − s b).
        let dr = [-s * a - c * b, c * a - s * b];
        match self.body {
            Body::Front => [[1.0, 0.0, dr[0], 0.0], [0.0, 1.0, dr[1], 0.0]],
            Body::Rear => {
                let j = AxlePoint::Rear.jacobian(p, x);
                // φ = θ − β: +dr along θ, −dr along β.
                [
                    [j[0][0], j[0][1], j[0][2] + dr[0], j[0][3] - dr[0]],
                    [j[1][0], j[1][1], j[1][2] + dr[1], j[1][3] - dr[1]],
                ]
            }
        }
    }
}

/// Origin and heading of a body's frame.
fn body_frame(body: Body, p: &MachineParams, x: &State) -> (P2, f64) {
    match body {
        Body::Front => ([x[ix::X], x[ix::Y]], x[ix::THETA]),
        Body::Rear => (AxlePoint::Rear.position(p, x), x[ix::THETA] - x[ix::BETA]),
    }
}

impl Outline {
    /// An outline of these circles (1 to [`MAX_OUTLINE_CIRCLES`], finite
    /// offsets, radii > 0) of a machine `half_width` wide on each side.
    pub fn new(circles: Vec<OutlineCircle>, half_width: f64) -> Result<Self, OutlineError> {
        if !(half_width.is_finite() && half_width > 0.0) {
            return Err(OutlineError::BadHalfWidth(half_width));
        }
        if circles.is_empty() {
            return Err(OutlineError::Empty);
        }
        if circles.len() > MAX_OUTLINE_CIRCLES {
            return Err(OutlineError::TooMany(circles.len()));
        }
        for (i, c) in circles.iter().enumerate() {
            if !(c.offset[0].is_finite()
                && c.offset[1].is_finite()
                && c.radius.is_finite()
                && c.radius > 0.0)
            {
                return Err(OutlineError::BadCircle(i));
            }
        }
        Ok(Self {
            circles: full_capacity(&circles),
            half_width,
        })
    }

    /// Today's model (DESIGN §10): one circle of the half-width at each axle
    /// point. With it, the clearance to a physical circle of radius R equals
    /// `obstacle::footprint_clearance` against that circle inflated to
    /// R + half_width, so every existing figure keeps its meaning.
    pub fn axle_circles(half_width: f64) -> Result<Self, OutlineError> {
        Self::new(
            vec![
                OutlineCircle {
                    body: Body::Front,
                    offset: [0.0, 0.0],
                    radius: half_width,
                },
                OutlineCircle {
                    body: Body::Rear,
                    offset: [0.0, 0.0],
                    radius: half_width,
                },
            ],
            half_width,
        )
    }

    /// The Avant 635 (the paper's machine, L_f = L_r = 0.6 m) as five
    /// circles covering two rectangles of its full width.
    ///
    /// Dimensions: Avant Tecno's published figures for the 635, about
    /// 3.1 m long with the standard bucket and 1.3 m wide (over the tyres
    /// and the bucket); the wheelbase is the paper's Table I, 1.2 m. The
    /// split of the length is ours (no published drawing gives it): the
    /// bucket's lip 1.2 m ahead of the front axle (arms, quick-attach plate
    /// and a 0.6 m deep bucket), the counterweight's back 0.7 m behind the
    /// rear axle: 1.2 + 1.2 + 0.7 = 3.1 m.
    ///
    /// Covering (checked by a test, [`Outline::covers_body_rectangle`]):
    /// - front body, x ∈ [−0.6, 1.2] (joint to bucket lip), |y| ≤ 0.65:
    ///   three circles at x = −0.3, 0.3, 0.9, r = 0.72
    ///   (√(0.3² + 0.65²) = 0.716);
    /// - rear body, x ∈ [−0.7, 0.6] (counterweight to joint), |y| ≤ 0.65:
    ///   two circles at x = −0.375, 0.275, r = 0.73
    ///   (√(0.325² + 0.65²) = 0.727).
    pub fn avant635() -> Self {
        Self::axial(
            0.65,
            &[
                (Body::Front, -0.3, 0.72),
                (Body::Front, 0.3, 0.72),
                (Body::Front, 0.9, 0.72),
                (Body::Rear, -0.375, 0.73),
                (Body::Rear, 0.275, 0.73),
            ],
        )
    }

    /// The large loader of issue 19 (L_f 0.9 m, L_r 1.1 m: a 2.0 m
    /// wheelbase) as seven circles covering two rectangles of its width.
    ///
    /// It is a parameter set, not a named product, so no data sheet is its
    /// own. Its outline takes the proportions of compact articulated loaders
    /// of a 2.0 m wheelbase (the Volvo L25H class: about 4.9 m long with
    /// bucket, 1.8 m wide over the bucket); replace them with the machine's
    /// data sheet when there is one. The split: bucket lip 1.7 m ahead of the
    /// front axle, counterweight 1.2 m behind the rear axle:
    /// 1.7 + 2.0 + 1.2 = 4.9 m.
    ///
    /// Covering (checked by a test):
    /// - front body, x ∈ [−0.9, 1.7], |y| ≤ 0.9: four circles at
    ///   x = −0.575, 0.075, 0.725, 1.375, r = 0.96 (√(0.325² + 0.9²) = 0.957);
    /// - rear body, x ∈ [−1.2, 1.1], |y| ≤ 0.9: three circles at
    ///   x = −0.8167, −0.05, 0.7167, r = 0.98 (√(0.3833² + 0.9²) = 0.978).
    pub fn large_loader() -> Self {
        Self::axial(
            0.9,
            &[
                (Body::Front, -0.575, 0.96),
                (Body::Front, 0.075, 0.96),
                (Body::Front, 0.725, 0.96),
                (Body::Front, 1.375, 0.96),
                (Body::Rear, -0.8167, 0.98),
                (Body::Rear, -0.05, 0.98),
                (Body::Rear, 0.7167, 0.98),
            ],
        )
    }

    /// The outlines by name: `axle-circles` (the default: a circle of
    /// 0.65 m at each axle, [`crate::world::default_outline`]), `avant635`,
    /// `large-loader`, `large-loader-axles` (a circle of 0.9 m at each axle).
    pub fn named(name: &str) -> Option<Self> {
        match name {
            "axle-circles" => Some(crate::world::default_outline()),
            "avant635" => Some(Self::avant635()),
            "large-loader" => Some(Self::large_loader()),
            "large-loader-axles" => Self::axle_circles(0.9).ok(),
            _ => None,
        }
    }

    /// The names [`Outline::named`] knows.
    pub const NAMES: [&'static str; 4] = [
        "axle-circles",
        "avant635",
        "large-loader",
        "large-loader-axles",
    ];

    fn axial(half_width: f64, spec: &[(Body, f64, f64)]) -> Self {
        let circles: Vec<OutlineCircle> = spec
            .iter()
            .map(|&(body, x, radius)| OutlineCircle {
                body,
                offset: [x, 0.0],
                radius,
            })
            .collect();
        Self {
            half_width,
            circles: full_capacity(&circles),
        }
    }

    pub fn circles(&self) -> &[OutlineCircle] {
        &self.circles
    }

    /// The machine's half-width [m] (what a v2 wire circle's radius includes).
    pub fn half_width(&self) -> f64 {
        self.half_width
    }

    /// The radius of the largest disc around `body`'s axle that the body's
    /// circles cover (0 if none covers the axle): what a test of an axle's
    /// position alone may assume of the machine (the route search's grid
    /// heuristic, the minimum-time bound). The default outline's: its
    /// half-width.
    pub fn axle_radius(&self, body: Body) -> f64 {
        self.circles
            .iter()
            .filter(|c| c.body == body)
            .map(|c| c.radius - c.offset[0].hypot(c.offset[1]))
            .fold(0.0, f64::max)
    }

    /// How far the centre of circle `i` can be from the front axle [m] (the
    /// lever arm a heading error acts on): its offset on the front body; the
    /// wheelbase plus its offset on the rear body.
    pub fn lever_arm(&self, i: usize, p: &MachineParams) -> f64 {
        let c = &self.circles[i];
        let off = c.offset[0].hypot(c.offset[1]);
        match c.body {
            Body::Front => off,
            Body::Rear => p.l_f + p.l_r + off,
        }
    }

    pub fn len(&self) -> usize {
        self.circles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.circles.is_empty()
    }

    /// The largest radius (what a coarse "anything near?" test grows by).
    pub fn max_radius(&self) -> f64 {
        self.circles.iter().map(|c| c.radius).fold(0.0, f64::max)
    }

    /// The world circles for state `x`, in the outline's order.
    pub fn world_circles<'a>(
        &'a self,
        p: &'a MachineParams,
        x: &'a State,
    ) -> impl Iterator<Item = WorldCircle> + 'a {
        self.circles.iter().map(move |c| WorldCircle {
            center: c.center(p, x),
            radius: c.radius,
        })
    }

    /// Writes the world circles for state `x` into `out` (at least
    /// [`Outline::len`] long; a shorter `out` gets the first ones) and
    /// returns how many it wrote. Allocation-free.
    pub fn place(&self, p: &MachineParams, x: &State, out: &mut [WorldCircle]) -> usize {
        let mut n = 0;
        for (slot, c) in out.iter_mut().zip(self.world_circles(p, x)) {
            *slot = c;
            n += 1;
        }
        n
    }

    /// Whether this body's circles cover the rectangle x ∈ [x_min, x_max],
    /// |y| ≤ half_width of its frame. A sufficient test: a circle (a, b, r)
    /// with |b| + half_width ≤ r covers the full-height strip
    /// |x − a| ≤ √(r² − (|b| + half_width)²); the strips' union must cover
    /// [x_min, x_max].
    pub fn covers_body_rectangle(
        &self,
        body: Body,
        x_min: f64,
        x_max: f64,
        half_width: f64,
    ) -> bool {
        let mut strips: Vec<(f64, f64)> = self
            .circles
            .iter()
            .filter(|c| c.body == body)
            .filter_map(|c| {
                let h = c.offset[1].abs() + half_width;
                (c.radius >= h).then(|| {
                    let w = (c.radius * c.radius - h * h).sqrt();
                    (c.offset[0] - w, c.offset[0] + w)
                })
            })
            .collect();
        strips.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut reach = x_min;
        for (lo, hi) in strips {
            if lo > reach {
                break;
            }
            reach = reach.max(hi);
        }
        reach >= x_max
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacle::{footprint_clearance, Obstacle};
    use crate::site::geometry::{Circle, Shape};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_state(rng: &mut ChaCha8Rng, p: &MachineParams) -> State {
        State::new(
            rng.gen_range(-5.0..5.0),
            rng.gen_range(-5.0..5.0),
            rng.gen_range(-3.2..3.2),
            rng.gen_range(-p.beta_max..p.beta_max),
            0.0,
            0.0,
        )
    }

    #[test]
    fn axle_circles_reproduce_todays_footprint_clearance() {
        let p = MachineParams::default();
        let hw = 0.65;
        let outline = Outline::axle_circles(hw).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..500 {
            let x = random_state(&mut rng, &p);
            let (cx, cy, r) = (
                rng.gen_range(-6.0..6.0),
                rng.gen_range(-6.0..6.0),
                rng.gen_range(0.2..2.0),
            );
            let wire = [Obstacle::new(cx, cy, r + hw)];
            let physical = Shape::Circle(Circle {
                center: [cx, cy],
                radius: r,
            });
            let ours = outline
                .world_circles(&p, &x)
                .map(|c| physical.clearance(c.center, c.radius))
                .fold(f64::INFINITY, f64::min);
            assert!((ours - footprint_clearance(&p, &x, &wire)).abs() < 1e-12);
        }
    }

    #[test]
    fn world_centres_follow_the_body_frames() {
        // Heading +y, bent left 90°: the rear body heads along 0 rad.
        let p = MachineParams::default();
        let x = State::new(
            1.0,
            2.0,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
        );
        let front = OutlineCircle {
            body: Body::Front,
            offset: [1.0, 0.5],
            radius: 0.1,
        };
        let c = front.center(&p, &x);
        // Forward is +y, left is −x.
        assert!((c[0] - 0.5).abs() < 1e-12 && (c[1] - 3.0).abs() < 1e-12);
        let rear = OutlineCircle {
            body: Body::Rear,
            offset: [-0.7, 0.2],
            radius: 0.1,
        };
        // Joint (1, 1.4); rear axle L_r behind along 0 rad: (0.4, 1.4); the
        // offset's forward is +x, left +y.
        let c = rear.center(&p, &x);
        assert!(
            (c[0] + 0.3).abs() < 1e-12 && (c[1] - 1.6).abs() < 1e-12,
            "{c:?}"
        );
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let p = MachineParams {
            l_f: 0.9,
            l_r: 1.1,
            ..MachineParams::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for body in [Body::Front, Body::Rear] {
            for _ in 0..20 {
                let c = OutlineCircle {
                    body,
                    offset: [rng.gen_range(-1.5..1.5), rng.gen_range(-0.8..0.8)],
                    radius: 0.5,
                };
                let x = random_state(&mut rng, &p);
                let j = c.jacobian(&p, &x);
                for (k, i) in [ix::X, ix::Y, ix::THETA, ix::BETA].into_iter().enumerate() {
                    let e = 1e-6;
                    let (mut a, mut b) = (x, x);
                    a[i] += e;
                    b[i] -= e;
                    let (ca, cb) = (c.center(&p, &a), c.center(&p, &b));
                    for row in 0..2 {
                        let fd = (ca[row] - cb[row]) / (2.0 * e);
                        assert!((fd - j[row][k]).abs() < 1e-7, "{body:?} row {row} col {k}");
                    }
                }
            }
        }
    }

    /// Dense sampling of a body rectangle: every sample inside some circle.
    fn sampled_cover(o: &Outline, body: Body, x_min: f64, x_max: f64, hw: f64) -> bool {
        let n = 200;
        (0..=n).all(|i| {
            (0..=n).all(|j| {
                let q = [
                    x_min + (x_max - x_min) * i as f64 / n as f64,
                    -hw + 2.0 * hw * j as f64 / n as f64,
                ];
                o.circles()
                    .iter()
                    .filter(|c| c.body == body)
                    .any(|c| (q[0] - c.offset[0]).hypot(q[1] - c.offset[1]) <= c.radius)
            })
        })
    }

    #[test]
    fn published_outlines_cover_their_bodies() {
        let cases = [
            (
                Outline::avant635(),
                [(Body::Front, -0.6, 1.2), (Body::Rear, -0.7, 0.6)],
                0.65,
            ),
            (
                Outline::large_loader(),
                [(Body::Front, -0.9, 1.7), (Body::Rear, -1.2, 1.1)],
                0.9,
            ),
        ];
        for (o, bodies, hw) in cases {
            assert!(Outline::new(o.circles().to_vec(), o.half_width()).is_ok());
            for (body, lo, hi) in bodies {
                assert!(o.covers_body_rectangle(body, lo, hi, hw), "{body:?}");
                assert!(sampled_cover(&o, body, lo, hi, hw), "{body:?} sampled");
                // The test can fail: a rectangle 10 cm longer is not covered.
                assert!(!o.covers_body_rectangle(body, lo, hi + 0.1, hw));
                assert!(!sampled_cover(&o, body, lo, hi + 0.1, hw));
            }
        }
    }

    #[test]
    fn outline_validation_and_serde() {
        assert_eq!(Outline::new(vec![], 0.65), Err(OutlineError::Empty));
        let bad = OutlineCircle {
            body: Body::Rear,
            offset: [0.0, f64::NAN],
            radius: 1.0,
        };
        assert_eq!(
            Outline::new(vec![bad], 0.65),
            Err(OutlineError::BadCircle(0))
        );
        let o = Outline::avant635();
        let text = serde_json::to_string(&o).unwrap();
        let back: Outline = serde_json::from_str(&text).unwrap();
        assert_eq!(back, o);
        assert!(serde_json::from_str::<Outline>(r#"{"circles": []}"#).is_err());
        assert!(serde_json::from_str::<Outline>(
            r#"{"circles": [{"body": "front", "offset": [0, 0], "radius": 1, "extra": 1}]}"#
        )
        .is_err());
        let mut buf = [WorldCircle::default(); MAX_OUTLINE_CIRCLES];
        let p = MachineParams::default();
        let x = State::zeros();
        assert_eq!(o.place(&p, &x, &mut buf), 5);
        assert!((buf[0].center[0] + 0.3).abs() < 1e-12 && buf[4].radius == 0.73);
    }

    /// The truer outlines cover the default outline's axle discs of their
    /// half-width (points on and inside the discs, every articulation): a
    /// motion free for the truer outline is free for the default one, so the
    /// default's minimum-time bound is a lower bound for them too
    /// (scripts/measure-sites.sh).
    #[test]
    fn truer_outlines_cover_their_axle_discs() {
        let p = MachineParams::default();
        for (outline, hw) in [(Outline::avant635(), 0.65), (Outline::large_loader(), 0.9)] {
            for beta in [-0.6, 0.0, 0.6] {
                let x = State::new(0.0, 0.0, 0.3, beta, 0.0, 0.0);
                let centres = [
                    [x[crate::model::ix::X], x[crate::model::ix::Y]],
                    AxlePoint::Rear.position(&p, &x),
                ];
                for c in centres {
                    for k in 0..72 {
                        for r in [0.5 * hw, hw] {
                            let a = k as f64 * std::f64::consts::PI / 36.0;
                            let q = [c[0] + r * a.cos(), c[1] + r * a.sin()];
                            let covered = outline.world_circles(&p, &x).any(|w| {
                                (q[0] - w.center[0]).hypot(q[1] - w.center[1]) <= w.radius + 1e-9
                            });
                            assert!(covered, "{q:?} (β {beta}) outside the outline");
                        }
                    }
                }
            }
        }
    }
}
