//! One MPC tick: delay compensation, warm start (shift or roll-out), SQP
//! iterations (build the QP at the linearisation point, solve, step), output
//! and fallback.

use std::time::{Duration, Instant};

use crate::critic::{Derivatives, TerminalDerivatives};
use crate::model::VelocityCommand;
use crate::model::{ix, Control, Goal, State};
use crate::obstacle::PENETRATION_TOLERANCE;

use super::constraints::{fill_bounds, fill_obstacles, ObstacleRows};
use super::cost::{stage_block, terminal_block, StageCost};
use super::dynamics::Dynamics;
use super::layout::{QpLayout, AXLE_POINTS, NU, NX, NZ};
use super::path_cost::{PathTerm, POSE_INDEX};
use super::qp::{QpBackend, QpStatus};
use super::settings::{MpcError, MpcSettings};
use super::solution::{FallbackReason, StepStatus};
use super::{Mpc, Qp, Solution};
use crate::site::outline::{Body, MAX_OUTLINE_CIRCLES};
use crate::world::{push_smallest, RowPair, Target};

/// The linear slack penalties in q (constant).
pub(super) fn fill_slack_costs(layout: &QpLayout, settings: &MpcSettings, q: &mut [f64]) {
    for n in 1..=layout.horizon {
        for c in 0..3 {
            q[layout.state_slack(n, c)] = settings.state_slack_weight;
        }
    }
    for k in 0..layout.horizon {
        if layout.n_obs > 0 {
            q[layout.obstacle_slack(k)] = settings.obstacle_slack_weight;
        }
    }
}

/// The largest weight the obstacle rows' exact penalty is raised to.
pub const MAX_OBSTACLE_WEIGHT: f64 = 1e6;

fn derivatives_finite(value: f64, grad: &[f64], hess: &[f64]) -> bool {
    value.is_finite() && grad.iter().chain(hess).all(|v| v.is_finite())
}

/// A path term as the derivatives of a stage cost over z = (x, u).
fn path_derivatives(term: &PathTerm, out: &mut Derivatives) {
    out.value = term.value;
    out.grad = [0.0; NZ];
    out.hess = [[0.0; NZ]; NZ];
    for (r, &i) in POSE_INDEX.iter().enumerate() {
        out.grad[i] = term.grad_pose[r];
        for (c, &j) in POSE_INDEX.iter().enumerate() {
            out.hess[i][j] = term.hess_pose[r][c];
        }
    }
    for c in 0..NU {
        out.grad[NX + c] = term.grad_control[c];
        out.hess[NX + c][NX + c] = term.hess_control[c];
    }
}

fn finite(x: &State) -> bool {
    x.iter().all(|v| v.is_finite())
}

impl<C: StageCost, D: Dynamics, B: QpBackend> Mpc<C, D, B> {
    /// One tick from the state measured now. Returns `Err` only when no goal is
    /// set; every numerical failure is reported in the [`Solution`] and
    /// answered with the shifted previous plan, and the command is always
    /// finite and within the machine's velocity bounds.
    ///
    /// `now` is the time `measured` was taken [s, any monotonic clock, the one
    /// [`Mpc::sent`] is given]: the delay compensation propagates the state over
    /// the commands sent before it. The command returned is not recorded: send
    /// it (or what is sent instead) through [`Mpc::sent`].
    pub fn step(&mut self, measured: &State, now: f64) -> Result<&Solution, MpcError> {
        self.step_within(measured, now, Instant::now())
    }

