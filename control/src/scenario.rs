//! Scenario files (DESIGN §7): CSV with a required header, angles in radians,
//! one scenario a row, obstacles as `x:y:r` items separated by `;`. Parsed from
//! text (callers read the file); errors name the source, line and column.

use crate::model::{Goal, State};
pub use crate::obstacle::Obstacle;

/// The header every scenario file starts with.
pub const HEADER: &str = "name,x0,y0,theta0,beta0,beta_dot0,v0,x_goal,y_goal,theta_goal,obstacles";

#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    pub name: String,
    pub start: State,
    pub goal: Goal,
    pub obstacles: Vec<Obstacle>,
}

/// A malformed scenario file, with the position of the problem (1-based).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{source_name}:{line}:{column}: {message}")]
pub struct ScenarioError {
    pub source_name: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
}

/// Parses a scenario file's text; `source` names it in errors.
pub fn parse(text: &str, source: &str) -> Result<Vec<Scenario>, ScenarioError> {
    let fail = |line: usize, column: usize, message: String| ScenarioError {
        source_name: source.to_string(),
        line,
        column,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(fail(
            1,
            1,
            format!("empty file: expected the header `{HEADER}`"),
        ));
    };
    let header = header.trim().trim_start_matches('\u{feff}');
    if header != HEADER {
        return Err(fail(
            1,
            1,
            format!("bad header `{header}`: expected `{HEADER}`"),
        ));
    }
    let mut out = Vec::new();
    for (index, raw) in lines {
        let line_no = index + 1;
        let line = raw.trim_end_matches('\r');
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != 11 {
            return Err(fail(
                line_no,
                1,
                format!("expected 11 fields, found {}", fields.len()),
            ));
        }
        let mut column = 1;
        let mut columns = Vec::with_capacity(11);
        for f in &fields {
            columns.push(column);
            column += f.chars().count() + 1;
        }
        let name = fields[0].trim();
        if name.is_empty() {
            return Err(fail(line_no, 1, "empty scenario name".into()));
        }
        let mut v = [0.0; 9];
        for (k, slot) in v.iter_mut().enumerate() {
            let text = fields[k + 1].trim();
            let key = HEADER.split(',').nth(k + 1).unwrap_or("?");
            *slot = text
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    fail(
                        line_no,
                        columns[k + 1],
                        format!("`{key}`: `{text}` is not a finite number"),
                    )
                })?;
        }
        let mut obstacles = Vec::new();
        let obs_text = fields[10];
        let mut col = columns[10];
        if !obs_text.trim().is_empty() {
            for item in obs_text.split(';') {
                let parts: Vec<&str> = item.split(':').collect();
                let parsed: Option<Vec<f64>> = (parts.len() == 3)
                    .then(|| {
                        parts
                            .iter()
                            .map(|p| p.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
                            .collect()
                    })
                    .flatten();
                match parsed.as_deref() {
                    Some(&[x, y, r]) if r > 0.0 => obstacles.push(Obstacle::new(x, y, r)),
                    Some(&[_, _, r]) => {
                        return Err(fail(
                            line_no,
                            col,
                            format!("obstacle radius must be > 0 (got {r})"),
                        ))
                    }
                    _ => {
                        return Err(fail(
                            line_no,
                            col,
                            format!("obstacle `{item}` is not `x:y:r` with finite numbers"),
                        ))
                    }
                }
                col += item.chars().count() + 1;
            }
        }
        out.push(Scenario {
            name: name.to_string(),
            start: State::new(v[0], v[1], v[2], v[3], v[4], v[5]),
            goal: Goal::new(v[6], v[7], v[8]),
            obstacles,
        });
    }
    Ok(out)
}

/// Writes scenarios in the file format (round-trips through [`parse`]).
pub fn to_csv(scenarios: &[Scenario]) -> String {
    let mut s = String::from(HEADER);
    s.push('\n');
    for sc in scenarios {
        let x = &sc.start;
        let obs: Vec<String> = sc
            .obstacles
            .iter()
            .map(|o| format!("{}:{}:{}", o.x, o.y, o.radius))
            .collect();
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{}\n",
            sc.name,
            x[0],
            x[1],
            x[2],
            x[3],
            x[4],
            x[5],
            sc.goal.x,
            sc.goal.y,
            sc.goal.theta,
            obs.join(";")
        ));
    }
    s
}

