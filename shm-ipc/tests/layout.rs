//! The documented wire layout, checked the way a foreign peer would see it: as raw bytes at
//! the documented offsets. (`msg.rs` also freezes sizes and offsets at compile time.)

use core::mem::{align_of, offset_of, size_of};

use iceoryx2::prelude::ZeroCopySend;
use shm_ipc::{
    pose_flags, AbortReason, Command, GoalKind, GoalOutcome, GoalReply, GoalRequest, LiveObstacle,
    LiveObstacleError, LiveObstacleSet, MachineState, Mode, Obstacle, ObstacleClass, ObstacleShape,
    Pose2, PoseEstimate, RejectCode, Telemetry, MAX_LIVE_OBSTACLES, MAX_OBSTACLES,
    MAX_POLYGON_VERTICES, MAX_ROUTE, MAX_TRAJECTORY, REASON_TEXT_CAPACITY, SITE_ID_CAPACITY,
};

/// The bytes of a padding-free POD value.
fn bytes<T>(v: &T) -> &[u8] {
    // SAFETY: every payload type is repr(C) without implicit padding (checked by the size
    // assertions below), so all bytes are initialised.
    unsafe { core::slice::from_raw_parts((v as *const T).cast::<u8>(), size_of::<T>()) }
}

fn u32_at(b: &[u8], off: usize) -> u32 {
    u32::from_le_bytes(b[off..off + 4].try_into().expect("4 bytes"))
}
fn u64_at(b: &[u8], off: usize) -> u64 {
    u64::from_le_bytes(b[off..off + 8].try_into().expect("8 bytes"))
}
fn f64_at(b: &[u8], off: usize) -> f64 {
    f64::from_le_bytes(b[off..off + 8].try_into().expect("8 bytes"))
}

#[test]
fn sizes_alignments_and_offsets() {
    assert_eq!((size_of::<Pose2>(), align_of::<Pose2>()), (24, 8));
    assert_eq!((size_of::<Obstacle>(), align_of::<Obstacle>()), (24, 8));
    assert_eq!(
        (size_of::<MachineState>(), align_of::<MachineState>()),
        (48, 8)
    );
    assert_eq!((size_of::<Command>(), align_of::<Command>()), (16, 8));
    assert_eq!(
        (size_of::<GoalRequest>(), align_of::<GoalRequest>()),
        (232, 8)
    );
    assert_eq!((size_of::<GoalReply>(), align_of::<GoalReply>()), (152, 8));
    assert_eq!(
        (size_of::<PoseEstimate>(), align_of::<PoseEstimate>()),
        (112, 8)
    );
    assert_eq!((size_of::<Telemetry>(), align_of::<Telemetry>()), (2816, 8));

    // No implicit padding: the sizes are the sums of the fields.
    assert_eq!(
        size_of::<GoalRequest>(),
        8 + 4 + 4 + 24 + MAX_OBSTACLES * 24
    );
    assert_eq!(size_of::<GoalReply>(), 8 + 4 * 4 + 128);
    assert_eq!(size_of::<PoseEstimate>(), 8 + 4 + 4 + 3 * 8 + 9 * 8);
    assert_eq!(
        size_of::<Telemetry>(),
        3 * 8
            + 6 * 4
            + 4 * 8
            + 48
            + 24
            + 16
            + MAX_TRAJECTORY * 48
            + 8
            + 4 * 4
            + REASON_TEXT_CAPACITY
            + 2 * 4
            + 24
            + MAX_ROUTE * 24
            + 2 * 8
            + 2 * 4
            + 2 * 8
            + 2 * 4
            + SITE_ID_CAPACITY
    );

    assert_eq!(offset_of!(GoalRequest, obstacles), 40);
    assert_eq!(offset_of!(GoalReply, reason), 24);
    assert_eq!(offset_of!(PoseEstimate, covariance), 40);
    assert_eq!(offset_of!(Telemetry, state), 80);
    assert_eq!(offset_of!(Telemetry, trajectory), 168);
    assert_eq!(offset_of!(Telemetry, outcome_request_id), 2136);
    assert_eq!(offset_of!(Telemetry, outcome_text), 2160);
    assert_eq!(offset_of!(Telemetry, route), 2320);
    assert_eq!(offset_of!(Telemetry, plan_time_us), 2704);
    assert_eq!(offset_of!(Telemetry, route_age_s), 2712);
    assert_eq!(offset_of!(Telemetry, at_rest), 2720);
    assert_eq!(offset_of!(Telemetry, site_version), 2728);
    assert_eq!(offset_of!(Telemetry, site_hash), 2736);
    assert_eq!(offset_of!(Telemetry, site_id_len), 2744);
    assert_eq!(offset_of!(Telemetry, site_id), 2752);
}

