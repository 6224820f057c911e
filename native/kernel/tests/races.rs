//! A second local user races root on every file operation another user could aim at:
//! writing outputs (and putting them back, and sweeping what a killed write kept), making and
//! reading a cookie, making a private folder (the server's socket folder), loading a scene and
//! its referenced files, checking a TLS folder. The attacker is a forked process that drops to
//! uid/gid 65534 and swaps a folder or file of hers with a symbolic link or a FIFO
//! (`renameat2(RENAME_EXCHANGE)`), or plants files open to all, as fast as it can, thousands
//! of times over the test; a reader of hers tries to read everything it sees. Nothing may
//! escape: no root-only secret in a result, nothing outside created, written, chmodded or
//! removed, a cookie only ever whole at 0600, no output taking the mode of her file.
//!
//! Needs root (to be two users); without it each test says so and passes without racing.

use ring_tracer_kernel::files::{self, Confinement};
use ring_tracer_kernel::safe_fs::{self, Dir, Replace};
use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The attacker's uid and gid.
const THEM: u32 = 65534;

/// How many times root does each operation under attack.
const ROUNDS: usize = 3000;

fn root() -> bool {
    if rustix::process::geteuid().is_root() {
        true
    } else {
        eprintln!("races: skipped, not root (a second user is made by dropping root's rights)");
        false
    }
}

fn cstr(p: &Path) -> CString {
    CString::new(p.as_os_str().as_bytes()).unwrap()
}

/// One thing the attacker does in her loop.
enum Step {
    /// Swap two names.
    Exchange(CString, CString),
    /// Make a symbolic link `link` to `target` (if the name is free).
    Symlink(CString, CString),
    /// Make a file open to everyone (mode 0666) at the name (if it is free).
    Plant(CString),
}

/// The attacker: a child process as uid/gid 65534 doing its steps in a loop, until dropped.
struct Attacker {
    pid: libc::pid_t,
}

impl Attacker {
    fn start(steps: Vec<Step>) -> Attacker {
        let mut fds = [0; 2];
        // SAFETY: a valid array of two ints.
        assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
        let (r, w) = (fds[0], fds[1]);
        // SAFETY: after fork the child makes only raw system calls on memory prepared
        // before it (no allocation, no lock), then `_exit`s.
        let pid = unsafe { libc::fork() };
        assert!(pid >= 0, "fork failed");
        if pid == 0 {
            unsafe {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                if libc::setgroups(0, std::ptr::null()) != 0
                    || libc::setgid(THEM) != 0
                    || libc::setuid(THEM) != 0
                    || libc::getuid() != THEM
                {
                    libc::_exit(3);
                }
                let mut told = false;
                loop {
                    for s in &steps {
                        match s {
                            Step::Exchange(a, b) => {
                                libc::syscall(
                                    libc::SYS_renameat2,
                                    libc::AT_FDCWD,
                                    a.as_ptr(),
                                    libc::AT_FDCWD,
                                    b.as_ptr(),
                                    libc::RENAME_EXCHANGE,
                                );
                            }
                            Step::Symlink(target, link) => {
                                libc::symlink(target.as_ptr(), link.as_ptr());
                            }
                            Step::Plant(path) => {
                                let fd = libc::open(
                                    path.as_ptr(),
                                    libc::O_WRONLY | libc::O_CREAT | libc::O_EXCL,
                                    0o666,
                                );
                                if fd >= 0 {
                                    libc::fchmod(fd, 0o666);
                                    libc::close(fd);
                                }
                            }
                        }
                    }
                    if !told {
                        // started, as the other user
                        libc::write(w, b"x".as_ptr().cast(), 1);
                        libc::close(w);
                        told = true;
                    }
                }
            }
        }
        unsafe { libc::close(w) };
        let mut b = [0u8; 1];
        // SAFETY: reads one byte into a valid buffer.
        let n = unsafe { libc::read(r, b.as_mut_ptr().cast(), 1) };
        unsafe { libc::close(r) };
        assert_eq!(n, 1, "the attacker could not become uid {THEM}");
        Attacker { pid }
    }
}

