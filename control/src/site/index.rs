//! A spatial index over a site's features, built once at load (DESIGN §17):
//! a uniform grid over the bounds' box, each cell listing the features whose
//! box overlaps it (compressed rows: one offset per cell, one feature number
//! per entry). No dependency, no allocation after [`SiteIndex::new`].
//!
//! Memory, bounded whatever the site: at most [`MAX_CELLS`] + 1 cell offsets
//! and [`MAX_ENTRIES`] entries of 4 bytes (≤ 9 MiB), plus one box (32 bytes)
//! per feature; [`SiteIndex::memory_bytes`] says what one index holds. The
//! cell size starts at the median feature extent (at most 16 cells per feature)
//! and doubles until both limits hold. On the large pit (520 features, 4.7 m
//! cells) an outline test took the same time with cells of 2 to 16 m, and
//! 1.7 × as long with 32 m (`cargo bench -p control --bench site`).
//!
//! Queries visit cells in rings of growing Chebyshev distance around the
//! query point and stop when the nearest cell not yet visited is farther
//! than what could still change the answer, so their answers are exactly
//! those of a linear scan over every feature (tested against one).

use super::geometry::{Aabb, Nearest, P2};
use super::outline::{Outline, WorldCircle, MAX_OUTLINE_CIRCLES};
use super::Site;
use crate::model::{MachineParams, State};

/// Most grid cells.
pub const MAX_CELLS: usize = 1 << 18;
/// Most (cell, feature) entries.
pub const MAX_ENTRIES: usize = 1 << 21;

/// Slack of the box-distance pruning [m]: a box's distance and a shape's
/// exact distance are rounded differently; pruning only what is farther by
/// more than this keeps the answers identical to a linear scan's.
const PRUNE_SLACK: f64 = 1e-9;

/// What a clearance was measured to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// `site.features()[i]`.
    Feature(usize),
    /// The site's bounds (the outline must stay inside).
    Bounds,
}

impl Target {
    /// Tie-break order: features by number, then the bounds.
    fn key(self) -> usize {
        match self {
            Target::Feature(i) => i,
            Target::Bounds => usize::MAX,
        }
    }
}

/// The worst clearance of a set of circles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub target: Target,
    /// Distance between circle and target [m], negative when they overlap
    /// (for the bounds: how far the circle stays inside them).
    pub clearance: f64,
    /// Which of the query's circles.
    pub circle: usize,
}

impl Hit {
    fn better_than(&self, o: &Hit) -> bool {
        (self.clearance, self.target.key(), self.circle) < (o.clearance, o.target.key(), o.circle)
    }
}

/// One of the k nearest features to a point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Near {
    /// `site.features()[feature]`.
    pub feature: usize,
    /// Its nearest outline point (signed distance negative inside).
    pub nearest: Nearest,
}

