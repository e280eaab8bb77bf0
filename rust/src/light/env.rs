//! Dome light environments: a latlong texture, and the importance table that samples it.
//!
//! Importance sampling (Pharr, Jakob & Humphreys, *PBRT* 3rd ed. §14.2.4): the texture is read
//! once at a reduced MIP level ([`crate::texture::TextureSampler::texels`], at most
//! [`TABLE_MAX_WIDTH`] texels wide) and each texel's luminance × sin θ (the latlong map's
//! solid-angle weight) becomes a piecewise-constant 2-D density over the map: a marginal density
//! over rows (θ) and one conditional density over columns (φ) per row. A direction's solid-angle
//! density is the map density over the Jacobian 2π² sin θ. Lookups for radiance still read the
//! full-resolution texture; the table only decides where samples go, so a coarse table costs
//! variance, never bias (every texel keeps a small floor so no direction the texture lights has
//! density 0).

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat3A, Vec3A};

use crate::texture::{Lookup, TextureHandle, TextureSampler, Wrap};

/// Widest importance table read from a dome texture, texels (its height is half that): 0.7° per
/// texel, finer than the filter radiance lookups use.
pub const TABLE_MAX_WIDTH: u32 = 512;

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: Vec3A) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// A piecewise-constant density over [0, 1) with `n` equal cells.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution1D {
    func: Vec<f32>,
    /// cdf[i] = ∫₀^{i/n}; cdf[n] = 1.
    cdf: Vec<f32>,
    /// ∫₀¹ of the (non-negative) function; 0 makes the density uniform.
    integral: f32,
}

impl Distribution1D {
    /// From cell values (negative and non-finite values count as 0). All zero: uniform.
    pub fn new(values: &[f32]) -> Self {
        let n = values.len().max(1);
        let func: Vec<f32> = (0..n).map(|i| values.get(i).copied().filter(|v| v.is_finite() && *v > 0.0).unwrap_or(0.0)).collect();
        let mut cdf = vec![0.0f64; n + 1];
        for i in 0..n {
            cdf[i + 1] = cdf[i] + f64::from(func[i]) / n as f64;
        }
        let integral = cdf[n];
        let cdf: Vec<f32> = if integral > 0.0 {
            cdf.iter().map(|c| (c / integral) as f32).collect()
        } else {
            (0..=n).map(|i| i as f32 / n as f32).collect()
        };
        Distribution1D { func, cdf, integral: integral as f32 }
    }

    /// Cells.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// True when it has no cells (never: an empty input makes one uniform cell).
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// ∫₀¹ of the function.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Density of cell `i` (per unit of [0, 1)).
    pub fn pdf_cell(&self, i: usize) -> f32 {
        let n = self.func.len();
        if self.integral > 0.0 {
            self.func.get(i).map_or(0.0, |f| f / self.integral)
        } else if i < n {
            1.0
        } else {
            0.0
        }
    }

    /// A point in [0, 1) with density ∝ the function, from uniform `u`: (x, density, cell).
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        // The last cell whose cdf start is ≤ u.
        let i = self.cdf.partition_point(|&c| c <= u).saturating_sub(1).min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 { ((u - self.cdf[i]) / width).clamp(0.0, 1.0) } else { 0.5 };
        let x = ((i as f32 + du) / n as f32).min(1.0 - f32::EPSILON * 0.5);
        (x, self.pdf_cell(i), i)
    }
}

/// A piecewise-constant density over [0, 1)² (x along a row, y down the rows).
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// From `width` × `height` cell values, row-major.
    pub fn new(values: &[f32], width: usize, height: usize) -> Self {
        let (w, h) = (width.max(1), height.max(1));
        let rows: Vec<Distribution1D> = (0..h).map(|j| Distribution1D::new(values.get(j * w..(j + 1) * w).unwrap_or(&[]))).collect();
        let marginal = Distribution1D::new(&rows.iter().map(Distribution1D::integral).collect::<Vec<_>>());
        Distribution2D { rows, marginal }
    }

    /// A point (x, y) with density ∝ the function, from two uniform numbers, and its density.
    pub fn sample(&self, u: [f32; 2]) -> ([f32; 2], f32) {
        let (y, py, j) = self.marginal.sample(u[1]);
        let (x, px, _) = self.rows[j].sample(u[0]);
        ([x, y], px * py)
    }

    /// Density at (x, y).
    pub fn pdf(&self, p: [f32; 2]) -> f32 {
        let h = self.rows.len();
        let j = ((p[1] * h as f32) as usize).min(h - 1);
        let w = self.rows[j].len();
        let i = ((p[0] * w as f32) as usize).min(w - 1);
        self.marginal.pdf_cell(j) * self.rows[j].pdf_cell(i)
    }
}

