//! `wlnav-train` refuses weights trained for another machine or Δt than a
//! training config given beside them (`verify`/`stalls --terminal-from`,
//! `publish`'s run config), and an actor and critic that disagree; each message
//! names the key and both values.

use std::path::Path;
use std::process::Command;

use control::mlp::PAPER_HIDDEN;
use control::weights::{encode, random_network, FileDtype, NetworkMetadata, NetworkRole};
use control::MachineParams;

const BIN: &str = env!("CARGO_BIN_EXE_wlnav-train");

/// Small random networks trained-for `machine` and Δt 0.2 s in `dir`.
fn write_networks(dir: &Path, critic: MachineParams, actor: MachineParams) {
    for (role, outputs, name, machine) in [
        (NetworkRole::Critic, 4, "critic.safetensors", critic),
        (NetworkRole::Actor, 4, "actor.safetensors", actor),
    ] {
        let mut meta = NetworkMetadata::new(role, outputs);
        meta.machine = machine;
        let w = random_network(meta, &PAPER_HIDDEN, 1);
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F32).unwrap();
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// Runs `wlnav-train ARGS`; it must fail; returns its stderr.
fn fails(args: &[&str]) -> String {
    let out = Command::new(BIN).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "succeeded: {args:?}\n{err}");
    err
}

fn large() -> MachineParams {
    MachineParams {
        l_f: 0.9,
        ..MachineParams::default()
    }
}

#[test]
fn verify_and_stalls_refuse_a_terminal_config_for_another_machine_or_dt() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_networks(d, MachineParams::default(), MachineParams::default());
    let (critic, actor) = (d.join("critic.safetensors"), d.join("actor.safetensors"));
    let config = d.join("large.toml");
    std::fs::write(&config, "[machine]\nl_f = 0.9\n").unwrap();
    let (critic, actor, config) = (
        critic.to_str().unwrap(),
        actor.to_str().unwrap(),
        config.to_str().unwrap(),
    );
    let args = [
        "verify",
        "--actor",
        actor,
        "--critic",
        critic,
        "--episodes",
        "1",
        "--terminal-from",
        config,
    ];
    let err = fails(&args);
    assert!(err.contains(config) && err.contains(critic), "{err}");
    assert!(
        err.contains("trained for `machine.l_f` = 0.6, incompatible with the configured 0.9"),
        "{err}"
    );
    let err = fails(&[
        "stalls",
        "--actor",
        actor,
        "--episodes",
        "1",
        "--terminal-from",
        config,
    ]);
    assert!(err.contains(config) && err.contains(actor), "{err}");
    assert!(
        err.contains("`machine.l_f` = 0.6") && err.contains("0.9"),
        "{err}"
    );

    std::fs::write(d.join("dt.toml"), "dt = 0.1\n").unwrap();
    let dt_config = d.join("dt.toml");
    let mut args = args;
    args[8] = dt_config.to_str().unwrap();
    let err = fails(&args);
    assert!(
        err.contains("trained for `dt` = 0.2, incompatible with the configured 0.1"),
        "{err}"
    );
}

#[test]
fn verify_refuses_an_actor_and_a_critic_of_different_machines() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_networks(d, MachineParams::default(), large());
    let err = fails(&[
        "verify",
        "--actor",
        d.join("actor.safetensors").to_str().unwrap(),
        "--critic",
        d.join("critic.safetensors").to_str().unwrap(),
        "--episodes",
        "1",
    ]);
    assert!(err.contains("different machines"), "{err}");
    assert!(
        err.contains("trained for `machine.l_f` = 0.9, incompatible with the configured 0.6"),
        "{err}"
    );
}

#[test]
fn publish_refuses_a_run_whose_config_and_weights_disagree() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    std::fs::create_dir(&run).unwrap();
    write_networks(&run, large(), large());
    for f in ["log.csv", "eval.csv"] {
        std::fs::write(run.join(f), "").unwrap();
    }
    // The run's config names the default machine; its weights the large one.
    std::fs::write(run.join("config.toml"), "seed = 1\n").unwrap();
    let out = dir.path().join("published");
    let err = fails(&[
        "publish",
        "--run",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--command",
        "test",
    ]);
    assert!(err.contains("config.toml"), "{err}");
    assert!(
        err.contains("trained for `machine.l_f` = 0.9, incompatible with the configured 0.6"),
        "{err}"
    );
    assert!(
        !out.exists(),
        "publish wrote {} before refusing",
        out.display()
    );
}
