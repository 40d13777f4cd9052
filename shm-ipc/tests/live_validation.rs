//! Every rule of the live-obstacle validator: the valid set passes, and each defect alone
//! is rejected with its own reason, naming the obstacle by index and id.

use shm_ipc::{
    polygon_defect, Field, LiveObstacle, LiveObstacleSet, LiveObstacleValidator, LiveSetRejection,
    ObstacleClass, PolygonDefect, MAX_OBSTACLE_ABS,
};

/// The reader's "now" in these tests [ns].
const NOW: u64 = 1_000_000_000_000;
/// Stamps a little in the past, as a real perception's are.
const SET_STAMP: u64 = NOW - 30_000_000;
const OBSTACLE_STAMP: u64 = NOW - 40_000_000;

fn square_ccw() -> Vec<[f64; 2]> {
    vec![[10.0, 0.0], [12.0, 0.0], [12.0, 1.0], [10.0, 1.0]]
}

/// A valid set: a person (circle), a truck (counter-clockwise rectangle), a machine
/// (clockwise pentagon with a straight vertex), a pile (triangle, static).
fn valid_set() -> LiveObstacleSet {
    let mut set = LiveObstacleSet::empty(SET_STAMP, 5);
    let obstacles = [
        LiveObstacle::circle(
            11,
            ObstacleClass::Person,
            [3.0, -1.0],
            0.4,
            [0.0, 1.4],
            OBSTACLE_STAMP,
        ),
        LiveObstacle::polygon(
            12,
            ObstacleClass::Vehicle,
            &square_ccw(),
            [-2.0, 0.0],
            OBSTACLE_STAMP,
        )
        .expect("polygon"),
        LiveObstacle::polygon(
            13,
            ObstacleClass::Machine,
            // Clockwise; (0, -4) lies on the straight edge from (-2, -4) to (2, -4).
            &[
                [-2.0, -3.0],
                [2.0, -3.0],
                [2.0, -4.0],
                [0.0, -4.0],
                [-2.0, -4.0],
            ],
            [0.0, 0.0],
            OBSTACLE_STAMP,
        )
        .expect("polygon"),
        LiveObstacle::polygon(
            14,
            ObstacleClass::Static,
            &[[-5.0, 5.0], [-4.0, 5.0], [-4.5, 6.0]],
            [0.0, 0.0],
            SET_STAMP,
        )
        .expect("polygon"),
    ];
    for o in obstacles {
        set.push(o).expect("room");
    }
    set
}

fn validator() -> LiveObstacleValidator {
    LiveObstacleValidator::default()
}

/// `set` with obstacle `index` changed by `change`.
fn with(index: usize, change: impl FnOnce(&mut LiveObstacle)) -> LiveObstacleSet {
    let mut set = valid_set();
    change(&mut set.obstacles[index]);
    set
}

/// The rejection of `set`, after checking that its text names the obstacle (when it is
/// about one) and that the rule name is the one expected.
fn reject(set: &LiveObstacleSet, rule: &str) -> LiveSetRejection {
    let r = validator()
        .validate(set, NOW)
        .expect_err("should be rejected");
    assert_eq!(r.rule(), rule, "{r}");
    if let Some((index, id)) = r.obstacle() {
        let text = r.to_string();
        assert!(text.contains(&format!("obstacle {index}")), "{text}");
        assert!(text.contains(&format!("id {id}")), "{text}");
    }
    r
}

#[test]
fn the_valid_set_passes_and_so_does_an_empty_one() {
    assert_eq!(validator().validate(&valid_set(), NOW), Ok(()));
    assert_eq!(
        validator().validate(&LiveObstacleSet::empty(NOW, 0), NOW),
        Ok(())
    );
    // Fields a shape does not read are not judged: a polygon's centre and radius.
    let set = with(1, |o| {
        o.x = f64::NAN;
        o.radius = -1.0;
    });
    assert_eq!(validator().validate(&set, NOW), Ok(()));
}

#[test]
fn limits_are_inclusive() {
    let v = validator();
    // A stamp exactly max_future ahead of now, and an obstacle that far after its set.
    let mut set = valid_set();
    set.timestamp_ns = NOW + 50_000_000;
    set.obstacles[0].timestamp_ns = NOW + 50_000_000;
    assert_eq!(v.validate(&set, NOW), Ok(()));
    let set = with(0, |o| {
        o.radius = 30.0;
        o.vx = 30.0;
        o.vy = 0.0;
        o.x = MAX_OBSTACLE_ABS;
    });
    assert_eq!(v.validate(&set, NOW), Ok(()));
    // A polygon exactly 60 m across (its diameter: the base of a flat triangle).
    let set = with(1, |o| {
        *o = LiveObstacle::polygon(
            12,
            ObstacleClass::Vehicle,
            &[[0.0, 0.0], [60.0, 0.0], [30.0, 0.01]],
            [0.0, 0.0],
            OBSTACLE_STAMP,
        )
        .expect("polygon")
    });
    assert_eq!(v.validate(&set, NOW), Ok(()));
}

