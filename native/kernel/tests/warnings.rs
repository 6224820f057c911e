//! Nothing is dropped or overridden silently: what cannot mean what it says is an error, what
//! renders but maybe not as meant is a warning with file and line (docs/scene-format.md has
//! the table). One test per case, in the table's order.

use ring_tracer_kernel::files::Unreadable;
use ring_tracer_kernel::{limits, Format, Scene};

fn no_files(_: &str) -> Result<Vec<u8>, Unreadable> {
    Err(Unreadable::Missing("no files here".into()))
}

fn parse_with(
    src: &str,
    format: Format,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Result<Scene, String> {
    let name = match format {
        Format::Nff => "w.nff",
        Format::Toml => "w.toml",
        Format::Obj => "w.obj",
    };
    Scene::parse(src.as_bytes(), format, name, resolve).map_err(|e| e.to_string())
}

/// The warnings of a scene that must parse, as printed.
fn warnings(src: &str, format: Format) -> Vec<String> {
    warnings_with(src, format, &no_files)
}

fn warnings_with(
    src: &str,
    format: Format,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Vec<String> {
    match parse_with(src, format, resolve) {
        Ok(s) => s.warnings().kept().iter().map(|w| w.to_string()).collect(),
        Err(e) => panic!("expected a scene, got {e}"),
    }
}

fn error(src: &str, format: Format) -> String {
    match parse_with(src, format, &no_files) {
        Ok(_) => panic!("expected an error for {src:?}"),
        Err(e) => e,
    }
}

/// View (lines 1-6), a light (7) and a fill (8); what a test adds starts at line 9.
const NFF: &str =
    "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 8 8\nl 1 2 3\nf 1 0 0 1 0 1 0 1\n";
const SPHERE: &str = "s 0 0 0 1\n";

/// Camera (lines 1-3) and a light (4-5); objects start at line 6.
const TOML: &str = "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[[lights]]\nposition = [1, 2, 3]\n";

fn nff(extra: &str) -> String {
    format!("{NFF}{extra}")
}

fn toml(extra: &str) -> String {
    format!("{TOML}{extra}")
}

fn assert_one(got: Vec<String>, want: &str) {
    assert_eq!(got, vec![want.to_string()]);
}

#[test]
fn clean_scenes_have_no_warnings() {
    assert!(warnings(&nff(SPHERE), Format::Nff).is_empty());
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes");
    let mut seen = 0;
    for sub in [dir.clone(), dir.join("spd")] {
        for entry in std::fs::read_dir(&sub).unwrap() {
            let path = entry.unwrap().path();
            if Format::from_path(&path.to_string_lossy()).is_err() {
                continue;
            }
            let scene = Scene::load(&path).unwrap();
            let shown: Vec<String> = scene
                .warnings()
                .kept()
                .iter()
                .map(|w| w.to_string())
                .collect();
            assert!(shown.is_empty(), "{}: {shown:?}", path.display());
            seen += 1;
        }
    }
    assert!(seen >= 14, "{seen} scenes");
}

// ---- degenerate geometry: warnings (the rest of the scene renders) ----

#[test]
fn zero_radius_sphere_warns() {
    assert_one(
        warnings(&nff("s 0 0 0 0\ns 0 0 0 1\n"), Format::Nff),
        "w.nff:9: warning: sphere 's' has radius 0 and is not rendered",
    );
    let src = toml("[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 0\n");
    assert_eq!(
        warnings(&src, Format::Toml),
        vec![
            "w.toml:6: warning: sphere has 'radius' 0 and is not rendered",
            "w.toml: warning: the scene has no objects to render: the image is the background only",
        ]
    );
}

#[test]
fn zero_area_polygons_and_triangles_warn() {
    let src = nff("p 3\n0 0 0\n1 1 1\n2 2 2\np 4\n0 0 0\n0 0 0\n0 0 0\n0 0 0\ns 0 0 0 1\n");
    assert_eq!(
        warnings(&src, Format::Nff),
        vec![
            "w.nff:9: warning: polygon 'p' has zero area (its vertices are equal or on one line) \
             and is not rendered",
            "w.nff:13: warning: polygon 'p' has zero area (its vertices are equal or on one line) \
             and is not rendered",
        ]
    );
    let src = nff("pp 3\n0 0 0 0 0 1\n0 0 0 0 0 1\n1 0 0 0 0 1\ns 0 0 0 1\n");
    assert_one(
        warnings(&src, Format::Nff),
        "w.nff:9: warning: patch 'pp' has zero area (its vertices are equal or on one line) and \
         is not rendered",
    );
    let src = toml(
        "[[objects]]\ntype = \"triangle\"\nvertices = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]\n\
         [[objects]]\ntype = \"polygon\"\nvertices = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]\n\
         [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n",
    );
    assert_eq!(
        warnings(&src, Format::Toml),
        vec![
            "w.toml:6: warning: triangle has zero area (its vertices are equal or on one line) \
             and is not rendered",
            "w.toml:9: warning: polygon has zero area (its vertices are equal or on one line) and \
             is not rendered",
        ]
    );
}

#[test]
fn degenerate_cones_warn() {
    let src = nff("c 0 0 0 1 0 0 0 0.5\nc 0 0 0 0 0 1 0 0\ns 0 0 0 1\n");
    assert_eq!(
        warnings(&src, Format::Nff),
        vec![
            "w.nff:9: warning: cone/cylinder 'c' has a zero-length axis or both radii 0 and is \
             not rendered",
            "w.nff:10: warning: cone/cylinder 'c' has a zero-length axis or both radii 0 and is \
             not rendered",
        ]
    );
    let src = toml(
        "[[objects]]\ntype = \"cone\"\nbase = [0, 0, 0]\nbase_radius = 0\napex = [0, 1, 0]\n\
         apex_radius = 0\n[[objects]]\ntype = \"cylinder\"\nbase = [1, 0, 0]\napex = [1, 0, 0]\n\
         radius = 1\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n",
    );
    assert_eq!(
        warnings(&src, Format::Toml),
        vec![
            "w.toml:6: warning: cone has base = apex or both radii 0 and is not rendered",
            "w.toml:12: warning: cylinder has base = apex or 'radius' 0 and is not rendered",
        ]
    );
}

#[test]
fn zero_vertex_normals_warn() {
    let src = nff("pp 3\n0 0 0 0 0 0\n1 0 0 0 0 1\n0 1 0 0 0 1\n");
    assert_one(
        warnings(&src, Format::Nff),
        "w.nff:9: warning: patch 'pp' has a zero vertex normal, which has no direction: the \
         shading there follows the other vertices' normals",
    );
    let src = toml(
        "[[objects]]\ntype = \"triangle\"\nvertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]\n\
         normals = [[0, 0, 1], [0, 0, 0], [0, 0, 1]]\n",
    );
    assert_one(
        warnings(&src, Format::Toml),
        "w.toml:6: warning: triangle has a zero vertex normal, which has no direction: the \
         shading there follows the other vertices' normals",
    );
}

#[test]
fn empty_and_unlit_scenes_warn() {
    assert_eq!(
        warnings("v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\n", Format::Nff),
        vec![
            "w.nff: warning: the scene has no objects to render: the image is the background only",
            "w.nff: warning: the scene has no lights: only the ambient term lights it",
        ]
    );
    assert_one(
        warnings("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[[objects]]\ntype = \"plane\"\npoint = [0, 0, 0]\nnormal = [0, 1, 0]\n", Format::Toml),
        "w.toml: warning: the scene has no lights: only the ambient term lights it",
    );
}

// ---- values out of their useful range: warnings; meaningless ones: errors ----

#[test]
fn surface_values_out_of_range_warn() {
    let src = format!("{NFF}f 1.5 0 0 1 0.6 -3 0.6 1.5\n{SPHERE}");
    assert_eq!(
        warnings(&src, Format::Nff),
        vec![
            "w.nff:9: warning: fill colour 'f': colour 1.5 0 0 is outside [0, 1]: a surface \
             reflects at most the light it receives",
            "w.nff:9: warning: fill colour 'f': Ks + T is 1.2, more than 1: the surface reflects \
             and transmits more light than it receives",
            "w.nff:9: warning: fill colour 'f': Shine -3 is negative: a Phong exponent is 0 or \
             more",
            // and the fill at line 8 was replaced before any object used it
            "w.nff:8: warning: fill colour 'f' is used by no object: the 'f' at line 9 replaces \
             it first",
        ]
    );
    let src = toml(
        "[materials.m]\nkd = 2\nchecker = { color2 = [0, -1, 0] }\n[[objects]]\n\
         type = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"m\"\n",
    );
    assert_eq!(
        warnings(&src, Format::Toml),
        vec![
            "w.toml:6: warning: material 'm': checker colour 0 -1 0 is outside [0, 1]: a surface \
             reflects at most the light it receives",
            "w.toml:6: warning: material 'm': 'kd' 2 is outside [0, 1]",
        ]
    );
}

#[test]
fn negative_light_and_background_colours_warn() {
    let src = format!("b 0 -0.1 0\nl 0 5 0 1 -1 1\n{NFF}{SPHERE}");
    assert_eq!(
        warnings(&src, Format::Nff),
        vec![
            "w.nff:1: warning: background colour 0 -0.1 0 has a negative component, which takes \
             light away",
            "w.nff:2: warning: light colour 1 -1 1 has a negative component, which takes light \
             away",
        ]
    );
    // bright lights are fine
    assert!(warnings(&format!("l 0 5 0 9 9 9\n{NFF}{SPHERE}"), Format::Nff).is_empty());
    let src = format!(
        "background = [-1, 0, 0]\nambient = -0.5\n{TOML}color = [1, 0, -2]\n\
         [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n"
    );
    assert_eq!(
        warnings(&src, Format::Toml),
        vec![
            "w.toml:1: warning: background -1 0 0 has a negative component, which takes light \
             away",
            "w.toml:2: warning: ambient -0.5 -0.5 -0.5 has a negative component, which takes \
             light away",
            "w.toml:6: warning: light 'color' 1 0 -2 has a negative component, which takes light \
             away",
        ]
    );
}

#[test]
fn unused_fill_at_the_end_warns() {
    assert_one(
        warnings(&format!("{NFF}{SPHERE}f 0 1 0 1 0 1 0 1\n"), Format::Nff),
        "w.nff:10: warning: fill colour 'f' is used by no object: none follows it",
    );
}

#[test]
fn transparent_surface_without_an_index_is_an_error() {
    assert_eq!(
        error(&format!("{NFF}f 1 1 1 0 0 1 0.5 0\n{SPHERE}"), Format::Nff),
        "w.nff:9: index of refraction 0 with T 0.5: a transparent surface needs an index of \
         refraction > 0"
    );
    // an opaque one may say 0: the SPD's files do
    assert!(warnings(
        &format!("{NFF}{SPHERE}f 1 1 1 1 0 1 0 0\n{SPHERE}"),
        Format::Nff
    )
    .is_empty());
    assert_eq!(
        error(
            &toml("[materials.glass]\nt = 0.9\nior = -1\n"),
            Format::Toml
        ),
        "w.toml:6: material 'glass': 'ior' -1 with 't' 0.9: a transparent surface needs an index \
         of refraction > 0"
    );
}

#[test]
fn field_of_view_outside_0_180_is_an_error() {
    for angle in ["0", "180", "-10", "200"] {
        let e = error(
            &format!("v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle {angle}\n{SPHERE}"),
            Format::Nff,
        );
        assert_eq!(
            e,
            format!("w.nff:1: viewpoint 'angle' {angle} is not in (0, 180) degrees")
        );
        let e = error(
            &format!("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\nfov = {angle}\n"),
            Format::Toml,
        );
        assert_eq!(
            e,
            format!("w.toml:1: camera 'fov' {angle} is not in (0, 180) degrees")
        );
    }
}

#[test]
fn cone_radii_of_opposite_signs_are_an_error() {
    assert_eq!(
        error(&nff("c 0 0 0 1 0 1 0 -1\n"), Format::Nff),
        "w.nff:9: cone/cylinder 'c': radii 1 and -1 have opposite signs (both negative: seen \
         from inside only; both positive: from outside)"
    );
    let src = toml(
        "[[objects]]\ntype = \"cone\"\nbase = [0, 0, 0]\nbase_radius = -1\napex = [0, 1, 0]\n\
         apex_radius = 0.5\n",
    );
    assert_eq!(
        error(&src, Format::Toml),
        "w.toml:6: cone radii -1 and 0.5 have opposite signs (both negative: seen from inside \
         only; both positive: from outside)"
    );
    // a zero radius goes with either sign
    assert!(warnings(&nff("c 0 0 0 0 0 1 0 -1\n"), Format::Nff).is_empty());
}

// ---- a keyword given twice: errors (one of the two values would be lost) ----

#[test]
fn a_second_viewpoint_or_background_is_an_error() {
    assert_eq!(
        error(
            &format!("{NFF}{SPHERE}v\nfrom 1 1 1\nat 0 0 0\nup 0 1 0\nangle 30\n"),
            Format::Nff
        ),
        "w.nff:10: second viewpoint 'v' (the first is at line 1): a scene has one view, and this \
         one would replace it"
    );
    assert_eq!(
        error(&format!("b 0 0 0\n{NFF}b 1 1 1\n"), Format::Nff),
        "w.nff:10: second background colour 'b' (the first is at line 1): a scene has one, and \
         this one would replace it"
    );
}

#[test]
fn a_view_keyword_twice_is_an_error() {
    assert_eq!(
        error(
            "v\nfrom 0 0 5\nat 0 0 0\nfrom 0 0 6\nup 0 1 0\nangle 45\n",
            Format::Nff
        ),
        "w.nff:4: 'from' given twice in the viewpoint 'v' (first at line 2)"
    );
    assert_eq!(
        error(
            "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nresolution 8 8\nresolution 9 9\n",
            Format::Nff
        ),
        "w.nff:7: 'resolution' given twice in the viewpoint 'v' (first at line 6)"
    );
}

#[test]
fn toml_keys_given_twice_are_errors() {
    for (src, line) in [
        ("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\nfrom = [1, 1, 1]\n", 4),
        (
            "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[camera]\nfov = 30\n",
            4,
        ),
        (
            "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[materials.a]\nkd = 1\n[materials.a]\nks = 1\n",
            6,
        ),
        (
            "background = [0, 0, 0]\nbackground = [1, 1, 1]\n[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n",
            2,
        ),
        (
            "materials.a.kd = 1\n[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n[materials.a]\nks = 1\n",
            5,
        ),
    ] {
        let e = error(src, Format::Toml);
        assert!(e.starts_with(&format!("w.toml:{line}: ")), "{e}");
        assert!(e.contains("duplicate") || e.contains("redefin"), "{e}");
    }
    // a key of another object type is unknown, not ignored
    let e = error(
        &toml(
            "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nnormal = [0, 1, 0]\n",
        ),
        Format::Toml,
    );
    assert!(e.starts_with("w.toml:6: unknown field `normal`"), "{e}");
}

// ---- OBJ meshes ----

const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

#[test]
fn obj_missing_material_library_and_names_warn() {
    let src = format!("mtllib m.mtl\n{QUAD}usemtl red\nf 1 2 3\n");
    assert_one(
        warnings(&src, Format::Obj),
        "w.obj:1: warning: mtllib 'm.mtl' not found: the faces are grey",
    );
    let mtl = |p: &str| -> Result<Vec<u8>, Unreadable> {
        match p {
            "m.mtl" => Ok(b"newmtl red\nKd 2 0 0\nKs 0.5 0.5 0.5\n".to_vec()),
            _ => Err(Unreadable::Missing("no such file".into())),
        }
    };
    let src =
        format!("usemtl red\nmtllib m.mtl\n{QUAD}usemtl red\nf 1 2 3\nusemtl blue\nf 1 3 4\n");
    assert_eq!(
        warnings_with(&src, Format::Obj, &mtl),
        vec![
            "w.obj: warning: material 'red': Kd 2 0 0 is outside [0, 1]: a surface reflects at \
             most the light it receives; clamped to [0, 1]",
            "w.obj:1: warning: usemtl 'red' has no mtllib before it: its faces are grey",
            "w.obj:9: warning: usemtl 'blue' names no material of the mtllib: its faces are grey",
        ]
    );
    // a mesh with its own material in a TOML scene uses neither the library nor the names
    let toml_src =
        toml("[materials.m]\n[[objects]]\ntype = \"mesh\"\nfile = \"x.obj\"\nmaterial = \"m\"\n");
    let mesh = move |p: &str| -> Result<Vec<u8>, Unreadable> {
        match p {
            "x.obj" => Ok(src.clone().into_bytes()),
            _ => Err(Unreadable::Missing("no".into())),
        }
    };
    assert!(warnings_with(&toml_src, Format::Toml, &mesh).is_empty());
}

#[test]
fn obj_degenerate_and_unrendered_elements_warn() {
    let src = format!("{QUAD}f 1 2 3\nf 1 1 2\nf 1 2 4 3\nl 1 2\np 1\nf 1 2\n");
    assert_eq!(
        warnings(&src, Format::Obj),
        vec![
            "w.obj:8: warning: 3 point, line, curve or surface element(s), the first here, are \
             not rendered: only faces are",
            "w.obj: warning: 1 of its 4 triangles have zero area (vertices equal or on one line) \
             and are not rendered",
        ]
    );
    // in a TOML scene the warnings name the mesh file
    let toml_src = toml("[[objects]]\ntype = \"mesh\"\nfile = \"x.obj\"\n");
    let mesh = |p: &str| -> Result<Vec<u8>, Unreadable> {
        match p {
            "x.obj" => Ok(b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n".to_vec()),
            _ => Err(Unreadable::Missing("no".into())),
        }
    };
    assert_eq!(
        warnings_with(&toml_src, Format::Toml, &mesh),
        vec![
            "x.obj: warning: 1 of its 1 triangles have zero area (vertices equal or on one line) \
             and are not rendered",
            "w.toml: warning: the scene has no objects to render: the image is the background only",
        ]
    );
    let mesh = |_: &str| -> Result<Vec<u8>, Unreadable> { Ok(b"v 0 0 0\n".to_vec()) };
    assert_eq!(
        warnings_with(&toml_src, Format::Toml, &mesh)[0],
        "x.obj: warning: the mesh has no faces: nothing of it is rendered"
    );
}

#[test]
fn an_instanced_mesh_warns_once() {
    // referenced twice: read once and instanced; its warnings are the scene's, said once
    let toml_src = toml(
        "[[objects]]\ntype = \"mesh\"\nfile = \"x.obj\"\n\
         [[objects]]\ntype = \"mesh\"\nfile = \"x.obj\"\ntranslate = [3, 0, 0]\n",
    );
    let mesh = |p: &str| -> Result<Vec<u8>, Unreadable> {
        match p {
            "x.obj" => Ok(b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec()),
            _ => Err(Unreadable::Missing("no".into())),
        }
    };
    assert_eq!(
        warnings_with(&toml_src, Format::Toml, &mesh),
        vec!["x.obj:1: warning: mtllib 'm.mtl' not found: the faces are grey"]
    );
}

// ---- the cap: a huge file of degenerate lines keeps 100 warnings and counts the rest ----

#[test]
fn warnings_are_capped_and_counted() {
    let n = 100_000;
    let src = nff(&"s 1 2 3 0\n".repeat(n));
    let scene = parse_with(&src, Format::Nff, &no_files).unwrap();
    let w = scene.warnings();
    assert_eq!(w.kept().len(), limits::MAX_WARNINGS);
    // every sphere, and the scene that has no objects
    assert_eq!(w.total(), n as u64 + 1);
    assert_eq!(w.omitted(), n as u64 + 1 - limits::MAX_WARNINGS as u64);
    assert_eq!(
        w.kept()[99].to_string(),
        "w.nff:108: warning: sphere 's' has radius 0 and is not rendered"
    );
}

// ---- token and file-size limits ----

#[test]
fn long_tokens_are_refused_before_parsing() {
    let big = "7".repeat(limits::MAX_TOKEN_BYTES + 1);
    let limit = "a token is 4097 bytes, more than the limit of 4096 (limits::MAX_TOKEN_BYTES); \
                 raise the constant in native/kernel/src/limits.rs and rebuild";
    assert_eq!(
        error(&nff(&format!("s 0 0 {big} 1\n")), Format::Nff),
        format!("w.nff:9: {limit}")
    );
    // a long comment is no token
    let comment = nff(&format!("# {big}\n{SPHERE}"));
    assert!(warnings(&comment, Format::Nff).is_empty());
    assert_eq!(
        error(&format!("{QUAD}\nf 1 2 {big}\n"), Format::Obj),
        format!("w.obj:6: {limit}")
    );
    assert_eq!(
        error(&toml(&format!("[materials.\"{big}\"]\n")), Format::Toml),
        format!("w.toml:6: {limit}")
    );
}

#[test]
fn toml_scenes_are_bounded_in_size() {
    let mut src = toml("").into_bytes();
    src.resize(limits::MAX_TOML_BYTES as usize + 1, b'\n');
    let e = Scene::parse(&src, Format::Toml, "big.toml", &no_files)
        .err()
        .unwrap()
        .to_string();
    assert_eq!(
        e,
        "the size of big.toml is 67108865 bytes, more than the limit of 67108864 \
         (limits::MAX_TOML_BYTES); put large geometry in OBJ meshes (type = \"mesh\") or raise \
         the constant in native/kernel/src/limits.rs"
    );
}
