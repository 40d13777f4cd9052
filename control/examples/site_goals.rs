//! Writes a site's goal set as a scenario file to stdout (DESIGN §17, issue
//! 40; `control::site::goals`), reproducible by its seed; a summary (goals,
//! V-cycle legs, mean start–goal distance) goes to stderr.
//!
//! `cargo run -p control --example site_goals -- sim/sites/quarry.json 40 40 > sim/scenarios/site-quarry.csv`
//!
//! A site that cannot give all that is asked fails (exit 1) naming what is
//! missing, and writes nothing.

use std::sync::Arc;

use control::scenario::{to_csv, Scenario};
use control::site::goals::site_scenarios;
use control::site::{Site, SiteIndex};
use control::world::World;
use control::MachineParams;

fn summary(site: &Arc<SiteIndex>, scenarios: &[Scenario]) -> String {
    let legs = scenarios
        .iter()
        .filter(|s| s.name.starts_with("vcycle"))
        .count();
    // The random goals whose straight line a disc of the default outline's
    // radius cannot sweep (what the generator aims for in three of four).
    let mut world = World::with_axle_circles(MachineParams::default(), 0);
    world.set_site(Some(site.clone()));
    let r = world.outline().half_width();
    let randoms: Vec<&Scenario> = scenarios
        .iter()
        .filter(|s| s.name.starts_with("goal"))
        .collect();
    let blocked = randoms
        .iter()
        .filter(|s| !world.segment_clear([s.start[0], s.start[1]], [s.goal.x, s.goal.y], r, 0.0))
        .count();
    let mean = scenarios
        .iter()
        .map(|s| (s.goal.x - s.start[0]).hypot(s.goal.y - s.start[1]))
        .sum::<f64>()
        / scenarios.len().max(1) as f64;
    format!(
        "{} goals, {legs} V-cycle legs, {blocked} of {} random goals' straight line blocked, mean start-goal distance {mean:.1} m",
        scenarios.len(),
        randoms.len()
    )
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: site_goals SITE_FILE SEED COUNT";
    let [file, seed, count] = args.as_slice() else {
        return Err(usage.to_string());
    };
    let seed: u64 = seed
        .parse()
        .map_err(|_| format!("seed {seed:?}: {usage}"))?;
    let count: usize = count
        .parse()
        .map_err(|_| format!("count {count:?}: {usage}"))?;
    let bytes = std::fs::read(file).map_err(|e| format!("{file}: {e}"))?;
    let site = Site::parse(&bytes).map_err(|e| format!("{file}: {e}"))?;
    let id = site.id().to_string();
    let index = Arc::new(SiteIndex::new(site));
    match site_scenarios(&index, &MachineParams::default(), seed, count) {
        Ok(scenarios) => {
            print!("{}", to_csv(&scenarios));
            eprintln!("{id}: {}", summary(&index, &scenarios));
            Ok(())
        }
        Err(short) => Err(format!(
            "{id}: {short} ({})",
            summary(&index, &short.scenarios)
        )),
    }
}
