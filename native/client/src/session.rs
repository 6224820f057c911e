//! One command through the server: send the request, relay the output.

use crate::{frame, signals, FALLBACK};
use std::ffi::OsString;
use std::io::{IsTerminal, Write};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::UnixStream;
use std::path::Path;

/// Runs the command `args` on the server at `socket`, for the folder `cwd`;
/// returns the exit status.
pub fn run(socket: &Path, cwd: &OsString, args: Vec<OsString>) -> u8 {
    let Ok(mut stream) = UnixStream::connect(socket) else {
        return FALLBACK;
    };
    if let Some(why) = crate::peer::refusal(&stream) {
        eprintln!("ringtracer: {}: {why}", socket.display());
        return FALLBACK;
    }
    if request(&mut stream, cwd, &args).is_err() {
        return FALLBACK;
    }
    if let Ok(mut writer) = stream.try_clone() {
        // Without signals a Ctrl-C still ends the command: the launcher's
        // second one kills this process, and the server sees it go.
        let _ = signals::watch(move |tag| {
            let _ = frame::write(&mut writer, tag, b"");
        });
    }
    relay(&mut stream)
}

fn request(stream: &mut UnixStream, cwd: &OsString, args: &[OsString]) -> std::io::Result<()> {
    frame::write(stream, b'C', cwd.as_bytes())?;
    for arg in args {
        frame::write(stream, b'A', arg.as_bytes())?;
    }
    let tty = if std::io::stderr().is_terminal() {
        b"1"
    } else {
        b"0"
    };
    frame::write(stream, b'T', tty)?;
    if let Some(umask) = umask() {
        frame::write(stream, b'U', format!("{umask:o}").as_bytes())?;
    }
    frame::write(stream, b'G', b"")
}

/// This process's umask, from `/proc/self/status` (the server gives the files it creates for
/// this command the permissions it would give them); `None` where it cannot be read.
fn umask() -> Option<u32> {
    std::fs::read_to_string("/proc/self/status")
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("Umask:"))
        .and_then(|v| u32::from_str_radix(v.trim(), 8).ok())
}

fn relay(stream: &mut UnixStream) -> u8 {
    let (mut out, mut err) = (std::io::stdout().lock(), std::io::stderr());
    let mut wrote = false;
    loop {
        match frame::read(stream) {
            // A closed stdout (`| head`) does not stop the command.
            Ok(Some((b'O', data))) => {
                wrote = true;
                let _ = out.write_all(&data).and_then(|_| out.flush());
            }
            Ok(Some((b'E', data))) => {
                wrote = true;
                let _ = err.write_all(&data);
            }
            Ok(Some((b'X', data))) if data.len() == 1 => {
                let _ = out.flush();
                return data[0];
            }
            Ok(Some((b'F', _))) if !wrote => return FALLBACK,
            Ok(Some((tag, _))) => {
                eprintln!("ringtracer: unexpected frame {tag} from the server");
                return 1;
            }
            Ok(None) | Err(_) => {
                if !wrote {
                    // The server went before it began: a VM of our own can still do it.
                    return FALLBACK;
                }
                eprintln!("ringtracer: the server closed the connection");
                return 1;
            }
        }
    }
}