impl Drop for Attacker {
    fn drop(&mut self) {
        // SAFETY: our own child.
        unsafe {
            libc::kill(self.pid, libc::SIGKILL);
            libc::waitpid(self.pid, std::ptr::null_mut(), 0);
        }
    }
}

/// The attacker's reader: reads every file it can see in `dir` (hidden ones too) in a loop and
/// prints `LEAK` when one holds `secret`.
struct Reader {
    child: std::process::Child,
}

impl Reader {
    fn start(dir: &Path, secret: &str) -> Reader {
        use std::os::unix::process::CommandExt;
        let child = std::process::Command::new("/bin/sh")
            .arg("-c")
            .arg(
                "while :; do for f in \"$0\"/* \"$0\"/.[!.]*; do \
                 grep -qs \"$1\" \"$f\" && echo LEAK \"$f\"; done; done",
            )
            .arg(dir)
            .arg(secret)
            .uid(THEM)
            .gid(THEM)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        Reader { child }
    }

    /// What it printed (nothing, or the leaks).
    fn finish(mut self) -> String {
        let _ = self.child.kill();
        let out = self.child.wait_with_output().unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    }
}

/// A test's folder that the attacker can enter (its temporary folder is root's, mode 0700).
fn base() -> tempfile::TempDir {
    let t = tempfile::tempdir().unwrap();
    std::fs::set_permissions(t.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    t
}

/// A folder of the attacker's (owned by her, mode `mode`).
fn theirs(path: &Path, mode: u32) -> PathBuf {
    std::fs::create_dir(path).unwrap();
    std::os::unix::fs::chown(path, Some(THEM), Some(THEM)).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    path.to_path_buf()
}

/// A symbolic link of the attacker's.
fn their_link(target: &Path, link: &Path) {
    std::os::unix::fs::symlink(target, link).unwrap();
    std::os::unix::fs::lchown(link, Some(THEM), Some(THEM)).unwrap();
}

/// Names, modes and contents under `dir` (one level), to compare before and after.
fn snapshot(dir: &Path) -> Vec<(String, u32, Vec<u8>)> {
    let mut v = vec![(
        ".".to_string(),
        std::fs::metadata(dir).unwrap().mode(),
        Vec::new(),
    )];
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let m = std::fs::symlink_metadata(e.path()).unwrap();
        let data = if m.is_file() {
            std::fs::read(e.path()).unwrap()
        } else {
            Vec::new()
        };
        v.push((e.file_name().to_string_lossy().into_owned(), m.mode(), data));
    }
    v.sort();
    v
}

