//! The QP's layout: where every decision variable and constraint row lives, and
//! the fixed sparsity pattern of P and A with the position of each entry that
//! changes from tick to tick. Everything else in `mpc` depends on this file.
//!
//! Decision variables (deltas from the linearisation point, paper eq. 20–21):
//!
//! ```text
//! w = [Δx_0 Δu_0 | Δx_1 Δu_1 | … | Δx_{N−1} Δu_{N−1} | Δx_N | s_state | s_obs]
//!      └ z_0 (8) ┘                                      (6)   3 per n=1..N   1 per row k
//! ```
//!
//! so each stage's z_n = (x_n, u_n) is contiguous and P is block diagonal with
//! dense 8×8 blocks and a 6×6 terminal block; slack columns have no P entries
//! (their cost is linear: exact L1 penalty).
//!
//! Rows (Clarabel form A w + s = b, s in the cone), in this order:
//!
//! | block | rows | cone | meaning |
//! |---|---|---|---|
//! | initial | 6 | zero | Δx_0 = x̂ − x̄_0 |
//! | dynamics | 6N | zero | Δx_{n+1} − A_n Δx_n − B_n Δu_n = f(x̄_n, ū_n) − x̄_{n+1} |
//! | controls | 4N | ≥ 0 | ±(ū_n + Δu_n) ≤ u_max (hard) |
//! | states | 6N | ≥ 0 | ±(x̄_{n,c} + Δx_{n,c}) − s_{n,c} ≤ max_c, c ∈ {β, β̇, v_f}, n = 1..N |
//! | state slacks | 3N | ≥ 0 | s_{n,c} ≥ 0 |
//! | obstacles | 2·n_obs·N | ≥ 0 | linearised h_{j,a} + s_k ≥ 0 (or its CBF form), row k = 0..N−1, axle point a ∈ {front, rear} |
//! | obstacle slacks | N (if n_obs > 0) | ≥ 0 | s_k ≥ 0 |
//!
//! All obstacles and both axle points of one row share its slack, so the
//! penalty is w·Σ_k max_{j,a} (violation): still an exact penalty, with far
//! fewer variables and rows than one slack per constraint (the interior-point
//! cost grows with the KKT size). Each obstacle row has entries on
//! (x_f, y_f, θ, β) of x_{k+1} (and of x_k in the CBF form): the rear axle
//! moves with θ and β (DESIGN §10); the front rows write zeros there.

use super::settings::ObstacleConstraint;
/// State and control dimensions: the model's.
pub use crate::model::{NU, NX};

/// Stage variables z = (x, u).
pub const NZ: usize = NX + NU;
/// Soft-bounded state components: β, β̇, v_f.
pub const SOFT_STATES: [usize; 3] = [3, 4, 5];
/// State components an obstacle row depends on: x_f, y_f, θ, β.
pub const OBS_STATES: [usize; 4] = [0, 1, 2, 3];
/// Axle points constrained per obstacle (front, rear; DESIGN §10).
pub const AXLE_POINTS: usize = 2;

/// A fixed CSC sparsity pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct CscPattern {
    pub rows: usize,
    pub cols: usize,
    pub colptr: Vec<usize>,
    pub rowval: Vec<usize>,
}

impl CscPattern {
    pub fn nnz(&self) -> usize {
        self.rowval.len()
    }
}

/// Collects (row, col) entries in any order; `finish` sorts them into CSC and
/// tells where each entry went.
struct PatternBuilder {
    rows: usize,
    cols: usize,
    entries: Vec<(usize, usize)>,
}

impl PatternBuilder {
    fn new(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            entries: Vec::new(),
        }
    }

    /// Adds an entry and returns its handle (index in insertion order).
    fn push(&mut self, row: usize, col: usize) -> usize {
        debug_assert!(row < self.rows && col < self.cols);
        self.entries.push((row, col));
        self.entries.len() - 1
    }

    /// The pattern and, for each handle, its position in `nzval`.
    fn finish(self) -> (CscPattern, Vec<usize>) {
        let mut order: Vec<usize> = (0..self.entries.len()).collect();
        order.sort_by_key(|&k| (self.entries[k].1, self.entries[k].0));
        let mut position = vec![0; self.entries.len()];
        let mut colptr = vec![0; self.cols + 1];
        let mut rowval = Vec::with_capacity(order.len());
        for (pos, &k) in order.iter().enumerate() {
            let (row, col) = self.entries[k];
            if let Some(&(prev_row, prev_col)) = pos.checked_sub(1).map(|p| &self.entries[order[p]])
            {
                assert!(
                    (prev_col, prev_row) != (col, row),
                    "duplicate QP entry ({row}, {col})"
                );
            }
            position[k] = pos;
            rowval.push(row);
            colptr[col + 1] += 1;
        }
        for c in 0..self.cols {
            colptr[c + 1] += colptr[c];
        }
        (
            CscPattern {
                rows: self.rows,
                cols: self.cols,
                colptr,
                rowval,
            },
            position,
        )
    }
}

