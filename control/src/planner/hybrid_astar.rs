//! Hybrid A* over the front axle's (x, y, θ) (Dolgov et al. 2008; the planner
//! of Nav2's Smac Hybrid-A*): nodes carry continuous poses, a 3D grid of
//! (cell, heading bin) keeps one node per cell, successors are the model's
//! [`Primitive`]s (forward and reverse arcs at a few articulations), and every
//! sample of a successor is checked with BOTH axle points against the circles.
//!
//! Cost [m]: arc length, × `reverse_penalty` when reversing; plus the time an
//! articulation change takes (|Δβ| / β̇_max at top speed, as metres) and
//! `direction_change_penalty` at a cusp (stop and restart). Heuristic: the
//! largest of the Euclidean distance, the 2D obstacle-aware grid distance
//! ([`ObstacleHeuristic`]) and the arc the heading error needs at the tightest
//! turn, each reduced by its tolerance so it stays a lower bound.
//!
//! Goal: a node inside the goal region (position and heading tolerances), or
//! a successful goal shot: the actor rolled out from the node reaches the goal
//! pose without touching the margin (the MPC drives the last leg itself, so
//! the shot checks exactly what will happen; Nav2 shoots a Reeds–Shepp curve).
//! The first way found is not taken at once: a shot from a node that heads
//! away from the goal reaches it on a wide loop. The search goes on for
//! `refine_expansions` and keeps the cheapest, a shot priced at its duration
//! at top speed (the edges' metres of time).
//!
//! Bounded: at most `max_expansions` expansions, at most `max_nodes` nodes
//! (pool and heap preallocated), a grid allocated once. Allocation-free after
//! construction.

use std::collections::BinaryHeap;
use std::time::{Duration, Instant};

use crate::actor::{Actor, ActorWorkspace};
use crate::model::{ix, wrap_angle, Goal, MachineParams, State};

use super::grid::{GridFrame, ObstacleHeuristic};
use super::primitives::{self, compose, Primitive};
use super::queue::Open;
use super::rollout::{roll_out, Arrival};
use super::world::CheckedWorld;
use super::{PathPose, SearchSettings};

/// Why a search ended without a route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchFailure {
    /// The 2D grid shows the goal cannot be reached from the start's cell.
    Unreachable,
    /// The open set emptied: every reachable pose was expanded.
    Exhausted,
    /// `max_expansions` or `max_nodes` ran out first.
    Budget,
}

/// What one search did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SearchStats {
    pub expansions: usize,
    pub nodes: usize,
    pub shots: usize,
    pub duration: Duration,
    /// The cost of the way found [m of time] (0 without one).
    pub cost: f64,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    pose: [f64; 3],
    beta: f64,
    direction: i8,
    g: f64,
    parent: u32,
    closed: bool,
}

const NO_PARENT: u32 = u32::MAX;

/// Steps of a goal shot over `dist`: the distance at a cautious pace plus the
/// final approach.
pub(super) fn shot_steps(dist: f64, dt: f64) -> usize {
    ((2.0 * dist + 8.0) / dt).ceil() as usize
}

/// Both axle points keep the margin along `prim` driven from `pose` (every
/// sample, at the primitive's articulation). Articulating from the node's
/// `beta` to the primitive's swings the rear axle about the joint at the
/// start pose, so the start pose is checked with the new β too.
pub fn primitive_free(world: &CheckedWorld, pose: &[f64; 3], beta: f64, prim: &Primitive) -> bool {
    if (prim.beta - beta).abs() > 1e-9 && !world.pose_free(pose[0], pose[1], pose[2], prim.beta) {
        return false;
    }
    prim.samples.iter().all(|rel| {
        let q = compose(pose[0], pose[1], pose[2], rel);
        world.pose_free(q[0], q[1], q[2], prim.beta)
    })
}

/// The search with its preallocated buffers.
#[derive(Debug, Clone)]
pub struct HybridAStar {
    params: MachineParams,
    prims: Vec<Primitive>,
    n_cells: usize,
    resolution: f64,
    heading_bins: usize,
    /// Per (cell, heading bin): the node occupying it, valid when the stamp
    /// equals `generation` (so the grid is never cleared).
    cell_stamp: Vec<u32>,
    cell_node: Vec<u32>,
    generation: u32,
    nodes: Vec<Node>,
    open: BinaryHeap<Open>,
    heuristic: ObstacleHeuristic,
    /// Tightest front-axle turning radius [m] (for the heading heuristic).
    min_turn_radius: f64,
    settings: SearchLimits,
}

/// The settings the search uses (copied from [`SearchSettings`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct SearchLimits {
    max_expansions: usize,
    max_nodes: usize,
    reverse_penalty: f64,
    direction_change_penalty: f64,
    heuristic_weight: f64,
    goal_position_tolerance: f64,
    goal_heading_tolerance: f64,
    shot_interval: usize,
    max_shots: usize,
    shot_range: f64,
    shot_tolerance: f64,
    refine_expansions: usize,
    dt: f64,
}