/// A dome's importance table and what the light sampler needs to know about the dome.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvDistribution {
    /// Over the latlong map: x = s, y = θ/π (0 at the top, +Y of the light's space).
    pub map: Distribution2D,
    /// Mean radiance over the sphere of directions (RGB, texture units): the dome's irradiance
    /// on any surface is about π times its luminance.
    pub mean: Vec3A,
    /// The table's size in texels.
    pub size: [u32; 2],
}

impl EnvDistribution {
    /// The table of a latlong image given as texels (see [`crate::texture::Texels`]: first row
    /// at the top). RGB is read from the first three channels (one channel is grey).
    pub fn from_texels(t: &crate::texture::Texels) -> Self {
        let (w, h) = (t.width.max(1), t.height.max(1));
        let rgb = |i: u32, j: u32| -> Vec3A {
            let c = |k: u32| t.at(i, j, k.min(t.channels - 1));
            let v = Vec3A::new(c(0), c(1), c(2));
            if v.is_finite() {
                v.max(Vec3A::ZERO)
            } else {
                Vec3A::ZERO
            }
        };
        let mut lum = vec![0.0f32; (w * h) as usize];
        let mut mean = Vec3A::ZERO;
        let mut lum_sum = 0.0f64;
        for j in 0..h {
            let (t0, t1) = (PI * j as f32 / h as f32, PI * (j + 1) as f32 / h as f32);
            // The solid angle of one texel of this row.
            let row_solid = 2.0 * PI / w as f32 * (t0.cos() - t1.cos());
            for i in 0..w {
                let c = rgb(i, j);
                mean += c * row_solid;
                let l = luminance(c);
                lum_sum += f64::from(l * row_solid);
                lum[(j * w + i) as usize] = l;
            }
        }
        mean /= 4.0 * PI;
        // A floor of 1e-3 of the mean (and a tiny absolute one), spread as the solid angle is, so
        // no direction the full-resolution lookups light has density 0.
        let floor = (1e-3 * (lum_sum / (4.0 * std::f64::consts::PI)) as f32).max(1e-12);
        let mut weights = vec![0.0f32; (w * h) as usize];
        for j in 0..h {
            let (t0, t1) = (PI * j as f32 / h as f32, PI * (j + 1) as f32 / h as f32);
            // The mean of sin θ over the row: the latlong map's solid-angle weight.
            let sin_mean = (t0.cos() - t1.cos()) / (t1 - t0);
            for i in 0..w {
                // Each texel weighs as the mean over its area of the lookups lighting reads,
                // which interpolate the table's level between texel centres: the texels blurred
                // by [1/8, 3/4, 1/8] in each direction (periodic in s), as PBRT's image
                // infinite light builds its density. So no texel that lookups light is left
                // with a weight far below its radiance (whose rare samples would carry huge
                // weights), and none is given weight it does not have.
                let mut l = 0.0f32;
                for (dj, wj) in [(-1i64, 0.125f32), (0, 0.75), (1, 0.125)] {
                    let jj = (i64::from(j) + dj).clamp(0, i64::from(h) - 1) as u32;
                    for (di, wi) in [(-1i64, 0.125f32), (0, 0.75), (1, 0.125)] {
                        let ii = (i64::from(i) + di).rem_euclid(i64::from(w)) as u32;
                        l += wj * wi * lum[(jj * w + ii) as usize];
                    }
                }
                weights[(j * w + i) as usize] = (l + floor) * sin_mean;
            }
        }
        EnvDistribution { map: Distribution2D::new(&weights, w as usize, h as usize), mean, size: [w, h] }
    }
}