/// A site with its grid: what every layer queries.
#[derive(Debug, Clone)]
pub struct SiteIndex {
    site: Site,
    origin: P2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Entries of cell (i, j) are `items[start[j·nx + i] .. start[j·nx + i + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
    boxes: Vec<Aabb>,
}

impl SiteIndex {
    /// Builds the grid over a validated site, cells about a typical
    /// feature's size (see [`SiteIndex::with_cell`]).
    pub fn new(site: Site) -> SiteIndex {
        let b = site.bounds().aabb();
        let (w, h) = (
            (b.max[0] - b.min[0]).max(1e-6),
            (b.max[1] - b.min[1]).max(1e-6),
        );
        let boxes: Vec<Aabb> = site.features().iter().map(|f| f.shape.aabb()).collect();
        // Cells about a typical feature's size (the median box extent), so
        // a query near a feature reads few cells, but no more than 16 per
        // feature: a site of tiny features keeps a small grid.
        let n = boxes.len().max(1) as f64;
        let mut extents: Vec<f64> = boxes
            .iter()
            .map(|bx| (bx.max[0] - bx.min[0]).max(bx.max[1] - bx.min[1]))
            .collect();
        extents.sort_by(f64::total_cmp);
        let median = extents.get(extents.len() / 2).copied().unwrap_or(0.0);
        let cell = median.max((w * h / (16.0 * n)).sqrt()).max(1e-3);
        Self::with_cell(site, cell)
    }

    /// Builds the grid with cells of about `cell` metres (doubled until the
    /// memory limits hold; what the benchmark compares cell sizes with).
    pub fn with_cell(site: Site, cell: f64) -> SiteIndex {
        let boxes: Vec<Aabb> = site.features().iter().map(|f| f.shape.aabb()).collect();
        let b = site.bounds().aabb();
        let (w, h) = (
            (b.max[0] - b.min[0]).max(1e-6),
            (b.max[1] - b.min[1]).max(1e-6),
        );
        let mut cell = if cell.is_finite() {
            cell.max(1e-3)
        } else {
            w.max(h)
        };
        let dims = |cell: f64| {
            (
                ((w / cell).ceil() as usize).max(1),
                ((h / cell).ceil() as usize).max(1),
            )
        };
        loop {
            let (nx, ny) = dims(cell);
            if nx.saturating_mul(ny) <= MAX_CELLS {
                let entries: usize = boxes
                    .iter()
                    .map(|bx| {
                        let (i0, i1, j0, j1) = cell_range(b.min, cell, nx, ny, bx);
                        (i1 - i0 + 1) * (j1 - j0 + 1)
                    })
                    .sum();
                if entries <= MAX_ENTRIES {
                    break;
                }
            }
            cell *= 2.0;
        }
        let (nx, ny) = dims(cell);
        let mut count = vec![0u32; nx * ny + 1];
        for bx in &boxes {
            let (i0, i1, j0, j1) = cell_range(b.min, cell, nx, ny, bx);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    count[j * nx + i + 1] += 1;
                }
            }
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        let start = count;
        let mut fill: Vec<u32> = start[..nx * ny].to_vec();
        let mut items = vec![0u32; start[nx * ny] as usize];
        for (f, bx) in boxes.iter().enumerate() {
            let (i0, i1, j0, j1) = cell_range(b.min, cell, nx, ny, bx);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let slot = &mut fill[j * nx + i];
                    items[*slot as usize] = f as u32;
                    *slot += 1;
                }
            }
        }
        SiteIndex {
            site,
            origin: b.min,
            cell,
            nx,
            ny,
            start,
            items,
            boxes,
        }
    }

    pub fn site(&self) -> &Site {
        &self.site
    }

    /// What a hit names: the feature's id, or `bounds`.
    pub fn name(&self, t: Target) -> &str {
        match t {
            Target::Feature(f) => self.site.features().get(f).map_or("?", |x| x.id.as_str()),
            Target::Bounds => "bounds",
        }
    }

    /// Bytes held by the grid (offsets, entries, boxes), not the site.
    pub fn memory_bytes(&self) -> usize {
        4 * (self.start.len() + self.items.len()) + std::mem::size_of::<Aabb>() * self.boxes.len()
    }

    /// Cell edge length [m] and grid size (nx, ny).
    pub fn grid(&self) -> (f64, usize, usize) {
        (self.cell, self.nx, self.ny)
    }

    /// The cell holding `p`, as grid indices that may lie outside the grid
    /// (clamped to within nx + ny cells of it, so ring arithmetic cannot
    /// overflow; a point farther out only loses pruning, not exactness).
    fn cell_of(&self, p: P2) -> (isize, isize) {
        let reach = (self.nx + self.ny) as f64;
        let f = |v: f64, o: f64, n: usize| {
            let k = ((v - o) / self.cell).floor();
            if k.is_nan() {
                0
            } else {
                k.clamp(-reach, n as f64 - 1.0 + reach) as isize
            }
        };
        (
            f(p[0], self.origin[0], self.nx),
            f(p[1], self.origin[1], self.ny),
        )
    }

    fn cell_items(&self, i: usize, j: usize) -> &[u32] {
        let k = j * self.nx + i;
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }

    /// Visits the cells in rings around `p`'s cell; `visit` gets each
    /// cell's features and returns the distance beyond which nothing
    /// matters any more (it may shrink as results come in). Stops when the
    /// cells left are all farther than that, or none are left.
    fn rings(&self, p: P2, mut visit: impl FnMut(&[u32]) -> f64) {
        let (ci, cj) = self.cell_of(p);
        let (nx, ny) = (self.nx as isize, self.ny as isize);
        let mut limit = f64::INFINITY;
        // Rings nearer than the grid hold no cells: start at the first that
        // reaches it.
        let mut k: isize = 0.max(-ci).max(ci - (nx - 1)).max(-cj).max(cj - (ny - 1));
        loop {
            if k > 0 {
                // Every cell not yet visited lies outside the box of rings
                // 0..k−1; its distance from p is at least p's to that box's
                // border (0 when p lies outside the box).
                let lo = [
                    self.origin[0] + (ci - k + 1) as f64 * self.cell,
                    self.origin[1] + (cj - k + 1) as f64 * self.cell,
                ];
                let hi = [
                    self.origin[0] + (ci + k) as f64 * self.cell,
                    self.origin[1] + (cj + k) as f64 * self.cell,
                ];
                let border = (p[0] - lo[0])
                    .min(hi[0] - p[0])
                    .min(p[1] - lo[1])
                    .min(hi[1] - p[1])
                    .max(0.0);
                if border - PRUNE_SLACK > limit {
                    return;
                }
                if ci - k < 0 && cj - k < 0 && ci + k >= nx && cj + k >= ny {
                    return;
                }
            }
            if k == 0 {
                // Inside the grid (k starts above 0 otherwise).
                limit = visit(self.cell_items(ci as usize, cj as usize));
            } else {
                for i in (ci - k).max(0)..=(ci + k).min(nx - 1) {
                    for j in [cj - k, cj + k] {
                        if j >= 0 && j < ny {
                            limit = visit(self.cell_items(i as usize, j as usize));
                        }
                    }
                }
                for j in (cj - k + 1).max(0)..=(cj + k - 1).min(ny - 1) {
                    for i in [ci - k, ci + k] {
                        if i >= 0 && i < nx {
                            limit = visit(self.cell_items(i as usize, j as usize));
                        }
                    }
                }
            }
            k += 1;
        }
    }

    /// The worst clearance of `circles` to every feature (obstacles and
    /// keep-outs) and to the bounds, among those below `cutoff` (`None` if
    /// none is): the least, ties broken by feature number (the bounds last),
    /// then circle number. `cutoff = f64::INFINITY` asks for the exact
    /// least over the whole site.
    pub fn clearance(&self, circles: &[WorldCircle], cutoff: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (ci, c) in circles.iter().enumerate() {
            let hit = Hit {
                target: Target::Bounds,
                clearance: -self.site.bounds().signed_distance(c.center) - c.radius,
                circle: ci,
            };
            if hit.clearance < cutoff && best.is_none_or(|b| hit.better_than(&b)) {
                best = Some(hit);
            }
        }
        for (ci, c) in circles.iter().enumerate() {
            self.rings(c.center, |items| {
                for &f in items {
                    let f = f as usize;
                    let bound = best.map_or(cutoff, |b| b.clearance.min(cutoff));
                    // Outside its box, a feature is at least the box's
                    // distance away; inside, it may hold the point.
                    let d = self.boxes[f].distance(c.center);
                    if d > 0.0 && d - c.radius - PRUNE_SLACK > bound {
                        continue;
                    }
                    let clearance = self.site.features()[f].shape.clearance(c.center, c.radius);
                    let hit = Hit {
                        target: Target::Feature(f),
                        clearance,
                        circle: ci,
                    };
                    if clearance < cutoff && best.is_none_or(|b| hit.better_than(&b)) {
                        best = Some(hit);
                    }
                }
                best.map_or(cutoff, |b| b.clearance.min(cutoff)) + c.radius
            });
        }
        best
    }

    /// Whether the outline at state `x` comes nearer than `margin` to an
    /// obstacle or keep-out, or to the outside of the bounds: the worst such
    /// contact, or `None` when it keeps `margin` from everything. Use
    /// `margin = 0` for "meets or leaves".
    pub fn outline_meets(
        &self,
        outline: &Outline,
        p: &MachineParams,
        x: &State,
        margin: f64,
    ) -> Option<Hit> {
        let mut buf = [WorldCircle::default(); MAX_OUTLINE_CIRCLES];
        let n = outline.place(p, x, &mut buf);
        self.clearance(&buf[..n], margin)
    }

    /// The k = `out.len()` features nearest to `p` whose signed distance is
    /// at most `radius`, nearest first (ties by feature number), written
    /// into `out`; returns how many. Allocation-free.
    pub fn nearest(&self, p: P2, radius: f64, out: &mut [Near]) -> usize {
        let k = out.len();
        let mut n = 0;
        if k == 0 {
            return 0;
        }
        self.rings(p, |items| {
            for &f in items {
                let f = f as usize;
                let bound = if n == k {
                    out[k - 1].nearest.distance.min(radius)
                } else {
                    radius
                };
                let d = self.boxes[f].distance(p);
                if d > 0.0 && d - PRUNE_SLACK > bound {
                    continue;
                }
                if out[..n].iter().any(|q| q.feature == f) {
                    continue;
                }
                let nearest = self.site.features()[f].shape.nearest(p);
                if nearest.distance > radius {
                    continue;
                }
                let key = (nearest.distance, f);
                // Insertion into the sorted prefix.
                let pos = out[..n]
                    .iter()
                    .position(|q| key < (q.nearest.distance, q.feature))
                    .unwrap_or(n);
                if pos >= k {
                    continue;
                }
                let end = if n < k { n } else { k - 1 };
                out.copy_within(pos..end, pos + 1);
                out[pos] = Near {
                    feature: f,
                    nearest,
                };
                n = (n + 1).min(k);
            }
            if n == k {
                out[k - 1].nearest.distance.min(radius)
            } else {
                radius
            }
        });
        n
    }
}

/// Cells (i0..=i1, j0..=j1) a box overlaps, clamped to the grid.
fn cell_range(
    origin: P2,
    cell: f64,
    nx: usize,
    ny: usize,
    b: &Aabb,
) -> (usize, usize, usize, usize) {
    let c = |v: f64, o: f64, n: usize| {
        let k = ((v - o) / cell).floor();
        if k.is_nan() || k < 0.0 {
            0
        } else {
            (k as usize).min(n - 1)
        }
    };
    (
        c(b.min[0], origin[0], nx),
        c(b.max[0], origin[0], nx),
        c(b.min[1], origin[1], ny),
        c(b.max[1], origin[1], ny),
    )
}

#[cfg(test)]
mod tests;
