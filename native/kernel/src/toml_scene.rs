//! RingTracer's native scene format (TOML).
//!
//! Unknown keys are errors, and so are keys and tables given twice (TOML forbids them); errors
//! carry `file:line`. All numbers must be finite; `fov` must be in (0, 180); a cone's radii may
//! not have opposite signs; a transparent material (`t > 0`) needs `ior > 0`. Input that
//! renders but maybe not as meant gives a warning with file and line ([`Scene::warnings`]): a
//! degenerate object (zero radius or area, base = apex), a zero vertex normal, colours, kd, ks
//! or t outside [0, 1], ks + t > 1, a negative shine, negative light, ambient or background
//! colours, and a scene without objects or lights (docs/scene-format.md has the table). A file
//! is at most [`limits::MAX_TOML_BYTES`], a key or string at most [`limits::MAX_TOKEN_BYTES`].
//! Colours are linear RGB triples; a material no object uses is fine (a library of them).
//! docs/scene-format.md is the reference of every key, with its type, default and bounds.
//! Example with every feature:
//!
//! ```toml
//! background = [0.45, 0.65, 0.95]   # top-level keys come before the first [table]
//! ambient = 0.15                    # number or [r, g, b]; default sqrt(n)/(2n) for n lights
//!
//! [camera]
//! from = [0.0, 1.5, 6.0]
//! at = [0.0, 1.0, 0.0]
//! up = [0.0, 1.0, 0.0]      # default +y
//! fov = 45.0                # degrees, NFF convention (see crate::camera); default 45
//! width = 640               # default 640
//! height = 480              # default 480
//!
//! [[lights]]
//! position = [5.0, 8.0, 6.0]
//! color = [0.9, 0.9, 0.9]   # default: sqrt(n)/(2n) white
//!
//! [materials.glass]
//! color = [1.0, 1.0, 1.0]   # default white
//! kd = 0.0                  # default 1
//! ks = 0.15                 # default 0
//! shine = 80.0              # default 20
//! t = 0.85                  # default 0
//! ior = 1.5                 # default 1
//!
//! [materials.floor]
//! color = [1.0, 0.1, 0.1]
//! checker = { color2 = [1.0, 1.0, 0.1], scale = 1.0 }
//!
//! [[objects]]
//! type = "sphere"           # a negative radius: seen from inside only
//! center = [0.0, 1.0, 0.0]
//! radius = 1.0
//! material = "glass"        # every object: optional, default white diffuse
//!
//! [[objects]]
//! type = "plane"            # infinite, kept outside the BVH
//! point = [0.0, 0.0, 0.0]
//! normal = [0.0, 1.0, 0.0]
//! material = "floor"
//!
//! [[objects]]
//! type = "triangle"
//! vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
//! normals = [[0, 0, 1], [0, 0, 1], [0, 0, 1]]   # optional, smooth shading
//!
//! [[objects]]
//! type = "polygon"          # planar, convex or concave, CCW seen from the front
//! vertices = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
//!
//! [[objects]]
//! type = "cone"             # no end caps; negative radii: inside only
//! base = [2, 0, 0]
//! base_radius = 0.5
//! apex = [2, 1, 0]
//! apex_radius = 0.1
//!
//! [[objects]]
//! type = "cylinder"
//! base = [-2, 0, 0]
//! apex = [-2, 1, 0]
//! radius = 0.3
//!
//! [[objects]]
//! type = "mesh"
//! file = "meshes/teapot.obj"        # resolved relative to the scene file
//! translate = [0, 0, -3]            # transform = translate * rotate_y * scale ...
//! scale = 0.5                       # number or [sx, sy, sz]
//! rotate_y_degrees = 30
//! # matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0]]   # ... or a 3x4 / 4x4 row-major matrix instead
//! smooth = true                     # use the OBJ's vertex normals (default true)
//! material = "glass"                # overrides the MTL colours
//!
//! [[objects]]
//! type = "mesh"                     # the same file again: read once, drawn twice
//! file = "meshes/teapot.obj"
//! matrix = [[0.5, 0, 0, 2], [0, 0.5, 0, 0], [0, 0, -0.5, -3]]   # a mirror image
//!
//! [[objects]]
//! type = "include"                  # the objects of an NFF file, e.g. an SPD scene; static
//! file = "spd/balls_s1.nff"         # resolved as a mesh's file; its 'v' and 'b' left out
//! lights = false                    # its lights too (default false)
//! ```
//!
//! An `[animation]` table and `animate` key lists on the camera, lights, materials and objects
//! make the scene a sequence of frames: see [`crate::animated`]; [`parse`] gives the first.
//!
//! Meshes: every distinct (`file` as written, `smooth`) is read and parsed once. If the scene
//! references it once, its triangles are transformed into the scene (flattened, as they
//! always were). If it references it more than once, its triangles and their BVH are built
//! once in the OBJ's own space and each reference is an instance of them: the transform and
//! its inverse and the material (see [`crate::instance`]). So a mesh drawn 3 000 times costs
//! one mesh in memory plus a few hundred bytes per reference, and its triangles count once
//! towards [`limits::MAX_PRIMITIVES`]; [`Scene::primitive_count`] still counts them once per
//! reference (what the image holds). An instance gives the hits a flattened copy would, up to
//! rounding (distances and normals within 1e-4, mostly within 1e-6). Two spellings of one path
//! (`a.obj`, `./a.obj`) are two meshes. At most [`limits::MAX_MESH_REFERENCES`] references;
//! every transform must be invertible.

use crate::animated::AnimatedScene;
use crate::camera::Camera;
use crate::error::{quoted_snippets, snippet};
use crate::files::Unreadable;
use crate::light::{spd_intensity, Light};
use crate::limits;
use crate::material::{check_light_colour, Checker, Material};
use crate::scene::{Scene, SceneBuilder};
use crate::warning::Warnings;
use crate::Error;
use glam::{Affine3A, Mat3A, Vec3A};
use serde::de::IgnoredAny;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::ops::Range;
use toml::Spanned;

