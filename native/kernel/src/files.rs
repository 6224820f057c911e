//! The files a scene may read.
//!
//! Two rules, for the scene file itself and for every file it references (TOML `mesh` files,
//! OBJ `mtllib`s):
//! - [`read_regular`]: only a regular file is read, never a FIFO (which would block forever),
//!   a device, a socket or a directory, and nothing of the kernel's pseudo-filesystems
//!   (`/proc/self/environ`, `/sys/...`); its size is checked against a bound before a byte is
//!   read, and no more than the bound is read even if the file grows meanwhile. The checks are
//!   made on the open file (`fstat`, `fstatfs`), opened non-blocking.
//! - [`Confinement`]: a file a scene references must lie, after every `..` and symbolic link
//!   is resolved, inside one of a set of folders (the scene's own, and any the user allows).
//!   `../../etc/passwd`, `/etc/shadow` and a symbolic link out of the folder are refused, with
//!   a message naming the reference as written and where it leads. The folders are held open
//!   as descriptors, and a file is opened beneath one of them by the kernel in one call
//!   (`openat2` with `RESOLVE_BENEATH`), so a folder swapped for a symbolic link while a scene
//!   loads cannot lead the open outside. The scene's own folder is the one [`open_scene`]
//!   read the scene file in, held from that moment ([`Confinement::beneath`]): it is never
//!   looked up again by its name, so the folder (or a parent) swapped for a link between
//!   reading the scene and reading its meshes changes nothing.
//!
//! ```no_run
//! use ring_tracer_kernel::files::{open_scene, Confinement};
//! use ring_tracer_kernel::limits::MAX_FILE_BYTES;
//! use std::path::Path;
//! let scene = open_scene(Path::new("scenes/teapot.toml"), MAX_FILE_BYTES)?;
//! let confined = Confinement::beneath(scene.dir, ["more_meshes"])?;
//! let mesh = confined.read("meshes/teapot.obj");
//! assert!(confined.read("../../etc/passwd").is_err());
//! # Ok::<(), ring_tracer_kernel::Error>(())
//! ```
//!
//! Every check is made on the file opened (first with `O_PATH`, which has no effect on a
//! device or a FIFO; then reopened through `/proc/self/fd` for reading), never on a name
//! looked up again. A symbolic link inside an allowed folder that leads to a file inside one
//! (the same or another) is followed, as before; its target is then opened beneath that
//! folder, so a link swapped meanwhile is refused, not followed out. Needs Linux 5.6 or later
//! (`openat2`); an older kernel refuses every referenced file, saying so.

use crate::error::escape_bounded;
use crate::limits;
use crate::safe_fs::errno_text;
use crate::Error;
use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Component, Path, PathBuf};

/// Why a file a scene references could not be had, as a resolver (see
/// [`crate::Scene::parse`]) says it. The two cases differ: a missing OBJ material library
/// falls back to a grey material, a refused one stops the load.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Unreadable {
    /// There is no such file (or it was not shipped with the scene).
    #[error("{0}")]
    Missing(String),
    /// The file is there but may not be read: outside the allowed folders, not a regular
    /// file, on a pseudo-filesystem, too large, or unreadable.
    #[error("{0}")]
    Refused(String),
}

/// A resolver's own message (a test's, a fuzz driver's) counts as a missing file.
impl From<String> for Unreadable {
    fn from(message: String) -> Self {
        Unreadable::Missing(message)
    }
}

impl From<&str> for Unreadable {
    fn from(message: &str) -> Self {
        Unreadable::Missing(message.to_string())
    }
}

/// At most this many characters of a path or reference are shown in a message.
const PATH_CHARS: usize = 1024;

/// Folders of the kernel's pseudo-filesystems: nothing under them is read, whatever `fstatfs`
/// says (some sandboxes, gVisor among them, may report another filesystem type).
const PSEUDO_DIRS: [&str; 2] = ["/proc", "/sys"];

/// `bytes` without the UTF-8 byte order mark some editors put first: a scene or mesh is read
/// the same with it or without.
pub(crate) fn without_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// A path or reference as messages show it: escaped, bounded.
fn shown(path: &Path) -> String {
    escape_bounded(&path.to_string_lossy(), PATH_CHARS)
}

fn io_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Io {
        file: shown(path),
        message: message.into(),
    }
}

