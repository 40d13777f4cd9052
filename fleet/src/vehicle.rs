//! The vehicle as the master sees it: the order book, action states and errors, driven by
//! events (an order, instant actions, a telemetry sample, a goal reply, the daemon lost or
//! back) and answering with effects (requests for the daemon, "publish the state now",
//! "publish the factsheet now"). No I/O: `bridge.rs` carries the effects out, and the unit
//! tests below drive it with made-up telemetry.

use std::collections::HashSet;
use std::time::Duration;

use shm_ipc::{
    fault_flags, AbortReason, GoalOutcome, GoalReply, GoalRequest, Mode, Pose2, RejectCode,
    Telemetry,
};

use crate::config::MachineInfo;
use crate::order::{self, Decision, Identity, Limits, OrderBook, Target, VehicleMap};
use crate::vda::{
    self, ActionState, ActionStatus, AgvPosition, BatteryState, EStop, EdgeState, ErrorLevel,
    Header, NodeState, OperatingMode, SafetyState, State, Velocity,
};

/// A goal refused as not ready (daemon starting, faulted) is sent again after this long.
const RETRY_AFTER: Duration = Duration::from_secs(1);
/// Errors kept from rejected messages and ended goals (the newest).
const MAX_KEPT_ERRORS: usize = 32;

/// What the bridge must do after an event.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Send this request to the daemon and report the reply with [`Vehicle::on_reply`].
    Daemon(GoalRequest),
    /// Publish the state now (an event the specification lists).
    PublishState,
    /// Publish the factsheet now (`factsheetRequest`).
    PublishFactsheet,
}

/// The goal the bridge has handed the daemon.
#[derive(Debug, Clone, PartialEq)]
struct SentGoal {
    request_id: u64,
    node_id: String,
    sequence_id: u64,
}

/// Settings the vehicle logic needs.
#[derive(Debug, Clone)]
pub struct VehicleSettings {
    /// Manufacturer and serial number.
    pub identity: Identity,
    /// Message limits.
    pub limits: Limits,
    /// The map while the daemon has no site (the configuration's `map_id`); with a site
    /// the site's id is the map ([`VehicleMap`]).
    pub map_id: String,
    /// See [`crate::config::Config::first_node_range`].
    pub first_node_range: f64,
    /// Factsheet and battery values.
    pub machine: MachineInfo,
}

/// The vehicle's state machine (see the module docs).
#[derive(Debug)]
pub struct Vehicle {
    settings: VehicleSettings,
    book: OrderBook,
    actions: Vec<ActionState>,
    /// Errors of rejected messages, failed actions and ended goals: kept until the next new
    /// order.
    kept_errors: Vec<vda::Error>,
    telemetry: Option<Telemetry>,
    daemon_ok: bool,
    daemon_seen: bool,
    goal: Option<SentGoal>,
    /// Goals the bridge itself cancelled or replaced: their outcome is expected.
    expected_end: HashSet<u64>,
    retry_at: Option<Duration>,
    paused: bool,
    /// The actionId of a running cancelOrder, finished once at rest. Meanwhile every
    /// order is refused (it would be dropped with the cancelled one) and so is another
    /// cancelOrder.
    cancel_action: Option<String>,
    /// The actionIds of running startPause actions, all finished once at rest with the
    /// stop latched (or by stopPause).
    pause_actions: Vec<String>,
    next_id: u64,
    distance_since_last_node: f64,
    last_xy: Option<(f64, f64)>,
    omega: f64,
    last_heading: Option<(u64, f64)>,
    now: Duration,
}

impl Vehicle {
    /// A vehicle with no order; request ids start at `first_request_id` (give a value no
    /// other client of the daemon uses, e.g. the monotonic clock).
    pub fn new(settings: VehicleSettings, first_request_id: u64) -> Self {
        Self {
            settings,
            book: OrderBook::default(),
            actions: Vec::new(),
            kept_errors: Vec::new(),
            telemetry: None,
            daemon_ok: false,
            daemon_seen: false,
            goal: None,
            expected_end: HashSet::new(),
            retry_at: None,
            paused: false,
            cancel_action: None,
            pause_actions: Vec::new(),
            next_id: first_request_id.max(1),
            distance_since_last_node: 0.0,
            last_xy: None,
            omega: 0.0,
            last_heading: None,
            now: Duration::ZERO,
        }
    }

    /// The order book (for tests and logs).
    pub fn book(&self) -> &OrderBook {
        &self.book
    }