#[test]
fn type_names_are_stable() {
    // iceoryx2 compares these when a peer opens a service; C++ peers set IOX2_TYPE_NAME.
    unsafe {
        assert_eq!(GoalRequest::type_name(), "wlnav::v2::GoalRequest");
        assert_eq!(GoalReply::type_name(), "wlnav::v2::GoalReply");
        assert_eq!(PoseEstimate::type_name(), "wlnav::v2::PoseEstimate");
        assert_eq!(Telemetry::type_name(), "wlnav::v2::Telemetry");
        assert_eq!(LiveObstacle::type_name(), "wlnav::v2::LiveObstacle");
        assert_eq!(LiveObstacleSet::type_name(), "wlnav::v2::LiveObstacleSet");
    }
}

#[test]
fn live_obstacle_sizes_and_offsets() {
    assert_eq!((MAX_LIVE_OBSTACLES, MAX_POLYGON_VERTICES), (128, 8));
    assert_eq!(
        (size_of::<LiveObstacle>(), align_of::<LiveObstacle>()),
        (192, 8)
    );
    // No implicit padding: the size is the sum of the fields.
    assert_eq!(size_of::<LiveObstacle>(), 4 * 4 + 8 + 5 * 8 + 8 * 2 * 8);
    assert_eq!(offset_of!(LiveObstacle, timestamp_ns), 16);
    assert_eq!(offset_of!(LiveObstacle, vertices), 64);
    assert_eq!(
        (size_of::<LiveObstacleSet>(), align_of::<LiveObstacleSet>()),
        (24592, 8)
    );
    assert_eq!(size_of::<LiveObstacleSet>(), 8 + 4 + 4 + 128 * 192);
    assert_eq!(offset_of!(LiveObstacleSet, obstacles), 16);
}

#[test]
fn live_obstacle_bytes() {
    let circle = LiveObstacle::circle(
        0xA1B2_C3D4,
        ObstacleClass::Person,
        [3.5, -1.25],
        0.4,
        [0.5, 1.4],
        1_000_000_007,
    );
    let b = bytes(&circle);
    assert_eq!(u32_at(b, 0), 0xA1B2_C3D4);
    assert_eq!(u32_at(b, 4), 0, "shape: circle");
    assert_eq!(u32_at(b, 8), 1, "class: person");
    assert_eq!(u32_at(b, 12), 0, "a circle has no vertices");
    assert_eq!(u64_at(b, 16), 1_000_000_007);
    assert_eq!(
        (f64_at(b, 24), f64_at(b, 32), f64_at(b, 40)),
        (3.5, -1.25, 0.4)
    );
    assert_eq!((f64_at(b, 48), f64_at(b, 56)), (0.5, 1.4));
    assert!(b[64..].iter().all(|&x| x == 0), "unused vertices are zero");

    let square = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]];
    let poly =
        LiveObstacle::polygon(9, ObstacleClass::Machine, &square, [-1.0, 0.0], 5).expect("polygon");
    let b = bytes(&poly);
    assert_eq!((u32_at(b, 4), u32_at(b, 8), u32_at(b, 12)), (1, 3, 4));
    assert_eq!(
        (f64_at(b, 24), f64_at(b, 32), f64_at(b, 40)),
        (0.0, 0.0, 0.0)
    );
    assert_eq!((f64_at(b, 48), f64_at(b, 56)), (-1.0, 0.0));
    // Vertex k at 64 + 16 k: x, then y.
    assert_eq!(
        (f64_at(b, 64 + 16 * 2), f64_at(b, 64 + 16 * 2 + 8)),
        (2.0, 1.0)
    );
    assert!(b[64 + 16 * 4..].iter().all(|&x| x == 0));
    assert_eq!(poly.vertices(), &square);

    let mut set = LiveObstacleSet::empty(77, 3);
    set.push(circle).expect("room");
    set.push(poly).expect("room");
    let b = bytes(&set);
    assert_eq!((u64_at(b, 0), u32_at(b, 8), u32_at(b, 12)), (77, 3, 2));
    assert_eq!(&b[16..16 + 192], bytes(&circle));
    assert_eq!(&b[16 + 192..16 + 384], bytes(&poly));
    assert!(b[16 + 384..].iter().all(|&x| x == 0));
}