type V3 = [f32; 3];

#[derive(Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct SceneDef {
    /// Read by [`crate::animated`] (a second pass over the text keeps the spans of the keys).
    #[serde(default)]
    animation: Option<IgnoredAny>,
    pub(crate) camera: Spanned<CameraDef>,
    #[serde(default)]
    background: Option<Spanned<V3>>,
    #[serde(default)]
    ambient: Option<Spanned<Scalar3>>,
    #[serde(default)]
    pub(crate) lights: Vec<Spanned<LightDef>>,
    #[serde(default)]
    pub(crate) materials: BTreeMap<String, Spanned<MaterialDef>>,
    #[serde(default)]
    pub(crate) objects: Vec<Spanned<ObjectDef>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
pub(crate) enum Scalar3 {
    One(f32),
    Three(V3),
}

impl Scalar3 {
    fn vec(self) -> Vec3A {
        match self {
            Scalar3::One(v) => Vec3A::splat(v),
            Scalar3::Three(v) => Vec3A::from_array(v),
        }
    }
}

fn up_y() -> V3 {
    [0.0, 1.0, 0.0]
}
fn fov45() -> f32 {
    45.0
}
fn w640() -> u32 {
    640
}
fn h480() -> u32 {
    480
}
fn one3() -> V3 {
    [1.0; 3]
}
fn one() -> f32 {
    1.0
}
fn twenty() -> f32 {
    20.0
}
fn yes() -> bool {
    true
}

#[derive(Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraDef {
    pub(crate) from: V3,
    pub(crate) at: V3,
    #[serde(default = "up_y")]
    pub(crate) up: V3,
    #[serde(default = "fov45")]
    pub(crate) fov: f32,
    #[serde(default = "w640")]
    width: u32,
    #[serde(default = "h480")]
    height: u32,
    #[serde(default)]
    animate: Option<IgnoredAny>,
}

#[derive(Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct LightDef {
    pub(crate) position: V3,
    #[serde(default)]
    pub(crate) color: Option<V3>,
    #[serde(default)]
    animate: Option<IgnoredAny>,
}

#[derive(Deserialize, Clone)]
#[serde(deny_unknown_fields)]
struct CheckerDef {
    color2: V3,
    #[serde(default = "one")]
    scale: f32,
}

#[derive(Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct MaterialDef {
    #[serde(default = "one3")]
    pub(crate) color: V3,
    #[serde(default = "one")]
    kd: f32,
    #[serde(default)]
    ks: f32,
    #[serde(default = "twenty")]
    shine: f32,
    #[serde(default)]
    t: f32,
    #[serde(default = "one")]
    ior: f32,
    #[serde(default)]
    checker: Option<CheckerDef>,
    #[serde(default)]
    animate: Option<IgnoredAny>,
}

/// An object as written; `animate` (its key lists) is read by [`crate::animated`].
#[derive(Deserialize, Clone)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub(crate) enum ObjectDef {
    Sphere {
        center: V3,
        radius: f32,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Plane {
        point: V3,
        normal: V3,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Triangle {
        vertices: [V3; 3],
        #[serde(default)]
        normals: Option<[V3; 3]>,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Polygon {
        vertices: Vec<V3>,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Cone {
        base: V3,
        base_radius: f32,
        apex: V3,
        apex_radius: f32,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Cylinder {
        base: V3,
        apex: V3,
        radius: f32,
        #[serde(default)]
        material: Option<String>,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
    Mesh {
        file: String,
        #[serde(default)]
        translate: Option<V3>,
        #[serde(default)]
        scale: Option<Scalar3>,
        #[serde(default)]
        rotate_y_degrees: Option<f32>,
        #[serde(default)]
        matrix: Option<Vec<Vec<f32>>>,
        #[serde(default)]
        material: Option<String>,
        #[serde(default = "yes")]
        smooth: bool,
        #[serde(default)]
        animate: Option<IgnoredAny>,
        /// The animation's move at a clock, applied after the mesh's own placement.
        #[serde(skip)]
        motion: Option<Affine3A>,
    },
    /// The objects of an NFF file (its lights too with `lights = true`).
    Include {
        file: String,
        #[serde(default)]
        lights: bool,
        #[serde(default)]
        animate: Option<IgnoredAny>,
    },
}

pub(crate) fn line_of(src: &[u8], offset: usize) -> usize {
    1 + src
        .get(..offset.min(src.len()))
        .map_or(0, |s| s.iter().filter(|&&c| c == b'\n').count())
}

/// The text of a TOML scene and its name, for errors and warnings with lines.
pub(crate) struct Ctx<'a> {
    pub(crate) src: &'a [u8],
    pub(crate) file: &'a str,
}

impl Ctx<'_> {
    pub(crate) fn line(&self, span: &Range<usize>) -> usize {
        line_of(self.src, span.start)
    }

    fn warn(&self, warnings: &mut Warnings, span: &Range<usize>, w: String) {
        warnings.add(self.file, Some(self.line(span)), move || w)
    }

    pub(crate) fn err(&self, span: Range<usize>, msg: impl Into<String>) -> Error {
        Error::parse(self.file, line_of(self.src, span.start), msg)
    }

    pub(crate) fn finite(
        &self,
        span: &Range<usize>,
        what: &str,
        vals: &[f32],
    ) -> Result<(), Error> {
        if vals.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(self.err(
                span.clone(),
                format!("{what} must be finite numbers (32-bit floats reach about 3.4e38)"),
            ))
        }
    }

    fn v3(&self, span: &Range<usize>, what: &str, v: V3) -> Result<Vec3A, Error> {
        self.finite(span, what, &v)?;
        Ok(Vec3A::from_array(v))
    }
}

/// Parses a TOML scene; an animated one gives its first frame (see [`crate::animated`]).
pub fn parse(
    bytes: &[u8],
    file: &str,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Result<Scene, Error> {
    Ok(parse_animated(bytes, file, resolve)?.into_first_frame())
}

/// Parses a TOML scene with its animation: a scene without `[animation]` is a still (one
/// frame at clock 0).
pub(crate) fn parse_animated(
    bytes: &[u8],
    file: &str,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
) -> Result<AnimatedScene, Error> {
    let def = read(bytes, file)?;
    let cx = Ctx { src: bytes, file };
    if def.animated() {
        return AnimatedScene::from_toml(def, &cx, resolve);
    }
    Ok(AnimatedScene::still(
        build(&def, &cx, resolve, &|_| false)?.scene,
    ))
}

/// Reads the text of a TOML scene into its definition: size, encoding, token lengths and
/// TOML syntax checked, every key known.
pub(crate) fn read(bytes: &[u8], file: &str) -> Result<SceneDef, Error> {
    limits::check_with(
        format!("the size of {file}"),
        bytes.len() as u64,
        " bytes",
        limits::MAX_TOML_BYTES,
        "MAX_TOML_BYTES",
        limits::MESHES,
    )?;
    let text = text(bytes, file)?;
    // before the TOML reader copies any key or string
    limits::check_tokens(bytes, limits::Tokens::Toml, file)?;
    from_toml(text, bytes, file)
}

/// The text of a TOML file; not UTF-8 is an error at the line of the first bad byte.
pub(crate) fn text<'a>(bytes: &'a [u8], file: &str) -> Result<&'a str, Error> {
    std::str::from_utf8(bytes).map_err(|e| {
        Error::parse(
            file,
            line_of(bytes, e.valid_up_to()),
            "the file is not valid UTF-8",
        )
    })
}

/// Deserialises TOML text, with a TOML error at its line.
pub(crate) fn from_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    bytes: &[u8],
    file: &str,
) -> Result<T, Error> {
    toml::from_str(text).map_err(|e| {
        let line = e.span().map_or(1, |s| line_of(bytes, s.start));
        Error::parse(file, line, quoted_snippets(e.message().trim()))
    })
}

