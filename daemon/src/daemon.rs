//! Wiring: configuration → weights → CAN backend → iceoryx2 endpoint → control
//! thread → READY=1 → run until shutdown → stop the machine → exit.
//!
//! Threads and tasks:
//! * the **control thread** (`wlnavd-control`): builds the MPC, runs the first
//!   solve, sends READY=1, then ticks ([`crate::control_loop`]);
//! * a tokio current-thread runtime on the calling thread with the **CAN I/O
//!   task** ([`crate::can_io`]), the **goal server** ([`crate::ipc`]), the
//!   **signal handler** (SIGTERM/SIGINT → controlled stop, then exit), a periodic
//!   **statistics log**, and, with `can.backend = "sim"`, the **simulated machine**
//!   ([`crate::sim`]).
//!
//! [`run`] is what `main` calls; tests call it too, with their own controller and
//! a [`ShutdownHandle`] instead of signals.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use shm_ipc::{DaemonEndpoint, IpcConfig};
use thiserror::Error;
use tokio::sync::{mpsc, oneshot, Notify};

use crate::can::{CanBus, CandumpWriter, LoggingBus, SocketCanBus, MACHINE_STATE_ID};
use crate::can_io::{self, CanShared, CommandGuard};
use crate::clock::DaemonClock;
use crate::config::{CanBackend, Config};
use crate::control_loop::{ControlLoop, ExitReason, LoopContext};
use crate::controller::{self, ControllerFactory, LoadError};
use crate::ipc::{self, SharedGoals};
use crate::notify::Notifier;
use crate::sim::{self, SimHandle, SimLog};
use crate::site::SiteSlot;
use crate::stats::{self, LoopStats};

