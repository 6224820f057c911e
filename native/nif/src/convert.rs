//! Term conversions shared by the NIFs.

/// A new file's permission bits as the Elixir side gives them: a negative number for none
/// given (`0o666` less the umask is then used), else its permission bits.
pub fn mode_arg(mode: i64) -> Option<u32> {
    u32::try_from(mode).ok().map(|m| m & 0o777)
}

use ring_tracer_kernel::{Error, RayStats, Region, Settings};
use rustler::{Atom, Binary, Encoder, Env, NifMap, OwnedBinary, Term};
use std::borrow::Cow;

/// Render settings as the Elixir side sends them: a map with atom keys.
#[derive(NifMap)]
pub struct SettingsTerm {
    pub width: u32,
    pub height: u32,
    pub depth: u32,
    pub cutoff: f64,
    pub samples: u32,
    pub spd: bool,
    /// Only this part of the image, `{x0, y0, width, height}`, or nil.
    pub region: Option<(u32, u32, u32, u32)>,
}

impl SettingsTerm {
    /// The kernel's settings, validated against its limits.
    pub fn to_kernel(&self) -> Result<Settings, String> {
        let settings = Settings {
            width: self.width,
            height: self.height,
            depth: self.depth,
            cutoff: self.cutoff as f32,
            samples: self.samples,
            spd: self.spd,
            region: self.region.map(|(x0, y0, width, height)| Region {
                x0,
                y0,
                width,
                height,
            }),
        };
        settings.validate().map_err(|e| e.to_string())?;
        Ok(settings)
    }
}

/// Ray counters as a map with atom keys, the kernel's names ([`RayStats::counters`]).
pub struct RayStatsTerm(pub RayStats);

impl Encoder for RayStatsTerm {
    fn encode<'a>(&self, env: Env<'a>) -> Term<'a> {
        let pairs: Vec<(Atom, u64)> = self
            .0
            .counters()
            .iter()
            .map(|c| (atom(env, c.name), c.value))
            .collect();
        Term::map_from_pairs(env, &pairs).expect("distinct atom keys")
    }
}

impl From<RayStats> for RayStatsTerm {
    fn from(s: RayStats) -> Self {
        RayStatsTerm(s)
    }
}

/// The atom named `name` (created if new: the names come from the kernel, never from a term).
pub fn atom(env: Env, name: &str) -> Atom {
    Atom::from_str(env, name).expect("an atom name shorter than 256 characters")
}

/// A kernel error as the message Elixir shows (`file:line: problem`).
pub fn message(e: Error) -> String {
    e.to_string()
}

/// Linear RGB floats as one binary of native-endian `f32`s, 12 bytes a pixel.
pub fn floats_to_binary<'a>(env: Env<'a>, rgb: &[f32]) -> Result<Binary<'a>, String> {
    let mut bin = OwnedBinary::new(std::mem::size_of_val(rgb));
    copy_floats(bin.as_mut_slice(), rgb);
    Ok(bin.release(env))
}

/// `rgb` as native-endian bytes into `dst`, as many floats as both hold.
pub fn copy_floats(dst: &mut [u8], rgb: &[f32]) {
    for (d, v) in dst.chunks_exact_mut(4).zip(rgb) {
        d.copy_from_slice(&v.to_ne_bytes());
    }
}

/// The inverse of [`floats_to_binary`].
pub fn binary_to_floats<'a>(bin: &'a Binary) -> Result<Cow<'a, [f32]>, String> {
    if !bin.len().is_multiple_of(4) {
        return Err(format!(
            "pixel binary has {} bytes, not a multiple of 4",
            bin.len()
        ));
    }
    // the binary's own bytes where they are aligned (as a large binary's are), else a copy
    Ok(match bytemuck::try_cast_slice(bin.as_slice()) {
        Ok(floats) => Cow::Borrowed(floats),
        Err(_) => Cow::Owned(
            bin.as_slice()
                .chunks_exact(4)
                .map(|c| f32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        ),
    })
}
