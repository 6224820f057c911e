//! Files written where another local user may be racing us: every output, the cookie, the
//! benchmarks' scratch folder and the server's socket folder.
//!
//! A folder is opened once, as a descriptor ([`Dir`]), and everything after that is done
//! relative to it: a new file is created in it with `O_CREAT | O_EXCL | O_NOFOLLOW` and mode
//! 0600, filled, given its final mode with `fchmod` on its descriptor, then renamed over its
//! target (or, for a file that must not replace one, put there with `RENAME_NOREPLACE`). No
//! name is resolved twice, nothing is chmodded by name, and no staging folder exists that
//! someone could swap for a symbolic link between two steps.
//!
//! [`private_dir`] makes a folder with mode 0700 in one `mkdir` and checks the folder it then
//! opened (`O_NOFOLLOW`, `fstat`): a directory, this user's, closed to others.
//!
//! ```no_run
//! use ring_tracer_kernel::safe_fs::{Dir, Replace};
//! use std::io::Write;
//! let dir = Dir::open(std::path::Path::new("renders"))?;
//! dir.write_file("a.json", None, Replace::Yes, |f| {
//!     f.write_all(b"{}").map_err(|e| ring_tracer_kernel::Error::Image(e.to_string()))
//! })?;
//! # Ok::<(), ring_tracer_kernel::Error>(())
//! ```

use crate::Error;
use rustix::fs::{self as rfs, AtFlags, Mode, OFlags, RenameFlags};
use rustix::io::Errno;
use std::fs::File;
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, OwnedFd};
use std::path::{Path, PathBuf};

/// The crate's error for a file, with the system's error number where there is one (so that
/// callers can tell "exists" from "no space").
fn fs_error(path: &Path, errno: Option<i32>, message: String) -> Error {
    Error::Fs {
        file: path.display().to_string(),
        errno,
        message,
    }
}

fn io_error(e: std::io::Error, path: &Path) -> Error {
    fs_error(path, e.raw_os_error(), plain(&e))
}

/// The same error, about `path`.
fn about(e: Error, path: &Path) -> Error {
    match e {
        Error::Fs { errno, message, .. } => fs_error(path, errno, message),
        Error::Io { message, .. } => fs_error(path, None, message),
        other => fs_error(path, None, other.to_string()),
    }
}

/// An `Errno` in words, without its number.
pub(crate) fn errno_text(e: Errno) -> String {
    plain(&std::io::Error::from(e))
}

/// An `io::Error`'s text without its " (os error N)" tail.
fn plain(e: &std::io::Error) -> String {
    let s = e.to_string();
    match s.find(" (os error ") {
        Some(i) => s[..i].to_string(),
        None => s,
    }
}

fn errno_error(path: &Path, e: Errno) -> Error {
    fs_error(path, Some(e.raw_os_error()), errno_text(e))
}

fn message_error(path: &Path, message: impl Into<String>) -> Error {
    fs_error(path, None, message.into())
}

/// Whether a new file may replace an existing one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Replace {
    /// Rename over whatever is at the name (a file, a symbolic link: replaced, never followed).
    Yes,
    /// Refuse when something is at the name (`EEXIST`); nothing is replaced, ever.
    No,
}

/// What [`Dir::keep`] kept of a name: nothing was there, or a hard link to what was (a file
/// or the symbolic link itself, never what it points to) under a hidden name in the folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Kept {
    /// Nothing was at the name.
    Nothing,
    /// What was there, under this hidden name.
    Link(String),
}

/// How long ago a hidden link [`Dir::keep`] made must have been made (or its name's file
/// replaced) to be taken for one a killed write left behind ([`Dir::sweep_kept`]): far longer
/// than any write of a render's outputs takes.
pub const STALE_KEPT: std::time::Duration = std::time::Duration::from_secs(3600);

/// A folder opened once; its files are reached through the descriptor only.
#[derive(Debug)]
pub struct Dir {
    fd: OwnedFd,
    path: PathBuf,
}

/// A random hidden name beside `name`, ending in `suffix`.
fn hidden_name(name: &str, suffix: &str) -> String {
    let mut bytes = [0u8; 8];
    let mut filled = 0;
    while filled < bytes.len() {
        match rustix::rand::getrandom(&mut bytes[filled..], rustix::rand::GetRandomFlags::empty()) {
            Ok(n) => filled += n,
            Err(Errno::INTR) => {}
            Err(_) => {
                // never fails on Linux ≥ 3.17 once the pool is ready; a clock is unique enough
                // for O_EXCL to do the rest
                let t = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_nanos() as u64)
                    .unwrap_or(0);
                bytes = (t ^ u64::from(std::process::id())).to_le_bytes();
                break;
            }
        }
    }
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    // keep the name within NAME_MAX whatever `name` is
    let head: String = name.chars().take(200).collect();
    format!(".{head}.{hex}{suffix}")
}

/// A name for a file in a folder: one component, not `.` or `..`.
fn check_name(dir: &Path, name: &str) -> Result<(), Error> {
    if name.is_empty() || name == "." || name == ".." || name.contains('/') || name.contains('\0') {
        return Err(message_error(
            &dir.join(name),
            "not a file name (one path component is needed)",
        ));
    }
    Ok(())
}

/// The most symbolic links one path may go through (the kernel's own bound).
const MAX_LINKS: usize = 40;

/// What a walk does with a symbolic link as the path's last component.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LastLink {
    /// Follows it (when it is this user's or root's, as every link on the way).
    Follow,
    /// Refuses it: the path must name the folder itself.
    Refuse,
}

/// A check a walk makes on every folder it goes through (each one it opens something in),
/// given the folder's descriptor and the path it was reached by.
type FolderCheck<'a> = &'a dyn Fn(&OwnedFd, &Path) -> Result<(), Error>;