/// A latlong environment (UsdLux.DomeLight `texture:file`) in OpenEXR's latlong layout, as
/// UsdLux specifies ([`latlong_st`]): +Y up in the light's space, the image's centre column
/// looking down +Z. With its importance table.
#[derive(Clone)]
pub struct EnvTexture {
    pub sampler: Arc<dyn TextureSampler>,
    pub texture: TextureHandle,
    /// Render-space directions to the light's space (the inverse of its rotation).
    pub light_from_render: Mat3A,
    /// Light-space directions to render space.
    pub render_from_light: Mat3A,
    /// `None` when the texels could not be read: the dome is then sampled like a uniform one.
    pub distribution: Option<Arc<EnvDistribution>>,
}

/// Filter width of lighting lookups without a table: about a degree.
const LIGHTING_FILTER: [f32; 2] = [1.0 / 360.0, 1.0 / 180.0];

impl std::fmt::Debug for EnvTexture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EnvTexture")
            .field("texture", &self.texture)
            .field("table", &self.distribution.as_ref().map(|d| d.size))
            .finish_non_exhaustive()
    }
}

impl PartialEq for EnvTexture {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.sampler, &o.sampler) && self.texture == o.texture && self.light_from_render == o.light_from_render
    }
}

impl EnvTexture {
    /// An environment read through `sampler`, oriented by `render_from_light` (the light's
    /// rotation; any scale is divided out of directions). Reads its importance table now.
    pub fn new(sampler: Arc<dyn TextureSampler>, texture: TextureHandle, render_from_light: Mat3A) -> Self {
        let inverse = render_from_light.inverse();
        let light_from_render = if inverse.is_finite() { inverse } else { Mat3A::IDENTITY };
        let render_from_light = if inverse.is_finite() { render_from_light } else { Mat3A::IDENTITY };
        let distribution = sampler.texels(texture, TABLE_MAX_WIDTH, 3).map(|t| Arc::new(EnvDistribution::from_texels(&t)));
        EnvTexture { sampler, texture, light_from_render, render_from_light, distribution }
    }

    /// The environment's RGB radiance (before the light's intensity) toward render-space `wi`,
    /// as lighting reads it: filtered over one texel of the importance table (about a degree
    /// without one), so what is sampled is what the table describes. Lights are integrated
    /// over many samples, not seen; [`EnvTexture::radiance_filtered`] is the sharper lookup a
    /// camera or mirror ray needs.
    pub fn radiance(&self, wi: Vec3A) -> Vec3A {
        let [ws, wt] = self.distribution.as_ref().map_or(LIGHTING_FILTER, |d| [1.0 / d.size[0] as f32, 1.0 / d.size[1] as f32]);
        self.lookup(wi, ws, wt)
    }

    /// The radiance toward `wi` seen by a ray whose directional spread is `spread_rad` (its
    /// differential, the paper's §4: a camera or mirror ray's beam), filtered over that
    /// angle: for a dome seen as the background or in a mirror.
    pub fn radiance_filtered(&self, wi: Vec3A, spread_rad: f32) -> Vec3A {
        let spread = if spread_rad.is_finite() { spread_rad.clamp(0.0, PI) } else { 0.0 };
        self.lookup(wi, spread / (2.0 * PI), spread / PI)
    }

    fn lookup(&self, wi: Vec3A, ws: f32, wt: f32) -> Vec3A {
        let [s, t] = latlong_st((self.light_from_render * wi).normalize_or(Vec3A::Y));
        let mut rgb = [0.0f32; 3];
        let lookup = Lookup { wrap_s: Wrap::Periodic, wrap_t: Wrap::Clamp, ..Default::default() };
        if self.sampler.sample(self.texture, [s, t], [ws, 0.0], [0.0, wt], &lookup, &mut rgb) {
            let c = Vec3A::from(rgb);
            if c.is_finite() {
                c.max(Vec3A::ZERO)
            } else {
                Vec3A::ZERO
            }
        } else {
            Vec3A::ONE
        }
    }

    /// Mean radiance over all directions (texture units); white without a table.
    pub fn mean(&self) -> Vec3A {
        self.distribution.as_ref().map_or(Vec3A::ONE, |d| d.mean)
    }

