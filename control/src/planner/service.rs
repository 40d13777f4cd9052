//! Where routes are planned: a [`RouteService`] takes a [`PlanJob`] and hands
//! it back answered. The navigator never waits for one; until an answer is
//! there it holds (a first route) or follows the route it has (a replan).
//!
//! - [`PlannerThread`]: the daemon's. A thread of its own runs the
//!   [`RoutePlanner`]; the tick only sends and polls (bounded channels, the
//!   job's buffers travel with it: no allocation).
//! - [`InlineRoutes`]: `wlnav-sim`'s and the tests'. It plans at once on the
//!   calling thread and hands the answer back `delay` later on the
//!   simulated clock, so an evaluation charges plan time as the daemon's
//!   planner thread costs it (an answer at the next tick) and stays
//!   deterministic.

use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;

use super::route_planner::{PlanJob, RoutePlanner};

/// Plans routes somewhere else than in the tick.
pub trait RouteService: Send {
    /// Takes a job to plan (at most one at a time: the navigator sends the
    /// next only after the last came back).
    fn submit(&mut self, job: Box<PlanJob>);
    /// The answered job, once it is there at `now` [s, the navigator's clock].
    fn poll(&mut self, now: f64) -> Option<Box<PlanJob>>;
    /// Whether a job is being planned right now (not yet answered).
    fn working(&self) -> bool {
        false
    }
    /// Wall time spent planning on the caller's thread since the last call
    /// (an inline service's; a thread's is zero): what a caller timing its
    /// tick subtracts, the plan being charged as simulated delay instead.
    fn take_time_on_caller(&mut self) -> std::time::Duration {
        std::time::Duration::ZERO
    }
}

/// How [`InlineRoutes`] charges a plan's time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlanDelay {
    /// A fixed delay [s] from the request's stamp: 0 answers in the same
    /// tick (a planner infinitely fast), one tick Δt as the daemon's
    /// planner thread does whenever a plan takes less than a tick.
    Fixed(f64),
    /// The plan's measured wall time (not deterministic: for measuring).
    Measured,
}

/// Plans on the calling thread, answers after the charged delay.
pub struct InlineRoutes {
    planner: RoutePlanner,
    delay: PlanDelay,
    answered: Option<(f64, Box<PlanJob>)>,
    /// Planning time on the calling thread not yet taken.
    time_on_caller: std::time::Duration,
}

impl InlineRoutes {
    pub fn new(planner: RoutePlanner, delay: PlanDelay) -> Self {
        Self {
            planner,
            delay,
            answered: None,
            time_on_caller: std::time::Duration::ZERO,
        }
    }
}

impl RouteService for InlineRoutes {
    fn submit(&mut self, mut job: Box<PlanJob>) {
        let t0 = std::time::Instant::now();
        self.planner.plan(&mut job);
        self.time_on_caller += t0.elapsed();
        let delay = match self.delay {
            PlanDelay::Fixed(d) => d,
            PlanDelay::Measured => job.route.report.duration.as_secs_f64(),
        };
        self.answered = Some((job.request.stamp + delay, job));
    }

    fn poll(&mut self, now: f64) -> Option<Box<PlanJob>> {
        // A tick's clock is a multiple of Δt in floating point: an answer due
        // "at" a tick is there at it.
        match &self.answered {
            Some((due, _)) if now + 1e-9 >= *due => self.answered.take().map(|(_, j)| j),
            _ => None,
        }
    }

    fn take_time_on_caller(&mut self) -> std::time::Duration {
        std::mem::take(&mut self.time_on_caller)
    }
}

/// The daemon's planner thread.
pub struct PlannerThread {
    jobs: Option<SyncSender<Box<PlanJob>>>,
    answers: Receiver<Box<PlanJob>>,
    thread: Option<JoinHandle<()>>,
    /// Set from a submit until the answer is sent back.
    working: Arc<AtomicBool>,
    /// An answer that came back in the tick that asked for it.
    held: Option<Box<PlanJob>>,
}

impl PlannerThread {
    /// Starts the thread (named `wlnav-planner`) with its planner.
    pub fn spawn(mut planner: RoutePlanner) -> std::io::Result<Self> {
        // One job at a time; room for one more so a send never blocks.
        let (job_tx, job_rx) = sync_channel::<Box<PlanJob>>(2);
        let (answer_tx, answer_rx) = sync_channel::<Box<PlanJob>>(2);
        let working = Arc::new(AtomicBool::new(false));
        let flag = working.clone();
        let thread = std::thread::Builder::new()
            .name("wlnav-planner".into())
            .spawn(move || {
                while let Ok(mut job) = job_rx.recv() {
                    planner.plan(&mut job);
                    let sent = answer_tx.send(job);
                    flag.store(false, Ordering::Release);
                    if sent.is_err() {
                        break;
                    }
                }
            })?;
        Ok(Self {
            jobs: Some(job_tx),
            answers: answer_rx,
            thread: Some(thread),
            working,
            held: None,
        })
    }
}

impl RouteService for PlannerThread {
    fn submit(&mut self, job: Box<PlanJob>) {
        if let Some(tx) = &self.jobs {
            self.working.store(true, Ordering::Release);
            // Full or gone: the job is lost with the thread, and the
            // navigator's progress window ends the goal.
            if tx.try_send(job).is_err() {
                self.working.store(false, Ordering::Release);
            }
        }
    }

    fn working(&self) -> bool {
        self.working.load(Ordering::Acquire)
    }

    /// An answer is taken from the tick after the one that asked for it on:
    /// what a plan costs does not depend on how fast it was (the simulator's
    /// one-tick charge is then exactly the daemon's behaviour).
    fn poll(&mut self, now: f64) -> Option<Box<PlanJob>> {
        if self.held.is_none() {
            match self.answers.try_recv() {
                Ok(job) => self.held = Some(job),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => return None,
            }
        }
        match &self.held {
            Some(job) if now > job.request.stamp + 1e-9 => self.held.take(),
            _ => None,
        }
    }
}

impl Drop for PlannerThread {
    fn drop(&mut self) {
        // Closing the channel ends the thread's loop after the plan it runs.
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

thread_local! {
    static TICK_THREAD: Cell<bool> = const { Cell::new(false) };
}

/// Marks the calling thread as the control loop's tick thread: a route
/// planned on it fails a debug assertion (no search runs in the tick).
pub fn mark_tick_thread() {
    TICK_THREAD.with(|t| t.set(true));
}

/// Whether [`mark_tick_thread`] marked the calling thread.
pub fn on_tick_thread() -> bool {
    TICK_THREAD.with(|t| t.get())
}