/// Opens the folder `path` (`O_PATH`), one component at a time from a descriptor, following
/// a symbolic link only when it belongs to this user or to root (and the last component's
/// only with [`LastLink::Follow`]). Another local user's link on the way is refused: whoever
/// owns a link, or can swap one into a folder of hers, would choose where the caller writes.
/// (`openat2` cannot say "only links of these owners", hence the walk; each step is one
/// `openat` with `O_NOFOLLOW` on the folder reached, nothing is resolved by name twice.)
/// `check`, when given, is made on every folder the walk opens something in (not on the
/// folder it ends at), before it does.
fn walk(path: &Path, last_link: LastLink, check: Option<FolderCheck>) -> Result<OwnedFd, Error> {
    use std::os::unix::ffi::OsStrExt;
    let dir_flags = OFlags::PATH | OFlags::DIRECTORY | OFlags::CLOEXEC;
    let me = rustix::process::geteuid().as_raw();
    // where the walk is, by the names it went through (for `check`'s messages), and what is
    // left to walk
    let (mut cur, mut at, mut todo) = walk_start(path, dir_flags)?;
    let mut links = 0;
    while let Some((part, last)) = todo.pop_front() {
        let bytes = part.as_bytes();
        if bytes == b"/" {
            cur = rfs::open("/", dir_flags, Mode::empty()).map_err(|e| errno_error(path, e))?;
            at = PathBuf::from("/");
            continue;
        }
        if bytes == b"." || bytes.is_empty() {
            continue;
        }
        if let Some(check) = check {
            check(&cur, &at)?;
        }
        let next = rfs::openat(
            &cur,
            part.as_os_str(),
            OFlags::PATH | OFlags::NOFOLLOW | OFlags::CLOEXEC,
            Mode::empty(),
        )
        .map_err(|e| errno_error(path, e))?;
        let st = rfs::fstat(&next).map_err(|e| errno_error(path, e))?;
        match rfs::FileType::from_raw_mode(st.st_mode) {
            rfs::FileType::Directory => {
                cur = next;
                if bytes == b".." {
                    at.pop();
                } else {
                    at.push(&part);
                }
            }
            rfs::FileType::Symlink => {
                if last && last_link == LastLink::Refuse {
                    return Err(message_error(path, "is a symbolic link, not a folder"));
                }
                let target = link_target(path, &part, &next, st.st_uid, me, &mut links)?;
                let comps: Vec<std::path::Component> = target.components().collect();
                for (i, c) in comps.iter().enumerate().rev() {
                    todo.push_front((c.as_os_str().to_os_string(), last && i + 1 == comps.len()));
                }
            }
            _ => return Err(errno_error(path, Errno::NOTDIR)),
        }
    }
    Ok(cur)
}

/// What is left of a walk: components, `true` marking the path's own last one.
type Todo = std::collections::VecDeque<(std::ffi::OsString, bool)>;

/// Where [`walk`] of `path` starts: the folder it is relative to (`/` or `.`, opened with
/// `dir_flags`), that folder's path, and the path's components.
fn walk_start(path: &Path, dir_flags: OFlags) -> Result<(OwnedFd, PathBuf, Todo), Error> {
    let root = if path.is_absolute() { "/" } else { "." };
    let cur = rfs::open(root, dir_flags, Mode::empty()).map_err(|e| errno_error(path, e))?;
    let parts: Vec<std::path::Component> = path.components().collect();
    let todo = (parts.iter().enumerate())
        .map(|(i, c)| (c.as_os_str().to_os_string(), i + 1 == parts.len()))
        .collect();
    Ok((cur, PathBuf::from(root), todo))
}

/// The target of symbolic link `next`, named `part`, owned by `uid`, met by [`walk`] of
/// `path`: refused unless the link is this user's (`me`) or root's, and past [`MAX_LINKS`]
/// links on the way (`links` counts them).
fn link_target(
    path: &Path,
    part: &std::ffi::OsStr,
    next: &OwnedFd,
    uid: u32,
    me: u32,
    links: &mut usize,
) -> Result<PathBuf, Error> {
    use std::os::unix::ffi::OsStrExt;
    if uid != me && uid != 0 {
        return Err(message_error(
            path,
            format!(
                "goes through a symbolic link ({}) that belongs to user {}; \
                 not following it (name the folder it leads to instead)",
                Path::new(part).display(),
                uid
            ),
        ));
    }
    *links += 1;
    if *links > MAX_LINKS {
        return Err(errno_error(path, Errno::LOOP));
    }
    let target = rfs::readlinkat(next, "", Vec::new()).map_err(|e| errno_error(path, e))?;
    Ok(PathBuf::from(std::ffi::OsStr::from_bytes(
        target.as_bytes(),
    )))
}

/// The folder and file name of `path` (`a.png` is in `.`).
pub fn split(path: &Path) -> Result<(PathBuf, String), Error> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| message_error(path, "not a file name"))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((dir, name.to_string()))
}

/// This process's umask, read from `/proc/self/status` (setting it to read it back would change
/// it for every thread meanwhile); `0o077` where it cannot be read, so that a file is then
/// never more open than its owner's.
pub fn umask() -> u32 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Umask:"))
                .and_then(|v| u32::from_str_radix(v.trim(), 8).ok())
        })
        .unwrap_or(0o077)
}

impl Dir {
    /// Opens the folder `path` (symbolic links on the way are followed, once).
    pub fn open(path: &Path) -> Result<Dir, Error> {
        Self::open_with(path, LastLink::Follow)
    }

    /// Opens the folder `path`, refusing a symbolic link as its last component.
    pub fn open_nofollow(path: &Path) -> Result<Dir, Error> {
        Self::open_with(path, LastLink::Refuse)
    }

    fn open_with(path: &Path, last_link: LastLink) -> Result<Dir, Error> {
        let found = walk(path, last_link, None)?;
        Self::reopen(path, &found)
    }

    /// The folder `found` (`O_PATH`) opened for reading, through its descriptor.
    fn reopen(path: &Path, found: &OwnedFd) -> Result<Dir, Error> {
        let fd = rfs::openat(
            found,
            ".",
            OFlags::RDONLY | OFlags::DIRECTORY | OFlags::CLOEXEC,
            Mode::empty(),
        )
        .map_err(|e| match e {
            Errno::NOTDIR => message_error(path, "not a folder"),
            e => errno_error(path, e),
        })?;
        Ok(Dir {
            fd,
            path: path.to_path_buf(),
        })
    }

