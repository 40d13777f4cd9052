//! mosquitto (Debian's) on a free localhost port, with a generated configuration: the
//! broker of the fleet tests.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::timing_scale;

/// How long mosquitto may take to listen, natively (times `WLNAV_TIMING_SCALE`).
pub const LISTEN_LIMIT: Duration = Duration::from_secs(10);

/// A free TCP port on localhost.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind a free port")
        .local_addr()
        .expect("its address")
        .port()
}

fn mosquitto_binary() -> PathBuf {
    for p in ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"] {
        if Path::new(p).exists() {
            return p.into();
        }
    }
    panic!("mosquitto not installed (apt-get install mosquitto; scripts/apt-packages.txt)");
}

/// A running broker (stopped when dropped).
pub struct Broker {
    /// Its port on 127.0.0.1.
    pub port: u16,
    child: Option<Child>,
    dir: PathBuf,
}

impl Broker {
    /// Starts mosquitto on a free port and waits until it listens.
    pub fn start() -> Self {
        let port = free_port();
        let dir =
            std::env::temp_dir().join(format!("wlnav-test-broker-{}-{port}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("broker directory");
        let mut b = Self {
            port,
            child: None,
            dir,
        };
        b.spawn();
        b
    }

    fn log(&self) -> PathBuf {
        self.dir.join("mosquitto.log")
    }

    fn spawn(&mut self) {
        let conf = self.dir.join("mosquitto.conf");
        std::fs::write(
            &conf,
            format!(
                "listener {} 127.0.0.1\nallow_anonymous true\npersistence false\nlog_dest stderr\nlog_type error\nlog_type warning\n",
                self.port
            ),
        )
        .expect("write mosquitto.conf");
        let log = std::fs::File::create(self.log()).expect("mosquitto.log");
        let mut child = Command::new(mosquitto_binary())
            .arg("-c")
            .arg(&conf)
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("log"))
            .stderr(log)
            .spawn()
            .expect("start mosquitto");
        let limit = timing_scale::real(LISTEN_LIMIT);
        let deadline = Instant::now() + limit;
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            if let Ok(Some(status)) = child.try_wait() {
                panic!(
                    "mosquitto exited ({status}) before it listened on {}; its log:\n{}",
                    self.port,
                    crate::tail(&self.log(), 20)
                );
            }
            if Instant::now() >= deadline {
                let what = crate::daemon::describe(child.id());
                crate::terminate(&mut child, Duration::from_secs(2));
                panic!(
                    "mosquitto did not listen on {} within {limit:?}; {what}; its log:\n{}",
                    self.port,
                    crate::tail(&self.log(), 20)
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        self.child = Some(child);
    }

    /// `127.0.0.1:port`.
    pub fn addr(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Stops the broker (SIGTERM) and starts it again on the same port after `down_for`.
    pub fn restart(&mut self, down_for: Duration) {
        self.stop();
        std::thread::sleep(down_for);
        self.spawn();
    }

    /// Stops the broker (SIGTERM, SIGKILL after 5 s, scaled).
    pub fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            crate::terminate(&mut c, Duration::from_secs(5));
        }
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        self.stop();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
