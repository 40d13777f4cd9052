//! `wlnav-train train` from a config to published weights in one command: it
//! trains, keeps each checkpoint as a candidate, drives the MPC with every
//! candidate on the seeded selection set once the run is complete, and
//! publishes the best with a README naming the command, the chosen update and
//! the selection table.

use std::process::Command;

use control::weights::{self, NetworkRole};

const BIN: &str = env!("CARGO_BIN_EXE_wlnav-train");

#[test]
fn train_selects_the_best_candidate_in_closed_loop_and_publishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(
        &config,
        "n_envs = 8\nbatch_size = 32\nbuffer_size = 20000\nwarmup_transitions = 500\n\
         total_updates = 60\nhidden = [16, 16]\ncritic_outputs = 4\neval_every = 30\n\
         eval_goals = 2\nlog_every = 20\n",
    )
    .unwrap();
    let out = dir.path().join("run");
    let run = |extra: &[&str]| {
        let o = Command::new(BIN)
            .args(["train", "--config"])
            .arg(&config)
            .arg("--out")
            .arg(&out)
            .args(["--selection-goals", "2"])
            .args(extra)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(
            o.status.success(),
            "{text}\n{}",
            String::from_utf8_lossy(&o.stderr)
        );
        text
    };
    // Stopped early: a candidate, but no selection yet.
    let first = run(&["--max-updates", "30"]);
    assert!(first.contains("not complete"), "{first}");
    assert!(!out.join("published").exists());
    // Resumed to the end: two candidates (updates 30 and 60) are compared and the
    // best is published.
    let second = run(&["--resume"]);
    let scores = std::fs::read_to_string(out.join("selection.csv")).unwrap();
    let rows: Vec<&str> = scores.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{scores}");
    assert!(
        rows[0].starts_with("30,") && rows[1].starts_with("60,"),
        "{scores}"
    );
    assert!(
        second.contains("update        30") && second.contains("update        60"),
        "{second}"
    );
    let published = out.join("published");
    let readme = std::fs::read_to_string(published.join("README.md")).unwrap();
    assert!(readme.contains("wlnav-train train --config"), "{readme}");
    assert!(readme.contains("## Closed-loop selection"), "{readme}");
    // Both invocations, the first and the resume, are named.
    let invocations = readme
        .lines()
        .filter(|l| l.starts_with("- `") && l.contains("wlnav-train train"))
        .collect::<Vec<_>>();
    assert_eq!(invocations.len(), 2, "{readme}");
    assert!(
        invocations[0].contains("--max-updates 30") && invocations[1].contains("--resume"),
        "{readme}"
    );
    // The published networks are the candidate the README names as chosen.
    let critic = weights::load(&published.join(weights::CRITIC_FILE), NetworkRole::Critic).unwrap();
    assert!(
        readme.contains(&format!("the checkpoint at update {}", critic.meta.steps)),
        "{readme}"
    );
    let chosen = std::fs::read(
        out.join("candidates")
            .join(format!("u{:09}", critic.meta.steps))
            .join(weights::ACTOR_FILE),
    )
    .unwrap();
    assert_eq!(
        std::fs::read(published.join(weights::ACTOR_FILE)).unwrap(),
        chosen
    );
    for f in [
        "learning_curves.svg",
        "train-config.toml",
        "log.csv",
        "eval.csv",
    ] {
        assert!(published.join(f).exists(), "{f}");
    }

    // `publish` on the finished run takes the selection's choice, not the last
    // export (update 60): with the table saying update 30 reached more goals,
    // update 30's networks.
    let publish = |out_dir: &std::path::Path| {
        Command::new(BIN)
            .args(["publish", "--run"])
            .arg(&out)
            .arg("--out")
            .arg(out_dir)
            .args(["--command", "by hand"])
            .output()
            .unwrap()
    };
    std::fs::write(
        out.join("selection.csv"),
        "updates,reached,goals,mean_time_s\n30,2,2,9.000\n60,1,2,8.000\n",
    )
    .unwrap();
    let again = dir.path().join("again");
    let o = publish(&again);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let actor_of = |d: &std::path::Path| std::fs::read(d.join(weights::ACTOR_FILE)).unwrap();
    let u30 = out.join("candidates").join(format!("u{:09}", 30));
    assert_eq!(actor_of(&again), actor_of(&u30));
    assert_ne!(
        actor_of(&again),
        actor_of(&out),
        "the last export is update 60"
    );
    let readme = std::fs::read_to_string(again.join("README.md")).unwrap();
    assert!(readme.contains("the checkpoint at update 30"), "{readme}");
    // A damaged table is refused by file and line.
    std::fs::write(
        out.join("selection.csv"),
        "updates,reached,goals,mean_time_s\n30,2,x,9\n",
    )
    .unwrap();
    let o = publish(&dir.path().join("damaged"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("selection.csv line 2"), "{err}");
}