    /// The folder as it was named when opened (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The descriptor.
    pub fn fd(&self) -> BorrowedFd<'_> {
        self.fd.as_fd()
    }

    /// A path that names this very folder for as long as this `Dir` lives, in this process
    /// only: `/proc/self/fd/N` (e.g. to bind a Unix socket in it without naming it again).
    pub fn proc_path(&self) -> PathBuf {
        PathBuf::from(format!("/proc/self/fd/{}", self.fd.as_raw_fd()))
    }

    fn at(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// The permission bits a file replacing `name` gets: those of the regular file there now
    /// when it is this user's (a symbolic link is not followed), without setuid, setgid and
    /// sticky; else `new_mode`, else `0o666` less the umask. A file another user put at the
    /// name (in a folder both can write in) gives nothing: its mode is hers to choose, and
    /// copying it would open this user's output to whoever she likes.
    pub fn mode_for(&self, name: &str, new_mode: Option<u32>) -> u32 {
        let me = rustix::process::geteuid().as_raw();
        match rfs::statat(&self.fd, name, AtFlags::SYMLINK_NOFOLLOW) {
            Ok(st)
                if rfs::FileType::from_raw_mode(st.st_mode) == rfs::FileType::RegularFile
                    && st.st_uid == me =>
            {
                st.st_mode & 0o777
            }
            _ => new_file_mode(new_mode),
        }
    }

    /// Puts a new file at `name`: created under a hidden random name in this folder
    /// (`O_CREAT | O_EXCL | O_NOFOLLOW`, mode 0600), filled by `fill`, flushed to disk, given
    /// its final mode (see [`Dir::mode_for`]) with `fchmod`, then renamed to `name`. On any
    /// failure the hidden file is removed and `name` is as it was.
    pub fn write_file(
        &self,
        name: &str,
        new_mode: Option<u32>,
        replace: Replace,
        fill: impl FnOnce(&mut File) -> Result<(), Error>,
    ) -> Result<(), Error> {
        check_name(&self.path, name)?;
        let target = self.at(name);
        let mode = match replace {
            Replace::Yes => self.mode_for(name, new_mode),
            Replace::No => new_file_mode(new_mode),
        };
        let (tmp, mut file) = self.create_hidden(name, ".tmp")?;
        let done = (|| {
            fill(&mut file).map_err(|e| about(e, &target))?;
            file.sync_all().map_err(|e| io_error(e, &target))?;
            rfs::fchmod(&file, Mode::from_raw_mode(mode)).map_err(|e| errno_error(&target, e))?;
            self.place(&tmp, name, replace)
        })();
        if done.is_err() {
            let _ = rfs::unlinkat(&self.fd, tmp.as_str(), AtFlags::empty());
        }
        done
    }

    /// A new empty file under a hidden random name, mode 0600, and its name.
    fn create_hidden(&self, name: &str, suffix: &str) -> Result<(String, File), Error> {
        for _ in 0..16 {
            let tmp = hidden_name(name, suffix);
            match rfs::openat(
                &self.fd,
                tmp.as_str(),
                OFlags::WRONLY | OFlags::CREATE | OFlags::EXCL | OFlags::NOFOLLOW | OFlags::CLOEXEC,
                Mode::from_raw_mode(0o600),
            ) {
                Ok(fd) => return Ok((tmp, File::from(fd))),
                Err(Errno::EXIST) => continue,
                Err(e) => return Err(errno_error(&self.at(name), e)),
            }
        }
        Err(message_error(
            &self.at(name),
            "could not make a temporary file beside it",
        ))
    }

    /// Moves the hidden file `tmp` to `name`.
    fn place(&self, tmp: &str, name: &str, replace: Replace) -> Result<(), Error> {
        let target = self.at(name);
        match replace {
            Replace::Yes => {
                rfs::renameat(&self.fd, tmp, &self.fd, name).map_err(|e| errno_error(&target, e))
            }
            Replace::No => {
                match rfs::renameat_with(&self.fd, tmp, &self.fd, name, RenameFlags::NOREPLACE) {
                    Ok(()) => Ok(()),
                    // a filesystem without RENAME_NOREPLACE: a hard link refuses an existing
                    // name just as well
                    Err(Errno::INVAL) | Err(Errno::NOSYS) => {
                        rfs::linkat(&self.fd, tmp, &self.fd, name, AtFlags::empty())
                            .map_err(|e| errno_error(&target, e))?;
                        let _ = rfs::unlinkat(&self.fd, tmp, AtFlags::empty());
                        Ok(())
                    }
                    Err(e) => Err(errno_error(&target, e)),
                }
            }
        }
    }

    /// Whether a new file can be made in this folder: tried for real (permission bits do not
    /// tell the whole story: root, ACLs, read-only mounts), then removed.
    pub fn probe(&self, name: &str) -> Result<(), Error> {
        check_name(&self.path, name)?;
        let (tmp, file) = self.create_hidden(name, ".tmp")?;
        drop(file);
        rfs::unlinkat(&self.fd, tmp.as_str(), AtFlags::empty())
            .map_err(|e| errno_error(&self.at(name), e))
    }

    /// Keeps what is at `name` now (a regular file, a symbolic link, anything) as a hard link
    /// under a hidden name, without following a link, so that [`Dir::put_back`] can restore
    /// exactly it. First removes this user's hidden links for `name` older than
    /// [`STALE_KEPT`] ([`Dir::sweep_kept`]): those a killed write left.
    pub fn keep(&self, name: &str) -> Result<Kept, Error> {
        check_name(&self.path, name)?;
        let target = self.at(name);
        // what a killed write of this output kept and never took back
        self.sweep_kept(name, STALE_KEPT)?;
        match rfs::statat(&self.fd, name, AtFlags::SYMLINK_NOFOLLOW) {
            Err(Errno::NOENT) => return Ok(Kept::Nothing),
            Err(e) => return Err(errno_error(&target, e)),
            Ok(_) => {}
        }
        for _ in 0..16 {
            let kept = hidden_name(name, ".kept");
            match rfs::linkat(&self.fd, name, &self.fd, kept.as_str(), AtFlags::empty()) {
                Ok(()) => return Ok(Kept::Link(kept)),
                Err(Errno::EXIST) => continue,
                Err(Errno::NOENT) => return Ok(Kept::Nothing),
                Err(e) => return Err(errno_error(&target, e)),
            }
        }
        Err(message_error(&target, "could not keep it beside itself"))
    }

    /// Removes the hidden links [`Dir::keep`] made for `name` and that nothing took back: a
    /// write of several outputs killed (`SIGKILL`) before it put back or dropped what it kept
    /// leaves one behind. Only an entry whose name is exactly one `keep` makes for `name`
    /// (`.NAME.` sixteen hex digits `.kept`), that belongs to this user, and whose inode last
    /// changed (`ctime`: the link made, or the name it was kept for replaced) more than
    /// `older_than` ago, so that a write of the same output still running elsewhere keeps its
    /// own. Listed and removed through the folder's descriptor (`unlinkat` removes the entry,
    /// never follows it). Returns how many were removed.
    pub fn sweep_kept(&self, name: &str, older_than: std::time::Duration) -> Result<usize, Error> {
        check_name(&self.path, name)?;
        let target = self.at(name);
        let head: String = name.chars().take(200).collect();
        let prefix = format!(".{head}.");
        let ours = |entry: &str| {
            entry
                .strip_prefix(prefix.as_str())
                .and_then(|rest| rest.strip_suffix(".kept"))
                .is_some_and(|hex| {
                    hex.len() == 16 && hex.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
                })
        };
        let me = rustix::process::geteuid().as_raw();
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        let before = now.saturating_sub(older_than.as_secs());
        let mut list = rfs::Dir::read_from(&self.fd).map_err(|e| errno_error(&target, e))?;
        let mut removed = 0;
        while let Some(entry) = list.read() {
            let entry = entry.map_err(|e| errno_error(&target, e))?;
            let Ok(entry) = entry.file_name().to_str() else {
                continue;
            };
            if !ours(entry) {
                continue;
            }
            let Ok(st) = rfs::statat(&self.fd, entry, AtFlags::SYMLINK_NOFOLLOW) else {
                continue;
            };
            let changed = u64::try_from(st.st_ctime).unwrap_or(0);
            if st.st_uid != me || changed > before {
                continue;
            }
            match rfs::unlinkat(&self.fd, entry, AtFlags::empty()) {
                Ok(()) => removed += 1,
                Err(Errno::NOENT) => {}
                Err(e) => return Err(errno_error(&self.at(entry), e)),
            }
        }
        Ok(removed)
    }

    /// Puts back what [`Dir::keep`] kept at `name`: the link renamed over `name`, or `name`
    /// removed when nothing was there.
    pub fn put_back(&self, name: &str, kept: &Kept) -> Result<(), Error> {
        check_name(&self.path, name)?;
        let target = self.at(name);
        match kept {
            Kept::Link(link) => {
                rfs::renameat(&self.fd, link.as_str(), &self.fd, name)
                    .map_err(|e| errno_error(&target, e))?;
                // when `name` is still the file kept (nothing replaced it), the rename does
                // nothing at all (two links to one file) and the hidden link stays: remove it
                match rfs::unlinkat(&self.fd, link.as_str(), AtFlags::empty()) {
                    Ok(()) | Err(Errno::NOENT) => Ok(()),
                    Err(e) => Err(errno_error(&target, e)),
                }
            }
            Kept::Nothing => match rfs::unlinkat(&self.fd, name, AtFlags::empty()) {
                Ok(()) | Err(Errno::NOENT) => Ok(()),
                Err(e) => Err(errno_error(&target, e)),
            },
        }
    }

    /// Drops what [`Dir::keep`] kept (after a success).
    pub fn discard(&self, kept: &Kept) -> Result<(), Error> {
        match kept {
            Kept::Nothing => Ok(()),
            Kept::Link(link) => match rfs::unlinkat(&self.fd, link.as_str(), AtFlags::empty()) {
                Ok(()) | Err(Errno::NOENT) => Ok(()),
                Err(e) => Err(errno_error(&self.at(link), e)),
            },
        }
    }
}

