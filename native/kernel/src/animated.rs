//! Animated scenes: a TOML scene with an `[animation]` table and key lists, and the [`Scene`]
//! of each of its frames.
//!
//! ```toml
//! [animation]
//! frames = 24               # at least 1; default clock [0, 1]
//! clock = [0.0, 1.0]        # the clock runs from the first to the last frame
//! cyclic = false            # POV-Ray's +KC: the last frame stops one step short of the end
//!
//! [camera]
//! from = [0.0, 1.5, 6.0]    # the value when the clock is not in a key list's hands
//! at = [0.0, 1.0, 0.0]
//!
//! [camera.animate.from]     # a key list: the item's 'animate' table, one per property
//! interpolation = "smooth"  # "linear" (default) or "smooth" (Catmull-Rom, C1)
//! keys = [
//!   { clock = 0.0, value = [0.0, 1.5, 6.0] },
//!   { clock = 0.5, value = [6.0, 1.5, 0.0] },
//!   { clock = 1.0, value = [0.0, 1.5, -6.0] },
//! ]
//! ```
//!
//! What can move (`[ITEM.animate.PROPERTY]`; a number or an `[x, y, z]` value as the
//! property has):
//!
//! | item | properties |
//! |---|---|
//! | `[camera]` | `from`, `at`, `up` (triples), `fov` (number) |
//! | `[[lights]]` | `position`, `color` |
//! | `[materials.NAME]` | `color` |
//! | `[[objects]]` sphere | `center`, `radius`, and the motion below |
//! | `[[objects]]` any other but `include` | `translate`, `rotate` (Euler degrees `[x, y, z]`), `scale` (a number or a triple) |
//!
//! The motion of an object moves it as written (for a mesh: as its own `translate`/`scale`/
//! `rotate_y_degrees` or `matrix` place it): `world = T(translate) * Rz * Ry * Rx * S(scale)`,
//! the rotation about the world's origin, X first. Spheres, cones and cylinders stay what they
//! are only under a uniform scale, so their `scale` keys must be one positive number (or three
//! equal ones). An `include`'s objects are static. A property with a key list takes its value
//! from the keys at every clock; the value written in the item is then only its default for a
//! still.
//!
//! Errors name the file and the line: keys not in increasing clock order, a key's clock
//! outside the clock range, an unknown property or one that cannot move, a value of the wrong
//! kind, key lists without an `[animation]` table. A value that only a frame reveals as wrong
//! (a camera whose `from` meets its `at` at some clock, a smooth `fov` that overshoots 180) is an
//! error of that frame, naming the line and the clock.
//!
//! Cost: when only the camera, the lights and material colours move, every frame shares the
//! first frame's primitives and BVH ([`Scene::shares_geometry_with`]) and costs a copy of the
//! lights and materials. A mesh that moves (by `translate`, `rotate`, `scale`) is always an
//! instance ([`crate::instance`], also when referenced once): when only meshes move, a frame
//! also shares every primitive and mesh BVH ([`Scene::shares_primitives_with`]) and rebuilds
//! only the top-level BVH over the instances. When any other object moves, a frame is built
//! anew from the definition ([`AnimatedScene::rebuilds_primitives`]; the referenced files are
//! read once, at the parse, and kept). Every way, frame `n` is a function of its clock alone,
//! so it is the same scene, to the bit, whichever frames came before it.

use crate::animation::{Animation, Interpolation, Track};
use crate::error::snippet;
use crate::files::Unreadable;
use crate::scene::{Format, Scene};
use crate::toml_scene::{self, line_of, Ctx, MovingMesh, ObjectDef, SceneDef};
use crate::warning::Warnings;
use crate::{files, limits, Error};
use glam::{Affine3A, Vec3A};
use serde::Deserialize;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// A scene with its animation: the [`Scene`] of each frame. A scene without an `[animation]`
/// table (and every NFF or OBJ scene) is a still: one frame, at clock 0, the scene as parsed.
#[derive(Debug)]
pub struct AnimatedScene {
    animation: Animation,
    /// The first frame.
    first: Scene,
    rig: Option<Rig>,
}

/// What moves, and what a frame is built from.
struct Rig {
    def: SceneDef,
    src: Vec<u8>,
    file: String,
    bindings: Vec<Binding>,
    /// Referenced files as read at the parse, by reference as written (frames with moving
    /// objects are built from these).
    files: BTreeMap<String, Vec<u8>>,
    moves_objects: bool,
    /// Whether the objects that move are all meshes moved by their motion (`translate`,
    /// `rotate`, `scale`): then a frame moves their instances only.
    only_meshes_move: bool,
    /// The index in the scene's materials of each material whose colour moves.
    materials: Vec<(String, u32)>,
    /// The instance of each moving mesh object, by object index.
    moving_meshes: BTreeMap<usize, MovingMesh>,
}

impl std::fmt::Debug for Rig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rig")
            .field("file", &self.file)
            .field("bindings", &self.bindings)
            .field("moves_objects", &self.moves_objects)
            .finish_non_exhaustive()
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Target {
    From,
    At,
    Up,
    Fov,
    LightPosition(usize),
    LightColor(usize),
    MaterialColor(String),
    Center(usize),
    Radius(usize),
    Translate(usize),
    Rotate(usize),
    Scale(usize),
}

#[derive(Debug)]
struct Binding {
    target: Target,
    track: Track,
}

impl AnimatedScene {
    /// Parses scene bytes as [`Scene::parse`] does, with the animation of a TOML scene.
    pub fn parse(
        bytes: &[u8],
        format: Format,
        name: &str,
        resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    ) -> Result<AnimatedScene, Error> {
        match format {
            Format::Toml => {
                limits::check_file_size(format!("the size of {name}"), bytes.len() as u64)?;
                toml_scene::parse_animated(files::without_bom(bytes), name, resolve)
            }
            _ => Scene::parse(bytes, format, name, resolve).map(AnimatedScene::still),
        }
    }

