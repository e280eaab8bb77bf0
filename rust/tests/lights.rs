//! Lights and the direct-lighting estimator against truth: light-sampling densities against the
//! lights' solid angles, a lambertian plane under each light type against its closed-form
//! irradiance, multiple importance sampling against the light-only and BSDF-only estimators, and
//! dome importance sampling against cosine sampling.

mod lights_common;

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat3A, Mat4, Vec3A};
use lights_common::*;
use mipray::bsdf::{Lambertian, Scattering};
use mipray::light::{latlong_direction, EnvTexture, Light, LightShape};
use mipray::light_sampler::LightSampler;
use mipray::sampling::Sampler;
use mipray::scene::Scene;
use mipray::texture::TextureSampler;

/// Directions on a fine stratified grid over the sphere, each standing for 4π / count sr.
fn sphere_grid(n_theta: usize, n_phi: usize) -> impl Iterator<Item = Vec3A> {
    (0..n_theta).flat_map(move |i| {
        (0..n_phi).map(move |j| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n_theta as f32;
            let phi = 2.0 * PI * (j as f32 + 0.5) / n_phi as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3A::new(r * phi.cos(), r * phi.sin(), z)
        })
    })
}

/// ∫ pdf dω over the sphere and the solid angle where pdf > 0, by quadrature on the grid.
fn pdf_integrals(light: &Light, p: Vec3A, n: Vec3A) -> (f64, f64) {
    let (nt, np) = (1200, 2400);
    let dw = 4.0 * std::f64::consts::PI / (nt * np) as f64;
    let (mut integral, mut support) = (0.0f64, 0.0f64);
    for w in sphere_grid(nt, np) {
        let pdf = light.pdf(p, n, w);
        integral += f64::from(pdf) * dw;
        if pdf > 0.0 {
            support += dw;
        }
    }
    (integral, support)
}

#[test]
fn light_densities_integrate_to_one_over_the_light_s_solid_angle() {
    let p = Vec3A::ZERO;
    let n = Vec3A::Z;
    let close = |got: f64, want: f64, tol: f64, what: &str| assert!((got - want).abs() <= tol * want, "{what}: {got} vs {want}");

    // A sphere of radius 1 at distance 3: a cone of sin θ = 1/3.
    let sphere = area(LightShape::Sphere { center: Vec3A::new(1.0, 2.0, 2.0), radius: 1.0 }, 1.0);
    let cos_max = (1.0f64 - 1.0 / 9.0).sqrt();
    let (i, s) = pdf_integrals(&sphere, p, n);
    close(i, 1.0, 0.01, "sphere ∫pdf");
    close(s, 2.0 * std::f64::consts::PI * (1.0 - cos_max), 0.01, "sphere solid angle");

    // A 2a × 2b rect facing down at height h, centred above p: Ω = 4 asin(ab / √((a²+h²)(b²+h²))).
    let (a, b, h) = (1.0f32, 0.5f32, 1.5f32);
    let rect = area(LightShape::Rect { center: Vec3A::Z * h, u: Vec3A::X * a, v: Vec3A::Y * b, normal: Vec3A::NEG_Z }, 1.0);
    let (i, s) = pdf_integrals(&rect, p, n);
    let omega = 4.0 * (f64::from(a * b) / (f64::from(a * a + h * h) * f64::from(b * b + h * h)).sqrt()).asin();
    close(i, 1.0, 0.01, "rect ∫pdf");
    close(s, omega, 0.01, "rect solid angle");

    // A disk of radius r at height h on the axis: Ω = 2π (1 − h / √(h² + r²)).
    let (r, h) = (0.8f32, 1.2f32);
    let disk = area(LightShape::Disk { center: Vec3A::Z * h, u: Vec3A::X * r, v: Vec3A::Y * r, normal: Vec3A::NEG_Z }, 1.0);
    let (i, s) = pdf_integrals(&disk, p, n);
    close(i, 1.0, 0.01, "disk ∫pdf");
    close(s, 2.0 * std::f64::consts::PI * (1.0 - f64::from(h) / f64::from(h * h + r * r).sqrt()), 0.01, "disk solid angle");

    // A distant light of angular diameter 20°: a cone of half-angle 10°.
    let sun = Light::usd_distant("/sun", &Mat4::from_rotation_x(0.4), 1.0, 0.0, Vec3A::ONE, 20.0, true);
    let (i, s) = pdf_integrals(&sun, p, n);
    close(i, 1.0, 0.01, "cone ∫pdf");
    close(s, 2.0 * std::f64::consts::PI * (1.0 - 10f64.to_radians().cos()), 0.01, "cone solid angle");

    // A textured dome: its importance density over all directions.
    let env = spot_dome(Vec3A::new(0.3, 0.8, 0.5).normalize(), 4.0, 50.0, 0.05);
    let (i, s) = pdf_integrals(&env, p, n);
    close(i, 1.0, 0.01, "dome ∫pdf");
    close(s, 4.0 * std::f64::consts::PI, 1e-3, "dome support");

    // Every sample's density is what pdf() says, and a sample toward an area light meets it.
    let mut rng = Sampler::new(5, 6, 7);
    for light in [&sphere, &rect, &disk, &sun, &env] {
        for _ in 0..2000 {
            let Some(ls) = light.sample(p, n, rng.next_f32(), rng.next_f32()) else { continue };
            let pdf = light.pdf(p, n, ls.wi);
            assert!((pdf - ls.pdf).abs() <= 2e-3 * ls.pdf, "{}: sample pdf {} vs pdf() {pdf}", light.name, ls.pdf);
            if ls.distance.is_finite() {
                let hit = light.intersect(p, ls.wi, f32::INFINITY).expect("the sampled direction meets the light");
                assert!((hit.t - ls.distance).abs() <= 1e-3 * ls.distance && (hit.pdf - ls.pdf).abs() <= 2e-3 * ls.pdf);
            } else {
                assert!(light.environment(ls.wi).max_element() > 0.0 || light.name == "/dome");
            }
        }
    }
}