/// Makes the folder `path` (with `create`; an existing one is taken as it is when
/// `may_exist`) with mode 0700 in the one `mkdir`, opens it without following a symbolic
/// link, and checks the folder opened: a directory, owned by this user, that nobody else can
/// enter (group and other bits clear). Refused otherwise, with what is wrong and, when it is
/// this user's, the command that fixes it.
pub fn private_dir(path: &Path, may_exist: bool) -> Result<Dir, Error> {
    let (parent, name) = split(path)?;
    check_name(&parent, &name)?;
    let parent_dir = Dir::open(&parent)?;
    match rfs::mkdirat(&parent_dir.fd, name.as_str(), Mode::from_raw_mode(0o700)) {
        Ok(()) => {}
        Err(Errno::EXIST) if may_exist => {}
        Err(e) => return Err(errno_error(path, e)),
    }
    let fd = rfs::openat(
        &parent_dir.fd,
        name.as_str(),
        OFlags::RDONLY | OFlags::DIRECTORY | OFlags::NOFOLLOW | OFlags::CLOEXEC,
        Mode::empty(),
    )
    .map_err(|e| match e {
        Errno::NOTDIR | Errno::LOOP => message_error(path, "is not a folder"),
        e => errno_error(path, e),
    })?;
    let st = rfs::fstat(&fd).map_err(|e| errno_error(path, e))?;
    let me = rustix::process::geteuid().as_raw();
    if st.st_uid != me {
        return Err(message_error(
            path,
            format!(
                "belongs to user {}, not to this user ({me}); refusing to use it",
                st.st_uid
            ),
        ));
    }
    if st.st_mode & 0o077 != 0 {
        return Err(message_error(
            path,
            format!(
                "can be entered by others (chmod 700 {}; its mode is {:04o})",
                path.display(),
                st.st_mode & 0o7777
            ),
        ));
    }
    Ok(Dir {
        fd,
        path: path.to_path_buf(),
    })
}