#[test]
fn count_beyond_capacity() {
    let mut set = valid_set();
    set.count = 129;
    let r = reject(&set, "too-many-obstacles");
    assert_eq!(r, LiveSetRejection::TooManyObstacles { count: 129 });
    assert_eq!(r.obstacle(), None);
    assert_eq!(
        r.to_string(),
        "the set claims 129 obstacles, at most 128 fit"
    );
}

#[test]
fn set_stamp_from_the_future() {
    let mut set = valid_set();
    set.timestamp_ns = NOW + 200_000_000;
    let r = reject(&set, "set-stamp-in-future");
    assert_eq!(
        r.to_string(),
        "the set is stamped 0.200 s in the future (at most 0.050 s allowed)"
    );
}

#[test]
fn unknown_shape_and_class_codes() {
    let r = reject(&with(2, |o| o.shape = 7), "unknown-shape");
    assert_eq!(
        r,
        LiveSetRejection::UnknownShape {
            index: 2,
            id: 13,
            code: 7
        }
    );
    let r = reject(&with(0, |o| o.class = 5), "unknown-class");
    assert_eq!(r.to_string(), "obstacle 0 (id 11): unknown class code 5");
}

#[test]
fn non_finite_numbers() {
    for (index, change, field) in [
        (
            0,
            (|o: &mut LiveObstacle| o.y = f64::NAN) as fn(&mut LiveObstacle),
            Field::Y,
        ),
        (0, |o| o.radius = f64::INFINITY, Field::Radius),
        (0, |o| o.vx = f64::NEG_INFINITY, Field::Vx),
        (1, |o| o.vertices[2][1] = f64::NAN, Field::VertexY(2)),
    ] {
        let r = reject(&with(index, change), "non-finite");
        match r {
            LiveSetRejection::NonFinite { field: got, .. } => assert_eq!(got, field, "{r}"),
            other => panic!("{other:?}"),
        }
    }
    let r = reject(&with(1, |o| o.vertices[2][1] = f64::NAN), "non-finite");
    assert_eq!(
        r.to_string(),
        "obstacle 1 (id 12): vertex 2 y is not finite (NaN)"
    );
}

#[test]
fn radius_not_positive_or_absurd() {
    for radius in [0.0, -0.4] {
        let r = reject(&with(0, |o| o.radius = radius), "radius-not-positive");
        assert!(r.to_string().contains("must be positive"), "{r}");
    }
    let r = reject(&with(0, |o| o.radius = 400.0), "radius-too-large");
    assert_eq!(
        r.to_string(),
        "obstacle 0 (id 11): radius 400.000 m is too large (at most 30.000 m)"
    );
}

#[test]
fn polygon_vertex_count() {
    for count in [0, 2, 9, u32::MAX] {
        let r = reject(&with(3, |o| o.vertex_count = count), "vertex-count");
        assert_eq!(
            r,
            LiveSetRejection::VertexCount {
                index: 3,
                id: 14,
                count
            }
        );
    }
}

fn polygon_at(vertices: &[[f64; 2]]) -> LiveObstacleSet {
    with(1, |o| {
        *o = LiveObstacle::polygon(
            12,
            ObstacleClass::Vehicle,
            vertices,
            [0.0, 0.0],
            OBSTACLE_STAMP,
        )
        .expect("polygon")
    })
}

#[test]
fn non_convex_polygons_in_either_winding() {
    // An L-shaped hexagon: reflex at vertex 3, counter-clockwise; reversed, clockwise.
    let l_shape = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 1.0],
        [1.0, 1.0],
        [1.0, 2.0],
        [0.0, 2.0],
    ];
    let r = reject(&polygon_at(&l_shape), "not-convex");
    assert_eq!(
        r,
        LiveSetRejection::BadPolygon {
            index: 1,
            id: 12,
            defect: PolygonDefect::NotConvex {
                vertex: 3,
                counter_clockwise: true
            }
        }
    );
    assert!(
        r.to_string()
            .contains("winds counter-clockwise but turns the other way at vertex 3"),
        "{r}"
    );
    let mut reversed = l_shape;
    reversed.reverse();
    let r = reject(&polygon_at(&reversed), "not-convex");
    assert!(
        r.to_string()
            .contains("winds clockwise but turns the other way at vertex 2"),
        "{r}"
    );
    // The same hexagon made convex (vertex 3 moved out) passes in both windings.
    let mut convex = l_shape;
    convex[3] = [1.5, 1.5];
    assert_eq!(polygon_defect(&convex), None);
    convex.reverse();
    assert_eq!(polygon_defect(&convex), None);
}

