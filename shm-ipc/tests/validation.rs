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
    // Headings need not be wrapped (they are normalised), up to the absurd.
    assert!(validator().validate(&goal(0.0, 0.0, 100.0, &[])).is_ok());
    assert!(validator()
        .validate(&goal(0.0, 0.0, shm_ipc::MAX_HEADING_ABS, &[]))
        .is_ok());
}

fn accepted_heading(heading: f64) -> f64 {
    match validator().validate(&goal(1.0, 1.0, heading, &[])) {
        Ok(ValidRequest::SetGoal { goal, .. }) => goal.heading,
        other => panic!("{heading}: {other:?}"),
    }
}

#[test]
fn headings_are_normalised_to_minus_pi_exclusive_pi_inclusive() {
    use std::f64::consts::PI;
    assert_eq!(accepted_heading(PI), PI);
    assert_eq!(accepted_heading(-PI), PI);
    assert_eq!(accepted_heading(3.0 * PI), PI);
    assert!((accepted_heading(100.0) - (100.0 - 32.0 * PI)).abs() < 1e-12);
    assert!((accepted_heading(-0.5 - 4.0 * PI) + 0.5).abs() < 1e-12);
    assert_eq!(accepted_heading(0.0), 0.0);
    for k in -2000..2000 {
        let h = accepted_heading(k as f64 * 0.37);
        assert!(h > -PI && h <= PI, "{k}: {h}");
    }
    assert!(shm_ipc::normalize_angle(-1e-18).abs() < 1e-15);
}

#[test]
fn absurd_finite_values_are_rejected_with_readable_numbers() {
    let reason = reject(&goal(1.0, 1.0, 1e300, &[]));
    assert_eq!(reason.code(), RejectCode::OutOfWorkspace);
    assert!(matches!(reason, RejectReason::HeadingOutOfRange { .. }));
    let text = reason.to_string();
    assert!(text.contains("1.000e300"), "{text}");
    assert!(text.len() < 100, "{text}");
    let reason = reject(&goal(-1e300, 1.0, 0.0, &[]));
    assert!(reason.to_string().contains("-1.000e300"), "{reason}");
    // Obstacles far beyond any site.
    let reason = reject(&goal(1.0, 1.0, 0.0, &[Obstacle::new(1e300, 0.0, 1.0)]));
    assert_eq!(reason.code(), RejectCode::BadObstacle);
    assert!(reason.to_string().contains("1.000e300"), "{reason}");
    let reason = reject(&goal(1.0, 1.0, 0.0, &[Obstacle::new(0.0, 10.0, 1e7)]));
    assert!(matches!(
        reason,
        RejectReason::ObstacleOutOfRange { field: "r", .. }
    ));
}

#[test]
fn huge_numbers_print_short_and_reasons_are_never_cut_inside_a_number() {
    let reason = reject(&goal(1e308, 1e308, 0.0, &[]));
    let text = reason.to_string();
    assert!(text.contains("(1.000e308, 1.000e308)"), "{text}");
    assert!(
        text.len() <= REASON_TEXT_CAPACITY,
        "{} bytes: {text}",
        text.len()
    );
    let reply = reason.to_reply(1);
    assert_eq!(reply.reason_text(), text, "fits whole");
    // A message that does not fit is cut between words: every number kept is whole.
    let numbers: Vec<String> = (0..40)
        .map(|i| format!("{}", 1234.5678 + i as f64))
        .collect();
    let message = numbers.join(" ");
    let reply = GoalReply::reject(1, RejectCode::Other, &message);
    let kept = reply.reason_text();
    assert!(kept.len() <= REASON_TEXT_CAPACITY);
    assert!(kept.ends_with('…'), "{kept}");
    for word in kept.trim_end_matches('…').split_whitespace() {
        assert!(
            numbers.iter().any(|n| n == word),
            "cut number {word:?} in {kept:?}"
        );
    }
    for n in [0.0, 1.5, -2.25, 999_999.0, 1e6, 1e-4, f64::NAN] {
        let s = shm_ipc::Num::new(n).to_string();
        assert!(s.len() <= 12, "{n}: {s}");
    }
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
    // 1-5 are the kinds (set goal, cancel, stop, resume, reload site).
    for kind in [0, 6, u32::MAX] {
        let mut req = goal(0.0, 0.0, 0.0, &[]);
        req.kind = kind;
        let reason = reject(&req);
        assert_eq!(reason, RejectReason::UnknownKind(kind));
        assert_eq!(reason.code(), RejectCode::UnknownKind);
    }
}

#[test]
fn cancel_stop_resume_and_reload_are_accepted_even_with_garbage_goal_fields() {
    for mut req in [
        GoalRequest::cancel(5),
        GoalRequest::stop(6),
        GoalRequest::resume(7),
        GoalRequest::reload_site(8),
    ] {
        req.goal = Pose2::new(f64::NAN, f64::INFINITY, 1e300);
        req.obstacle_count = 1000;
        let (result, reply) = validator().validate_and_reply(&req);
        assert!(reply.is_accepted());
        match result.expect("valid") {
            ValidRequest::Cancel { request_id } => assert_eq!(request_id, 5),
            ValidRequest::Stop { request_id } => assert_eq!(request_id, 6),
            ValidRequest::Resume { request_id } => assert_eq!(request_id, 7),
            ValidRequest::ReloadSite { request_id } => assert_eq!(request_id, 8),
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
    // One long "word": cut at a character boundary, marked with an ellipsis.
    let long = "é".repeat(200); // 400 bytes, 2 per char
    let reply = GoalReply::reject(1, RejectCode::Other, &long);
    assert!(reply.reason_len as usize <= REASON_TEXT_CAPACITY);
    assert_eq!(
        reply.reason_text(),
        format!("{}…", "é".repeat((REASON_TEXT_CAPACITY - 3) / 2))
    );

    let three = "€".repeat(100); // 3 bytes per char: 128 is not a boundary
    let reply = GoalReply::reject(1, RejectCode::Other, &three);
    assert!(reply.reason_len as usize <= REASON_TEXT_CAPACITY);
    assert!(reply.reason_text().ends_with('…'));
    assert!(reply
        .reason_text()
        .trim_end_matches('…')
        .chars()
        .all(|c| c == '€'));

    // A short message is kept whole.
    let reply = GoalReply::reject(1, RejectCode::Other, "fits");
    assert_eq!(reply.reason_text(), "fits");

    // Garbage from a foreign peer: a length beyond the buffer, invalid UTF-8, unknown code.
    let mut bad = GoalReply::reject(1, RejectCode::Other, "ok");
    bad.reason_len = u32::MAX;
    bad.reason[2] = 0xff;
    bad.reason_code = 999;
    assert_eq!(bad.reason_text(), "ok");
    assert_eq!(bad.reject_code(), Err(999));
}
