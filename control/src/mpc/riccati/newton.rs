//! The Newton system of one interior-point iteration, by the Riccati
//! recursion over the stages (the method is described in the parent
//! module): the factorisation of the stage blocks for the iteration's
//! scaling D, and the backward and forward sweeps of a predictor or
//! corrector direction.

use super::*;

impl RiccatiBackend {
    /// Condensed stage Hessians for D = λ/t (in `dmat`), then the Riccati
    /// factorisation. False if a Q_uu is not positive definite.
    pub(super) fn factor(&mut self) -> bool {
        let l = &self.layout;
        let n = l.horizon;
        let neq = l.n_eq;
        for k in 0..=n {
            self.hc[k] = self.h[k];
        }
        for k in 0..n {
            let r = l.row_controls(k) - neq;
            for i in 0..NU {
                self.hc[k][(NX + i, NX + i)] += self.dmat[r + i] + self.dmat[r + 2 + i];
            }
        }
        for m in 1..=n {
            for (c, &ix) in SOFT_STATES.iter().enumerate() {
                let ru = l.row_states(m) + c - neq;
                let rl = ru + 3;
                let r0 = l.row_state_slack(m, c) - neq;
                let (du, dl, d0) = (self.dmat[ru], self.dmat[rl], self.dmat[r0]);
                let d = du + dl + d0;
                let gi = st_group(m, c);
                self.st_v[gi] = du - dl;
                self.st_d[gi] = d;
                // D_u + D_l − (D_u − D_l)²/d without cancellation.
                self.hc[m][(ix, ix)] += (4.0 * du * dl + d0 * (du + dl)) / d;
            }
        }
        if l.n_obs > 0 {
            for k in 0..n {
                let mut s = 0.0;
                let mut v = V8::zeros();
                for j in 0..l.n_obs {
                    for a in 0..AXLE_POINTS {
                        let e = l.obstacle_entry(k, j, a);
                        let di = self.dmat[l.row_obstacle(k, j, a) - neq];
                        s += di;
                        v += self.obs_a[e] * di;
                    }
                }
                let d0 = self.dmat[l.row_obstacle_slack(k) - neq];
                let d = s + d0;
                let mean = if s > 0.0 { v / s } else { V8::zeros() };
                let hk = &mut self.hc[k];
                for j in 0..l.n_obs {
                    for a in 0..AXLE_POINTS {
                        let e = l.obstacle_entry(k, j, a);
                        let di = self.dmat[l.row_obstacle(k, j, a) - neq];
                        let dev = self.obs_a[e] - mean;
                        hk.ger(di, &dev, &dev, 1.0);
                    }
                }
                hk.ger(s * d0 / d, &mean, &mean, 1.0);
                self.obs_v[k] = v;
                self.obs_d[k] = d;
            }
        }
        // Riccati: P_N = H_N; P_k = Q_xx − Q_uxᵀ Q_uu⁻¹ Q_ux.
        self.pm[n] = self.hc[n].fixed_view::<NX, NX>(0, 0).into_owned();
        for k in (0..n).rev() {
            let pn = &self.pm[k + 1];
            let (a, b) = (&self.a[k], &self.b[k]);
            let pa = pn * a;
            let pb = pn * b;
            let hk = &self.hc[k];
            let qxx = hk.fixed_view::<NX, NX>(0, 0) + a.tr_mul(&pa);
            let qux = hk.fixed_view::<NU, NX>(NX, 0) + b.tr_mul(&pa);
            let mut quu = hk.fixed_view::<NU, NU>(NX, NX) + b.tr_mul(&pb);
            let scale = quu[(0, 0)].abs().max(quu[(1, 1)].abs()).max(1.0);
            for i in 0..NU {
                quu[(i, i)] += REGULARISATION * scale;
            }
            // 2×2 Cholesky.
            let l11 = quu[(0, 0)];
            if !(l11 > 0.0) {
                return false;
            }
            let l21 = quu[(1, 0)] / l11.sqrt();
            let l22 = quu[(1, 1)] - l21 * l21;
            if !(l22 > 0.0) || !l22.is_finite() {
                return false;
            }
            let det = l11 * l22;
            let inv = M2::new(quu[(1, 1)], -quu[(0, 1)], -quu[(1, 0)], quu[(0, 0)]) / det;
            let kk = -(inv * qux);
            let mut p = qxx + qux.tr_mul(&kk);
            p = (p + p.transpose()) * 0.5;
            self.pm[k] = p;
            self.k[k] = kk;
            self.quu_inv[k] = inv;
        }
        true
    }

