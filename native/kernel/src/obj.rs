//! Wavefront OBJ meshes (via `tobj`), with MTL diffuse colours.
//!
//! Used two ways:
//! - as a standalone scene ([`Format::Obj`](crate::Format::Obj)): the mesh with a default
//!   camera looking at the centre of its bounding box from `centre + (0.3, 0.3, 1.1) * diagonal`
//!   (45 degrees, +y up), one white light above and behind the camera, 640x480;
//! - inside a TOML scene (`type = "mesh"`) with a transform: flattened into the scene when
//!   referenced once, else loaded once in its own space and instanced (see
//!   [`crate::toml_scene`] and [`crate::instance`]).
//!
//! Faces are triangulated (fan). Vertex normals, when the file has them, give smooth shading.
//! MTL `Kd` becomes the material colour (Kd coefficient 0.9), `Ks` (max channel) the specular
//! weight, `Ns` the Phong exponent. Missing MTL files fall back to a light-grey material.
//!
//! Warnings ([`Scene::warnings`](crate::Scene::warnings), naming the OBJ and, where there is
//! one, the line): a missing or unreadable `mtllib` and a `usemtl` that names no material of it
//! (those faces are grey), `Kd`/`Ks` outside [0, 1] (clamped), points, lines, curves and
//! surfaces (not rendered: only faces are), zero-area triangles (left out, counted), and a mesh
//! without faces. A word longer than [`limits::MAX_TOKEN_BYTES`] is an error.

use crate::camera::Camera;
use crate::error::snippet;
use crate::files::Unreadable;
use crate::geometry::Aabb;
use crate::light::Light;
use crate::limits;
use crate::material::{check_unit_colour, Material};
use crate::scene::{Scene, SceneBuilder};
use crate::Error;
use glam::{Affine3A, Vec3A};
use std::collections::HashSet;

fn grey() -> Material {
    Material {
        color: Vec3A::splat(0.8),
        kd: 0.9,
        ks: 0.0,
        shine: 20.0,
        ..Material::default()
    }
}

/// Loads an OBJ into the builder; returns the bounding box of the added triangles.
pub(crate) fn load_mesh(
    bytes: &[u8],
    name: &str,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    xf: Affine3A,
    material: Option<u32>,
    smooth: bool,
    b: &mut SceneBuilder,
) -> Result<Aabb, Error> {
    let bytes = check_before_reading(bytes, name, b.max_mesh_triangles)?;
    let (models, mtls, missing) = read_obj(bytes, name, resolve)?;
    let total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    limits::check(
        format!("the triangle count of mesh {name}"),
        total as u64,
        b.max_mesh_triangles as u64,
        "MAX_MESH_TRIANGLES",
    )?;
    let default_mat = match material {
        Some(m) => m,
        None => b.material(grey()),
    };
    let mtl_ids: Vec<u32> = match (&mtls, material) {
        (Ok(ms), None) => ms.iter().map(|m| mtl_material(m, name, b)).collect(),
        _ => Vec::new(),
    };
    scan_warnings(bytes, name, &mtls, &missing, material.is_some(), b);
    let before = b.primitive_count();
    let mut bounds = Aabb::EMPTY;
    for model in &models {
        let mat = (model.mesh.material_id)
            .and_then(|i| mtl_ids.get(i).copied())
            .unwrap_or(default_mat);
        bounds = bounds.union(add_model(&model.mesh, name, xf, smooth, mat, b)?);
    }
    let added = b.primitive_count() - before;
    if total == 0 {
        b.warnings.add(name, None, || {
            "the mesh has no faces: nothing of it is rendered".into()
        });
    } else if added < total {
        b.warnings.add(name, None, || {
            format!(
                "{} of its {total} triangles have zero area (vertices equal or on one line) and \
                 are not rendered",
                total - added
            )
        });
    }
    Ok(bounds)
}

