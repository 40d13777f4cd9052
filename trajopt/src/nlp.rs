//! Sparse NLPs assembled from small elements, the way transcribed optimal
//! control problems are built: each element touches a few variables (one
//! collocation interval, one node's obstacles, ...), contributes to the
//! objective and owns a few constraints, and gives its exact gradient and
//! Jacobian. The assembled problem implements [`Nlp`] for IPOPT.
//!
//! The Hessian of the Lagrangian is either left to IPOPT's L-BFGS, or formed
//! element by element by forward differences of the *exact* element
//! gradients (each element has at most ~15 variables, so this is cheap and
//! accurate to ~1e-7, and keeps the block-banded sparsity).

use std::collections::HashMap;

use crate::ipopt::Nlp;

/// IPOPT's infinity.
pub const INF: f64 = 2e19;

/// One part of the problem.
pub trait Element: Send + Sync {
    /// Global indices of the variables it reads (no repeats).
    fn vars(&self) -> &[usize];
    /// Number of constraints it owns.
    fn n_cons(&self) -> usize;
    /// Bounds of its constraints.
    fn con_bounds(&self, lower: &mut [f64], upper: &mut [f64]);
    /// At the local variables `z`: objective contribution, its gradient
    /// (len nv), constraint values (len nc) and their Jacobian (nc × nv,
    /// row-major).
    fn eval(&self, z: &[f64], obj: &mut f64, grad: &mut [f64], g: &mut [f64], jac: &mut [f64]);
    /// Whether the element is linear in its local variable `local` (no
    /// Hessian row or column: the finite differences skip it).
    fn is_linear_in(&self, _local: usize) -> bool {
        false
    }
    /// Whether the element has an objective term (else, with all its
    /// multipliers below [`NEGLIGIBLE_MULTIPLIER`], it adds nothing to the
    /// Hessian of the Lagrangian).
    fn has_objective(&self) -> bool {
        true
    }
}

/// Multipliers below this leave an element without objective out of the
/// Hessian: its curvature times them is below the finite differences' own
/// error (~1e-5 relative). Inactive inequality rows (the footprint's, far from
/// the obstacles) have multipliers ~ μ / slack.
pub const NEGLIGIBLE_MULTIPLIER: f64 = 1e-7;

/// How IPOPT gets the Hessian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HessianKind {
    /// Forward differences of the exact element gradients.
    FiniteDifference,
    /// IPOPT's limited-memory quasi-Newton approximation.
    Lbfgs,
}

/// An NLP made of elements.
pub struct ElementNlp {
    n: usize,
    pub z_lower: Vec<f64>,
    pub z_upper: Vec<f64>,
    elements: Vec<Box<dyn Element>>,
    con_offset: Vec<usize>,
    m: usize,
    hessian: HessianKind,
    /// Per element, the global Hessian entry of each local (a, b), b ≤ a.
    hess_index: Vec<Vec<usize>>,
    hess_rows: Vec<usize>,
    hess_cols: Vec<usize>,
    // Scratch.
    local_z: Vec<f64>,
    grad: Vec<f64>,
    g: Vec<f64>,
    jac: Vec<f64>,
}

impl ElementNlp {
    pub fn new(n: usize, elements: Vec<Box<dyn Element>>, hessian: HessianKind) -> Self {
        let mut con_offset = Vec::with_capacity(elements.len());
        let mut m = 0;
        let mut max_nv = 0;
        let mut max_nc = 0;
        for e in &elements {
            con_offset.push(m);
            m += e.n_cons();
            max_nv = max_nv.max(e.vars().len());
            max_nc = max_nc.max(e.n_cons());
        }
        let mut map: HashMap<(usize, usize), usize> = HashMap::new();
        let (mut hess_rows, mut hess_cols) = (Vec::new(), Vec::new());
        let mut hess_index = Vec::with_capacity(elements.len());
        for e in &elements {
            let v = e.vars();
            let mut idx = Vec::with_capacity(v.len() * (v.len() + 1) / 2);
            for a in 0..v.len() {
                for b in 0..=a {
                    let key = (v[a].max(v[b]), v[a].min(v[b]));
                    let next = hess_rows.len();
                    let k = *map.entry(key).or_insert_with(|| {
                        hess_rows.push(key.0);
                        hess_cols.push(key.1);
                        next
                    });
                    idx.push(k);
                }
            }
            hess_index.push(idx);
        }
        Self {
            n,
            z_lower: vec![-INF; n],
            z_upper: vec![INF; n],
            elements,
            con_offset,
            m,
            hessian,
            hess_index,
            hess_rows,
            hess_cols,
            local_z: vec![0.0; max_nv],
            grad: vec![0.0; 3 * max_nv],
            g: vec![0.0; max_nc],
            jac: vec![0.0; max_nc * max_nv],
        }
    }