/// The paper's 128 scenarios (DESIGN §7): start at rest at the origin, heading
/// 0; goals at 4.5 m and 9 m × 8 bearings × 8 headings, 45° apart.
pub fn paper_scenarios() -> Vec<Scenario> {
    let mut out = Vec::with_capacity(128);
    for r in [4.5, 9.0] {
        for b in 0..8 {
            for h in 0..8 {
                let bearing = (b as f64 * 45.0).to_radians();
                let heading = crate::model::wrap_angle((h as f64 * 45.0).to_radians());
                out.push(Scenario {
                    name: format!("r{r}_b{}_h{}", b * 45, h * 45),
                    start: State::zeros(),
                    goal: Goal::new(r * bearing.cos(), r * bearing.sin(), heading),
                    obstacles: Vec::new(),
                });
            }
        }
    }
    out
}

/// A selection set for choosing among trained checkpoints without looking at
/// the paper's 128 (the acceptance set): `n` goals from the same start, at a
/// uniform radius in [4.5, 9] m, bearing and heading, drawn from `seed`.
pub fn selection_scenarios(n: usize, seed: u64) -> Vec<Scenario> {
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|i| {
            let r = rng.gen_range(4.5..=9.0);
            let bearing = rng.gen_range(0.0..2.0 * PI);
            let heading = crate::model::wrap_angle(rng.gen_range(-PI..PI));
            Scenario {
                name: format!("sel{i}"),
                start: State::zeros(),
                goal: Goal::new(r * bearing.cos(), r * bearing.sin(), heading),
                obstacles: Vec::new(),
            }
        })
        .collect()
}

/// The kinds of work-site scenario in [`obstacle_scenarios`] (DESIGN §10):
/// the straight way from start to goal is blocked in each.
pub const OBSTACLE_KINDS: [&str; 4] = ["circles", "wall", "gap", "dock"];

/// Distance from point `q` to the segment a–b.
fn segment_distance(q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (q[0] - a[0] - t * dx).hypot(q[1] - a[1] - t * dy)
}

/// True when the straight segment from the start's front axle to the goal
/// crosses a circle: the way a controller without a global layer would take.
pub fn straight_path_blocked(sc: &Scenario) -> bool {
    let a = [sc.start[0], sc.start[1]];
    let b = [sc.goal.x, sc.goal.y];
    sc.obstacles
        .iter()
        .any(|o| segment_distance([o.x, o.y], a, b) < o.radius)
}

