//! Optional real-time set-up of the tick thread (`[loop.realtime]`, DESIGN §13):
//! `SCHED_FIFO` at a configured priority, `mlockall(MCL_CURRENT | MCL_FUTURE)`, and
//! pinning to one CPU.
//!
//! Nothing here can stop the daemon: every step the system refuses (no
//! `CAP_SYS_NICE` and `RLIMIT_RTPRIO` below the priority, systemd's
//! `RestrictRealtime=yes`, a cgroup without real-time budget, no `CAP_IPC_LOCK` and a
//! finite `RLIMIT_MEMLOCK`, a CPU outside the allowed set) is logged as a warning that
//! says what to change, and the loop runs with the ordinary scheduler.
//!
//! The decisions are pure functions ([`plan_mlock`], [`refusal_advice`]) so tests
//! reach them without privileges; [`setup_tick_thread`] does the system calls, which
//! exist only on Linux (elsewhere it logs that real-time set-up is unsupported).
//!
//! `mlockall` is skipped, not attempted, when `RLIMIT_MEMLOCK` is finite and the
//! process lacks `CAP_IPC_LOCK`: with `MCL_FUTURE` every later mapping (a thread
//! stack, a shared-memory segment, a `malloc` arena) would then fail with `ENOMEM`
//! once the limit is reached, which turns a scheduling nicety into a crash.

use serde::{Deserialize, Serialize};

/// `[loop.realtime]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeConfig {
    /// Try the real-time set-up for the tick thread. Default false.
    pub enabled: bool,
    /// `SCHED_FIFO` priority of the tick thread, 1–99. Default 40: above every
    /// ordinary process, below the threaded interrupt handlers of a PREEMPT_RT kernel
    /// (50), so the CAN controller's interrupt still preempts the loop.
    pub priority: i32,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page faults in the loop. Default true.
    pub lock_memory: bool,
    /// Pin the tick thread to this CPU (index as in `/proc/cpuinfo`); absent = no
    /// pinning. Default absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpu: Option<usize>,
}

impl Default for RealtimeConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            priority: 40,
            lock_memory: true,
            cpu: None,
        }
    }
}

/// Lowest and highest `SCHED_FIFO` priority on Linux.
pub const PRIORITY_RANGE: std::ops::RangeInclusive<i32> = 1..=99;

