//! Tests of the ray differentials against real neighbour rays (see the parent module).
//! The truth is traced in `f64`: real neighbour rays one pixel away in x and in y through the
//! same pinhole, along the same specular path, with analytic ray–plane and ray–sphere
//! intersection; derivatives are central differences `(ray(+1) − ray(−1)) / 2`, whose own
//! error is second order. Run with `--nocapture` for one error line per case.
use super::*;
use glam::{DVec3, Vec3};

fn f(v: DVec3) -> Vec3A {
    v.as_vec3().into()
}
/// `|est − truth| / |truth|`.
fn rel(est: Vec3A, truth: DVec3) -> f64 {
    (Vec3::from(est).as_dvec3() - truth).length() / truth.length()
}

/// A pinhole: the unnormalized direction through the pixel (x, y) pixels from the main one
/// is `fwd + x h right − y h up`; `h` is the pixel spacing in radians at the centre.
struct Pinhole(DVec3, [DVec3; 3], f64);
impl Pinhole {
    fn look_at(eye: DVec3, target: DVec3, h: f64) -> Self {
        let fwd = (target - eye).normalize();
        let right = fwd.cross(DVec3::Y).normalize();
        Pinhole(eye, [fwd, right, right.cross(fwd)], h)
    }
    fn dir(&self, x: f64, y: f64) -> DVec3 {
        let [fwd, right, up] = self.1;
        fwd + x * self.2 * right - y * self.2 * up
    }
    fn differential(&self) -> RayDifferential {
        let [_, right, up] = self.1.map(|v| f(v * self.2));
        RayDifferential::from_pinhole(f(self.dir(0.0, 0.0)), right, -up)
    }
}

#[derive(Clone, Copy)]
enum Shape {
    Plane(DVec3, DVec3), // a point and the unit normal
    Sphere(DVec3, f64),  // centre, radius; the normal points out
}
#[derive(Clone, Copy)]
enum Event {
    Reflect,
    Refract(f64),
    Stop,
}
type Path = Vec<(Shape, Event)>;

/// The main ray's hits: `(t, [p, d_in, n, d_out])`.
fn trace(cam: &Pinhole, x: f64, y: f64, path: &Path) -> Vec<(f64, [DVec3; 4])> {
    let (mut o, mut d) = (cam.0, cam.dir(x, y).normalize());
    let mut hits = Vec::new();
    for &(shape, event) in path {
        let (t, n) = match shape {
            Shape::Plane(p0, n) => ((p0 - o).dot(n) / d.dot(n), n),
            Shape::Sphere(c, r) => {
                let (b, cc) = ((o - c).dot(d), (o - c).length_squared() - r * r);
                let (t0, t1) = (-b - (b * b - cc).sqrt(), -b + (b * b - cc).sqrt());
                let t = if t0 > 1e-9 { t0 } else { t1 };
                (t, (o + t * d - c) / r)
            }
        };
        assert!(t > 1e-9, "test ray missed");
        let d_out = match event {
            Event::Reflect => d - 2.0 * d.dot(n) * n,
            // Snell in tangential form, independent of the module's formula.
            Event::Refract(eta) => {
                let (n, e) = if d.dot(n) > 0.0 { (-n, eta) } else { (n, 1.0 / eta) };
                let tan = e * (d - d.dot(n) * n);
                tan - (1.0 - tan.length_squared()).sqrt() * n
            }
            Event::Stop => d,
        };
        hits.push((t, [o + t * d, d, n, d_out]));
        (o, d) = (o + t * d, d_out);
    }
    hits
}

/// The sphere `c + r (sin u cos v, sin u sin v, cos u)` at `p`: dpdu, dpdv (their cross
/// product points out), dpduu, dpduv, dpdvv.
fn sphere_derivs(c: DVec3, r: f64, p: DVec3) -> [Vec3A; 5] {
    let q = (p - c) / r;
    let (u, v) = (q.z.clamp(-1.0, 1.0).acos(), q.y.atan2(q.x));
    let ((su, cu), (sv, cv)) = (u.sin_cos(), v.sin_cos());
    #[rustfmt::skip]
    let d = [[cu * cv, cu * sv, -su], [-su * sv, su * cv, 0.0], [-su * cv, -su * sv, -cu],
        [-cu * sv, cu * cv, 0.0], [-su * cv, -su * sv, 0.0]];
    d.map(|x| f(DVec3::from(x) * r))
}