/// Radiance of a white lambertian plane at the origin (normal +z) under `lights`, by the full
/// estimator: mean and standard error over `calls` shading points' worth of samples.
fn plane_radiance(lights: Vec<Light>, n_samples: u32, calls: u32) -> (f32, f32, f64) {
    let mut scene = ground(100.0);
    scene.lights = lights;
    let stats = estimate_at(&scene, Vec3A::ZERO, n_samples, calls, Mode::Mis, |sp| -> Box<dyn Scattering> {
        Box::new(Lambertian { r: Vec3A::ONE, n: sp.ns, ng: sp.ng })
    });
    (stats.mean.x, stats.std_error, stats.shadow_rays_per_call)
}

fn assert_near(what: &str, (mean, se, _): (f32, f32, f64), truth: f32) {
    let tol = 4.0 * se + 2e-4 * truth;
    assert!((mean - truth).abs() <= tol, "{what}: {mean} ± {se} vs {truth}");
}

#[test]
fn a_lambertian_plane_under_each_light_has_the_closed_form_radiance() {
    let l = 3.0f32;
    // Distant, a point at infinity 40° off the normal: E cos θ, exactly, one shadow ray.
    let tilt = Mat4::from_rotation_x(40f32.to_radians());
    let point = Light::usd_distant("/p", &tilt, 2.0, 0.0, Vec3A::ONE, 0.0, false);
    let got = plane_radiance(vec![point], 4, 50);
    assert!((got.0 - 2.0 * 40f32.to_radians().cos() / PI).abs() < 1e-5 && got.1 < 1e-6, "{got:?}");
    assert!((got.2 - 1.0).abs() < 1e-9, "a delta light chosen 4 times traces one shadow ray: {}", got.2);
    // Distant of angle 8°, normalized, 40° off: a cap entirely above the horizon delivers
    // E cos θc; not normalized, L π sin²(4°) cos θc.
    let sun = Light::usd_distant("/s", &tilt, 2.0, 0.0, Vec3A::ONE, 8.0, true);
    assert_near("normalized distant cone", plane_radiance(vec![sun], 4, 3000), 2.0 * 40f32.to_radians().cos() / PI);
    let raw = Light::usd_distant("/s", &tilt, 2.0, 0.0, Vec3A::ONE, 8.0, false);
    let e = 2.0 * PI * 4f32.to_radians().sin().powi(2) * 40f32.to_radians().cos();
    assert_near("radiance distant cone", plane_radiance(vec![raw], 4, 3000), e / PI);
    // A sphere entirely above the horizon: E = π L sin²θmax cos θc.
    let c = Vec3A::new(1.0, -0.5, 2.0);
    let sphere = area(LightShape::Sphere { center: c, radius: 0.6 }, l);
    let e = PI * l * 0.36 / c.length_squared() * c.normalize().z;
    assert_near("sphere", plane_radiance(vec![sphere], 4, 3000), e / PI);
    // A rect centred above: E = 2L [A/√(1+A²) atan(B/√(1+A²)) + B/√(1+B²) atan(A/√(1+B²))].
    let (a, b, h) = (1.0f32, 0.5f32, 1.5f32);
    let rect = area(LightShape::Rect { center: Vec3A::Z * h, u: Vec3A::X * a, v: Vec3A::Y * b, normal: Vec3A::NEG_Z }, l);
    let (ca, cb) = (a / h, b / h);
    let e = 2.0
        * l
        * (ca / (1.0 + ca * ca).sqrt() * (cb / (1.0 + ca * ca).sqrt()).atan()
            + cb / (1.0 + cb * cb).sqrt() * (ca / (1.0 + cb * cb).sqrt()).atan());
    assert_near("rect", plane_radiance(vec![rect], 4, 3000), e / PI);
    // A disk on the axis: E = π L r² / (h² + r²).
    let (r, h) = (0.8f32, 1.2f32);
    let disk = area(LightShape::Disk { center: Vec3A::Z * h, u: Vec3A::X * r, v: Vec3A::Y * r, normal: Vec3A::NEG_Z }, l);
    assert_near("disk", plane_radiance(vec![disk], 4, 3000), l * r * r / (h * h + r * r));
    // A uniform dome: E = π L.
    let dome = area(LightShape::Dome(None), l);
    assert_near("uniform dome", plane_radiance(vec![dome], 4, 2000), l);
    // A textured dome (a bright cap 30° off the normal, radius 5°, on a dim sky): the cap
    // delivers (L_cap − L_sky) π sin² r cos θc on top of the sky's π L_sky.
    let spot = Vec3A::new(0.0, 30f32.to_radians().sin(), 30f32.to_radians().cos());
    let textured = spot_dome(spot, 5.0, 80.0, 0.1);
    let e = PI * 0.1 + (80.0 - 0.1) * PI * 5f32.to_radians().sin().powi(2) * 30f32.to_radians().cos();
    assert_near("textured dome", plane_radiance(vec![textured], 4, 4000), e / PI);
}

