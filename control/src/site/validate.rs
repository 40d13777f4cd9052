//! Shape checks of the site loader (DESIGN §17): finite numbers, positive
//! radii and widths, simple polygons, features inside the bounds.
//!
//! The simplicity test is the plain O(n²) edge-pair test (with a box
//! rejection first); [`super::MAX_SHAPE_VERTICES`] bounds it at load.

use super::geometry::{
    orient, segment_distance, segments_intersect, signed_area2, sub, Aabb, Polygon, Polyline,
    Shape, P2,
};
use super::{FeatureProblem, BOUNDS_TOLERANCE, MAX_SHAPE_VERTICES};

fn finite(ring: &[P2]) -> Result<(), FeatureProblem> {
    match ring
        .iter()
        .position(|q| !(q[0].is_finite() && q[1].is_finite()))
    {
        Some(vertex) => Err(FeatureProblem::NotFinite { vertex }),
        None => Ok(()),
    }
}

fn vertex_count(ring: &[P2], min: usize) -> Result<(), FeatureProblem> {
    if ring.len() < min {
        return Err(FeatureProblem::TooFewVertices {
            found: ring.len(),
            min,
        });
    }
    if ring.len() > MAX_SHAPE_VERTICES {
        return Err(FeatureProblem::TooManyVertices {
            found: ring.len(),
            limit: MAX_SHAPE_VERTICES,
        });
    }
    Ok(())
}

/// A simple polygon: ≥ 3 finite vertices, no vertex repeating its
/// predecessor (nor the last the first: the ring is closed implicitly), a
/// non-zero area, no two edges meeting except neighbours at their shared
/// vertex, and no neighbour folding back onto the other.
pub fn simple_polygon(ring: &[P2]) -> Result<(), FeatureProblem> {
    vertex_count(ring, 3)?;
    finite(ring)?;
    let n = ring.len();
    for i in 0..n {
        let j = (i + 1) % n;
        if ring[i] == ring[j] {
            return Err(FeatureProblem::RepeatedVertex {
                vertex: j,
                earlier: i,
            });
        }
    }
    let boxes: Vec<Aabb> = (0..n)
        .map(|i| Aabb::of_points(&[ring[i], ring[(i + 1) % n]]))
        .collect();
    for i in 0..n {
        for j in i + 1..n {
            let (a1, a2) = (ring[i], ring[(i + 1) % n]);
            let (b1, b2) = (ring[j], ring[(j + 1) % n]);
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            if adjacent {
                // Shared vertex v; the neighbours' far ends must not lie on
                // the same ray from v (an edge folding back onto the other).
                let (v, a, b) = if j == i + 1 {
                    (a2, a1, b2)
                } else {
                    (a1, a2, b1)
                };
                let (da, db) = (sub(a, v), sub(b, v));
                if orient(v, a, b) == 0.0 && da[0] * db[0] + da[1] * db[1] > 0.0 {
                    return Err(FeatureProblem::SelfIntersection {
                        edge_a: i,
                        edge_b: j,
                    });
                }
                continue;
            }
            if boxes[i].overlaps(&boxes[j]) && segments_intersect(a1, a2, b1, b2) {
                return Err(FeatureProblem::SelfIntersection {
                    edge_a: i,
                    edge_b: j,
                });
            }
        }
    }
    // After the crossing test: a symmetric bow-tie has zero area too, and
    // "edges cross" is the better message.
    let scale = Aabb::of_points(ring);
    let extent = (scale.max[0] - scale.min[0]).max(scale.max[1] - scale.min[1]);
    if signed_area2(ring).abs() <= 1e-12 * extent * extent {
        return Err(FeatureProblem::ZeroArea);
    }
    Ok(())
}

/// A polyline: ≥ 2 finite vertices, no zero-length segment, width finite
/// and > 0. It may cross itself (a wall that does is still a set of capsules).
pub fn polyline(line: &[P2], width: f64) -> Result<(), FeatureProblem> {
    vertex_count(line, 2)?;
    finite(line)?;
    for i in 1..line.len() {
        if line[i] == line[i - 1] {
            return Err(FeatureProblem::RepeatedVertex {
                vertex: i,
                earlier: i - 1,
            });
        }
    }
    if !(width.is_finite() && width > 0.0) {
        return Err(FeatureProblem::NonPositiveWidth(width));
    }
    Ok(())
}

/// A circle: finite centre, radius finite and > 0.
pub fn circle(c: [f64; 3]) -> Result<(), FeatureProblem> {
    if !(c[0].is_finite() && c[1].is_finite()) {
        return Err(FeatureProblem::NotFinite { vertex: 0 });
    }
    if !(c[2].is_finite() && c[2] > 0.0) {
        return Err(FeatureProblem::NonPositiveRadius(c[2]));
    }
    Ok(())
}

