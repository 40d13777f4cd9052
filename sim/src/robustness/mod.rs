//! `robustness`: the MPC on a machine that is not its model (DESIGN §12,
//! issue 16). Each [`control::plant::PlantPerturbation`] alone over a range of
//! levels, and all of them at moderate levels at once, on the paper's 128
//! scenarios and a seeded subset of the obstacle set; writes
//! `docs/robustness.md`, a plot per perturbation and CSVs.
//!
//! This module holds the cases and sweeps; the others:
//! - `options`: the command-line values of the perturbation options (`eval`
//!   and `robustness` share them), each rejected with the flag's name;
//! - `figures`: the figures of a case on a scenario set, and the acceptance test;
//! - `run`: runs every case (each kept on disk, so an interrupted run continues);
//! - `csv_files`, `markdown`, `plot`: the CSVs, the page and its plots.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use control::envelope::EnvelopeSettings;
use control::plant::PlantPerturbation;
use control::scenario::Scenario;
use control::MachineParams;

mod csv_files;
mod figures;
mod markdown;
mod options;
mod plot;
mod run;

pub use figures::{accepted, Figures};
pub use options::{describe, parse_factor, parse_pose_noise, parse_seconds, PerturbationOptions};
pub use run::Inputs;

/// One closed-loop configuration: the perturbation and the delay the MPC compensates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    pub perturbation: PlantPerturbation,
    /// `--delay`: the delay the MPC compensates (and the plant's, unless the
    /// perturbation sets its own) [s].
    pub compensated: f64,
}

/// A level of a sweep: its value on the sweep's axis and its case.
#[derive(Debug, Clone)]
pub struct Level {
    pub x: f64,
    pub label: String,
    pub case: Case,
    /// An acceptance level of issue 16.
    pub acceptance: bool,
}

/// One perturbation over its levels (the nominal level included).
#[derive(Debug, Clone)]
pub struct Sweep {
    /// The `eval` flag.
    pub flag: &'static str,
    pub title: &'static str,
    pub x_desc: &'static str,
    /// The unperturbed value on the axis.
    pub nominal: f64,
    pub levels: Vec<Level>,
}

impl Case {
    /// The safety envelope as an integrator who knows these bounds configures
    /// it (DESIGN §14, README "The safety envelope"): the geometry's error
    /// (|ΔL_f| + |ΔL_r|), the pose noise, and an actuator delay beyond the
    /// compensated one as response lag, an actuator gain above 1 as the
    /// largest gain. The pose's age is known from its stamp
    /// (compensated exactly), so its latency adds no tolerance.
    pub fn stated_envelope(&self, base: EnvelopeSettings, p: &MachineParams) -> EnvelopeSettings {
        let q = &self.perturbation;
        EnvelopeSettings {
            geometry_tolerance: (q.scale_lf - 1.0).abs() * p.l_f + (q.scale_lr - 1.0).abs() * p.l_r,
            pose_noise_xy: q.pose_noise_xy,
            pose_noise_theta: q.pose_noise_theta,
            response_lag: (q.delay.unwrap_or(self.compensated) - self.compensated).max(0.0),
            actuator_gain_max: q.actuator_gain.max(1.0),
            ..base
        }
    }
}

fn case(perturbation: PlantPerturbation, compensated: f64) -> Case {
    Case {
        perturbation,
        compensated,
    }
}

/// The "all moderate at once" case of issue 16: geometry × 1.05, 0.25 s plant
/// delay with 0.2 s compensated, gain 0.9, pose noise 0.02 m / 0.01 rad,
/// pose latency 0.05 s.
pub fn all_moderate() -> Case {
    case(
        PlantPerturbation {
            scale_lf: 1.05,
            scale_lr: 1.05,
            delay: Some(0.25),
            actuator_gain: 0.9,
            pose_noise_xy: 0.02,
            pose_noise_theta: 0.01,
            pose_latency: 0.05,
            ..Default::default()
        },
        0.2,
    )
}

