//! The scene the core renders: meshes (prototypes with their limit surfaces), instances of them
//! with transforms, a camera, lights and materials. The render delegate (`hd-mipray`) owns the
//! Hydra-shaped prims and builds this flat description for a render.

use std::sync::Arc;

use glam::{Mat4, Vec3A};

use crate::camera::Camera;
use crate::displacement::DisplacementShader;
use crate::light::Light;
use crate::material::Material;
use crate::patch::LimitSurface;

/// One mesh prototype: its patches (object space) and what shading needs. Instances share it,
/// its subpatches and its geometry cache entries.
#[derive(Clone)]
pub struct Mesh {
    /// Prim path, for messages and stats.
    pub name: String,
    pub surface: Arc<dyn LimitSurface>,
    /// Index into [`Scene::materials`]; out of range means the default material.
    pub material: usize,
    /// How far displacement may move the surface along its normal, object units. Subpatch
    /// bounds grow by this much.
    pub displacement_bound: f32,
    /// Bumped when the mesh's points change, so old cache entries can never be hit again.
    pub generation: u32,
    /// USD `orientation = "leftHanded"`: the front face winds clockwise, so geometric and
    /// shading normals are negated. Patch sources evaluate the surface as given.
    pub left_handed: bool,
    /// Displacement along the limit normal, applied when tessellating.
    pub displacement: Option<DisplacementShader>,
    /// The mesh's key in a geometry cache that outlives one render (the delegate's): stable
    /// across edits of other prims. `None`: its index in [`Scene::meshes`].
    pub cache_id: Option<u32>,
    /// Per control (base) face, an index into [`Scene::materials`] overriding [`Mesh::material`]
    /// (USD GeomSubsets with their own material bindings, uniform `displayColor`). `None`, a
    /// face past the end, or an index out of range: the mesh's material.
    pub face_materials: Option<Arc<[u32]>>,
    /// Authored normals (USD `normals` / `primvars:normals` on a polygonal mesh): the surface's
    /// 2-float primvar channels holding (x, y) and (z, ·), object space, interpolated over each
    /// face and normalized for shading (smooth shading of a faceted mesh). `None`: the limit
    /// surface's own normal.
    pub normals: Option<[usize; 2]>,
}

impl std::fmt::Debug for Mesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mesh")
            .field("name", &self.name)
            .field("patches", &self.surface.patch_count())
            .field("material", &self.material)
            .finish()
    }
}

impl Mesh {
    pub fn new(name: impl Into<String>, surface: Arc<dyn LimitSurface>) -> Self {
        Mesh {
            name: name.into(),
            surface,
            material: usize::MAX,
            displacement_bound: 0.0,
            generation: 0,
            left_handed: false,
            displacement: None,
            cache_id: None,
            face_materials: None,
            normals: None,
        }
    }
}

/// A placement of a mesh in the scene.
#[derive(Clone, Debug)]
pub struct Instance {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Object-to-render (world) transform, column-vector convention.
    pub render_from_object: Mat4,
    /// The id the `instanceId` AOV reports.
    pub id: u32,
    /// The transform over the shutter when it changes within it (transform motion blur);
    /// `render_from_object` is then its value at shutter open.
    pub motion: Option<Arc<crate::motion::MotionTransform>>,
}

/// Everything one render needs. Render space is USD's world space.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub meshes: Vec<Mesh>,
    pub instances: Vec<Instance>,
    pub camera: Camera,
    pub lights: Vec<Light>,
    pub materials: Vec<Material>,
    /// The texture system materials and displacement read through, for the stats'
    /// `texture_cache` object.
    pub textures: Option<std::sync::Arc<dyn crate::texture::TextureSampler>>,
}

impl Scene {
    /// Adds a mesh prototype and returns its index.
    pub fn add_mesh(&mut self, mesh: Mesh) -> usize {
        self.meshes.push(mesh);
        self.meshes.len() - 1
    }

    /// Places mesh `mesh` with transform `render_from_object`; returns the instance index.
    pub fn add_instance(&mut self, mesh: usize, render_from_object: Mat4) -> usize {
        let id = self.instances.len() as u32;
        self.instances.push(Instance { mesh, render_from_object, id, motion: None });
        self.instances.len() - 1
    }

    /// Places mesh `mesh` moving through `motion` during the shutter; returns the instance index.
    pub fn add_moving_instance(&mut self, mesh: usize, motion: crate::motion::MotionTransform) -> usize {
        let id = self.instances.len() as u32;
        let render_from_object = motion.at(0.0);
        self.instances.push(Instance { mesh, render_from_object, id, motion: Some(Arc::new(motion)) });
        self.instances.len() - 1
    }

    /// The instances whose transform changes within the shutter.
    pub fn moving_instances(&self) -> impl Iterator<Item = &Instance> {
        self.instances.iter().filter(|i| i.motion.is_some())
    }

    /// Adds a material and returns its index.
    pub fn add_material(&mut self, material: Material) -> usize {
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// The material of a mesh (the default material when unbound).
    pub fn material_of(&self, mesh: usize) -> &Material {
        static DEFAULT: std::sync::OnceLock<Material> = std::sync::OnceLock::new();
        self.meshes.get(mesh).and_then(|m| self.materials.get(m.material)).unwrap_or_else(|| DEFAULT.get_or_init(Material::default))
    }

    /// The material at patch `patch` of mesh `mesh`: its base face's entry in
    /// [`Mesh::face_materials`] if there is one, else [`Scene::material_of`].
    pub fn material_at(&self, mesh: usize, patch: usize) -> &Material {
        let face_material = self.meshes.get(mesh).and_then(|m| {
            let table = m.face_materials.as_ref()?;
            let face = m.surface.patch_param(patch).base_face as usize;
            self.materials.get(*table.get(face)? as usize)
        });
        face_material.unwrap_or_else(|| self.material_of(mesh))
    }
}

impl Scene {
    /// The name (prim path) of mesh `mesh` (an index into [`Scene::meshes`]), if there is one.
    pub fn mesh_name(&self, mesh: u32) -> Option<&str> {
        self.meshes.get(mesh as usize).map(|m| m.name.as_str())
    }

    /// Radiance (RGB) arriving along render-space unit `wi` from rays that escape the scene, as
    /// lighting integrates it: the sum of every dome light and of every distant light with an
    /// angle whose disk `wi` falls in ([`Light::environment`]). Zero without such lights. What
    /// the direct-light estimator's BSDF samples and a path tracer's MIS-weighted escaped rays
    /// add.
    pub fn environment(&self, wi: Vec3A) -> Vec3A {
        self.lights.iter().filter(|l| l.is_infinite()).map(|l| l.environment(wi)).sum()
    }

    /// The background a camera ray, or a mirror's reflection, sees along unit `wi` when it
    /// escapes, filtered over the ray's directional spread `spread_rad` (radians, from its
    /// differential: [`crate::differential::RayDifferential::directional_spread_rad`]), so a
    /// dome seen directly is as sharp as the pixel ([`Light::seen`]). Zero without dome or
    /// angular distant lights.
    pub fn background(&self, wi: Vec3A, spread_rad: f32) -> Vec3A {
        self.lights.iter().filter(|l| l.is_infinite()).map(|l| l.seen(wi, spread_rad)).sum()
    }
}