impl SceneDef {
    /// Whether the file has an `[animation]` table or a key list (`animate`) anywhere.
    fn animated(&self) -> bool {
        self.animation.is_some()
            || self.camera.get_ref().animate.is_some()
            || self.lights.iter().any(|l| l.get_ref().animate.is_some())
            || self
                .materials
                .values()
                .any(|m| m.get_ref().animate.is_some())
            || self.objects.iter().any(|o| o.get_ref().animate().is_some())
    }
}

impl SceneDef {
    /// A copy without the objects: all that a frame needs when only the camera, the lights
    /// and material colours move.
    pub(crate) fn without_objects(&self) -> SceneDef {
        SceneDef {
            animation: self.animation,
            camera: self.camera.clone(),
            background: self.background.clone(),
            ambient: self.ambient.clone(),
            lights: self.lights.clone(),
            materials: self.materials.clone(),
            objects: Vec::new(),
        }
    }
}

impl ObjectDef {
    fn animate(&self) -> Option<IgnoredAny> {
        match self {
            ObjectDef::Sphere { animate, .. }
            | ObjectDef::Plane { animate, .. }
            | ObjectDef::Triangle { animate, .. }
            | ObjectDef::Polygon { animate, .. }
            | ObjectDef::Cone { animate, .. }
            | ObjectDef::Cylinder { animate, .. }
            | ObjectDef::Mesh { animate, .. }
            | ObjectDef::Include { animate, .. } => *animate,
        }
    }
}

/// The camera and the image size of a scene definition.
pub(crate) fn camera(def: &SceneDef, cx: &Ctx) -> Result<(Camera, (u32, u32)), Error> {
    let cspan = def.camera.span();
    let c = def.camera.get_ref();
    let from = cx.v3(&cspan, "camera 'from'", c.from)?;
    let at = cx.v3(&cspan, "camera 'at'", c.at)?;
    let up = cx.v3(&cspan, "camera 'up'", c.up)?;
    cx.finite(&cspan, "camera 'fov'", &[c.fov])?;
    if !(c.fov > 0.0 && c.fov < 180.0) {
        return Err(cx.err(
            cspan,
            format!("camera 'fov' {} is not in (0, 180) degrees", c.fov),
        ));
    }
    let camera = Camera::new(from, at, up, c.fov).ok_or_else(|| {
        cx.err(
            cspan.clone(),
            "degenerate camera: 'from' equals 'at', or 'up' is parallel to the view direction",
        )
    })?;
    limits::check_resolution(c.width, c.height)
        .map_err(|e| cx.err(cspan.clone(), format!("camera resolution: {e}")))?;
    Ok((camera, (c.width, c.height)))
}

/// The lights of a scene definition; their warnings go to `warnings`.
pub(crate) fn lights(
    def: &SceneDef,
    cx: &Ctx,
    warnings: &mut Warnings,
) -> Result<Vec<Light>, Error> {
    limits::check(
        "light count",
        def.lights.len() as u64,
        limits::MAX_LIGHTS as u64,
        "MAX_LIGHTS",
    )
    .map_err(|e| {
        let first_extra = def
            .lights
            .get(limits::MAX_LIGHTS)
            .map_or(0..0, |l| l.span());
        cx.err(first_extra, e.to_string())
    })?;
    let n = def.lights.len();
    let mut out = Vec::with_capacity(n);
    for l in &def.lights {
        let span = l.span();
        let l = l.get_ref();
        let position = cx.v3(&span, "light 'position'", l.position)?;
        let color = match l.color {
            Some(c) => {
                let c = cx.v3(&span, "light 'color'", c)?;
                if let Some(w) = check_light_colour("light 'color'", c) {
                    cx.warn(warnings, &span, w);
                }
                c
            }
            None => Vec3A::splat(spd_intensity(n)),
        };
        out.push(Light { position, color });
    }
    Ok(out)
}