/// The checks made before the OBJ reader allocates or copies anything: the file's size, an
/// upper bound of its triangles (under `max_triangles`), its words, numbers and face indices.
/// Returns the bytes without a byte order mark.
fn check_before_reading<'a>(
    bytes: &'a [u8],
    name: &str,
    max_triangles: usize,
) -> Result<&'a [u8], Error> {
    limits::check_file_size(format!("the size of mesh {name}"), bytes.len() as u64)?;
    let bytes = crate::files::without_bom(bytes);
    // an upper bound from the face lines, before the OBJ reader allocates anything
    limits::check(
        format!("the triangle count of mesh {name} (from its face lines)"),
        limits::obj_triangle_bound(bytes),
        max_triangles as u64,
        "MAX_MESH_TRIANGLES",
    )?;
    // before the OBJ reader copies any line
    limits::check_tokens(bytes, limits::Tokens::Words, name)?;
    check_numbers(bytes, name)?;
    check_face_indices(bytes, name)?;
    Ok(bytes)
}

/// The OBJ's models (faces triangulated), its materials (or why its material libraries could
/// not be read), and the material libraries that are missing, as written.
type ReadObj = (
    Vec<tobj::Model>,
    Result<Vec<tobj::Material>, tobj::LoadError>,
    Vec<String>,
);

/// Reads checked OBJ `bytes` with `tobj`, its material libraries through `resolve`.
fn read_obj(
    bytes: &[u8],
    name: &str,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Result<ReadObj, Error> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // A material library that is missing (or was not shipped) falls back to
    // grey, as documented; one that is refused (outside the allowed folders,
    // not a regular file, too large) stops the load.
    let refused: std::cell::RefCell<Option<String>> = std::cell::RefCell::new(None);
    // material libraries that are missing, as written (for the warning)
    let missing: std::cell::RefCell<Vec<String>> = std::cell::RefCell::new(Vec::new());
    let loaded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut reader = std::io::BufReader::new(bytes);
        tobj::load_obj_buf(&mut reader, &opts, |p| {
            let rel = p.to_string_lossy();
            match resolve(&rel) {
                Ok(data) => tobj::load_mtl_buf(&mut std::io::BufReader::new(data.as_slice())),
                Err(Unreadable::Missing(_)) => {
                    missing.borrow_mut().push(rel.into_owned());
                    Err(tobj::LoadError::OpenFileFailed)
                }
                Err(Unreadable::Refused(e)) => {
                    refused.borrow_mut().get_or_insert(e);
                    Err(tobj::LoadError::OpenFileFailed)
                }
            }
        })
    }));
    if let Some(e) = refused.into_inner() {
        return Err(Error::scene(name, format!("cannot load its mtllib: {e}")));
    }
    match loaded {
        Ok(Ok((models, mtls))) => Ok((models, mtls, missing.into_inner())),
        Ok(Err(e)) => Err(Error::scene(name, format!("invalid OBJ: {e}"))),
        Err(_) => Err(Error::scene(name, "invalid OBJ (the OBJ reader failed)")),
    }
}

/// Adds MTL material `m` to `b` (colours clamped to [0, 1], with a warning); its index.
fn mtl_material(m: &tobj::Material, name: &str, b: &mut SceneBuilder) -> u32 {
    let ok3 = |v: Option<[f32; 3]>| v.filter(|a| a.iter().all(|x| x.is_finite()));
    let mut mat = grey();
    let clamped = |b: &mut SceneBuilder, what: &str, c: Vec3A| {
        if let Some(w) = check_unit_colour(what, c) {
            b.warnings.add(name, None, || {
                format!("material '{}': {w}; clamped to [0, 1]", snippet(&m.name))
            });
        }
    };
    if let Some(kd) = ok3(m.diffuse) {
        clamped(b, "Kd", Vec3A::from_array(kd));
        mat.color = Vec3A::from_array(kd).clamp(Vec3A::ZERO, Vec3A::ONE);
    }
    if let Some(ks) = ok3(m.specular) {
        clamped(b, "Ks", Vec3A::from_array(ks));
        mat.ks = Vec3A::from_array(ks).max_element().clamp(0.0, 1.0);
    }
    if let Some(ns) = m.shininess.filter(|s| s.is_finite() && *s >= 0.0) {
        mat.shine = ns;
    }
    b.material(mat)
}

