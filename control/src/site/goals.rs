//! Goal sets on a site (DESIGN §17, issue 40): seeded scenarios whose world
//! is the site (their `obstacles` column is empty), with V-shaped loading
//! cycles between a pile face and a truck, and random goals whose straight
//! line is mostly blocked. Pure and deterministic: same site, parameters,
//! seed and count, same scenarios (byte for byte through
//! [`crate::scenario::to_csv`]).
//!
//! The committed sets (`control/tests/sites.rs` checks each equals this
//! generator's output):
//!
//! ```text
//! cargo run -p control --example site_goals -- sim/sites/quarry.json 40 40 > sim/scenarios/site-quarry.csv
//! cargo run -p control --example site_goals -- sim/sites/yard.json 40 40 > sim/scenarios/site-yard.csv
//! cargo run -p control --example site_goals -- sim/sites/lane.json 40 40 > sim/scenarios/site-lane.csv
//! cargo run -p control --example site_goals -- sim/sites/large-pit-40.json 40 40 > sim/scenarios/site-large-pit-40.csv
//! ```
//!
//! Every pose (starts at rest with β = 0, goals with β = 0) is at least
//! [`MARGIN`] from every feature, keep-out and the bounds for both the
//! default outline ([`crate::world::default_outline`]) and the Avant 635's
//! ([`Outline::avant635`]): the goal check cannot reject it and the machine
//! can start there.
//!
//! **V-cycles** (named `vcycle{k:02}_{leg}`, k from 1): a *pile face* — the
//! machine's front axle on the line from the pile's nearest point, heading at
//! that point, the Avant 635's bucket circle (its foremost front circle)
//! [`FACE_CLEARANCE`] from the pile — then a *back-out* 3–5 m behind it,
//! reached reversing while turning 40–70° (the V's vertex, turned so that
//! its heading points at the other arm's end), then a *truck side* pose
//! facing a long side of the truck (its polygon's longest edges, ±8° off the
//! perpendicular) at the same clearance of the bucket, then a second
//! back-out reversing away from the truck. Four legs, each a scenario whose
//! start is the previous leg's goal at rest:
//! `a_backout` (pile face → back-out), `b_truck` (back-out → truck side),
//! `c_backout` (truck side → back-out 2), `d_pile` (back-out 2 → the pile
//! face again: the cycle closes). The truck: the features whose ids start
//! with `truck`, nearest first, its side within [`CYCLE_REACH`] of the pile
//! face (a pile with no truck that near gives no cycle). A site without a
//! truck (the lane: two rows of piles; the large pit) loads and dumps
//! between piles: a face of another pile 5–25 m away (centre to centre)
//! plays the truck, the pile most nearly behind the machine at the first
//! face tried first: in the lane, a pile of the other row, across the lane.
//! The reversing turns are checked by a filter only (the arc's poses at
//! β = 0 clear of everything), not by a route search: whether a route
//! exists is the planner's question.
//!
//! **Random goals** (named `goal{k:03}`, k from 1): a start at rest anywhere
//! inside the bounds, free; a goal 6–30 m away, free, with any heading;
//! three in four have their straight line blocked (a disc of the default
//! outline's radius swept from start to goal meets something), when one is
//! found within the tries.
//!
//! The route search's square (`[navigator.search] workspace_half_size`:
//! 2 × 20 m a side by default, centred between start and goal) bounds what
//! the planner can solve; [`CYCLE_REACH`] keeps the V-cycle legs within
//! 27 m. With the former 14 m, 1 of the 40 in the quarry and 1 in the lane
//! had no route (checked with `RoutePlanner` and the shipped actor when the
//! sets were made); the default was raised for them.
//!
//! Counts: `count` scenarios in all; V-cycles take `max(3, count / 10)`
//! cycles (4 legs each; at least 12 legs) when the site has a pile and a
//! truck or two piles, and at most `count / 4` cycles when `count` < 12.
//! Rejection sampling with bounded tries: a site that cannot give what is
//! asked returns what it could in a [`Shortfall`] naming what is missing.
//!
//! Poses are rounded (mm, 0.1 mrad) before they are checked, so the file's
//! numbers are the numbers checked.

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geometry::{Shape, P2};
use super::outline::{Body, Outline, MAX_OUTLINE_CIRCLES};
use super::SiteIndex;
use crate::model::{wrap_angle, Goal, MachineParams, State};
use crate::scenario::Scenario;
use crate::world::{default_outline, World};