    /// Reads a scene file as [`Scene::load`] does (referenced files confined to its folder).
    pub fn load(path: &Path) -> Result<AnimatedScene, Error> {
        let shown = path.display().to_string();
        let format = Format::from_path(&shown)?;
        let file = files::open_scene(path, limits::MAX_FILE_BYTES)?;
        let confinement = files::Confinement::beneath(file.dir, Vec::<PathBuf>::new())?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or(shown);
        let resolve = move |rel: &str| -> Result<Vec<u8>, Unreadable> {
            confinement.read(rel).map(|(bytes, _)| bytes)
        };
        AnimatedScene::parse(&file.bytes, format, &name, &resolve)
    }

    /// A still: one frame, `scene`.
    pub fn still(scene: Scene) -> AnimatedScene {
        AnimatedScene {
            animation: Animation::STILL,
            first: scene,
            rig: None,
        }
    }

    /// The frames and the clock.
    pub fn animation(&self) -> Animation {
        self.animation
    }

    /// Whether objects move (key lists on objects); otherwise the frames share the first
    /// frame's primitives and BVH ([`AnimatedScene::rebuilds_primitives`] says what moving
    /// objects cost).
    pub fn moves_objects(&self) -> bool {
        self.rig.as_ref().is_some_and(|r| r.moves_objects)
    }

    /// Whether each frame builds its primitives and BVH anew: when objects other than meshes
    /// move (a mesh moved by `translate`/`rotate`/`scale` is an instance, and a frame rebuilds
    /// only the top-level BVH over the instances).
    pub fn rebuilds_primitives(&self) -> bool {
        self.rig
            .as_ref()
            .is_some_and(|r| r.moves_objects && !r.only_meshes_move)
    }

    /// The first frame (frame 0), with the parse's warnings.
    pub fn first_frame(&self) -> &Scene {
        &self.first
    }

    /// The first frame, without a copy.
    pub fn into_first_frame(self) -> Scene {
        self.first
    }

    /// The scene of frame `n` (from 0) at its clock ([`Animation::clock_of`]).
    pub fn frame(&self, n: u32) -> Result<Scene, Error> {
        self.at_clock(self.animation.clock_of(n)?)
    }

    /// The scene at `clock`, which must be within the clock range ([`Animation::contains`]).
    pub fn at_clock(&self, clock: f64) -> Result<Scene, Error> {
        if !self.animation.contains(clock) {
            let (a, b) = self.animation.clock_range();
            return Err(Error::InvalidArgument(format!(
                "clock {clock} is outside the animation's clock range [{a}, {b}]"
            )));
        }
        match &self.rig {
            None => Ok(self.first.clone()),
            Some(rig) => rig.scene_at(clock, &self.first),
        }
    }

    /// Parses the animation of a TOML scene whose definition `def` has one (a second pass over
    /// the text, for the lines of the keys), and builds its first frame.
    pub(crate) fn from_toml(
        def: SceneDef,
        cx: &Ctx,
        resolve: &dyn Fn(&str) -> Result<Vec<u8>, Unreadable>,
    ) -> Result<AnimatedScene, Error> {
        let text = toml_scene::text(cx.src, cx.file)?;
        let doc: AnimDoc = toml_scene::from_toml(text, cx.src, cx.file)?;
        let (animation, bindings) = bindings(&def, doc, cx)?;
        let moves_objects = bindings.iter().any(|b| {
            matches!(
                b.target,
                Target::Center(_)
                    | Target::Radius(_)
                    | Target::Translate(_)
                    | Target::Rotate(_)
                    | Target::Scale(_)
            )
        });
        let only_meshes_move = bindings.iter().all(|b| match b.target {
            Target::Center(_) | Target::Radius(_) => false,
            Target::Translate(i) | Target::Rotate(i) | Target::Scale(i) => matches!(
                def.objects.get(i).map(|o| o.get_ref()),
                Some(ObjectDef::Mesh { .. })
            ),
            _ => true,
        });
        let read = RefCell::new(BTreeMap::new());
        let keeping = |rel: &str| -> Result<Vec<u8>, Unreadable> {
            let data = resolve(rel)?;
            if moves_objects && !only_meshes_move {
                read.borrow_mut().insert(rel.to_string(), data.clone());
            }
            Ok(data)
        };
        let mut rig = Rig {
            def,
            src: cx.src.to_vec(),
            file: cx.file.to_string(),
            bindings,
            files: BTreeMap::new(),
            moves_objects,
            only_meshes_move,
            materials: Vec::new(),
            moving_meshes: BTreeMap::new(),
        };
        let clock = animation.clock_of(0)?;
        let first_def = rig.def_at(clock, true).map_err(|e| at_clock(e, clock))?;
        let built = toml_scene::build(&first_def, cx, &keeping, &|n| rig.moves(n))
            .map_err(|e| at_clock(e, clock))?;
        let first = built.scene;
        rig.files = read.into_inner();
        rig.materials = (built.materials.into_iter())
            .filter(|(n, _)| rig.moves(n))
            .collect();
        rig.moving_meshes = built.moving_meshes;
        Ok(AnimatedScene {
            animation,
            first,
            rig: Some(rig),
        })
    }
}

impl Rig {
    /// Whether material `name`'s colour moves.
    fn moves(&self, name: &str) -> bool {
        self.bindings
            .iter()
            .any(|b| matches!(&b.target, Target::MaterialColor(n) if n == name))
    }