/// Adds the triangles of model mesh `m` under `xf` with material `mat` (and its vertex
/// normals with `smooth`); returns their bounding box.
fn add_model(
    m: &tobj::Mesh,
    name: &str,
    xf: Affine3A,
    smooth: bool,
    mat: u32,
    b: &mut SceneBuilder,
) -> Result<Aabb, Error> {
    let nxf = xf.matrix3.inverse().transpose();
    let pos = |i: u32| -> Result<Vec3A, Error> {
        let i = i as usize * 3;
        let p = m
            .positions
            .get(i..i + 3)
            .ok_or_else(|| Error::scene(name, "vertex index out of range"))?;
        let v = Vec3A::new(p[0], p[1], p[2]);
        if !v.is_finite() {
            return Err(Error::scene(
                name,
                "vertex coordinate is not a finite number",
            ));
        }
        Ok(xf.transform_point3a(v))
    };
    let has_normals = smooth
        && nxf.is_finite()
        && !m.normals.is_empty()
        && m.normal_indices.len() == m.indices.len();
    let nrm = |i: u32| -> Option<Vec3A> {
        let i = i as usize * 3;
        let p = m.normals.get(i..i + 3)?;
        let n = Vec3A::new(p[0], p[1], p[2]);
        (nxf * n).try_normalize()
    };
    let mut bounds = Aabb::EMPTY;
    for (k, tri) in m.indices.chunks_exact(3).enumerate() {
        let v = [pos(tri[0])?, pos(tri[1])?, pos(tri[2])?];
        bounds = bounds.grow(v[0]).grow(v[1]).grow(v[2]);
        let normals = if has_normals {
            let ni = m.normal_indices.get(k * 3..k * 3 + 3);
            match ni {
                Some(ni) => match (nrm(ni[0]), nrm(ni[1]), nrm(ni[2])) {
                    (Some(a), Some(b2), Some(c)) => Some([a, b2, c]),
                    _ => None,
                },
                None => None,
            }
        } else {
            None
        };
        b.triangle(v, normals, mat)?;
    }
    Ok(bounds)
}

/// Checks what the OBJ reader would refuse without saying where, so that the error names the
/// line: text that is not UTF-8, a vertex or normal line without three numbers, a texture
/// coordinate line without two, a number that is not finite as a 32-bit float (`nan`, `inf`,
/// `1e39`), and an index of an `f` or `l` line that is not an integer.
fn check_numbers(bytes: &[u8], name: &str) -> Result<(), Error> {
    for (i, raw) in bytes.split(|&c| c == b'\n').enumerate() {
        let Ok(line) = std::str::from_utf8(raw) else {
            return Err(Error::parse(name, i + 1, "the line is not UTF-8 text"));
        };
        let mut words = line.split_ascii_whitespace();
        let (what, needed) = match words.next() {
            Some("v") => ("vertex", 3),
            Some("vn") => ("normal", 3),
            // the OBJ reader wants both u and v
            Some("vt") => ("texture coordinate", 2),
            Some("f") | Some("l") => {
                for word in words {
                    for part in word.split('/').take(3).filter(|p| !p.is_empty()) {
                        if part.parse::<i64>().is_err() {
                            return Err(Error::parse(
                                name,
                                i + 1,
                                format!("index '{}' is not an integer", snippet(part)),
                            ));
                        }
                    }
                }
                continue;
            }
            _ => continue,
        };
        let values: Vec<&str> = words.collect();
        if values.len() < needed {
            return Err(Error::parse(
                name,
                i + 1,
                format!("a {what} line needs {needed} numbers, got {}", values.len()),
            ));
        }
        for (k, word) in values.iter().enumerate().take(needed) {
            match word.parse::<f32>() {
                Ok(x) if x.is_finite() => {}
                Ok(_) => {
                    return Err(Error::parse(
                        name,
                        i + 1,
                        format!(
                            "{what} value '{}' is not a finite number (32-bit floats reach \
                             about 3.4e38)",
                            snippet(word)
                        ),
                    ))
                }
                Err(_) => {
                    return Err(Error::parse(
                        name,
                        i + 1,
                        format!("{what} value {} '{}' is not a number", k + 1, snippet(word)),
                    ))
                }
            }
        }
    }
    Ok(())
}