impl RealtimeConfig {
    /// Checks the values; the error is `(key under loop.realtime, message)`. The CPU
    /// index is checked against the CPUs this process may run on, on this machine
    /// (so `--check-config` on the target catches a CPU it does not have).
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !PRIORITY_RANGE.contains(&self.priority) {
            return Err((
                "priority",
                format!(
                    "must be a SCHED_FIFO priority from {} to {} (got {})",
                    PRIORITY_RANGE.start(),
                    PRIORITY_RANGE.end(),
                    self.priority
                ),
            ));
        }
        if let Some(cpu) = self.cpu {
            let allowed = allowed_cpus();
            if !allowed.is_empty() && !allowed.contains(&cpu) {
                return Err((
                    "cpu",
                    format!(
                        "CPU {cpu} does not exist or is not available to this process \
                         (available: {})",
                        cpu_list(&allowed)
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// `[0, 1, 2, 5]` → `"0-2, 5"`.
fn cpu_list(cpus: &[usize]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < cpus.len() {
        let mut j = i;
        while j + 1 < cpus.len() && cpus[j + 1] == cpus[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            cpus[i].to_string()
        } else {
            format!("{}-{}", cpus[i], cpus[j])
        });
        i = j + 1;
    }
    parts.join(", ")
}

/// The CPUs this process may run on (its affinity mask); empty if unknown.
#[cfg(target_os = "linux")]
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: cpu_set_t is plain data; sched_getaffinity writes at most its size.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return Vec::new();
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

/// The CPUs this process may run on; empty if unknown.
#[cfg(not(target_os = "linux"))]
pub fn allowed_cpus() -> Vec<usize> {
    Vec::new()
}

/// One step of the set-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// `pthread_setschedparam(SCHED_FIFO)`.
    Fifo,
    /// `mlockall`.
    LockMemory,
    /// `sched_setaffinity` of the tick thread.
    Pin,
}

/// What the system lets this process do, as far as it can be read beforehand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Privileges {
    /// `RLIMIT_MEMLOCK` soft limit [bytes]; None = unlimited.
    pub memlock_limit: Option<u64>,
    /// `CAP_IPC_LOCK` in the effective set.
    pub cap_ipc_lock: bool,
}

/// Whether to call `mlockall`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MlockPlan {
    /// Not configured.
    Off,
    /// Safe to call: the limit cannot bite later.
    Lock,
    /// Skipped, with the warning to log.
    Skip(String),
}

/// Decides about `mlockall` (see the module documentation for why a finite limit
/// without `CAP_IPC_LOCK` means skip).
pub fn plan_mlock(config: &RealtimeConfig, p: Privileges) -> MlockPlan {
    if !config.enabled || !config.lock_memory {
        return MlockPlan::Off;
    }
    match p.memlock_limit {
        None => MlockPlan::Lock,
        Some(_) if p.cap_ipc_lock => MlockPlan::Lock,
        Some(limit) => MlockPlan::Skip(format!(
            "real-time: not locking memory (mlockall): RLIMIT_MEMLOCK is {} KiB and the \
             process lacks CAP_IPC_LOCK; with MCL_FUTURE later allocations would fail once \
             the limit is reached. Set LimitMEMLOCK=infinity in the unit (see \
             systemd/wlnavd.service.d/realtime.conf) or loop.realtime.lock_memory = false",
            limit / 1024
        )),
    }
}

/// The warning for a step the system refused with `errno`: what was refused, why
/// that usually happens, what to change. The daemon goes on either way.
pub fn refusal_advice(step: Step, errno: i32, config: &RealtimeConfig) -> String {
    let err = std::io::Error::from_raw_os_error(errno);
    let what = match step {
        Step::Fifo => format!(
            "SCHED_FIFO priority {} for the tick thread",
            config.priority
        ),
        Step::LockMemory => "mlockall(MCL_CURRENT | MCL_FUTURE)".to_owned(),
        Step::Pin => format!("pinning the tick thread to CPU {}", config.cpu.unwrap_or(0)),
    };
    let hint = match (step, errno) {
        (Step::Fifo, libc::EPERM) => format!(
            "the process needs CAP_SYS_NICE or RLIMIT_RTPRIO >= {} (systemd: LimitRTPRIO={} \
             and RestrictRealtime=no, as in systemd/wlnavd.service.d/realtime.conf); in a \
             cgroup with its own real-time budget (CONFIG_RT_GROUP_SCHED) that budget must \
             be > 0",
            config.priority, config.priority
        ),
        (Step::Fifo, libc::EINVAL) => "the priority is outside the system's range".to_owned(),
        (Step::LockMemory, libc::ENOMEM) | (Step::LockMemory, libc::EPERM) => {
            "the process needs CAP_IPC_LOCK or LimitMEMLOCK=infinity".to_owned()
        }
        (Step::LockMemory, libc::EAGAIN) => {
            "some memory could not be locked (try again with more free memory)".to_owned()
        }
        (Step::Pin, libc::EINVAL) => {
            "the CPU is not in this process's allowed set (cpuset, CPUAffinity=)".to_owned()
        }
        (Step::Pin, libc::EPERM) => "not permitted to change the affinity".to_owned(),
        _ => "unexpected error".to_owned(),
    };
    format!("real-time: {what} refused ({err}): {hint}; running with the normal scheduler")
}

/// What [`setup_tick_thread`] achieved.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RealtimeReport {
    /// `SCHED_FIFO` was set.
    pub fifo: bool,
    /// Memory is locked.
    pub memory_locked: bool,
    /// The thread is pinned.
    pub pinned: bool,
    /// The warnings logged.
    pub warnings: Vec<String>,
}

impl RealtimeReport {
    fn warn(&mut self, message: String) {
        tracing::warn!("{message}");
        self.warnings.push(message);
    }
}

/// Applies `config` to the calling thread (the tick thread) and the process's
/// memory; logs what it did and every refusal. Never fails.
pub fn setup_tick_thread(config: &RealtimeConfig) -> RealtimeReport {
    let mut report = RealtimeReport::default();
    if !config.enabled {
        return report;
    }
    imp::apply(config, &mut report);
    if report.warnings.is_empty() {
        tracing::info!(
            "real-time: tick thread SCHED_FIFO priority {}{}{}",
            config.priority,
            if report.memory_locked {
                ", memory locked"
            } else {
                ""
            },
            match config.cpu {
                Some(c) if report.pinned => format!(", pinned to CPU {c}"),
                _ => String::new(),
            }
        );
    }
    report
}

#[cfg(target_os = "linux")]
mod imp {
    use super::*;

    fn errno() -> i32 {
        std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
    }

