//! Motion primitives of the Hybrid A* search, integrated from the machine model
//! (paper eq. 5) rather than from a bicycle approximation: at constant
//! articulation β (β̇ = 0) the front axle turns at the steady-state rate
//! θ̇ = v sin β / (L_f cos β + L_r), which [`rk4_step`] integrates.
//!
//! Each primitive is stored as front-axle poses relative to its start pose
//! (start at the origin, heading 0), sampled along the arc for the collision
//! check; the search composes them with a node's pose.

use crate::model::{ix, rk4_step, Control, MachineParams, State};

/// A pose of the front axle relative to a primitive's start: (dx, dy, dθ).
pub type RelPose = [f64; 3];

/// One forward or reverse arc at a fixed articulation.
#[derive(Debug, Clone, PartialEq)]
pub struct Primitive {
    /// Articulation held along the arc [rad].
    pub beta: f64,
    /// +1 forward, −1 reverse.
    pub direction: i8,
    /// Arc length of the front axle [m].
    pub length: f64,
    /// Relative poses along the arc, equally spaced, the last one the end.
    pub samples: Vec<RelPose>,
}

impl Primitive {
    pub fn end(&self) -> RelPose {
        // `build` always stores at least one sample.
        self.samples[self.samples.len() - 1]
    }
}

/// Substeps of the RK4 integration per sample: the arc is integrated much
/// finer than it is sampled, so the samples carry no visible integration error.
const SUBSTEPS_PER_SAMPLE: usize = 8;

/// Forward and reverse arcs at each articulation in `betas`, `length` long,
/// sampled every `sample_spacing` metres or finer.
pub fn build(
    params: &MachineParams,
    betas: &[f64],
    length: f64,
    sample_spacing: f64,
) -> Vec<Primitive> {
    let n_samples = ((length / sample_spacing).ceil() as usize).max(1);
    let mut out = Vec::with_capacity(2 * betas.len());
    for direction in [1i8, -1] {
        for &beta in betas {
            out.push(integrate(params, beta, direction, length, n_samples));
        }
    }
    out
}

fn integrate(
    params: &MachineParams,
    beta: f64,
    direction: i8,
    length: f64,
    n_samples: usize,
) -> Primitive {
    // Unit speed: the duration equals the arc length.
    let v = f64::from(direction);
    let dt = length / (n_samples * SUBSTEPS_PER_SAMPLE) as f64;
    let mut x = State::new(0.0, 0.0, 0.0, beta, 0.0, v);
    let mut samples = Vec::with_capacity(n_samples);
    for _ in 0..n_samples {
        for _ in 0..SUBSTEPS_PER_SAMPLE {
            x = rk4_step(params, &x, &Control::zeros(), dt);
        }
        samples.push([x[ix::X], x[ix::Y], x[ix::THETA]]);
    }
    Primitive {
        beta,
        direction,
        length,
        samples,
    }
}

/// The pose reached from (x, y, θ) by the relative pose `rel`.
#[inline]
pub fn compose(x: f64, y: f64, theta: f64, rel: &RelPose) -> [f64; 3] {
    let (s, c) = theta.sin_cos();
    [
        x + c * rel[0] - s * rel[1],
        y + s * rel[0] + c * rel[1],
        theta + rel[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent check: the closed-form circle of constant articulation.
    /// Turning radius of the front axle R = (L_f cos β + L_r) / sin β (centre
    /// on the left for β > 0), heading change s / R after arc length s.
    #[test]
    fn primitives_match_the_closed_form_arc() {
        let p = MachineParams {
            l_f: 0.9,
            l_r: 1.3,
            ..MachineParams::default()
        };
        let betas = [-p.beta_max, -0.3, 0.0, 0.25, p.beta_max];
        let prims = build(&p, &betas, 0.7, 0.1);
        assert_eq!(prims.len(), 10);
        for prim in &prims {
            assert_eq!(prim.samples.len(), 7);
            for (k, rel) in prim.samples.iter().enumerate() {
                let s = f64::from(prim.direction) * prim.length * (k + 1) as f64 / 7.0;
                let expected = if prim.beta == 0.0 {
                    [s, 0.0, 0.0]
                } else {
                    let r = (p.l_f * prim.beta.cos() + p.l_r) / prim.beta.sin();
                    let dth = s / r;
                    [r * dth.sin(), r * (1.0 - dth.cos()), dth]
                };
                for i in 0..3 {
                    assert!(
                        (rel[i] - expected[i]).abs() < 1e-9,
                        "β {} dir {} sample {k} component {i}: {} vs {}",
                        prim.beta,
                        prim.direction,
                        rel[i],
                        expected[i]
                    );
                }
            }
        }
    }

    #[test]
    fn compose_rotates_into_the_start_frame() {
        let q = compose(1.0, 2.0, std::f64::consts::FRAC_PI_2, &[1.0, 0.5, 0.3]);
        assert!((q[0] - 0.5).abs() < 1e-12);
        assert!((q[1] - 3.0).abs() < 1e-12);
        assert!((q[2] - (std::f64::consts::FRAC_PI_2 + 0.3)).abs() < 1e-12);
    }
}
