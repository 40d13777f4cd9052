//! The environment's stage cost c = ‖W e‖_p (paper eq. 9).

use serde::{Deserialize, Serialize};

use crate::model::{pose_error, Goal, State};

/// Errors in cost parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CostError {
    #[error("cost weight `w[{index}]` must be finite and >= 0 (got {value})")]
    BadWeight { index: usize, value: f64 },
    #[error("cost exponent `p` must be finite and > 0 (got {0})")]
    BadExponent(f64),
}

/// Weights W on e = [e_xy (m), e_θ (rad), β (rad), β̇ (rad/s), v_f (m/s)] and the
/// exponent p of the (quasi-)norm. The paper gives p = 0.25 and leaves W open.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostWeights {
    pub w: [f64; 5],
    pub p: f64,
}

impl Default for CostWeights {
    /// Position and heading dominate, the rates and speed only have to vanish
    /// at rest. A heading error of 0.1 rad weighs like 0.1 m (the success test
    /// of DESIGN §7 treats them alike); β, β̇, v_f get a smaller weight. The
    /// overall scale 1/100 keeps c of order 1 far from the goal (p = 1/4 sums
    /// fourth roots, so five moderate errors add up to a few hundred times one),
    /// and so the critic's values of order 10–100.
    fn default() -> Self {
        Self {
            w: [0.01, 0.01, 0.003, 0.003, 0.005],
            p: 0.25,
        }
    }
}

impl CostWeights {
    pub fn validate(&self) -> Result<(), CostError> {
        for (index, &value) in self.w.iter().enumerate() {
            if !(value.is_finite() && value >= 0.0) {
                return Err(CostError::BadWeight { index, value });
            }
        }
        if !(self.p.is_finite() && self.p > 0.0) {
            return Err(CostError::BadExponent(self.p));
        }
        Ok(())
    }

    /// c(s, g) = (Σ |wᵢ eᵢ|^p)^(1/p).
    pub fn stage_cost(&self, x: &State, g: &Goal) -> f64 {
        let e = pose_error(x, g);
        let s: f64 = e
            .iter()
            .zip(self.w)
            .map(|(e, w)| (w * e).abs().powf(self.p))
            .sum();
        s.powf(1.0 / self.p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn p_one_is_weighted_l1_and_p_quarter_is_sparse() {
        let g = Goal::new(0.0, 0.0, 0.0);
        let x = State::new(3.0, 4.0, 0.5, 0.1, -0.2, 0.3);
        let c1 = CostWeights {
            w: [1.0, 2.0, 1.0, 1.0, 1.0],
            p: 1.0,
        };
        assert!((c1.stage_cost(&x, &g) - (5.0 + 1.0 + 0.1 + 0.2 + 0.3)).abs() < 1e-12);
        let cq = CostWeights {
            w: [1.0, 0.0, 0.0, 0.0, 0.0],
            p: 0.25,
        };
        assert!((cq.stage_cost(&x, &g) - 5.0).abs() < 1e-12);
        // Two equal terms: (2 a^p)^(1/p) = 16 a for p = 1/4.
        let x2 = State::new(1.0, 0.0, 1.0, 0.0, 0.0, 0.0);
        let c2 = CostWeights {
            w: [1.0, 1.0, 0.0, 0.0, 0.0],
            p: 0.25,
        };
        assert!((c2.stage_cost(&x2, &g) - 16.0).abs() < 1e-12);
        assert_eq!(c2.stage_cost(&State::zeros(), &g), 0.0);
    }

    #[test]
    fn validation_names_the_field() {
        let mut c = CostWeights::default();
        assert!(c.validate().is_ok());
        c.w[3] = -1.0;
        assert!(c.validate().unwrap_err().to_string().contains("w[3]"));
        let c = CostWeights {
            p: 0.0,
            ..Default::default()
        };
        assert!(c.validate().unwrap_err().to_string().contains("`p`"));
    }
}
