//! `ringtracer-client SOCKET COMMAND [ARGS...]`: runs a command of
//! `ringtracer serve` (the resident render node) for `bin/ringtracer`.
//!
//! It sends the caller's folder (`RINGTRACER_CWD`, else its own), the
//! arguments and whether stderr is a terminal; then writes what the command
//! writes and exits with its status. SIGUSR2 (the launcher's first Ctrl-C)
//! and SIGTERM are passed on as interrupts, and end this client within a
//! second even if the server does not answer; SIGINT itself is the
//! launcher's to handle. Exit status 200, with nothing written to stdout: no
//! server answers in time (connecting, or taking the command, within
//! `session::ANSWER_WAIT`), or the server says the command needs a VM of its
//! own, or the server ended before the command did, or the server runs as
//! another user (said on stderr); the launcher then boots a VM of its own.
//! With `RINGTRACER_SERVER=only` a server that does not answer or ends is a
//! failure (status 1) instead.

mod frame;
mod peer;
mod session;
mod signals;

use std::process::ExitCode;
use std::sync::mpsc;

/// The status that sends the launcher to a VM of its own.
pub const FALLBACK: u8 = 200;

fn main() -> ExitCode {
    let mut args = std::env::args_os().skip(1);
    let Some(socket) = args.next() else {
        eprintln!("usage: ringtracer-client SOCKET COMMAND [ARGS...]");
        return ExitCode::from(2);
    };
    // Interrupts are ours from the start: one that comes while the server is
    // slow to answer ends this client at once instead of being held.
    let (tx, rx) = mpsc::channel();
    let signal_tx = tx.clone();
    if let Err(e) = signals::watch(move |tag| {
        let _ = signal_tx.send(session::Event::Signal(tag));
    }) {
        eprintln!("ringtracer: cannot watch for signals: {e}");
        return ExitCode::from(FALLBACK);
    }
    let cwd = std::env::var_os("RINGTRACER_CWD")
        .or_else(|| std::env::current_dir().ok().map(|d| d.into_os_string()))
        .unwrap_or_default();
    ExitCode::from(session::run(
        socket.as_ref(),
        &cwd,
        args.collect(),
        (tx, rx),
    ))
}
