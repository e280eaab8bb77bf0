//! Shared by the light tests: a ground plane, a procedural environment, and the direct-lighting
//! estimator run many times at one shading point, by several strategies.
#![allow(dead_code)]

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat3A, Mat4, Vec3A};
use mipray::bilinear::BilinearSurface;
use mipray::bsdf::Scattering;
use mipray::differential::RayDifferential;
use mipray::geometry_cache::CacheConfig;
use mipray::integrator::direct_light::{DirectLight, LightEstimate};
use mipray::integrator::{shading_point, ShadingPoint};
use mipray::light::{latlong_direction, EnvTexture, Light, LightShape};
use mipray::ray::{offset_origin, Ray, RayKind};
use mipray::sampling::Sampler;
use mipray::scene::{Mesh, Scene};
use mipray::texture::{FilterMode, Lookup, TextureError, TextureHandle, TextureSampler};
use mipray::topology::{MeshTopology, Scheme};
use mipray::trace::{TraceCounters, Tracer};

/// A light of `shape` with radiance `l` (white, not normalized), named after its kind.
pub fn area(shape: LightShape, l: f32) -> Light {
    let name = match shape {
        LightShape::Sphere { .. } => "/sphere",
        LightShape::Rect { .. } => "/rect",
        LightShape::Disk { .. } => "/disk",
        LightShape::Dome(_) => "/dome",
        LightShape::Distant { .. } => "/distant",
        LightShape::Cylinder { .. } => "/cylinder",
        LightShape::Mesh(_) => "/mesh",
    };
    Light::usd_area(name, shape, l, 0.0, Vec3A::ONE, false)
}

/// A scene holding only a square ground at z = 0 facing +z, `half` units from the origin.
pub fn ground(half: f32) -> Scene {
    let topo =
        MeshTopology { scheme: Scheme::None, face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() };
    let pts = [[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]];
    let mut scene = Scene::default();
    let mesh = scene.add_mesh(Mesh::new("/ground", Arc::new(BilinearSurface::new(&topo, &pts).unwrap())));
    scene.add_instance(mesh, Mat4::IDENTITY);
    scene
}

/// A latlong environment that is `spot` within a cap of angular radius acos(`cos_r`) around
/// light-space `dir` and `base` elsewhere, point-sampled (lookups ignore their widths). Its
/// texels come from the trait's default (one lookup per texel centre).
#[derive(Debug)]
pub struct SpotEnv {
    pub dir: Vec3A,
    pub cos_r: f32,
    pub spot: f32,
    pub base: f32,
}

impl TextureSampler for SpotEnv {
    fn handle(&self, _path: &str) -> Result<TextureHandle, TextureError> {
        Ok(TextureHandle::new(0))
    }

    fn sample(&self, _h: TextureHandle, st: [f32; 2], _dx: [f32; 2], _dy: [f32; 2], _l: &Lookup, out: &mut [f32]) -> bool {
        let d = latlong_direction(st[0].rem_euclid(1.0), (1.0 - st[1].clamp(0.0, 1.0)) * PI);
        out.fill(if d.dot(self.dir) >= self.cos_r { self.spot } else { self.base });
        true
    }

    fn resolution(&self, _h: TextureHandle) -> Option<[u32; 2]> {
        Some([2048, 1024])
    }

    fn filter_mode(&self) -> FilterMode {
        FilterMode::Differentials
    }

    fn stats(&self) -> mipray::texture::serde_json::Value {
        mipray::texture::serde_json::json!({})
    }
}

/// A dome light (intensity 1) textured with a [`SpotEnv`] whose cap is around render-space
/// `dir` (the light is not rotated), `radius_deg` wide.
pub fn spot_dome(dir: Vec3A, radius_deg: f32, spot: f32, base: f32) -> Light {
    let sampler: Arc<dyn TextureSampler> = Arc::new(SpotEnv { dir, cos_r: radius_deg.to_radians().cos(), spot, base });
    let handle = sampler.handle("spot").unwrap();
    Light::usd_area("/dome", LightShape::Dome(Some(EnvTexture::new(sampler, handle, Mat3A::IDENTITY))), 1.0, 0.0, Vec3A::ONE, false)
}

/// Which estimator of direct light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    /// [`DirectLight::estimate`]: light and BSDF samples with multiple importance sampling.
    Mis,
    /// Light samples only, unweighted (the light sampler's choice, the light's density).
    LightOnly,
    /// As `LightOnly` but choosing among the lights uniformly: what importance is measured
    /// against.
    UniformChoice,
    /// BSDF samples only, unweighted, adding every light the direction meets.
    BsdfOnly,
    /// [`DirectLight::estimate_lights`] plus one BSDF-sampled continuation ray whose light
    /// [`DirectLight::emitted`] weights: what a path tracer does.
    PathTracer,
}