    /// `CAP_IPC_LOCK` (bit 14) in `CapEff` of `/proc/self/status`.
    fn has_cap_ipc_lock() -> bool {
        const CAP_IPC_LOCK: u32 = 14;
        std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix("CapEff:"))
                    .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
            })
            .is_some_and(|caps| caps & (1 << CAP_IPC_LOCK) != 0)
    }

    fn privileges() -> Privileges {
        // SAFETY: getrlimit writes into the struct we own.
        let limit = unsafe {
            let mut r: libc::rlimit = std::mem::zeroed();
            if libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut r) == 0 {
                (r.rlim_cur != libc::RLIM_INFINITY).then_some(r.rlim_cur as u64)
            } else {
                Some(0)
            }
        };
        Privileges {
            memlock_limit: limit,
            cap_ipc_lock: has_cap_ipc_lock(),
        }
    }

    pub(super) fn apply(config: &RealtimeConfig, report: &mut RealtimeReport) {
        // Pin first: the FIFO thread then never migrates.
        if let Some(cpu) = config.cpu {
            // SAFETY: cpu_set_t is plain data; CPU_SET checks the index against its size
            // (validated < CPU_SETSIZE by the configuration: it is an allowed CPU).
            let rc = unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                if cpu < libc::CPU_SETSIZE as usize {
                    libc::CPU_SET(cpu, &mut set);
                }
                // pid 0 = the calling thread.
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
            };
            if rc == 0 {
                report.pinned = true;
            } else {
                report.warn(refusal_advice(Step::Pin, errno(), config));
            }
        }
        match plan_mlock(config, privileges()) {
            MlockPlan::Off => {}
            MlockPlan::Skip(w) => report.warn(w),
            MlockPlan::Lock => {
                // SAFETY: mlockall has no memory-safety preconditions.
                if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
                    report.memory_locked = true;
                } else {
                    report.warn(refusal_advice(Step::LockMemory, errno(), config));
                }
            }
        }
        // Zeroed, then the one field: some libcs (musl) have more fields.
        // SAFETY: sched_param is plain data.
        let mut param: libc::sched_param = unsafe { std::mem::zeroed() };
        param.sched_priority = config.priority;
        // SAFETY: pthread_self() is this live thread; param outlives the call.
        let rc =
            unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        // pthread functions return the error number instead of setting errno.
        if rc == 0 {
            report.fifo = true;
        } else {
            report.warn(refusal_advice(Step::Fifo, rc, config));
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    use super::*;

    pub(super) fn apply(_config: &RealtimeConfig, report: &mut RealtimeReport) {
        report.warn(
            "real-time: loop.realtime is only implemented on Linux; running with the normal \
             scheduler"
                .to_owned(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on() -> RealtimeConfig {
        RealtimeConfig {
            enabled: true,
            ..Default::default()
        }
    }

    #[test]
    fn priority_range_is_checked() {
        for p in [0, 100, -1] {
            let c = RealtimeConfig {
                priority: p,
                ..on()
            };
            let (key, msg) = c.validate().unwrap_err();
            assert_eq!(key, "priority");
            assert!(msg.contains("1 to 99"), "{msg}");
        }
        for p in [1, 50, 99] {
            RealtimeConfig {
                priority: p,
                ..on()
            }
            .validate()
            .unwrap();
        }
    }

    #[test]
    fn cpu_must_be_available() {
        let allowed = allowed_cpus();
        if allowed.is_empty() {
            return;
        }
        RealtimeConfig {
            cpu: Some(allowed[0]),
            ..on()
        }
        .validate()
        .unwrap();
        let (key, msg) = RealtimeConfig {
            cpu: Some(100_000),
            ..on()
        }
        .validate()
        .unwrap_err();
        assert_eq!(key, "cpu");
        assert!(
            msg.contains("CPU 100000") && msg.contains("available"),
            "{msg}"
        );
    }

    #[test]
    fn cpu_lists_are_compact() {
        assert_eq!(cpu_list(&[0, 1, 2, 5, 7, 8]), "0-2, 5, 7-8");
        assert_eq!(cpu_list(&[3]), "3");
    }

    #[test]
    fn mlock_only_when_the_limit_cannot_bite() {
        let limited = Privileges {
            memlock_limit: Some(8 << 20),
            cap_ipc_lock: false,
        };
        let unlimited = Privileges {
            memlock_limit: None,
            cap_ipc_lock: false,
        };
        let capable = Privileges {
            memlock_limit: Some(8 << 20),
            cap_ipc_lock: true,
        };
        assert_eq!(plan_mlock(&on(), unlimited), MlockPlan::Lock);
        assert_eq!(plan_mlock(&on(), capable), MlockPlan::Lock);
        match plan_mlock(&on(), limited) {
            MlockPlan::Skip(w) => assert!(w.contains("LimitMEMLOCK=infinity"), "{w}"),
            other => panic!("{other:?}"),
        }
        let off = RealtimeConfig {
            lock_memory: false,
            ..on()
        };
        assert_eq!(plan_mlock(&off, unlimited), MlockPlan::Off);
        assert_eq!(
            plan_mlock(&RealtimeConfig::default(), unlimited),
            MlockPlan::Off
        );
    }

    #[test]
    fn refusals_say_what_to_change() {
        let c = RealtimeConfig {
            priority: 80,
            cpu: Some(1),
            ..on()
        };
        let w = refusal_advice(Step::Fifo, libc::EPERM, &c);
        assert!(w.contains("SCHED_FIFO priority 80"), "{w}");
        assert!(
            w.contains("LimitRTPRIO=80") && w.contains("RestrictRealtime=no"),
            "{w}"
        );
        assert!(w.contains("normal scheduler"), "{w}");
        let w = refusal_advice(Step::LockMemory, libc::ENOMEM, &c);
        assert!(w.contains("CAP_IPC_LOCK"), "{w}");
        let w = refusal_advice(Step::Pin, libc::EINVAL, &c);
        assert!(w.contains("CPU 1"), "{w}");
    }

    #[test]
    fn disabled_does_nothing() {
        let r = setup_tick_thread(&RealtimeConfig::default());
        assert_eq!(r, RealtimeReport::default());
    }
}
