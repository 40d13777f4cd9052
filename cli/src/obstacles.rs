//! `wlnav obstacles publish FILE|-`: live obstacle sets from JSON Lines to the daemon's
//! `{prefix}/v2/obstacles` service (DESIGN §18), as a perception stack would publish them.
//!
//! One set per line:
//!
//! ```json
//! {"obstacles":[{"id":1,"class":"person","circle":{"x":3.0,"y":0.0,"radius":0.4},"velocity":[0.0,1.4]},
//!               {"id":2,"polygon":[[0,0],[2,0],[2,1],[0,1]]}]}
//! ```
//!
//! (on one line in the file). `id` (0 to 4294967295) and one of `circle` (`x`, `y`,
//! `radius`: the physical radius, metres) or `polygon` (3 to 8 `[x, y]` vertices, convex,
//! either winding) are required; `class` (`unknown`, `person`, `vehicle`, `machine`,
//! `static`; default `unknown`) and `velocity` (`[vx, vy]` m/s, default at rest) are
//! optional. Unknown fields are errors: a typo must not pass silently. Blank lines are
//! skipped. Every line is checked with the daemon's own [`LiveObstacleValidator`], so a
//! set the daemon would reject is refused here, naming the line and the rule.

use std::io::BufRead;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde_json::{Map, Value};

use shm_ipc::{
    monotonic_now_ns, LiveObstacle, LiveObstacleSet, LiveObstacleValidator, ObstacleClass,
    ObstaclePublisher, MAX_LIVE_OBSTACLES,
};

use super::commands::emit;
use super::{exit, signal, Cli, ObstaclesPublishArgs};

/// One line's obstacles, without stamps (those are taken when the set is published).
pub type ParsedSet = Vec<LiveObstacle>;

/// The number at `key` of `obj`, which must be there.
fn number(obj: &Map<String, Value>, key: &str, what: &str) -> Result<f64, String> {
    match obj.get(key) {
        None => Err(format!("{what}: `{key}` is missing")),
        Some(v) => v
            .as_f64()
            .ok_or_else(|| format!("{what}: `{key}` must be a number, got {v}")),
    }
}

/// A `[x, y]` pair.
fn pair(v: &Value, what: &str) -> Result<[f64; 2], String> {
    match v.as_array().map(Vec::as_slice) {
        Some([x, y]) => match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => Ok([x, y]),
            _ => Err(format!("{what} must be two numbers [x, y], got {v}")),
        },
        _ => Err(format!("{what} must be two numbers [x, y], got {v}")),
    }
}

/// `obj`'s keys must all be in `allowed`.
fn only_keys(obj: &Map<String, Value>, allowed: &[&str], what: &str) -> Result<(), String> {
    match obj.keys().find(|k| !allowed.contains(&k.as_str())) {
        Some(k) => Err(format!(
            "{what}: unknown field `{k}` (expected {})",
            allowed.join(", ")
        )),
        None => Ok(()),
    }
}

/// One obstacle of a line, stamped `stamp_ns`.
fn obstacle(v: &Value, index: usize, stamp_ns: u64) -> Result<LiveObstacle, String> {
    let what = format!("obstacle {index}");
    let obj = v
        .as_object()
        .ok_or_else(|| format!("{what} must be an object, got {v}"))?;
    only_keys(
        obj,
        &["id", "class", "circle", "polygon", "velocity"],
        &what,
    )?;
    let id = obj
        .get("id")
        .ok_or_else(|| format!("{what}: `id` is missing"))?;
    let id = id
        .as_u64()
        .and_then(|id| u32::try_from(id).ok())
        .ok_or_else(|| format!("{what}: `id` must be a whole number 0 to 4294967295, got {id}"))?;
    let what = format!("obstacle {index} (id {id})");
    let class = match obj.get("class") {
        None => ObstacleClass::Unknown,
        Some(c) => c
            .as_str()
            .and_then(ObstacleClass::from_name)
            .ok_or_else(|| {
                let names: Vec<&str> = ObstacleClass::ALL.iter().map(|c| c.name()).collect();
                format!("{what}: unknown class {c} (expected {})", names.join(", "))
            })?,
    };
    let velocity = match obj.get("velocity") {
        None => [0.0, 0.0],
        Some(v) => pair(v, &format!("{what}: `velocity`"))?,
    };
    match (obj.get("circle"), obj.get("polygon")) {
        (Some(c), None) => {
            let what = format!("{what}: `circle`");
            let c = c
                .as_object()
                .ok_or_else(|| format!("{what} must be an object {{x, y, radius}}, got {c}"))?;
            only_keys(c, &["x", "y", "radius"], &what)?;
            let centre = [number(c, "x", &what)?, number(c, "y", &what)?];
            let radius = number(c, "radius", &what)?;
            Ok(LiveObstacle::circle(
                id, class, centre, radius, velocity, stamp_ns,
            ))
        }
        (None, Some(p)) => {
            let what = format!("{what}: `polygon`");
            let points = p
                .as_array()
                .ok_or_else(|| format!("{what} must be a list of [x, y] vertices, got {p}"))?;
            let vertices = points
                .iter()
                .enumerate()
                .map(|(k, v)| pair(v, &format!("{what} vertex {k}")))
                .collect::<Result<Vec<_>, _>>()?;
            LiveObstacle::polygon(id, class, &vertices, velocity, stamp_ns)
                .map_err(|e| format!("{what}: {e}"))
        }
        (Some(_), Some(_)) => Err(format!("{what}: give `circle` or `polygon`, not both")),
        (None, None) => Err(format!("{what}: `circle` or `polygon` is missing")),
    }
}