/// Material `name` of a scene definition; its warnings go to `warnings`.
pub(crate) fn material(
    cx: &Ctx,
    name: &str,
    m: &Spanned<MaterialDef>,
    warnings: &mut Warnings,
) -> Result<Material, Error> {
    let span = m.span();
    let m = m.get_ref();
    let what = format!("material '{}'", snippet(name));
    cx.finite(&span, &what, &[m.kd, m.ks, m.shine, m.t, m.ior])?;
    let checker = match &m.checker {
        Some(ch) => {
            if !(ch.scale.is_finite() && ch.scale > 0.0) {
                return Err(cx.err(span, format!("{what}: checker scale must be > 0")));
            }
            Some(Checker {
                color2: cx.v3(&span, &what, ch.color2)?,
                scale: ch.scale,
            })
        }
        None => None,
    };
    let mat = Material {
        color: cx.v3(&span, &what, m.color)?,
        kd: m.kd,
        ks: m.ks,
        shine: m.shine,
        t: m.t,
        ior: m.ior,
        checker,
    };
    let keys = ["'kd'", "'ks'", "'shine'", "'t'", "'ior'"];
    for w in mat
        .check(keys)
        .map_err(|e| cx.err(span.clone(), format!("{what}: {e}")))?
    {
        cx.warn(warnings, &span, format!("{what}: {w}"));
    }
    Ok(mat)
}

/// What [`build`] made: the scene, each named material's index in it, and for each mesh
/// object that moves (has a `motion`) its instance.
pub(crate) struct Built {
    pub(crate) scene: Scene,
    pub(crate) materials: BTreeMap<String, u32>,
    pub(crate) moving_meshes: BTreeMap<usize, MovingMesh>,
}

/// A moving mesh object's instance: its index in the scene's placements
/// ([`Scene::with_moved_instances`]), the transform of the object as written (the motion
/// applies after it), and the object's line.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MovingMesh {
    pub(crate) instance: usize,
    pub(crate) placed: Affine3A,
    pub(crate) line: usize,
}

/// Builds the scene a definition describes. `own(name)`: material `name` gets an index of its
/// own (an animated colour must not change a material that happens to equal it). A mesh with
/// a `motion` is always an instance (also when referenced once), so that moving it moves only
/// the instance.
pub(crate) fn build(
    def: &SceneDef,
    cx: &Ctx,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    own: &dyn Fn(&str) -> bool,
) -> Result<Built, Error> {
    let file = cx.file;
    let mut b = SceneBuilder::new();
    let (camera, resolution) = camera(def, cx)?;
    b.camera = Some(camera);
    b.resolution = resolution;
    lighting(def, cx, &mut b)?;
    // Mesh references by (file as written, smooth): a mesh referenced once is flattened into
    // the scene, one referenced more often is read once and instanced.
    let mesh_refs = mesh_references(&def.objects, limits::MAX_MESH_REFERENCES, cx)?;
    let default_mat = b.material(Material::default());
    let names = named_materials(def, cx, own, &mut b)?;
    let mut objects = Objects {
        cx,
        resolve,
        names: &names,
        default_mat,
        mesh_refs,
        shared: BTreeMap::new(),
        moving_meshes: BTreeMap::new(),
    };
    for (index, o) in def.objects.iter().enumerate() {
        objects.add(&mut b, index, o)?;
    }
    let moving_meshes = objects.moving_meshes;
    crate::warning::scene_warnings(&mut b, file);
    Ok(Built {
        scene: b.build(file)?,
        materials: names,
        moving_meshes,
    })
}

/// The background, the ambient light and the lights, into `b`.
fn lighting(def: &SceneDef, cx: &Ctx, b: &mut SceneBuilder) -> Result<(), Error> {
    if let Some(bg) = &def.background {
        b.background = cx.v3(&bg.span(), "background", *bg.get_ref())?;
        if let Some(w) = check_light_colour("background", b.background) {
            cx.warn(&mut b.warnings, &bg.span(), w);
        }
    }
    if let Some(a) = &def.ambient {
        let v = a.get_ref().vec();
        cx.finite(&a.span(), "ambient", &v.to_array())?;
        if let Some(w) = check_light_colour("ambient", v) {
            cx.warn(&mut b.warnings, &a.span(), w);
        }
        b.ambient = Some(v);
    }
    b.lights = lights(def, cx, &mut b.warnings)?;
    Ok(())
}

/// The named materials, added to `b` (an own index for those `own` names): each name's index.
fn named_materials(
    def: &SceneDef,
    cx: &Ctx,
    own: &dyn Fn(&str) -> bool,
    b: &mut SceneBuilder,
) -> Result<BTreeMap<String, u32>, Error> {
    let mut names: BTreeMap<String, u32> = BTreeMap::new();
    for (name, m) in &def.materials {
        let mat = material(cx, name, m, &mut b.warnings)?;
        let idx = if own(name) {
            b.materials.push(mat);
            (b.materials.len() - 1) as u32
        } else {
            b.material(mat)
        };
        names.insert(name.clone(), idx);
    }
    Ok(names)
}

/// A builder's error (a limit, the memory left) as an error at the object's line.
fn at_object(cx: &Ctx, span: &Range<usize>, e: Error) -> Error {
    cx.err(span.clone(), e.to_string())
}

