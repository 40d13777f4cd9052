//! The pilot: the one composition of the global layer ([`Navigator`]), the
//! MPC and the safety envelope (DESIGN §10, §14) that the daemon and
//! `wlnav-sim` both drive, so the evaluation runs the wiring that ships.
//!
//! Per tick ([`Pilot::step`]): the navigator picks the target (or holds
//! while the first route is planned, or ends the goal), the MPC drives to it
//! (following the navigator's path cost where there is one), and the
//! envelope checks whatever is proposed — the MPC's command, or the stop of a
//! hold — against every circle before it is returned. The caller sends the
//! command (or what it sends instead) back through [`Pilot::sent`], which
//! both the MPC's delay compensation and the envelope's record use.
//!
//! Before anything else each tick, the envelope's assumptions are checked
//! against what the machine did ([`crate::assumption_check`], issue 43): the
//! envelope guards with the tolerances in force (the stated ones, widened to
//! what was measured), and a break beyond what may be widened ends the goal
//! ([`PilotDecision::Stop`]). The machine never goes on silently with a model
//! it has just seen to be wrong.

use std::time::{Duration, Instant};

use crate::assumption_check::{self, Assessment, AssumptionMonitor, Decision, Finding};
use crate::delay::DelayCompensator;
use crate::envelope::{self, EnvelopeInput, EnvelopeSettings, Guarded, LiveContact, LiveView};
use crate::live::{self, Freshness, FreshnessState, LiveSet, LiveSettings};
use crate::model::{ix, Goal, MachineParams, State, VelocityCommand};
use crate::mpc::{Mpc, MpcError, Solution, StageCost};
use crate::obstacle::Obstacle;
use crate::planner::{AbortReason, NavError, NavStep, Navigator, PlanReport};
use crate::progress::{ProgressChecker, ProgressSettings};
use crate::site::outline::{Body, Outline, MAX_OUTLINE_CIRCLES};
use crate::site::SiteIndex;
use crate::site::P2;
use crate::world::World;
use std::sync::Arc;

/// Errors of [`Pilot`]'s calls: each names the part that refused.
#[derive(Debug, thiserror::Error)]
pub enum PilotError {
    #[error("MPC: {0}")]
    Mpc(#[from] MpcError),
    #[error("global layer: {0}")]
    Navigator(#[from] NavError),
    #[error("envelope: {0}")]
    Envelope(String),
}

/// What the pilot proposes this tick, already checked by the envelope.
#[derive(Debug, Clone, Copy)]
pub struct PilotStep<'a> {
    /// The command to send: the envelope's choice.
    pub command: VelocityCommand,
    /// What the MPC (or the hold) proposed.
    pub proposed: VelocityCommand,
    /// The envelope's verdict on the proposal.
    pub guarded: Guarded,
    /// The MPC's solution (`None` while holding for the first route).
    pub solution: Option<&'a Solution>,
    /// The subgoal driven to, when it is not the goal itself.
    pub subgoal: Option<Goal>,
    /// The route not yet passed, ending with the goal (empty without a global
    /// layer, or while holding).
    pub route: &'a [Goal],
    /// How old the route followed was when it arrived [s].
    pub route_age: f64,
    /// The last plan: what it did (its outcome, whether its route was
    /// shaped into a trajectory) and its wall time (`None` without one).
    pub last_plan: Option<PlanReport>,
    /// A plan was taken this step (it is `last_plan`).
    pub new_plan: bool,
    /// The check of the envelope's assumptions this tick (`Continue`, or
    /// `Widen` with the finding the envelope was widened to).
    pub assumptions: Assessment,
    /// What the live obstacles did to this tick (`None` without perception).
    pub live: Option<LiveStatus>,
}

/// The live obstacles' effect on a tick ([`Pilot::enable_live`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveStatus {
    /// The perception's freshness.
    pub freshness: FreshnessState,
    /// Perception is required and not fresh: the command is a stop.
    pub stale_stop: bool,
    /// The slow-down field's factor on the speed (1: none).
    pub slow: f64,
    /// Held after a protective stop until the way has been clear for
    /// [`LiveSettings::resume_wait`].
    pub holding: bool,
    /// The live obstacle the command sent comes nearest to.
    pub contact: Option<LiveContact>,
}

