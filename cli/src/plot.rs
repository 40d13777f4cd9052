//! SVG of a driven path with the planned MPC horizons (plotters, SVG backend, no font
//! dependencies: text is laid out naively and rendered by the SVG viewer).

use std::path::Path;

use anyhow::anyhow;
use plotters::prelude::*;

use shm_ipc::Pose2;

/// Leg colours: dark enough on white for thin horizon lines.
const LEG_COLORS: [RGBColor; 6] = [
    RGBColor(200, 40, 40),
    RGBColor(30, 130, 60),
    RGBColor(30, 90, 200),
    RGBColor(150, 60, 170),
    RGBColor(210, 120, 0),
    RGBColor(0, 140, 150),
];

/// One goal's part of the drive.
#[derive(Debug, Clone, Default)]
pub struct LegTrace {
    /// Label in the legend.
    pub name: String,
    /// The goal pose.
    pub goal: Pose2,
    /// Driven front-axle positions, one per tick [m].
    pub path: Vec<(f64, f64)>,
    /// Planned horizons x₀..x_N (positions), a sample of the ticks [m].
    pub horizons: Vec<Vec<(f64, f64)>>,
    /// Whether the daemon reported the goal reached.
    pub reached: bool,
    /// The leg's obstacles (x, y, inflated radius) [m].
    pub obstacles: Vec<(f64, f64, f64)>,
    /// The global layer's first route for the leg (subgoals, then the goal) [m]; empty
    /// when the way was direct.
    pub route: Vec<(f64, f64)>,
}

/// A circle of radius `r` about (`x`, `y`) as a polygon in data coordinates (plotters'
/// `Circle` has its radius in pixels).
fn circle_points(x: f64, y: f64, r: f64) -> Vec<(f64, f64)> {
    (0..=48)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 48.0;
            (x + r * a.cos(), y + r * a.sin())
        })
        .collect()
}

/// Axis ranges with equal metres per pixel on both axes, and the picture size.
fn layout(points: &[(f64, f64)]) -> ((f64, f64), (f64, f64), (u32, u32)) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
    {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    let margin = 1.0;
    (x0, x1, y0, y1) = (x0 - margin, x1 + margin, y0 - margin, y1 + margin);
    // Fixed chart decorations (label areas, margins, caption) in pixels.
    let (extra_w, extra_h) = (90.0, 120.0);
    let width = 900.0;
    let px_per_m = (width - extra_w) / (x1 - x0);
    let mut height = (y1 - y0) * px_per_m + extra_h;
    if height > 900.0 {
        // Too tall: keep the height, widen the x range instead.
        height = 900.0;
        let px_per_m = (height - extra_h) / (y1 - y0);
        let want = (width - extra_w) / px_per_m;
        let grow = (want - (x1 - x0)) / 2.0;
        (x0, x1) = (x0 - grow, x1 + grow);
    } else if height < 360.0 {
        height = 360.0;
        let want = (height - extra_h) / px_per_m;
        let grow = (want - (y1 - y0)) / 2.0;
        (y0, y1) = (y0 - grow, y1 + grow);
    }
    ((x0, x1), (y0, y1), (width as u32, height as u32))
}

/// Writes the picture: each leg's obstacles (grey discs) and planned route (dashed, through
/// its subgoals), driven path (thick), planned horizons (thin, faint), goal (dot and a
/// heading tick 0.5 m long), and the start pose.
pub fn write_svg(path: &Path, title: &str, start: Pose2, legs: &[LegTrace]) -> anyhow::Result<()> {
    let mut all: Vec<(f64, f64)> = vec![(start.x, start.y)];
    for leg in legs {
        all.extend(&leg.path);
        all.extend(leg.horizons.iter().flatten());
        all.push((leg.goal.x, leg.goal.y));
        for &(x, y, r) in &leg.obstacles {
            all.extend([(x - r, y - r), (x + r, y + r)]);
        }
    }
    let ((x0, x1), (y0, y1), size) = layout(&all);
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("cannot draw {}: {e}", path.display());

    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(err)?;

    for (i, leg) in legs.iter().enumerate() {
        let color = LEG_COLORS[i % LEG_COLORS.len()];
        for &(x, y, r) in &leg.obstacles {
            chart
                .draw_series([Polygon::new(
                    circle_points(x, y, r),
                    RGBColor(150, 150, 150).mix(0.6).filled(),
                )])
                .map_err(err)?;
        }
        if !leg.route.is_empty() {
            chart
                .draw_series(DashedLineSeries::new(
                    leg.route.iter().copied(),
                    6,
                    4,
                    color.mix(0.8).stroke_width(2),
                ))
                .map_err(err)?;
            chart
                .draw_series(
                    leg.route
                        .iter()
                        .map(|&p| Cross::new(p, 4, color.stroke_width(2))),
                )
                .map_err(err)?;
        }
        for h in &leg.horizons {
            chart
                .draw_series(LineSeries::new(
                    h.iter().copied(),
                    color.mix(0.45).stroke_width(1),
                ))
                .map_err(err)?;
        }
        let label = format!(
            "{}. {} ({})",
            i + 1,
            leg.name,
            if leg.reached {
                "reached"
            } else {
                "not reached"
            }
        );
        chart
            .draw_series(LineSeries::new(
                leg.path.iter().copied(),
                color.stroke_width(3),
            ))
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
        let g = leg.goal;
        let tip = (g.x + 0.5 * g.heading.cos(), g.y + 0.5 * g.heading.sin());
        chart
            .draw_series([PathElement::new(
                vec![(g.x, g.y), tip],
                color.stroke_width(1),
            )])
            .map_err(err)?;
        chart
            .draw_series([Circle::new((g.x, g.y), 5, color.filled())])
            .map_err(err)?;
    }
    let tip = (
        start.x + 0.8 * start.heading.cos(),
        start.y + 0.8 * start.heading.sin(),
    );
    chart
        .draw_series([PathElement::new(
            vec![(start.x, start.y), tip],
            BLACK.stroke_width(2),
        )])
        .map_err(err)?;
    chart
        .draw_series([Rectangle::new(
            [
                (start.x - 0.08, start.y - 0.08),
                (start.x + 0.08, start.y + 0.08),
            ],
            BLACK.filled(),
        )])
        .map_err(err)?
        .label(
            "start (black); ticks: goal headings; faint: planned horizons; dashed: route; grey: obstacles",
        )
        .legend(|(x, y)| Rectangle::new([(x + 6, y - 4), (x + 14, y + 4)], BLACK.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
