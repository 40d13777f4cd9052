//! `wlnav obstacles publish`: the JSON Lines it reads, what it refuses (naming the line
//! and the rule), and what reaches the daemon's side. The daemon here is the library's
//! [`DaemonEndpoint`] on its own prefix: it creates the services as wlnavd does, and the
//! test reads what arrives.

use std::io::Write;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use shm_ipc::{
    DaemonEndpoint, IpcConfig, LiveObstacleSet, LiveObstacleValidator, ObstacleClass,
    ObstaclePublisher, ObstacleShape,
};
use wlnav_cli::obstacles::{parse_line, read_all};

const EXAMPLE: &str = r#"{"obstacles":[{"id":1,"class":"person","circle":{"x":3.0,"y":0.0,"radius":0.4},"velocity":[0.0,1.4]},{"id":2,"polygon":[[0,0],[2,0],[2,1],[0,1]]}]}"#;

fn unique_config(test: &str) -> IpcConfig {
    IpcConfig::new(format!(
        "wlnav-test/{}/cli-{test}/{}",
        std::process::id(),
        shm_ipc::monotonic_now_ns()
    ))
}

fn parse(line: &str) -> Result<Option<Vec<shm_ipc::LiveObstacle>>, String> {
    parse_line(line, &LiveObstacleValidator::default())
}

