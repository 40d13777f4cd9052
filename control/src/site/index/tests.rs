//! The grid's answers against a linear scan over every feature, on seeded
//! random sites: they must be identical, not merely close.

use super::*;
use crate::site::generate::random_site;
use crate::site::outline::Outline;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The worst clearance by brute force, with the index's tie-break.
fn scan_clearance(site: &Site, circles: &[WorldCircle], cutoff: f64) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (ci, c) in circles.iter().enumerate() {
        let mut consider = |hit: Hit| {
            if hit.clearance < cutoff && best.is_none_or(|b| hit.better_than(&b)) {
                best = Some(hit);
            }
        };
        for (f, feat) in site.features().iter().enumerate() {
            consider(Hit {
                target: Target::Feature(f),
                clearance: feat.shape.clearance(c.center, c.radius),
                circle: ci,
            });
        }
        consider(Hit {
            target: Target::Bounds,
            clearance: -site.bounds().signed_distance(c.center) - c.radius,
            circle: ci,
        });
    }
    best
}

fn scan_nearest(site: &Site, p: P2, radius: f64, k: usize) -> Vec<(usize, f64)> {
    let mut all: Vec<(f64, usize)> = site
        .features()
        .iter()
        .enumerate()
        .map(|(f, feat)| (feat.shape.signed_distance(p), f))
        .filter(|&(d, _)| d <= radius)
        .collect();
    all.sort_by(|a, b| a.partial_cmp(b).unwrap());
    all.into_iter().take(k).map(|(d, f)| (f, d)).collect()
}

fn sites() -> Vec<SiteIndex> {
    [
        (1, 300, 100.0),
        (2, 40, 60.0),
        (3, 1, 30.0),
        (4, 800, 150.0),
    ]
    .into_iter()
    .map(|(seed, n, size)| SiteIndex::new(Site::from_file(random_site(seed, n, size), 0).unwrap()))
    .collect()
}

#[test]
fn clearance_is_identical_to_a_linear_scan() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut hits = [0usize; 3];
    for idx in sites() {
        let size = idx.site().bounds().aabb().max[0];
        for _ in 0..400 {
            let n = rng.gen_range(1..6);
            let circles: Vec<WorldCircle> = (0..n)
                .map(|_| WorldCircle {
                    // Some centres outside the bounds too.
                    center: [
                        rng.gen_range(-5.0..size + 5.0),
                        rng.gen_range(-5.0..size + 5.0),
                    ],
                    radius: rng.gen_range(0.1..1.5),
                })
                .collect();
            for cutoff in [f64::INFINITY, 2.0, 0.0, -0.3] {
                let got = idx.clearance(&circles, cutoff);
                assert_eq!(
                    got,
                    scan_clearance(idx.site(), &circles, cutoff),
                    "cutoff {cutoff}"
                );
                match got.map(|h| h.target) {
                    None => hits[0] += 1,
                    Some(Target::Feature(_)) => hits[1] += 1,
                    Some(Target::Bounds) => hits[2] += 1,
                }
            }
        }
    }
    // Every kind of answer was exercised.
    assert!(hits.iter().all(|&h| h > 50), "{hits:?}");
    // Far outside the grid (rings start where the grid begins), and absurdly far.
    for idx in sites() {
        for center in [[-700.0, 35.0], [2e3, -3e3], [1e12, -1e12], [35.0, 900.0]] {
            let c = [WorldCircle {
                center,
                radius: 0.5,
            }];
            for cutoff in [f64::INFINITY, -1e3] {
                assert_eq!(
                    idx.clearance(&c, cutoff),
                    scan_clearance(idx.site(), &c, cutoff)
                );
            }
            let mut buf = [Near::default(); 3];
            let n = idx.nearest(center, f64::INFINITY, &mut buf);
            let got: Vec<(usize, f64)> = buf[..n]
                .iter()
                .map(|q| (q.feature, q.nearest.distance))
                .collect();
            assert_eq!(got, scan_nearest(idx.site(), center, f64::INFINITY, 3));
        }
    }
}

