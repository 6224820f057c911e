//! Scenes as NIF resources. A handle means something only on the node that
//! parsed it: Elixir ships scene bytes between nodes and parses on each.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::Mutex;

use ring_tracer_kernel::{Format, Scene};
use rustler::{Binary, Env, NifMap, OwnedBinary, ResourceArc};

use crate::convert::message;

static LIVE_SCENES: AtomicI64 = AtomicI64::new(0);

/// A parsed scene with its BVH, shared by every grandchild on this node.
pub struct SceneResource {
    pub scene: Scene,
}

impl SceneResource {
    fn new(scene: Scene) -> Self {
        LIVE_SCENES.fetch_add(1, Ordering::Relaxed);
        SceneResource { scene }
    }
}

impl Drop for SceneResource {
    fn drop(&mut self) {
        LIVE_SCENES.fetch_sub(1, Ordering::Relaxed);
    }
}

#[rustler::resource_impl]
impl rustler::Resource for SceneResource {}

/// What Elixir learns about a scene when it is parsed.
#[derive(NifMap)]
pub struct SceneInfo {
    pub width: u32,
    pub height: u32,
    pub primitives: u64,
    pub lights: u64,
}

/// Parses scene bytes. `base_dir`, when given, is where referenced files
/// (OBJ meshes, MTL) are read from; `includes` holds referenced files shipped
/// as bytes (used first). Returns the resource, its info, and every referenced
/// file's bytes so that they can be shipped to other nodes.
#[rustler::nif(schedule = "DirtyCpu")]
#[allow(clippy::type_complexity)]
fn scene_parse<'a>(
    env: Env<'a>,
    bytes: Binary<'a>,
    format: String,
    name: String,
    base_dir: Option<String>,
    includes: HashMap<String, Binary<'a>>,
) -> Result<
    (
        ResourceArc<SceneResource>,
        SceneInfo,
        Vec<(String, Binary<'a>)>,
    ),
    String,
> {
    let format = Format::from_path(&format!("{name}.{format}")).map_err(message)?;
    let shipped: HashMap<String, Vec<u8>> = includes
        .iter()
        .map(|(k, v)| (k.clone(), v.as_slice().to_vec()))
        .collect();
    let used: Mutex<Vec<(String, Vec<u8>)>> = Mutex::new(Vec::new());
    let resolve = |rel: &str| -> Result<Vec<u8>, String> {
        let data = if let Some(data) = shipped.get(rel) {
            data.clone()
        } else if let Some(dir) = &base_dir {
            let path = PathBuf::from(dir).join(rel);
            std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?
        } else {
            return Err(format!(
                "{rel}: referenced file was not shipped with the scene"
            ));
        };
        if let Ok(mut used) = used.lock() {
            used.push((rel.to_string(), data.clone()));
        }
        Ok(data)
    };
    let scene = Scene::parse(bytes.as_slice(), format, &name, &resolve).map_err(message)?;
    let (width, height) = scene.resolution();
    let info = SceneInfo {
        width,
        height,
        primitives: scene.primitive_count() as u64,
        lights: scene.light_count() as u64,
    };
    let used = used.into_inner().unwrap_or_default();
    let mut files = Vec::with_capacity(used.len());
    for (rel, data) in used {
        let bin = OwnedBinary::from_slice(&data);
        files.push((rel, bin.release(env)));
    }
    Ok((ResourceArc::new(SceneResource::new(scene)), info, files))
}

/// How many parsed scenes are alive on this node (for leak checks).
#[rustler::nif]
fn scene_live_count() -> i64 {
    LIVE_SCENES.load(Ordering::Relaxed)
}