/// The sweeps: each perturbation alone, the acceptance levels of issue 16
/// among wider ones (to find where it breaks). The plant is the `eval`
/// default (ideal, no delay) except for the delay sweep, whose MPC
/// compensates 0.2 s.
pub fn standard_sweeps() -> Vec<Sweep> {
    let d = PlantPerturbation::default;
    let mut sweeps = Vec::new();
    let scale = |flag, title, x_desc, lf: bool| Sweep {
        flag,
        title,
        x_desc,
        nominal: 1.0,
        levels: [0.8, 0.9, 1.0, 1.1, 1.2]
            .iter()
            .map(|&k| Level {
                x: k,
                label: format!("× {k}"),
                case: case(
                    if lf {
                        PlantPerturbation { scale_lf: k, ..d() }
                    } else {
                        PlantPerturbation { scale_lr: k, ..d() }
                    },
                    0.0,
                ),
                acceptance: k == 0.9 || k == 1.1,
            })
            .collect(),
    };
    sweeps.push(scale(
        "--plant-scale-lf",
        "Geometry: plant L_f = K × nominal",
        "K (plant L_f / model L_f)",
        true,
    ));
    sweeps.push(scale(
        "--plant-scale-lr",
        "Geometry: plant L_r = K × nominal",
        "K (plant L_r / model L_r)",
        false,
    ));
    sweeps.push(Sweep {
        flag: "--plant-delay",
        title: "True plant delay, 0.2 s compensated",
        x_desc: "plant delay [s] (MPC compensates 0.2 s)",
        nominal: 0.2,
        levels: [0.0, 0.1, 0.2, 0.35, 0.5, 0.8]
            .iter()
            .map(|&s| Level {
                x: s,
                label: format!("{s} s"),
                case: case(
                    PlantPerturbation {
                        delay: Some(s),
                        ..d()
                    },
                    0.2,
                ),
                acceptance: s == 0.1 || s == 0.35,
            })
            .collect(),
    });
    sweeps.push(Sweep {
        flag: "--actuator-gain",
        title: "Actuator gain: achieved β̇, v = K × command",
        x_desc: "K",
        nominal: 1.0,
        levels: [0.6, 0.8, 1.0, 1.2, 1.4]
            .iter()
            .map(|&k| Level {
                x: k,
                label: format!("{k}"),
                case: case(
                    PlantPerturbation {
                        actuator_gain: k,
                        ..d()
                    },
                    0.0,
                ),
                acceptance: k == 0.8 || k == 1.2,
            })
            .collect(),
    });
    sweeps.push(Sweep {
        flag: "--pose-noise",
        title: "Pose noise (x, y and θ)",
        x_desc: "σ_xy [m] (σ_θ in the table)",
        nominal: 0.0,
        levels: [
            (0.0, 0.0),
            (0.01, 0.005),
            (0.03, 0.02),
            (0.06, 0.04),
            (0.1, 0.06),
        ]
        .iter()
        .map(|&(sxy, sth)| Level {
            x: sxy,
            label: format!("{sxy} m / {sth} rad"),
            case: case(
                PlantPerturbation {
                    pose_noise_xy: sxy,
                    pose_noise_theta: sth,
                    ..d()
                },
                0.0,
            ),
            acceptance: sxy == 0.03,
        })
        .collect(),
    });
    sweeps.push(Sweep {
        flag: "--pose-latency",
        title: "Pose latency",
        x_desc: "age of the pose [s]",
        nominal: 0.0,
        levels: [0.0, 0.05, 0.1, 0.2]
            .iter()
            .map(|&s| Level {
                x: s,
                label: format!("{s} s"),
                case: case(
                    PlantPerturbation {
                        pose_latency: s,
                        ..d()
                    },
                    0.0,
                ),
                acceptance: s == 0.1,
            })
            .collect(),
    });
    sweeps
}

/// A seeded fixed subset of `set`: `per_kind` scenarios of each kind (the
/// name without its number), chosen by a hash of (seed, name); in file order.
pub fn subset(set: &[Scenario], per_kind: usize, seed: u64) -> Vec<Scenario> {
    let key = |name: &str| {
        let mut h = seed ^ 0x9e37_79b9_7f4a_7c15;
        for b in name.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        // splitmix64 finaliser
        h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        h ^ (h >> 31)
    };
    let kind = |n: &str| n.trim_end_matches(|c: char| c.is_ascii_digit()).to_string();
    let mut by_kind: HashMap<String, Vec<&Scenario>> = HashMap::new();
    for sc in set {
        by_kind.entry(kind(&sc.name)).or_default().push(sc);
    }
    let mut chosen: Vec<&str> = Vec::new();
    for v in by_kind.values_mut() {
        v.sort_by_key(|s| key(&s.name));
        chosen.extend(v.iter().take(per_kind).map(|s| s.name.as_str()));
    }
    set.iter()
        .filter(|s| chosen.contains(&s.name.as_str()))
        .cloned()
        .collect()
}

/// Runs the sweeps and writes `out/robustness.md` and `out/robustness/`.
pub fn robustness(inp: &Inputs, sweeps: &[Sweep], out: &Path) -> Result<()> {
    let start = Instant::now();
    let results = run::run_cases(inp, sweeps, out, start)?;
    let assets = out.join(&inp.name);
    std::fs::create_dir_all(&assets).with_context(|| format!("creating {}", assets.display()))?;
    csv_files::write(&results, sweeps, &assets)?;
    let path = markdown::write_page(inp, sweeps, &results, &assets, out)?;
    eprintln!(
        "robustness: {} cases in {:.0} s; wrote {}",
        results.cases.len(),
        results.wall,
        path.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subset_is_seeded_and_stratified() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenarios/obstacles200.csv"
        ))
        .unwrap();
        let set = control::scenario::parse(&text, "obstacles200").unwrap();
        let a = subset(&set, 10, 16);
        let b = subset(&set, 10, 16);
        let names = |v: &[Scenario]| v.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&a), names(&b));
        assert_ne!(names(&a), names(&subset(&set, 10, 17)));
        assert_eq!(a.len(), 40);
        for kind in ["circles", "wall", "gap", "dock"] {
            let n = a.iter().filter(|s| s.name.starts_with(kind)).count();
            assert!(n == 10 || n == 0, "{kind}: {n}");
        }
    }

    #[test]
    fn acceptance_levels_are_in_the_sweeps() {
        let s = standard_sweeps();
        let acc: Vec<String> = s
            .iter()
            .flat_map(|s| {
                s.levels
                    .iter()
                    .filter(|l| l.acceptance)
                    .map(move |l| format!("{} {}", s.flag, describe(&l.case.perturbation)))
            })
            .collect();
        assert_eq!(acc.len(), 10, "{acc:?}");
        let m = all_moderate();
        assert_eq!(m.compensated, 0.2);
        assert_eq!(m.perturbation.delay, Some(0.25));
    }
}