#[test]
fn nearest_is_identical_to_a_linear_scan() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut buf = [Near::default(); 8];
    let mut full = 0;
    for idx in sites() {
        let size = idx.site().bounds().aabb().max[0];
        for _ in 0..400 {
            let p = [
                rng.gen_range(-5.0..size + 5.0),
                rng.gen_range(-5.0..size + 5.0),
            ];
            for radius in [f64::INFINITY, 3.0, 0.5, 0.0] {
                let k = rng.gen_range(1..=8);
                let n = idx.nearest(p, radius, &mut buf[..k]);
                let got: Vec<(usize, f64)> = buf[..n]
                    .iter()
                    .map(|q| (q.feature, q.nearest.distance))
                    .collect();
                assert_eq!(
                    got,
                    scan_nearest(idx.site(), p, radius, k),
                    "{p:?} r {radius} k {k}"
                );
                full += (n == k) as usize;
            }
        }
    }
    assert!(full > 500);
}

#[test]
fn outline_meets_sees_obstacles_keepouts_and_the_bounds() {
    let text = r#"{ "format": "wlnav-site-v1", "id": "t", "version": 1,
      "bounds": [[-20, -20], [20, -20], [20, 20], [-20, 20]],
      "obstacles": [ { "id": "pile", "polygon": [[3, -1], [5, -1], [5, 1], [3, 1]] } ],
      "keepout": [ { "id": "office", "polygon": [[-1, 6], [1, 6], [1, 8], [-1, 8]] } ] }"#;
    let idx = SiteIndex::new(Site::parse(text.as_bytes()).unwrap());
    let p = MachineParams::default();
    let o = Outline::avant635();
    let name = |h: Option<Hit>| h.map_or("none", |h| idx.name(h.target)).to_string();
    // At the origin heading +x: the bucket (front circle at 0.9 m, r 0.72)
    // reaches 1.62 m; the pile starts at 3 m.
    let x = State::zeros();
    assert_eq!(name(idx.outline_meets(&o, &p, &x, 0.0)), "none");
    // A margin of 1.5 m sees it.
    assert_eq!(name(idx.outline_meets(&o, &p, &x, 1.5)), "pile");
    // 1.5 m further on, the bucket is in the pile.
    let x = State::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.0);
    let hit = idx.outline_meets(&o, &p, &x, 0.0).unwrap();
    assert_eq!(name(Some(hit)), "pile");
    assert!((hit.clearance - (3.0 - 2.4 - 0.72)).abs() < 1e-12);
    // Facing the office: a keep-out.
    let x = State::new(0.0, 5.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0);
    assert_eq!(name(idx.outline_meets(&o, &p, &x, 0.0)), "office");
    // Backing out of the bounds: the counterweight is past x = −20.
    let x = State::new(-17.8, 0.0, 0.0, 0.0, 0.0, 0.0);
    assert_eq!(name(idx.outline_meets(&o, &p, &x, 0.0)), "bounds");
    // Today's axle circles at the same pose do not leave the bounds.
    let axles = Outline::axle_circles(0.65).unwrap();
    assert_eq!(name(idx.outline_meets(&axles, &p, &x, 0.0)), "none");
}

#[test]
fn memory_stays_within_the_stated_bound() {
    for idx in sites() {
        let (cell, nx, ny) = idx.grid();
        assert!(cell > 0.0 && nx * ny <= MAX_CELLS);
        assert!(
            idx.memory_bytes()
                <= 4 * (MAX_CELLS + 1 + MAX_ENTRIES) + 32 * idx.site().features().len()
        );
    }
    // One feature over a huge bounds with many tiny others: still bounded.
    let mut f = random_site(5, 2000, 100.0);
    f.bounds = vec![[0.0, 0.0], [1e5, 0.0], [1e5, 1e5], [0.0, 1e5]];
    f.obstacles.push(crate::site::ObstacleEntry {
        id: "everything".into(),
        circle: Some([5e4, 5e4, 4.9e4]),
        ..Default::default()
    });
    let idx = SiteIndex::new(Site::from_file(f, 0).unwrap());
    let (_, nx, ny) = idx.grid();
    assert!(nx * ny <= MAX_CELLS && idx.items.len() <= MAX_ENTRIES);
}
