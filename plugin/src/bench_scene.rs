//! The geometry-cache benchmark scene (the paper's §6.3.2, made here): many individually
//! modelled Catmull-Clark objects — no instancing, every one a different shape — half chrome
//! and half matte with ambient occlusion, some displaced, on a matte ground under a sun. Most
//! rays are incoherent AO and curved-mirror rays: the case the multiresolution cache is for.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec3A};
use mipray::camera::Camera;
use mipray::displacement::Displacement;
use mipray::light::Light;
use mipray::material::Material;
use mipray::scene::{Mesh, Scene};
use mipray::topology::{MeshTopology, Scheme};
use mipray_bridge::OsdSurface;

/// Which objects the scene is made of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchKind {
    /// Cube-sphere blobs ([`blob_mesh`]): every vertex regular but the eight cube corners, a
    /// third displaced, half chrome and half matte under ambient occlusion (the paper's §6.3.2).
    Cubes,
    /// Latitude-longitude blobs ([`latlong_blob_mesh`]): `2·face_res` segments and `face_res`
    /// rings, so two poles of valence `2·face_res` each, ringed by triangles; half mirrors, no
    /// ambient occlusion, a sun. Control faces about a pixel on screen, and at the poles many
    /// small irregular patches: the scene of issue 15.
    LatLong,
}

impl BenchKind {
    pub const fn name(self) -> &'static str {
        match self {
            BenchKind::Cubes => "cubes",
            BenchKind::LatLong => "latlong",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [BenchKind::Cubes, BenchKind::LatLong].into_iter().find(|k| k.name() == name)
    }
}

/// Size of the generated scene.
#[derive(Clone, Copy, Debug)]
pub struct BenchSceneSpec {
    /// Objects along x and along y on the ground.
    pub grid: (usize, usize),
    /// Quads per cube-face side of each object's control mesh (6·n² faces), or rings of a
    /// lat-long blob (2·n² faces).
    pub face_res: usize,
    pub seed: u64,
    pub kind: BenchKind,
    /// Build each object's OpenSubdiv tables when a ray first reaches it
    /// ([`mipray::lazy_surface::LazySurface`], as the delegate does) rather than up front.
    pub lazy: bool,
    /// The camera's focal length, mm on a 36 mm aperture (24: the whole grid in view; longer
    /// lenses see fewer objects).
    pub focal_length: f32,
}

impl Default for BenchSceneSpec {
    /// 24 × 20 objects of 6·13² = 1014 control faces: about 1.8 GB of vertices if every
    /// subpatch were tessellated at 17×17.
    fn default() -> Self {
        BenchSceneSpec { grid: (24, 20), face_res: 13, seed: 1, kind: BenchKind::Cubes, lazy: false, focal_length: 24.0 }
    }
}

impl BenchSceneSpec {
    /// The lat-long blob scene at the size `make bench-cache` renders it: 12 × 8 blobs of
    /// 80 segments × 40 rings (3,200 control faces, two valence-80 poles each), 307k control
    /// faces in all.
    pub fn latlong() -> Self {
        BenchSceneSpec { grid: (12, 8), face_res: 40, seed: 1, kind: BenchKind::LatLong, lazy: false, focal_length: 24.0 }
    }
}

fn hash(mut x: u64) -> u64 {
    x ^= x >> 33;
    x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
    x ^= x >> 33;
    x = x.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    x ^ (x >> 33)
}

/// The seed of object `k` of a scene built with `seed`.
pub fn object_seed(seed: u64, k: u64) -> u64 {
    hash(seed ^ k)
}

fn rand01(seed: u64, k: u64) -> f32 {
    (hash(seed.wrapping_mul(0x9E37_79B9).wrapping_add(k)) >> 40) as f32 / (1u64 << 24) as f32
}

