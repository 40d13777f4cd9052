//! `robustness`: the MPC on a machine that is not its model (DESIGN §12,
//! issue 16). Each [`control::plant::PlantPerturbation`] alone over a range of
//! levels, and all of them at moderate levels at once, on the paper's 128
//! scenarios and a seeded subset of the obstacle set; writes
//! `docs/robustness.md`, a plot per perturbation and CSVs.
//!
//! Also the command-line values of the perturbation options (`eval` and
//! `robustness` share them), each rejected with the flag's name.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use control::envelope::EnvelopeSettings;
use control::plant::PlantPerturbation;
use control::scenario::Scenario;
use control::MachineParams;
use plotters::style::RGBColor;

use crate::eval;
use crate::plots::{self, SweepPanel, SweepSeries};
use crate::report::PENETRATION_TOLERANCE;
use crate::results::ResultRow;
use crate::runner::{EvalConfig, Method, Networks};

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

/// The figures of one case on one scenario set.
#[derive(Debug, Clone)]
pub struct Figures {
    pub scenarios: usize,
    pub reached: usize,
    /// Mean convergence time of the reached runs [s].
    pub t_mean: Option<f64>,
    /// Mean t / T* over the reached runs with a T*.
    pub t_ratio: Option<f64>,
    /// Largest t / T*.
    pub t_ratio_max: Option<f64>,
    /// Smallest footprint clearance over all runs [m] (None: no obstacles).
    pub worst_clearance: Option<f64>,
    /// Runs deeper than [`PENETRATION_TOLERANCE`] into an obstacle.
    pub penetrations: usize,
}

impl Figures {
    pub fn of(rows: &[ResultRow], t_star: &HashMap<String, f64>) -> Self {
        let reached: Vec<&ResultRow> = rows.iter().filter(|r| r.success).collect();
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        let t: Vec<f64> = reached.iter().filter_map(|r| r.t_converge).collect();
        let ratios: Vec<f64> = reached
            .iter()
            .filter_map(|r| Some(r.t_converge? / t_star.get(&r.name)?.max(1e-9)))
            .collect();
        let cl: Vec<f64> = rows.iter().filter_map(|r| r.min_clearance).collect();
        Self {
            scenarios: rows.len(),
            reached: reached.len(),
            t_mean: mean(&t),
            t_ratio: mean(&ratios),
            t_ratio_max: ratios.iter().cloned().reduce(f64::max),
            worst_clearance: cl.iter().cloned().reduce(f64::min),
            penetrations: cl.iter().filter(|&&c| c < -PENETRATION_TOLERANCE).count(),
        }
    }

    pub fn success_rate(&self) -> f64 {
        self.reached as f64 / self.scenarios.max(1) as f64
    }
}

/// Acceptance of issue 16: on the paper set at least `min_success` reached;
/// on the obstacle set no run deeper than [`PENETRATION_TOLERANCE`].
pub fn accepted(paper: &Figures, obstacles: &Figures, min_success: f64) -> bool {
    paper.success_rate() >= min_success - 1e-12 && obstacles.penetrations == 0
}

/// The run's results of one case.
struct Outcome {
    paper: Vec<ResultRow>,
    obstacles: Vec<ResultRow>,
    /// Obstacle-set ticks the safety envelope overrode, and in how many runs.
    overrides: (usize, usize),
    wall_s: f64,
}

/// Everything the command needs.
pub struct Inputs<'a> {
    pub base: EvalConfig,
    pub nets: &'a Networks,
    pub paper: &'a [Scenario],
    pub paper_name: String,
    pub obstacles: &'a [Scenario],
    /// How the obstacle scenarios were chosen (for the page).
    pub obstacles_note: String,
    /// T* per scenario name (min-time rows of a results file).
    pub t_star: HashMap<String, f64>,
    pub t_star_source: String,
    pub command: String,
    pub commit: String,
    /// Base name of the page and its asset directory (`robustness`).
    pub name: String,
}

