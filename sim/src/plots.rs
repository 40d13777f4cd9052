//! SVG plots (paper Fig. 5–8): trajectories with goal arrows and obstacles,
//! and the histogram of convergence times. plotters' SVG backend without font
//! features: text is laid out naively and left to the SVG viewer's fonts.

use std::path::Path;

use anyhow::{anyhow, Result};
use control::model::{Goal, State};
use control::scenario::Scenario;
use control::site::{FeatureKind, Shape, Site};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Colours of the methods, in a fixed order.
pub fn method_color(method: &str) -> RGBColor {
    match method {
        "mpc" => RGBColor(31, 119, 180),
        "baseline" => RGBColor(214, 39, 40),
        "actor" => RGBColor(44, 160, 44),
        "min-time" => RGBColor(148, 103, 189),
        _ => RGBColor(255, 127, 14),
    }
}

/// A trajectory to draw.
pub struct Track<'a> {
    pub label: String,
    pub states: &'a [State],
    pub color: RGBColor,
    /// The global layer's routes (subgoals ending with the goal), drawn
    /// dashed from the track's start through the subgoals; empty for none.
    pub routes: &'a [Vec<Goal>],
}

/// A dashed polyline: every other piece of `pts` cut into `dash`-long pieces.
fn dashed(pts: &[(f64, f64)], dash: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut on = true;
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        let n = (len / dash).ceil().max(1.0) as usize;
        for k in 0..n {
            let (f0, f1) = (k as f64 / n as f64, (k + 1) as f64 / n as f64);
            if on {
                out.push(vec![
                    (a.0 + f0 * (b.0 - a.0), a.1 + f0 * (b.1 - a.1)),
                    (a.0 + f1 * (b.0 - a.0), a.1 + f1 * (b.1 - a.1)),
                ]);
            }
            on = !on;
        }
    }
    out
}

fn arrow(x: f64, y: f64, theta: f64, len: f64) -> [Vec<(f64, f64)>; 2] {
    let tip = (x + len * theta.cos(), y + len * theta.sin());
    let head = 0.35 * len;
    let l = (
        tip.0 + head * (theta + 2.6).cos(),
        tip.1 + head * (theta + 2.6).sin(),
    );
    let r = (
        tip.0 + head * (theta - 2.6).cos(),
        tip.1 + head * (theta - 2.6).sin(),
    );
    [vec![(x, y), tip], vec![l, tip, r]]
}

fn circle(x: f64, y: f64, r: f64) -> Vec<(f64, f64)> {
    (0..=48)
        .map(|i| {
            let a = i as f64 / 48.0 * std::f64::consts::TAU;
            (x + r * a.cos(), y + r * a.sin())
        })
        .collect()
}

/// A site's bounds (outline), obstacles (grey) and keep-outs (red, hatched
/// by transparency) under the trajectories.
fn draw_site<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    site: &Site,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let mut ring = site.bounds().vertices().to_vec();
    ring.push(ring[0]);
    chart
        .draw_series(std::iter::once(PathElement::new(
            ring.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
            BLACK.stroke_width(1),
        )))
        .map_err(err)?;
    for f in site.features() {
        let color = match f.kind {
            FeatureKind::Obstacle => RGBColor(140, 140, 140).mix(0.6),
            FeatureKind::KeepOut => RGBColor(214, 39, 40).mix(0.35),
        };
        match &f.shape {
            Shape::Circle(c) => chart
                .draw_series(std::iter::once(Polygon::new(
                    circle(c.center[0], c.center[1], c.radius),
                    color.filled(),
                )))
                .map(|_| ()),
            Shape::Polygon(g) => chart
                .draw_series(std::iter::once(Polygon::new(
                    g.vertices()
                        .iter()
                        .map(|p| (p[0], p[1]))
                        .collect::<Vec<_>>(),
                    color.filled(),
                )))
                .map(|_| ()),
            Shape::Polyline(l) => {
                // A capsule chain: a disc at each vertex, a quad per segment.
                let r = l.half_width();
                let v = l.vertices();
                let mut shapes: Vec<Vec<(f64, f64)>> =
                    v.iter().map(|p| circle(p[0], p[1], r)).collect();
                for s in v.windows(2) {
                    let (dx, dy) = (s[1][0] - s[0][0], s[1][1] - s[0][1]);
                    let n = dx.hypot(dy).max(1e-9);
                    let (nx, ny) = (-dy / n * r, dx / n * r);
                    shapes.push(vec![
                        (s[0][0] + nx, s[0][1] + ny),
                        (s[1][0] + nx, s[1][1] + ny),
                        (s[1][0] - nx, s[1][1] - ny),
                        (s[0][0] - nx, s[0][1] - ny),
                    ]);
                }
                chart
                    .draw_series(shapes.into_iter().map(|p| Polygon::new(p, color.filled())))
                    .map(|_| ())
            }
        }
        .map_err(err)?;
    }
    Ok(())
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e}")
}

