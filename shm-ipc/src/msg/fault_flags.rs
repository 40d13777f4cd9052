/// No pose received yet, or the newest is older than the configured limit.
pub const POSE_STALE: u32 = 1 << 0;
/// Machine state (CAN) missing or older than the configured limit.
pub const MACHINE_STATE_STALE: u32 = 1 << 1;
/// A CAN frame failed its CRC-8 check.
pub const CAN_CRC: u32 = 1 << 2;
/// A CAN frame's alive counter did not advance as expected.
pub const CAN_ALIVE: u32 = 1 << 3;
/// The solver failed or returned non-finite values.
pub const SOLVE_FAILED: u32 = 1 << 4;
/// Driving on the shifted previous plan after a failed solve.
pub const FALLBACK_PLAN: u32 = 1 << 5;
/// The previous tick missed its deadline.
pub const OVERRUN: u32 = 1 << 6;
/// An operator stop is latched: goals are rejected until a resume request.
pub const STOP_REQUESTED: u32 = 1 << 7;
/// The CAN bus reported an error or is off.
pub const CAN_BUS: u32 = 1 << 8;
/// Pose samples were rejected by the daemon's gate (timestamp in the future, a jump the
/// machine cannot make, outside the workspace, non-finite). Set on the tick that saw a
/// rejected sample and while a run of rejects holds; a run of
/// `loop.pose_reject_stop` consecutive rejects is a pose fault (controlled stop).
pub const POSE_REJECTED: u32 = 1 << 9;
/// The safety envelope replaced the controller's command this tick (DESIGN §14): under
/// it, the predicted motion until the next tick and a stop at the braking limits after
/// it would have come closer to an obstacle than the protective margin. Not a fault:
/// the machine brakes (or brakes while steering) and the controller goes on.
pub const ENVELOPE_OVERRIDE: u32 = 1 << 10;
/// The machine was seen to break one of the safety envelope's stated tolerances
/// (issue 43): the assumption bits below name which. Alone, a warning: the envelope
/// was widened to what was measured (and stays so). With the mode `fault`, the
/// measurement was beyond what the envelope may be widened to: controlled stop, the
/// goal aborted with the measurement in its reason text.
pub const ASSUMPTION_BROKEN: u32 = 1 << 11;
/// … the geometry (`envelope.geometry_tolerance`): the heading's response says the
/// rear axle is farther from the modelled one.
pub const ASSUMPTION_GEOMETRY: u32 = 1 << 12;
/// … the actuator delay beyond the configured one (`envelope.response_lag`).
pub const ASSUMPTION_DELAY: u32 = 1 << 13;
/// … the actuator gain (`envelope.actuator_gain_max`).
pub const ASSUMPTION_GAIN: u32 = 1 << 14;
/// … the pose estimate's noise (`envelope.pose_noise_xy` or `pose_noise_theta`).
pub const ASSUMPTION_POSE_NOISE: u32 = 1 << 15;
/// Live obstacles are required (`live.required`) and the newest set on
/// `{prefix}/v2/obstacles` is older than `live.max_age` (or none came, or they
/// came again for less than `live.recover_span`): controlled stop; the machine
/// moves again once sets have been fresh for the span (DESIGN §18).
pub const PERCEPTION_STALE: u32 = 1 << 16;
/// Held after a protective stop for a live obstacle ([`super::Telemetry::live_id`]
/// names it) until the way has been clear for `live.resume_wait`.
pub const PROTECTIVE_STOP: u32 = 1 << 17;
/// A live-obstacle set was rejected since the last tick (the log names the rule
/// and the obstacle); the sets before it stay in force, and they age.
pub const LIVE_REJECTED: u32 = 1 << 18;
/// The speed is scaled down in a live obstacle's slow-down field.
pub const LIVE_SLOWING: u32 = 1 << 19;
/// [`super::Telemetry::live_id`] holds the id of the live obstacle the command
/// comes nearest to (within 1 m of its stop field).
pub const LIVE_NEAR: u32 = 1 << 20;

/// Every bit and its name, in bit order (logs, reject reasons, `wlnav watch`).
pub const NAMES: [(u32, &str); 21] = [
    (POSE_STALE, "pose-stale"),
    (MACHINE_STATE_STALE, "machine-state-stale"),
    (CAN_CRC, "can-crc"),
    (CAN_ALIVE, "can-alive"),
    (SOLVE_FAILED, "solve-failed"),
    (FALLBACK_PLAN, "fallback-plan"),
    (OVERRUN, "overrun"),
    (STOP_REQUESTED, "stop-requested"),
    (CAN_BUS, "can-bus"),
    (POSE_REJECTED, "pose-rejected"),
    (ENVELOPE_OVERRIDE, "envelope-override"),
    (ASSUMPTION_BROKEN, "assumption-broken"),
    (ASSUMPTION_GEOMETRY, "assumption-geometry"),
    (ASSUMPTION_DELAY, "assumption-delay"),
    (ASSUMPTION_GAIN, "assumption-gain"),
    (ASSUMPTION_POSE_NOISE, "assumption-pose-noise"),
    (PERCEPTION_STALE, "perception-stale"),
    (PROTECTIVE_STOP, "protective-stop"),
    (LIVE_REJECTED, "live-rejected"),
    (LIVE_SLOWING, "live-slowing"),
    (LIVE_NEAR, "live-near"),
];

/// Names of the bits set in `flags`, in bit order ([`NAMES`]); bits
/// without a name as `bit-N` (a newer daemon's). For logs, reject reasons
/// and the CLI: one list for all of them.
pub fn names(flags: u32) -> Vec<String> {
    let mut names: Vec<String> = NAMES
        .iter()
        .filter(|(bit, _)| flags & bit != 0)
        .map(|(_, n)| (*n).to_owned())
        .collect();
    let known = NAMES.iter().fold(0, |acc, (bit, _)| acc | bit);
    for bit in 0..32 {
        if flags & !known & (1 << bit) != 0 {
            names.push(format!("bit-{bit}"));
        }
    }
    names
}