/// Runs the sweeps and writes `out/robustness.md` and `out/robustness/`.
pub fn robustness(inp: &Inputs, sweeps: &[Sweep], out: &Path) -> Result<()> {
    let start = Instant::now();
    // Distinct cases, the nominal first, then sweep order, all moderate last.
    let nominal = case(PlantPerturbation::default(), 0.0);
    let mut cases: Vec<Case> = vec![nominal];
    for s in sweeps {
        for l in &s.levels {
            if !cases.contains(&l.case) {
                cases.push(l.case);
            }
        }
    }
    let moderate = all_moderate();
    cases.push(moderate);
    let both: Vec<Scenario> = inp.paper.iter().chain(inp.obstacles).cloned().collect();
    // Each finished case is kept in OUT/NAME/cases/ (its rows and a key of
    // everything that determines them), so an interrupted run continues
    // where it stopped: rerun the same command.
    let cache = out.join(&inp.name).join("cases");
    std::fs::create_dir_all(&cache).with_context(|| format!("creating {}", cache.display()))?;
    let mut outcomes: Vec<Outcome> = Vec::new();
    for (k, c) in cases.iter().enumerate() {
        let t0 = Instant::now();
        let key = format!(
            "{:?} | {:?} | {:?} | {} | {} | {}",
            c,
            inp.base.mpc,
            c.stated_envelope(inp.base.envelope, &inp.base.params),
            inp.paper_name,
            inp.nets.source,
            inp.obstacles
                .iter()
                .map(|s| s.name.as_str())
                .collect::<Vec<_>>()
                .join(",")
        );
        let (rows_file, meta_file) = (
            cache.join(format!("{k:02}.csv")),
            cache.join(format!("{k:02}.key")),
        );
        if let (Ok(text), Ok(meta)) = (
            std::fs::read_to_string(&rows_file),
            std::fs::read_to_string(&meta_file),
        ) {
            let mut lines = meta.lines();
            let stored_key = lines.next().unwrap_or_default();
            let numbers: Vec<f64> = lines
                .next()
                .unwrap_or_default()
                .split(',')
                .filter_map(|v| v.parse().ok())
                .collect();
            let rows = crate::results::parse(&text, &rows_file.display().to_string())?;
            if stored_key == key && numbers.len() == 3 && rows.len() == both.len() {
                let (paper, obstacles) = rows.split_at(inp.paper.len());
                eprintln!(
                    "robustness [{}/{}] {}: kept from {}",
                    k + 1,
                    cases.len(),
                    describe(&c.perturbation),
                    rows_file.display()
                );
                outcomes.push(Outcome {
                    paper: paper.to_vec(),
                    obstacles: obstacles.to_vec(),
                    overrides: (numbers[0] as usize, numbers[1] as usize),
                    wall_s: numbers[2],
                });
                continue;
            }
        }
        let cfg = EvalConfig {
            methods: vec![Method::Mpc],
            plant: control::plant::PlantConfig {
                delay: c.compensated,
                ..control::plant::PlantConfig::ideal()
            },
            perturbation: c.perturbation,
            envelope: c.stated_envelope(inp.base.envelope, &inp.base.params),
            end_at_rest: true,
            progress: false,
            ..inp.base.clone()
        };
        let ev = eval::evaluate(&cfg, inp.nets, &both)?;
        let (paper, obstacles) = ev.rows.split_at(inp.paper.len());
        let per_run: Vec<usize> = ev.runs[inp.paper.len()..]
            .iter()
            .flat_map(|s| s.runs.iter().map(|(_, r)| r.envelope_overrides))
            .collect();
        let o = Outcome {
            paper: paper.to_vec(),
            obstacles: obstacles.to_vec(),
            overrides: (
                per_run.iter().sum(),
                per_run.iter().filter(|&&n| n > 0).count(),
            ),
            wall_s: t0.elapsed().as_secs_f64(),
        };
        std::fs::write(&rows_file, crate::results::to_csv(&ev.rows))
            .with_context(|| format!("writing {}", rows_file.display()))?;
        std::fs::write(
            &meta_file,
            format!("{key}\n{},{},{}\n", o.overrides.0, o.overrides.1, o.wall_s),
        )
        .with_context(|| format!("writing {}", meta_file.display()))?;
        let fp = Figures::of(&o.paper, &inp.t_star);
        let fo = Figures::of(&o.obstacles, &HashMap::new());
        eprintln!(
            "robustness [{}/{}] {} (delay compensated {} s): paper {}/{}, t/T* {}; obstacles {}/{}, worst clearance {} m, {} below -{} m; {:.1} s (total {:.0} s)",
            k + 1,
            cases.len(),
            describe(&c.perturbation),
            c.compensated,
            fp.reached,
            fp.scenarios,
            opt(fp.t_ratio, 3),
            fo.reached,
            fo.scenarios,
            opt(fo.worst_clearance, 3),
            fo.penetrations,
            PENETRATION_TOLERANCE,
            o.wall_s,
            start.elapsed().as_secs_f64()
        );
        outcomes.push(o);
    }
    let wall = start.elapsed().as_secs_f64();
    let of = |c: &Case| &outcomes[cases.iter().position(|x| x == c).expect("every case ran")];
    // Obstacle-set times are compared with the nominal MPC's on the same scenario.
    let t_nominal_obst: HashMap<String, f64> = of(&nominal)
        .obstacles
        .iter()
        .filter_map(|r| Some((r.name.clone(), r.t_converge?)))
        .collect();
    let figures = |c: &Case| {
        let o = of(c);
        (
            Figures::of(&o.paper, &inp.t_star),
            Figures::of(&o.obstacles, &t_nominal_obst),
        )
    };

    let assets = out.join(&inp.name);
    std::fs::create_dir_all(&assets).with_context(|| format!("creating {}", assets.display()))?;
    // CSVs: one row per case and set; one row per run.
    let mut summary_csv = String::from(
        "sweep,level,perturbation,compensated_delay,set,scenarios,reached,t_mean,t_ratio_mean,t_ratio_max,worst_clearance,penetrations\n",
    );
    let mut runs_csv =
        String::from("sweep,level,set,name,success,t_converge,min_clearance,solve_ms_max\n");
    let mut labelled: Vec<(&str, String, Case)> = Vec::new();
    for s in sweeps {
        for l in &s.levels {
            labelled.push((s.flag, l.label.clone(), l.case));
        }
    }
    labelled.push(("all-moderate", "all".into(), moderate));
    for (flag, label, c) in &labelled {
        let (fp, fo) = figures(c);
        for (set, f) in [("paper", &fp), ("obstacles", &fo)] {
            let _ = writeln!(
                summary_csv,
                "{flag},{label},\"{}\",{},{set},{},{},{},{},{},{},{}",
                describe(&c.perturbation),
                c.compensated,
                f.scenarios,
                f.reached,
                opt(f.t_mean, 3),
                opt(f.t_ratio, 4),
                opt(f.t_ratio_max, 4),
                opt(f.worst_clearance, 4),
                f.penetrations
            );
        }
        let o = of(c);
        for (set, rows) in [("paper", &o.paper), ("obstacles", &o.obstacles)] {
            for r in rows.iter() {
                let _ = writeln!(
                    runs_csv,
                    "{flag},{label},{set},{},{},{},{},{:.2}",
                    r.name,
                    r.success,
                    r.t_converge.map_or(String::new(), |t| format!("{t}")),
                    r.min_clearance.map_or(String::new(), |c| format!("{c:.4}")),
                    r.solve_ms_max
                );
            }
        }
    }
    std::fs::write(assets.join("summary.csv"), summary_csv)?;
    std::fs::write(assets.join("runs.csv"), runs_csv)?;

    // The page.
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Robustness: the real machine is not the model{}\n",
        if inp.base.mpc.gain_estimation || inp.base.mpc.delay_estimation {
            ""
        } else {
            " (MPC without its gain and delay estimates)"
        }
    );
    let _ = writeln!(
        md,
        "Generated by `{}` at commit `{}` (DESIGN §12, issue 16); every number and figure on this page comes from that \
         one run (wall time {:.0} s on {} threads, {} closed-loop cases).\n",
        inp.command, inp.commit, wall, inp.base.jobs, cases.len()
    );
    let _ = writeln!(
        md,
        "- Controller: the MPC with the daemon's defaults (N = {}, {:?} Hessian, {} SQP iteration(s) per tick, {:?} \
         obstacle rows with a {} m margin ({} m for the rear axle), online actuator-gain estimate {}, online delay estimate {}) and the global layer; \
         networks: {}. It always uses the nominal model.",
        inp.base.mpc.horizon,
        inp.base.mpc.hessian,
        inp.base.mpc.sqp_iterations,
        inp.base.mpc.obstacle_constraint,
        inp.base.mpc.obstacle_margin,
        inp.base.mpc.obstacle_margin_rear,
        if inp.base.mpc.gain_estimation { "on" } else { "off" },
        if inp.base.mpc.delay_estimation { "on" } else { "off" },
        inp.nets.source
    );
    let _ = writeln!(
        md,
        "- Plant: `wlnav-sim eval`'s default (ideal: no delay, no lag; the MPC compensates nothing), changed by one \
         perturbation (`control::plant::PlantPerturbation`); the plant-delay sweep and the all-moderate case compensate \
         0.2 s (`--delay 0.2`). The same run with `wlnav-sim eval --methods mpc` and the flag in the tables \
         reproduces a level. Pose noise is seeded per scenario (its name hashed with seed 0)."
    );
    let _ = writeln!(
        md,
        "- Judged on the plant's true state and geometry: success = ‖(x_f − x_g, y_f − y_g, e_θ)‖ < {} within {} s; \
         t = first such instant; min clearance = smallest distance of either (true) axle point to an obstacle's edge \
         on the plant's sub-steps. A run ends once it has stayed inside the test at rest (|v_f| < 0.05) for 1 s \
         (nothing after that is scored).",
        inp.base.tolerance, inp.base.duration
    );
    let _ = writeln!(
        md,
        "- Scenario sets: {} ({} scenarios; t/T* with T* from `{}`) and {}.",
        inp.paper_name,
        inp.paper.len(),
        inp.t_star_source,
        inp.obstacles_note
    );
    let _ = writeln!(
        md,
        "- Acceptance (issue 16): each level alone ≥ 98 % of the paper set reached and no obstacle-set run deeper than \
         {} m into an obstacle; all moderate at once ≥ 95 %.\n",
        PENETRATION_TOLERANCE
    );

    let _ = writeln!(md, "## Acceptance levels\n");
    let _ = writeln!(
        md,
        "| perturbation | paper reached | t/T* mean (max) | obstacles reached | obstacles t/t₀ | worst clearance [m] | runs below −{} m | envelope overrides: ticks (runs) | accepted |\n|---|---|---|---|---|---|---|---|---|",
        PENETRATION_TOLERANCE
    );
    // `penetration`: whether the obstacle criterion applies (each level alone).
    let row = |md: &mut String, name: &str, c: &Case, min: f64, penetration: bool| {
        let (fp, fo) = figures(c);
        let ok = if penetration {
            accepted(&fp, &fo, min)
        } else {
            fp.success_rate() >= min - 1e-12
        };
        let (ticks, runs) = of(c).overrides;
        let _ = writeln!(
            md,
            "| {name} | {}/{} ({:.1} %) | {} ({}) | {}/{} | {} | {} | {} | {ticks} ({runs}) | {} |",
            fp.reached,
            fp.scenarios,
            100.0 * fp.success_rate(),
            opt(fp.t_ratio, 3),
            opt(fp.t_ratio_max, 2),
            fo.reached,
            fo.scenarios,
            opt(fo.t_ratio, 3),
            opt(fo.worst_clearance, 3),
            fo.penetrations,
            if ok { "yes" } else { "**no**" }
        );
    };
    row(&mut md, "nominal (none)", &nominal, 0.98, true);
    for s in sweeps {
        for l in s.levels.iter().filter(|l| l.acceptance) {
            row(
                &mut md,
                &format!("`{}` {}", s.flag, l.label),
                &l.case,
                0.98,
                true,
            );
        }
    }
    row(
        &mut md,
        &format!(
            "all moderate: {}, 0.2 s compensated",
            describe(&moderate.perturbation)
        ),
        &moderate,
        0.95,
        true,
    );
    md.push('\n');
    let _ = writeln!(
        md,
        "t₀: the unperturbed MPC's time on the same obstacle scenario (no T* for this set here). The all-moderate case needs \
         ≥ 95 % (issue 16) and no run below −{} m (issue 26). Each case runs with the safety envelope's tolerances \
         stated as an integrator who knows these bounds would (`Case::stated_envelope`: geometry |ΔL_f| + |ΔL_r|, the \
         pose noise, a delay beyond the compensated one as response lag, a gain above 1 as `actuator_gain_max`); an override is a tick whose command the \
         envelope replaced.\n",
        PENETRATION_TOLERANCE
    );
    md.push_str(NOTES);

    let _ = writeln!(md, "## Sweeps\n");
    for s in sweeps {
        let _ = writeln!(md, "### `{}`: {}\n", s.flag, s.title);
        let _ = writeln!(
            md,
            "| level | paper reached | t/T* mean (max) | obstacles reached | obstacles t/t₀ | worst clearance [m] | below −{} m | envelope overrides: ticks (runs) |\n|---|---|---|---|---|---|---|---|",
            PENETRATION_TOLERANCE
        );
        for l in &s.levels {
            let (fp, fo) = figures(&l.case);
            let (ticks, runs) = of(&l.case).overrides;
            let _ = writeln!(
                md,
                "| {}{} | {}/{} | {} ({}) | {}/{} | {} | {} | {} | {ticks} ({runs}) |",
                l.label,
                if l.acceptance { " (acceptance)" } else { "" },
                fp.reached,
                fp.scenarios,
                opt(fp.t_ratio, 3),
                opt(fp.t_ratio_max, 2),
                fo.reached,
                fo.scenarios,
                opt(fo.t_ratio, 3),
                opt(fo.worst_clearance, 3),
                fo.penetrations
            );
        }
        let _ = writeln!(md, "\n{}\n", breaks(s, &figures));
        let file = format!("{}.svg", s.flag.trim_start_matches('-'));
        sweep_plot(s, &figures, &assets.join(&file))?;
        let _ = writeln!(md, "![{}]({}/{file})\n", s.flag, inp.name);
    }
    let _ = writeln!(
        md,
        "CSV: [{n}/summary.csv]({n}/summary.csv) (one row per level and set), \
         [{n}/runs.csv]({n}/runs.csv) (one row per run).\n",
        n = inp.name
    );
    let path = out.join(format!("{}.md", inp.name));
    std::fs::write(&path, md).with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "robustness: {} cases in {wall:.0} s; wrote {}",
        cases.len(),
        path.display()
    );
    Ok(())
}

