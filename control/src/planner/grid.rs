//! The square grid both searches discretise the workspace with: `n × n` cells
//! of side `resolution`, re-centred on each plan (the midpoint of start and
//! goal) so its size stays fixed and its buffers are allocated once.
//!
//! [`ObstacleHeuristic`] is the 2D part of Hybrid A*'s heuristic (as Nav2's
//! Smac planner's obstacle heuristic): Dijkstra distance from the goal over the
//! cells the front axle may occupy. It makes the search go around a wall
//! instead of flooding the pocket in front of it, and an unreachable start
//! cell proves at once that no route exists.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::world::CheckedWorld;

/// Where the grid lies this plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridFrame {
    /// Corner (minimum x, minimum y) [m].
    pub origin: [f64; 2],
    pub resolution: f64,
    /// Cells per side.
    pub n: usize,
}

impl GridFrame {
    /// A grid of `n` cells a side centred on `centre`.
    pub fn centred(centre: [f64; 2], resolution: f64, n: usize) -> Self {
        let half = 0.5 * resolution * n as f64;
        Self {
            origin: [centre[0] - half, centre[1] - half],
            resolution,
            n,
        }
    }

    /// The cell (column, row) holding (x, y), if inside.
    #[inline]
    pub fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let i = ((x - self.origin[0]) / self.resolution).floor();
        let j = ((y - self.origin[1]) / self.resolution).floor();
        let n = self.n as f64;
        // NaN fails both comparisons.
        if (0.0..n).contains(&i) && (0.0..n).contains(&j) {
            Some((i as usize, j as usize))
        } else {
            None
        }
    }

    #[inline]
    pub fn index(&self, cell: (usize, usize)) -> usize {
        cell.1 * self.n + cell.0
    }

    pub fn centre(&self, cell: (usize, usize)) -> [f64; 2] {
        [
            self.origin[0] + (cell.0 as f64 + 0.5) * self.resolution,
            self.origin[1] + (cell.1 as f64 + 0.5) * self.resolution,
        ]
    }
}

/// A Dijkstra queue entry; the heap pops the smallest distance first.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    dist: f32,
    index: u32,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.dist.total_cmp(&self.dist)
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Distance to the goal over free cells, for every cell.
#[derive(Debug, Clone)]
pub struct ObstacleHeuristic {
    frame: GridFrame,
    dist: Vec<f32>,
    heap: BinaryHeap<Entry>,
    /// The goal's cell of the last `compute` (None: outside the grid).
    goal_cell: Option<(usize, usize)>,
}

impl ObstacleHeuristic {
    /// Buffers for an `n × n` grid.
    pub fn new(n: usize) -> Self {
        Self {
            frame: GridFrame::centred([0.0, 0.0], 1.0, n),
            dist: vec![f32::INFINITY; n * n],
            // Each cell is pushed at most once per neighbour that settles (8)
            // plus the goal itself, so this never grows.
            heap: BinaryHeap::with_capacity(8 * n * n + 1),
            goal_cell: None,
        }
    }