/// The module along the main path, in `f32`: per hit, the differential transferred there
/// and the outgoing one.
fn propagate(cam: &Pinhole, path: &Path) -> Vec<(RayDifferential, RayDifferential)> {
    let mut rd = cam.differential();
    let mut out = Vec::new();
    for ((t, [p, d, n, _]), &(shape, event)) in trace(cam, 0.0, 0.0, path).iter().zip(path) {
        let (at, c0) = rd.transfer_checked(f(*d), *t as f32, f(*n));
        let (n, dndx, dndy) = match shape {
            Shape::Plane(..) => (f(*n), Vec3A::ZERO, Vec3A::ZERO),
            Shape::Sphere(c, r) => {
                let [pu, pv, puu, puv, pvv] = sphere_derivs(c, r, *p);
                let (dndu, dndv) = dndu_dndv(pu, pv, puu, puv, pvv);
                let uv = UvDifferentials::from_footprint(at.dpdx, at.dpdy, pu, pv);
                let (dndx, dndy) = uv.chain(dndu, dndv);
                (pu.cross(pv).normalize(), dndx, dndy)
            }
        };
        let c1;
        (rd, c1) = match event {
            Event::Reflect => at.reflect_checked(f(*d), n, dndx, dndy),
            Event::Refract(eta) => at.refract_checked(f(*d), n, dndx, dndy, eta as f32).expect("TIR"),
            Event::Stop => (at, false),
        };
        assert!(!c0 && !c1, "nothing here is degenerate");
        out.push((at, rd));
    }
    out
}

/// The truth per hit, `[dP/dx, dP/dy, dD_out/dx, dD_out/dy]`: central differences of the
/// neighbour rays at ±1 pixel (`back = -1`), or the one-sided difference to the neighbour
/// at +1 pixel (`back = 0`), which is what a pbrt-style neighbour ray represents.
fn truth(cam: &Pinhole, path: &Path, back: f64) -> Vec<[DVec3; 4]> {
    let [xp, xm, yp, ym] = [(1.0, 0.0), (back, 0.0), (0.0, 1.0), (0.0, back)].map(|(x, y)| trace(cam, x, y, path));
    let d = |a: &[(f64, [DVec3; 4])], b: &[(f64, [DVec3; 4])], i: usize, k: usize| (a[i].1[k] - b[i].1[k]) / (1.0 - back);
    let per_hit = |i| [d(&xp, &xm, i, 0), d(&yp, &ym, i, 0), d(&xp, &xm, i, 3), d(&yp, &ym, i, 3)];
    (0..path.len()).map(per_hit).collect()
}

/// The specular scenes: name, camera, path. Each has hits away from silhouettes and poles.
#[rustfmt::skip]
fn scenes(h: f64) -> Vec<(&'static str, Pinhole, Path)> {
    let v = DVec3::new;
    let (unit, wall_x8) = (Shape::Sphere(DVec3::ZERO, 1.0), Shape::Plane(v(8.0, 0.0, 0.0), -DVec3::X));
    vec![
        ("flat mirror", Pinhole::look_at(v(0.0, 2.0, 4.0), v(0.3, 0.0, 0.0), h),
         vec![(Shape::Plane(DVec3::ZERO, v(0.1, 1.0, 0.05).normalize()), Event::Reflect),
              (Shape::Plane(v(0.0, 0.0, -10.0), DVec3::Z), Event::Stop)]),
        ("convex mirror", Pinhole::look_at(v(4.0, 0.5, 0.3), v(0.0, 0.3, 0.2), h),
         vec![(unit, Event::Reflect), (wall_x8, Event::Stop)]),
        // Inside a sphere of radius 2, the eye 1.6 from the mirror: 1/s + 1/s' = 2/R puts
        // the crossover at s' = 8/3 along the reflected ray, before the far wall (≈ 4).
        ("concave mirror", Pinhole::look_at(v(-0.4, 0.06, 0.04), v(-2.0, 0.08, 0.05), h),
         vec![(Shape::Sphere(DVec3::ZERO, 2.0), Event::Reflect),
              (Shape::Sphere(DVec3::ZERO, 2.0), Event::Stop)]),
        ("glass sphere", Pinhole::look_at(v(5.0, 0.3, 0.2), v(0.0, 0.25, 0.15), h),
         vec![(unit, Event::Refract(1.5)), (unit, Event::Refract(1.5)),
              (Shape::Plane(v(-6.0, 0.0, 0.0), DVec3::X), Event::Stop)]),
    ]
}

