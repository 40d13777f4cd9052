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
    /// The global layer's first route for the leg (subgoals, then the goal) [m]; empty
    /// when the way was direct.
    pub route: Vec<(f64, f64)>,
    /// The machine where the leg ended: front axle x, y, heading θ, articulation β.
    pub end: Option<[f64; 4]>,
    /// Where the daemon slowed down for a live obstacle (`live-slowing`) [m].
    pub slowed: Vec<(f64, f64)>,
    /// Where it held after a protective stop for one (`protective-stop`) [m].
    pub held: Vec<(f64, f64)>,
}

/// The demo machine's geometry for drawing its outline: the Avant 635 (DESIGN §2: L_f =
/// L_r = 0.6 m) with wlnavd's default outline, a circle of the half-width (0.65 m) at each
/// axle (DESIGN §17). The client speaks only the wire, which carries no geometry.
const DEMO_L_F: f64 = 0.6;
const DEMO_L_R: f64 = 0.6;
const DEMO_HALF_WIDTH: f64 = 0.65;

/// The default outline's circles (front axle, rear axle) for a machine state.
fn outline_circles(end: [f64; 4]) -> [(f64, f64); 2] {
    let [x, y, th, beta] = end;
    let rear = (
        x - DEMO_L_F * th.cos() - DEMO_L_R * (th - beta).cos(),
        y - DEMO_L_F * th.sin() - DEMO_L_R * (th - beta).sin(),
    );
    [(x, y), rear]
}

/// A site file's shapes, read for drawing only (the daemon validates the file; a shape
/// this cannot read is left out of the picture).
#[derive(Debug, Clone, Default)]
pub struct SiteDrawing {
    /// The site's id.
    pub id: String,
    /// The bounds' ring.
    pub bounds: Vec<(f64, f64)>,
    /// Filled shapes: (outline, keep-out?); a polyline is several.
    pub shapes: Vec<(Vec<(f64, f64)>, bool)>,
    /// The features drawn (obstacles and keep-outs).
    pub features: usize,
}

impl SiteDrawing {
    /// Reads a `wlnav-site-v1` file (DESIGN §17).
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow!("site file {}: {e}", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| anyhow!("site file {}: {e}", path.display()))?;
        let ring = |v: &serde_json::Value| -> Vec<(f64, f64)> {
            v.as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|p| Some((p.get(0)?.as_f64()?, p.get(1)?.as_f64()?)))
                        .collect()
                })
                .unwrap_or_default()
        };
        let mut d = SiteDrawing {
            id: v["id"].as_str().unwrap_or_default().to_owned(),
            bounds: ring(&v["bounds"]),
            shapes: Vec::new(),
            features: 0,
        };
        for (list, keepout) in [("obstacles", false), ("keepout", true)] {
            for f in v[list].as_array().into_iter().flatten() {
                let shapes_before = d.shapes.len();
                if let Some(c) = f["circle"].as_array() {
                    let c: Vec<f64> = c.iter().filter_map(|x| x.as_f64()).collect();
                    if c.len() == 3 {
                        d.shapes.push((circle_points(c[0], c[1], c[2]), keepout));
                    }
                } else if f["polygon"].is_array() {
                    d.shapes.push((ring(&f["polygon"]), keepout));
                } else if f["polyline"].is_array() {
                    let line = ring(&f["polyline"]);
                    let r = 0.5 * f["width"].as_f64().unwrap_or(0.0);
                    // A capsule chain: a disc at each vertex, a quad per segment.
                    for &(x, y) in &line {
                        d.shapes.push((circle_points(x, y, r), keepout));
                    }
                    for s in line.windows(2) {
                        let (dx, dy) = (s[1].0 - s[0].0, s[1].1 - s[0].1);
                        let n = dx.hypot(dy).max(1e-9);
                        let (nx, ny) = (-dy / n * r, dx / n * r);
                        d.shapes.push((
                            vec![
                                (s[0].0 + nx, s[0].1 + ny),
                                (s[1].0 + nx, s[1].1 + ny),
                                (s[1].0 - nx, s[1].1 - ny),
                                (s[0].0 - nx, s[0].1 - ny),
                            ],
                            keepout,
                        ));
                    }
                }
                d.features += usize::from(d.shapes.len() > shapes_before);
            }
        }
        Ok(d)
    }
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

