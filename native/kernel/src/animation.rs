//! Animation arithmetic: the clock of each frame, and key lists (tracks) interpolated over it.
//!
//! The clock is POV-Ray's (3.x, "Animation options"): a sequence of `frames` frames runs the
//! clock from `start` to `end`. Frame `n` (counted from 0 here; POV-Ray's frame
//! `Initial_Frame + n`) has
//!
//! - `clock = start + (end - start) * n / (frames - 1)`: the first frame shows `start`, the
//!   last `end`;
//! - with `cyclic` (POV-Ray's `+KC`), `clock = start + (end - start) * n / frames`: the last
//!   frame stops one step short of `end`, which is the first frame again, so the sequence
//!   loops without a repeated frame;
//! - one frame alone shows `start`.
//!
//! A subset of the frames (POV-Ray's `+SF`/`+EF`) keeps these clocks: frame `n`'s clock depends
//! only on `n` and the whole sequence. The first and last frames' clocks are `start` and `end`
//! exactly (no rounding).
//!
//! A [`Track`] is a key list: (clock, value) pairs in strictly increasing clock order, each
//! value a number or an `[x, y, z]` triple, interpolated per component:
//!
//! - [`Interpolation::Linear`]: straight between neighbouring keys (continuous, C0);
//! - [`Interpolation::Smooth`]: a Catmull-Rom spline for keys at any spacing: a cubic Hermite
//!   segment between neighbouring keys, whose slope at a key is the slope from the key before it
//!   to the key after it (`(p[i+1] - p[i-1]) / (t[i+1] - t[i-1])`), and at the first and last
//!   key the slope to their one neighbour. Both pass through every key and have a continuous
//!   first derivative in the clock (C1). When the track is periodic (a cyclic animation whose
//!   first key is at `start` and last at `end` with the same value), the slope at both ends is
//!   taken across the wrap, so the loop is C1 too.
//!
//! Before the first key a track holds the first value, after the last key the last one. Values
//! are computed in f64 from the clock and rounded to f32 once at the end, so a value depends on
//! the clock alone.
//!
//! Rotations are per-axis Euler angles in degrees, interpolated per axis like any triple (so a
//! key list can spin an object by more than one turn, which interpolating quaternions cannot);
//! the rotation applies about X first, then Y, then Z (see [`crate::animated`]).

use crate::Error;

/// The frames and the clock of an animation ([`crate::AnimatedScene::animation`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Animation {
    frames: u32,
    start: f64,
    end: f64,
    cyclic: bool,
}

impl Animation {
    /// A still: one frame, at clock 0 (every scene without an `[animation]` table).
    pub const STILL: Animation = Animation {
        frames: 1,
        start: 0.0,
        end: 0.0,
        cyclic: false,
    };

    /// `frames` frames (at least 1, at most [`crate::limits::MAX_FRAMES`]) running the clock
    /// from `start` to `end` (finite; `end < start` runs it backwards), cyclic or not. The
    /// message says what is wrong.
    pub fn new(frames: u32, start: f64, end: f64, cyclic: bool) -> Result<Animation, String> {
        if frames == 0 {
            return Err("an animation needs at least 1 frame".into());
        }
        crate::limits::check(
            "frame count",
            frames as u64,
            crate::limits::MAX_FRAMES as u64,
            "MAX_FRAMES",
        )
        .map_err(|e| e.to_string())?;
        if !(start.is_finite() && end.is_finite()) {
            return Err("the clock's start and end must be finite numbers".into());
        }
        Ok(Animation {
            frames,
            start,
            end,
            cyclic,
        })
    }

    /// Number of frames.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// The clock's range, `(start, end)`.
    pub fn clock_range(&self) -> (f64, f64) {
        (self.start, self.end)
    }

    /// Whether the sequence loops (POV-Ray's `+KC`).
    pub fn cyclic(&self) -> bool {
        self.cyclic
    }

    /// Whether `clock` is within the range (either way round, ends included).
    pub fn contains(&self, clock: f64) -> bool {
        clock >= self.start.min(self.end) && clock <= self.start.max(self.end)
    }

