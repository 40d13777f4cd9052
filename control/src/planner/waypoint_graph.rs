//! A critic-cost graph over waypoints (after Eysenbach et al., "Search on the
//! Replay Buffer", NeurIPS 2019): the goal-conditioned critic already knows
//! how far any pose is from any other in open ground, so a graph whose nodes
//! are poses that avoid the obstacles and whose edge costs are the critic's
//! cost-to-go strings local, obstacle-blind manoeuvres into a route.
//!
//! - Nodes: the start, the goal, and `ring_points` poses around every circle
//!   at radius + margin + `ring_offset`, heading along the ring both ways
//!   (the way around a circle is tangent to it); poses whose footprint does
//!   not keep the margin are dropped (most of a wall's inner rings).
//! - Edges, made when their node is first expanded: to the
//!   `graph_neighbours` nearest nodes ahead (bearing within ±100° of the
//!   node's heading) whose straight segment misses every circle, and to the
//!   goal. Estimated cost: the critic L(x_i at rest, 0, g_j) in seconds
//!   (× `seconds_per_cost`, fitted to actor roll-out times at construction:
//!   L is close to proportional to the time to go, see `docs/global-layer.md`).
//! - Search: lazy shortest path (LazySP) — A* on the estimates (heuristic:
//!   distance at top speed), then the found path's edges are checked in order
//!   by rolling the actor out from one node to the next against the circles
//!   (the MPC's own warm start does the same). A failed edge is removed and
//!   the search repeats; a checked edge costs its roll-out's time. At most
//!   `max_edge_checks` roll-outs per plan.
//!
//! Needs the networks. Allocation-free after construction.

use std::collections::BinaryHeap;
use std::time::Instant;

use crate::actor::{Actor, ActorWorkspace};
use crate::critic::{Critic, CriticWorkspace};
use crate::model::{ix, wrap_angle, Control, Goal, MachineParams, State};

use super::hybrid_astar::{SearchFailure, SearchStats};
use super::queue::Open;
use super::rollout::{roll_out, Arrival};
use super::world::World;
use super::{NavigatorSettings, PathPose};

/// Bearing window of an edge relative to its node's heading: the machine
/// leaves a waypoint roughly the way it arrived.
const AHEAD: f64 = 100.0 * std::f64::consts::PI / 180.0;
const START: usize = 0;
const GOAL: usize = 1;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EdgeState {
    Estimated,
    Checked,
    Invalid,
}

#[derive(Debug, Clone, Copy)]
struct Edge {
    to: u32,
    cost: f64,
    state: EdgeState,
}

/// The graph with its preallocated buffers.
#[derive(Debug, Clone)]
pub struct WaypointGraph {
    params: MachineParams,
    ring_points: usize,
    ring_offset: f64,
    neighbours: usize,
    max_edge_checks: usize,
    max_edge_length: f64,
    subgoal_radius: f64,
    shot_tolerance: f64,
    dt: f64,
    /// Seconds of actor roll-out per unit of critic cost-to-go.
    seconds_per_cost: f64,
    poses: Vec<[f64; 3]>,
    /// Edges of node i at `edges[i * neighbours' ..]`, `edge_count[i]` of
    /// them; `None` until the node is first expanded.
    edges: Vec<Edge>,
    edge_count: Vec<Option<usize>>,
    g: Vec<f64>,
    parent: Vec<u32>,
    /// The edge (index into `edges`) that set `parent`.
    parent_edge: Vec<u32>,
    closed: Vec<bool>,
    open: BinaryHeap<Open>,
    /// Scratch: candidate (distance, node) pairs of one expansion.
    candidates: Vec<(f64, u32)>,
    /// Scratch: the node sequence of the current path, goal first.
    chain: Vec<u32>,
}

impl WaypointGraph {
    /// Buffers for `settings.max_obstacles` circles; `seconds_per_cost` from
    /// [`calibrate`].
    pub fn new(params: MachineParams, s: &NavigatorSettings, seconds_per_cost: f64) -> Self {
        let max_nodes = 2 + 2 * s.ring_points * s.max_obstacles;
        // One slot more per node: the goal is always a candidate.
        let per_node = s.graph_neighbours + 1;
        Self {
            params,
            ring_points: s.ring_points,
            ring_offset: s.ring_offset,
            neighbours: s.graph_neighbours,
            max_edge_checks: s.max_edge_checks,
            max_edge_length: s.graph_edge_length,
            subgoal_radius: s.subgoal_radius,
            shot_tolerance: s.shot_tolerance,
            dt: s.rollout_dt,
            seconds_per_cost,
            poses: Vec::with_capacity(max_nodes),
            edges: vec![
                Edge {
                    to: 0,
                    cost: 0.0,
                    state: EdgeState::Invalid
                };
                max_nodes * per_node
            ],
            edge_count: vec![None; max_nodes],
            g: vec![0.0; max_nodes],
            parent: vec![u32::MAX; max_nodes],
            parent_edge: vec![0; max_nodes],
            closed: vec![false; max_nodes],
            open: BinaryHeap::with_capacity(max_nodes * per_node + 1),
            candidates: Vec::with_capacity(max_nodes),
            chain: Vec::with_capacity(max_nodes),
        }
    }

