//! IPOPT reads `ipopt.opt` from the working directory and lets it override
//! the program's options. The trajectory the daemon plans with must not
//! depend on a file nobody configured: this binary (its own process, as it
//! changes the working directory) plans among a wall from a directory whose
//! `ipopt.opt` would cut every solve after one iteration.

use control::model::{Goal, MachineParams, State};
use control::obstacle::Obstacle;
use control::planner::world::CheckedWorld;
use control::planner::{NavigatorSettings, PlanJob, PlanKind, RoutePlanner, TrajectoryOptimiser};
use trajopt::trajectory::{IpoptTrajectory, TrajectorySettings};

#[test]
fn an_ipopt_opt_in_the_working_directory_does_not_change_the_trajectory() {
    let p = MachineParams::default();
    let settings = NavigatorSettings::default();
    let wall: Vec<Obstacle> = (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect();
    let (start, goal) = (State::zeros(), Goal::new(8.0, 0.0, 0.0));
    let mut planner = RoutePlanner::new(p, &settings, None).unwrap();
    let mut job = PlanJob::new(&p, &settings.search);
    job.request.kind = PlanKind::First;
    job.request.start = start;
    job.request.goal = goal;
    job.request.world.set_circles(&wall).unwrap();
    planner.plan(&mut job);
    let mut world = CheckedWorld::new(p, 16, settings.search.clearance_margin);
    world.set(&wall).unwrap();
    let ts = TrajectorySettings {
        max_solve_seconds: 60.0,
        ..TrajectorySettings::default()
    };
    let plan = |out: &mut Vec<State>| {
        IpoptTrajectory::new(p, ts).optimise(
            &world,
            &start,
            &goal,
            &job.route.path,
            &job.route.shot,
            out,
        )
    };
    let mut here = Vec::with_capacity(4096);
    let dt = plan(&mut here).expect("a trajectory round the wall");

    let dir = std::env::temp_dir().join(format!("wlnav-ipopt-opt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("ipopt.opt"), "max_iter 1\n").unwrap();
    std::env::set_current_dir(&dir).unwrap();
    let mut there = Vec::with_capacity(4096);
    let dt_there = plan(&mut there);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(dt_there, Ok(dt), "the options file changed the solve");
    assert_eq!(there, here);
}
