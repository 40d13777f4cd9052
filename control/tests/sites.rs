//! Every site file under `sim/sites/` loads and indexes (DESIGN §17), the
//! generated large pit is what its generator writes for its seed, and the
//! site goal sets (`sim/scenarios/site-*.csv`, issue 40) are their
//! generator's output, free for both outlines, with chained V-cycles.

use std::path::PathBuf;
use std::sync::Arc;

use control::scenario::{parse, to_csv, Scenario};
use control::site::generate::large_pit;
use control::site::goals::{site_scenarios, LEGS};
use control::site::{Body, FeatureKind, Outline, Site, SiteIndex};
use control::world::{default_outline, World};
use control::{MachineParams, State};

fn sites_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../sim/sites")
}

#[test]
fn every_site_file_loads() {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(sites_dir()).expect("sim/sites exists") {
        let path = entry.expect("readable directory").path();
        if path.extension().and_then(|e| e.to_str()) != Some("json") {
            continue;
        }
        let bytes = std::fs::read(&path).expect("readable file");
        let site = Site::parse(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        assert_eq!(
            site.id(),
            stem,
            "{}: the id is the file's name",
            path.display()
        );
        let idx = SiteIndex::new(site);
        // The evaluation's sites have work to do; the demo's is small on purpose.
        let least = if stem == "demo" { 3 } else { 10 };
        assert!(idx.site().features().len() >= least, "{}", path.display());
        names.push(stem);
    }
    for name in ["lane", "large-pit-40", "quarry", "yard"] {
        assert!(
            names.iter().any(|n| n == name),
            "{name} is missing from sim/sites"
        );
    }
}

#[test]
fn the_large_pit_file_is_its_generators_output() {
    let path = sites_dir().join("large-pit-40.json");
    let text = std::fs::read_to_string(&path).expect("the large pit is committed");
    let generated = large_pit(40, 520);
    assert_eq!(text, generated.to_json(), "regenerate: cargo run -p control --example site_gen -- large-pit 40 520 > sim/sites/large-pit-40.json");
    let site = Site::parse(text.as_bytes()).unwrap();
    assert!(site.features().len() >= 500);
}

#[test]
fn the_hand_made_sites_have_what_issue_40_asks_for() {
    let load = |name: &str| {
        let bytes = std::fs::read(sites_dir().join(format!("{name}.json"))).expect("site file");
        Site::parse(&bytes).expect("valid site")
    };
    let quarry = load("quarry");
    assert!(quarry.features().iter().any(|f| f.id.starts_with("berm")));
    assert!(
        quarry
            .features()
            .iter()
            .filter(|f| f.id.starts_with("pile"))
            .count()
            >= 6
    );
    let yard = load("yard");
    assert!(yard
        .features()
        .iter()
        .any(|f| f.kind == FeatureKind::KeepOut));
    assert!(yard.features().iter().any(|f| f.id.starts_with("truck")));
    let lane = load("lane");
    assert!(
        lane.features()
            .iter()
            .filter(|f| f.id.starts_with("pile"))
            .count()
            >= 12
    );
}

/// The committed site goal sets (issue 40): file, site, seed, count, and
/// whether V-cycles are asked of it.
const SITE_SETS: [(&str, &str, u64, usize, bool); 4] = [
    ("site-quarry.csv", "quarry", 40, 40, true),
    ("site-yard.csv", "yard", 40, 40, true),
    ("site-lane.csv", "lane", 40, 40, true),
    ("site-large-pit-40.csv", "large-pit-40", 40, 40, false),
];

fn scenarios_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios")
}

fn site_index(name: &str) -> Arc<SiteIndex> {
    let bytes = std::fs::read(sites_dir().join(format!("{name}.json"))).expect("site file");
    Arc::new(SiteIndex::new(Site::parse(&bytes).expect("valid site")))
}

/// The least clearance of a pose at rest (β = 0) over the default outline
/// and the Avant 635's, measured here and not by the generator.
fn least_clearance(site: &Arc<SiteIndex>, x: &State) -> f64 {
    [default_outline(), Outline::avant635()]
        .into_iter()
        .map(|o| {
            let mut w = World::new(MachineParams::default(), o, 0);
            w.set_site(Some(site.clone()));
            w.clearance(x)
        })
        .fold(f64::INFINITY, f64::min)
}

