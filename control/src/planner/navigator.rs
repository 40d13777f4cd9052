//! The global layer's tick side: it holds the route, passes its subgoals,
//! sets the path cost the MPC follows, watches progress and asks for a
//! replan or a retry when it stalls. Routes come from a [`RouteService`]
//! (the planner thread); this side never searches.

use crate::critic::{Critic, CriticWorkspace};
use crate::model::{
    goal_distance, ix, wrap_angle, Control, Goal, MachineParams, State, REACH_SPEED,
};
use crate::mpc::{PathCost, PathWeights, TrackCost, TrackWeights};
use crate::obstacle::{AxlePoint, Obstacle};
use crate::progress::ProgressChecker;
use crate::Actor;

use super::path_geometry;
use super::route_planner::{retry_approach, PlanJob, PlanKind, Route, RoutePlanner};
use super::service::{InlineRoutes, PlanDelay, RouteService};
use super::world::CheckedWorld;
use super::{AbortReason, NavError, NavStep, NavigatorSettings, PathPose, PlanOutcome, PlanReport};

/// The critic's cost of a metre when there is no critic or its fit fails
/// (measured on the published critic: 3.0).
const FALLBACK_COST_PER_METRE: f64 = 3.0;

/// Arc length the projection onto the path looks ahead each tick [m]: twice
/// the 3 m the machine covers in about a horizon at top speed.
const PROJECTION_WINDOW: f64 = 6.0;

/// Below this speed, within `approach_distance` of the goal and without
/// approach for `replan_after`, the machine is stuck near the goal [m/s]: not
/// only at rest, as the critic may also crawl back and forth beside it
/// (`wall038` of obstacles200: measured, 0.05 m/s missed it, 0.2 and 0.3 reach
/// it and change no other run; a machine turning towards the goal at speed is
/// not stuck).
const STUCK_SPEED: f64 = 0.2;

/// How much farther than the nearest reference point a later one may be and
/// still be taken as the machine's [m]: where the trajectory stands still (a
/// cusp, its end) its points coincide, and the latest of them moves on.
const TRACK_TIE: f64 = 0.05;

/// How long the trajectory's last state (the goal, at rest) is tracked after
/// the machine's time on it reached its end, before the critic takes over
/// [s]: the machine settles on it rather than being handed over while it
/// moves.
const TRACK_SETTLE: f64 = 1.0;

/// The critic's cost of a metre of way to the goal: its mean slope in the
/// goal distance between 3 and 10 m (the range it was trained on), over goals
/// on every side of the machine at rest and every relative heading. The
/// critic is close to proportional to the time to go (`docs/global-layer.md`),
/// so this is its price of a metre at cruising speed.
pub fn critic_cost_per_metre(critic: &Critic, ws: &mut CriticWorkspace) -> Option<f64> {
    let (near, far) = (3.0, 10.0);
    let (mut sum, mut count) = (0.0, 0.0);
    for bearing in [0.0f64, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0] {
        for heading in [0.0f64, 90.0, 180.0, 270.0] {
            let (b, h) = (bearing.to_radians(), heading.to_radians());
            let mut value = |d: f64| {
                let g = Goal::new(d * b.cos(), d * b.sin(), h);
                critic.value(ws, &State::zeros(), &Control::zeros(), &g)
            };
            sum += (value(far) - value(near)) / (far - near);
            count += 1.0;
        }
    }
    let slope = sum / count;
    (slope.is_finite() && slope > 0.0).then_some(slope)
}

