//! Soak/benchmark: the loop runs for many ticks against the simulated machine in
//! accelerated time, driving back and forth between two goals, and reports tick
//! start jitter (median, p99, max), solve time, resident memory and the live heap
//! after warm-up and at the end; the heap must not grow.
//!
//! Memory is the live heap of this test executable (every allocation through Rust's
//! global allocator, counted by [`LiveHeap`]: the in-process daemon's, its tokio
//! runtime's, iceoryx2's, the controller's), not the resident set: under qemu-user
//! `/proc/self/statm` is the emulator's process, whose own memory grew by 2.5 MB in a
//! loaded run while the daemon's did not (README, "The Jetson"). The daemon's resident
//! memory is still printed. [`a_leak_in_the_loop_fails_the_heap_check`] checks that the
//! check sees a leak.
//!
//! The short run (1,000 ticks) is part of the suite; the full 10,000-tick run is
//! `cargo test -p daemon --release --test soak -- --ignored --nocapture`
//! (or `wlnavd --sim --cost quadratic --time-scale 20 --max-ticks 10000`
//! with goals from `wlnav`).

#[path = "e2e/common.rs"]
mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use common::*;
use control::VelocityCommand;
use shm_ipc::Pose2;
use wlnav_test_kit::controller::{Forwarding, Hooks};
use wlnavd::controller::{load_controller, Controller, ControllerFactory};
use wlnavd::stats::LoopStats;

/// Rust's global allocator with a count of the bytes allocated and not yet freed, by the
/// threads that count (all but a run's client thread: [`soak`]).
struct LiveHeap;

static LIVE_BYTES: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    // Const-initialised and without a destructor: reading it never allocates.
    static UNCOUNTED: Cell<bool> = const { Cell::new(false) };
}

fn counted() -> bool {
    // `try_with`: a thread being torn down may still allocate.
    !UNCOUNTED.try_with(Cell::get).unwrap_or(false)
}

#[global_allocator]
static HEAP: LiveHeap = LiveHeap;

// SAFETY: every call is passed to `System` unchanged; the count is only arithmetic.
unsafe impl GlobalAlloc for LiveHeap {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() && counted() {
            LIVE_BYTES.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() && counted() {
            LIVE_BYTES.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        if counted() {
            LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
        }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() && counted() {
            LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
            LIVE_BYTES.fetch_add(new_size, Ordering::Relaxed);
        }
        p
    }
}

/// How much the live heap may grow between warm-up and the end of a run [bytes].
const HEAP_GROWTH_ALLOWED: usize = 64 * 1024;

/// Ticks over which the heap's low point is taken, after warm-up and before the end.
const WINDOW: u64 = 100;

/// One run at a time: the heap count is the whole executable's.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The live heap's low point in the window after the daemon's warm-up (ticks 100-199) and in the
/// window before the daemon stops (the last 100 ticks but the final 20, which may see
/// its shutdown), taken every 20 ms with the tick of the newest telemetry. The low
/// point of a window leaves out what a tick, a goal or the telemetry allocate for a
/// moment; what is left and grows is a leak.
struct HeapWindows {
    warm: usize,
    end: usize,
}

impl HeapWindows {
    fn growth(&self) -> isize {
        self.end as isize - self.warm as isize
    }
}

/// Runs the daemon for `ticks` ticks at `time_scale` (divided by `WLNAV_TIMING_SCALE`),
/// alternating two goals; returns the run's report and the heap's windows.
fn soak(
    ticks: u64,
    time_scale: f64,
    controller: Option<ControllerFactory>,
) -> (wlnavd::RunReport, HeapWindows, wlnavd::config::Config) {
    assert!(ticks >= 3 * WINDOW, "too short for the heap's windows");
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    // This thread is the client (goals, telemetry): what it allocates is not the daemon's.
    UNCOUNTED.with(|c| c.set(true));
    // On a slower CPU (WLNAV_TIMING_SCALE) the daemon's clock runs slower by that factor.
    let time_scale = timing_scale::daemon_time_scale(time_scale);
    let mut config = sim_config("soak");
    config.sim.time_scale = time_scale;
    config.control.max_ticks = ticks;
    let d = start(config.clone(), controller);
    d.goal(5.0, 0.0, 0.0);
    // Alternate goals every 15 daemon seconds until the daemon stops by itself.
    let leg = Duration::from_secs_f64(15.0 / time_scale);
    let goals = [Pose2::new(0.0, 0.0, 0.0), Pose2::new(5.0, 0.0, 0.0)];
    let mut i = 0;
    let mut next = Instant::now() + leg;
    let warm = LoopStats::WARM_TICK..LoopStats::WARM_TICK + WINDOW;
    let end = ticks - WINDOW..ticks - 20;
    let (mut heap_warm, mut heap_end) = (usize::MAX, usize::MAX);
    let mut tick = 0;
    let report;
    let mut d = Some(d);
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let running = d.as_mut().unwrap();
        if running.thread.as_ref().unwrap().is_finished() {
            report = running.thread.take().unwrap().join().unwrap().unwrap();
            break;
        }
        while let Some(t) = running.telemetry.try_recv().unwrap() {
            tick = t.tick;
        }
        let live = LIVE_BYTES.load(Ordering::Relaxed);
        if warm.contains(&tick) {
            heap_warm = heap_warm.min(live);
        } else if end.contains(&tick) {
            heap_end = heap_end.min(live);
        }
        if Instant::now() > next {
            let _ = running.client.set_goal(
                goals[i % 2],
                &[],
                timing_scale::real(Duration::from_secs(1)),
            );
            i += 1;
            next += leg;
        }
    }
    drop(d);
    assert!(
        heap_warm != usize::MAX && heap_end != usize::MAX,
        "no heap sample after warm-up ({warm:?}) or before the end ({end:?}): \
         the telemetry's ticks were not seen"
    );
    let heap = HeapWindows {
        warm: heap_warm,
        end: heap_end,
    };
    println!(
        "soak: {ticks} ticks at time scale {time_scale}\n{}\n\
         live heap (low point of ticks {warm:?} / {end:?}): {:.1} KiB / {:.1} KiB, grew by {:.1} KiB",
        report.summary(),
        heap.warm as f64 / 1024.0,
        heap.end as f64 / 1024.0,
        heap.growth() as f64 / 1024.0,
    );
    (report, heap, config)
}