/// Every scene, every hit, errors relative to each vector's length. Against central
/// differences at 1e-4 rad per pixel (the derivative itself) the measured errors are
/// ≤ 1.4e-6 (f32 rounding) and we assert 1e-4, tight enough to catch a dropped curvature
/// term. Against the one-sided neighbour ray one pixel away at 1e-3 rad per pixel (a
/// 1000-pixel, 57° image) the first-order error shows and we assert the required 2%.
#[test]
fn specular_paths_match_real_neighbour_rays() {
    for (h, back, tol) in [(1e-4, -1.0, 1e-4), (1e-3, 0.0, 0.02)] {
        for (name, cam, path) in scenes(h) {
            let (est, tru) = (propagate(&cam, &path), truth(&cam, &path, back));
            let mut worst = 0.0f64;
            for ((at, out), t) in est.iter().zip(&tru) {
                let e = [rel(at.dpdx, t[0]), rel(at.dpdy, t[1]), rel(out.dddx, t[2]), rel(out.dddy, t[3])];
                worst = e.into_iter().fold(worst, f64::max);
            }
            eprintln!(
                "{name:>14} h={h:.0e} {}: {} hits, worst relative error {worst:.2e}",
                if back < 0.0 { "central" } else { "one-sided" },
                path.len()
            );
            assert!(worst < tol, "{name} h={h}: {worst:.3e} ≥ {tol:.0e}");
        }
    }
}

#[test]
fn flat_mirror_keeps_the_spread_convex_mirror_widens_it() {
    let s = scenes(1e-4);
    let spread = |i: usize| propagate(&s[i].1, &s[i].2)[0].1.directional_spread_rad();
    let camera = s[0].1.differential().directional_spread_rad();
    assert!((spread(0) / camera - 1.0).abs() < 1e-5, "flat: the unfolded straight beam");
    assert!(spread(1) > 3.0 * s[1].1.differential().directional_spread_rad());
}

#[test]
fn concave_mirror_narrows_then_widens_past_the_crossover() {
    let (_, cam, path) = &scenes(1e-4)[2];
    let (est, tru) = (propagate(cam, path)[0].1, truth(cam, path, -1.0)[0]);
    let q = |t: f64| (tru[0] + t * tru[2], tru[1] + t * tru[3]);
    let w0 = est.beam_width_at(0.0) as f64;
    let ts = [0.0, 1.0, 2.0, 2.5, 8.0 / 3.0, 2.8, 3.5, 3.9];
    let w = ts.map(|t| {
        let (qx, qy) = q(t);
        let (w, truth) = (est.beam_width_at(t as f32) as f64, qx.length().max(qy.length()));
        // The width nearly vanishes at the crossover: errors relative to the width at t = 0.
        eprintln!("concave t={t:.3}: width {w:.4e} truth {truth:.4e} err/w0 {:.1e}", (w - truth).abs() / w0);
        assert!((w - truth).abs() < 1e-4 * w0, "t {t}: {w} vs {truth}");
        w
    });
    assert!(w[1] < 0.7 * w[0] && w[2] < w[1] && w[3] < w[2], "narrows: {w:?}");
    assert!(w[4] < 0.05 * w[0], "crosses over near 8/3: {w:?}");
    assert!(w[5] > w[4] && w[6] > w[5] && w[7] > 0.3 * w[0], "widens: {w:?}");
    // The beam's x edge reverses past the crossover, in the module as in the truth.
    let ex = |t: f32| est.dpdx + t * est.dddx;
    assert!(ex(1.0).dot(ex(3.9)) < 0.0 && q(1.0).0.dot(q(3.9).0) < 0.0);
}