/// The signed distance of `p` to the bounds must be ≤ `limit` (+ tolerance).
fn point_within(
    bounds: &Polygon,
    p: P2,
    limit: f64,
    what: impl FnOnce() -> String,
) -> Result<(), FeatureProblem> {
    let d = bounds.signed_distance(p);
    if d > limit + BOUNDS_TOLERANCE {
        return Err(FeatureProblem::OutsideBounds {
            detail: format!(
                "{} ({:.3}, {:.3}) is {:.3} m beyond the allowed extent",
                what(),
                p[0],
                p[1],
                d - limit
            ),
        });
    }
    Ok(())
}

/// A circle lies inside the bounds (touching allowed).
pub fn circle_inside(bounds: &Polygon, c: P2, r: f64) -> Result<(), FeatureProblem> {
    point_within(bounds, c, -r, || "its edge at centre".into())
}

/// A polygon lies inside the bounds: every vertex and edge midpoint inside
/// (within the tolerance) and no edge properly crossing a bounds edge.
pub fn polygon_inside(bounds: &Polygon, ring: &[P2]) -> Result<(), FeatureProblem> {
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        point_within(bounds, a, 0.0, || format!("vertex {i}"))?;
        let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
        point_within(bounds, m, 0.0, || format!("the middle of edge {i}"))?;
        crossing(bounds, a, b, i)?;
    }
    no_bounds_vertex_inside(bounds, &Shape::Polygon(Polygon::new(ring.to_vec())))
}

/// Whether feature edge a–b crosses a bounds edge by more than the
/// tolerance: each segment's ends lie on opposite sides of the other's line,
/// farther from it than [`BOUNDS_TOLERANCE`] (an imported map's cells lie
/// along its bounds, a rounding error off them).
fn crossing(bounds: &Polygon, a: P2, b: P2, i: usize) -> Result<(), FeatureProblem> {
    let eb = Aabb::of_points(&[a, b]);
    let nb = bounds.vertices().len();
    let side = |p: P2, q: P2, x: P2| {
        let l = (q[0] - p[0]).hypot(q[1] - p[1]);
        let d = orient(p, q, x) / l;
        if d > BOUNDS_TOLERANCE {
            1
        } else if d < -BOUNDS_TOLERANCE {
            -1
        } else {
            0
        }
    };
    for k in 0..nb {
        let (c, d) = bounds.edge(k);
        if eb.overlaps(&Aabb::of_points(&[c, d]))
            && side(c, d, a) * side(c, d, b) == -1
            && side(a, b, c) * side(a, b, d) == -1
        {
            return Err(FeatureProblem::OutsideBounds {
                detail: format!("edge {i} crosses the bounds' edge {k}"),
            });
        }
    }
    Ok(())
}

/// No bounds vertex lies inside the feature (by more than the tolerance):
/// next to a vertex of the bounds there are points outside them, so a
/// feature holding one holds those too. Catches an edge that slips out
/// through a bounds vertex, which [`crossing`] sees as touching.
fn no_bounds_vertex_inside(bounds: &Polygon, shape: &Shape) -> Result<(), FeatureProblem> {
    let b = shape.aabb();
    for (k, &v) in bounds.vertices().iter().enumerate() {
        if b.distance(v) == 0.0 && shape.signed_distance(v) < -BOUNDS_TOLERANCE {
            return Err(FeatureProblem::OutsideBounds {
                detail: format!("it holds the bounds' vertex {k}"),
            });
        }
    }
    Ok(())
}

