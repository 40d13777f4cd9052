//! Weight-file round trip and every malformed case rejected with a message that
//! names the file and the tensor or key.

mod common;

use std::collections::HashMap;

use control::model::{Control, Goal, MachineParams, State};
use control::weights::{
    decode, encode, load, load_for, FileDtype, NetworkRole, WeightsProblem, ACTOR_FILE,
    CRITIC_FILE, DEFAULT_DIR,
};
use control::{Actor, ActorWorkspace, Critic, CriticWorkspace};
use safetensors::tensor::{Dtype, TensorView};

const FILE: &str = "critic-weights/avant635/critic.safetensors";

fn good_bytes() -> Vec<u8> {
    let w = common::random_critic_weights(4, 1);
    encode(&w.meta, &w.mlp, FileDtype::F32).unwrap()
}

/// Rebuilds a file from its tensors and metadata after `edit` changed them.
fn rebuild(
    bytes: &[u8],
    edit: impl FnOnce(&mut Vec<(String, Dtype, Vec<usize>, Vec<u8>)>, &mut HashMap<String, String>),
) -> Vec<u8> {
    let st = safetensors::SafeTensors::deserialize(bytes).unwrap();
    let (_, header) = safetensors::SafeTensors::read_metadata(bytes).unwrap();
    let mut meta = header.metadata().clone().unwrap();
    let mut tensors: Vec<_> = st
        .tensors()
        .into_iter()
        .map(|(n, v)| (n, v.dtype(), v.shape().to_vec(), v.data().to_vec()))
        .collect();
    edit(&mut tensors, &mut meta);
    let views: Vec<_> = tensors
        .iter()
        .map(|(n, d, s, b)| (n.clone(), TensorView::new(*d, s.clone(), b).unwrap()))
        .collect();
    safetensors::serialize(views, &Some(meta)).unwrap()
}

fn expect_error(bytes: &[u8], needle: &str) -> WeightsProblem {
    let err = decode(bytes, FILE).expect_err("malformed file accepted");
    let msg = err.to_string();
    assert!(msg.contains(FILE), "message does not name the file: {msg}");
    assert!(
        msg.contains(needle),
        "message `{msg}` does not mention `{needle}`"
    );
    err.problem
}

#[test]
fn round_trip_preserves_values_and_metadata() {
    let w = common::random_critic_weights(4, 1);
    for dtype in [FileDtype::F64, FileDtype::F32] {
        let bytes = encode(&w.meta, &w.mlp, dtype).unwrap();
        let back = decode(&bytes, FILE).unwrap();
        assert_eq!(back.meta, w.meta);
        for (a, b) in back.mlp.layers().iter().zip(w.mlp.layers()) {
            for (x, y) in a.weight.iter().zip(&b.weight) {
                let tol = if dtype == FileDtype::F64 {
                    0.0
                } else {
                    1e-7 * y.abs().max(1e-3)
                };
                assert!((x - y).abs() <= tol);
            }
        }
    }
    // Same value from the f64 file as from the in-memory network.
    let critic = Critic::from_weights(w.clone()).unwrap();
    let loaded = Critic::from_weights(
        decode(&encode(&w.meta, &w.mlp, FileDtype::F64).unwrap(), FILE).unwrap(),
    )
    .unwrap();
    let (mut a, mut b) = (CriticWorkspace::new(&critic), CriticWorkspace::new(&loaded));
    let (x, u, g) = (
        State::new(1.0, 2.0, 0.3, 0.1, 0.0, 0.5),
        Control::new(0.1, -0.2),
        Goal::new(4.0, 0.0, 1.0),
    );
    assert_eq!(
        critic.value(&mut a, &x, &u, &g),
        loaded.value(&mut b, &x, &u, &g)
    );
}

#[test]
fn not_safetensors() {
    expect_error(b"definitely not a weights file", "not a safetensors file");
    expect_error(&[], "not a safetensors file");
    let mut truncated = good_bytes();
    truncated.truncate(truncated.len() - 100);
    expect_error(&truncated, "not a safetensors file");
}

