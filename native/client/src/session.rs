//! One command through the server: send the request, wait (with a
//! deadline) for the server to take it, then relay the output.
//!
//! Nothing here waits on the server without a deadline until the server has
//! taken the command: connecting, sending the request and the server's first
//! answer each have one, and a server that misses them (stopped, wedged) is
//! left for a VM of our own. The command runs only once the server has
//! answered `R` and this client has confirmed with `Y`, so a server that
//! wakes up late never runs a command that a VM of ours runs too.
//! Interrupts end this client within a second whatever the server does.

use crate::{frame, FALLBACK};
use std::ffi::OsString;
use std::io::{ErrorKind, IsTerminal, Write};
use std::os::fd::OwnedFd;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

/// How long connecting to the socket may take.
const CONNECT_WAIT: Duration = Duration::from_secs(1);
/// How long one write of a frame to the server may block.
const WRITE_WAIT: Duration = Duration::from_secs(1);
/// How long the server has to take the command once it is sent.
pub const ANSWER_WAIT: Duration = Duration::from_secs(2);
/// How long the server has to end the command once it was told to stop.
pub const STOP_WAIT: Duration = Duration::from_millis(800);
/// How long the server may send nothing while it runs the command: it
/// sends `P` every second, so silence this long is a server stopped or
/// wedged mid-command.
#[cfg(not(test))]
pub const SILENCE_WAIT: Duration = Duration::from_secs(30);
#[cfg(test)]
pub const SILENCE_WAIT: Duration = Duration::from_secs(1);
/// Sets the silence allowed, in whole seconds, where a test needs less than `SILENCE_WAIT`.
const SILENCE_WAIT_VAR: &str = "RINGTRACER_SILENCE_WAIT";

/// The silence allowed: `RINGTRACER_SILENCE_WAIT` seconds (a whole number
/// from 1) when set, else `SILENCE_WAIT`; a value that is not one is named
/// on stderr, and the default holds.
fn silence_wait() -> Duration {
    let Some(value) = std::env::var_os(SILENCE_WAIT_VAR) else {
        return SILENCE_WAIT;
    };
    match silence_from(&value.to_string_lossy()) {
        Some(wait) => wait,
        None => {
            eprintln!(
                "ringtracer: {SILENCE_WAIT_VAR}={} is not a whole number of seconds from 1; \
                 waiting {} s",
                value.to_string_lossy(),
                SILENCE_WAIT.as_secs()
            );
            SILENCE_WAIT
        }
    }
}

fn silence_from(value: &str) -> Option<Duration> {
    value
        .parse::<u64>()
        .ok()
        .filter(|s| *s >= 1)
        .map(Duration::from_secs)
}

/// What the client waits for: a frame, the end of the stream, a signal
/// (`b'I'` an interrupt, `b'K'` SIGTERM).
pub enum Event {
    Frame(u8, Vec<u8>),
    Closed,
    Signal(u8),
}

/// Whether a launcher that cannot use the server must fail rather than boot
/// a VM of its own (`RINGTRACER_SERVER=only`).
fn only() -> bool {
    std::env::var_os("RINGTRACER_SERVER").is_some_and(|v| v == "only")
}

/// What to do when the server cannot be used: fall back to a VM of our own,
/// or, with `RINGTRACER_SERVER=only`, fail saying why.
fn cannot_use(socket: &Path, why: &str) -> u8 {
    if only() {
        eprintln!("ringtracer: {}: {why}", socket.display());
        1
    } else {
        eprintln!(
            "ringtracer: {}: {why}; rendering in a VM of its own",
            socket.display()
        );
        FALLBACK
    }
}

/// The exit status and the word for an interrupt frame's tag.
fn interrupt(tag: u8) -> (u8, &'static str) {
    if tag == b'K' {
        (143, "terminated")
    } else {
        (130, "interrupted")
    }
}

/// Runs the command `args` on the server at `socket`, for the folder `cwd`;
/// returns the exit status. Signals arrive on `events` (whose sender the
/// frames from the server use too).
pub fn run(
    socket: &Path,
    cwd: &OsString,
    args: Vec<OsString>,
    events: (Sender<Event>, Receiver<Event>),
) -> u8 {
    let (tx, rx) = events;
    // `tx` stays here, so the channel outlives the reader thread
    let mut stream = match connect(socket) {
        Ok(stream) => stream,
        // a socket left by a server that is gone: nothing to say
        Err(e) if e.kind() == ErrorKind::ConnectionRefused || e.kind() == ErrorKind::NotFound => {
            return FALLBACK
        }
        // one too busy to let us in (its queue is full), or slow to
        Err(e) => return cannot_use(socket, &format!("cannot connect to the server: {e}")),
    };
    let status = over(socket, &mut stream, cwd, &args, tx.clone(), &rx);
    // the reader's clone of the stream ends too
    let _ = stream.shutdown(std::net::Shutdown::Both);
    status
}

