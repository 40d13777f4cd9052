//! The goal lifecycle (DESIGN §10 "Goal outcomes" and "Goal validation", §11 operator
//! stop): which requests are accepted, which goal the loop drives, and how every accepted
//! goal ends — in exactly one outcome, reported once.
//!
//! [`GoalLifecycle`] is a small state machine without I/O or clocks of its own. Two sides
//! feed it:
//!
//! * **requests** ([`GoalLifecycle::on_request`], the IPC task, at once): accept or reject
//!   a validated request. A set-goal is rejected while the daemon shuts down, while an
//!   operator stop is latched, while a fault blocks driving, or when [`check_goal`] finds
//!   the footprint at the goal, or the machine's current footprint, inside an obstacle.
//!   An accepted goal preempts the one being driven; cancel and stop end it as
//!   `cancelled`; stop latches until resume.
//! * **ticks** ([`GoalLifecycle::on_tick`], the control thread, once per tick): given the
//!   measured state and whether the goal can be driven at all, end the goal as
//!   `aborted` (a fault, shutdown) or `succeeded` (reached, DESIGN §7 test at rest), and
//!   tell the loop what to do ([`TickPlan`]). What the pilot decided while tracking
//!   (`no-progress`, `no-route`, a broken envelope assumption) and a solver failure end
//!   it through [`GoalLifecycle::abort_active`]: the pilot owns the progress window, the
//!   lifecycle reports it.
//!
//! Ended goals queue as [`Outcome`]s; the loop publishes one per tick
//! ([`GoalLifecycle::next_outcome`]) in the order they ended. Only a goal being driven can
//! end: a reached goal has its outcome already, and the machine holds it until a new goal,
//! a cancel, a stop or a fault drops it without a second report.

use std::collections::VecDeque;

use control::goal_check::{check_goal, GoalConflict};
use control::model::{goal_distance, ix};
use control::obstacle::Obstacle;
use control::site::{Outline, SiteIndex};
use control::world::World;
use control::{Goal, MachineParams, State};
use shm_ipc::{fault_flags, AbortReason, GoalOutcome, RejectCode, ValidRequest, MAX_OBSTACLES};
use std::sync::Arc;

/// Outcomes waiting for their tick; beyond this the oldest are dropped (a flood of goals
/// ending faster than 5 per second). Documented in the `shm-ipc` crate docs.
pub const MAX_PENDING_OUTCOMES: usize = 32;

/// What the lifecycle needs to decide.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LifecycleSettings {
    /// The machine (footprint of the goal check).
    pub machine: MachineParams,
    /// Reached when ‖(x_f − x_g, y_f − y_g, e_θ)‖ is below this …
    pub reach_tolerance: f64,
    /// … and |v_f| below this [m/s].
    pub reach_speed: f64,
}

/// A goal the daemon accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcceptedGoal {
    /// The client's request id.
    pub request_id: u64,
    /// The goal pose.
    pub goal: Goal,
    obstacles: [Obstacle; MAX_OBSTACLES],
    n_obstacles: usize,
    /// 1, 2, … per accepted goal: the loop plans anew when it changes (a new goal may
    /// repeat the previous pose and request id).
    pub generation: u64,
}

impl AcceptedGoal {
    /// The goal's obstacles.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles[..self.n_obstacles]
    }
}

/// How a goal ended, ready for telemetry.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The ended goal's request id.
    pub request_id: u64,
    /// Succeeded, cancelled, preempted or aborted.
    pub outcome: GoalOutcome,
    /// Why, when aborted ([`AbortReason::None`] otherwise).
    pub abort_reason: AbortReason,
    /// Human-readable reason.
    pub text: String,
    /// 1, 2, … per ended goal.
    pub seq: u32,
}

/// Why a request is refused.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// The wire code.
    pub code: RejectCode,
    /// The reason text sent back.
    pub text: String,
}

/// Why the goal cannot be driven this tick (ends it as aborted).
#[derive(Debug, Clone, PartialEq)]
pub struct Abort {
    /// The wire reason.
    pub reason: AbortReason,
    /// Human-readable detail (which fault).
    pub text: String,
}

