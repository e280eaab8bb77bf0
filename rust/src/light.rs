//! Lights (UsdLux): distant, sphere, rect, disk and dome (constant colour).
//!
//! Units. A distant light delivers irradiance `intensity · 2^exposure · color` on a surface facing
//! it, so a white lambertian surface facing a light of intensity 1 has radiance 1/π. Area lights
//! (sphere, rect, disk) emit radiance `intensity · 2^exposure · color` from their surface; with
//! `normalize` the radiance is divided by the light's area, so its power does not change with its
//! size (UsdLux's definition). A dome light is an environment of that radiance in every
//! direction.
//!
//! Sampling (the paper's §4.3 and §4.5): point-like lights (a distant light with no angle) get one
//! narrow shadow ray; area lights and distant lights with an angle get `shadow_samples` rays
//! whose directional spread is the light's solid angle over the number of rays, so wide lights
//! cast wide, incoherent, coarsely tessellated shadow rays.

use glam::{Mat4, Vec3A};

use crate::sampling::{cosine_hemisphere, frame};

#[derive(Clone, Debug, PartialEq)]
pub enum LightShape {
    /// Light arriving from direction −`direction`; `direction` is where it travels (render space,
    /// unit length): a UsdLux.DistantLight emits along its local −Z. `angle_deg` is the angular
    /// diameter of the source (0: a point at infinity).
    Distant { direction: Vec3A, angle_deg: f32 },
    /// A sphere of `radius` (render units) around `center`, emitting outward.
    Sphere { center: Vec3A, radius: f32 },
    /// A parallelogram `center ± u ± v` (half-extent vectors), emitting along its `normal`
    /// (UsdLux: the light's −Z).
    Rect { center: Vec3A, u: Vec3A, v: Vec3A, normal: Vec3A },
    /// An ellipse `center + a·u + b·v`, a² + b² ≤ 1, emitting along `normal`.
    Disk { center: Vec3A, u: Vec3A, v: Vec3A, normal: Vec3A },
    /// Radiance from every direction: uniform, or a latlong environment texture.
    Dome(Option<EnvTexture>),
}

/// A latlong environment (UsdLux.DomeLight `texture:file`): +Y up in the light's space, the
/// image's centre column looking down −Z, as USD's dome lights are authored.
#[derive(Clone)]
pub struct EnvTexture {
    pub sampler: std::sync::Arc<dyn crate::texture::TextureSampler>,
    pub texture: crate::texture::TextureHandle,
    /// Render-space directions to the light's space (the inverse of its rotation).
    pub light_from_render: glam::Mat3A,
}

impl std::fmt::Debug for EnvTexture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EnvTexture").field("texture", &self.texture).finish_non_exhaustive()
    }
}

impl PartialEq for EnvTexture {
    fn eq(&self, o: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.sampler, &o.sampler) && self.texture == o.texture && self.light_from_render == o.light_from_render
    }
}

impl EnvTexture {
    /// The environment's RGB radiance (before the light's intensity) toward render-space `wi`.
    pub fn radiance(&self, wi: Vec3A) -> Vec3A {
        let d = (self.light_from_render * wi).normalize_or(Vec3A::Y);
        let s = 0.5 + d.x.atan2(-d.z) / (2.0 * std::f32::consts::PI);
        let t = 1.0 - d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
        // About a degree of filtering: lights are integrated over many samples, not seen.
        let w = 1.0 / 360.0;
        let mut rgb = [0.0f32; 3];
        let lookup =
            crate::texture::Lookup { wrap_s: crate::texture::Wrap::Periodic, wrap_t: crate::texture::Wrap::Clamp, ..Default::default() };
        if self.sampler.sample(self.texture, [s, t], [w, 0.0], [0.0, w], &lookup, &mut rgb) {
            Vec3A::from(rgb).max(Vec3A::ZERO)
        } else {
            Vec3A::ONE
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Prim path, for messages and stats.
    pub name: String,
    pub shape: LightShape,
    /// Linear RGB: the irradiance of a distant light, the emitted radiance of the others.
    pub radiance_scale: Vec3A,
    pub casts_shadows: bool,
}

/// One sample of a light as seen from a point: direction (unit, toward the light), distance
/// (infinite for distant and dome lights), incident radiance over pdf (what the integrator
/// multiplies by the BRDF and cosine), and the light's solid angle seen from the point (for the
/// shadow ray's differential).
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub wi: Vec3A,
    pub distance: f32,
    pub weight: Vec3A,
    pub solid_angle_sr: f32,
}

impl Light {
    /// A distant light travelling along `direction` with irradiance `irradiance` (RGB).
    pub fn distant(name: impl Into<String>, direction: Vec3A, irradiance: Vec3A) -> Self {
        Light {
            name: name.into(),
            shape: LightShape::Distant { direction: direction.normalize_or(Vec3A::NEG_Z), angle_deg: 0.0 },
            radiance_scale: irradiance,
            casts_shadows: true,
        }
    }