/// What a file that is not a regular one is, in words (from its type as `fstat` gives it).
pub(crate) fn kind_words(kind: rfs::FileType) -> &'static str {
    use rfs::FileType as T;
    match kind {
        T::RegularFile => "a regular file",
        T::Directory => "a directory",
        T::Fifo => "a FIFO (named pipe)",
        T::Socket => "a socket",
        T::CharacterDevice => "a character device",
        T::BlockDevice => "a block device",
        T::Symlink => "a symbolic link",
        _ => "a file of another kind",
    }
}

/// Reads a secret file (a cookie) that must be this user's own: opened once, without following
/// a symbolic link as its last component and without blocking (`O_NOFOLLOW | O_NONBLOCK`, so a
/// FIFO or a device swapped in never hangs the open), then checked on that descriptor
/// (`fstat`): a regular file, owned by this user, no bit for group or others, at most
/// `max_bytes`; and read from that same descriptor, never more than `max_bytes + 1` bytes
/// (a file that grows meanwhile is refused too). Nothing is looked up by name twice, so no
/// other file can be swapped in between the checks and the read.
pub fn read_private(path: &Path, max_bytes: u64) -> Result<Vec<u8>, Error> {
    use std::io::Read;
    let fd = rfs::open(
        path,
        OFlags::RDONLY | OFlags::NOFOLLOW | OFlags::NONBLOCK | OFlags::NOCTTY | OFlags::CLOEXEC,
        Mode::empty(),
    )
    .map_err(|e| match e {
        Errno::LOOP => fs_error(
            path,
            Some(e.raw_os_error()),
            "is a symbolic link (not followed: name the file itself)".to_string(),
        ),
        e => errno_error(path, e),
    })?;
    let st = rfs::fstat(&fd).map_err(|e| errno_error(path, e))?;
    let kind = rfs::FileType::from_raw_mode(st.st_mode);
    if kind != rfs::FileType::RegularFile {
        return Err(message_error(
            path,
            format!("is {}, not a regular file", kind_words(kind)),
        ));
    }
    let me = rustix::process::geteuid().as_raw();
    if st.st_uid != me {
        return Err(message_error(
            path,
            format!("belongs to user {}, not to this user ({me})", st.st_uid),
        ));
    }
    let open_bits = st.st_mode & 0o077;
    if open_bits != 0 {
        let what = if open_bits & 0o044 != 0 {
            "read"
        } else if open_bits & 0o022 != 0 {
            "changed"
        } else {
            "run"
        };
        return Err(message_error(
            path,
            format!(
                "can be {what} by other users (mode {:04o}); fix it with: chmod 600 {}",
                st.st_mode & 0o7777,
                path.display()
            ),
        ));
    }
    let too_large = |size: u64| {
        message_error(
            path,
            format!("is too large ({size} bytes, at most {max_bytes})"),
        )
    };
    let size = u64::try_from(st.st_size).unwrap_or(u64::MAX);
    if size > max_bytes {
        return Err(too_large(size));
    }
    let mut bytes = Vec::new();
    File::from(fd)
        .take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| io_error(e, path))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// How closed a file in a trusted folder must be ([`Dir::check_trusted_file`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Secrecy {
    /// Anyone may read it (a certificate): this user's or root's, nobody else may change it.
    Public,
    /// Only its owner may read it (a private key): this user's, no bit for group or others.
    Private,
}

/// Opens the folder `path` after checking every folder on the way to it, from `/` (a relative
/// path is taken from the current folder's absolute name), and every symbolic link followed:
/// each belongs to this user or to root and no other user can change it (no write bit for
/// group or others, or the sticky bit, as on `/tmp`: others may add names there but not
/// rename or remove this user's or root's, and what comes next on the way is checked for its
/// own owner), so nobody else can rename or replace anything on the way, now or later;
/// the folder itself must be this user's and closed to changes by others. What is checked
/// is what is opened (descriptors, `fstat`); refused otherwise, naming the folder at fault
/// and why. Files in it are then checked with [`Dir::check_trusted_file`]: a program that
/// later reads them by name (OTP's ssl reads a node's certificates so) reads the same files.
pub fn trusted_dir(path: &Path) -> Result<Dir, Error> {
    let me = rustix::process::geteuid().as_raw();
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map_err(|e| io_error(e, path))?
            .join(path)
    };
    let on_the_way = |fd: &OwnedFd, at: &Path| -> Result<(), Error> {
        let st = rfs::fstat(fd).map_err(|e| errno_error(at, e))?;
        if st.st_uid != me && st.st_uid != 0 {
            return Err(message_error(
                at,
                format!(
                    "is on the way to {} and belongs to user {}, who could swap what is in it; \
                     use a folder that only you and root can change",
                    path.display(),
                    st.st_uid
                ),
            ));
        }
        // A sticky folder (/tmp) lets others add names but not rename or remove what is not
        // theirs: the next folder or link on the way is then checked for its own owner.
        let sticky = st.st_mode & 0o1000 != 0;
        if st.st_mode & 0o022 != 0 && !sticky {
            return Err(message_error(
                at,
                format!(
                    "is on the way to {} and can be changed by other users (mode {:04o}), who \
                     could swap what is in it; use a folder that only you and root can change",
                    path.display(),
                    st.st_mode & 0o7777
                ),
            ));
        }
        Ok(())
    };
    let found = walk(&absolute, LastLink::Follow, Some(&on_the_way))?;
    let st = rfs::fstat(&found).map_err(|e| errno_error(path, e))?;
    if st.st_uid != me {
        return Err(message_error(
            path,
            format!(
                "belongs to user {}, not to you: use a folder of your own",
                st.st_uid
            ),
        ));
    }
    if st.st_mode & 0o022 != 0 {
        return Err(message_error(
            path,
            format!(
                "can be changed by other users; fix it with: chmod 700 {}",
                path.display()
            ),
        ));
    }
    Dir::reopen(path, &found)
}

