//! The event-service wake-ups: notifying, draining a listener, polling listeners'
//! descriptors, and a listener's wait error.

use core::time::Duration;
use std::os::fd::RawFd;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{EventId, FileDescriptorBased};

use super::{boxed, IpcService};
use crate::error::IpcError;

/// Waits until one of the file descriptors is readable or `timeout` passes. Returns which
/// were readable; an interrupting signal counts as a timeout (callers loop anyway).
pub(super) fn poll_fds(
    fds: &[RawFd],
    timeout: Option<Duration>,
) -> Result<Vec<bool>, std::io::Error> {
    let mut pfds: Vec<libc::pollfd> = fds
        .iter()
        .map(|&fd| libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        })
        .collect();
    let timeout_ms: libc::c_int = match timeout {
        None => -1,
        // Round up so a 0.5 ms timeout does not become a busy 0 ms poll.
        Some(t) => t
            .as_micros()
            .div_ceil(1000)
            .try_into()
            .unwrap_or(libc::c_int::MAX),
    };
    // SAFETY: `pfds` is a valid, exclusively borrowed array of `pfds.len()` pollfd structs.
    let rc = unsafe { libc::poll(pfds.as_mut_ptr(), pfds.len() as libc::nfds_t, timeout_ms) };
    if rc < 0 {
        let err = std::io::Error::last_os_error();
        if err.kind() == std::io::ErrorKind::Interrupted {
            return Ok(vec![false; fds.len()]);
        }
        return Err(err);
    }
    Ok(pfds
        .iter()
        .map(|p| p.revents & (libc::POLLIN | libc::POLLERR | libc::POLLHUP) != 0)
        .collect())
}

pub(super) fn listener_fd(listener: &Listener<IpcService>) -> RawFd {
    // SAFETY: the descriptor stays valid as long as the listener, which the caller owns;
    // we only hand out the number.
    unsafe { listener.file_descriptor().native_handle() }
}

pub(super) fn drain(listener: &Listener<IpcService>, service: &str) -> Result<(), IpcError> {
    listener
        .try_wait(|_| {})
        .map(|_| ())
        .map_err(|e| IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        })
}

pub(super) fn notify(
    notifier: &Notifier<IpcService>,
    id: usize,
    service: &str,
) -> Result<(), IpcError> {
    notifier
        .notify_with_custom_event_id(EventId::new(id))
        .map(|_| ())
        .map_err(|e| IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        })
}

/// Maps a listener wait error: a signal is [`IpcError::Interrupted`] (the caller decides),
/// anything else an event error on `service`.
pub(super) fn wait_error(
    e: iceoryx2::port::listener::ListenerWaitError,
    service: &str,
) -> IpcError {
    if e == iceoryx2::port::listener::ListenerWaitError::InterruptSignal {
        IpcError::Interrupted
    } else {
        IpcError::Event {
            service: service.to_owned(),
            source: boxed(e),
        }
    }
}
