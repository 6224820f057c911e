//! `ringtracer-client SOCKET COMMAND [ARGS...]`: runs a command of
//! `ringtracer serve` (the resident render node) for `bin/ringtracer`.
//!
//! It sends the caller's folder (`RINGTRACER_CWD`, else its own), the
//! arguments and whether stderr is a terminal; then writes what the command
//! writes and exits with its status. SIGUSR2 (the launcher's first Ctrl-C)
//! and SIGTERM are passed on as interrupts; SIGINT itself is the launcher's
//! to handle. Exit status 200, with nothing written: no server answers, or
//! the server says the command needs a VM of its own (the launcher then
//! boots one), or the server runs as another user (said on stderr; the
//! command then runs in a VM of its own too).

mod frame;
mod peer;
mod session;
mod signals;

use std::process::ExitCode;

/// The status that sends the launcher to a VM of its own.
pub const FALLBACK: u8 = 200;

fn main() -> ExitCode {
    let mut args = std::env::args_os().skip(1);
    let Some(socket) = args.next() else {
        eprintln!("usage: ringtracer-client SOCKET COMMAND [ARGS...]");
        return ExitCode::from(2);
    };
    let cwd = std::env::var_os("RINGTRACER_CWD")
        .or_else(|| std::env::current_dir().ok().map(|d| d.into_os_string()))
        .unwrap_or_default();
    ExitCode::from(session::run(socket.as_ref(), &cwd, args.collect()))
}