#[test]
fn camera_differentials_are_exact() {
    // A wide (90°), skewed, non-orthonormal pinhole: d(x, y) = o + x sx + y sy.
    let (o, sx, sy) = (DVec3::new(0.2, -0.1, -1.0), DVec3::new(0.03, 0.004, 0.01), DVec3::new(-0.002, -0.025, 0.005));
    let unit = |x: f64, y: f64| (o + x * sx + y * sy).normalize();
    let mut worst = 0.0f64;
    for (x, y) in [(0.0, 0.0), (32.0, 32.0), (-32.0, 32.0), (32.0, -40.0), (-7.0, 3.0)] {
        let rd = RayDifferential::from_pinhole(f(o + x * sx + y * sy), f(sx), f(sy));
        let e = 1e-3; // pixels: central differences of the normalized direction
        let tx = (unit(x + e, y) - unit(x - e, y)) / (2.0 * e);
        let ty = (unit(x, y + e) - unit(x, y - e)) / (2.0 * e);
        worst = worst.max(rel(rd.dddx, tx)).max(rel(rd.dddy, ty));
        assert!(rd.dpdx == Vec3A::ZERO && rd.dpdy == Vec3A::ZERO);
    }
    eprintln!("pinhole: worst relative error {worst:.2e}");
    assert!(worst < 1e-5);
    // Orthographic: the origin moves by the pixel spacing, the direction does not change.
    let rd = RayDifferential::from_orthographic(f(sx), f(sy));
    assert!(rel(rd.dpdx, sx) < 1e-7 && rel(rd.dpdy, sy) < 1e-7 && rd.dddx == Vec3A::ZERO);
    assert_eq!(rd.beam_width_at(0.0), rd.beam_width_at(1e3));
}

#[test]
fn pinhole_beam_width_grows_linearly_with_t() {
    let cam = Pinhole::look_at(DVec3::ZERO, DVec3::new(0.3, -0.2, -1.0), 2e-3);
    let rd = cam.differential();
    assert_eq!(rd.beam_width_at(0.0), 0.0);
    let (w1, a1) = (rd.beam_width_at(1.0), rd.beam_width_area_at(1.0));
    for t in [0.5f32, 2.0, 10.0, 1000.0] {
        assert!((rd.beam_width_at(t) / (t * w1) - 1.0).abs() < 1e-6);
        assert!((rd.beam_width_area_at(t) / (t * a1) - 1.0).abs() < 1e-5);
        // It is the distance between real neighbour rays at that distance.
        let q = |x: f64, y: f64| t as f64 * cam.dir(x, y).normalize();
        let (qx, qy) = ((q(1.0, 0.0) - q(-1.0, 0.0)) / 2.0, (q(0.0, 1.0) - q(0.0, -1.0)) / 2.0);
        assert!((rd.beam_width_at(t) as f64 / qx.length().max(qy.length()) - 1.0).abs() < 1e-5);
    }
}

#[test]
fn cosine_weighted_hemisphere_is_narrower_at_the_pole() {
    let (theta_p, theta_h, n) = (0.1f32, 1.5f32, 256);
    let spread = |theta: f32| spread_from_pdf_rad(theta.cos() / PI, n);
    let (ratio, expected) = (spread(theta_p) / spread(theta_h), (theta_h.cos() / theta_p.cos()).sqrt());
    eprintln!("hemisphere: spread ratio {ratio:.7}, expected {expected:.7}");
    assert!((ratio / expected - 1.0).abs() < 1e-5);
    assert!((spread(0.0) - (PI / 256.0).sqrt()).abs() < 1e-6);
    // Its differential: the footprint, and two orthogonal vectors ⟂ dir of that length.
    let at_hit = RayDifferential::new(Vec3A::X * 0.01, Vec3A::Y * 0.02, Vec3A::ONE, Vec3A::ZERO);
    let dir = Vec3A::new(0.3, 0.2, 0.9).normalize();
    let ((rd, clamped), s) = (at_hit.hemisphere_checked(dir, 0.9 / PI, n), spread_from_pdf_rad(0.9 / PI, n));
    assert!(rd.dpdx == at_hit.dpdx && rd.dpdy == at_hit.dpdy && !clamped);
    assert!((rd.dddx.length() - s).abs() < 1e-6 && (rd.dddy.length() - s).abs() < 1e-6);
    assert!([rd.dddx.dot(dir), rd.dddy.dot(dir), rd.dddx.dot(rd.dddy)].iter().all(|c| c.abs() < 1e-6));
    // At the horizon (p = 0): the widest spread, flagged.
    let (edge, clamped) = at_hit.hemisphere_checked(Vec3A::X, 0.0, n);
    assert!(clamped && edge.directional_spread_rad() == MAX_SPREAD_RAD);
    assert!((MAX_SPREAD_RAD - (4.0 * PI).sqrt()).abs() < 1e-6);
}