/// Perception's part of the pilot: the newest set, its freshness, the hold
/// after a protective stop.
#[derive(Debug, Clone)]
struct Live {
    settings: LiveSettings,
    set: LiveSet,
    freshness: Freshness,
    /// Held since a protective stop: (since, clear since).
    hold: Option<(f64, Option<f64>)>,
    /// Held, slowed by the slow-down field, or stopped short by the MPC's
    /// live rows, since: waiting for a live obstacle (the progress windows
    /// pause, up to `max_hold`).
    waiting_since: Option<f64>,
    /// The standing obstacle the machine waits for, and since when (its
    /// id; [`LiveSettings::replan_after`]).
    blocked: Option<(u32, f64)>,
    /// Obstacles planned round for this goal: their ids and where they
    /// stood (each once, while it stays; [`Live::plan_round`]).
    avoided: [(u32, P2); MAX_AVOIDED],
    n_avoided: usize,
    /// What to tell the navigator at the next step.
    route_change: Option<RouteChange>,
    /// A set's arrival slowed the machine since the last tick.
    slowed_between_ticks: bool,
}

impl Live {
    /// Replanning round what stays (issue 41 item 4), given the standing
    /// obstacle (index in the set) the machine waits for this tick: one
    /// that has kept it waiting for `replan_after` is planned round, as a
    /// circle of its stop field while the set is fresh (C_stop + σ_u ·
    /// max_age; the MPC's rows grow it further along their horizon) plus
    /// `extra`; not larger, as a start inside the circle would leave no
    /// route. Once one of them has gone (out of the set, or moved on), all
    /// are forgotten (a route round nothing is a detour) and what still
    /// stands is planned round again when it keeps the machine waiting.
    fn plan_round(&mut self, standing: Option<usize>, now: f64, extra: f64) {
        let obstacles = self.set.obstacles();
        self.blocked = match (standing, self.blocked) {
            (Some(i), Some((id, since))) if obstacles[i].id == id => Some((id, since)),
            (Some(i), _) => Some((obstacles[i].id, now)),
            (None, _) => None,
        };
        let gone = self.avoided[..self.n_avoided].iter().any(|&(id, at)| {
            !obstacles.iter().any(|o| {
                let p = o.moved(o.shape.bounding_circle().0, now);
                o.id == id && (p[0] - at[0]).hypot(p[1] - at[1]) < live::JUMP_TOLERANCE
            })
        });
        if gone {
            self.n_avoided = 0;
            self.route_change = Some(RouteChange::Forget);
        }
        let (Some(i), Some((id, since))) = (standing, self.blocked) else {
            return;
        };
        let done = self.avoided[..self.n_avoided].iter().any(|a| a.0 == id);
        if done || now - since < self.settings.replan_after || self.n_avoided == MAX_AVOIDED {
            return;
        }
        let o = &obstacles[i];
        let (c, r) = o.shape.bounding_circle();
        let at = o.moved(c, now);
        self.avoided[self.n_avoided] = (id, at);
        self.n_avoided += 1;
        let radius = r + self.settings.reach(self.settings.max_age) + extra;
        self.route_change = Some(RouteChange::Avoid(Obstacle::new(at[0], at[1], radius)));
    }
}

/// A change of the route's world for a live obstacle (issue 41 item 4).
#[derive(Debug, Clone, Copy)]
enum RouteChange {
    /// Plan round this circle (wire radius).
    Avoid(Obstacle),
    /// What was planned round has gone: plan without it.
    Forget,
}

/// At most this many live obstacles are planned around per goal.
pub const MAX_AVOIDED: usize = 8;

/// A plan whose clearance to a live obstacle's stop field is below this
/// [m] is pressed against it: a machine nearly at rest with such a plan is
/// waiting for that obstacle.
const PRESSED: f64 = 0.1;