impl HybridAStar {
    pub fn new(params: MachineParams, s: &SearchSettings) -> Self {
        let betas: Vec<f64> = s
            .articulations
            .iter()
            .flat_map(|&f| {
                let b = f * params.beta_max;
                if b == 0.0 {
                    vec![0.0]
                } else {
                    vec![-b, b]
                }
            })
            .collect();
        let prims = primitives::build(&params, &betas, s.primitive_length, s.sample_spacing);
        let n = s.grid_cells();
        let cells = n * n * s.heading_bins;
        let b = params.beta_max;
        Self {
            params,
            prims,
            n_cells: n,
            resolution: s.grid_resolution,
            heading_bins: s.heading_bins,
            cell_stamp: vec![0; cells],
            cell_node: vec![0; cells],
            generation: 0,
            nodes: Vec::with_capacity(s.max_nodes),
            open: BinaryHeap::with_capacity(s.max_nodes),
            heuristic: ObstacleHeuristic::new(n),
            min_turn_radius: (params.l_f * b.cos() + params.l_r) / b.sin(),
            settings: SearchLimits {
                max_expansions: s.max_expansions,
                max_nodes: s.max_nodes,
                reverse_penalty: s.reverse_penalty,
                direction_change_penalty: s.direction_change_penalty,
                heuristic_weight: s.heuristic_weight,
                goal_position_tolerance: s.goal_position_tolerance,
                goal_heading_tolerance: s.goal_heading_tolerance,
                shot_interval: s.shot_interval,
                max_shots: s.max_shots,
                shot_range: s.shot_range,
                shot_tolerance: s.shot_tolerance,
                refine_expansions: s.refine_expansions,
                dt: s.rollout_dt,
            },
        }
    }

    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// Searches from `start` to `goal`; on success writes the path (start
    /// first, the node the goal is reached or shot from last) into `path`,
    /// which must have room for `max_nodes` poses. Allocation-free.
    pub fn search(
        &mut self,
        world: &CheckedWorld,
        start: &State,
        goal: &Goal,
        mut actor: Option<(&Actor, &mut ActorWorkspace)>,
        path: &mut Vec<PathPose>,
    ) -> (Result<(), SearchFailure>, SearchStats) {
        let t0 = Instant::now();
        let mut stats = SearchStats::default();
        let s = self.settings;
        path.clear();
        self.nodes.clear();
        self.open.clear();
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // Stamps from 2³² plans ago could alias: clear once per wrap.
            self.cell_stamp.fill(0);
            self.generation = 1;
        }
        let centre = [0.5 * (start[ix::X] + goal.x), 0.5 * (start[ix::Y] + goal.y)];
        let frame = GridFrame::centred(centre, self.resolution, self.n_cells);
        self.heuristic.compute(frame, world, [goal.x, goal.y]);
        let h0 = self.heuristic.distance(start[ix::X], start[ix::Y]);
        if !h0.is_finite() {
            stats.duration = t0.elapsed();
            return (Err(SearchFailure::Unreachable), stats);
        }
        let direction = if start[ix::V] > 0.05 {
            1
        } else if start[ix::V] < -0.05 {
            -1
        } else {
            0
        };
        self.nodes.push(Node {
            pose: [start[ix::X], start[ix::Y], start[ix::THETA]],
            beta: start[ix::BETA],
            direction,
            g: 0.0,
            parent: NO_PARENT,
            closed: false,
        });
        self.open.push(Open {
            f: self.h(&self.nodes[0].pose, goal),
            node: 0,
        });
        let mut since_shot = s.shot_interval;
        // The cheapest way to the goal found so far: its last node and total
        // cost (a goal shot's priced as its duration at top speed, metres as
        // the edges); the search goes on `refine_expansions` past the first.
        let mut best: Option<(u32, f64)> = None;
        let mut stop_after = usize::MAX;
        let v_max = self.params.v_max;
        let refine = s.refine_expansions;
        let offer =
            |best: &mut Option<(u32, f64)>, stop_after: &mut usize, node, total, at: usize| {
                if best.is_none_or(|(_, t)| total < t) {
                    *best = Some((node, total));
                    *stop_after = (*stop_after).min(at.saturating_add(refine));
                }
            };
        while let Some(Open { node, .. }) = self.open.pop() {
            let k = node as usize;
            if self.nodes[k].closed {
                continue;
            }
            self.nodes[k].closed = true;
            stats.expansions += 1;
            if stats.expansions > stop_after {
                break;
            }
            let n = self.nodes[k];
            // h is a lower bound: nothing through this node beats the best.
            if best.is_some_and(|(_, t)| n.g + self.h(&n.pose, goal) >= t) {
                continue;
            }
            if self.in_goal_region(&n.pose, goal) {
                offer(&mut best, &mut stop_after, node, n.g, stats.expansions);
                continue;
            }
            // The goal shot, when the goal is in sight and not too far.
            since_shot += 1;
            if let Some((a, ws)) = actor.as_mut() {
                let dist = (n.pose[0] - goal.x).hypot(n.pose[1] - goal.y);
                // Shots get more frequent closer to the goal (as Nav2's
                // analytic expansion), and are only tried along a clear line
                // of sight: the obstacle-blind actor heads roughly straight.
                let interval = (s.shot_interval as f64 * dist / s.shot_range) as usize;
                if dist <= s.shot_range
                    && since_shot >= interval
                    && stats.shots < s.max_shots
                    && world.segment_clear([n.pose[0], n.pose[1]], [goal.x, goal.y], world.margin())
                {
                    since_shot = 0;
                    stats.shots += 1;
                    let x = State::new(n.pose[0], n.pose[1], n.pose[2], n.beta, 0.0, 0.0);
                    let r = roll_out(
                        &self.params,
                        a,
                        ws,
                        world,
                        &x,
                        goal,
                        Arrival::Pose(s.shot_tolerance),
                        s.dt,
                        shot_steps(dist, s.dt),
                        None,
                    );
                    if r.reached {
                        let total = n.g + r.duration(s.dt) * v_max;
                        offer(&mut best, &mut stop_after, node, total, stats.expansions);
                        continue;
                    }
                }
            }
            if stats.expansions >= s.max_expansions {
                break;
            }
            if self.expand(k, world, goal, frame) {
                // Pool full.
                break;
            }
        }
        let found = best.map(|(node, _)| node);
        stats.cost = best.map_or(0.0, |(_, cost)| cost);
        stats.nodes = self.nodes.len();
        let result = match found {
            Some(end) => {
                self.write_path(end, path);
                Ok(())
            }
            None if self.open.is_empty() => Err(SearchFailure::Exhausted),
            None => Err(SearchFailure::Budget),
        };
        stats.duration = t0.elapsed();
        (result, stats)
    }

    /// Adds the successors of node `k`; true when the node pool is full.
    fn expand(&mut self, k: usize, world: &CheckedWorld, goal: &Goal, frame: GridFrame) -> bool {
        let s = self.settings;
        let n = self.nodes[k];
        let (beta_dot_max, v_max) = (self.params.beta_dot_max, self.params.v_max);
        for p in 0..self.prims.len() {
            let prim = &self.prims[p];
            if !primitive_free(world, &n.pose, n.beta, prim) {
                continue;
            }
            let end = compose(n.pose[0], n.pose[1], n.pose[2], &prim.end());
            let Some(cell) = frame.cell(end[0], end[1]) else {
                continue;
            };
            let mut cost = prim.length;
            if prim.direction < 0 {
                cost *= s.reverse_penalty;
            }
            cost += (prim.beta - n.beta).abs() / beta_dot_max * v_max;
            if n.direction != 0 && n.direction != prim.direction {
                cost += s.direction_change_penalty;
            }
            let g = n.g + cost;
            let slot = self.slot(frame.index(cell), end[2]);
            if self.cell_stamp[slot] == self.generation {
                let other = &self.nodes[self.cell_node[slot] as usize];
                if other.closed || other.g <= g {
                    continue;
                }
            }
            let h = self.h(&end, goal);
            if !h.is_finite() {
                continue;
            }
            if self.nodes.len() >= s.max_nodes {
                return true;
            }
            let id = self.nodes.len() as u32;
            self.nodes.push(Node {
                pose: [end[0], end[1], wrap_angle(end[2])],
                beta: prim.beta,
                direction: prim.direction,
                g,
                parent: k as u32,
                closed: false,
            });
            self.cell_stamp[slot] = self.generation;
            self.cell_node[slot] = id;
            self.open.push(Open {
                f: g + s.heuristic_weight * h,
                node: id,
            });
        }
        false
    }

    fn slot(&self, cell: usize, theta: f64) -> usize {
        let turn = std::f64::consts::TAU;
        let bins = self.heading_bins;
        let b = ((theta.rem_euclid(turn) / turn) * bins as f64) as usize % bins;
        cell * bins + b
    }

    /// Lower bound of the remaining cost [m] (see the module doc).
    fn h(&self, pose: &[f64; 3], goal: &Goal) -> f64 {
        let s = &self.settings;
        let euclid = (pose[0] - goal.x).hypot(pose[1] - goal.y) - s.goal_position_tolerance;
        let grid = self.heuristic.distance(pose[0], pose[1])
            - self.resolution * std::f64::consts::SQRT_2
            - s.goal_position_tolerance;
        let turn = (wrap_angle(pose[2] - goal.theta).abs() - s.goal_heading_tolerance)
            * self.min_turn_radius;
        euclid.max(grid).max(turn).max(0.0)
    }

    fn in_goal_region(&self, pose: &[f64; 3], goal: &Goal) -> bool {
        (pose[0] - goal.x).hypot(pose[1] - goal.y) <= self.settings.goal_position_tolerance
            && wrap_angle(pose[2] - goal.theta).abs() <= self.settings.goal_heading_tolerance
    }

    fn write_path(&self, end: u32, path: &mut Vec<PathPose>) {
        let mut k = end;
        while k != NO_PARENT {
            let n = &self.nodes[k as usize];
            if path.len() < path.capacity() {
                path.push(PathPose {
                    x: n.pose[0],
                    y: n.pose[1],
                    theta: n.pose[2],
                    beta: n.beta,
                    direction: n.direction,
                });
            }
            k = n.parent;
        }
        path.reverse();
    }
}
