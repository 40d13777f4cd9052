//! Every site file under `sim/sites/` loads and indexes (DESIGN §17), and the
//! generated large pit is what its generator writes for its seed.

use std::path::PathBuf;

use control::site::generate::large_pit;
use control::site::{FeatureKind, Site, SiteIndex};

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
        assert!(idx.site().features().len() >= 10, "{}", path.display());
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
