//! The render delegate: the prims it supports, insert / mark dirty / sync / remove, and the flat
//! scene a render pass hands to the core. Instancers ([`crate::instancer`]) are flattened there:
//! one core mesh per prototype, one core instance per placement.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::{Arc, Mutex};

use mipray::displacement::{DisplacementShader, TextureDisplacement};
use mipray::displacement_texture::DisplacementTextures;
use mipray::material::network::{NetworkLookup, Op};
use mipray::material::{Input, InputNetwork, Material, TexturedColor};
use mipray::texture::{SourceColorSpace, TextureHandle, TextureSampler, UdimSampler};
use mipray_bridge::{OiioTextureOptions, OiioTextureSystem};

use glam::{Mat4, Vec3A};

use mipray::geometry_cache::{CacheConfig, GeometryCache};
use mipray::tessellate::Tessellation;

use mipray::scene::{Mesh, Scene};

use crate::camera::{Camera, CameraPrim};
use crate::dirty_bits::DirtyBits;
use crate::error::DelegateError;
use crate::instancer::{check_references, expand, instance_motion, InstancerData, InstancerPrim, Pose};
use crate::light::{AreaKind, DistantLightData, LightPrim, LinkData};
use crate::material::{is_color, set_input, NetworkInput, SurfaceInputs, TextureInput};
use crate::mesh::{MeshData, MeshPrim};

/// Rprim types the delegate renders.
pub const RPRIM_TYPES: &[&str] = &["mesh"];
/// Instancer types (Hydra keeps instancers beside the prim types).
pub const INSTANCER_TYPES: &[&str] = &["instancer"];
/// Sprim types the delegate understands.
pub const SPRIM_TYPES: &[&str] = &["camera", "distantLight", "sphereLight", "rectLight", "diskLight", "domeLight"];
/// Bprim types.
pub const BPRIM_TYPES: &[&str] = &["renderBuffer"];

/// Holds the synced prims of one scene, and the geometry cache they share across renders.
#[derive(Default)]
pub struct RenderDelegate {
    meshes: BTreeMap<String, MeshPrim>,
    cameras: BTreeMap<String, CameraPrim>,
    lights: BTreeMap<String, LightPrim>,
    instancers: BTreeMap<String, InstancerPrim>,
    next_cache_id: u32,
    /// Kept between renders while the cache settings stay the same, so an edit to one prim
    /// costs only that prim's tessellations.
    cache: Option<(CacheConfig, Arc<GeometryCache<Tessellation>>)>,
    /// OpenImageIO's texture system, made on the first render that needs one, remade when the
    /// texture settings change; with the store of the displacement textures read through it
    /// (kept across renders with it, so a texture is read once).
    textures: Option<(OiioTextureOptions, Arc<OiioTextureSystem>, Arc<DisplacementTextures>)>,
    /// Texture problems already reported, so each is said once, not once per render.
    warned: Mutex<HashSet<String>>,
    /// Build OpenSubdiv surfaces at sync rather than when a ray first reaches them (benchmarks
    /// and tests compare the two; off by default).
    eager_surfaces: bool,
}

