//! Shared helpers for the control crate's integration tests.
#![allow(dead_code)]

use control::mlp::PAPER_HIDDEN;
use control::weights::{random_network, NetworkMetadata, NetworkRole, NetworkWeights};
use control::{Actor, Critic};

/// A random critic of the paper's sizes with `m` outputs.
pub fn random_critic_weights(m: usize, seed: u64) -> NetworkWeights {
    random_network(
        NetworkMetadata::new(NetworkRole::Critic, m),
        &PAPER_HIDDEN,
        seed,
    )
}

pub fn random_critic(m: usize, seed: u64) -> Critic {
    Critic::from_weights(random_critic_weights(m, seed)).expect("random critic is valid")
}

pub fn random_actor(seed: u64) -> Actor {
    let w = random_network(
        NetworkMetadata::new(NetworkRole::Actor, 4),
        &PAPER_HIDDEN,
        seed,
    );
    Actor::from_weights(w).expect("random actor is valid")
}

/// A global allocator that counts allocations, for the allocation-free tests.
/// Each such test binary installs it with
/// `#[global_allocator] static GLOBAL: common::CountingAllocator = common::CountingAllocator;`
/// and holds a single test. It counts per thread: the test harness's own
/// threads may allocate while a test counts (4 allocations in CI under load).
pub struct CountingAllocator;

thread_local! {
    // Const-initialised and without a destructor: reading it never allocates.
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Allocations (and reallocations) so far on the calling thread.
pub fn allocations() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

fn count() {
    // `try_with`: a thread being torn down may still allocate.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        count();
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}
