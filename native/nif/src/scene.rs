//! Scenes as NIF resources. A handle means something only on the node that
//! parsed it: Elixir ships scene bytes between nodes and parses on each.

use std::collections::HashMap;
use std::os::fd::OwnedFd;
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::{Arc, Mutex};

use ring_tracer_kernel::files::{self, Confinement, Unreadable};
use ring_tracer_kernel::{limits, AnimatedScene, Format, Scene};
use rustler::{Binary, Env, NifMap, OwnedBinary, ResourceArc};

use crate::convert::message;

static LIVE_SCENES: AtomicI64 = AtomicI64::new(0);

/// A parsed scene with its BVH, shared by every grandchild on this node: one frame of its
/// animation (the first, as parsed; a still has only that one), and the animation, from which
/// [`scene_frame`] makes the resource of any other frame.
pub struct SceneResource {
    pub scene: Scene,
    pub animated: Arc<AnimatedScene>,
}

impl SceneResource {
    fn new(scene: Scene, animated: Arc<AnimatedScene>) -> Self {
        LIVE_SCENES.fetch_add(1, Ordering::Relaxed);
        SceneResource { scene, animated }
    }
}

impl Drop for SceneResource {
    fn drop(&mut self) {
        LIVE_SCENES.fetch_sub(1, Ordering::Relaxed);
    }
}

#[rustler::resource_impl]
impl rustler::Resource for SceneResource {}

/// The folder a scene file was read in, held open (`files::open_scene`): the root its
/// references are confined to. Closed when Erlang lets go of the handle.
pub struct SceneDirResource {
    fd: OwnedFd,
}

#[rustler::resource_impl]
impl rustler::Resource for SceneDirResource {}

/// What Elixir learns about a scene when it is parsed.
#[derive(NifMap)]
pub struct SceneInfo {
    pub width: u32,
    pub height: u32,
    pub primitives: u64,
    pub lights: u64,
    /// The parse's warnings, at most `limits::MAX_WARNINGS` of them, in the order found.
    pub warnings: Vec<WarningTerm>,
    /// How many more warnings there were than those in `warnings`.
    pub warnings_omitted: u64,
}

/// A kernel warning (`ring_tracer_kernel::Warning`) as a map; `line` is `nil` for a warning
/// about a whole file.
#[derive(NifMap)]
pub struct WarningTerm {
    pub file: String,
    pub line: Option<u64>,
    pub message: String,
}

/// A path as Erlang sees one: its bytes, as they are (no UTF-8 required).
fn path_binary<'a>(env: Env<'a>, path: &Path) -> Binary<'a> {
    OwnedBinary::from_slice(path.as_os_str().as_bytes()).release(env)
}

/// Parses scene bytes. `includes` holds referenced files shipped as bytes,
/// keyed by the reference as written (used first: that is how a node parses a
/// scene without touching its own disk). Otherwise, when `scene_dir` is given
/// (the folder `read_scene_file` read the scene in, held open), a referenced
/// file (TOML mesh, OBJ `mtllib`) is read relative to that very folder,
/// confined to it and the `allow_dirs` folders (`files::Confinement::beneath`),
/// and only if it is a regular file of at most `limits::MAX_FILE_BYTES`.
///
/// Returns the resource, its info (with the parse's warnings), every referenced file's bytes keyed by its
/// reference (to ship to other nodes), and the canonical absolute paths of the
/// files read from disk, in the order first read (so that an output never
/// overwrites an input).
#[rustler::nif(schedule = "DirtyCpu")]
#[allow(clippy::type_complexity)]
fn scene_parse<'a>(
    env: Env<'a>,
    bytes: Binary<'a>,
    format: String,
    name: String,
    scene_dir: Option<ResourceArc<SceneDirResource>>,
    allow_dirs: Vec<String>,
    includes: HashMap<String, Binary<'a>>,
) -> Result<
    (
        ResourceArc<SceneResource>,
        SceneInfo,
        Vec<(String, Binary<'a>)>,
        Vec<Binary<'a>>,
    ),
    String,
> {
    let format = Format::from_path(&format!("{name}.{format}")).map_err(message)?;
    let shipped: HashMap<String, Vec<u8>> = includes
        .iter()
        .map(|(k, v)| (k.clone(), v.as_slice().to_vec()))
        .collect();
    let disk = match &scene_dir {
        Some(dir) => {
            let fd = dir
                .fd
                .try_clone()
                .map_err(|e| format!("the scene's folder: {e}"))?;
            Some(Confinement::beneath(fd, &allow_dirs).map_err(message)?)
        }
        None => None,
    };
    let used: Mutex<Vec<(String, Vec<u8>)>> = Mutex::new(Vec::new());
    let read: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    let resolve = |rel: &str| -> Result<Vec<u8>, Unreadable> {
        let data = if let Some(data) = shipped.get(rel) {
            data.clone()
        } else if let Some(confinement) = &disk {
            let (data, path) = confinement.read(rel)?;
            if let Ok(mut read) = read.lock() {
                if !read.contains(&path) {
                    read.push(path);
                }
            }
            data
        } else {
            // `rel` is not echoed: the caller names the reference, escaped
            return Err(Unreadable::Missing(
                "referenced file was not shipped with the scene".to_string(),
            ));
        };
        if let Ok(mut used) = used.lock() {
            used.push((rel.to_string(), data.clone()));
        }
        Ok(data)
    };
    let animated =
        AnimatedScene::parse(bytes.as_slice(), format, &name, &resolve).map_err(message)?;
    let scene = animated.first_frame().clone();
    let (width, height) = scene.resolution();
    let info = SceneInfo {
        width,
        height,
        primitives: scene.primitive_count() as u64,
        lights: scene.light_count() as u64,
        warnings: scene
            .warnings()
            .kept()
            .iter()
            .map(|w| WarningTerm {
                file: w.file.clone(),
                line: w.line.map(|l| l as u64),
                message: w.message.clone(),
            })
            .collect(),
        warnings_omitted: scene.warnings().omitted(),
    };
    let used = used.into_inner().unwrap_or_default();
    let mut files = Vec::with_capacity(used.len());
    for (rel, data) in used {
        let bin = OwnedBinary::from_slice(&data);
        files.push((rel, bin.release(env)));
    }
    let read = read
        .into_inner()
        .unwrap_or_default()
        .iter()
        .map(|p| path_binary(env, p))
        .collect();
    Ok((
        ResourceArc::new(SceneResource::new(scene, Arc::new(animated))),
        info,
        files,
        read,
    ))
}

/// Reads a top-level scene file the user named (anywhere: no confinement),
/// with `files::open_scene`: its folder opened once, the file opened beneath
/// it without following a link (a link's target taken from that folder), a
/// regular file, not on procfs/sysfs, at most `limits::MAX_FILE_BYTES`
/// (checked before reading). Returns its bytes, its canonical absolute path
/// and the folder it was read in, held open (for `scene_parse`).
#[rustler::nif(schedule = "DirtyIo")]
#[allow(clippy::type_complexity)]
fn read_scene_file<'a>(
    env: Env<'a>,
    path: String,
) -> Result<(Binary<'a>, Binary<'a>, ResourceArc<SceneDirResource>), String> {
    let file = files::open_scene(Path::new(&path), limits::MAX_FILE_BYTES).map_err(message)?;
    Ok((
        OwnedBinary::from_slice(&file.bytes).release(env),
        path_binary(env, &file.path),
        ResourceArc::new(SceneDirResource { fd: file.dir }),
    ))
}