    /// The clock of frame `frame` (from 0), as the module docs define it; an
    /// [`Error::InvalidArgument`] for a frame past the last.
    pub fn clock_of(&self, frame: u32) -> Result<f64, Error> {
        if frame >= self.frames {
            return Err(Error::InvalidArgument(format!(
                "frame {frame} of an animation of {} frames (they count from 0)",
                self.frames
            )));
        }
        let steps = if self.cyclic {
            self.frames
        } else {
            self.frames - 1
        };
        Ok(if frame == 0 || steps == 0 {
            self.start
        } else if frame == steps {
            self.end
        } else {
            self.start + (self.end - self.start) * (frame as f64 / steps as f64)
        })
    }
}

/// How a key list is interpolated between its keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Straight lines between neighbouring keys.
    Linear,
    /// Catmull-Rom (C1), see the module docs.
    Smooth,
}

/// A key list: values at clocks, interpolated between them (module docs). Values are triples;
/// a number is kept in the first component.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    times: Vec<f64>,
    values: Vec<[f64; 3]>,
    /// Slope (per unit of clock) at each key, for [`Interpolation::Smooth`].
    slopes: Vec<[f64; 3]>,
    interpolation: Interpolation,
}

impl Track {
    /// A track through `keys` (clock, value), which must be in strictly increasing clock order
    /// and finite; `Err(i)` names the first key out of order (or not finite), `Err(0)` an empty
    /// list. `periodic`: the slopes at the ends are taken across the wrap (used only when the
    /// first and last values are equal and there are at least 3 keys).
    pub fn new(
        keys: &[(f64, [f64; 3])],
        interpolation: Interpolation,
        periodic: bool,
    ) -> Result<Track, usize> {
        if keys.is_empty() {
            return Err(0);
        }
        for (i, (t, v)) in keys.iter().enumerate() {
            if !t.is_finite() || v.iter().any(|x| !x.is_finite()) {
                return Err(i);
            }
            if i > 0 && *t <= keys[i - 1].0 {
                return Err(i);
            }
        }
        let times: Vec<f64> = keys.iter().map(|k| k.0).collect();
        let values: Vec<[f64; 3]> = keys.iter().map(|k| k.1).collect();
        let n = keys.len();
        let slope = |a: usize, b: usize, dt: f64| -> [f64; 3] {
            std::array::from_fn(|c| (values[b][c] - values[a][c]) / dt)
        };
        let mut slopes = vec![[0.0; 3]; n];
        if n >= 2 {
            for (i, s) in slopes.iter_mut().enumerate() {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                *s = slope(a, b, times[b] - times[a]);
            }
            if periodic && n >= 3 && values[0] == values[n - 1] {
                let dt = (times[1] - times[0]) + (times[n - 1] - times[n - 2]);
                let s = slope(n - 2, 1, dt);
                slopes[0] = s;
                slopes[n - 1] = s;
            }
        }
        Ok(Track {
            times,
            values,
            slopes,
            interpolation,
        })
    }