    pub fn elements(&self) -> &[Box<dyn Element>] {
        &self.elements
    }

    /// Largest violation of the variable and constraint bounds at `z`.
    pub fn max_violation(&mut self, z: &[f64]) -> f64 {
        let mut worst: f64 = 0.0;
        for ((zi, lo), hi) in z.iter().zip(&self.z_lower).zip(&self.z_upper) {
            worst = worst.max(lo - zi).max(zi - hi);
        }
        let mut g = vec![0.0; self.m];
        self.constraints(z, &mut g);
        let (mut gl, mut gu) = (vec![0.0; self.m], vec![0.0; self.m]);
        let (mut a, mut b) = (vec![0.0; self.n], vec![0.0; self.n]);
        self.bounds(&mut a, &mut b, &mut gl, &mut gu);
        for i in 0..self.m {
            worst = worst.max(gl[i] - g[i]).max(g[i] - gu[i]);
        }
        worst
    }

    fn gather(&mut self, e: usize, z: &[f64]) -> usize {
        let vars = self.elements[e].vars();
        for (slot, &i) in self.local_z.iter_mut().zip(vars) {
            *slot = z[i];
        }
        vars.len()
    }

    /// Evaluates element `e` at the global point `z`: returns its objective and
    /// leaves its gradient in `self.grad`; its constraints and Jacobian go to `g`
    /// and `jac` when given (else to scratch).
    fn eval_element(
        &mut self,
        e: usize,
        z: &[f64],
        g: Option<&mut [f64]>,
        jac: Option<&mut [f64]>,
    ) -> f64 {
        let nv = self.gather(e, z);
        let nc = self.elements[e].n_cons();
        let g = g.unwrap_or(&mut self.g[..nc]);
        let jac = jac.unwrap_or(&mut self.jac[..nc * nv]);
        let mut obj = 0.0;
        self.elements[e].eval(&self.local_z[..nv], &mut obj, &mut self.grad[..nv], g, jac);
        obj
    }
}

impl Nlp for ElementNlp {
    fn n(&self) -> usize {
        self.n
    }

    fn m(&self) -> usize {
        self.m
    }

    fn bounds(&self, z_l: &mut [f64], z_u: &mut [f64], g_l: &mut [f64], g_u: &mut [f64]) {
        z_l.copy_from_slice(&self.z_lower);
        z_u.copy_from_slice(&self.z_upper);
        for (e, &off) in self.elements.iter().zip(&self.con_offset) {
            let nc = e.n_cons();
            e.con_bounds(&mut g_l[off..off + nc], &mut g_u[off..off + nc]);
        }
    }

    fn objective(&mut self, z: &[f64]) -> Option<f64> {
        let mut total = 0.0;
        for e in 0..self.elements.len() {
            total += self.eval_element(e, z, None, None);
        }
        total.is_finite().then_some(total)
    }

    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> bool {
        grad.fill(0.0);
        for e in 0..self.elements.len() {
            self.eval_element(e, z, None, None);
            for (k, &i) in self.elements[e].vars().iter().enumerate() {
                grad[i] += self.grad[k];
            }
        }
        grad.iter().all(|v| v.is_finite())
    }

