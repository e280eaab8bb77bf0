//! Portals (UsdLux `PortalLight`): rects through which a dome's light enters an interior, used
//! to guide the dome's light sampling.
//!
//! **What a portal changes.** Only *how* the dome is sampled, never what it contributes: a dome
//! with portals still sends its radiance along every direction, and its light-sampling density
//! is the mixture
//!
//! p(ω) = Q · Σₖ Pₖ(x) pₖ(x, ω) + (1 − Q) · p_dome(ω),
//!
//! where pₖ is uniform area sampling of portal k converted to solid angle
//! (dist² / (cos · area)), Pₖ(x) the probability of choosing portal k at x (∝ the solid angle it
//! subtends there), p_dome the dome's own strategy (its importance table, or cosine about the
//! normal) and Q = [`PORTAL_FRACTION`] when some portal faces x (0 otherwise). The mixture keeps
//! every direction the dome lights at a positive density, so the estimator stays unbiased on
//! its own — for light-sampling-only paths too (a shadow-linked dome, an integrator without
//! BSDF samples) and when the portals do not cover every opening. The alternative Karma and
//! RenderMan take (light sampling only through portals, the rest of the dome left to BSDF
//! rays) would be biased on those paths. The price is the (1 − Q) share of light samples drawn
//! as without portals.
//!
//! A portal passes light along its `normal` (the light's −Z, like a rect light's emission): it
//! guides points on that side only.

use std::f32::consts::PI;

use glam::Vec3A;

/// The share of a portal-guided dome's light samples drawn through its portals (where some
/// portal faces the shading point).
pub const PORTAL_FRACTION: f32 = 0.75;

/// A UsdLux.PortalLight in render space: the parallelogram `center ± u ± v` (half-extent
/// vectors: the light's X × width/2 and Y × height/2), passing light along unit `normal` (its
/// −Z).
#[derive(Clone, Debug, PartialEq)]
pub struct Portal {
    /// Prim path, for stats and messages.
    pub name: String,
    pub center: Vec3A,
    pub u: Vec3A,
    pub v: Vec3A,
    pub normal: Vec3A,
}

impl Portal {
    /// Area, render units².
    pub fn area(&self) -> f32 {
        4.0 * self.u.cross(self.v).length()
    }

    /// An estimate of the solid angle (sr) the portal subtends from `p`, 0 when `p` is not on
    /// the side the portal lets light into (or the portal is degenerate): the weight by which
    /// portals are chosen at `p`.
    pub fn weight(&self, p: Vec3A) -> f32 {
        let d = p - self.center;
        let h = self.normal.dot(d);
        let d2 = d.length_squared();
        let area = self.area();
        if !(h > 0.0 && d2 > 0.0 && area > 0.0) {
            return 0.0;
        }
        // area · cos / dist², capped at a hemisphere (a point close to a large portal).
        let w = (area * h / (d2 * d2.sqrt())).min(2.0 * PI);
        if w.is_finite() {
            w
        } else {
            0.0
        }
    }

    /// A unit direction from `p` through a uniformly chosen point of the portal, from two
    /// uniform numbers, and its solid-angle density; `None` when `p` is not in front.
    pub fn sample(&self, p: Vec3A, u1: f32, u2: f32) -> Option<(Vec3A, f32)> {
        let y = self.center + self.u * (2.0 * u1 - 1.0) + self.v * (2.0 * u2 - 1.0);
        let d = y - p;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0 && dist2.is_finite()) {
            return None;
        }
        let wi = d / dist2.sqrt();
        let cos = -self.normal.dot(wi);
        let pdf = dist2 / (cos * self.area());
        (cos > 0.0 && pdf.is_finite() && pdf > 0.0).then_some((wi, pdf))
    }

    /// The solid-angle density [`Portal::sample`] gives unit `wi` from `p`: 0 unless the ray
    /// crosses the portal from its front.
    pub fn pdf(&self, p: Vec3A, wi: Vec3A) -> f32 {
        let cos = -self.normal.dot(wi);
        if !(cos > 0.0) {
            return 0.0;
        }
        let t = self.normal.dot(p - self.center) / cos;
        if !(t > 0.0 && t.is_finite()) {
            return 0.0;
        }
        let q = p + wi * t - self.center;
        let (uu, uv, vv) = (self.u.dot(self.u), self.u.dot(self.v), self.v.dot(self.v));
        let det = uu * vv - uv * uv;
        if !(det > 0.0) {
            return 0.0;
        }
        let (qu, qv) = (q.dot(self.u), q.dot(self.v));
        let a = (qu * vv - qv * uv) / det;
        let b = (qv * uu - qu * uv) / det;
        if !(a.abs() <= 1.0 && b.abs() <= 1.0) {
            return 0.0;
        }
        let pdf = t * t / (cos * self.area());
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }
}

/// The portals guiding one dome light at a point: which to choose and with what probability
/// (weights recomputed as needed rather than stored: no allocation per light sample).
pub(crate) struct PortalChoice<'a> {
    portals: &'a [Portal],
    p: Vec3A,
    total: f32,
}

impl<'a> PortalChoice<'a> {
    pub(crate) fn at(portals: &'a [Portal], p: Vec3A) -> Self {
        PortalChoice { portals, p, total: portals.iter().map(|q| q.weight(p)).sum() }
    }

    /// The share Q of light samples drawn through portals here (0 when none faces the point).
    pub(crate) fn fraction(&self) -> f32 {
        if self.total > 0.0 {
            PORTAL_FRACTION
        } else {
            0.0
        }
    }

    /// A direction through a portal chosen by weight, from uniform `u1` (reused within the
    /// chosen portal's share) and `u2`.
    pub(crate) fn sample(&self, u1: f32, u2: f32) -> Option<Vec3A> {
        if !(self.total > 0.0) {
            return None;
        }
        let target = u1 * self.total;
        let mut acc = 0.0;
        let mut pick = None;
        for (k, q) in self.portals.iter().enumerate() {
            let w = q.weight(self.p);
            if w > 0.0 {
                pick = Some((k, ((target - acc) / w).clamp(0.0, 1.0 - f32::EPSILON)));
                if target < acc + w {
                    break;
                }
                acc += w;
            }
        }
        let (k, u) = pick?;
        self.portals[k].sample(self.p, u, u2).map(|(wi, _)| wi)
    }

    /// Σₖ Pₖ pₖ(`wi`): the density of [`PortalChoice::sample`] (overlapping portals add).
    pub(crate) fn pdf(&self, wi: Vec3A) -> f32 {
        if !(self.total > 0.0) {
            return 0.0;
        }
        self.portals
            .iter()
            .map(|q| {
                let w = q.weight(self.p);
                if w > 0.0 {
                    w / self.total * q.pdf(self.p, wi)
                } else {
                    0.0
                }
            })
            .sum()
    }
}
