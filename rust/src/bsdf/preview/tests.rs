//! The preview-surface BSDF against truth: white furnaces, closed-form Fresnel, Monte Carlo
//! against quadrature, reciprocity, the delta limit, and finiteness everywhere.

use std::f32::consts::PI;

use glam::Vec3A;

use super::*;
use crate::bsdf::microfacet::fresnel_dielectric_exact;
use crate::sampling::Sampler;

fn surface(f: impl FnOnce(&mut PreviewSurface)) -> PreviewSurface {
    let mut s = PreviewSurface::default();
    f(&mut s);
    s
}

fn white_lambert() -> PreviewSurface {
    surface(|s| {
        s.diffuse_color = Vec3A::ONE;
        s.use_specular_workflow = true;
        s.specular_color = Vec3A::ZERO;
    })
}

fn white_metal(roughness: f32) -> PreviewSurface {
    surface(|s| {
        s.diffuse_color = Vec3A::ONE;
        s.metallic = 1.0;
        s.roughness = roughness;
    })
}

fn glass(roughness: f32, ior: f32) -> PreviewSurface {
    surface(|s| {
        s.diffuse_color = Vec3A::ONE;
        s.opacity = 0.0;
        s.roughness = roughness;
        s.ior = ior;
    })
}

/// wo at polar angle `theta` (radians) from +z.
fn dir(theta: f32, phi: f32) -> Vec3A {
    Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
}

fn bsdf(s: &PreviewSurface) -> PreviewSurfaceBsdf {
    PreviewSurfaceBsdf::new(s, Vec3A::Z, Vec3A::Z, true)
}

/// Mean sample weight (the directional albedo, `∫ f cos`) from `n × n` stratified samples, and
/// the same with refraction counted as flux (times η², undoing radiance compression).
fn mc_albedo(b: &PreviewSurfaceBsdf, wo: Vec3A, n: u32, seed: u64) -> (Vec3A, Vec3A) {
    let mut rng = Sampler::new(seed, 1, 2);
    let (mut sum, mut flux) = (Vec3A::ZERO, Vec3A::ZERO);
    for i in 0..n {
        for j in 0..n {
            let u = [rng.next_f32(), (i as f32 + rng.next_f32()) / n as f32, (j as f32 + rng.next_f32()) / n as f32];
            if let Some(s) = b.sample(wo, u) {
                assert!(s.weight.is_finite() && s.weight.min_element() >= 0.0, "{s:?}");
                sum += s.weight;
                let k = if s.lobe == Lobe::Transmission { 1.0 / (s.eta * s.eta) } else { 1.0 };
                flux += s.weight * k;
            }
        }
    }
    let m = (n * n) as f32;
    (sum / m, flux / m)
}

/// `∫ eval(wo, wi).total() dωi` and `∫ eval(wo, wi).pdf dωi` over the whole sphere by a midpoint
/// rule in (cos θ, φ).
fn quadrature(b: &PreviewSurfaceBsdf, wo: Vec3A, nt: usize, np: usize) -> (Vec3A, f32) {
    let (mut f, mut p) = (Vec3A::ZERO, 0.0f64);
    for a in 0..nt {
        let z = -1.0 + 2.0 * (a as f32 + 0.5) / nt as f32;
        let s = (1.0 - z * z).max(0.0).sqrt();
        for c in 0..np {
            let phi = (c as f32 + 0.5) / np as f32 * 2.0 * PI;
            let wi = Vec3A::new(s * phi.cos(), s * phi.sin(), z);
            let e = b.eval(wo, wi);
            f += e.total();
            p += e.pdf as f64;
        }
    }
    let dw = 4.0 * PI / (nt * np) as f32;
    (f * dw, (p * dw as f64) as f32)
}

#[test]
fn a_white_lambertian_preview_surface_is_exactly_lambert() {
    let b = bsdf(&white_lambert());
    let l = crate::bsdf::Lambertian { r: Vec3A::ONE, n: Vec3A::Z, ng: Vec3A::Z };
    assert_eq!(b.diffuse_reflectance(), Vec3A::ONE);
    assert!(!b.has_delta() && !b.has_glossy());
    for (to, ti) in [(0.1f32, 0.2f32), (0.8, 1.4), (1.5, 0.01), (0.0, 1.55)] {
        let (wo, wi) = (dir(to, 0.3), dir(ti, 2.0));
        let (e, r) = (b.eval(wo, wi), l.eval(wo, wi));
        assert!((e.diffuse - r.diffuse).abs().max_element() < 1e-6 && e.specular == Vec3A::ZERO, "{e:?} {r:?}");
        assert!((e.pdf - r.pdf).abs() < 1e-6);
        assert!((b.diffuse_albedo(wo) - Vec3A::ONE).abs().max_element() < 1e-6);
    }
    for theta in [0.0f32, 0.7, 1.3, 1.55] {
        let (a, _) = mc_albedo(&b, dir(theta, 0.0), 64, 1);
        assert!((a - Vec3A::ONE).abs().max_element() < 1e-4, "θ {theta}: {a}");
    }
}