    /// A UsdLux.DistantLight from its world transform and inputs.
    pub fn usd_distant(
        name: impl Into<String>,
        render_from_light: &Mat4,
        intensity: f32,
        exposure: f32,
        color: Vec3A,
        angle_deg: f32,
    ) -> Self {
        let dir = render_from_light.transform_vector3a(Vec3A::NEG_Z);
        let mut l = Light::distant(name, dir, color * intensity * exposure.exp2());
        if let LightShape::Distant { angle_deg: a, .. } = &mut l.shape {
            *a = angle_deg.clamp(0.0, 180.0);
        }
        l
    }

    /// An area or dome light from its UsdLux inputs: `shape` already in render space. With
    /// `normalize`, the radiance is divided by the area.
    pub fn usd_area(name: impl Into<String>, shape: LightShape, intensity: f32, exposure: f32, color: Vec3A, normalize: bool) -> Self {
        let mut radiance = color * intensity * exposure.exp2();
        if normalize {
            let area = shape_area(&shape);
            if area > 0.0 {
                radiance /= area;
            }
        }
        Light { name: name.into(), shape, radiance_scale: radiance, casts_shadows: true }
    }

    /// True when one sample represents the light exactly (a point at infinity).
    pub fn is_delta(&self) -> bool {
        matches!(self.shape, LightShape::Distant { angle_deg, .. } if angle_deg <= 0.0)
    }