    fn constraints(&mut self, z: &[f64], g: &mut [f64]) -> bool {
        for e in 0..self.elements.len() {
            let (off, nc) = (self.con_offset[e], self.elements[e].n_cons());
            self.eval_element(e, z, Some(&mut g[off..off + nc]), None);
        }
        g.iter().all(|v| v.is_finite())
    }

    fn jacobian_structure(&self) -> (Vec<usize>, Vec<usize>) {
        let (mut rows, mut cols) = (Vec::new(), Vec::new());
        for (e, &off) in self.elements.iter().zip(&self.con_offset) {
            for c in 0..e.n_cons() {
                for &i in e.vars() {
                    rows.push(off + c);
                    cols.push(i);
                }
            }
        }
        (rows, cols)
    }

    fn jacobian(&mut self, z: &[f64], values: &mut [f64]) -> bool {
        let mut pos = 0;
        for e in 0..self.elements.len() {
            let len = self.elements[e].n_cons() * self.elements[e].vars().len();
            self.eval_element(e, z, None, Some(&mut values[pos..pos + len]));
            pos += len;
        }
        values.iter().all(|v| v.is_finite())
    }

    fn hessian_structure(&self) -> Option<(Vec<usize>, Vec<usize>)> {
        match self.hessian {
            HessianKind::Lbfgs => None,
            HessianKind::FiniteDifference => Some((self.hess_rows.clone(), self.hess_cols.clone())),
        }
    }

    fn hessian(&mut self, z: &[f64], sigma: f64, lambda: &[f64], values: &mut [f64]) -> bool {
        values.fill(0.0);
        let mut h_local = Vec::new();
        for e in 0..self.elements.len() {
            let nv = self.gather(e, z);
            let nc = self.elements[e].n_cons();
            let lam = &lambda[self.con_offset[e]..self.con_offset[e] + nc];
            let elem = &self.elements[e];
            if !elem.has_objective() && lam.iter().all(|l| l.abs() < NEGLIGIBLE_MULTIPLIER) {
                continue;
            }
            // ∇ of σ f_e + λ_eᵀ g_e at local z.
            let lagrangian_grad =
                |zl: &[f64], out: &mut [f64], g: &mut [f64], jac: &mut [f64], grad: &mut [f64]| {
                    let mut obj = 0.0;
                    elem.eval(zl, &mut obj, grad, g, jac);
                    for a in 0..nv {
                        let mut s = sigma * grad[a];
                        for c in 0..nc {
                            s += lam[c] * jac[c * nv + a];
                        }
                        out[a] = s;
                    }
                };
            h_local.clear();
            h_local.resize(nv * nv, 0.0);
            let mut zl = self.local_z[..nv].to_vec();
            let (g_step, rest) = self.grad.split_at_mut(nv);
            let (g_base, gr) = rest.split_at_mut(nv);
            // Forward differences of the exact gradient from the point itself
            // (one evaluation per variable; the error O(h) ~ 1e-7 relative is
            // far below what the Newton step needs; central ones cost twice).
            lagrangian_grad(
                &zl,
                g_base,
                &mut self.g[..nc],
                &mut self.jac[..nc * nv],
                &mut gr[..nv],
            );
            for j in 0..nv {
                if elem.is_linear_in(j) {
                    continue;
                }
                let h = 1e-7 * (1.0 + zl[j].abs());
                let orig = zl[j];
                zl[j] = orig + h;
                lagrangian_grad(
                    &zl,
                    g_step,
                    &mut self.g[..nc],
                    &mut self.jac[..nc * nv],
                    &mut gr[..nv],
                );
                zl[j] = orig;
                // The step actually taken (z + h rounded).
                let h = (orig + h) - orig;
                for a in 0..nv {
                    h_local[a * nv + j] = (g_step[a] - g_base[a]) / h;
                }
            }
            let idx = &self.hess_index[e];
            let mut k = 0;
            for a in 0..nv {
                for b in 0..=a {
                    values[idx[k]] += 0.5 * (h_local[a * nv + b] + h_local[b * nv + a]);
                    k += 1;
                }
            }
        }
        values.iter().all(|v| v.is_finite())
    }
}