/// A lumpy closed control mesh: a cube of `n×n` quads per face pushed onto a sphere, then
/// dented by a few random smooth lumps so every object is a different shape.
pub fn blob_mesh(n: usize, seed: u64) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts: Vec<[f32; 3]> = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut idx = Vec::new();
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (-Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (-Vec3::Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (-Vec3::Z, Vec3::Y, Vec3::X),
    ];
    let lumps = lumps(seed);
    let mut vid = |p: Vec3| -> i32 {
        // Shared cube edges produce the same point from two faces: key by rounded position.
        let key = ((p.x * 4096.0).round() as i64, (p.y * 4096.0).round() as i64, (p.z * 4096.0).round() as i64);
        *index.entry(key).or_insert_with(|| {
            let s = p.normalize();
            pts.push((s * lumped_radius(&lumps, s)).to_array());
            (pts.len() - 1) as i32
        })
    };
    for (nrm, a, b) in faces {
        for j in 0..n {
            for i in 0..n {
                let at = |i: usize, j: usize| nrm + a * (2.0 * i as f32 / n as f32 - 1.0) + b * (2.0 * j as f32 / n as f32 - 1.0);
                let q = [vid(at(i, j)), vid(at(i + 1, j)), vid(at(i + 1, j + 1)), vid(at(i, j + 1))];
                idx.extend(q);
            }
        }
    }
    let topo = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: vec![4; 6 * n * n],
        face_vertex_indices: idx,
        ..Default::default()
    };
    (topo, pts)
}

/// A lumpy latitude-longitude sphere: `2·rings` segments around, `rings` bands from pole to
/// pole, triangles at the two poles (so each pole is a vertex of valence `2·rings`), quads
/// elsewhere, dented by the same random smooth lumps as [`blob_mesh`].
pub fn latlong_blob_mesh(rings: usize, seed: u64) -> (MeshTopology, Vec<[f32; 3]>) {
    let rings = rings.max(2);
    let segments = 2 * rings;
    let lumps = lumps(seed);
    let place = |s: Vec3| -> [f32; 3] { (s * lumped_radius(&lumps, s)).to_array() };
    // South pole, rings − 1 circles of latitude, north pole.
    let mut pts = vec![place(-Vec3::Z)];
    for r in 1..rings {
        let lat = std::f32::consts::PI * (r as f32 / rings as f32 - 0.5);
        for i in 0..segments {
            let lon = std::f32::consts::TAU * i as f32 / segments as f32;
            pts.push(place(Vec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin())));
        }
    }
    pts.push(place(Vec3::Z));
    let north = (pts.len() - 1) as i32;
    let at = |r: usize, i: usize| (1 + (r - 1) * segments + i % segments) as i32;
    let (mut counts, mut idx) = (Vec::new(), Vec::new());
    // Counter-clockwise seen from outside: along the longitude, then up.
    for i in 0..segments {
        counts.push(3);
        idx.extend([0, at(1, i + 1), at(1, i)]);
    }
    for r in 1..rings - 1 {
        for i in 0..segments {
            counts.push(4);
            idx.extend([at(r, i), at(r, i + 1), at(r + 1, i + 1), at(r + 1, i)]);
        }
    }
    for i in 0..segments {
        counts.push(3);
        idx.extend([at(rings - 1, i), at(rings - 1, i + 1), north]);
    }
    let topo = MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: counts, face_vertex_indices: idx, ..Default::default() };
    (topo, pts)
}

/// Five random smooth lumps (direction, height) of a blob.
fn lumps(seed: u64) -> Vec<(Vec3, f32)> {
    (0..5)
        .map(|k| {
            let d =
                Vec3::new(rand01(seed, 3 * k) - 0.5, rand01(seed, 3 * k + 1) - 0.5, rand01(seed, 3 * k + 2) - 0.5).normalize_or(Vec3::Z);
            (d, 0.35 * (rand01(seed, 100 + k) - 0.4))
        })
        .collect()
}

/// The radius of a blob with `lumps` in unit direction `s`.
fn lumped_radius(lumps: &[(Vec3, f32)], s: Vec3) -> f32 {
    1.0 + lumps.iter().map(|(d, a)| a * (-(1.0 - s.dot(*d)) * 4.0).exp()).sum::<f32>()
}

/// Distance between neighbouring objects' centres on the ground, scene units.
const SPACING: f32 = 2.6;
/// Half the ground quad's side, scene units.
const GROUND_HALF: f32 = 200.0;
/// The direction the sun shines along (render space, not normalized).
const SUN_DIRECTION: Vec3 = Vec3::new(0.4, 0.6, -0.7);