/// Start-up and run-time failures that end the daemon with a non-zero exit code.
#[derive(Debug, Error)]
pub enum DaemonError {
    /// Weights could not be loaded (the message names the file and the problem).
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The controller could not be built or its first solve failed.
    #[error("start-up self-test: {0}")]
    FirstSolve(String),
    /// iceoryx2 services.
    #[error("iceoryx2: {0}")]
    Ipc(#[from] shm_ipc::IpcError),
    /// CAN interface.
    #[error(transparent)]
    Can(#[from] crate::can::CanError),
    /// The simulated machine.
    #[error(transparent)]
    Sim(#[from] sim::SimError),
    /// Runtime or thread set-up, CAN log file.
    #[error("{0}")]
    Io(String),
    /// The control thread panicked.
    #[error("control thread panicked: {0}")]
    Panic(String),
    /// The site file could not be loaded (the message names the file and what is wrong).
    #[error("{0}")]
    Site(String),
    /// `[outline]`.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
}

/// Requests a controlled stop and exit from outside (tests; signals use it too).
#[derive(Debug, Clone, Default)]
pub struct ShutdownHandle(Arc<AtomicBool>);

impl ShutdownHandle {
    /// A handle not yet triggered.
    pub fn new() -> Self {
        Self::default()
    }

    /// Stop the machine and exit.
    pub fn trigger(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// True once triggered.
    pub fn is_triggered(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// How to run.
#[derive(Default)]
pub struct RunOptions {
    /// Use this controller instead of the one the configuration names (tests).
    pub controller: Option<ControllerFactory>,
    /// Shutdown trigger.
    pub shutdown: ShutdownHandle,
    /// Install SIGTERM/SIGINT handlers (the binary does; tests don't).
    pub handle_signals: bool,
    /// Receives the simulated machine's handle once it runs (tests).
    pub sim_handle: Option<oneshot::Sender<SimHandle>>,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// Why the loop ended.
    pub exit: ExitReason,
    /// Loop statistics.
    pub stats: LoopStats,
    /// Command frames sent.
    pub commands_sent: u64,
    /// Commands the last-line guard had to change (0 unless there is a bug).
    pub commands_clamped: u64,
    /// Goal requests served and rejected.
    pub goal_requests: (u64, u64),
    /// Resident memory after warm-up (tick 100, or ready if the run was shorter)
    /// and at the end [bytes].
    pub rss: (Option<u64>, Option<u64>),
    /// The simulated machine's log (sim backend).
    pub sim: Option<SimLog>,
}

impl RunReport {
    /// A human-readable summary (printed by the binary at exit).
    pub fn summary(&self) -> String {
        let mb =
            |b: Option<u64>| b.map_or("?".into(), |b| format!("{:.1} MiB", b as f64 / 1048576.0));
        format!(
            "ticks {}, overruns {}, missed deadlines {}, envelope overrides {}\n\
             tick start jitter: {}\n\
             solve time: {}\n\
             tick time: {}\n\
             plan time (planner thread): {}\n\
             commands sent {}, clamped by the guard {}\n\
             goal requests {} ({} rejected)\n\
             resident memory: after warm-up {}, at the end {}",
            self.stats.ticks,
            self.stats.overruns,
            self.stats.missed_deadlines,
            self.stats.envelope_overrides,
            self.stats.jitter(),
            self.stats.solve(),
            self.stats.tick(),
            self.stats.plan(),
            self.commands_sent,
            self.commands_clamped,
            self.goal_requests.0,
            self.goal_requests.1,
            mb(self.rss.0),
            mb(self.rss.1),
        )
    }
}

/// Runs the daemon until shutdown; blocking. Builds its own tokio runtime.
pub fn run(config: Config, options: RunOptions) -> Result<RunReport, DaemonError> {
    let factory = match options.controller {
        Some(f) => f,
        None => controller::load_controller(&config)?,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .thread_name("wlnavd-io")
        .build()
        .map_err(|e| DaemonError::Io(format!("tokio runtime: {e}")))?;
    runtime.block_on(run_async(
        config,
        factory,
        options.shutdown,
        options.handle_signals,
        options.sim_handle,
    ))
}

async fn run_async(
    config: Config,
    factory: ControllerFactory,
    shutdown: ShutdownHandle,
    handle_signals: bool,
    sim_handle_tx: Option<oneshot::Sender<SimHandle>>,
) -> Result<RunReport, DaemonError> {
    let scale = match config.can.backend {
        CanBackend::Sim => config.sim.time_scale,
        CanBackend::Socketcan => 1.0,
    };
    let clock = DaemonClock::new(scale);
    let endpoint = Arc::new(DaemonEndpoint::new(&IpcConfig::new(
        config.ipc.prefix.clone(),
    ))?);
    {
        use shm_ipc::qos;
        let names = endpoint.service_names();
        tracing::info!(
            "iceoryx2 services (each with an event service of the same name): {} \
             (request-response, {} clients), {} (the reserved stop path, request-response, \
             {} clients), {} (publish-subscribe, {} publisher), {} (publish-subscribe, {} \
             subscribers)",
            names.goal,
            qos::GOAL_MAX_CLIENTS,
            names.stop,
            qos::STOP_MAX_CLIENTS,
            names.pose,
            qos::POSE_MAX_PUBLISHERS,
            names.telemetry,
            qos::TELEMETRY_MAX_SUBSCRIBERS
        );
        // What a client needs to pre-check a goal (shm-ipc docs, "Goals").
        let w = &config.ipc.workspace;
        tracing::info!(
            "goal checks: workspace x [{}, {}] y [{}, {}] m (inclusive); footprint: front \
             axle at the goal, rear axle L_f + L_r = {} m behind it (L_f {} m, L_r {} m)",
            w.x_min,
            w.x_max,
            w.y_min,
            w.y_max,
            config.machine.l_f + config.machine.l_r,
            config.machine.l_f,
            config.machine.l_r
        );
    }

    let mut sim_parts = None;
    let bus: Box<dyn CanBus> = match config.can.backend {
        CanBackend::Sim => {
            let (bus, handle, task) = sim::spawn(&config, clock, sim_handle_tx.is_some())?;
            tracing::info!(
                "simulated machine (time scale {}, plant delay {} s)",
                scale,
                config.sim.plant.delay
            );
            if let Some(tx) = sim_handle_tx {
                let _ = tx.send(handle.clone());
            }
            sim_parts = Some((handle, task));
            Box::new(bus)
        }
        CanBackend::Socketcan => {
            let bus = SocketCanBus::open_filtered(&config.can.interface, &[MACHINE_STATE_ID])?;
            tracing::info!("CAN interface {}", config.can.interface);
            Box::new(bus)
        }
    };
    let bus: Box<dyn CanBus> = if config.can.log.as_os_str().is_empty() {
        bus
    } else {
        let name = bus.name().to_owned();
        let writer = CandumpWriter::append_to(&config.can.log, &name).map_err(|e| {
            DaemonError::Io(format!(
                "config key `can.log`: cannot open {}: {e}",
                config.can.log.display()
            ))
        })?;
        Box::new(LoggingBus::new(bus, writer))
    };

    let can_shared = Arc::new(CanShared::default());
    let (cmd_tx, cmd_rx) = mpsc::channel(16);
    let can_task = tokio::spawn(can_io::run(
        bus,
        cmd_rx,
        can_shared.clone(),
        clock,
        CommandGuard::new(&config.machine),
        config.control.can_max_lost,
    ));

    // The site is loaded whole before anything starts; the first tick puts it
    // in force (after the start-up self-test's goal, which knows no site).
    let site = SiteSlot::new(config.site.path().map(Path::to_path_buf));
    if config.site.path().is_some() {
        let text = site.reload(false).map_err(DaemonError::Site)?;
        tracing::info!("{text}");
    }
    let goals = Arc::new(SharedGoals::new(
        config.lifecycle_settings(),
        site,
        config.outline.outline()?,
    ));
    let stats = Arc::new(Mutex::new(LoopStats::new()));
    let ctx = LoopContext {
        config: config.clone(),
        clock,
        endpoint: endpoint.clone(),
        can: can_shared.clone(),
        commands: cmd_tx,
        goals: goals.clone(),
        shutdown: shutdown.0.clone(),
        stats: stats.clone(),
    };
    let (ready_tx, ready_rx) = oneshot::channel::<Result<(), String>>();
    let control = std::thread::Builder::new()
        .name("wlnavd-control".into())
        .spawn(move || -> Option<ExitReason> {
            // No route search runs here: the planner thread plans (a debug
            // build asserts it).
            control::planner::mark_tick_thread();
            let mut controller = match factory() {
                Ok(c) => c,
                Err(e) => {
                    let _ = ready_tx.send(Err(format!("building the controller: {e}")));
                    return None;
                }
            };
            match controller::first_solve(controller.as_mut()) {
                Ok(t) => {
                    tracing::info!("first solve succeeded in {:.2} ms", t.as_secs_f64() * 1e3);
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e.to_string()));
                    return None;
                }
            }
            let mut notifier = Notifier::new();
            notifier.ready("idle: ready for goals");
            let _ = ready_tx.send(Ok(()));
            crate::realtime::setup_tick_thread(&ctx.config.control.realtime);
            Some(ControlLoop::new(ctx, controller, notifier).run())
        })
        .map_err(|e| DaemonError::Io(format!("control thread: {e}")))?;

    let ready = ready_rx.await;
    let startup_error = match ready {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(e),
        Err(_) => Some("control thread ended during start-up".into()),
    };
    if let Some(e) = startup_error {
        let _ = tokio::task::spawn_blocking(move || control.join()).await;
        let _ = can_task.await;
        if let Some((_, task)) = sim_parts {
            let _ = task.await;
        }
        return Err(DaemonError::FirstSolve(e));
    }
    let rss_ready = stats::resident_memory();
    if let Some(interval) = Notifier::watchdog_interval() {
        tracing::info!("systemd watchdog every {:?}", interval);
    }
    tracing::info!(
        "ready: {} Hz loop (1 / mpc.dt), prefix `{}`",
        1.0 / config.period(),
        config.ipc.prefix
    );

    let stop_ipc = Arc::new(Notify::new());
    let ipc_task = tokio::spawn(ipc::serve_goals(
        endpoint.clone(),
        config.goal_validator(),
        goals.clone(),
        shutdown.0.clone(),
        stop_ipc.clone(),
    ));
    let signal_task = handle_signals.then(|| tokio::spawn(wait_for_signals(shutdown.clone())));
    let stats_task = {
        let stats = stats.clone();
        let period = clock.real_duration(30.0);
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(period).await;
                let s = stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
                tracing::info!(
                    "loop: {} ticks, {} overruns, {} envelope overrides; jitter {}; solve {}",
                    s.ticks,
                    s.overruns,
                    s.envelope_overrides,
                    s.jitter(),
                    s.solve()
                );
            }
        })
    };

    let joined = tokio::task::spawn_blocking(move || control.join())
        .await
        .map_err(|e| DaemonError::Panic(e.to_string()))?;
    let exit = match joined {
        Ok(Some(r)) => r,
        Ok(None) => return Err(DaemonError::Panic("control loop did not run".into())),
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            return Err(DaemonError::Panic(msg));
        }
    };
    // The control thread dropped its command sender: the CAN task sends what is
    // queued (ending with the stop) and returns.
    let _ = can_task.await;
    stop_ipc.notify_one();
    let _ = ipc_task.await;
    stats_task.abort();
    if let Some(t) = signal_task {
        t.abort();
    }
    let sim = match sim_parts {
        Some((handle, task)) => {
            let _ = task.await;
            Some(handle.snapshot())
        }
        None => None,
    };
    let stats = stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let rss_warm = stats.rss_warm.or(rss_ready);
    let report = RunReport {
        exit,
        stats,
        commands_sent: can_shared.sent(),
        commands_clamped: can_shared.clamped(),
        goal_requests: (goals.requests(), goals.rejected()),
        rss: (rss_warm, stats::resident_memory()),
        sim,
    };
    tracing::info!("stopped ({:?})", report.exit);
    Ok(report)
}

async fn wait_for_signals(shutdown: ShutdownHandle) {
    use tokio::signal::unix::{signal, SignalKind};
    let (Ok(mut term), Ok(mut int)) = (
        signal(SignalKind::terminate()),
        signal(SignalKind::interrupt()),
    ) else {
        tracing::error!("cannot install signal handlers");
        return;
    };
    tokio::select! {
        _ = term.recv() => tracing::info!("SIGTERM: stopping the machine, then exiting"),
        _ = int.recv() => tracing::info!("SIGINT: stopping the machine, then exiting"),
    }
    shutdown.trigger();
}