    /// The scene at `clock`: a new build when objects other than meshes move, else `first`
    /// seen and lit as the clock says, with its moving meshes' instances moved.
    fn scene_at(&self, clock: f64, first: &Scene) -> Result<Scene, Error> {
        let cx = Ctx {
            src: &self.src,
            file: &self.file,
        };
        let rebuild = self.moves_objects && !self.only_meshes_move;
        let frame = |def: &SceneDef| -> Result<Scene, Error> {
            if rebuild {
                let resolve = |rel: &str| -> Result<Vec<u8>, Unreadable> {
                    self.files.get(rel).cloned().ok_or_else(|| {
                        Unreadable::Missing("not among the files read with the scene".into())
                    })
                };
                return Ok(toml_scene::build(def, &cx, &resolve, &|n| self.moves(n))?.scene);
            }
            let (camera, _) = toml_scene::camera(def, &cx)?;
            let mut ignored = Warnings::default();
            let mut lights = toml_scene::lights(def, &cx, &mut ignored)?;
            // an include's lights come after the TOML's own, and do not move
            lights.extend(first.lights.iter().skip(def.lights.len()).copied());
            let mut materials = first.materials.clone();
            for (name, index) in &self.materials {
                if let (Some(m), Some(slot)) =
                    (def.materials.get(name), materials.get_mut(*index as usize))
                {
                    *slot = toml_scene::material(&cx, name, m, &mut ignored)?;
                }
            }
            let seen = first.with_view(camera, lights, materials);
            if self.moving_meshes.is_empty() {
                return Ok(seen);
            }
            let motions = self.motions(clock);
            let moved: Vec<(usize, Affine3A)> = (self.moving_meshes.iter())
                .map(|(i, m)| {
                    let xf = motions.get(i).map_or(m.placed, |(xf, _)| *xf * m.placed);
                    (m.instance, xf)
                })
                .collect();
            seen.with_moved_instances(&moved, &self.file)?.map_err(|k| {
                let line = self.moving_meshes.values().nth(k).map_or(1, |m| m.line);
                Error::parse(&self.file, line, "mesh transform is singular (zero scale?)")
            })
        };
        self.def_at(clock, rebuild)
            .and_then(|def| frame(&def))
            .map_err(|e| at_clock(e, clock))
    }

    /// Each moving object's motion at `clock`, and its scale (for spheres and cones, whose
    /// scale is uniform).
    fn motions(&self, clock: f64) -> BTreeMap<usize, (Affine3A, f32)> {
        let mut motion: BTreeMap<usize, [[f64; 3]; 3]> = BTreeMap::new();
        for b in &self.bindings {
            let (i, k) = match b.target {
                Target::Translate(i) => (i, 0),
                Target::Rotate(i) => (i, 1),
                Target::Scale(i) => (i, 2),
                _ => continue,
            };
            motion.entry(i).or_insert(STILL_MOTION)[k] = b.track.at(clock);
        }
        let v3 = |v: [f64; 3]| Vec3A::from_array(v.map(|x| x as f32));
        (motion.into_iter())
            .map(|(i, [t, r, s])| {
                let xf = Affine3A::from_translation(v3(t).into())
                    * Affine3A::from_rotation_z((r[2] as f32).to_radians())
                    * Affine3A::from_rotation_y((r[1] as f32).to_radians())
                    * Affine3A::from_rotation_x((r[0] as f32).to_radians())
                    * Affine3A::from_scale(v3(s).into());
                (i, (xf, s[0] as f32))
            })
            .collect()
    }

    /// The definition with every key list's value at `clock`; without the objects unless
    /// `objects`.
    fn def_at(&self, clock: f64, objects: bool) -> Result<SceneDef, Error> {
        let mut def = if objects {
            self.def.clone()
        } else {
            self.def.without_objects()
        };
        let v3 = |v: [f64; 3]| v.map(|x| x as f32);
        for b in &self.bindings {
            let v = b.track.at(clock);
            match &b.target {
                Target::From => def.camera.get_mut().from = v3(v),
                Target::At => def.camera.get_mut().at = v3(v),
                Target::Up => def.camera.get_mut().up = v3(v),
                Target::Fov => def.camera.get_mut().fov = v[0] as f32,
                Target::LightPosition(i) => {
                    if let Some(l) = def.lights.get_mut(*i) {
                        l.get_mut().position = v3(v);
                    }
                }
                Target::LightColor(i) => {
                    if let Some(l) = def.lights.get_mut(*i) {
                        l.get_mut().color = Some(v3(v));
                    }
                }
                Target::MaterialColor(n) => {
                    if let Some(m) = def.materials.get_mut(n) {
                        m.get_mut().color = v3(v);
                    }
                }
                Target::Center(i) | Target::Radius(i) => {
                    if let Some(ObjectDef::Sphere { center, radius, .. }) =
                        def.objects.get_mut(*i).map(|o| o.get_mut())
                    {
                        if b.target == Target::Radius(*i) {
                            *radius = v[0] as f32;
                        } else {
                            *center = v3(v);
                        }
                    }
                }
                Target::Translate(_) | Target::Rotate(_) | Target::Scale(_) => {}
            }
        }
        if objects {
            for (i, (xf, s)) in self.motions(clock) {
                if let Some(o) = def.objects.get_mut(i) {
                    let uniform = matches!(
                        o.get_ref(),
                        ObjectDef::Sphere { .. }
                            | ObjectDef::Cone { .. }
                            | ObjectDef::Cylinder { .. }
                    );
                    // keys are positive, but a smooth list can overshoot below zero
                    if uniform && (s <= 0.0 || s.is_nan()) {
                        let line = line_of(&self.src, o.span().start);
                        return Err(Error::parse(
                            &self.file,
                            line,
                            format!("object {} is scaled by {s}: a scale must be > 0", i + 1),
                        ));
                    }
                    move_object(o.get_mut(), &xf, s);
                }
            }
        }
        Ok(def)
    }
}

/// Translation, rotation and scale of an object that does not move.
const STILL_MOTION: [[f64; 3]; 3] = [[0.0; 3], [0.0; 3], [1.0; 3]];