/// Least clearance of every pose to everything, for both outlines [m].
pub const MARGIN: f64 = 0.3;
/// Clearance of the bucket circle to the pile or truck it faces [m].
pub const FACE_CLEARANCE: (f64, f64) = (0.3, 0.6);
/// Fewest V-cycle legs asked of a site with piles and a truck (or two piles).
pub const MIN_VCYCLE_LEGS: usize = 12;
/// Distance of a back-out from the pose it reverses out of [m].
pub const BACKOUT_DISTANCE: (f64, f64) = (3.0, 5.0);
/// Heading change while backing out [deg].
pub const BACKOUT_TURN_DEG: (f64, f64) = (40.0, 70.0);
/// Start–goal distance of a random goal [m].
pub const GOAL_DISTANCE: (f64, f64) = (6.0, 30.0);
/// Centre distance of a pile that stands in for the truck [m].
pub const STAND_IN_DISTANCE: (f64, f64) = (5.0, 25.0);

/// Distance between a V-cycle's pile face and its truck side (front axles)
/// [m]: a truck farther than this is not the pile's.
pub const CYCLE_REACH: (f64, f64) = (3.0, 22.0);

/// The legs of a V-cycle, in order.
pub const LEGS: [&str; 4] = ["a_backout", "b_truck", "c_backout", "d_pile"];

const FACE_TRIES: usize = 60;
const BACKOUT_TRIES: usize = 60;
const CYCLE_TRIES_PER_PILE: usize = 6;
const START_TRIES: usize = 2000;
const GOAL_TRIES: usize = 80;
const RANDOM_TRIES_PER_GOAL: usize = 40;

/// What a site could not give: the scenarios it could, and why not more.
#[derive(Debug, Clone, PartialEq)]
pub struct Shortfall {
    pub scenarios: Vec<Scenario>,
    pub missing: Vec<String>,
}

impl std::fmt::Display for Shortfall {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} scenarios only: {}",
            self.scenarios.len(),
            self.missing.join("; ")
        )
    }
}

impl std::error::Error for Shortfall {}

/// A pose of the front axle: x, y, θ.
type Pose = [f64; 3];

fn round_pose(p: Pose) -> Pose {
    let mm = |v: f64| (v * 1000.0).round() / 1000.0;
    [mm(p[0]), mm(p[1]), (wrap_angle(p[2]) * 1e4).round() / 1e4]
}

fn at_rest(p: Pose) -> State {
    State::new(p[0], p[1], p[2], 0.0, 0.0, 0.0)
}

fn dir(a: f64) -> P2 {
    [a.cos(), a.sin()]
}

fn centre(shape: &Shape) -> P2 {
    let b = shape.aabb();
    [0.5 * (b.min[0] + b.max[0]), 0.5 * (b.min[1] + b.max[1])]
}

/// Whether the pose keeps `margin` from everything for every outline.
fn clear_of(worlds: &[World], p: Pose, margin: f64) -> bool {
    let x = at_rest(p);
    let margins = [margin; MAX_OUTLINE_CIRCLES];
    worlds.iter().all(|w| w.excess(&x, &margins, 0.0).is_none())
}

/// The least clearance of the pose (at rest, β = 0) to anything in `site`
/// over both outlines (the default and the Avant 635's) [m].
pub fn pose_clearance(site: &Arc<SiteIndex>, params: &MachineParams, p: Pose) -> f64 {
    [default_outline(), Outline::avant635()]
        .into_iter()
        .map(|o| {
            let mut w = World::new(*params, o, 0);
            w.set_site(Some(site.clone()));
            w.clearance(&at_rest(p))
        })
        .fold(f64::INFINITY, f64::min)
}

struct Gen<'a> {
    site: &'a Arc<SiteIndex>,
    params: MachineParams,
    /// The default outline's world, then the Avant 635's.
    worlds: [World; 2],
    /// The Avant 635's foremost front circle (its bucket): offset, radius.
    bucket: (P2, f64),
    rng: ChaCha8Rng,
}

