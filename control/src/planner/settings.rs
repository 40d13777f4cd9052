//! The global layer's settings, declared once: `Default` gives the measured
//! best (`docs/global-layer.md`), serde reads them from the daemon's
//! configuration (`[navigator.search]`, …) and `wlnav-sim eval --navigator`
//! overrides, so neither keeps a copy of its own.
//!
//! Three groups: how a route is searched ([`SearchSettings`]), how it is
//! followed ([`FollowingSettings`]), and what a stall does
//! ([`StallSettings`]).

use serde::{Deserialize, Serialize};

use crate::model::SUCCESS_TOLERANCE;
use crate::progress::ProgressSettings;

use super::NavError;

/// Everything the navigator is tuned with; `Default` gives the measured best.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavigatorSettings {
    pub search: SearchSettings,
    pub following: FollowingSettings,
    pub stall: StallSettings,
    /// A route delivered by the planner this long after the state it was
    /// planned from is not followed: the machine has moved on (it is asked
    /// for again from where the machine is) [s]. Default 2 (plans take
    /// milliseconds; a planner that falls this far behind is stuck).
    pub max_route_age: f64,
    /// Shape every way among obstacles into a minimum-time trajectory on the
    /// planner's side and track it (issue 42; [`super::TrajectoryOptimiser`],
    /// given by the program that builds the planner: `trajopt`'s IPOPT
    /// one in `wlnavd` and `wlnav-sim`). Default true (measured:
    /// `docs/global-layer.md`, obstacles200 1.153 × the bound against 1.252);
    /// open ground is the critic's either way.
    pub trajectory: bool,
}

impl Default for NavigatorSettings {
    fn default() -> Self {
        Self {
            search: SearchSettings::default(),
            following: FollowingSettings::default(),
            stall: StallSettings::default(),
            max_route_age: 2.0,
            trajectory: true,
        }
    }
}