#[test]
fn glossy_area_light_path_and_scale() {
    // Glossy: N rays share a cone's solid angle 2π (1 − cos α).
    let a = 0.2f32;
    assert!((glossy_spread_rad(a, 64) / (2.0 * PI * (1.0 - a.cos()) / 64.0).sqrt() - 1.0).abs() < 1e-4);
    assert!(glossy_spread_rad(a, 256) < glossy_spread_rad(a, 64) && glossy_spread_rad(0.0, 4) == 0.0);
    // Flat mirror: the specular spread is the camera's, so the glossy one wins; curved: a
    // wider specular spread is kept (§4.4's max).
    let cam = Pinhole::look_at(DVec3::ZERO, -DVec3::Z, 1e-3).differential();
    let dir = Vec3A::new(0.0, 0.6, 0.8);
    let flat = cam.glossy(dir, a, 64);
    assert!((flat.directional_spread_rad() - glossy_spread_rad(a, 64)).abs() < 1e-7);
    let curved = RayDifferential::new(Vec3A::ZERO, Vec3A::ZERO, Vec3A::X * 0.5, Vec3A::Y * 0.1);
    assert!((curved.glossy(dir, a, 64).directional_spread_rad() - 0.5).abs() < 1e-6);
    // Area lights: Ω shared by N rays; a point light (Ω = 0) gives a narrow ray (§4.3).
    assert!((area_light_spread_rad(0.04, 16) - 0.05).abs() < 1e-7);
    let (point, clamped) = cam.area_light_shadow_checked(dir, 0.0, 16);
    assert!(point.directional_spread_rad() == 0.0 && !clamped);
    // Path differential: the hemisphere spread at depth 1; wider deeper; capped at 1.
    let p = 0.7 / PI;
    let (hemi, path) = (cam.hemisphere(dir, p, 256), cam.path(dir, p, 1, 256));
    assert!((hemi.directional_spread_rad() / path.directional_spread_rad() - 1.0).abs() < 1e-6);
    assert!((path_sample_spacing(1, 256) - 1.0 / 16.0).abs() < 1e-7);
    assert!((path_sample_spacing(2, 256) - 0.5).abs() < 1e-6 && path_sample_spacing(3, 1) == 1.0);
    // scale(1/√spp): 16 samples per pixel, a quarter of the width.
    let mut rd = RayDifferential::new(Vec3A::X, Vec3A::Y * 2.0, Vec3A::Z * 0.1, Vec3A::X * 0.3);
    let w = rd.beam_width_at(3.0);
    assert!(!rd.scale(0.25) && (rd.beam_width_at(3.0) - w / 4.0).abs() < 1e-6);
    assert!(rd.scale(f32::NAN) && (rd.beam_width_at(3.0) - w / 4.0).abs() < 1e-6);
}

