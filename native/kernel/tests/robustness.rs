//! Malformed input must give errors, never panics; limits are checked before allocation.

use ring_tracer_kernel::files::Unreadable;
use ring_tracer_kernel::{render_image, trace_span, AnimatedScene, Error, Format, Scene, Settings};

fn resolve(_: &str) -> Result<Vec<u8>, Unreadable> {
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
            assert_eq!(what, "resolution 16384x16384");
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

// ---- limits: every bound is checked before allocating, and says how to raise it ----

use ring_tracer_kernel::limits;

fn parse_err(src: &[u8], format: Format, name: &str) -> Error {
    match Scene::parse(src, format, name, &resolve) {
        Ok(_) => panic!("expected an error for {name}"),
        Err(e) => e,
    }
}

const VIEW: &str = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\n";

/// A 10-gigapixel (40 GB of f32 RGB) NFF resolution is a parse error at its line, found before
/// any pixel buffer exists; the message names the value, the bound, the constant and the way out.
#[test]
fn limit_nff_resolution_total_pixels() {
    let src = format!("{VIEW}resolution 100000 100000\ns 0 0 0 1\n");
    let e = parse_err(src.as_bytes(), Format::Nff, "big.nff");
    assert_eq!(
        e.to_string(),
        "big.nff:6: resolution 100000x100000 is 10000000000 pixels, more than the limit of \
         67108864 (limits::MAX_PIXELS); render in tiles or raise the constant in \
         native/kernel/src/limits.rs"
    );
    // values beyond u32 and u64 products are not truncated or overflowed into something small
    let src = format!("{VIEW}resolution 4294967296 1\n");
    let e = parse_err(src.as_bytes(), Format::Nff, "wrap.nff").to_string();
    assert!(
        e.starts_with("wrap.nff:6: resolution 4294967296x1 is 4294967296 pixels"),
        "{e}"
    );
    let src = format!("{VIEW}resolution 18446744073709551615 18446744073709551615\n");
    let e = parse_err(src.as_bytes(), Format::Nff, "huge.nff").to_string();
    assert!(e.contains("limits::MAX_PIXELS"), "{e}");
    let src = format!("{VIEW}resolution 0 10\n");
    assert!(Scene::parse(src.as_bytes(), Format::Nff, "z.nff", &resolve).is_err());
}

#[test]
fn limit_resolution_per_side() {
    let src = format!("{VIEW}resolution 16385 8\n");
    let e = parse_err(src.as_bytes(), Format::Nff, "wide.nff").to_string();
    assert_eq!(
        e,
        "wide.nff:6: image width is 16385 pixels, more than the limit of 16384 \
         (limits::MAX_SIDE); render in tiles or raise the constant in native/kernel/src/limits.rs"
    );
    let toml = "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\nwidth = 8\nheight = 70000\n";
    let e = parse_err(toml.as_bytes(), Format::Toml, "tall.toml").to_string();
    assert!(
        e.starts_with("tall.toml:1: camera resolution: image height is 70000"),
        "{e}"
    );
    assert!(e.contains("(limits::MAX_SIDE)"), "{e}");
    let scene = Scene::parse(NFF.as_bytes(), Format::Nff, "a.nff", &resolve).unwrap();
    let s = Settings {
        width: limits::MAX_SIDE + 1,
        height: 1,
        ..Settings::for_scene(&scene)
    };
    assert!(matches!(
        trace_span(&scene, &s, 0, 1),
        Err(Error::Limit {
            constant: "MAX_SIDE",
            ..
        })
    ));
    let s = Settings {
        width: 9000,
        height: 9000,
        ..Settings::for_scene(&scene)
    };
    // render_image would need 972 MB: refused before allocating
    assert!(matches!(
        render_image(&scene, &s, 1),
        Err(Error::Limit {
            constant: "MAX_PIXELS",
            value: 81_000_000,
            ..
        })
    ));
}

#[test]
fn limit_samples_and_depth() {
    let scene = Scene::parse(NFF.as_bytes(), Format::Nff, "a.nff", &resolve).unwrap();
    let base = Settings::for_scene(&scene);
    let s = Settings {
        samples: limits::MAX_SAMPLES + 1,
        ..base.clone()
    };
    assert_eq!(
        s.validate().unwrap_err().to_string(),
        "samples per pixel side is 17, more than the limit of 16 (limits::MAX_SAMPLES); raise \
         the constant in native/kernel/src/limits.rs and rebuild"
    );
    let s = Settings {
        depth: limits::MAX_DEPTH + 1,
        ..base.clone()
    };
    assert_eq!(
        trace_span(&scene, &s, 0, 1).unwrap_err().to_string(),
        "ray depth is 65, more than the limit of 64 (limits::MAX_DEPTH); raise the constant in \
         native/kernel/src/limits.rs and rebuild"
    );
    let ok = Settings {
        samples: limits::MAX_SAMPLES,
        depth: limits::MAX_DEPTH,
        ..base
    };
    assert!(ok.validate().is_ok());
}

#[test]
fn limit_polygon_vertices() {
    // the count is checked before a single vertex is read or stored
    let n = limits::MAX_POLYGON_VERTICES + 1;
    for entity in ["p", "pp"] {
        let src = format!("{VIEW}resolution 4 4\n{entity} {n}\n0 0 0\n");
        let e = parse_err(src.as_bytes(), Format::Nff, "poly.nff").to_string();
        assert!(e.starts_with("poly.nff:7: the vertex count of "), "{e}");
        assert!(
            e.contains("is 1048577, more than the limit of 1048576 (limits::MAX_POLYGON_VERTICES)"),
            "{e}"
        );
    }
}

#[test]
fn limit_light_count() {
    let mut src = format!("{VIEW}resolution 4 4\n");
    for _ in 0..limits::MAX_LIGHTS {
        src.push_str("l 0 0 1\n");
    }
    assert!(Scene::parse(src.as_bytes(), Format::Nff, "lights.nff", &resolve).is_ok());
    src.push_str("l 0 0 1\n");
    let e = parse_err(src.as_bytes(), Format::Nff, "lights.nff").to_string();
    assert_eq!(
        e,
        format!(
            "lights.nff:{}: light count is 65537, more than the limit of 65536 \
             (limits::MAX_LIGHTS); raise the constant in native/kernel/src/limits.rs and rebuild",
            limits::MAX_LIGHTS + 7
        )
    );
}

/// One face of 20 000 003 vertices on one line, so 20 000 001 triangles: refused by the scan
/// of the face lines before the OBJ reader would allocate ~240 MB of indices.
#[test]
fn limit_mesh_triangles() {
    let n = limits::MAX_MESH_TRIANGLES + 3;
    let mut obj = Vec::with_capacity(2 * n + 32);
    obj.extend_from_slice(b"v 0 0 0\nf");
    for _ in 0..n {
        obj.extend_from_slice(b" 1");
    }
    obj.push(b'\n');
    let e = parse_err(&obj, Format::Obj, "big.obj").to_string();
    assert_eq!(
        e,
        "the triangle count of mesh big.obj (from its face lines) is 20000001, more than the \
         limit of 20000000 (limits::MAX_MESH_TRIANGLES); raise the constant in \
         native/kernel/src/limits.rs and rebuild"
    );
    // the same through a TOML mesh reference
    let toml = "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[[objects]]\ntype = \"mesh\"\nfile = \"big.obj\"\n";
    let big = move |_: &str| -> Result<Vec<u8>, Unreadable> { Ok(obj.clone()) };
    let e = Scene::parse(toml.as_bytes(), Format::Toml, "m.toml", &big)
        .unwrap_err()
        .to_string();
    assert!(e.contains("(limits::MAX_MESH_TRIANGLES)"), "{e}");
}

/// A sparse file one byte over the bound: refused from its metadata, never read.
#[test]
fn limit_file_size() {
    let dir = std::env::temp_dir().join(format!("rt_limit_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let big = dir.join("huge.nff");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(limits::MAX_FILE_BYTES + 1).unwrap();
    drop(f);
    let e = Scene::load(&big).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Limit {
                constant: "MAX_FILE_BYTES",
                value: 1_073_741_825,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains(" bytes, more than the limit of 1073741824"),
        "{e}"
    );
    // a mesh referenced by a scene goes through the same check
    let mesh = dir.join("huge.obj");
    std::fs::rename(&big, &mesh).unwrap();
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[[objects]]\ntype = \"mesh\"\nfile = \"huge.obj\"\n",
    )
    .unwrap();
    let e = Scene::load(&scene).unwrap_err().to_string();
    assert!(e.contains("limits::MAX_FILE_BYTES"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `Scene::load` reads referenced files only inside the scene's folder.
#[test]
fn load_confines_references() {
    let t = tempfile::tempdir().unwrap();
    let quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n";
    std::fs::write(t.path().join("quad.obj"), quad).unwrap();
    let dir = t.path().join("scenes");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("quad.obj"), quad).unwrap();
    let scene = |file: &str| {
        let path = dir.join("s.toml");
        std::fs::write(
            &path,
            format!("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[[objects]]\ntype = \"mesh\"\nfile = \"{file}\"\n"),
        )
        .unwrap();
        Scene::load(&path).map_err(|e| e.to_string())
    };
    assert_eq!(scene("quad.obj").unwrap().primitive_count(), 1);
    let e = scene("../quad.obj").unwrap_err();
    assert!(
        e.starts_with("s.toml:4: cannot load mesh '../quad.obj': '../quad.obj' resolves to "),
        "{e}"
    );
    assert!(e.contains("outside the scene's folder"), "{e}");
    let e = scene("/etc/passwd").unwrap_err();
    assert!(
        e.contains("'/etc/passwd' resolves to /etc/passwd, outside"),
        "{e}"
    );
    assert!(!e.contains("root:"), "{e}");
}

// ---- the fuzz seeds (native/fuzz/corpus/<target>/) on stable, through the fuzz driver's steps ----

/// What the fuzz targets' resolver returns: a small quad mesh, or its material library.
fn fuzz_resolve(path: &str) -> Result<Vec<u8>, Unreadable> {
    if path.ends_with(".mtl") {
        Ok(b"newmtl red\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 30\n".to_vec())
    } else {
        Ok(b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nusemtl red\nf 1//1 2//1 3//1 4//1\n".to_vec())
    }
}

#[test]
fn fuzz_seed_corpora_parse_and_trace() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus");
    let mut seen = 0;
    for (dir, format) in [
        ("nff", Format::Nff),
        ("toml_scene", Format::Toml),
        ("obj", Format::Obj),
    ] {
        for entry in std::fs::read_dir(root.join(dir)).expect("corpus directory") {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            let scene = Scene::parse(&bytes, format, "seed", &fuzz_resolve)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let s = Settings {
                width: 4,
                height: 4,
                depth: 3,
                ..Settings::for_scene(&scene)
            };
            let (rgb, _) = trace_span(&scene, &s, 0, 16).unwrap();
            assert!(rgb.iter().all(|v| v.is_finite()), "{}", path.display());
            let spd = Settings {
                width: 3,
                height: 2,
                spd: true,
                ..s
            };
            trace_span(&scene, &spd, 1, 4).unwrap();
            if format == Format::Toml {
                // every frame of an animated seed (a still has one, the scene itself)
                let animated = AnimatedScene::parse(&bytes, format, "seed", &fuzz_resolve)
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                for n in 0..animated.animation().frames() {
                    let frame = animated.frame(n).unwrap();
                    let (rgb, _) = trace_span(&frame, &s, 0, 16).unwrap();
                    assert!(
                        rgb.iter().all(|v| v.is_finite()),
                        "{} frame {n}",
                        path.display()
                    );
                }
            }
            seen += 1;
        }
    }
    assert!(seen >= 6, "only {seen} seeds");
}

#[test]
fn a_refused_mtllib_stops_the_load_and_a_missing_one_falls_back_to_grey() {
    let obj = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let refused = |_: &str| -> Result<Vec<u8>, Unreadable> {
        Err(Unreadable::Refused(
            "'m.mtl' resolves to /etc/passwd, outside".into(),
        ))
    };
    let e = match Scene::parse(obj, Format::Obj, "m.obj", &refused) {
        Ok(_) => panic!("a refused mtllib is an error"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.starts_with("m.obj: cannot load its mtllib: 'm.mtl'"),
        "{e}"
    );
    let missing = |_: &str| -> Result<Vec<u8>, Unreadable> {
        Err(Unreadable::Missing("'m.mtl' does not exist".into()))
    };
    assert!(Scene::parse(obj, Format::Obj, "m.obj", &missing).is_ok());
}

/// A UTF-8 byte order mark before a scene or a mesh changes nothing.
#[test]
fn a_byte_order_mark_is_skipped() {
    let nff = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 4 4\n\
               l 0 5 5\nf 1 0 0 1 0 0 0 0\ns 0 0 0 1\n";
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n";
    for (text, format, name) in [(nff, Format::Nff, "b.nff"), (obj, Format::Obj, "b.obj")] {
        let plain = Scene::parse(text.as_bytes(), format, name, &resolve).unwrap();
        let marked = [b"\xEF\xBB\xBF".as_slice(), text.as_bytes()].concat();
        let marked = Scene::parse(&marked, format, name, &resolve).unwrap();
        assert_eq!(
            (plain.primitive_count(), plain.resolution()),
            (marked.primitive_count(), marked.resolution()),
            "{name}"
        );
    }
}

/// What the OBJ reader refuses without a line (bad numbers, non-UTF-8 text) is found first, and
/// named with its line.
#[test]
fn obj_numbers_the_reader_would_refuse_name_their_line() {
    let tri = "v 0 0 0\nv 1 0 0\nv 1 1 0\n";
    for (line, message) in [
        (
            "v nan 0 0",
            "vertex value 'nan' is not a finite number (32-bit floats reach about 3.4e38)",
        ),
        (
            "v 0 1e39 0",
            "vertex value '1e39' is not a finite number (32-bit floats reach about 3.4e38)",
        ),
        ("vn 0 0", "a normal line needs 3 numbers, got 2"),
        ("vt 0.5 x", "texture coordinate value 2 'x' is not a number"),
        ("vt 0.5", "a texture coordinate line needs 2 numbers, got 1"),
        (
            "f 1 2 99999999999999999999",
            "index '99999999999999999999' is not an integer",
        ),
        ("l 1 two", "index 'two' is not an integer"),
    ] {
        let src = format!("{tri}{line}\nf 1 2 3\n");
        let e = parse_err(src.as_bytes(), Format::Obj, "n.obj").to_string();
        assert_eq!(e, format!("n.obj:4: {message}"));
    }
    let latin1 = [tri.as_bytes(), b"# caf\xe9\nf 1 2 3\n"].concat();
    let e = parse_err(&latin1, Format::Obj, "n.obj").to_string();
    assert_eq!(e, "n.obj:4: the line is not UTF-8 text");
    // numbers past the third, colours say, and CR line ends are the reader's business
    let ok = "v 0 0 0 1 0 0\r\nv 1 0 0 0 1 0\r\nv 1 1 0 0 0 1\r\nvt 0.5 0.5\r\nf 1 2 3\r\n";
    assert!(Scene::parse(ok.as_bytes(), Format::Obj, "ok.obj", &resolve).is_ok());
}

/// Found by the obj fuzz target: a relative normal index reaching back before the first normal
/// made the OBJ reader's index arithmetic overflow. Face indices are checked before it runs.
#[test]
fn obj_face_indices_that_name_nothing_are_errors() {
    let quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n";
    for (face, message) in [
        (
            "f 1//-4 2//1 3//1",
            "normal index -4 reaches back before the first normal (only 1 so far)",
        ),
        ("f 0 1 2", "vertex index 0: OBJ indices count from 1"),
        (
            "f 1 2 99999999999999999",
            "vertex index 99999999999999999, but the file has 4 of them",
        ),
        (
            "f 1/2/1 2 3",
            "texture coordinate index 2, but the file has 0 of them",
        ),
        (
            "l 1 -5",
            "vertex index -5 reaches back before the first vertex (only 4 so far)",
        ),
    ] {
        let src = format!("{quad}{face}\n");
        let e = parse_err(src.as_bytes(), Format::Obj, "i.obj").to_string();
        assert_eq!(e, format!("i.obj:6: {message}"));
    }
    // the fuzzer's own input, as it found it
    let found = b"mtllib m.mtl\no qu\nv 5 0 0\nv 1 0 0\nv 2 1 0\nv\x030 1 0\nvn  5 0 0\nv 1 0 0\n\
v 2 1 0\nv\x030 1 0\nvn -4 -3 -2\nf  0\nusemtl red\nf 2/1/-4 -3 -2\nf  0\nusemtl red\n\
f 2/1/1 2/1/1 3/1/0 4/1/1\n";
    assert!(Scene::parse(found, Format::Obj, "found.obj", &resolve).is_err());
    // relative indices that stay inside are fine
    let ok = format!("{quad}f -4//-1 -3//-1 -2//-1\n");
    assert!(Scene::parse(ok.as_bytes(), Format::Obj, "ok.obj", &resolve).is_ok());
}