/// One object of the grid, as both [`build`] and [`write_usda`] place it.
struct Blob {
    /// Column and row in the grid.
    i: usize,
    j: usize,
    /// Index in the grid, row by row.
    k: u64,
    latlong: bool,
    topo: MeshTopology,
    pts: Vec<[f32; 3]>,
    /// Render from object.
    transform: Mat4,
    chrome: bool,
}

/// The objects of `spec`'s grid, row by row.
fn blobs(spec: &BenchSceneSpec) -> impl Iterator<Item = Blob> + '_ {
    let (gx, gy) = spec.grid;
    (0..gy).flat_map(move |j| (0..gx).map(move |i| (i, j))).map(move |(i, j)| {
        let k = (j * gx + i) as u64;
        let seed = object_seed(spec.seed, k);
        let latlong = spec.kind == BenchKind::LatLong;
        let (topo, pts) = if latlong { latlong_blob_mesh(spec.face_res, seed) } else { blob_mesh(spec.face_res, seed) };
        let x = (i as f32 - (gx as f32 - 1.0) / 2.0) * SPACING;
        let y = j as f32 * SPACING;
        let s = 0.8 + 0.4 * rand01(seed, 7);
        let transform = Mat4::from_translation(Vec3::new(x, y, s))
            * Mat4::from_rotation_z(rand01(seed, 8) * std::f32::consts::TAU)
            // Lat-long blobs lean their poles every way, toward the camera too.
            * Mat4::from_rotation_x(if latlong { rand01(seed, 9) * std::f32::consts::PI } else { 0.0 })
            * Mat4::from_scale(Vec3::splat(s));
        Blob { i, j, k, latlong, topo, pts, transform, chrome: (i + j) % 2 == 0 }
    })
}

/// The camera's render from camera: above and behind the first row, looking into the grid.
fn camera_transform(spec: &BenchSceneSpec) -> Mat4 {
    let eye = Vec3::new(0.0, -9.0, 6.0);
    Camera::look_at(eye, Vec3::new(0.0, spec.grid.1 as f32 * SPACING * 0.45, 0.0), Vec3::Z)
}

/// Builds the scene (OpenSubdiv patch tables for every object). Returns the scene and the
/// number of control faces.
///
/// # Errors
/// OpenSubdiv refusing a generated mesh (a bug in the generator).
pub fn build(spec: &BenchSceneSpec) -> Result<Scene, mipray::error::MeshError> {
    let mut scene = Scene::default();
    let chrome = scene.add_material(Material::mirror("/materials/chrome", Vec3A::splat(0.05), Vec3A::splat(0.9)));
    let matte = scene.add_material(Material::lambertian("/materials/matte", Vec3A::new(0.6, 0.55, 0.5)).0);
    let ground_mat = scene.add_material(Material::lambertian("/materials/ground", Vec3A::splat(0.4)).0);
    for Blob { i, j, k, latlong, topo, pts, transform, chrome: is_chrome } in blobs(spec) {
        let name = format!("/objects/blob_{i}_{j}");
        let surface: Arc<dyn mipray::patch::LimitSurface> = if spec.lazy {
            let hull = mipray::bounds::Bounds3::from_points(pts.iter().map(|&p| p.into()));
            let faces = topo.face_count();
            let n = name.clone();
            Arc::new(mipray::lazy_surface::LazySurface::new(
                hull,
                faces,
                Box::new(move || {
                    OsdSurface::new(&n, &topo, &pts).map(|s| Arc::new(s) as Arc<dyn mipray::patch::LimitSurface>).map_err(|e| e.to_string())
                }),
            ))
        } else {
            Arc::new(OsdSurface::new(&name, &topo, &pts)?)
        };
        let mut mesh = Mesh::new(&name, surface);
        mesh.material = if is_chrome { chrome } else { matte };
        if k % 3 == 0 && !latlong {
            mesh.displacement = Some(Displacement { amplitude: 0.03, frequency: 3.0, octaves: 4, gain: 0.5 }.into());
            mesh.displacement_bound = 0.06;
        }
        let m = scene.add_mesh(mesh);
        scene.add_instance(m, transform);
    }
    let ground = BilinearGround::new(GROUND_HALF)?;
    let mut gm = Mesh::new("/ground", Arc::new(ground));
    gm.material = ground_mat;
    let g = scene.add_mesh(gm);
    scene.add_instance(g, Mat4::IDENTITY);
    scene.lights.push(Light::distant("/sun", SUN_DIRECTION.into(), Vec3A::splat(2.5)));
    scene.camera = Camera {
        render_from_camera: camera_transform(spec),
        focal_length: spec.focal_length,
        horizontal_aperture: 36.0,
        vertical_aperture: 24.0,
        clipping_range: (0.1, 1e5),
        ..Default::default()
    };
    Ok(scene)
}

