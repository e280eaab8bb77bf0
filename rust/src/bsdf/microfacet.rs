//! The GGX (Trowbridge–Reitz) microfacet distribution and what a microfacet BSDF needs of it:
//! the normal distribution `D`, Smith's height-correlated masking–shadowing `G2`, sampling of
//! the distribution of visible normals (Heitz 2018), Schlick's Fresnel, and tables of the
//! directional albedo of a GGX reflector used for energy conservation.
//!
//! **Frame.** Every direction here is a unit vector in the *local shading frame*: `z` is the
//! shading normal, `x`, `y` any tangents (the distribution is isotropic). `alpha` is GGX's
//! width, UsdPreviewSurface's `roughness²`.
//!
//! References: B. Walter et al., *Microfacet Models for Refraction through Rough Surfaces*,
//! EGSR 2007; E. Heitz, *Understanding the Masking-Shadowing Function in Microfacet-Based
//! BRDFs*, JCGT 2014; E. Heitz, *Sampling the GGX Distribution of Visible Normals*, JCGT 2018;
//! C. Schlick, *An Inexpensive BRDF Model for Physically-based Rendering*, 1994.

use std::f32::consts::PI;

use glam::Vec3A;

/// The GGX normal distribution `D(h)` (per steradian of microfacet normal), zero below the
/// surface. Written as `1 / (π α² k²)` with `k = (hx² + hy²)/α² + hz²`, which does not cancel
/// near `h = z` the way `(α² − 1) cos² + 1` does when α is tiny.
#[inline]
pub fn ggx_d(h: Vec3A, alpha: f32) -> f32 {
    if h.z <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let k = (h.x * h.x + h.y * h.y) / a2 + h.z * h.z;
    let d = 1.0 / (PI * a2 * k * k);
    if d.is_finite() {
        d
    } else {
        0.0
    }
}

/// Smith's Λ for GGX: `(√(1 + α² tan²θ) − 1) / 2`, computed as `a / (2 (√(1 + a) + 1))` with
/// `a = α² tan²θ` so a narrow lobe keeps its digits; infinite at the horizon.
#[inline]
pub fn ggx_lambda(w: Vec3A, alpha: f32) -> f32 {
    let z2 = w.z * w.z;
    let a = alpha * alpha * (w.x * w.x + w.y * w.y) / z2;
    if !a.is_finite() {
        return f32::INFINITY;
    }
    a / (2.0 * ((1.0 + a).sqrt() + 1.0))
}

/// Smith's masking `G1(w) = 1 / (1 + Λ(w))`.
#[inline]
pub fn ggx_g1(w: Vec3A, alpha: f32) -> f32 {
    1.0 / (1.0 + ggx_lambda(w, alpha))
}

/// Smith's height-correlated masking–shadowing `G2 = 1 / (1 + Λ(wo) + Λ(wi))` (Heitz 2014), for
/// reflection and for transmission alike (as pbrt-v4 and Walter et al. use it).
#[inline]
pub fn ggx_g2(wo: Vec3A, wi: Vec3A, alpha: f32) -> f32 {
    1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))
}

/// A microfacet normal from the distribution of normals visible from `wo` (`wo.z > 0`), from
/// two uniform numbers (Heitz 2018): density [`ggx_vndf_pdf`].
pub fn ggx_sample_vndf(wo: Vec3A, alpha: f32, u1: f32, u2: f32) -> Vec3A {
    // The view direction in the hemisphere configuration (α stretched to 1).
    let vh = Vec3A::new(alpha * wo.x, alpha * wo.y, wo.z).normalize_or(Vec3A::Z);
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 0.0 { Vec3A::new(-vh.y, vh.x, 0.0) / lensq.sqrt() } else { Vec3A::X };
    let t2 = vh.cross(t1);
    // A point on the projected disk, warped toward the visible half.
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    Vec3A::new(alpha * nh.x, alpha * nh.y, nh.z.max(0.0)).normalize_or(Vec3A::Z)
}

