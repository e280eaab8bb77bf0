//! # mipray-bridge — OpenSubdiv and OpenImageIO for mipray
//!
//! The C++ shim (through `cxx`) that implements the core's traits: [`OsdSurface`] is a
//! [`mipray::patch::LimitSurface`] made of OpenSubdiv's adaptive patches (with face-varying
//! primvars), [`OiioImageIo`] is a [`mipray::image_io::ImageIo`] by OpenImageIO, and
//! [`OiioTextureSystem`] is a [`mipray::texture::TextureSampler`] by OpenImageIO's
//! `TextureSystem`. Nothing in C++ can abort or unwind into Rust: failures come back as the
//! core's `MeshError` / `ImageError` / `TextureError`, naming the mesh or the path.
//!
//! ```
//! use mipray::patch::LimitSurface;
//! use mipray::topology::{MeshTopology, Scheme};
//! use mipray_bridge::OsdSurface;
//!
//! // A cube of six quads, Catmull-Clark: its limit surface is a rounded box inside the cube.
//! let points = [
//!     [-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, 1.0],
//!     [-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [-1.0, -1.0, -1.0], [1.0, -1.0, -1.0],
//! ];
//! let topology = MeshTopology {
//!     scheme: Scheme::CatmullClark,
//!     face_vertex_counts: vec![4; 6],
//!     face_vertex_indices: vec![
//!         0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4,
//!     ],
//!     ..Default::default()
//! };
//! let surface = OsdSurface::new("/cube", &topology, &points).unwrap();
//! assert!(surface.patch_count() >= 6);
//! let center = surface.evaluate(0, 0.5, 0.5);
//! assert!(center.p.length() < 1.0 && center.dpdu.cross(center.dpdv).length() > 0.0);
//! ```

// No unwrap across the FFI boundary: a panic here would abort a render host (STYLE.md).
#![cfg_attr(not(test), warn(clippy::unwrap_used))]

mod ffi;
pub mod oiio;
pub mod osd;
pub mod texture;
pub mod texture_cache;

pub use oiio::{oiio_version, OiioImageIo};
pub use osd::{limit_fvar_reference, limit_reference, LimitSample, OsdOptions, OsdSurface, UniformMesh};
pub use texture::{OiioTextureOptions, OiioTextureSystem};