/// Largest relative error between the exact gradient / Jacobian of `nlp` and
/// central differences of its objective / constraints at `z`
/// (max |exact − fd| / (1 + |fd|)), as (gradient error, Jacobian error).
pub fn finite_difference_check(nlp: &mut dyn Nlp, z: &[f64]) -> (f64, f64) {
    let (n, m) = (nlp.n(), nlp.m());
    let mut grad = vec![0.0; n];
    assert!(nlp.gradient(z, &mut grad));
    let (rows, cols) = nlp.jacobian_structure();
    let mut jv = vec![0.0; rows.len()];
    assert!(nlp.jacobian(z, &mut jv));
    // Dense Jacobian from the sparse one (entries may repeat: sum them).
    let mut dense = vec![0.0; m * n];
    for k in 0..rows.len() {
        dense[rows[k] * n + cols[k]] += jv[k];
    }
    let mut zp = z.to_vec();
    let (mut gp, mut gm) = (vec![0.0; m], vec![0.0; m]);
    let (mut err_g, mut err_j): (f64, f64) = (0.0, 0.0);
    for j in 0..n {
        let h = 1e-6 * (1.0 + z[j].abs());
        zp[j] = z[j] + h;
        let fp = nlp.objective(&zp).expect("finite objective");
        nlp.constraints(&zp, &mut gp);
        zp[j] = z[j] - h;
        let fm = nlp.objective(&zp).expect("finite objective");
        nlp.constraints(&zp, &mut gm);
        zp[j] = z[j];
        let fd = (fp - fm) / (2.0 * h);
        err_g = err_g.max((grad[j] - fd).abs() / (1.0 + fd.abs()));
        for i in 0..m {
            let fd = (gp[i] - gm[i]) / (2.0 * h);
            err_j = err_j.max((dense[i * n + j] - fd).abs() / (1.0 + fd.abs()));
        }
    }
    (err_g, err_j)
}

/// Largest relative error between the Hessian of the Lagrangian σ f + λᵀ g
/// that `nlp` gives (lower triangle) and central differences of the assembled
/// gradient and Jacobian (∇f σ + Jᵀλ) at `z`: an independent computation of
/// what the element-wise differences, the linear variables and the skipped
/// negligible multipliers give (max |exact − fd| / (1 + |fd|)).
pub fn hessian_check(nlp: &mut dyn Nlp, z: &[f64], sigma: f64, lambda: &[f64]) -> f64 {
    let n = nlp.n();
    let (rows, cols) = nlp.hessian_structure().expect("an exact Hessian");
    let mut values = vec![0.0; rows.len()];
    assert!(nlp.hessian(z, sigma, lambda, &mut values));
    let mut dense = vec![0.0; n * n];
    for k in 0..rows.len() {
        dense[rows[k] * n + cols[k]] += values[k];
    }
    let (jr, jc) = nlp.jacobian_structure();
    let mut jv = vec![0.0; jr.len()];
    let mut lagrangian_grad = |x: &[f64], out: &mut [f64]| {
        assert!(nlp.gradient(x, out));
        assert!(nlp.jacobian(x, &mut jv));
        for v in out.iter_mut() {
            *v *= sigma;
        }
        for k in 0..jr.len() {
            out[jc[k]] += lambda[jr[k]] * jv[k];
        }
    };
    let (mut gp, mut gm) = (vec![0.0; n], vec![0.0; n]);
    let mut zp = z.to_vec();
    let mut err: f64 = 0.0;
    for j in 0..n {
        let h = 1e-5 * (1.0 + z[j].abs());
        zp[j] = z[j] + h;
        lagrangian_grad(&zp, &mut gp);
        zp[j] = z[j] - h;
        lagrangian_grad(&zp, &mut gm);
        zp[j] = z[j];
        // Row a ≥ j of column j (the lower triangle).
        for a in j..n {
            let fd = (gp[a] - gm[a]) / (2.0 * h);
            err = err.max((dense[a * n + j] - fd).abs() / (1.0 + fd.abs()));
        }
    }
    err
}