/// How a route is found: the "is anything in the way?" roll-out and the
/// Hybrid A* search ([`super::HybridAStar`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SearchSettings {
    /// Clearance both axle points keep from every (inflated) circle on a
    /// planned route [m]. Default 0.15.
    pub clearance_margin: f64,
    /// Clearance the actor's roll-out must keep for "nothing in the way"
    /// [m]: more than the route's, since the MPC does not drive the actor's
    /// path exactly. Default 0.3.
    pub direct_margin: f64,
    /// Plan every goal among circles, not only those the actor's roll-out
    /// finds blocked: where the roll-out finds the way open, the search's way
    /// is taken only if it is cheaper than the roll-out (its duration at top
    /// speed). Without circles the way is direct, as always. Default true
    /// (measured: `docs/global-layer.md`).
    pub plan_every_goal: bool,
    /// Half the side of the square searched, centred between start and goal
    /// [m]. Default 20: a site's goals lie up to 30 m away, and the way round
    /// a berm can leave a 28 m square (issue 40: quarry `goal021` had no route
    /// at 14); obstacles200's 200 runs are identical at 14 and 20.
    pub workspace_half_size: f64,
    /// Side of a grid cell [m]. Default 0.3.
    pub grid_resolution: f64,
    /// Heading bins of the grid. Default 72 (5°).
    pub heading_bins: usize,
    /// Arc length of a motion primitive [m]. Default 0.6 (leaves its cell).
    pub primitive_length: f64,
    /// Collision samples along a primitive, at most this far apart [m]. Default 0.15.
    pub sample_spacing: f64,
    /// Articulations of the primitives as fractions of β_max (each also
    /// mirrored). Default [0, 0.5, 1].
    pub articulations: Vec<f64>,
    /// Cost factor of reversing. Default 2.
    pub reverse_penalty: f64,
    /// Cost of a cusp (stop, change gear, restart) [m]. Default 2.
    pub direction_change_penalty: f64,
    /// f = g + w h (w > 1 trades optimality for far fewer expansions: on a
    /// wall across the path 92 expansions at 2 against 7 301 at 1). Default 2.
    pub heuristic_weight: f64,
    /// Expansion budget. Default 20 000.
    pub max_expansions: usize,
    /// Node pool. Default 100 000.
    pub max_nodes: usize,
    /// Expansions after the first way to the goal is found in search of a
    /// cheaper one (0: the first is taken). Default 1000.
    pub refine_expansions: usize,
    /// Goal region (position [m], heading [rad]); the MPC does the last part
    /// itself. Defaults 0.5 and 0.35.
    pub goal_position_tolerance: f64,
    pub goal_heading_tolerance: f64,
    /// Goal shots (actor roll-outs to the goal): at most one per this many
    /// expansions, at most `max_shots`, only within `shot_range` [m] and a
    /// line of sight. Defaults 10, 10, 8.
    pub shot_interval: usize,
    pub max_shots: usize,
    pub shot_range: f64,
    /// A roll-out has reached the goal within this pose error. Default 0.2.
    pub shot_tolerance: f64,
    /// Step of every roll-out [s]: the actor's own Δt. Default 0.2.
    pub rollout_dt: f64,
    /// Length of the "is anything in the way?" roll-out [s]. Default 30.
    pub direct_horizon: f64,
    /// Circles the planner takes. Default 32.
    pub max_obstacles: usize,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            clearance_margin: 0.15,
            direct_margin: 0.3,
            plan_every_goal: true,
            workspace_half_size: 20.0,
            grid_resolution: 0.3,
            heading_bins: 72,
            primitive_length: 0.6,
            sample_spacing: 0.15,
            articulations: vec![0.0, 0.5, 1.0],
            reverse_penalty: 2.0,
            direction_change_penalty: 2.0,
            heuristic_weight: 2.0,
            max_expansions: 20_000,
            max_nodes: 100_000,
            refine_expansions: 1000,
            goal_position_tolerance: 0.5,
            goal_heading_tolerance: 0.35,
            shot_interval: 10,
            max_shots: 10,
            shot_range: 8.0,
            shot_tolerance: 0.2,
            rollout_dt: 0.2,
            direct_horizon: 30.0,
            max_obstacles: 32,
        }
    }
}

/// How a planned path is followed: progress along it is the MPC's cost
/// ([`crate::mpc::PathCost`]) one direction of travel at a time; within
/// `handover` of the next cusp or the path's end the critic drives to that
/// pose. The route's subgoals are the progress markers and the critic's
/// targets on reversing parts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FollowingSettings {
    /// Within this arc length of the next cusp or the path's end the critic
    /// takes over [m]. Default 3 (the critic's final approach).
    pub handover: f64,
    /// The prices of the squared lateral error [1/m²], the heading error
    /// (1 − cos) and the squared controls relative to their bounds, each a
    /// multiple of the critic's cost of a metre (the arc length left is
    /// priced at 1 ×). Defaults 4, 3, 0.1.
    pub lateral: f64,
    pub heading: f64,
    pub control: f64,
    /// A subgoal is passed when the front axle is within this distance of it
    /// [m]. Default 1.0.
    pub subgoal_radius: f64,
    /// Distance between subgoals along a planned path [m]. Default 2.5.
    pub subgoal_spacing: f64,
}

impl Default for FollowingSettings {
    fn default() -> Self {
        Self {
            handover: 3.0,
            lateral: 4.0,
            heading: 3.0,
            control: 0.1,
            subgoal_radius: 1.0,
            subgoal_spacing: 2.5,
        }
    }
}

