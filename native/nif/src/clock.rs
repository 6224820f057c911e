//! CPU time, which the OS gives other programs none of: the calling scheduler thread's (what a
//! process that paces its own work, the live preview's server, spent) and the whole OS
//! process's (what a kernel render's threads spent, for benchmarks on a shared machine).

/// Microseconds of CPU time the calling thread has used (`CLOCK_THREAD_CPUTIME_ID`).
#[rustler::nif]
fn thread_cpu_us() -> i64 {
    cpu_us(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// Microseconds of CPU time every thread of the OS process has used (`CLOCK_PROCESS_CPUTIME_ID`).
#[rustler::nif]
fn process_cpu_us() -> i64 {
    cpu_us(libc::CLOCK_PROCESS_CPUTIME_ID)
}

/// The clock's reading in microseconds, -1 if it cannot be read.
fn cpu_us(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock ids used are constants Linux knows.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    if rc != 0 {
        return -1;
    }
    ts.tv_sec * 1_000_000 + ts.tv_nsec / 1_000
}