    fn per_node(&self) -> usize {
        self.neighbours + 1
    }

    /// Plans from `start` to `goal`; on success the path (start first, the
    /// goal last) is in `path`. Allocation-free.
    #[allow(clippy::too_many_arguments)]
    pub fn search(
        &mut self,
        world: &World,
        start: &State,
        goal: &Goal,
        actor: &Actor,
        actor_ws: &mut ActorWorkspace,
        critic: &Critic,
        critic_ws: &mut CriticWorkspace,
        path: &mut Vec<PathPose>,
    ) -> (Result<(), SearchFailure>, SearchStats) {
        let t0 = Instant::now();
        let mut stats = SearchStats::default();
        path.clear();
        self.build_nodes(world, start, goal);
        stats.nodes = self.poses.len();
        let mut checks = 0;
        let result = loop {
            if !self.shortest(world, goal, critic, critic_ws, &mut stats) {
                break Err(SearchFailure::Exhausted);
            }
            // The path's nodes, goal first.
            self.chain.clear();
            let mut k = GOAL as u32;
            while k != u32::MAX && self.chain.len() < self.chain.capacity() {
                self.chain.push(k);
                k = self.parent[k as usize];
            }
            // Check its estimated edges from the start on; the first failure
            // sends the search back.
            let mut all_checked = true;
            for w in (1..self.chain.len()).rev() {
                let (from, to) = (self.chain[w] as usize, self.chain[w - 1] as usize);
                let e = self.parent_edge[to] as usize;
                if self.edges[e].state == EdgeState::Checked {
                    continue;
                }
                if checks >= self.max_edge_checks {
                    all_checked = false;
                    break;
                }
                checks += 1;
                stats.shots += 1;
                let x = if from == START {
                    *start
                } else {
                    let p = self.poses[from];
                    State::new(p[0], p[1], p[2], 0.0, 0.0, 0.0)
                };
                let p = self.poses[to];
                let target = Goal::new(p[0], p[1], p[2]);
                let arrival = if to == GOAL {
                    Arrival::Pose(self.shot_tolerance)
                } else {
                    Arrival::Position(self.subgoal_radius)
                };
                // Up to three times the estimate, and never under 5 s.
                let budget = (3.0 * self.edges[e].cost).max(5.0);
                let steps = (budget / self.dt).ceil() as usize;
                let r = roll_out(
                    &self.params,
                    actor,
                    actor_ws,
                    world,
                    &x,
                    &target,
                    arrival,
                    self.dt,
                    steps,
                    None,
                );
                if r.reached {
                    self.edges[e].state = EdgeState::Checked;
                    self.edges[e].cost = r.duration(self.dt);
                } else {
                    self.edges[e].state = EdgeState::Invalid;
                    all_checked = false;
                    break;
                }
            }
            if all_checked {
                for &k in self.chain.iter().rev() {
                    let p = self.poses[k as usize];
                    path.push(PathPose {
                        x: p[0],
                        y: p[1],
                        theta: p[2],
                        beta: if k as usize == START {
                            start[ix::BETA]
                        } else {
                            0.0
                        },
                        direction: 1,
                    });
                }
                break Ok(());
            }
            if checks >= self.max_edge_checks {
                break Err(SearchFailure::Budget);
            }
        };
        stats.duration = t0.elapsed();
        (result, stats)
    }

    fn build_nodes(&mut self, world: &World, start: &State, goal: &Goal) {
        self.poses.clear();
        self.poses
            .push([start[ix::X], start[ix::Y], start[ix::THETA]]);
        self.poses.push([goal.x, goal.y, goal.theta]);
        let margin = world.margin();
        for o in world.obstacles() {
            let r = o.radius + margin + self.ring_offset;
            for k in 0..self.ring_points {
                let a = k as f64 * std::f64::consts::TAU / self.ring_points as f64;
                let (x, y) = (o.x + r * a.cos(), o.y + r * a.sin());
                for heading in [
                    a + std::f64::consts::FRAC_PI_2,
                    a - std::f64::consts::FRAC_PI_2,
                ] {
                    let heading = wrap_angle(heading);
                    if self.poses.len() < self.poses.capacity()
                        && world.pose_free(x, y, heading, 0.0)
                    {
                        self.poses.push([x, y, heading]);
                    }
                }
            }
        }
        let n = self.poses.len();
        self.edge_count[..n].fill(None);
        self.g[..n].fill(f64::INFINITY);
        self.parent[..n].fill(u32::MAX);
    }