/// What adding a scene's objects needs and gathers: the named materials, how often each mesh
/// is referenced, the shared meshes read so far, and the instances of moving meshes.
struct Objects<'a> {
    cx: &'a Ctx<'a>,
    resolve: &'a dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    names: &'a BTreeMap<String, u32>,
    default_mat: u32,
    mesh_refs: BTreeMap<(&'a str, bool), usize>,
    /// Shared meshes by (file as written, smooth).
    shared: BTreeMap<(&'a str, bool), u32>,
    moving_meshes: BTreeMap<usize, MovingMesh>,
}

impl<'a> Objects<'a> {
    /// The index of material `m` (the default one if none is named).
    fn find(&self, span: &Range<usize>, m: &Option<String>) -> Result<u32, Error> {
        match m {
            None => Ok(self.default_mat),
            Some(n) => self.names.get(n.as_str()).copied().ok_or_else(|| {
                self.cx
                    .err(span.clone(), format!("unknown material '{}'", snippet(n)))
            }),
        }
    }

    /// Adds object `index`, `o`, to `b`, with a warning if it is degenerate and left out.
    fn add(
        &mut self,
        b: &mut SceneBuilder,
        index: usize,
        o: &'a Spanned<ObjectDef>,
    ) -> Result<(), Error> {
        let span = o.span();
        let before = b.primitive_count();
        // what a degenerate object of this kind is, for the warning that it is left out
        let degenerate = match o.get_ref() {
            ObjectDef::Sphere { .. } | ObjectDef::Plane { .. } => {
                self.sphere_or_plane(b, &span, o.get_ref())?
            }
            ObjectDef::Triangle {
                vertices,
                normals,
                material,
                ..
            } => {
                self.triangle(b, &span, vertices, normals, material)?;
                Some("triangle has zero area (its vertices are equal or on one line)")
            }
            ObjectDef::Polygon {
                vertices, material, ..
            } => {
                self.polygon(b, &span, vertices, material)?;
                Some("polygon has zero area (its vertices are equal or on one line)")
            }
            ObjectDef::Cone { .. } | ObjectDef::Cylinder { .. } => {
                self.cone(b, &span, o.get_ref())?
            }
            ObjectDef::Mesh { .. } => {
                self.mesh(b, index, &span, o.get_ref())?;
                None
            }
            ObjectDef::Include {
                file: included,
                lights,
                ..
            } => {
                include(self.cx, self.resolve, b, &span, included, *lights)?;
                None
            }
        };
        if let Some(what) = degenerate.filter(|_| b.primitive_count() == before) {
            (self.cx).warn(
                &mut b.warnings,
                &span,
                format!("{what} and is not rendered"),
            );
        }
        Ok(())
    }

    /// A sphere or a plane object; for a sphere, what it is when degenerate.
    fn sphere_or_plane(
        &self,
        b: &mut SceneBuilder,
        span: &Range<usize>,
        o: &ObjectDef,
    ) -> Result<Option<&'static str>, Error> {
        let cx = self.cx;
        let lim = |e: Error| at_object(cx, span, e);
        match o {
            ObjectDef::Sphere {
                center,
                radius,
                material,
                ..
            } => {
                let c = cx.v3(span, "sphere 'center'", *center)?;
                cx.finite(span, "sphere 'radius'", &[*radius])?;
                b.sphere(c, *radius, self.find(span, material)?)
                    .map_err(lim)?;
                Ok(Some("sphere has 'radius' 0"))
            }
            ObjectDef::Plane {
                point,
                normal,
                material,
                ..
            } => {
                let p = cx.v3(span, "plane 'point'", *point)?;
                let n = cx.v3(span, "plane 'normal'", *normal)?;
                if b.plane(p, n, self.find(span, material)?)
                    .map_err(lim)?
                    .is_none()
                {
                    return Err(cx.err(span.clone(), "plane 'normal' must not be zero"));
                }
                Ok(None)
            }
            _ => Ok(None),
        }
    }

    /// A cone or a cylinder object; what it is when degenerate.
    fn cone(
        &self,
        b: &mut SceneBuilder,
        span: &Range<usize>,
        o: &ObjectDef,
    ) -> Result<Option<&'static str>, Error> {
        let cx = self.cx;
        let lim = |e: Error| at_object(cx, span, e);
        match o {
            ObjectDef::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
                material,
                ..
            } => {
                let b0 = cx.v3(span, "cone 'base'", *base)?;
                let a0 = cx.v3(span, "cone 'apex'", *apex)?;
                cx.finite(span, "cone radii", &[*base_radius, *apex_radius])?;
                crate::nff::check_cone_radii(*base_radius, *apex_radius)
                    .map_err(|e| cx.err(span.clone(), format!("cone {e}")))?;
                b.cone(
                    b0,
                    *base_radius,
                    a0,
                    *apex_radius,
                    self.find(span, material)?,
                )
                .map_err(lim)?;
                Ok(Some("cone has base = apex or both radii 0"))
            }
            ObjectDef::Cylinder {
                base,
                apex,
                radius,
                material,
                ..
            } => {
                let b0 = cx.v3(span, "cylinder 'base'", *base)?;
                let a0 = cx.v3(span, "cylinder 'apex'", *apex)?;
                cx.finite(span, "cylinder 'radius'", &[*radius])?;
                b.cone(b0, *radius, a0, *radius, self.find(span, material)?)
                    .map_err(lim)?;
                Ok(Some("cylinder has base = apex or 'radius' 0"))
            }
            _ => Ok(None),
        }
    }

    /// A triangle object, its vertex normals normalised (a zero one with a warning).
    fn triangle(
        &self,
        b: &mut SceneBuilder,
        span: &Range<usize>,
        vertices: &[V3; 3],
        normals: &Option<[V3; 3]>,
        material: &Option<String>,
    ) -> Result<(), Error> {
        let cx = self.cx;
        let v = [
            cx.v3(span, "triangle 'vertices'", vertices[0])?,
            cx.v3(span, "triangle 'vertices'", vertices[1])?,
            cx.v3(span, "triangle 'vertices'", vertices[2])?,
        ];
        let n = match normals {
            Some(n) => {
                let n = [
                    cx.v3(span, "triangle 'normals'", n[0])?,
                    cx.v3(span, "triangle 'normals'", n[1])?,
                    cx.v3(span, "triangle 'normals'", n[2])?,
                ];
                if n.contains(&Vec3A::ZERO) {
                    cx.warn(
                        &mut b.warnings,
                        span,
                        "triangle has a zero vertex normal, which has no direction: the \
                         shading there follows the other vertices' normals"
                            .into(),
                    );
                }
                Some(n.map(Vec3A::normalize_or_zero))
            }
            None => None,
        };
        b.triangle(v, n, self.find(span, material)?)
            .map_err(|e| at_object(cx, span, e))
    }

    /// A polygon object: at least 3 vertices, at most [`limits::MAX_POLYGON_VERTICES`].
    fn polygon(
        &self,
        b: &mut SceneBuilder,
        span: &Range<usize>,
        vertices: &[V3],
        material: &Option<String>,
    ) -> Result<(), Error> {
        let cx = self.cx;
        let lim = |e: Error| at_object(cx, span, e);
        if vertices.len() < 3 {
            return Err(cx.err(
                span.clone(),
                format!("polygon needs at least 3 vertices, got {}", vertices.len()),
            ));
        }
        limits::check(
            "polygon vertex count",
            vertices.len() as u64,
            limits::MAX_POLYGON_VERTICES as u64,
            "MAX_POLYGON_VERTICES",
        )
        .map_err(lim)?;
        let vs = vertices
            .iter()
            .map(|v| cx.v3(span, "polygon 'vertices'", *v))
            .collect::<Result<Vec<_>, _>>()?;
        b.polygon(&vs, self.find(span, material)?).map_err(lim)
    }

    /// Mesh object `index`, `mesh`: flattened into the scene when referenced once and not
    /// moving, else an instance of the mesh read once (recorded in `moving_meshes` if it moves).
    fn mesh(
        &mut self,
        b: &mut SceneBuilder,
        index: usize,
        span: &Range<usize>,
        mesh: &'a ObjectDef,
    ) -> Result<(), Error> {
        let ObjectDef::Mesh {
            file: mesh_file,
            material,
            smooth,
            motion,
            ..
        } = mesh
        else {
            return Ok(());
        };
        let cx = self.cx;
        let resolve = self.resolve;
        let placed = mesh_transform(cx, span, mesh)?;
        let xf = motion.map_or(placed, |m| m * placed);
        // the inverse is what an instance keeps, so it must exist whatever the count
        if xf.matrix3.determinant() == 0.0 || !xf.inverse().is_finite() {
            return Err(cx.err(span.clone(), "mesh transform is singular (zero scale?)"));
        }
        let shown = snippet(mesh_file);
        let mat = match material {
            Some(_) => Some(self.find(span, material)?),
            None => None,
        };
        let key = (mesh_file.as_str(), *smooth);
        let load = |xf: Affine3A, mat: Option<u32>, b: &mut SceneBuilder| {
            let data = resolve(mesh_file)
                .map_err(|e| cx.err(span.clone(), format!("cannot load mesh '{shown}': {e}")))?;
            crate::obj::load_mesh(&data, &shown, resolve, xf, mat, *smooth, b)
                .map_err(|e| at_object(cx, span, e))
        };
        if self.mesh_refs.get(&key).copied().unwrap_or(0) <= 1 && motion.is_none() {
            // referenced once: flattened, as it always was
            load(xf, mat, b)?;
            return Ok(());
        }
        let mesh = match self.shared.get(&key) {
            Some(&m) => m,
            None => {
                let mut mb = b.for_mesh();
                load(Affine3A::IDENTITY, None, &mut mb)?;
                let m = b.add_mesh(mb, &shown).map_err(|e| at_object(cx, span, e))?;
                self.shared.insert(key, m);
                m
            }
        };
        let instance = b.placed_instances();
        if !b
            .instance(mesh, xf, mat)
            .map_err(|e| at_object(cx, span, e))?
        {
            return Err(cx.err(span.clone(), "mesh transform is singular (zero scale?)"));
        }
        // (an empty mesh places no instance, and there is nothing to move)
        if motion.is_some() && b.placed_instances() > instance {
            let line = cx.line(span);
            self.moving_meshes.insert(
                index,
                MovingMesh {
                    instance,
                    placed,
                    line,
                },
            );
        }
        Ok(())
    }
}