/// Density of [`ggx_sample_vndf`] per steradian of microfacet normal:
/// `G1(wo) max(0, wo·h) D(h) / wo.z`.
#[inline]
pub fn ggx_vndf_pdf(wo: Vec3A, h: Vec3A, alpha: f32) -> f32 {
    if wo.z <= 0.0 {
        return 0.0;
    }
    ggx_g1(wo, alpha) * wo.dot(h).max(0.0) * ggx_d(h, alpha) / wo.z
}

/// Schlick's Fresnel with reflectance `f0` at normal incidence and `f90` at grazing:
/// `f0 + (f90 − f0)(1 − cos)^5`, for `cos` in [0, 1] (clamped).
#[inline]
pub fn schlick(cos: f32, f0: Vec3A, f90: f32) -> Vec3A {
    let w = schlick_weight(cos);
    f0 * (1.0 - w) + Vec3A::splat(f90 * w)
}

/// `(1 − cos)^5`, the grazing weight of Schlick's approximation.
#[inline]
pub fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's Fresnel for an interface a ray may cross: `eta` is the index on the far side over
/// the index on the side `cos` is measured in (`cos = wo·h`, `wo` on the near side). Going into
/// a denser medium the usual form; going into a thinner one, Schlick's form at the cosine of the
/// *transmitted* angle (the angle in the thinner medium, where the approximation is made), and
/// 1 — total internal reflection — past the critical angle. At normal incidence it is `f0`
/// either way, as the exact Fresnel equations are.
#[inline]
pub fn schlick_dielectric(cos: f32, f0: Vec3A, f90: f32, eta: f32) -> Vec3A {
    let cos = cos.clamp(0.0, 1.0);
    if eta >= 1.0 {
        return schlick(cos, f0, f90);
    }
    let sin2_t = (1.0 - cos * cos) / (eta * eta);
    if sin2_t >= 1.0 {
        return Vec3A::ONE;
    }
    schlick((1.0 - sin2_t).sqrt(), f0, f90)
}

