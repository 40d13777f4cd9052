//! Acceptance (5): delay compensation equals integrating the (zero-lag) plant
//! forward by the delay, for delays that are and are not multiples of the
//! command period, including acceleration-limited commands; and the MPC plans
//! from exactly that state in closed loop.

use control::delay::DelayCompensator;
use control::model::{Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, QuadraticCost};
use control::{Plant, PlantConfig, VelocityCommand};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const PERIOD: f64 = 0.2;

#[test]
fn compensation_equals_the_plant_integrated_over_the_delay() {
    let p = MachineParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for delay in [0.0, 0.05, 0.2, 0.23, 0.4, 0.45, 0.61] {
        let config = PlantConfig {
            delay,
            ..PlantConfig::ideal()
        };
        let x0 = State::new(0.5, -0.2, 0.3, 0.1, 0.0, 0.2);
        let mut plant = Plant::new(p, config, x0).unwrap();
        let mut comp = DelayCompensator::new(p, delay, PERIOD).unwrap();
        let mut worst: f64 = 0.0;
        for k in 0..60 {
            let t = k as f64 * PERIOD;
            let predicted = comp.propagate(t, &plant.state());
            let mut future = plant.clone();
            future.advance(delay);
            worst = worst.max((predicted - future.state()).amax());
            assert!(
                future.state()[3].abs() < p.beta_max,
                "keep off the articulation stop (see below)"
            );
            // Mostly reachable commands, sometimes far ones (acceleration-limited
            // ramps). β̇ is steered back towards β = 0: at the articulation stop
            // the plant zeroes β̇ within its sub-steps while its ramp goes on, and
            // the compensator, which continues ramps from the measured β̇, only
            // approximates that (to ~1e-4).
            let x = plant.state();
            let cmd = if k % 7 == 3 {
                VelocityCommand {
                    beta_dot: rng.gen_range(-0.6..0.6) - x[3],
                    v: rng.gen_range(-1.0..1.0),
                }
            } else {
                VelocityCommand {
                    beta_dot: x[4] + rng.gen_range(-0.1..0.1) - 0.3 * x[3],
                    v: x[5] + rng.gen_range(-0.2..0.2),
                }
            };
            plant.command(cmd).unwrap();
            comp.record(t, cmd);
            plant.advance(PERIOD);
        }
        assert!(
            worst < 1e-9,
            "delay {delay}: compensated state differs from the plant by {worst:e}"
        );
    }
}

/// The quadratic-cost MPC with `settings` towards (4, 2, 1), and an ideal plant
/// with the same input delay, moving at 0.3 m/s.
fn mpc_and_plant(settings: MpcSettings) -> (Mpc<QuadraticCost>, Plant) {
    let p = MachineParams::default();
    let mut cost = QuadraticCost::diagonal([0.2, 0.2, 0.5, 0.1, 0.5, 0.5], [0.5, 0.5]);
    cost.q_pos = 2.0;
    let mut mpc = Mpc::new(p, cost, None, settings).unwrap();
    mpc.set_goal(Goal::new(4.0, 2.0, 1.0), &[]).unwrap();
    let config = PlantConfig {
        delay: settings.delay,
        ..PlantConfig::ideal()
    };
    let plant = Plant::new(p, config, State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.3)).unwrap();
    (mpc, plant)
}

#[test]
fn mpc_plans_from_the_delay_compensated_state() {
    for delay in [0.2, 0.3] {
        let settings = MpcSettings {
            delay,
            ..MpcSettings::default()
        };
        let (mut mpc, mut plant) = mpc_and_plant(settings);
        let mut worst: f64 = 0.0;
        for tick in 0..40 {
            let now = tick as f64 * settings.dt;
            let sol = mpc.step(&plant.state(), now).unwrap();
            let mut future = plant.clone();
            future.advance(delay);
            worst = worst.max((sol.initial_state - future.state()).amax());
            assert_eq!(sol.states[0], sol.initial_state);
            let cmd = sol.command;
            plant.command(cmd).unwrap();
            mpc.sent(now, cmd);
            plant.advance(settings.dt);
        }
        assert!(
            worst < 1e-9,
            "delay {delay}: x̂ differs from the plant by {worst:e}"
        );
    }
}

/// The daemon's view: the compensator runs on the real clock and is fed with the
/// commands actually sent. Ticks are skipped now and then (a late tick: the
/// command in force lasts two periods), some ticks send a stop ramp instead of
/// the MPC's command, and a new goal mid-drive keeps the command history (the
/// commands in the delay window still act). x̂ stays the plant's state one
/// delay ahead throughout (off the articulation stop, which the compensator
/// only approximates: see the first test).
#[test]
fn mpc_compensates_with_the_commands_sent_on_the_real_clock() {
    let p = MachineParams::default();
    let delay = 0.3;
    let settings = MpcSettings {
        delay,
        delay_estimation: false,
        gain_estimation: false,
        ..MpcSettings::default()
    };
    let (mut mpc, mut plant) = mpc_and_plant(settings);
    let (mut now, mut worst, mut last) = (3.7, 0.0_f64, VelocityCommand::ZERO);
    for tick in 0..40 {
        if tick == 20 {
            mpc.clear_goal();
            mpc.set_goal(Goal::new(6.0, 3.0, 0.8), &[]).unwrap();
        }
        let sol = mpc.step(&plant.state(), now).unwrap();
        let mut future = plant.clone();
        future.advance(delay);
        worst = worst.max((sol.initial_state - future.state()).amax());
        assert!(
            future.state()[3].abs() < p.beta_max - 0.05,
            "keep off the articulation stop"
        );
        // Ticks 8..12: a stop ramp the loop decided, not the MPC's command.
        let cmd = if (8..12).contains(&tick) {
            VelocityCommand {
                beta_dot: last.beta_dot * 0.5,
                v: last.v * 0.5,
            }
        } else {
            sol.command
        };
        plant.command(cmd).unwrap();
        mpc.sent(now, cmd);
        last = cmd;
        // Every fifth tick comes a period late.
        let period = if tick % 5 == 4 { 2.0 } else { 1.0 } * settings.dt;
        plant.advance(period);
        now += period;
    }
    assert!(worst < 1e-9, "x̂ differs from the plant by {worst:e}");
}
