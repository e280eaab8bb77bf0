//! A fuzz target over random topologies fed to OpenSubdiv through [`OsdSurface::new`], written
//! as a deterministic randomized test so it runs on stable Rust in every `cargo test` (the
//! cargo-fuzz skeleton in `bridge/fuzz/` needs nightly). Thousands of meshes: well-formed ones of
//! every scheme and rule, creases, corners, holes, non-manifold fans, degenerate faces — and
//! garbage: indices out of range or negative, counts below 3 or not adding up, crease chains
//! that do not fit, non-finite points and sharpnesses.
//!
//! The process must never abort and nothing may panic: every mesh either builds (and then
//! evaluates to finite or non-finite values without crashing, refines uniformly, and finds
//! patches) or is refused with an error naming it. `MIPRAY_FUZZ_CASES` changes the count
//! (default 5000), `MIPRAY_FUZZ_SEED` the seed.

#![allow(clippy::unwrap_used)]

use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::topology::{BoundaryInterpolation, FaceVaryingInterpolation, MeshTopology, Scheme, TriangleSubdivision};
use mipray_bridge::OsdSurface;

/// SplitMix64: the same cases everywhere.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            0
        } else {
            self.next() % n
        }
    }
    fn chance(&mut self, p: f64) -> bool {
        ((self.next() >> 11) as f64 / (1u64 << 53) as f64) < p
    }
    fn f32(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[self.below(xs.len() as u64) as usize]
    }
}

