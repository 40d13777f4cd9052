//! The site layer on the generated large pit (DESIGN §17, issue 40: ≥ 500
//! features): load (parse + validate) and index build, and the queries the
//! envelope, the MPC and the planner make per outline.
//! `cargo bench -p control --bench site`; figures go into the report.

use std::hint::black_box;

use control::model::{MachineParams, State};
use control::site::generate::{large_pit, random_site};
use control::site::{Near, Outline, Site, SiteIndex, WorldCircle, MAX_OUTLINE_CIRCLES};
use criterion::{criterion_group, criterion_main, Criterion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn site(c: &mut Criterion) {
    let text = large_pit(40, 520).to_json();
    let bytes = text.as_bytes();
    let idx = SiteIndex::new(Site::parse(bytes).expect("valid pit"));
    println!(
        "large pit: {} features, {} bytes of JSON, grid {:?}, index {} bytes",
        idx.site().features().len(),
        bytes.len(),
        idx.grid(),
        idx.memory_bytes()
    );
    let p = MachineParams::default();
    let outline = Outline::avant635();
    // Poses all over the pit, headings and articulations at random.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let poses: Vec<State> = (0..1024)
        .map(|_| {
            State::new(
                rng.gen_range(60.0..360.0),
                rng.gen_range(40.0..260.0),
                rng.gen_range(-3.1..3.1),
                rng.gen_range(-0.6..0.6),
                0.0,
                0.0,
            )
        })
        .collect();

    let mut group = c.benchmark_group("site");
    // Short runs: the machine is shared; 20 queries' spread is in the output.
    group.warm_up_time(std::time::Duration::from_secs(1));
    group.measurement_time(std::time::Duration::from_secs(3));
    group.bench_function("load+index (large pit)", |b| {
        b.iter(|| SiteIndex::new(Site::parse(black_box(bytes)).expect("valid")))
    });
    group.bench_function("parse+validate (large pit)", |b| {
        b.iter(|| Site::parse(black_box(bytes)).expect("valid"))
    });
    // Near the loader's limits: 20 000 features (MAX_FEATURES), ~85 000
    // vertices, overlapping at random over 1 km².
    let big = random_site(7, 20_000, 1000.0).to_json();
    let big_idx = SiteIndex::new(Site::parse(big.as_bytes()).expect("valid random site"));
    println!(
        "random site: {} features, {} bytes of JSON, grid {:?}, index {} bytes",
        big_idx.site().features().len(),
        big.len(),
        big_idx.grid(),
        big_idx.memory_bytes()
    );
    group.sample_size(10);
    group.bench_function("load+index (20 000 random features)", |b| {
        b.iter(|| SiteIndex::new(Site::parse(black_box(big.as_bytes())).expect("valid")))
    });
    group.sample_size(100);
    let site = Site::parse(bytes).expect("valid");
    group.bench_function("index build (large pit)", |b| {
        b.iter(|| SiteIndex::new(black_box(site.clone())))
    });
    let mut k = 0;
    let mut buf = [WorldCircle::default(); MAX_OUTLINE_CIRCLES];
    group.bench_function("outline clearance, exact (Avant 635, 5 circles)", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            let n = outline.place(&p, &poses[k], &mut buf);
            idx.clearance(black_box(&buf[..n]), f64::INFINITY)
        })
    });
    group.bench_function("outline meets, margin 0.3 m (Avant 635)", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            idx.outline_meets(&outline, &p, black_box(&poses[k]), 0.3)
        })
    });
    let mut near = [Near::default(); 8];
    group.bench_function("8 nearest within 10 m", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            idx.nearest(black_box([poses[k][0], poses[k][1]]), 10.0, &mut near)
        })
    });
    // Cell sizes side by side (same process, same load): what `new`'s
    // choice (the median feature extent) is measured against.
    for cell in [2.0, 4.7, 8.0, 16.0, 32.0] {
        let other = SiteIndex::with_cell(site.clone(), cell);
        group.bench_function(format!("outline meets, margin 0.3 m, cell {cell} m"), |b| {
            b.iter(|| {
                k = (k + 1) % poses.len();
                other.outline_meets(&outline, &p, black_box(&poses[k]), 0.3)
            })
        });
        group.bench_function(format!("8 nearest within 10 m, cell {cell} m"), |b| {
            b.iter(|| {
                k = (k + 1) % poses.len();
                other.nearest(black_box([poses[k][0], poses[k][1]]), 10.0, &mut near)
            })
        });
    }
    // The linear scan the index replaces, for scale.
    group.bench_function("outline clearance, linear scan", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            let n = outline.place(&p, &poses[k], &mut buf);
            buf[..n]
                .iter()
                .flat_map(|c| {
                    site.features()
                        .iter()
                        .map(move |f| f.shape.clearance(c.center, c.radius))
                })
                .fold(f64::INFINITY, f64::min)
        })
    });
    group.finish();
}

criterion_group!(benches, site);
criterion_main!(benches);