    /// A render-space direction by the importance table from two uniform numbers, and its
    /// solid-angle density; `None` without a table or at a pole (density undefined).
    pub fn sample(&self, u: [f32; 2]) -> Option<(Vec3A, f32)> {
        let d = self.distribution.as_ref()?;
        let ([x, y], pdf_map) = d.map.sample(u);
        let theta = y * PI;
        let sin_t = theta.sin();
        if !(sin_t > 0.0 && pdf_map > 0.0) {
            return None;
        }
        let wi = (self.render_from_light * latlong_direction(x, theta)).normalize_or_zero();
        if wi == Vec3A::ZERO {
            return None;
        }
        Some((wi, pdf_map / (2.0 * PI * PI * sin_t)))
    }

    /// The solid-angle density [`EnvTexture::sample`] gives render-space `wi` (0 without a table).
    pub fn pdf(&self, wi: Vec3A) -> f32 {
        let Some(d) = self.distribution.as_ref() else { return 0.0 };
        let local = (self.light_from_render * wi).normalize_or(Vec3A::Y);
        let [s, t] = latlong_st(local);
        let y = 1.0 - t;
        let sin_t = (1.0 - local.y * local.y).max(0.0).sqrt();
        if !(sin_t > 0.0) {
            return 0.0;
        }
        d.map.pdf([s.rem_euclid(1.0), y.clamp(0.0, 1.0)]) / (2.0 * PI * PI * sin_t)
    }
}

/// (s, t) of a light-space unit direction on the latlong map, as UsdLux's DomeLight specifies
/// (OpenEXR's latlong): t = 1 at +Y (latitude +π/2); longitude 0 (+Z) at s = ½, +π/2 (+X) at
/// s = ¼, ±π (−Z) at the left and right edges (s = ½ − longitude / 2π).
pub fn latlong_st(d: Vec3A) -> [f32; 2] {
    let s = 0.5 - d.x.atan2(d.z) / (2.0 * PI);
    let t = 1.0 - d.y.clamp(-1.0, 1.0).acos() / PI;
    [s, t]
}

/// The light-space unit direction at map column fraction `s` and polar angle `theta` (from +Y):
/// the inverse of [`latlong_st`].
pub fn latlong_direction(s: f32, theta: f32) -> Vec3A {
    let longitude = (0.5 - s) * 2.0 * PI;
    let (st, ct) = theta.sin_cos();
    Vec3A::new(st * longitude.sin(), ct, st * longitude.cos())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    #[test]
    fn distribution_1d_samples_its_density() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0, 0.0]);
        assert!((d.integral() - 1.0).abs() < 1e-6);
        let mut s = Sampler::new(1, 0, 0);
        let mut hist = [0u32; 4];
        for _ in 0..40_000 {
            let (x, pdf, i) = d.sample(s.next_f32());
            assert!((0.0..1.0).contains(&x) && i == (x * 4.0) as usize);
            assert!((pdf - d.pdf_cell(i)).abs() < 1e-6 && pdf > 0.0);
            hist[i] += 1;
        }
        assert_eq!((hist[1], hist[3]), (0, 0));
        assert!((hist[2] as f32 / hist[0] as f32 - 3.0).abs() < 0.15, "{hist:?}");
        let zero = Distribution1D::new(&[0.0, 0.0]);
        assert_eq!(zero.pdf_cell(1), 1.0);
    }

    #[test]
    fn latlong_round_trips_and_matches_openexr() {
        // OpenEXR: latitude 0, longitude 0 is +Z (the map's centre); longitude π/2 is +X; the
        // first column has longitude +π.
        assert!((latlong_direction(0.5, PI / 2.0) - Vec3A::Z).length() < 1e-6);
        assert!((latlong_direction(0.25, PI / 2.0) - Vec3A::X).length() < 1e-6);
        assert!((latlong_direction(0.0, PI / 2.0) - Vec3A::NEG_Z).length() < 1e-6);
        assert!((latlong_direction(0.3, 0.0) - Vec3A::Y).length() < 1e-6);
        for (s, theta) in [(0.1, 0.3), (0.5, 1.2), (0.9, 2.9), (0.75, PI / 2.0)] {
            let [s2, t2] = latlong_st(latlong_direction(s, theta));
            assert!((s2 - s).abs() < 1e-5 && (t2 - (1.0 - theta / PI)).abs() < 1e-5, "{s} {theta}: {s2} {t2}");
        }
    }
}