/// Seeded work-site scenarios (DESIGN §10, issue 14): `per_kind` of each of
/// [`OBSTACLE_KINDS`], every one with its straight path blocked, start and
/// goal footprints (both axle points, `params`) at least 0.3 m clear of every
/// circle, and about a third starting in motion or articulated.
///
/// - `circles`: 1–3 circles (radius 0.5–1.2 m) on the straight path;
/// - `wall`: a wall of 3–6 overlapping circles across the path;
/// - `gap`: two walls across the path with a 1.2–2.2 m gap between their
///   edges, off the straight line;
/// - `dock`: the goal just beyond a pile of 1–3 large circles (radius
///   1.0–1.8 m), 0.3–0.8 m from its edge, facing along or away from it.
///
/// Radii include the machine's half-width (as on the wire). Goals lie 6–11 m
/// from the start; at most 8 circles a scenario (the wire's limit).
pub fn obstacle_scenarios(
    per_kind: usize,
    seed: u64,
    params: &crate::model::MachineParams,
) -> Vec<Scenario> {
    use crate::obstacle::footprint_clearance;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(per_kind * OBSTACLE_KINDS.len());
    for kind in OBSTACLE_KINDS {
        let mut made = 0;
        while made < per_kind {
            // Start: at the origin, any heading; a third moving or articulated.
            let theta0 = crate::model::wrap_angle(rng.gen_range(-PI..PI));
            let mut start = State::new(0.0, 0.0, theta0, 0.0, 0.0, 0.0);
            if rng.gen_bool(0.35) {
                start[3] = rng.gen_range(-0.5..0.5);
                start[5] = if rng.gen_bool(0.6) {
                    rng.gen_range(0.2..params.v_max)
                } else {
                    0.0
                };
            }
            let r = rng.gen_range(6.0..11.0);
            let bearing = rng.gen_range(-PI..PI);
            let (ub, vb) = (
                (bearing.cos(), bearing.sin()),
                (-bearing.sin(), bearing.cos()),
            );
            // A point `along` metres on the way and `side` metres to its left.
            let at =
                |along: f64, side: f64| [along * ub.0 + side * vb.0, along * ub.1 + side * vb.1];
            let mut obstacles = Vec::new();
            let mut goal_heading = crate::model::wrap_angle(rng.gen_range(-PI..PI));
            let goal_r = r;
            match kind {
                "circles" => {
                    let n = rng.gen_range(1..=3);
                    for _ in 0..n {
                        let c = at(rng.gen_range(0.3..0.7) * r, rng.gen_range(-0.6..0.6));
                        obstacles.push(crate::obstacle::Obstacle::new(
                            c[0],
                            c[1],
                            rng.gen_range(0.5..1.2),
                        ));
                    }
                }
                "wall" => {
                    let n = rng.gen_range(3..=6);
                    let rad = rng.gen_range(0.5..0.7);
                    let spacing = 1.5 * rad;
                    let along = rng.gen_range(0.4..0.6) * r;
                    let shift = rng.gen_range(-0.5..0.5) * spacing * (n as f64 - 1.0) * 0.5;
                    let tilt: f64 = rng.gen_range(-0.4..0.4);
                    for i in 0..n {
                        let s = (i as f64 - 0.5 * (n as f64 - 1.0)) * spacing + shift;
                        let c = at(along + s * tilt.sin(), s * tilt.cos());
                        obstacles.push(crate::obstacle::Obstacle::new(c[0], c[1], rad));
                    }
                }
                "gap" => {
                    let rad = rng.gen_range(0.5..0.65);
                    let spacing = 1.5 * rad;
                    let gap = rng.gen_range(1.2..2.2);
                    let along = rng.gen_range(0.4..0.6) * r;
                    // The gap's centre 1–2.5 m to one side: the straight line hits a wall.
                    let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                    let centre = side * rng.gen_range(1.0..2.5);
                    let (n_a, n_b) = (rng.gen_range(2..=4), rng.gen_range(2..=4));
                    let half = 0.5 * gap + rad;
                    for i in 0..n_a {
                        let c = at(along, centre + half + i as f64 * spacing);
                        obstacles.push(crate::obstacle::Obstacle::new(c[0], c[1], rad));
                    }
                    for i in 0..n_b {
                        let c = at(along, centre - half - i as f64 * spacing);
                        obstacles.push(crate::obstacle::Obstacle::new(c[0], c[1], rad));
                    }
                }
                _ => {
                    // dock: the pile just short of the goal, the goal beside its far edge.
                    let rad = rng.gen_range(1.0..1.8);
                    let clear = rng.gen_range(0.3..0.8);
                    let pile = goal_r - rad - clear;
                    let c = at(pile, 0.0);
                    obstacles.push(crate::obstacle::Obstacle::new(c[0], c[1], rad));
                    for _ in 0..rng.gen_range(0..=2) {
                        let a: f64 = rng.gen_range(-PI..PI);
                        let d = rad * rng.gen_range(0.8..1.3);
                        let r2 = rng.gen_range(0.7..1.2);
                        obstacles.push(crate::obstacle::Obstacle::new(
                            c[0] + d * a.cos(),
                            c[1] + d * a.sin(),
                            r2,
                        ));
                    }
                    // Along the pile's face (either way) or away from it.
                    goal_heading = crate::model::wrap_angle(match rng.gen_range(0..3) {
                        0 => bearing + PI / 2.0,
                        1 => bearing - PI / 2.0,
                        _ => bearing,
                    });
                }
            }
            let g = at(goal_r, 0.0);
            let goal = Goal::new(g[0], g[1], goal_heading);
            let sc = Scenario {
                name: format!("{kind}{made:03}"),
                start,
                goal,
                obstacles,
            };
            let goal_state = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
            let clear = footprint_clearance(params, &sc.start, &sc.obstacles)
                .min(footprint_clearance(params, &goal_state, &sc.obstacles));
            if clear >= 0.3 && straight_path_blocked(&sc) && sc.obstacles.len() <= 8 {
                out.push(sc);
                made += 1;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selection_set_is_seeded_in_range_and_apart_from_the_paper_set() {
        let set = selection_scenarios(64, 1);
        assert_eq!(set, selection_scenarios(64, 1));
        assert_ne!(set, selection_scenarios(64, 2));
        let paper = paper_scenarios();
        for s in &set {
            let r = s.goal.x.hypot(s.goal.y);
            assert!((4.5..=9.0).contains(&r), "{}: radius {r}", s.name);
            assert!(s.goal.theta.abs() <= std::f64::consts::PI);
            assert!(paper
                .iter()
                .all(|p| (p.goal.x - s.goal.x).hypot(p.goal.y - s.goal.y) > 1e-6));
        }
        let back = parse(&to_csv(&set), "selection.csv").unwrap();
        assert_eq!(back, set);
    }

    #[test]
    fn obstacle_set_is_seeded_blocked_and_clear_at_both_ends() {
        let p = crate::model::MachineParams::default();
        let set = obstacle_scenarios(12, 7, &p);
        assert_eq!(set, obstacle_scenarios(12, 7, &p));
        assert_ne!(set, obstacle_scenarios(12, 8, &p));
        assert_eq!(set.len(), 48);
        for kind in OBSTACLE_KINDS {
            assert_eq!(set.iter().filter(|s| s.name.starts_with(kind)).count(), 12);
        }
        let mut moving = 0;
        for sc in &set {
            assert!(straight_path_blocked(sc), "{}", sc.name);
            assert!((1..=8).contains(&sc.obstacles.len()), "{}", sc.name);
            let g = State::new(sc.goal.x, sc.goal.y, sc.goal.theta, 0.0, 0.0, 0.0);
            for x in [&sc.start, &g] {
                assert!(
                    crate::obstacle::footprint_clearance(&p, x, &sc.obstacles) >= 0.3,
                    "{}",
                    sc.name
                );
            }
            moving += usize::from(sc.start[3] != 0.0 || sc.start[5] != 0.0);
        }
        assert!(
            moving > 5 && moving < 30,
            "{moving} moving or articulated starts"
        );
        // Round trip through the file format.
        assert_eq!(parse(&to_csv(&set), "o.csv").unwrap(), set);
    }

    #[test]
    fn a_clear_straight_path_is_not_blocked() {
        let mut sc = paper_scenarios().remove(0);
        assert!(!straight_path_blocked(&sc));
        sc.obstacles
            .push(crate::obstacle::Obstacle::new(2.0, 0.9, 1.0));
        assert!(straight_path_blocked(&sc));
        sc.obstacles[0].y = 1.1;
        assert!(!straight_path_blocked(&sc));
    }

    #[test]
    fn paper_set_round_trips() {
        let set = paper_scenarios();
        assert_eq!(set.len(), 128);
        let back = parse(&to_csv(&set), "paper.csv").unwrap();
        assert_eq!(back, set);
        assert!(set
            .iter()
            .all(|s| (s.goal.x.hypot(s.goal.y) - 4.5).abs() < 1e-12
                || (s.goal.x.hypot(s.goal.y) - 9.0).abs() < 1e-12));
    }

    #[test]
    fn obstacles_parse() {
        let text = format!("{HEADER}\nc,0,0,0,0,0,0,9,0,0,3:0.2:1;6:-1:0.8\n");
        let s = parse(&text, "f.csv").unwrap();
        assert_eq!(
            s[0].obstacles,
            vec![Obstacle::new(3.0, 0.2, 1.0), Obstacle::new(6.0, -1.0, 0.8)]
        );
    }

    #[test]
    fn malformed_cases_name_their_position() {
        let cases = [
            ("", 1, 1, "empty file"),
            ("name,x0\n", 1, 1, "bad header"),
            (
                &format!("{HEADER}\na,0,0,0,0,0,0,1,1\n"),
                2,
                1,
                "expected 11 fields",
            ),
            (
                &format!("{HEADER}\na,0,zero,0,0,0,0,1,1,0,\n"),
                2,
                5,
                "`y0`: `zero`",
            ),
            (
                &format!("{HEADER}\na,0,0,0,0,0,0,1,NaN,0,\n"),
                2,
                17,
                "`y_goal`",
            ),
            (
                &format!("{HEADER}\na,0,0,0,0,0,0,1,1,0,1:2:3;4:5\n"),
                2,
                27,
                "obstacle `4:5`",
            ),
            (
                &format!("{HEADER}\na,0,0,0,0,0,0,1,1,0,1:2:-3\n"),
                2,
                21,
                "radius must be > 0",
            ),
            (
                &format!("{HEADER}\n,0,0,0,0,0,0,1,1,0,\n"),
                2,
                1,
                "empty scenario name",
            ),
        ];
        for (text, line, column, needle) in cases {
            let e = parse(text, "bad.csv").unwrap_err();
            assert_eq!((e.line, e.column), (line, column), "{e}");
            assert!(
                e.to_string()
                    .starts_with(&format!("bad.csv:{line}:{column}: ")),
                "{e}"
            );
            assert!(e.message.contains(needle), "{e}");
        }
    }
}