/// A glossy lobe (normalized Phong) plus an optional lambertian part: a BSDF whose light
/// sampling and BSDF sampling disagree, to test their combination.
struct Glossy {
    n: Vec3A,
    exponent: f32,
    kd: f32,
    ks: f32,
}

impl Glossy {
    fn lobe(&self, wo: Vec3A, wi: Vec3A) -> (f32, f32) {
        let r = 2.0 * self.n.dot(wo) * self.n - wo;
        let c = r.dot(wi).max(0.0);
        let lobe = c.powf(self.exponent);
        ((self.exponent + 2.0) / (2.0 * PI) * lobe, (self.exponent + 1.0) / (2.0 * PI) * lobe)
    }

    fn p_spec(&self) -> f32 {
        self.ks / (self.ks + self.kd)
    }
}

impl Scattering for Glossy {
    fn eval(&self, wo: Vec3A, wi: Vec3A) -> mipray::bsdf::BsdfEval {
        let cos_i = self.n.dot(wi);
        if cos_i <= 0.0 || self.n.dot(wo) <= 0.0 {
            return Default::default();
        }
        let (f, pdf_s) = self.lobe(wo, wi);
        let pdf = self.p_spec() * pdf_s + (1.0 - self.p_spec()) * cos_i / PI;
        mipray::bsdf::BsdfEval { diffuse: Vec3A::splat(self.kd * cos_i / PI), specular: Vec3A::splat(self.ks * f * cos_i), pdf }
    }