/// A mesh object's transform as written (its `motion` not applied): its `matrix`, or its
/// `translate`, `scale` and `rotate_y_degrees`.
fn mesh_transform(cx: &Ctx, span: &Range<usize>, mesh: &ObjectDef) -> Result<Affine3A, Error> {
    let ObjectDef::Mesh {
        translate,
        scale,
        rotate_y_degrees,
        matrix,
        ..
    } = mesh
    else {
        return Ok(Affine3A::IDENTITY);
    };
    if let Some(m) = matrix {
        if translate.is_some() || scale.is_some() || rotate_y_degrees.is_some() {
            return Err(cx.err(
                span.clone(),
                "mesh: give either 'matrix' or 'translate'/'scale'/'rotate_y_degrees', not both",
            ));
        }
        return matrix_transform(m).ok_or_else(|| {
            cx.err(
                span.clone(),
                "mesh 'matrix' must be 3x4 or 4x4 (rows) of finite numbers with last row 0 0 0 1",
            )
        });
    }
    let t = cx.v3(span, "mesh 'translate'", translate.unwrap_or([0.0; 3]))?;
    let s = scale.map_or(Vec3A::ONE, Scalar3::vec);
    cx.finite(span, "mesh 'scale'", &s.to_array())?;
    let r = rotate_y_degrees.unwrap_or(0.0);
    cx.finite(span, "mesh 'rotate_y_degrees'", &[r])?;
    Ok(Affine3A::from_translation(t.into())
        * Affine3A::from_rotation_y(r.to_radians())
        * Affine3A::from_scale(s.into()))
}

