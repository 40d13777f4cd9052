//! The site file's loader: format, validation, errors, hash.

use super::*;

const GOOD: &str = r#"{ "format": "wlnav-site-v1", "id": "north-pit", "version": 3,
  "bounds": [[0, 0], [50, 0], [50, 40], [0, 40]],
  "obstacles": [
    { "id": "pile-1", "circle": [10, 10, 2] },
    { "id": "berm-2", "polygon": [[20, 5], [30, 5], [30, 15], [25, 8]] },
    { "id": "wall-3", "polyline": [[5, 30], [45, 30]], "width": 0.5 } ],
  "keepout": [ { "id": "office", "polygon": [[40, 35], [40, 38], [45, 38], [45, 35]] } ] }"#;

fn with(from: &str, to: &str) -> Vec<u8> {
    assert!(GOOD.contains(from), "{from}");
    GOOD.replacen(from, to, 1).into_bytes()
}

#[test]
fn the_example_loads() {
    let s = Site::parse(GOOD.as_bytes()).unwrap();
    assert_eq!((s.id(), s.version()), ("north-pit", 3));
    assert_eq!(s.features().len(), 4);
    let kinds: Vec<_> = s
        .features()
        .iter()
        .map(|f| (f.id.as_str(), f.kind))
        .collect();
    assert_eq!(kinds[3], ("office", FeatureKind::KeepOut));
    assert!(matches!(s.features()[1].shape, Shape::Polygon(_)));
    assert_eq!(s.find("wall-3").map(|(i, _)| i), Some(2));
    assert_eq!(s.hash(), content_hash(GOOD.as_bytes()));
    assert_eq!(s.hash_hex().len(), 16);
}

#[test]
fn fnv1a_matches_its_published_test_vectors() {
    // From the FNV reference (Fowler, Noll, Vo): FNV-1a 64 of "" and "a".
    assert_eq!(content_hash(b""), 0xcbf29ce484222325);
    assert_eq!(content_hash(b"a"), 0xaf63dc4c8601ec8c);
    assert_eq!(content_hash(b"foobar"), 0x85944171f73967e8);
    assert_eq!(
        content_hash_extend(content_hash(b"foo"), b"bar"),
        content_hash(b"foobar")
    );
}

#[test]
fn a_round_trip_through_the_writer_gives_the_same_site() {
    let s = Site::parse(GOOD.as_bytes()).unwrap();
    let text = s.to_file().to_json();
    let back = Site::parse(text.as_bytes()).unwrap();
    assert_eq!(back.features(), s.features());
    assert_eq!(back.bounds(), s.bounds());
    // The writer puts one feature per line.
    assert_eq!(
        text.lines()
            .filter(|l| l.trim_start().starts_with("{\"id\""))
            .count(),
        4
    );
}

fn err(bytes: Vec<u8>) -> SiteError {
    Site::parse(&bytes).unwrap_err()
}

#[test]
fn syntax_errors_give_line_and_column() {
    let e = err(with("\"version\": 3,", "\"version\": 3,,"));
    assert!(matches!(e, SiteError::Json { line: 1, .. }), "{e}");
    let e = err(with("\"bounds\"", "\"bound\""));
    match &e {
        SiteError::Json { line, message, .. } => {
            assert_eq!(*line, 2);
            assert!(message.contains("unknown field `bound`"), "{message}");
        }
        _ => panic!("{e}"),
    }
    assert!(e.to_string().starts_with("site file, line 2 column"), "{e}");
}

#[test]
fn format_is_exact() {
    let e = err(with("wlnav-site-v1", "wlnav-site-v2"));
    assert_eq!(
        e,
        SiteError::Format {
            found: "wlnav-site-v2".into()
        }
    );
    assert!(Site::parse(&with("wlnav-site-v1", "WLNAV-site-v1")).is_err());
}

