//! Test data: a xorshift generator the kernel's tests share.

/// The next value of the xorshift sequence in `seed`, in [-1, 1) (24 bits).
pub(crate) fn rng(seed: &mut u64) -> f32 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
}
