//! Memory whose amount the input decides, claimed so that a scene too big for the memory at
//! hand is an [`Error::Memory`] naming the need, never an aborted process (through the NIF,
//! an aborted Erlang VM).
//!
//! Rust aborts the process when an allocation fails, so nothing that grows with the input may
//! be allocated the ordinary way:
//!
//! - the arrays of primitives, their shading data and the BVH's build arrays are reserved
//!   with `try_reserve` ([`try_reserve`], [`try_with_capacity`]), after a check that they fit
//!   in the address space left ([`check`]);
//! - before each stage of a BVH build, its need ([`limits::BVH_BYTES_PER_BOX`] per box, then
//!   [`limits::BVH_BYTES_PER_NODE`] per binary node) is checked the same way;
//! - the rest is bounded by the documented limits ([`crate::limits`]).
//!
//! "Left" is the process's `RLIMIT_AS` soft limit (`ulimit -v`, `prlimit --as`) less what it
//! has mapped already (`/proc/self/statm`), less [`limits::MEMORY_HEADROOM`] kept for everything
//! else that is allocated on the way (small arrays, the VM's own needs). Without a limit the
//! operating system decides: Linux normally overcommits, so a scene too big for the machine
//! is then refused only by the documented limits, or ends with the out-of-memory killer.
//!
//! [`limits::BVH_BYTES_PER_BOX`]: crate::limits::BVH_BYTES_PER_BOX
//! [`limits::BVH_BYTES_PER_NODE`]: crate::limits::BVH_BYTES_PER_NODE
//! [`limits::MEMORY_HEADROOM`]: crate::limits::MEMORY_HEADROOM

use crate::limits::MEMORY_HEADROOM;
use crate::Error;

/// Bytes of address space this process may still map under its `RLIMIT_AS` soft limit,
/// `None` if it has no such limit.
pub fn address_space_left() -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit only writes the struct it is handed, which lives for the call.
    if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut lim) } != 0
        || lim.rlim_cur == libc::RLIM_INFINITY
    {
        return None;
    }
    Some(lim.rlim_cur.saturating_sub(mapped_bytes()))
}

/// The process's mapped size (`VmSize`): the first field of `/proc/self/statm`, in pages.
/// 0 if it cannot be read (the checks then trust the limit alone, and `try_reserve` remains).
fn mapped_bytes() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(4096) as u64;
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_ascii_whitespace().next()?.parse::<u64>().ok())
        .map_or(0, |pages| pages.saturating_mul(page))
}

/// `Err(Error::Memory)` if `bytes` more (for `what`) would leave less than
/// [`MEMORY_HEADROOM`] of the address space left ([`address_space_left`]); `Ok` when the
/// process has no address-space limit.
pub fn check(what: impl FnOnce() -> String, bytes: u64) -> Result<(), Error> {
    match address_space_left() {
        Some(left) if bytes.saturating_add(MEMORY_HEADROOM) > left => Err(Error::Memory {
            what: what(),
            needed: bytes,
            why: format!(
                "more than the {} bytes of address space the process has left under its limit \
                 (RLIMIT_AS) less {MEMORY_HEADROOM} kept free (limits::MEMORY_HEADROOM)",
                left
            ),
        }),
        _ => Ok(()),
    }
}

/// Room in `v` for `additional` more items: [`check`]ed, then `try_reserve`d (amortized: a
/// full array doubles), so that neither a limit nor a failed allocation aborts. Does nothing
/// while there is room.
pub fn try_reserve<T>(
    v: &mut Vec<T>,
    additional: usize,
    what: impl Fn() -> String,
) -> Result<(), Error> {
    if v.capacity() - v.len() >= additional {
        return Ok(());
    }
    let wanted = v.len().saturating_add(additional).max(v.capacity() * 2);
    let bytes = (wanted as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    check(&what, bytes)?;
    v.try_reserve(additional).map_err(|_| failed(what(), bytes))
}

/// An empty vector with room for exactly `n` items, [`check`]ed and allocated fallibly.
pub fn try_with_capacity<T>(n: usize, what: impl Fn() -> String) -> Result<Vec<T>, Error> {
    let mut v = Vec::new();
    let bytes = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    check(&what, bytes)?;
    v.try_reserve_exact(n).map_err(|_| failed(what(), bytes))?;
    Ok(v)
}

/// The error for an allocation the system refused.
fn failed(what: String, needed: u64) -> Error {
    Error::Memory {
        what,
        needed,
        why: "and the system refused to allocate it".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_needs_pass_and_huge_ones_are_errors_not_aborts() {
        let mut v: Vec<u64> = Vec::new();
        try_reserve(&mut v, 10, || "ten".into()).unwrap();
        assert!(v.capacity() >= 10);
        // more than any address space: refused by the check or by the allocator, never an abort
        let n = usize::MAX / 64;
        let e = try_with_capacity::<[u8; 64]>(n, || "the test's array".into()).unwrap_err();
        let Error::Memory { what, needed, .. } = &e else {
            panic!("{e:?}")
        };
        assert_eq!(what, "the test's array");
        assert_eq!(*needed, n as u64 * 64);
        assert!(e.to_string().starts_with("the test's array needs "), "{e}");
        let mut w: Vec<[u8; 64]> = vec![[0; 64]];
        let e = try_reserve(&mut w, n, || "w".into()).unwrap_err();
        assert!(matches!(e, Error::Memory { .. }), "{e:?}");
        assert_eq!(w.len(), 1);
    }

    #[test]
    fn the_address_space_left_is_below_the_limit() {
        // the test process normally has no limit; when it has one, what is left is less
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: as in address_space_left
        assert_eq!(unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut lim) }, 0);
        match address_space_left() {
            None => assert_eq!(lim.rlim_cur, libc::RLIM_INFINITY),
            Some(left) => assert!(left < lim.rlim_cur),
        }
        assert!(mapped_bytes() > 0);
    }
}