/// What a stall does: replan, retry the final approach, or abort.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StallSettings {
    /// The abort window: no approach to the current target for
    /// `progress.timeout` (default 10 s) → `Abort(NoProgress)`. The one
    /// progress window of a goal (the pilot decides, the daemon's goal lifecycle reports it).
    #[serde(skip)]
    pub progress: ProgressSettings,
    /// Seconds without approach to the current target before a replan from
    /// the current state. Default 4.
    pub replan_after: f64,
    /// Replans per goal. Default 3.
    pub max_replans: usize,
    /// A stall on the goal itself that a replan cannot help (open ground, or
    /// already inside the search's goal region) is retried: the MPC drives to
    /// the approach pose, this far behind the goal on its heading (ahead of
    /// it when that is blocked), then to the goal again [m]. Why: a critic
    /// can stop beside its goal with the articulation at its limit. Default 3.
    pub approach_distance: f64,
    /// Retries per goal. Default 2.
    pub max_retries: usize,
    /// Retry (rather than replan) a stall near the goal among circles too
    /// when the goal is in sight: a replan would shoot straight at it and
    /// hand back the route that stalled. Default true.
    pub retry_in_sight: bool,
    /// Within this pose error of the goal the machine is holding it, not
    /// stalled. Default [`SUCCESS_TOLERANCE`].
    pub reached_tolerance: f64,
    /// A tracked machine this far from its trajectory's reference [m] (a
    /// push, a slip, a machine unlike the model) is planned again from where
    /// it is, as a stall is (counted among `max_replans`, at most every
    /// `replan_after`). Default 1.
    pub max_track_deviation: f64,
    /// A tracked machine this far behind its trajectory's time [s] (weaker
    /// or later than the model, or held) follows the rest of the route's path
    /// instead. Default 1 (measured: `docs/decisions.md`).
    pub max_track_lag: f64,
}

impl Default for StallSettings {
    fn default() -> Self {
        Self {
            progress: ProgressSettings::default(),
            replan_after: 4.0,
            max_replans: 3,
            approach_distance: 3.0,
            max_retries: 2,
            retry_in_sight: true,
            reached_tolerance: SUCCESS_TOLERANCE,
            max_track_deviation: 1.0,
            max_track_lag: 1.0,
        }
    }
}

impl SearchSettings {
    /// Cells a side of the search grid.
    pub fn grid_cells(&self) -> usize {
        (2.0 * self.workspace_half_size / self.grid_resolution).ceil() as usize
    }
}

impl NavigatorSettings {
    /// The settings with the route's clearance widened by the envelope's
    /// tolerances ([`crate::envelope::EnvelopeSettings::tolerance_widening`],
    /// [front, rear]), as the MPC's planned clearances are
    /// ([`crate::mpc::MpcSettings::widened`]): otherwise routes lead through
    /// gaps the MPC, planning wider, cannot follow. The route's one margin
    /// serves both axle points: it grows by their mean. Measured on
    /// obstacles200 with the shipped tolerances (front +0.07, rear +0.17 m;
    /// three perturbed runs, docs/envelope-tolerances.md): unwidened
    /// 193/192/192 reached, + front 195/194/195, + mean 197/196/197.
    pub fn widened(mut self, widening: [f64; 2]) -> Self {
        self.search.clearance_margin += 0.5 * (widening[0] + widening[1]);
        self
    }

