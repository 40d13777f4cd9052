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

/// How the weighted errors |wᵢeᵢ| are combined with the exponent p.
///
/// The paper writes c = ‖We‖_{0.25} and wants "a nearly constant cost to states
/// which have not converged to the goal" (§IV-C), so that only reaching the goal
/// lowers it and the optimal policy is time-optimal. The literal quasi-norm
/// (Σ|wᵢeᵢ|^p)^(1/p) does not behave so: it is linear in a single error and
/// super-additive in several (five equal terms cost 625 times one), so every
/// manoeuvre that turns and moves costs tens of times more per step than
/// standing still off the goal, and under discounting standing still wins for
/// goals that need a turn. The authors' public code uses (Σ wᵢ|eᵢ|)^p instead:
/// flat far away, steep (infinite slope) at the goal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CostForm {
    /// c = (Σ |wᵢ eᵢ|^p)^(1/p), DESIGN §3 read literally.
    #[default]
    QuasiNorm,
    /// c = (Σ wᵢ |eᵢ|)^p, the authors' implementation (DESIGN §4).
    PowerOfSum,
}

impl CostForm {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::QuasiNorm => "quasi-norm",
            Self::PowerOfSum => "power-of-sum",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        [Self::QuasiNorm, Self::PowerOfSum]
            .into_iter()
            .find(|f| f.as_str() == s)
    }
}

/// Weights W on e = [e_xy (m), e_θ (rad), β (rad), β̇ (rad/s), v_f (m/s)], the
/// exponent p and how they combine. The paper gives p = 0.25 and leaves W open.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostWeights {
    pub w: [f64; 5],
    pub p: f64,
    pub form: CostForm,
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
            form: CostForm::QuasiNorm,
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

    /// c(s, g) as selected by `form`.
    pub fn stage_cost(&self, x: &State, g: &Goal) -> f64 {
        let e = pose_error(x, g);
        let we = e.iter().zip(self.w).map(|(e, w)| (w * e).abs());
        match self.form {
            CostForm::QuasiNorm => we.map(|a| a.powf(self.p)).sum::<f64>().powf(1.0 / self.p),
            CostForm::PowerOfSum => we.sum::<f64>().powf(self.p),
        }
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
            form: CostForm::QuasiNorm,
        };
        assert!((c1.stage_cost(&x, &g) - (5.0 + 1.0 + 0.1 + 0.2 + 0.3)).abs() < 1e-12);
        let cq = CostWeights {
            w: [1.0, 0.0, 0.0, 0.0, 0.0],
            p: 0.25,
            form: CostForm::QuasiNorm,
        };
        assert!((cq.stage_cost(&x, &g) - 5.0).abs() < 1e-12);
        // Two equal terms: (2 a^p)^(1/p) = 16 a for p = 1/4.
        let x2 = State::new(1.0, 0.0, 1.0, 0.0, 0.0, 0.0);
        let c2 = CostWeights {
            w: [1.0, 1.0, 0.0, 0.0, 0.0],
            p: 0.25,
            form: CostForm::QuasiNorm,
        };
        assert!((c2.stage_cost(&x2, &g) - 16.0).abs() < 1e-12);
        assert_eq!(c2.stage_cost(&State::zeros(), &g), 0.0);
    }

    #[test]
    fn power_of_sum_is_the_root_of_the_weighted_l1_error() {
        let g = Goal::new(0.0, 0.0, 0.0);
        // e = [5, 0.5, 0.1, 0.2, 0.3] (|(3, 4)| = 5).
        let x = State::new(3.0, 4.0, 0.5, 0.1, -0.2, 0.3);
        let c = CostWeights {
            w: [1.0, 2.0, 1.0, 1.0, 1.0],
            p: 0.25,
            form: CostForm::PowerOfSum,
        };
        let l1: f64 = 5.0 + 1.0 + 0.1 + 0.2 + 0.3;
        assert!((c.stage_cost(&x, &g) - l1.powf(0.25)).abs() < 1e-12);
        // Sub-additive: two equal errors cost 2^p times one, not 2^(1/p).
        let one = State::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let two = State::new(1.0, 0.0, 0.5, 0.0, 0.0, 0.0);
        let ratio = c.stage_cost(&two, &g) / c.stage_cost(&one, &g);
        assert!((ratio - 2f64.powf(0.25)).abs() < 1e-12);
        assert_eq!(c.stage_cost(&State::zeros(), &g), 0.0);
        for f in [CostForm::QuasiNorm, CostForm::PowerOfSum] {
            assert_eq!(CostForm::parse(f.as_str()), Some(f));
        }
        assert_eq!(CostForm::parse("l2"), None);
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
