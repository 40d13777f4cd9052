//! systemd's notification protocol (`sd_notify`): READY=1 once start-up is
//! complete, WATCHDOG=1 from a healthy control loop, STATUS= with the mode,
//! STOPPING=1 on shutdown. Without `NOTIFY_SOCKET` (not started by systemd) every
//! call is a no-op.

use sd_notify::NotifyState;

/// Sends notifications; failures are logged once and otherwise ignored (the
/// daemon's job is the machine, not the service manager).
#[derive(Debug, Default)]
pub struct Notifier {
    errors: u64,
}

impl Notifier {
    /// A notifier.
    pub fn new() -> Self {
        Self::default()
    }

    /// The watchdog interval systemd expects (`WatchdogSec=`), if enabled for us.
    pub fn watchdog_interval() -> Option<std::time::Duration> {
        sd_notify::watchdog_enabled()
    }

    fn send(&mut self, states: &[NotifyState]) {
        if let Err(e) = sd_notify::notify(states) {
            self.errors += 1;
            if self.errors == 1 {
                tracing::warn!("sd_notify failed: {e}");
            }
        }
    }

    /// READY=1 with a status text.
    pub fn ready(&mut self, status: &str) {
        self.send(&[NotifyState::Ready, NotifyState::Status(status)]);
    }

    /// WATCHDOG=1.
    pub fn watchdog(&mut self) {
        self.send(&[NotifyState::Watchdog]);
    }

    /// STATUS=….
    pub fn status(&mut self, status: &str) {
        self.send(&[NotifyState::Status(status)]);
    }

    /// STOPPING=1 with a status text.
    pub fn stopping(&mut self, status: &str) {
        self.send(&[NotifyState::Stopping, NotifyState::Status(status)]);
    }
}