    /// [`Self::step`] with the time budget counted from `tick_start` (the
    /// start of the control loop's tick, so what ran before the MPC in the
    /// tick is charged to the budget too).
    pub fn step_within(
        &mut self,
        measured: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<&Solution, MpcError> {
        let start = Instant::now();
        let goal = self.goal.ok_or(MpcError::NoGoal)?;
        self.measured = Some((now, *measured));
        if self.settings.delay_estimation && finite(measured) {
            self.delay_estimate.observe(measured);
            let d = self.delay_estimate.delay();
            if d != self.delay.delay() {
                self.delay.set_delay(d);
                self.gain.set_delay(d, self.settings.dt);
            }
        }
        if self.settings.gain_estimation {
            self.gain.observe(measured);
        }
        let x_hat = if finite(measured) {
            self.delay.propagate(now, measured)
        } else {
            *measured
        };
        self.solution.initial_state = x_hat;
        // The QP of this tick: rows for the circles within reach of x̂.
        self.n_reach =
            super::reachable_obstacles(&self.settings, &self.world, &x_hat, &mut self.active);
        if let Some(l) = &mut self.live {
            let reach = super::plan_reach(&self.settings, &self.world);
            l.select(
                &x_hat,
                now + self.delay.delay(),
                self.settings.horizon,
                reach,
            );
        }
        self.n_active = self.layout_for(self.n_reach);
        self.solution.qp_iterations = 0;
        self.solution.sqp_iterations = 0;
        self.solution.step_norm = 0.0;
        self.solution.restarted = false;
        self.solution.qp_time = Duration::ZERO;
        self.solution.derivatives_time = Duration::ZERO;
        self.solution.assembly_time = Duration::ZERO;
        self.solution.qp_status = QpStatus::NotRun;
        self.solution.cost = f64::NAN;

        let status = if !finite(&x_hat) {
            if self.has_plan {
                self.shift(&goal);
            }
            StepStatus::Fallback(FallbackReason::NonFiniteState)
        } else {
            let shifted = self.has_plan;
            if shifted {
                self.shift(&goal);
            } else {
                self.roll_out(&x_hat, &goal);
                self.has_plan = true;
            }
            self.xs[0] = x_hat;
            self.iterate(&x_hat, &goal, tick_start.min(start), shifted)
        };
        self.solution.status = status;

        // Output: the plan and (β̇, v_f) of x₁, checked and limited.
        let mut command = if self.has_plan {
            VelocityCommand {
                beta_dot: self.xs[1][ix::BETA_DOT],
                v: self.xs[1][ix::V],
            }
        } else {
            VelocityCommand::ZERO
        };
        if !command.is_finite() && self.solution.status == StepStatus::Solved {
            self.solution.status = StepStatus::Fallback(FallbackReason::NonFiniteSolution);
        }
        command = command.limited(&self.params);
        // With the gain estimate: send the command that achieves the plan's
        // velocities.
        if self.settings.gain_estimation {
            command = self.gain.to_send(command);
        }
        self.solution.command = command;
        self.solution.states.copy_from_slice(&self.xs);
        self.solution.controls.copy_from_slice(&self.us);
        self.solution.solve_time = start.elapsed();
        Ok(&self.solution)
    }

    /// Warm start: the plan moves one stage earlier, the new last control
    /// comes from the actor (or is zero) and the new last state from the model.
    fn shift(&mut self, goal: &Goal) {
        let n = self.settings.horizon;
        self.xs.copy_within(1.., 0);
        self.us.copy_within(1.., 0);
        let u = self.policy(&self.xs[n - 1].clone(), goal);
        self.us[n - 1] = u;
        self.xs[n] = self.dynamics.step(&self.xs[n - 1], &u, self.settings.dt);
    }

    /// Initial guess on a new goal: the actor rolled out over the horizon from
    /// x̂ (without an actor: zero controls, i.e. holding the current velocities).
    fn roll_out(&mut self, x_hat: &State, goal: &Goal) {
        self.xs[0] = *x_hat;
        for k in 0..self.settings.horizon {
            let u = self.policy(&self.xs[k].clone(), goal);
            self.us[k] = u;
            self.xs[k + 1] = self.dynamics.step(&self.xs[k], &u, self.settings.dt);
        }
    }

    fn policy(&mut self, x: &State, goal: &Goal) -> Control {
        match &mut self.actor {
            Some((actor, ws)) if finite(x) => {
                let u = self.params.clamp_control(&actor.action(ws, x, goal));
                if u.iter().all(|v| v.is_finite()) {
                    u
                } else {
                    Control::zeros()
                }
            }
            _ => Control::zeros(),
        }
    }

    /// SQP iterations at the current plan; returns the tick's status.
    ///
    /// If the first QP fails at a shifted warm start (which can drift into a
    /// bad region, e.g. towards the model's singularity at L_f cos β + L_r = 0
    /// when state slacks are cheap), it is retried once from a fresh roll-out
    /// within the time budget; if that fails too the shifted plan is kept.
    fn iterate(&mut self, x_hat: &State, goal: &Goal, start: Instant, shifted: bool) -> StepStatus {
        let budget = Duration::from_secs_f64(self.settings.time_budget);
        let mut status = StepStatus::Fallback(FallbackReason::QpFailed);
        let mut may_restart = shifted;
        // The plan before this tick's iterations: the fallback if they fail or
        // their plan penetrates a circle.
        self.backup_xs.copy_from_slice(&self.xs);
        self.backup_us.copy_from_slice(&self.us);
        let mut attempts = 0;
        while attempts < self.settings.sqp_iterations {
            attempts += 1;
            let it_start = Instant::now();
            let failure = self.sqp_iteration(x_hat, goal);
            if let Some(reason) = failure {
                if self.solution.sqp_iterations > 0 {
                    break;
                }
                status = StepStatus::Fallback(reason);
                if may_restart && start.elapsed() + it_start.elapsed() <= budget {
                    may_restart = false;
                    self.roll_out(x_hat, goal);
                    self.solution.restarted = true;
                    attempts -= 1;
                    continue;
                }
                if self.solution.restarted {
                    self.xs.copy_from_slice(&self.backup_xs);
                    self.us.copy_from_slice(&self.backup_us);
                }
                break;
            }
            status = StepStatus::Solved;
            if self.solution.step_norm < self.settings.sqp_tolerance {
                break;
            }
            if start.elapsed() + it_start.elapsed() > budget {
                break;
            }
        }
        if status == StepStatus::Solved && self.plan_penetrates(x_hat) {
            self.xs.copy_from_slice(&self.backup_xs);
            self.us.copy_from_slice(&self.backup_us);
            status = StepStatus::Fallback(FallbackReason::PlanPenetrates);
        }
        status
    }

    /// True if a planned state x₁..x_N puts an axle point more than
    /// [`PENETRATION_TOLERANCE`] inside a circle and deeper than x̂ is (a
    /// machine already inside may plan its way out, not further in).
    fn plan_penetrates(&self, x_hat: &State) -> bool {
        if self.world.is_empty() {
            return false;
        }
        let start = self.world.clearance(x_hat);
        let floor = (-PENETRATION_TOLERANCE).min(start - PENETRATION_TOLERANCE);
        let zeros = [0.0; MAX_OUTLINE_CIRCLES];
        self.xs[1..]
            .iter()
            .any(|x| self.world.excess(x, &zeros, floor).is_some())
    }

    /// Builds and solves one QP and takes its step; on failure nothing changes
    /// and the reason is returned.
    fn sqp_iteration(&mut self, x_hat: &State, goal: &Goal) -> Option<FallbackReason> {
        if !self.build_qp(x_hat, goal) {
            return Some(FallbackReason::NonFiniteData);
        }
        let qp_start = Instant::now();
        let qp = &mut self.qps[self.n_active];
        if qp.backend.update(&qp.data).is_err() {
            self.solution.qp_status = QpStatus::UpdateFailed;
            return Some(FallbackReason::QpFailed);
        }
        let outcome = qp.backend.solve();
        self.solution.qp_time += qp_start.elapsed();
        self.solution.qp_status = outcome.status;
        self.solution.qp_iterations += outcome.iterations;
        if !outcome.status.is_usable() {
            return Some(FallbackReason::QpFailed);
        }
        let w = qp.backend.primal();
        if !(w.len() == qp.layout.n_var && w.iter().all(|v| v.is_finite())) {
            return Some(FallbackReason::NonFiniteSolution);
        }
        self.take_step();
        self.solution.sqp_iterations += 1;
        None
    }

    /// Fills P, q, A, b at the current plan (the linearisation point) with x̂
    /// as x₀. Returns false if any value is not finite.
    fn build_qp(&mut self, x_hat: &State, goal: &Goal) -> bool {
        self.select_rows();
        let row_margins = self.row_margins();
        let s = self.settings;
        let Qp {
            layout: l, data: d, ..
        } = &mut self.qps[self.n_active];
        let l = &*l;
        let derivatives_start = Instant::now();
        let mut cost = 0.0;
        // Cost blocks (paper eq. 19–21).
        let mut der = Derivatives::default();
        let (mut h, mut g) = ([[0.0; NZ]; NZ], [0.0; NZ]);
        // With a path, its progress is the cost (projected stage by stage
        // from x̂'s segment onwards), else the critic.
        let track = !self.track_cost.is_empty();
        let path = !track && !self.path_cost.is_empty();
        let mut hint = self.path_hint;
        for k in 0..s.horizon {
            if track {
                self.track_cost
                    .eval(&self.xs[k], &self.us[k], k as f64 * s.dt, &mut der);
            } else if path {
                let term = self.path_cost.eval(&self.xs[k], &self.us[k], hint);
                hint = term.segment;
                if k == 0 {
                    self.path_hint = hint;
                }
                path_derivatives(&term, &mut der);
            } else {
                self.cost.stage(
                    &mut self.cost_ws,
                    &self.xs[k],
                    &self.us[k],
                    goal,
                    s.hessian,
                    &mut der,
                );
            }
            // Checked before the projection, which could hide a NaN.
            if !derivatives_finite(der.value, &der.grad, der.hess.as_flattened()) {
                return false;
            }
            cost += s.dt * der.value;
            stage_block(
                &der,
                s.dt,
                s.hessian,
                s.min_eigenvalue,
                s.levenberg_marquardt,
                &mut h,
                &mut g,
            );
            let block = &l.p_stage[k];
            let c0 = l.x(k);
            for i in 0..NZ {
                d.q[c0 + i] = g[i];
                for j in i..NZ {
                    d.p[block[i][j]] = h[i][j];
                }
            }
        }
        let mut term = TerminalDerivatives::default();
        let (mut ht, mut gt) = ([[0.0; NX]; NX], [0.0; NX]);
        if track {
            let mut full = Derivatives::default();
            self.track_cost.eval(
                &self.xs[s.horizon],
                &Control::zeros(),
                s.horizon as f64 * s.dt,
                &mut full,
            );
            term = TerminalDerivatives::state_block(&full);
        } else if path {
            let mut full = Derivatives::default();
            let t = self
                .path_cost
                .eval(&self.xs[s.horizon], &Control::zeros(), hint);
            path_derivatives(&t, &mut full);
            term = TerminalDerivatives::state_block(&full);
        } else {
            self.cost.terminal(
                &mut self.cost_ws,
                &self.xs[s.horizon],
                goal,
                s.hessian,
                &mut term,
            );
        }
        if !derivatives_finite(term.value, &term.grad, term.hess.as_flattened()) {
            return false;
        }
        cost += term.value;
        terminal_block(
            &term,
            s.hessian,
            s.min_eigenvalue,
            s.levenberg_marquardt,
            &mut ht,
            &mut gt,
        );
        let c0 = l.x(s.horizon);
        for i in 0..NX {
            d.q[c0 + i] = gt[i];
            for j in i..NX {
                d.p[l.p_terminal[i][j]] = ht[i][j];
            }
        }
        self.solution.cost = cost;
        let assembly_start = Instant::now();
        self.solution.derivatives_time += assembly_start - derivatives_start;
        // Initial state and linearised dynamics.
        for i in 0..NX {
            d.b[i] = x_hat[i] - self.xs[0][i];
        }
        for k in 0..s.horizon {
            let (next, a, b) = self
                .dynamics
                .step_with_jacobians(&self.xs[k], &self.us[k], s.dt);
            let r = l.row_dynamics(k);
            for i in 0..NX {
                for j in 0..NX {
                    d.a[l.a_dyn_x[k][i][j]] = -a[(i, j)];
                }
                for j in 0..NU {
                    d.a[l.a_dyn_u[k][i][j]] = -b[(i, j)];
                }
                d.b[r + i] = next[i] - self.xs[k + 1][i];
            }
        }
        // Bounds and obstacles.
        // A machine that achieves less than commanded cannot reach the
        // nominal β̇ and v bounds: plan within gain × bound (exactly the
        // nominal bounds while the applied gain is 1).
        let p = self.params;
        let [gb, gv] = if self.settings.gain_estimation {
            self.gain.applied_gains()
        } else {
            [1.0, 1.0]
        };
        let bounds = crate::model::MachineParams {
            beta_dot_max: p.beta_dot_max * gb.min(1.0),
            v_max: p.v_max * gv.min(1.0),
            ..p
        };
        fill_bounds(l, &bounds, &self.xs, &self.us, &mut d.b);
        fill_obstacles(
            l,
            &ObstacleRows {
                world: &self.world,
                margins: row_margins,
                pairs: &self.rows,
                len: &self.row_len,
                stride: super::row_stride(&s),
                live: self.live.as_ref(),
            },
            s.obstacle_constraint,
            s.cbf_gamma,
            &self.xs,
            &mut d.a,
            &mut d.b,
        );
        let finite = d.is_finite();
        self.solution.assembly_time += assembly_start.elapsed();
        finite
    }

    /// The QP of a tick with `n_reach` of the goal's circles within reach:
    /// with a site or live obstacles near, the one with every row; else the
    /// fewest slots that hold every (outline circle, circle) pair (for the
    /// default outline: one slot per circle, as before the site).
    fn layout_for(&self, n_reach: usize) -> usize {
        let max = self.settings.max_obstacles;
        if self.world.site().is_some() || self.live_near() {
            return max;
        }
        let pairs = n_reach * self.world.outline().len();
        pairs.div_ceil(super::layout::AXLE_POINTS).min(max)
    }

    /// Whether live obstacles are near this tick's plan.
    fn live_near(&self) -> bool {
        self.live.as_ref().is_some_and(|l| !l.near().is_empty())
    }

    /// Each outline circle's margin [m]: its body's, plus its own extra.
    fn row_margins(&self) -> [f64; MAX_OUTLINE_CIRCLES] {
        let s = &self.settings;
        let mut m = *self.world.extra_margins();
        for (mi, c) in m.iter_mut().zip(self.world.outline().circles()) {
            *mi += match c.body {
                Body::Front => s.obstacle_margin,
                Body::Rear => s.obstacle_margin_rear,
            };
        }
        m
    }

    /// Chooses each row k's (outline circle, target) pairs at x̄_{k+1}
    /// (DESIGN §17, §18). Without a site or live obstacles, when every pair of the goal's circles
    /// within reach has a slot, all of them in a fixed order (circle j, then
    /// outline circle: the rows of before the site, for the default
    /// outline); otherwise the pairs of least excess over their margins,
    /// the site's features nearest the stage's outline among them.
    /// Allocation-free.
    fn select_rows(&mut self) {
        let stride = super::row_stride(&self.settings);
        let slots = super::layout::AXLE_POINTS * self.qps[self.n_active].layout.n_obs;
        let circles = self.world.outline().len();
        let fixed =
            self.world.site().is_none() && !self.live_near() && self.n_reach * circles <= slots;
        let margins = self.row_margins();
        let body = [
            self.settings.obstacle_margin,
            self.settings.obstacle_margin_rear,
        ];
        let reach = self.settings.obstacle_reach(&self.params);
        for k in 0..self.settings.horizon {
            let out = &mut self.rows[k * stride..k * stride + slots];
            let mut len = 0;
            if fixed {
                for &j in &self.active[..self.n_reach] {
                    for c in 0..circles {
                        out[len] = RowPair {
                            circle: c,
                            target: Target::Circle(j),
                            excess: 0.0,
                        };
                        len += 1;
                    }
                }
            } else {
                let x = &self.xs[k + 1];
                for &j in &self.active[..self.n_reach] {
                    for (c, m) in margins[..circles].iter().enumerate() {
                        let target = Target::Circle(j);
                        let (h, _) = self.world.row(x, c, target);
                        let pair = RowPair {
                            circle: c,
                            target,
                            excess: h - m,
                        };
                        push_smallest(out, &mut len, pair);
                    }
                }
                self.world
                    .site_rows(x, body, reach, &mut self.near, out, &mut len);
                if let Some(l) = &self.live {
                    for &i in l.near() {
                        for c in 0..circles {
                            let (h, _) = l.row(&self.world, x, k + 1, c, i);
                            if h < reach {
                                let pair = RowPair {
                                    circle: c,
                                    target: Target::Live(i),
                                    excess: h,
                                };
                                push_smallest(out, &mut len, pair);
                            }
                        }
                    }
                }
            }
            self.row_len[k] = len;
        }
    }

    /// Exact penalty for the obstacle rows (DESIGN §14, issue 26): the L1
    /// weight is exact only while it exceeds the multipliers of the hard rows
    /// (Nocedal & Wright, Thm 17.3). A QP whose slack went beyond the planned
    /// margin (into the circle itself) while its stage multipliers reached the
    /// weight bought the penetration: the weight is raised tenfold (up to
    /// [`MAX_OBSTACLE_WEIGHT`]) for the ticks that follow, and a new goal
    /// starts again from the configured one. The margin stays soft (a slack
    /// within it is a plan closer than planned, not inside), so a QP that
    /// never buys penetration never changes the weight.
    fn raise_obstacle_weight(&mut self) {
        let margin = self
            .settings
            .obstacle_margin
            .min(self.settings.obstacle_margin_rear);
        let bought = self.solution.max_obstacle_slack() > margin + PENETRATION_TOLERANCE
            && self.solution.obstacle_multiplier >= 0.999 * self.obstacle_weight;
        if bought && self.obstacle_weight < MAX_OBSTACLE_WEIGHT {
            self.set_obstacle_weight((10.0 * self.obstacle_weight).min(MAX_OBSTACLE_WEIGHT));
        }
    }

    /// Puts `weight` on every obstacle slack of every QP's q.
    pub(super) fn set_obstacle_weight(&mut self, weight: f64) {
        self.obstacle_weight = weight;
        for qp in &mut self.qps {
            if qp.layout.n_obs > 0 {
                for k in 0..qp.layout.horizon {
                    qp.data.q[qp.layout.obstacle_slack(k)] = weight;
                }
            }
        }
    }

    /// Applies α·Δ from the QP solution, projects the controls onto their box
    /// (removing interior-point round-off) and records the slacks.
    fn take_step(&mut self) {
        let s = self.settings;
        let qp = &self.qps[self.n_active];
        let (l, w) = (&qp.layout, qp.backend.primal());
        let alpha = s.step_length;
        let mut norm: f64 = 0.0;
        for k in 0..=s.horizon {
            let c = l.x(k);
            for i in 0..NX {
                norm = norm.max(w[c + i].abs());
                // x₀ is x̂ itself (Δx₀ = 0 up to round-off).
                if k > 0 {
                    self.xs[k][i] += alpha * w[c + i];
                }
            }
            if k < s.horizon {
                let c = l.u(k);
                for i in 0..NU {
                    norm = norm.max(w[c + i].abs());
                    self.us[k][i] += alpha * w[c + i];
                }
                self.us[k] = self.params.clamp_control(&self.us[k]);
            }
        }
        self.solution.step_norm = norm;
        let mut slack_cost = 0.0;
        for n in 1..=s.horizon {
            for c in 0..3 {
                let v = w[l.state_slack(n, c)].max(0.0);
                self.solution.state_slacks[n - 1][c] = v;
                slack_cost += s.state_slack_weight * v;
            }
        }
        for k in 0..s.horizon {
            let v = if l.n_obs > 0 {
                w[l.obstacle_slack(k)].max(0.0)
            } else {
                0.0
            };
            self.solution.obstacle_slacks[k] = v;
            slack_cost += self.obstacle_weight * v;
        }
        self.solution.slack_cost = slack_cost;
        let z = qp.backend.dual();
        let mut multiplier: f64 = 0.0;
        for k in 0..s.horizon {
            let mut stage = 0.0;
            for j in 0..l.n_obs {
                for a in 0..AXLE_POINTS {
                    stage += z.get(l.row_obstacle(k, j, a)).copied().unwrap_or(0.0);
                }
            }
            multiplier = multiplier.max(stage);
        }
        self.solution.obstacle_multiplier = multiplier;
        self.raise_obstacle_weight();
    }
}