impl Gen<'_> {
    fn free(&self, p: Pose) -> bool {
        clear_of(&self.worlds, p, MARGIN)
    }

    fn shape(&self, f: usize) -> &Shape {
        &self.site.site().features()[f].shape
    }

    /// Clearance of the bucket circle at pose `p` to `shape`.
    fn bucket_clearance(&self, p: Pose, shape: &Shape) -> f64 {
        let (s, c) = p[2].sin_cos();
        let (o, r) = self.bucket;
        let q = [p[0] + c * o[0] - s * o[1], p[1] + s * o[0] + c * o[1]];
        shape.clearance(q, r)
    }

    fn face_ok(&self, p: Pose, shape: &Shape) -> bool {
        let c = self.bucket_clearance(p, shape);
        (FACE_CLEARANCE.0..=FACE_CLEARANCE.1).contains(&c) && self.free(p)
    }

    /// A pile face: heading at the pile's nearest point, the bucket at a
    /// clearance drawn in the face range.
    fn pile_face(&mut self, f: usize) -> Option<Pose> {
        let shape = self.shape(f).clone();
        let c = centre(&shape);
        let b = shape.aabb();
        let ext = 0.5 * (b.max[0] - b.min[0]).hypot(b.max[1] - b.min[1]);
        let reach = self.bucket.0[0] + self.bucket.1;
        for _ in 0..FACE_TRIES {
            let psi = self.rng.gen_range(0.0..std::f64::consts::TAU);
            let t = self.rng.gen_range(0.33..0.55);
            let d = dir(psi);
            let mut p = [
                c[0] + (ext + reach + t) * d[0],
                c[1] + (ext + reach + t) * d[1],
            ];
            let mut ok = true;
            for _ in 0..6 {
                let near = shape.nearest(p);
                if near.distance <= 1e-6 {
                    ok = false;
                    break;
                }
                let u = [
                    (near.point[0] - p[0]) / near.distance,
                    (near.point[1] - p[1]) / near.distance,
                ];
                let cb = self.bucket_clearance([p[0], p[1], u[1].atan2(u[0])], &shape);
                p = [p[0] - (t - cb) * u[0], p[1] - (t - cb) * u[1]];
            }
            if !ok {
                continue;
            }
            let near = shape.nearest(p);
            if near.distance <= 1e-6 {
                continue;
            }
            let theta = (near.point[1] - p[1]).atan2(near.point[0] - p[0]);
            let pose = round_pose([p[0], p[1], theta]);
            if self.face_ok(pose, &shape) {
                return Some(pose);
            }
        }
        None
    }

    /// A truck side: facing one of the truck polygon's longest edges (within
    /// 80 % of the longest), ±8° off its perpendicular. A truck of another
    /// shape is faced like a pile.
    fn truck_side(&mut self, f: usize) -> Option<Pose> {
        let shape = self.shape(f).clone();
        let Shape::Polygon(g) = &shape else {
            return self.pile_face(f);
        };
        let n = g.vertices().len();
        let len = |i: usize| {
            let (a, b) = g.edge(i);
            (b[0] - a[0]).hypot(b[1] - a[1])
        };
        let longest = (0..n).map(len).fold(0.0, f64::max);
        let sides: Vec<usize> = (0..n).filter(|&i| len(i) >= 0.8 * longest).collect();
        let reach = self.bucket.0[0] + self.bucket.1;
        for _ in 0..FACE_TRIES {
            let i = sides[self.rng.gen_range(0..sides.len())];
            let (a, b) = g.edge(i);
            let s = self.rng.gen_range(0.25..0.75);
            let q = [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])];
            let nrm = g.outward_normal(i);
            let jitter = self.rng.gen_range(-8.0f64..8.0).to_radians();
            let theta = (-nrm[1]).atan2(-nrm[0]) + jitter;
            let u = dir(theta);
            let t = self.rng.gen_range(0.33..0.55);
            let mut p = [q[0] - (reach + t) * u[0], q[1] - (reach + t) * u[1]];
            for _ in 0..6 {
                let cb = self.bucket_clearance([p[0], p[1], theta], &shape);
                p = [p[0] - (t - cb) * u[0], p[1] - (t - cb) * u[1]];
            }
            let pose = round_pose([p[0], p[1], theta]);
            if self.face_ok(pose, &shape) {
                return Some(pose);
            }
        }
        None
    }

    /// A back-out: reversing 3–5 m (chord) out of `from` while turning
    /// 40–70°, the turn's side chosen so the end heading points more at
    /// `toward` (the other side after half the tries). The arc's poses at
    /// β = 0 must clear everything.
    fn backout(&mut self, from: Pose, toward: P2) -> Option<Pose> {
        // Which side points the end heading more at `toward`.
        let to = (toward[1] - from[1]).atan2(toward[0] - from[0]);
        let mid = 0.5 * (BACKOUT_TURN_DEG.0 + BACKOUT_TURN_DEG.1).to_radians();
        let score = |s: f64| (from[2] + s * mid - to).cos();
        let preferred = if score(1.0) >= score(-1.0) { 1.0 } else { -1.0 };
        // The tightest turn the machine can make: R = (L_f cos β + L_r) / sin β.
        let bm = self.params.beta_max;
        let r_min = (self.params.l_f * bm.cos() + self.params.l_r) / bm.sin();
        for k in 0..BACKOUT_TRIES {
            let side = if k < BACKOUT_TRIES / 2 {
                preferred
            } else {
                -preferred
            };
            let d = self.rng.gen_range(BACKOUT_DISTANCE.0..BACKOUT_DISTANCE.1);
            let turn = self
                .rng
                .gen_range(BACKOUT_TURN_DEG.0..BACKOUT_TURN_DEG.1)
                .to_radians();
            // The arc of chord d over `turn`: radius d / (2 sin(turn / 2)).
            let r = d / (2.0 * (0.5 * turn).sin());
            if r < 1.1 * r_min {
                continue;
            }
            let arc = |lambda: f64| {
                let a = lambda * turn;
                let chord = 2.0 * r * (0.5 * a).sin();
                let h = dir(from[2] + side * 0.5 * a);
                [
                    from[0] - chord * h[0],
                    from[1] - chord * h[1],
                    from[2] + side * a,
                ]
            };
            let pose = round_pose(arc(1.0));
            if !self.free(pose) {
                continue;
            }
            if (1..8).all(|j| clear_of(&self.worlds, arc(j as f64 / 8.0), 0.0)) {
                return Some(pose);
            }
        }
        None
    }

    /// One V-cycle from pile `pile` to one of `targets` (trucks or stand-in
    /// piles): its four poses (pile face, back-out, truck side, back-out 2).
    fn cycle(&mut self, pile: usize, targets: &[usize], trucks: bool) -> Option<[Pose; 4]> {
        for _ in 0..CYCLE_TRIES_PER_PILE {
            let Some(face) = self.pile_face(pile) else {
                continue;
            };
            let mut order: Vec<usize> = targets.iter().copied().filter(|&t| t != pile).collect();
            if trucks {
                // Nearest truck first.
                let fc = [face[0], face[1]];
                order.sort_by(|&a, &b| {
                    let da = self.shape(a).signed_distance(fc);
                    let db = self.shape(b).signed_distance(fc);
                    da.total_cmp(&db)
                });
            } else {
                // Other piles 5–25 m away (centre to centre), the one most
                // nearly behind the machine at the face first: across the
                // lane in a lane.
                let pc = centre(self.shape(pile));
                order.retain(|&t| {
                    let c = centre(self.shape(t));
                    let d = (c[0] - pc[0]).hypot(c[1] - pc[1]);
                    (STAND_IN_DISTANCE.0..=STAND_IN_DISTANCE.1).contains(&d)
                });
                let back = dir(face[2] + std::f64::consts::PI);
                let behind = |c: P2| {
                    let v = [c[0] - face[0], c[1] - face[1]];
                    (v[0] * back[0] + v[1] * back[1]) / v[0].hypot(v[1]).max(1e-9)
                };
                order.sort_by(|&a, &b| {
                    behind(centre(self.shape(b))).total_cmp(&behind(centre(self.shape(a))))
                });
            }
            for t in order {
                let side = if trucks {
                    self.truck_side(t)
                } else {
                    self.pile_face(t)
                };
                let Some(side) = side else {
                    continue;
                };
                let reach = (side[0] - face[0]).hypot(side[1] - face[1]);
                if !(CYCLE_REACH.0..=CYCLE_REACH.1).contains(&reach) {
                    continue;
                }
                let Some(b1) = self.backout(face, [side[0], side[1]]) else {
                    continue;
                };
                let Some(b2) = self.backout(side, [face[0], face[1]]) else {
                    continue;
                };
                return Some([face, b1, side, b2]);
            }
        }
        None
    }

    /// A random scenario: a free start, a free goal 6–30 m away; its
    /// straight line blocked if `blocked` and one is found.
    fn random_goal(&mut self, blocked: bool) -> Option<(Pose, Pose)> {
        let b = self.site.site().bounds().aabb();
        let mut fallback = None;
        for _ in 0..RANDOM_TRIES_PER_GOAL {
            let start = (0..START_TRIES).find_map(|_| {
                let p = round_pose([
                    self.rng.gen_range(b.min[0]..b.max[0]),
                    self.rng.gen_range(b.min[1]..b.max[1]),
                    self.rng
                        .gen_range(-std::f64::consts::PI..std::f64::consts::PI),
                ]);
                self.free(p).then_some(p)
            })?;
            for _ in 0..GOAL_TRIES {
                let d = self.rng.gen_range(GOAL_DISTANCE.0..GOAL_DISTANCE.1);
                let a = self.rng.gen_range(0.0..std::f64::consts::TAU);
                let goal = round_pose([
                    start[0] + d * a.cos(),
                    start[1] + d * a.sin(),
                    self.rng
                        .gen_range(-std::f64::consts::PI..std::f64::consts::PI),
                ]);
                if !self.free(goal) {
                    continue;
                }
                let r = self.worlds[0].outline().half_width();
                let is_blocked =
                    !self.worlds[0].segment_clear([start[0], start[1]], [goal[0], goal[1]], r, 0.0);
                if is_blocked == blocked {
                    return Some((start, goal));
                }
                fallback.get_or_insert((start, goal));
            }
        }
        fallback
    }
}