    fn sample(&self, wo: Vec3A, u: [f32; 3]) -> Option<mipray::bsdf::BsdfSample> {
        let wi = if u[2] < self.p_spec() {
            let r = 2.0 * self.n.dot(wo) * self.n - wo;
            let cos_a = u[0].powf(1.0 / (self.exponent + 1.0));
            let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
            let phi = 2.0 * PI * u[1];
            let (t, b) = mipray::sampling::frame(r);
            t * (sin_a * phi.cos()) + b * (sin_a * phi.sin()) + r * cos_a
        } else {
            let (local, _) = mipray::sampling::cosine_hemisphere(u[0], u[1]);
            let (t, b) = mipray::sampling::frame(self.n);
            t * local.x + b * local.y + self.n * local.z
        };
        let e = self.eval(wo, wi);
        if !(e.pdf > 0.0) || e.total().max_element() <= 0.0 {
            return None;
        }
        Some(mipray::bsdf::BsdfSample {
            wi,
            weight: e.total() / e.pdf,
            pdf: e.pdf,
            lobe: mipray::bsdf::Lobe::Glossy,
            delta: false,
            eta: 1.0,
        })
    }

    fn diffuse_reflectance(&self) -> Vec3A {
        Vec3A::splat(self.kd)
    }

    fn has_delta(&self) -> bool {
        false
    }
}

#[test]
fn multiple_importance_sampling_agrees_with_light_only_and_bsdf_only_and_is_robust() {
    // A glossy plane viewed at 45° reflecting a small bright rect light (0.01 sr): with a wide
    // lobe light sampling is the better strategy, with a narrow one BSDF sampling is, and the
    // other is 15 to 10 000 times noisier. MIS must have the mean of both and stay near the
    // better one whatever the lobe (the power heuristic, one sample of each: measured within
    // 8× of the better, and under a tenth of the worse).
    let mut scene = ground(100.0);
    let wo = Vec3A::new(0.0, -1.0, 1.0).normalize();
    let mirror_dir = Vec3A::new(0.0, 1.0, 1.0).normalize();
    let c = mirror_dir * 3.0;
    let (u, v) = (Vec3A::X * 0.15, mirror_dir.cross(Vec3A::X).normalize() * 0.15);
    scene.lights.push(area(LightShape::Rect { center: c, u, v, normal: -mirror_dir }, 40.0));
    for exponent in [30.0f32, 300.0, 3000.0] {
        let glossy = move |sp: &mipray::integrator::ShadingPoint| -> Box<dyn Scattering> {
            Box::new(Glossy { n: sp.ns, exponent, kd: 0.0, ks: 0.8 })
        };
        let calls = 8000;
        let mis = estimate_view(&scene, Vec3A::ZERO, wo, 1, calls, Mode::Mis, &glossy);
        let light = estimate_view(&scene, Vec3A::ZERO, wo, 1, calls, Mode::LightOnly, &glossy);
        let bsdf = estimate_view(&scene, Vec3A::ZERO, wo, 1, calls, Mode::BsdfOnly, &glossy);
        let path = estimate_view(&scene, Vec3A::ZERO, wo, 1, calls, Mode::PathTracer, &glossy);
        for (name, s) in [("light only", &light), ("bsdf only", &bsdf), ("path tracer's split", &path)] {
            let tol = 4.0 * (mis.std_error.powi(2) + s.std_error.powi(2)).sqrt();
            assert!(
                (mis.mean.x - s.mean.x).abs() <= tol,
                "exponent {exponent}: MIS {} ± {} vs {name} {} ± {}",
                mis.mean.x,
                mis.std_error,
                s.mean.x,
                s.std_error
            );
        }
        assert!(mis.mean.x > 1.0, "the light is reflected: {}", mis.mean.x);
        let (best, worst) = (light.variance.min(bsdf.variance), light.variance.max(bsdf.variance));
        println!("exponent {exponent}: variance MIS {} light {} BSDF {}", mis.variance, light.variance, bsdf.variance);
        assert!(mis.variance < 0.1 * worst && mis.variance < 8.0 * best, "exponent {exponent}: MIS {} vs {best}..{worst}", mis.variance);
    }

    // A diffuse + glossy surface under a dome with a bright sun spot: the diffuse part of the
    // estimate is exactly what a lambertian of that reflectance gets, and the estimators agree
    // on the total.
    let mut scene = ground(100.0);
    let spot = Vec3A::new(0.0, 0.5, 0.8).normalize();
    scene.lights.push(spot_dome(spot, 3.0, 300.0, 0.2));
    let mixed =
        |sp: &mipray::integrator::ShadingPoint| -> Box<dyn Scattering> { Box::new(Glossy { n: sp.ns, exponent: 50.0, kd: 0.5, ks: 0.4 }) };
    let lambert = |sp: &mipray::integrator::ShadingPoint| -> Box<dyn Scattering> {
        Box::new(Lambertian { r: Vec3A::splat(0.5), n: sp.ns, ng: sp.ng })
    };
    let calls = 8000;
    let mis = estimate_view(&scene, Vec3A::ZERO, wo, 2, calls, Mode::Mis, &mixed);
    let diffuse_only = estimate_view(&scene, Vec3A::ZERO, wo, 2, calls, Mode::Mis, &lambert);
    let tol = 4.0 * (mis.diffuse_std_error.powi(2) + diffuse_only.std_error.powi(2)).sqrt();
    assert!((mis.diffuse.x - diffuse_only.mean.x).abs() <= tol, "diffuse part {} vs lambertian {}", mis.diffuse.x, diffuse_only.mean.x);
    for mode in [Mode::LightOnly, Mode::BsdfOnly, Mode::PathTracer] {
        let s = estimate_view(&scene, Vec3A::ZERO, wo, 2, calls, mode, &mixed);
        let tol = 4.0 * (mis.std_error.powi(2) + s.std_error.powi(2)).sqrt();
        assert!((mis.mean.x - s.mean.x).abs() <= tol, "{mode:?}: {} ± {} vs MIS {} ± {}", s.mean.x, s.std_error, mis.mean.x, mis.std_error);
    }
}