    /// Dijkstra from the goal position over the cells of `frame` free for the
    /// front axle with the world's margin. A cell is blocked when its centre
    /// lies within radius + margin − resolution/2 of some circle: so that the
    /// waist between two overlapping circles of a wall is closed (a test of
    /// the whole square against each circle alone leaves it open), while a
    /// free front axle lies in a blocked cell only within 0.2 × resolution of
    /// the margin. Allocation-free.
    pub fn compute(&mut self, frame: GridFrame, world: &CheckedWorld, goal: [f64; 2]) {
        debug_assert_eq!(frame.n, self.frame.n);
        self.frame = frame;
        let n = frame.n;
        let inset = 0.5 * frame.resolution;
        let margin = world.margin();
        // Blocked cells are marked −1 before the search.
        for (k, d) in self.dist.iter_mut().enumerate() {
            let c = frame.centre((k % n, k / n));
            let blocked = world.front_axle_blocked(c, margin - inset);
            *d = if blocked { -1.0 } else { f32::INFINITY };
        }
        self.heap.clear();
        self.goal_cell = frame.cell(goal[0], goal[1]);
        let Some(goal_cell) = self.goal_cell else {
            return;
        };
        let g = frame.index(goal_cell);
        self.dist[g] = 0.0;
        self.heap.push(Entry {
            dist: 0.0,
            index: g as u32,
        });
        let res = frame.resolution as f32;
        let diag = res * std::f32::consts::SQRT_2;
        while let Some(Entry { dist, index }) = self.heap.pop() {
            let k = index as usize;
            if dist > self.dist[k] {
                continue;
            }
            for (m, diagonal) in neighbours(n, k) {
                if self.dist[m] < 0.0 {
                    continue;
                }
                let step = if diagonal { diag } else { res };
                let nd = dist + step;
                if nd < self.dist[m] && self.heap.len() < self.heap.capacity() {
                    self.dist[m] = nd;
                    self.heap.push(Entry {
                        dist: nd,
                        index: m as u32,
                    });
                }
            }
        }
    }

    /// Grid distance to the goal from (x, y); +∞ outside the grid, in a
    /// blocked cell or where the goal cannot be reached.
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        match self.frame.cell(x, y) {
            Some(c) => {
                let d = self.dist[self.frame.index(c)];
                if d < 0.0 {
                    f64::INFINITY
                } else {
                    f64::from(d)
                }
            }
            None => f64::INFINITY,
        }
    }
}

/// The cells next to cell `k` of an `n × n` grid (row-major), and whether each
/// is a diagonal neighbour.
fn neighbours(n: usize, k: usize) -> impl Iterator<Item = (usize, bool)> {
    let (i, j) = ((k % n) as isize, (k / n) as isize);
    let n = n as isize;
    NEIGHBOURS.into_iter().filter_map(move |(di, dj)| {
        let (a, b) = (i + di, j + dj);
        ((0..n).contains(&a) && (0..n).contains(&b))
            .then_some(((b * n + a) as usize, di != 0 && dj != 0))
    })
}

const NEIGHBOURS: [(isize, isize); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::MachineParams;
    use crate::obstacle::Obstacle;

    /// A wall x = 0, |y| ≤ 3.2 of circles overlapping by 0.4 m, no margin.
    fn wall_world() -> CheckedWorld {
        let mut world = CheckedWorld::new(MachineParams::default(), 32, 0.0);
        let wall: Vec<Obstacle> = (-4..=4)
            .map(|k| Obstacle::new(0.0, 0.8 * k as f64, 0.6))
            .collect();
        world.set(&wall).unwrap();
        world
    }

    #[test]
    fn distance_goes_around_a_wall_and_is_infinite_inside_a_ring() {
        // The wall between (−2, 0) and the goal (2, 0).
        let mut world = wall_world();
        let frame = GridFrame::centred([0.0, 0.0], 0.2, 100);
        let mut h = ObstacleHeuristic::new(100);
        h.compute(frame, &world, [2.0, 0.0]);
        let d = h.distance(-2.0, 0.0);
        // Around the wall's end (0, ±3.8): about 2 × hypot(2, 3.8).
        let around = 2.0 * 2.0f64.hypot(3.8);
        assert!(d > around - 0.5 && d < around * 1.15, "{d} vs {around}");
        assert!(h.distance(0.0, 0.0).is_infinite());
        // A ring around the goal: unreachable.
        let ring: Vec<Obstacle> = (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 12.0;
                Obstacle::new(2.0 + 2.0 * a.cos(), 2.0 * a.sin(), 0.7)
            })
            .collect();
        world.set(&ring).unwrap();
        h.compute(frame, &world, [2.0, 0.0]);
        assert!(h.distance(-2.0, 0.0).is_infinite());
        assert!(h.distance(2.5, 0.0).is_finite());
    }
}
