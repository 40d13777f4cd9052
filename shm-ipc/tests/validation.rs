//! Every reject reason of the goal validator, its wire code, and its message.

use shm_ipc::{
    GoalReply, GoalRequest, GoalValidator, Obstacle, Pose2, RejectCode, RejectReason, ValidRequest,
    Workspace, MAX_OBSTACLES, REASON_TEXT_CAPACITY,
};

fn validator() -> GoalValidator {
    GoalValidator::new(Workspace::new(-10.0, 20.0, -5.0, 5.0).expect("workspace"))
}

fn goal(x: f64, y: f64, heading: f64, obstacles: &[Obstacle]) -> GoalRequest {
    GoalRequest::set_goal(17, Pose2::new(x, y, heading), obstacles).expect("request")
}

fn reject(req: &GoalRequest) -> RejectReason {
    let (result, reply) = validator().validate_and_reply(req);
    let reason = result.expect_err("should be rejected");
    // The reply carries the same code and message, for the same request.
    assert_eq!(reply.request_id, req.request_id);
    assert!(!reply.is_accepted());
    assert_eq!(reply.reject_code(), Ok(reason.code()));
    assert_eq!(reply.reason_text(), reason.to_string());
    reason
}

#[test]
fn valid_goal_is_accepted_with_its_obstacles() {
    let obstacles = [Obstacle::new(3.0, 1.0, 0.5), Obstacle::new(-2.0, 0.0, 1.0)];
    let req = goal(4.5, 0.0, 1.0, &obstacles);
    let (result, reply) = validator().validate_and_reply(&req);
    assert!(reply.is_accepted());
    assert_eq!(reply.reject_code(), Ok(RejectCode::None));
    assert_eq!(reply.reason_text(), "");
    match result.expect("valid") {
        ValidRequest::SetGoal {
            request_id,
            goal,
            obstacles: got,
        } => {
            assert_eq!(request_id, 17);
            assert_eq!(goal, Pose2::new(4.5, 0.0, 1.0));
            assert_eq!(got.as_slice(), &obstacles);
        }
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn boundaries_are_accepted() {
    // On the workspace edge.
    assert!(validator().validate(&goal(20.0, -5.0, 0.0, &[])).is_ok());
    // Exactly on an obstacle's boundary (distance = r): reachable under distance ≥ r.
    assert!(validator()
        .validate(&goal(1.0, 0.0, 0.0, &[Obstacle::new(0.0, 0.0, 1.0)]))
        .is_ok());
    // Exactly eight obstacles.
    let eight = [Obstacle::new(-8.0, 4.0, 0.1); MAX_OBSTACLES];
    assert!(validator().validate(&goal(0.0, 0.0, 0.0, &eight)).is_ok());
    // Headings need not be wrapped.
    assert!(validator().validate(&goal(0.0, 0.0, 100.0, &[])).is_ok());
}

#[test]
fn non_finite_goal_is_rejected() {
    for (req, field) in [
        (goal(f64::NAN, 0.0, 0.0, &[]), "x"),
        (goal(0.0, f64::INFINITY, 0.0, &[]), "y"),
        (goal(0.0, 0.0, f64::NEG_INFINITY, &[]), "heading"),
    ] {
        let reason = reject(&req);
        assert_eq!(reason.code(), RejectCode::NonFinite);
        assert!(
            matches!(reason, RejectReason::NonFiniteGoal { field: f, .. } if f == field),
            "{reason:?}"
        );
        assert!(reason.to_string().contains("not finite"));
    }
}

#[test]
fn non_finite_obstacle_is_rejected() {
    let reason = reject(&goal(
        1.0,
        1.0,
        0.0,
        &[
            Obstacle::new(5.0, 1.0, 1.0),
            Obstacle::new(f64::NAN, 0.0, 1.0),
        ],
    ));
    assert_eq!(reason.code(), RejectCode::NonFinite);
    assert!(matches!(
        reason,
        RejectReason::NonFiniteObstacle {
            index: 1,
            field: "x",
            ..
        }
    ));
    assert!(reason.to_string().contains("obstacle 1"));
}

#[test]
fn out_of_workspace_is_rejected() {
    for (x, y) in [
        (20.5, 0.0),
        (-10.1, 0.0),
        (0.0, 5.01),
        (0.0, -7.0),
        (1e9, 1e9),
    ] {
        let reason = reject(&goal(x, y, 0.0, &[]));
        assert_eq!(reason.code(), RejectCode::OutOfWorkspace);
        assert!(
            reason.to_string().contains("outside the workspace"),
            "{reason}"
        );
    }
}

#[test]
fn too_many_obstacles_is_rejected() {
    let mut req = goal(0.0, 0.0, 0.0, &[]);
    for count in [9, 100, u32::MAX] {
        req.obstacle_count = count;
        let reason = reject(&req);
        assert_eq!(reason, RejectReason::TooManyObstacles { count });
        assert_eq!(reason.code(), RejectCode::TooManyObstacles);
    }
    // The builder refuses to construct such a request at all.
    assert!(GoalRequest::set_goal(1, Pose2::default(), &[Obstacle::default(); 9]).is_none());
}

#[test]
fn bad_obstacle_radius_is_rejected() {
    for r in [0.0, -1.0, f64::NAN, f64::INFINITY, -0.0] {
        let reason = reject(&goal(0.0, 0.0, 0.0, &[Obstacle::new(5.0, 2.0, r)]));
        assert_eq!(reason.code(), RejectCode::BadObstacle, "r = {r}");
        assert!(matches!(
            reason,
            RejectReason::BadObstacleRadius { index: 0, .. }
        ));
        assert!(reason.to_string().contains("positive and finite"));
    }
}

#[test]
fn obstacle_geometry_is_left_to_the_daemon() {
    // The validator knows neither the machine's footprint nor its position: a goal inside
    // an obstacle passes here and is the daemon's to reject (goal-in-collision).
    let obstacles = [Obstacle::new(-5.0, 0.0, 1.0), Obstacle::new(3.0, 1.0, 0.5)];
    assert!(matches!(
        GoalValidator::default().validate(&goal(3.2, 1.1, 0.0, &obstacles)),
        Ok(ValidRequest::SetGoal { .. })
    ));
}

#[test]
fn unknown_kind_is_rejected() {
    for kind in [0, 5, u32::MAX] {
        let mut req = goal(0.0, 0.0, 0.0, &[]);
        req.kind = kind;
        let reason = reject(&req);
        assert_eq!(reason, RejectReason::UnknownKind(kind));
        assert_eq!(reason.code(), RejectCode::UnknownKind);
    }
}

#[test]
fn cancel_stop_and_resume_are_accepted_even_with_garbage_goal_fields() {
    for mut req in [
        GoalRequest::cancel(5),
        GoalRequest::stop(6),
        GoalRequest::resume(7),
    ] {
        req.goal = Pose2::new(f64::NAN, f64::INFINITY, 1e300);
        req.obstacle_count = 1000;
        let (result, reply) = validator().validate_and_reply(&req);
        assert!(reply.is_accepted());
        match result.expect("valid") {
            ValidRequest::Cancel { request_id } => assert_eq!(request_id, 5),
            ValidRequest::Stop { request_id } => assert_eq!(request_id, 6),
            ValidRequest::Resume { request_id } => assert_eq!(request_id, 7),
            other => panic!("unexpected {other:?}"),
        }
    }
}

#[test]
fn check_order_is_deterministic() {
    // Non-finite goal and too many obstacles: the count is reported first (it decides
    // which obstacle entries are even meaningful).
    let mut req = goal(f64::NAN, 0.0, 0.0, &[]);
    req.obstacle_count = 9;
    assert_eq!(reject(&req).code(), RejectCode::TooManyObstacles);
    // Out of workspace and a bad radius: workspace first.
    let req = goal(100.0, 0.0, 0.0, &[Obstacle::new(0.0, 0.0, -1.0)]);
    assert_eq!(reject(&req).code(), RejectCode::OutOfWorkspace);
}

#[test]
fn workspace_rejects_bad_bounds() {
    assert!(Workspace::new(0.0, 0.0, -1.0, 1.0).is_none());
    assert!(Workspace::new(1.0, 0.0, -1.0, 1.0).is_none());
    assert!(Workspace::new(f64::NAN, 1.0, -1.0, 1.0).is_none());
    assert!(Workspace::new(0.0, f64::INFINITY, -1.0, 1.0).is_none());
    assert!(Workspace::new(0.0, 1.0, -1.0, 1.0).is_some());
}

#[test]
fn reason_text_is_truncated_at_char_boundary_and_never_panics() {
    let long = "é".repeat(200); // 400 bytes, 2 per char
    let reply = GoalReply::reject(1, RejectCode::Other, &long);
    assert_eq!(reply.reason_len as usize, REASON_TEXT_CAPACITY);
    assert_eq!(reply.reason_text(), "é".repeat(REASON_TEXT_CAPACITY / 2));

    let three = "€".repeat(100); // 3 bytes per char: 128 is not a boundary
    let reply = GoalReply::reject(1, RejectCode::Other, &three);
    assert_eq!(reply.reason_len, 126);
    assert!(reply.reason_text().chars().all(|c| c == '€'));

    // Garbage from a foreign peer: a length beyond the buffer, invalid UTF-8, unknown code.
    let mut bad = GoalReply::reject(1, RejectCode::Other, "ok");
    bad.reason_len = u32::MAX;
    bad.reason[2] = 0xff;
    bad.reason_code = 999;
    assert_eq!(bad.reason_text(), "ok");
    assert_eq!(bad.reject_code(), Err(999));
}