/// The command over the connected `stream`.
fn over(
    socket: &Path,
    stream: &mut UnixStream,
    cwd: &OsString,
    args: &[OsString],
    tx: Sender<Event>,
    rx: &Receiver<Event>,
) -> u8 {
    if let Some(why) = crate::peer::refusal(stream) {
        eprintln!("ringtracer: {}: {why}", socket.display());
        return FALLBACK;
    }
    if stream.set_write_timeout(Some(WRITE_WAIT)).is_err() || request(stream, cwd, args).is_err() {
        return cannot_use(socket, "the server did not take the request");
    }
    let Ok(mut reader) = stream.try_clone() else {
        return FALLBACK;
    };
    std::thread::spawn(move || loop {
        match frame::read(&mut reader) {
            Ok(Some((tag, data))) => {
                if tx.send(Event::Frame(tag, data)).is_err() {
                    return;
                }
            }
            Ok(None) | Err(_) => {
                let _ = tx.send(Event::Closed);
                return;
            }
        }
    });
    match next(rx, Instant::now() + ANSWER_WAIT) {
        Some(Event::Frame(b'R', _)) => {}
        Some(Event::Frame(b'F', _)) => return FALLBACK,
        Some(Event::Signal(tag)) => {
            // the server never runs it: it waits for our `Y`
            let (status, what) = interrupt(tag);
            eprintln!("ringtracer: {what}; nothing written");
            return status;
        }
        Some(Event::Frame(tag, _)) => {
            eprintln!("ringtracer: unexpected frame {tag} from the server");
            return 1;
        }
        Some(Event::Closed) => return cannot_use(socket, "the server closed the connection"),
        None => {
            let why = format!(
                "the server did not answer within {} s (stopped or busy?)",
                ANSWER_WAIT.as_secs()
            );
            return cannot_use(socket, &why);
        }
    }
    if frame::write(stream, b'Y', b"").is_err() {
        return cannot_use(socket, "the server did not take the request");
    }
    relay(socket, stream, rx)
}

/// Connects to `socket`, or fails within `CONNECT_WAIT` (a server whose
/// queue of connections is full).
fn connect(socket: &Path) -> std::io::Result<UnixStream> {
    let addr = socket2::SockAddr::unix(socket)?;
    let sock = socket2::Socket::new(socket2::Domain::UNIX, socket2::Type::STREAM, None)?;
    sock.connect_timeout(&addr, CONNECT_WAIT)?;
    sock.set_nonblocking(false)?;
    Ok(UnixStream::from(OwnedFd::from(sock)))
}