/// The exact Fresnel reflectance of unpolarized light at a dielectric interface (the closed
/// form the tests compare Schlick's with): `cos` on the incident side, `eta` = transmitted over
/// incident index. 1 at total internal reflection.
pub fn fresnel_dielectric_exact(cos: f32, eta: f32) -> f32 {
    let cos_i = cos.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// The refracted direction of `wo` (pointing away from the surface, `wo·h > 0`) through a
/// (micro)surface of normal `h` with `eta` = far index over near index; `None` at total
/// internal reflection. The result points into the far side.
#[inline]
pub fn refract(wo: Vec3A, h: Vec3A, eta: f32) -> Option<Vec3A> {
    let cos_i = wo.dot(h);
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    (-wo / eta + (cos_i / eta - cos_t) * h).try_normalize()
}

/// Grid size of the albedo tables, in each of `cos θo` and roughness.
pub(super) const ALBEDO_TABLE_SIZE: usize = 32;
const N: usize = ALBEDO_TABLE_SIZE;

/// The directional albedo of a GGX reflector with Schlick's Fresnel, tabulated: because
/// Schlick's form is linear in `f0` and `f90`, the albedo is `f0·A(μ, r) + f90·B(μ, r)` for two
/// scalar tables over `μ = cos θo` and roughness `r` (α = r²), and its cosine-weighted
/// hemispherical average `E_avg = 2∫ E(μ) μ dμ` is `f0·A_avg(r) + f90·B_avg(r)`.
///
/// Computed by importance sampling the visible normals with a 32 × 32 stratified pattern per
/// entry ([`AlbedoTable::compute`]): each sample's weight is `F · G2/G1`, so the estimates are
/// within about 1e-3 of the integral. The averages integrate the piecewise-linear interpolant
/// exactly, so they are consistent with the lookups: that is what makes [`super::preview`]'s
/// diffuse scaling conserve energy.
///
/// The table a render uses is that computation's output, stored in `albedo_table_data.rs`: the
/// million GGX samples cost about 190 M instructions (60 ms), which a render paid inside its
/// first tile, blocking every thread that shaded a glossy surface, on every run. A test
/// recomputes it and fails if the stored copy drifts.
pub struct AlbedoTable {
    a: [[f32; N]; N],
    b: [[f32; N]; N],
    a_avg: [f32; N],
    b_avg: [f32; N],
}

impl AlbedoTable {
    /// The shared table.
    #[inline]
    pub fn get() -> &'static AlbedoTable {
        static TABLE: AlbedoTable = AlbedoTable {
            a: super::albedo_table_data::A,
            b: super::albedo_table_data::B,
            a_avg: super::albedo_table_data::A_AVG,
            b_avg: super::albedo_table_data::B_AVG,
        };
        &TABLE
    }

    /// The table computed afresh (what `albedo_table_data.rs` stores; see the type's doc).
    pub fn compute() -> AlbedoTable {
        let mut t = AlbedoTable { a: [[0.0; N]; N], b: [[0.0; N]; N], a_avg: [0.0; N], b_avg: [0.0; N] };
        let strata = 32;
        for (j, (ra, rb)) in t.a.iter_mut().zip(t.b.iter_mut()).enumerate() {
            let r = j as f32 / (N - 1) as f32;
            let alpha = r * r;
            for i in 0..N {
                let mu = (i as f32 / (N - 1) as f32).max(1e-3);
                if j == 0 {
                    // The delta mirror reflects exactly Schlick's F at its own angle.
                    let w = schlick_weight(mu);
                    (ra[i], rb[i]) = (1.0 - w, w);
                    continue;
                }
                let wo = Vec3A::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let (mut sa, mut sb) = (0.0f64, 0.0f64);
                for p in 0..strata {
                    for q in 0..strata {
                        let u1 = (p as f32 + 0.5) / strata as f32;
                        let u2 = (q as f32 + 0.5) / strata as f32;
                        let h = ggx_sample_vndf(wo, alpha, u1, u2);
                        let cos_h = wo.dot(h);
                        let wi = 2.0 * cos_h * h - wo;
                        if wi.z <= 0.0 || cos_h <= 0.0 {
                            continue;
                        }
                        let weight = (ggx_g2(wo, wi, alpha) / ggx_g1(wo, alpha)) as f64;
                        let w = schlick_weight(cos_h) as f64;
                        sa += (1.0 - w) * weight;
                        sb += w * weight;
                    }
                }
                let n = (strata * strata) as f64;
                (ra[i], rb[i]) = ((sa / n) as f32, (sb / n) as f32);
            }
        }
        for j in 0..N {
            t.a_avg[j] = cosine_average(&t.a[j]);
            t.b_avg[j] = cosine_average(&t.b[j]);
        }
        t
    }

    /// Rust source of `albedo_table_data.rs` holding this table (`{:?}` prints an `f32` that
    /// reads back as the same value).
    #[cfg(test)]
    fn to_source(&self) -> String {
        use std::fmt::Write;
        let mut s = String::from(
            "//! The GGX albedo tables of [`super::microfacet::AlbedoTable`], as `AlbedoTable::compute` makes\n\
             //! them. Generated: `MIPRAY_WRITE_ALBEDO_TABLE=1 cargo test -p mipray --lib stored_albedo_table`.\n\n\
             use super::microfacet::ALBEDO_TABLE_SIZE as N;\n",
        );
        let row = |r: &[f32; N]| r.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>().join(", ");
        for (name, t) in [("A", &self.a), ("B", &self.b)] {
            let _ = writeln!(s, "\n#[rustfmt::skip]\npub(super) const {name}: [[f32; N]; N] = [");
            for r in t {
                let _ = writeln!(s, "    [{}],", row(r));
            }
            s.push_str("];\n");
        }
        for (name, t) in [("A_AVG", &self.a_avg), ("B_AVG", &self.b_avg)] {
            let _ = writeln!(s, "\n#[rustfmt::skip]\npub(super) const {name}: [f32; N] = [{}];", row(t));
        }
        s
    }

    /// `(A, B)` at `mu = cos θo` and `roughness`, bilinear.
    pub fn lookup(&self, mu: f32, roughness: f32) -> (f32, f32) {
        let (i, fi) = cell(mu);
        let (j, fj) = cell(roughness);
        let bil = |t: &[[f32; N]; N]| {
            let lo = t[j][i] * (1.0 - fi) + t[j][i + 1] * fi;
            let hi = t[j + 1][i] * (1.0 - fi) + t[j + 1][i + 1] * fi;
            lo * (1.0 - fj) + hi * fj
        };
        (bil(&self.a), bil(&self.b))
    }

    /// `(A_avg, B_avg)` at `roughness`: the cosine-weighted averages over `μ` of the lookups.
    pub fn average(&self, roughness: f32) -> (f32, f32) {
        let (j, fj) = cell(roughness);
        let lerp = |t: &[f32; N]| t[j] * (1.0 - fj) + t[j + 1] * fj;
        (lerp(&self.a_avg), lerp(&self.b_avg))
    }

    /// Directional albedo `f0·A + f90·B` per channel.
    pub fn albedo(&self, mu: f32, roughness: f32, f0: Vec3A, f90: f32) -> Vec3A {
        let (a, b) = self.lookup(mu, roughness);
        f0 * a + Vec3A::splat(f90 * b)
    }

    /// Hemispherical average albedo `f0·A_avg + f90·B_avg` per channel.
    pub fn average_albedo(&self, roughness: f32, f0: Vec3A, f90: f32) -> Vec3A {
        let (a, b) = self.average(roughness);
        f0 * a + Vec3A::splat(f90 * b)
    }
}

