//! Writes a large triangle mesh as OBJ, for ray-casting benchmarks on big models:
//! `cargo run --release --example big_mesh -- OUT.obj [TRIANGLES]` (default 600,000).
//!
//! The mesh is a bumpy tube around a (3, 2) torus knot: it winds through itself, so rays
//! meet several layers and many boxes overlap, unlike a height field. Quads of the tube's
//! grid (`along x around`, about 5 : 1) are split into two triangles each.

use std::f32::consts::TAU;
use std::io::Write;

fn knot(s: f32) -> [f32; 3] {
    let (p, q) = (3.0, 2.0);
    let r = 2.0 + (q * s).cos();
    [r * (p * s).cos(), r * (p * s).sin(), -(q * s).sin()]
}

fn main() -> std::io::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(out) = args.first() else {
        eprintln!("usage: big_mesh OUT.obj [TRIANGLES]");
        std::process::exit(2);
    };
    let want: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(600_000);
    let around = (((want / 10) as f64).sqrt().ceil() as usize).max(3);
    let along = (want / (2 * around)).max(3);
    let mut f = std::io::BufWriter::new(std::fs::File::create(out)?);
    writeln!(
        f,
        "# bumpy (3,2) torus-knot tube: {} triangles",
        2 * along * around
    )?;
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let unit = |a: [f32; 3]| {
        let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(1e-12);
        [a[0] / l, a[1] / l, a[2] / l]
    };
    for i in 0..along {
        let s = TAU * i as f32 / along as f32;
        let c = knot(s);
        let t = unit(sub(knot(s + 1e-3), knot(s - 1e-3)));
        let n = unit(cross(t, [0.0, 0.0, 1.0]));
        let b = cross(t, n);
        for j in 0..around {
            let a = TAU * j as f32 / around as f32;
            let r = 0.45
                + 0.04 * (17.0 * s).sin() * (9.0 * a).cos()
                + 0.015 * (61.0 * s + 5.0 * a).sin();
            let (ca, sa) = (a.cos() * r, a.sin() * r);
            writeln!(
                f,
                "v {} {} {}",
                c[0] + n[0] * ca + b[0] * sa,
                c[1] + n[1] * ca + b[1] * sa,
                c[2] + n[2] * ca + b[2] * sa
            )?;
        }
    }
    let idx = |i: usize, j: usize| (i % along) * around + (j % around) + 1;
    for i in 0..along {
        for j in 0..around {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            writeln!(f, "f {a} {b} {c}\nf {a} {c} {d}")?;
        }
    }
    f.flush()
}
