//! Files written race-free (`ring_tracer_kernel::safe_fs`): a folder opened once as a
//! descriptor (a resource the caller holds), everything else done relative to it.
//!
//! Errors come back as `{posix, message}`: `posix` the system's reason as `:file` names it
//! (`:eexist`, `:enospc`, ...; `:eio` for one without a name here; `nil` for a refusal that is
//! no system error), `message` in words.

use std::path::Path;

use ring_tracer_kernel::safe_fs::{self, Dir, Kept, Replace, Secrecy};
use ring_tracer_kernel::Error;
use rustler::{Atom, Binary, Env, OwnedBinary, ResourceArc};

use crate::convert::mode_arg;

rustler::atoms! { ok }

/// A folder held open. Dropped (closed) when Erlang lets go of the handle.
pub struct DirResource {
    pub dir: Dir,
}

#[rustler::resource_impl]
impl rustler::Resource for DirResource {}

type FsResult<'a, T> = Result<T, (Atom, String)>;

/// The `:file`-style reason of an errno; `nil` when there is none (the message says it all).
fn posix(env: Env, errno: Option<i32>) -> Atom {
    let name = match errno {
        None => "nil",
        Some(libc::EEXIST) => "eexist",
        Some(libc::ENOENT) => "enoent",
        Some(libc::EACCES) => "eacces",
        Some(libc::EPERM) => "eperm",
        Some(libc::ENOSPC) => "enospc",
        Some(libc::EDQUOT) => "edquot",
        Some(libc::EROFS) => "erofs",
        Some(libc::ENOTDIR) => "enotdir",
        Some(libc::EISDIR) => "eisdir",
        Some(libc::ELOOP) => "eloop",
        Some(libc::EXDEV) => "exdev",
        Some(libc::EMFILE) => "emfile",
        Some(libc::ENFILE) => "enfile",
        Some(libc::ENAMETOOLONG) => "enametoolong",
        Some(libc::EBUSY) => "ebusy",
        Some(libc::EINVAL) => "einval",
        Some(libc::EMLINK) => "emlink",
        Some(libc::ENOTEMPTY) => "enotempty",
        Some(_) => "eio",
    };
    Atom::from_str(env, name).unwrap_or_else(|_| ok())
}

fn fail(env: Env, e: Error) -> (Atom, String) {
    match e {
        Error::Fs { errno, message, .. } => (posix(env, errno), message),
        other => (posix(env, None), other.to_string()),
    }
}

/// Writes `data` to `path` atomically in the folder opened once (see
/// `safe_fs::Dir::write_file`). `mode`: the permissions of a new file (negative: `0o666` less
/// the umask); `replace`: false refuses an existing name (`:eexist`).
#[rustler::nif(schedule = "DirtyIo")]
fn fs_write<'a>(
    env: Env<'a>,
    path: String,
    data: Binary<'a>,
    mode: i64,
    replace: bool,
) -> FsResult<'a, Atom> {
    let replace = if replace { Replace::Yes } else { Replace::No };
    safe_fs::write_path(Path::new(&path), data.as_slice(), mode_arg(mode), replace)
        .map_err(|e| fail(env, e))?;
    Ok(ok())
}

/// Reads the secret file `path` (a cookie), which must be this user's, closed to others and
/// at most `max_bytes`: opened once without following a link or blocking, checked by `fstat`
/// and read through that descriptor (`safe_fs::read_private`).
#[rustler::nif(schedule = "DirtyIo")]
fn fs_read_private<'a>(env: Env<'a>, path: String, max_bytes: u64) -> FsResult<'a, Binary<'a>> {
    let bytes = safe_fs::read_private(Path::new(&path), max_bytes).map_err(|e| fail(env, e))?;
    Ok(OwnedBinary::from_slice(&bytes).release(env))
}