#[test]
fn white_furnace_for_a_white_metal_across_roughness() {
    // Single-scattering GGX: ≤ 1 always; ≥ 0.9 for smooth and moderate roughness, less where
    // rough microfacets shadow each other (energy multiple scattering would return).
    for r in [0.0f32, 0.05, 0.2, 0.25, 0.35, 0.5, 0.75, 1.0] {
        let b = bsdf(&white_metal(r));
        for theta in [0.0f32, 0.5, 1.0, 1.3] {
            let (a, _) = mc_albedo(&b, dir(theta, 0.0), 48, 3);
            assert!(a.max_element() <= 1.0 + 5e-3, "r {r} θ {theta}: albedo {a}");
            if r <= 0.25 {
                assert!(a.min_element() >= 0.93, "r {r} θ {theta}: albedo {a}");
            } else if r <= 0.5 {
                assert!(a.min_element() >= 0.82, "r {r} θ {theta}: albedo {a}");
            }
            if r == 0.0 {
                assert!((a - Vec3A::ONE).abs().max_element() < 1e-6, "the white mirror reflects everything: {a}");
            }
        }
    }
    // Against an independent quadrature of the same single-scattering GGX (numpy, 1500 × 3000
    // directions, height-correlated Smith G2): (roughness, cos θo) → albedo.
    for (r, mu, truth) in
        [(0.25f32, 0.5f32, 0.9883f32), (0.5, 1.0, 0.9158), (0.5, 0.2, 0.8482), (0.75, 0.5, 0.6632), (1.0, 1.0, 0.3069), (1.0, 0.2, 0.6416)]
    {
        let b = bsdf(&white_metal(r));
        let (a, _) = mc_albedo(&b, Vec3A::new((1.0 - mu * mu).sqrt(), 0.0, mu), 96, 17);
        assert!((a.x - truth).abs() < 0.01, "r {r} μ {mu}: {} vs {truth}", a.x);
    }
}

#[test]
fn every_input_combination_conserves_energy() {
    // Plastic (with the energy-compensated diffuse), coated, mixed, specular workflow, glass:
    // directional albedo (flux) ≤ 1, by importance sampling with 64² samples.
    let cases: Vec<PreviewSurface> = vec![
        surface(|s| s.diffuse_color = Vec3A::ONE),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.roughness = 0.0;
        }),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.roughness = 0.9;
            s.ior = 3.0;
        }),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.clearcoat = 1.0;
            s.clearcoat_roughness = 0.0;
            s.roughness = 0.3;
        }),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.clearcoat = 1.0;
            s.clearcoat_roughness = 0.4;
            s.metallic = 0.5;
            s.roughness = 0.6;
        }),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.use_specular_workflow = true;
            s.specular_color = Vec3A::new(1.0, 0.5, 0.2);
            s.roughness = 0.25;
        }),
        surface(|s| {
            s.diffuse_color = Vec3A::ONE;
            s.opacity = 0.5;
            s.roughness = 0.4;
            s.clearcoat = 0.7;
        }),
        glass(0.0, 1.5),
        glass(0.3, 1.5),
        glass(0.7, 2.4),
        glass(0.5, 1.0),
    ];
    for (i, s) in cases.iter().enumerate() {
        for front in [true, false] {
            let b = PreviewSurfaceBsdf::new(s, Vec3A::Z, Vec3A::Z, front);
            for theta in [0.0f32, 0.6, 1.2, 1.5] {
                // 128² samples: the estimate's noise is well under the 1 % allowed.
                let (_, flux) = mc_albedo(&b, dir(theta, 1.0), 128, 5);
                assert!(flux.max_element() <= 1.0 + 0.01, "case {i} front {front} θ {theta}: {flux}");
            }
        }
    }
}