#[test]
fn a_typo_in_a_feature_names_its_id() {
    let e = err(with("\"circle\": [10, 10, 2]", "\"circel\": [10, 10, 2]"));
    match &e {
        SiteError::Feature {
            kind,
            id,
            problem: FeatureProblem::Entry(m),
        } => {
            assert_eq!((*kind, id.as_str()), (FeatureKind::Obstacle, "pile-1"));
            assert!(m.contains("unknown field `circel`"), "{m}");
            assert!(m.ends_with("(line 4 column 30)"), "{m}");
        }
        _ => panic!("{e}"),
    }
    assert!(
        e.to_string().starts_with("obstacle `pile-1` unknown field"),
        "{e}"
    );
    // No id to name: its place in the list.
    let e = err(with("\"id\": \"office\", ", ""));
    assert!(
        e.to_string().starts_with("keepout[0]: missing field `id`"),
        "{e}"
    );
}

#[test]
fn a_repeated_key_is_an_error_not_a_silent_choice() {
    let e = err(with(
        "\"circle\": [10, 10, 2]",
        "\"circle\": [10, 10, 2], \"circle\": [30, 30, 2]",
    ));
    match &e {
        SiteError::Json {
            line: 4, message, ..
        } => {
            assert!(message.contains("duplicate field `circle`"), "{message}")
        }
        _ => panic!("{e}"),
    }
    let e = err(with("\"version\": 3,", "\"version\": 3, \"version\": 4,"));
    assert!(e.to_string().contains("duplicate field `version`"), "{e}");
}

#[test]
fn each_shape_check_names_the_feature_and_the_problem() {
    let cases: Vec<(Vec<u8>, &str, FeatureProblem)> = vec![
        (
            with("[10, 10, 2]", "[10, 10, 0]"),
            "pile-1",
            FeatureProblem::NonPositiveRadius(0.0),
        ),
        (
            with("[10, 10, 2]", "[10, 10, -1]"),
            "pile-1",
            FeatureProblem::NonPositiveRadius(-1.0),
        ),
        (
            with("\"width\": 0.5", "\"width\": 0"),
            "wall-3",
            FeatureProblem::NonPositiveWidth(0.0),
        ),
        (
            with(", \"width\": 0.5", ""),
            "wall-3",
            FeatureProblem::MissingWidth,
        ),
        (
            with(
                "[[20, 5], [30, 5], [30, 15], [25, 8]]",
                "[[20, 5], [30, 15], [30, 5], [20, 15]]",
            ),
            "berm-2",
            FeatureProblem::SelfIntersection {
                edge_a: 0,
                edge_b: 2,
            },
        ),
        (
            with(
                "[[20, 5], [30, 5], [30, 15], [25, 8]]",
                "[[20, 5], [30, 5]]",
            ),
            "berm-2",
            FeatureProblem::TooFewVertices { found: 2, min: 3 },
        ),
        (
            with(
                "\"circle\": [10, 10, 2]",
                "\"circle\": [10, 10, 2], \"polygon\": [[1, 1], [2, 1], [2, 2]]",
            ),
            "pile-1",
            FeatureProblem::SeveralShapes,
        ),
        (
            with("\"circle\": [10, 10, 2]", "\"width\": 2"),
            "pile-1",
            FeatureProblem::NoShape,
        ),
        (
            with(
                "\"circle\": [10, 10, 2]",
                "\"circle\": [10, 10, 2], \"width\": 2",
            ),
            "pile-1",
            FeatureProblem::WidthWithoutPolyline,
        ),
    ];
    for (bytes, id, problem) in cases {
        match Site::parse(&bytes) {
            Err(SiteError::Feature {
                id: got,
                problem: p,
                ..
            }) => {
                assert_eq!((got.as_str(), &p), (id, &problem));
            }
            other => panic!("{id} {problem}: {other:?}"),
        }
    }
}