impl RenderDelegate {
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds OpenSubdiv surfaces at sync (`true`) or when a ray first reaches them (`false`,
    /// the default), from the next sync of each mesh on.
    pub fn set_eager_surfaces(&mut self, eager: bool) {
        self.eager_surfaces = eager;
    }

    /// Inserts a mesh, or updates it and marks dirty exactly what changed. The data is checked
    /// here, once ([`MeshData::validate`]): unusable data is kept but not built, each render
    /// reports it in its `prim_errors` (as Hydra's delegates report at sync), and
    /// [`RenderDelegate::mesh_problem`] says why at once.
    pub fn set_mesh(&mut self, path: &str, data: MeshData) {
        match self.meshes.get_mut(path) {
            Some(m) => {
                let d = m.diff(&data);
                m.dirty = m.dirty | d;
                m.invalid = data.validate().err();
                m.data = data;
            }
            None => {
                let id = self.next_cache_id;
                self.next_cache_id += 1;
                self.meshes.insert(path.to_string(), MeshPrim::new(path, data, id));
            }
        }
    }

    /// Why the mesh at `path` was refused by its last [`RenderDelegate::set_mesh`], if it was.
    pub fn mesh_problem(&self, path: &str) -> Option<DelegateError> {
        self.meshes.get(path).and_then(|m| m.invalid.as_ref()).map(|p| DelegateError::prim(path, p))
    }

    /// Moves a mesh: a new object-to-world transform (for a prototype mesh: to its prototype's
    /// root) without resending its points. Rebuilds nothing and keeps its cache entries.
    ///
    /// # Errors
    /// No mesh at `path`, or a transform that is not finite.
    pub fn set_transform(&mut self, path: &str, transform: Mat4) -> Result<(), DelegateError> {
        let m = self.meshes.get_mut(path).ok_or_else(|| DelegateError::prim(path, "set_transform: no mesh at this path"))?;
        if !transform.is_finite() {
            return Err(DelegateError::prim(path, "transform is not finite"));
        }
        if m.data.transform != transform {
            m.data.transform = transform;
            m.dirty = m.dirty | DirtyBits::TRANSFORM;
            if m.invalid.is_some() {
                // The refused data may have been refused for its transform alone.
                m.invalid = m.data.validate().err();
            }
        }
        Ok(())
    }

    /// Sets a mesh's transform over the shutter: `keys` at shutter times in [0, 1] (0 = open),
    /// its world transform, or for a prototype's mesh its transform to the prototype's root
    /// (its instances compose it with their own). Keys that do not move (fewer than two, or all
    /// equal) clear the motion.
    ///
    /// # Errors
    /// No mesh at `path`, or a key that is not finite.
    pub fn set_motion(&mut self, path: &str, keys: Vec<mipray::motion::MotionKey>) -> Result<(), DelegateError> {
        let m = self.meshes.get_mut(path).ok_or_else(|| DelegateError::prim(path, "set_motion: no mesh at this path"))?;
        if let Some(k) = keys.iter().find(|k| !(k.time.is_finite() && k.render_from_object.is_finite())) {
            return Err(DelegateError::prim(path, format!("motion key at shutter time {} is not finite", k.time)));
        }
        let motion = mipray::motion::MotionTransform::new(keys).map(std::sync::Arc::new);
        if m.motion != motion {
            m.motion = motion;
            m.dirty = m.dirty | DirtyBits::TRANSFORM;
        }
        Ok(())
    }

    /// Sets the mesh's points at times across the camera's shutter (deformation motion blur,
    /// [`mipray::deform`]); no samples clear them. Each sample has the mesh's point count; the
    /// topology is the mesh's. Points and curves prims deform too (their points, and with
    /// `widths`, one list per sample, their widths; empty `widths` keep the prim's own), and
    /// implicit prims by `shapes`, one per sample (their points samples empty). Samples that
    /// do not change the mesh's shape rebuild nothing.
    ///
    /// # Errors
    /// No mesh at `path`, a NurbsPatch, samples [`crate::mesh::check_deformation`] refuses,
    /// widths [`crate::mesh::check_deformation_widths`] refuses, or shapes
    /// [`crate::mesh::check_deformation_shapes`] refuses: one line.
    pub fn set_deformation(
        &mut self,
        path: &str,
        samples: crate::mesh::DeformSamples,
        widths: Vec<Vec<f32>>,
        shapes: Vec<mipray::implicit::Shape>,
    ) -> Result<(), DelegateError> {
        let m = self.meshes.get_mut(path).ok_or_else(|| DelegateError::prim(path, "set_deformation: no mesh at this path"))?;
        let deformation = if samples.is_empty() {
            None
        } else {
            if let Some(crate::mesh::Gprim::Nurbs(_)) = &m.data.gprim {
                return Err(DelegateError::prim(
                    path,
                    "set_deformation: a NurbsPatch does not deform (meshes, Points, curves and implicit prims do)",
                ));
            }
            crate::mesh::check_deformation(&samples, m.data.points.len()).map_err(|e| DelegateError::prim(path, e))?;
            crate::mesh::check_deformation_widths(&widths, &samples, &m.data).map_err(|e| DelegateError::prim(path, e))?;
            crate::mesh::check_deformation_shapes(&shapes, &samples, &m.data).map_err(|e| DelegateError::prim(path, e))?;
            Some(std::sync::Arc::new(samples))
        };
        let widths = (deformation.is_some() && !widths.is_empty()).then(|| std::sync::Arc::new(widths));
        let shapes = (deformation.is_some() && !shapes.is_empty()).then(|| std::sync::Arc::new(shapes));
        if m.deformation != deformation || m.deformation_widths != widths || m.deformation_shapes != shapes {
            m.deformation = deformation;
            m.deformation_widths = widths;
            m.deformation_shapes = shapes;
            m.dirty = m.dirty | DirtyBits::POINTS;
        }
        Ok(())
    }

    /// Inserts or replaces an instancer. Its prototypes need not exist yet: they are looked up
    /// when a render pass syncs.
    /// when a render pass syncs. Its instances stop moving until
    /// [`Delegate::set_instancer_motion`] is called again.
    pub fn set_instancer(&mut self, path: &str, data: InstancerData) {
        let updates = self.instancers.get(path).map_or(0, |i| i.updates) + 1;
        self.instancers.insert(path.to_string(), InstancerPrim { path: path.to_string(), data, motion: Vec::new(), updates });
    }

    /// Sets the instancer's per-instance transforms over the camera's shutter (transform motion
    /// blur of instances): `transforms[k * n + i]` is instance `i`'s at shutter time `times[k]`
    /// (0 = open, 1 = close), `n` its instance count, in the frame of its `transforms`. Instances
    /// whose keys are all equal keep their transform; no times clear the motion. Every mesh the
    /// instance places, and every mesh light, moves with it.
    ///
    /// # Errors
    /// No instancer at `path`, sizes that disagree with its instance count, or values that are
    /// not finite: one line naming the instancer.
    pub fn set_instancer_motion(&mut self, path: &str, times: &[f32], transforms: &[Mat4]) -> Result<(), DelegateError> {
        let inst =
            self.instancers.get_mut(path).ok_or_else(|| DelegateError::prim(path, "set_instancer_motion: no instancer at this path"))?;
        inst.motion = instance_motion(path, inst.data.len(), times, transforms)?;
        Ok(())
    }

    /// The instancer at `path`, if any.
    pub fn instancer(&self, path: &str) -> Option<&InstancerPrim> {
        self.instancers.get(path)
    }

    /// Inserts or replaces a camera; the scene's camera carries `path` as its name.
    pub fn set_camera(&mut self, path: &str, camera: Camera) {
        let camera = Camera { name: path.to_string(), ..camera };
        self.cameras.insert(path.to_string(), CameraPrim { path: path.to_string(), camera });
    }

    /// Inserts or replaces a distant light.
    pub fn set_distant_light(&mut self, path: &str, data: DistantLightData) {
        self.set_light(LightPrim { path: path.to_string(), data, area: None, shaping: None, links: LinkData::default() });
    }

    /// Inserts or replaces a light of any kind, with its shaping and links.
    pub fn set_light(&mut self, light: LightPrim) {
        self.lights.insert(light.path.clone(), light);
    }

    /// Inserts or replaces a sphere, rect, disk or dome light: the shared inputs and its shape.
    pub fn set_area_light(&mut self, path: &str, data: DistantLightData, area: AreaKind) {
        self.set_light(LightPrim { path: path.to_string(), data, area: Some(area), shaping: None, links: LinkData::default() });
    }

    /// Removes a prim of any type; returns whether it existed.
    pub fn remove(&mut self, path: &str) -> bool {
        let mesh = self.meshes.remove(path);
        if let (Some(m), Some((_, cache))) = (&mesh, &self.cache) {
            cache.invalidate_mesh(m.cache_id);
        }
        mesh.is_some() | self.cameras.remove(path).is_some() | self.lights.remove(path).is_some() | self.instancers.remove(path).is_some()
    }

    /// Makes (or keeps) the texture system for `options` when some mesh uses textures. A change
    /// of options (say, forcing the finest MIP level) changes what textured displacement
    /// tessellates to, so those meshes' cache entries are dropped.
    ///
    /// # Errors
    /// OpenImageIO could not start a texture system.
    pub fn prepare_textures(&mut self, options: OiioTextureOptions) -> Result<(), DelegateError> {
        let needed = self.meshes.values().any(|m| {
            m.data.displacement_texture.is_some()
                || m.data.material.as_ref().is_some_and(SurfaceInputs::reads_files)
                || m.data.face_materials.as_ref().is_some_and(|f| f.materials.iter().any(SurfaceInputs::reads_files))
        }) || self
            .lights
            .values()
            .any(|l| matches!(&l.area, Some(AreaKind::Dome { texture: Some(_), .. } | AreaKind::Rect { texture: Some(_), .. })));
        if !needed || matches!(&self.textures, Some((o, _, _)) if *o == options) {
            return Ok(());
        }
        let had = self.textures.is_some();
        let system = OiioTextureSystem::new(options).map_err(|e| DelegateError::prim("textures", e))?;
        let system = Arc::new(system);
        let store = Arc::new(DisplacementTextures::new(system.clone()));
        self.textures = Some((options, system, store));
        if had {
            for m in self.meshes.values_mut().filter(|m| m.data.displacement_texture.is_some()) {
                m.generation = m.generation.wrapping_add(1);
                if let Some((_, cache)) = &self.cache {
                    cache.invalidate_mesh(m.cache_id);
                }
            }
        }
        Ok(())
    }

    /// Logs `message` the first time `key` (prim and file) comes up.
    fn warn_once(&self, key: String, message: String) {
        let mut w = self.warned.lock().unwrap_or_else(|e| e.into_inner());
        if w.insert(key) {
            log::warn!("{message}");
        }
    }

    /// The texture system as the core's trait, if one was prepared.
    fn sampler(&self) -> Option<Arc<dyn TextureSampler>> {
        self.textures.as_ref().map(|(_, t, _)| t.clone() as Arc<dyn TextureSampler>)
    }

    /// The geometry cache for `config`: the one kept from earlier renders if its settings are
    /// the same, else a new one.
    pub fn geometry_cache(&mut self, config: CacheConfig) -> Arc<GeometryCache<Tessellation>> {
        match &self.cache {
            Some((c, cache)) if *c == config => cache.clone(),
            _ => {
                let cache = Arc::new(GeometryCache::new(config));
                self.cache = Some((config, cache.clone()));
                cache
            }
        }
    }

    /// Every prim path held, sorted.
    pub fn prim_paths(&self) -> Vec<String> {
        let mut v: Vec<String> =
            self.meshes.keys().chain(self.cameras.keys()).chain(self.lights.keys()).chain(self.instancers.keys()).cloned().collect();
        v.sort();
        v
    }

    pub fn mesh(&self, path: &str) -> Option<&MeshPrim> {
        self.meshes.get(path)
    }

    /// Syncs every dirty prim. A prim that fails is skipped (and reported); the rest sync.
    /// Instancers whose prototypes are missing are reported on every sync, as they stay broken
    /// until a prototype appears.
    pub fn sync(&mut self) -> Vec<DelegateError> {
        // NoProgress never cancels.
        self.sync_or_cancel(&mipray::progress::NoProgress).unwrap_or_default()
    }

    /// As [`RenderDelegate::sync`], starting no more meshes once `progress` is cancelled (Ctrl-C
    /// during a long sync); the meshes not synced stay dirty for the next render. Meshes sync
    /// in parallel on rayon's pool.
    ///
    /// # Errors
    /// [`RenderError::Cancelled`](mipray::error::RenderError::Cancelled).
    pub fn sync_or_cancel(&mut self, progress: &dyn mipray::progress::Progress) -> Result<Vec<DelegateError>, mipray::error::RenderError> {
        use rayon::prelude::*;
        let mut errors = Vec::new();
        // Meshes sync in parallel (each builds its own OpenSubdiv tables); results are taken in
        // path order, so errors and cache invalidations come out as a serial sync's would.
        let mut dirty: Vec<&mut MeshPrim> = self.meshes.values_mut().filter(|m| !m.dirty.is_clean()).collect();
        for m in &mut dirty {
            m.lazy = !self.eager_surfaces;
        }
        let results: Vec<Option<Result<bool, DelegateError>>> = dirty
            .par_iter_mut()
            .with_max_len(1)
            .map(|m| {
                if progress.cancelled() {
                    return None;
                }
                // A panic in one prim's sync (its patch tables, its primvars) drops that prim only.
                Some(std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| m.sync())).unwrap_or_else(|payload| {
                    m.surface = None;
                    let e = DelegateError::internal(&m.path, mipray::dropped::panic_message(payload.as_ref()));
                    m.error = Some(e.to_string());
                    Err(e)
                }))
            })
            .collect();
        let mut cancelled = false;
        for (m, synced) in dirty.iter().zip(results) {
            match synced {
                // Not started: the mesh stays dirty for the next render.
                None => cancelled = true,
                Some(Ok(true)) => {
                    // New points or topology: this mesh's tessellations are stale, nobody else's.
                    if let Some((_, cache)) = &self.cache {
                        cache.invalidate_mesh(m.cache_id);
                    }
                }
                Some(Ok(false)) => {}
                Some(Err(e)) => {
                    log::error!("{e}");
                    errors.push(e);
                }
            }
        }
        if cancelled {
            return Err(mipray::error::RenderError::Cancelled);
        }
        let meshes = &self.meshes;
        for e in check_references(&self.instancers, &|p| meshes.contains_key(p)) {
            log::error!("{e}");
            errors.push(e);
        }
        Ok(errors)
    }

    /// The flat scene for a render from camera `camera_path`. Unsynced or failed meshes are
    /// left out.
    ///
    /// # Errors
    /// The camera does not exist.
    pub fn build_scene(&self, camera_path: &str, default_displacement_bound: f32) -> Result<Scene, DelegateError> {
        let cam = self.cameras.get(camera_path).ok_or_else(|| {
            let known: Vec<&str> = self.cameras.keys().map(String::as_str).collect();
            DelegateError::prim(
                camera_path,
                format!("no such camera (cameras: {})", if known.is_empty() { "none".into() } else { known.join(", ") }),
            )
        })?;
        let mut scene = Scene { camera: cam.camera.clone(), ..Default::default() };
        // Core mesh index per prim path, added on first placement: a prototype nobody places
        // costs nothing, and one placed 10,000 times is one core mesh.
        let mut index: HashMap<&str, Option<usize>> = HashMap::new();
        // Where each emissive mesh is placed (instance pose; identity for one on its own).
        let mut light_places: Vec<(&str, Pose)> = Vec::new();
        let mut place = |scene: &mut Scene, path: &str, pose: Pose| {
            let Some((path, m)) = self.meshes.get_key_value(path) else { return };
            if m.data.light.is_some() {
                // An emissive mesh is a light, not geometry (added with the lights below).
                light_places.push((path.as_str(), pose));
                return;
            }
            let slot = *index.entry(path.as_str()).or_insert_with(|| self.core_mesh(m, default_displacement_bound, scene));
            if let Some(idx) = slot {
                match mesh_pose(m, &pose) {
                    Pose::Moving(motion) => {
                        scene.add_moving_instance(idx, (*motion).clone());
                    }
                    Pose::Fixed(transform) => {
                        scene.add_instance(idx, transform);
                    }
                }
            }
        };
        for m in self.meshes.values().filter(|m| !m.data.prototype) {
            place(&mut scene, &m.path, Pose::Fixed(Mat4::IDENTITY));
        }
        let is_mesh = |p: &str| self.meshes.contains_key(p);
        let top = Pose::Fixed(Mat4::IDENTITY);
        for inst in self.instancers.values().filter(|i| !i.data.prototype) {
            expand(&self.instancers, inst, &top, &is_mesh, &mut |p, t| place(&mut scene, p, t));
        }
        let sampler = self.sampler();
        let mesh_index = |p: &str| index.get(p).copied().flatten();
        scene.lights = crate::light::scene_lights(self.lights.values(), sampler.as_ref(), &mesh_index);
        scene.lights.extend(self.mesh_lights(&light_places, &mesh_index));
        scene.textures = sampler;
        Ok(scene)
    }

    /// The emissive meshes' lights, one per placement in `places` (mesh path, instance pose:
    /// identity for a mesh on its own, which then moves by its own motion), their links resolved
    /// by `mesh_index`. A light placed more than once is named `path[k]`, k its placement's
    /// order. A mesh light whose surface did not sync, or has no area, is left out with one
    /// warning.
    fn mesh_lights(&self, places: &[(&str, Pose)], mesh_index: &dyn Fn(&str) -> Option<usize>) -> Vec<mipray::light::Light> {
        let mut out = Vec::new();
        let mut count: HashMap<&str, usize> = HashMap::new();
        for (path, _) in places {
            *count.entry(path).or_default() += 1;
        }
        let mut seen: HashMap<&str, usize> = HashMap::new();
        let mut tints: HashMap<&str, crate::light::MeshEmitters> = HashMap::new();
        for (path, pose) in places {
            let path = *path;
            let Some(m) = self.meshes.get(path) else { continue };
            let k = seen.entry(path).or_default();
            let name = if count[path] > 1 { format!("{path}[{k}]") } else { path.to_string() };
            *k += 1;
            let (Some(data), Some(surface)) = (&m.data.light, &m.surface) else { continue };
            // A deforming polygonal mesh too (its samples are bilinear surfaces).
            let polygonal = matches!(surface, crate::mesh::Surface::Bilinear(_))
                || (m.data.topology.scheme == mipray::topology::Scheme::None && matches!(surface, crate::mesh::Surface::Deforming(_)));
            let limit = surface.as_limit_surface();
            let d = &m.data;
            let tint = tints.entry(path).or_insert_with(|| self.mesh_emitters(path, d, data));
            // Placed as the geometry is (see `mesh_pose`).
            let (placed, motion) = match mesh_pose(m, pose) {
                Pose::Fixed(placed) => (placed, None),
                Pose::Moving(motion) => (Mat4::IDENTITY, Some(motion)),
            };
            let motion = motion.as_deref();
            match crate::light::mesh_light(
                &name,
                data,
                tint,
                limit.as_ref(),
                polygonal,
                &placed,
                motion,
                d.topology.left_handed,
                d.double_sided,
            ) {
                Some(mut l) => {
                    let resolve = |paths: &[String]| {
                        mipray::light::MeshFilter::excluding(paths.iter().filter_map(|p| mesh_index(p)).map(|i| i as u32).collect())
                    };
                    l.illuminates = resolve(&data.links.unlit);
                    l.shadowed_by = resolve(&data.links.no_shadow);
                    out.push(l);
                }
                None => self.warn_once(format!("{path} mesh light"), format!("{path}: the mesh light has no area; it emits nothing")),
            }
        }
        out
    }

    /// What mesh light `path`'s faces emit as a factor of its colour (UsdLux
    /// `materialGlowTintsLight`): on faces a GeomSubset in `light.tint_materials` binds, that
    /// material's emission; on the others the mesh's own material's when `light.tint`, else 1
    /// ([`Delegate::emitter`]). Uniform when every face emits the same constant.
    fn mesh_emitters(&self, path: &str, data: &crate::mesh::MeshData, light: &crate::light::MeshLightData) -> crate::light::MeshEmitters {
        use crate::light::MeshEmitters;
        use mipray::light::Emitter;
        let st_channel = data.st.as_ref().map(|_| data.channels().st);
        let own = match (&data.material, light.tint) {
            (Some(inputs), true) => self.emitter(path, inputs, st_channel),
            _ => Emitter::Color(Vec3A::ONE),
        };
        let subsets = data
            .face_materials
            .as_ref()
            .filter(|fm| !light.tint_materials.is_empty() && fm.materials.iter().any(|m| light.tint_materials.contains(&m.name)));
        let Some(fm) = subsets else {
            return match own {
                Emitter::Color(c) => MeshEmitters::Uniform(c),
                texture => MeshEmitters::PerFace { emitters: vec![texture], per_face: vec![0; data.face_count()], st_channel },
            };
        };
        // 0: the mesh's own; 1: faces whose material does not tint (the light's colour alone).
        let own_name = data.material.as_ref().filter(|_| light.tint).map(|m| m.name.as_str());
        let mut emitters = vec![own, Emitter::Color(Vec3A::ONE)];
        let slots: Vec<u32> = fm
            .materials
            .iter()
            .map(|m| {
                if light.tint_materials.contains(&m.name) {
                    emitters.push(self.emitter(path, m, st_channel));
                    emitters.len() as u32 - 1
                } else if Some(m.name.as_str()) == own_name {
                    0
                } else {
                    1
                }
            })
            .collect();
        let per_face = fm.indices.iter().map(|&i| if i < 0 { 0 } else { slots[i as usize] }).collect();
        MeshEmitters::PerFace { emitters, per_face, st_channel }
    }

    /// What material `inputs` makes mesh light `path`'s faces emit: its UsdPreviewSurface's
    /// `emissiveColor`, UsdPreviewSurface's fallback black when unauthored (those faces then
    /// emit nothing: one warning), or its texture read at each point's `st` (the texture's
    /// `fallback` where it cannot be read, or where the mesh has no `st`: warned).
    fn emitter(&self, path: &str, inputs: &SurfaceInputs, st_channel: Option<usize>) -> mipray::light::Emitter {
        use mipray::light::Emitter;
        let tint = match inputs.textures.iter().find(|(i, _)| *i == Input::EmissiveColor) {
            Some((input, tex)) => match self.textured_color(path, *input, tex) {
                Some(mut t) => match st_channel {
                    Some(channel) => {
                        t.st_channel = channel;
                        return Emitter::Texture(t);
                    }
                    None => {
                        self.warn_once(
                            format!("{path} no st light"),
                            format!(
                                "{path}: the mesh light's emissiveColor texture {} has no st to read; it emits the texture's fallback",
                                tex.file
                            ),
                        );
                        t.fallback
                    }
                },
                None => tex.affine(*input).2,
            },
            None => {
                if inputs.networks.iter().any(|(i, _)| *i == Input::EmissiveColor) {
                    self.warn_once(
                        format!("{path} network light {}", inputs.name),
                        format!(
                            "{path}: material {}'s emissiveColor is a node network, which a mesh light's tint does not evaluate; using its constant",
                            inputs.name
                        ),
                    );
                }
                inputs.surface.emissive_color
            }
        };
        let tint = if tint.is_finite() { tint.max(Vec3A::ZERO) } else { Vec3A::ZERO };
        if tint.max_element() <= 0.0 {
            self.warn_once(
                format!("{path} black tint {}", inputs.name),
                format!(
                    "{path}: light:materialSyncMode is materialGlowTintsLight and material {}'s emissiveColor is black, so the mesh light emits nothing from the faces bound to it (author emissiveColor, or materialSyncMode independent)",
                    inputs.name
                ),
            );
        }
        Emitter::Color(tint)
    }

    /// The texture `tex` feeding UsdPreviewSurface input `input`, or `None` (warned once,
    /// naming prim, input and file) when the texture cannot be read. Float inputs read the
    /// connected output's channel: scale, bias and fallback are that channel's.
    fn textured_color(&self, path: &str, input: Input, tex: &TextureInput) -> Option<TexturedColor> {
        let (sampler, texture) = self.open_texture(path, input, tex)?;
        let (scale, bias, fallback) = tex.affine(input);
        Some(TexturedColor { sampler, texture, path: tex.file.clone(), lookup: tex.lookup(), scale, bias, fallback, st_channel: 0 })
    }

    /// The sampler and handle that read `tex` (a `<UDIM>` set through a [`UdimSampler`]), or
    /// `None` (warned once, naming prim, input and file) when it cannot be read.
    fn open_texture(&self, path: &str, input: Input, tex: &TextureInput) -> Option<(Arc<dyn TextureSampler>, TextureHandle)> {
        if !tex.udim_tiles.is_empty() {
            return self.open_udim(path, input, tex);
        }
        let problem = match self.sampler() {
            // prepare_textures makes a texture system whenever a mesh has a texture input.
            None => "no texture system".to_string(),
            Some(sampler) => match sampler.handle_encoded(&tex.file, tex.color_space) {
                Ok(texture) => {
                    if !is_color(input) {
                        self.warn_data_decoded(path, input.usd_name(), tex, sampler.as_ref(), texture);
                    }
                    return Some((sampler, texture));
                }
                Err(e) => e.message,
            },
        };
        self.warn_once(
            format!("{path} {}", tex.file),
            format!("{path}: cannot read {} texture {}: {problem}; using its fallback", input.usd_name(), tex.file),
        );
        None
    }

    /// [`Delegate::open_texture`] for a `<UDIM>` set: every tile opened (one that cannot be is
    /// warned about, naming it, and its st reads the fallback), looked up through a
    /// [`UdimSampler`]; `None` when no tile can be read.
    fn open_udim(&self, path: &str, input: Input, tex: &TextureInput) -> Option<(Arc<dyn TextureSampler>, TextureHandle)> {
        let sampler = self.sampler()?;
        let mut tiles = Vec::new();
        for (number, file) in &tex.udim_tiles {
            match sampler.handle_encoded(file, tex.color_space) {
                Ok(handle) => tiles.push((*number, handle)),
                Err(e) => self.warn_once(
                    format!("{path} {file}"),
                    format!("{path}: cannot read {} texture tile {file}: {}; using its fallback there", input.usd_name(), e.message),
                ),
            }
        }
        if tiles.is_empty() {
            self.warn_once(
                format!("{path} {}", tex.file),
                format!("{path}: no tile of {} texture {} can be read; using its fallback", input.usd_name(), tex.file),
            );
            return None;
        }
        let udim: Arc<dyn TextureSampler> = Arc::new(UdimSampler::new(sampler, tiles));
        if !is_color(input) {
            self.warn_data_decoded(path, input.usd_name(), tex, udim.as_ref(), TextureHandle::new(0));
        }
        Some((udim, TextureHandle::new(0)))
    }

    /// The core network of `net` feeding `input`: each lookup's texture opened (one that cannot
    /// be read is warned about by [`Delegate::open_texture`] and gives its fallback). `None`
    /// (warned) for a list that does not check, which `_mipray`'s `set_mesh` already refuses.
    fn input_network(&self, path: &str, input: Input, net: &NetworkInput) -> Option<InputNetwork> {
        let mut ops = net.ops.clone();
        let mut lookups = Vec::new();
        let mut slot = Vec::with_capacity(net.lookups.len());
        for l in &net.lookups {
            let fallback = glam::Vec4::from(l.texture.fallback);
            slot.push(match self.open_texture(path, input, &l.texture) {
                Some((sampler, texture)) => {
                    lookups.push(NetworkLookup {
                        sampler,
                        texture,
                        path: l.texture.file.clone(),
                        lookup: l.texture.lookup(),
                        channels: l.channels,
                        fallback,
                        st_transform: l.st_transform,
                    });
                    Ok(lookups.len() as u16 - 1)
                }
                None => Err(if l.channels == 1 { glam::Vec4::splat(fallback.x) } else { fallback }),
            });
        }
        for op in &mut ops {
            if let Op::Texture(i) = op {
                *op = match slot.get(*i as usize) {
                    Some(Ok(k)) => Op::Texture(*k),
                    Some(Err(v)) => Op::Const(v.to_array()),
                    None => *op, // refused by InputNetwork::new below
                };
            }
        }
        InputNetwork::with_primvars(ops, lookups, net.primvars.clone())
            .map_err(|e| {
                self.warn_once(
                    format!("{path} network {}", input.usd_name()),
                    format!("{path}: {} network: {e}; using its constant", input.usd_name()),
                )
            })
            .ok()
    }

    /// The core material of a mesh bound to a UsdPreviewSurface: its inputs clamped into range
    /// (one warning per material naming the inputs), a [`TexturedColor`] per readable textured
    /// input, and for an unreadable one the texture's `fallback` as the constant, as
    /// UsdUVTexture defines it.
    fn preview_material(&self, path: &str, inputs: &SurfaceInputs) -> Material {
        let mut surface = inputs.surface;
        let mut textures = Vec::new();
        for (input, tex) in &inputs.textures {
            match self.textured_color(path, *input, tex) {
                Some(t) => textures.push((*input, t)),
                None => set_input(&mut surface, *input, tex.affine(*input).2),
            }
        }
        let (mut material, clamped) = Material::preview_surface(inputs.name.as_str(), surface);
        if !clamped.is_empty() {
            self.warn_once(
                format!("clamped {}", inputs.name),
                format!("{}: UsdPreviewSurface inputs out of range, clamped: {}", inputs.name, clamped.join(", ")),
            );
        }
        material.textures = textures;
        material.networks =
            inputs.networks.iter().filter_map(|(input, net)| Some((*input, self.input_network(path, *input, net)?))).collect();
        material
    }

    /// One warning when `auto` read a file that feeds data (normal, roughness, displacement, …)
    /// as sRGB: Hydra's rule decodes every 8-bit RGB file, which bends normals and heights, and
    /// only the author knows the file holds data.
    fn warn_data_decoded(&self, path: &str, input: &str, tex: &TextureInput, sampler: &dyn TextureSampler, handle: TextureHandle) {
        if tex.color_space == SourceColorSpace::Auto && sampler.decoded_from_srgb(handle) {
            self.warn_once(
                format!("{path} {} srgb", tex.file),
                format!(
                    "{path}: {input} texture {} is 8-bit RGB, so sourceColorSpace auto reads it as sRGB (Hydra's rule); \
                     author sourceColorSpace = \"raw\" if it holds data rather than colour",
                    tex.file
                ),
            );
        }
    }

    /// A texture displacement for `input`, or `None` (warned once) when unreadable.
    fn texture_displacement(&self, path: &str, input: &crate::material::TextureInput) -> Option<DisplacementShader> {
        let store = self.textures.as_ref().map(|(_, _, store)| store.clone())?;
        match TextureDisplacement::in_store(&store, &input.file, input.color_space, 0) {
            Ok(mut d) => {
                self.warn_data_decoded(path, "displacement", input, store.sampler().as_ref(), d.texture());
                let c = (input.channel as usize).min(3);
                d.lookup = input.lookup();
                d.scale = input.scale[c];
                d.bias = input.bias[c];
                d.fallback = input.fallback[c];
                Some(DisplacementShader::Texture(Arc::new(d)))
            }
            Err(e) => {
                self.warn_once(
                    format!("{path} {}", input.file),
                    format!("{path}: cannot read displacement texture {}: {}; not displaced", input.file, e.message),
                );
                None
            }
        }
    }

    /// Adds mesh prim `m` (its materials too) to `scene` as a core mesh; `None` when it has no
    /// synced surface (it failed to sync, or was never synced) and is left out.
    fn core_mesh(&self, m: &MeshPrim, default_displacement_bound: f32, scene: &mut Scene) -> Option<usize> {
        let surface = m.surface.as_ref()?;
        let material = match &m.data.material {
            Some(inputs) => self.preview_material(&m.path, inputs),
            // UsdPreviewSurface's fallback colour, lambertian as a display colour is.
            None => Material::lambertian(m.path.as_str(), Vec3A::splat(0.18)).0,
        };
        let channels = m.data.channels();
        let mut material = material;
        for (_, t) in &mut material.textures {
            t.st_channel = channels.st;
        }
        for (_, n) in &mut material.networks {
            n.st_channel = channels.st;
            channels.place(&mut n.primvars);
        }
        material.primvars = channels.inputs.clone();
        let mat = scene.add_material(material);
        let mut mesh = Mesh::new(&m.path, surface.as_limit_surface());
        mesh.material = mat;
        if let Some(fm) = &m.data.face_materials {
            // A subset's whole network: its own textures and lobes, not only its diffuse colour.
            let ids: Vec<u32> = fm
                .materials
                .iter()
                .map(|inputs| {
                    let mut material = self.preview_material(&m.path, inputs);
                    for (_, t) in &mut material.textures {
                        t.st_channel = channels.st;
                    }
                    for (_, n) in &mut material.networks {
                        n.st_channel = channels.st;
                        channels.place(&mut n.primvars);
                    }
                    scene.add_material(material) as u32
                })
                .collect();
            let table: Vec<u32> = fm.indices.iter().map(|&i| if i < 0 { mat as u32 } else { ids[i as usize] }).collect();
            mesh.face_materials = Some(table.into());
        }
        mesh.normals = channels.normals;
        mesh.generation = m.generation;
        mesh.cache_id = Some(m.cache_id);
        mesh.left_handed = m.data.topology.left_handed;
        mesh.displacement = m.data.displacement.map(Into::into);
        if let Some(input) = &m.data.displacement_texture {
            if let Some(d) = self.texture_displacement(&m.path, input) {
                mesh.displacement = Some(d);
            }
        }
        // The authored bound, else the displacement's own (exact) one, else the setting.
        mesh.displacement_bound =
            m.data.displacement_bound.or(mesh.displacement.as_ref().map(DisplacementShader::bound)).unwrap_or(default_displacement_bound);
        if mesh.surface.exact().is_some() || mesh.surface.curves().is_some() {
            // Exact surfaces are not tessellated, and curves are tessellated along their length
            // only, so there is nothing to displace.
            if mesh.displacement.take().is_some() {
                log::warn!("{}: displacement is not applied to implicit prims, points and curves", m.path);
            }
            mesh.displacement_bound = 0.0;
        }
        Some(scene.add_mesh(mesh))
    }
}

/// Where mesh `m` placed at instance pose `pose` (identity for a mesh on its own) is over the
/// shutter. A mesh on its own moves by its own motion (its world transform); a prototype's mesh
/// sits in its prototype's space, so it is `pose × its transform`, or `pose × its motion` when
/// it moves within the prototype (that motion is relative to the prototype's root). Nothing
/// moving gives the product the static path always made.
fn mesh_pose(m: &crate::mesh::MeshPrim, pose: &Pose) -> Pose {
    match (&m.motion, pose) {
        (Some(motion), Pose::Fixed(t)) if !m.data.prototype && *t == Mat4::IDENTITY => Pose::Moving(motion.clone()),
        (Some(motion), _) if m.data.prototype => pose.then(&Pose::Moving(motion.clone())),
        (_, Pose::Fixed(t)) => Pose::Fixed(*t * m.data.transform),
        (_, moving) => moving.then(&Pose::Fixed(m.data.transform)),
    }
}