/// Draws the scenarios' start and goal arrows and obstacles, and the tracks,
/// with equal axis scales.
pub fn trajectory_svg(
    path: &Path,
    title: &str,
    scenarios: &[&Scenario],
    site: Option<&Site>,
    tracks: &[Track],
) -> Result<()> {
    let (w, h) = (720u32, 640u32);
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = Vec::new();
    // Several scenarios: the whole site; one: what it needs (the site's
    // features are clipped to the frame).
    if let (Some(site), true) = (site, scenarios.len() > 1) {
        let b = site.bounds().aabb();
        xs.extend([b.min[0], b.max[0]]);
        ys.extend([b.min[1], b.max[1]]);
    }
    for sc in scenarios {
        xs.extend([sc.start[0], sc.goal.x]);
        ys.extend([sc.start[1], sc.goal.y]);
        for o in &sc.obstacles {
            xs.extend([o.x - o.radius, o.x + o.radius]);
            ys.extend([o.y - o.radius, o.y + o.radius]);
        }
    }
    for t in tracks {
        for x in t.states {
            if x[0].is_finite() && x[1].is_finite() {
                xs.push(x[0]);
                ys.push(x[1]);
            }
        }
    }
    let (mut x0, mut x1) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (mut y0, mut y1) = ys
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    x0 -= 1.0;
    x1 += 1.0;
    y0 -= 1.0;
    y1 += 1.0;
    // Equal scales: the plotting area is about (w − 70) × (h − 90) pixels.
    let aspect = (w as f64 - 70.0) / (h as f64 - 90.0);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let (mut sx, mut sy) = (x1 - x0, y1 - y0);
    if sx / sy > aspect {
        sy = sx / aspect;
    } else {
        sx = sy * aspect;
    }
    let (x0, x1, y0, y1) = (cx - sx / 2.0, cx + sx / 2.0, cy - sy / 2.0, cy + sy / 2.0);
    let arrow_len = 0.04 * sx.max(sy).max(4.0);

    let root = SVGBackend::new(path, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    if let Some(site) = site {
        draw_site(&mut chart, site)?;
    }
    for sc in scenarios {
        for o in &sc.obstacles {
            chart
                .draw_series(std::iter::once(Polygon::new(
                    circle(o.x, o.y, o.radius),
                    RGBColor(160, 160, 160).mix(0.5).filled(),
                )))
                .map_err(err)?;
        }
        for part in arrow(sc.goal.x, sc.goal.y, sc.goal.theta, arrow_len) {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    part,
                    BLACK.stroke_width(2),
                )))
                .map_err(err)?;
        }
        let orange = RGBColor(255, 127, 14);
        for part in arrow(sc.start[0], sc.start[1], sc.start[2], arrow_len) {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    part,
                    orange.stroke_width(2),
                )))
                .map_err(err)?;
        }
    }
    // Routes under the tracks: dashed from where the track starts (the
    // machine) through the subgoals, a dot on each subgoal.
    for t in tracks {
        let Some(x0) = t.states.first() else {
            continue;
        };
        for route in t.routes.iter().filter(|r| r.len() > 1) {
            let mut pts = vec![(x0[0], x0[1])];
            pts.extend(route.iter().map(|g| (g.x, g.y)));
            let style = t.color.mix(0.6).stroke_width(1);
            chart
                .draw_series(
                    dashed(&pts, 0.15)
                        .into_iter()
                        .map(|p| PathElement::new(p, style)),
                )
                .map_err(err)?;
            chart
                .draw_series(
                    route[..route.len() - 1]
                        .iter()
                        .map(|g| Circle::new((g.x, g.y), 3, t.color.mix(0.8).filled())),
                )
                .map_err(err)?;
        }
    }
    let mut labelled: Vec<String> = Vec::new();
    for t in tracks {
        let pts: Vec<(f64, f64)> = t
            .states
            .iter()
            .filter(|x| x[0].is_finite() && x[1].is_finite())
            .map(|x| (x[0], x[1]))
            .collect();
        let color = t.color;
        let series = chart
            .draw_series(LineSeries::new(pts, color.stroke_width(2)))
            .map_err(err)?;
        if !labelled.contains(&t.label) {
            labelled.push(t.label.clone());
            series.label(t.label.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        }
    }
    if !labelled.is_empty() {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}

/// Histogram of convergence times, one bar colour per method, 1 s bins
/// (paper Fig. 8).
pub fn histogram_svg(path: &Path, title: &str, series: &[(String, Vec<f64>)]) -> Result<()> {
    value_histogram_svg(path, title, "convergence time [s]", 1.0, series)
}

/// Histogram of any values, one bar colour per series, bins of `bin` from
/// the largest multiple of `bin` at or below the smallest value (or 0).
pub fn value_histogram_svg(
    path: &Path,
    title: &str,
    x_desc: &str,
    bin: f64,
    series: &[(String, Vec<f64>)],
) -> Result<()> {
    let values = || {
        series
            .iter()
            .flat_map(|(_, v)| v.iter().cloned())
            .filter(|v| v.is_finite())
    };
    let lo = (values().fold(0.0, f64::min) / bin).floor() * bin;
    let hi = (values().fold(lo + bin, f64::max) / bin).floor() * bin + bin;
    let bins = ((hi - lo) / bin).round().max(1.0) as usize;
    let mut counts = vec![vec![0usize; bins]; series.len()];
    for (m, (_, v)) in series.iter().enumerate() {
        for &t in v.iter().filter(|v| v.is_finite()) {
            let b = (((t - lo) / bin).floor().max(0.0) as usize).min(bins - 1);
            counts[m][b] += 1;
        }
    }
    let c_max = counts.iter().flatten().cloned().max().unwrap_or(1).max(1);
    let root = SVGBackend::new(path, (720, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(lo..hi, 0.0..(c_max as f64 * 1.1))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("scenarios")
        .light_line_style(WHITE)
        .draw()
        .map_err(err)?;
    let width = 0.9 * bin / series.len().max(1) as f64;
    for (m, (name, _)) in series.iter().enumerate() {
        let color = method_color(name);
        let bars = counts[m]
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(b, &c)| {
                let x = lo + b as f64 * bin + 0.05 * bin + m as f64 * width;
                Rectangle::new([(x, 0.0), (x + width, c as f64)], color.mix(0.8).filled())
            });
        chart
            .draw_series(bars)
            .map_err(err)?
            .label(name.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// One line of a [`sweep_svg`] panel: (level, value) points, `None` where the
/// value does not exist (drawn as a gap).
pub struct SweepSeries {
    pub label: String,
    pub color: RGBColor,
    pub points: Vec<(f64, Option<f64>)>,
}

/// A panel of [`sweep_svg`]: its y axis, an optional dashed threshold line and
/// its series.
pub struct SweepPanel {
    pub y_desc: String,
    pub threshold: Option<f64>,
    pub series: Vec<SweepSeries>,
}

/// Metrics over the levels of one perturbation (robustness sweep): one panel
/// per metric stacked vertically, sharing the level axis; the nominal level
/// as a vertical grey line.
pub fn sweep_svg(
    path: &Path,
    title: &str,
    x_desc: &str,
    nominal: f64,
    panels: &[SweepPanel],
) -> Result<()> {
    let xs = || {
        panels
            .iter()
            .flat_map(|p| p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)))
            .chain(std::iter::once(nominal))
    };
    let x0 = xs().fold(f64::INFINITY, f64::min);
    let x1 = xs().fold(f64::NEG_INFINITY, f64::max);
    let pad = ((x1 - x0) * 0.05).max(1e-3);
    let (x0, x1) = (x0 - pad, x1 + pad);
    let height = 40 + 250 * panels.len() as u32;
    let root = SVGBackend::new(path, (720, height)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 18)).map_err(err)?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (area, panel) in areas.iter().zip(panels) {
        let ys: Vec<f64> = panel
            .series
            .iter()
            .flat_map(|s| s.points.iter().filter_map(|q| q.1))
            .chain(panel.threshold)
            .filter(|v| v.is_finite())
            .collect();
        let lo = ys.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo.is_finite() {
            let m = ((hi - lo) * 0.1).max(1e-3);
            (lo - m, hi + m)
        } else {
            (0.0, 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, lo..hi)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(panel.y_desc.as_str())
            .light_line_style(WHITE)
            .draw()
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(nominal, lo), (nominal, hi)],
                RGBColor(170, 170, 170),
            )))
            .map_err(err)?;
        if let Some(t) = panel.threshold {
            let dashes = (0..40).map(|k| {
                let a = x0 + (x1 - x0) * k as f64 / 40.0;
                let b = a + (x1 - x0) / 80.0;
                PathElement::new(vec![(a, t), (b, t)], RED)
            });
            chart.draw_series(dashes).map_err(err)?;
        }
        for s in &panel.series {
            let color = s.color;
            // Lines between consecutive existing points; markers on each.
            let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
            for &(x, y) in &s.points {
                match y {
                    Some(y) if y.is_finite() => segments.last_mut().expect("one").push((x, y)),
                    _ => segments.push(Vec::new()),
                }
            }
            for seg in segments.iter().filter(|s| s.len() > 1) {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        seg.clone(),
                        color.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
            chart
                .draw_series(
                    segments
                        .iter()
                        .flatten()
                        .map(|&(x, y)| Circle::new((x, y), 4, color.filled())),
                )
                .map_err(err)?
                .label(s.label.clone())
                .legend(move |(x, y)| Circle::new((x + 7, y), 4, color.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::LowerLeft)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}
