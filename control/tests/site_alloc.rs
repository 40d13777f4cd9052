//! The site's queries allocate nothing after load (DESIGN §17: the tick stays
//! allocation-free): clearance, outline_meets, nearest, the outline's
//! placement. One test in this binary, so no other test thread allocates
//! while we count (the counter is per thread anyway).

mod common;

use control::model::{MachineParams, State};
use control::site::generate::large_pit;
use control::site::{Near, Outline, Site, SiteIndex, WorldCircle, MAX_OUTLINE_CIRCLES};

#[global_allocator]
static GLOBAL: common::CountingAllocator = common::CountingAllocator;

#[test]
fn queries_do_not_allocate() {
    let idx =
        SiteIndex::new(Site::parse(large_pit(40, 520).to_json().as_bytes()).expect("valid pit"));
    let p = MachineParams::default();
    let outline = Outline::avant635();
    let mut buf = [WorldCircle::default(); MAX_OUTLINE_CIRCLES];
    let mut near = [Near::default(); 8];
    let poses: Vec<State> = (0..200)
        .map(|k| {
            let t = k as f64;
            State::new(
                60.0 + 1.5 * t,
                40.0 + 1.1 * t,
                0.1 * t,
                0.5 * (0.3 * t).sin(),
                0.0,
                0.0,
            )
        })
        .collect();
    let before = common::allocations();
    let mut seen = (0, 0);
    for x in &poses {
        let n = outline.place(&p, x, &mut buf);
        if idx.clearance(&buf[..n], f64::INFINITY).is_some() {
            seen.0 += 1;
        }
        if idx.outline_meets(&outline, &p, x, 0.5).is_some() {
            seen.1 += 1;
        }
        idx.nearest([x[0], x[1]], 15.0, &mut near);
        let _ = outline.world_circles(&p, x).count();
    }
    assert_eq!(common::allocations() - before, 0);
    // The queries did something: every pose has a worst clearance, and some
    // pass near a feature.
    assert_eq!(seen.0, poses.len());
    assert!(seen.1 > 0 && seen.1 < poses.len(), "{seen:?}");
}
