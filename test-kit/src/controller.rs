//! A controller wrapper that forwards every call of the daemon's `Controller` trait, so a
//! test controller that changes one call (fails, stalls, leaks) changes only that one. A
//! hand-written wrapper forwards the calls it names and silently takes the trait's
//! default for the others: the tests' `Failing`, `Stalling` and `Leaking` each dropped
//! `compensated_delay`, so the safety envelope under them assumed the configured delay
//! instead of the MPC's estimate (issue 44).
//!
//! [`Forwarding`] implements every method of the trait itself, defaults included, each by
//! a call of its [`Hooks`]; every hook's default forwards to the wrapped controller. A
//! method added to the trait must be added to both (the test below names them all).

use std::time::{Duration, Instant};

use control::envelope::Guarded;
use control::live::LiveSet;
use control::mpc::Obstacle;
use control::site::SiteIndex;
use control::{Goal, State, VelocityCommand};
use std::sync::Arc;
use wlnavd::controller::{Controller, ControllerError, Step};

/// What a test controller changes; each default forwards to `inner`.
pub trait Hooks {
    /// `Controller::set_goal`.
    fn set_goal(
        &mut self,
        inner: &mut dyn Controller,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), ControllerError> {
        inner.set_goal(start, goal, obstacles, now)
    }
    /// `Controller::reset`.
    fn reset(&mut self, inner: &mut dyn Controller) {
        inner.reset()
    }
    /// `Controller::step`.
    fn step<'a>(
        &'a mut self,
        inner: &'a mut dyn Controller,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'a>, ControllerError> {
        inner.step(state, now, tick_start)
    }
    /// `Controller::sent`.
    fn sent(&mut self, inner: &mut dyn Controller, now: f64, command: VelocityCommand) {
        inner.sent(now, command)
    }
    /// `Controller::set_site`.
    fn set_site(&mut self, inner: &mut dyn Controller, site: Option<Arc<SiteIndex>>) {
        inner.set_site(site)
    }
    /// `Controller::compensated_delay`.
    fn compensated_delay(&self, inner: &dyn Controller) -> Option<f64> {
        inner.compensated_delay()
    }
    /// `Controller::planner_working`.
    fn planner_working(&self, inner: &dyn Controller) -> bool {
        inner.planner_working()
    }
    /// `Controller::set_live`.
    fn set_live(&mut self, inner: &mut dyn Controller, set: &LiveSet) {
        inner.set_live(set)
    }
    /// `Controller::check_live`.
    fn check_live(&mut self, inner: &mut dyn Controller, x: &State, now: f64) -> Option<Guarded> {
        inner.check_live(x, now)
    }
}

/// Hooks that change nothing.
pub struct Unchanged;
impl Hooks for Unchanged {}

/// `inner` with `hooks` in front of it.
pub struct Forwarding<H> {
    /// The wrapped controller.
    pub inner: Box<dyn Controller>,
    /// What the test changes.
    pub hooks: H,
}

impl<H: Hooks> Forwarding<H> {
    /// Wraps `inner`.
    pub fn new(inner: Box<dyn Controller>, hooks: H) -> Self {
        Self { inner, hooks }
    }
}

impl<H: Hooks> Controller for Forwarding<H> {
    fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), ControllerError> {
        self.hooks
            .set_goal(self.inner.as_mut(), start, goal, obstacles, now)
    }
    fn reset(&mut self) {
        self.hooks.reset(self.inner.as_mut())
    }
    fn step(
        &mut self,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'_>, ControllerError> {
        self.hooks.step(self.inner.as_mut(), state, now, tick_start)
    }
    fn sent(&mut self, now: f64, command: VelocityCommand) {
        self.hooks.sent(self.inner.as_mut(), now, command)
    }
    fn compensated_delay(&self) -> Option<f64> {
        self.hooks.compensated_delay(self.inner.as_ref())
    }
    fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.hooks.set_site(self.inner.as_mut(), site)
    }
    fn planner_working(&self) -> bool {
        self.hooks.planner_working(self.inner.as_ref())
    }
    fn set_live(&mut self, set: &LiveSet) {
        self.hooks.set_live(self.inner.as_mut(), set)
    }
    fn check_live(&mut self, x: &State, now: f64) -> Option<Guarded> {
        self.hooks.check_live(self.inner.as_mut(), x, now)
    }
}

/// Sleeps `d` (times `WLNAV_TIMING_SCALE`): for hooks that stall.
pub fn stall(d: Duration) {
    std::thread::sleep(crate::timing_scale::real(d));
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::rc::Rc;

    /// Records every call it gets; its delay estimate is 0.37 s.
    struct Recording(Rc<RefCell<Vec<&'static str>>>);

    impl Controller for Recording {
        fn set_goal(
            &mut self,
            _: &State,
            _: Goal,
            _: &[Obstacle],
            _: f64,
        ) -> Result<(), ControllerError> {
            self.0.borrow_mut().push("set_goal");
            Ok(())
        }
        fn reset(&mut self) {
            self.0.borrow_mut().push("reset");
        }
        fn step(&mut self, _: &State, _: f64, _: Instant) -> Result<Step<'_>, ControllerError> {
            self.0.borrow_mut().push("step");
            Err(ControllerError("recorded".into()))
        }
        fn sent(&mut self, _: f64, _: VelocityCommand) {
            self.0.borrow_mut().push("sent");
        }
        fn compensated_delay(&self) -> Option<f64> {
            self.0.borrow_mut().push("compensated_delay");
            Some(0.37)
        }
        fn set_site(&mut self, _: Option<Arc<SiteIndex>>) {
            self.0.borrow_mut().push("set_site");
        }
        fn planner_working(&self) -> bool {
            self.0.borrow_mut().push("planner_working");
            true
        }
        fn set_live(&mut self, _: &LiveSet) {
            self.0.borrow_mut().push("set_live");
        }
        fn check_live(&mut self, _: &State, _: f64) -> Option<Guarded> {
            self.0.borrow_mut().push("check_live");
            None
        }
    }

    #[test]
    fn every_call_reaches_the_wrapped_controller() {
        let calls = Rc::new(RefCell::new(Vec::new()));
        let mut c = Forwarding::new(Box::new(Recording(calls.clone())), Unchanged);
        let x = State::zeros();
        c.set_goal(&x, Goal::new(1.0, 0.0, 0.0), &[], 0.0).unwrap();
        c.reset();
        assert!(c.step(&x, 0.0, Instant::now()).is_err());
        c.sent(
            0.0,
            VelocityCommand {
                beta_dot: 0.0,
                v: 0.0,
            },
        );
        assert_eq!(c.compensated_delay(), Some(0.37));
        c.set_site(None);
        assert!(c.planner_working());
        c.set_live(&LiveSet::new());
        assert_eq!(c.check_live(&x, 0.0), None);
        assert_eq!(
            *calls.borrow(),
            [
                "set_goal",
                "reset",
                "step",
                "sent",
                "compensated_delay",
                "set_site",
                "planner_working",
                "set_live",
                "check_live"
            ]
        );
    }
}