#[test]
fn features_must_lie_inside_the_bounds() {
    for (from, to, id) in [
        ("[10, 10, 2]", "[1, 10, 2]", "pile-1"),
        ("[30, 15]", "[30, 45]", "berm-2"),
        ("[[5, 30], [45, 30]]", "[[5, 39.9], [45, 39.9]]", "wall-3"),
        ("[45, 38]", "[55, 38]", "office"),
    ] {
        match err(with(from, to)) {
            SiteError::Feature {
                id: got,
                problem: FeatureProblem::OutsideBounds { .. },
                ..
            } => {
                assert_eq!(got, id)
            }
            e => panic!("{id}: {e}"),
        }
    }
    // Touching the bounds is fine.
    assert!(Site::parse(&with("[10, 10, 2]", "[2, 10, 2]")).is_ok());
}

#[test]
fn ids_are_unique_and_readable() {
    let e = err(with("\"id\": \"office\"", "\"id\": \"pile-1\""));
    assert_eq!(
        e,
        SiteError::DuplicateId {
            id: "pile-1".into()
        }
    );
    let e = err(with("\"id\": \"pile-1\"", "\"id\": \"\""));
    assert!(
        matches!(
            e,
            SiteError::Entry {
                list: "obstacles",
                index: 0,
                problem: FeatureProblem::BadId(_)
            }
        ),
        "{e}"
    );
    let e = err(with("\"north-pit\"", "\"\""));
    assert_eq!(e, SiteError::BadSiteId("is empty"));
}

#[test]
fn bounds_are_checked_like_a_polygon() {
    let e = err(with(
        "[[0, 0], [50, 0], [50, 40], [0, 40]]",
        "[[0, 0], [50, 40], [50, 0], [0, 40]]",
    ));
    assert!(
        matches!(
            e,
            SiteError::Bounds(FeatureProblem::SelfIntersection { .. })
        ),
        "{e}"
    );
}

#[test]
fn numbers_json_cannot_hold_are_refused_with_a_position() {
    // JSON has no NaN or infinity; an overflowing literal is a syntax error.
    let e = err(with("[10, 10, 2]", "[10, 10, 1e999]"));
    assert!(
        matches!(e, SiteError::Feature { .. } | SiteError::Json { .. }),
        "{e}"
    );
    let e = err(with("[10, 10, 2]", "[10, NaN, 2]"));
    assert!(matches!(e, SiteError::Json { line: 4, .. }), "{e}");
}

#[test]
fn limits_bound_the_work_at_load() {
    let ring: Vec<String> = (0..MAX_SHAPE_VERTICES + 1)
        .map(|k| {
            let a = k as f64 / (MAX_SHAPE_VERTICES + 1) as f64 * std::f64::consts::TAU;
            format!("[{}, {}]", 25.0 + 5.0 * a.cos(), 20.0 + 5.0 * a.sin())
        })
        .collect();
    let e = err(with(
        "[[20, 5], [30, 5], [30, 15], [25, 8]]",
        &format!("[{}]", ring.join(", ")),
    ));
    assert!(
        matches!(
            e,
            SiteError::Feature {
                problem: FeatureProblem::TooManyVertices { .. },
                ..
            }
        ),
        "{e}"
    );
    let big = vec![b' '; MAX_FILE_BYTES + 1];
    assert!(matches!(
        Site::parse(&big),
        Err(SiteError::FileTooLarge { .. })
    ));
}

#[test]
fn generated_sites_are_valid() {
    let pit = generate::large_pit(40, 520);
    assert!(pit.obstacles.len() + pit.keepout.len() >= 500);
    assert!(!pit.keepout.is_empty());
    let text = pit.to_json();
    let s = Site::parse(text.as_bytes()).unwrap();
    assert_eq!(s.features().len(), 520);
    assert_eq!(generate::large_pit(40, 520).to_json(), text);
    for seed in 0..20 {
        let f = generate::random_site(seed, 200, 80.0);
        Site::from_file(f, 0).unwrap();
    }
}