    /// Solves the Newton system for the current `rho` (and `dmat`, factored):
    /// writes dw, dy (as the new y minus the current), dλ and dt.
    pub(super) fn newton(&mut self) {
        let l = &self.layout;
        let n = l.horizon;
        let neq = l.n_eq;
        // Condensed gradients g̃ = r_z + Gᵀρ − v ρ_ς / d.
        for k in 0..=n {
            let c0 = l.x(k);
            let dim = if k < n { NZ } else { NX };
            let mut g = V8::zeros();
            for i in 0..dim {
                g[i] = self.rz[c0 + i];
            }
            self.gc[k] = g;
        }
        for k in 0..n {
            let r = l.row_controls(k) - neq;
            for i in 0..NU {
                self.gc[k][NX + i] += self.rho[r + i] - self.rho[r + 2 + i];
            }
        }
        for m in 1..=n {
            for (c, &ix) in SOFT_STATES.iter().enumerate() {
                let ru = l.row_states(m) + c - neq;
                let rl = ru + 3;
                let r0 = l.row_state_slack(m, c) - neq;
                let gi = st_group(m, c);
                let rs = self.rho[ru] + self.rho[rl] + self.rho[r0] - self.rz[l.state_slack(m, c)];
                self.st_rs[gi] = rs;
                self.gc[m][ix] += self.rho[ru] - self.rho[rl] - self.st_v[gi] * rs / self.st_d[gi];
            }
        }
        if l.n_obs > 0 {
            for k in 0..n {
                let mut sum = V8::zeros();
                let mut rs = -self.rz[l.obstacle_slack(k)];
                for j in 0..l.n_obs {
                    for a in 0..AXLE_POINTS {
                        let e = l.obstacle_entry(k, j, a);
                        let rho = self.rho[l.row_obstacle(k, j, a) - neq];
                        sum += self.obs_a[e] * rho;
                        rs += rho;
                    }
                }
                rs += self.rho[l.row_obstacle_slack(k) - neq];
                self.obs_rs[k] = rs;
                self.gc[k] += sum - self.obs_v[k] * (rs / self.obs_d[k]);
            }
        }
        // Backward: p_N = g̃_N; p_k = q_x + K_kᵀ q_u with s = P c + p.
        self.pv[n] = self.gc[n].fixed_rows::<NX>(0).into_owned();
        for k in (0..n).rev() {
            let r = l.row_dynamics(k);
            let c = -V6::from_column_slice(&self.re[r..r + NX]);
            let s = self.pm[k + 1] * c + self.pv[k + 1];
            let qx = self.gc[k].fixed_rows::<NX>(0) + self.a[k].tr_mul(&s);
            let qu = self.gc[k].fixed_rows::<NU>(NX) + self.b[k].tr_mul(&s);
            self.pv[k] = qx + self.k[k].tr_mul(&qu);
            // Keep q_u for the forward sweep in the terminal-unused slot of gc.
            self.gc[k][NX] = qu[0];
            self.gc[k][NX + 1] = qu[1];
        }
        // Forward.
        let mut dx = -V6::from_column_slice(&self.re[0..NX]);
        for k in 0..=n {
            let c0 = l.x(k);
            for i in 0..NX {
                self.dw[c0 + i] = dx[i];
            }
            if k < n {
                let qu = V2::new(self.gc[k][NX], self.gc[k][NX + 1]);
                let du = self.k[k] * dx - self.quu_inv[k] * qu;
                for i in 0..NU {
                    self.dw[l.u(k) + i] = du[i];
                }
                let r = l.row_dynamics(k);
                let c = -V6::from_column_slice(&self.re[r..r + NX]);
                dx = self.a[k] * dx + self.b[k] * du + c;
            }
        }
        // Slacks, dλ = D(G dw) + ρ and dt = −r_p − G dw. In a slack's group
        // dλ is written so that a row with large D does not multiply the
        // round-off of dz − ds by it (the slack absorbs that row's motion).
        for k in 0..n {
            let r = l.row_controls(k) - neq;
            for i in 0..NU {
                let du = self.dw[l.u(k) + i];
                for (row, g) in [(r + i, du), (r + 2 + i, -du)] {
                    self.dlam[row] = self.dmat[row] * g + self.rho[row];
                    self.dt[row] = -self.rp[row] - g;
                }
            }
        }
        for m in 1..=n {
            for (c, &ix) in SOFT_STATES.iter().enumerate() {
                let gi = st_group(m, c);
                let dx = self.dw[l.x(m) + ix];
                let d = self.st_d[gi];
                let ds = (self.st_rs[gi] + self.st_v[gi] * dx) / d;
                let sv = l.state_slack(m, c);
                self.dw[sv] = ds;
                let rs = self.rz[sv];
                let ru = l.row_states(m) + c - neq;
                let (rl, r0) = (ru + 3, l.row_state_slack(m, c) - neq);
                let (du, dl, d0) = (self.dmat[ru], self.dmat[rl], self.dmat[r0]);
                let (pu, pl, p0) = (self.rho[ru], self.rho[rl], self.rho[r0]);
                self.dlam[ru] =
                    (du * (2.0 * dl + d0) * dx + (dl + d0) * pu - du * (pl + p0 - rs)) / d;
                self.dlam[rl] =
                    (-dl * (2.0 * du + d0) * dx + (du + d0) * pl - dl * (pu + p0 - rs)) / d;
                self.dlam[r0] = (-d0 * (du - dl) * dx + (du + dl) * p0 - d0 * (pu + pl - rs)) / d;
                self.dt[ru] = -self.rp[ru] - (dx - ds);
                self.dt[rl] = -self.rp[rl] + dx + ds;
                self.dt[r0] = -self.rp[r0] + ds;
            }
        }
        if l.n_obs > 0 {
            let rows = AXLE_POINTS * l.n_obs;
            let mut alpha = [0.0; 2 * MAX_OBSTACLES];
            let mut rows_of = [0usize; 2 * MAX_OBSTACLES];
            for k in 0..n {
                let c0 = l.x(k);
                let mut dz = V8::zeros();
                for i in 0..NZ {
                    dz[i] = self.dw[c0 + i];
                }
                let d = self.obs_d[k];
                let ds = (self.obs_rs[k] + self.obs_v[k].dot(&dz)) / d;
                let sv = l.obstacle_slack(k);
                self.dw[sv] = ds;
                let rs = self.rz[sv];
                let r0 = l.row_obstacle_slack(k) - neq;
                let (d0, p0) = (self.dmat[r0], self.rho[r0]);
                let (mut sum_da, mut sum_rho, mut sum_d) = (0.0, 0.0, 0.0);
                for j in 0..l.n_obs {
                    for a in 0..AXLE_POINTS {
                        let e = l.obstacle_entry(k, j, a);
                        let i = e - k * rows;
                        let row = l.row_obstacle(k, j, a) - neq;
                        rows_of[i] = row;
                        alpha[i] = self.obs_a[e].dot(&dz);
                        sum_da += self.dmat[row] * alpha[i];
                        sum_rho += self.rho[row];
                        sum_d += self.dmat[row];
                    }
                }
                for i in 0..rows {
                    let row = rows_of[i];
                    let (mut spread, mut others_d, mut others_rho) = (0.0, 0.0, 0.0);
                    for j in 0..rows {
                        if j != i {
                            let dj = self.dmat[rows_of[j]];
                            spread += dj * (alpha[i] - alpha[j]);
                            others_d += dj;
                            others_rho += self.rho[rows_of[j]];
                        }
                    }
                    let di = self.dmat[row];
                    self.dlam[row] = (di * (d0 * alpha[i] + spread)
                        + (d0 + others_d) * self.rho[row]
                        - di * (others_rho + p0 - rs))
                        / d;
                    self.dt[row] = -self.rp[row] - (alpha[i] - ds);
                }
                self.dlam[r0] = (-d0 * sum_da + sum_d * p0 - d0 * (sum_rho - rs)) / d;
                self.dt[r0] = -self.rp[r0] + ds;
            }
        }
        // The new equality multipliers from the states' stationarity rows,
        // backwards (y_{k−1} = −(r_z + H dz + Gᵀdλ)_x + A_kᵀ y_k): exact in
        // those rows whatever the round-off of the Riccati's large D terms.
        let mut sd = std::mem::take(&mut self.scratch);
        self.stationarity(&self.dw, &self.dlam, false, &mut sd);
        let l = &self.layout;
        let mut y = V6::zeros();
        for k in (0..=n).rev() {
            let c0 = l.x(k);
            let mut r = -V6::from_iterator((0..NX).map(|i| self.rz[c0 + i] + sd[c0 + i]));
            if k < n {
                r += self.a[k].tr_mul(&y);
            }
            y = r;
            let row = if k == 0 { 0 } else { l.row_dynamics(k - 1) };
            for i in 0..NX {
                self.dy[row + i] = y[i] - self.y[row + i];
            }
        }
        // The controls' stationarity rows likewise: a control at its bound
        // has D ~ 1/t huge, so D·(G dw) amplifies the round-off of du; its
        // bound row's dλ is taken from the row instead (the other bound's, with
        // small D, is accurate).
        let neq = l.n_eq;
        for k in 0..n {
            let r = l.row_dynamics(k);
            let yk = V6::from_column_slice(&self.y[r..r + NX])
                + V6::from_column_slice(&self.dy[r..r + NX]);
            let by = self.b[k].tr_mul(&yk);
            let rc = l.row_controls(k) - neq;
            for i in 0..NU {
                let v = l.u(k) + i;
                let e = self.rz[v] + sd[v] - by[i];
                let (up, lo) = (rc + i, rc + 2 + i);
                if self.dmat[up] >= self.dmat[lo] {
                    self.dlam[up] -= e;
                } else {
                    self.dlam[lo] += e;
                }
            }
        }
        self.scratch = sd;
    }
}
