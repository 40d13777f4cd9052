//! The plot of one sweep: reached, time ratio and worst clearance over its levels.

use std::path::Path;

use anyhow::Result;
use plotters::style::RGBColor;

use super::figures::Figures;
use super::{Case, Sweep};
use crate::plots::{self, SweepPanel, SweepSeries};
use crate::report::PENETRATION_TOLERANCE;

/// Writes the sweep's SVG to `path`.
pub(super) fn sweep_plot(
    s: &Sweep,
    figures: &dyn Fn(&Case) -> (Figures, Figures),
    path: &Path,
) -> Result<()> {
    let paper_c = RGBColor(31, 119, 180);
    let obst_c = RGBColor(255, 127, 14);
    let f: Vec<(f64, Figures, Figures)> = s
        .levels
        .iter()
        .map(|l| {
            let (a, b) = figures(&l.case);
            (l.x, a, b)
        })
        .collect();
    let series = |label: &str, color, g: &dyn Fn(&Figures, &Figures) -> Option<f64>| SweepSeries {
        label: label.into(),
        color,
        points: f.iter().map(|(x, a, b)| (*x, g(a, b))).collect(),
    };
    let panels = vec![
        SweepPanel {
            y_desc: "reached [%]".into(),
            threshold: Some(98.0),
            series: vec![
                series("paper 128", paper_c, &|a, _| Some(100.0 * a.success_rate())),
                series("obstacles", obst_c, &|_, b| Some(100.0 * b.success_rate())),
            ],
        },
        SweepPanel {
            y_desc: "time ratio (mean)".into(),
            threshold: None,
            series: vec![
                series("paper: t / T*", paper_c, &|a, _| a.t_ratio),
                series("obstacles: t / t₀", obst_c, &|_, b| b.t_ratio),
            ],
        },
        SweepPanel {
            y_desc: "worst clearance [m]".into(),
            threshold: Some(-PENETRATION_TOLERANCE),
            series: vec![series("obstacles", obst_c, &|_, b| b.worst_clearance)],
        },
    ];
    plots::sweep_svg(path, s.title, s.x_desc, s.nominal, &panels)
}
