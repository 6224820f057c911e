//! The CPU time of the calling scheduler thread: what a process that paces its own work (the
//! live preview's server) spent, without the time the OS gave the core to other programs.

/// Microseconds of CPU time the calling thread has used (`CLOCK_THREAD_CPUTIME_ID`).
#[rustler::nif]
fn thread_cpu_us() -> i64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant Linux knows.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return -1;
    }
    ts.tv_sec * 1_000_000 + ts.tv_nsec / 1_000
}
