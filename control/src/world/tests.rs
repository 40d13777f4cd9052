//! The world's answers against independent computations: the pre-site
//! footprint (default outline, goal circles), a linear scan over the site's
//! features, and finite differences of the rows.

use super::*;
use crate::obstacle::footprint_clearance;
use crate::site::generate::random_site;
use crate::site::Site;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_state(rng: &mut ChaCha8Rng, size: f64) -> State {
    State::new(
        rng.gen_range(0.0..size),
        rng.gen_range(0.0..size),
        rng.gen_range(-3.2..3.2),
        rng.gen_range(-0.7..0.7),
        0.0,
        0.0,
    )
}

fn random_circles(rng: &mut ChaCha8Rng, size: f64, n: usize) -> Vec<Obstacle> {
    (0..n)
        .map(|_| {
            Obstacle::new(
                rng.gen_range(0.0..size),
                rng.gen_range(0.0..size),
                rng.gen_range(0.3..2.0),
            )
        })
        .collect()
}

fn site(seed: u64, n: usize, size: f64) -> Arc<SiteIndex> {
    Arc::new(SiteIndex::new(
        Site::from_file(random_site(seed, n, size), 0).unwrap(),
    ))
}

/// With the default outline and no site, the clearance is the pre-site
/// footprint's (both axle points against the wire's inflated circles),
/// bit for bit: the figures measured before the site keep their meaning.
#[test]
fn the_default_outline_reproduces_the_axle_footprint_exactly() {
    let p = MachineParams::default();
    let mut w = World::with_axle_circles(p, 8);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..2000 {
        let n = rng.gen_range(1..=8);
        let circles = random_circles(&mut rng, 10.0, n);
        w.set_circles(&circles).unwrap();
        let x = random_state(&mut rng, 10.0);
        assert_eq!(w.clearance(&x), footprint_clearance(&p, &x, &circles));
        // And each row's value is the axle point's clearance.
        for j in 0..circles.len() {
            for (a, point) in crate::obstacle::AxlePoint::ALL.iter().enumerate() {
                let (h, g) = w.row(&x, a, Target::Circle(j));
                let (h0, g0) = circles[j].point_clearance(&p, *point, &x);
                assert_eq!(h, h0);
                for k in 0..4 {
                    assert!((g[k] - g0[k]).abs() < 1e-15, "{g:?} {g0:?}");
                }
            }
        }
    }
}

/// The least excess with per-circle margins against a scan over every
/// feature, the bounds and the circles; its target is the scan's.
#[test]
fn excess_is_a_linear_scans() {
    let p = MachineParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for (seed, n, size) in [(1, 200, 60.0), (2, 30, 30.0)] {
        let idx = site(seed, n, size);
        for outline in [default_outline(), Outline::avant635()] {
            let mut w = World::new(p, outline.clone(), 8);
            w.set_site(Some(idx.clone()));
            let margins: Vec<f64> = (0..outline.len()).map(|i| 0.05 + 0.01 * i as f64).collect();
            for _ in 0..300 {
                let k = rng.gen_range(0..4);
                let circles = random_circles(&mut rng, size, k);
                w.set_circles(&circles).unwrap();
                let x = random_state(&mut rng, size);
                let placed = w.place(&x);
                let mut scan = f64::INFINITY;
                for (i, c) in placed[..outline.len()].iter().enumerate() {
                    for f in idx.site().features() {
                        scan = scan.min(f.shape.clearance(c.center, c.radius) - margins[i]);
                    }
                    scan = scan.min(
                        -idx.site().bounds().signed_distance(c.center) - c.radius - margins[i],
                    );
                    for o in &circles {
                        let phys = o.radius - outline.half_width();
                        let d = (c.center[0] - o.x).hypot(c.center[1] - o.y);
                        scan = scan.min(d - phys - c.radius - margins[i]);
                    }
                }
                let got = w.excess(&x, &margins, f64::INFINITY).unwrap();
                assert!((got.clearance - scan).abs() < 1e-9, "{got:?} vs {scan}");
                // The contact's own row says the same.
                let (h, _) = w.row(&x, got.circle, got.target);
                assert!((h - margins[got.circle] - got.clearance).abs() < 1e-9);
                // A cutoff below the answer finds nothing; above, the same.
                assert_eq!(w.excess(&x, &margins, scan - 1e-6), None);
                let cut = w.excess(&x, &margins, scan + 0.5).unwrap();
                assert!((cut.clearance - scan).abs() < 1e-9);
            }
        }
    }
}