/// An `include` object: the objects of an NFF file (and its lights with `lights`).
fn include(
    cx: &Ctx,
    resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    b: &mut SceneBuilder,
    span: &Range<usize>,
    included: &str,
    lights: bool,
) -> Result<(), Error> {
    let shown = snippet(included);
    let data = resolve(included)
        .map_err(|e| cx.err(span.clone(), format!("cannot include '{shown}': {e}")))?;
    let format = crate::scene::Format::from_path(included);
    if format != Ok(crate::scene::Format::Nff) {
        return Err(cx.err(
            span.clone(),
            format!(
                "cannot include '{shown}': only NFF files (.nff) are included; an \
                 OBJ file is a \"mesh\""
            ),
        ));
    }
    let data = crate::files::without_bom(&data);
    crate::nff::include(data, &shown, b, lights)
}

/// How often each (mesh file as written, smooth flag) is referenced; [`Error::Limit`] at the
/// first reference past `max` (which is [`limits::MAX_MESH_REFERENCES`]), before any mesh is
/// read.
fn mesh_references<'a>(
    objects: &'a [Spanned<ObjectDef>],
    max: usize,
    cx: &Ctx,
) -> Result<BTreeMap<(&'a str, bool), usize>, Error> {
    let mut refs: BTreeMap<(&str, bool), usize> = BTreeMap::new();
    let mut count = 0u64;
    let mut first_extra = 0..0;
    for o in objects {
        if let ObjectDef::Mesh { file, smooth, .. } = o.get_ref() {
            count += 1;
            if count > max as u64 {
                if first_extra.is_empty() {
                    first_extra = o.span();
                }
            } else {
                *refs.entry((file.as_str(), *smooth)).or_default() += 1;
            }
        }
    }
    limits::check(
        "mesh reference count",
        count,
        max as u64,
        "MAX_MESH_REFERENCES",
    )
    .map_err(|e| cx.err(first_extra, e.to_string()))?;
    Ok(refs)
}

