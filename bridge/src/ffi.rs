//! The one `#[cxx::bridge]` between mipray and its C++ libraries (OpenSubdiv's Far, OpenImageIO).
//!
//! Everything here is raw: flat `f32` arrays, integer codes for enums. The safe wrappers in
//! [`crate::osd`], [`crate::oiio`] and [`crate::texture`] validate inputs before they cross and turn results into the
//! core's types. Functions that can throw in C++ return `Result` (cxx turns the exception into an
//! `Err` carrying `what()`); the C++ side also catches everything itself, so nothing unwinds
//! across the boundary. Functions without `Result` are written never to throw (no allocation,
//! bounds checked).

#[cxx::bridge(namespace = "mipray_bridge")]
#[allow(clippy::too_many_arguments)]
pub(crate) mod bridge {
    /// A mesh as OpenSubdiv's `Far::TopologyDescriptor` wants it, plus the refinement options.
    #[derive(Clone, Debug, Default)]
    struct OsdMeshDesc {
        /// 0 Catmull-Clark, 1 Loop, 2 bilinear.
        scheme: u8,
        /// `Sdc::Options::VtxBoundaryInterpolation`: 0 none, 1 edge-only, 2 edge-and-corner.
        boundary: u8,
        /// `Sdc::Options::FVarLinearInterpolation`: 0 none … 5 all (`FVAR_LINEAR_*` order).
        fvar: u8,
        /// `Sdc::Options::TriangleSubdivision`: 0 Catmull-Clark, 1 smooth.
        triangle_subdivision: u8,
        /// Adaptive isolation level for sharp features (1..=10).
        isolation_level: u8,
        /// Shallower isolation level for smooth extraordinary features (≤ `isolation_level`).
        secondary_level: u8,
        num_vertices: i32,
        face_vertex_counts: Vec<i32>,
        face_vertex_indices: Vec<i32>,
        /// Crease edges as vertex pairs, with one sharpness per pair.
        crease_pairs: Vec<i32>,
        crease_weights: Vec<f32>,
        corner_indices: Vec<i32>,
        corner_weights: Vec<f32>,
        hole_indices: Vec<i32>,
        /// Face-varying channels: the number of values of each channel; their values, 2 floats
        /// each, channel after channel; and per channel one index per face-vertex (into that
        /// channel's values), channel after channel.
        fvar_value_counts: Vec<i32>,
        fvar_values: Vec<f32>,
        fvar_indices: Vec<i32>,
        /// Vertex-interpolated 2-float primvars: 2 × `num_vertices` floats per channel.
        vertex_primvars: Vec<f32>,
    }

    /// One patch of the table, decoded from `Far::PatchParam` and `PatchDescriptor`.
    #[derive(Clone, Copy, Debug, Default)]
    struct OsdPatchInfo {
        ptex_face: i32,
        base_face: i32,
        /// Origin and signed edge length of the patch in its ptex face (see `osd.rs`).
        u0: f32,
        v0: f32,
        size: f32,
        depth: u8,
        boundary: u8,
        transition: u8,
        /// 0 bilinear quad, 1 regular B-spline, 2 Gregory basis, 3 Loop, 4 Gregory triangle,
        /// 5 anything else.
        kind: u8,
    }

    /// Result of OpenSubdiv's uniform refinement.
    #[derive(Clone, Debug, Default)]
    struct OsdUniform {
        points: Vec<f32>,
        face_vertex_counts: Vec<i32>,
        face_vertex_indices: Vec<i32>,
    }

    /// Limit positions and first derivatives from the reference paths, 3 floats each.
    #[derive(Clone, Debug, Default)]
    struct OsdLimitSamples {
        p: Vec<f32>,
        dpdu: Vec<f32>,
        dpdv: Vec<f32>,
    }

    /// One metadata attribute to write. `kind`: 0 string, 1 int, 2 float, 3 4×4 matrix.
    #[derive(Clone, Debug, Default)]
    struct OiioAttr {
        name: String,
        kind: u8,
        s: String,
        i: i32,
        f: f32,
        /// 16 floats, row-major, for `kind == 3`.
        m: Vec<f32>,
    }

    /// Settings of an `OiioTexSys` (see `crate::texture::OiioTextureOptions`).
    #[derive(Clone, Copy, Debug, Default)]
    struct OiioTexOptions {
        max_memory_mb: f32,
        max_open_files: i32,
        autotile: i32,
        automip: bool,
        max_textures: u32,
        /// Finest MIP level only, bilinear (the caller also zeroes the derivatives).
        finest: bool,
    }

