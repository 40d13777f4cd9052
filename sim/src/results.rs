//! Result files (DESIGN §7) and the summary statistics of an evaluation.
//!
//! `results.csv`: header
//! `name,method,success,t_converge,t_settle,path_length,min_clearance,solve_ms_median,solve_ms_max`,
//! and with movers (DESIGN §18) also `min_clearance_moving,protective_stops`;
//! one row a scenario and method; `success` is `true`/`false`; a quantity that
//! does not exist (no convergence, no obstacles) is an empty field. Times in
//! seconds, lengths in metres, solve times in milliseconds.

use std::fmt::Write as _;

/// The header of `results.csv`.
pub const HEADER: &str =
    "name,method,success,t_converge,t_settle,path_length,min_clearance,solve_ms_median,solve_ms_max";

/// The columns a run with movers adds (DESIGN §18).
pub const MOVING_COLUMNS: &str = "min_clearance_moving,protective_stops";

/// One row of `results.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct ResultRow {
    pub name: String,
    pub method: String,
    pub success: bool,
    /// First instant the success test holds [s].
    pub t_converge: Option<f64>,
    /// Instant after which it holds and |v_f| < 0.05 for the rest of the run [s].
    pub t_settle: Option<f64>,
    /// Front-axle path length up to convergence (the whole run if none) [m].
    pub path_length: f64,
    /// Smallest distance from the front axle to an obstacle's (inflated) circle [m].
    pub min_clearance: Option<f64>,
    pub solve_ms_median: f64,
    pub solve_ms_max: f64,
    /// With movers: the smallest clearance to one while the machine moved
    /// (`None`: none came while it moved) [m].
    pub min_clearance_moving: Option<f64>,
    /// With movers: how many protective stops (`None`: a run without movers).
    pub protective_stops: Option<usize>,
}

/// A malformed results file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{source_name}:{line}:{column}: {message}")]
pub struct ResultsError {
    pub source_name: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

/// Writes rows in the file format (round-trips through [`parse`]); the
/// movers' columns when a row has them.
pub fn to_csv(rows: &[ResultRow]) -> String {
    let moving = rows.iter().any(|r| r.protective_stops.is_some());
    let mut s = String::from(HEADER);
    if moving {
        s.push(',');
        s.push_str(MOVING_COLUMNS);
    }
    s.push('\n');
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{}",
            r.name,
            r.method,
            r.success,
            opt(r.t_converge),
            opt(r.t_settle),
            r.path_length,
            opt(r.min_clearance),
            r.solve_ms_median,
            r.solve_ms_max
        );
        if moving {
            s.pop();
            let _ = writeln!(
                s,
                ",{},{}",
                opt(r.min_clearance_moving),
                r.protective_stops.map_or(String::new(), |n| n.to_string())
            );
        }
    }
    s
}