/// Mean and spread of an estimator's values (red channel) over many independent calls.
#[derive(Clone, Debug)]
pub struct Stats {
    pub mean: Vec3A,
    pub diffuse: Vec3A,
    pub variance: f32,
    pub std_error: f32,
    pub diffuse_std_error: f32,
    pub shadow_rays_per_call: f64,
}

/// [`estimate_view`] seen from straight above.
pub fn estimate_at(
    scene: &Scene,
    p: Vec3A,
    n_samples: u32,
    calls: u32,
    mode: Mode,
    bsdf: impl Fn(&ShadingPoint) -> Box<dyn Scattering>,
) -> Stats {
    estimate_view(scene, p, Vec3A::Z, n_samples, calls, mode, &bsdf)
}

/// Direct light scattered toward `wo` at the ground point `p`, estimated `calls` times with
/// `n_samples` samples each (independent sampler streams), by `mode`.
pub fn estimate_view(
    scene: &Scene,
    p: Vec3A,
    wo: Vec3A,
    n_samples: u32,
    calls: u32,
    mode: Mode,
    bsdf: &dyn Fn(&ShadingPoint) -> Box<dyn Scattering>,
) -> Stats {
    let tracer = Tracer::new(scene, CacheConfig::unbounded(), 1.0);
    let mut counters = TraceCounters::default();
    let (e1, e2) = wo.any_orthonormal_pair();
    let ray = Ray {
        o: p + wo,
        d: -wo,
        t_min: 0.0,
        t_max: f32::INFINITY,
        diff: RayDifferential::from_spread(e1 * 1e-3, e2 * 1e-3, -wo, 1e-3),
        kind: RayKind::Camera,
        time: 0.0,
    };
    let hit = tracer.intersect(&ray, &mut counters).expect("the ray meets the ground");
    let sp = shading_point(&tracer, scene, &ray, &hit);
    let footprint = ray.diff.transfer(ray.d, hit.t, sp.ng);
    let f = bsdf(&sp);
    let direct = DirectLight::new(scene, true, n_samples);
    let shadow = RayKind::ALL.iter().position(|k| *k == RayKind::Shadow).unwrap();
    let mut shadow_rays = 0u64;
    // Sums in f64: a constant estimator must show no variance.
    let (mut sum, mut sum2, mut dsum, mut dsum2) = ([0.0f64; 3], 0.0f64, [0.0f64; 3], 0.0f64);
    for k in 0..calls {
        let mut s = Sampler::new(17, 3, u64::from(k));
        let before = counters.rays[shadow];
        let v: LightEstimate = match mode {
            Mode::Mis => direct.estimate(&tracer, scene, &sp, &hit, &footprint, f.as_ref(), wo, &mut s, &mut counters),
            Mode::PathTracer => {
                let mut est = direct.estimate_lights(&tracer, scene, &sp, &hit, &footprint, f.as_ref(), wo, &mut s, &mut counters);
                let u = [s.next_f32(), s.next_f32(), s.next_f32()];
                if let Some(bs) = f.sample(wo, u).filter(|b| !b.delta) {
                    let e = f.eval(wo, bs.wi);
                    if e.pdf > 0.0 {
                        let r = Ray {
                            o: offset_origin(sp.p, hit.p_error, sp.ng, bs.wi),
                            d: bs.wi,
                            t_min: 0.0,
                            t_max: f32::INFINITY,
                            diff: footprint.hemisphere(bs.wi, e.pdf, 1),
                            kind: RayKind::Diffuse,
                            time: 0.0,
                        };
                        let t_hit = tracer.intersect_from(&r, &hit, &mut counters).map_or(f32::INFINITY, |h| h.t);
                        let le = direct.emitted(scene, &sp, bs.wi, t_hit, Some(e.pdf));
                        est.diffuse += le * e.diffuse / e.pdf;
                        est.specular += le * e.specular / e.pdf;
                    }
                }
                est
            }
            Mode::LightOnly | Mode::UniformChoice => {
                let uniform = mode == Mode::UniformChoice;
                light_only(&tracer, scene, &direct, uniform, &sp, &hit, f.as_ref(), wo, n_samples, &mut s, &mut counters)
            }
            Mode::BsdfOnly => bsdf_only(&tracer, scene, &sp, &hit, f.as_ref(), wo, n_samples, &mut s, &mut counters),
        };
        shadow_rays += counters.rays[shadow] - before;
        let t = v.total();
        assert!(t.is_finite() && t.min_element() >= 0.0, "{mode:?}: {t}");
        for c in 0..3 {
            sum[c] += f64::from(t[c]);
            dsum[c] += f64::from(v.diffuse[c]);
        }
        sum2 += f64::from(t.x).powi(2);
        dsum2 += f64::from(v.diffuse.x).powi(2);
    }
    let n = f64::from(calls);
    let (m, dm) = (sum.map(|s| s / n), dsum.map(|s| s / n));
    let variance = ((sum2 / n - m[0] * m[0]) * n / (n - 1.0)).max(0.0);
    let dvar = ((dsum2 / n - dm[0] * dm[0]) * n / (n - 1.0)).max(0.0);
    let (mean, dmean) = (Vec3A::new(m[0] as f32, m[1] as f32, m[2] as f32), Vec3A::new(dm[0] as f32, dm[1] as f32, dm[2] as f32));
    Stats {
        mean,
        diffuse: dmean,
        variance: variance as f32,
        std_error: (variance / n).sqrt() as f32,
        diffuse_std_error: (dvar / n).sqrt() as f32,
        shadow_rays_per_call: shadow_rays as f64 / n,
    }
}