/// A random mesh; `garbage` lets it break the rules.
fn random_mesh(rng: &mut Rng, garbage: bool) -> (MeshTopology, Vec<[f32; 3]>) {
    let scheme = rng.pick(&[Scheme::CatmullClark, Scheme::Loop, Scheme::Bilinear, Scheme::None]);
    let n_points = 3 + rng.below(30) as usize;
    let mut points: Vec<[f32; 3]> = (0..n_points).map(|_| [rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0]).collect();
    if rng.chance(0.2) {
        // Coincident points.
        let (a, b) = (rng.below(n_points as u64) as usize, rng.below(n_points as u64) as usize);
        points[a] = points[b];
    }
    let n_faces = 1 + rng.below(24) as usize;
    let mut counts = Vec::new();
    let mut indices = Vec::new();
    for _ in 0..n_faces {
        let n = if scheme == Scheme::Loop && !rng.chance(0.05) { 3 } else { rng.pick(&[3, 4, 4, 4, 5, 6, 8]) };
        let n = n.min(n_points);
        counts.push(n as i32);
        // Distinct vertices (a partial shuffle), now and then one repeated.
        let mut pool: Vec<i32> = (0..n_points as i32).collect();
        for k in 0..n {
            let j = k + rng.below((n_points - k) as u64) as usize;
            pool.swap(k, j);
        }
        if rng.chance(0.15) {
            // A vertex visited twice: in a row, wrapping round, or apart.
            let (a, b) = (rng.below(n as u64) as usize, rng.below(n as u64) as usize);
            pool[a] = pool[b];
        }
        indices.extend_from_slice(&pool[..n]);
    }
    let mut t = MeshTopology {
        scheme,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        boundary: rng.pick(&[BoundaryInterpolation::None, BoundaryInterpolation::EdgeOnly, BoundaryInterpolation::EdgeAndCorner]),
        face_varying: rng.pick(&[
            FaceVaryingInterpolation::None,
            FaceVaryingInterpolation::CornersOnly,
            FaceVaryingInterpolation::CornersPlus1,
            FaceVaryingInterpolation::CornersPlus2,
            FaceVaryingInterpolation::Boundaries,
            FaceVaryingInterpolation::All,
        ]),
        triangle_subdivision: rng.pick(&[TriangleSubdivision::CatmullClark, TriangleSubdivision::Smooth]),
        left_handed: rng.chance(0.5),
        ..Default::default()
    };
    if rng.chance(0.5) {
        let chains = 1 + rng.below(4) as usize;
        for _ in 0..chains {
            let len = 2 + rng.below(4) as usize;
            t.crease_lengths.push(len as i32);
            for _ in 0..len {
                t.crease_indices.push(rng.below(n_points as u64) as i32);
            }
            t.crease_sharpnesses.push(rng.pick(&[0.0, 0.5, 1.0, 2.5, 10.0, -1.0, 1e6]));
        }
    }
    if rng.chance(0.3) {
        for _ in 0..1 + rng.below(3) {
            t.corner_indices.push(rng.below(n_points as u64) as i32);
            t.corner_sharpnesses.push(rng.pick(&[1.0, 3.0, 10.0]));
        }
    }
    if rng.chance(0.3) {
        t.hole_indices.push(rng.below(n_faces as u64) as i32);
    }
    if garbage {
        match rng.below(10) {
            0 => {
                let k = rng.below(t.face_vertex_indices.len() as u64) as usize;
                t.face_vertex_indices[k] = rng.pick(&[-1, n_points as i32, i32::MAX, i32::MIN]);
            }
            1 => {
                let k = rng.below(t.face_vertex_counts.len() as u64) as usize;
                t.face_vertex_counts[k] = rng.pick(&[0, 1, 2, -3, 1000, i32::MAX]);
            }
            2 => {
                t.face_vertex_indices.pop();
            }
            3 => {
                t.crease_indices.push(-7);
                t.crease_lengths.push(1);
                t.crease_sharpnesses.push(1.0);
            }
            4 => {
                t.crease_lengths.push(i32::MAX);
            }
            5 => t.corner_sharpnesses.push(f32::NAN),
            6 => t.hole_indices.push(rng.pick(&[-1, n_faces as i32, i32::MAX])),
            7 => {
                let k = rng.below(points.len() as u64) as usize;
                points[k][rng.below(3) as usize] = rng.pick(&[f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
            }
            8 => {
                t.crease_indices.extend([0, 1]);
                t.crease_lengths.push(2);
                t.crease_sharpnesses.push(rng.pick(&[f32::NAN, f32::INFINITY]));
            }
            _ => {
                t.face_vertex_counts.clear();
                t.face_vertex_indices.clear();
            }
        }
    }
    (t, points)
}

/// Uses a surface that was built the way the renderer would: every call must return.
fn exercise(s: &OsdSurface, rng: &mut Rng) {
    let n = s.patch_count();
    let mut grid = GridSamples::default();
    for _ in 0..4.min(n) {
        let p = rng.below(n as u64) as usize;
        let _ = s.patch_param(p);
        let _ = s.patch_bounds(p);
        let _ = s.evaluate(p, rng.f32(), rng.f32());
        s.evaluate_grid(p, UvRect::UNIT, 5, true, &mut grid);
        assert_eq!(grid.p.len(), 25);
    }
    for _ in 0..4 {
        let face = rng.below(s.ptex_face_count() as u64 + 2) as u32;
        let (u, v) = (rng.f32() * 1.2 - 0.1, rng.f32() * 1.2 - 0.1);
        let _ = s.limit_at(face, u, v);
    }
    if n < 400 {
        let _ = s.uniform_refinement(1);
    }
}

#[test]
fn random_topologies_never_crash_opensubdiv() {
    let cases: usize = std::env::var("MIPRAY_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(5000);
    let seed: u64 = std::env::var("MIPRAY_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0x5EED);
    let mut rng = Rng(seed);
    let (mut built, mut refused) = (0, 0);
    let mut kinds = std::collections::BTreeMap::new();
    for case in 0..cases {
        let garbage = rng.chance(0.4);
        let (topo, points) = random_mesh(&mut rng, garbage);
        let name = format!("/fuzz{case}");
        if std::env::var_os("MIPRAY_FUZZ_VERBOSE").is_some() {
            eprintln!("case {case}: {topo:?} points {points:?}");
        }
        match OsdSurface::new(&name, &topo, &points) {
            Ok(s) => {
                built += 1;
                exercise(&s, &mut rng);
            }
            Err(e) => {
                refused += 1;
                let msg = e.to_string();
                assert!(msg.contains(&name), "case {case}: the error does not name the mesh: {msg}");
                *kinds.entry(msg.split(':').next().unwrap_or_default().to_string()).or_insert(0) += 1;
            }
        }
    }
    println!("{cases} random topologies (seed {seed}): {built} built, {refused} refused {kinds:?}");
    assert!(built > cases / 4 && refused > cases / 10, "the generator must exercise both paths: {built} built, {refused} refused");
}

/// The case that aborted the process (OpenSubdiv's `assignSmoothMaskForVertex` assertion) before
/// such faces were refused: face 15 is pinched at vertex 18. Now an error naming the mesh.
#[test]
fn a_face_that_visits_a_vertex_twice_apart_is_refused_not_aborted() {
    let counts = vec![6, 5, 5, 8, 5, 4, 4, 6, 6, 3, 4, 8, 6, 4, 4, 6, 3, 6, 3, 3, 4, 4, 4];
    let indices = vec![
        20, 17, 10, 14, 1, 13, 10, 7, 7, 16, 12, 5, 11, 19, 2, 1, 1, 9, 17, 9, 3, 5, 21, 4, 7, 13, 10, 14, 4, 19, 2, 21, 15, 3, 17, 14, 14,
        2, 1, 7, 19, 15, 10, 7, 5, 5, 9, 4, 17, 20, 9, 6, 21, 15, 14, 5, 12, 11, 7, 1, 4, 18, 14, 3, 3, 7, 20, 6, 4, 1, 0, 17, 2, 4, 10, 3,
        11, 2, 14, 18, 4, 19, 18, 10, 21, 15, 16, 6, 4, 1, 3, 0, 4, 21, 3, 4, 16, 20, 15, 12, 19, 4, 1, 15, 1, 4, 9, 11, 20, 5, 8,
    ];
    let topo = MeshTopology {
        scheme: Scheme::CatmullClark,
        face_vertex_counts: counts,
        face_vertex_indices: indices,
        crease_indices: vec![8, 1, 6, 2, 15, 20, 17, 3, 3, 7, 15, 16, 13, 6],
        crease_lengths: vec![5, 4, 2, 3],
        crease_sharpnesses: vec![-1.0, 1e6, 1.0, 1e6],
        face_varying: FaceVaryingInterpolation::All,
        ..Default::default()
    };
    let points: Vec<[f32; 3]> = (0..22)
        .map(|i| {
            let a = i as f32 * 2.399;
            [a.cos(), a.sin(), (i as f32 * 0.37).fract() - 0.5]
        })
        .collect();
    let e = OsdSurface::new("/repeat", &topo, &points).unwrap_err().to_string();
    assert!(e.contains("/repeat") && e.contains("face 15 is pinched at vertex 18") && e.contains("not supported"), "{e}");
    // The smallest mesh that aborted: two faces sharing two edges at vertex 18, which the
    // second face visits again further on.
    let topo = MeshTopology {
        face_vertex_counts: vec![8, 6],
        face_vertex_indices: vec![12, 11, 7, 1, 4, 18, 14, 3, 14, 18, 4, 19, 18, 10],
        ..Default::default()
    };
    let e = OsdSurface::new("/repeat2", &topo, &points).unwrap_err().to_string();
    assert!(e.contains("face 1 is pinched at vertex 18"), "{e}");
    // OpenSubdiv's own shapes visit vertices twice in ways it takes (a collapsed edge, a fold
    // back along an edge): those still build.
    let topo = MeshTopology { face_vertex_counts: vec![4, 4], face_vertex_indices: vec![0, 1, 2, 2, 3, 4, 3, 5], ..Default::default() };
    assert!(OsdSurface::new("/kept", &topo, &points).is_ok());
}

/// Builds the mesh in the file `MIPRAY_FUZZ_REPRO` (lines: `counts …`, `indices …`,
/// `crease_indices …`, `crease_lengths …`, `crease_sharpnesses …`, `scheme N`), for
/// minimising a crash found above in a child process.
#[test]
#[ignore]
fn repro_from_file() {
    let Some(path) = std::env::var_os("MIPRAY_FUZZ_REPRO") else { return };
    let text = std::fs::read_to_string(path).unwrap();
    let mut t = MeshTopology::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or_default();
        let ints = || line.split_whitespace().skip(1).map(|x| x.parse::<i32>().unwrap()).collect::<Vec<_>>();
        match key {
            "counts" => t.face_vertex_counts = ints(),
            "indices" => t.face_vertex_indices = ints(),
            "crease_indices" => t.crease_indices = ints(),
            "crease_lengths" => t.crease_lengths = ints(),
            "crease_sharpnesses" => t.crease_sharpnesses = line.split_whitespace().skip(1).map(|x| x.parse::<f32>().unwrap()).collect(),
            "fvar_all" => t.face_varying = FaceVaryingInterpolation::All,
            _ => {}
        }
    }
    let n = t.face_vertex_indices.iter().copied().max().unwrap_or(0) as usize + 1;
    let points: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let a = i as f32 * 2.399;
            [a.cos(), a.sin(), (i as f32 * 0.37).fract() - 0.5]
        })
        .collect();
    let r = OsdSurface::new("/repro", &t, &points);
    println!("REPRO {:?}", r.map(|s| s.patch_count()));
}
