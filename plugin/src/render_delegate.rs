//! The render delegate: the prims it supports, insert / mark dirty / sync / remove, and the flat
//! scene a render pass hands to the core.

use std::collections::BTreeMap;
use std::sync::Arc;

use mipray::geometry_cache::{CacheConfig, GeometryCache};
use mipray::tessellate::Tessellation;

use mipray::scene::{Mesh, Scene};

use crate::camera::{Camera, CameraPrim};
use crate::error::DelegateError;
use crate::light::{DistantLightData, LightPrim};
use crate::material::mesh_material;
use crate::mesh::{MeshData, MeshPrim};

/// Rprim types the delegate renders.
pub const RPRIM_TYPES: &[&str] = &["mesh"];
/// Sprim types the delegate understands.
pub const SPRIM_TYPES: &[&str] = &["camera", "distantLight"];
/// Bprim types.
pub const BPRIM_TYPES: &[&str] = &["renderBuffer"];

/// Holds the synced prims of one scene, and the geometry cache they share across renders.
#[derive(Default)]
pub struct RenderDelegate {
    meshes: BTreeMap<String, MeshPrim>,
    cameras: BTreeMap<String, CameraPrim>,
    lights: BTreeMap<String, LightPrim>,
    next_cache_id: u32,
    /// Kept between renders while the cache settings stay the same, so an edit to one prim
    /// costs only that prim's tessellations.
    cache: Option<(CacheConfig, Arc<GeometryCache<Tessellation>>)>,
}

impl RenderDelegate {
    pub fn new() -> Self {
        Self::default()
    }

    /// Inserts a mesh, or updates it and marks dirty exactly what changed.
    pub fn set_mesh(&mut self, path: &str, data: MeshData) {
        match self.meshes.get_mut(path) {
            Some(m) => {
                let d = m.diff(&data);
                m.dirty = m.dirty | d;
                m.data = data;
            }
            None => {
                let id = self.next_cache_id;
                self.next_cache_id += 1;
                self.meshes.insert(path.to_string(), MeshPrim::new(path, data, id));
            }
        }
    }

    /// Inserts or replaces a camera.
    pub fn set_camera(&mut self, path: &str, camera: Camera) {
        self.cameras.insert(path.to_string(), CameraPrim { path: path.to_string(), camera });
    }

    /// Inserts or replaces a distant light.
    pub fn set_distant_light(&mut self, path: &str, data: DistantLightData) {
        self.lights.insert(path.to_string(), LightPrim { path: path.to_string(), data });
    }

    /// Removes a prim of any type; returns whether it existed.
    pub fn remove(&mut self, path: &str) -> bool {
        let mesh = self.meshes.remove(path);
        if let (Some(m), Some((_, cache))) = (&mesh, &self.cache) {
            cache.invalidate_mesh(m.cache_id);
        }
        mesh.is_some() | self.cameras.remove(path).is_some() | self.lights.remove(path).is_some()
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
        let mut v: Vec<String> = self.meshes.keys().chain(self.cameras.keys()).chain(self.lights.keys()).cloned().collect();
        v.sort();
        v
    }

    pub fn mesh(&self, path: &str) -> Option<&MeshPrim> {
        self.meshes.get(path)
    }

    /// Syncs every dirty prim. A prim that fails is skipped (and reported); the rest sync.
    pub fn sync(&mut self) -> Vec<DelegateError> {
        let mut errors = Vec::new();
        for m in self.meshes.values_mut() {
            if m.dirty.is_clean() {
                continue;
            }
            match m.sync() {
                Ok(true) => {
                    // New points or topology: this mesh's tessellations are stale, nobody else's.
                    if let Some((_, cache)) = &self.cache {
                        cache.invalidate_mesh(m.cache_id);
                    }
                }
                Ok(false) => {}
                Err(e) => {
                    log::error!("{e}");
                    errors.push(e);
                }
            }
        }
        errors
    }

    /// The flat scene for a render from camera `camera_path`. Unsynced or failed meshes are
    /// left out.
    ///
    /// # Errors
    /// The camera does not exist.
    pub fn build_scene(&self, camera_path: &str, default_displacement_bound: f32) -> Result<Scene, DelegateError> {
        let cam = self.cameras.get(camera_path).ok_or_else(|| {
            let known: Vec<&str> = self.cameras.keys().map(String::as_str).collect();
            DelegateError::prim(camera_path, format!("no such camera (cameras: {})", if known.is_empty() { "none".into() } else { known.join(", ") }))
        })?;
        let mut scene = Scene { camera: cam.camera.clone(), ..Default::default() };
        for m in self.meshes.values() {
            // A mesh without a surface failed to sync (or was never synced): left out.
            let Some(surface) = &m.surface else { continue };
            let mat = scene.add_material(mesh_material(&m.path, m.data.albedo, m.data.mirror));
            let mut mesh = Mesh::new(&m.path, surface.as_limit_surface());
            mesh.material = mat;
            mesh.generation = m.generation;
            mesh.cache_id = Some(m.cache_id);
            mesh.left_handed = m.data.topology.left_handed;
            mesh.displacement = m.data.displacement;
            // The authored bound, else the procedural displacement's exact one, else the setting.
            mesh.displacement_bound = m.data.displacement_bound.or(m.data.displacement.map(|d| d.bound())).unwrap_or(default_displacement_bound);
            let idx = scene.add_mesh(mesh);
            scene.add_instance(idx, m.data.transform);
        }
        scene.lights = self.lights.values().map(LightPrim::to_light).collect();
        Ok(scene)
    }
}
