//! Who holds a service's ports: the text every "slots taken" and "already served" error
//! carries, so a field engineer knows which process to stop (README fault table, rows 7,
//! 8 and 24–26).
//!
//! iceoryx2 records, for every port of a service, the id of the node that created it
//! (`dynamic_config().list_clients(..)` etc.), and for every node its name, process id and
//! executable (`Node::list`). Matching the two names the holder. A node whose details
//! cannot be read (another user's, or removed meanwhile) is reported as such: "the holder
//! could not be found".

use std::collections::BTreeMap;

use crate::endpoint::IpcService;
use crate::msg::{GoalReply, GoalRequest};
use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

type GoalFactory = request_response::PortFactory<IpcService, GoalRequest, (), GoalReply, ()>;

/// The node ids of a service's ports of one kind, with their count.
type Counts = BTreeMap<u128, usize>;

/// One node as a reader needs it: `node "squatter" (pid 4711, squat-helper)`.
fn describe_node(state: &NodeState<IpcService>) -> Option<(u128, String)> {
    let (view_id, details, dead) = match state {
        NodeState::Alive(v) => (v.id().value(), v.details().clone(), false),
        NodeState::Dead(v) => (v.id().value(), v.details().clone(), true),
        NodeState::Inaccessible(id) => {
            return Some((
                id.value(),
                "a node of another user (details not readable)".into(),
            ))
        }
        NodeState::Undefined(id) => {
            return Some((id.value(), "a node in an undefined state".into()))
        }
    };
    let text = match details {
        Some(d) => {
            let pid = d.process_id().value();
            format!(
                "{}node {:?} (pid {pid}, {})",
                if dead { "dead " } else { "" },
                d.name().to_string(),
                executable(pid, &d.executable().to_string())
            )
        }
        None => format!(
            "a {} node without details",
            if dead { "dead" } else { "live" }
        ),
    };
    Some((view_id, text))
}

/// The executable's full path from `/proc` when the process is alive and readable, else
/// the file name iceoryx2 recorded. A program run by an emulator through binfmt_misc (an
/// arm64 binary under `qemu-aarch64-static` on an x86-64 machine) has the emulator as its
/// `/proc/<pid>/exe`; then the program is named from the command line the kernel gave the
/// emulator, and the emulator too: `/path/to/program (under /usr/bin/qemu-aarch64-static)`.
fn executable(pid: i32, recorded: &str) -> String {
    let Ok(exe) = std::fs::read_link(format!("/proc/{pid}/exe")) else {
        return recorded.to_owned();
    };
    if !is_emulator(&exe, &binfmt_interpreters()) {
        return exe.display().to_string();
    }
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    let cwd = std::fs::read_link(format!("/proc/{pid}/cwd")).ok();
    match emulated_program(&cmdline, cwd.as_deref()) {
        Some(program) => format!("{} (under {})", program.display(), exe.display()),
        None => format!("{recorded} (under {})", exe.display()),
    }
}

/// The interpreters registered with binfmt_misc (enabled or not), resolved: the files a
/// `/proc/<pid>/exe` of an emulated program points to. Empty where binfmt_misc is not
/// mounted or readable.
fn binfmt_interpreters() -> Vec<std::path::PathBuf> {
    let Ok(entries) = std::fs::read_dir("/proc/sys/fs/binfmt_misc") else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .filter_map(|text| {
            text.lines()
                .find_map(|l| l.strip_prefix("interpreter "))
                .map(|i| std::fs::canonicalize(i).unwrap_or_else(|_| i.into()))
        })
        .collect()
}

/// Whether `exe` (a resolved `/proc/<pid>/exe`) is an emulator: one of the binfmt_misc
/// `interpreters`, or a QEMU user-mode emulator (`qemu-<arch>`, `qemu-<arch>-static`;
/// also run by hand, or registered where this process cannot read binfmt_misc).
fn is_emulator(exe: &std::path::Path, interpreters: &[std::path::PathBuf]) -> bool {
    interpreters.iter().any(|i| i == exe)
        || exe
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("qemu-"))
}

/// The program an emulator runs, from the emulator's command line (`/proc/<pid>/cmdline`):
/// binfmt_misc starts it as `interpreter program [argv0] args…`, and `qemu-<arch> program
/// args…` by hand gives the same; a relative path is taken from the process's `cwd`. None
/// when the first argument is missing or an option (the emulator's own, by hand).
fn emulated_program(cmdline: &[u8], cwd: Option<&std::path::Path>) -> Option<std::path::PathBuf> {
    use std::os::unix::ffi::OsStrExt;
    let arg = cmdline.split(|b| *b == 0).nth(1)?;
    if arg.is_empty() || arg.starts_with(b"-") {
        return None;
    }
    let program = std::path::Path::new(std::ffi::OsStr::from_bytes(arg));
    Some(match cwd {
        Some(dir) if program.is_relative() => dir.join(program),
        _ => program.to_owned(),
    })
}