/// A root-only folder holding a root-only file `name` with `secret`, its mode 0755 so that a
/// chmod to 0700 would show.
fn victim(base: &Path, name: &str, secret: &str) -> PathBuf {
    let v = base.join("victim");
    std::fs::create_dir(&v).unwrap();
    std::fs::set_permissions(&v, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::write(v.join(name), secret).unwrap();
    std::fs::set_permissions(v.join(name), std::fs::Permissions::from_mode(0o600)).unwrap();
    v
}

#[test]
fn outputs_are_written_only_where_named_and_put_back_exactly() {
    if !root() {
        return;
    }
    let t = base();
    let victim = victim(t.path(), "a.json", "victim's own");
    let before = snapshot(&victim);
    // her folder holds `out` (a real folder) and `decoy` (her link to the victim), swapped
    let mine = theirs(&t.path().join("mine"), 0o755);
    let out = theirs(&mine.join("out"), 0o777);
    their_link(&victim, &mine.join("decoy"));
    let attacker = Attacker::start(vec![Step::Exchange(
        cstr(&mine.join("out")),
        cstr(&mine.join("decoy")),
    )]);
    let reader = Reader::start(&mine.join("out"), "ROOT-ONLY");
    let (mut written, mut refused) = (0, 0);
    for i in 0..ROUNDS {
        let path = out.join("a.json");
        let data = format!("ROOT-ONLY {i}");
        match safe_fs::write_path(&path, data.as_bytes(), Some(0o600), Replace::Yes) {
            Ok(()) => written += 1,
            Err(e) => {
                let e = e.to_string();
                assert!(
                    e.contains("symbolic link") || e.contains("No such file"),
                    "{e}"
                );
                refused += 1;
            }
        }
        // keep and put back, as a failed render does
        if let Ok(dir) = Dir::open(&out) {
            if let Ok(kept) = dir.keep("a.json") {
                dir.put_back("a.json", &kept).unwrap();
            }
        }
    }
    drop(attacker);
    let leaks = reader.finish();
    eprintln!("outputs: {written} written, {refused} refused under attack");
    assert_eq!(written + refused, ROUNDS);
    assert_eq!(snapshot(&victim), before, "something outside was changed");
    assert_eq!(leaks, "", "the other user read a root-only output");
    // whichever way the folders ended, no hidden file is left in either
    for d in [mine.join("out"), mine.join("decoy")] {
        if let Ok(rd) = std::fs::read_dir(&d) {
            for e in rd {
                let n = e.unwrap().file_name().to_string_lossy().into_owned();
                assert!(!n.starts_with('.'), "left behind: {n}");
            }
        }
    }
}

#[test]
fn a_cookie_is_only_ever_seen_whole_at_0600() {
    if !root() {
        return;
    }
    let t = base();
    let victim = victim(t.path(), "keep", "x");
    let before = snapshot(&victim);
    // a shared folder she can write in (root's, sticky, like /tmp), and a folder of hers
    // swapped with a link to the victim
    let shared = t.path().join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
    let mine = theirs(&t.path().join("mine"), 0o755);
    theirs(&mine.join("out"), 0o777);
    their_link(&victim, &mine.join("decoy"));
    // she plants links at the names root will use, too
    let mut steps = vec![Step::Exchange(
        cstr(&mine.join("out")),
        cstr(&mine.join("decoy")),
    )];
    for i in 0..64 {
        steps.push(Step::Symlink(
            cstr(&victim.join("keep")),
            cstr(&shared.join(format!("cookie{i}"))),
        ));
    }
    let attacker = Attacker::start(steps);
    let reader = Reader::start(&shared, "SECRET");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    // root's watcher: every cookie seen is whole and 0600
    let watcher = {
        let stop = stop.clone();
        let shared = shared.clone();
        std::thread::spawn(move || {
            let mut seen = 0;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                for e in std::fs::read_dir(&shared).unwrap() {
                    let e = e.unwrap();
                    let Ok(m) = std::fs::symlink_metadata(e.path()) else {
                        continue;
                    };
                    if !m.is_file() {
                        continue;
                    }
                    assert_eq!(m.mode() & 0o7777, 0o600, "{:?}", e.path());
                    assert_eq!(m.uid(), 0);
                    if let Ok(data) = std::fs::read(e.path()) {
                        let name = e.file_name().to_string_lossy().into_owned();
                        if !name.starts_with('.') {
                            assert_eq!(data, format!("SECRET {name}\n").as_bytes());
                            seen += 1;
                        }
                    }
                }
            }
            seen
        })
    };
    let (mut made, mut refused) = (0, 0);
    for i in 0..ROUNDS {
        let name = format!("cookie{}", i % 128);
        let data = format!("SECRET {name}\n");
        for path in [shared.join(&name), mine.join("out").join(&name)] {
            match safe_fs::write_path(&path, data.as_bytes(), Some(0o600), Replace::No) {
                Ok(()) => made += 1,
                Err(_) => refused += 1,
            }
        }
        // free the name for the next round (hers too: she may have planted a link)
        let _ = std::fs::remove_file(shared.join(&name));
        if let Ok(d) = Dir::open(&mine.join("out")) {
            let _ = d.put_back(&name, &safe_fs::Kept::Nothing);
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let seen = watcher
        .join()
        .expect("a cookie was seen partial or not 0600");
    drop(attacker);
    let leaks = reader.finish();
    eprintln!("cookies: {made} made, {refused} refused, {seen} seen whole by the watcher");
    assert!(made > 0);
    assert_eq!(snapshot(&victim), before, "something outside was changed");
    assert_eq!(leaks, "", "the other user read a cookie");
}

#[test]
fn a_private_folder_is_ours_closed_and_bound_in_place() {
    if !root() {
        return;
    }
    let t = base();
    let victim = victim(t.path(), "keep", "x");
    let before = snapshot(&victim);
    let victim_ino = std::fs::metadata(&victim).unwrap().ino();
    // $XDG_RUNTIME_DIR (or ~/.cache) of hers: she swaps root's new folder with her link
    let parent = theirs(&t.path().join("runtime"), 0o777);
    let run = parent.join("run");
    their_link(&victim, &parent.join("decoy"));
    let attacker = Attacker::start(vec![
        Step::Exchange(cstr(&run), cstr(&parent.join("decoy"))),
        Step::Symlink(cstr(&victim), cstr(&run)),
    ]);
    let (mut ok, mut refused) = (0, 0);
    for _ in 0..ROUNDS {
        match safe_fs::private_dir(&run, true) {
            Ok(dir) => {
                let st = rustix::fs::fstat(dir.fd()).unwrap();
                assert_eq!(st.st_uid, 0);
                assert_eq!(st.st_mode & 0o7777, 0o700);
                assert_ne!(st.st_ino, victim_ino);
                // the socket is bound in the folder held, not wherever the name leads now
                let sock = dir.proc_path().join("s.sock");
                let listener = std::os::unix::net::UnixListener::bind(&sock).unwrap();
                assert!(rustix::fs::statat(
                    dir.fd(),
                    "s.sock",
                    rustix::fs::AtFlags::SYMLINK_NOFOLLOW
                )
                .is_ok());
                drop(listener);
                rustix::fs::unlinkat(dir.fd(), "s.sock", rustix::fs::AtFlags::empty()).unwrap();
                ok += 1;
            }
            Err(e) => {
                let e = e.to_string();
                assert!(
                    e.contains("is not a folder")
                        || e.contains("belongs to user")
                        || e.contains("No such file"),
                    "{e}"
                );
                refused += 1;
            }
        }
        // start again: nothing at the name, her link beside it, root's folder gone
        // wherever it went
        for n in ["run", "decoy"] {
            let p = parent.join(n);
            let _ = std::fs::remove_dir(&p).or_else(|_| std::fs::remove_file(&p));
        }
        let _ = std::os::unix::fs::symlink(&victim, parent.join("decoy"))
            .and_then(|_| std::os::unix::fs::lchown(parent.join("decoy"), Some(THEM), Some(THEM)));
    }
    drop(attacker);
    eprintln!("private folders: {ok} made and checked, {refused} refused under attack");
    assert_eq!(ok + refused, ROUNDS);
    assert_eq!(snapshot(&victim), before, "something outside was changed");
}

#[test]
fn a_scene_never_reads_outside_its_folder() {
    if !root() {
        return;
    }
    let t = base();
    let secret_dir = t.path().join("root_only");
    std::fs::create_dir(&secret_dir).unwrap();
    std::fs::set_permissions(&secret_dir, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::fs::write(secret_dir.join("mesh.obj"), "# ROOT-ONLY\nv 9 9 9\n").unwrap();
    // her scene folder: `m/mesh.obj` public, `decoy` her link to the root-only folder (one
    // absolute, one relative), swapped with `m`
    let scene = theirs(&t.path().join("scene"), 0o755);
    let m = theirs(&scene.join("m"), 0o755);
    std::fs::write(m.join("mesh.obj"), "v 0 0 0\n").unwrap();
    their_link(&secret_dir, &scene.join("decoy"));
    their_link(Path::new("../root_only"), &scene.join("decoy2"));
    let attacker = Attacker::start(vec![
        Step::Exchange(cstr(&scene.join("m")), cstr(&scene.join("decoy"))),
        Step::Exchange(cstr(&scene.join("m")), cstr(&scene.join("decoy2"))),
    ]);
    let confinement = Confinement::new([&scene]).unwrap();
    let (mut read, mut refused) = (0, 0);
    let t0 = Instant::now();
    for _ in 0..ROUNDS {
        match confinement.read("m/mesh.obj") {
            Ok((bytes, path)) => {
                assert_eq!(bytes, b"v 0 0 0\n", "read {path:?}");
                assert!(path.starts_with(confinement.roots()[0].as_path()));
                read += 1;
            }
            Err(e) => {
                assert!(!e.to_string().contains("ROOT-ONLY"));
                refused += 1;
            }
        }
    }
    drop(attacker);
    eprintln!(
        "scene files: {read} read, {refused} refused under attack in {:?}",
        t0.elapsed()
    );
    assert_eq!(read + refused, ROUNDS);
    assert!(t0.elapsed() < Duration::from_secs(120));
}

#[test]
fn a_cookie_is_read_only_from_this_users_own_closed_file() {
    if !root() {
        return;
    }
    let t = base();
    let victim = victim(t.path(), "secret", "ROOT-ONLY\n");
    // root's cookie in a folder of hers, which she swaps with her link to a root-only file
    // (regular, root's, 0600: what a check by name that follows links would accept) and
    // with her FIFO (which would hang a blocking open), as fast as she can
    let mine = theirs(&t.path().join("mine"), 0o755);
    let cookie = mine.join("cookie");
    std::fs::write(&cookie, "GOOD\n").unwrap();
    std::fs::set_permissions(&cookie, std::fs::Permissions::from_mode(0o600)).unwrap();
    their_link(&victim.join("secret"), &mine.join("link"));
    let fifo = mine.join("fifo");
    rustix::fs::mknodat(
        rustix::fs::CWD,
        &fifo,
        rustix::fs::FileType::Fifo,
        rustix::fs::Mode::from_raw_mode(0o666),
        0,
    )
    .unwrap();
    std::os::unix::fs::lchown(&fifo, Some(THEM), Some(THEM)).unwrap();
    let attacker = Attacker::start(vec![
        Step::Exchange(cstr(&cookie), cstr(&mine.join("link"))),
        Step::Exchange(cstr(&cookie), cstr(&fifo)),
    ]);
    // the reads run on a thread of their own so that a hung read fails the test
    let (tx, rx) = std::sync::mpsc::channel();
    let path = cookie.clone();
    std::thread::spawn(move || {
        let (mut read, mut refused) = (0, 0);
        // at least ROUNDS reads, and on until both a read and a refusal were seen (her swaps
        // can stay ahead for a while), for at most a minute
        let t0 = Instant::now();
        while read + refused < ROUNDS
            || ((read == 0 || refused == 0) && t0.elapsed() < Duration::from_secs(60))
        {
            match safe_fs::read_private(&path, 4096) {
                Ok(bytes) => {
                    assert_eq!(bytes, b"GOOD\n", "read something other than the cookie");
                    read += 1;
                }
                Err(e) => {
                    let e = e.to_string();
                    assert!(!e.contains("ROOT-ONLY"), "{e}");
                    assert!(
                        e.contains("is a symbolic link")
                            || e.contains("is a FIFO")
                            || e.contains("belongs to user")
                            || e.contains("No such file"),
                        "{e}"
                    );
                    refused += 1;
                }
            }
        }
        let _ = tx.send((read, refused));
    });
    let (read, refused) = rx
        .recv_timeout(Duration::from_secs(180))
        .expect("a cookie read hung, or found something else than the cookie");
    drop(attacker);
    eprintln!("cookie reads: {read} read, {refused} refused under attack");
    assert!(read + refused >= ROUNDS);
    assert!(read > 0 && refused > 0, "the swaps did not race the reads");
}

/// Her scene tree for the scene-folder races: `top/scene/s/{scene.toml, mesh.obj}` (hers,
/// public), `top/scene/decoy` her link to a root-only folder holding a `mesh.obj` (and no
/// scene), `top/decoyp` her link to a root-only folder holding `s/mesh.obj`. Returns the
/// scene file's path and her swaps: the scene's folder with `decoy`, its parent with
/// `decoyp`.
fn scene_tree(t: &Path) -> (PathBuf, Vec<Step>) {
    let secret = "# ROOT-ONLY\nv 9 9 9\nv 9 9 8\nv 9 8 9\nf 1 2 3\n";
    let root_only = t.join("root_only");
    std::fs::create_dir(&root_only).unwrap();
    std::fs::set_permissions(&root_only, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::fs::write(root_only.join("mesh.obj"), secret).unwrap();
    let root_parent = t.join("root_parent");
    std::fs::create_dir_all(root_parent.join("s")).unwrap();
    std::fs::set_permissions(&root_parent, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::fs::write(root_parent.join("s/mesh.obj"), secret).unwrap();
    let top = theirs(&t.join("top"), 0o755);
    let scene = theirs(&top.join("scene"), 0o755);
    let s = theirs(&scene.join("s"), 0o755);
    std::fs::write(
        s.join("scene.toml"),
        "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n\n\
         [[lights]]\nposition = [0, 5, 5]\n\n\
         [[objects]]\ntype = \"mesh\"\nfile = \"mesh.obj\"\n",
    )
    .unwrap();
    std::fs::write(s.join("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    their_link(&root_only, &scene.join("decoy"));
    their_link(&root_parent, &top.join("decoyp"));
    let steps = vec![
        Step::Exchange(cstr(&scene.join("s")), cstr(&scene.join("decoy"))),
        Step::Exchange(cstr(&scene), cstr(&top.join("decoyp"))),
    ];
    (s.join("scene.toml"), steps)
}

#[test]
fn a_scene_reads_its_meshes_in_the_folder_it_was_read_in() {
    if !root() {
        return;
    }
    let t = base();
    let (path, steps) = scene_tree(t.path());
    let attacker = Attacker::start(steps);
    let (mut read, mut refused, mut loaded) = (0, 0, 0);
    let t0 = Instant::now();
    // at least ROUNDS rounds, and on until one has read the mesh (her swaps can win every
    // round for a while), for at most a minute
    let mut i = 0;
    while i < ROUNDS || (read == 0 && t0.elapsed() < Duration::from_secs(60)) {
        i += 1;
        // as a render loads it: the scene file, then its mesh beneath the folder held
        match files::open_scene(&path, 1 << 20) {
            Ok(scene) => {
                assert!(scene.bytes.starts_with(b"[camera]"));
                let confinement = Confinement::beneath(scene.dir, Vec::<PathBuf>::new()).unwrap();
                match confinement.read("mesh.obj") {
                    Ok((bytes, at)) => {
                        assert_eq!(
                            bytes, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                            "read {at:?}"
                        );
                        read += 1;
                    }
                    Err(e) => {
                        assert!(!e.to_string().contains("ROOT-ONLY"), "{e}");
                        refused += 1;
                    }
                }
            }
            Err(e) => {
                assert!(!e.to_string().contains("ROOT-ONLY"), "{e}");
                refused += 1;
            }
        }
        // and the kernel's own load, every tenth round: her one triangle, never root's
        if i % 10 == 0 {
            if let Ok(scene) = ring_tracer_kernel::Scene::load(&path) {
                assert!(scene.bounds().min.x < 1.0, "loaded root's mesh");
                loaded += 1;
            }
        }
    }
    drop(attacker);
    eprintln!(
        "scenes: {read} meshes read, {refused} refused, {loaded} loaded whole under attack in {:?}",
        t0.elapsed()
    );
    assert_eq!(read + refused, i);
    assert!(read > 0, "no round in a minute read the scene's mesh");
}

/// A node's TLS folder `name` in `parent` (0700, owned by `uid`) holding `ca.pem`,
/// `node.pem` (0644) and `node.key` (0600) with `text`.
fn tls_folder(parent: &Path, name: &str, uid: u32, text: &str) -> PathBuf {
    let d = parent.join(name);
    std::fs::create_dir(&d).unwrap();
    for (file, mode) in [("ca.pem", 0o644), ("node.pem", 0o644), ("node.key", 0o600)] {
        std::fs::write(d.join(file), text).unwrap();
        std::fs::set_permissions(d.join(file), std::fs::Permissions::from_mode(mode)).unwrap();
        std::os::unix::fs::chown(d.join(file), Some(uid), Some(uid)).unwrap();
    }
    std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::os::unix::fs::chown(&d, Some(uid), Some(uid)).unwrap();
    d
}

/// The checks of a TLS folder (as `RingTracer.Cluster.TLS.check_dir/1` makes them).
fn check_tls(d: &Path) -> Result<(), ring_tracer_kernel::Error> {
    use safe_fs::Secrecy;
    let dir = safe_fs::trusted_dir(d)?;
    dir.check_trusted_file("ca.pem", Secrecy::Public)?;
    dir.check_trusted_file("node.pem", Secrecy::Public)?;
    dir.check_trusted_file("node.key", Secrecy::Private)
}

#[test]
fn a_tls_folder_is_trusted_only_when_nobody_else_can_swap_it() {
    if !root() {
        return;
    }
    // not under /tmp (every user can write in it): a folder whose every parent is root's
    let t = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    std::fs::set_permissions(t.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let good = tls_folder(t.path(), "good", 0, "root's");
    // root's TLS folder inside a folder of hers, which she swaps with her own TLS folder
    // and with her link to root's good one, as fast as she can; and root's own link to it
    let hers = theirs(&t.path().join("hers"), 0o755);
    let tls = tls_folder(&hers, "tls", 0, "root's");
    tls_folder(&hers, "mine", THEM, "HERS");
    their_link(&good, &hers.join("link"));
    std::os::unix::fs::symlink(&tls, t.path().join("rootlink")).unwrap();
    let attacker = Attacker::start(vec![
        Step::Exchange(cstr(&tls), cstr(&hers.join("mine"))),
        Step::Exchange(cstr(&tls), cstr(&hers.join("link"))),
        // and she tries the same on root's folders (refused: not hers)
        Step::Exchange(cstr(&good), cstr(&hers.join("mine"))),
    ]);
    let t0 = Instant::now();
    for _ in 0..ROUNDS {
        // through her folder: refused every time, whatever is at the name at that moment
        for via in [tls.clone(), t.path().join("rootlink")] {
            let e = check_tls(&via).expect_err("trusted a folder she can swap");
            let e = e.to_string();
            assert!(
                e.contains("is on the way to") && e.contains("belongs to user 65534"),
                "{e}"
            );
        }
        // root's own: accepted every time, and it holds root's files
        check_tls(&good).unwrap();
        assert_eq!(std::fs::read(good.join("node.key")).unwrap(), b"root's");
    }
    drop(attacker);
    eprintln!(
        "tls folders: {} checks of each kind in {:?}",
        ROUNDS,
        t0.elapsed()
    );
}

#[test]
fn a_tls_folder_in_a_sticky_folder_stays_roots() {
    if !root() {
        return;
    }
    // a folder both can write in, sticky (as /tmp): she may add names, not rename root's; she
    // tries to swap root's TLS folder for hers and for her link, and to take its name first
    let t = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    std::fs::set_permissions(t.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let shared = t.path().join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
    let tls = tls_folder(&shared, "tls", 0, "root's");
    let hers = tls_folder(&shared, "hers", THEM, "HERS");
    their_link(&hers, &shared.join("herlink"));
    let attacker = Attacker::start(vec![
        Step::Exchange(cstr(&tls), cstr(&hers)),
        Step::Exchange(cstr(&tls), cstr(&shared.join("herlink"))),
    ]);
    for _ in 0..ROUNDS {
        check_tls(&tls).unwrap();
        assert_eq!(std::fs::read(tls.join("node.key")).unwrap(), b"root's");
        // hers, and her link, are refused every time
        let e = check_tls(&hers)
            .expect_err("trusted her folder")
            .to_string();
        assert!(e.contains("belongs to user 65534"), "{e}");
        let e = check_tls(&shared.join("herlink")).expect_err("followed her link");
        assert!(e.to_string().contains("belongs to user 65534"), "{e}");
    }
    drop(attacker);
}

#[test]
fn an_output_replacing_her_file_does_not_take_its_mode() {
    if !root() {
        return;
    }
    let t = base();
    // a folder both can write in (root's, sticky, like /tmp); she plants files open to all at
    // the output's name whenever it is free, and reads all she can
    let shared = t.path().join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
    let out = shared.join("out.json");
    let attacker = Attacker::start(vec![Step::Plant(cstr(&out))]);
    let reader = Reader::start(&shared, "ROOT-ONLY");
    let (mut over_hers, mut fresh) = (0, 0);
    for i in 0..ROUNDS {
        let hers = std::fs::symlink_metadata(&out).is_ok_and(|m| m.uid() == THEM);
        let data = format!("ROOT-ONLY {i}");
        safe_fs::write_path(&out, data.as_bytes(), Some(0o600), Replace::Yes).unwrap();
        let m = std::fs::symlink_metadata(&out).unwrap();
        assert_eq!(m.uid(), 0);
        assert_eq!(
            m.mode() & 0o7777,
            0o600,
            "round {i}: took the mode of her file"
        );
        if hers {
            over_hers += 1;
        } else {
            fresh += 1;
        }
        std::fs::remove_file(&out).unwrap();
    }
    drop(attacker);
    let leaks = reader.finish();
    eprintln!("outputs over hers: {over_hers} replaced her file, {fresh} others");
    assert!(over_hers > 0, "she never planted a file in time");
    assert_eq!(leaks, "", "the other user read a root-only output");
}

#[test]
fn a_sweep_of_kept_links_removes_only_roots_own() {
    if !root() {
        return;
    }
    let t = base();
    let victim = victim(t.path(), "keep", "x");
    let before = snapshot(&victim);
    // root's output in a folder of hers, where she keeps names that look like root's hidden
    // links: her file, and her link to a root-only file, swapped with each other and with a
    // link to the victim folder, as fast as she can
    let out = theirs(&t.path().join("out"), 0o777);
    let a = out.join(".out.json.aaaaaaaaaaaaaaaa.kept");
    let b = out.join(".out.json.bbbbbbbbbbbbbbbb.kept");
    std::fs::write(&a, "hers").unwrap();
    std::os::unix::fs::lchown(&a, Some(THEM), Some(THEM)).unwrap();
    their_link(&victim.join("keep"), &b);
    let attacker = Attacker::start(vec![Step::Exchange(cstr(&a), cstr(&b))]);
    let (mut swept, mut kept) = (0, 0);
    for i in 0..ROUNDS {
        let Ok(dir) = Dir::open(&out) else { continue };
        safe_fs::write_path(
            &out.join("out.json"),
            format!("{i}").as_bytes(),
            None,
            Replace::Yes,
        )
        .unwrap();
        // a killed write's leftover: kept, never put back nor dropped
        if dir.keep("out.json").is_ok() {
            kept += 1;
        }
        swept += dir.sweep_kept("out.json", Duration::ZERO).unwrap();
    }
    drop(attacker);
    eprintln!("kept links: {kept} left behind, {swept} swept under attack");
    assert_eq!(
        swept, kept,
        "a leftover of root's was missed, or one of hers removed"
    );
    // hers are both still there, and nothing else is left
    let mut left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        [
            ".out.json.aaaaaaaaaaaaaaaa.kept",
            ".out.json.bbbbbbbbbbbbbbbb.kept",
            "out.json"
        ]
    );
    assert_eq!(snapshot(&victim), before, "something outside was changed");
}