/// What the controller does about the perturbations, and what the numbers
/// mean (fixed text; the numbers are in the tables above it).
const NOTES: &str = "\
## What the controller does about them

- **Actuator gain** (`control::gain`, `MpcSettings::gain_estimation`, default on). The MPC commands the velocities of \
its planned x₁, i.e. the measured velocity plus one tick of bounded acceleration; a machine that achieves K × the \
command closes that loop with a pole at K: velocities grow by K a tick at K > 1 and stall at K·a_max·Δt / (1 − K) at \
K < 1. The MPC estimates K per channel online (least squares with forgetting on steady velocity samples), divides its \
commands by it, tells the delay compensator the velocities they should achieve, and plans within K × the β̇ and v \
bounds when K < 1. Estimates within 3 % of 1 are not applied, so the nominal machine gets bit-identical commands.
- **True delay ≠ compensated delay** (`control::delay_estimate`, `MpcSettings::delay_estimation`, default on). A bank \
of delay compensators on a 0.05 s grid up to 0.6 s (and the configured delay) predicts each tick's velocities one \
tick ahead; the MPC compensates the best-scoring delay once it clearly beats the current one. Its estimate stays on \
the configured delay when that is right. Beyond the grid (0.8 s) it breaks.
- **Geometry.** Not estimated. The obstacle rows keep the *planned* axle points out of every circle by a margin; \
the rear axle's position is computed from the measured front pose through L_f and L_r, so with L_r × 1.1 the true \
rear axle is up to 0.06 m (0.1 × 0.6 m) from where the model puts it, more than the 0.05 m margin. The rear rows \
have their own margin (`obstacle_margin_rear`); 0.08 m keeps every run out at L_r × 1.1 but costs goals \
(README, robustness), so the default stays 0.05 m.
- **Pose noise and latency.** No filter: the MPC plans from the measured pose, and a pose S old is S × v behind \
(0.1 m at 0.1 s and 1 m/s), which the 0.05 m front margin does not cover: the clearance goes first. The next step is \
to propagate each pose over its age (it is stamped) with the machine-state velocities, as the delay compensator does \
over the actuator delay.
- The same sweeps with both estimates off: `wlnav-sim robustness --no-estimation --name robustness-no-estimation` \
([robustness-no-estimation.md](robustness-no-estimation.md)).

