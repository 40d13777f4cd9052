//! The site (DESIGN §17, issue 40) end to end: `[site] file` loaded at start and
//! named in telemetry; a goal behind a berm polygon reached around it; a goal in a
//! keep-out rejected naming it; a broken reload keeps the old site and says why; a
//! reload that puts a pile on the route is planned around or stopped for, never
//! crossed.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use control::site::{Site, SiteIndex};
use control::world::World;
use shm_ipc::{GoalOutcome, Mode, Pose2, RejectCode, Telemetry};

use crate::common::*;

const T: Duration = Duration::from_secs(60);

/// The test site: bounds around the origin (the simulated machine starts there),
/// an L-shaped berm across the straight way to (16, 0), an office keep-out.
fn site_json(version: u64, extra: &str) -> String {
    format!(
        r#"{{"format": "wlnav-site-v1", "id": "e2e-yard", "version": {version},
            "bounds": [[-8, -14], [30, -14], [30, 14], [-8, 14]],
            "obstacles": [
              {{"id": "berm", "polygon": [[5, -4], [7, -4], [7, 2], [9, 2], [9, 4], [5, 4]]}}{extra}],
            "keepout": [{{"id": "office", "polygon": [[18, 6], [24, 6], [24, 11], [18, 11]]}}]}}"#
    )
}

fn write_site(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("yard.json");
    std::fs::write(&path, text).unwrap();
    path
}

fn start_in_site(name: &str, file: &Path) -> Running {
    let mut config = with_committed_weights(sim_config(name), control::weights::DEFAULT_DIR);
    config.site.file = file.to_path_buf();
    config.validate().unwrap();
    start(config, None)
}