/// Parses one JSON line into its obstacles and checks the set they make with the
/// daemon's validator (stamped now, as it will be when published). `Ok(None)` for a
/// blank line. The error says what is wrong in plain words (without the line number).
pub fn parse_line(
    line: &str,
    validator: &LiveObstacleValidator,
) -> Result<Option<ParsedSet>, String> {
    if line.trim().is_empty() {
        return Ok(None);
    }
    let v: Value = serde_json::from_str(line).map_err(|e| format!("not valid JSON: {e}"))?;
    let obj = v
        .as_object()
        .ok_or_else(|| format!("a set must be an object {{\"obstacles\": [...]}}, got {v}"))?;
    only_keys(obj, &["obstacles"], "the set")?;
    let list = obj
        .get("obstacles")
        .ok_or("the set: `obstacles` is missing")?
        .as_array()
        .ok_or("the set: `obstacles` must be a list")?;
    if list.len() > MAX_LIVE_OBSTACLES {
        return Err(format!(
            "the set has {} obstacles, at most {MAX_LIVE_OBSTACLES} fit",
            list.len()
        ));
    }
    let now = monotonic_now_ns();
    let obstacles = list
        .iter()
        .enumerate()
        .map(|(i, o)| obstacle(o, i, now))
        .collect::<Result<ParsedSet, _>>()?;
    let set = stamped(&obstacles, now, 0);
    validator
        .validate(&set, now)
        .map_err(|r| format!("the daemon would reject this set ({}): {r}", r.rule()))?;
    Ok(Some(obstacles))
}

/// The set of `obstacles`, the set and every obstacle stamped `now_ns`.
pub fn stamped(obstacles: &[LiveObstacle], now_ns: u64, sequence: u32) -> LiveObstacleSet {
    let mut set = LiveObstacleSet::empty(now_ns, sequence);
    for (slot, o) in set.obstacles.iter_mut().zip(obstacles) {
        *slot = LiveObstacle {
            timestamp_ns: now_ns,
            ..*o
        };
    }
    set.count = obstacles.len().min(MAX_LIVE_OBSTACLES) as u32;
    set
}

/// A bad input line: its number (1-based) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadLine {
    /// 1-based line number
    pub line: usize,
    /// What is wrong
    pub why: String,
}

impl std::fmt::Display for BadLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.why)
    }
}

/// What the publishing loop gets next.
enum Next {
    /// A set to publish.
    Set(ParsedSet),
    /// Nothing yet (standard input is quiet): publish the last set again.
    Pending,
    /// The input has ended.
    End,
    /// A bad line: stop.
    Bad(BadLine),
}

/// Every set of `reader`, checked before anything is published.
pub fn read_all(
    reader: impl BufRead,
    validator: &LiveObstacleValidator,
) -> anyhow::Result<Result<Vec<ParsedSet>, BadLine>> {
    let mut sets = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.with_context(|| format!("cannot read line {}", i + 1))?;
        match parse_line(&line, validator) {
            Ok(Some(set)) => sets.push(set),
            Ok(None) => {}
            Err(why) => return Ok(Err(BadLine { line: i + 1, why })),
        }
    }
    Ok(Ok(sets))
}

