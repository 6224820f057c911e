//! Interrupts: SIGUSR2 and SIGTERM, turned into bytes on a pipe that a
//! thread reads (a signal handler may only do async-signal-safe things).

use std::fs::File;
use std::io::Read;
use std::os::fd::FromRawFd;
use std::sync::atomic::{AtomicI32, Ordering};

/// The pipe's write end, for the handler.
static WRITE_FD: AtomicI32 = AtomicI32::new(-1);

extern "C" fn handler(signal: libc::c_int) {
    let byte = if signal == libc::SIGTERM { b'K' } else { b'I' };
    let fd = WRITE_FD.load(Ordering::Relaxed);
    if fd >= 0 {
        // SAFETY: write(2) is async-signal-safe; `byte` outlives the call and
        // the length is 1. The write end is non-blocking, so a full pipe
        // (bytes the reader has not taken yet) drops this byte with EAGAIN
        // instead of blocking inside the handler, which is harmless: a byte
        // waiting already wakes the reader. errno is the thread's own,
        // saved before and restored after, so that the code the signal
        // interrupted never sees write(2)'s.
        unsafe {
            let errno = libc::__errno_location();
            let saved = *errno;
            libc::write(fd, (&byte as *const u8).cast(), 1);
            *errno = saved;
        }
    }
}

/// Installs the handlers and calls `on_signal` with `b'I'` (SIGUSR2, an
/// interrupt) or `b'K'` (SIGTERM) from a thread of its own, each time one
/// arrives. SIGINT is ignored: the launcher turns it into SIGUSR2.
pub fn watch(mut on_signal: impl FnMut(u8) + Send + 'static) -> std::io::Result<()> {
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: `fds` is a valid array of two ints for pipe2(2) to fill.
    if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // the handler's end never blocks (the reader's does, to wait for bytes)
    // SAFETY: fds[1] was just made by pipe2(2); F_SETFL takes an int flag set.
    if unsafe { libc::fcntl(fds[1], libc::F_SETFL, libc::O_NONBLOCK) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    WRITE_FD.store(fds[1], Ordering::Relaxed);
    // SAFETY: fds[0] was just made by pipe(2) and nothing else owns it.
    let mut read_end = unsafe { File::from_raw_fd(fds[0]) };
    for signal in [libc::SIGUSR2, libc::SIGTERM] {
        // SAFETY: `handler` only calls write(2) (async-signal-safe) and reads
        // an atomic; the sigaction struct is zeroed, then filled.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = handler as *const () as libc::sighandler_t;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            if libc::sigaction(signal, &action, std::ptr::null_mut()) != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
    }
    // SAFETY: ignoring a signal has no handler to be sound about.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_IGN);
    }
    std::thread::spawn(move || {
        let mut byte = [0u8; 1];
        while let Ok(1) = read_end.read(&mut byte) {
            on_signal(byte[0]);
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Duration;

    #[test]
    fn signals_reach_the_callback() {
        let (tx, rx) = mpsc::channel();
        watch(move |b| tx.send(b).unwrap()).unwrap();
        // SAFETY: raise(3) sends a signal to this process, whose handler was
        // installed above.
        unsafe {
            libc::raise(libc::SIGUSR2);
        }
        assert_eq!(rx.recv_timeout(Duration::from_secs(5)).unwrap(), b'I');
        // SAFETY: as above; SIGTERM's handler is ours, so the test goes on.
        unsafe {
            libc::raise(libc::SIGTERM);
        }
        assert_eq!(rx.recv_timeout(Duration::from_secs(5)).unwrap(), b'K');
        // the write end never blocks, and the read end still does
        let fd = WRITE_FD.load(Ordering::Relaxed);
        // SAFETY: F_GETFL on a descriptor this process owns reads its flags.
        let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
        assert!(
            flags >= 0 && flags & libc::O_NONBLOCK != 0,
            "flags {flags:#x}"
        );
    }
}
