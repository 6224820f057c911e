//! The scene of the `instances` example (and of the full-size instancing test): a tessellated
//! sphere OBJ of about 2 MB referenced many times from a TOML scene.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Longitude and latitude divisions of the sphere: 2 * 160 * 95 = 30 400 triangles and 15 202
/// vertices with their normals, 2.0 MB of OBJ.
pub const LON: usize = 160;
/// See [`LON`].
pub const LAT: usize = 96;

/// Triangles of [`sphere_obj`]`(lon, lat)`.
pub fn sphere_triangles(lon: usize, lat: usize) -> usize {
    2 * lon * (lat - 1)
}

/// A UV sphere of radius 1 with vertex normals (the poles as triangle fans).
pub fn sphere_obj(lon: usize, lat: usize) -> String {
    let mut s = String::from("# UV sphere\nv 0 1 0\nvn 0 1 0\n");
    for i in 1..lat {
        let th = std::f64::consts::PI * i as f64 / lat as f64;
        for j in 0..lon {
            let ph = std::f64::consts::TAU * j as f64 / lon as f64;
            let (x, y, z) = (th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            let _ = writeln!(s, "v {x:.6} {y:.6} {z:.6}\nvn {x:.5} {y:.5} {z:.5}");
        }
    }
    s += "v 0 -1 0\nvn 0 -1 0\n";
    let idx = |i: usize, j: usize| 2 + (i - 1) * lon + j % lon;
    let last = 2 + (lat - 1) * lon;
    let mut f = |a: usize, b: usize, c: usize| {
        let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
    };
    for j in 0..lon {
        f(1, idx(1, j + 1), idx(1, j));
    }
    for i in 1..lat - 1 {
        for j in 0..lon {
            f(idx(i, j), idx(i, j + 1), idx(i + 1, j + 1));
            f(idx(i, j), idx(i + 1, j + 1), idx(i + 1, j));
        }
    }
    for j in 0..lon {
        f(last, idx(lat - 1, j), idx(lat - 1, j + 1));
    }
    s
}

/// A scene of `refs` references to `sphere.obj` on a square grid over a floor, each scaled,
/// squashed and turned differently, in one of three materials; `width` x `height` pixels.
pub fn scene_toml(refs: usize, width: u32, height: u32) -> String {
    let n = (refs as f64).sqrt().ceil().max(1.0) as usize;
    let half = (n as f32 - 1.0) * 1.25;
    let mut s = format!(
        "background = [0.05, 0.06, 0.08]\nambient = 0.15\n\n\
         [camera]\nfrom = [0, {:.2}, {:.2}]\nat = [0, -1, {:.2}]\nfov = 50\n\
         width = {width}\nheight = {height}\n\n\
         [[lights]]\nposition = [{:.2}, {:.2}, {:.2}]\ncolor = [0.9, 0.9, 0.9]\n\n\
         [materials.red]\ncolor = [0.9, 0.2, 0.1]\nks = 0.2\nshine = 40\n\
         [materials.green]\ncolor = [0.2, 0.8, 0.3]\n\
         [materials.mirror]\ncolor = [0.8, 0.8, 0.85]\nkd = 0.3\nks = 0.6\n\n\
         [[objects]]\ntype = \"plane\"\npoint = [0, -1.2, 0]\nnormal = [0, 1, 0]\n",
        half * 1.1 + 3.0,
        half * 1.6 + 4.0,
        half * 0.2,
        -half,
        half * 2.0 + 6.0,
        half + 4.0,
    );
    let mats = ["red", "green", "mirror"];
    for i in 0..refs {
        let (x, z) = ((i % n) as f32 * 2.5 - half, (i / n) as f32 * 2.5 - half);
        let k = 0.6 + 0.4 * ((i * 7919) % 100) as f32 / 100.0;
        let _ = write!(
            s,
            "\n[[objects]]\ntype = \"mesh\"\nfile = \"sphere.obj\"\n\
             translate = [{x:.2}, 0, {z:.2}]\nrotate_y_degrees = {}\n\
             scale = [{k:.2}, {:.2}, {k:.2}]\nmaterial = \"{}\"\n",
            (i * 37) % 360,
            k * (0.8 + 0.1 * (i % 5) as f32),
            mats[i % 3],
        );
    }
    s
}

/// Writes `sphere.obj` and `instances.toml` (`refs` references, `width` x `height`) into
/// `dir`; returns the scene's path.
pub fn write_scene(dir: &Path, refs: usize, width: u32, height: u32) -> std::io::Result<PathBuf> {
    std::fs::write(dir.join("sphere.obj"), sphere_obj(LON, LAT))?;
    let scene = dir.join("instances.toml");
    std::fs::write(&scene, scene_toml(refs, width, height))?;
    Ok(scene)
}