impl Abort {
    /// An abort for `reason` with `text`.
    pub fn new(reason: AbortReason, text: impl Into<String>) -> Self {
        Self {
            reason,
            text: text.into(),
        }
    }
}

/// One tick's inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct TickInput<'a> {
    /// Daemon time [s].
    pub now: f64,
    /// The measured state, when pose and machine state are fresh.
    pub state: Option<&'a State>,
    /// Set when the goal cannot be driven (fault, shutdown, machine not in auto).
    pub abort: Option<Abort>,
    /// Faults that make new goals wait ([`fault_flags`] bits; 0 = goals welcome).
    pub blocking_faults: u32,
}

/// What the loop does this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TickPlan {
    /// No goal: come to rest (or stay there).
    NoGoal,
    /// The goal was reached: hold still at it.
    Hold(AcceptedGoal),
    /// Drive towards the goal.
    Track(AcceptedGoal),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Driving,
    Reached,
}

/// The goal lifecycle (see the module docs).
#[derive(Debug, Clone)]
pub struct GoalLifecycle {
    settings: LifecycleSettings,
    goal: Option<(AcceptedGoal, Phase)>,
    generation: u64,
    operator_stop: bool,
    blocking_faults: u32,
    /// Latest measured state, for the request-time footprint check.
    machine: Option<State>,
    /// The site and the outline the goal check uses (the pilot's, DESIGN §17);
    /// its circles are each request's.
    world: World,
    pending: VecDeque<Outcome>,
    next_seq: u32,
    dropped: u64,
}

impl GoalLifecycle {
    /// No goal; goals wait for the first fresh pose and machine state.
    pub fn new(settings: LifecycleSettings) -> Self {
        Self {
            settings,
            goal: None,
            generation: 0,
            operator_stop: false,
            blocking_faults: fault_flags::POSE_STALE | fault_flags::MACHINE_STATE_STALE,
            machine: None,
            world: World::with_axle_circles(settings.machine, MAX_OBSTACLES),
            pending: VecDeque::with_capacity(MAX_PENDING_OUTCOMES + 1),
            next_seq: 1,
            dropped: 0,
        }
    }

