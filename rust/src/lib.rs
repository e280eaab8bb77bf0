//! # mipray — the tracing core
//!
//! Ray tracing of subdivision surfaces with on-demand, per-subpatch tessellation at the rate each
//! ray's beam width asks for, cached in a three-tier "tessellation MIP map" (Christensen et al.,
//! *Ray Differentials and Multiresolution Geometry Caching for Distribution Ray Tracing in Complex
//! Scenes*, 2003). Pure Rust: OpenSubdiv and OpenImageIO come in through the [`patch::LimitSurface`]
//! and [`image_io::ImageIo`] traits, implemented by `mipray-bridge`.
//!
//! ```
//! use mipray::prelude::*;
//! // A unit quad facing +z, lit head-on by a distant light, seen by an orthographic camera.
//! let topo = MeshTopology {
//!     scheme: Scheme::None,
//!     face_vertex_counts: vec![4],
//!     face_vertex_indices: vec![0, 1, 2, 3],
//!     ..Default::default()
//! };
//! let pts = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]];
//! let surface = BilinearSurface::new(&topo, &pts).unwrap();
//! let mut scene = Scene::default();
//! let mesh = scene.add_mesh(Mesh::new("/quad", std::sync::Arc::new(surface)));
//! scene.add_instance(mesh, glam::Mat4::IDENTITY);
//! scene.lights.push(Light::distant("/sun", glam::Vec3A::new(0.0, 0.0, -1.0), glam::Vec3A::ONE));
//! scene.camera = Camera::orthographic(glam::Mat4::from_translation(glam::Vec3::new(0.0, 0.0, 5.0)), 1.0, 1.0);
//! let out = render(&scene, &RenderOptions { width: 4, height: 4, ..Default::default() }, &NoProgress).unwrap();
//! let c = out.film.pixel("color", 2, 2);
//! assert!((c[0] - 0.18 / std::f32::consts::PI).abs() < 1e-3);
//! ```

pub mod aov;
pub mod bilinear;
pub mod bounds;
pub mod bsdf;
pub mod bvh;
pub mod camera;
pub mod curves;
pub mod deform;
pub mod differential;
pub mod displacement;
pub mod displacement_texture;
pub mod dropped;
pub mod effects;
pub mod error;
pub mod film;
pub mod geometry_budget;
pub mod geometry_cache;
pub mod hit;
pub mod image_io;
pub mod image_output;
pub mod implicit;
pub mod integrator;
pub mod intersect;
pub mod irradiance_cache;
pub mod lazy_surface;
pub mod light;
pub mod light_sampler;
pub mod material;
pub mod motion;
pub mod nurbs;
pub mod obj_shape;
pub mod options;
pub mod patch;
pub mod progress;
pub mod ray;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod seam;
pub mod settings;
pub mod stats;
pub mod subpatch;
pub mod tessellate;
pub mod texture;
pub mod topology;
pub mod trace;
pub mod transform;
pub mod trim;

/// The names most users need.
pub mod prelude {
    pub use crate::bilinear::BilinearSurface;
    pub use crate::camera::Camera;
    pub use crate::film::Film;
    pub use crate::light::Light;
    pub use crate::material::Material;
    pub use crate::options::RenderOptions;
    pub use crate::patch::{LimitSurface, PatchParam, SurfacePoint};
    pub use crate::progress::{NoProgress, Progress};
    pub use crate::render::{render, RenderOutput};
    pub use crate::scene::{Mesh, Scene};
    pub use crate::topology::{MeshTopology, Scheme};
}