#[test]
fn smooth_glass_reflects_and_refracts_all_of_the_light_with_schlicks_fresnel() {
    let f0 = 0.04f32;
    for (front, eta) in [(true, 1.5f32), (false, 1.0 / 1.5)] {
        let b = PreviewSurfaceBsdf::new(&glass(0.0, 1.5), Vec3A::Z, Vec3A::Z, front);
        assert!(b.has_delta() && !b.has_glossy());
        for theta in [0.0f32, 0.3, 0.6, 0.7, 0.75, 1.0, 1.4] {
            let wo = dir(theta, 0.2);
            let [r, t] = b.delta_lobes(wo);
            let r = r.expect("glass always reflects");
            let cos = theta.cos();
            let expect_r = schlick_dielectric(cos, Vec3A::splat(f0), 1.0, eta).x;
            assert!((r.weight.x - expect_r).abs() < 1e-5, "{front} θ {theta}: R {} vs {expect_r}", r.weight.x);
            // Schlick near the exact Fresnel where both are defined.
            assert!((r.weight.x - fresnel_dielectric_exact(cos, eta)).abs() < 0.1);
            let tf = t.map_or(0.0, |t| t.weight.x * eta * eta);
            assert!((r.weight.x + tf - 1.0).abs() < 1e-5, "{front} θ {theta}: R {} + T {tf}", r.weight.x);
            if let Some(t) = t {
                // Snell's law, and eta is incident over transmitted index.
                assert!((t.eta - 1.0 / eta).abs() < 1e-6 && t.wi.z < 0.0);
                let sin_t = (1.0 - t.wi.z * t.wi.z).sqrt();
                assert!((sin_t * eta - theta.sin()).abs() < 1e-4, "Snell {sin_t}");
            }
            // sample() picks between them with the right expectation.
            let (_, flux) = mc_albedo(&b, wo, 64, 9);
            assert!((flux.x - 1.0).abs() < 1e-4, "{flux}");
        }
    }
}

#[test]
fn total_internal_reflection_inside_glass() {
    let b = PreviewSurfaceBsdf::new(&glass(0.0, 1.5), Vec3A::Z, Vec3A::Z, false);
    let crit = (1.0f32 / 1.5).asin();
    for theta in [crit + 0.01, 1.0, 1.5] {
        let wo = dir(theta, 0.0);
        let [r, t] = b.delta_lobes(wo);
        assert!(t.is_none(), "no refraction past the critical angle");
        assert!((r.unwrap().weight - Vec3A::ONE).abs().max_element() < 1e-6);
        for k in 0..16 {
            let s = b.sample(wo, [k as f32 / 16.0, 0.5, 0.5]).unwrap();
            assert!(s.lobe == Lobe::Specular && s.delta && (s.weight - Vec3A::ONE).abs().max_element() < 1e-6);
        }
    }
    // Rough glass: nothing refracts from microfacets past their critical angle either.
    let rough = PreviewSurfaceBsdf::new(&glass(0.2, 1.5), Vec3A::Z, Vec3A::Z, false);
    let (_, flux) = mc_albedo(&rough, dir(1.3, 0.0), 64, 4);
    assert!(flux.max_element() <= 1.0 + 0.01 && flux.min_element() > 0.8, "{flux}");
}

#[test]
fn sample_weights_are_eval_over_pdf_and_the_pdf_integrates_to_the_non_delta_share() {
    let cases = [
        surface(|s| s.roughness = 0.4),
        white_metal(0.3),
        surface(|s| {
            s.diffuse_color = Vec3A::new(0.8, 0.3, 0.1);
            s.clearcoat = 1.0;
            s.clearcoat_roughness = 0.3;
            s.roughness = 0.6;
        }),
        glass(0.4, 1.5),
        surface(|s| {
            s.opacity = 0.4;
            s.roughness = 0.5;
            s.metallic = 0.2;
        }),
    ];
    let mut rng = Sampler::new(11, 0, 0);
    for (i, s) in cases.iter().enumerate() {
        for front in [true, false] {
            let b = PreviewSurfaceBsdf::new(s, Vec3A::Z, Vec3A::Z, front);
            for theta in [0.2f32, 0.9, 1.35] {
                let wo = dir(theta, 0.5);
                for _ in 0..200 {
                    let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
                    let Some(smp) = b.sample(wo, u) else { continue };
                    assert!(!smp.delta);
                    let e = b.eval(wo, smp.wi);
                    assert!((e.pdf - smp.pdf).abs() <= 1e-3 * smp.pdf, "case {i}: pdf {} vs {}", e.pdf, smp.pdf);
                    let w = e.total() / e.pdf;
                    assert!((w - smp.weight).abs().max_element() <= 1e-3 * w.max_element().max(1e-3), "case {i}: {w} vs {}", smp.weight);
                }
                // No delta lobes: the pdf integrates to 1 less what falls below the horizon
                // (never more), and importance sampling estimates the same integral as quadrature.
                let (fq, pq) = quadrature(&b, wo, 600, 600);
                assert!(pq <= 1.0 + 0.01 && pq > 0.8, "case {i} θ {theta}: ∫pdf = {pq}");
                let (mc, _) = mc_albedo(&b, wo, 96, 13);
                assert!((mc - fq).abs().max_element() < 0.01 + 0.02 * fq.max_element(), "case {i} θ {theta}: MC {mc} vs quadrature {fq}");
            }
        }
    }
    // With a delta lobe, ∫pdf is the probability of picking a non-delta lobe.
    let b = bsdf(&surface(|s| {
        s.roughness = 0.0;
        s.diffuse_color = Vec3A::splat(0.5);
    }));
    let wo = dir(0.5, 0.0);
    let (_, pq) = quadrature(&b, wo, 400, 400);
    let mut delta = 0;
    let n = 4000;
    for k in 0..n {
        if b.sample(wo, [(k as f32 + 0.5) / n as f32, 0.3, 0.6]).is_some_and(|s| s.delta) {
            delta += 1;
        }
    }
    assert!((pq - (1.0 - delta as f32 / n as f32)).abs() < 0.01, "∫pdf {pq}, delta share {}", delta as f32 / n as f32);
}

