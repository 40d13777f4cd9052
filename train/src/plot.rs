//! SVG learning curves from a run's CSV logs.

use std::path::Path;

use anyhow::{Context, Result};
use plotters::prelude::*;

/// Reads a CSV with a header into (header, rows of numbers); unparsable cells become NaN.
pub fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|c| c.trim().parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    Ok((header, rows))
}

fn column(header: &[String], rows: &[Vec<f64>], name: &str) -> Vec<f64> {
    match header.iter().position(|h| h == name) {
        Some(i) => rows
            .iter()
            .map(|r| r.get(i).copied().unwrap_or(f64::NAN))
            .collect(),
        None => Vec::new(),
    }
}

/// One panel: series of (x, y) named, on a linear or log y axis.
fn panel(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    title: &str,
    x: &[f64],
    series: &[(&str, Vec<f64>)],
    log_y: bool,
) -> Result<()> {
    let points: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|(_, ys)| {
            x.iter()
                .zip(ys)
                .filter(|(a, b)| a.is_finite() && b.is_finite() && (!log_y || **b > 0.0))
                .map(|(a, b)| (*a, if log_y { b.log10() } else { *b }))
                .collect()
        })
        .collect();
    let all: Vec<&(f64, f64)> = points.iter().flatten().collect();
    if all.is_empty() {
        return Ok(());
    }
    let (x0, x1) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let pad = ((y1 - y0) * 0.05).max(1e-9);
    let mut chart = ChartBuilder::on(area)
        .caption(
            if log_y {
                format!("{title} (log10)")
            } else {
                title.to_string()
            },
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(28)
        .y_label_area_size(48)
        .build_cartesian_2d(x0..x1.max(x0 + 1.0), (y0 - pad)..(y1 + pad))?;
    chart
        .configure_mesh()
        .x_desc("updates")
        .light_line_style(WHITE)
        .draw()?;
    for (k, ((name, _), pts)) in series.iter().zip(points).enumerate() {
        let color = Palette99::pick(k).to_rgba();
        chart
            .draw_series(LineSeries::new(pts, color.stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Writes `learning_curves.svg` in `run_dir` from `log.csv` and `eval.csv`.
pub fn learning_curves(run_dir: &Path) -> Result<()> {
    let (h, rows) = read_csv(&run_dir.join("log.csv"))?;
    let eval = read_csv(&run_dir.join("eval.csv")).unwrap_or_default();
    let out = run_dir.join("learning_curves.svg");
    let root = SVGBackend::new(&out, (1200, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((2, 2));
    let x = column(&h, &rows, "updates");
    panel(
        &areas[0],
        "critic loss",
        &x,
        &[
            ("critic", column(&h, &rows, "critic_loss")),
            ("gradient penalty", column(&h, &rows, "penalty")),
        ],
        true,
    )?;
    panel(
        &areas[1],
        "multipliers",
        &x,
        &[
            ("lambda_l", column(&h, &rows, "lambda_l")),
            ("lambda_e", column(&h, &rows, "lambda_e")),
        ],
        false,
    )?;
    panel(
        &areas[2],
        "mean L and Delta L",
        &x,
        &[
            ("mean L", column(&h, &rows, "mean_l")),
            ("Delta L", column(&h, &rows, "delta_l")),
        ],
        false,
    )?;
    let (eh, erows) = eval;
    let ex = column(&eh, &erows, "updates");
    panel(
        &areas[3],
        "actor success on held-out goals",
        &ex,
        &[
            ("within 0.1", column(&eh, &erows, "success_0.1")),
            ("within 0.3", column(&eh, &erows, "success_0.3")),
        ],
        false,
    )?;
    root.present()?;
    Ok(())
}