/// Moves an object by `xf`; `s` is its scale where it must be uniform (spheres, cones).
fn move_object(o: &mut ObjectDef, xf: &Affine3A, s: f32) {
    let p = |v: &mut [f32; 3]| *v = xf.transform_point3a(Vec3A::from_array(*v)).to_array();
    let normal_matrix = xf.matrix3.inverse().transpose();
    let n = |v: &mut [f32; 3]| *v = (normal_matrix * Vec3A::from_array(*v)).to_array();
    match o {
        ObjectDef::Sphere { center, radius, .. } => {
            p(center);
            *radius *= s;
        }
        ObjectDef::Plane { point, normal, .. } => {
            p(point);
            n(normal);
        }
        ObjectDef::Triangle {
            vertices, normals, ..
        } => {
            vertices.iter_mut().for_each(p);
            if normal_matrix.is_finite() {
                if let Some(ns) = normals {
                    ns.iter_mut().for_each(n);
                }
            } else {
                *normals = None;
            }
        }
        ObjectDef::Polygon { vertices, .. } => vertices.iter_mut().for_each(p),
        ObjectDef::Cone {
            base,
            base_radius,
            apex,
            apex_radius,
            ..
        } => {
            p(base);
            p(apex);
            *base_radius *= s;
            *apex_radius *= s;
        }
        ObjectDef::Cylinder {
            base, apex, radius, ..
        } => {
            p(base);
            p(apex);
            *radius *= s;
        }
        ObjectDef::Mesh { motion, .. } => *motion = Some(*xf),
        ObjectDef::Include { .. } => {}
    }
}

/// A frame's error, with the clock that showed it.
fn at_clock(e: Error, clock: f64) -> Error {
    match e {
        Error::Parse {
            file,
            line,
            message,
        } => Error::Parse {
            file,
            line,
            message: format!("{message} (at clock {clock})"),
        },
        e => e,
    }
}

/// The second reading of the text: the animation and the key lists, with their spans.
#[derive(Deserialize)]
struct AnimDoc {
    #[serde(default)]
    animation: Option<Spanned<AnimationDef>>,
    #[serde(default)]
    camera: Option<Item>,
    #[serde(default)]
    lights: Vec<Item>,
    #[serde(default)]
    materials: BTreeMap<String, Item>,
    #[serde(default)]
    objects: Vec<Item>,
}