#[test]
fn live_obstacle_codes_and_constructors() {
    for (code, class, name) in [
        (0, ObstacleClass::Unknown, "unknown"),
        (1, ObstacleClass::Person, "person"),
        (2, ObstacleClass::Vehicle, "vehicle"),
        (3, ObstacleClass::Machine, "machine"),
        (4, ObstacleClass::Static, "static"),
    ] {
        assert_eq!(ObstacleClass::try_from(code), Ok(class));
        assert_eq!((class.code(), class.name()), (code, name));
        assert_eq!(ObstacleClass::from_name(name), Some(class));
    }
    assert_eq!(ObstacleClass::try_from(5), Err(5));
    assert_eq!(ObstacleClass::from_name("Person"), None);
    assert_eq!(ObstacleShape::try_from(0), Ok(ObstacleShape::Circle));
    assert_eq!(ObstacleShape::try_from(1), Ok(ObstacleShape::Polygon));
    assert_eq!(ObstacleShape::try_from(2), Err(2));
    assert_eq!(ObstacleShape::Polygon.name(), "polygon");

    let two = [[0.0, 0.0], [1.0, 0.0]];
    let nine = [[0.0, 0.0]; 9];
    for bad in [&two[..], &nine[..]] {
        assert_eq!(
            LiveObstacle::polygon(1, ObstacleClass::Unknown, bad, [0.0, 0.0], 0),
            Err(LiveObstacleError::VertexCount(bad.len()))
        );
    }
    // A corrupt vertex count from shared memory cannot make `vertices` panic.
    let mut o = LiveObstacle::ZERO;
    o.vertex_count = u32::MAX;
    assert_eq!(o.vertices().len(), MAX_POLYGON_VERTICES);

    let mut set = LiveObstacleSet::empty(1, 1);
    for id in 0..MAX_LIVE_OBSTACLES as u32 {
        set.push(LiveObstacle::circle(
            id,
            ObstacleClass::Unknown,
            [0.0, 0.0],
            1.0,
            [0.0, 0.0],
            1,
        ))
        .expect("room");
    }
    assert_eq!(set.as_slice().len(), MAX_LIVE_OBSTACLES);
    assert_eq!(
        set.push(LiveObstacle::ZERO),
        Err(LiveObstacleError::SetFull)
    );
    // A count beyond the capacity is clamped, never trusted.
    set.count = 1000;
    assert_eq!(set.as_slice().len(), MAX_LIVE_OBSTACLES);
    assert_eq!(
        set.push(LiveObstacle::ZERO),
        Err(LiveObstacleError::SetFull)
    );
}