/// Index maps of the QP for one horizon, obstacle count and obstacle form.
#[derive(Debug, Clone)]
pub struct QpLayout {
    pub horizon: usize,
    pub n_obs: usize,
    pub obstacle_constraint: ObstacleConstraint,
    /// Number of variables.
    pub n_var: usize,
    /// Number of equality rows (zero cone, first).
    pub n_eq: usize,
    /// Number of inequality rows (nonnegative cone, after the equalities).
    pub n_ineq: usize,
    /// Upper triangle of P.
    pub p: CscPattern,
    /// A.
    pub a: CscPattern,
    /// nzval position of P's (i, j) in stage block n (symmetric: both orders map to the entry with i ≤ j).
    pub p_stage: Vec<[[usize; NZ]; NZ]>,
    /// nzval position of P's (i, j) in the terminal block.
    pub p_terminal: [[usize; NX]; NX],
    /// nzval position of −∂f/∂x (i, j) in the dynamics rows of stage n.
    pub a_dyn_x: Vec<[[usize; NX]; NX]>,
    /// nzval position of −∂f/∂u (i, j) in the dynamics rows of stage n.
    pub a_dyn_u: Vec<[[usize; NU]; NX]>,
    /// nzval positions of obstacle row (k, j, a): ∂/∂(x_f, y_f, θ, β) of x_{k+1}
    /// and, in the CBF form, of x_k; index [`Self::obstacle_entry`].
    pub a_obs: Vec<[usize; 2 * OBS_STATES.len()]>,
    /// A's values that never change (identities, ±1 of bounds and slacks);
    /// the changing positions hold nominal values for the equilibration.
    pub a_constant: Vec<f64>,
}

impl QpLayout {
    pub fn new(horizon: usize, n_obs: usize, obstacle_constraint: ObstacleConstraint) -> Self {
        let n = horizon;
        let n_obs_slack = if n_obs > 0 { n } else { 0 };
        let n_var = NZ * n + NX + 3 * n + n_obs_slack;
        let n_eq = NX * (n + 1);
        let n_ineq = 13 * n + AXLE_POINTS * n_obs * n + n_obs_slack;
        let mut layout = Self {
            horizon,
            n_obs,
            obstacle_constraint,
            n_var,
            n_eq,
            n_ineq,
            p: CscPattern {
                rows: 0,
                cols: 0,
                colptr: vec![],
                rowval: vec![],
            },
            a: CscPattern {
                rows: 0,
                cols: 0,
                colptr: vec![],
                rowval: vec![],
            },
            p_stage: vec![[[0; NZ]; NZ]; n],
            p_terminal: [[0; NX]; NX],
            a_dyn_x: vec![[[0; NX]; NX]; n],
            a_dyn_u: vec![[[0; NU]; NX]; n],
            a_obs: vec![[0; 2 * OBS_STATES.len()]; AXLE_POINTS * n * n_obs],
            a_constant: vec![],
        };
        layout.build_p();
        layout.build_a();
        layout
    }

    /// Column of x_n (n = 0..=N).
    pub fn x(&self, n: usize) -> usize {
        NZ * n
    }

    /// Column of u_n (n = 0..N).
    pub fn u(&self, n: usize) -> usize {
        NZ * n + NX
    }

    /// Column of the slack of soft state component c (0..3) at stage n = 1..=N.
    pub fn state_slack(&self, n: usize, c: usize) -> usize {
        NZ * self.horizon + NX + 3 * (n - 1) + c
    }

    /// Column of the slack shared by the obstacle rows k (k = 0..N; only with n_obs > 0).
    pub fn obstacle_slack(&self, k: usize) -> usize {
        NZ * self.horizon + NX + 3 * self.horizon + k
    }

    /// Row of the dynamics block of stage n (6 rows).
    pub fn row_dynamics(&self, n: usize) -> usize {
        NX + NX * n
    }

    /// First row of the control bounds of stage n: [u₁ ≤, u₂ ≤, −u₁ ≤, −u₂ ≤].
    pub fn row_controls(&self, n: usize) -> usize {
        self.n_eq + 4 * n
    }

    /// First row of the state bounds of x_n, n = 1..=N: [upper c=0..3, lower c=0..3].
    pub fn row_states(&self, n: usize) -> usize {
        self.n_eq + 4 * self.horizon + 6 * (n - 1)
    }

    /// Row of s_{n,c} ≥ 0.
    pub fn row_state_slack(&self, n: usize, c: usize) -> usize {
        self.n_eq + 10 * self.horizon + 3 * (n - 1) + c
    }