/// The soak's checks: every tick ran, commands in bounds, no heap growth, few overruns.
fn check(ticks: u64, time_scale: f64) {
    let (report, heap, config) = soak(ticks, time_scale, None);
    check_commands(&report, &config.machine);
    assert!(report.stats.ticks >= ticks);
    assert!(report.stats.solve().count > 0, "the MPC never ran");
    assert!(
        heap.growth() <= HEAP_GROWTH_ALLOWED as isize,
        "the live heap grew from {} to {} bytes after warm-up (allowed: {HEAP_GROWTH_ALLOWED})",
        heap.warm,
        heap.end
    );
    // Timing: on a loaded 2-core machine a few late ticks are tolerated, not many.
    assert!(
        report.stats.overruns * 100 <= ticks,
        "{} overruns in {ticks} ticks",
        report.stats.overruns
    );
}

#[test]
fn soak_1000_ticks() {
    check(1000, 10.0);
}

#[test]
#[ignore = "long: 10,000 ticks (about 100 s); run with --ignored"]
fn soak_10000_ticks() {
    check(10_000, 20.0);
}

/// Hooks on the daemon's controller, leaking `bytes` on every tick; every call reaches
/// the controller (the kit's wrapper forwards it).
struct Leaking {
    bytes: usize,
}

impl Hooks for Leaking {
    fn sent(&mut self, inner: &mut dyn Controller, now: f64, command: VelocityCommand) {
        // Written, so that it is resident too.
        std::hint::black_box(Vec::leak(vec![1u8; self.bytes]));
        inner.sent(now, command)
    }
}

/// The heap check sees a leak of 4 KiB a tick, i.e. 400 KiB between its windows
/// (more than [`HEAP_GROWTH_ALLOWED`]), in a shorter run.
#[test]
fn a_leak_in_the_loop_fails_the_heap_check() {
    const LEAK: usize = 4096;
    let inner = load_controller(&sim_config("soak")).unwrap();
    let factory: ControllerFactory = Box::new(move || {
        Ok(Box::new(Forwarding::new(inner()?, Leaking { bytes: LEAK })) as Box<dyn Controller>)
    });
    let (report, heap, _) = soak(3 * WINDOW, 10.0, Some(factory));
    assert!(report.stats.ticks >= 3 * WINDOW);
    assert!(
        heap.growth() > HEAP_GROWTH_ALLOWED as isize,
        "a leak of {LEAK} bytes a tick: the heap grew by {} bytes only",
        heap.growth()
    );
    // Between the windows' low points lie at least 100 - 20 ticks of leaks.
    assert!(
        heap.growth() >= (LEAK * 80) as isize,
        "a leak of {LEAK} bytes a tick: the heap grew by {} bytes only",
        heap.growth()
    );
}
