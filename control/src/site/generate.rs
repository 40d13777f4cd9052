//! Generated sites, reproducible by a seed: the large pit used for scale
//! (DESIGN §17, issue 40: ≥ 500 features) and random sites for tests and
//! benchmarks.
//!
//! `cargo run -p control --example site_gen -- large-pit 40 520 > sim/sites/large-pit-40.json`
//! writes the committed file; a test (`control/tests/sites.rs`) checks the two agree.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geometry::{point_in_polygon, P2};
use super::{KeepoutEntry, ObstacleEntry, SiteFile, FORMAT};

/// Rounds to centimetres, so files stay short and their text exact.
fn cm(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

/// A star-shaped polygon around `c`: `n` vertices at sorted angles, radii
/// within [r_min, r_max]; simple since every ray from `c` meets it once.
fn star(rng: &mut ChaCha8Rng, c: P2, n: usize, r_min: f64, r_max: f64) -> Vec<P2> {
    let phase = rng.gen_range(0.0..std::f64::consts::TAU);
    (0..n)
        .map(|k| {
            let a =
                phase + std::f64::consts::TAU * (k as f64 + rng.gen_range(-0.3..0.3)) / n as f64;
            let r = rng.gen_range(r_min..r_max);
            [cm(c[0] + r * a.cos()), cm(c[1] + r * a.sin())]
        })
        .collect()
}

/// A large open pit, about 420 m × 300 m inside a convex octagon: piles
/// (star polygons), rocks (circles), berms (polylines with a width) and a
/// few keep-outs, one per cell of a 12 m grid, in cells drawn at random
/// until `features` are placed; lanes stay between them. Same seed, same
/// site (byte for byte through [`SiteFile::to_json`]).
pub fn large_pit(seed: u64, features: usize) -> SiteFile {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h, chamfer) = (420.0, 300.0, 60.0);
    let bounds: Vec<P2> = vec![
        [chamfer, 0.0],
        [w - chamfer, 0.0],
        [w, chamfer],
        [w, h - chamfer],
        [w - chamfer, h],
        [chamfer, h],
        [0.0, h - chamfer],
        [0.0, chamfer],
    ];
    let cell = 12.0;
    let (nx, ny) = ((w / cell) as usize, (h / cell) as usize);
    // Cells wholly inside the (convex) bounds, with a 1 m margin.
    let mut cells: Vec<(usize, usize)> = (0..nx)
        .flat_map(|i| (0..ny).map(move |j| (i, j)))
        .filter(|&(i, j)| {
            let (x0, y0) = (i as f64 * cell, j as f64 * cell);
            [
                [x0 - 1.0, y0 - 1.0],
                [x0 + cell + 1.0, y0 - 1.0],
                [x0 + cell + 1.0, y0 + cell + 1.0],
                [x0 - 1.0, y0 + cell + 1.0],
            ]
            .iter()
            .all(|&q| point_in_polygon(q, &bounds))
        })
        .collect();
    // Fisher–Yates with the seeded generator: the cells used, in order.
    for k in (1..cells.len()).rev() {
        let m = rng.gen_range(0..=k);
        cells.swap(k, m);
    }
    let mut obstacles = Vec::new();
    let mut keepout = Vec::new();
    for (n, &(i, j)) in cells.iter().take(features).enumerate() {
        // Feature centre in the middle 6 m of the cell: ≥ 6 m lanes between.
        let c = [
            i as f64 * cell + 6.0 + rng.gen_range(-1.5..1.5),
            j as f64 * cell + 6.0 + rng.gen_range(-1.5..1.5),
        ];
        let kind = if n % 97 == 13 {
            3
        } else {
            rng.gen_range(0..10)
        };
        match kind {
            3 if n % 97 == 13 => keepout.push(KeepoutEntry {
                id: format!("keepout-{}", keepout.len() + 1),
                polygon: vec![
                    [cm(c[0] - 3.0), cm(c[1] - 2.5)],
                    [cm(c[0] + 3.0), cm(c[1] - 2.5)],
                    [cm(c[0] + 3.0), cm(c[1] + 2.5)],
                    [cm(c[0] - 3.0), cm(c[1] + 2.5)],
                ],
            }),
            0..=5 => {
                let nv = rng.gen_range(5..11);
                obstacles.push(ObstacleEntry {
                    id: format!("pile-{n}"),
                    polygon: Some(star(&mut rng, c, nv, 1.5, 3.0)),
                    ..Default::default()
                });
            }
            6 | 7 => obstacles.push(ObstacleEntry {
                id: format!("rock-{n}"),
                circle: Some([cm(c[0]), cm(c[1]), cm(rng.gen_range(0.4..2.0))]),
                ..Default::default()
            }),
            _ => {
                let a: f64 = rng.gen_range(0.0..std::f64::consts::PI);
                let (s, co) = a.sin_cos();
                let line = (0..3)
                    .map(|k| {
                        let t = (k as f64 - 1.0) * 2.0;
                        let off = if k == 1 {
                            rng.gen_range(-0.8..0.8)
                        } else {
                            0.0
                        };
                        [cm(c[0] + t * co - off * s), cm(c[1] + t * s + off * co)]
                    })
                    .collect();
                obstacles.push(ObstacleEntry {
                    id: format!("berm-{n}"),
                    polyline: Some(line),
                    width: Some(cm(rng.gen_range(0.8..2.0))),
                    ..Default::default()
                });
            }
        }
    }
    SiteFile {
        format: FORMAT.to_string(),
        id: format!("large-pit-{seed}"),
        version: 1,
        bounds,
        obstacles,
        keepout,
    }
}