/// The next event, or `None` once `deadline` has passed.
fn next(rx: &Receiver<Event>, deadline: Instant) -> Option<Event> {
    let left = deadline.saturating_duration_since(Instant::now());
    // a timeout or a closed channel: nothing more comes in time
    rx.recv_timeout(left).ok()
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
    // `~` in a path is this user's home, not the server's
    if let Some(home) = std::env::var_os("HOME").filter(|h| !h.is_empty()) {
        frame::write(stream, b'H', home.as_bytes())?;
    }
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

fn relay(socket: &Path, stream: &mut UnixStream, rx: &Receiver<Event>) -> u8 {
    let (mut out, mut err) = (std::io::stdout().lock(), std::io::stderr());
    // Set by an interrupt: its tag, and when the server must have ended the command.
    let mut stopping: Option<(u8, Instant)> = None;
    let mut heard = Instant::now();
    let silence = silence_wait();
    loop {
        let deadline = stopping.map_or(heard + silence, |(_, d)| d);
        let Some(event) = next(rx, deadline) else {
            let Some((tag, _)) = stopping else {
                let _ = out.flush();
                eprintln!(
                    "ringtracer: the server has sent nothing for {} s (stopped or wedged?); \
                     giving up on this command (the server cancels it once it sees this client gone)",
                    silence.as_secs()
                );
                return 1;
            };
            // The server did not end the command in time: this client goes,
            // and the server cancels the job of a client that went.
            let (status, what) = interrupt(tag);
            let _ = out.flush();
            eprintln!(
                "ringtracer: {what}; the server did not confirm within {} ms, its job is cancelled as this client goes",
                STOP_WAIT.as_millis()
            );
            return status;
        };
        if matches!(event, Event::Frame(..)) {
            heard = Instant::now();
        }
        match event {
            // the server is alive and the command runs
            Event::Frame(b'P', _) => {}
            // A closed stdout (`| head`) does not stop the command.
            Event::Frame(b'O', data) => {
                let _ = out.write_all(&data).and_then(|_| out.flush());
            }
            Event::Frame(b'E', data) => {
                let _ = err.write_all(&data);
            }
            Event::Frame(b'X', data) if data.len() == 1 => {
                let _ = out.flush();
                return data[0];
            }
            Event::Frame(tag, _) => {
                eprintln!("ringtracer: unexpected frame {tag} from the server");
                return 1;
            }
            Event::Signal(tag) => {
                // a write that blocks (a stopped server) gives up after WRITE_WAIT,
                // which is longer than we wait: the deadline is set first
                if stopping.is_none() {
                    stopping = Some((tag, Instant::now() + STOP_WAIT));
                }
                let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
                let _ = frame::write(stream, tag, b"");
            }
            Event::Closed => {
                let _ = out.flush();
                if let Some((tag, _)) = stopping {
                    let (status, what) = interrupt(tag);
                    eprintln!("ringtracer: {what}; the server closed the connection");
                    return status;
                }
                // The server went (killed, out of memory) before the command
                // ended: its outputs are written only at the end, so a VM of
                // our own can still do it.
                return cannot_use(socket, "the server ended before this command did");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::net::UnixListener;
    use std::sync::mpsc;

    fn socket_path(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("rt-client-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir.join("s.sock")
    }

    /// `render` through the socket at `path`, as the launcher runs it.
    fn render(path: &Path) -> u8 {
        run(
            path,
            &OsString::from("/"),
            vec!["render".into()],
            mpsc::channel(),
        )
    }

    /// A server on `listener` that takes one client's command (`R` to its
    /// `G`) and, once the client says `Y`, hands the connection to `then`.
    fn server<T: Send + 'static>(
        listener: UnixListener,
        then: impl FnOnce(UnixStream) -> T + Send + 'static,
    ) -> std::thread::JoinHandle<T> {
        std::thread::spawn(move || {
            let (mut conn, _) = listener.accept().unwrap();
            while let Ok(Some((tag, _))) = frame::read(&mut conn) {
                if tag == b'G' {
                    frame::write(&mut conn, b'R', b"").unwrap();
                }
                if tag == b'Y' {
                    return then(conn);
                }
            }
            panic!("no Y");
        })
    }

    /// A server that lets the client in and then never answers (a stopped
    /// or wedged `ringtracer serve`): the client gives up on it in time and
    /// asks for a VM of its own.
    #[test]
    fn a_server_that_never_answers_is_left_in_time() {
        let path = socket_path("silent");
        let listener = UnixListener::bind(&path).unwrap();
        let t = Instant::now();
        let status = render(&path);
        let took = t.elapsed();
        assert_eq!(status, FALLBACK);
        assert!(
            took >= ANSWER_WAIT && took < ANSWER_WAIT + Duration::from_secs(2),
            "{took:?}"
        );
        // The request reached the socket, and no `Y`: such a server never runs it.
        let (mut conn, _) = listener.accept().unwrap();
        conn.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut tags = vec![];
        while let Ok(Some((tag, _))) = frame::read(&mut conn) {
            tags.push(tag);
        }
        assert_eq!(tags.first(), Some(&b'C'));
        assert!(tags.contains(&b'G'), "{tags:?}");
        assert!(!tags.contains(&b'Y'), "{tags:?}");
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A server that takes the command, then dies: the client asks for a VM
    /// of its own (nothing was written).
    #[test]
    fn a_server_that_goes_mid_command_leaves_it_to_a_vm_of_our_own() {
        let path = socket_path("dies");
        let listener = UnixListener::bind(&path).unwrap();
        let server = server(listener, |mut conn| {
            frame::write(&mut conn, b'E', b"progress\n").unwrap();
        });
        let status = render(&path);
        server.join().unwrap();
        assert_eq!(status, FALLBACK);
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    #[test]
    fn the_silence_allowed_is_whole_seconds_from_one() {
        assert_eq!(silence_from("5"), Some(Duration::from_secs(5)));
        assert_eq!(silence_from("0"), None);
        assert_eq!(silence_from("-1"), None);
        assert_eq!(silence_from("2.5"), None);
        assert_eq!(silence_from(""), None);
    }

    /// A server that takes the command and then goes silent (stopped
    /// mid-command): the client gives up after `SILENCE_WAIT`, while pings
    /// keep it waiting.
    #[test]
    fn a_server_silent_mid_command_is_left_in_time() {
        let path = socket_path("silent-mid");
        let listener = UnixListener::bind(&path).unwrap();
        let server = server(listener, |mut conn| {
            // pings for twice the silence allowed, then nothing
            for _ in 0..8 {
                std::thread::sleep(SILENCE_WAIT / 4);
                frame::write(&mut conn, b'P', b"").unwrap();
            }
            conn
        });
        let t = Instant::now();
        let status = render(&path);
        let took = t.elapsed();
        let _conn = server.join().unwrap();
        assert_eq!(status, 1);
        assert!(
            took >= SILENCE_WAIT * 3 && took < SILENCE_WAIT * 3 + Duration::from_secs(2),
            "{took:?}"
        );
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    #[test]
    fn the_exit_status_is_the_servers() {
        let path = socket_path("status");
        let listener = UnixListener::bind(&path).unwrap();
        let server = server(listener, |mut conn| {
            frame::write(&mut conn, b'X', &[7]).unwrap();
        });
        assert_eq!(render(&path), 7);
        server.join().unwrap();
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }
}
