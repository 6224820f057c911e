//! Shared driver of the fuzz targets: parse arbitrary bytes as a scene and, when that succeeds,
//! check its warnings (at most `limits::MAX_WARNINGS` kept, each short) and trace a few pixels at
//! a tiny resolution so the BVH and the integrator see odd scenes too.

use ring_tracer_kernel::files::Unreadable;
use ring_tracer_kernel::{limits, trace_span, AnimatedScene, Format, Scene, Settings};

/// A small fixed mesh (a quad as two triangles, with normals) that every mesh reference resolves
/// to; files ending in `.mtl` get a small material library instead.
pub const MESH_OBJ: &[u8] = b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
vn 0 0 1\nusemtl red\nf 1//1 2//1 3//1 4//1\n";
/// The material library returned for `.mtl` paths.
pub const MESH_MTL: &[u8] = b"newmtl red\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 30\n";

fn resolve(path: &str) -> Result<Vec<u8>, Unreadable> {
    if path.ends_with(".mtl") {
        Ok(MESH_MTL.to_vec())
    } else if path.contains("missing") {
        Err(format!("{path}: no such file").into())
    } else {
        Ok(MESH_OBJ.to_vec())
    }
}

/// Parses `data` as `format`; on success traces a 4x4 image at depth 3 and a 3x2 SPD image.
/// An animated TOML scene also traces a few pixels of its middle and last frames (whose
/// errors, a camera that degenerates at some clock, must be short too).
pub fn run(data: &[u8], format: Format) {
    if format == Format::Toml {
        frames(data);
    }
    let scene = match Scene::parse(data, format, "fuzz", &resolve) {
        Ok(scene) => scene,
        Err(e) => {
            // errors echo file text only cut short
            assert!(e.to_string().len() < 2048, "long error: {e}");
            return;
        }
    };
    let warnings = scene.warnings();
    assert!(warnings.kept().len() <= limits::MAX_WARNINGS);
    assert!(warnings.omitted() == 0 || warnings.kept().len() == limits::MAX_WARNINGS);
    for w in warnings.kept() {
        let shown = w.to_string();
        assert!(shown.len() < 2048, "long warning: {shown}");
        assert!(
            !shown.contains(['\n', '\x1b']),
            "unescaped warning: {shown:?}"
        );
    }
    let base = Settings {
        width: 4,
        height: 4,
        depth: 3,
        ..Settings::for_scene(&scene)
    };
    let (rgb, _) = trace_span(&scene, &base, 0, 16).expect("valid span traces");
    assert_eq!(rgb.len(), 48);
    let jittered = Settings {
        samples: 2,
        ..base.clone()
    };
    trace_span(&scene, &jittered, 5, 3).expect("valid span traces");
    let spd = Settings {
        width: 3,
        height: 2,
        spd: true,
        ..base
    };
    trace_span(&scene, &spd, 1, 4).expect("valid span traces");
}

fn frames(data: &[u8]) {
    let Ok(animated) = AnimatedScene::parse(data, Format::Toml, "fuzz", &resolve) else {
        return;
    };
    let last = animated.animation().frames() - 1;
    for n in [last / 2, last] {
        match animated.frame(n) {
            Ok(scene) => {
                let s = Settings {
                    width: 4,
                    height: 4,
                    depth: 3,
                    ..Settings::for_scene(&scene)
                };
                trace_span(&scene, &s, 0, 16).expect("valid span traces");
            }
            Err(e) => assert!(e.to_string().len() < 2048, "long error: {e}"),
        }
    }
}
