//! Who is at the other end of the server's socket: the client hands its
//! commands (its folder, its arguments, its outputs' paths) only to a server
//! of the same user. A socket at the expected path can belong to someone
//! else, e.g. after `su` without `-` kept another user's `XDG_RUNTIME_DIR`.

use std::os::fd::AsRawFd;
use std::os::unix::net::UnixStream;

/// The user id of the process that made the other end of `stream`, as the
/// kernel recorded it (`SO_PEERCRED`), which that process cannot forge.
pub fn uid(stream: &UnixStream) -> std::io::Result<u32> {
    let mut cred = libc::ucred {
        pid: 0,
        uid: 0,
        gid: 0,
    };
    let mut len = std::mem::size_of::<libc::ucred>() as libc::socklen_t;
    // SAFETY: the descriptor is the stream's own and open for the call;
    // `cred` is a `ucred`, the type SO_PEERCRED writes, and `len` holds its
    // size, so the kernel writes at most that many bytes into it.
    let rc = unsafe {
        libc::getsockopt(
            stream.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_PEERCRED,
            (&mut cred as *mut libc::ucred).cast(),
            &mut len,
        )
    };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    if len as usize != std::mem::size_of::<libc::ucred>() {
        return Err(std::io::Error::other("SO_PEERCRED returned a short answer"));
    }
    Ok(cred.uid)
}

/// This process's effective user id.
pub fn own_uid() -> u32 {
    // SAFETY: geteuid takes no arguments and cannot fail.
    unsafe { libc::geteuid() }
}

/// Why the server at the other end of `stream` is not to be used, if it is
/// not: `None` when it runs as this user.
pub fn refusal(stream: &UnixStream) -> Option<String> {
    match uid(stream) {
        Ok(uid) if uid == own_uid() => None,
        Ok(uid) => Some(format!(
            "the server on this socket runs as user {uid}, not as you ({}); not using it",
            own_uid()
        )),
        Err(e) => Some(format!(
            "cannot tell who runs the server on this socket: {e}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_socket_of_this_process_is_its_own_users() {
        let (a, b) = UnixStream::pair().unwrap();
        assert_eq!(uid(&a).unwrap(), own_uid());
        assert_eq!(uid(&b).unwrap(), own_uid());
        assert_eq!(refusal(&a), None);
    }

    /// A server of another user: a child process that drops to `nobody` and
    /// then listens. Needs root to change user (CI runs as root) and
    /// python3; without them it checks nothing and says so.
    #[test]
    fn a_server_of_another_user_is_refused() {
        if own_uid() != 0 {
            eprintln!("skipped: changing user needs root");
            return;
        }
        let dir = std::env::temp_dir().join(format!("rt-peer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.sock");
        let _ = std::fs::remove_file(&path);
        // 65534: nobody
        let script = format!(
            "import os, socket\n\
             os.setgid(65534); os.setuid(65534)\n\
             s = socket.socket(socket.AF_UNIX)\n\
             os.umask(0)\n\
             s.bind({path:?}); s.listen(1)\n\
             c, _ = s.accept(); c.recv(1)\n",
            path = path.to_str().unwrap()
        );
        std::fs::set_permissions(&dir, std::os::unix::fs::PermissionsExt::from_mode(0o777))
            .unwrap();
        let Ok(mut child) = std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .spawn()
        else {
            eprintln!("skipped: no python3 to run the other user's server");
            let _ = std::fs::remove_dir_all(&dir);
            return;
        };
        let t = std::time::Instant::now();
        let stream = loop {
            if let Ok(s) = UnixStream::connect(&path) {
                break s;
            }
            assert!(
                t.elapsed().as_secs() < 20,
                "the other user's server never listened"
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        assert_eq!(uid(&stream).unwrap(), 65534);
        let why = refusal(&stream).unwrap();
        assert!(why.contains("runs as user 65534, not as you (0)"), "{why}");
        drop(stream);
        let _ = child.wait();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