/// Checks every index of the `f` and `l` lines before the OBJ reader sees them: OBJ indices
/// count from 1, and a negative one counts back from the last element read so far. An index of
/// 0, one that reaches back before the first element, or one past the file's last element of
/// its kind cannot name anything (and the OBJ reader's arithmetic on such an index overflows).
fn check_face_indices(bytes: &[u8], name: &str) -> Result<(), Error> {
    const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    let kind_of = |keyword: &[u8]| match keyword {
        b"v" => Some(0),
        b"vt" => Some(1),
        b"vn" => Some(2),
        _ => None,
    };
    fn keyword(line: &[u8]) -> &[u8] {
        line.split(|c| c.is_ascii_whitespace())
            .find(|w| !w.is_empty())
            .unwrap_or_default()
    }
    let mut totals = [0i64; 3];
    for line in bytes.split(|&c| c == b'\n') {
        if let Some(k) = kind_of(keyword(line)) {
            totals[k] += 1;
        }
    }
    let mut seen = [0i64; 3];
    for (i, line) in bytes.split(|&c| c == b'\n').enumerate() {
        let first = keyword(line);
        if let Some(k) = kind_of(first) {
            seen[k] += 1;
            continue;
        }
        if first != b"f" && first != b"l" {
            continue;
        }
        let words = line
            .split(|c| c.is_ascii_whitespace())
            .filter(|w| !w.is_empty())
            .skip(1);
        for word in words {
            for (k, part) in word.split(|&c| c == b'/').enumerate().take(3) {
                // what is not a number is the OBJ reader's to refuse
                let Some(x) = std::str::from_utf8(part)
                    .ok()
                    .and_then(|p| p.parse::<i64>().ok())
                else {
                    continue;
                };
                let problem = if x == 0 {
                    Some(format!("{} index 0: OBJ indices count from 1", KINDS[k]))
                } else if x < 0 && seen[k] + x < 0 {
                    Some(format!(
                        "{} index {x} reaches back before the first {} (only {} so far)",
                        KINDS[k], KINDS[k], seen[k]
                    ))
                } else if x > totals[k] {
                    Some(format!(
                        "{} index {x}, but the file has {} of them",
                        KINDS[k], totals[k]
                    ))
                } else {
                    None
                };
                if let Some(p) = problem {
                    return Err(Error::parse(name, i + 1, p));
                }
            }
        }
    }
    Ok(())
}

/// The warnings a scan of the OBJ's lines finds: a material library that is missing or not
/// MTL (faces grey), `usemtl` naming no material of the library (those faces grey), and
/// elements that are not rendered (points, lines, curves and surfaces: only faces are). No
/// material warnings when the scene gives the mesh its own material (`overridden`).
fn scan_warnings(
    bytes: &[u8],
    name: &str,
    mtls: &Result<Vec<tobj::Material>, tobj::LoadError>,
    missing: &[String],
    overridden: bool,
    b: &mut SceneBuilder,
) {
    let known: HashSet<&str> = match mtls {
        Ok(ms) => ms.iter().map(|m| m.name.as_str()).collect(),
        Err(_) => HashSet::new(),
    };
    let mut libraries = 0usize;
    let (mut unrendered, mut first_unrendered) = (0u64, 0usize);
    for (i, raw) in bytes.split(|&c| c == b'\n').enumerate() {
        let line = i + 1;
        let text = String::from_utf8_lossy(raw);
        let text = text.trim();
        let (keyword, rest) = text
            .split_once(|c: char| c.is_ascii_whitespace())
            .map_or((text, ""), |(k, r)| (k, r.trim()));
        match keyword {
            "mtllib" if !overridden => {
                libraries += 1;
                if missing.iter().any(|m| m == rest) {
                    b.warnings.add(name, Some(line), || {
                        format!("mtllib '{}' not found: the faces are grey", snippet(rest))
                    });
                }
            }
            // the OBJ reader looks the name up when it reads the `usemtl`
            "usemtl" if !overridden && libraries == 0 => {
                b.warnings.add(name, Some(line), || {
                    format!(
                        "usemtl '{}' has no mtllib before it: its faces are grey",
                        snippet(rest)
                    )
                });
            }
            "usemtl" if !overridden && mtls.is_ok() && !known.contains(rest) => {
                b.warnings.add(name, Some(line), || {
                    format!(
                        "usemtl '{}' names no material of the mtllib: its faces are grey",
                        snippet(rest)
                    )
                });
            }
            "p" | "l" | "curv" | "curv2" | "surf" => {
                unrendered += 1;
                if first_unrendered == 0 {
                    first_unrendered = line;
                }
            }
            "f" if rest.split_ascii_whitespace().count() < 3 => {
                unrendered += 1;
                if first_unrendered == 0 {
                    first_unrendered = line;
                }
            }
            _ => {}
        }
    }
    if let Err(e) = mtls {
        if libraries > 0 && missing.len() < libraries {
            b.warnings.add(name, None, || {
                format!("its mtllib could not be read ({e}): the faces are grey")
            });
        }
    }
    if unrendered > 0 {
        b.warnings.add(name, Some(first_unrendered), || {
            format!(
                "{unrendered} point, line, curve or surface element(s), the first here, are not \
                 rendered: only faces are"
            )
        });
    }
}