fn matrix_transform(m: &[Vec<f32>]) -> Option<Affine3A> {
    if !(m.len() == 3 || m.len() == 4)
        || m.iter()
            .any(|r| r.len() != 4 || r.iter().any(|v| !v.is_finite()))
    {
        return None;
    }
    if let Some(last) = m.get(3) {
        if last.as_slice() != [0.0, 0.0, 0.0, 1.0] {
            return None;
        }
    }
    let r = |i: usize, j: usize| m[i][j];
    let mat = Mat3A::from_cols(
        Vec3A::new(r(0, 0), r(1, 0), r(2, 0)),
        Vec3A::new(r(0, 1), r(1, 1), r(2, 1)),
        Vec3A::new(r(0, 2), r(1, 2), r(2, 2)),
    );
    Some(Affine3A {
        matrix3: mat,
        translation: Vec3A::new(r(0, 3), r(1, 3), r(2, 3)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_files(_: &str) -> Result<Vec<u8>, Unreadable> {
        Err("no files in this test".into())
    }

    fn err(src: &str) -> String {
        match parse(src.as_bytes(), "s.toml", &no_files) {
            Ok(_) => panic!("expected error"),
            Err(e) => e.to_string(),
        }
    }

    const CAM: &str = "[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n";

    #[test]
    fn parses_module_doc_example() {
        let src = crate::test_support::doc_example(include_str!("toml_scene.rs"));
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
        let resolve = |p: &str| -> Result<Vec<u8>, Unreadable> {
            if p == "meshes/teapot.obj" {
                Ok(obj.as_bytes().to_vec())
            } else if p == "spd/balls_s1.nff" {
                Ok(b"l 9 9 9\nf 1 1 1 1 0 0 0 0\ns 0 0 -5 1\n".to_vec())
            } else {
                Err(format!("no {p}").into())
            }
        };
        let s = parse(src.as_bytes(), "doc.toml", &resolve).unwrap();
        assert_eq!(s.resolution(), (640, 480));
        // the mesh's one triangle is stored once and drawn twice; the include adds a sphere
        assert_eq!(s.primitive_count(), 9);
        assert_eq!(s.stored_primitive_count(), 9);
        assert_eq!((s.mesh_count(), s.instance_count()), (1, 2));
        assert_eq!(s.light_count(), 1);
    }

    #[test]
    fn errors_have_lines() {
        assert_eq!(
            err(&format!("{CAM}\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"nope\"\n")),
            "s.toml:5: unknown material 'nope'"
        );
        let e = err(&format!("{CAM}bogus = 1\n"));
        assert!(e.starts_with("s.toml:4: unknown field `bogus`"), "{e}");
        let e = err(&format!("{CAM}\n\n[[objects]]\ntype = \"blob\"\n"));
        assert!(e.starts_with("s.toml:"), "{e}");
        let e = err(&format!(
            "{CAM}\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, nan]\nradius = 1\n"
        ));
        assert_eq!(
            e,
            "s.toml:5: sphere 'center' must be finite numbers (32-bit floats reach about 3.4e38)"
        );
        let e = err("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\nwidth = 100000\n");
        assert!(
            e.starts_with("s.toml:1: camera resolution: image width is 100000"),
            "{e}"
        );
        let e = err(&format!(
            "{CAM}\n[[objects]]\ntype = \"mesh\"\nfile = \"x.obj\"\n"
        ));
        assert!(e.starts_with("s.toml:5: cannot load mesh 'x.obj'"), "{e}");
        let e = err("[camera]\nfrom = [0, 0, 5\n");
        assert!(e.starts_with("s.toml:2:"), "{e}");
    }

    #[test]
    fn includes_the_objects_of_an_nff_file() {
        let nff = "v\nfrom 0 0 9\nat 0 0 0\nup 0 1 0\nangle 30\nhither 1\nresolution 8 8\n\
                   b 0.1 0.2 0.3\nl 1 1 1\nl 2 2 2 0.5 0.5 0.5\nf 1 0 0 1 0 0 0 0\n\
                   s 0 0 0 1\np 3\n0 0 0\n1 0 0\n0 1 0\n";
        let files = |p: &str| -> Result<Vec<u8>, Unreadable> {
            match p {
                "spd/x.nff" => Ok(nff.as_bytes().to_vec()),
                "bad.nff" => Ok(b"s 0 0 0 1\np 2\n".to_vec()),
                "m.obj" => Ok(b"v 0 0 0\n".to_vec()),
                _ => Err(format!("no {p}").into()),
            }
        };
        let scene = |extra: &str| {
            let src = format!(
                "{CAM}[[lights]]\nposition = [0, 9, 0]\n\n[[objects]]\ntype = \"sphere\"\n\
                 center = [3, 0, 0]\nradius = 1\n\n[[objects]]\ntype = \"include\"\n{extra}"
            );
            parse(src.as_bytes(), "s.toml", &files)
        };
        let s = scene("file = \"spd/x.nff\"\n").unwrap();
        // the NFF's sphere and triangle, beside the TOML's sphere; its view and background
        // are left out, its lights too unless asked for
        assert_eq!(s.primitive_count(), 3);
        assert_eq!(s.camera().from, Vec3A::new(0.0, 0.0, 5.0));
        assert_eq!(s.resolution(), (640, 480));
        assert_eq!(s.background, Vec3A::ZERO);
        assert_eq!(s.light_count(), 1);
        assert!(!s.display_referred());
        let s = scene("file = \"spd/x.nff\"\nlights = true\n").unwrap();
        assert_eq!(s.light_count(), 3);
        // a light without a colour has the SPD's intensity for the NFF's own two lights
        let half = spd_intensity(2);
        assert_eq!(s.lights[1].color, Vec3A::splat(half));
        assert_eq!(s.lights[2].color, Vec3A::splat(0.5));
        // an error in the included file names it and its line
        let e = scene("file = \"bad.nff\"\n").unwrap_err().to_string();
        assert_eq!(e, "bad.nff:2: polygon needs at least 3 vertices, got 2");
        let e = scene("file = \"gone.nff\"\n").unwrap_err().to_string();
        assert!(
            e.starts_with("s.toml:12: cannot include 'gone.nff': no gone.nff"),
            "{e}"
        );
        let e = scene("file = \"m.obj\"\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "s.toml:12: cannot include 'm.obj': only NFF files (.nff) are included; an OBJ file \
             is a \"mesh\""
        );
        let e = scene("lights = true\n").unwrap_err().to_string();
        assert!(
            e.starts_with("s.toml:") && e.contains("missing field `file`"),
            "{e}"
        );
    }

    #[test]
    fn mesh_references_are_counted_and_bounded_before_any_mesh_is_read() {
        let mut src = CAM.to_string();
        for (file, smooth) in [
            ("a.obj", true),
            ("b.obj", true),
            ("a.obj", false),
            ("a.obj", true),
        ] {
            src +=
                &format!("\n[[objects]]\ntype = \"mesh\"\nfile = \"{file}\"\nsmooth = {smooth}\n");
        }
        let def: SceneDef = toml::from_str(&src).unwrap();
        let cx = Ctx {
            src: src.as_bytes(),
            file: "m.toml",
        };
        let refs = mesh_references(&def.objects, 4, &cx).unwrap();
        let want = [
            (("a.obj", false), 1),
            (("a.obj", true), 2),
            (("b.obj", true), 1),
        ];
        assert_eq!(refs.into_iter().collect::<Vec<_>>(), want);
        assert_eq!(
            mesh_references(&def.objects, 2, &cx)
                .unwrap_err()
                .to_string(),
            "m.toml:15: mesh reference count is 4, more than the limit of 2 \
             (limits::MAX_MESH_REFERENCES); raise the constant in native/kernel/src/limits.rs \
             and rebuild"
        );
    }

    #[test]
    fn echoed_text_is_escaped_and_short() {
        let long = "q".repeat(10 << 20);
        let e = err(&format!("{CAM}\n[[objects]]\ntype = \"{long}\"\n"));
        assert!(e.len() < 700, "{} bytes", e.len());
        let e = err(&format!("{CAM}{long} = 1\n"));
        assert!(e.len() < 700, "{} bytes", e.len());
        // longer ones stop at the token limit, before the TOML reader copies them
        let e = err(&format!("{CAM}\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"{long}\"\n"));
        assert!(
            e.starts_with("s.toml:9: a token is 10485760 bytes, more than the limit of 4096"),
            "{e}"
        );
        // names up to the token limit reach the messages that echo them, cut short there
        let long = "q".repeat(limits::MAX_TOKEN_BYTES - 20);
        let e = err(&format!("{CAM}\n[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"\\u001b[31m{long}\"\n"));
        assert!(
            e.starts_with("s.toml:5: unknown material '\\u{1b}[31mqqq"),
            "{e}"
        );
        assert!(e.len() < 300 && !e.contains('\x1b'), "{e}");
        let e = err(&format!(
            "{CAM}\n[[objects]]\ntype = \"mesh\"\nfile = \"a\\u0007{long}.obj\"\n"
        ));
        assert!(
            e.starts_with("s.toml:5: cannot load mesh 'a\\u{7}qqq"),
            "{e}"
        );
        assert!(e.len() < 300 && !e.contains('\x07'), "{e}");
        let e = err("[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n\"\\u001b[2J\" = 1\n");
        assert!(e.contains("\\u{1b}[2J") && !e.contains('\x1b'), "{e}");
    }
}