/// Checks a folder whose files another program reads later by name (a node's TLS folder):
/// every folder on the way and every link followed is this user's or root's and closed to
/// changes by others, the folder is this user's, `public` files are regular files nobody
/// else can change, `private` ones regular files of this user's closed to others
/// (`safe_fs::trusted_dir`, `Dir::check_trusted_file`). Errors are `{posix, file, message}`,
/// `file` the folder or file at fault.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_check_trusted(
    env: Env,
    path: String,
    public: Vec<String>,
    private: Vec<String>,
) -> Result<Atom, (Atom, String, String)> {
    let checked = safe_fs::trusted_dir(Path::new(&path)).and_then(|dir| {
        let public = public.iter().map(|n| (n, Secrecy::Public));
        let private = private.iter().map(|n| (n, Secrecy::Private));
        public
            .chain(private)
            .try_for_each(|(name, secrecy)| dir.check_trusted_file(name, secrecy))
    });
    checked.map_err(|e| match e {
        Error::Fs {
            file,
            errno,
            message,
        } => (posix(env, errno), file, message),
        other => (posix(env, None), path.clone(), other.to_string()),
    })?;
    Ok(ok())
}

/// `fs_write` into a folder held open (`fs_open_dir`), as `name` there.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_write_in<'a>(
    env: Env<'a>,
    dir: ResourceArc<DirResource>,
    name: String,
    data: Binary<'a>,
    mode: i64,
    replace: bool,
) -> FsResult<'a, Atom> {
    use std::io::Write;
    let replace = if replace { Replace::Yes } else { Replace::No };
    let target = dir.dir.path().join(&name);
    dir.dir
        .write_file(&name, mode_arg(mode), replace, |f| {
            f.write_all(data.as_slice()).map_err(|e| Error::Io {
                file: target.display().to_string(),
                message: e.to_string(),
            })
        })
        .map_err(|e| fail(env, e))?;
    Ok(ok())
}

/// Whether a new file can be made beside `path` (made for real in its folder, then removed).
#[rustler::nif(schedule = "DirtyIo")]
fn fs_probe(env: Env, path: String) -> FsResult<Atom> {
    safe_fs::open_parent(Path::new(&path))
        .and_then(|(dir, name)| dir.probe(&name))
        .map_err(|e| fail(env, e))?;
    Ok(ok())
}

/// Opens the folder `path` once.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_open_dir(env: Env, path: String) -> FsResult<ResourceArc<DirResource>> {
    let dir = Dir::open(Path::new(&path)).map_err(|e| fail(env, e))?;
    Ok(ResourceArc::new(DirResource { dir }))
}

/// Makes the private folder `path` (mode 0700 in one `mkdir`; an existing one taken when
/// `may_exist`), opens it without following a link and checks it by `fstat`: this user's,
/// closed to others.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_private_dir(env: Env, path: String, may_exist: bool) -> FsResult<ResourceArc<DirResource>> {
    let dir = safe_fs::private_dir(Path::new(&path), may_exist).map_err(|e| fail(env, e))?;
    Ok(ResourceArc::new(DirResource { dir }))
}

/// `/proc/self/fd/N` of a folder held open: names it in this OS process while held.
#[rustler::nif]
fn fs_dir_path(dir: ResourceArc<DirResource>) -> String {
    dir.dir.proc_path().to_string_lossy().into_owned()
}

/// Keeps what is at `name` in the folder as a hidden hard link (a symbolic link kept as
/// itself): `nil` when nothing is there, else the hidden name.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_keep(env: Env, dir: ResourceArc<DirResource>, name: String) -> FsResult<Option<String>> {
    match dir.dir.keep(&name).map_err(|e| fail(env, e))? {
        Kept::Nothing => Ok(None),
        Kept::Link(link) => Ok(Some(link)),
    }
}

fn kept(link: Option<String>) -> Kept {
    match link {
        None => Kept::Nothing,
        Some(l) => Kept::Link(l),
    }
}

/// Puts back at `name` what `fs_keep` kept (`nil`: removes `name`).
#[rustler::nif(schedule = "DirtyIo")]
fn fs_put_back(
    env: Env,
    dir: ResourceArc<DirResource>,
    name: String,
    link: Option<String>,
) -> FsResult<Atom> {
    dir.dir
        .put_back(&name, &kept(link))
        .map_err(|e| fail(env, e))?;
    Ok(ok())
}

/// Removes what `fs_keep` kept.
#[rustler::nif(schedule = "DirtyIo")]
fn fs_discard(env: Env, dir: ResourceArc<DirResource>, link: Option<String>) -> FsResult<Atom> {
    dir.dir.discard(&kept(link)).map_err(|e| fail(env, e))?;
    Ok(ok())
}
