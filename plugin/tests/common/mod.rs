//! Meshes and ray helpers shared by the hard-case tests.

#![allow(dead_code, clippy::unwrap_used)]

use glam::Vec3A;
use mipray::differential::RayDifferential;
use mipray::ray::{Ray, RayKind};
use mipray::topology::{MeshTopology, Scheme};

/// A small deterministic generator (SplitMix64): the same numbers on every platform.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A uniformly distributed unit vector.
    pub fn unit(&mut self) -> Vec3A {
        let z = 2.0 * self.f32() - 1.0;
        let phi = std::f32::consts::TAU * self.f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3A::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// A closed "cube sphere": each face of a cube cut into `m × m` quads, every vertex pushed onto
/// the unit sphere. Counter-clockwise seen from outside; eight valence-3 extraordinary
/// vertices, so OpenSubdiv's adaptive patches come in several sizes.
pub fn cube_sphere(m: usize, scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut points: Vec<[f32; 3]> = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut idx = Vec::new();
    // Faces as (origin corner, u axis, v axis) on the cube [-1, 1]³, u × v pointing outward.
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([-1.0, -1.0, 1.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
        ([1.0, -1.0, -1.0], [-2.0, 0.0, 0.0], [0.0, 2.0, 0.0]),
        ([1.0, -1.0, 1.0], [0.0, 0.0, -2.0], [0.0, 2.0, 0.0]),
        ([-1.0, -1.0, -1.0], [0.0, 0.0, 2.0], [0.0, 2.0, 0.0]),
        ([-1.0, 1.0, 1.0], [2.0, 0.0, 0.0], [0.0, 0.0, -2.0]),
        ([-1.0, -1.0, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0]),
    ];
    let mut vertex = |p: [f32; 3]| -> i32 {
        // Cube lattice coordinates are exact multiples of 2/m: key on them before projecting.
        let key = p.map(|c| ((c + 1.0) * m as f32 / 2.0).round() as i64);
        *index.entry(key).or_insert_with(|| {
            let v = Vec3A::from(p).normalize();
            points.push(v.into());
            (points.len() - 1) as i32
        })
    };
    for (o, u, v) in faces {
        for j in 0..m {
            for i in 0..m {
                let at = |a: usize, b: usize| {
                    let (s, t) = (a as f32 / m as f32, b as f32 / m as f32);
                    [o[0] + s * u[0] + t * v[0], o[1] + s * u[1] + t * v[1], o[2] + s * u[2] + t * v[2]]
                };
                let quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                for q in quad {
                    idx.push(vertex(q));
                }
            }
        }
    }
    let counts = vec![4; idx.len() / 4];
    let topo = MeshTopology { scheme, face_vertex_counts: counts, face_vertex_indices: idx, ..Default::default() };
    (topo, points)
}

/// A ray with a beam that is `w0` wide at its origin and spreads by `spread_rad` per unit
/// distance (world units): the beam width the tracer reads to choose a rate.
pub fn beam_ray(o: Vec3A, d: Vec3A, w0: f32, spread_rad: f32, kind: RayKind) -> Ray {
    let (e1, e2) = d.any_orthonormal_pair();
    let diff = RayDifferential::from_spread(e1 * w0, e2 * w0, d, spread_rad);
    Ray { o, d, t_min: 0.0, t_max: f32::INFINITY, diff, kind, time: 0.0 }
}

/// A disk of `n` quads around one vertex of valence `n` (an extraordinary vertex unless n = 4):
/// centre 0, ring vertices at radius 1, corner vertices at radius 1.4 between them; faces
/// counter-clockwise seen from +z, slightly domed so normals vary.
pub fn quad_pole(n: usize) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = vec![[0.0, 0.0, 0.3]];
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        pts.push([a.cos(), a.sin(), 0.1]);
        let b = std::f32::consts::TAU * (i as f32 + 0.5) / n as f32;
        pts.push([1.4 * b.cos(), 1.4 * b.sin(), 0.0]);
    }
    let r = |i: usize| (1 + 2 * (i % n)) as i32;
    let q = |i: usize| (2 + 2 * (i % n)) as i32;
    let idx: Vec<i32> = (0..n).flat_map(|i| [0, r(i), q(i), r(i + 1)]).collect();
    (MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; n], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// A fan of `n` triangles around one vertex (Catmull-Clark splits each into three quads, so the
/// centre keeps valence `n`).
pub fn triangle_fan(n: usize) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = vec![[0.0, 0.0, 0.2]];
    for i in 0..n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        pts.push([a.cos(), a.sin(), 0.0]);
    }
    let idx: Vec<i32> = (0..n).flat_map(|i| [0, 1 + i as i32, 1 + ((i + 1) % n) as i32]).collect();
    (MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![3; n], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// An `n × n` grid of quads over [−half, half]² in z = 0, counter-clockwise seen from +z.
pub fn grid(n: usize, half: f32, scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let mut pts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pts.push([-half + 2.0 * half * i as f32 / n as f32, -half + 2.0 * half * j as f32 / n as f32, 0.0]);
        }
    }
    let v = |i: usize, j: usize| (j * (n + 1) + i) as i32;
    let idx: Vec<i32> = (0..n).flat_map(|j| (0..n).flat_map(move |i| [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)])).collect();
    (MeshTopology { scheme, face_vertex_counts: vec![4; n * n], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// A box from −h to h (half-sizes), six quads, counter-clockwise seen from outside.
pub fn boxed(h: [f32; 3], scheme: Scheme) -> (MeshTopology, Vec<[f32; 3]>) {
    let [x, y, z] = h;
    let pts = vec![[-x, -y, -z], [x, -y, -z], [x, y, -z], [-x, y, -z], [-x, -y, z], [x, -y, z], [x, y, z], [-x, y, z]];
    let idx = vec![0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6, 3, 0, 4, 7];
    (MeshTopology { scheme, face_vertex_counts: vec![4; 6], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// A delegate with a 35 mm camera at `eye` looking at `target` (Y up, 20-unit square aperture)
/// and a unit distant light shining down −Z that casts shadows or not.
pub fn delegate_with_camera(eye: glam::Vec3, target: glam::Vec3, shadows: bool) -> hd_mipray::RenderDelegate {
    use hd_mipray::camera::Camera;
    use hd_mipray::light::DistantLightData;
    let mut d = hd_mipray::RenderDelegate::new();
    d.set_camera(
        "/cam",
        Camera {
            render_from_camera: Camera::look_at(eye, target, glam::Vec3::Y),
            horizontal_aperture: 20.0,
            vertical_aperture: 20.0,
            focal_length: 35.0,
            clipping_range: (0.1, 1000.0),
            ..Default::default()
        },
    );
    d.set_distant_light(
        "/sun",
        DistantLightData {
            transform: glam::Mat4::IDENTITY,
            intensity: 1.0,
            exposure: 0.0,
            color: [1.0; 3],
            angle_deg: 0.5,
            normalize: false,
            shadow_enable: shadows,
        },
    );
    d
}

/// A cube of side 2 centred on the origin, outward winding, as a Catmull-Clark control mesh.
pub fn cube() -> (MeshTopology, Vec<[f32; 3]>) {
    let pts = vec![
        [-1.0, -1.0, -1.0],
        [1.0, -1.0, -1.0],
        [1.0, 1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
        [1.0, -1.0, 1.0],
        [1.0, 1.0, 1.0],
        [-1.0, 1.0, 1.0],
    ];
    let idx = vec![0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6, 3, 0, 4, 7];
    (MeshTopology { scheme: Scheme::CatmullClark, face_vertex_counts: vec![4; 6], face_vertex_indices: idx, ..Default::default() }, pts)
}

/// A mesh of `shape` (topology, points) in place, shaded lambertian in grey `grey` (linear): a
/// display colour without a material, as the USD front end sends it; named `name`.
pub fn grey_mesh(name: &str, shape: (MeshTopology, Vec<[f32; 3]>), grey: f32) -> hd_mipray::mesh::MeshData {
    let (topology, points) = shape;
    let material = Some(hd_mipray::material::SurfaceInputs::lambertian(name, [grey; 3]));
    hd_mipray::mesh::MeshData { topology, points, transform: glam::Mat4::IDENTITY, material, ..Default::default() }
}