/// The clearance of the Avant 635's foremost front circle (its bucket) at
/// `x` to the nearest feature whose id starts with `prefix`.
fn bucket_clearance(site: &SiteIndex, x: &State, prefix: &str) -> f64 {
    let avant = Outline::avant635();
    let p = MachineParams::default();
    let bucket = avant
        .world_circles(&p, x)
        .zip(avant.circles())
        .filter(|(_, c)| c.body == Body::Front)
        .max_by(|a, b| a.1.offset[0].total_cmp(&b.1.offset[0]))
        .map(|(w, _)| w)
        .expect("a front circle");
    site.site()
        .features()
        .iter()
        .filter(|f| f.id.starts_with(prefix))
        .map(|f| f.shape.clearance(bucket.center, bucket.radius))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn every_site_goal_file_is_its_generators_output() {
    for (file, site, seed, count, _) in SITE_SETS {
        let text = std::fs::read_to_string(scenarios_dir().join(file))
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        let generated = site_scenarios(&site_index(site), &MachineParams::default(), seed, count)
            .unwrap_or_else(|e| panic!("{site}: {e}"));
        assert_eq!(
            text,
            to_csv(&generated),
            "regenerate: cargo run -p control --example site_goals -- sim/sites/{site}.json {seed} {count} > sim/scenarios/{file}"
        );
    }
}

#[test]
fn site_goals_are_free_and_their_v_cycles_chain() {
    for (file, site, _, count, cycles) in SITE_SETS {
        let text = std::fs::read_to_string(scenarios_dir().join(file)).expect("committed");
        let set = parse(&text, file).unwrap_or_else(|e| panic!("{e}"));
        let idx = site_index(site);
        assert!(
            set.len() >= 40 && set.len() >= count,
            "{file}: {}",
            set.len()
        );
        let legs: Vec<&Scenario> = set
            .iter()
            .filter(|s| s.name.starts_with("vcycle"))
            .collect();
        if cycles {
            assert!(legs.len() >= 12, "{file}: {} V-cycle legs", legs.len());
        }
        for s in &set {
            assert!(
                s.obstacles.is_empty(),
                "{file} {}: the site is the world",
                s.name
            );
            assert_eq!(
                [s.start[3], s.start[4], s.start[5]],
                [0.0; 3],
                "{file} {}: starts at rest, straight",
                s.name
            );
            let goal = State::new(s.goal.x, s.goal.y, s.goal.theta, 0.0, 0.0, 0.0);
            for (what, x) in [("start", &s.start), ("goal", &goal)] {
                let c = least_clearance(&idx, x);
                assert!(c >= 0.29, "{file} {}: {what} only {c:.3} m clear", s.name);
            }
            if s.name.starts_with("goal") {
                let d = (s.goal.x - s.start[0]).hypot(s.goal.y - s.start[1]);
                assert!((6.0..=30.0).contains(&d), "{file} {}: {d:.2} m", s.name);
            }
        }
        // Four legs a cycle, in order; each starts where the previous ended
        // and the last ends at the first's start (the pile face).
        assert_eq!(legs.len() % 4, 0, "{file}");
        for cycle in legs.chunks(4) {
            let k = &cycle[0].name[..8];
            for (leg, name) in cycle.iter().zip(LEGS) {
                assert_eq!(leg.name, format!("{k}_{name}"), "{file}");
            }
            for (i, leg) in cycle.iter().enumerate() {
                let next = cycle[(i + 1) % 4];
                assert_eq!(
                    [leg.goal.x, leg.goal.y, leg.goal.theta],
                    [next.start[0], next.start[1], next.start[2]],
                    "{file}: {} ends where {} starts",
                    leg.name,
                    next.name
                );
            }
            // The pile face and the truck side (a pile's face where the site
            // has no truck): the Avant 635's foremost circle 0.3–0.6 m away.
            let has_truck = idx
                .site()
                .features()
                .iter()
                .any(|f| f.id.starts_with("truck"));
            for (at, prefix) in [(0, "pile"), (2, if has_truck { "truck" } else { "pile" })] {
                let c = bucket_clearance(&idx, &cycle[at].start, prefix);
                assert!(
                    (0.29..=0.61).contains(&c),
                    "{file} {}: the bucket is {c:.3} m from the nearest {prefix}",
                    cycle[at].name
                );
            }
        }
    }
}
