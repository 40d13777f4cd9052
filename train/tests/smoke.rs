//! A short training run lowers the critic loss, writes a checkpoint and
//! weights that load, and `--resume` continues from the same step count.

use control::weights::{self, NetworkRole};
use train::config::TrainConfig;
use train::run::{candidate_dir, train, RunOptions, CHECKPOINT};

fn small() -> TrainConfig {
    TrainConfig {
        n_envs: 16,
        batch_size: 64,
        buffer_size: 50_000,
        warmup_transitions: 2_000,
        total_updates: 400,
        hidden: vec![32, 32],
        critic_outputs: 4,
        eval_every: 200,
        eval_goals: 4,
        log_every: 50,
        ..Default::default()
    }
}

#[test]
fn smoke_run_learns_checkpoints_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let cfg = small();
    let opts = RunOptions {
        out_dir: out.clone(),
        resume: false,
        max_updates: Some(300),
        max_wall_s: None,
        git_commit: "test".into(),
        quiet: true,
    };
    let first = train(&cfg, &opts).unwrap();
    assert_eq!(first.updates, 300);
    assert!(
        first.last_critic_loss < 0.5 * first.first_critic_loss,
        "critic loss did not fall: {} -> {}",
        first.first_critic_loss,
        first.last_critic_loss
    );
    assert!(out.join(CHECKPOINT).exists());
    // Exported for the run's machine and Δt.
    for (name, role) in [
        (weights::CRITIC_FILE, NetworkRole::Critic),
        (weights::ACTOR_FILE, NetworkRole::Actor),
    ] {
        let w = weights::load_for(&out.join(name), role, &cfg.machine, cfg.dt).unwrap();
        assert_eq!(w.meta.steps, 300);
        assert_eq!(w.meta.git_commit, "test");
    }
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    assert_eq!(log.lines().count(), 1 + 300 / 50);
    assert!(out.join("learning_curves.svg").exists());

    // A second start without --resume refuses to overwrite the run.
    assert!(train(&cfg, &opts)
        .unwrap_err()
        .to_string()
        .contains("--resume"));

    // A run killed between checkpoints logged rows the resume will redo.
    let mut log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    log.push_str("350,0,99.0,1,0,0,0,0,0,0,0,0\n");
    std::fs::write(out.join("log.csv"), log).unwrap();

    // Resume: same step count, then on to the end.
    let resumed = train(
        &cfg,
        &RunOptions {
            resume: true,
            max_updates: None,
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(resumed.updates, 400);
    // Each end of a part (and each timed checkpoint) keeps its networks as a
    // candidate for the closed-loop selection.
    for updates in [300, 400] {
        let w = weights::load(
            &candidate_dir(&out, updates).join(weights::CRITIC_FILE),
            NetworkRole::Critic,
        )
        .unwrap();
        assert_eq!(w.meta.steps, updates);
    }
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    let steps: Vec<u64> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(
        steps,
        (1..=8).map(|k| k * 50).collect::<Vec<_>>(),
        "resume continued from update 300"
    );
    // The run's wall clock carries across the resume: the logged wall time never
    // falls, and the resumed summary counts the first part too.
    let walls: Vec<f64> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(
        walls.windows(2).all(|w| w[1] >= w[0]),
        "wall time restarted on resume: {walls:?}"
    );
    assert!(
        resumed.wall_s > walls[5],
        "resumed run reports {} s, less than its first 300 updates took ({} s)",
        resumed.wall_s,
        walls[5]
    );

    // A wall-time budget the run has already spent stops it after one update.
    let budget = train(
        &TrainConfig {
            total_updates: 1000,
            ..cfg.clone()
        },
        &RunOptions {
            resume: true,
            max_updates: None,
            max_wall_s: Some(walls[7]),
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(budget.updates, 401);
}
