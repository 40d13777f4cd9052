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
/// and holds a single test, so no other test thread allocates while it counts.
pub struct CountingAllocator;

static ALLOCATIONS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Allocations (and reallocations) so far in this process.
pub fn allocations() -> usize {
    ALLOCATIONS.load(std::sync::atomic::Ordering::SeqCst)
}

unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}