/// Light sampling alone: the light sampler's choice and the light's own density, no weights.
#[allow(clippy::too_many_arguments)]
fn light_only(
    tracer: &Tracer<'_>,
    scene: &Scene,
    direct: &DirectLight,
    uniform: bool,
    sp: &ShadingPoint,
    hit: &mipray::trace::Hit,
    f: &dyn Scattering,
    wo: Vec3A,
    n: u32,
    s: &mut Sampler,
    counters: &mut TraceCounters,
) -> LightEstimate {
    let mut out = LightEstimate::default();
    for _ in 0..n {
        let (u, u1, u2) = (s.next_f32(), s.next_f32(), s.next_f32());
        let choice = if uniform {
            let k = scene.lights.len();
            Some((((u * k as f32) as usize).min(k - 1), 1.0 / k as f32))
        } else {
            direct.light_sampler().sample(sp.p, sp.ns, u)
        };
        let Some((j, prob)) = choice else { continue };
        let Some(ls) = scene.lights[j].sample(sp.p, sp.ns, u1, u2) else { continue };
        let e = f.eval(wo, ls.wi);
        if e.total().max_element() <= 0.0 {
            continue;
        }
        let r = shadow(sp, hit, ls.wi, ls.distance);
        if tracer.occluded_from(&r, hit, counters) {
            continue;
        }
        let w = ls.radiance / (prob * ls.pdf * n as f32);
        out.diffuse += e.diffuse * w;
        out.specular += e.specular * w;
    }
    out
}

/// BSDF sampling alone: every light the sampled direction meets, no weights.
#[allow(clippy::too_many_arguments)]
fn bsdf_only(
    tracer: &Tracer<'_>,
    scene: &Scene,
    sp: &ShadingPoint,
    hit: &mipray::trace::Hit,
    f: &dyn Scattering,
    wo: Vec3A,
    n: u32,
    s: &mut Sampler,
    counters: &mut TraceCounters,
) -> LightEstimate {
    let mut out = LightEstimate::default();
    for _ in 0..n {
        let u = [s.next_f32(), s.next_f32(), s.next_f32()];
        let Some(bs) = f.sample(wo, u) else { continue };
        let e = f.eval(wo, bs.wi);
        if !(e.pdf > 0.0) {
            continue;
        }
        let mut le = Vec3A::ZERO;
        for light in &scene.lights {
            if let Some(h) = light.intersect(sp.p, bs.wi, f32::INFINITY) {
                if !tracer.occluded_from(&shadow(sp, hit, bs.wi, h.t), hit, counters) {
                    le += h.radiance;
                }
            } else if light.is_infinite() && !tracer.occluded_from(&shadow(sp, hit, bs.wi, f32::INFINITY), hit, counters) {
                le += light.environment(bs.wi);
            }
        }
        out.diffuse += le * e.diffuse / (e.pdf * n as f32);
        out.specular += le * e.specular / (e.pdf * n as f32);
    }
    out
}

fn shadow(sp: &ShadingPoint, hit: &mipray::trace::Hit, wi: Vec3A, distance: f32) -> Ray {
    Ray {
        o: offset_origin(sp.p, hit.p_error, sp.ng, wi),
        d: wi,
        t_min: 0.0,
        t_max: if distance.is_finite() { distance * (1.0 - 1e-4) } else { f32::INFINITY },
        diff: RayDifferential::default(),
        kind: RayKind::Shadow,
        time: 0.0,
    }
}