/// One tick's decision.
#[derive(Debug, Clone, Copy)]
pub enum PilotDecision<'a> {
    Drive(PilotStep<'a>),
    /// The global layer ended the goal (no route, no progress): bring the
    /// machine to rest.
    Abort(AbortReason),
    /// The machine broke an assumption of the envelope beyond what it may be
    /// widened to (or the check's action is `stop`): a fault, bring the
    /// machine to rest. `broken`: every assumption broken so far (bit
    /// `Assumption as usize`).
    Stop {
        finding: Finding,
        broken: u8,
    },
}

/// Between ticks a set's slow-down is sent only when it takes at least this
/// off the speed [m/s] (smaller ones wait for the tick).
pub const ARRIVAL_SLOWDOWN: f64 = 0.05;

/// Navigator + MPC + envelope, built once.
pub struct Pilot<C: StageCost> {
    params: MachineParams,
    mpc: Mpc<C>,
    navigator: Option<Navigator>,
    /// The envelope's stated tolerances, checked against the machine each
    /// tick; its effective settings are the envelope's.
    assumptions: AssumptionMonitor,
    /// The commands sent, as the envelope replays them (after the longer of
    /// the configured and the estimated delay).
    sent: DelayCompensator,
    configured_delay: f64,
    dt: f64,
    last: VelocityCommand,
    /// The site, the goal's circles and the outline: the envelope's world,
    /// kept equal to the MPC's and the navigator's (DESIGN §17).
    world: World,
    /// The navigator's path cost version the MPC has.
    costs_seen: Option<u64>,
    /// The navigator's plan count at the last step.
    plans_seen: u64,
    /// The goal's progress window without a navigator (with one, the
    /// navigator's window towards its current target decides, among its
    /// replans and retries): the pilot is the one owner of `no-progress`.
    progress: ProgressChecker,
    /// Live obstacles from perception (`None`: not configured).
    live: Option<Live>,
    /// When the last step ran (the MPC's plan starts a delay after it).
    last_step_at: f64,
}

impl<C: StageCost> Pilot<C> {
    /// The MPC under `navigator` (none: it drives straight to the goal, and a
    /// goal not approached within `progress` ends `NoProgress`), checked by
    /// the envelope with `envelope`'s tolerances.
    pub fn new(
        params: MachineParams,
        mpc: Mpc<C>,
        navigator: Option<Navigator>,
        envelope: EnvelopeSettings,
        progress: ProgressSettings,
    ) -> Result<Self, PilotError> {
        envelope
            .validate()
            .map_err(|e| PilotError::Envelope(e.to_string()))?;
        let s = *mpc.settings();
        let sent = envelope::command_record(params, &envelope, s.delay, s.dt)
            .map_err(|e| PilotError::Envelope(e.to_string()))?;
        Ok(Self {
            params,
            navigator,
            assumptions: AssumptionMonitor::new(params, envelope, s.delay),
            sent,
            configured_delay: s.delay,
            dt: s.dt,
            last: VelocityCommand::ZERO,
            world: World::with_axle_circles(params, s.max_obstacles),
            costs_seen: None,
            plans_seen: 0,
            progress: ProgressChecker::new(progress),
            live: None,
            last_step_at: 0.0,
            mpc,
        })
    }

    /// Checks live obstacles from now on ([`crate::live`]): the envelope
    /// keeps their stop fields, the speed is scaled down in their slow-down
    /// field, a protective stop holds until the way has been clear for
    /// `resume_wait`, and (when `required`) a stale set stops the machine.
    pub fn enable_live(&mut self, settings: LiveSettings) -> Result<(), PilotError> {
        settings
            .validate()
            .map_err(|e| PilotError::Envelope(e.to_string()))?;
        self.mpc.enable_live(settings);
        self.live = Some(Live {
            settings,
            set: LiveSet::new(),
            freshness: Freshness::default(),
            hold: None,
            waiting_since: None,
            blocked: None,
            avoided: [(0, [0.0; 2]); MAX_AVOIDED],
            n_avoided: 0,
            route_change: None,
            slowed_between_ticks: false,
        });
        Ok(())
    }