/// The global layer: built once, then `set_goal` per goal and `update` per tick.
pub struct Navigator {
    params: MachineParams,
    settings: NavigatorSettings,
    /// The goal's circles: the tick's own geometric tests (line of sight,
    /// open ground).
    world: CheckedWorld,
    routes: Box<dyn RouteService>,
    /// The job buffers when no plan is out (`None`: one is being planned).
    spare: Option<Box<PlanJob>>,
    /// A plan to ask for as soon as the planner is free.
    wanted: Option<PlanKind>,
    /// Counts goals: answers for an older one are dropped.
    goal_seq: u64,
    route: Route,
    route_index: usize,
    /// The machine's projection onto the route's path.
    path_index: usize,
    goal: Option<Goal>,
    checker: ProgressChecker,
    /// The target of the checker's window on the last tick: an approach only
    /// counts on a window that was already running (a replan's new target
    /// restarts the window, which is no progress).
    window_target: Option<Goal>,
    /// How many of the world's circles are the goal's (the rest were
    /// added by [`Navigator::avoid`]).
    goal_circles: usize,
    /// Set by `set_goal`: the first `update` starts the clocks.
    clocks_pending: bool,
    last_progress: f64,
    last_replan: f64,
    replans: usize,
    retries: usize,
    aborted: Option<AbortReason>,
    last_plan: Option<PlanReport>,
    plans: u64,
    /// Answers dropped for their age ([`NavigatorSettings::max_route_age`]).
    stale_routes: u64,
    /// The age of the route followed when it arrived [s].
    route_age: f64,
    /// Counts the changes of the MPC's path cost.
    cost_version: u64,
    /// The critic's cost of a metre (calibrated at construction).
    cost_per_metre: f64,
    /// The current forward part of the path, and what it was made for (plan
    /// count, index of its last pose).
    path_cost: PathCost,
    path_key: Option<(u64, usize)>,
    /// Within the handover distance of its end: the critic drives.
    path_handed: bool,
    /// The path cost's segment the machine was last projected onto.
    path_hint: usize,
    /// The route's trajectory while it is tracked (issue 42), its time the
    /// first stage's reference time; and the plan count it was set for.
    track: TrackCost,
    track_plan: u64,
    /// The last tick's time [s].
    track_now: f64,
    /// When the track's time reached the trajectory's end [s].
    track_ended: Option<f64>,
    /// The machine's distance from the trajectory's reference at the
    /// track's time [m] (0 while nothing is tracked).
    track_deviation: f64,
    /// When the tracked trajectory was set [s].
    track_started: f64,
}

impl Navigator {
    /// A navigator whose routes are planned at once on the calling thread
    /// (tests, tools; the daemon plans on a [`super::PlannerThread`] and
    /// `wlnav-sim` charges the plan time: [`Self::with_routes`]).
    pub fn new(
        params: MachineParams,
        settings: NavigatorSettings,
        networks: Option<(Actor, Critic)>,
    ) -> Result<Self, NavError> {
        let (actor, critic) = match networks {
            Some((a, c)) => (Some(a), Some(c)),
            None => (None, None),
        };
        let planner = RoutePlanner::new(params, &settings, actor)?;
        let routes = Box::new(InlineRoutes::new(planner, PlanDelay::Fixed(0.0)));
        Self::with_routes(params, settings, critic.as_ref(), routes)
    }

    /// A navigator whose routes come from `routes`; `critic` prices the path
    /// cost (its cost of a metre).
    pub fn with_routes(
        params: MachineParams,
        settings: NavigatorSettings,
        critic: Option<&Critic>,
        routes: Box<dyn RouteService>,
    ) -> Result<Self, NavError> {
        params.validate().map_err(|_| NavError::BadSettings {
            name: "params",
            requirement: "machine parameters must be valid",
            value: f64::NAN,
        })?;
        settings.validate()?;
        let cost_per_metre = critic
            .and_then(|c| critic_cost_per_metre(c, &mut CriticWorkspace::new(c)))
            .unwrap_or(FALLBACK_COST_PER_METRE);
        let s = &settings.search;
        Ok(Self {
            params,
            world: CheckedWorld::new(params, s.max_obstacles, s.clearance_margin),
            routes,
            spare: Some(Box::new(PlanJob::new(&params, s))),
            wanted: None,
            goal_seq: 0,
            route: Route::with_capacity(s),
            route_index: 0,
            path_index: 0,
            goal: None,
            checker: ProgressChecker::new(settings.stall.progress),
            window_target: None,
            goal_circles: 0,
            clocks_pending: false,
            last_progress: 0.0,
            last_replan: 0.0,
            replans: 0,
            retries: 0,
            aborted: None,
            last_plan: None,
            plans: 0,
            stale_routes: 0,
            route_age: 0.0,
            cost_version: 0,
            cost_per_metre,
            path_cost: PathCost::new(),
            path_key: None,
            path_handed: false,
            path_hint: 0,
            track: TrackCost::new(),
            track_plan: 0,
            track_now: 0.0,
            track_ended: None,
            track_deviation: 0.0,
            track_started: 0.0,
            settings,
        })
    }