/// The pseudo-filesystem a file is on (by `fstatfs`), if any.
#[cfg(target_os = "linux")]
fn pseudo_filesystem(file: &File) -> Result<Option<&'static str>, std::io::Error> {
    use std::os::fd::AsRawFd;
    // SAFETY: `statfs` is plain old data, fully written by a successful `fstatfs`; the file
    // descriptor is open for the duration of the call.
    let st = unsafe {
        let mut st: libc::statfs = std::mem::zeroed();
        if libc::fstatfs(file.as_raw_fd(), &mut st) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        st
    };
    let known = [
        (libc::PROC_SUPER_MAGIC, "proc"),
        (libc::SYSFS_MAGIC, "sysfs"),
        (libc::DEBUGFS_MAGIC, "debugfs"),
        (libc::TRACEFS_MAGIC, "tracefs"),
        (libc::SECURITYFS_MAGIC, "securityfs"),
        (libc::CGROUP2_SUPER_MAGIC, "cgroup2"),
        (libc::BPF_FS_MAGIC, "bpf"),
    ];
    Ok(known
        .iter()
        .find(|(magic, _)| st.f_type == *magic)
        .map(|(_, name)| *name))
}

/// Elsewhere only the path rule ([`PSEUDO_DIRS`]) applies.
#[cfg(not(target_os = "linux"))]
fn pseudo_filesystem(_file: &File) -> Result<Option<&'static str>, std::io::Error> {
    Ok(None)
}

/// Where an open descriptor leads, as the kernel says (`/proc/self/fd/N`).
fn fd_path(fd: &OwnedFd) -> Option<PathBuf> {
    std::fs::read_link(format!("/proc/self/fd/{}", fd.as_raw_fd())).ok()
}

/// Checks a file opened with `O_PATH` (named `path` in messages): a regular file, not under
/// [`PSEUDO_DIRS`] (by where the descriptor leads: `real`), then reopens that very file
/// through `/proc/self/fd` read-only and non-blocking (a FIFO never blocks the open) and
/// checks the open file too: the same file, not on a pseudo-filesystem. Returns it with its
/// size.
fn open_found(path: &Path, found: &OwnedFd, real: &Path) -> Result<(File, u64), Error> {
    if let Some(dir) = PSEUDO_DIRS.iter().find(|d| real.starts_with(d)) {
        return Err(io_error(
            path,
            format!(
                "is {}, under {dir}: not a file a scene may read",
                shown(real)
            ),
        ));
    }
    let meta = rustix::fs::fstat(found).map_err(|e| io_error(path, errno_text(e)))?;
    let kind = rustix::fs::FileType::from_raw_mode(meta.st_mode);
    if kind != rustix::fs::FileType::RegularFile {
        return Err(not_regular(path, kind));
    }
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC | libc::O_NOCTTY)
        .open(format!("/proc/self/fd/{}", found.as_raw_fd()))
        .map_err(|e| io_error(path, e.to_string()))?;
    let again = file.metadata().map_err(|e| io_error(path, e.to_string()))?;
    {
        use std::os::unix::fs::MetadataExt;
        if again.dev() != meta.st_dev || again.ino() != meta.st_ino {
            return Err(io_error(path, "changed while it was opened"));
        }
    }
    checked_open_file(path, file, again)
}

/// The checks on an open file, given its metadata (from `fstat`: the file opened, not
/// whatever the name points to now): a regular file, not on a pseudo-filesystem.
fn checked_open_file(
    path: &Path,
    file: File,
    meta: std::fs::Metadata,
) -> Result<(File, u64), Error> {
    use std::os::unix::fs::MetadataExt;
    if !meta.file_type().is_file() {
        return Err(not_regular(
            path,
            rustix::fs::FileType::from_raw_mode(meta.mode()),
        ));
    }
    match pseudo_filesystem(&file) {
        Ok(None) => {}
        Ok(Some(fs)) => {
            return Err(io_error(
                path,
                format!("is on the kernel's {fs} filesystem, not a file a scene may read"),
            ))
        }
        Err(e) => return Err(io_error(path, e.to_string())),
    }
    Ok((file, meta.len()))
}

/// Opens `path` read-only and non-blocking, refusing a symbolic link as its last component,
/// and checks the open file (see [`checked_open_file`]).
#[cfg(test)]
fn open_checked(path: &Path) -> Result<(File, u64), Error> {
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC | libc::O_NOCTTY | libc::O_NOFOLLOW)
        .open(path)
        .map_err(|e| io_error(path, e.to_string()))?;
    let meta = file.metadata().map_err(|e| io_error(path, e.to_string()))?;
    checked_open_file(path, file, meta)
}

/// Why a file that is not a regular file (its type from `fstat`) is refused, naming what it
/// is where it can.
fn not_regular(path: &Path, kind: rustix::fs::FileType) -> Error {
    io_error(
        path,
        format!(
            "is {}, not a regular file",
            crate::safe_fs::kind_words(kind)
        ),
    )
}