/// The default view of a bounding box used for OBJ scenes (and the ray-casting benchmark):
/// looking at the centre from `centre + (0.3, 0.3, 1.1) * diagonal`, 45 degrees, +y up.
pub fn default_camera(bounds: Aabb) -> Camera {
    let (c, diag) = if bounds.is_empty() {
        (Vec3A::ZERO, 1.0)
    } else {
        (bounds.centre(), bounds.diagonal().max(1e-6))
    };
    let from = c + Vec3A::new(0.3, 0.3, 1.1) * diag;
    Camera::new(from, c, Vec3A::Y, 45.0).unwrap_or(Camera {
        from,
        forward: -Vec3A::Z,
        right: Vec3A::X,
        up: Vec3A::Y,
        tan_half: (22.5f32).to_radians().tan(),
    })
}

/// A standalone OBJ scene.
pub(crate) fn parse_scene(
    bytes: &[u8],
    name: &str,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Result<Scene, Error> {
    let mut b = SceneBuilder::new();
    let bounds = load_mesh(bytes, name, resolve, Affine3A::IDENTITY, None, true, &mut b)?;
    if b.primitive_count() == 0 {
        return Err(Error::scene(name, "the OBJ file has no faces"));
    }
    let cam = default_camera(bounds);
    let diag = bounds.diagonal().max(1e-6);
    b.lights.push(Light {
        position: cam.from + Vec3A::new(0.5, 1.0, 0.2) * diag,
        color: Vec3A::splat(0.85),
    });
    b.ambient = Some(Vec3A::splat(0.15));
    b.background = Vec3A::new(0.05, 0.06, 0.08);
    b.camera = Some(cam);
    b.resolution = (640, 480);
    b.build(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(obj: &str, max: usize) -> Result<usize, Error> {
        let mut b = SceneBuilder::new();
        b.max_mesh_triangles = max;
        let none = |_: &str| -> Result<Vec<u8>, Unreadable> {
            Err(Unreadable::Missing("no files".into()))
        };
        load_mesh(
            obj.as_bytes(),
            "m.obj",
            &none,
            Affine3A::IDENTITY,
            None,
            true,
            &mut b,
        )?;
        Ok(b.primitive_count())
    }

    /// Each triangle counts once against the bound, by the scan of the face lines and by the
    /// count after the reader alike: a mesh of exactly the bound loads, one more is refused.
    #[test]
    fn triangles_count_once_against_the_bound() {
        let verts = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0.5 0\n";
        // 2 triangles of a quad, 3 of a pentagon, 1 triangle: 6
        let obj = format!("{verts}f 1 2 4 3\nf 1 2 5 4 3\nf 1 2 3\n");
        assert_eq!(limits::obj_triangle_bound(obj.as_bytes()), 6);
        assert_eq!(load(&obj, 6).unwrap(), 6);
        let e = load(&obj, 5).unwrap_err().to_string();
        assert_eq!(
            e,
            "the triangle count of mesh m.obj (from its face lines) is 6, more than the limit \
             of 5 (limits::MAX_MESH_TRIANGLES); raise the constant in native/kernel/src/limits.rs \
             and rebuild"
        );
        // many triangle faces: n of them fit a bound of n
        let many = format!("{verts}{}", "f 1 2 3\n".repeat(3000));
        assert_eq!(load(&many, 3000).unwrap(), 3000);
        assert!(load(&many, 2999).is_err());
    }
}