    /// The number of keys.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether there are no keys (never: [`Track::new`] refuses an empty list).
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The value at `clock`.
    pub fn at(&self, clock: f64) -> [f64; 3] {
        let n = self.times.len();
        let (Some(&first), Some(&last)) = (self.times.first(), self.times.last()) else {
            return [0.0; 3];
        };
        // (not after the first key, or not a number at all)
        if clock <= first || clock.is_nan() || n == 1 {
            return self.values[0];
        }
        if clock >= last {
            return self.values[n - 1];
        }
        // the segment [t[i], t[i+1]) holding the clock
        let i = self.times.partition_point(|&t| t <= clock) - 1;
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        let (p0, p1) = (self.values[i], self.values[i + 1]);
        let h = t1 - t0;
        let u = (clock - t0) / h;
        match self.interpolation {
            Interpolation::Linear => std::array::from_fn(|c| p0[c] + (p1[c] - p0[c]) * u),
            Interpolation::Smooth => {
                let (m0, m1) = (self.slopes[i], self.slopes[i + 1]);
                let (u2, u3) = (u * u, u * u * u);
                let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
                let h10 = u3 - 2.0 * u2 + u;
                let h01 = -2.0 * u3 + 3.0 * u2;
                let h11 = u3 - u2;
                std::array::from_fn(|c| {
                    h00 * p0[c] + h10 * h * m0[c] + h01 * p1[c] + h11 * h * m1[c]
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(k: &[(f64, f64)]) -> Vec<(f64, [f64; 3])> {
        k.iter().map(|&(t, v)| (t, [v, -v, 2.0 * v])).collect()
    }

    const UNEVEN: [(f64, f64); 5] = [(0.0, 1.0), (0.1, 3.0), (0.45, -2.0), (0.5, 0.5), (1.0, 4.0)];

    #[test]
    fn the_clock_of_a_frame_is_povrays() {
        let a = Animation::new(5, 0.0, 1.0, false).unwrap();
        let clocks: Vec<f64> = (0..5).map(|n| a.clock_of(n).unwrap()).collect();
        assert_eq!(clocks, [0.0, 0.25, 0.5, 0.75, 1.0]);
        // cyclic: the step is 1/frames, and the last frame stops short of the end
        let c = Animation::new(4, 0.0, 1.0, true).unwrap();
        let clocks: Vec<f64> = (0..4).map(|n| c.clock_of(n).unwrap()).collect();
        assert_eq!(clocks, [0.0, 0.25, 0.5, 0.75]);
        // the ends are exact, whatever the rounding in between
        let odd = Animation::new(7, 0.1, 0.7, false).unwrap();
        assert_eq!(odd.clock_of(0).unwrap(), 0.1);
        assert_eq!(odd.clock_of(6).unwrap(), 0.7);
        // backwards, and one frame alone shows the start
        let back = Animation::new(3, 2.0, -2.0, false).unwrap();
        assert_eq!(back.clock_of(1).unwrap(), 0.0);
        assert_eq!(back.clock_of(2).unwrap(), -2.0);
        assert!(back.contains(-1.0) && !back.contains(2.5));
        assert_eq!(
            Animation::new(1, 3.0, 9.0, false).unwrap().clock_of(0),
            Ok(3.0)
        );
        assert_eq!(Animation::STILL.clock_of(0), Ok(0.0));
        // a frame past the last is an error
        assert_eq!(
            a.clock_of(5).unwrap_err().to_string(),
            "invalid argument: frame 5 of an animation of 5 frames (they count from 0)"
        );
        assert!(Animation::new(0, 0.0, 1.0, false).is_err());
        assert!(Animation::new(2, 0.0, f64::NAN, false).is_err());
    }

    #[test]
    fn a_subset_of_frames_keeps_the_whole_sequences_clock() {
        // POV-Ray's +SF/+EF: frames 10..=12 of 24 have the clocks they have in the whole run,
        // which depend on the frame alone
        let whole = Animation::new(24, 0.0, 1.0, false).unwrap();
        for n in 10..=12 {
            assert_eq!(whole.clock_of(n).unwrap(), n as f64 / 23.0);
        }
        let cyc = Animation::new(24, 0.0, 1.0, true).unwrap();
        assert_eq!(cyc.clock_of(12).unwrap(), 0.5);
    }

    #[test]
    fn linear_hits_every_key_exactly_and_holds_outside() {
        let k = keys(&UNEVEN);
        let t = Track::new(&k, Interpolation::Linear, false).unwrap();
        for (clock, v) in &k {
            assert_eq!(t.at(*clock), *v, "at {clock}");
        }
        assert_eq!(t.at(-5.0), k[0].1);
        assert_eq!(t.at(7.0), k[4].1);
        // half way between two keys, and straight
        assert_eq!(t.at(0.05), [2.0, -2.0, 4.0]);
        let q = t.at(0.475)[0];
        assert!((q - (-0.75)).abs() < 1e-12, "{q}");
    }

    #[test]
    fn smooth_passes_through_the_keys_and_is_c1() {
        let k = keys(&UNEVEN);
        let t = Track::new(&k, Interpolation::Smooth, false).unwrap();
        for (clock, v) in &k {
            assert_eq!(t.at(*clock), *v, "at {clock}");
        }
        // the slope from the left and from the right agree at every inner key
        let d = 1e-7;
        for (clock, _) in &k[1..k.len() - 1] {
            for c in 0..3 {
                let left = (t.at(*clock)[c] - t.at(clock - d)[c]) / d;
                let right = (t.at(clock + d)[c] - t.at(*clock)[c]) / d;
                assert!(
                    (left - right).abs() < 1e-3 * (1.0 + left.abs()),
                    "at {clock}: {left} vs {right}"
                );
            }
        }
        // and it is not just linear: between keys it leaves the straight line
        let lin = Track::new(&k, Interpolation::Linear, false).unwrap();
        assert!((t.at(0.3)[0] - lin.at(0.3)[0]).abs() > 0.1);
        // linear, by contrast, has a corner at a key
        let left = (lin.at(0.1)[0] - lin.at(0.1 - d)[0]) / d;
        let right = (lin.at(0.1 + d)[0] - lin.at(0.1)[0]) / d;
        assert!((left - right).abs() > 1.0, "{left} {right}");
    }

    #[test]
    fn a_periodic_smooth_track_wraps_c1() {
        // a loop: first and last key at the ends of the clock, with the same value
        let k = keys(&[(0.0, 0.0), (0.3, 1.0), (0.6, -1.0), (1.0, 0.0)]);
        let t = Track::new(&k, Interpolation::Smooth, true).unwrap();
        let a = Animation::new(24, 0.0, 1.0, true).unwrap();
        // the frame after the last is the first again: clock 1 gives frame 0's value
        let step = a.clock_of(1).unwrap() - a.clock_of(0).unwrap();
        let after_last = a.clock_of(23).unwrap() + step;
        assert_eq!(t.at(after_last), t.at(a.clock_of(0).unwrap()));
        // and the slope leaving clock 0 is the slope arriving at clock 1
        let d = 1e-7;
        let leaving = (t.at(d)[0] - t.at(0.0)[0]) / d;
        let arriving = (t.at(1.0)[0] - t.at(1.0 - d)[0]) / d;
        assert!((leaving - arriving).abs() < 1e-4, "{leaving} {arriving}");
        // not periodic: the ends keep their one-sided slopes, which differ here
        let open = Track::new(&k, Interpolation::Smooth, false).unwrap();
        let leaving = (open.at(d)[0] - open.at(0.0)[0]) / d;
        let arriving = (open.at(1.0)[0] - open.at(1.0 - d)[0]) / d;
        assert!((leaving - arriving).abs() > 0.5, "{leaving} {arriving}");
    }

    #[test]
    fn keys_out_of_order_or_not_finite_are_refused() {
        let k = keys(&[(0.0, 1.0), (0.5, 2.0), (0.5, 3.0)]);
        assert_eq!(Track::new(&k, Interpolation::Linear, false), Err(2));
        let k = keys(&[(0.4, 1.0), (0.2, 2.0)]);
        assert_eq!(Track::new(&k, Interpolation::Smooth, false), Err(1));
        let k = keys(&[(0.0, f64::INFINITY)]);
        assert_eq!(Track::new(&k, Interpolation::Smooth, false), Err(0));
        assert_eq!(Track::new(&[], Interpolation::Linear, false), Err(0));
        // one key: a constant
        let one = Track::new(&keys(&[(0.3, 2.0)]), Interpolation::Smooth, false).unwrap();
        assert_eq!(one.at(0.0), one.at(1.0));
        // a clock that is not a number gives the first value, not a panic
        let two = Track::new(&keys(&UNEVEN), Interpolation::Smooth, false).unwrap();
        assert_eq!(two.at(f64::NAN), two.at(0.0));
    }
}