/// Parses a results file; `source` names it in errors.
pub fn parse(text: &str, source: &str) -> Result<Vec<ResultRow>, ResultsError> {
    let fail = |line: usize, column: usize, message: String| ResultsError {
        source_name: source.to_string(),
        line,
        column,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let with_movers = format!("{HEADER},{MOVING_COLUMNS}");
    let moving = match lines.next() {
        Some((_, h)) if h.trim().trim_start_matches('\u{feff}') == HEADER => false,
        Some((_, h)) if h.trim().trim_start_matches('\u{feff}') == with_movers => true,
        Some((_, h)) => {
            return Err(fail(
                1,
                1,
                format!(
                    "bad header `{}`: expected `{HEADER}` or `{with_movers}`",
                    h.trim()
                ),
            ))
        }
        None => {
            return Err(fail(
                1,
                1,
                format!("empty file: expected the header `{HEADER}`"),
            ))
        }
    };
    let header = if moving { with_movers.as_str() } else { HEADER };
    let keys: Vec<&str> = header.split(',').collect();
    let mut rows = Vec::new();
    for (index, raw) in lines {
        let line_no = index + 1;
        let fields: Vec<&str> = raw.trim_end_matches('\r').split(',').collect();
        if fields.len() != keys.len() {
            return Err(fail(
                line_no,
                1,
                format!("expected {} fields, found {}", keys.len(), fields.len()),
            ));
        }
        let mut columns = Vec::with_capacity(fields.len());
        let mut c = 1;
        for f in &fields {
            columns.push(c);
            c += f.chars().count() + 1;
        }
        let number = |k: usize| -> Result<f64, ResultsError> {
            let t = fields[k].trim();
            t.parse::<f64>()
                .ok()
                .filter(|v| !v.is_nan())
                .ok_or_else(|| {
                    fail(
                        line_no,
                        columns[k],
                        format!("`{}`: `{t}` is not a number", keys[k]),
                    )
                })
        };
        let optional = |k: usize| -> Result<Option<f64>, ResultsError> {
            if fields[k].trim().is_empty() {
                Ok(None)
            } else {
                number(k).map(Some)
            }
        };
        let success = match fields[2].trim() {
            "true" => true,
            "false" => false,
            t => {
                return Err(fail(
                    line_no,
                    columns[2],
                    format!("`success`: `{t}` is not true or false"),
                ))
            }
        };
        if fields[0].trim().is_empty() {
            return Err(fail(line_no, 1, "empty scenario name".into()));
        }
        if fields[1].trim().is_empty() {
            return Err(fail(line_no, columns[1], "empty method".into()));
        }
        rows.push(ResultRow {
            name: fields[0].trim().to_string(),
            method: fields[1].trim().to_string(),
            success,
            t_converge: optional(3)?,
            t_settle: optional(4)?,
            path_length: number(5)?,
            min_clearance: optional(6)?,
            solve_ms_median: number(7)?,
            solve_ms_max: number(8)?,
            min_clearance_moving: if moving { optional(9)? } else { None },
            protective_stops: if moving {
                let t = fields[10].trim();
                Some(t.parse::<usize>().map_err(|_| {
                    fail(
                        line_no,
                        columns[10],
                        format!("`protective_stops`: `{t}` is not a count"),
                    )
                })?)
            } else {
                None
            },
        });
    }
    Ok(rows)
}

/// Mean, standard deviation (sample), median of a non-empty set.
pub fn mean_std_median(v: &[f64]) -> Option<(f64, f64, f64)> {
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt(), quantile(v, 0.5)))
}

/// Quantile by linear interpolation between order statistics (q in [0, 1]).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let i = pos.floor() as usize;
    let f = pos - i as f64;
    if i + 1 < s.len() {
        s[i] * (1.0 - f) + s[i + 1] * f
    } else {
        s[i]
    }
}

/// Statistics of one method over a scenario set.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodSummary {
    pub method: String,
    pub scenarios: usize,
    pub successes: usize,
    /// Convergence time over successful scenarios: mean, std, median [s].
    pub t_converge: Option<(f64, f64, f64)>,
    /// Against the baseline on the scenarios both solved: (improvement of
    /// the mean %, improvement of the median %, scenarios compared).
    pub vs_baseline: Option<(f64, f64, usize)>,
    /// Mean of t / T* over the scenarios both solved, and how many.
    pub vs_min_time: Option<(f64, usize)>,
    /// Solve time per tick (per solve for the NLP methods): median, p99, max [ms].
    pub solve_ms: Option<(f64, f64, f64)>,
    /// Wall time spent on this method, summed over scenarios [s].
    pub wall_s: f64,
}

