//! `SIGTERM` and `SIGINT` close the window as its close button does, so that `view --stats` is written (`on_exit`)
//! and the exit is the ordinary one, instead of the process dying with the frame log unwritten.
//!
//! signal-hook's iterator turns the signal into a byte on a self-pipe, read by a thread of ours, which asks the
//! window to close (a signal handler itself may do almost nothing: no locks, no allocation). A second signal while
//! the window is still closing (a hung frame, an impatient user), or one after it has closed, does what the signal
//! would have done without us: the process ends.

use std::sync::{Arc, Mutex, PoisonError};

/// The signals that close the window.
#[cfg(unix)]
pub const CLOSING_SIGNALS: [i32; 2] = [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT];

/// What the first signal calls, until it is called or the guard dropped.
type CloseAction = Arc<Mutex<Option<Box<dyn FnOnce() + Send>>>>;

/// Calls a function on the first `SIGTERM` or `SIGINT` while it is held (on its own thread).
pub struct CloseOnSignal {
    close: CloseAction,
}

impl CloseOnSignal {
    /// Calls `close` (on a thread of its own) on the first of [`CLOSING_SIGNALS`] while the guard is held; any later
    /// one, or one after the guard is dropped, terminates the process as it would have without this. Fails when the
    /// handlers or the thread cannot be set up.
    #[cfg(unix)]
    pub fn install(close: impl FnOnce() + Send + 'static) -> std::io::Result<CloseOnSignal> {
        let action: CloseAction = Arc::new(Mutex::new(Some(Box::new(close))));
        let mut signals = signal_hook::iterator::Signals::new(CLOSING_SIGNALS)?;
        let pending = action.clone();
        // The thread lives as long as the process: signal-hook cannot give a signal its default action back once it
        // has taken it (unregistering would leave SIGTERM ignored), so this thread applies it from then on.
        std::thread::Builder::new().name("voxstream-signals".into()).spawn(move || {
            for signal in signals.forever() {
                let close = pending.lock().unwrap_or_else(PoisonError::into_inner).take();
                match close {
                    Some(close) => close(),
                    // Already closing and asked again, or the window has closed: the signal's own action.
                    None => {
                        let _ = signal_hook::low_level::emulate_default_handler(signal);
                    }
                }
            }
        })?;
        Ok(CloseOnSignal { close: action })
    }

    /// Signals are left to their default actions where there are no POSIX signals.
    #[cfg(not(unix))]
    pub fn install(close: impl FnOnce() + Send + 'static) -> std::io::Result<CloseOnSignal> {
        Ok(CloseOnSignal { close: Arc::new(Mutex::new(Some(Box::new(close)))) })
    }
}

impl Drop for CloseOnSignal {
    fn drop(&mut self) {
        // From now on a signal terminates (the window it would close is gone).
        self.close.lock().unwrap_or_else(PoisonError::into_inner).take();
    }
}

#[cfg(all(test, unix))]
mod tests {
    use std::sync::mpsc;
    use std::time::Duration;

    use super::*;

    #[test]
    fn a_termination_signal_calls_close_once_and_the_guard_lets_go() {
        let (sender, receiver) = mpsc::channel();
        let guard = CloseOnSignal::install(move || sender.send("closed").unwrap()).unwrap();
        // Raised in this process: without the handler, SIGTERM would end the test binary.
        signal_hook::low_level::raise(signal_hook::consts::SIGTERM).unwrap();
        assert_eq!(receiver.recv_timeout(Duration::from_secs(10)), Ok("closed"));
        // A dropped guard lets go of the action (a second signal would end the test binary: not raised).
        drop(guard);
    }
}