#[test]
fn goal_request_bytes() {
    let obstacles = [Obstacle::new(1.0, 2.0, 0.5), Obstacle::new(-3.0, 4.0, 1.5)];
    let req = GoalRequest::set_goal(
        0x0102_0304_0506_0708,
        Pose2::new(4.5, -1.25, 0.75),
        &obstacles,
    )
    .expect("request");
    let b = bytes(&req);
    assert_eq!(u64_at(b, 0), 0x0102_0304_0506_0708);
    assert_eq!(u32_at(b, 8), GoalKind::SetGoal.code());
    assert_eq!(u32_at(b, 8), 1);
    assert_eq!(u32_at(b, 12), 2);
    assert_eq!(
        (f64_at(b, 16), f64_at(b, 24), f64_at(b, 32)),
        (4.5, -1.25, 0.75)
    );
    assert_eq!(
        (f64_at(b, 40), f64_at(b, 48), f64_at(b, 56)),
        (1.0, 2.0, 0.5)
    );
    assert_eq!(
        (f64_at(b, 64), f64_at(b, 72), f64_at(b, 80)),
        (-3.0, 4.0, 1.5)
    );
    // Unused obstacle slots are zero.
    assert!(b[88..].iter().all(|&x| x == 0));
    assert_eq!(u32_at(bytes(&GoalRequest::cancel(1)), 8), 2);
    assert_eq!(u32_at(bytes(&GoalRequest::stop(1)), 8), 3);
    assert_eq!(u32_at(bytes(&GoalRequest::resume(1)), 8), 4);
    assert_eq!(GoalKind::try_from(4), Ok(GoalKind::Resume));
}

#[test]
fn goal_reply_bytes() {
    let r = GoalReply::reject(99, RejectCode::GoalInCollision, "inside");
    let b = bytes(&r);
    assert_eq!(u64_at(b, 0), 99);
    assert_eq!(u32_at(b, 8), 0);
    assert_eq!(u32_at(b, 12), 5);
    assert_eq!(u32_at(b, 16), 6);
    assert_eq!(u32_at(b, 20), 0);
    assert_eq!(&b[24..30], b"inside");
    assert!(
        b[30..].iter().all(|&x| x == 0),
        "NUL-terminated, zero-filled"
    );
    let a = GoalReply::accept(7);
    assert_eq!(u32_at(bytes(&a), 8), 1);
    assert_eq!(u32_at(bytes(&a), 12), 0);
    let m = GoalReply::reject(1, RejectCode::MachineInCollision, "on the machine");
    assert_eq!(u32_at(bytes(&m), 12), 9);
    assert_eq!(RejectCode::try_from(9), Ok(RejectCode::MachineInCollision));
    assert_eq!(RejectCode::try_from(10), Err(10));
}

#[test]
fn pose_estimate_bytes() {
    let mut p = PoseEstimate::new(123_456_789, 42, Pose2::new(1.5, -2.5, 3.0));
    p.covariance[4] = 0.25;
    p.flags |= pose_flags::COVARIANCE_VALID;
    let b = bytes(&p);
    assert_eq!(u64_at(b, 0), 123_456_789);
    assert_eq!(u32_at(b, 8), 42);
    assert_eq!(u32_at(b, 12), 0b11);
    assert_eq!(
        (f64_at(b, 16), f64_at(b, 24), f64_at(b, 32)),
        (1.5, -2.5, 3.0)
    );
    assert_eq!(f64_at(b, 40 + 4 * 8), 0.25);
}

#[test]
fn telemetry_bytes() {
    let mut t = Telemetry::ZERO;
    t.tick = 11;
    t.timestamp_ns = 22;
    t.goal_request_id = 33;
    t.mode = Mode::Reached.code();
    t.fault_flags = shm_ipc::fault_flags::OVERRUN;
    t.goal_active = 1;
    t.qp_iterations = 9;
    t.sqp_iterations = 1;
    t.solve_time_us = 512.5;
    t.cost = 0.125;
    t.pose_error_xy = 0.05;
    t.pose_error_heading = -0.01;
    t.state = MachineState::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    t.goal = Pose2::new(7.0, 8.0, 9.0);
    t.command = Command {
        beta_dot: 0.1,
        v: 0.2,
    };
    let plan: Vec<_> = (0..MAX_TRAJECTORY + 5)
        .map(|i| MachineState::from_array([i as f64; 6]))
        .collect();
    assert_eq!(t.set_trajectory(&plan), MAX_TRAJECTORY);
    let b = bytes(&t);
    assert_eq!((u64_at(b, 0), u64_at(b, 8), u64_at(b, 16)), (11, 22, 33));
    assert_eq!(u32_at(b, 24), 3);
    assert_eq!(u32_at(b, 28), 1 << 6);
    assert_eq!(u32_at(b, 32), 1);
    assert_eq!(u32_at(b, 36), 41);
    assert_eq!((u32_at(b, 40), u32_at(b, 44)), (9, 1));
    assert_eq!(
        (f64_at(b, 48), f64_at(b, 56), f64_at(b, 64), f64_at(b, 72)),
        (512.5, 0.125, 0.05, -0.01)
    );
    for (i, v) in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0].iter().enumerate() {
        assert_eq!(f64_at(b, 80 + 8 * i), *v);
    }
    assert_eq!(
        (f64_at(b, 128), f64_at(b, 136), f64_at(b, 144)),
        (7.0, 8.0, 9.0)
    );
    assert_eq!((f64_at(b, 152), f64_at(b, 160)), (0.1, 0.2));
    // trajectory[k].v_f at 168 + 48 k + 40
    assert_eq!(f64_at(b, 168 + 48 * 40 + 40), 40.0);
    assert_eq!(t.trajectory().len(), 41);

    // A corrupt length from a foreign peer is clamped, not trusted.
    t.trajectory_len = u32::MAX;
    assert_eq!(t.trajectory().len(), MAX_TRAJECTORY);
    t.mode = 77;
    assert_eq!(t.mode(), Err(77));
}