    /// One texture lookup: handle, (s, t) with t up, and its derivatives; wrap codes 0 from the
    /// file, 1 black, 2 clamp, 3 periodic, 4 mirror.
    #[derive(Clone, Copy, Debug, Default)]
    struct OiioLookup {
        handle: u32,
        s: f32,
        t: f32,
        dsdx: f32,
        dtdx: f32,
        dsdy: f32,
        dtdy: f32,
        first_channel: i32,
        wrap_s: u8,
        wrap_t: u8,
        fill: f32,
    }

    /// The shape of one MIP level of a texture (see `OiioTexSys::level_shapes`).
    #[derive(Clone, Copy, Debug, Default)]
    struct OiioLevel {
        width: u32,
        height: u32,
        /// 0 uint8, 1 uint16, 2 half, 3 float.
        format: u8,
    }

    /// One named statistic.
    #[derive(Clone, Debug, Default)]
    struct OiioStat {
        name: String,
        value: f64,
    }

    /// One metadata attribute read back, formatted as text by OpenImageIO.
    #[derive(Clone, Debug, Default)]
    struct OiioAttrText {
        name: String,
        value: String,
    }

    unsafe extern "C++" {
        include!("mipray-bridge/include/osd.h");
        include!("mipray-bridge/include/oiio.h");
        include!("mipray-bridge/include/texture.h");

        /// Patch table, stencils and refined control points of one mesh.
        type OsdMesh;

        /// Builds the refiner and the adaptive patch table with Gregory-basis end caps (bilinear above
        /// a valence of 256, see `simplified`), and refines
        /// `points` (3 floats per point) into the control points; keeps the table and the points.
        fn osd_mesh_new(desc: &OsdMeshDesc, points: &[f32]) -> Result<UniquePtr<OsdMesh>>;
        /// Warnings OpenSubdiv reported while building (one per line; empty when none).
        fn warnings(self: &OsdMesh) -> String;
        /// What was made cheaper than the exact limit surface to bound the work, one line
        /// (empty: nothing): bilinear end caps above a valence threshold.
        fn simplified(self: &OsdMesh) -> String;
        fn ptex_face_count(self: &OsdMesh) -> usize;
        fn patch_infos(self: &OsdMesh) -> Result<Vec<OsdPatchInfo>>;
        /// A patch's bounds into `out[0..6]` (min xyz, max xyz): a regular patch's Bézier hull,
        /// any other patch's control hull. False for a bad index or a short `out`.
        fn patch_bound(self: &OsdMesh, patch: usize, out: &mut [f32]) -> bool;
        /// A cone holding the direction (up to sign) of a regular patch's normal dP/du × dP/dv
        /// everywhere on it, from its Bézier net: axis into `out[0..3]`, the sine of its
        /// half-angle into `out[3]`. False for an irregular patch (end caps), a bad index, a
        /// short `out`, or a patch whose normals no cone narrower than a half-space holds.
        fn patch_normal_cone(self: &OsdMesh, patch: usize, out: &mut [f32]) -> bool;
        /// A single-crease patch's knots across its crease (see `LimitSurface::edge_knots`):
        /// 1 when they run along u, 2 along v, 0 for any other patch; `out[0..2]` the knots,
        /// NaN where fewer.
        fn edge_knots(self: &OsdMesh, patch: usize, out: &mut [f32]) -> u8;
        /// Bytes held, by part: control points, patch vertex indices, patch params, end-cap
        /// (local point) stencils, per-patch handles and types with the ptex-to-face map,
        /// primvar values. Not counted: the patch map's quadtree and OpenSubdiv's small members.
        fn memory_parts(self: &OsdMesh) -> Result<Vec<u64>>;
        /// Copies the mesh's own points (the first control points) into `out`; false if `out` is
        /// not 3 × the point count long.
        fn base_points(self: &OsdMesh, out: &mut [f32]) -> bool;
        /// Recomputes the refined and local control points from new mesh points, refining
        /// `desc` (the descriptor the mesh was built from) again.
        fn update_points(self: Pin<&mut OsdMesh>, desc: &OsdMeshDesc, points: &[f32]) -> Result<()>;
        /// Position, d/du, d/dv, d²/du², d²/dudv, d²/dv² (18 floats) at the patch's local (u, v).
        /// Returns false (and leaves `out` alone) for a bad patch index or a short `out`.
        fn evaluate(self: &OsdMesh, patch: usize, u: f32, v: f32, out: &mut [f32]) -> bool;
        /// An n×n grid over [u0, u1]×[v0, v1] of the patch's local domain, u fastest. `du`, `dv`
        /// are filled when non-empty. Returns false for a bad index or wrongly sized outputs.
        fn evaluate_grid(
            self: &OsdMesh,
            patch: usize,
            u0: f32,
            v0: f32,
            u1: f32,
            v1: f32,
            n: usize,
            p: &mut [f32],
            du: &mut [f32],
            dv: &mut [f32],
        ) -> bool;
        /// Positions only (3 floats each into `p`) at the patch's local (u, v) pairs `uv`: what
        /// `evaluate` gives as its first three floats, without the derivatives. Returns false for
        /// a bad index or wrongly sized outputs.
        fn evaluate_points(self: &OsdMesh, patch: usize, uv: &[f32], p: &mut [f32]) -> bool;
        /// `Far::PatchMap`: the patch holding (u, v) of a ptex face (its index, or -1 when there
        /// is none: a hole, or out of range), and the patch's local (u, v) there in `local_uv`.
        fn find_patch(self: &OsdMesh, ptex_face: i32, u: f32, v: f32, local_uv: &mut [f32]) -> i64;
        /// Face-varying channels built (as given in the descriptor).
        fn fvar_channel_count(self: &OsdMesh) -> usize;
        /// Vertex primvars built.
        fn vertex_primvar_count(self: &OsdMesh) -> usize;
        /// A 2-float primvar (face-varying channel, or vertex primvar when `vertex`) at the
        /// patch's local (u, v): value, d/du, d/dv into `out[0..6]`. False for a bad index or a
        /// short `out`.
        fn evaluate_primvar(self: &OsdMesh, vertex: bool, channel: usize, patch: usize, u: f32, v: f32, out: &mut [f32]) -> bool;
        /// `evaluate_primvar` at every vertex of the n×n grid over [u0, u1] × [v0, v1] of the
        /// patch (u fastest; the (u, v) of `evaluate_grid`): 6 floats a vertex into `out`, which
        /// holds 6n². A vertex primvar on a regular patch is contracted row by row as the
        /// positions are (equal to the point evaluation within rounding); every other case is
        /// the point evaluation at each vertex. False for a bad index or a wrong `out` size.
        #[allow(clippy::too_many_arguments)]
        fn evaluate_primvar_grid(
            self: &OsdMesh,
            vertex: bool,
            channel: usize,
            patch: usize,
            u0: f32,
            v0: f32,
            u1: f32,
            v1: f32,
            n: usize,
            out: &mut [f32],
        ) -> bool;

        /// Reference path: a fresh refiner and patch table with `Far::LimitStencilTableFactory`'s
        /// options, points refined level by level, `Far::PatchMap` and `PatchTable::EvaluateBasis`
        /// at the given (ptex face, u, v) locations.
        fn osd_limit_reference_eval(
            desc: &OsdMeshDesc,
            points: &[f32],
            ptex_faces: &[i32],
            u: &[f32],
            v: &[f32],
        ) -> Result<OsdLimitSamples>;
        /// Reference path for face-varying channel `channel`, as `osd_limit_reference_eval` for
        /// points: a fresh refiner, the patch table `Far::LimitStencilTableFactory` would build
        /// in face-varying mode, the channel's values refined level by level, `Far::PatchMap` and
        /// `PatchTable::EvaluateBasisFaceVarying` at (ptex face, u, v) locations. Values and
        /// derivatives come back as 3 floats each, the third 0.
        fn osd_limit_reference_fvar_eval(
            desc: &OsdMeshDesc,
            channel: usize,
            ptex_faces: &[i32],
            u: &[f32],
            v: &[f32],
        ) -> Result<OsdLimitSamples>;
        /// Uniform refinement to `level`: the refined points and faces of the last level.
        fn osd_uniform_refine(desc: &OsdMeshDesc, points: &[f32], level: i32) -> Result<OsdUniform>;

        /// Opened image file for reading.
        type OiioReader;

        fn oiio_version() -> String;
        /// Writes interleaved f32 pixels; `formats` has one code per channel (0 half, 1 float,
        /// 2 uint8).
        fn oiio_write(
            path: &str,
            width: u32,
            height: u32,
            channel_names: &Vec<String>,
            formats: &[u8],
            pixels: &[f32],
            attrs: &Vec<OiioAttr>,
            software: &str,
        ) -> Result<()>;
        fn oiio_open(path: &str) -> Result<UniquePtr<OiioReader>>;
        fn width(self: &OiioReader) -> u32;
        fn height(self: &OiioReader) -> u32;
        fn channel_names(self: &OiioReader) -> Result<Vec<String>>;
        fn metadata(self: &OiioReader) -> Result<Vec<OiioAttrText>>;
        /// Reads the whole first subimage as f32 into `out` (width × height × channels).
        fn read_pixels(self: Pin<&mut OiioReader>, out: &mut [f32]) -> Result<()>;

        /// A TextureSystem over a private ImageCache.
        type OiioTexSys;

        fn oiio_texsys_new(options: &OiioTexOptions) -> Result<UniquePtr<OiioTexSys>>;
        /// Opens a texture: its index in the handle table.
        fn open(self: &OiioTexSys, path: &str) -> Result<u32>;
        /// One filtered lookup of `out.len()` channels; false on failure.
        fn sample(self: &OiioTexSys, lookup: &OiioLookup, out: &mut [f32]) -> bool;
        /// Finest-level resolution into `out[0..2]`; false if unknown.
        fn resolution(self: &OiioTexSys, handle: u32, out: &mut [i32]) -> bool;
        /// Channels the file has; 0 if unknown.
        fn channels(self: &OiioTexSys, handle: u32) -> i32;
        /// The first MIP level at most `max_width` wide (up to `channels` channels), scanlines
        /// top first; width, height, channels into `dims[0..3]`.
        fn texels(self: &OiioTexSys, handle: u32, max_width: u32, channels: u32, dims: &mut [i32]) -> Result<Vec<f32>>;
        /// The MIP levels (automip's for a file without levels) of a texture with file channel
        /// `channel`, finest first, and the format they are read in (the file's; float for
        /// formats other than uint8, uint16, half); the file's wrap codes (s, t; 0 when it names
        /// none) into `wrap[0..2]`.
        fn level_shapes(self: &OiioTexSys, handle: u32, channel: i32, wrap: &mut [u8]) -> Result<Vec<OiioLevel>>;
        /// Channel `channel` of every level `level_shapes` gave, one after another in `out`
        /// (native byte order, rows top first), in format `format`.
        fn read_levels(self: &OiioTexSys, handle: u32, channel: i32, format: u8, out: &mut [u8]) -> Result<()>;
        fn cache_stats(self: &OiioTexSys) -> Result<Vec<OiioStat>>;
        fn file_stats(self: &OiioTexSys, handle: u32) -> Result<Vec<OiioStat>>;
        /// OpenImageIO's statistics report (level 1..=5), for logs.
        fn report(self: &OiioTexSys, level: i32) -> Result<String>;
        /// This thread's pending OpenImageIO error, cleared.
        fn take_error(self: &OiioTexSys) -> Result<String>;
        /// Whether sourceColorSpace `auto` decodes the file as sRGB (8-bit, 3 or 4 channels).
        fn oiio_auto_is_srgb(path: &str) -> Result<bool>;
        /// Writes `dst`, a linear half-float tiled MIP map of the sRGB-encoded `src`.
        fn oiio_make_linear_texture(src: &str, dst: &str) -> Result<()>;
    }
}

// SAFETY: an `OsdMesh` owns its OpenSubdiv tables outright (no references to other objects, no
// thread-affine state). Every `&self` method only reads them: `PatchTable::EvaluateBasis` and
// `PatchMap::FindPatch` are const and keep no scratch state, and the control points are only
// written through `Pin<&mut OsdMesh>`, which Rust's borrow rules make exclusive.
unsafe impl Send for bridge::OsdMesh {}
// SAFETY: see `Send` above: shared access is read-only.
unsafe impl Sync for bridge::OsdMesh {}

// SAFETY: an `OiioTexSys` owns its ImageCache and TextureSystem (created unshared) and a handle
// table; nothing in it is tied to the creating thread. OpenImageIO's TextureSystem is documented
// thread safe for concurrent lookups; its per-thread state is fetched per calling thread (cached
// in a C++ `thread_local` keyed by a never-reused system id); the handle table is written under a
// mutex and read through atomics.
unsafe impl Send for bridge::OiioTexSys {}
// SAFETY: see `Send` above: every `&self` method is safe to call from many threads at once.
unsafe impl Sync for bridge::OiioTexSys {}
