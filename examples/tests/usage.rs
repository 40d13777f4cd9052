//! The examples refuse arguments they do not take, naming the usage (their runs against a
//! daemon are scripts/examples.sh). This test also makes `cargo test --workspace` build
//! the example binaries with the test build's features, so the script rebuilds nothing.

use std::process::Command;

#[test]
fn unknown_arguments_print_the_usage_and_fail() {
    for (bin, name) in [
        (env!("CARGO_BIN_EXE_goal-client"), "goal-client"),
        (env!("CARGO_BIN_EXE_pose-publisher"), "pose-publisher"),
        (env!("CARGO_BIN_EXE_person-publisher"), "person-publisher"),
    ] {
        let out = Command::new(bin).arg("--bogus").output().unwrap();
        assert!(!out.status.success(), "{name} accepted --bogus");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(&format!("usage: {name} [--prefix P]")),
            "{name}: {err}"
        );
    }
}