fn shuffle<T>(rng: &mut ChaCha8Rng, v: &mut [T]) {
    for k in (1..v.len()).rev() {
        let m = rng.gen_range(0..=k);
        v.swap(k, m);
    }
}

fn scenario(name: String, from: Pose, to: Pose) -> Scenario {
    Scenario {
        name,
        start: at_rest(from),
        goal: Goal::new(to[0], to[1], to[2]),
        obstacles: Vec::new(),
    }
}

/// The outline's foremost front circle (the bucket): offset and radius.
fn bucket_of(outline: &Outline) -> (P2, f64) {
    outline
        .circles()
        .iter()
        .filter(|c| c.body == Body::Front)
        .max_by(|a, b| a.offset[0].total_cmp(&b.offset[0]))
        .map(|c| (c.offset, c.radius))
        .unwrap_or(([0.0, 0.0], outline.max_radius()))
}

/// How many V-cycles a set of `count` asks for (module docs).
pub fn vcycles_wanted(count: usize) -> usize {
    if count >= MIN_VCYCLE_LEGS {
        (MIN_VCYCLE_LEGS / 4).max(count / 10)
    } else {
        count / 4
    }
}

/// The site's goal set (module docs): V-cycles first (when the site has a
/// pile and a truck, or two piles), then random goals, `count` in all.
pub fn site_scenarios(
    site: &Arc<SiteIndex>,
    params: &MachineParams,
    seed: u64,
    count: usize,
) -> Result<Vec<Scenario>, Shortfall> {
    let avant = Outline::avant635();
    let bucket = bucket_of(&avant);
    let mut worlds = [
        World::new(*params, default_outline(), 0),
        World::new(*params, avant, 0),
    ];
    for w in &mut worlds {
        w.set_site(Some(site.clone()));
    }
    let mut g = Gen {
        site,
        params: *params,
        worlds,
        bucket,
        rng: ChaCha8Rng::seed_from_u64(seed),
    };
    let features = site.site().features();
    let ids = |prefix: &str| -> Vec<usize> {
        (0..features.len())
            .filter(|&i| features[i].id.starts_with(prefix))
            .collect()
    };
    let piles = ids("pile");
    let trucks = ids("truck");
    let has_trucks = !trucks.is_empty();
    let targets = if has_trucks { trucks } else { piles.clone() };
    let asks_cycles = !piles.is_empty() && (has_trucks || piles.len() >= 2);

    let mut out = Vec::with_capacity(count);
    let mut missing = Vec::new();
    let wanted = if asks_cycles {
        vcycles_wanted(count)
    } else {
        0
    };
    if wanted > 0 {
        let mut order = piles.clone();
        shuffle(&mut g.rng, &mut order);
        let mut made = 0;
        // Round robin over the piles; a pile that gives no cycle is dropped.
        let mut live = order;
        let mut k = 0;
        while made < wanted && !live.is_empty() {
            let at = k % live.len();
            let pile = live[at];
            match g.cycle(pile, &targets, has_trucks) {
                Some(poses) => {
                    made += 1;
                    for (leg, name) in LEGS.iter().enumerate() {
                        out.push(scenario(
                            format!("vcycle{made:02}_{name}"),
                            poses[leg],
                            poses[(leg + 1) % 4],
                        ));
                    }
                    k += 1;
                }
                None => {
                    live.remove(at);
                }
            }
        }
        if made < wanted {
            missing.push(format!(
                "{} of {} V-cycles ({} of {} legs): no pile face with a {} and back-outs found",
                made,
                wanted,
                4 * made,
                4 * wanted,
                if has_trucks {
                    "truck side"
                } else {
                    "second pile's face"
                }
            ));
        }
    }
    let randoms = count.saturating_sub(out.len());
    for k in 0..randoms {
        match g.random_goal(k % 4 != 3) {
            Some((s, t)) => out.push(scenario(format!("goal{:03}", k + 1), s, t)),
            None => {
                missing.push(format!(
                    "{} of {randoms} random goals: no free start and goal found",
                    k
                ));
                break;
            }
        }
    }
    if missing.is_empty() {
        Ok(out)
    } else {
        Err(Shortfall {
            scenarios: out,
            missing,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::Site;

    fn small_site(obstacles: &str) -> Arc<SiteIndex> {
        let text = format!(
            r#"{{"format": "wlnav-site-v1", "id": "t", "version": 1,
                "bounds": [[0, 0], [40, 0], [40, 30], [0, 30]],
                "obstacles": [{obstacles}]}}"#
        );
        Arc::new(SiteIndex::new(Site::parse(text.as_bytes()).expect("valid")))
    }

    #[test]
    fn same_seed_same_set_and_every_pose_is_free() {
        let site = small_site(
            r#"{"id": "pile-1", "circle": [10, 20, 2.5]},
               {"id": "pile-2", "polygon": [[25, 18], [30, 18], [30, 23], [25, 23]]},
               {"id": "truck-1", "polygon": [[16, 5], [24, 5], [24, 7.5], [16, 7.5]]},
               {"id": "rock-1", "circle": [20, 14, 1.0]}"#,
        );
        let p = MachineParams::default();
        let a = site_scenarios(&site, &p, 7, 40).expect("an open site gives everything");
        let b = site_scenarios(&site, &p, 7, 40).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, site_scenarios(&site, &p, 8, 40).unwrap());
        assert_eq!(a.len(), 40);
        let legs = a.iter().filter(|s| s.name.starts_with("vcycle")).count();
        assert_eq!(legs, 16);
        for s in &a {
            let start = [s.start[0], s.start[1], s.start[2]];
            let goal = [s.goal.x, s.goal.y, s.goal.theta];
            for q in [start, goal] {
                assert!(pose_clearance(&site, &p, q) >= MARGIN - 1e-9, "{}", s.name);
            }
        }
        // Pile faces and truck sides: the bucket at the face clearance.
        let truck = &site.site().find("truck-1").unwrap().1.shape;
        for s in a.iter().filter(|s| s.name.ends_with("_b_truck")) {
            let g = Gen {
                site: &site,
                params: p,
                worlds: [
                    World::new(p, default_outline(), 0),
                    World::new(p, Outline::avant635(), 0),
                ],
                bucket: bucket_of(&Outline::avant635()),
                rng: ChaCha8Rng::seed_from_u64(0),
            };
            let c = g.bucket_clearance([s.goal.x, s.goal.y, s.goal.theta], truck);
            assert!((0.3..=0.6).contains(&c), "{}: {c}", s.name);
        }
    }

    #[test]
    fn a_site_without_room_says_what_is_missing() {
        // A pile and a truck with no room beside either: no V-cycle.
        let text = r#"{"format": "wlnav-site-v1", "id": "t", "version": 1,
            "bounds": [[0, 0], [12, 0], [12, 3], [0, 3]],
            "obstacles": [{"id": "pile-1", "circle": [2, 1.5, 1.4]},
                          {"id": "truck-1", "polygon": [[7.5, 0.2], [11, 0.2], [11, 2.8], [7.5, 2.8]]}]}"#;
        let site = Arc::new(SiteIndex::new(Site::parse(text.as_bytes()).unwrap()));
        let e = site_scenarios(&site, &MachineParams::default(), 1, 40).unwrap_err();
        assert!(e.missing[0].contains("0 of 4 V-cycles"), "{e}");
        assert!(e.missing.iter().any(|m| m.contains("random goals")), "{e}");
    }
}