fn clock01() -> [f64; 2] {
    [0.0, 1.0]
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AnimationDef {
    frames: u32,
    #[serde(default = "clock01")]
    clock: [f64; 2],
    #[serde(default)]
    cyclic: bool,
}

/// Any item, for its key lists (the rest was read by the first pass).
#[derive(Deserialize)]
struct Item {
    #[serde(default)]
    animate: BTreeMap<String, Spanned<TrackDef>>,
}

#[derive(Deserialize, Clone, Copy, Default)]
#[serde(rename_all = "lowercase")]
enum InterpolationDef {
    #[default]
    Linear,
    Smooth,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackDef {
    #[serde(default)]
    interpolation: InterpolationDef,
    keys: Vec<Spanned<KeyDef>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyDef {
    clock: f64,
    value: KeyValue,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum KeyValue {
    Number(f64),
    Triple([f64; 3]),
}

/// What values a property's keys take.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Triple,
    Number,
    /// A number or a triple (a scale).
    Scale,
    /// A positive number, or three equal ones (the scale of a sphere, cone or cylinder).
    Uniform,
}

/// A property that can move: its name, the kind of its values, what it drives.
type Prop = (&'static str, Kind, Target);

/// An item's key lists: the item as errors name it (`light 2`), the object type (or ""),
/// what it can move, and its key lists by property.
type Movable = (
    String,
    &'static str,
    Vec<Prop>,
    BTreeMap<String, Spanned<TrackDef>>,
);

/// The animation and the key lists of a scene, checked against its definition.
fn bindings(def: &SceneDef, doc: AnimDoc, cx: &Ctx) -> Result<(Animation, Vec<Binding>), Error> {
    let AnimDoc {
        animation,
        camera,
        lights,
        materials,
        objects,
    } = doc;
    let lists = movables(def, camera, lights, materials, objects);
    let animation = animation_of(animation, &lists, cx)?;
    let mut out = Vec::new();
    for (what, kind, can, tracks) in lists {
        for (prop, track) in tracks {
            let span = track.span();
            let Some((_, value_kind, target)) = can.iter().find(|c| c.0 == prop) else {
                let message = if kind == "include" {
                    format!("{what} cannot move: an include's objects are static")
                } else {
                    let names: Vec<&str> = can.iter().map(|c| c.0).collect();
                    format!(
                        "{what} cannot animate '{}' (it can: {})",
                        snippet(&prop),
                        names.join(", ")
                    )
                };
                return Err(cx.err(span, message));
            };
            let name = format!("{what} '{prop}'");
            let track = track_of(&name, &what, &prop, track, *value_kind, &animation, cx)?;
            out.push(Binding {
                target: target.clone(),
                track,
            });
        }
    }
    Ok((animation, out))
}

/// Each item that has key lists, with what it can move.
fn movables(
    def: &SceneDef,
    camera: Option<Item>,
    lights: Vec<Item>,
    materials: BTreeMap<String, Item>,
    objects: Vec<Item>,
) -> Vec<Movable> {
    let mut lists: Vec<Movable> = Vec::new();
    let motion = |i: usize, s: Kind| {
        vec![
            ("translate", Kind::Triple, Target::Translate(i)),
            ("rotate", Kind::Triple, Target::Rotate(i)),
            ("scale", s, Target::Scale(i)),
        ]
    };
    if let Some(c) = camera {
        let can = vec![
            ("from", Kind::Triple, Target::From),
            ("at", Kind::Triple, Target::At),
            ("up", Kind::Triple, Target::Up),
            ("fov", Kind::Number, Target::Fov),
        ];
        lists.push(("the camera".into(), "", can, c.animate));
    }
    for (i, l) in lights.into_iter().enumerate() {
        let can = vec![
            ("position", Kind::Triple, Target::LightPosition(i)),
            ("color", Kind::Triple, Target::LightColor(i)),
        ];
        lists.push((format!("light {}", i + 1), "", can, l.animate));
    }
    for (name, m) in materials {
        let can = vec![("color", Kind::Triple, Target::MaterialColor(name.clone()))];
        lists.push((format!("material '{}'", snippet(&name)), "", can, m.animate));
    }
    for (i, o) in objects.into_iter().enumerate() {
        let (kind, can) = match def.objects.get(i).map(|o| o.get_ref()) {
            Some(ObjectDef::Sphere { .. }) => {
                let mut can = vec![
                    ("center", Kind::Triple, Target::Center(i)),
                    ("radius", Kind::Number, Target::Radius(i)),
                ];
                can.extend(motion(i, Kind::Uniform));
                ("sphere", can)
            }
            Some(ObjectDef::Cone { .. }) => ("cone", motion(i, Kind::Uniform)),
            Some(ObjectDef::Cylinder { .. }) => ("cylinder", motion(i, Kind::Uniform)),
            Some(ObjectDef::Plane { .. }) => ("plane", motion(i, Kind::Scale)),
            Some(ObjectDef::Triangle { .. }) => ("triangle", motion(i, Kind::Scale)),
            Some(ObjectDef::Polygon { .. }) => ("polygon", motion(i, Kind::Scale)),
            Some(ObjectDef::Mesh { .. }) => ("mesh", motion(i, Kind::Scale)),
            Some(ObjectDef::Include { .. }) | None => ("include", Vec::new()),
        };
        lists.push((format!("object {} ({kind})", i + 1), kind, can, o.animate));
    }
    lists
}

/// The scene's `[animation]`, or [`Animation::STILL`] if it has none (and no key lists).
fn animation_of(
    def: Option<Spanned<AnimationDef>>,
    lists: &[Movable],
    cx: &Ctx,
) -> Result<Animation, Error> {
    let first_list = lists
        .iter()
        .flat_map(|l| l.3.values())
        .map(|t| t.span())
        .min_by_key(|s| s.start);
    match def {
        Some(a) => {
            let span = a.span();
            let a = a.into_inner();
            Animation::new(a.frames, a.clock[0], a.clock[1], a.cyclic)
                .map_err(|e| cx.err(span, format!("[animation]: {e}")))
        }
        None => {
            if let Some(span) = first_list {
                return Err(cx.err(
                    span,
                    "key lists ('animate') need an [animation] table with the frame count",
                ));
            }
            Ok(Animation::STILL)
        }
    }
}

/// The track of key list `track` of property `prop` of item `what` (`name`: both, as errors
/// name them), its values of kind `value_kind`, its clocks in `animation`'s range.
fn track_of(
    name: &str,
    what: &str,
    prop: &str,
    track: Spanned<TrackDef>,
    value_kind: Kind,
    animation: &Animation,
    cx: &Ctx,
) -> Result<Track, Error> {
    let span = track.span();
    let track_def = track.into_inner();
    if track_def.keys.is_empty() {
        return Err(cx.err(
            span,
            format!("{what}: the key list of '{prop}' has no keys"),
        ));
    }
    let mut keys = Vec::with_capacity(track_def.keys.len());
    for k in &track_def.keys {
        keys.push(key_of(name, k, value_kind, animation, cx)?);
    }
    let (start, end) = animation.clock_range();
    let (lo, hi) = (start.min(end), start.max(end));
    let periodic = animation.cyclic()
        && keys.first().map(|k| k.0) == Some(lo)
        && keys.last().map(|k| k.0) == Some(hi);
    let interpolation = match track_def.interpolation {
        InterpolationDef::Linear => Interpolation::Linear,
        InterpolationDef::Smooth => Interpolation::Smooth,
    };
    Track::new(&keys, interpolation, periodic).map_err(|i| {
        let (before, at) = (keys[i.saturating_sub(1)].0, keys[i].0);
        cx.err(
            track_def.keys[i].span(),
            format!(
                "{name}: keys out of order: clock {at} does not come after the \
                 key before it (clock {before}); keys go in increasing clock order"
            ),
        )
    })
}

/// Key `k` of the key list `name` (item and property, as errors name them): its clock and
/// its value as a triple, both finite, the clock in `animation`'s range.
fn key_of(
    name: &str,
    k: &Spanned<KeyDef>,
    value_kind: Kind,
    animation: &Animation,
    cx: &Ctx,
) -> Result<(f64, [f64; 3]), Error> {
    let kspan = k.span();
    let key = k.get_ref();
    let value = key_value(key.value, value_kind).ok_or_else(|| {
        let want = match value_kind {
            Kind::Triple => "a triple [x, y, z]",
            Kind::Number => "a number",
            Kind::Scale => "a number or a triple [x, y, z]",
            Kind::Uniform => "one positive number (or three equal ones): it scales uniformly",
        };
        cx.err(
            kspan.clone(),
            format!("{name}: a key's value must be {want}"),
        )
    })?;
    if !(key.clock.is_finite() && value.iter().all(|v| v.is_finite())) {
        return Err(cx.err(
            kspan,
            format!("{name}: a key's clock and value must be finite numbers"),
        ));
    }
    if !animation.contains(key.clock) {
        let (start, end) = animation.clock_range();
        return Err(cx.err(
            kspan,
            format!(
                "{name}: a key at clock {} is outside the animation's clock range \
                 [{start}, {end}]",
                key.clock
            ),
        ));
    }
    Ok((key.clock, value))
}

/// A key's value as a triple of the kind the property takes (a number in the first
/// component, or in all three for a scale), or `None` if it is not of that kind.
fn key_value(v: KeyValue, kind: Kind) -> Option<[f64; 3]> {
    match (kind, v) {
        (Kind::Triple, KeyValue::Triple(t)) => Some(t),
        (Kind::Number, KeyValue::Number(x)) => Some([x, 0.0, 0.0]),
        (Kind::Scale, KeyValue::Number(x)) => Some([x; 3]),
        (Kind::Scale, KeyValue::Triple(t)) => Some(t),
        (Kind::Uniform, KeyValue::Number(x)) if x > 0.0 => Some([x; 3]),
        (Kind::Uniform, KeyValue::Triple(t)) if t[0] > 0.0 && t[0] == t[1] && t[1] == t[2] => {
            Some(t)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{trace_span, Settings};

    fn no_files(_: &str) -> Result<Vec<u8>, Unreadable> {
        Err("no files in this test".into())
    }

    fn parse(src: &str) -> Result<AnimatedScene, Error> {
        AnimatedScene::parse(src.as_bytes(), Format::Toml, "a.toml", &no_files)
    }

    fn err(src: &str) -> String {
        match parse(src) {
            Ok(_) => panic!("expected an error"),
            Err(e) => e.to_string(),
        }
    }

    /// Every pixel of a small image of `scene`.
    fn pixels(scene: &Scene) -> Vec<u32> {
        let mut s = Settings::new(48, 36);
        s.depth = 4;
        let (rgb, _) = trace_span(scene, &s, 0, 48 * 36).unwrap();
        rgb.iter().map(|v| v.to_bits()).collect()
    }

    const STILL: &str = r#"
background = [0.2, 0.3, 0.5]

[camera]
from = [0, 1, 6]
at = [0, 0.5, 0]

[[lights]]
position = [4, 6, 5]

[materials.red]
color = [0.9, 0.1, 0.1]
ks = 0.3

[materials.glass]
t = 0.8
ior = 1.5
kd = 0.1

[[objects]]
type = "plane"
point = [0, -1, 0]
normal = [0, 1, 0]

[[objects]]
type = "sphere"
center = [0, 0.5, 0]
radius = 1
material = "red"

[[objects]]
type = "sphere"
center = [1.5, 0, 1]
radius = 0.5
material = "glass"
"#;

    const ORBIT: &str = r#"
[animation]
frames = 6
clock = [0, 1]
cyclic = true

[camera.animate.from]
interpolation = "smooth"
keys = [
  { clock = 0.0, value = [0, 1, 6] },
  { clock = 0.25, value = [6, 2, 0] },
  { clock = 0.5, value = [0, 3, -6] },
  { clock = 0.75, value = [-6, 2, 0] },
  { clock = 1.0, value = [0, 1, 6] },
]

[lights.animate.color]
keys = [{ clock = 0.0, value = [1, 1, 1] }, { clock = 1.0, value = [0.2, 0.2, 0.9] }]

[materials.red.animate.color]
keys = [{ clock = 0.0, value = [0.9, 0.1, 0.1] }, { clock = 0.5, value = [0.1, 0.9, 0.1] }]
"#;

    /// `STILL` with the tables of `extra` appended (TOML lets a later `[x.animate.y]` add to
    /// the last `[[x]]` only, so the moving parts go after the objects they move).
    fn with(extra: &str) -> String {
        format!("{STILL}{extra}")
    }

    #[test]
    fn parses_module_doc_example() {
        let src = crate::test_support::doc_example(include_str!("animated.rs"));
        let a = parse(&src).unwrap();
        assert_eq!(a.animation().frames(), 24);
        assert_eq!(
            a.frame(23).unwrap().camera().from,
            Vec3A::new(0.0, 1.5, -6.0)
        );
    }

    #[test]
    fn the_example_scenes_load_and_move_as_they_say() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../priv/scenes");
        let orbit = AnimatedScene::load(&dir.join("whitted_orbit.toml")).unwrap();
        assert_eq!(
            orbit.animation(),
            Animation::new(48, 0.0, 1.0, true).unwrap()
        );
        assert!(orbit.moves_objects());
        assert!(orbit.first_frame().warnings().kept().is_empty());
        // a quarter of the way round, the camera is on the far side of the scene's x axis
        let quarter = orbit.frame(12).unwrap();
        assert!(
            quarter.camera().from.x < -7.0,
            "{:?}",
            quarter.camera().from
        );
        // the glass sphere is on the floor at the start and up at an eighth (mid-bounce)
        let up = orbit.frame(6).unwrap();
        assert!(up.bounds().max.y > orbit.first_frame().bounds().max.y);

        let fly = AnimatedScene::load(&dir.join("balls_flythrough.toml")).unwrap();
        assert_eq!(fly.animation().frames(), 24);
        assert!(!fly.moves_objects());
        let nff = Scene::load(&dir.join("spd/balls_s3.nff")).unwrap();
        let first = fly.first_frame();
        assert_eq!(fly.frame(0).unwrap().lights, first.lights);
        assert_eq!(first.primitive_count(), nff.primitive_count());
        assert_eq!(first.light_count(), nff.light_count());
        assert_eq!(first.camera(), nff.camera());
        for n in [1, 12, 23] {
            let f = fly.frame(n).unwrap();
            assert!(f.shares_geometry_with(first), "frame {n}");
            assert_eq!(f.lights, first.lights, "frame {n}");
            assert_ne!(f.camera(), first.camera());
        }
    }

    #[test]
    fn a_scene_without_animation_is_a_still_at_clock_0() {
        let a = parse(STILL).unwrap();
        assert_eq!(a.animation(), Animation::STILL);
        assert!(!a.moves_objects());
        let direct = Scene::parse(STILL.as_bytes(), Format::Toml, "a.toml", &no_files).unwrap();
        assert_eq!(pixels(&a.frame(0).unwrap()), pixels(&direct));
        assert!(a.frame(1).is_err());
        assert!(a.at_clock(0.5).is_err());
    }

    #[test]
    fn camera_light_and_colour_moves_share_the_bvh_and_change_the_picture() {
        let a = parse(&with(ORBIT)).unwrap();
        assert_eq!(a.animation().frames(), 6);
        assert_eq!(a.animation().clock_range(), (0.0, 1.0));
        assert!(a.animation().cyclic());
        assert!(!a.moves_objects());
        let frames: Vec<Scene> = (0..6).map(|n| a.frame(n).unwrap()).collect();
        for f in &frames {
            assert!(f.shares_geometry_with(a.first_frame()));
        }
        // the camera moved between frames: different pictures
        assert_ne!(pixels(&frames[0]), pixels(&frames[1]));
        // the camera's key at clock 0.5 is frame 3 of 6 (cyclic: clock n / 6)
        assert_eq!(frames[3].camera().from, Vec3A::new(0.0, 3.0, -6.0));
    }

    #[test]
    fn a_frame_is_the_same_whichever_frames_came_before() {
        for extra in [ORBIT, MOVING] {
            let a = parse(&with(extra)).unwrap();
            let n = a.animation().frames();
            let in_order: Vec<Vec<u32>> = (0..n).map(|k| pixels(&a.frame(k).unwrap())).collect();
            // each frame again, alone, from a fresh parse, backwards
            for k in (0..n).rev() {
                let fresh = parse(&with(extra)).unwrap();
                assert_eq!(
                    pixels(&fresh.frame(k).unwrap()),
                    in_order[k as usize],
                    "frame {k}"
                );
            }
            // and the same frame twice in a row
            assert_eq!(pixels(&a.frame(2).unwrap()), pixels(&a.frame(2).unwrap()));
        }
    }

    #[test]
    fn a_frame_at_a_key_is_the_still_written_with_the_keys_values() {
        // linear keys are hit exactly, so the frame at a key's clock is that still, to the bit
        // (camera, ray offset, lights, colours and moved objects alike)
        let a = parse(&with(MOVING)).unwrap();
        let still = STILL
            .replace("center = [1.5, 0, 1]", "center = [1.5, 2, 1]")
            .replace("from = [0, 1, 6]", "from = [2, 1, 6]")
            .replace("color = [0.9, 0.1, 0.1]", "color = [0.1, 0.1, 0.9]");
        let still = Scene::parse(still.as_bytes(), Format::Toml, "a.toml", &no_files).unwrap();
        // clock 0.5 is frame 2 of 5
        assert_eq!(pixels(&a.frame(2).unwrap()), pixels(&still));
        // and not another frame's
        assert_ne!(pixels(&a.frame(1).unwrap()), pixels(&still));
    }

    const MOVING: &str = r#"
[objects.animate.center]
keys = [
  { clock = 0.0, value = [1.5, 0, 1] },
  { clock = 0.5, value = [1.5, 2, 1] },
  { clock = 1.0, value = [1.5, 0, 1] },
]

[animation]
frames = 5

[camera.animate.from]
keys = [{ clock = 0.0, value = [0, 1, 6] }, { clock = 0.5, value = [2, 1, 6] }]

[materials.red.animate.color]
keys = [{ clock = 0.5, value = [0.1, 0.1, 0.9] }]
"#;

    /// Lines 1-9: an animation, a camera, a light, a material and a sphere.
    const BASE: &str = "[animation]\nframes = 4\n[camera]\nfrom = [0, 0, 5]\nat = [0, 0, 0]\n\
                        [[lights]]\nposition = [1, 1, 1]\n[materials.m]\n\
                        [[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n";

    #[test]
    fn bad_animation_input_is_an_error_with_file_and_line() {
        let cases = [
            // keys out of order: the line of the offending key
            (
                "[objects.animate.radius]\nkeys = [\n{ clock = 0.5, value = 1 },\n\
                 { clock = 0.25, value = 2 },\n]\n",
                "a.toml:16: object 1 (sphere) 'radius': keys out of order: clock 0.25 does not \
                 come after the key before it (clock 0.5); keys go in increasing clock order",
            ),
            // two keys at one clock are out of order too
            (
                "[objects.animate.radius]\nkeys = [{ clock = 0.5, value = 1 },\n\
                 { clock = 0.5, value = 2 }]\n",
                "a.toml:15: object 1 (sphere) 'radius': keys out of order: clock 0.5 does not \
                 come after the key before it (clock 0.5); keys go in increasing clock order",
            ),
            // an unknown target
            (
                "[objects.animate.colour]\nkeys = [{ clock = 0, value = 1 }]\n",
                "a.toml:13: object 1 (sphere) cannot animate 'colour' (it can: center, radius, \
                 translate, rotate, scale)",
            ),
            // something that cannot move
            (
                "[camera.animate.width]\nkeys = [{ clock = 0, value = 1 }]\n",
                "a.toml:13: the camera cannot animate 'width' (it can: from, at, up, fov)",
            ),
            (
                "[[objects]]\ntype = \"include\"\nfile = \"x.nff\"\n\
                 [objects.animate.translate]\nkeys = [{ clock = 0, value = [1, 0, 0] }]\n",
                "a.toml:16: object 2 (include) cannot move: an include's objects are static",
            ),
            // a sphere scales uniformly only
            (
                "[objects.animate.scale]\nkeys = [{ clock = 0, value = [1, 2, 1] }]\n",
                "a.toml:14: object 1 (sphere) 'scale': a key's value must be one positive number \
                 (or three equal ones): it scales uniformly",
            ),
            // a value of the wrong kind
            (
                "[materials.m.animate.color]\nkeys = [{ clock = 0, value = 0.5 }]\n",
                "a.toml:14: material 'm' 'color': a key's value must be a triple [x, y, z]",
            ),
            // a clock outside the range
            (
                "[lights.animate.position]\nkeys = [{ clock = 0, value = [0, 0, 1] },\n\
                 { clock = 1.5, value = [1, 0, 1] }]\n",
                "a.toml:15: light 1 'position': a key at clock 1.5 is outside the animation's \
                 clock range [0, 1]",
            ),
            // an empty key list, and a key without its value
            (
                "[camera.animate.fov]\nkeys = []\n",
                "a.toml:13: the camera: the key list of 'fov' has no keys",
            ),
            (
                "[camera.animate.fov]\nkeys = [\n{ clock = 0 }]\n",
                "a.toml:15: missing field `value`",
            ),
            (
                "[camera.animate.fov]\ninterpolation = \"cubic\"\nkeys = [{ clock = 0, value = 9 }]\n",
                "a.toml:14: unknown variant `cubic`, expected `linear` or `smooth`",
            ),
        ];
        let got: Vec<String> = cases
            .iter()
            .map(|(extra, _)| err(&format!("{BASE}{extra}")))
            .collect();
        let want: Vec<&str> = cases.iter().map(|c| c.1).collect();
        assert_eq!(got, want);
        // key lists without an [animation] table
        let no_anim = BASE.replace("[animation]\nframes = 4\n", "");
        assert_eq!(
            err(&format!(
                "{no_anim}[camera.animate.fov]\nkeys = [{{ clock = 0, value = 30 }}]\n"
            )),
            "a.toml:11: key lists ('animate') need an [animation] table with the frame count"
        );
        // a bad [animation] table
        assert_eq!(
            err(&BASE.replace("frames = 4", "frames = 0")),
            "a.toml:1: [animation]: an animation needs at least 1 frame"
        );
        let e = err(&BASE.replace("frames = 4", "frames = 4\nspeed = 2"));
        assert!(e.starts_with("a.toml:3: unknown field `speed`"), "{e}");
        // a value that a frame shows wrong: the frame's error names the line and the clock
        let a = parse(&format!(
            "{BASE}[camera.animate.from]\nkeys = [{{ clock = 0, value = [0, 0, 5] }},\n\
             {{ clock = 1, value = [0, 0, -5] }}]\n"
        ))
        .unwrap();
        assert!(a.frame(1).is_ok());
        let e = a.at_clock(0.5).unwrap_err().to_string();
        assert_eq!(
            e,
            "a.toml:3: degenerate camera: 'from' equals 'at', or 'up' is parallel to the view \
             direction (at clock 0.5)"
        );
        assert_eq!(
            a.at_clock(1.25).unwrap_err().to_string(),
            "invalid argument: clock 1.25 is outside the animation's clock range [0, 1]"
        );
        // a smooth scale that overshoots below zero between positive keys
        let a = parse(&format!(
            "{BASE}[objects.animate.scale]\ninterpolation = \"smooth\"\nkeys = [\n\
             {{ clock = 0, value = 3 }}, {{ clock = 0.5, value = 0.1 }},\n\
             {{ clock = 0.75, value = 0.1 }}, {{ clock = 1, value = 3 }}]\n"
        ))
        .unwrap();
        assert!(a.at_clock(0.25).is_ok());
        let e = a.at_clock(0.625).unwrap_err().to_string();
        assert!(
            e.starts_with("a.toml:9: object 1 is scaled by -0.")
                && e.ends_with(": a scale must be > 0 (at clock 0.625)"),
            "{e}"
        );
    }

    #[test]
    fn moving_meshes_move_their_instances_only() {
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
        let files = |p: &str| -> Result<Vec<u8>, Unreadable> {
            if p == "tet.obj" {
                Ok(obj.as_bytes().to_vec())
            } else {
                Err(format!("no {p}").into())
            }
        };
        let src = with(
            "\n[[objects]]\ntype = \"mesh\"\nfile = \"tet.obj\"\nscale = 0.8\nmaterial = \"red\"\n\
             [objects.animate.rotate]\ninterpolation = \"smooth\"\n\
             keys = [{ clock = 0, value = [0, 0, 0] }, { clock = 1, value = [0, 400, 30] }]\n\
             [objects.animate.translate]\n\
             keys = [{ clock = 0, value = [-2, 0, 0] }, { clock = 1, value = [1, 1, 2] }]\n\
             [animation]\nframes = 5\n",
        );
        let a = AnimatedScene::parse(src.as_bytes(), Format::Toml, "a.toml", &files).unwrap();
        assert!(a.moves_objects() && !a.rebuilds_primitives());
        // the mesh, referenced once, is an instance so that it can move
        assert_eq!(a.first_frame().instance_count(), 1);
        let frames: Vec<Scene> = (0..5).map(|n| a.frame(n).unwrap()).collect();
        for f in &frames[1..] {
            assert!(f.shares_primitives_with(a.first_frame()));
            assert!(!f.shares_geometry_with(a.first_frame()));
        }
        let pictures: Vec<Vec<u32>> = frames.iter().map(pixels).collect();
        assert_ne!(pictures[1], pictures[2]);
        // frame 0 from the moved instances is the first frame as built
        assert_eq!(pictures[0], pixels(a.first_frame()));
        // each frame is the scene a full build at its clock makes, to the bit, and the same
        // when made alone from a fresh parse
        let rig = a.rig.as_ref().unwrap();
        let cx = Ctx {
            src: src.as_bytes(),
            file: "a.toml",
        };
        for (n, picture) in pictures.iter().enumerate() {
            let clock = a.animation().clock_of(n as u32).unwrap();
            let def = rig.def_at(clock, true).unwrap();
            let built = toml_scene::build(&def, &cx, &files, &|m| rig.moves(m)).unwrap();
            assert_eq!(pixels(&built.scene), *picture, "frame {n}");
            let fresh = AnimatedScene::parse(src.as_bytes(), Format::Toml, "a.toml", &files);
            assert_eq!(pixels(&fresh.unwrap().frame(n as u32).unwrap()), *picture);
        }
        // a scale through zero is that frame's error, at the mesh's line and clock
        let flat = src.replace(
            "material = \"red\"\n[objects",
            "material = \"red\"\n[objects.animate.scale]\n\
             keys = [{ clock = 0, value = 1 }, { clock = 1, value = -1 }]\n[objects",
        );
        let b = AnimatedScene::parse(flat.as_bytes(), Format::Toml, "a.toml", &files).unwrap();
        assert!(b.frame(1).is_ok());
        assert_eq!(
            b.frame(2).unwrap_err().to_string(),
            "a.toml:37: mesh transform is singular (zero scale?) (at clock 0.5)"
        );
    }

    #[test]
    fn moving_objects_rebuild_and_move() {
        // MOVING's first table belongs to the last object of STILL (the glass sphere)
        let a = parse(&with(MOVING)).unwrap();
        assert!(a.moves_objects() && a.rebuilds_primitives());
        let f0 = a.frame(0).unwrap();
        let f2 = a.frame(2).unwrap();
        assert!(!f2.shares_geometry_with(&f0));
        assert!(
            f2.bounds().max.y > f0.bounds().max.y + 0.9,
            "{:?}",
            f2.bounds()
        );
    }
}
