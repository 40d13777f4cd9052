//! The command-line values of the perturbation options (`eval` and
//! `robustness` share them), each rejected with the flag's name, and a
//! one-line description of a perturbation.

use anyhow::{Context, Result};
use control::plant::PlantPerturbation;

/// A scale factor K of `--plant-scale-lf`, `--plant-scale-lr`, `--actuator-gain`.
pub fn parse_factor(s: &str) -> Result<f64, String> {
    parse_number(s, |k| k > 0.0 && k <= 10.0, "a factor in (0, 10]")
}

/// A duration S [s] of `--plant-delay`, `--pose-latency`.
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    parse_number(s, |t| (0.0..=10.0).contains(&t), "in [0, 10] s")
}

/// `SXY,STHETA` of `--pose-noise`: standard deviations [m], [rad].
pub fn parse_pose_noise(s: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [a, b] = parts[..] else {
        return Err(format!(
            "expected SXY,STHETA (two standard deviations, [m] and [rad]), got `{s}`"
        ));
    };
    let sd = |v| {
        parse_number(
            v,
            |x| (0.0..=10.0).contains(&x),
            "a standard deviation in [0, 10]",
        )
    };
    Ok((sd(a)?, sd(b)?))
}

/// `text` as a finite number that `valid` accepts; `range` describes the valid
/// values in the error.
fn parse_number(text: &str, valid: impl Fn(f64) -> bool, range: &str) -> Result<f64, String> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    if v.is_finite() && valid(v) {
        Ok(v)
    } else {
        Err(format!("must be {range} (got {text})"))
    }
}

/// The perturbation options as parsed (each `None` when not given).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PerturbationOptions {
    pub plant_scale_lf: Option<f64>,
    pub plant_scale_lr: Option<f64>,
    pub plant_delay: Option<f64>,
    pub actuator_gain: Option<f64>,
    pub pose_noise: Option<(f64, f64)>,
    pub pose_latency: Option<f64>,
    pub seed: u64,
}

impl PerturbationOptions {
    /// The one [`PlantPerturbation`] they describe (validated).
    pub fn perturbation(&self) -> Result<PlantPerturbation> {
        let d = PlantPerturbation::default();
        let (sxy, sth) = self.pose_noise.unwrap_or((0.0, 0.0));
        let p = PlantPerturbation {
            scale_lf: self.plant_scale_lf.unwrap_or(d.scale_lf),
            scale_lr: self.plant_scale_lr.unwrap_or(d.scale_lr),
            delay: self.plant_delay,
            actuator_gain: self.actuator_gain.unwrap_or(d.actuator_gain),
            pose_noise_xy: sxy,
            pose_noise_theta: sth,
            pose_latency: self.pose_latency.unwrap_or(d.pose_latency),
            seed: self.seed,
        };
        p.validate().context("plant perturbation options")?;
        Ok(p)
    }
}

/// A one-line description, e.g. `L_f × 1.1, actuator gain 0.9`; `none`.
pub fn describe(p: &PlantPerturbation) -> String {
    let mut v = Vec::new();
    if p.scale_lf != 1.0 {
        v.push(format!("L_f × {}", p.scale_lf));
    }
    if p.scale_lr != 1.0 {
        v.push(format!("L_r × {}", p.scale_lr));
    }
    if let Some(d) = p.delay {
        v.push(format!("plant delay {d} s"));
    }
    if p.actuator_gain != 1.0 {
        v.push(format!("actuator gain {}", p.actuator_gain));
    }
    if p.pose_noise_xy > 0.0 || p.pose_noise_theta > 0.0 {
        v.push(format!(
            "pose noise {} m / {} rad",
            p.pose_noise_xy, p.pose_noise_theta
        ));
    }
    if p.pose_latency > 0.0 {
        v.push(format!("pose latency {} s", p.pose_latency));
    }
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn option_values_are_checked() {
        assert_eq!(parse_factor("1.1"), Ok(1.1));
        for bad in ["0", "-1", "nan", "inf", "x", "11"] {
            assert!(parse_factor(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_seconds("0.35"), Ok(0.35));
        assert!(parse_seconds("-0.1").is_err());
        assert!(parse_seconds("NaN").is_err());
        assert_eq!(parse_pose_noise("0.03,0.02"), Ok((0.03, 0.02)));
        for bad in ["0.03", "0.03,0.02,1", "a,b", "-0.1,0.0", "0.1,inf"] {
            assert!(parse_pose_noise(bad).is_err(), "{bad}");
        }
        let o = PerturbationOptions {
            plant_scale_lf: Some(1.1),
            pose_noise: Some((0.03, 0.02)),
            ..Default::default()
        };
        let p = o.perturbation().unwrap();
        assert_eq!(p.scale_lf, 1.1);
        assert_eq!((p.pose_noise_xy, p.pose_noise_theta), (0.03, 0.02));
        assert!(PerturbationOptions::default()
            .perturbation()
            .unwrap()
            .is_nominal());
    }
}