    /// A* over the current edge costs; true when the goal was reached.
    fn shortest(
        &mut self,
        world: &World,
        goal: &Goal,
        critic: &Critic,
        critic_ws: &mut CriticWorkspace,
        stats: &mut SearchStats,
    ) -> bool {
        let n = self.poses.len();
        self.g[..n].fill(f64::INFINITY);
        self.parent[..n].fill(u32::MAX);
        self.closed[..n].fill(false);
        self.open.clear();
        self.g[START] = 0.0;
        self.open.push(Open {
            f: self.h(START, goal),
            node: START as u32,
        });
        while let Some(Open { node, .. }) = self.open.pop() {
            let i = node as usize;
            if self.closed[i] {
                continue;
            }
            self.closed[i] = true;
            if i == GOAL {
                return true;
            }
            stats.expansions += 1;
            if self.edge_count[i].is_none() {
                self.make_edges(i, world, critic, critic_ws);
            }
            let base = i * self.per_node();
            for e in base..base + self.edge_count[i].unwrap_or(0) {
                let edge = self.edges[e];
                let j = edge.to as usize;
                if edge.state == EdgeState::Invalid || self.closed[j] {
                    continue;
                }
                let g = self.g[i] + edge.cost;
                if g < self.g[j] && self.open.len() < self.open.capacity() {
                    self.g[j] = g;
                    self.parent[j] = i as u32;
                    self.parent_edge[j] = e as u32;
                    self.open.push(Open {
                        f: g + self.h(j, goal),
                        node: j as u32,
                    });
                }
            }
        }
        false
    }

    /// Remaining time at top speed in a straight line: a lower bound.
    fn h(&self, i: usize, goal: &Goal) -> f64 {
        let p = self.poses[i];
        (p[0] - goal.x).hypot(p[1] - goal.y) / self.params.v_max
    }

    fn make_edges(&mut self, i: usize, world: &World, critic: &Critic, ws: &mut CriticWorkspace) {
        let p = self.poses[i];
        self.candidates.clear();
        for (j, q) in self.poses.iter().enumerate() {
            if j == i || j == START || j == GOAL {
                continue;
            }
            let d = (q[0] - p[0]).hypot(q[1] - p[1]);
            let bearing = (q[1] - p[1]).atan2(q[0] - p[0]);
            if d <= self.max_edge_length
                && wrap_angle(bearing - p[2]).abs() <= AHEAD
                && world.segment_clear([p[0], p[1]], [q[0], q[1]], 0.0)
            {
                self.candidates.push((d, j as u32));
            }
        }
        let k = self.neighbours.min(self.candidates.len());
        if k > 0 {
            self.candidates
                .select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        }
        let base = i * self.per_node();
        let mut count = 0;
        let x = State::new(p[0], p[1], p[2], 0.0, 0.0, 0.0);
        let goal_pose = self.poses[GOAL];
        // The goal is always a candidate (its edge decides whether a shot works).
        let goal_ok = world.segment_clear([p[0], p[1]], [goal_pose[0], goal_pose[1]], 0.0);
        for c in 0..k + usize::from(goal_ok) {
            let j = if c < k {
                self.candidates[c].1
            } else {
                GOAL as u32
            };
            let q = self.poses[j as usize];
            let target = Goal::new(q[0], q[1], q[2]);
            let cost = self.seconds_per_cost * critic.value(ws, &x, &Control::zeros(), &target);
            self.edges[base + count] = Edge {
                to: j,
                cost: cost.max(0.0),
                state: EdgeState::Estimated,
            };
            count += 1;
        }
        self.edge_count[i] = Some(count);
    }
}

/// Fits seconds per unit of critic cost-to-go: the actor rolled out from rest
/// at the origin to goals 2–10 m away at a few bearings and headings; least
/// squares through the origin of roll-out time against L(x₀, 0, g).
pub fn calibrate(
    params: &MachineParams,
    actor: &Actor,
    actor_ws: &mut ActorWorkspace,
    critic: &Critic,
    critic_ws: &mut CriticWorkspace,
    dt: f64,
    tolerance: f64,
) -> Option<f64> {
    let world = World::new(*params, 0, 0.0);
    let x0 = State::zeros();
    let (mut lt, mut ll) = (0.0, 0.0);
    for d in [2.0, 4.0, 7.0, 10.0] {
        for bearing in [0.0f64, 45.0, 90.0] {
            for heading in [0.0f64, 90.0] {
                let b = bearing.to_radians();
                let g = Goal::new(d * b.cos(), d * b.sin(), b + heading.to_radians());
                let r = roll_out(
                    params,
                    actor,
                    actor_ws,
                    &world,
                    &x0,
                    &g,
                    Arrival::Pose(tolerance),
                    dt,
                    (30.0 / dt) as usize,
                    None,
                );
                if r.reached {
                    let l = critic.value(critic_ws, &x0, &Control::zeros(), &g);
                    lt += l * r.duration(dt);
                    ll += l * l;
                }
            }
        }
    }
    (ll > 0.0 && lt > 0.0).then(|| lt / ll)
}