    /// Index of obstacle row (k, j, axle point a) among the obstacle rows and in `a_obs`.
    pub fn obstacle_entry(&self, k: usize, j: usize, a: usize) -> usize {
        (k * self.n_obs + j) * AXLE_POINTS + a
    }

    /// Row of obstacle constraint (k, j, axle point a).
    pub fn row_obstacle(&self, k: usize, j: usize, a: usize) -> usize {
        self.n_eq + 13 * self.horizon + self.obstacle_entry(k, j, a)
    }

    /// Row of obstacle slack k ≥ 0.
    pub fn row_obstacle_slack(&self, k: usize) -> usize {
        self.n_eq + 13 * self.horizon + AXLE_POINTS * self.horizon * self.n_obs + k
    }

    fn build_p(&mut self) {
        let mut b = PatternBuilder::new(self.n_var, self.n_var);
        let mut stage = vec![[[0; NZ]; NZ]; self.horizon];
        for (n, block) in stage.iter_mut().enumerate() {
            let c0 = self.x(n);
            for j in 0..NZ {
                for i in 0..=j {
                    let h = b.push(c0 + i, c0 + j);
                    block[i][j] = h;
                    block[j][i] = h;
                }
            }
        }
        let mut term = [[0; NX]; NX];
        let c0 = self.x(self.horizon);
        for j in 0..NX {
            for i in 0..=j {
                let h = b.push(c0 + i, c0 + j);
                term[i][j] = h;
                term[j][i] = h;
            }
        }
        let (pattern, pos) = b.finish();
        for block in &mut stage {
            for row in block.iter_mut() {
                for h in row.iter_mut() {
                    *h = pos[*h];
                }
            }
        }
        for row in term.iter_mut() {
            for h in row.iter_mut() {
                *h = pos[*h];
            }
        }
        self.p = pattern;
        self.p_stage = stage;
        self.p_terminal = term;
    }