impl Dir {
    /// Checks the file `name` in this folder, without following a symbolic link (refused):
    /// a regular file, and as `secrecy` says. Made on the file opened (`O_PATH`, `fstat`).
    pub fn check_trusted_file(&self, name: &str, secrecy: Secrecy) -> Result<(), Error> {
        check_name(&self.path, name)?;
        let target = self.at(name);
        let fd = rfs::openat(
            &self.fd,
            name,
            OFlags::PATH | OFlags::NOFOLLOW | OFlags::CLOEXEC,
            Mode::empty(),
        )
        .map_err(|e| errno_error(&target, e))?;
        let st = rfs::fstat(&fd).map_err(|e| errno_error(&target, e))?;
        let kind = rfs::FileType::from_raw_mode(st.st_mode);
        if kind != rfs::FileType::RegularFile {
            return Err(message_error(
                &target,
                format!(
                    "is {}, not a regular file (put the file itself in the folder)",
                    kind_words(kind)
                ),
            ));
        }
        let me = rustix::process::geteuid().as_raw();
        let (owners_ok, open_bits, fix) = match secrecy {
            Secrecy::Public => (st.st_uid == me || st.st_uid == 0, 0o022, "go-w"),
            Secrecy::Private => (st.st_uid == me, 0o077, "600"),
        };
        if !owners_ok {
            return Err(message_error(
                &target,
                format!(
                    "belongs to user {}, not to you: use a folder of your own",
                    st.st_uid
                ),
            ));
        }
        let bits = st.st_mode & open_bits;
        if bits != 0 {
            let what = if bits & 0o044 != 0 {
                "read"
            } else if bits & 0o022 != 0 {
                "changed"
            } else {
                "run"
            };
            return Err(message_error(
                &target,
                format!(
                    "can be {what} by other users; fix it with: chmod {fix} {}",
                    target.display()
                ),
            ));
        }
        Ok(())
    }
}

/// The permission bits of a new file: `new_mode`, else `0o666` less the umask (read only
/// then).
fn new_file_mode(new_mode: Option<u32>) -> u32 {
    new_mode.unwrap_or_else(|| 0o666 & !umask()) & 0o777
}

/// The folder `path` is in, opened (errors about `path`), and its name there.
pub fn open_parent(path: &Path) -> Result<(Dir, String), Error> {
    let (dir, name) = split(path)?;
    let dir = Dir::open(&dir).map_err(|e| about(e, path))?;
    Ok((dir, name))
}