    /// The newest set perception published (validated by the caller; its
    /// stamps on the pilot's clock). Ignored unless [`Self::enable_live`].
    /// No allocation.
    pub fn set_live(&mut self, set: &LiveSet) {
        if let Some(l) = &mut self.live {
            if let Some(stamp) = set.stamp() {
                let consistent = !live::jumped(&l.set, set, &l.settings);
                l.freshness.arrived(stamp, consistent, &l.settings);
            }
            l.set.copy_from(set);
            self.mpc.set_live(set);
        }
    }

    /// The check when a set arrives between ticks (DESIGN §18): the command
    /// last sent, as if sent at `now` from the state `x` measured then,
    /// against the newest set, and the slow-down field along the last plan.
    /// `Some`: send its command at once (and record it through
    /// [`Self::sent`]): a protective stop (the hold starts), or the last
    /// command slowed down by the field (when that is at least
    /// [`ARRIVAL_SLOWDOWN`] slower; once between two ticks).
    pub fn check_live(&mut self, x: &State, now: f64) -> Option<Guarded> {
        let l = self.live.as_ref()?;
        if l.set.is_empty() || self.last == VelocityCommand::ZERO || l.hold.is_some() {
            return None;
        }
        let slowed_already = l.slowed_between_ticks;
        let guarded = envelope::guard(&self.envelope_input(x, now), self.last);
        let protective = guarded.overridden() && guarded.live.is_some_and(|c| c.excess < 0.0);
        if protective {
            if let Some(l) = &mut self.live {
                l.hold = Some((now, None));
            }
            return Some(guarded);
        }
        // The slow-down field along the plan of the last tick (its states
        // from then on).
        let slow = slow_factor(
            &self.world,
            l,
            self.assumptions.effective(),
            self.mpc.solution(),
            self.last_step_at + self.sent.delay(),
            self.dt,
        );
        let slowed = VelocityCommand {
            v: self.last.v * slow,
            ..self.last
        };
        // One slow-down between ticks (the next tick slows on): with the
        // protective stop, at most three commands a period
        // ([`crate::delay::MAX_COMMANDS_PER_PERIOD`]).
        if slowed_already || (self.last.v - slowed.v).abs() < ARRIVAL_SLOWDOWN {
            return None;
        }
        if let Some(l) = &mut self.live {
            l.slowed_between_ticks = true;
        }
        Some(envelope::guard(&self.envelope_input(x, now), slowed))
    }

    /// What the envelope checks against at `now` from the state `x`.
    fn envelope_input<'a>(&'a self, x: &'a State, now: f64) -> EnvelopeInput<'a> {
        EnvelopeInput {
            params: &self.params,
            settings: self.assumptions.effective(),
            sent: &self.sent,
            now,
            state: x,
            world: &self.world,
            dt: self.dt,
            last: self.last,
            live: self.live.as_ref().map(|l| LiveView {
                set: &l.set,
                settings: &l.settings,
            }),
        }
    }