/// Reads at most `max_bytes` of an open, checked file of `size` bytes.
fn read_bounded(path: &Path, file: File, size: u64, max_bytes: u64) -> Result<Vec<u8>, Error> {
    let over = |value: u64| {
        limits::check_with(
            format!("the size of {}", shown(path)),
            value,
            " bytes",
            max_bytes,
            "MAX_FILE_BYTES",
            limits::RAISE,
        )
    };
    over(size)?;
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(size as usize)
        .map_err(|e| io_error(path, e.to_string()))?;
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| io_error(path, e.to_string()))?;
    over(bytes.len() as u64)?;
    Ok(bytes)
}

/// Reads a regular file of at most `max_bytes` bytes (normally [`limits::MAX_FILE_BYTES`]).
///
/// Refused, each with a message naming the path and why: a path that does not exist, anything
/// but a regular file (a FIFO, a device, a socket, a directory: named in the message), a file
/// under `/proc` or `/sys` or on one of the kernel's pseudo-filesystems, and a file larger
/// than `max_bytes` ([`Error::Limit`], checked before reading; at most `max_bytes + 1` bytes
/// are ever read, so a file that grows is still bounded). The open is non-blocking, so a FIFO
/// swapped in after the checks does not hang the caller either.
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, Error> {
    read_regular_with_path(path, max_bytes).map(|(bytes, _)| bytes)
}

/// [`read_regular`], also returning the canonical absolute path of the file read (every
/// symbolic link and `..` resolved, as the kernel says of the descriptor read), e.g. so that
/// an output file never overwrites an input. The name is resolved once (`O_PATH`, symbolic
/// links followed: this is a path the user named); every check is made on what was opened.
pub fn read_regular_with_path(path: &Path, max_bytes: u64) -> Result<(Vec<u8>, PathBuf), Error> {
    let found = rustix::fs::open(
        path,
        rustix::fs::OFlags::PATH | rustix::fs::OFlags::CLOEXEC,
        rustix::fs::Mode::empty(),
    )
    .map_err(|e| io_error(path, std::io::Error::from(e).to_string()))?;
    let canonical = match fd_path(&found) {
        Some(p) => p,
        None => std::fs::canonicalize(path).map_err(|e| io_error(path, e.to_string()))?,
    };
    let (file, size) = open_found(path, &found, &canonical)?;
    Ok((read_bounded(path, file, size, max_bytes)?, canonical))
}

/// A scene file the user named, read, and the folder it is in, held open: the root its
/// references are confined to ([`Confinement::beneath`]).
#[derive(Debug)]
pub struct SceneFile {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// Its canonical absolute path, as the kernel says of the descriptor read.
    pub path: PathBuf,
    /// The folder it was opened in (`O_PATH`): the very folder, whatever its name leads to
    /// later.
    pub dir: OwnedFd,
}

/// Reads the scene file `path` as [`read_regular_with_path`] does, and keeps the folder it
/// is in open. The folder `path` names is opened once (following the path the user gave);
/// the file is opened beneath that descriptor with `O_NOFOLLOW`. When the file is a symbolic
/// link, its target is taken from that descriptor (`readlinkat`) and opened the same way,
/// from the folder the link is in (at most 40 links): the folder held at the end is the one
/// the file read is in, reached through descriptors only, never looked up again by name.
pub fn open_scene(path: &Path, max_bytes: u64) -> Result<SceneFile, Error> {
    use rustix::fs::{FileType, Mode, OFlags};
    use std::os::unix::ffi::OsStrExt;
    let sys = |e: rustix::io::Errno| io_error(path, errno_text(e));
    let dir_flags = OFlags::PATH | OFlags::DIRECTORY | OFlags::CLOEXEC;
    // the folder and name of a path (`a.nff` is in `.`)
    let split = |p: &Path| -> Result<(PathBuf, std::ffi::OsString), Error> {
        let name = match p.components().next_back() {
            Some(Component::Normal(n)) => n.to_os_string(),
            _ => return Err(io_error(path, "is not a file name")),
        };
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        Ok((dir, name))
    };
    let (first, mut name) = split(path)?;
    let mut dir = rustix::fs::open(&first, dir_flags, Mode::empty()).map_err(|e| match e {
        rustix::io::Errno::NOTDIR => io_error(path, "its folder is not a folder"),
        e => sys(e),
    })?;
    let mut links = 0;
    let found = loop {
        let found = rustix::fs::openat(
            &dir,
            name.as_os_str(),
            OFlags::PATH | OFlags::NOFOLLOW | OFlags::CLOEXEC,
            Mode::empty(),
        )
        .map_err(sys)?;
        let st = rustix::fs::fstat(&found).map_err(sys)?;
        if FileType::from_raw_mode(st.st_mode) != FileType::Symlink {
            break found;
        }
        links += 1;
        if links > 40 {
            return Err(sys(rustix::io::Errno::LOOP));
        }
        let target = rustix::fs::readlinkat(&found, "", Vec::new()).map_err(sys)?;
        let target = PathBuf::from(std::ffi::OsStr::from_bytes(target.as_bytes()));
        let (tdir, tname) = split(&target)?;
        // relative to the folder the link is in (an absolute target ignores it)
        dir = rustix::fs::openat(&dir, &tdir, dir_flags, Mode::empty()).map_err(sys)?;
        name = tname;
    };
    let real = fd_path(&found).ok_or_else(|| io_error(path, "where it leads cannot be told"))?;
    let (file, size) = open_found(path, &found, &real)?;
    let bytes = read_bounded(path, file, size, max_bytes)?;
    Ok(SceneFile {
        bytes,
        path: real,
        dir,
    })
}