/// A polyline's capsules lie inside the bounds: every vertex at least the
/// half-width inside, no segment nearer a bounds edge than the half-width.
pub fn polyline_inside(bounds: &Polygon, l: &Polyline) -> Result<(), FeatureProblem> {
    let hw = l.half_width();
    let v = l.vertices();
    for (i, &p) in v.iter().enumerate() {
        point_within(bounds, p, -hw, || {
            format!("the edge of its width at vertex {i}")
        })?;
    }
    let nb = bounds.vertices().len();
    for i in 0..v.len() - 1 {
        let (a, b) = (v[i], v[i + 1]);
        crossing(bounds, a, b, i)?;
        let eb = Aabb::of_points(&[a, b]).grown(hw);
        for k in 0..nb {
            let (c, d) = bounds.edge(k);
            if eb.overlaps(&Aabb::of_points(&[c, d])) {
                let dist = segment_distance(a, b, c, d);
                if dist < hw - BOUNDS_TOLERANCE {
                    return Err(FeatureProblem::OutsideBounds {
                        detail: format!(
                            "segment {i} comes within {dist:.3} m of the bounds' edge {k}, less than its half-width {hw}"
                        ),
                    });
                }
            }
        }
    }
    // Nothing more can leave: a capsule that does either has a centre-line
    // point outside (a vertex, or a crossing) or comes nearer a bounds edge
    // than its half-width.
    no_bounds_vertex_inside(bounds, &Shape::Polyline(l.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simple_polygons_pass_and_bowties_fail() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert_eq!(simple_polygon(&square), Ok(()));
        let bowtie = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(matches!(
            simple_polygon(&bowtie),
            Err(FeatureProblem::SelfIntersection { .. })
        ));
        // Touching itself at a vertex (a figure eight through (1, 1)).
        let eight = [
            [0.0, 0.0],
            [1.0, 1.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [1.0, 1.0],
            [0.0, 2.0],
        ];
        assert!(simple_polygon(&eight).is_err());
        // Folding back: a spike along an edge.
        let spike = [[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        assert!(simple_polygon(&spike).is_err());
        let closed = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]];
        assert_eq!(
            simple_polygon(&closed),
            Err(FeatureProblem::RepeatedVertex {
                vertex: 0,
                earlier: 3
            })
        );
        // Three collinear points: the last edge folds back over the others.
        let line = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
        assert!(simple_polygon(&line).is_err());
        let sliver = [[0.0, 0.0], [1.0, 0.0], [2.0, 1e-13]];
        assert_eq!(simple_polygon(&sliver), Err(FeatureProblem::ZeroArea));
        assert!(matches!(
            simple_polygon(&[[0.0, 0.0], [1.0, 0.0]]),
            Err(FeatureProblem::TooFewVertices { found: 2, min: 3 })
        ));
        assert_eq!(
            simple_polygon(&[[0.0, 0.0], [f64::NAN, 0.0], [1.0, 1.0]]),
            Err(FeatureProblem::NotFinite { vertex: 1 })
        );
    }

    #[test]
    fn inside_bounds_checks_a_non_convex_bounds() {
        // An L-shaped bounds; a polygon whose vertices are all inside but
        // whose edge cuts across the notch is outside.
        let bounds = Polygon::new(vec![
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 4.0],
            [4.0, 4.0],
            [4.0, 10.0],
            [0.0, 10.0],
        ]);
        let ok = [[1.0, 1.0], [3.0, 1.0], [3.0, 8.0], [1.0, 8.0]];
        assert_eq!(polygon_inside(&bounds, &ok), Ok(()));
        let cuts = [[8.0, 1.0], [9.0, 1.0], [2.0, 9.0]];
        assert!(polygon_inside(&bounds, &cuts).is_err());
        // Touching the bounds is allowed (imported maps fill them).
        let edge = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert_eq!(polygon_inside(&bounds, &edge), Ok(()));
        assert_eq!(circle_inside(&bounds, [2.0, 2.0], 2.0), Ok(()));
        assert!(circle_inside(&bounds, [2.0, 2.0], 2.1).is_err());
        let wall = Polyline::new(vec![[1.0, 1.0], [1.0, 9.0]], 2.0);
        assert_eq!(polyline_inside(&bounds, &wall), Ok(()));
        let wall = Polyline::new(vec![[1.0, 1.0], [1.0, 9.0]], 2.2);
        assert!(polyline_inside(&bounds, &wall).is_err());
        // Its centre line stays inside, but passes the notch's corner too
        // closely for its width.
        let wall = Polyline::new(vec![[3.0, 3.0], [9.0, 3.0]], 2.5);
        assert!(polyline_inside(&bounds, &wall).is_err());
    }

    #[test]
    fn a_feature_holding_a_bounds_vertex_is_outside() {
        let bounds = Polygon::new(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]);
        let over = Shape::Polygon(Polygon::new(vec![
            [8.0, 8.0],
            [12.0, 8.0],
            [12.0, 12.0],
            [8.0, 12.0],
        ]));
        assert!(no_bounds_vertex_inside(&bounds, &over).is_err());
        let corner = Shape::Polygon(Polygon::new(vec![
            [8.0, 8.0],
            [10.0, 8.0],
            [10.0, 10.0],
            [8.0, 10.0],
        ]));
        assert_eq!(no_bounds_vertex_inside(&bounds, &corner), Ok(()));
        let wall = Shape::Polyline(Polyline::new(vec![[9.0, 9.0], [9.9, 9.9]], 0.5));
        assert!(no_bounds_vertex_inside(&bounds, &wall).is_err());
    }
}