/// The machine's least clearance (default outline) to `site` over the ticks of
/// `log` from `from` on.
fn worst_clearance(log: &[Telemetry], site: &str) -> f64 {
    let index = Arc::new(SiteIndex::new(Site::parse(site.as_bytes()).unwrap()));
    let mut w = World::with_axle_circles(control::MachineParams::default(), 0);
    w.set_site(Some(index));
    log.iter()
        .filter(|t| t.state.x_f.is_finite())
        .map(|t| {
            let s = &t.state;
            w.clearance(&control::State::new(
                s.x_f, s.y_f, s.theta_f, s.beta, s.beta_dot, s.v_f,
            ))
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn a_goal_behind_a_berm_is_reached_around_it_and_a_keep_out_goal_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = site_json(1, "");
    let d = start_in_site("site-berm", &write_site(dir.path(), &text));
    let mut log = Vec::new();
    let idle = d.record_until(&mut log, T, "idle", |t| t.mode() == Ok(Mode::Idle));
    assert_eq!(idle.site_id(), "e2e-yard");
    assert_eq!(idle.site_version, 1);
    assert_eq!(
        idle.site_hash,
        control::site::content_hash(text.as_bytes()),
        "the hash of the file's bytes"
    );
    // Inside the office: refused, naming it.
    let (_, reply) = d.request_goal(Pose2::new(21.0, 8.5, 0.0), &[]);
    assert_eq!(reply.reject_code(), Ok(RejectCode::GoalInCollision));
    assert!(
        reply
            .reason_text()
            .contains("keep-out `office` of site `e2e-yard`"),
        "{}",
        reply.reason_text()
    );
    // Behind the berm: reached, around it.
    let (id, reply) = d.request_goal(Pose2::new(16.0, 0.0, 0.0), &[]);
    assert!(reply.is_accepted(), "{}", reply.reason_text());
    let end = d.record_until(&mut log, T, "the outcome", |t| t.outcome_request_id == id);
    assert_eq!(
        end.outcome(),
        Ok(GoalOutcome::Succeeded),
        "{}",
        end.outcome_text()
    );
    let worst = worst_clearance(&log, &text);
    assert!(worst > -0.005, "cut {:.3} m into the site", -worst);
    d.stop();
}

#[test]
fn a_broken_reload_keeps_the_old_site_and_a_good_one_is_in_force_at_the_next_tick() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_site(dir.path(), &site_json(1, ""));
    let d = start_in_site("site-reload", &path);
    let mut log = Vec::new();
    let before = d.record_until(&mut log, T, "idle", |t| t.mode() == Ok(Mode::Idle));
    // A pile with a negative radius: rejected, the feature named, the old site kept.
    write_site(
        dir.path(),
        &site_json(2, r#", {"id": "pile-9", "circle": [12, 8, -1]}"#),
    );
    let reply = d.client.reload_site(Duration::from_secs(5)).unwrap();
    assert!(!reply.is_accepted());
    assert_eq!(reply.reject_code(), Ok(RejectCode::Other));
    assert!(
        reply.reason_text().contains("pile-9") && reply.reason_text().contains("yard.json"),
        "{}",
        reply.reason_text()
    );
    let after: Vec<Telemetry> = d.wait_for(T, "3 ticks", {
        let t0 = before.tick;
        move |t| t.tick >= t0 + 3
    });
    assert!(after
        .iter()
        .all(|t| t.site_version == 1 && t.site_hash == before.site_hash));
    // A valid version 2: accepted, in force from a tick boundary on.
    let v2 = site_json(2, r#", {"id": "pile-9", "circle": [12, 8, 1]}"#);
    write_site(dir.path(), &v2);
    let reply = d.client.reload_site(Duration::from_secs(5)).unwrap();
    assert!(reply.is_accepted(), "{}", reply.reason_text());
    let swapped = d.record_until(&mut log, T, "version 2", |t| t.site_version == 2);
    assert_eq!(
        swapped.site_hash,
        control::site::content_hash(v2.as_bytes())
    );
    // The goal check uses it: a goal on the new pile is refused.
    let (_, reply) = d.request_goal(Pose2::new(12.0, 8.0, 0.0), &[]);
    assert!(
        reply.reason_text().contains("pile-9"),
        "{}",
        reply.reason_text()
    );
    d.stop();
}

#[test]
fn a_reload_that_puts_a_pile_on_the_route_is_driven_around_or_stopped_for_never_crossed() {
    let dir = tempfile::tempdir().unwrap();
    // Open ground on the way to (20, -8) at first: the berm is off to the side.
    let open = site_json(1, "").replace(
        "[[5, -4], [7, -4], [7, 2], [9, 2], [9, 4], [5, 4]]",
        "[[5, 8], [7, 8], [7, 10], [5, 10]]",
    );
    let path = write_site(dir.path(), &open);
    let d = start_in_site("site-new-pile", &path);
    let mut log = Vec::new();
    d.record_until(&mut log, T, "idle", |t| t.mode() == Ok(Mode::Idle));
    let (id, reply) = d.request_goal(Pose2::new(20.0, -8.0, -0.4), &[]);
    assert!(reply.is_accepted(), "{}", reply.reason_text());
    // Once moving, and at least 6 m before it, a pile appears across the way.
    d.record_until(&mut log, T, "moving", |t| {
        t.state.v_f > 0.3 && t.state.x_f > 1.0
    });
    let pile = r#", {"id": "pile-new", "polygon": [[9, -8], [12, -8], [12, -1], [9, -1]]}"#;
    let text = format!(
        "{}",
        open.replace("\"version\": 1", "\"version\": 2")
            .replace("[5, 10]]}", &format!("[5, 10]]}}{pile}"))
    );
    write_site(dir.path(), &text);
    let reply = d.client.reload_site(Duration::from_secs(5)).unwrap();
    assert!(reply.is_accepted(), "{}", reply.reason_text());
    let swap = log.len();
    d.record_until(&mut log, T, "version 2", |t| t.site_version == 2);
    let end = d.record_until(&mut log, T, "the outcome", |t| t.outcome_request_id == id);
    let worst = worst_clearance(&log[swap..], &text);
    assert!(
        worst > -0.005,
        "cut {:.3} m into the new pile ({})",
        -worst,
        end.outcome_text()
    );
    // Planned around it (or, if not, ended with the machine at rest).
    if end.outcome() != Ok(GoalOutcome::Succeeded) {
        d.record_until(&mut log, T, "at rest", |t| t.at_rest == 1);
    }
    d.stop();
}