#[test]
fn weingarten_and_uv_least_squares_are_exact() {
    // A skewed saddle p = (u + 0.3 v, v, 0.4 u² − 0.7 uv + 0.2 v²) (F ≠ 0); truth: central
    // differences of normalize(dpdu × dpdv) in f64. Scale free: scaled surfaces agree.
    let pu = |u: f64, v: f64| DVec3::new(1.0, 0.0, 0.8 * u - 0.7 * v);
    let pv = |u: f64, v: f64| DVec3::new(0.3, 1.0, -0.7 * u + 0.4 * v);
    let nrm = |u: f64, v: f64| pu(u, v).cross(pv(u, v)).normalize();
    let second = [0.8, -0.7, 0.4].map(|z| DVec3::new(0.0, 0.0, z));
    for ((u, v), s) in [(0.0, 0.0), (0.5, -0.3), (-1.2, 0.8)].into_iter().zip([1.0, 1e-12, 1e12]) {
        let e = 1e-5;
        let tu = (nrm(u + e, v) - nrm(u - e, v)) / (2.0 * e);
        let tv = (nrm(u, v + e) - nrm(u, v - e)) / (2.0 * e);
        let [a, b, c, d, g] = [pu(u, v), pv(u, v), second[0], second[1], second[2]].map(|x| f(x * s));
        let (dndu, dndv) = dndu_dndv(a, b, c, d, g);
        assert!(rel(dndu, tu).max(rel(dndv, tv)) < 1e-5, "({u}, {v}) scale {s}");
    }
    // A sphere of radius 3 with the outward normal: dN/du = dpdu / 3.
    let [pu, pv, puu, puv, pvv] = sphere_derivs(DVec3::ZERO, 3.0, DVec3::new(1.0, 2.0, 2.0));
    let (dndu, dndv) = dndu_dndv(pu, pv, puu, puv, pvv);
    assert!((dndu - pu / 3.0).length() < 1e-6 && (dndv - pv / 3.0).length() < 1e-6);
    // Least squares recovers the coefficients and discards the normal component.
    let (dpdu, dpdv) = (Vec3A::new(2.0, 0.1, 0.0), Vec3A::new(0.5, 1.5, 0.2));
    let n = dpdu.cross(dpdv).normalize();
    for s in [1.0f32, 1e-15, 1e6] {
        let dpdx = (0.3 * dpdu - 0.2 * dpdv + 0.7 * n) * s;
        let dpdy = (-0.05 * dpdu + 0.4 * dpdv - 0.1 * n) * s;
        let uv = UvDifferentials::from_footprint(dpdx, dpdy, dpdu * s, dpdv * s);
        let got = [uv.dudx, uv.dvdx, uv.dudy, uv.dvdy];
        assert!(got.iter().zip([0.3, -0.2, -0.05, 0.4]).all(|(g, w)| (g - w).abs() < 1e-5), "{got:?}");
        assert!(!uv.clamped);
    }
    let degenerate = UvDifferentials::from_footprint(Vec3A::X, Vec3A::Y, dpdu, 2.0 * dpdu);
    assert!(degenerate.clamped && degenerate.dudx == 0.0);
}

#[test]
fn direction_helpers_obey_the_laws() {
    let (d, n) = (Vec3A::new(0.3, -0.8, 0.2).normalize(), Vec3A::Y);
    assert!((reflect_direction(d, n) - Vec3A::new(d.x, -d.y, d.z)).length() < 1e-6);
    let t = refract_direction(d, n, 1.5).expect("entering never reflects totally");
    // Snell: sin θt = sin θi / 1.5, in the plane of d and n; and the reverse path.
    assert!((t.cross(n).length() - d.cross(n).length() / 1.5).abs() < 1e-6);
    assert!(t.dot(d.cross(n)).abs() < 1e-6 && t.dot(n) < 0.0);
    assert!((refract_direction(-t, n, 1.5).expect("reverse") + d).length() < 1e-5);
    // Leaving glass 60° from the normal: 1.5 sin 60° > 1, total internal reflection.
    let steep = Vec3A::new(0.866_025_4, 0.5, 0.0);
    assert!(refract_direction(steep, n, 1.5).is_none());
    assert!(RayDifferential::ZERO.refract(steep, n, Vec3A::ZERO, Vec3A::ZERO, 1.5).is_none());
}