/// Summarises rows per method (in `methods` order); `solve_samples` are each
/// method's individual solve times [ms] and `wall` its summed wall time [s].
pub fn summarize(
    rows: &[ResultRow],
    methods: &[String],
    solve_samples: &[Vec<f64>],
    wall: &[f64],
) -> Vec<MethodSummary> {
    let time_of = |method: &str, name: &str| -> Option<f64> {
        rows.iter()
            .find(|r| r.method == method && r.name == name && r.success)
            .and_then(|r| r.t_converge)
    };
    methods
        .iter()
        .enumerate()
        .map(|(mi, m)| {
            let mine: Vec<&ResultRow> = rows.iter().filter(|r| &r.method == m).collect();
            let times: Vec<f64> = mine
                .iter()
                .filter(|r| r.success)
                .filter_map(|r| r.t_converge)
                .collect();
            let paired = |other: &str| -> Vec<(f64, f64)> {
                mine.iter()
                    .filter(|r| r.success)
                    .filter_map(|r| Some((r.t_converge?, time_of(other, &r.name)?)))
                    .collect()
            };
            let vs_baseline = (m != "baseline")
                .then(|| paired("baseline"))
                .filter(|p| !p.is_empty())
                .map(|p| {
                    let a: Vec<f64> = p.iter().map(|x| x.0).collect();
                    let b: Vec<f64> = p.iter().map(|x| x.1).collect();
                    let (ma, mb) = (
                        a.iter().sum::<f64>() / a.len() as f64,
                        b.iter().sum::<f64>() / b.len() as f64,
                    );
                    let (qa, qb) = (quantile(&a, 0.5), quantile(&b, 0.5));
                    (100.0 * (mb - ma) / mb, 100.0 * (qb - qa) / qb, p.len())
                });
            let vs_min_time = (m != "min-time")
                .then(|| paired("min-time"))
                .filter(|p| !p.is_empty())
                .map(|p| {
                    (
                        p.iter().map(|(t, tm)| t / tm.max(1e-9)).sum::<f64>() / p.len() as f64,
                        p.len(),
                    )
                });
            let samples = solve_samples.get(mi).map(|v| v.as_slice()).unwrap_or(&[]);
            let solve_ms = (!samples.is_empty()).then(|| {
                (
                    quantile(samples, 0.5),
                    quantile(samples, 0.99),
                    samples.iter().cloned().fold(0.0, f64::max),
                )
            });
            MethodSummary {
                method: m.clone(),
                scenarios: mine.len(),
                successes: mine.iter().filter(|r| r.success).count(),
                t_converge: mean_std_median(&times),
                vs_baseline,
                vs_min_time,
                solve_ms,
                wall_s: wall.get(mi).copied().unwrap_or(0.0),
            }
        })
        .collect()
}

/// The summary as a Markdown table.
pub fn summary_markdown(summaries: &[MethodSummary]) -> String {
    let mut s = String::from(
        "| method | success | t_converge mean ± std [s] | median [s] | vs baseline (mean / median) | t / T* (mean) | solve ms median / p99 / max | wall [s] |\n|---|---|---|---|---|---|---|---|\n",
    );
    for m in summaries {
        let t = m
            .t_converge
            .map_or("–".into(), |(a, b, _)| format!("{a:.2} ± {b:.2}"));
        let med = m
            .t_converge
            .map_or("–".into(), |(_, _, c)| format!("{c:.2}"));
        let vb = m.vs_baseline.map_or("–".into(), |(a, b, n)| {
            format!("{a:+.1} % / {b:+.1} % (n = {n})")
        });
        let vm = m
            .vs_min_time
            .map_or("–".into(), |(r, n)| format!("{r:.3} (n = {n})"));
        let sm = m.solve_ms.map_or("–".into(), |(a, b, c)| {
            format!("{a:.2} / {b:.2} / {c:.2}")
        });
        let _ = writeln!(
            s,
            "| {} | {}/{} | {} | {} | {} | {} | {} | {:.1} |",
            m.method, m.successes, m.scenarios, t, med, vb, vm, sm, m.wall_s
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_stats() {
        let v = [3.0, 1.0, 2.0, 4.0];
        assert_eq!(quantile(&v, 0.5), 2.5);
        assert_eq!(quantile(&v, 1.0), 4.0);
        let (m, s, med) = mean_std_median(&v).unwrap();
        assert_eq!((m, med), (2.5, 2.5));
        assert!((s - (5.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!(mean_std_median(&[]).is_none());
    }
}