#[test]
fn reflection_is_reciprocal() {
    let cases = [
        surface(|s| s.roughness = 0.3),
        white_metal(0.6),
        surface(|s| {
            s.diffuse_color = Vec3A::new(0.2, 0.6, 0.9);
            s.clearcoat = 0.8;
            s.clearcoat_roughness = 0.2;
            s.roughness = 0.5;
            s.metallic = 0.3;
        }),
        surface(|s| {
            s.use_specular_workflow = true;
            s.specular_color = Vec3A::new(0.9, 0.6, 0.1);
            s.roughness = 0.8;
        }),
    ];
    for s in &cases {
        let b = bsdf(s);
        for (to, po, ti, pi) in [(0.3f32, 0.0f32, 1.1f32, 2.0f32), (1.4, 1.0, 0.2, -2.5), (0.7, 0.1, 0.8, 3.0)] {
            let (a, c) = (dir(to, po), dir(ti, pi));
            // f(a→c) = f(c→a): divide out each call's own cos θi.
            let f1 = b.eval(a, c).total() / c.z;
            let f2 = b.eval(c, a).total() / a.z;
            assert!((f1 - f2).abs().max_element() <= 1e-4 * f1.max_element().max(1e-3), "{f1} vs {f2}");
        }
    }
}

#[test]
fn a_barely_rough_lobe_estimates_what_the_delta_lobe_gives() {
    // A smoothly varying environment: the glossy estimate at roughness 1e-3 converges to the
    // mirror's (and the smooth glass's) radiance.
    let env = |w: Vec3A| 1.0 + 0.5 * w.x + 0.3 * w.y * w.z + 0.2 * w.z;
    let lit = |b: &PreviewSurfaceBsdf, wo: Vec3A| {
        let mut rng = Sampler::new(5, 6, 7);
        let n = 20_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            if let Some(s) = b.sample(wo, [rng.next_f32(), rng.next_f32(), rng.next_f32()]) {
                sum += (s.weight.x * env(s.wi)) as f64;
            }
        }
        (sum / n as f64) as f32
    };
    for (smooth, rough) in [(white_metal(0.0), white_metal(DELTA_ROUGHNESS)), (glass(0.0, 1.5), glass(DELTA_ROUGHNESS, 1.5))] {
        let (bs, br) = (bsdf(&smooth), bsdf(&rough));
        assert!(bs.has_delta() && !br.has_delta() && br.has_glossy());
        for theta in [0.1f32, 0.8, 1.2] {
            let wo = dir(theta, 0.4);
            let (a, b) = (lit(&bs, wo), lit(&br, wo));
            assert!((a - b).abs() < 0.02 * a, "θ {theta}: delta {a} vs roughness 1e-3 {b}");
        }
    }
}

