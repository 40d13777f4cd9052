//! Geometry of a planned path that path following uses: its directions of
//! travel (cusps, where the machine must stop and change gear), arc lengths,
//! and the machine's projection onto it, which only moves forward and never
//! past the next cusp.
//!
//! Pure functions over the path; the navigator keeps the projection index.

use super::PathPose;

/// Whether the path changes direction after pose `i` (forward ↔ reverse):
/// the machine must come to rest at `path[i]`.
pub fn is_cusp(path: &[PathPose], i: usize) -> bool {
    i + 1 < path.len() && i > 0 && (path[i].direction as i32) * (path[i + 1].direction as i32) < 0
}

/// The last pose of the direction of travel `i` is on: the next cusp at or
/// after `i`, or the path's last pose.
pub fn direction_end(path: &[PathPose], i: usize) -> usize {
    let last = path.len().saturating_sub(1);
    (i.min(last)..last)
        .find(|&k| is_cusp(path, k))
        .unwrap_or(last)
}

/// The first pose of the direction of travel `i` is on: the cusp before `i`
/// (where the machine starts again the other way), or 0.
pub fn direction_start(path: &[PathPose], i: usize) -> usize {
    (1..i.min(path.len()))
        .rev()
        .find(|&k| is_cusp(path, k))
        .unwrap_or(0)
}

/// Arc length from pose `from` to pose `to` (0 unless `from < to`).
pub fn arc_between(path: &[PathPose], from: usize, to: usize) -> f64 {
    (from..to.min(path.len().saturating_sub(1)))
        .map(|i| step(path, i))
        .sum()
}

fn step(path: &[PathPose], i: usize) -> f64 {
    (path[i + 1].x - path[i].x).hypot(path[i + 1].y - path[i].y)
}

/// The machine's progress along the path: the index of the pose nearest to
/// the front axle (x, y), searched from `from` over at most `window` metres
/// of arc and never beyond the next cusp, so the index only grows and cannot
/// jump to a later part of the path that passes close by (a path folding back
/// over itself at a cusp). A cusp is passed when the front axle is within
/// `cusp_radius` of it: the index then moves to the pose after it.
pub fn project(
    path: &[PathPose],
    from: usize,
    x: f64,
    y: f64,
    window: f64,
    cusp_radius: f64,
) -> usize {
    if path.is_empty() {
        return 0;
    }
    let from = from.min(path.len() - 1);
    let distance = |i: usize| (path[i].x - x).hypot(path[i].y - y);
    let (mut best, mut best_d) = (from, distance(from));
    let mut arc = 0.0;
    let mut i = from;
    while i + 1 < path.len() && !is_cusp(path, i) && arc < window {
        arc += step(path, i);
        i += 1;
        let d = distance(i);
        if d < best_d {
            (best, best_d) = (i, d);
        }
    }
    if is_cusp(path, best) && best_d < cusp_radius {
        best + 1
    } else {
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, y: f64, direction: i8) -> PathPose {
        PathPose {
            x,
            y,
            theta: 0.0,
            beta: 0.0,
            direction,
        }
    }

    /// Forward along x from 0 to 6 in 0.5 m steps (a cusp at 6), then reverse
    /// back to 3.
    fn with_cusp() -> Vec<PathPose> {
        let mut path: Vec<PathPose> = (0..=12)
            .map(|k| pose(0.5 * k as f64, 0.0, if k == 0 { 0 } else { 1 }))
            .collect();
        path.extend((1..=6).map(|k| pose(6.0 - 0.5 * k as f64, 0.0, -1)));
        path
    }

    #[test]
    fn cusps_are_where_the_direction_flips() {
        let path = with_cusp();
        let cusps: Vec<usize> = (0..path.len()).filter(|&i| is_cusp(&path, i)).collect();
        // Not the start (direction 0 → forward), not the end: the pose at x = 6.
        assert_eq!(cusps, vec![12]);
    }

    #[test]
    fn a_direction_runs_from_cusp_to_cusp_and_its_arc_is_summed() {
        let path = with_cusp();
        // Forward: poses 0..=12; reversing: from the cusp (12) to the end (18).
        for i in 0..=12 {
            assert_eq!(
                (direction_start(&path, i), direction_end(&path, i)),
                (0, 12)
            );
        }
        for i in 13..path.len() {
            assert_eq!(
                (direction_start(&path, i), direction_end(&path, i)),
                (12, 18)
            );
        }
        assert_eq!(arc_between(&path, 2, 12), 5.0);
        assert_eq!(arc_between(&path, 12, 18), 3.0);
        assert_eq!(arc_between(&path, 12, 2), 0.0);
        assert_eq!(arc_between(&path, 16, 99), 1.0);
        assert_eq!(direction_end(&[], 0), 0);
    }

    #[test]
    fn the_projection_grows_stops_at_a_cusp_and_passes_it_when_near() {
        let path = with_cusp();
        // Beside x = 2.1: nearest pose x = 2.0 (index 4).
        assert_eq!(project(&path, 0, 2.1, 0.3, 10.0, 1.0), 4);
        // Never backwards: a machine behind its last projection stays there.
        assert_eq!(project(&path, 4, 0.5, 0.0, 10.0, 1.0), 4);
        // The window limits the search: 1 m of arc from index 4 reaches x = 3.
        assert_eq!(project(&path, 4, 5.0, 0.0, 1.0, 1.0), 6);
        // At x = 4.4 the reverse leg's x = 4.5 (index 15) is as near as the
        // forward leg's, but the cusp bounds the search: index 9 (x = 4.5).
        assert_eq!(project(&path, 6, 4.4, 0.0, 10.0, 1.0), 9);
        // Near the cusp but not within its radius: held at it.
        assert_eq!(project(&path, 9, 6.0, 1.5, 10.0, 1.0), 12);
        // Within the radius: onto the reverse leg.
        assert_eq!(project(&path, 9, 5.9, 0.2, 10.0, 1.0), 13);
        // Then it follows the reverse leg.
        assert_eq!(project(&path, 13, 4.0, 0.0, 10.0, 1.0), 16);
    }
}