#[test]
fn dome_importance_sampling_has_the_mean_of_cosine_sampling_and_far_less_variance() {
    // A dark sky with a small, very bright sun (radius 2°, 20 000× the sky) 35° off the normal.
    let spot = Vec3A::new(0.2, 35f32.to_radians().sin(), 35f32.to_radians().cos()).normalize();
    let (radius, sun, sky) = (2.0f32, 2000.0f32, 0.1f32);
    let truth = (PI * sky + (sun - sky) * PI * radius.to_radians().sin().powi(2) * spot.z) / PI;
    let mut with_table = ground(100.0);
    with_table.lights.push(spot_dome(spot, radius, sun, sky));
    let mut cosine = with_table.clone();
    if let LightShape::Dome(Some(env)) = &mut cosine.lights[0].shape {
        env.distribution = None;
    }
    let lambert =
        |sp: &mipray::integrator::ShadingPoint| -> Box<dyn Scattering> { Box::new(Lambertian { r: Vec3A::ONE, n: sp.ns, ng: sp.ng }) };
    let calls = 6000;
    let is = estimate_view(&with_table, Vec3A::ZERO, Vec3A::Z, 4, calls, Mode::LightOnly, &lambert);
    let cos = estimate_view(&cosine, Vec3A::ZERO, Vec3A::Z, 4, calls, Mode::LightOnly, &lambert);
    assert_near("importance-sampled dome", (is.mean.x, is.std_error, 0.0), truth);
    assert_near("cosine-sampled dome", (cos.mean.x, cos.std_error, 0.0), truth);
    assert!(is.variance < 0.02 * cos.variance, "importance {} vs cosine {} variance", is.variance, cos.variance);
}