    /// Samples the light from point `p` with normal `n` (the dome is cosine-sampled about `n`),
    /// with two uniform numbers. `None` when the sample cannot light `p` (behind the light).
    pub fn sample(&self, p: Vec3A, n: Vec3A, u1: f32, u2: f32) -> Option<LightSample> {
        match &self.shape {
            LightShape::Distant { direction, angle_deg } => {
                let toward = -*direction;
                if *angle_deg <= 0.0 {
                    return Some(LightSample { wi: toward, distance: f32::INFINITY, weight: self.radiance_scale, solid_angle_sr: 0.0 });
                }
                // Uniform over the cone of the source's angular radius; the irradiance is
                // spread evenly over it, so every sample carries the whole irradiance.
                let cos_max = (angle_deg.to_radians() * 0.5).cos();
                let cos_t = 1.0 - u1 * (1.0 - cos_max);
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = 2.0 * std::f32::consts::PI * u2;
                let (t, b) = frame(toward);
                let wi = (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + toward * cos_t).normalize();
                Some(LightSample {
                    wi,
                    distance: f32::INFINITY,
                    weight: self.radiance_scale,
                    solid_angle_sr: 2.0 * std::f32::consts::PI * (1.0 - cos_max),
                })
            }
            LightShape::Dome(env) => {
                let (local, pdf) = cosine_hemisphere(u1, u2);
                if pdf <= 0.0 {
                    return None;
                }
                let (t, b) = frame(n);
                let wi = t * local.x + b * local.y + n * local.z;
                let texel = env.as_ref().map_or(Vec3A::ONE, |e| e.radiance(wi));
                Some(LightSample {
                    wi,
                    distance: f32::INFINITY,
                    weight: self.radiance_scale * texel / pdf,
                    solid_angle_sr: 2.0 * std::f32::consts::PI,
                })
            }
            shape => {
                let (y, ny, area) = sample_surface(shape, u1, u2)?;
                let d = y - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0 && dist2.is_finite()) {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = -ny.dot(wi);
                if cos_l <= 0.0 {
                    return None;
                }
                // Area sampling: pdf in solid angle = dist² / (cos_l · area).
                let weight = self.radiance_scale * (cos_l * area / dist2);
                let solid = (area * cos_l / dist2).min(4.0 * std::f32::consts::PI);
                Some(LightSample { wi, distance: dist, weight, solid_angle_sr: solid })
            }
        }
    }
}

/// Area of an area light's surface (render units²); 0 for distant and dome lights.
pub fn shape_area(shape: &LightShape) -> f32 {
    match shape {
        LightShape::Sphere { radius, .. } => 4.0 * std::f32::consts::PI * radius * radius,
        LightShape::Rect { u, v, .. } => 4.0 * u.cross(*v).length(),
        LightShape::Disk { u, v, .. } => std::f32::consts::PI * u.cross(*v).length(),
        _ => 0.0,
    }
}

/// A uniformly distributed point on an area light: (point, outward normal, area).
fn sample_surface(shape: &LightShape, u1: f32, u2: f32) -> Option<(Vec3A, Vec3A, f32)> {
    let area = shape_area(shape);
    if !(area > 0.0) {
        return None;
    }
    match shape {
        LightShape::Sphere { center, radius } => {
            let z = 1.0 - 2.0 * u1;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = 2.0 * std::f32::consts::PI * u2;
            let n = Vec3A::new(r * phi.cos(), r * phi.sin(), z);
            Some((*center + n * *radius, n, area))
        }
        LightShape::Rect { center, u, v, normal } => Some((*center + *u * (2.0 * u1 - 1.0) + *v * (2.0 * u2 - 1.0), *normal, area)),
        LightShape::Disk { center, u, v, normal } => {
            let r = u1.sqrt();
            let phi = 2.0 * std::f32::consts::PI * u2;
            Some((*center + *u * (r * phi.cos()) + *v * (r * phi.sin()), *normal, area))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    /// Monte Carlo irradiance at `p` (normal `n`) from `light`, no occlusion.
    fn irradiance(light: &Light, p: Vec3A, n: Vec3A, samples: u32) -> f32 {
        let mut s = Sampler::new(1, 2, 3);
        let mut e = 0.0f64;
        for _ in 0..samples {
            if let Some(ls) = light.sample(p, n, s.next_f32(), s.next_f32()) {
                e += f64::from(ls.weight.x * ls.wi.dot(n).max(0.0));
            }
        }
        (e / f64::from(samples)) as f32
    }

    #[test]
    fn sphere_light_irradiance_is_analytic() {
        // A sphere of radiance L, radius r, at distance d on the normal: E = π L (r/d)².
        let light =
            Light::usd_area("/s", LightShape::Sphere { center: Vec3A::new(0.0, 0.0, 4.0), radius: 0.5 }, 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&light, Vec3A::ZERO, Vec3A::Z, 200_000);
        let expected = std::f32::consts::PI * (0.5f32 / 4.0).powi(2);
        assert!((e - expected).abs() < 0.02 * expected, "{e} vs {expected}");
    }

    #[test]
    fn disk_light_irradiance_is_analytic_and_normalize_divides_by_area() {
        // A disk of radius r facing the point from height h: E = π L r² / (h² + r²).
        let down = Vec3A::NEG_Z;
        let shape = LightShape::Disk { center: Vec3A::new(0.0, 0.0, 2.0), u: Vec3A::X, v: Vec3A::Y, normal: down };
        let light = Light::usd_area("/d", shape.clone(), 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&light, Vec3A::ZERO, Vec3A::Z, 200_000);
        let expected = std::f32::consts::PI / (4.0 + 1.0);
        assert!((e - expected).abs() < 0.02 * expected, "{e} vs {expected}");
        let normalized = Light::usd_area("/d", shape, 1.0, 0.0, Vec3A::ONE, true);
        assert!((normalized.radiance_scale.x - 1.0 / std::f32::consts::PI).abs() < 1e-6);
        // Behind the disk nothing arrives.
        assert_eq!(irradiance(&light, Vec3A::new(0.0, 0.0, 4.0), Vec3A::NEG_Z, 1000), 0.0);
    }

    #[test]
    fn dome_and_distant_cone_deliver_their_irradiance() {
        let dome = Light::usd_area("/dome", LightShape::Dome(None), 1.0, 0.0, Vec3A::ONE, false);
        let e = irradiance(&dome, Vec3A::ZERO, Vec3A::Z, 100_000);
        assert!((e - std::f32::consts::PI).abs() < 1e-4, "{e}");
        let sun = Light::usd_distant("/sun", &Mat4::IDENTITY, 2.0, 0.0, Vec3A::ONE, 10.0);
        let e = irradiance(&sun, Vec3A::ZERO, Vec3A::Z, 100_000);
        // The cone of 5° radius around +Z: mean cosine (1 + cos 5°)/2.
        let expected = 2.0 * (1.0 + 5f32.to_radians().cos()) / 2.0;
        assert!((e - expected).abs() < 2e-3, "{e} vs {expected}");
        assert!(!sun.is_delta() && Light::distant("/p", Vec3A::NEG_Z, Vec3A::ONE).is_delta());
    }
}
