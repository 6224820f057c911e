//! Whitted materials (the NFF `f` entity plus an optional checker texture).

use glam::Vec3A;

/// A two-colour 3D checker texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checker {
    /// The second colour (the first is the material colour).
    pub color2: Vec3A,
    /// Edge length of one check in world units (> 0).
    pub scale: f32,
}

/// Surface description in Whitted's model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Surface colour (linear RGB, 0..1).
    pub color: Vec3A,
    /// Diffuse coefficient.
    pub kd: f32,
    /// Specular coefficient: Phong highlight weight and mirror-reflection weight.
    pub ks: f32,
    /// Phong exponent.
    pub shine: f32,
    /// Transmittance: weight of the refracted ray.
    pub t: f32,
    /// Index of refraction (used when `t > 0`; values <= 0 are treated as 1).
    pub ior: f32,
    /// Optional checker texture.
    pub checker: Option<Checker>,
}

impl Material {
    /// The default material: white, diffuse only.
    pub const DEFAULT: Material = Material {
        color: Vec3A::ONE,
        kd: 1.0,
        ks: 0.0,
        shine: 0.0,
        t: 0.0,
        ior: 1.0,
        checker: None,
    };
}

impl Default for Material {
    fn default() -> Self {
        Material::DEFAULT
    }
}

impl Material {
    /// Surface colour at world point `p`.
    #[inline]
    pub fn color_at(&self, p: Vec3A) -> Vec3A {
        match self.checker {
            None => self.color,
            Some(c) => {
                let q = (p / c.scale + Vec3A::splat(1e-4)).floor();
                let s = q.x as i64 + q.y as i64 + q.z as i64;
                if s & 1 == 0 {
                    self.color
                } else {
                    c.color2
                }
            }
        }
    }

    /// Effective index of refraction.
    #[inline]
    pub fn eta(&self) -> f32 {
        if self.ior > 0.0 {
            self.ior
        } else {
            1.0
        }
    }
}

/// A colour as a warning shows it: `1.5 0 0`.
pub(crate) fn show(c: Vec3A) -> String {
    format!("{} {} {}", c.x, c.y, c.z)
}

/// A warning if a surface colour (`what`, e.g. `colour`) has a component outside [0, 1]: a
/// surface reflects at most the light it receives, so above 1 it glows and below 0 it takes
/// light away.
pub(crate) fn check_unit_colour(what: &str, c: Vec3A) -> Option<String> {
    (c.min_element() < 0.0 || c.max_element() > 1.0).then(|| {
        format!(
            "{what} {} is outside [0, 1]: a surface reflects at most the light it receives",
            show(c)
        )
    })
}

/// A warning if a light or background colour (`what`) has a negative component (it would take
/// light away). Above 1 is fine: lights may be bright.
pub(crate) fn check_light_colour(what: &str, c: Vec3A) -> Option<String> {
    (c.min_element() < 0.0).then(|| {
        format!(
            "{what} {} has a negative component, which takes light away",
            show(c)
        )
    })
}

impl Material {
    /// Checks the values against their useful ranges. `Err` when the material cannot mean
    /// anything (a transparent surface, `t > 0`, with an index of refraction <= 0); otherwise the
    /// warnings: colours outside [0, 1], `kd`, `ks` or `t` outside [0, 1], `ks + t > 1` (more
    /// light reflected and transmitted than received), a negative Phong exponent. `names` are
    /// the format's names of kd, ks, shine, t, ior (NFF `Kd`..., TOML `kd`...).
    pub(crate) fn check(&self, names: [&str; 5]) -> Result<Vec<String>, String> {
        let [kd, ks, shine, t, ior] = names;
        if self.t > 0.0 && self.ior <= 0.0 {
            return Err(format!(
                "{ior} {} with {t} {}: a transparent surface needs an index of refraction > 0",
                self.ior, self.t
            ));
        }
        let mut w = Vec::new();
        w.extend(check_unit_colour("colour", self.color));
        if let Some(c) = self.checker {
            w.extend(check_unit_colour("checker colour", c.color2));
        }
        for (name, v) in [(kd, self.kd), (ks, self.ks), (t, self.t)] {
            if !(0.0..=1.0).contains(&v) {
                w.push(format!("{name} {v} is outside [0, 1]"));
            }
        }
        if self.ks + self.t > 1.0 && self.ks <= 1.0 && self.t <= 1.0 {
            w.push(format!(
                "{ks} + {t} is {}, more than 1: the surface reflects and transmits more light \
                 than it receives",
                self.ks + self.t
            ));
        }
        if self.shine < 0.0 {
            w.push(format!(
                "{shine} {} is negative: a Phong exponent is 0 or more",
                self.shine
            ));
        }
        Ok(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: [&str; 5] = ["Kd", "Ks", "Shine", "T", "ior"];

    #[test]
    fn checks_useful_ranges() {
        assert_eq!(Material::default().check(NAMES), Ok(vec![]));
        let glass = Material {
            t: 0.5,
            ior: 0.0,
            ..Material::default()
        };
        assert_eq!(
            glass.check(NAMES),
            Err("ior 0 with T 0.5: a transparent surface needs an index of refraction > 0".into())
        );
        // an index is not used by an opaque surface
        let opaque = Material {
            ior: 0.0,
            ..Material::default()
        };
        assert_eq!(opaque.check(NAMES), Ok(vec![]));
        let odd = Material {
            color: Vec3A::new(1.5, 0.0, 0.0),
            kd: -0.5,
            ks: 0.6,
            t: 0.6,
            ior: 1.5,
            shine: -2.0,
            checker: Some(Checker {
                color2: Vec3A::splat(-1.0),
                scale: 1.0,
            }),
        };
        assert_eq!(
            odd.check(NAMES).unwrap(),
            vec![
                "colour 1.5 0 0 is outside [0, 1]: a surface reflects at most the light it \
                 receives"
                    .to_string(),
                "checker colour -1 -1 -1 is outside [0, 1]: a surface reflects at most the light \
                 it receives"
                    .to_string(),
                "Kd -0.5 is outside [0, 1]".to_string(),
                "Ks + T is 1.2, more than 1: the surface reflects and transmits more light than \
                 it receives"
                    .to_string(),
                "Shine -2 is negative: a Phong exponent is 0 or more".to_string(),
            ]
        );
        assert!(check_light_colour("light colour", Vec3A::splat(3.0)).is_none());
        assert!(check_light_colour("light colour", Vec3A::new(1.0, -1.0, 0.0)).is_some());
    }
}
