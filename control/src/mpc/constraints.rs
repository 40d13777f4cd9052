//! Constraint rows of the QP (paper eq. 17–18 and the control bounds of §IV-E):
//! hard control bounds, soft state bounds on n = 1..N, soft circular obstacles
//! on both axle points (linearised distance, or the discrete-time CBF form),
//! all linearised at the linearisation point (x̄, ū). Rows and entries are
//! those of [`super::layout::QpLayout`].

pub use crate::obstacle::Obstacle;

use crate::model::{Control, MachineParams, State};
use crate::site::outline::MAX_OUTLINE_CIRCLES;
use crate::world::{RowPair, Target, World};

use super::live_rows::LiveRows;

use super::layout::{QpLayout, AXLE_POINTS, OBS_STATES, SOFT_STATES};
use super::settings::ObstacleConstraint;

/// Right-hand sides of the control and state bounds:
/// ±(ū + Δu) ≤ u_max and ±(x̄_c + Δx_c) − s ≤ max_c.
pub fn fill_bounds(
    layout: &QpLayout,
    p: &MachineParams,
    xbar: &[State],
    ubar: &[Control],
    b: &mut [f64],
) {
    let umax = p.control_max();
    for (n, u) in ubar.iter().enumerate() {
        let r = layout.row_controls(n);
        for i in 0..2 {
            b[r + i] = umax[i] - u[i];
            b[r + 2 + i] = umax[i] + u[i];
        }
    }
    let smax = [p.beta_max, p.beta_dot_max, p.v_max];
    for (n, x) in xbar.iter().enumerate().skip(1) {
        let r = layout.row_states(n);
        for (c, &k) in SOFT_STATES.iter().enumerate() {
            b[r + c] = smax[c] - x[k];
            b[r + 3 + c] = smax[c] + x[k];
        }
    }
}

/// What the obstacle rows are built from: row k's (outline circle, target)
/// pairs `pairs[k · stride ..][..len[k]]`, the world that measures them and
/// each outline circle's margin.
pub struct ObstacleRows<'a> {
    pub world: &'a World,
    pub margins: [f64; MAX_OUTLINE_CIRCLES],
    pub pairs: &'a [RowPair],
    pub len: &'a [usize],
    pub stride: usize,
    /// The live obstacles' rows (pairs of target `Target::Live`).
    pub live: Option<&'a LiveRows>,
}

/// Obstacle rows (paper eq. 18 on the outline, DESIGN §17): for each row
/// k = 0..N−1 and slot s (the layout's slot s / 2, row s mod 2) holding the
/// pair (outline circle c, target t),
///
/// * distance form: h(x̄_{k+1}) + ∇h·Δx_{k+1} + s ≥ 0,
/// * CBF form: h(x̄_{k+1}) + ∇h_{k+1}·Δx_{k+1} − (1 − γ)(h(x̄_k) + ∇h_k·Δx_k) + s ≥ 0,
///
/// with h the clearance of c to t less c's margin ([`World::row`]: a
/// feature's nearest edge is its half-plane at x̄; a live obstacle is
/// predicted to the stage's time, [`LiveRows::row`]) and ∇h over
/// (x_f, y_f, θ, β), written as A w ≤ b. Empty slots get zero coefficients
/// and b = 1 (always satisfied with a zero slack).
pub fn fill_obstacles(
    layout: &QpLayout,
    rows: &ObstacleRows,
    form: ObstacleConstraint,
    gamma: f64,
    xbar: &[State],
    a: &mut [f64],
    b: &mut [f64],
) {
    let cbf = form == ObstacleConstraint::Cbf;
    let m = OBS_STATES.len();
    for k in 0..layout.horizon {
        let pairs = &rows.pairs[k * rows.stride..][..rows.len[k]];
        for j in 0..layout.n_obs {
            for ai in 0..AXLE_POINTS {
                let e = &layout.a_obs[layout.obstacle_entry(k, j, ai)];
                let r = layout.row_obstacle(k, j, ai);
                let Some(pair) = pairs.get(j * AXLE_POINTS + ai) else {
                    let used = if cbf { 2 * m } else { m };
                    for &pos in &e[..used] {
                        a[pos] = 0.0;
                    }
                    b[r] = 1.0;
                    continue;
                };
                // A live row's margins are in its h ([`LiveRows::row`]).
                let (row, margin) = match (pair.target, rows.live) {
                    (Target::Live(i), Some(live)) => (Some((live, i)), 0.0),
                    _ => (None, rows.margins[pair.circle]),
                };
                let h = |n: usize| match row {
                    Some((live, i)) => live.row(rows.world, &xbar[n], n, pair.circle, i),
                    None => rows.world.row(&xbar[n], pair.circle, pair.target),
                };
                let (h1, g1) = h(k + 1);
                for c in 0..m {
                    a[e[c]] = -g1[c];
                }
                b[r] = h1 - margin;
                if cbf {
                    let (h0, g0) = h(k);
                    let keep = 1.0 - gamma;
                    for c in 0..m {
                        a[e[m + c]] = keep * g0[c];
                    }
                    b[r] -= keep * (h0 - margin);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obstacle::AxlePoint;

    /// The rear-axle row carries the clearance's θ and β derivatives; an
    /// obstacle only the rear axle is near gives the smaller right-hand side.
    #[test]
    fn rear_axle_rows_are_filled() {
        let p = MachineParams::default();
        let layout = QpLayout::new(2, 1, ObstacleConstraint::Distance);
        let xbar = vec![State::new(0.0, 0.0, 0.3, 0.2, 0.0, 0.0); 3];
        let o = [Obstacle::new(-1.5, -0.3, 0.2)];
        let mut a = layout.a_constant.clone();
        let mut b = vec![0.0; layout.n_eq + layout.n_ineq];
        let mut world = World::with_axle_circles(p, 1);
        world.set_circles(&o).unwrap();
        let pair = |circle| RowPair {
            circle,
            target: crate::world::Target::Circle(0),
            excess: 0.0,
        };
        let mut margins = [0.0; MAX_OUTLINE_CIRCLES];
        margins[..2].copy_from_slice(&[0.05, 0.08]);
        fill_obstacles(
            &layout,
            &ObstacleRows {
                world: &world,
                margins,
                pairs: &[pair(0), pair(1), pair(0), pair(1)],
                len: &[2, 2],
                stride: 2,
                live: None,
            },
            ObstacleConstraint::Distance,
            0.0,
            &xbar,
            &mut a,
            &mut b,
        );
        assert_eq!(AXLE_POINTS, 2);
        for k in 0..2 {
            let (hf, _) = o[0].point_clearance(&p, AxlePoint::Front, &xbar[k + 1]);
            let (hr, gr) = o[0].point_clearance(&p, AxlePoint::Rear, &xbar[k + 1]);
            assert!((b[layout.row_obstacle(k, 0, 0)] - (hf - 0.05)).abs() < 1e-15);
            // Each axle point its own margin.
            assert!((b[layout.row_obstacle(k, 0, 1)] - (hr - 0.08)).abs() < 1e-15);
            assert!(hr < hf);
            let e = layout.a_obs[layout.obstacle_entry(k, 0, 1)];
            for c in 0..4 {
                assert_eq!(a[e[c]], -gr[c]);
            }
            assert!(gr[2] != 0.0 && gr[3] != 0.0);
            let ef = layout.a_obs[layout.obstacle_entry(k, 0, 0)];
            assert_eq!((a[ef[2]], a[ef[3]]), (0.0, 0.0));
        }
    }
}