#[test]
fn telemetry_outcome_subgoal_and_route_bytes() {
    let mut t = Telemetry::ZERO;
    let b = bytes(&t);
    assert!(
        b[2136..].iter().all(|&x| x == 0),
        "no outcome, no route: zeros"
    );
    t.set_outcome(
        0xAABB,
        GoalOutcome::Aborted,
        AbortReason::NoProgress,
        3,
        "no approach",
    );
    t.subgoal_active = 1;
    t.subgoal = Pose2::new(1.0, 2.0, 0.5);
    let route: Vec<_> = (0..MAX_ROUTE + 3)
        .map(|i| Pose2::new(i as f64, -(i as f64), 0.25))
        .collect();
    assert_eq!(t.set_route(&route), MAX_ROUTE);
    let b = bytes(&t);
    assert_eq!(u64_at(b, 2136), 0xAABB);
    assert_eq!((u32_at(b, 2144), u32_at(b, 2148)), (4, 1));
    assert_eq!((u32_at(b, 2152), u32_at(b, 2156)), (3, 11));
    assert_eq!(&b[2160..2171], b"no approach");
    assert!(b[2171..2288].iter().all(|&x| x == 0), "zero-filled text");
    assert_eq!((u32_at(b, 2288), u32_at(b, 2292)), (1, 16));
    assert_eq!(
        (f64_at(b, 2296), f64_at(b, 2304), f64_at(b, 2312)),
        (1.0, 2.0, 0.5)
    );
    // route[k] at 2320 + 24 k
    assert_eq!(
        (f64_at(b, 2320 + 24 * 15), f64_at(b, 2320 + 24 * 15 + 8)),
        (15.0, -15.0)
    );
    assert_eq!(t.outcome(), Ok(GoalOutcome::Aborted));
    assert_eq!(t.abort_reason(), Ok(AbortReason::NoProgress));
    assert_eq!(t.outcome_text(), "no approach");
    assert_eq!(t.route().len(), MAX_ROUTE);
    // Corrupt values from a foreign peer are clamped or reported, never trusted.
    t.route_len = u32::MAX;
    t.outcome_text_len = u32::MAX;
    t.outcome = 42;
    t.abort_reason = 42;
    assert_eq!(t.route().len(), MAX_ROUTE);
    assert_eq!(t.outcome_text().len(), REASON_TEXT_CAPACITY);
    assert!(t.outcome_text().starts_with("no approach"));
    assert_eq!((t.outcome(), t.abort_reason()), (Err(42), Err(42)));
    // A long text is cut at a character boundary.
    t.set_outcome(
        1,
        GoalOutcome::Cancelled,
        AbortReason::None,
        4,
        &"é".repeat(100),
    );
    assert_eq!(t.outcome_text_len, 128);
    assert_eq!(t.outcome_text().chars().count(), 64);
}