/// A ground quad, as bilinear patches.
struct BilinearGround;

impl BilinearGround {
    #[allow(clippy::new_ret_no_self)]
    fn new(half: f32) -> Result<mipray::bilinear::BilinearSurface, mipray::error::MeshError> {
        let topo =
            MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
        mipray::bilinear::BilinearSurface::new(&topo, &[[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    }
}

/// The crease edges of a cube blob from [`blob_mesh`] (`face_res` faces a side): its twelve cube
/// edges, the edges between faces of different cube sides (faces come side by side, n² each), as
/// (lower, higher) point index pairs. `write_usda` with `creased` gives them sharpness 3.
pub fn cube_blob_creases(face_res: usize, topo: &MeshTopology) -> Vec<(i32, i32)> {
    let per_side = face_res * face_res;
    let mut sides: std::collections::HashMap<(i32, i32), usize> = std::collections::HashMap::new();
    let mut creases = Vec::new();
    for (face, q) in topo.face_vertex_indices.chunks(4).enumerate() {
        for e in 0..4 {
            let (a, b) = (q[e], q[(e + 1) % 4]);
            let key = (a.min(b), a.max(b));
            match sides.get(&key) {
                Some(&side) if side != face / per_side => creases.push(key),
                Some(_) => {}
                None => {
                    sides.insert(key, face / per_side);
                }
            }
        }
    }
    creases
}

/// A cube blob from [`blob_mesh`] with its twelve cube edges semi-sharp creases of `sharpness`
/// (the creased scene of docs/memory-usd.md, as `write_usda` with `creased` writes it).
pub fn creased_blob_mesh(face_res: usize, seed: u64, sharpness: f32) -> (MeshTopology, Vec<[f32; 3]>) {
    let (mut topo, pts) = blob_mesh(face_res, seed);
    let creases = cube_blob_creases(face_res, &topo);
    topo.crease_indices = creases.iter().flat_map(|&(a, b)| [a, b]).collect();
    topo.crease_lengths = vec![2; creases.len()];
    topo.crease_sharpnesses = vec![sharpness; creases.len()];
    (topo, pts)
}

/// Writes the scene of `spec` as a USD stage (text, `.usda`), for measuring it as a user renders
/// a stage: through usd-core, the Python scene delegate and `mipray-record`. The same objects,
/// placements, materials (UsdPreviewSurface: chrome as metallic at roughness 0, matte as
/// diffuse), ground, sun and camera as [`build`]. With `creased`, each cube blob's twelve cube
/// edges are semi-sharp creases (sharpness 3; cube blobs only). Displacement is not written.
///
/// # Errors
/// Writing the file.
pub fn write_usda(spec: &BenchSceneSpec, creased: bool, path: &std::path::Path) -> std::io::Result<()> {
    use std::fmt::Write as _;
    use std::io::Write as _;
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    let matrix = |m: Mat4| {
        // USD's matrices act on row vectors: its rows are glam's columns.
        let c = m.to_cols_array_2d();
        let row = |r: [f32; 4]| format!("({}, {}, {}, {})", r[0], r[1], r[2], r[3]);
        format!("( {}, {}, {}, {} )", row(c[0]), row(c[1]), row(c[2]), row(c[3]))
    };
    let join = |v: &mut dyn Iterator<Item = String>| v.collect::<Vec<_>>().join(", ");
    writeln!(f, "#usda 1.0\n(\n    defaultPrim = \"World\"\n    metersPerUnit = 1\n    upAxis = \"Z\"\n)\n")?;
    writeln!(f, "def Xform \"World\"\n{{")?;
    writeln!(f, "    def Scope \"Looks\"\n    {{")?;
    for (name, diffuse, metallic, roughness) in
        [("chrome", "(0.05, 0.05, 0.05)", 1.0, 0.0), ("matte", "(0.6, 0.55, 0.5)", 0.0, 1.0), ("ground", "(0.4, 0.4, 0.4)", 0.0, 1.0)]
    {
        writeln!(
            f,
            "        def Material \"{name}\"\n        {{\n            token outputs:surface.connect = </World/Looks/{name}/pbr.outputs:surface>\n            def Shader \"pbr\"\n            {{\n                uniform token info:id = \"UsdPreviewSurface\"\n                color3f inputs:diffuseColor = {diffuse}\n                float inputs:metallic = {metallic}\n                float inputs:roughness = {roughness}\n                token outputs:surface\n            }}\n        }}"
        )?;
    }
    writeln!(f, "    }}")?;
    for Blob { i, j, latlong, topo, pts, transform: xf, chrome, .. } in blobs(spec) {
        let mut body = String::new();
        let _ = writeln!(body, "        uniform token subdivisionScheme = \"catmullClark\"");
        let _ = writeln!(body, "        int[] faceVertexCounts = [{}]", join(&mut topo.face_vertex_counts.iter().map(|c| c.to_string())));
        let _ = writeln!(body, "        int[] faceVertexIndices = [{}]", join(&mut topo.face_vertex_indices.iter().map(|c| c.to_string())));
        let _ = writeln!(body, "        point3f[] points = [{}]", join(&mut pts.iter().map(|p| format!("({}, {}, {})", p[0], p[1], p[2]))));
        if creased && !latlong {
            let creases = cube_blob_creases(spec.face_res, &topo);
            let _ = writeln!(body, "        int[] creaseIndices = [{}]", join(&mut creases.iter().map(|(a, b)| format!("{a}, {b}"))));
            let _ = writeln!(body, "        int[] creaseLengths = [{}]", join(&mut creases.iter().map(|_| "2".to_string())));
            let _ = writeln!(body, "        float[] creaseSharpnesses = [{}]", join(&mut creases.iter().map(|_| "3".to_string())));
        }
        let material = if chrome { "chrome" } else { "matte" };
        writeln!(
            f,
            "    def Mesh \"blob_{i}_{j}\" (\n        prepend apiSchemas = [\"MaterialBindingAPI\"]\n    )\n    {{\n{body}        rel material:binding = </World/Looks/{material}>\n        matrix4d xformOp:transform = {}\n        uniform token[] xformOpOrder = [\"xformOp:transform\"]\n    }}",
            matrix(xf)
        )?;
    }
    let half = GROUND_HALF;
    writeln!(
        f,
        "    def Mesh \"ground\" (\n        prepend apiSchemas = [\"MaterialBindingAPI\"]\n    )\n    {{\n        uniform token subdivisionScheme = \"none\"\n        int[] faceVertexCounts = [4]\n        int[] faceVertexIndices = [0, 1, 2, 3]\n        point3f[] points = [(-{half}, -{half}, 0), ({half}, -{half}, 0), ({half}, {half}, 0), (-{half}, {half}, 0)]\n        rel material:binding = </World/Looks/ground>\n    }}"
    )?;
    // A distant light shines down its own −Z: aimed along SUN_DIRECTION.
    let sun = Camera::look_at(Vec3::ZERO, SUN_DIRECTION, Vec3::Z);
    writeln!(
        f,
        "    def DistantLight \"sun\"\n    {{\n        float inputs:intensity = 2.5\n        matrix4d xformOp:transform = {}\n        uniform token[] xformOpOrder = [\"xformOp:transform\"]\n    }}",
        matrix(sun)
    )?;
    let cam = camera_transform(spec);
    writeln!(
        f,
        "    def Camera \"camera\"\n    {{\n        float focalLength = {}\n        float horizontalAperture = 36\n        float verticalAperture = 24\n        float2 clippingRange = (0.1, 100000)\n        matrix4d xformOp:transform = {}\n        uniform token[] xformOpOrder = [\"xformOp:transform\"]\n    }}\n}}",
        spec.focal_length,
        matrix(cam)
    )?;
    f.flush()
}
