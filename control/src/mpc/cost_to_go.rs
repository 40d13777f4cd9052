//! A cost-to-go field added to the critic's cost (issue 27, design (b);
//! DESIGN §15): what the obstacle-blind critic does not know about the way to
//! the goal.
//!
//! The critic prices the distance to the goal as if the way were open; behind a
//! wall that is the straight line, and the MPC stalls against the wall. The
//! field is the *excess* of the distance around the circles over the open
//! distance, φ(p) = D(p) − D₀(p), on a grid (the planner's Dijkstra distance D
//! from the goal over the cells free for the front axle, and D₀ the same
//! search's distance without obstacles, so the two differ only where circles are
//! in the way: φ = 0 wherever the way is open, exactly, however coarse the grid).
//! Weighted by the critic's own price of a metre (its slope along the way to a
//! goal, [`crate::planner`] calibrates it), critic + w·φ ≈ w·D far from the
//! goal, and near the goal, where the way is open, the critic alone: the
//! blending DESIGN §15 asks for needs no switch.
//!
//! The value is bilinear between cell centres (continuous, gradient piecewise
//! constant); outside the grid the edge values continue (gradient 0). Its
//! Hessian is taken as zero (φ is piecewise linear at the grid's scale; the
//! critic's Hessian and the Levenberg–Marquardt term keep each block positive
//! definite), the Gauss–Newton choice for a term whose curvature is an
//! artefact of the interpolation.

/// The weighted excess distance w·φ on an `n × n` grid of cell centres.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CostToGo {
    /// Centre of cell (0, 0) [m].
    origin: [f64; 2],
    resolution: f64,
    n: usize,
    /// w·φ at cell (i, j), row-major by j: `values[j * n + i]`.
    values: Vec<f64>,
}

impl CostToGo {
    /// Room for an `n × n` grid (allocated once; [`Self::fill`] within it does
    /// not allocate).
    pub fn with_cells(n: usize) -> Self {
        Self {
            origin: [0.0; 2],
            resolution: 1.0,
            n: 0,
            values: Vec::with_capacity(n * n),
        }
    }

    /// An empty field (value 0 everywhere).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    pub fn clear(&mut self) {
        self.n = 0;
        self.values.clear();
    }

    /// Sets the grid: cell (i, j) has its centre at `origin + resolution·(i, j)`
    /// and the value `value(i, j)`. A non-finite value or a bad resolution
    /// leaves the field empty (no term): a broken field must not steer.
    pub fn fill(
        &mut self,
        origin: [f64; 2],
        resolution: f64,
        n: usize,
        mut value: impl FnMut(usize, usize) -> f64,
    ) {
        self.values.clear();
        self.n = 0;
        if !(resolution > 0.0 && resolution.is_finite() && origin.iter().all(|o| o.is_finite())) {
            return;
        }
        for j in 0..n {
            for i in 0..n {
                let v = value(i, j);
                if !v.is_finite() {
                    self.values.clear();
                    return;
                }
                self.values.push(v);
            }
        }
        self.origin = origin;
        self.resolution = resolution;
        self.n = n;
    }

    /// Copies `other` into this field's buffer (no allocation when it fits).
    pub fn copy_from(&mut self, other: &CostToGo) {
        self.origin = other.origin;
        self.resolution = other.resolution;
        self.n = other.n;
        self.values.clear();
        self.values.extend_from_slice(&other.values);
    }

    /// w·φ at (x, y) and its gradient.
    pub fn eval(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        if self.n == 0 || !(x.is_finite() && y.is_finite()) {
            return (0.0, [0.0; 2]);
        }
        if self.n == 1 {
            return (self.values[0], [0.0; 2]);
        }
        let last = (self.n - 1) as f64;
        let u = (x - self.origin[0]) / self.resolution;
        let v = (y - self.origin[1]) / self.resolution;
        // Outside the centres' square the edge continues: clamp, and the
        // clamped coordinate has no gradient.
        let (uc, vc) = (u.clamp(0.0, last), v.clamp(0.0, last));
        let i = (uc.floor() as usize).min(self.n - 2);
        let j = (vc.floor() as usize).min(self.n - 2);
        let (s, t) = (uc - i as f64, vc - j as f64);
        let at = |a: usize, b: usize| self.values[b * self.n + a];
        let (f00, f10, f01, f11) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        let value =
            f00 * (1.0 - s) * (1.0 - t) + f10 * s * (1.0 - t) + f01 * (1.0 - s) * t + f11 * s * t;
        let du = (f10 - f00) * (1.0 - t) + (f11 - f01) * t;
        let dv = (f01 - f00) * (1.0 - s) + (f11 - f10) * s;
        let inside_u = u > 0.0 && u < last;
        let inside_v = v > 0.0 && v < last;
        let gx = if inside_u { du / self.resolution } else { 0.0 };
        let gy = if inside_v { dv / self.resolution } else { 0.0 };
        (value, [gx, gy])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_value_and_gradient_match_a_plane_and_finite_differences() {
        // A plane is reproduced exactly inside the grid.
        let mut f = CostToGo::with_cells(10);
        f.fill([1.0, -2.0], 0.5, 10, |i, j| {
            3.0 + 2.0 * i as f64 - 1.0 * j as f64
        });
        let (x, y) = (2.3, -0.7);
        let (v, g) = f.eval(x, y);
        let (u, w) = ((x - 1.0) / 0.5, (y + 2.0) / 0.5);
        assert!((v - (3.0 + 2.0 * u - w)).abs() < 1e-12, "{v}");
        assert!(
            (g[0] - 4.0).abs() < 1e-12 && (g[1] + 2.0).abs() < 1e-12,
            "{g:?}"
        );
        // A curved field: the gradient is the finite difference of the value
        // away from cell boundaries.
        f.fill([0.0, 0.0], 0.3, 10, |i, j| ((i * i + 3 * j) as f64).sqrt());
        for (x, y) in [(0.41, 0.52), (1.7, 2.05), (2.2, 0.1)] {
            let (_, g) = f.eval(x, y);
            let h = 1e-6;
            let dx = (f.eval(x + h, y).0 - f.eval(x - h, y).0) / (2.0 * h);
            let dy = (f.eval(x, y + h).0 - f.eval(x, y - h).0) / (2.0 * h);
            assert!(
                (dx - g[0]).abs() < 1e-6 && (dy - g[1]).abs() < 1e-6,
                "{g:?} vs {dx}, {dy}"
            );
        }
        // Outside the grid: the edge value, no gradient across the edge.
        let (v_out, g_out) = f.eval(-5.0, 1.0);
        let (v_edge, _) = f.eval(0.0, 1.0);
        assert!((v_out - v_edge).abs() < 1e-12 && g_out[0] == 0.0);
    }

    #[test]
    fn an_empty_or_broken_field_is_no_term() {
        let mut f = CostToGo::with_cells(4);
        assert_eq!(f.eval(0.0, 0.0), (0.0, [0.0; 2]));
        f.fill(
            [0.0, 0.0],
            1.0,
            4,
            |i, _| if i == 2 { f64::NAN } else { 1.0 },
        );
        assert!(f.is_empty());
        assert_eq!(f.eval(1.0, 1.0), (0.0, [0.0; 2]));
        f.fill([0.0, 0.0], 0.0, 4, |_, _| 1.0);
        assert!(f.is_empty());
        f.fill([0.0, 0.0], 1.0, 4, |_, _| 1.0);
        assert_eq!(f.eval(1.5, 1.5).0, 1.0);
        assert_eq!(f.eval(f64::NAN, 1.5), (0.0, [0.0; 2]));
    }
}
