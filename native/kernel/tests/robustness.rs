//! Malformed input must give errors, never panics; limits are checked before allocation.

use ring_tracer_kernel::{render_image, trace_span, Error, Format, Scene, Settings};

fn resolve(_: &str) -> Result<Vec<u8>, String> {
    Err("no files here".into())
}

const NFF: &str = "b 0.1 0.2 0.3
v
from 0 -5 1
at 0 0 0
up 0 0 1
angle 40
hither 1
resolution 6 5
l 1 -3 3
l -2 -2 4 0.5 0.5 0.5
f 1 0.5 0.2 0.7 0.3 20 0 1
p 4
-3 -3 0
3 -3 0
3 3 0
-3 3 0
f 0.9 0.9 1 0.1 0.4 50 0.6 1.4
s 0 0 1 0.8
c 1 0 0 0.3 1 0 1 0.1
pp 3
-1 0 0 0 -1 0
-2 0 0 0 -1 0
-1.5 0 1 0 -1 0.2
";

const TOML: &str = "background = [0.2, 0.3, 0.5]
[camera]
from = [0, 1, 5]
at = [0, 0, 0]
width = 6
height = 5
[[lights]]
position = [2, 4, 3]
[materials.m]
color = [1, 0, 0]
ks = 0.3
t = 0.5
ior = 1.3
checker = { color2 = [0, 0, 1], scale = 0.5 }
[[objects]]
type = \"sphere\"
center = [0, 0, 0]
radius = 1
material = \"m\"
[[objects]]
type = \"plane\"
point = [0, -1, 0]
normal = [0, 1, 0]
[[objects]]
type = \"cone\"
base = [1, -1, 0]
base_radius = 0.4
apex = [1, 1, 0]
apex_radius = 0.1
";

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn mutate(src: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut v = src.to_vec();
    let alphabet = b" \n#-.0123456789eEpsfcvlbinf[]=\"{},x\xff";
    for _ in 0..1 + rng.next() % 4 {
        if v.is_empty() {
            break;
        }
        let i = (rng.next() % v.len() as u64) as usize;
        match rng.next() % 4 {
            0 => {
                v.remove(i);
            }
            1 => v.insert(i, alphabet[(rng.next() % alphabet.len() as u64) as usize]),
            2 => v[i] = alphabet[(rng.next() % alphabet.len() as u64) as usize],
            _ => {
                let j = (i + 1 + (rng.next() % 40) as usize).min(v.len());
                v.drain(i..j);
            }
        }
    }
    v
}

fn exercise(format: Format, src: &str, iterations: usize) {
    let mut rng = Rng(0x1234_5678_9ABC_DEF1);
    let mut parsed = 0;
    for _ in 0..iterations {
        let bytes = mutate(src.as_bytes(), &mut rng);
        if let Ok(scene) = Scene::parse(&bytes, format, "fuzz", &resolve) {
            parsed += 1;
            let mut s = Settings::for_scene(&scene);
            s.width = s.width.min(6);
            s.height = s.height.min(5);
            let (rgb, _) = render_image(&scene, &s, 1).expect("valid settings render");
            assert_eq!(rgb.len(), (s.width * s.height * 3) as usize);
            s.spd = true;
            trace_span(&scene, &s, 0, 3).expect("spd span renders");
        }
    }
    assert!(parsed > 0);
}

#[test]
fn mutated_nff_never_panics() {
    exercise(Format::Nff, NFF, 1500);
}

#[test]
fn mutated_toml_never_panics() {
    exercise(Format::Toml, TOML, 1500);
}

#[test]
fn obj_garbage_never_panics() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1 2 3 4 5\n";
    let mut rng = Rng(99);
    for _ in 0..500 {
        let bytes = mutate(obj.as_bytes(), &mut rng);
        let _ = Scene::parse(&bytes, Format::Obj, "fuzz.obj", &resolve);
    }
}

#[test]
fn extreme_numbers_are_harmless() {
    let src = "v\nfrom 0 0 3e38\nat 0 0 0\nup 0 1 0\nangle 179.9\nresolution 4 4\n\
               s 0 0 0 3e38\np 3\n-3e38 -3e38 0\n3e38 -3e38 0\n0 3e38 0\nc 0 0 0 1e-30 0 0 1e-30 1e-30\n";
    let scene = Scene::parse(src.as_bytes(), Format::Nff, "x.nff", &resolve).unwrap();
    let s = Settings::for_scene(&scene);
    let (rgb, _) = render_image(&scene, &s, 2).unwrap();
    assert_eq!(rgb.len(), 48);
}

#[test]
fn limits_reported_with_bound() {
    let scene = Scene::parse(NFF.as_bytes(), Format::Nff, "a.nff", &resolve).unwrap();
    let s = Settings {
        width: 16_384,
        height: 16_384,
        ..Settings::for_scene(&scene)
    };
    match s.validate() {
        Err(Error::Limit {
            what, value, max, ..
        }) => {
            assert_eq!(what, "image pixel count");
            assert_eq!(value, 16_384 * 16_384);
            assert_eq!(max, ring_tracer_kernel::limits::MAX_PIXELS);
        }
        other => panic!("{other:?}"),
    }
    let s = Settings {
        samples: 17,
        ..Settings::for_scene(&scene)
    };
    let e = s.validate().unwrap_err().to_string();
    assert!(e.contains("samples") && e.contains("16"), "{e}");
}

#[test]
fn cutoff_prunes_weak_branches() {
    let scene = Scene::parse(NFF.as_bytes(), Format::Nff, "a.nff", &resolve).unwrap();
    let base = Settings {
        width: 24,
        height: 20,
        ..Settings::for_scene(&scene)
    };
    let full = Settings {
        cutoff: 0.0,
        ..base.clone()
    };
    let strong = Settings {
        cutoff: 0.5,
        ..base.clone()
    };
    let (_, a) = render_image(&scene, &full, 2).unwrap();
    let (_, b) = render_image(&scene, &base, 2).unwrap();
    let (_, c) = render_image(&scene, &strong, 2).unwrap();
    assert!(a.reflected + a.refracted >= b.reflected + b.refracted);
    let mid = Settings {
        cutoff: 0.05,
        ..base.clone()
    };
    let (_, m) = render_image(&scene, &mid, 2).unwrap();
    assert!(b.reflected + b.refracted > m.reflected + m.refracted);
    assert!(b.reflected + b.refracted > c.reflected + c.refracted);
    // Ks = 0.4, T = 0.6: with cutoff 0.5 only first-level refraction survives
    assert_eq!(c.reflected, 0);
    assert!(c.refracted > 0);
}
