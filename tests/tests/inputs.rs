//! Inputs that lie, from outside through the real binaries (issue 15): a process that holds
//! every goal client slot cannot keep `wlnav stop` out; a crashed client's slots come
//! back; `wlnav` exits 130 on Ctrl-C and 4 when the daemon is lost during `goal --wait`.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use e2e::{binaries, SimDaemon};
use shm_ipc::{Client, IpcConfig, Mode};

/// Helper process for the tests below (run as a child of this test binary): opens up to 40
/// clients on `WLNAV_HOLD_PREFIX`, prints how many it holds, then sleeps until killed.
#[test]
#[ignore = "helper process for a_process_holding_every_client_slot_cannot_keep_a_stop_out"]
fn hold_clients_helper() {
    let Ok(prefix) = std::env::var("WLNAV_HOLD_PREFIX") else {
        return;
    };
    let config = IpcConfig::new(prefix);
    let held: Vec<Client> = (0..40).filter_map(|_| Client::new(&config).ok()).collect();
    println!("held {}", held.len());
    std::thread::sleep(Duration::from_secs(120));
}

fn spawn_holder(prefix: &str) -> (Child, usize) {
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--ignored", "--exact", "hold_clients_helper", "--nocapture"])
        .env("WLNAV_HOLD_PREFIX", prefix)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn the holder");
    let out = child.stdout.take().unwrap();
    let mut held = None;
    for line in BufReader::new(out).lines() {
        let line = line.unwrap();
        if let Some(n) = line.strip_prefix("held ") {
            held = Some(n.trim().parse().unwrap());
            break;
        }
    }
    (child, held.expect("the holder reports"))
}

fn wlnav(args: &[&str]) -> std::process::Output {
    Command::new(&binaries().wlnav)
        .args(args)
        .output()
        .expect("run wlnav")
}

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn a_process_holding_every_client_slot_cannot_keep_a_stop_out() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("slots", e2e::FAST);
    let p = d.prefix().to_owned();
    let o = wlnav(&["--prefix", &p, "goal", "8", "0", "0"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(20));
    loop {
        let t = d.next(Duration::from_secs(2));
        if t.mode() == Ok(Mode::Tracking) && t.state.v_f > 0.3 {
            break;
        }
        assert!(Instant::now() < deadline, "never drove: {t:?}");
    }
    // Another process takes every goal client slot (40 asked, 32 exist; our own client
    // holds one).
    let (mut holder, held) = spawn_holder(&p);
    assert!(held >= 30, "the holder got only {held} clients");
    let o = wlnav(&["--prefix", &p, "goal", "5", "0", "0"]);
    assert_eq!(
        o.status.code(),
        Some(4),
        "goal slots still free? {}",
        text(&o)
    );
    // The stop gets through and the machine stops.
    let o = wlnav(&["--prefix", &p, "stop"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("stop: accepted"), "{}", text(&o));
    let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(10));
    loop {
        let t = d.next(Duration::from_secs(2));
        if t.goal_active == 0 && t.command.v == 0.0 && t.at_rest == 1 {
            break;
        }
        assert!(Instant::now() < deadline, "not stopping: {t:?}");
    }
    // The stop latched like any operator stop: after the holder crashes its slots come
    // back (stale-node clean-up), a resume releases the latch and goals work again.
    holder.kill().unwrap();
    holder.wait().unwrap();
    let o = wlnav(&["--prefix", &p, "resume"]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "slots not recovered after the holder crashed? {}",
        text(&o)
    );
    let o = wlnav(&["--prefix", &p, "goal", "5", "0", "0"]);
    assert_eq!(o.status.code(), Some(0), "goal after resume: {}", text(&o));
    d.stop();
}

/// Sends SIGINT to `child` once it has printed a line on stdout (or after a second if
/// `wait_for_line` is false), and returns its exit code and output.
fn interrupt(mut child: Child, wait_for_line: bool) -> (Option<i32>, String) {
    let out = child.stdout.take().unwrap();
    let mut lines = BufReader::new(out).lines();
    let first = if wait_for_line {
        lines.next().expect("a line").unwrap()
    } else {
        std::thread::sleep(Duration::from_millis(700));
        String::new()
    };
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGINT) }, 0);
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let status = child.wait().unwrap();
    (status.code(), format!("{first}\n{}", rest.join("\n")))
}

#[test]
fn ctrl_c_exits_130_and_a_lost_daemon_during_goal_wait_exits_4() {
    let _serial = e2e::serial();
    let mut d = SimDaemon::start("exit-codes", 1.0);
    let p = d.prefix().to_owned();
    let dir = std::env::temp_dir().join(format!("wlnav-e2e-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let wlnav_cmd = |args: &[&str]| {
        Command::new(&binaries().wlnav)
            .arg("--prefix")
            .arg(&p)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn wlnav")
    };
    let (code, out) = interrupt(wlnav_cmd(&["watch"]), true);
    assert_eq!(code, Some(130), "watch:\n{out}");
    let file = dir.join("x.mcap");
    let (code, out) = interrupt(wlnav_cmd(&["record", file.to_str().unwrap()]), false);
    assert!(out.contains("wrote"), "record finishes its file:\n{out}");
    assert_eq!(code, Some(130), "record:\n{out}");
    let (code, out) = interrupt(wlnav_cmd(&["goal", "20", "0", "0", "--wait"]), true);
    assert_eq!(code, Some(130), "goal --wait:\n{out}");

    // The daemon dies (kill -9) while `goal --wait` follows a goal: exit 4.
    let mut child = wlnav_cmd(&["goal", "20", "0", "0", "--wait"]);
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    out.read_line(&mut first).unwrap();
    assert!(first.contains("accepted"), "{first}");
    let pid = d.process.pid().expect("daemon pid");
    // SAFETY: kill(2) on the daemon we started.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut out, &mut rest).unwrap();
    let status = child.wait().unwrap();
    assert_eq!(
        status.code(),
        Some(4),
        "goal --wait after the daemon died:\n{rest}"
    );
    let _ = d.process.try_wait();
    let _ = std::fs::remove_dir_all(&dir);
}