#[test]
fn no_nan_or_inf_anywhere() {
    let mut cases = Vec::new();
    for r in [0.0f32, 5e-4, 1e-3, 0.01, 1.0] {
        for ior in [1.0f32, 1.0001, 1.5, 1e-3, 50.0] {
            for opacity in [0.0f32, 0.5, 1.0] {
                for coat_r in [0.0f32, 0.3] {
                    cases.push(surface(|s| {
                        s.roughness = r;
                        s.ior = ior;
                        s.opacity = opacity;
                        s.clearcoat = 1.0;
                        s.clearcoat_roughness = coat_r;
                        s.metallic = 0.5;
                        s.diffuse_color = Vec3A::new(1.0, 0.0, 0.5);
                    }));
                }
            }
        }
    }
    cases.push(surface(|s| {
        s.use_specular_workflow = true;
        s.specular_color = Vec3A::ONE;
        s.diffuse_color = Vec3A::ONE;
        s.roughness = 0.0;
    }));
    // Shading normal bent away from the geometric one, as normal maps do.
    let normals = [(Vec3A::Z, Vec3A::Z), (Vec3A::new(0.6, 0.0, 0.8), Vec3A::Z), (Vec3A::new(0.0, 0.999, 0.0447).normalize(), Vec3A::Z)];
    let mut dirs = Vec::new();
    for t in [0.0f32, 0.5, 1.2, PI / 2.0 - 1e-4, PI / 2.0, PI / 2.0 + 1e-4, 2.0, PI] {
        for p in [0.0f32, 1.0, 3.0] {
            dirs.push(dir(t, p));
        }
    }
    let mut rng = Sampler::new(1, 1, 1);
    for s in &cases {
        for &(n, ng) in &normals {
            for front in [true, false] {
                let b = PreviewSurfaceBsdf::new(s, n, ng, front);
                let dr = b.diffuse_reflectance();
                assert!(dr.is_finite() && dr.min_element() >= 0.0);
                for &wo in &dirs {
                    assert!(b.diffuse_albedo(wo).is_finite());
                    for &wi in &dirs {
                        let e = b.eval(wo, wi);
                        assert!(
                            e.total().is_finite() && e.total().min_element() >= 0.0 && e.pdf.is_finite() && e.pdf >= 0.0,
                            "{s:?} {wo} {wi}: {e:?}"
                        );
                    }
                    for _ in 0..8 {
                        if let Some(x) = b.sample(wo, [rng.next_f32(), rng.next_f32(), rng.next_f32()]) {
                            assert!(x.weight.is_finite() && x.weight.min_element() >= 0.0 && x.pdf.is_finite() && x.pdf > 0.0, "{x:?}");
                            assert!(x.wi.is_finite() && (x.wi.length() - 1.0).abs() < 1e-3 && x.eta.is_finite() && x.eta > 0.0);
                        }
                        if let Some(g) = b.sample_glossy(wo, [rng.next_f32(), rng.next_f32(), rng.next_f32()]) {
                            assert!(g.sample.weight.is_finite() && g.lobe_half_angle_rad.is_finite());
                        }
                    }
                    for d in b.delta_lobes(wo).into_iter().flatten() {
                        assert!(d.weight.is_finite() && d.wi.is_finite());
                    }
                }
            }
        }
    }
}

#[test]
fn glossy_sampling_covers_only_the_rough_non_diffuse_lobes() {
    // A coated plastic: glossy samples weigh the specular and coat value, never the diffuse; the
    // mean of glossy weights plus the diffuse albedo is the full albedo.
    let s = surface(|s| {
        s.diffuse_color = Vec3A::new(0.5, 0.4, 0.3);
        s.roughness = 0.4;
        s.clearcoat = 0.6;
        s.clearcoat_roughness = 0.2;
    });
    let b = bsdf(&s);
    let wo = dir(0.6, 0.0);
    let n = 128;
    let mut g = Vec3A::ZERO;
    for i in 0..n {
        for j in 0..n {
            let u = [(i as f32 + 0.5) / n as f32, (j as f32 + 0.37) / n as f32, ((i * 7 + j * 13) % n) as f32 / n as f32];
            if let Some(x) = b.sample_glossy(wo, u) {
                assert!(x.sample.lobe == Lobe::Glossy && !x.sample.delta);
                g += x.sample.weight;
            }
        }
    }
    g /= (n * n) as f32;
    let (full, _) = mc_albedo(&b, wo, 128, 21);
    let diffuse = b.diffuse_albedo(wo);
    // diffuse_albedo uses the coat's average on the light side: a small approximation.
    assert!((g + diffuse - full).abs().max_element() < 0.01, "glossy {g} + diffuse {diffuse} vs {full}");
    // A lambertian has nothing glossy.
    assert!(bsdf(&white_lambert()).sample_glossy(wo, [0.5; 3]).is_none());
}