#[test]
fn wrong_shape() {
    let bytes = rebuild(&good_bytes(), |t, _| {
        let b = t.iter_mut().find(|t| t.0 == "layers.2.bias").unwrap();
        b.2 = vec![b.2[0] - 1];
        b.3.truncate(b.3.len() - 4);
    });
    expect_error(&bytes, "layers.2.bias");
    let bytes = rebuild(&good_bytes(), |t, _| {
        let w = t.iter_mut().find(|t| t.0 == "layers.1.weight").unwrap();
        w.2 = vec![w.2[0] * w.2[1]];
    });
    expect_error(&bytes, "layers.1.weight");
}

#[test]
fn layer_chain_mismatch() {
    // Layer 3 claims 97 inputs where layer 2 gives 144.
    let bytes = rebuild(&good_bytes(), |t, _| {
        let w = t.iter_mut().find(|t| t.0 == "layers.3.weight").unwrap();
        let (o, i) = (w.2[0], w.2[1]);
        w.2 = vec![o * i / 96, 96];
        let n = w.2[0];
        let b = t.iter_mut().find(|t| t.0 == "layers.3.bias").unwrap();
        b.2 = vec![n];
        b.3 = vec![0; n * 4];
    });
    let p = expect_error(&bytes, "layer 3");
    assert!(matches!(p, WeightsProblem::Chain(_)));
}

#[test]
fn missing_and_unexpected_tensors() {
    let bytes = rebuild(&good_bytes(), |t, _| t.retain(|t| t.0 != "layers.4.bias"));
    expect_error(&bytes, "layers.4.bias");
    let bytes = rebuild(&good_bytes(), |t, _| t.retain(|t| t.0 != "layers.0.weight"));
    expect_error(&bytes, "layers.0.weight");
    let bytes = rebuild(&good_bytes(), |t, _| {
        t.push(("extra.scale".into(), Dtype::F32, vec![1], vec![0; 4]))
    });
    expect_error(&bytes, "extra.scale");
}

#[test]
fn non_finite_values() {
    for bad in [f32::NAN, f32::INFINITY] {
        let bytes = rebuild(&good_bytes(), |t, _| {
            let w = t.iter_mut().find(|t| t.0 == "layers.5.weight").unwrap();
            w.3[8..12].copy_from_slice(&bad.to_le_bytes());
        });
        expect_error(&bytes, "layers.5.weight` has a non-finite value at index 2");
    }
}

#[test]
fn wrong_dtype() {
    let bytes = rebuild(&good_bytes(), |t, _| {
        let b = t.iter_mut().find(|t| t.0 == "layers.0.bias").unwrap();
        b.1 = Dtype::I32;
    });
    expect_error(&bytes, "layers.0.bias` has dtype I32");
}

#[test]
fn missing_or_bad_metadata() {
    for key in [
        "format_version",
        "encoder",
        "machine.beta_max",
        "dt",
        "cost.w",
        "output_size",
        "git_commit",
    ] {
        let bytes = rebuild(&good_bytes(), |_, m| {
            m.remove(key);
        });
        expect_error(&bytes, &format!("`{key}` is missing"));
    }
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("gamma".into(), "zero point nine".into());
    });
    expect_error(&bytes, "`gamma` has an invalid value");
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("cost.w".into(), "1,2,3".into());
    });
    expect_error(&bytes, "`cost.w`");
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("cost.form".into(), "l2".into());
    });
    expect_error(&bytes, "`cost.form` has an invalid value `l2`");
    // Files from before the key existed load as the quasi-norm.
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.remove("cost.form");
    });
    let w = decode(&bytes, "old.safetensors").expect("loads without cost.form");
    assert_eq!(w.meta.cost.form, control::CostForm::QuasiNorm);
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("output_size".into(), "3".into());
    });
    expect_error(&bytes, "3 outputs (metadata `output_size`)");
}