/// `path` with `.` and `..` resolved by the text alone (no symbolic link followed).
fn lexical(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// The folders whose files a scene may reference: the scene's own folder first, then any the
/// user allows. Held open (descriptors) and by their canonical paths (absolute, symbolic
/// links resolved: where the descriptors lead).
#[derive(Debug)]
pub struct Confinement {
    roots: Vec<PathBuf>,
    fds: Vec<OwnedFd>,
}

/// Opens a file beneath `root`: `rel` (relative, no `..` left in it) is resolved by the
/// kernel, symbolic links included, and may not leave `root` (`RESOLVE_BENEATH`, no `/proc`
/// magic links).
fn open_beneath(root: &OwnedFd, rel: &Path) -> Result<OwnedFd, rustix::io::Errno> {
    use rustix::fs::{Mode, OFlags, ResolveFlags};
    let rel = if rel.as_os_str().is_empty() {
        Path::new(".")
    } else {
        rel
    };
    loop {
        match rustix::fs::openat2(
            root,
            rel,
            OFlags::PATH | OFlags::CLOEXEC,
            Mode::empty(),
            ResolveFlags::BENEATH | ResolveFlags::NO_MAGICLINKS,
        ) {
            // the kernel asks for a retry when a rename raced the lookup
            Err(rustix::io::Errno::AGAIN) | Err(rustix::io::Errno::INTR) => continue,
            other => return other,
        }
    }
}

impl Confinement {
    /// The folders `roots`, the first being the scene's own (messages call it so). Each must
    /// exist and be a directory; each is opened once, here, following the path given.
    pub fn new<P: AsRef<Path>>(roots: impl IntoIterator<Item = P>) -> Result<Confinement, Error> {
        let mut confinement = Confinement {
            roots: Vec::new(),
            fds: Vec::new(),
        };
        for r in roots {
            let r = r.as_ref();
            let fd = rustix::fs::open(
                r,
                rustix::fs::OFlags::PATH
                    | rustix::fs::OFlags::DIRECTORY
                    | rustix::fs::OFlags::CLOEXEC,
                rustix::fs::Mode::empty(),
            )
            .map_err(|e| match e {
                rustix::io::Errno::NOTDIR => io_error(r, "is not a folder"),
                e => io_error(r, std::io::Error::from(e).to_string()),
            })?;
            confinement.push(r, fd)?;
        }
        Ok(confinement)
    }

    /// The scene's folder as a descriptor already open (see [`open_scene`]: the folder the
    /// scene file was read in), then the folders `allow` (opened here by their names).
    pub fn beneath<P: AsRef<Path>>(
        scene_dir: OwnedFd,
        allow: impl IntoIterator<Item = P>,
    ) -> Result<Confinement, Error> {
        let mut confinement = Confinement {
            roots: Vec::new(),
            fds: Vec::new(),
        };
        confinement.push(Path::new("the scene's folder"), scene_dir)?;
        let more = Confinement::new(allow)?;
        confinement.roots.extend(more.roots);
        confinement.fds.extend(more.fds);
        Ok(confinement)
    }

    /// Adds a folder held open, known by where its descriptor leads (`named` in messages).
    fn push(&mut self, named: &Path, fd: OwnedFd) -> Result<(), Error> {
        let canonical =
            fd_path(&fd).ok_or_else(|| io_error(named, "where it leads cannot be told"))?;
        self.roots.push(canonical);
        self.fds.push(fd);
        Ok(())
    }

    /// The canonical folders, the scene's first.
    pub fn roots(&self) -> &[PathBuf] {
        &self.roots
    }

    /// Whether a canonical path lies in one of the folders (component by component: `/a/bc`
    /// is not inside `/a/b`).
    pub fn contains(&self, canonical: &Path) -> bool {
        self.roots.iter().any(|r| canonical.starts_with(r))
    }

    fn outside(&self, reference: &str, to: &Path, how: &str) -> String {
        let mut folders = match self.roots.split_first() {
            None => "outside every allowed folder (there are none)".to_string(),
            Some((scene, [])) => format!("outside the scene's folder {}", shown(scene)),
            Some((scene, more)) => format!(
                "outside the scene's folder {} and the allowed folders {}",
                shown(scene),
                more.iter().map(|p| shown(p)).collect::<Vec<_>>().join(", ")
            ),
        };
        folders.push_str(" (allow it with --allow-dir)");
        format!(
            "'{}' resolves to {}{how}, {folders}",
            escape_bounded(reference, PATH_CHARS),
            shown(to)
        )
    }

    /// Opens `path` (absolute, lexically clean) beneath the first folder whose text contains
    /// it. `None` when no folder does.
    fn open_in_roots(&self, path: &Path) -> Option<Result<OwnedFd, rustix::io::Errno>> {
        let (i, root) = self
            .roots
            .iter()
            .enumerate()
            .find(|(_, r)| path.starts_with(r))?;
        let rel = path.strip_prefix(root).unwrap_or(Path::new(""));
        Some(open_beneath(&self.fds[i], rel))
    }

    /// Opens a reference (see [`Confinement::resolve`]) with `O_PATH`, beneath an allowed
    /// folder; returns it and where it leads.
    fn open(&self, reference: &str) -> Result<(OwnedFd, PathBuf), Unreadable> {
        use rustix::io::Errno;
        use Unreadable::{Missing, Refused};
        let quoted = escape_bounded(reference, PATH_CHARS);
        if reference.is_empty() {
            return Err(Refused("'' is an empty file name".to_string()));
        }
        // relative to the scene's folder: the text of where its descriptor leads, so that
        // the part under it is opened beneath that very descriptor
        let Some(base) = self.roots.first() else {
            return Err(Refused(self.outside(reference, Path::new(reference), "")));
        };
        let written = lexical(&base.join(reference));
        let missing = || Missing(format!("'{quoted}' does not exist ({})", shown(&written)));
        let other = |e: Errno| {
            Refused(format!(
                "'{quoted}': {}: {}",
                shown(&written),
                errno_text(e)
            ))
        };
        let fail = |e: Errno| match e {
            Errno::NOENT => missing(),
            Errno::NOSYS => Refused(no_openat2(&quoted)),
            e => other(e),
        };
        let Some(first) = self.open_in_roots(&written) else {
            return Err(Refused(self.outside(reference, &written, "")));
        };
        let found = match first {
            Ok(fd) => fd,
            // a symbolic link leaves that folder (or is absolute): allowed only if where it
            // leads now is in an allowed folder, and then opened beneath that one
            Err(Errno::XDEV) | Err(Errno::LOOP) => {
                let canonical = std::fs::canonicalize(&written).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::NotFound {
                        missing()
                    } else {
                        Refused(format!("'{quoted}': {}: {e}", shown(&written)))
                    }
                })?;
                let through = " (through a symbolic link)";
                match self.open_in_roots(&canonical) {
                    None => return Err(Refused(self.outside(reference, &canonical, through))),
                    Some(Ok(fd)) => fd,
                    Some(Err(Errno::XDEV)) | Some(Err(Errno::LOOP)) => {
                        return Err(Refused(format!(
                            "'{quoted}' changed while it was opened (a symbolic link on the way \
                             leads out of the allowed folders)"
                        )))
                    }
                    Some(Err(e)) => return Err(fail(e)),
                }
            }
            Err(e) => return Err(fail(e)),
        };
        let real = fd_path(&found)
            .ok_or_else(|| Refused(format!("'{quoted}': where it leads cannot be told")))?;
        if !self.contains(&real) {
            return Err(Refused(self.outside(
                reference,
                &real,
                " (through a symbolic link)",
            )));
        }
        Ok((found, real))
    }

    /// Where a reference written in a scene (or in a file it references) leads: relative ones
    /// are taken from the scene's folder (the first, held open: the part of the reference
    /// under it is opened beneath that descriptor, never by the folder's name), absolute ones
    /// as they are; `..` and symbolic links are resolved. The canonical path must lie inside one of the folders; the error names the
    /// reference as written and why, e.g. `'../../etc/passwd' resolves to /etc/passwd,
    /// outside the scene's folder /x/y (allow it with --allow-dir)` or `'m.obj' does not
    /// exist (/x/y/m.obj)`. A reference that leaves the folders by its text alone is refused
    /// before anything on disk is looked at (so whether a file exists outside is not told).
    /// `..` is taken by the text (`a/../b` is `b`, whatever `a` is); the rest is resolved by
    /// the kernel beneath an allowed folder.
    pub fn resolve(&self, reference: &str) -> Result<PathBuf, Unreadable> {
        self.open(reference).map(|(_, path)| path)
    }

    /// Reads a referenced file: opened as [`Confinement::resolve`] says, then read as
    /// [`read_regular`] does with [`limits::MAX_FILE_BYTES`], every check made on the file
    /// opened. Returns the bytes and the canonical path read.
    pub fn read(&self, reference: &str) -> Result<(Vec<u8>, PathBuf), Unreadable> {
        let (found, real) = self.open(reference)?;
        let refused = |e: Error| Unreadable::Refused(e.to_string());
        let (file, size) = open_found(&real, &found, &real).map_err(refused)?;
        let bytes = read_bounded(&real, file, size, limits::MAX_FILE_BYTES).map_err(refused)?;
        Ok((bytes, real))
    }
}