    fn build_a(&mut self) {
        let n_rows = self.n_eq + self.n_ineq;
        let mut b = PatternBuilder::new(n_rows, self.n_var);
        // Constant entries with their values, by handle.
        let mut constants: Vec<(usize, f64)> = Vec::new();
        let mut put = |b: &mut PatternBuilder, row, col, value| {
            let h = b.push(row, col);
            constants.push((h, value));
            h
        };
        // Initial state.
        for i in 0..NX {
            put(&mut b, i, self.x(0) + i, 1.0);
        }
        // Dynamics: −A_n, −B_n, +I. Nominal −A = −I, −B = 0 (replaced each tick).
        let mut dyn_x = vec![[[0; NX]; NX]; self.horizon];
        let mut dyn_u = vec![[[0; NU]; NX]; self.horizon];
        for n in 0..self.horizon {
            let r = self.row_dynamics(n);
            for i in 0..NX {
                for j in 0..NX {
                    dyn_x[n][i][j] = put(
                        &mut b,
                        r + i,
                        self.x(n) + j,
                        if i == j { -1.0 } else { 0.0 },
                    );
                }
                for j in 0..NU {
                    dyn_u[n][i][j] = put(&mut b, r + i, self.u(n) + j, 0.0);
                }
                put(&mut b, r + i, self.x(n + 1) + i, 1.0);
            }
        }
        // Control bounds.
        for n in 0..self.horizon {
            let r = self.row_controls(n);
            for i in 0..NU {
                put(&mut b, r + i, self.u(n) + i, 1.0);
                put(&mut b, r + 2 + i, self.u(n) + i, -1.0);
            }
        }
        // Soft state bounds and their slacks.
        for n in 1..=self.horizon {
            let r = self.row_states(n);
            for (c, &ix) in SOFT_STATES.iter().enumerate() {
                let s = self.state_slack(n, c);
                put(&mut b, r + c, self.x(n) + ix, 1.0);
                put(&mut b, r + c, s, -1.0);
                put(&mut b, r + 3 + c, self.x(n) + ix, -1.0);
                put(&mut b, r + 3 + c, s, -1.0);
                put(&mut b, self.row_state_slack(n, c), s, -1.0);
            }
        }
        // Obstacles. Nominal gradient (1/√2, 1/√2) in (x_f, y_f), 0 in θ, β.
        let g = -std::f64::consts::FRAC_1_SQRT_2;
        let nominal = [g, g, 0.0, 0.0];
        let cbf = self.obstacle_constraint == ObstacleConstraint::Cbf;
        let mut obs = vec![[0; 2 * OBS_STATES.len()]; AXLE_POINTS * self.horizon * self.n_obs];
        for k in 0..self.horizon {
            if self.n_obs == 0 {
                break;
            }
            let s = self.obstacle_slack(k);
            for j in 0..self.n_obs {
                for a in 0..AXLE_POINTS {
                    let r = self.row_obstacle(k, j, a);
                    let e = &mut obs[self.obstacle_entry(k, j, a)];
                    for (c, &ix) in OBS_STATES.iter().enumerate() {
                        e[c] = put(&mut b, r, self.x(k + 1) + ix, nominal[c]);
                        if cbf {
                            e[OBS_STATES.len() + c] = put(&mut b, r, self.x(k) + ix, -nominal[c]);
                        }
                    }
                    put(&mut b, r, s, -1.0);
                }
            }
            put(&mut b, self.row_obstacle_slack(k), s, -1.0);
        }
        let (pattern, pos) = b.finish();
        let mut values = vec![0.0; pattern.nnz()];
        for (h, v) in constants {
            values[pos[h]] = v;
        }
        for block in &mut dyn_x {
            for h in block.iter_mut().flatten() {
                *h = pos[*h];
            }
        }
        for block in &mut dyn_u {
            for h in block.iter_mut().flatten() {
                *h = pos[*h];
            }
        }
        for e in &mut obs {
            let used = if cbf { 2 } else { 1 } * OBS_STATES.len();
            for h in e.iter_mut().take(used) {
                *h = pos[*h];
            }
        }
        self.a = pattern;
        self.a_dyn_x = dyn_x;
        self.a_dyn_u = dyn_u;
        self.a_obs = obs;
        self.a_constant = values;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_are_consistent() {
        for (n, n_obs, form) in [
            (3, 0, ObstacleConstraint::Distance),
            (5, 2, ObstacleConstraint::Cbf),
            (10, 8, ObstacleConstraint::Distance),
        ] {
            let l = QpLayout::new(n, n_obs, form);
            assert_eq!(l.p.nnz(), 36 * n + 21);
            assert_eq!(l.a.rows, l.n_eq + l.n_ineq);
            assert_eq!(l.a.cols, l.n_var);
            assert_eq!(*l.a.colptr.last().unwrap(), l.a.nnz());
            // Rows strictly increasing within each column (valid CSC).
            for pat in [&l.p, &l.a] {
                for c in 0..pat.cols {
                    let rows = &pat.rowval[pat.colptr[c]..pat.colptr[c + 1]];
                    assert!(rows.windows(2).all(|w| w[0] < w[1]));
                }
            }
            // Upper triangle only.
            for c in 0..l.p.cols {
                assert!(l.p.rowval[l.p.colptr[c]..l.p.colptr[c + 1]]
                    .iter()
                    .all(|&r| r <= c));
            }
            // Row blocks tile the rows exactly.
            if n_obs > 0 {
                assert_eq!(l.row_obstacle_slack(n - 1) + 1, l.n_eq + l.n_ineq);
            } else {
                assert_eq!(l.row_state_slack(n, 2) + 1, l.n_eq + l.n_ineq);
            }
            assert_eq!(l.row_state_slack(n, 2) + 1, l.n_eq + 13 * n);
            let used = if n_obs > 0 {
                l.obstacle_slack(n - 1) + 1
            } else {
                l.state_slack(n, 2) + 1
            };
            assert_eq!(used, l.n_var);
            // Every index map points at the right (row, col).
            let at = |pat: &CscPattern, pos: usize| {
                let col = (0..pat.cols)
                    .find(|&c| pat.colptr[c] <= pos && pos < pat.colptr[c + 1])
                    .unwrap();
                (pat.rowval[pos], col)
            };
            for k in 0..n {
                assert_eq!(at(&l.p, l.p_stage[k][2][5]), (l.x(k) + 2, l.x(k) + 5));
                assert_eq!(at(&l.p, l.p_stage[k][7][1]), (l.x(k) + 1, l.x(k) + 7));
                assert_eq!(
                    at(&l.a, l.a_dyn_x[k][4][3]),
                    (l.row_dynamics(k) + 4, l.x(k) + 3)
                );
                assert_eq!(
                    at(&l.a, l.a_dyn_u[k][5][1]),
                    (l.row_dynamics(k) + 5, l.u(k) + 1)
                );
                for j in 0..n_obs {
                    for a in 0..AXLE_POINTS {
                        let e = l.a_obs[l.obstacle_entry(k, j, a)];
                        assert_eq!(at(&l.a, e[1]), (l.row_obstacle(k, j, a), l.x(k + 1) + 1));
                        assert_eq!(at(&l.a, e[3]), (l.row_obstacle(k, j, a), l.x(k + 1) + 3));
                        if form == ObstacleConstraint::Cbf {
                            assert_eq!(at(&l.a, e[6]), (l.row_obstacle(k, j, a), l.x(k) + 2));
                        }
                    }
                }
            }
            assert_eq!(at(&l.p, l.p_terminal[0][5]), (l.x(n), l.x(n) + 5));
        }
    }
}