";

fn opt(v: Option<f64>, d: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.d$}"))
}

/// Where a sweep breaks: on each side of the nominal level, the first level
/// that fails the acceptance test, or that it held over all levels tried.
fn breaks(s: &Sweep, figures: &dyn Fn(&Case) -> (Figures, Figures)) -> String {
    let mut out = Vec::new();
    let below: Vec<&Level> = s.levels.iter().rev().filter(|l| l.x < s.nominal).collect();
    let above: Vec<&Level> = s.levels.iter().filter(|l| l.x > s.nominal).collect();
    for (side, levels) in [("below", below), ("above", above)] {
        if levels.is_empty() {
            continue;
        }
        let mut held = None;
        let mut broke = None;
        for l in levels {
            let (fp, fo) = figures(&l.case);
            if accepted(&fp, &fo, 0.98) {
                held = Some(l);
            } else {
                let why = if fp.success_rate() < 0.98 - 1e-12 {
                    format!("{}/{} reached", fp.reached, fp.scenarios)
                } else {
                    format!(
                        "{} obstacle run(s) below −{} m, worst {} m",
                        fo.penetrations,
                        PENETRATION_TOLERANCE,
                        opt(fo.worst_clearance, 3)
                    )
                };
                broke = Some((l, why));
                break;
            }
        }
        out.push(match (held, broke) {
            (_, Some((l, why))) => format!(
                "{side} nominal it breaks at {} ({why}){}",
                l.label,
                held.map_or(String::new(), |h| format!("; holds at {}", h.label))
            ),
            (Some(h), None) => format!(
                "{side} nominal it holds at every level tried (to {})",
                h.label
            ),
            (None, None) => String::new(),
        });
    }
    format!("Where it breaks: {}.", out.join("; "))
}