/// Why nothing can be opened confined on a kernel without `openat2`.
fn no_openat2(quoted: &str) -> String {
    format!(
        "'{quoted}': this system cannot open a file confined to a folder (openat2 needs \
         Linux 5.6 or later); ship the file with the scene instead"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;
    use std::time::{Duration, Instant};

    /// The message of a refusal (and that it is one).
    fn refused(e: Unreadable) -> String {
        match e {
            Unreadable::Refused(m) => m,
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    /// The message of a missing file (and that it is one).
    fn missing(e: Unreadable) -> String {
        match e {
            Unreadable::Missing(m) => m,
            other => panic!("expected a missing file, got {other:?}"),
        }
    }

    /// A temporary folder `root` holding `scene/m.obj` and `outside.txt`.
    fn tree() -> (tempfile::TempDir, PathBuf) {
        let t = tempfile::tempdir().unwrap();
        let scene = t.path().join("scene");
        std::fs::create_dir(&scene).unwrap();
        std::fs::write(scene.join("m.obj"), "v 0 0 0\n").unwrap();
        std::fs::write(t.path().join("outside.txt"), "secret\n").unwrap();
        (t, scene)
    }

    fn canon(p: &Path) -> PathBuf {
        std::fs::canonicalize(p).unwrap()
    }

    #[test]
    fn reads_inside_and_names_what_it_read() {
        let (_t, scene) = tree();
        let c = Confinement::new([&scene]).unwrap();
        let (bytes, path) = c.read("m.obj").unwrap();
        assert_eq!(bytes, b"v 0 0 0\n");
        assert_eq!(path, canon(&scene.join("m.obj")));
        std::fs::create_dir(scene.join("sub")).unwrap();
        assert_eq!(
            c.resolve("sub/../m.obj").unwrap(),
            canon(&scene.join("m.obj"))
        );
        let abs = canon(&scene.join("m.obj"));
        assert_eq!(c.resolve(abs.to_str().unwrap()).unwrap(), abs);
        let e = missing(c.resolve("nope.obj").unwrap_err());
        assert!(e.starts_with("'nope.obj' does not exist ("), "{e}");
    }

    #[test]
    fn dot_dot_escape_is_refused() {
        let (t, scene) = tree();
        let c = Confinement::new([&scene]).unwrap();
        let e = refused(c.resolve("../outside.txt").unwrap_err());
        let root = canon(t.path());
        assert_eq!(
            e,
            format!(
                "'../outside.txt' resolves to {}, outside the scene's folder {} (allow it with \
                 --allow-dir)",
                root.join("outside.txt").display(),
                canon(&scene).display()
            )
        );
        let e = refused(c.read("../../../../../../../../etc/passwd").unwrap_err());
        assert!(
            e.starts_with("'../../../../../../../../etc/passwd' resolves to /etc/passwd, outside"),
            "{e}"
        );
        // whether a file exists outside is not told
        let e = refused(c.resolve("../no_such_file").unwrap_err());
        assert!(e.contains("outside the scene's folder"), "{e}");
        // allowed with a second root
        let c2 = Confinement::new([scene.clone(), t.path().to_path_buf()]).unwrap();
        assert_eq!(c2.read("../outside.txt").unwrap().0, b"secret\n");
        let e = Confinement::new([scene.clone(), scene.join("sub_missing")]).unwrap_err();
        assert!(e.to_string().contains("sub_missing"), "{e}");
        let e = Confinement::new([scene.join("m.obj")]).unwrap_err();
        assert!(e.to_string().ends_with("is not a folder"), "{e}");
    }

    #[test]
    fn absolute_path_outside_is_refused() {
        let (_t, scene) = tree();
        let c = Confinement::new([&scene]).unwrap();
        for r in ["/etc/shadow", "/etc/passwd", "/proc/self/environ"] {
            let e = refused(c.read(r).unwrap_err());
            assert!(
                e.starts_with(&format!(
                    "'{r}' resolves to {r}, outside the scene's folder"
                )),
                "{e}"
            );
        }
    }

    #[test]
    fn symlinks_are_followed_and_must_stay_inside() {
        let (t, scene) = tree();
        let c = Confinement::new([&scene]).unwrap();
        symlink(t.path().join("outside.txt"), scene.join("out.obj")).unwrap();
        let e = refused(c.read("out.obj").unwrap_err());
        assert!(
            e.starts_with(&format!(
                "'out.obj' resolves to {} (through a symbolic link), outside the scene's folder",
                canon(&t.path().join("outside.txt")).display()
            )),
            "{e}"
        );
        symlink("/etc", scene.join("etc")).unwrap();
        let e = refused(c.read("etc/passwd").unwrap_err());
        assert!(
            e.contains("resolves to /etc/passwd (through a symbolic link)"),
            "{e}"
        );
        // a link inside pointing inside is fine
        std::fs::create_dir(scene.join("meshes")).unwrap();
        symlink("../m.obj", scene.join("meshes/alias.obj")).unwrap();
        let (bytes, path) = c.read("meshes/alias.obj").unwrap();
        assert_eq!(bytes, b"v 0 0 0\n");
        assert_eq!(path, canon(&scene.join("m.obj")));
        // the scene's folder given through a link is taken as what it points to
        symlink(&scene, t.path().join("scene_link")).unwrap();
        let c = Confinement::new([t.path().join("scene_link")]).unwrap();
        assert!(c.read("m.obj").is_ok());
    }

    #[test]
    fn a_scene_is_read_in_the_folder_held_and_its_links_are_followed_there() {
        let (t, scene) = tree();
        std::fs::write(scene.join("a.toml"), "x").unwrap();
        let got = open_scene(&scene.join("a.toml"), 1 << 20).unwrap();
        assert_eq!(got.bytes, b"x");
        assert_eq!(got.path, canon(&scene.join("a.toml")));
        let c = Confinement::beneath(got.dir, [t.path()]).unwrap();
        assert_eq!(c.roots(), [canon(&scene), canon(t.path())]);
        assert_eq!(c.read("m.obj").unwrap().0, b"v 0 0 0\n");
        // a scene named through links (relative, absolute, chained) is read where they lead,
        // and its folder is the one the file is in
        let other = t.path().join("other");
        std::fs::create_dir(&other).unwrap();
        symlink("../scene/a.toml", other.join("rel.toml")).unwrap();
        symlink(scene.join("a.toml"), t.path().join("abs.toml")).unwrap();
        symlink("other/rel.toml", t.path().join("chain.toml")).unwrap();
        for via in ["other/rel.toml", "abs.toml", "chain.toml"] {
            let got = open_scene(&t.path().join(via), 1 << 20).unwrap();
            assert_eq!(got.path, canon(&scene.join("a.toml")), "{via}");
            let c = Confinement::beneath(got.dir, Vec::<PathBuf>::new()).unwrap();
            assert_eq!(c.roots(), [canon(&scene)], "{via}");
            assert!(c.read("m.obj").is_ok(), "{via}");
        }
        symlink("loop.toml", t.path().join("loop.toml")).unwrap();
        let e = open_scene(&t.path().join("loop.toml"), 1 << 20).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("loop.toml: Too many levels of symbolic links"),
            "{e}"
        );
        let e = open_scene(&scene, 1 << 20).unwrap_err().to_string();
        assert!(
            e.ends_with("scene: is a directory, not a regular file"),
            "{e}"
        );
        let e = open_scene(&scene.join("none.toml"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("none.toml: No such file or directory"), "{e}");
        let e = open_scene(&scene.join("m.obj/x.toml"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("x.toml: its folder is not a folder"), "{e}");
        std::fs::write(scene.join("big.toml"), "12345").unwrap();
        assert!(open_scene(&scene.join("big.toml"), 4).is_err());
        // relative to the current folder
        let cwd = std::env::current_dir().unwrap();
        let rel = pathdiff(&scene.join("a.toml"), &cwd);
        assert_eq!(open_scene(&rel, 1 << 20).unwrap().bytes, b"x");
    }

    /// `path` relative to `from` (both absolute), through `..` as needed.
    fn pathdiff(path: &Path, from: &Path) -> PathBuf {
        let common = from
            .components()
            .zip(path.components())
            .take_while(|(a, b)| a == b)
            .count();
        let mut out = PathBuf::new();
        for _ in from.components().skip(common) {
            out.push("..");
        }
        for c in path.components().skip(common) {
            out.push(c);
        }
        out
    }

    #[test]
    fn prefix_of_a_name_is_not_inside() {
        let t = tempfile::tempdir().unwrap();
        let (b, bc) = (t.path().join("b"), t.path().join("bc"));
        std::fs::create_dir(&b).unwrap();
        std::fs::create_dir(&bc).unwrap();
        std::fs::write(bc.join("x.obj"), "v 0 0 0\n").unwrap();
        let c = Confinement::new([&b]).unwrap();
        assert!(!c.contains(&canon(&bc.join("x.obj"))));
        let e = refused(c.resolve("../bc/x.obj").unwrap_err());
        assert!(e.contains("outside the scene's folder"), "{e}");
        let abs = canon(&bc).join("x.obj");
        assert!(c.resolve(abs.to_str().unwrap()).is_err());
        assert!(Confinement::new([&bc]).unwrap().contains(&abs));
    }

    #[test]
    fn fifo_is_refused_promptly() {
        let t = tempfile::tempdir().unwrap();
        let fifo = t.path().join("pipe.obj");
        let c_path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
        let (tx, rx) = std::sync::mpsc::channel();
        let f = fifo.clone();
        let dir = t.path().to_path_buf();
        std::thread::spawn(move || {
            let read = read_regular(&f, 1 << 20).map(|_| ());
            // the open itself, as if the FIFO had been swapped in after the stat
            let open = open_checked(&f).map(|_| ());
            let confined = Confinement::new([&dir]).unwrap().read("pipe.obj");
            let _ = tx.send((read, open, confined.map(|_| ())));
        });
        let t0 = Instant::now();
        let (read, open, confined) = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("reading a FIFO must not block");
        assert!(t0.elapsed() < Duration::from_secs(10));
        for e in [read.unwrap_err(), open.unwrap_err()] {
            assert!(
                e.to_string()
                    .ends_with("pipe.obj: is a FIFO (named pipe), not a regular file"),
                "{e}"
            );
        }
        assert!(refused(confined.unwrap_err()).contains("is a FIFO"));
    }

    #[test]
    fn directories_devices_and_procfs_are_refused() {
        let t = tempfile::tempdir().unwrap();
        let e = read_regular(t.path(), 1 << 20).unwrap_err().to_string();
        assert!(e.ends_with(": is a directory, not a regular file"), "{e}");
        let e = read_regular(Path::new("/dev/null"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "/dev/null: is a character device, not a regular file");
        let e = open_checked(Path::new("/dev/null"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("character device"), "{e}");
        let e = read_regular(Path::new("/proc/self/environ"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/proc/self/environ: is /proc/"), "{e}");
        assert!(
            e.ends_with("under /proc: not a file a scene may read"),
            "{e}"
        );
        // the open file's filesystem is checked too (where /proc reports itself)
        if let Ok(Some("proc")) =
            File::open("/proc/self/environ").map(|f| pseudo_filesystem(&f).unwrap_or(None))
        {
            let e = open_checked(Path::new("/proc/self/environ"))
                .unwrap_err()
                .to_string();
            assert!(
                e.ends_with("is on the kernel's proc filesystem, not a file a scene may read"),
                "{e}"
            );
        }
        let e = read_regular(
            Path::new("/sys/kernel/mm/transparent_hugepage/enabled"),
            1 << 20,
        );
        assert!(e.is_err());
        // a link to /proc is followed, then refused
        symlink("/proc/self/environ", t.path().join("env.nff")).unwrap();
        let e = read_regular(&t.path().join("env.nff"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.contains("under /proc"), "{e}");
        let e = read_regular(&t.path().join("missing.nff"), 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.nff: No such file"), "{e}");
    }

    #[test]
    fn size_is_checked_before_reading() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("big.nff");
        std::fs::write(&p, vec![b'x'; 101]).unwrap();
        let e = read_regular(&p, 100).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Limit {
                    value: 101,
                    max: 100,
                    constant: "MAX_FILE_BYTES",
                    ..
                }
            ),
            "{e}"
        );
        let s = e.to_string();
        assert!(
            s.contains("big.nff is 101 bytes, more than the limit of 100 (limits::MAX_FILE_BYTES)"),
            "{s}"
        );
        assert_eq!(read_regular(&p, 101).unwrap().len(), 101);
        // a sparse file far over the bound is refused from its size, never read
        let huge = t.path().join("huge.obj");
        File::create(&huge)
            .unwrap()
            .set_len(limits::MAX_FILE_BYTES + 1)
            .unwrap();
        let t0 = Instant::now();
        assert!(read_regular(&huge, limits::MAX_FILE_BYTES).is_err());
        assert!(t0.elapsed() < Duration::from_secs(2));
    }

    #[test]
    fn references_are_escaped_in_messages() {
        let (_t, scene) = tree();
        let c = Confinement::new([&scene]).unwrap();
        let e = refused(c.resolve("../\x1b[31mred\n.obj").unwrap_err());
        assert!(
            e.starts_with("'../\\u{1b}[31mred\\n.obj' resolves to "),
            "{e}"
        );
        assert!(!e.contains('\x1b') && !e.contains('\n'), "{e}");
        assert_eq!(
            refused(c.resolve("").unwrap_err()),
            "'' is an empty file name"
        );
        let e = refused(c.read(".").unwrap_err());
        assert!(e.contains("is a directory"), "{e}");
    }
}