/// Index of the grid cell holding `x` in [0, 1] and the fraction within it.
#[inline]
fn cell(x: f32) -> (usize, f32) {
    let s = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) } * (N - 1) as f32;
    let i = (s as usize).min(N - 2);
    (i, s - i as f32)
}

/// `2 ∫₀¹ f(μ) μ dμ` of the piecewise-linear interpolant of `f` on the grid, exactly.
fn cosine_average(f: &[f32; N]) -> f32 {
    let h = 1.0 / (N - 1) as f64;
    let mut s = 0.0f64;
    for i in 0..N - 1 {
        let (x0, x1) = (i as f64 * h, (i + 1) as f64 * h);
        let (f0, f1) = (f[i] as f64, f[i + 1] as f64);
        s += h * (f0 * (2.0 * x0 + x1) + f1 * (x0 + 2.0 * x1)) / 6.0;
    }
    (2.0 * s) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sph(theta: f32, phi: f32) -> Vec3A {
        Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
    }

    /// ∫ D(h) cos θh dωh = 1 (the projected microfacet area is the macro surface), by a
    /// midpoint rule in (cos θ, φ) that resolves even a narrow lobe.
    #[test]
    fn ggx_d_is_normalized() {
        for alpha in [0.02f32, 0.1, 0.3, 0.7, 1.0] {
            // Substitute t = tan²θ/α² (D is a function of it) on a fine grid.
            let n = 20_000;
            let mut s = 0.0f64;
            for k in 0..n {
                // x in (0, 1) ↦ t = x/(1 − x): covers t ∈ (0, ∞).
                let x = (k as f64 + 0.5) / n as f64;
                let t = x / (1.0 - x);
                let dt_dx = 1.0 / ((1.0 - x) * (1.0 - x));
                let tan2 = t * (alpha as f64).powi(2);
                let cos2 = 1.0 / (1.0 + tan2);
                let cos = cos2.sqrt();
                let h = Vec3A::new((1.0 - cos2).sqrt() as f32, 0.0, cos as f32);
                // dω = sin θ dθ dφ; with u = cos θ, dω = du dφ; du/dt = −α² cos³/2 ... use
                // dω = 2π |du/dt| dt where u = (1 + α² t)^{-1/2}.
                let du_dt = 0.5 * (alpha as f64).powi(2) * (1.0 + tan2).powf(-1.5);
                s += ggx_d(h, alpha) as f64 * cos * 2.0 * std::f64::consts::PI * du_dt * dt_dx / n as f64;
            }
            assert!((s - 1.0).abs() < 2e-3, "alpha {alpha}: {s}");
        }
    }

    /// The visible-normal density integrates to 1 and matches the histogram of samples.
    #[test]
    fn vndf_samples_follow_their_density() {
        for (alpha, theta_o) in [(0.2f32, 0.3f32), (0.5, 1.2), (0.9, 0.7)] {
            let wo = sph(theta_o, 0.4);
            // Histogram in (cos θh, φ) bins against ∫ pdf over each bin.
            let (nb_t, nb_p) = (8usize, 8usize);
            let mut hist = vec![0u32; nb_t * nb_p];
            let k = 256;
            for a in 0..k {
                for b in 0..k {
                    let h = ggx_sample_vndf(wo, alpha, (a as f32 + 0.5) / k as f32, (b as f32 + 0.5) / k as f32);
                    assert!((h.length() - 1.0).abs() < 1e-4 && h.z >= 0.0 && wo.dot(h) >= -1e-5);
                    let ti = ((1.0 - h.z) * nb_t as f32).min(nb_t as f32 - 1.0) as usize;
                    let phi = h.y.atan2(h.x).rem_euclid(2.0 * PI);
                    let pi = (phi / (2.0 * PI) * nb_p as f32).min(nb_p as f32 - 1.0) as usize;
                    hist[ti * nb_p + pi] += 1;
                }
            }
            let mut total = 0.0f64;
            for ti in 0..nb_t {
                for pi in 0..nb_p {
                    let m = 40;
                    let mut mass = 0.0f64;
                    for a in 0..m {
                        for b in 0..m {
                            let u = 1.0 - (ti as f32 + (a as f32 + 0.5) / m as f32) / nb_t as f32;
                            let phi = (pi as f32 + (b as f32 + 0.5) / m as f32) / nb_p as f32 * 2.0 * PI;
                            let h = Vec3A::new((1.0 - u * u).sqrt() * phi.cos(), (1.0 - u * u).sqrt() * phi.sin(), u);
                            mass += ggx_vndf_pdf(wo, h, alpha) as f64;
                        }
                    }
                    mass *= (1.0 / nb_t as f64) * (2.0 * std::f64::consts::PI / nb_p as f64) / (m * m) as f64;
                    total += mass;
                    let got = hist[ti * nb_p + pi] as f64 / (k * k) as f64;
                    assert!((got - mass).abs() < 0.01 + 0.05 * mass, "α {alpha} bin ({ti},{pi}): {got} vs {mass}");
                }
            }
            assert!((total - 1.0).abs() < 0.01, "{total}");
        }
    }

    #[test]
    fn schlick_matches_its_closed_form_and_the_exact_fresnel_near_normal_incidence() {
        let f0 = ((1.0f32 - 1.5) / (1.0 + 1.5)).powi(2);
        for cos in [1.0f32, 0.9, 0.7, 0.5, 0.3, 0.1, 0.0] {
            let s = schlick(cos, Vec3A::splat(f0), 1.0).x;
            assert!((s - (f0 + (1.0 - f0) * (1.0 - cos).powi(5))).abs() < 1e-6);
            let exact = fresnel_dielectric_exact(cos, 1.5);
            // Schlick's known error for glass stays under 0.04 over the whole range.
            assert!((s - exact).abs() < 0.04, "cos {cos}: schlick {s} exact {exact}");
        }
        assert!((fresnel_dielectric_exact(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric_exact(0.0, 1.5) - 1.0).abs() < 1e-6);
        // Inside glass, going out: total internal reflection past asin(1/1.5) = 41.8°.
        let crit = (1.0f32 / 1.5).asin();
        let past = (crit + 0.01).cos();
        let before = (crit - 0.05).cos();
        assert_eq!(fresnel_dielectric_exact(past, 1.0 / 1.5), 1.0);
        assert_eq!(schlick_dielectric(past, Vec3A::splat(f0), 1.0, 1.0 / 1.5), Vec3A::ONE);
        let sb = schlick_dielectric(before, Vec3A::splat(f0), 1.0, 1.0 / 1.5).x;
        let eb = fresnel_dielectric_exact(before, 1.0 / 1.5);
        assert!(sb < 1.0 && (sb - eb).abs() < 0.1, "{sb} vs {eb}");
        assert!((schlick_dielectric(1.0, Vec3A::splat(f0), 1.0, 1.0 / 1.5).x - f0).abs() < 1e-6);
        // Snell's law and TIR for the refracted direction.
        let wo = sph(0.6, 0.0);
        let wt = refract(wo, Vec3A::Z, 1.5).unwrap();
        assert!((wt.z + (1.0 - (0.6f32.sin() / 1.5).powi(2)).sqrt()).abs() < 1e-5);
        assert!(((wt.x * wt.x + wt.y * wt.y).sqrt() * 1.5 - 0.6f32.sin()).abs() < 1e-5);
        assert!(refract(sph(crit + 0.01, 0.0), Vec3A::Z, 1.0 / 1.5).is_none());
    }

    /// The stored table is the computation's output (to rounding: the sampling runs through the
    /// platform's `sin`, `cos` and `sqrt`). Regenerate it with
    /// `MIPRAY_WRITE_ALBEDO_TABLE=1 cargo test -p mipray --lib stored_albedo_table`.
    #[test]
    fn stored_albedo_table_is_the_computed_one() {
        let fresh = AlbedoTable::compute();
        if std::env::var_os("MIPRAY_WRITE_ALBEDO_TABLE").is_some() {
            let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/bsdf/albedo_table_data.rs");
            std::fs::write(path, fresh.to_source()).expect("write albedo_table_data.rs");
        }
        let stored = AlbedoTable::get();
        let rows = |t: &AlbedoTable| -> Vec<f32> {
            t.a.iter().chain(t.b.iter()).flatten().chain(t.a_avg.iter()).chain(t.b_avg.iter()).copied().collect()
        };
        let (s, f) = (rows(stored), rows(&fresh));
        let worst = s.iter().zip(&f).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-6, "albedo_table_data.rs is stale: an entry differs by {worst}; regenerate it (see this test's doc)");
    }

    /// The table against an independent estimate (uniform hemisphere sampling of the BRDF).
    #[test]
    fn albedo_table_matches_brute_force_integration() {
        let t = AlbedoTable::get();
        for (mu, r) in [(0.9f32, 0.3f32), (0.5, 0.6), (0.2, 0.9), (0.7, 1.0)] {
            let alpha = r * r;
            let wo = Vec3A::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            let n = 400;
            let (mut ea, mut eb) = (0.0f64, 0.0f64);
            for a in 0..n {
                for b in 0..n {
                    let z = (a as f32 + 0.5) / n as f32;
                    let phi = (b as f32 + 0.5) / n as f32 * 2.0 * PI;
                    let s = (1.0 - z * z).sqrt();
                    let wi = Vec3A::new(s * phi.cos(), s * phi.sin(), z);
                    let h = (wo + wi).normalize();
                    let f = ggx_d(h, alpha) * ggx_g2(wo, wi, alpha) / (4.0 * mu);
                    let w = schlick_weight(wo.dot(h));
                    ea += ((1.0 - w) * f) as f64;
                    eb += (w * f) as f64;
                }
            }
            let dw = 2.0 * std::f64::consts::PI / (n * n) as f64;
            let (a, b) = t.lookup(mu, r);
            // The table's μ grid is 1/31 apart and r too: interpolation error dominates.
            assert!(
                (a as f64 - ea * dw).abs() < 0.01 && (b as f64 - eb * dw).abs() < 0.01,
                "μ {mu} r {r}: {a} {b} vs {} {}",
                ea * dw,
                eb * dw
            );
            assert!(a + b <= 1.0 + 1e-3);
        }
        // Smooth: A + B → 1 (the mirror loses nothing); the averages of the delta row in closed
        // form: A_avg = 1 − 1/21, B_avg = 1/21.
        let (a0, b0) = t.average(0.0);
        assert!((a0 - 20.0 / 21.0).abs() < 5e-3 && (b0 - 1.0 / 21.0).abs() < 5e-3, "{a0} {b0}");
    }
}