/// Writes `data` to `path` atomically (see [`Dir::write_file`]).
pub fn write_path(
    path: &Path,
    data: &[u8],
    new_mode: Option<u32>,
    replace: Replace,
) -> Result<(), Error> {
    use std::io::Write;
    let (dir, name) = open_parent(path)?;
    dir.write_file(&name, new_mode, replace, |f| {
        f.write_all(data).map_err(|e| io_error(e, path))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::names;
    use std::os::unix::fs::{symlink, MetadataExt, PermissionsExt};

    #[test]
    fn writes_replace_and_refuse() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("a.json");
        write_path(&p, b"one", Some(0o640), Replace::Yes).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        assert_eq!(std::fs::metadata(&p).unwrap().mode() & 0o7777, 0o640);
        // a replaced file keeps its bits, but never setuid/setgid/sticky
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o6755)).unwrap();
        write_path(&p, b"two", Some(0o600), Replace::Yes).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::metadata(&p).unwrap().mode() & 0o7777, 0o755);
        let e = write_path(&p, b"three", Some(0o600), Replace::No).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Fs {
                    errno: Some(libc::EEXIST),
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        // a symbolic link at the name is replaced, its target untouched
        let victim = t.path().join("victim");
        std::fs::write(&victim, "keep").unwrap();
        let link = t.path().join("l.json");
        symlink(&victim, &link).unwrap();
        assert!(write_path(&link, b"x", None, Replace::No).is_err());
        write_path(&link, b"x", None, Replace::Yes).unwrap();
        assert_eq!(std::fs::read(&victim).unwrap(), b"keep");
        assert!(std::fs::symlink_metadata(&link).unwrap().is_file());
        assert_eq!(names(t.path()), ["a.json", "l.json", "victim"]);
        // another user's file at the name lends it nothing
        if rustix::process::geteuid().is_root() {
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o666)).unwrap();
            std::os::unix::fs::chown(&p, Some(65534), None).unwrap();
            write_path(&p, b"four", Some(0o600), Replace::Yes).unwrap();
            let m = std::fs::metadata(&p).unwrap();
            assert_eq!((m.uid(), m.mode() & 0o7777), (0, 0o600));
        }
    }

    #[test]
    fn a_failed_fill_leaves_nothing() {
        let t = tempfile::tempdir().unwrap();
        let dir = Dir::open(t.path()).unwrap();
        let e = dir
            .write_file("a.png", None, Replace::Yes, |_| {
                Err(message_error(Path::new(""), "disk full"))
            })
            .unwrap_err();
        assert!(e.to_string().ends_with("a.png: disk full"), "{e}");
        assert!(names(t.path()).is_empty());
        dir.probe("a.png").unwrap();
        assert!(names(t.path()).is_empty());
    }

    #[test]
    fn keep_and_put_back_restore_links_exactly() {
        let t = tempfile::tempdir().unwrap();
        let dir = Dir::open(t.path()).unwrap();
        std::fs::write(t.path().join("target"), "old").unwrap();
        symlink("target", t.path().join("out.png")).unwrap();
        let kept = dir.keep("out.png").unwrap();
        dir.write_file("out.png", None, Replace::Yes, |f| {
            use std::io::Write;
            f.write_all(b"new").map_err(|e| io_error(e, Path::new("")))
        })
        .unwrap();
        dir.put_back("out.png", &kept).unwrap();
        assert_eq!(
            std::fs::read_link(t.path().join("out.png")).unwrap(),
            Path::new("target")
        );
        assert_eq!(std::fs::read(t.path().join("target")).unwrap(), b"old");
        // put back when nothing replaced it (a write that failed first): no hidden link left
        let kept = dir.keep("out.png").unwrap();
        dir.put_back("out.png", &kept).unwrap();
        assert_eq!(names(t.path()), ["out.png", "target"]);
        let nothing = dir.keep("new.json").unwrap();
        assert_eq!(nothing, Kept::Nothing);
        write_path(&t.path().join("new.json"), b"{}", None, Replace::Yes).unwrap();
        dir.put_back("new.json", &nothing).unwrap();
        let kept = dir.keep("target").unwrap();
        dir.discard(&kept).unwrap();
        assert_eq!(names(t.path()), ["out.png", "target"]);
    }

    #[test]
    fn a_killed_writes_kept_link_is_swept_on_the_next_write() {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join("out.png"), "old").unwrap();
        // a child keeps the output, as a write of several does first, and is killed there
        // SAFETY: the child only calls this crate's code on memory it owns, then is killed
        // (or exits) without returning into the test harness.
        let pid = unsafe { libc::fork() };
        assert!(pid >= 0);
        if pid == 0 {
            let dir = Dir::open(t.path()).unwrap();
            let _ = dir.keep("out.png");
            unsafe { libc::raise(libc::SIGKILL) };
            unsafe { libc::_exit(1) };
        }
        let mut status = 0;
        // SAFETY: our own child.
        assert_eq!(unsafe { libc::waitpid(pid, &mut status, 0) }, pid);
        assert!(libc::WIFSIGNALED(status));
        let left = names(t.path());
        assert_eq!(left.len(), 2, "{left:?}");
        assert!(left[0].starts_with(".out.png.") && left[0].ends_with(".kept"));
        // names that only look alike, and another output's, are not touched
        for other in [
            ".out.png.kept",
            ".out.png.0123456789abcdeg.kept",
            ".a.png.0123456789abcdef.kept",
            "x.0123456789abcdef.kept",
        ] {
            std::fs::write(t.path().join(other), "").unwrap();
        }
        let dir = Dir::open(t.path()).unwrap();
        // too new to be taken for a killed write's: kept
        let kept = dir.keep("out.png").unwrap();
        assert_eq!(names(t.path()).len(), 7);
        dir.discard(&kept).unwrap();
        assert_eq!(
            dir.sweep_kept("out.png", std::time::Duration::ZERO)
                .unwrap(),
            1
        );
        assert_eq!(
            names(t.path()),
            [
                ".a.png.0123456789abcdef.kept",
                ".out.png.0123456789abcdeg.kept",
                ".out.png.kept",
                "out.png",
                "x.0123456789abcdef.kept"
            ]
        );
        assert_eq!(std::fs::read(t.path().join("out.png")).unwrap(), b"old");
        // another user's is not touched either
        if rustix::process::geteuid().is_root() {
            let theirs = t.path().join(".out.png.00000000000000ff.kept");
            std::fs::write(&theirs, "").unwrap();
            std::os::unix::fs::lchown(&theirs, Some(65534), None).unwrap();
            assert_eq!(
                dir.sweep_kept("out.png", std::time::Duration::ZERO)
                    .unwrap(),
                0
            );
            assert!(theirs.exists());
        }
    }

    #[test]
    fn private_dir_is_made_closed_and_checked() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("private");
        let d = private_dir(&p, false).unwrap();
        assert_eq!(std::fs::metadata(&p).unwrap().mode() & 0o777, 0o700);
        assert!(private_dir(&p, false).is_err());
        assert!(private_dir(&p, true).is_ok());
        // a name bound through /proc/self/fd lands in the folder opened
        std::fs::write(d.proc_path().join("x"), "1").unwrap();
        assert_eq!(names(&p), ["x"]);
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
        let e = private_dir(&p, true).unwrap_err().to_string();
        assert!(e.contains("can be entered by others (chmod 700 "), "{e}");
        assert!(e.ends_with("; its mode is 0755)"), "{e}");
        let l = t.path().join("link");
        symlink(&p, &l).unwrap();
        let e = private_dir(&l, true).unwrap_err().to_string();
        assert!(e.ends_with("link: is not a folder"), "{e}");
    }

    #[test]
    fn a_private_file_is_read_only_when_it_is_ours_closed_and_small() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("cookie");
        std::fs::write(&p, "abc\n").unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(read_private(&p, 4).unwrap(), b"abc\n");
        let e = read_private(&p, 3).unwrap_err().to_string();
        assert!(
            e.ends_with("cookie: is too large (4 bytes, at most 3)"),
            "{e}"
        );
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o640)).unwrap();
        let e = read_private(&p, 4).unwrap_err().to_string();
        assert!(
            e.ends_with(&format!(
                "cookie: can be read by other users (mode 0640); fix it with: chmod 600 {}",
                p.display()
            )),
            "{e}"
        );
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o620)).unwrap();
        let e = read_private(&p, 4).unwrap_err().to_string();
        assert!(
            e.contains("can be changed by other users (mode 0620)"),
            "{e}"
        );
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o400)).unwrap();
        assert_eq!(read_private(&p, 4).unwrap(), b"abc\n");
        // a symbolic link is not followed, even to a good file
        symlink(&p, t.path().join("link")).unwrap();
        let e = read_private(&t.path().join("link"), 4).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Fs {
                    errno: Some(libc::ELOOP),
                    ..
                }
            ),
            "{e}"
        );
        assert!(e
            .to_string()
            .ends_with("link: is a symbolic link (not followed: name the file itself)"));
        // a FIFO is refused at once, a folder too
        let fifo = t.path().join("fifo");
        rustix::fs::mknodat(
            rfs::CWD,
            &fifo,
            rfs::FileType::Fifo,
            Mode::from_raw_mode(0o600),
            0,
        )
        .unwrap();
        let e = read_private(&fifo, 4).unwrap_err().to_string();
        assert!(
            e.ends_with("fifo: is a FIFO (named pipe), not a regular file"),
            "{e}"
        );
        let e = read_private(t.path(), 4).unwrap_err().to_string();
        assert!(e.ends_with(": is a directory, not a regular file"), "{e}");
        let e = read_private(&t.path().join("none"), 4).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Fs {
                    errno: Some(libc::ENOENT),
                    ..
                }
            ),
            "{e}"
        );
        if rustix::process::geteuid().is_root() {
            std::os::unix::fs::chown(&p, Some(65534), None).unwrap();
            let e = read_private(&p, 4).unwrap_err().to_string();
            assert!(
                e.ends_with("cookie: belongs to user 65534, not to this user (0)"),
                "{e}"
            );
        }
    }

    /// A TLS folder `tls` (0700) holding `ca.pem`, `node.pem` (0644) and `node.key` (0600).
    fn tls_folder(parent: &Path) -> PathBuf {
        let d = parent.join("tls");
        std::fs::create_dir(&d).unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        for (name, mode) in [("ca.pem", 0o644), ("node.pem", 0o644), ("node.key", 0o600)] {
            std::fs::write(d.join(name), name).unwrap();
            std::fs::set_permissions(d.join(name), std::fs::Permissions::from_mode(mode)).unwrap();
        }
        d
    }

    fn check_tls(d: &Path) -> Result<(), Error> {
        let dir = trusted_dir(d)?;
        dir.check_trusted_file("ca.pem", Secrecy::Public)?;
        dir.check_trusted_file("node.pem", Secrecy::Public)?;
        dir.check_trusted_file("node.key", Secrecy::Private)
    }

    #[test]
    fn a_trusted_folder_is_closed_to_others_all_the_way_from_the_root() {
        // in the build's folder: every folder above it is closed to others, or sticky (/tmp)
        let t = tempfile::tempdir_in(concat!(env!("CARGO_MANIFEST_DIR"), "/../target")).unwrap();
        std::fs::set_permissions(t.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let d = tls_folder(t.path());
        check_tls(&d).unwrap();
        // this user's links on the way are followed, and what they lead through is checked
        symlink(&d, t.path().join("via")).unwrap();
        check_tls(&t.path().join("via")).unwrap();
        // a folder anyone can write in on the way: refused, also through a link; with the
        // sticky bit (as /tmp) others cannot rename or remove what is not theirs: accepted
        let shared = t.path().join("shared");
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o777)).unwrap();
        let open = tls_folder(&shared);
        let e = check_tls(&open).unwrap_err().to_string();
        assert!(
            e.contains(" can be changed by other users (mode 0777), who could swap"),
            "{e}"
        );
        symlink(&open, t.path().join("to_shared")).unwrap();
        let e = check_tls(&t.path().join("to_shared"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("is on the way to "), "{e}");
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
        check_tls(&open).unwrap();
        check_tls(&t.path().join("to_shared")).unwrap();
        // the folder, then each file
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o770)).unwrap();
        let e = check_tls(&d).unwrap_err().to_string();
        let shown = d.display();
        assert_eq!(
            e,
            format!("{shown}: can be changed by other users; fix it with: chmod 700 {shown}")
        );
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        let key = d.join("node.key");
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o640)).unwrap();
        let e = check_tls(&d).unwrap_err().to_string();
        assert!(
            e.ends_with(&format!(
                "node.key: can be read by other users; fix it with: chmod 600 {}",
                key.display()
            )),
            "{e}"
        );
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        std::fs::set_permissions(d.join("ca.pem"), std::fs::Permissions::from_mode(0o666)).unwrap();
        let e = check_tls(&d).unwrap_err().to_string();
        assert!(
            e.contains("ca.pem: can be changed by other users; fix it with: chmod go-w"),
            "{e}"
        );
        std::fs::set_permissions(d.join("ca.pem"), std::fs::Permissions::from_mode(0o644)).unwrap();
        std::fs::rename(d.join("node.pem"), t.path().join("node.pem")).unwrap();
        symlink(t.path().join("node.pem"), d.join("node.pem")).unwrap();
        let e = check_tls(&d).unwrap_err().to_string();
        assert!(e.ends_with("node.pem: is a symbolic link, not a regular file (put the file itself in the folder)"), "{e}");
        std::fs::remove_file(d.join("node.pem")).unwrap();
        std::fs::rename(t.path().join("node.pem"), d.join("node.pem")).unwrap();
        check_tls(&d).unwrap();
        if rustix::process::geteuid().is_root() {
            // another user's folder on the way, another user's file
            std::os::unix::fs::chown(t.path(), Some(65534), None).unwrap();
            let e = check_tls(&d).unwrap_err().to_string();
            assert!(
                e.contains("and belongs to user 65534, who could swap what is in it"),
                "{e}"
            );
            std::os::unix::fs::chown(t.path(), Some(0), None).unwrap();
            std::os::unix::fs::chown(d.join("node.key"), Some(65534), None).unwrap();
            let e = check_tls(&d).unwrap_err().to_string();
            assert!(
                e.ends_with(
                    "node.key: belongs to user 65534, not to you: use a folder of your own"
                ),
                "{e}"
            );
        }
    }

    #[test]
    fn folders_are_reached_through_own_links_only() {
        let t = tempfile::tempdir().unwrap();
        let real = t.path().join("real");
        std::fs::create_dir(&real).unwrap();
        // this user's links are followed, relative and absolute, `..` included
        symlink("real", t.path().join("rel")).unwrap();
        symlink(&real, t.path().join("abs")).unwrap();
        std::fs::create_dir(real.join("sub")).unwrap();
        symlink("../real/sub/..", real.join("up")).unwrap();
        for via in ["rel", "abs", "real/up", "rel/sub/../up"] {
            let p = t.path().join(via).join("x.json");
            write_path(&p, via.as_bytes(), None, Replace::Yes).unwrap();
            assert_eq!(std::fs::read(real.join("x.json")).unwrap(), via.as_bytes());
        }
        let e = Dir::open_nofollow(&t.path().join("rel"))
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("rel: is a symbolic link, not a folder"), "{e}");
        // a loop ends
        symlink("loop", t.path().join("loop")).unwrap();
        assert!(Dir::open(&t.path().join("loop")).is_err());
        // another user's link is not followed
        let theirs = t.path().join("theirs");
        symlink(&real, &theirs).unwrap();
        if rustix::process::geteuid().is_root() {
            rfs::chownat(
                rfs::CWD,
                &theirs,
                Some(rustix::process::Uid::from_raw(65534)),
                None,
                AtFlags::SYMLINK_NOFOLLOW,
            )
            .unwrap();
            let e = write_path(&theirs.join("y.json"), b"1", None, Replace::Yes)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("goes through a symbolic link (theirs) that belongs to user 65534"),
                "{e}"
            );
            assert!(!real.join("y.json").exists());
        }
    }
}