/// Every row's gradient against central differences of its value, on every
/// kind of target and both bodies of a truer outline.
#[test]
fn row_gradients_match_finite_differences() {
    let p = MachineParams::default();
    let idx = site(7, 60, 40.0);
    let mut w = World::new(p, Outline::avant635(), 8);
    w.set_site(Some(idx.clone()));
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    w.set_circles(&random_circles(&mut rng, 40.0, 3)).unwrap();
    let eps = 1e-6;
    let mut checked = 0;
    for _ in 0..300 {
        let x = random_state(&mut rng, 40.0);
        let targets = (0..idx.site().features().len())
            .map(Target::Feature)
            .chain([Target::Bounds])
            .chain((0..3).map(Target::Circle));
        for t in targets {
            for c in 0..w.outline().len() {
                let (h, g) = w.row(&x, c, t);
                // Away from kinks (polygon corners, medial axes) only: the
                // gradient is checked where the distance is smooth.
                let mut fd = [0.0; 4];
                let mut smooth = true;
                for k in 0..4 {
                    let (mut a, mut b) = (x, x);
                    a[k] += eps;
                    b[k] -= eps;
                    let (ha, _) = w.row(&a, c, t);
                    let (hb, _) = w.row(&b, c, t);
                    assert!(ha.is_finite() && hb.is_finite(), "{t:?} circle {c}");
                    fd[k] = (ha - hb) / (2.0 * eps);
                    smooth &= ((ha - h) - (h - hb)).abs() < 1e-9;
                }
                if !smooth || h.abs() > 30.0 {
                    continue;
                }
                for k in 0..4 {
                    assert!(
                        (fd[k] - g[k]).abs() < 1e-5,
                        "{t:?} circle {c}: {fd:?} vs {g:?}"
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 10_000, "{checked}");
}

/// The site's rows are the smallest (circle, feature) pairs within reach.
#[test]
fn site_rows_keep_the_nearest_pairs() {
    let p = MachineParams::default();
    let idx = site(4, 400, 80.0);
    let mut w = World::new(p, Outline::avant635(), 8);
    w.set_site(Some(idx.clone()));
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let margins = [0.05, 0.08];
    let mut near = [Near::default(); 16];
    for _ in 0..200 {
        let x = random_state(&mut rng, 80.0);
        let mut out = [RowPair::default(); 16];
        let mut len = 0;
        let reach = 4.0;
        w.site_rows(&x, margins, reach, &mut near, &mut out, &mut len);
        // The scan: every pair within reach.
        let placed = w.place(&x);
        let mut all = Vec::new();
        for (i, c) in placed[..w.outline().len()].iter().enumerate() {
            let m = margins[(w.outline().circles()[i].body == Body::Rear) as usize];
            for feat in idx.site().features() {
                let e = feat.shape.signed_distance(c.center) - c.radius - m;
                if e <= reach {
                    all.push(e);
                }
            }
            let b = -idx.site().bounds().signed_distance(c.center) - c.radius - m;
            if b < reach {
                all.push(b);
            }
        }
        all.sort_by(f64::total_cmp);
        let mut got: Vec<f64> = out[..len].iter().map(|r| r.excess).collect();
        got.sort_by(f64::total_cmp);
        let want = &all[..all.len().min(16)];
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{got:?} vs {want:?}");
        }
    }
}

#[test]
fn circles_beyond_the_capacity_or_invalid_are_refused() {
    let mut w = World::with_axle_circles(MachineParams::default(), 2);
    let o = Obstacle::new(1.0, 1.0, 1.0);
    assert!(matches!(
        w.set_circles(&[o, o, o]),
        Err(WorldError::TooManyObstacles { given: 3, max: 2 })
    ));
    assert!(matches!(
        w.set_circles(&[o, Obstacle::new(f64::NAN, 0.0, 1.0)]),
        Err(WorldError::BadObstacle(_))
    ));
    assert!(w.is_empty());
}

/// The swept-disc filter agrees with a dense check: never clear where a
/// point of the segment is closer than `extra`.
#[test]
fn segment_clear_never_passes_a_blocked_segment() {
    let p = MachineParams::default();
    let idx = site(2, 80, 40.0);
    let mut w = World::with_axle_circles(p, 8);
    w.set_site(Some(idx));
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut blocked = 0;
    for _ in 0..400 {
        let a = [rng.gen_range(0.0..40.0), rng.gen_range(0.0..40.0)];
        let b = [
            a[0] + rng.gen_range(-6.0..6.0),
            a[1] + rng.gen_range(-6.0..6.0),
        ];
        let extra = 0.2;
        let dense_blocked = (0..=2000).any(|k| {
            let t = k as f64 / 2000.0;
            let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            w.disc_clearance(q, 0.65, f64::INFINITY) < extra
        });
        if dense_blocked {
            blocked += 1;
            assert!(!w.segment_clear(a, b, 0.65, extra));
        }
    }
    assert!(blocked > 50, "{blocked}");
}

/// The region query and the exact distances to the features in it give the
/// index's answer wherever it is below what the region covers.
#[test]
fn excess_among_the_features_near_is_the_index_answer_within_reach() {
    let p = MachineParams::default();
    let idx = site(4, 400, 80.0);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let mut compared = 0;
    for outline in [default_outline(), Outline::avant635()] {
        let mut w = World::new(p, outline.clone(), 8);
        w.set_site(Some(idx.clone()));
        let margins: Vec<f64> = (0..outline.len()).map(|i| 0.1 + 0.02 * i as f64).collect();
        let extent = (0..outline.len())
            .map(|i| outline.lever_arm(i, &p) + outline.circles()[i].radius + margins[i])
            .fold(0.0, f64::max);
        let mut near = [Near::default(); 48];
        for _ in 0..300 {
            let x = random_state(&mut rng, 80.0);
            let reach = rng.gen_range(3.0..8.0);
            let Some(n) = w.features_near([x[0], x[1]], reach, &mut near) else {
                continue;
            };
            let cap = reach - extent;
            let full = w.excess(&x, &margins, cap).map(|c| c.clearance);
            let local = w
                .excess_among(&x, &margins, cap, Some(&near[..n]))
                .map(|c| c.clearance);
            match (full, local) {
                (Some(a), Some(b)) => {
                    assert!((a - b).abs() < 1e-9, "{a} vs {b}");
                    compared += 1;
                }
                (None, None) => {}
                other => panic!("{other:?} (reach {reach}, cap {cap})"),
            }
        }
    }
    // Only the cases with something within the cap compare two distances.
    assert!(compared > 300, "{compared}");
}

/// A live obstacle's row: its value is the obstacle's own clearance at the
/// row's time ([`LiveObstacle::clearance_at`], a second implementation)
/// less the reach, and its gradient the finite differences' (circles and
/// polygons, moving, both outlines).
#[test]
fn live_rows_are_the_predicted_clearance_and_its_gradient() {
    use crate::live::{LiveClass, LiveShape};
    let p = MachineParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let shapes = [
        LiveShape::circle([4.0, 1.0], 0.4).unwrap(),
        LiveShape::polygon(&[[3.0, -1.0], [5.5, -0.5], [5.0, 1.5], [3.2, 1.0]]).unwrap(),
    ];
    for outline in [default_outline(), Outline::avant635()] {
        let w = World::new(p, outline.clone(), 8);
        for shape in shapes {
            let o = LiveObstacle::new(7, LiveClass::Vehicle, shape, [-0.8, 0.6], 1.0).unwrap();
            for _ in 0..200 {
                let x = State::new(
                    rng.gen_range(-2.0..6.0),
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-3.2..3.2),
                    rng.gen_range(-0.7..0.7),
                    0.0,
                    0.0,
                );
                let t = rng.gen_range(1.0..4.0);
                for (c, placed) in w.place(&x)[..outline.len()].iter().enumerate() {
                    let (h, g) = w.live_row(&x, c, &o, t, 0.3);
                    let want = o.clearance_at(placed.center, placed.radius, t) - 0.3;
                    assert!((h - want).abs() < 1e-12, "{h} {want}");
                    for k in 0..4 {
                        let e = 1e-6;
                        let (mut xp, mut xm) = (x, x);
                        xp[k] += e;
                        xm[k] -= e;
                        let fd = (w.live_row(&xp, c, &o, t, 0.3).0
                            - w.live_row(&xm, c, &o, t, 0.3).0)
                            / (2.0 * e);
                        // Away from the polygon's corners' switch the
                        // distance is smooth.
                        assert!((g[k] - fd).abs() < 1e-5, "k {k}: {} vs {fd}", g[k]);
                    }
                }
            }
        }
    }
}