#[test]
fn grazing_and_degenerate_inputs_are_finite_and_flagged() {
    let rd = RayDifferential::new(Vec3A::X * 1e-3, Vec3A::Y * 1e-3, Vec3A::X * 1e-3, Vec3A::Z * 1e-3);
    let d = Vec3A::X;
    // Exactly and nearly grazing: finite, flagged, at most 1 / GRAZING_COS_MIN times wider.
    for n in [Vec3A::Y, Vec3A::new(1e-8, 1.0, 0.0), Vec3A::new(-1e-6, 1.0, 0.0)] {
        let (h, clamped) = rd.transfer_checked(d, 2.0, n);
        assert!(h.is_finite() && clamped);
        assert!(h.beam_width_at(0.0) <= 1.01 * rd.beam_width_at(2.0) / GRAZING_COS_MIN);
    }
    // Oblique but not grazing: in the tangent plane, unflagged.
    let n = Vec3A::new(-0.5, 0.8, 0.1).normalize();
    let (h, clamped) = rd.transfer_checked(d, 2.0, n);
    assert!(!clamped && h.dpdx.dot(n).abs() < 1e-9 && h.dpdy.dot(n).abs() < 1e-9);
    // A zero-area footprint (parallel axes): the area width is 0, the edge width is not.
    let flat = RayDifferential::from_orthographic(Vec3A::X * 0.01, Vec3A::X * 0.02);
    let (h, clamped) = flat.transfer_checked(-Vec3A::Z, 5.0, Vec3A::new(0.0, 0.3, 1.0));
    assert!(h.beam_width_area_at(0.0) == 0.0 && h.beam_width_at(0.0) > 0.019 && !clamped);
    // Degenerate normal, direction, camera direction.
    assert!(rd.transfer_checked(d, 1.0, Vec3A::ZERO).1);
    assert!(rd.transfer_checked(Vec3A::NAN, 1.0, n).1);
    assert!(RayDifferential::from_pinhole(Vec3A::ZERO, Vec3A::X, Vec3A::Y) == RayDifferential::ZERO);
    // Just below the critical angle: clamped, not infinite.
    let crit = (1.0f32 / 1.5).asin() - 1e-7;
    let inside = Vec3A::new(crit.sin(), crit.cos(), 0.0);
    let (near, clamped) = rd.refract_checked(inside, Vec3A::Y, Vec3A::ZERO, Vec3A::ZERO, 1.5).expect("below critical");
    assert!(near.is_finite() && clamped);
    // Infinite and huge keep their direction at the cap; NaN becomes zero.
    let inf = Vec3A::new(f32::INFINITY, 0.0, 0.0);
    let big = RayDifferential::new(inf, Vec3A::splat(1e30), Vec3A::NAN, Vec3A::ZERO);
    assert!(big.dpdx == Vec3A::X * MAX_DIFFERENTIAL && big.dddx == Vec3A::ZERO);
    assert!((big.dpdy.length() / MAX_DIFFERENTIAL - 1.0).abs() < 1e-6);
}