    /// The site goals are checked against (DESIGN §17), from the next request.
    pub fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.world.set_site(site);
    }

    /// The machine's outline the goal check uses.
    pub fn set_outline(&mut self, outline: Outline) {
        self.world.set_outline(outline);
    }

    /// True while an operator stop is latched (goals rejected until resume).
    pub fn operator_stop(&self) -> bool {
        self.operator_stop
    }

    /// Outcomes dropped because more than [`MAX_PENDING_OUTCOMES`] waited.
    pub fn dropped_outcomes(&self) -> u64 {
        self.dropped
    }

    /// Accepts or rejects a validated request (see the module docs). `shutting_down`
    /// rejects new goals.
    pub fn on_request(&mut self, req: &ValidRequest, shutting_down: bool) -> Result<(), Rejection> {
        let not_ready = |text: String| Rejection {
            code: RejectCode::NotReady,
            text,
        };
        match req {
            ValidRequest::SetGoal {
                request_id,
                goal,
                obstacles,
            } => {
                if shutting_down {
                    return Err(not_ready("daemon is shutting down".into()));
                }
                if self.operator_stop {
                    return Err(not_ready(
                        "stopped by an operator: send resume (`wlnav resume`) first".into(),
                    ));
                }
                if self.blocking_faults != 0 {
                    return Err(not_ready(format!(
                        "fault active: {}",
                        shm_ipc::fault_flags::names(self.blocking_faults).join(", ")
                    )));
                }
                let goal = Goal::new(goal.x, goal.y, goal.heading);
                let mut list = [Obstacle::default(); MAX_OBSTACLES];
                for (dst, o) in list.iter_mut().zip(obstacles.iter()) {
                    *dst = Obstacle::new(o.x, o.y, o.r);
                }
                let n_obstacles = obstacles.len().min(MAX_OBSTACLES);
                // Validated on the wire (finite, at most MAX_OBSTACLES).
                self.world
                    .set_circles(&list[..n_obstacles])
                    .map_err(|e| Rejection {
                        code: RejectCode::BadObstacle,
                        text: e.to_string(),
                    })?;
                check_goal(&self.world, self.machine.as_ref(), &goal).map_err(|conflict| {
                    Rejection {
                        code: match conflict {
                            GoalConflict::GoalInCollision { .. } => RejectCode::GoalInCollision,
                            GoalConflict::MachineInCollision { .. } => {
                                RejectCode::MachineInCollision
                            }
                        },
                        text: conflict.to_string(),
                    }
                })?;
                self.end_driven(
                    GoalOutcome::Preempted,
                    AbortReason::None,
                    format!("preempted by request {request_id}"),
                );
                self.generation += 1;
                let accepted = AcceptedGoal {
                    request_id: *request_id,
                    goal,
                    obstacles: list,
                    n_obstacles,
                    generation: self.generation,
                };
                self.goal = Some((accepted, Phase::Driving));
            }
            ValidRequest::Cancel { request_id } => {
                self.end_driven(
                    GoalOutcome::Cancelled,
                    AbortReason::None,
                    format!("cancelled by request {request_id}"),
                );
                self.goal = None;
            }
            ValidRequest::Stop { request_id } => {
                self.end_driven(
                    GoalOutcome::Cancelled,
                    AbortReason::None,
                    format!("stopped by an operator (request {request_id})"),
                );
                self.goal = None;
                self.operator_stop = true;
            }
            ValidRequest::Resume { .. } => self.operator_stop = false,
            // Served by the IPC task (crate::site); nothing of the goal changes.
            ValidRequest::ReloadSite { .. } => {}
        }
        Ok(())
    }

    /// One tick (see the module docs): ends the goal when it must end, and says what to
    /// drive.
    pub fn on_tick(&mut self, input: TickInput<'_>) -> TickPlan {
        self.blocking_faults = input.blocking_faults;
        self.machine = input.state.copied();
        let Some((goal, phase)) = self.goal else {
            return TickPlan::NoGoal;
        };
        if let Some(abort) = input.abort {
            self.end_driven(GoalOutcome::Aborted, abort.reason, abort.text);
            self.goal = None;
            return TickPlan::NoGoal;
        }
        if phase == Phase::Reached {
            return TickPlan::Hold(goal);
        }
        let Some(x) = input.state else {
            return TickPlan::Track(goal);
        };
        let distance = goal_distance(x, &goal.goal);
        let s = &self.settings;
        if distance < s.reach_tolerance && x[ix::V].abs() < s.reach_speed {
            let text = format!(
                "reached: error {distance:.3} < {} at {:.3} m/s",
                s.reach_tolerance,
                x[ix::V].abs()
            );
            self.end_driven(GoalOutcome::Succeeded, AbortReason::None, text);
            self.goal = Some((goal, Phase::Reached));
            return TickPlan::Hold(goal);
        }
        TickPlan::Track(goal)
    }

    /// Ends the goal being driven as aborted (a failure found while tracking, e.g. the
    /// solver) and drops it. Does nothing without one.
    pub fn abort_active(&mut self, abort: Abort) {
        if let Some((_, Phase::Driving)) = self.goal {
            self.end_driven(GoalOutcome::Aborted, abort.reason, abort.text);
            self.goal = None;
        }
    }

    /// The oldest outcome not yet published (one per tick).
    pub fn next_outcome(&mut self) -> Option<Outcome> {
        self.pending.pop_front()
    }

    /// Queues the outcome of the goal being driven, if there is one (a reached goal has
    /// been reported already).
    fn end_driven(&mut self, outcome: GoalOutcome, abort_reason: AbortReason, text: String) {
        let Some((goal, Phase::Driving)) = self.goal else {
            return;
        };
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1).max(1);
        self.pending.push_back(Outcome {
            request_id: goal.request_id,
            outcome,
            abort_reason,
            text,
            seq,
        });
        if self.pending.len() > MAX_PENDING_OUTCOMES {
            self.pending.pop_front();
            self.dropped += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_ipc::heapless_obstacles::Obstacles;
    use shm_ipc::{Obstacle as WireObstacle, Pose2};

    fn settings() -> LifecycleSettings {
        LifecycleSettings {
            machine: MachineParams::default(),
            reach_tolerance: 0.1,
            reach_speed: control::model::REACH_SPEED,
        }
    }

    /// A lifecycle past start-up (data seen, no fault) with the machine at `x`.
    fn ready(x: &State) -> GoalLifecycle {
        let mut l = GoalLifecycle::new(settings());
        assert_eq!(l.on_tick(tick(0.0, Some(x))), TickPlan::NoGoal);
        l
    }

    fn tick(now: f64, state: Option<&State>) -> TickInput<'_> {
        TickInput {
            now,
            state,
            abort: None,
            blocking_faults: 0,
        }
    }

    fn set_goal(id: u64, x: f64, y: f64, obstacles: &[WireObstacle]) -> ValidRequest {
        ValidRequest::SetGoal {
            request_id: id,
            goal: Pose2::new(x, y, 0.0),
            obstacles: Obstacles::from_slice(obstacles).unwrap(),
        }
    }

    fn at(x: f64) -> State {
        State::new(x, 0.0, 0.0, 0.0, 0.0, 0.0)
    }

    fn moving(x: f64, v: f64) -> State {
        State::new(x, 0.0, 0.0, 0.0, 0.0, v)
    }

    /// All queued outcomes as (request id, outcome, abort reason, seq).
    fn drain(l: &mut GoalLifecycle) -> Vec<(u64, GoalOutcome, AbortReason, u32)> {
        std::iter::from_fn(|| l.next_outcome())
            .map(|o| (o.request_id, o.outcome, o.abort_reason, o.seq))
            .collect()
    }

    #[test]
    fn reached_goal_succeeds_once_and_then_holds() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        assert!(
            matches!(l.on_tick(tick(0.2, Some(&moving(2.0, 1.0)))), TickPlan::Track(g) if g.request_id == 1)
        );
        assert!(drain(&mut l).is_empty());
        // Inside the tolerance but still moving: not yet.
        assert!(matches!(
            l.on_tick(tick(0.4, Some(&moving(4.95, 0.3)))),
            TickPlan::Track(_)
        ));
        assert!(
            matches!(l.on_tick(tick(0.6, Some(&moving(4.97, 0.01)))), TickPlan::Hold(g) if g.request_id == 1)
        );
        assert_eq!(
            drain(&mut l),
            [(1, GoalOutcome::Succeeded, AbortReason::None, 1)]
        );
        // Holding: no second report, whatever happens to the reached goal.
        for k in 0..100 {
            let t = 0.8 + 0.2 * k as f64;
            assert!(matches!(
                l.on_tick(tick(t, Some(&at(4.97)))),
                TickPlan::Hold(_)
            ));
        }
        l.on_request(&ValidRequest::Cancel { request_id: 2 }, false)
            .unwrap();
        assert_eq!(l.on_tick(tick(30.0, Some(&at(4.97)))), TickPlan::NoGoal);
        assert!(drain(&mut l).is_empty());
    }

    #[test]
    fn cancel_ends_the_goal_cancelled() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(7, 5.0, 0.0, &[]), false).unwrap();
        l.on_tick(tick(0.2, Some(&moving(1.0, 1.0))));
        l.on_request(&ValidRequest::Cancel { request_id: 8 }, false)
            .unwrap();
        assert_eq!(
            l.on_tick(tick(0.4, Some(&moving(1.2, 1.0)))),
            TickPlan::NoGoal
        );
        let o = l.next_outcome().unwrap();
        assert_eq!((o.request_id, o.outcome), (7, GoalOutcome::Cancelled));
        assert!(o.text.contains("request 8"), "{}", o.text);
        // A second cancel has nothing to end.
        l.on_request(&ValidRequest::Cancel { request_id: 9 }, false)
            .unwrap();
        assert!(l.next_outcome().is_none());
    }

    #[test]
    fn a_newer_goal_preempts_the_driven_one_and_a_goal_never_driven_too() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        l.on_tick(tick(0.2, Some(&moving(1.0, 1.0))));
        // Two goals before the next tick: 1 is preempted by 2, 2 by 3 (never driven).
        l.on_request(&set_goal(2, 6.0, 0.0, &[]), false).unwrap();
        l.on_request(&set_goal(3, 7.0, 0.0, &[]), false).unwrap();
        assert!(
            matches!(l.on_tick(tick(0.4, Some(&moving(1.2, 1.0)))), TickPlan::Track(g) if g.request_id == 3 && g.generation == 3)
        );
        assert_eq!(
            drain(&mut l),
            [
                (1, GoalOutcome::Preempted, AbortReason::None, 1),
                (2, GoalOutcome::Preempted, AbortReason::None, 2)
            ]
        );
    }

    #[test]
    fn a_fault_aborts_the_driven_goal_and_drops_a_reached_one_silently() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        l.on_tick(tick(0.2, Some(&moving(1.0, 1.0))));
        let mut t = tick(0.4, None);
        t.abort = Some(Abort::new(AbortReason::Fault, "fault: pose stale"));
        t.blocking_faults = fault_flags::POSE_STALE;
        assert_eq!(l.on_tick(t), TickPlan::NoGoal);
        let o = l.next_outcome().unwrap();
        assert_eq!(
            (o.request_id, o.outcome, o.abort_reason, o.text.as_str()),
            (
                1,
                GoalOutcome::Aborted,
                AbortReason::Fault,
                "fault: pose stale"
            )
        );
        // While the fault blocks, goals are not accepted.
        let r = l
            .on_request(&set_goal(2, 5.0, 0.0, &[]), false)
            .unwrap_err();
        assert_eq!(r.code, RejectCode::NotReady);
        assert!(r.text.contains("pose-stale"), "{}", r.text);
        // A reached goal is dropped by a fault without a second outcome.
        l.on_tick(tick(0.6, Some(&at(4.98))));
        l.on_request(&set_goal(3, 5.0, 0.0, &[]), false).unwrap();
        assert!(matches!(
            l.on_tick(tick(0.8, Some(&at(4.98)))),
            TickPlan::Hold(_)
        ));
        assert_eq!(
            drain(&mut l),
            [(3, GoalOutcome::Succeeded, AbortReason::None, 2)]
        );
        let here = at(4.98);
        let mut t = tick(1.0, Some(&here));
        t.abort = Some(Abort::new(AbortReason::Shutdown, "daemon shutting down"));
        assert_eq!(l.on_tick(t), TickPlan::NoGoal);
        assert!(l.next_outcome().is_none());
    }

    #[test]
    fn a_solver_failure_while_tracking_aborts_once() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(5, 5.0, 0.0, &[]), false).unwrap();
        l.on_tick(tick(0.2, Some(&moving(1.0, 1.0))));
        l.abort_active(Abort::new(AbortReason::Fault, "solver failed"));
        l.abort_active(Abort::new(AbortReason::Fault, "solver failed"));
        assert_eq!(
            drain(&mut l),
            [(5, GoalOutcome::Aborted, AbortReason::Fault, 1)]
        );
        assert_eq!(
            l.on_tick(tick(0.4, Some(&moving(1.1, 0.8)))),
            TickPlan::NoGoal
        );
    }

    #[test]
    fn goal_footprint_in_an_obstacle_is_rejected_and_the_driven_goal_kept() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        // The rear axle at the goal (3.8, 0) is inside; the front axle (5, 0) is not.
        let r = l
            .on_request(
                &set_goal(2, 5.0, 0.0, &[WireObstacle::new(3.8, 0.0, 0.4)]),
                false,
            )
            .unwrap_err();
        assert_eq!(r.code, RejectCode::GoalInCollision);
        assert!(
            r.text.contains("obstacle 0") && r.text.contains("rear"),
            "{}",
            r.text
        );
        // An obstacle on the machine itself (at the origin).
        let r = l
            .on_request(
                &set_goal(
                    3,
                    5.0,
                    3.0,
                    &[
                        WireObstacle::new(9.0, 9.0, 1.0),
                        WireObstacle::new(0.1, 0.0, 0.5),
                    ],
                ),
                false,
            )
            .unwrap_err();
        assert_eq!(r.code, RejectCode::MachineInCollision);
        assert!(r.text.contains("obstacle 1"), "{}", r.text);
        assert!(
            matches!(l.on_tick(tick(0.2, Some(&at(0.0)))), TickPlan::Track(g) if g.request_id == 1)
        );
        assert!(l.next_outcome().is_none(), "rejected goals have no outcome");
    }

    #[test]
    fn operator_stop_latches_until_resume() {
        let mut l = ready(&at(0.0));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        l.on_tick(tick(0.2, Some(&moving(1.0, 1.0))));
        l.on_request(&ValidRequest::Stop { request_id: 2 }, false)
            .unwrap();
        assert!(l.operator_stop());
        assert_eq!(
            drain(&mut l),
            [(1, GoalOutcome::Cancelled, AbortReason::None, 1)]
        );
        for k in 0..20 {
            l.on_tick(tick(0.4 + 0.2 * k as f64, Some(&at(1.0))));
            let r = l
                .on_request(&set_goal(10 + k, 5.0, 0.0, &[]), false)
                .unwrap_err();
            assert_eq!(r.code, RejectCode::NotReady);
            assert!(r.text.contains("stopped by an operator"), "{}", r.text);
        }
        // Cancel does not release the latch; resume does.
        l.on_request(&ValidRequest::Cancel { request_id: 3 }, false)
            .unwrap();
        assert!(l.operator_stop());
        l.on_request(&ValidRequest::Resume { request_id: 4 }, false)
            .unwrap();
        assert!(!l.operator_stop());
        l.on_request(&set_goal(5, 5.0, 0.0, &[]), false).unwrap();
        assert!(
            matches!(l.on_tick(tick(5.0, Some(&at(1.0)))), TickPlan::Track(g) if g.request_id == 5)
        );
    }

    #[test]
    fn goals_wait_for_data_and_shutdown_rejects_and_aborts() {
        let mut l = GoalLifecycle::new(settings());
        let r = l
            .on_request(&set_goal(1, 5.0, 0.0, &[]), false)
            .unwrap_err();
        assert_eq!(r.code, RejectCode::NotReady);
        l.on_tick(tick(0.0, Some(&at(0.0))));
        l.on_request(&set_goal(1, 5.0, 0.0, &[]), false).unwrap();
        let r = l.on_request(&set_goal(2, 5.0, 0.0, &[]), true).unwrap_err();
        assert!(r.text.contains("shutting down"));
        let here = at(0.0);
        let mut t = tick(0.2, Some(&here));
        t.abort = Some(Abort::new(AbortReason::Shutdown, "daemon shutting down"));
        assert_eq!(l.on_tick(t), TickPlan::NoGoal);
        assert_eq!(
            drain(&mut l),
            [(1, GoalOutcome::Aborted, AbortReason::Shutdown, 1)]
        );
    }

    #[test]
    fn a_flood_keeps_the_newest_outcomes_in_order_with_numbered_gaps() {
        let mut l = ready(&at(0.0));
        let n = MAX_PENDING_OUTCOMES as u64 + 11;
        for id in 1..=n + 1 {
            l.on_request(&set_goal(id, 5.0, 0.0, &[]), false).unwrap();
        }
        assert_eq!(l.dropped_outcomes(), 11);
        let out = drain(&mut l);
        assert_eq!(out.len(), MAX_PENDING_OUTCOMES);
        // Goals 12..=n were preempted and kept, in order, with their sequence numbers.
        for (k, (id, outcome, _, seq)) in out.iter().enumerate() {
            assert_eq!(*id, 12 + k as u64);
            assert_eq!(*seq as u64, *id);
            assert_eq!(*outcome, GoalOutcome::Preempted);
        }
    }
}