/// The animation of a parsed scene ([`ring_tracer_kernel::Animation`]); a still has one frame
/// at clock 0.
#[derive(NifMap)]
pub struct AnimationInfo {
    pub frames: u32,
    pub clock_start: f64,
    pub clock_end: f64,
    pub cyclic: bool,
    /// Whether objects move.
    pub moves_objects: bool,
    /// Whether each frame builds its primitives and BVH anew (objects other than meshes
    /// move); otherwise frames share the first frame's (moving meshes rebuild only the
    /// top-level BVH over their instances).
    pub rebuilds_primitives: bool,
}

/// The frame count and clock range of a parsed scene.
#[rustler::nif]
fn scene_animation(scene: ResourceArc<SceneResource>) -> AnimationInfo {
    let a = scene.animated.animation();
    let (clock_start, clock_end) = a.clock_range();
    AnimationInfo {
        frames: a.frames(),
        clock_start,
        clock_end,
        cyclic: a.cyclic(),
        moves_objects: scene.animated.moves_objects(),
        rebuilds_primitives: scene.animated.rebuilds_primitives(),
    }
}

/// A scene's pinhole camera as the kernel keeps it ([`ring_tracer_kernel::Camera`]): the eye,
/// the unit view direction and the unit right and up vectors of the image (orthonormal:
/// `right = forward x up_written`, normalised, and `up = right x forward`), and the field of
/// view in degrees across the image's smaller side. For a frame's resource, that frame's
/// camera.
#[derive(NifMap)]
pub struct CameraInfo {
    pub from: (f64, f64, f64),
    pub forward: (f64, f64, f64),
    pub right: (f64, f64, f64),
    pub up: (f64, f64, f64),
    pub fov: f64,
}

/// The camera of a parsed scene (or of one frame of it, see [`scene_frame`]).
#[rustler::nif]
fn scene_camera(scene: ResourceArc<SceneResource>) -> CameraInfo {
    let c = scene.scene.camera();
    let t = |v: ring_tracer_kernel::glam::Vec3A| (v.x as f64, v.y as f64, v.z as f64);
    CameraInfo {
        from: t(c.from),
        forward: t(c.forward),
        right: t(c.right),
        up: t(c.up),
        fov: 2.0 * (c.tan_half as f64).atan().to_degrees(),
    }
}

/// The scene of frame `frame` (from 0) of a parsed scene's animation, at the clock POV-Ray gives
/// it (`ring_tracer_kernel::Animation::clock_of`), as a resource that `trace_atom` and the
/// other scene calls take. Frame `n` is the same scene whichever frame's resource it is made
/// from. Cheap when only the camera, lights, colours or meshes move (the primitives and their
/// BVHs are shared); a dirty-CPU call, since other moving objects rebuild them.
#[rustler::nif(schedule = "DirtyCpu")]
fn scene_frame(
    scene: ResourceArc<SceneResource>,
    frame: u32,
) -> Result<ResourceArc<SceneResource>, String> {
    let animated = Arc::clone(&scene.animated);
    let frame = animated.frame(frame).map_err(message)?;
    Ok(ResourceArc::new(SceneResource::new(frame, animated)))
}

/// How many parsed scenes are alive on this node (for leak checks).
#[rustler::nif]
fn scene_live_count() -> i64 {
    LIVE_SCENES.load(Ordering::Relaxed)
}