/// Standard input, read on its own thread so a quiet pipe does not stop the publishing
/// (the last set repeats meanwhile). The channel holds a few lines: a producer faster than
/// `--rate` is slowed down, not buffered without bound.
fn stdin_lines(validator: LiveObstacleValidator) -> mpsc::Receiver<Next> {
    let (tx, rx) = mpsc::sync_channel(4);
    std::thread::spawn(move || {
        for (i, line) in std::io::stdin().lock().lines().enumerate() {
            let next = match line {
                Err(e) => Next::Bad(BadLine {
                    line: i + 1,
                    why: format!("cannot read standard input: {e}"),
                }),
                Ok(line) => match parse_line(&line, &validator) {
                    Ok(Some(set)) => Next::Set(set),
                    Ok(None) => continue,
                    Err(why) => Next::Bad(BadLine { line: i + 1, why }),
                },
            };
            let bad = matches!(next, Next::Bad(_));
            if tx.send(next).is_err() || bad {
                return;
            }
        }
        let _ = tx.send(Next::End);
    });
    rx
}

/// Sleeps until `deadline` in short slices; false if Ctrl-C came first.
fn sleep_until(deadline: Instant) -> bool {
    loop {
        if signal::requested() {
            return false;
        }
        let now = Instant::now();
        if now >= deadline {
            return true;
        }
        std::thread::sleep((deadline - now).min(Duration::from_millis(50)));
    }
}

/// `wlnav obstacles publish FILE|-`.
pub fn publish(cli: &Cli, a: &ObstaclesPublishArgs) -> anyhow::Result<u8> {
    let validator = LiveObstacleValidator::default();
    // A file is checked whole first: a bad line 40 must not go out after 39 good ones.
    let mut next: Box<dyn FnMut() -> Next> = if a.file == "-" {
        let rx = stdin_lines(validator);
        Box::new(move || match rx.try_recv() {
            Ok(next) => next,
            Err(mpsc::TryRecvError::Empty) => Next::Pending,
            Err(mpsc::TryRecvError::Disconnected) => Next::End,
        })
    } else {
        let file =
            std::fs::File::open(&a.file).with_context(|| format!("cannot open {}", a.file))?;
        let sets = match read_all(std::io::BufReader::new(file), &validator)? {
            Ok(sets) => sets,
            Err(bad) => {
                eprintln!("wlnav: {}: {bad}; nothing published", a.file);
                return Ok(exit::REJECTED);
            }
        };
        let mut sets = sets.into_iter();
        Box::new(move || match sets.next() {
            Some(set) => Next::Set(set),
            None => Next::End,
        })
    };
    let config = cli.ipc_config();
    let publisher = ObstaclePublisher::connect(&config, Duration::from_secs_f64(a.connect_timeout))
        .with_context(|| {
            format!(
                "cannot publish live obstacles on prefix {:?}",
                config.prefix
            )
        })?;
    let period = Duration::from_secs_f64(1.0 / a.rate);
    // The rate's ticks and the duration count from the first set: standard
    // input may deliver its first line late (a loaded machine), and a tick
    // with nothing to publish would be lost from the count.
    let mut clock: Option<(Instant, Option<Instant>)> = None;
    let mut last: Option<ParsedSet> = None;
    let (mut sequence, mut from_input, mut tick) = (0u32, 0usize, 0u32);
    let mut input_open = true;
    loop {
        if input_open {
            match next() {
                Next::Set(set) => {
                    last = Some(set);
                    from_input += 1;
                }
                Next::Pending => {}
                Next::End => input_open = false,
                Next::Bad(bad) => {
                    eprintln!("wlnav: standard input: {bad}; not published ({sequence} sets were)");
                    return Ok(exit::REJECTED);
                }
            }
        }
        if !input_open && a.once {
            break;
        }
        let Some(obstacles) = &last else {
            if !input_open {
                break;
            }
            // Nothing to publish yet: wait for the first line.
            if !sleep_until(Instant::now() + Duration::from_millis(1)) {
                emit("interrupted: published 0 sets (0 from the input)");
                return Ok(exit::INTERRUPTED);
            }
            continue;
        };
        let (start, end) = *clock.get_or_insert_with(|| {
            let start = Instant::now();
            (
                start,
                a.duration.map(|d| start + Duration::from_secs_f64(d)),
            )
        });
        publisher.publish(&stamped(obstacles, monotonic_now_ns(), sequence))?;
        sequence = sequence.wrapping_add(1);
        // Absolute deadlines: the rate does not drift with the time a publish takes.
        tick = tick.saturating_add(1);
        let deadline = start + period * tick;
        if end.is_some_and(|end| deadline >= end) {
            break;
        }
        if !sleep_until(deadline) {
            emit(&format!(
                "interrupted: published {sequence} sets ({from_input} from the input)"
            ));
            return Ok(exit::INTERRUPTED);
        }
    }
    emit(&format!(
        "published {sequence} sets on {} ({from_input} from the input)",
        publisher.service_name()
    ));
    Ok(exit::OK)
}