    /// Checks every field once; the error names it.
    pub fn validate(&self) -> Result<(), NavError> {
        let (s, f, st) = (&self.search, &self.following, &self.stall);
        let positive = [
            ("max_route_age", self.max_route_age),
            ("following.subgoal_radius", f.subgoal_radius),
            ("following.subgoal_spacing", f.subgoal_spacing),
            ("following.handover", f.handover),
            ("stall.progress.timeout", st.progress.timeout),
            ("stall.replan_after", st.replan_after),
            ("stall.approach_distance", st.approach_distance),
            ("stall.reached_tolerance", st.reached_tolerance),
            ("stall.max_track_deviation", st.max_track_deviation),
            ("stall.max_track_lag", st.max_track_lag),
            ("search.workspace_half_size", s.workspace_half_size),
            ("search.grid_resolution", s.grid_resolution),
            ("search.primitive_length", s.primitive_length),
            ("search.sample_spacing", s.sample_spacing),
            ("search.reverse_penalty", s.reverse_penalty),
            ("search.heuristic_weight", s.heuristic_weight),
            ("search.goal_position_tolerance", s.goal_position_tolerance),
            ("search.goal_heading_tolerance", s.goal_heading_tolerance),
            ("search.shot_range", s.shot_range),
            ("search.shot_tolerance", s.shot_tolerance),
            ("search.rollout_dt", s.rollout_dt),
            ("search.direct_horizon", s.direct_horizon),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, "must be finite and > 0", v));
            }
        }
        let non_negative = [
            ("stall.progress.min_approach", st.progress.min_approach),
            ("following.lateral", f.lateral),
            ("following.heading", f.heading),
            ("following.control", f.control),
            ("search.clearance_margin", s.clearance_margin),
            ("search.direct_margin", s.direct_margin),
            (
                "search.direction_change_penalty",
                s.direction_change_penalty,
            ),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(name, "must be finite and >= 0", v));
            }
        }
        if st.approach_distance <= f.subgoal_radius {
            return Err(bad(
                "stall.approach_distance",
                "must exceed following.subgoal_radius (or the approach pose is passed at once)",
                st.approach_distance,
            ));
        }
        if st.replan_after >= st.progress.timeout {
            return Err(bad(
                "stall.replan_after",
                "must be below the progress timeout (a replan comes before the abort)",
                st.replan_after,
            ));
        }
        // The grid must be left by a primitive, or successors land on their parent.
        if s.primitive_length <= s.grid_resolution * std::f64::consts::SQRT_2 {
            return Err(bad(
                "search.primitive_length",
                "must exceed the cell diagonal (grid_resolution × √2)",
                s.primitive_length,
            ));
        }
        let cells = s.grid_cells();
        if cells > 1024 || s.heading_bins == 0 || s.heading_bins > 360 {
            return Err(bad(
                "search.grid",
                "needs workspace_half_size / grid_resolution ≤ 512 and 1..=360 heading_bins",
                cells as f64,
            ));
        }
        if s.articulations.is_empty()
            || s.articulations
                .iter()
                .any(|a| !(a.is_finite() && (0.0..=1.0).contains(a)))
        {
            return Err(bad(
                "search.articulations",
                "must be a non-empty list of fractions in [0, 1]",
                f64::NAN,
            ));
        }
        let counts = [
            ("search.max_expansions", s.max_expansions),
            ("search.max_nodes", s.max_nodes),
            ("search.shot_interval", s.shot_interval),
            ("search.max_obstacles", s.max_obstacles),
        ];
        for (name, v) in counts {
            if v == 0 {
                return Err(bad(name, "must be > 0", 0.0));
            }
        }
        Ok(())
    }
}

fn bad(name: &'static str, requirement: &'static str, value: f64) -> NavError {
    NavError::BadSettings {
        name,
        requirement,
        value,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_serde_reads_one_field_of_a_group() {
        NavigatorSettings::default().validate().unwrap();
        let s: NavigatorSettings =
            toml_like(r#"{"search": {"heuristic_weight": 1.5}, "max_route_age": 1.0}"#);
        assert_eq!(s.search.heuristic_weight, 1.5);
        assert_eq!(s.max_route_age, 1.0);
        // The rest keeps its default.
        assert_eq!(s.search.max_expansions, 20_000);
        assert_eq!(s.following, FollowingSettings::default());
        // A typo is an error, not a silent default.
        assert!(
            serde_json::from_str::<NavigatorSettings>(r#"{"search": {"heuristc": 1}}"#).is_err()
        );
    }

    fn toml_like(json: &str) -> NavigatorSettings {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn validation_names_the_field() {
        let mut s = NavigatorSettings::default();
        s.following.subgoal_radius = 5.0;
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("stall.approach_distance"), "{e}");
        let mut s = NavigatorSettings::default();
        s.search.grid_resolution = f64::NAN;
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("search.grid_resolution"), "{e}");
    }
}