#[test]
fn environment_is_what_escaping_rays_see() {
    let mut scene = Scene::default();
    assert_eq!(scene.environment(Vec3A::Z), Vec3A::ZERO);
    scene.lights.push(area(LightShape::Dome(None), 0.5));
    scene.lights.push(Light::usd_distant("/sun", &Mat4::IDENTITY, 1.0, 0.0, Vec3A::ONE, 2.0, false));
    scene.lights.push(Light::distant("/point", Vec3A::NEG_Z, Vec3A::ONE));
    // Looking up the sun's axis (+z: the light travels down −z): the dome plus the sun's disk.
    assert!((scene.environment(Vec3A::Z) - Vec3A::splat(1.5)).abs().max_element() < 1e-6);
    assert!((scene.environment(Vec3A::X) - Vec3A::splat(0.5)).abs().max_element() < 1e-6);
    // A camera ray sees the background (the dome and the sun's disk) and the area lights it
    // crosses before its hit.
    scene.lights.push(area(LightShape::Sphere { center: Vec3A::new(0.0, 0.0, 5.0), radius: 1.0 }, 2.0));
    let direct = mipray::integrator::direct_light::DirectLight::new(&scene, true, 4);
    let ray = |d: Vec3A| mipray::ray::Ray {
        o: Vec3A::ZERO,
        d,
        t_min: 0.0,
        t_max: f32::INFINITY,
        diff: mipray::differential::RayDifferential::from_spread(Vec3A::ZERO, Vec3A::ZERO, d, 1e-3),
        kind: mipray::ray::RayKind::Camera,
        time: 0.0,
    };
    assert!((direct.seen(&scene, &ray(Vec3A::Z), f32::INFINITY) - Vec3A::splat(3.5)).abs().max_element() < 1e-5);
    assert!((direct.seen(&scene, &ray(Vec3A::Z), 4.5) - Vec3A::splat(2.0)).abs().max_element() < 1e-5);
    assert_eq!(direct.seen(&scene, &ray(Vec3A::Z), 3.0), Vec3A::ZERO);
    assert!((scene.background(Vec3A::X, 1e-3) - Vec3A::splat(0.5)).abs().max_element() < 1e-6);
    // A sphere light is met by a ray, a rect only from its emitting side.
    let sphere = area(LightShape::Sphere { center: Vec3A::Z * 5.0, radius: 1.0 }, 2.0);
    let hit = sphere.intersect(Vec3A::ZERO, Vec3A::Z, f32::INFINITY).unwrap();
    assert!((hit.t - 4.0).abs() < 1e-5 && hit.radiance == Vec3A::splat(2.0));
    assert!(sphere.intersect(Vec3A::ZERO, Vec3A::Z, 3.0).is_none());
    let rect = area(LightShape::Rect { center: Vec3A::Z, u: Vec3A::X, v: Vec3A::Y, normal: Vec3A::NEG_Z }, 1.0);
    assert!(rect.intersect(Vec3A::ZERO, Vec3A::Z, f32::INFINITY).is_some());
    assert!(rect.intersect(Vec3A::Z * 2.0, Vec3A::NEG_Z, f32::INFINITY).is_none(), "the back of a rect light is dark");
}

#[test]
fn the_dome_texture_is_oriented_as_usdlux_says() {
    // UsdLux (OpenEXR latlong): the map's centre column looks down +Z of the light, s = ¼ is +X,
    // the top row +Y. A spot at s = ¼ on the horizon lights from +X in the light's space; the
    // light rotated 90° about Y (+X → −Z) lights from −Z.
    let spot_light_space = latlong_direction(0.25, PI / 2.0);
    assert!((spot_light_space - Vec3A::X).length() < 1e-6);
    let sampler: Arc<dyn TextureSampler> =
        Arc::new(SpotEnv { dir: spot_light_space, cos_r: 5f32.to_radians().cos(), spot: 10.0, base: 0.0 });
    let handle = sampler.handle("spot").unwrap();
    let env = EnvTexture::new(sampler, handle, Mat3A::from_rotation_y(PI / 2.0));
    assert!(env.radiance(Vec3A::NEG_Z).x > 9.0 && env.radiance(Vec3A::X).x < 1e-6);
    // Sampling draws directions around −Z.
    let mut rng = Sampler::new(1, 1, 1);
    let mut near = 0;
    for _ in 0..1000 {
        let (w, pdf) = env.sample([rng.next_f32(), rng.next_f32()]).unwrap();
        assert!(pdf > 0.0 && (pdf - env.pdf(w)).abs() < 1e-3 * pdf);
        near += u32::from(w.dot(Vec3A::NEG_Z) > 6f32.to_radians().cos());
    }
    assert!(near > 950, "{near} of 1000 samples near the spot");
}

#[test]
fn a_sampler_over_no_lights_or_black_lights_chooses_nothing() {
    let s = LightSampler::new(&[]);
    assert!(s.is_empty() && s.sample(Vec3A::ZERO, Vec3A::Z, 0.5).is_none());
    let black = area(LightShape::Sphere { center: Vec3A::Z * 3.0, radius: 1.0 }, 0.0);
    let s = LightSampler::new(&[black]);
    assert!(s.is_empty() && s.pmf(Vec3A::ZERO, Vec3A::Z, 0) == 0.0);
}