fn sweep_plot(s: &Sweep, figures: &dyn Fn(&Case) -> (Figures, Figures), path: &Path) -> Result<()> {
    let paper_c = RGBColor(31, 119, 180);
    let obst_c = RGBColor(255, 127, 14);
    let f: Vec<(f64, Figures, Figures)> = s
        .levels
        .iter()
        .map(|l| {
            let (a, b) = figures(&l.case);
            (l.x, a, b)
        })
        .collect();
    let series = |label: &str, color, g: &dyn Fn(&Figures, &Figures) -> Option<f64>| SweepSeries {
        label: label.into(),
        color,
        points: f.iter().map(|(x, a, b)| (*x, g(a, b))).collect(),
    };
    let panels = vec![
        SweepPanel {
            y_desc: "reached [%]".into(),
            threshold: Some(98.0),
            series: vec![
                series("paper 128", paper_c, &|a, _| Some(100.0 * a.success_rate())),
                series("obstacles", obst_c, &|_, b| Some(100.0 * b.success_rate())),
            ],
        },
        SweepPanel {
            y_desc: "time ratio (mean)".into(),
            threshold: None,
            series: vec![
                series("paper: t / T*", paper_c, &|a, _| a.t_ratio),
                series("obstacles: t / t₀", obst_c, &|_, b| b.t_ratio),
            ],
        },
        SweepPanel {
            y_desc: "worst clearance [m]".into(),
            threshold: Some(-PENETRATION_TOLERANCE),
            series: vec![series("obstacles", obst_c, &|_, b| b.worst_clearance)],
        },
    ];
    plots::sweep_svg(path, s.title, s.x_desc, s.nominal, &panels)
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