/// Adversarial fuzz: every public function, fed zeros, tiny, huge, infinite and NaN
/// components and counts, returns finite values.
#[test]
fn no_nan_escapes_any_public_function() {
    #[rustfmt::skip]
    let palette = [0.0, -0.0, 1.0, -1.0, 0.5, 1e-3, 1e-30, -1e-38, 1e30, -3e38, f32::MAX,
        f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3.7, -2.2];
    let counts = [0u32, 1, 7, 256, u32::MAX];
    let mut state = 0x2545_f491_4f6c_dd1du64; // xorshift: deterministic
    let mut x = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        palette[(state % palette.len() as u64) as usize]
    };
    let mut flagged = 0;
    for i in 0..20_000 {
        let [v0, v1, v2, v3, v4, v5, v6, v7, v8] = [(); 9].map(|_| Vec3A::new(x(), x(), x()));
        let (a, b, c, t, k) = (x(), x(), x(), x(), counts[i % counts.len()]);
        let raw = RayDifferential { dpdx: v0, dpdy: v1, dddx: v2, dddy: v3 };
        let mut scaled = raw;
        let scale_clamped = scaled.scale(t);
        let outs = [
            (RayDifferential::new(v0, v1, v2, v3), false),
            (RayDifferential::from_pinhole(v4, v5, v6), false),
            (RayDifferential::from_orthographic(v4, v5), false),
            (RayDifferential::from_spread(v0, v1, v4, a), false),
            (raw.transfer(v4, t, v5), false),
            raw.transfer_checked(v4, t, v5),
            raw.reflect_checked(v4, v5, v6, v7),
            raw.refract_checked(v4, v5, v6, v7, a).unwrap_or_default(),
            raw.glossy_checked(v4, a, k),
            raw.area_light_shadow_checked(v4, b, k),
            raw.hemisphere_checked(v4, c, k),
            raw.path_checked(v4, c, k, k.wrapping_mul(3)),
            (scaled, scale_clamped),
        ];
        assert!(outs.iter().all(|o| o.0.is_finite()), "{outs:?}");
        flagged += outs.iter().filter(|o| o.1).count();
        let (w, wa, sd) = (raw.beam_width_at(t), raw.beam_width_area_at(t), raw.directional_spread_rad());
        let (sp, sg, sa) = (spread_from_pdf_rad(c, k), glossy_spread_rad(a, k), area_light_spread_rad(b, k));
        let scalars = [w, wa, sd, sp, sg, sa, path_sample_spacing(k, k)];
        assert!(scalars.iter().all(|s| s.is_finite() && *s >= 0.0), "{scalars:?}");
        let uv = UvDifferentials::from_footprint(v0, v1, v4, v5);
        let ((n1, n2), (c1, c2)) = (dndu_dndv(v4, v5, v6, v7, v8), uv.chain(v6, v7));
        let r = [reflect_direction(v4, v5), refract_direction(v4, v5, a).unwrap_or_default()];
        assert!([uv.dudx, uv.dvdx, uv.dudy, uv.dvdy].iter().all(|x| x.is_finite()));
        assert!([n1, n2, c1, c2, r[0], r[1]].iter().all(|v| v.is_finite()));
    }
    assert!(flagged > 0);
}

#[test]
fn a_hemisphere_fan_gives_each_ray_the_differential_and_clamp_flag_of_hemisphere_checked() {
    // Footprints ordinary, huge, infinite and NaN; directions unit, unnormalised and zero;
    // densities ordinary, zero and NaN: the fan's ray is hemisphere_checked's, bit for bit.
    let big = MAX_DIFFERENTIAL * 4.0;
    let footprints = [
        RayDifferential::new(Vec3A::new(0.01, 0.0, 0.002), Vec3A::new(0.0, 0.02, 0.0), Vec3A::new(1e-3, 0.0, 0.0), Vec3A::ZERO),
        RayDifferential { dpdx: Vec3A::new(big, big, 0.0), dpdy: Vec3A::new(f32::INFINITY, 0.0, 1.0), dddx: Vec3A::X, dddy: Vec3A::Y },
        RayDifferential { dpdx: Vec3A::new(f32::NAN, 0.0, 0.0), dpdy: Vec3A::new(0.0, 1e-30, 0.0), dddx: Vec3A::ZERO, dddy: Vec3A::ZERO },
    ];
    let dirs = [Vec3A::Z, Vec3A::new(0.3, -0.4, 0.866), Vec3A::new(3.0, 4.0, 0.0), Vec3A::ZERO];
    let mut clamped = 0;
    for fp in &footprints {
        let fan = fp.hemisphere_fan();
        for d in dirs {
            for pdf in [0.3, 1.0 / std::f32::consts::PI, 0.0, f32::NAN] {
                for n in [1, 64] {
                    let (want, wc) = fp.hemisphere_checked(d, pdf, n);
                    let (got, gc) = fan.ray(d, pdf, n);
                    let bits = |r: &RayDifferential| [r.dpdx, r.dpdy, r.dddx, r.dddy].map(|v| v.to_array().map(f32::to_bits));
                    assert_eq!(bits(&got), bits(&want), "{fp:?} {d} {pdf} {n}");
                    assert_eq!(gc, wc);
                    clamped += usize::from(gc);
                }
            }
        }
    }
    assert!(clamped > 0 && clamped < footprints.len() * dirs.len() * 8, "{clamped} clamped");
}