    /// A new goal seen from the state `start` measured at `now` (the global
    /// layer validates it against the circles; its route is planned off the
    /// tick, from `start`).
    pub fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), PilotError> {
        self.reset();
        if obstacles.len() > self.world.capacity() {
            return Err(PilotError::Mpc(MpcError::TooManyObstacles {
                given: obstacles.len(),
                max: self.world.capacity(),
            }));
        }
        match &mut self.navigator {
            Some(nav) => nav.set_goal(start, goal, obstacles, now)?,
            None => {
                self.mpc.set_goal(goal, obstacles)?;
                self.progress.reset(goal, now);
            }
        }
        self.world
            .set_circles(obstacles)
            .map_err(|e| PilotError::Envelope(e.to_string()))?;
        Ok(())
    }

    /// The site every layer keeps off (`None`: the goal's circles only):
    /// the envelope and the MPC from the next step on, the navigator from
    /// its next plan. Call it between ticks (a swap at a tick boundary). No
    /// allocation.
    pub fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.world.set_site(site.clone());
        self.mpc.set_site(site.clone());
        if let Some(nav) = &mut self.navigator {
            nav.set_site(site);
        }
    }

    /// The machine's outline for every layer; the MPC's rows and the route's
    /// checks get each circle's envelope margin beyond its body's, so that
    /// they plan outside what the envelope guards.
    pub fn set_outline(&mut self, outline: Outline) {
        let settings = self.assumptions.stated();
        let per_circle = settings.circle_margins(&self.params, &outline);
        let [front, rear] = settings.margins(&self.params);
        let mut extra = [0.0; MAX_OUTLINE_CIRCLES];
        for (i, c) in outline.circles().iter().enumerate() {
            extra[i] = per_circle[i]
                - match c.body {
                    Body::Front => front,
                    Body::Rear => rear,
                };
        }
        let extra = &extra[..outline.len()];
        self.mpc.set_outline(outline.clone(), extra);
        if let Some(nav) = &mut self.navigator {
            nav.set_outline(outline.clone(), extra);
        }
        self.world.set_outline(outline);
        self.world.set_extra_margins(extra);
    }

    /// Forgets goal and plan (not the commands sent: they still act).
    pub fn reset(&mut self) {
        if let Some(l) = &mut self.live {
            l.blocked = None;
            l.n_avoided = 0;
            l.route_change = None;
        }
        self.mpc.clear_goal();
        self.world.clear_circles();
        self.costs_seen = None;
        // The next residual must not span the ticks between goals.
        self.assumptions.gap();
        if let Some(nav) = &mut self.navigator {
            nav.clear();
        }
    }

    /// One tick from the state `x` measured at `now` [s]; `tick_start` is
    /// when the tick began (the MPC's time budget counts from there).
    pub fn step(
        &mut self,
        x: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<PilotDecision<'_>, PilotError> {
        self.last_step_at = now;
        // What the machine did against the envelope's model, before any
        // decision that relies on it (the estimates are last tick's).
        let assumptions = self.assumptions.observe(&assumption_check::TickInput {
            now,
            measured: x,
            delay_estimate: self.mpc.compensated_delay(),
            gain_estimate: self.mpc.actuator_gains(),
        });
        if let (Decision::Stop, Some(finding)) = (assumptions.decision, assumptions.finding) {
            return Ok(PilotDecision::Stop {
                finding,
                broken: assumptions.broken,
            });
        }
        // Waiting for a live obstacle (held, or slowed by its field) pauses
        // the progress windows, up to `max_hold`.
        if let Some(since) = self.live.as_ref().and_then(|l| l.waiting_since) {
            let max_hold = self
                .live
                .as_ref()
                .map_or(f64::INFINITY, |l| l.settings.max_hold);
            if now - since > max_hold {
                return Ok(PilotDecision::Abort(AbortReason::NoProgress));
            }
            match &mut self.navigator {
                Some(nav) => nav.hold_clocks(now),
                None => self.progress.hold(now),
            }
        }
        let mut subgoal = None;
        let mut holding = false;
        if let Some(l) = &mut self.live {
            l.slowed_between_ticks = false;
        }
        let change = self.live.as_mut().and_then(|l| l.route_change.take());
        match (change, &mut self.navigator) {
            (Some(RouteChange::Avoid(circle)), Some(nav)) => {
                // A goal without room for it goes on as it was (the
                // hold's bound, `max_hold`, decides).
                let _ = nav.avoid(circle, x, now);
            }
            (Some(RouteChange::Forget), Some(nav)) => nav.forget_avoided(x, now),
            _ => {}
        }
        if let Some(nav) = &mut self.navigator {
            match nav.update(x, now) {
                NavStep::Drive {
                    target,
                    final_target,
                } => {
                    // The first target starts from an actor roll-out; later
                    // ones (subgoal switches, replans) keep the plan.
                    match self.mpc.goal() {
                        None => self.mpc.set_goal(target, self.world.circles())?,
                        Some(g) if g != target => self.mpc.retarget(target)?,
                        Some(_) => {}
                    }
                    if self.costs_seen != Some(nav.cost_version()) {
                        self.costs_seen = Some(nav.cost_version());
                        self.mpc.set_path_cost(nav.path_cost());
                        self.mpc.set_track_cost(nav.track_cost());
                    }
                    if let Some(track) = nav.track_cost() {
                        self.mpc.set_track_time(track.time());
                    }
                    subgoal = (!final_target).then_some(target);
                }
                NavStep::Hold => holding = true,
                NavStep::Abort(reason) => return Ok(PilotDecision::Abort(reason)),
            }
        } else if let Some(goal) = self.mpc.goal() {
            if self.progress.update(x, &goal, now) {
                return Ok(PilotDecision::Abort(AbortReason::NoProgress));
            }
        }
        let plans = self.navigator.as_ref().map_or(0, |n| n.plans());
        let new_plan = plans != self.plans_seen;
        self.plans_seen = plans;
        let (route, route_age, last_plan) = match &self.navigator {
            Some(nav) => (nav.remaining_route(), nav.route_age(), nav.last_plan()),
            None => (&[][..], 0.0, None),
        };
        // The envelope's margins as they are now (widened or not by the
        // assumptions' check): the MPC's live rows keep them.
        let live_margins = self
            .assumptions
            .effective()
            .circle_margins(&self.params, self.world.outline());
        if self.live.is_some() {
            self.mpc
                .set_live_margins(&live_margins[..self.world.outline().len()]);
        }
        let mut proposed = if holding {
            // Holding for the first route: a stop at the limits (at rest, rest).
            envelope::stop_command(self.last, Some(x), &self.params, self.dt)
        } else {
            self.mpc.step_within(x, now, tick_start)?.command
        };
        self.sent
            .set_delay(self.configured_delay.max(self.mpc.compensated_delay()));
        // The live obstacles' slow-down field scales the speed down along
        // the MPC's plan (ISO 21815: slow and stop, never steer).
        let unscaled = proposed;
        let mut slow = 1.0;
        if let (Some(l), false) = (&self.live, holding) {
            slow = slow_factor(
                &self.world,
                l,
                self.assumptions.effective(),
                self.mpc.solution(),
                now + self.sent.delay(),
                self.dt,
            );
            proposed.v *= slow;
        }
        let input = self.envelope_input(x, now);
        let guarded = envelope::guard(&input, proposed);
        let inside = |c: Option<LiveContact>| c.is_some_and(|c| c.excess < 0.0);
        // Held after a protective stop, the way is clear once the MPC's plan
        // keeps out of the stop fields for the slow-down field's time, and
        // so does what it proposes (before the slow-down).
        let blocked = self.live.as_ref().is_some_and(|l| {
            l.hold.is_some() && (slow < 1.0 || inside(envelope::predict(&input, unscaled).live))
        });
        // The standing live obstacle the MPC's plan is pressed against
        // while the machine is nearly at rest: what it waits for.
        let pressed = if holding || x[ix::V].abs() >= live::STANDING_SPEED {
            None
        } else {
            self.pressed_against()
        };
        let stop = envelope::stop_command(self.last, Some(x), &self.params, self.dt);
        let mut command = guarded.command;
        // What a circle planned round adds to the obstacle's stop field:
        // the rows' largest margin and the half-width (a wire circle's
        // radius holds it).
        let round_extra = live_margins.iter().fold(0.0, |m: f64, v| m.max(*v))
            + crate::mpc::live_rows::PLAN_MARGIN
            + self.world.outline().half_width();
        let live_status = self.live.as_mut().map(|l| {
            let freshness = l.freshness.update(now, &l.settings);
            if guarded.overridden() && inside(guarded.live) {
                // A protective stop: held until the way clears.
                l.hold = Some((l.hold.map_or(now, |h| h.0), None));
            } else if let Some((since, clear_since)) = l.hold {
                // It must stay clear for `resume_wait`.
                let clear = if blocked {
                    None
                } else {
                    clear_since.or(Some(now))
                };
                l.hold = match clear {
                    Some(t) if now - t >= l.settings.resume_wait => None,
                    clear => Some((since, clear)),
                };
            }
            l.waiting_since = if l.hold.is_some() || slow < 1.0 || pressed.is_some() {
                l.waiting_since.or(Some(now))
            } else {
                None
            };
            // A standing obstacle that keeps it waiting is planned round.
            let standing = pressed.or_else(|| {
                guarded
                    .live
                    .filter(|c| l.hold.is_some() && c.excess < PRESSED)
                    .and_then(|c| l.set.obstacles().iter().position(|o| o.id == c.id))
                    .filter(|&i| l.set.obstacles()[i].speed() < live::STANDING_SPEED)
            });
            l.plan_round(standing, now, round_extra);
            let stale = l.settings.required && freshness != FreshnessState::Fresh;
            if l.hold.is_some() || stale {
                command = stop;
            }
            LiveStatus {
                freshness,
                stale_stop: stale,
                slow,
                holding: l.hold.is_some(),
                contact: guarded.live,
            }
        });
        Ok(PilotDecision::Drive(PilotStep {
            command,
            proposed,
            guarded,
            solution: (!holding).then(|| self.mpc.solution()),
            subgoal,
            route: if holding { &[] } else { route },
            route_age,
            last_plan,
            new_plan,
            assumptions,
            live: live_status,
        }))
    }

    /// The command sent to the machine at `now`, whoever decided it (the
    /// pilot's, a stop ramp, a hold): every tick, in time order.
    pub fn sent(&mut self, now: f64, command: VelocityCommand) {
        self.mpc.sent(now, command);
        self.sent.record(now, command);
        self.last = command;
    }

    /// The delay the MPC compensates now [s] (its online estimate, if on).
    pub fn compensated_delay(&self) -> f64 {
        self.mpc.compensated_delay()
    }

    pub fn mpc(&self) -> &Mpc<C> {
        &self.mpc
    }

    pub fn navigator(&self) -> Option<&Navigator> {
        self.navigator.as_ref()
    }

    /// Wall time routes were planned on the tick's thread since the last
    /// call ([`Navigator::take_plan_time_on_tick`]; zero with the planner
    /// thread): `wlnav-sim` leaves it out of the tick's time.
    pub fn take_plan_time_on_tick(&mut self) -> Duration {
        self.navigator
            .as_mut()
            .map_or(Duration::ZERO, Navigator::take_plan_time_on_tick)
    }

    pub fn params(&self) -> &MachineParams {
        &self.params
    }
}