#[test]
fn the_documented_line_parses_with_its_defaults() {
    let set = parse(EXAMPLE).expect("valid").expect("a set");
    assert_eq!(set.len(), 2);
    let (person, box_) = (&set[0], &set[1]);
    assert_eq!((person.id, person.class()), (1, Ok(ObstacleClass::Person)));
    assert_eq!(person.shape(), Ok(ObstacleShape::Circle));
    assert_eq!((person.x, person.y, person.radius), (3.0, 0.0, 0.4));
    assert_eq!(person.velocity(), [0.0, 1.4]);
    // Class and velocity are optional.
    assert_eq!((box_.id, box_.class()), (2, Ok(ObstacleClass::Unknown)));
    assert_eq!(box_.shape(), Ok(ObstacleShape::Polygon));
    assert_eq!(
        box_.vertices(),
        &[[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    );
    assert_eq!(box_.velocity(), [0.0, 0.0]);
    assert_eq!(parse("   ").expect("blank"), None);
    assert_eq!(
        parse(r#"{"obstacles":[]}"#).expect("empty"),
        Some(Vec::new())
    );
}

#[test]
fn bad_lines_say_what_is_wrong() {
    let cases = [
        (
            r#"{"obstacles":[{"id":1,"circle":{"x":1,"y":0,"radius":0.5}}"#,
            "not valid JSON",
        ),
        (r#"{"obstacle":[]}"#, "unknown field `obstacle`"),
        (
            r#"{"obstacles":[{"circle":{"x":1,"y":0,"radius":0.5}}]}"#,
            "obstacle 0: `id` is missing",
        ),
        (
            r#"{"obstacles":[{"id":-1,"circle":{"x":1,"y":0,"radius":0.5}}]}"#,
            "`id` must be a whole number",
        ),
        (
            r#"{"obstacles":[{"id":3,"class":"persn","circle":{"x":1,"y":0,"radius":0.5}}]}"#,
            "obstacle 0 (id 3): unknown class \"persn\"",
        ),
        (
            r#"{"obstacles":[{"id":3,"circle":{"x":1,"y":0,"r":0.5}}]}"#,
            "unknown field `r` (expected x, y, radius)",
        ),
        (
            r#"{"obstacles":[{"id":3}]}"#,
            "`circle` or `polygon` is missing",
        ),
        (
            r#"{"obstacles":[{"id":3,"circle":{"x":1,"y":0,"radius":0.5},"polygon":[[0,0],[1,0],[0,1]]}]}"#,
            "not both",
        ),
        (
            r#"{"obstacles":[{"id":3,"polygon":[[0,0],[1,0]]}]}"#,
            "3 to 8 vertices, 2 given",
        ),
        (
            r#"{"obstacles":[{"id":3,"polygon":[[0,0],[1,0],[1]]}]}"#,
            "vertex 2 must be two numbers",
        ),
        (
            r#"{"obstacles":[{"id":3,"circle":{"x":1,"y":0,"radius":0.5},"velocity":[1]}]}"#,
            "`velocity` must be two numbers",
        ),
        // The daemon's rules, named.
        (
            r#"{"obstacles":[{"id":3,"circle":{"x":1,"y":0,"radius":0}}]}"#,
            "(radius-not-positive): obstacle 0 (id 3)",
        ),
        (
            r#"{"obstacles":[{"id":3,"circle":{"x":1,"y":0,"radius":1}},{"id":3,"circle":{"x":5,"y":0,"radius":1}}]}"#,
            "(duplicate-id): obstacle 1 has id 3",
        ),
        (
            r#"{"obstacles":[{"id":4,"polygon":[[0,0],[2,0],[2,1],[1,0.5],[0,1]]}]}"#,
            "(not-convex)",
        ),
        (
            r#"{"obstacles":[{"id":4,"circle":{"x":1,"y":0,"radius":1},"velocity":[40,0]}]}"#,
            "(speed-too-high)",
        ),
    ];
    for (line, want) in cases {
        let err = parse(line).expect_err(line);
        assert!(err.contains(want), "{line}: {err}");
    }
    let too_many = format!(
        r#"{{"obstacles":[{}]}}"#,
        vec![r#"{"id":1,"circle":{"x":1,"y":0,"radius":1}}"#; 129].join(",")
    );
    assert!(parse(&too_many)
        .expect_err("129")
        .contains("at most 128 fit"));
}

#[test]
fn a_file_is_checked_whole_and_the_bad_line_named() {
    let input = format!("{EXAMPLE}\n\n{EXAMPLE}\n{{\"obstacles\":[{{\"id\":1}}]}}\n{EXAMPLE}\n");
    let bad = read_all(input.as_bytes(), &LiveObstacleValidator::default())
        .expect("read")
        .expect_err("line 4 is bad");
    assert_eq!(bad.line, 4);
    assert_eq!(
        bad.to_string(),
        "line 4: obstacle 0 (id 1): `circle` or `polygon` is missing"
    );
    let good = format!("{EXAMPLE}\n\n{EXAMPLE}\n");
    let sets = read_all(good.as_bytes(), &LiveObstacleValidator::default())
        .expect("read")
        .expect("all good");
    assert_eq!(sets.len(), 2, "the blank line is skipped");
}

fn wlnav(config: &IpcConfig, args: &[&str], stdin: Option<&str>) -> Output {
    wlnav_after(config, args, stdin, Duration::ZERO)
}

/// [`wlnav`] with standard input written `delay` after the start (a slow
/// producer, or a loaded machine).
fn wlnav_after(config: &IpcConfig, args: &[&str], stdin: Option<&str>, delay: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_wlnav"))
        .arg("--prefix")
        .arg(&config.prefix)
        .args(["obstacles", "publish"])
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("wlnav");
    let mut pipe = child.stdin.take().expect("stdin");
    std::thread::sleep(delay);
    if let Some(text) = stdin {
        pipe.write_all(text.as_bytes()).expect("write stdin");
    }
    drop(pipe);
    child.wait_with_output().expect("wlnav output")
}

fn write_file(test: &str, text: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!(
        "wlnav-obstacles-{}-{test}.jsonl",
        std::process::id()
    ));
    std::fs::write(&path, text).expect("write");
    path
}

/// Every set the daemon's side reads while `run` runs on another thread.
fn collect_while<T: Send>(
    ep: &DaemonEndpoint,
    run: impl FnOnce() -> T + Send,
) -> (T, Vec<LiveObstacleSet>) {
    std::thread::scope(|s| {
        let handle = s.spawn(run);
        let mut sets = Vec::new();
        while !handle.is_finished() {
            ep.wait(Some(Duration::from_millis(5))).expect("wait");
            while let Some(set) = ep.receive_obstacles().expect("read") {
                sets.push(set);
            }
        }
        let out = handle.join().expect("run");
        sets.extend(ep.latest_obstacles().expect("read"));
        (out, sets)
    })
}

#[test]
fn sets_reach_the_daemon_in_turn_stamped_when_sent() {
    let config = unique_config("in_turn");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let moved = EXAMPLE.replace("\"x\":3.0", "\"x\":5.0");
    let path = write_file("in_turn", &format!("{EXAMPLE}\n{moved}\n"));
    let start = shm_ipc::monotonic_now_ns();
    let (out, sets) = collect_while(&ep, || {
        wlnav(
            &config,
            &[path.to_str().expect("path"), "--once", "--rate", "20"],
            None,
        )
    });
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{out:?}");
    assert!(
        stdout.contains("published 2 sets on") && stdout.contains("(2 from the input)"),
        "{stdout}"
    );
    let last = sets.last().expect("a set arrived");
    assert_eq!(last.sequence, 1);
    assert_eq!(
        last.as_slice()[0].x,
        5.0,
        "the second line's set is the last"
    );
    let now = shm_ipc::monotonic_now_ns();
    for set in &sets {
        assert!(set.timestamp_ns >= start && set.timestamp_ns <= now);
        assert!(set
            .as_slice()
            .iter()
            .all(|o| o.timestamp_ns == set.timestamp_ns));
        assert_eq!(LiveObstacleValidator::default().validate(set, now), Ok(()));
    }
    std::fs::remove_file(&path).ok();
}

#[test]
fn the_last_set_repeats_with_fresh_stamps_until_the_duration() {
    // The first line written at once, and 0.3 s late: the ticks count from
    // the first set either way (a late first line once cost a tick under load).
    for delay in [0, 300] {
        repeats_until_the_duration(Duration::from_millis(delay));
    }
}

fn repeats_until_the_duration(delay: Duration) {
    let config = unique_config("repeat");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let started = Instant::now();
    let (out, sets) = collect_while(&ep, || {
        wlnav_after(
            &config,
            &["-", "--rate", "20", "--duration", "0.5"],
            Some(&format!("{EXAMPLE}\n")),
            delay,
        )
    });
    assert!(out.status.success(), "{out:?}");
    assert!(started.elapsed() >= Duration::from_millis(450));
    let stdout = String::from_utf8_lossy(&out.stdout);
    // 0.5 s at 20 Hz: sets 0 to 9, all from the one line.
    assert!(
        stdout.contains("published 10 sets") && stdout.contains("(1 from the input)"),
        "{stdout}"
    );
    assert_eq!(sets.last().map(|s| s.sequence), Some(9));
    let stamps: Vec<u64> = sets.iter().map(|s| s.timestamp_ns).collect();
    assert!(sets.len() >= 2, "{} sets seen", sets.len());
    assert!(
        stamps.windows(2).all(|w| w[0] < w[1]),
        "fresh stamps: {stamps:?}"
    );
    assert!(sets.iter().all(|s| s.as_slice().len() == 2));
}

#[test]
fn a_bad_line_exits_1_naming_it_and_publishes_nothing() {
    let config = unique_config("bad_line");
    let ep = DaemonEndpoint::new(&config).expect("daemon");
    let bad = r#"{"obstacles":[{"id":7,"polygon":[[0,0],[1,1],[1,0],[0,1]]}]}"#;
    let path = write_file("bad_line", &format!("{EXAMPLE}\n{bad}\n"));
    let out = wlnav(&config, &[path.to_str().expect("path"), "--once"], None);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(
            "line 2: the daemon would reject this set (self-intersecting): obstacle 0 (id 7)"
        ),
        "{stderr}"
    );
    assert!(stderr.contains("nothing published"), "{stderr}");
    assert_eq!(
        ep.latest_obstacles().expect("read"),
        None,
        "line 1 did not go out either"
    );
    std::fs::remove_file(&path).ok();

    // On standard input the lines before it went out.
    let (out, sets) = collect_while(&ep, || {
        wlnav(
            &config,
            &["-", "--once"],
            Some(&format!("{EXAMPLE}\nnot json\n")),
        )
    });
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("standard input: line 2: not valid JSON"),
        "{stderr}"
    );
    assert!(
        !sets.is_empty() && sets.iter().all(|s| s.sequence == 0),
        "{} sets",
        sets.len()
    );
}

#[test]
fn no_daemon_or_a_second_publisher_exits_4_naming_why() {
    let config = unique_config("no_daemon");
    let out = wlnav(
        &config,
        &["-", "--once", "--connect-timeout", "0.2"],
        Some(EXAMPLE),
    );
    assert_eq!(out.status.code(), Some(4), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no daemon serves") && stderr.contains("/v2/obstacles"),
        "{stderr}"
    );

    let _ep = DaemonEndpoint::new(&config).expect("daemon");
    let _first = ObstaclePublisher::new(&config).expect("first publisher");
    let out = wlnav(&config, &["-", "--once"], Some(EXAMPLE));
    assert_eq!(out.status.code(), Some(4), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("another process already publishes live obstacles"),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!("pid {}", std::process::id())),
        "{stderr}"
    );
}

#[test]
fn publish_arguments_parse_and_bad_ones_are_named() {
    use clap::Parser;
    let cli = wlnav_cli::Cli::try_parse_from([
        "wlnav",
        "obstacles",
        "publish",
        "-",
        "--rate",
        "5",
        "--once",
    ])
    .expect("parses");
    let wlnav_cli::Command::Obstacles(wlnav_cli::ObstaclesCommand::Publish(a)) = cli.command else {
        panic!("not obstacles publish")
    };
    assert_eq!(
        (a.file.as_str(), a.rate, a.once, a.duration),
        ("-", 5.0, true, None)
    );
    for (args, want) in [
        (&["--rate", "0"][..], "the rate must be above 0"),
        (&["--rate", "nan"][..], "the rate must be a finite number"),
        (&["--duration", "0"][..], "the duration must be positive"),
    ] {
        let err = wlnav_cli::Cli::try_parse_from(
            ["wlnav", "obstacles", "publish", "f.jsonl"]
                .iter()
                .chain(args),
        )
        .expect_err("refused")
        .to_string();
        assert!(err.contains(want), "{args:?}: {err}");
    }
}