#[test]
fn incompatible_metadata() {
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("encoder".into(), "some-other-encoder".into());
    });
    expect_error(&bytes, "`encoder` = some-other-encoder is incompatible");
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("format_version".into(), "2".into());
    });
    expect_error(&bytes, "`format_version` = 2 is incompatible");
    let bytes = rebuild(&good_bytes(), |_, m| {
        m.insert("activation".into(), "relu".into());
    });
    expect_error(&bytes, "`activation` = relu");

    // Trained for other machine bounds than configured.
    let w = decode(&good_bytes(), FILE).unwrap();
    let mut configured = MachineParams::default();
    assert!(w.meta.check_compatible(&configured, 0.2).is_ok());
    configured.v_max = 2.0;
    let e = w.meta.check_compatible(&configured, 0.2).unwrap_err();
    assert!(
        e.to_string()
            .contains("trained for `machine.v_max` = 1, incompatible with the configured 2"),
        "{e}"
    );
    let e = w
        .meta
        .check_compatible(&MachineParams::default(), 0.1)
        .unwrap_err();
    assert!(e.to_string().contains("`dt`"), "{e}");
}

#[test]
fn roles_are_checked() {
    let w = decode(&good_bytes(), FILE).unwrap();
    let e = Actor::from_weights(w).unwrap_err();
    assert!(
        e.to_string().contains("role is `critic`, expected `actor`"),
        "{e}"
    );
    // A critic file whose first layer takes the actor's 7 inputs.
    let actor = common::random_actor(2);
    let mut meta = actor.metadata().clone();
    meta.role = NetworkRole::Critic;
    let bytes = encode(&meta, actor.mlp(), FileDtype::F32).unwrap();
    expect_error(&bytes, "9 inputs for the critic encoder");
}

#[test]
fn actor_action_is_bounded_tanh_of_mean() {
    let actor = common::random_actor(4);
    let mut ws = ActorWorkspace::new(&actor);
    let p = MachineParams::default();
    let g = Goal::new(5.0, -2.0, 1.0);
    for k in 0..20 {
        let x = State::new(k as f64 * 0.5, -1.0, 0.1 * k as f64, 0.0, 0.1, 0.3);
        let m = actor.mean(&mut ws, &x, &g);
        let a = actor.action(&mut ws, &x, &g);
        assert!((a[0] - m[0].tanh() * p.beta_ddot_max).abs() < 1e-15);
        assert!((a[1] - m[1].tanh() * p.a_max).abs() < 1e-15);
        assert!(a[0].abs() <= p.beta_ddot_max && a[1].abs() <= p.a_max);
    }
}

#[test]
fn load_names_the_file_on_a_read_error_a_wrong_role_and_a_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nothing-here.safetensors");
    let e = load(&missing, NetworkRole::Critic).unwrap_err();
    assert!(
        matches!(e.problem, WeightsProblem::Read { kind, .. } if kind == std::io::ErrorKind::NotFound),
        "{e:?}"
    );
    let msg = e.to_string();
    assert!(msg.contains(&missing.display().to_string()), "{msg}");
    assert!(msg.contains("cannot read"), "{msg}");

    let path = dir.path().join(CRITIC_FILE);
    std::fs::write(&path, good_bytes()).unwrap();
    let w = load(&path, NetworkRole::Critic).unwrap();
    assert_eq!(w.source, path.display().to_string());
    let e = load(&path, NetworkRole::Actor).unwrap_err();
    assert_eq!(
        e.problem,
        WeightsProblem::WrongRole {
            expected: NetworkRole::Actor,
            found: NetworkRole::Critic
        }
    );
    assert!(e.to_string().contains(&path.display().to_string()), "{e}");

    let machine = MachineParams::default();
    assert!(load_for(&path, NetworkRole::Critic, &machine, 0.2).is_ok());
    let other = MachineParams {
        l_f: 0.9,
        ..machine
    };
    let e = load_for(&path, NetworkRole::Critic, &other, 0.2).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains("`machine.l_f`") && msg.contains("0.9"),
        "{msg}"
    );
    let e = load_for(&path, NetworkRole::Critic, &machine, 0.1).unwrap_err();
    assert!(e.to_string().contains("`dt` = 0.2"), "{e}");
}

#[test]
fn the_default_machine_directory_holds_both_networks() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(DEFAULT_DIR);
    let critic = load(&dir.join(CRITIC_FILE), NetworkRole::Critic).unwrap();
    let actor = load(&dir.join(ACTOR_FILE), NetworkRole::Actor).unwrap();
    // Both for the default machine (the daemon's default configuration).
    let (machine, dt) = (MachineParams::default(), critic.meta.dt);
    critic.meta.check_compatible(&machine, dt).unwrap();
    actor.meta.check_compatible(&machine, dt).unwrap();
}