    pub fn settings(&self) -> &NavigatorSettings {
        &self.settings
    }

    /// New goal. Errors: `Collision` (the goal pose's footprint, β = 0,
    /// inside a circle, or a circle containing the machine's current
    /// footprint: [`crate::goal_check::check_goal`]), and malformed input
    /// (`BadGoal`, `TooManyObstacles`, `BadObstacle`). In open ground the
    /// route is the goal at once; among circles the planner is asked from
    /// `start`, measured at `now`, and `update` holds until the route is there.
    pub fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), NavError> {
        if !(goal.x.is_finite() && goal.y.is_finite() && goal.theta.is_finite()) {
            return Err(NavError::BadGoal {
                x: goal.x,
                y: goal.y,
                theta: goal.theta,
            });
        }
        self.clear();
        self.world.set(obstacles)?;
        self.goal_circles = obstacles.len();
        if let Err(conflict) = crate::goal_check::check_goal(self.world.world(), Some(start), &goal)
        {
            self.world.clear();
            return Err(conflict.into());
        }
        self.goal = Some(goal);
        self.clocks_pending = true;
        if self.world.is_empty() {
            // Nothing to plan: the critic drives to the goal.
            self.go_direct(goal);
        } else {
            self.ask(PlanKind::First, start, now);
        }
        Ok(())
    }

    /// The machine is held at `now` by something outside the plan (a
    /// protective stop for a live obstacle, DESIGN §18): neither a stall
    /// nor missing progress; the windows start again when the hold ends.
    /// (The pilot bounds the hold itself.)
    pub fn hold_clocks(&mut self, now: f64) {
        if self.clocks_pending {
            return;
        }
        self.last_progress = self.last_progress.max(now);
        self.last_replan = self.last_replan.max(now);
        self.checker.hold(now);
    }

    /// Something that stays in the way (a live obstacle that has kept the
    /// machine waiting, DESIGN §18), as a circle of wire radius (the
    /// half-width included): every plan of this goal from now on keeps off
    /// it, and one is asked for at once from `x`. Errors: no goal, or no
    /// room left among the circles; the route stays as it was.
    pub fn avoid(&mut self, circle: Obstacle, x: &State, now: f64) -> Result<(), NavError> {
        if self.goal.is_none() || self.aborted.is_some() {
            return Err(NavError::NoGoal);
        }
        self.world.push(circle)?;
        self.last_replan = now;
        self.ask(PlanKind::Replan, x, now);
        Ok(())
    }

    /// Forgets every circle [`Self::avoid`] added (what stayed has gone)
    /// and asks for a plan from `x` without them. Nothing to forget: no
    /// change.
    pub fn forget_avoided(&mut self, x: &State, now: f64) {
        if self.world.obstacles().len() == self.goal_circles
            || self.goal.is_none()
            || self.aborted.is_some()
        {
            return;
        }
        self.world.truncate(self.goal_circles);
        self.last_replan = now;
        match self.goal {
            // Open ground again: the critic drives to the goal.
            Some(goal) if self.world.is_empty() => self.go_direct(goal),
            _ => self.ask(PlanKind::Replan, x, now),
        }
    }

    /// The route is the goal alone (open ground: the critic drives there).
    fn go_direct(&mut self, goal: Goal) {
        self.route.clear();
        self.route.targets.push(goal);
        self.route.target_path_index.push(0);
        self.route.report.outcome = PlanOutcome::Direct;
        self.route_index = 0;
        self.path_index = 0;
        self.last_plan = Some(self.route.report);
        self.plans += 1;
    }

    /// Every tick: what the MPC should drive to now. Allocation-free, and
    /// no search: plans are asked for and taken when they arrive.
    pub fn update(&mut self, x: &State, now: f64) -> NavStep {
        if let Some(r) = self.aborted {
            return NavStep::Abort(r);
        }
        let Some(goal) = self.goal else {
            return NavStep::Abort(AbortReason::NoRoute);
        };
        if self.clocks_pending {
            self.clocks_pending = false;
            self.last_progress = now;
            self.last_replan = now;
        }
        self.exchange(x, now);
        if let Some(r) = self.aborted {
            return NavStep::Abort(r);
        }
        if self.route.targets.is_empty() {
            // The first route is being planned: hold, within the abort window.
            if now - self.last_progress >= self.settings.stall.progress.timeout {
                return self.abort(AbortReason::NoProgress);
            }
            return NavStep::Hold;
        }
        self.advance(x, now);
        let target = self.route.targets[self.route_index];
        self.checker.update(x, &target, now);
        let stalled_for = self.checker.stalled_for(now);
        let st = self.settings.stall;
        let final_target = self.route_index + 1 == self.route.targets.len();
        let holding = final_target && goal_distance(x, &goal) < st.reached_tolerance;
        let approached = stalled_for == 0.0 && self.window_target == Some(target);
        self.window_target = Some(target);
        if approached || holding {
            self.last_progress = now;
        }
        if now - self.last_progress >= st.progress.timeout {
            return self.abort(AbortReason::NoProgress);
        }
        let stalled = !holding
            && self.wanted.is_none()
            && self.spare.is_some()
            && stalled_for >= st.replan_after
            && now - self.last_replan >= st.replan_after;
        if stalled
            && final_target
            && self.retries < st.max_retries
            && self.stuck_near(x, &goal)
            && (self.world.is_empty()
                || self.in_search_goal_region(x, &goal)
                || (st.retry_in_sight && self.goal_in_sight(x, &goal))
                || self.replan_gave_only_the_goal())
        {
            self.retries += 1;
            self.last_replan = now;
            // A new manoeuvre that may first lead away (to straighten the
            // machine out): its own window, bounded by `max_retries`.
            self.last_progress = now;
            if self.world.is_empty() {
                // Open ground: the approach behind the goal, nothing to check.
                self.retry_in_open_ground(&goal);
            } else {
                self.ask(PlanKind::Retry, x, now);
            }
        } else if (stalled || self.off_track(now))
            && !self.world.is_empty()
            && self.replans < st.max_replans
        {
            self.replans += 1;
            self.last_replan = now;
            self.ask(PlanKind::Replan, x, now);
            self.advance(x, now);
        }
        self.refresh_track(x, now);
        let (target, final_target) = if self.track.is_empty() {
            self.drive_target()
        } else {
            (goal, true)
        };
        self.refresh_path(x);
        NavStep::Drive {
            target,
            final_target,
        }
    }

    fn abort(&mut self, reason: AbortReason) -> NavStep {
        self.aborted = Some(reason);
        NavStep::Abort(reason)
    }

    /// Takes an answer if one arrived, then sends what is wanted.
    fn exchange(&mut self, x: &State, now: f64) {
        if let Some(wanted) = self.wanted {
            if self.spare.is_some() {
                self.wanted = None;
                self.ask(wanted, x, now);
            }
        }
        if let Some(job) = self.routes.poll(now) {
            self.receive(job, x, now);
        }
    }

    /// Sends a plan request from `x` (or remembers it until the planner is free).
    fn ask(&mut self, kind: PlanKind, x: &State, now: f64) {
        let (Some(goal), Some(mut job)) = (self.goal, self.spare.take()) else {
            self.wanted = Some(kind);
            return;
        };
        let r = &mut job.request;
        r.goal_seq = self.goal_seq;
        r.kind = kind;
        r.stamp = now;
        r.start = *x;
        r.goal = goal;
        r.world.copy_from(self.world.world());
        self.routes.submit(job);
        // An inline planner answers in the same tick when its delay is 0.
        if let Some(job) = self.routes.poll(now) {
            self.receive(job, x, now);
        }
    }

    /// An answer: followed if it is for this goal, fresh and a route.
    fn receive(&mut self, mut job: Box<PlanJob>, x: &State, now: f64) {
        let current = job.request.goal_seq == self.goal_seq && self.goal.is_some();
        let age = now - job.request.stamp;
        let kind = job.request.kind;
        if current && age > self.settings.max_route_age {
            // The machine has moved on: ask again from where it is.
            self.stale_routes += 1;
            self.spare = Some(job);
            self.ask(kind, x, now);
            return;
        }
        if current {
            let report = job.route.report;
            self.last_plan = Some(report);
            self.plans += 1;
            match report.outcome {
                PlanOutcome::NoRoute if kind == PlanKind::First => {
                    self.aborted = Some(AbortReason::NoRoute);
                }
                // A failed replan or retry keeps the route: the abort window decides.
                PlanOutcome::NoRoute => {}
                _ => {
                    std::mem::swap(&mut self.route, &mut job.route);
                    self.route_index = 0;
                    self.path_index = 0;
                    self.route_age = age;
                }
            }
        }
        self.spare = Some(job);
    }

    /// The retry in open ground: [approach pose behind the goal, goal].
    fn retry_in_open_ground(&mut self, goal: &Goal) {
        let d = self.settings.stall.approach_distance;
        if let Some(a) = retry_approach(d, goal, |_| true) {
            self.route.clear();
            self.route.targets.extend([a, *goal]);
            self.route.target_path_index.extend([0, 0]);
            self.route.report.outcome = PlanOutcome::Retry;
            self.route.report.replan = true;
            self.route_index = 0;
            self.path_index = 0;
            self.last_plan = Some(self.route.report);
            self.plans += 1;
        }
    }

    /// The current subgoal sequence ending with the goal ([goal] when direct;
    /// empty without a goal or before the first route).
    pub fn route(&self) -> &[Goal] {
        &self.route.targets
    }

    /// The subgoals not yet passed, ending with the goal.
    pub fn remaining_route(&self) -> &[Goal] {
        let t = &self.route.targets;
        &t[self.route_index.min(t.len())..]
    }

    /// The last planned path (empty when direct).
    pub fn path(&self) -> &[PathPose] {
        &self.route.path
    }

    pub fn goal(&self) -> Option<Goal> {
        self.goal
    }

    /// The last plan's report.
    pub fn last_plan(&self) -> Option<PlanReport> {
        self.last_plan
    }

    /// Plans taken since construction (a new report each time it grows).
    pub fn plans(&self) -> u64 {
        self.plans
    }

    /// How old the route followed was when it arrived [s] (0 in open ground).
    pub fn route_age(&self) -> f64 {
        self.route_age
    }

    /// Answers dropped for their age since construction.
    pub fn stale_routes(&self) -> u64 {
        self.stale_routes
    }

    /// Whether the planner is working on a plan right now (an answer that
    /// waits to be taken does not count).
    pub fn planner_working(&self) -> bool {
        self.routes.working()
    }

    /// Wall time its route service planned on the calling (tick) thread
    /// since the last call: zero with the planner thread; with the
    /// simulator's inline planner, what a tick's timing leaves out.
    pub fn take_plan_time_on_tick(&mut self) -> std::time::Duration {
        self.routes.take_time_on_caller()
    }

    /// The site the next plans keep off (DESIGN §17).
    /// A goal being driven is planned again in the new world (its route
    /// stays followed until the answer arrives).
    pub fn set_site(&mut self, site: Option<std::sync::Arc<crate::site::SiteIndex>>) {
        self.world.set_site(site);
        if self.goal.is_some() && self.aborted.is_none() {
            self.wanted = Some(PlanKind::Replan);
        }
    }

    /// The machine's outline every plan's checks use, each circle's extra
    /// margin `extra[i]` ([`crate::world::World::set_extra_margins`]).
    pub fn set_outline(&mut self, outline: crate::site::Outline, extra: &[f64]) {
        self.world.set_outline(outline, extra);
    }

    /// Forgets the goal and the route (an answer still out is dropped when it
    /// comes back).
    pub fn clear(&mut self) {
        self.goal = None;
        self.goal_seq += 1;
        self.wanted = None;
        self.route.clear();
        self.route_index = 0;
        self.path_index = 0;
        self.world.clear();
        self.checker = ProgressChecker::new(self.settings.stall.progress);
        self.window_target = None;
        self.clocks_pending = false;
        self.replans = 0;
        self.retries = 0;
        self.aborted = None;
        self.route_age = 0.0;
        self.path_cost.clear();
        self.path_key = None;
        self.path_handed = false;
        self.track.clear();
        self.cost_version += 1;
    }

    /// Off its trajectory by more than the settings allow, with nothing asked
    /// and no replan for `replan_after` (issue 42: re-optimised on a large
    /// deviation).
    fn off_track(&self, now: f64) -> bool {
        let st = &self.settings.stall;
        !self.track.is_empty()
            && self.track_deviation > st.max_track_deviation
            && self.wanted.is_none()
            && self.spare.is_some()
            && now - self.last_replan >= st.replan_after
    }

    /// The trajectory of a new route is tracked from its start; each tick
    /// the time on it moves to the reference point nearest to the machine's
    /// front axle among those from the last time up to twice the tick ahead
    /// (progress-indexed: it waits while the machine lags, never runs away
    /// from it, and never goes back, so a cusp's two legs are not mixed up).
    /// It ends [`TRACK_SETTLE`] after the time reached the trajectory's end
    /// (the critic then holds the goal).
    fn refresh_track(&mut self, x: &State, now: f64) {
        self.track_deviation = 0.0;
        let tick = (now - self.track_now).max(0.0);
        self.track_now = now;
        if self.track_plan != self.plans {
            self.track_plan = self.plans;
            let had = !self.track.is_empty();
            self.track.clear();
            if !self.route.trajectory.is_empty() {
                let weights = TrackWeights::default();
                self.track.set(
                    &self.route.trajectory,
                    self.route.trajectory_dt,
                    weights,
                    &self.params,
                );
            }
            if had || !self.track.is_empty() {
                self.cost_version += 1;
            }
            // Where the machine is now: it moved while the plan was made.
            let ahead = self.route_age.max(0.0);
            self.advance_track(x, ahead);
            self.track_ended = None;
            self.track_started = now - self.track.time();
            return;
        }
        if self.track.is_empty() {
            return;
        }
        self.advance_track(x, 2.0 * tick);
        let end = self.track.duration();
        let at_end = self.track.time() >= end - 1e-9;
        if !at_end
            && now - self.track_started - self.track.time() > self.settings.stall.max_track_lag
        {
            // The machine does not keep up with the trajectory (weaker or
            // later than the model, or held): the rest of the way is the
            // route's path, followed (the trajectory's, as the route has it).
            self.track.clear();
            self.cost_version += 1;
            return;
        }
        let r = self.track.reference(self.track.time());
        self.track_deviation = (x[ix::X] - r[ix::X]).hypot(x[ix::Y] - r[ix::Y]);
        if at_end {
            let since = *self.track_ended.get_or_insert(now);
            if now - since >= TRACK_SETTLE {
                self.track.clear();
                self.cost_version += 1;
            }
        }
    }

    /// Moves the track's time to the latest reference point within
    /// [`TRACK_TIE`] of the nearest to the front axle, among those from now
    /// to `window` ahead.
    fn advance_track(&mut self, x: &State, window: f64) {
        if self.track.is_empty() {
            return;
        }
        let (t0, step) = (self.track.time(), self.track.step());
        let steps = (window / step).ceil() as usize;
        let distance = |t: f64| {
            let r = self.track.reference(t);
            (x[ix::X] - r[ix::X]).hypot(x[ix::Y] - r[ix::Y])
        };
        let times = (0..=steps).map(|j| (t0 + j as f64 * step).min(self.track.duration()));
        let nearest = times.clone().map(distance).fold(f64::INFINITY, f64::min);
        let t = times
            .rev()
            .find(|&t| distance(t) <= nearest + TRACK_TIE)
            .unwrap_or(t0);
        self.track.set_time(t);
    }

    /// Passes every subgoal within `subgoal_radius` (never the goal) and every
    /// subgoal the projection onto the path has passed.
    fn advance(&mut self, x: &State, now: f64) {
        let f = self.settings.following;
        let following = !self.route.path.is_empty();
        if following {
            self.path_index = path_geometry::project(
                &self.route.path,
                self.path_index,
                x[ix::X],
                x[ix::Y],
                PROJECTION_WINDOW,
                f.subgoal_radius,
            );
        }
        while self.route_index + 1 < self.route.targets.len() {
            let t = &self.route.targets[self.route_index];
            let near = (x[ix::X] - t.x).hypot(x[ix::Y] - t.y) < f.subgoal_radius;
            let behind = following
                && self
                    .route
                    .target_path_index
                    .get(self.route_index)
                    .is_some_and(|&i| i < self.path_index);
            if !(near || behind) {
                break;
            }
            self.route_index += 1;
            self.last_progress = now;
        }
    }

    /// What the MPC drives to: on a forward part of the path, the end of that
    /// part (a cusp, or the goal); otherwise the current route entry.
    fn drive_target(&self) -> (Goal, bool) {
        let last = self.route.targets.len() - 1;
        if let Some(end) = self.followed_end().filter(|_| self.route_index < last) {
            // The path cost drives there; the critic, with this target, does
            // the last part.
            if end + 1 < self.route.path.len() {
                let p = &self.route.path[end];
                return (Goal::new(p.x, p.y, p.theta), false);
            }
            return (self.route.targets[last], true);
        }
        (
            self.route.targets[self.route_index],
            self.route_index == last,
        )
    }

    /// The path cost while following a forward part of the route's path: that
    /// part (from the machine's projection to the next cusp or the path's
    /// end, continued by the goal shot a path may end with), set once per plan
    /// and part; empty once the machine is within `handover` of its end (the
    /// critic's part), and without a path.
    fn refresh_path(&mut self, x: &State) {
        if !self.track.is_empty() {
            // The trajectory is tracked: no path.
            if self.path_key.take().is_some() {
                self.path_cost.clear();
                self.cost_version += 1;
            }
            return;
        }
        let goal = self.goal;
        let key = self
            .followed_end()
            .zip(goal)
            .map(|(end, _)| (self.plans, end));
        if key != self.path_key {
            self.path_key = key;
            self.path_handed = false;
            self.path_hint = 0;
            self.cost_version += 1;
            match (key, goal) {
                (Some((_, end)), Some(g)) => self.set_path_cost(end, &g),
                _ => self.path_cost.clear(),
            }
        }
        if self.path_handed || self.path_cost.is_empty() {
            return;
        }
        let (left, segment) = self.path_cost.arc_left(x, self.path_hint);
        self.path_hint = segment;
        // An open end is where the search's goal shot started: the critic
        // takes over there, where the shot showed the way is open.
        let handover = if self.path_cost.open_end() {
            0.0
        } else {
            self.settings.following.handover
        };
        if left <= handover {
            self.path_handed = true;
            self.path_cost.clear();
            self.cost_version += 1;
        }
    }

    /// The path cost for the part ending at pose `end`, followed by the
    /// leading axle (the rear one reversing). A forward path that
    /// ends where a goal shot starts is continued by the shot (the actor's
    /// way to the goal, driven again by the planner); a shot that reverses or
    /// did not reach leaves the path's end open (the critic takes over there).
    fn set_path_cost(&mut self, end: usize, goal: &Goal) {
        let path = &self.route.path;
        let point = if path[end].direction >= 0 {
            AxlePoint::Front
        } else {
            AxlePoint::Rear
        };
        let shot = self.shot_ends_path(goal, end);
        let f = &self.settings.following;
        let start = path_geometry::direction_start(path, self.path_index)
            .max(self.path_index.saturating_sub(1));
        let c = self.cost_per_metre;
        let weights = PathWeights {
            per_metre: c,
            lateral: f.lateral * c,
            heading: f.heading * c,
            control: f.control * c,
        };
        let params = self.params;
        let poses = path[start..=end].iter().map(|p| {
            let x = State::new(p.x, p.y, p.theta, p.beta, 0.0, 0.0);
            PathCost::point_pose(point, &params, &x)
        });
        // A shot that reverses on the way is a manoeuvre for the critic.
        let traced = &self.route.shot;
        let drivable = point == AxlePoint::Front
            && shot
            && !traced.is_empty()
            && !traced.iter().any(|x| x[ix::V] < -REACH_SPEED);
        let tail: &[State] = if drivable { traced } else { &[] };
        let tail = tail.iter().map(|x| [x[ix::X], x[ix::Y], x[ix::THETA]]);
        let open_end = shot && !drivable;
        self.path_cost
            .set(poses.chain(tail), weights, &params, open_end, point);
    }

    /// On a followed part of the route's path: the index of its last pose.
    /// Forward parts are followed by the front axle. Reversing parts are
    /// followed by the rear axle on the actor's roll-out only (an open way,
    /// or a retry's way to its approach pose); on a searched route they go by
    /// its subgoals, the critic's targets. Measured (docs/decisions.md):
    /// following the search's reversing parts too reached fewer goals (its
    /// primitives change β in steps at the nodes, where the rear axle's path
    /// jumps by up to L_r·Δβ), and the front axle trailing the rear locks
    /// the articulation and stalls.
    fn followed_end(&self) -> Option<usize> {
        let path = &self.route.path;
        if path.is_empty() {
            return None;
        }
        let end = path_geometry::direction_end(path, self.path_index);
        (path[end].direction >= 0 || self.route.rolled_out).then_some(end)
    }

    /// Whether pose `end` of the path is its last and a goal shot starts
    /// there (it is outside the search's goal region).
    fn shot_ends_path(&self, goal: &Goal, end: usize) -> bool {
        let p = &self.route.path[end];
        end + 1 == self.route.path.len()
            && (p.x - goal.x).hypot(p.y - goal.y) > self.settings.search.goal_position_tolerance
    }

    /// The path whose progress is the MPC's cost now (`None`: the critic).
    /// It changes only when [`Self::cost_version`] does.
    pub fn path_cost(&self) -> Option<&PathCost> {
        (!self.path_cost.is_empty()).then_some(&self.path_cost)
    }

    /// The trajectory the MPC tracks now (`None`: the path cost or the
    /// critic). It changes only when [`Self::cost_version`] does; its time
    /// every tick.
    pub fn track_cost(&self) -> Option<&TrackCost> {
        (!self.track.is_empty()).then_some(&self.track)
    }

    /// Counts the changes of [`Self::path_cost`] and [`Self::track_cost`].
    pub fn cost_version(&self) -> u64 {
        self.cost_version
    }

    /// Slower than [`STUCK_SPEED`] within `approach_distance` of the goal:
    /// stopped (or crawling) short of it, not manoeuvring towards it (a turn
    /// that first raises the pose error moves faster).
    fn stuck_near(&self, x: &State, goal: &Goal) -> bool {
        x[ix::V].abs() < STUCK_SPEED
            && (x[ix::X] - goal.x).hypot(x[ix::Y] - goal.y) <= self.settings.stall.approach_distance
    }

    /// Whether the straight line from the front axle to the goal keeps the
    /// route's margin: a replan from there shoots straight at the goal and
    /// hands back the route that stalled.
    fn goal_in_sight(&self, x: &State, goal: &Goal) -> bool {
        self.world
            .segment_clear([x[ix::X], x[ix::Y]], [goal.x, goal.y], self.world.margin())
    }

    /// Whether the route is a replan's that came back as the goal alone: from
    /// where the machine stalled the search sees nothing to route around, so
    /// another replan would hand back the same (the retry's approach does not).
    fn replan_gave_only_the_goal(&self) -> bool {
        self.route.report.replan
            && self.route.report.outcome == PlanOutcome::Route
            && self.route.targets.len() == 1
    }

    /// Whether `x` is inside the goal region of the search, where a replan
    /// has nothing left to plan.
    fn in_search_goal_region(&self, x: &State, goal: &Goal) -> bool {
        let s = &self.settings.search;
        (x[ix::X] - goal.x).hypot(x[ix::Y] - goal.y) <= s.goal_position_tolerance
            && wrap_angle(x[ix::THETA] - goal.theta).abs() <= s.goal_heading_tolerance
    }
}