#[test]
fn self_intersecting_polygons() {
    // A bow tie: edges 0 and 2 cross (its signed area is zero, yet it reads as crossing).
    let bow_tie = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
    let r = reject(&polygon_at(&bow_tie), "self-intersecting");
    assert!(
        r.to_string()
            .contains("crosses itself (edges 0 and 2 meet)"),
        "{r}"
    );
    // A pentagram: every turn the same way, but it winds twice.
    let star: Vec<[f64; 2]> = (0..5)
        .map(|k| {
            let a = std::f64::consts::FRAC_PI_2 + f64::from(k) * 4.0 * std::f64::consts::PI / 5.0;
            [a.cos(), a.sin()]
        })
        .collect();
    assert!(matches!(
        polygon_defect(&star),
        Some(PolygonDefect::SelfIntersecting { .. })
    ));
}

#[test]
fn degenerate_polygons() {
    let r = reject(
        &polygon_at(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]),
        "zero-area",
    );
    assert!(r.to_string().contains("encloses no area"), "{r}");
    let r = reject(
        &polygon_at(&[[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
        "repeated-vertex",
    );
    assert!(
        r.to_string()
            .contains("vertices 1 and the next one coincide"),
        "{r}"
    );
}

#[test]
fn polygon_extent() {
    let r = reject(
        &polygon_at(&[[0.0, 0.0], [50.0, 0.0], [50.0, 40.0]]),
        "extent-too-large",
    );
    assert_eq!(
        r.to_string(),
        "obstacle 1 (id 12): the polygon is 64.031 m across (at most 60.000 m)"
    );
}

#[test]
fn absurd_coordinates() {
    let r = reject(&with(0, |o| o.x = -2.0e6), "coordinate-out-of-range");
    assert!(
        r.to_string()
            .contains("centre x -2.000e6 m is out of range"),
        "{r}"
    );
    let r = reject(
        &with(2, |o| o.vertices[4][0] = 3.0e6),
        "coordinate-out-of-range",
    );
    assert!(matches!(
        r,
        LiveSetRejection::CoordinateOutOfRange {
            field: Field::VertexX(4),
            index: 2,
            id: 13,
            ..
        }
    ));
}

#[test]
fn absurd_speed() {
    // 25 m/s along each axis: 35.4 m/s, though each component is under the limit.
    let r = reject(
        &with(3, |o| {
            o.vx = 25.0;
            o.vy = -25.0
        }),
        "speed-too-high",
    );
    assert_eq!(
        r.to_string(),
        "obstacle 3 (id 14) moves at 35.355 m/s (at most 30.000 m/s)"
    );
}

#[test]
fn obstacle_stamps_from_the_future_or_after_the_set() {
    let r = reject(
        &with(2, |o| o.timestamp_ns = NOW + 100_000_000),
        "obstacle-stamp-in-future",
    );
    assert!(r.to_string().contains("0.100 s in the future"), "{r}");
    // Not ahead of now, but 0.06 s after the set's stamp.
    let r = reject(
        &with(2, |o| o.timestamp_ns = SET_STAMP + 60_000_000),
        "obstacle-newer-than-set",
    );
    assert_eq!(
        r.to_string(),
        "obstacle 2 (id 13) is stamped 0.060 s after its set (at most 0.050 s allowed)"
    );
}

#[test]
fn duplicate_ids() {
    let r = reject(&with(3, |o| o.id = 12), "duplicate-id");
    assert_eq!(
        r,
        LiveSetRejection::DuplicateId {
            index: 3,
            id: 12,
            first_index: 1
        }
    );
    assert_eq!(
        r.to_string(),
        "obstacle 3 has id 12, as obstacle 1 has: ids must be unique in a set"
    );
}

#[test]
fn the_first_bad_obstacle_is_named_and_the_set_rejected_whole() {
    // Obstacles 1 and 3 are both bad: the reason is obstacle 1's.
    let mut set = valid_set();
    set.obstacles[3].radius = 0.0;
    set.obstacles[3].shape = 0;
    set.obstacles[1].class = 99;
    let r = validator().validate(&set, NOW).expect_err("rejected");
    assert_eq!(r.obstacle(), Some((1, 12)));
}

#[test]
fn settings_must_be_positive_and_finite() {
    let d = LiveObstacleValidator::default();
    assert_eq!(
        (
            d.max_future_s,
            d.max_radius_m,
            d.max_extent_m,
            d.max_speed_mps,
            d.max_abs_coord
        ),
        (0.05, 30.0, 60.0, 30.0, MAX_OBSTACLE_ABS)
    );
    assert_eq!(
        LiveObstacleValidator::new(0.05, 30.0, 60.0, 30.0, MAX_OBSTACLE_ABS),
        Ok(d)
    );
    let e = LiveObstacleValidator::new(0.05, 30.0, f64::NAN, 30.0, 1.0).expect_err("NaN");
    assert_eq!(e.field, "max_extent_m");
    let e = LiveObstacleValidator::new(0.0, 30.0, 60.0, 30.0, 1.0).expect_err("zero");
    assert_eq!(
        e.to_string(),
        "live obstacle check: max_future_s must be a positive finite number, got 0.000"
    );
}