/// Axis ranges with equal metres per pixel on both axes, and the picture size; the top
/// `legend_px` pixels of the plot are left free of data for the legend.
fn layout(points: &[(f64, f64)], legend_px: f64) -> ((f64, f64), (f64, f64), (u32, u32)) {
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
    let mut height = (y1 - y0) * px_per_m + extra_h + legend_px;
    if height > 900.0 {
        // Too tall: keep the height, widen the x range instead.
        height = 900.0;
        let px_per_m = (height - extra_h - legend_px) / (y1 - y0);
        y1 += legend_px / px_per_m;
        let want = (width - extra_w) / px_per_m;
        let grow = (want - (x1 - x0)) / 2.0;
        (x0, x1) = (x0 - grow, x1 + grow);
    } else if height < 360.0 {
        y1 += legend_px / px_per_m;
        height = 360.0;
        let want = (height - extra_h) / px_per_m;
        let grow = (want - (y1 - y0)) / 2.0;
        (y0, y1) = (y0 - grow, y1 + grow);
    } else {
        y1 += legend_px / px_per_m;
    }
    ((x0, x1), (y0, y1), (width as u32, height as u32))
}

/// Writes the picture: the site (bounds, grey features, red keep-outs), each leg's planned
/// route (dashed, through its subgoals), driven path (thick), planned horizons (thin,
/// faint), goal (dot and a heading tick 0.5 m long), the outline where it ended, and the
/// start pose.
pub fn write_svg(
    path: &Path,
    title: &str,
    start: Pose2,
    legs: &[LegTrace],
    site: Option<&SiteDrawing>,
) -> anyhow::Result<()> {
    let mut all: Vec<(f64, f64)> = vec![(start.x, start.y)];
    if let Some(site) = site {
        all.extend(site.shapes.iter().flat_map(|(s, _)| s.iter().copied()));
    }
    for leg in legs {
        all.extend(&leg.path);
        all.extend(leg.horizons.iter().flatten());
        all.push((leg.goal.x, leg.goal.y));
    }
    // The legend's rows (one per leg, the live obstacles' two and the key) at about
    // 19 px each, and its frame.
    let live_rows = [
        legs.iter().any(|l| !l.slowed.is_empty()),
        legs.iter().any(|l| !l.held.is_empty()),
    ]
    .iter()
    .filter(|&&r| r)
    .count();
    let legend_px = 19.0 * (legs.len() + 1 + live_rows) as f64 + 16.0;
    let ((x0, x1), (y0, y1), size) = layout(&all, legend_px);
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

    if let Some(site) = site {
        let mut ring = site.bounds.clone();
        if let Some(&first) = ring.first() {
            ring.push(first);
        }
        chart
            .draw_series([PathElement::new(ring, BLACK.stroke_width(1))])
            .map_err(err)?;
        for (shape, keepout) in &site.shapes {
            let color = if *keepout {
                RGBColor(214, 39, 40).mix(0.35)
            } else {
                RGBColor(140, 140, 140).mix(0.6)
            };
            chart
                .draw_series([Polygon::new(shape.clone(), color.filled())])
                .map_err(err)?;
        }
    }
    for (i, leg) in legs.iter().enumerate() {
        let color = LEG_COLORS[i % LEG_COLORS.len()];
        if let Some(end) = leg.end {
            // The machine's outline where the leg ended.
            for (x, y) in outline_circles(end) {
                chart
                    .draw_series([PathElement::new(
                        circle_points(x, y, DEMO_HALF_WIDTH),
                        color.stroke_width(1),
                    )])
                    .map_err(err)?;
            }
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
    // Where live obstacles slowed the machine (orange rings) and held it after a
    // protective stop (red squares), every leg's.
    let slowed: Vec<(f64, f64)> = legs.iter().flat_map(|l| l.slowed.iter().copied()).collect();
    let held: Vec<(f64, f64)> = legs.iter().flat_map(|l| l.held.iter().copied()).collect();
    let orange = RGBColor(255, 127, 14);
    let red = RGBColor(214, 39, 40);
    if !slowed.is_empty() {
        chart
            .draw_series(
                slowed
                    .iter()
                    .map(|&p| Circle::new(p, 5, orange.stroke_width(2))),
            )
            .map_err(err)?
            .label("slowed for a live obstacle")
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, orange.stroke_width(2)));
    }
    if !held.is_empty() {
        chart
            .draw_series(held.iter().map(|&p| Circle::new(p, 6, red.filled())))
            .map_err(err)?
            .label("held after a protective stop (a live obstacle in the way)")
            .legend(move |(x, y)| Circle::new((x + 10, y), 6, red.filled()));
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
            "start (black); ticks: goal headings; faint: planned horizons; dashed: route; grey: obstacles; red: keep-outs; rings: the outline at each leg's end",
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