    fn next_request_id(&mut self) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        id
    }

    fn keep_error(&mut self, e: vda::Error) {
        tracing::warn!(
            error_type = %e.error_type,
            "{}",
            e.error_description.as_deref().unwrap_or("")
        );
        self.kept_errors.push(e);
        if self.kept_errors.len() > MAX_KEPT_ERRORS {
            self.kept_errors.remove(0);
        }
    }

    fn machine_pose(&self) -> Option<Pose2> {
        let t = self.telemetry.as_ref().filter(|_| self.daemon_ok)?;
        Some(Pose2::new(t.state.x_f, t.state.y_f, t.state.theta_f))
    }

    /// The map orders must be on now: the daemon's site as its newest telemetry sample
    /// names it (kept while the daemon is away), else the configured `map_id`; unknown
    /// before the first sample.
    pub fn map(&self) -> VehicleMap {
        VehicleMap::from_telemetry(self.telemetry.as_ref(), &self.settings.map_id)
    }

    fn at_rest(&self) -> bool {
        self.telemetry
            .as_ref()
            .is_some_and(|t| t.at_rest != 0 && t.mode != Mode::Tracking.code())
    }

    /// An `order` message arrived.
    pub fn on_order(&mut self, payload: &[u8], now: Duration) -> Vec<Effect> {
        self.now = now;
        let order = match order::parse_order(
            payload,
            &self.settings.identity,
            &self.settings.limits,
            &self.map(),
        ) {
            Ok(o) => o,
            Err(e) => {
                self.keep_error(e);
                return vec![Effect::PublishState];
            }
        };
        let decision =
            self.book
                .decide(&order, self.machine_pose(), self.settings.first_node_range);
        match &decision {
            Decision::Reject(e) => {
                self.keep_error(e.clone());
                return vec![Effect::PublishState];
            }
            Decision::Duplicate => return Vec::new(),
            _ if self.cancel_action.is_some() => {
                let cancel = self.cancel_action.clone().unwrap_or_default();
                let header_id = order.header.header_id.to_string();
                let update_id = order.ids.order_update_id.to_string();
                self.keep_error(vda::Error::new(
                    "orderUpdateError",
                    ErrorLevel::Warning,
                    format!(
                        "order {} is being cancelled (cancelOrder {cancel} runs until the \
                         machine is at rest); send orders once it is FINISHED",
                        self.book.ids.order_id
                    ),
                    &[
                        ("headerId", &header_id),
                        ("orderId", &order.ids.order_id),
                        ("orderUpdateId", &update_id),
                        ("actionId", &cancel),
                    ],
                ));
                return vec![Effect::PublishState];
            }
            Decision::New => {
                tracing::info!(order_id = %order.ids.order_id, nodes = order.nodes.len(), "new order");
                // A goal of the previous order the daemon may still drive (one the bridge
                // stopped sending after, e.g. when the site changed): replaced by the new
                // order's first goal, its end expected. (Goals are matched by sequenceId,
                // which the new order numbers afresh.)
                if let Some(g) = self.goal.take() {
                    self.expected_end.insert(g.request_id);
                }
                self.actions.clear();
                self.kept_errors.clear();
                self.distance_since_last_node = 0.0;
            }
            Decision::Update => {
                tracing::info!(
                    order_id = %order.ids.order_id,
                    update = order.ids.order_update_id,
                    "order update"
                );
            }
        }
        self.book.apply(order, &decision);
        // A new goal for the (possibly changed) target is decided by `drive`; an update
        // that turns the current target into a pass-through node keeps its goal.
        self.retry_at = None;
        let mut effects = vec![Effect::PublishState];
        effects.extend(self.drive());
        effects
    }

    /// An `instantActions` message arrived.
    pub fn on_instant_actions(&mut self, payload: &[u8], now: Duration) -> Vec<Effect> {
        self.now = now;
        let msg = match order::parse_instant_actions(
            payload,
            &self.settings.identity,
            &self.settings.limits,
        ) {
            Ok(m) => m,
            Err(e) => {
                self.keep_error(e);
                return vec![Effect::PublishState];
            }
        };
        let mut effects = vec![Effect::PublishState];
        for a in msg.actions {
            let mut state = ActionState {
                action_id: a.action_id.clone(),
                action_type: Some(a.action_type.clone()),
                action_description: a.action_description.clone(),
                action_status: ActionStatus::Finished,
                result_description: None,
            };
            match a.action_type.as_str() {
                "cancelOrder" => {
                    if let Some(running) = self.cancel_action.clone() {
                        state.action_status = ActionStatus::Failed;
                        state.result_description =
                            Some(format!("cancelOrder {running} is already running"));
                        self.keep_error(vda::Error::new(
                            "noOrderToCancel",
                            ErrorLevel::Warning,
                            format!(
                                "cancelOrder: the order is already being cancelled by {running}"
                            ),
                            &[("actionId", &a.action_id)],
                        ));
                    } else if !self.book.has_remaining() && self.goal.is_none() {
                        state.action_status = ActionStatus::Failed;
                        state.result_description = Some("no order to cancel".into());
                        self.keep_error(vda::Error::new(
                            "noOrderToCancel",
                            ErrorLevel::Warning,
                            "cancelOrder: there is no order to cancel",
                            &[("actionId", &a.action_id)],
                        ));
                    } else {
                        // No more goals; the nodes are dropped once the machine is at rest
                        // (the action then FINISHED), so a master sees the order end with it.
                        self.book.failed = true;
                        if let Some(g) = self.goal.take() {
                            self.expected_end.insert(g.request_id);
                        }
                        let id = self.next_request_id();
                        effects.push(Effect::Daemon(GoalRequest::cancel(id)));
                        state.action_status = ActionStatus::Running;
                        self.cancel_action = Some(a.action_id.clone());
                    }
                }
                "startPause" => {
                    if let Some(g) = self.goal.take() {
                        self.expected_end.insert(g.request_id);
                    }
                    self.paused = true;
                    let id = self.next_request_id();
                    effects.push(Effect::Daemon(GoalRequest::stop(id)));
                    state.action_status = ActionStatus::Running;
                    self.pause_actions.push(a.action_id.clone());
                }
                "stopPause" => {
                    self.paused = false;
                    let id = self.next_request_id();
                    effects.push(Effect::Daemon(GoalRequest::resume(id)));
                    for p in std::mem::take(&mut self.pause_actions) {
                        self.set_action_status(&p, ActionStatus::Finished, None);
                    }
                    self.retry_at = None;
                }
                "stateRequest" => {}
                "factsheetRequest" => effects.push(Effect::PublishFactsheet),
                "initPosition" => {
                    state.action_status = ActionStatus::Failed;
                    state.result_description = Some(
                        "the pose comes from the machine's localization (wlnav/pose); \
                         it cannot be set from the fleet"
                            .into(),
                    );
                }
                other => {
                    state.action_status = ActionStatus::Failed;
                    state.result_description = Some(format!("{other} is not supported"));
                    self.keep_error(vda::Error::new(
                        "unsupportedActionError",
                        ErrorLevel::Warning,
                        format!("instant action {other:?} is not supported by this vehicle"),
                        &[("actionId", &a.action_id), ("actionType", other)],
                    ));
                }
            }
            self.actions.retain(|s| s.action_id != state.action_id);
            self.actions.push(state);
        }
        effects.extend(self.drive());
        effects
    }

    /// The broker delivered a message beyond the MQTT packet limit (`limit` bytes; the
    /// bridge's is [`crate::bridge::MAX_PACKET`]): the MQTT client refused it and dropped the
    /// connection without reading it, so neither its topic nor its content is known. A
    /// `validationError` in the state says so once the bridge is connected again.
    pub fn on_oversized_message(&mut self, len: usize, limit: usize, now: Duration) -> Vec<Effect> {
        self.now = now;
        self.keep_error(vda::Error::new(
            "validationError",
            ErrorLevel::Warning,
            format!(
                "a message of {len} bytes exceeds the MQTT packet limit of {limit} bytes: \
                 refused unread (the connection to the broker was dropped and made anew)"
            ),
            &[("messageLength", &len.to_string())],
        ));
        vec![Effect::PublishState]
    }

    fn set_action_status(&mut self, id: &str, status: ActionStatus, result: Option<String>) {
        if let Some(s) = self.actions.iter_mut().find(|s| s.action_id == id) {
            s.action_status = status;
            if result.is_some() {
                s.result_description = result;
            }
        }
    }

    /// A telemetry sample from the daemon (every tick).
    pub fn on_telemetry(&mut self, t: &Telemetry, now: Duration) -> Vec<Effect> {
        self.now = now;
        let mut effects = Vec::new();
        if !self.daemon_ok {
            tracing::info!("wlnavd telemetry (back)");
            effects.push(Effect::PublishState);
        }
        self.daemon_ok = true;
        self.daemon_seen = true;
        // Odometry for distanceSinceLastNode and the turn rate.
        if let Some((x, y)) = self.last_xy {
            let step = (t.state.x_f - x).hypot(t.state.y_f - y);
            if step.is_finite() && step < 5.0 {
                self.distance_since_last_node += step;
            }
        }
        self.last_xy = Some((t.state.x_f, t.state.y_f));
        if let Some((ts, th)) = self.last_heading {
            let dt = t.timestamp_ns.saturating_sub(ts) as f64 * 1e-9;
            if dt > 1e-3 {
                self.omega = shm_ipc::normalize_angle(t.state.theta_f - th) / dt;
            }
        }
        self.last_heading = Some((t.timestamp_ns, t.state.theta_f));
        self.telemetry = Some(*t);

        if t.outcome != GoalOutcome::None.code() {
            effects.extend(self.on_outcome(t));
        }
        if self.at_rest() {
            if let Some(id) = self.cancel_action.take() {
                self.book.clear();
                self.set_action_status(&id, ActionStatus::Finished, None);
                effects.push(Effect::PublishState);
            }
            if t.fault_flags & fault_flags::STOP_REQUESTED != 0 {
                for id in std::mem::take(&mut self.pause_actions) {
                    self.set_action_status(&id, ActionStatus::Finished, None);
                    effects.push(Effect::PublishState);
                }
            }
        }
        effects.extend(self.drive());
        effects
    }

    fn on_outcome(&mut self, t: &Telemetry) -> Vec<Effect> {
        let id = t.outcome_request_id;
        if self.expected_end.remove(&id) {
            return Vec::new();
        }
        let Some(goal) = self.goal.clone().filter(|g| g.request_id == id) else {
            return Vec::new();
        };
        self.goal = None;
        let outcome = t.outcome();
        let text = t.outcome_text().to_owned();
        let refs = [
            ("orderId", self.book.ids.order_id.clone()),
            ("nodeId", goal.node_id.clone()),
            ("sequenceId", goal.sequence_id.to_string()),
        ];
        let refs: Vec<(&str, &str)> = refs.iter().map(|(k, v)| (*k, v.as_str())).collect();
        match outcome {
            Ok(GoalOutcome::Succeeded) => {
                if self
                    .book
                    .target(self.machine_pose().unwrap_or_default())
                    .is_some_and(|tg| tg.sequence_id == goal.sequence_id)
                {
                    self.traverse(&goal.node_id, goal.sequence_id);
                }
                vec![Effect::PublishState]
            }
            Ok(GoalOutcome::Aborted) => {
                let reason = t.abort_reason().unwrap_or(AbortReason::Fault);
                if reason == AbortReason::Shutdown {
                    // The daemon is going away; the goal is sent again when it is back.
                    return vec![Effect::PublishState];
                }
                let (error_type, level) = match reason {
                    AbortReason::NoRoute | AbortReason::GoalInCollision => {
                        ("noRouteError", ErrorLevel::Warning)
                    }
                    AbortReason::NoProgress => ("goalAbortedError", ErrorLevel::Warning),
                    _ => ("goalAbortedError", ErrorLevel::Fatal),
                };
                self.book.failed = true;
                self.keep_error(vda::Error::new(
                    error_type,
                    level,
                    format!(
                        "the goal for node {} was aborted ({}): {text}",
                        goal.node_id,
                        reason.name()
                    ),
                    &refs,
                ));
                vec![Effect::PublishState]
            }
            _ => {
                // Cancelled or preempted by someone else on the machine (an operator with
                // `wlnav cancel`, another local client): the order stops here.
                self.book.failed = true;
                let name = outcome.map(|o| o.name()).unwrap_or("unknown");
                self.keep_error(vda::Error::new(
                    "goalCancelledError",
                    ErrorLevel::Warning,
                    format!(
                        "the goal for node {} ended {name} on the machine, not by the fleet: {text}",
                        goal.node_id
                    ),
                    &refs,
                ));
                vec![Effect::PublishState]
            }
        }
    }

    fn traverse(&mut self, node_id: &str, sequence_id: u64) {
        tracing::info!(node_id, sequence_id, "node traversed");
        self.book.traverse(node_id, sequence_id);
        self.distance_since_last_node = 0.0;
    }

    /// The reply to a request [`Effect::Daemon`] asked for; `Err` when it could not be sent
    /// or no reply came.
    pub fn on_reply(
        &mut self,
        request_id: u64,
        reply: Result<GoalReply, String>,
        now: Duration,
    ) -> Vec<Effect> {
        self.now = now;
        let Some(goal) = self.goal.clone().filter(|g| g.request_id == request_id) else {
            // Replies to cancel / stop / resume: always accepted by the daemon.
            if let Err(e) = reply {
                tracing::warn!(request_id, "request to wlnavd failed: {e}");
            }
            return Vec::new();
        };
        match reply {
            Ok(r) if r.is_accepted() => Vec::new(),
            Ok(r) if r.reject_code() == Ok(RejectCode::NotReady) => {
                tracing::info!(
                    "goal refused, not ready ({}); again in 1 s",
                    r.reason_text()
                );
                self.goal = None;
                self.retry_at = Some(self.now + RETRY_AFTER);
                Vec::new()
            }
            Ok(r) => {
                // The daemon's own validation refused the node: out of the workspace, in an
                // obstacle, … The order stops; nothing was driven.
                self.goal = None;
                self.book.failed = true;
                let code = r
                    .reject_code()
                    .map(|c| format!("{c:?}"))
                    .unwrap_or_default();
                self.keep_error(vda::Error::new(
                    "noRouteError",
                    ErrorLevel::Warning,
                    format!(
                        "wlnavd refused node {} as a goal ({code}): {}",
                        goal.node_id,
                        r.reason_text()
                    ),
                    &[
                        ("orderId", &self.book.ids.order_id.clone()),
                        ("nodeId", &goal.node_id),
                    ],
                ));
                vec![Effect::PublishState]
            }
            Err(e) => {
                tracing::warn!("goal not delivered to wlnavd: {e}");
                self.goal = None;
                self.retry_at = Some(self.now + RETRY_AFTER);
                Vec::new()
            }
        }
    }

    /// No telemetry for the configured time: the daemon is gone (stopped, crashed,
    /// restarting). Reported as an error until it is back.
    pub fn on_daemon_lost(&mut self, now: Duration) -> Vec<Effect> {
        self.now = now;
        if !self.daemon_ok && self.daemon_seen {
            return Vec::new();
        }
        self.daemon_ok = false;
        self.daemon_seen = true;
        // Whatever goal it had is gone with it; it is sent again when the daemon is back.
        if let Some(g) = self.goal.take() {
            self.expected_end.insert(g.request_id);
        }
        tracing::warn!("no telemetry from wlnavd");
        vec![Effect::PublishState]
    }

    /// Decides the goal for the current target node, traverses pass-through nodes the
    /// machine is within, and asks for the goal when it changed.
    fn drive(&mut self) -> Vec<Effect> {
        let mut effects = Vec::new();
        if self.paused || !self.daemon_ok {
            return effects;
        }
        let Some(pose) = self.machine_pose() else {
            return effects;
        };
        if self
            .telemetry
            .is_some_and(|t| t.fault_flags & fault_flags::STOP_REQUESTED != 0)
        {
            // An operator stop is latched on the machine: nothing is sent until a resume.
            return effects;
        }
        loop {
            let Some(target) = self.book.target(pose) else {
                break;
            };
            if order::passed(&target, pose) {
                self.traverse(&target.node_id, target.sequence_id);
                effects.push(Effect::PublishState);
                continue;
            }
            if self
                .goal
                .as_ref()
                .is_some_and(|g| g.sequence_id == target.sequence_id)
            {
                break;
            }
            if self.retry_at.is_some_and(|t| self.now < t) {
                break;
            }
            self.retry_at = None;
            if let Err(why) = self.map().check_node(&target.node_id, &target.map_id) {
                // The daemon's site changed its id while the order ran (a reload, or a
                // daemon restarted with another site): no goal on a map the daemon no
                // longer has. A goal it already drives is its own business (it plans it
                // again in the new world); the order stops at its last traversed node.
                self.book.failed = true;
                let order_id = self.book.ids.order_id.clone();
                let last = self.book.last_node_id.clone();
                self.keep_error(vda::Error::new(
                    "noRouteError",
                    ErrorLevel::Warning,
                    format!(
                        "{why}: the site changed while order {order_id} ran; no goal is sent \
                         for node {}, the order stops at node {last}",
                        target.node_id
                    ),
                    &[
                        ("orderId", &order_id),
                        ("nodeId", &target.node_id),
                        ("mapId", &target.map_id),
                    ],
                ));
                effects.push(Effect::PublishState);
                break;
            }
            effects.push(Effect::Daemon(self.goal_request(&target)));
            break;
        }
        effects
    }

    /// The goal for `target`, without circles: the daemon's site is the world.
    fn goal_request(&mut self, target: &Target) -> GoalRequest {
        let id = self.next_request_id();
        if let Some(old) = self.goal.replace(SentGoal {
            request_id: id,
            node_id: target.node_id.clone(),
            sequence_id: target.sequence_id,
        }) {
            self.expected_end.insert(old.request_id);
        }
        tracing::info!(
            node = %target.node_id,
            x = target.goal.x,
            y = target.goal.y,
            heading = target.goal.heading,
            pass_through = target.pass_through,
            "goal"
        );
        GoalRequest::set_goal(id, target.goal, &[]).expect("no circles are within the limit")
    }

    fn position(&self) -> Option<AgvPosition> {
        let t = self.telemetry.as_ref()?;
        Some(AgvPosition {
            x: t.state.x_f,
            y: t.state.y_f,
            theta: shm_ipc::normalize_angle(t.state.theta_f),
            // With telemetry the map is known: the site's id, else the configured one.
            map_id: self.map().id().unwrap_or_default().to_owned(),
            map_description: None,
            position_initialized: self.daemon_ok && t.fault_flags & fault_flags::POSE_STALE == 0,
            localization_score: None,
            deviation_range: None,
        })
    }

    fn velocity(&self) -> Option<Velocity> {
        let t = self.telemetry.as_ref()?;
        Some(Velocity {
            vx: Some(t.state.v_f),
            vy: Some(0.0),
            omega: Some(if self.omega.is_finite() {
                self.omega
            } else {
                0.0
            }),
        })
    }

    /// The live errors: the daemon's absence and its faults.
    fn live_errors(&self) -> Vec<vda::Error> {
        let mut errors = Vec::new();
        if !self.daemon_ok {
            errors.push(vda::Error::new(
                "daemonUnavailableError",
                ErrorLevel::Fatal,
                if self.daemon_seen {
                    "no telemetry from wlnavd: the controller is stopped or restarting"
                } else {
                    "wlnavd not reached yet"
                },
                &[],
            ));
            return errors;
        }
        let Some(t) = &self.telemetry else {
            return errors;
        };
        let faults = t.fault_flags & !NOT_FAULTS;
        if faults != 0 || t.mode == Mode::Fault.code() {
            let level = if t.mode == Mode::Fault.code() {
                ErrorLevel::Fatal
            } else {
                ErrorLevel::Warning
            };
            errors.push(vda::Error::new(
                "machineFaultError",
                level,
                format!("wlnavd reports: {}", fault_names(faults)),
                &[("faultFlags", &format!("{faults:#x}"))],
            ));
        }
        errors
    }

    /// The state message (the bridge fills in the header).
    pub fn state(&self, header: Header) -> State {
        let t = self.telemetry.as_ref();
        let mode = t.and_then(|t| t.mode().ok());
        let operating_mode = match (self.daemon_ok, mode) {
            (true, Some(Mode::Idle | Mode::Tracking | Mode::Reached | Mode::Stopping)) => {
                OperatingMode::Automatic
            }
            _ => OperatingMode::Service,
        };
        let stop_latched = t.is_some_and(|t| t.fault_flags & fault_flags::STOP_REQUESTED != 0);
        let mut errors = self.kept_errors.clone();
        errors.extend(self.live_errors());
        State {
            header,
            ids: self.book.ids.clone(),
            last_node_id: self.book.last_node_id.clone(),
            last_node_sequence_id: self.book.last_node_sequence_id,
            // Moving, by the daemon's one "at rest" (telemetry `at_rest`), unless
            // holding a reached goal: the daemon reports a goal reached below its
            // reach speed, and the last centimetres per second of settling into a
            // stop node are not driving on.
            driving: self.daemon_ok
                && t.is_some_and(|t| t.at_rest == 0 && t.mode != Mode::Reached.code()),
            paused: Some(self.paused || stop_latched),
            new_base_request: None,
            distance_since_last_node: Some(self.distance_since_last_node),
            operating_mode,
            node_states: self.book.remaining_nodes().map(NodeState::from).collect(),
            edge_states: self.book.remaining_edges().map(EdgeState::from).collect(),
            agv_position: self.position(),
            velocity: self.velocity(),
            action_states: self.actions.clone(),
            battery_state: BatteryState {
                battery_charge: self.settings.machine.battery_charge,
                battery_voltage: None,
                battery_health: None,
                charging: false,
                reach: None,
            },
            errors,
            safety_state: SafetyState {
                e_stop: if stop_latched {
                    EStop::Remote
                } else {
                    EStop::None
                },
                field_violation: false,
            },
        }
    }

    /// The visualization message.
    pub fn visualization(&self, header: Header) -> vda::Visualization {
        vda::Visualization {
            header,
            agv_position: self.position(),
            velocity: self.velocity(),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &VehicleSettings {
        &self.settings
    }
}

/// Telemetry flags that are no fault: the operator stop (shown as `paused` and
/// `safetyState.eStop`) and the safety envelope braking near an obstacle (the controller
/// goes on; DESIGN §14).
const NOT_FAULTS: u32 = fault_flags::STOP_REQUESTED | fault_flags::ENVELOPE_OVERRIDE;

/// The names of the set fault bits, as the wire names them ([`fault_flags::NAMES`]); a bit
/// this build does not know (a newer daemon's) as `bit-N`.
pub fn fault_names(flags: u32) -> String {
    let names = fault_flags::names(flags);
    if names.is_empty() {
        "fault".into()
    } else {
        names.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn vehicle() -> Vehicle {
        Vehicle::new(
            VehicleSettings {
                identity: Identity {
                    manufacturer: "wlnav".into(),
                    serial_number: "L1".into(),
                },
                limits: Limits::default(),
                map_id: "site".into(),
                first_node_range: 1.0,
                machine: MachineInfo::default(),
            },
            100,
        )
    }

    fn header() -> Header {
        Header {
            header_id: 0,
            timestamp: "2024-01-01T00:00:00.000Z".into(),
            version: "2.0.0".into(),
            manufacturer: "wlnav".into(),
            serial_number: "L1".into(),
        }
    }

    fn telemetry(x: f64, y: f64, v: f64, mode: Mode) -> Telemetry {
        let mut t = Telemetry::ZERO;
        t.mode = mode.code();
        t.state.x_f = x;
        t.state.y_f = y;
        t.state.v_f = v;
        // As the daemon sets it (its default `loop.rest_speed`).
        t.at_rest = u32::from(v.abs() < 0.02);
        t
    }

    fn order(order_id: &str, update: u64, nodes: &[(&str, u64, f64, f64, f64)]) -> Vec<u8> {
        order_on("site", order_id, update, nodes)
    }

    /// An order whose nodes are all on map `map`.
    fn order_on(
        map: &str,
        order_id: &str,
        update: u64,
        nodes: &[(&str, u64, f64, f64, f64)],
    ) -> Vec<u8> {
        let ns: Vec<_> = nodes
            .iter()
            .map(|(id, seq, x, y, dev)| {
                json!({"nodeId": id, "sequenceId": seq, "released": true, "actions": [],
                "nodePosition": {"x": x, "y": y, "mapId": map, "allowedDeviationXY": dev}})
            })
            .collect();
        let es: Vec<_> = nodes
            .windows(2)
            .map(|w| {
                json!({"edgeId": format!("{}{}", w[0].0, w[1].0), "sequenceId": w[0].1 + 1,
                "released": true, "startNodeId": w[0].0, "endNodeId": w[1].0, "actions": []})
            })
            .collect();
        json!({"headerId": 1, "timestamp": "t", "version": "2.0.0", "manufacturer": "wlnav",
               "serialNumber": "L1", "orderId": order_id, "orderUpdateId": update,
               "nodes": ns, "edges": es})
        .to_string()
        .into_bytes()
    }

    fn instant(actions: &[(&str, &str)]) -> Vec<u8> {
        let a: Vec<_> = actions
            .iter()
            .map(|(ty, id)| json!({"actionType": ty, "actionId": id, "blockingType": "HARD"}))
            .collect();
        json!({"headerId": 1, "timestamp": "t", "version": "2.0.0", "manufacturer": "wlnav",
               "serialNumber": "L1", "actions": a})
        .to_string()
        .into_bytes()
    }

    fn goals(effects: &[Effect]) -> Vec<GoalRequest> {
        effects
            .iter()
            .filter_map(|e| match e {
                Effect::Daemon(r) => Some(*r),
                _ => None,
            })
            .collect()
    }

    const T: Duration = Duration::ZERO;

    #[test]
    fn faults_are_errors_and_the_envelope_is_not() {
        let mut v = vehicle();
        let mut t = telemetry(0.0, 0.0, 0.5, Mode::Tracking);
        t.fault_flags = fault_flags::ENVELOPE_OVERRIDE;
        v.on_telemetry(&t, T);
        assert!(
            v.state(header()).errors.is_empty(),
            "envelope braking is no fault"
        );
        t.fault_flags = fault_flags::ENVELOPE_OVERRIDE | fault_flags::OVERRUN | (1 << 30);
        v.on_telemetry(&t, T);
        let e = v.state(header()).errors;
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].error_type, "machineFaultError");
        assert_eq!(
            e[0].error_description.as_deref(),
            Some("wlnavd reports: overrun, bit-30")
        );
    }

    #[test]
    fn an_order_is_driven_node_by_node() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let fx = v.on_order(
            &order(
                "o",
                0,
                &[
                    ("A", 0, 0.0, 0.0, 0.0),
                    ("B", 2, 3.0, 0.0, 0.5),
                    ("C", 4, 6.0, 0.0, 0.0),
                ],
            ),
            T,
        );
        let g = goals(&fx);
        assert_eq!(g.len(), 1);
        // Without circles: the daemon's site is the world.
        assert_eq!((g[0].goal.x, g[0].obstacle_count), (3.0, 0));
        assert!(v
            .on_reply(g[0].request_id, Ok(GoalReply::accept(g[0].request_id)), T)
            .is_empty());
        let s = v.state(header());
        assert_eq!(s.last_node_id, "A");
        assert_eq!(s.node_states.len(), 2);
        // Within 0.5 m of B: passed without stopping, the goal moves on to C.
        let fx = v.on_telemetry(&telemetry(2.6, 0.0, 0.8, Mode::Tracking), T);
        let g2 = goals(&fx);
        assert_eq!(g2.len(), 1);
        assert_eq!(g2[0].goal.x, 6.0);
        assert_eq!(v.state(header()).last_node_id, "B");
        // B's goal ends preempted: expected, no error.
        let mut t = telemetry(2.8, 0.0, 0.8, Mode::Tracking);
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Preempted,
            AbortReason::None,
            1,
            "newer goal",
        );
        v.on_telemetry(&t, T);
        assert!(v.state(header()).errors.is_empty());
        // C succeeds: the order is done.
        let mut t = telemetry(6.0, 0.0, 0.0, Mode::Reached);
        t.set_outcome(
            g2[0].request_id,
            GoalOutcome::Succeeded,
            AbortReason::None,
            2,
            "",
        );
        v.on_telemetry(&t, T);
        let s = v.state(header());
        assert_eq!(
            (
                s.last_node_id.as_str(),
                s.node_states.len(),
                s.edge_states.len()
            ),
            ("C", 0, 0)
        );
        assert!(s.errors.is_empty());
        assert!(!s.driving);
    }

    #[test]
    fn aborted_goals_become_errors_and_stop_the_order() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let g = goals(&v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        ));
        let mut t = telemetry(1.0, 0.0, 0.0, Mode::Idle);
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Aborted,
            AbortReason::NoRoute,
            1,
            "no route",
        );
        v.on_telemetry(&t, T);
        let s = v.state(header());
        assert_eq!(s.errors.len(), 1);
        assert_eq!(s.errors[0].error_type, "noRouteError");
        assert_eq!(s.errors[0].error_level, ErrorLevel::Warning);
        assert!(goals(&v.on_telemetry(&telemetry(1.0, 0.0, 0.0, Mode::Idle), T)).is_empty());
        // A fault abort is FATAL.
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let g = goals(&v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        ));
        let mut t = telemetry(1.0, 0.0, 0.0, Mode::Fault);
        t.fault_flags = fault_flags::POSE_STALE;
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Aborted,
            AbortReason::Fault,
            1,
            "pose stale",
        );
        v.on_telemetry(&t, T);
        let s = v.state(header());
        assert!(s
            .errors
            .iter()
            .any(|e| e.error_type == "goalAbortedError" && e.error_level == ErrorLevel::Fatal));
        assert!(s.errors.iter().any(|e| e.error_type == "machineFaultError"));
        assert_eq!(s.operating_mode, OperatingMode::Service);
        assert!(!s.agv_position.unwrap().position_initialized);
    }

    #[test]
    fn a_goal_the_daemon_refuses_is_an_error_and_not_retried() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let g = goals(&v.on_order(
            &order(
                "o",
                0,
                &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 500.0, 0.0, 0.0)],
            ),
            T,
        ));
        let reply = GoalReply::reject(
            g[0].request_id,
            RejectCode::OutOfWorkspace,
            "outside the workspace",
        );
        v.on_reply(g[0].request_id, Ok(reply), T);
        let s = v.state(header());
        assert_eq!(s.errors[0].error_type, "noRouteError");
        assert!(s.errors[0]
            .error_description
            .as_ref()
            .unwrap()
            .contains("workspace"));
        assert!(goals(&v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T)).is_empty());
        // Not ready: tried again after a second.
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let g = goals(&v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        ));
        v.on_reply(
            g[0].request_id,
            Ok(GoalReply::reject(
                g[0].request_id,
                RejectCode::NotReady,
                "starting",
            )),
            T,
        );
        assert!(goals(&v.on_telemetry(
            &telemetry(0.0, 0.0, 0.0, Mode::Idle),
            Duration::from_millis(500)
        ))
        .is_empty());
        assert_eq!(
            goals(&v.on_telemetry(
                &telemetry(0.0, 0.0, 0.0, Mode::Idle),
                Duration::from_millis(1100)
            ))
            .len(),
            1
        );
    }

    #[test]
    fn instant_actions() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        // cancelOrder without an order fails.
        v.on_instant_actions(&instant(&[("cancelOrder", "c0")]), T);
        let s = v.state(header());
        assert_eq!(s.action_states[0].action_status, ActionStatus::Failed);
        assert_eq!(s.errors[0].error_type, "noOrderToCancel");
        // initPosition fails with a reason, factsheetRequest asks for the factsheet, an
        // unknown action fails.
        let fx = v.on_instant_actions(
            &instant(&[
                ("initPosition", "i"),
                ("factsheetRequest", "f"),
                ("dance", "d"),
            ]),
            T,
        );
        assert!(fx.contains(&Effect::PublishFactsheet));
        let s = v.state(header());
        let status = |id: &str| {
            s.action_states
                .iter()
                .find(|a| a.action_id == id)
                .unwrap()
                .action_status
        };
        assert_eq!(status("i"), ActionStatus::Failed);
        assert_eq!(status("f"), ActionStatus::Finished);
        assert_eq!(status("d"), ActionStatus::Failed);

        // A new order clears action states and errors.
        let g = goals(&v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        ));
        assert!(v.state(header()).action_states.is_empty());
        assert!(v.state(header()).errors.is_empty());
        // Pause: a stop; finished once at rest with the stop latched; no goal while paused.
        let fx = v.on_instant_actions(&instant(&[("startPause", "p")]), T);
        assert_eq!(goals(&fx)[0].kind, 3);
        let mut t = telemetry(1.0, 0.0, 0.3, Mode::Stopping);
        t.fault_flags = fault_flags::STOP_REQUESTED;
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Cancelled,
            AbortReason::None,
            1,
            "stop",
        );
        assert!(goals(&v.on_telemetry(&t, T)).is_empty());
        let s = v.state(header());
        assert_eq!(s.action_states[0].action_status, ActionStatus::Running);
        assert_eq!(s.paused, Some(true));
        assert_eq!(s.safety_state.e_stop, EStop::Remote);
        assert!(s.errors.is_empty(), "{:?}", s.errors);
        let mut t = telemetry(1.1, 0.0, 0.0, Mode::Idle);
        t.fault_flags = fault_flags::STOP_REQUESTED;
        v.on_telemetry(&t, T);
        assert_eq!(
            v.state(header()).action_states[0].action_status,
            ActionStatus::Finished
        );
        // Resume: the goal for B is sent again after the resume.
        let fx = v.on_instant_actions(&instant(&[("stopPause", "r")]), T);
        let g = goals(&fx);
        assert_eq!(g.len(), 1);
        assert_eq!(g[0].kind, 4);
        let fx = v.on_telemetry(&telemetry(1.1, 0.0, 0.0, Mode::Idle), T);
        assert_eq!(goals(&fx)[0].goal.x, 3.0);
        // Cancel: running until at rest, then finished; nodes dropped.
        let fx = v.on_instant_actions(&instant(&[("cancelOrder", "c1")]), T);
        assert_eq!(goals(&fx)[0].kind, 2);
        let s = v.state(header());
        let status = |s: &State, id: &str| {
            s.action_states
                .iter()
                .find(|a| a.action_id == id)
                .unwrap()
                .action_status
        };
        assert_eq!(status(&s, "c1"), ActionStatus::Running);
        assert!(goals(&v.on_telemetry(&telemetry(1.5, 0.0, 0.5, Mode::Stopping), T)).is_empty());
        let s = v.state(header());
        assert_eq!(status(&s, "c1"), ActionStatus::Running);
        assert_eq!(s.node_states.len(), 1);
        v.on_telemetry(&telemetry(1.6, 0.0, 0.0, Mode::Idle), T);
        let s = v.state(header());
        assert_eq!(status(&s, "c1"), ActionStatus::Finished);
        assert!(s.node_states.is_empty());
        assert_eq!(s.ids.order_id, "o");
        // Action states are kept until the next new order.
        assert_eq!(s.action_states.len(), 3);
    }

    #[test]
    fn a_lost_daemon_is_an_error_and_the_goal_is_sent_again() {
        let mut v = vehicle();
        assert_eq!(
            v.state(header()).errors[0].error_type,
            "daemonUnavailableError"
        );
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let g = goals(&v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        ));
        assert_eq!(g.len(), 1);
        let mut t = telemetry(1.0, 0.0, 0.0, Mode::Stopping);
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Aborted,
            AbortReason::Shutdown,
            1,
            "shutdown",
        );
        v.on_telemetry(&t, T);
        v.on_daemon_lost(T);
        let s = v.state(header());
        assert_eq!(s.errors.len(), 1);
        assert_eq!(s.errors[0].error_level, ErrorLevel::Fatal);
        let fx = v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        assert_eq!(goals(&fx)[0].goal.x, 3.0);
        assert!(v.state(header()).errors.is_empty());
    }

    fn status(s: &State, id: &str) -> Option<ActionStatus> {
        s.action_states
            .iter()
            .find(|a| a.action_id == id)
            .map(|a| a.action_status)
    }

    #[test]
    fn while_a_cancel_runs_orders_and_another_cancel_are_refused() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        let ab = [("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)];
        assert_eq!(goals(&v.on_order(&order("o", 0, &ab), T)).len(), 1);
        v.on_telemetry(&telemetry(1.0, 0.0, 0.8, Mode::Tracking), T);
        v.on_instant_actions(&instant(&[("cancelOrder", "c1")]), T);
        // Still moving: a new order, an update of the cancelled one and a second cancel
        // are refused; nothing goes to the daemon.
        let fx = v.on_order(
            &order("o2", 0, &[("X", 0, 1.2, 0.0, 0.0), ("Y", 2, 4.0, 0.0, 0.0)]),
            T,
        );
        assert!(goals(&fx).is_empty());
        let fx = v.on_order(
            &order("o", 1, &[("B", 2, 3.0, 0.0, 0.0), ("C", 4, 6.0, 0.0, 0.0)]),
            T,
        );
        assert!(goals(&fx).is_empty());
        let fx = v.on_instant_actions(&instant(&[("cancelOrder", "c2")]), T);
        assert!(goals(&fx).is_empty());
        let s = v.state(header());
        assert_eq!(s.ids.order_id, "o");
        assert_eq!(s.ids.order_update_id, 0);
        assert_eq!(status(&s, "c1"), Some(ActionStatus::Running));
        assert_eq!(status(&s, "c2"), Some(ActionStatus::Failed));
        let refused: Vec<_> = s
            .errors
            .iter()
            .filter(|e| e.error_type == "orderUpdateError")
            .collect();
        assert_eq!(refused.len(), 2, "{:?}", s.errors);
        assert!(refused[0]
            .error_description
            .as_deref()
            .unwrap()
            .contains("being cancelled"));
        assert!(s.errors.iter().any(|e| e.error_type == "noOrderToCancel"));
        // At rest: c1 finishes, the nodes are gone, and a new order is accepted and driven.
        v.on_telemetry(&telemetry(1.3, 0.0, 0.0, Mode::Idle), T);
        let s = v.state(header());
        assert_eq!(status(&s, "c1"), Some(ActionStatus::Finished));
        assert!(s.node_states.is_empty());
        let fx = v.on_order(
            &order("o2", 0, &[("X", 0, 1.2, 0.0, 0.0), ("Y", 2, 4.0, 0.0, 0.0)]),
            T,
        );
        assert_eq!(goals(&fx)[0].goal.x, 4.0);
        let s = v.state(header());
        assert_eq!((s.ids.order_id.as_str(), s.node_states.len()), ("o2", 1));
    }

    #[test]
    fn every_pending_pause_finishes() {
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        v.on_order(
            &order("o", 0, &[("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)]),
            T,
        );
        v.on_telemetry(&telemetry(1.0, 0.0, 0.8, Mode::Tracking), T);
        // A master that sends startPause twice before the machine is at rest.
        v.on_instant_actions(&instant(&[("startPause", "p1")]), T);
        v.on_instant_actions(&instant(&[("startPause", "p2")]), T);
        // Both RUNNING while stopping, both FINISHED at rest (the stop latched throughout).
        for (x, v_f, mode, want) in [
            (1.2, 0.3, Mode::Stopping, ActionStatus::Running),
            (1.3, 0.0, Mode::Idle, ActionStatus::Finished),
        ] {
            let mut t = telemetry(x, 0.0, v_f, mode);
            t.fault_flags = fault_flags::STOP_REQUESTED;
            v.on_telemetry(&t, T);
            let s = v.state(header());
            assert_eq!(
                (status(&s, "p1"), status(&s, "p2")),
                (Some(want), Some(want))
            );
        }
        // A pause resumed before the machine came to rest finishes with stopPause.
        v.on_instant_actions(&instant(&[("stopPause", "r1")]), T);
        v.on_telemetry(&telemetry(1.3, 0.0, 0.4, Mode::Tracking), T);
        v.on_instant_actions(&instant(&[("startPause", "p3")]), T);
        v.on_instant_actions(&instant(&[("stopPause", "r2")]), T);
        let s = v.state(header());
        assert_eq!(status(&s, "p3"), Some(ActionStatus::Finished));
        assert_eq!(s.paused, Some(false));
    }

    /// `telemetry` on site `id` version `version`.
    fn on_site(x: f64, v: f64, mode: Mode, id: &str, version: u64) -> Telemetry {
        let mut t = telemetry(x, 0.0, v, mode);
        t.set_site(Some((id, version, 0xfeed)));
        t
    }

    fn descriptions(s: &State, ty: &str) -> Vec<String> {
        s.errors
            .iter()
            .filter(|e| e.error_type == ty)
            .map(|e| e.error_description.clone().unwrap_or_default())
            .collect()
    }

    #[test]
    fn orders_are_refused_before_telemetry_and_off_the_daemons_site() {
        let ab = [("A", 0, 0.0, 0.0, 0.0), ("B", 2, 3.0, 0.0, 0.0)];
        let mut v = vehicle();
        // No telemetry yet: refused, whatever the map.
        assert!(goals(&v.on_order(&order("o", 0, &ab), T)).is_empty());
        let s = v.state(header());
        assert!(
            descriptions(&s, "noRouteError")[0].contains("no telemetry from wlnavd yet"),
            "{:?}",
            s.errors
        );
        assert!(s.agv_position.is_none());
        // The daemon's site is "quarry": an order on the configured map_id ("site") is
        // refused naming both ids; one on "quarry" is driven, and agvPosition says "quarry".
        v.on_telemetry(&on_site(0.0, 0.0, Mode::Idle, "quarry", 3), T);
        assert!(goals(&v.on_order(&order("o", 0, &ab), T)).is_empty());
        let s = v.state(header());
        assert_eq!(
            descriptions(&s, "validationError"),
            ["node A: mapId \"site\", but the daemon's site is \"quarry\" (version 3)"]
        );
        assert_eq!(s.agv_position.unwrap().map_id, "quarry");
        let g = goals(&v.on_order(&order_on("quarry", "o", 0, &ab), T));
        assert_eq!(g.len(), 1);
        assert_eq!(v.book().ids.order_id, "o");
        // A daemon without a site: the configured map_id again.
        let mut v = vehicle();
        v.on_telemetry(&telemetry(0.0, 0.0, 0.0, Mode::Idle), T);
        assert_eq!(v.state(header()).agv_position.unwrap().map_id, "site");
        assert!(goals(&v.on_order(&order_on("quarry", "o", 0, &ab), T)).is_empty());
        assert!(
            descriptions(&v.state(header()), "validationError")[0].contains("wlnavd has no site")
        );
        assert_eq!(goals(&v.on_order(&order("o", 0, &ab), T)).len(), 1);
    }

    #[test]
    fn a_site_reload_with_another_id_stops_the_order_before_its_next_goal() {
        let abc = [
            ("A", 0, 0.0, 0.0, 0.0),
            ("B", 2, 3.0, 0.0, 0.5),
            ("C", 4, 6.0, 0.0, 0.0),
        ];
        // A new version of the same site: nothing changes, C's goal is sent.
        let mut v = vehicle();
        v.on_telemetry(&on_site(0.0, 0.0, Mode::Idle, "quarry", 3), T);
        assert_eq!(
            goals(&v.on_order(&order_on("quarry", "o", 0, &abc), T)).len(),
            1
        );
        let fx = v.on_telemetry(&on_site(2.7, 0.8, Mode::Tracking, "quarry", 4), T);
        assert_eq!(goals(&fx)[0].goal.x, 6.0);

        // Another site: updates for the old map are refused; the goal the daemon drives
        // is its own (not cancelled); once B is passed no goal goes out for C.
        let mut v = vehicle();
        v.on_telemetry(&on_site(0.0, 0.0, Mode::Idle, "quarry", 3), T);
        let g = goals(&v.on_order(&order_on("quarry", "o", 0, &abc), T));
        assert_eq!(g.len(), 1);
        let fx = v.on_telemetry(&on_site(1.0, 0.8, Mode::Tracking, "yard", 1), T);
        assert!(goals(&fx).is_empty(), "{fx:?}");
        let up = [("C", 4, 6.0, 0.0, 0.0), ("D", 6, 9.0, 0.0, 0.0)];
        assert!(goals(&v.on_order(&order_on("quarry", "o", 1, &up), T)).is_empty());
        assert_eq!(
            descriptions(&v.state(header()), "validationError"),
            ["node C: mapId \"quarry\", but the daemon's site is \"yard\" (version 1)"]
        );
        let fx = v.on_telemetry(&on_site(2.7, 0.8, Mode::Tracking, "yard", 1), T);
        assert!(goals(&fx).is_empty(), "a goal on the old map: {fx:?}");
        let s = v.state(header());
        assert_eq!(s.last_node_id, "B");
        assert_eq!(s.agv_position.as_ref().unwrap().map_id, "yard");
        let stop = descriptions(&s, "noRouteError");
        assert_eq!(stop.len(), 1, "{:?}", s.errors);
        assert!(
            stop[0].starts_with(
                "node C: mapId \"quarry\", but the daemon's site is \"yard\" (version 1): \
                 the site changed while order o ran"
            ),
            "{}",
            stop[0]
        );
        assert!(!v.book().is_active());
        // Nothing more is sent for the old order; a new one on the new site is driven.
        v.on_telemetry(&on_site(3.2, 0.0, Mode::Idle, "yard", 1), T);
        assert!(goals(&v.on_telemetry(&on_site(3.2, 0.0, Mode::Idle, "yard", 1), T)).is_empty());
        let g2 = goals(&v.on_order(
            &order_on(
                "yard",
                "o2",
                0,
                &[("X", 0, 3.2, 0.0, 0.0), ("Y", 2, 5.0, 0.0, 0.0)],
            ),
            T,
        ));
        assert_eq!(g2[0].goal.x, 5.0);
        // The old goal (B's, which the daemon drove on) ends preempted: expected, no error.
        let mut t = on_site(3.3, 0.2, Mode::Tracking, "yard", 1);
        t.set_outcome(
            g[0].request_id,
            GoalOutcome::Preempted,
            AbortReason::None,
            1,
            "newer goal",
        );
        v.on_telemetry(&t, T);
        assert!(v.state(header()).errors.is_empty());
    }
}
