//! Peak memory of parsing a scene (and building its BVH) against the file's size.
//!
//! ```text
//! cargo build --release --example scene_memory
//! target/release/examples/scene_memory gen KIND MB FILE   # writes a scene of about MB MiB
//! /usr/bin/time -v target/release/examples/scene_memory load FILE   # "Maximum resident set size"
//! ```
//!
//! KIND is the densest scene of a format: `nff-spheres` (`s 1 2 3 1`, 10 bytes a sphere),
//! `nff-triangles` (`p 3` and three vertices), `toml-spheres` (`[[objects]]` sphere tables),
//! `obj` (a grid of vertices, two triangles per quad) or `obj-smooth` (the same with normals).
//! `load` prints the file's size, the primitive count, the warnings and the parse time;
//! docs/benchmarks.md has the table these give.

use ring_tracer_kernel::Scene;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["gen", kind, mb, file] => {
            let mb: u64 = mb.parse().unwrap_or_else(|_| usage());
            if let Err(e) = generate(kind, mb << 20, Path::new(file)) {
                eprintln!("{file}: {e}");
                std::process::exit(1);
            }
        }
        ["load", file] => {
            let t0 = Instant::now();
            let bytes = std::fs::metadata(file).map(|m| m.len()).unwrap_or(0);
            match Scene::load(Path::new(file)) {
                Ok(s) => println!(
                    "{file}: {bytes} bytes, {} primitives, {} warnings, {:.2} s",
                    s.primitive_count(),
                    s.warnings().total(),
                    t0.elapsed().as_secs_f64()
                ),
                Err(e) => {
                    eprintln!("{e}");
                    std::process::exit(1);
                }
            }
        }
        _ => usage(),
    }
}

fn usage() -> ! {
    eprintln!("usage: scene_memory gen nff-spheres|nff-triangles|toml-spheres|obj|obj-smooth MB FILE | scene_memory load FILE");
    std::process::exit(2);
}

fn generate(kind: &str, bytes: u64, path: &Path) -> std::io::Result<()> {
    let mut out = Out {
        w: std::io::BufWriter::new(std::fs::File::create(path)?),
        n: 0,
    };
    match kind {
        "nff-spheres" | "nff-triangles" => {
            out.put(
                "v\nfrom 5 5 25\nat 5 5 5\nup 0 1 0\nangle 45\nhither 1\nresolution 64 64\n\
                 l 5 20 20\nf 1 0.5 0.2 0.7 0.3 20 0 1\n",
            )?;
            let mut i = 0u64;
            while out.n < bytes {
                let (a, b, c) = (i % 10, (i / 10) % 10, (i / 100) % 10);
                let line = if kind == "nff-spheres" {
                    format!("s {a} {b} {c} 1\n")
                } else {
                    format!("p 3\n{a} {b} {c}\n{a}.5 {b} {c}\n{a} {b}.5 {c}\n")
                };
                out.put(&line)?;
                i += 1;
            }
        }
        "toml-spheres" => {
            out.put(
                "[camera]\nfrom = [5, 5, 25]\nat = [5, 5, 5]\nwidth = 64\nheight = 64\n\
                 [[lights]]\nposition = [5, 20, 20]\n",
            )?;
            let mut i = 0u64;
            while out.n < bytes {
                let (a, b, c) = (i % 10, (i / 10) % 10, (i / 100) % 10);
                out.put(&format!(
                    "[[objects]]\ntype = \"sphere\"\ncenter = [{a}, {b}, {c}]\nradius = 1\n"
                ))?;
                i += 1;
            }
        }
        "obj" | "obj-smooth" => {
            // an n x n grid: n^2 vertices (and normals), 2 (n-1)^2 triangles
            let smooth = kind == "obj-smooth";
            let per_quad = if smooth { 60 } else { 40 };
            let n = ((bytes / per_quad) as f64).sqrt().max(2.0) as u64;
            for y in 0..n {
                for x in 0..n {
                    out.put(&format!("v {x} {y} {}\n", (x * y) % 7))?;
                }
            }
            if smooth {
                out.put("vn 0 0 1\n")?;
            }
            for y in 0..n - 1 {
                for x in 0..n - 1 {
                    let a = y * n + x + 1;
                    let (b, c, d) = (a + 1, a + n + 1, a + n);
                    let face = if smooth {
                        format!("f {a}//1 {b}//1 {c}//1\nf {a}//1 {c}//1 {d}//1\n")
                    } else {
                        format!("f {a} {b} {c}\nf {a} {c} {d}\n")
                    };
                    out.put(&face)?;
                }
            }
        }
        _ => usage(),
    }
    out.w.flush()
}

/// A file being written, and how many bytes so far.
struct Out {
    w: std::io::BufWriter<std::fs::File>,
    n: u64,
}

impl Out {
    fn put(&mut self, s: &str) -> std::io::Result<()> {
        self.n += s.len() as u64;
        self.w.write_all(s.as_bytes())
    }
}