/// A random site for tests and benchmarks: a rectangular bounds of `size`
/// metres, `n` features of every kind (overlaps allowed), some large, some
/// tiny, non-convex polygons among them.
pub fn random_site(seed: u64, n: usize, size: f64) -> SiteFile {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Centres this far in: the largest shape (a keep-out of radius 10) fits.
    let margin = 11.0;
    let mut obstacles = Vec::new();
    let mut keepout = Vec::new();
    for k in 0..n {
        let c = [
            rng.gen_range(margin..size - margin),
            rng.gen_range(margin..size - margin),
        ];
        let scale = if rng.gen_bool(0.1) { 5.0 } else { 1.0 };
        match rng.gen_range(0..4) {
            0 => obstacles.push(ObstacleEntry {
                id: format!("c{k}"),
                circle: Some([c[0], c[1], rng.gen_range(0.05..1.0) * scale]),
                ..Default::default()
            }),
            1 => {
                let nv = rng.gen_range(3..12);
                obstacles.push(ObstacleEntry {
                    id: format!("p{k}"),
                    polygon: Some(star(&mut rng, c, nv, 0.2 * scale, 1.0 * scale)),
                    ..Default::default()
                })
            }
            2 => {
                let nv = rng.gen_range(2..6);
                let mut q = c;
                let line = (0..nv)
                    .map(|_| {
                        q = [
                            (q[0] + rng.gen_range(-2.0..2.0)).clamp(margin, size - margin),
                            (q[1] + rng.gen_range(-2.0..2.0)).clamp(margin, size - margin),
                        ];
                        q
                    })
                    .collect::<Vec<_>>();
                let mut line: Vec<P2> = line;
                line.dedup();
                if line.len() < 2 {
                    line.push([line[0][0] + 0.5, line[0][1]]);
                }
                obstacles.push(ObstacleEntry {
                    id: format!("l{k}"),
                    polyline: Some(line),
                    width: Some(rng.gen_range(0.1..1.5)),
                    ..Default::default()
                })
            }
            _ => {
                let nv = rng.gen_range(3..9);
                keepout.push(KeepoutEntry {
                    id: format!("k{k}"),
                    polygon: star(&mut rng, c, nv, 0.5 * scale, 2.0 * scale),
                })
            }
        }
    }
    SiteFile {
        format: FORMAT.to_string(),
        id: format!("random-{seed}"),
        version: 1,
        bounds: vec![[0.0, 0.0], [size, 0.0], [size, size], [0.0, size]],
        obstacles,
        keepout,
    }
}
