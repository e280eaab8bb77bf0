//! Light arriving at a shading point from the scene's lights, with ray-traced shadows toward
//! those that cast them (the paper's §4.3 and §4.5 for the shadow rays' differentials).

use glam::Vec3A;

use crate::differential::RayDifferential;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::trace::{Hit, TraceCounters, Tracer};

use super::ShadingPoint;

/// How direct light is gathered: set once per render from the effects and settings.
#[derive(Clone, Copy, Debug)]
pub struct DirectLight {
    /// Shadow rays are traced (the scene has lights that cast shadows).
    pub shadows: bool,
    /// Shadow rays per shading point toward each wide light.
    pub shadow_samples: u32,
}

impl DirectLight {
/// Light from every light (irradiance-weighted, over π for the lambertian BRDF), with shadow
/// rays toward those that cast them. A point-like light takes one ray; area and dome lights
/// and distant lights with an angle take `shadow_samples`, each with the §4.5 spread.
pub fn estimate(
    &self,
    tracer: &Tracer<'_>,
    scene: &Scene,
    sp: &ShadingPoint,
    hit: &Hit,
    footprint: &RayDifferential,
    sampler: &mut Sampler,
    counters: &mut TraceCounters,
) -> Vec3A {
    let mut sum = Vec3A::ZERO;
    for light in &scene.lights {
        let n = if light.is_delta() { 1 } else { self.shadow_samples.max(1) };
        let mut acc = Vec3A::ZERO;
        for _ in 0..n {
            let (u1, u2) = if light.is_delta() { (0.5, 0.5) } else { (sampler.next_f32(), sampler.next_f32()) };
            let Some(ls) = light.sample(sp.p, sp.ns, u1, u2) else { continue };
            let cos_s = sp.ns.dot(ls.wi);
            if cos_s <= 0.0 || sp.ng.dot(ls.wi) <= 0.0 {
                continue;
            }
            if self.shadows && light.casts_shadows {
                // Point-like lights: parallel shadow rays, the footprint as origin
                // differential (§4.3: narrow and coherent). Wide lights: the light's
                // solid angle over the number of rays (§4.5: wide and incoherent).
                let diff = if light.is_delta() {
                    RayDifferential::new(footprint.dpdx, footprint.dpdy, Vec3A::ZERO, Vec3A::ZERO)
                } else {
                    let (d, clamped) = footprint.area_light_shadow_checked(ls.wi, ls.solid_angle_sr, n);
                    counters.differential_clamps += u64::from(clamped);
                    d
                };
                let o = offset_origin(sp.p, hit.p_error, sp.ng, ls.wi);
                // Stop short of an area light's own surface (it is not geometry here, but a
                // mesh can coincide with it).
                let t_max = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) } else { f32::INFINITY };
                let shadow = Ray { o, d: ls.wi, t_min: 0.0, t_max, diff, kind: RayKind::Shadow, time: hit.time };
                if tracer.occluded_from(&shadow, hit, counters) {
                    continue;
                }
            }
            acc += ls.weight * (cos_s * std::f32::consts::FRAC_1_PI);
        }
        sum += acc / n as f32;
    }
    sum
}
}