impl<C: StageCost> Pilot<C> {
    /// The standing live obstacle (its index in the set) whose stop field
    /// the MPC's plan comes nearest, if within [`PRESSED`] of it.
    fn pressed_against(&self) -> Option<usize> {
        let rows = self.mpc.live_rows()?;
        let l = self.live.as_ref()?;
        let states = &self.mpc.solution().states;
        let circles = self.world.outline().len();
        let mut best: Option<(usize, f64)> = None;
        for &i in rows.near() {
            if l.set.obstacles()[i].speed() >= live::STANDING_SPEED {
                continue;
            }
            for (k, x) in states.iter().enumerate().skip(1) {
                for c in 0..circles {
                    let (h, _) = rows.row(self.mpc.world(), x, k, c, i);
                    if h < PRESSED && best.is_none_or(|b| h < b.1) {
                        best = Some((i, h));
                    }
                }
            }
        }
        best.map(|b| b.0)
    }
}

/// The slow-down field's factor ([`live::slow_factor`]) along the MPC's plan
/// (its states from `t0`, `dt` apart), against the live obstacles' stop
/// fields with the envelope's margins.
fn slow_factor(
    world: &World,
    l: &Live,
    settings: &EnvelopeSettings,
    sol: &Solution,
    t0: f64,
    dt: f64,
) -> f64 {
    if l.set.is_empty() {
        return 1.0;
    }
    let params = world.params();
    let margins = settings.circle_margins(params, world.outline());
    let n = world.outline().len();
    live::slow_factor(&sol.states, t0, dt, &l.settings, |t, x| {
        let placed = world.place(x);
        let mut least = f64::INFINITY;
        for o in l.set.obstacles() {
            let grow = l.settings.reach(t - o.stamp);
            for (c, m) in placed[..n].iter().zip(&margins) {
                least = least.min(o.clearance_at(c.center, c.radius + m + grow, t));
            }
        }
        least
    })
}