/// Names the nodes behind `counts` ("16 held by node … (pid …, …)"), or says that they
/// could not be found.
fn name_holders(counts: &Counts, what: &str) -> String {
    if counts.is_empty() {
        return format!(
            "the holder could not be found (iceoryx2 lists no {what}; they may have been \
             released meanwhile)"
        );
    }
    let mut known: BTreeMap<u128, String> = BTreeMap::new();
    let listed = Node::<IpcService>::list(iceoryx2::config::Config::global_config(), |state| {
        if let Some((id, text)) = describe_node(&state) {
            if counts.contains_key(&id) {
                known.insert(id, text);
            }
        }
        CallbackProgression::Continue
    });
    let mut parts: Vec<String> = counts
        .iter()
        .map(|(id, n)| {
            let who = known
                .get(id)
                .cloned()
                .unwrap_or_else(|| format!("node id {id:x}, whose process could not be found"));
            format!("{n} held by {who}")
        })
        .collect();
    if let Err(e) = listed {
        parts.push(format!("(listing the nodes failed: {e:?})"));
    }
    parts.join("; ")
}

fn count(counts: &mut Counts, id: u128) -> CallbackProgression {
    *counts.entry(id).or_default() += 1;
    CallbackProgression::Continue
}

/// Who holds the client ports of a request-response service.
pub(crate) fn client_holders(factory: &GoalFactory) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_clients(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "client ports")
}

/// Who holds the server port(s) of a request-response service.
pub(crate) fn server_holders(factory: &GoalFactory) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_servers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "server ports")
}

/// Who holds the publishers of a publish-subscribe service.
pub(crate) fn publisher_holders<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend>(
    factory: &publish_subscribe::PortFactory<IpcService, T, ()>,
) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_publishers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "publishers")
}

/// Who holds the subscribers of a publish-subscribe service.
pub(crate) fn subscriber_holders<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend>(
    factory: &publish_subscribe::PortFactory<IpcService, T, ()>,
) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_subscribers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "subscribers")
}

/// Who holds the notifiers of an event service.
pub(crate) fn notifier_holders(factory: &event::PortFactory<IpcService>) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_notifiers(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "notifiers")
}

/// Who holds the listeners of an event service.
pub(crate) fn listener_holders(factory: &event::PortFactory<IpcService>) -> String {
    let mut counts = Counts::new();
    factory
        .dynamic_config()
        .list_listeners(|d| count(&mut counts, d.node_id.value()));
    name_holders(&counts, "listeners")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    #[test]
    fn a_binfmt_interpreter_or_a_qemu_is_an_emulator_and_nothing_else() {
        let qemu = PathBuf::from("/usr/bin/qemu-aarch64-static");
        assert!(is_emulator(&qemu, std::slice::from_ref(&qemu)));
        assert!(is_emulator(&qemu, &[]));
        let box64 = PathBuf::from("/usr/local/bin/box64");
        assert!(is_emulator(&box64, std::slice::from_ref(&box64)));
        assert!(!is_emulator(Path::new("/usr/bin/wlnavd"), &[qemu]));
        assert!(!is_emulator(Path::new("/usr/bin/wlnavd"), &[]));
    }

    #[test]
    fn the_emulated_program_is_the_first_argument() {
        // binfmt_misc with flag P: interpreter, the program's path, its own argv[0], args.
        let binfmt = b"/usr/libexec/qemu-binfmt/aarch64-binfmt-P\0/opt/t/stop_squat-1\0/opt/t/stop_squat-1\0--ignored\0";
        assert_eq!(
            emulated_program(binfmt, Some(Path::new("/work"))),
            Some(PathBuf::from("/opt/t/stop_squat-1"))
        );
        // By hand, a relative path: from the process's working directory.
        assert_eq!(
            emulated_program(
                b"qemu-aarch64-static\0bin/wlnavd\0--sim\0",
                Some(Path::new("/work"))
            ),
            Some(PathBuf::from("/work/bin/wlnavd"))
        );
        // The emulator's own options first, or nothing: not known.
        assert_eq!(
            emulated_program(b"qemu-aarch64\0-cpu\0max\0bin/wlnavd\0", None),
            None
        );
        assert_eq!(emulated_program(b"qemu-aarch64\0", None), None);
        assert_eq!(emulated_program(b"", None), None);
    }

    #[test]
    fn a_native_process_is_named_by_its_executable() {
        let own = std::fs::read_link("/proc/self/exe").unwrap();
        let named = executable(std::process::id() as i32, "recorded");
        // Natively the path itself; under an emulator (the arm64 check) the path with the
        // emulator after it.
        assert!(
            named.starts_with(&own.display().to_string()) || named.contains(" (under "),
            "{named}"
        );
        assert_eq!(executable(i32::MAX, "recorded"), "recorded");
    }
}
