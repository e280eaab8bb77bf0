//! Visibility queries through opacity cut-outs: whether a shadow, ambient-occlusion or
//! hemisphere ray is blocked, and by which surface, when some surfaces are cut out by
//! UsdPreviewSurface's `opacityThreshold` (masking: where `opacity` < `opacityThreshold` there is
//! no surface, as Storm discards the fragment).
//!
//! Camera and secondary rays already pass through cut-outs when they look for the surface they
//! shade ([`super::hemisphere::visible`]); these are the queries that only ask *whether* (or
//! *where*) light is stopped: shadow rays toward every kind of light (delta, area and dome,
//! light samples and BSDF samples alike, [`super::direct_light`]), ambient-occlusion rays
//! ([`super::hemisphere::Hemisphere::occlusion`]) and the hemisphere rays of the irradiance and
//! occlusion caches' records ([`super::hemisphere::gather`]).
//!
//! **How.** One any-hit ray first, as before: nothing in the way is the common case and costs
//! what it always did, and a hit on a material that can never be cut out
//! ([`crate::material::Material::may_cut_out`]) blocks without more work. Only when the any-hit
//! ray stops on a material that may be cut out is the ray marched from its start through its
//! closest hits: at each, the material's opacity is evaluated at the hit (a textured opacity
//! looked up at the hit's `st` with filter widths from the ray's own differential transferred
//! there, exactly as shading does, [`crate::material::Material::cut_out_at`]); where it is cut
//! out the same ray goes on from the hit — origin offset off the card by the hit's error bound
//! ([`crate::ray::offset_origin`]), the card's own other tessellations ignored near it
//! ([`Tracer::intersect_from`]), its beam as it arrived. No random numbers are drawn, so the
//! answer is a function of the ray alone. After [`MAX_CUTOUTS`] cut-out surfaces the ray is
//! taken as blocked and counted (`render.cutout_limit_rays` in the stats); every pass-through is
//! counted too (`render.cutout_passes`).
//!
//! **Partial opacity without a threshold** (`opacity` < 1, `opacityThreshold` 0) is not a
//! cut-out: the BSDF makes it glass, a dielectric that reflects and refracts, and the integrators
//! trace that transmission with refraction rays. Shadow rays, as in a classic ray tracer, do not
//! refract: a glass surface blocks them like any opaque one (its caustic is not simulated), so
//! a pane of opacity 0.3 casts a full shadow under a light while the camera sees through it.
//! With a threshold above 0, opacity at or above it is fully opaque (the BSDF takes opacity as
//! 1), and below it there is nothing at all.

use crate::differential::RayDifferential;
use crate::light::MeshFilter;
use crate::ray::{offset_origin, Ray};
use crate::trace::{Hit, TraceCounters, Tracer};

use super::{shading_point, ShadingPoint};

/// Most cut-out surfaces one ray passes through before it is taken as blocked (a stack of leaf
/// cards, say): a bound so a degenerate scene cannot loop, not physics.
pub const MAX_CUTOUTS: u32 = 64;

/// The first surface along a ray that is not cut out: the ray segment that reached it (after
/// any cut-outs), its hit, and its distance from the original ray's origin (render units along
/// the unit direction).
#[derive(Clone, Copy, Debug)]
pub struct Blocker {
    pub ray: Ray,
    pub hit: Hit,
    pub distance: f32,
}

/// Where `ray` hits a cut-out at `hit`: the same ray going on from the far side of the surface
/// (its remaining reach, its differential transferred to the hit). `None` where the surface is
/// there (not cut out).
pub fn pass_cutout(tracer: &Tracer<'_>, ray: &Ray, hit: &Hit, counters: &mut TraceCounters) -> Option<Ray> {
    let scene = tracer.scene();
    let material = scene.material_at(hit.mesh as usize, hit.patch as usize);
    if !material.may_cut_out() {
        return None;
    }
    let sp = shading_point(tracer, scene, ray, hit);
    let footprint = footprint_at(ray, hit, &sp, counters);
    let mesh = &scene.meshes[hit.mesh as usize];
    if !material.cut_out_at(mesh.surface.as_ref(), hit, &sp, &footprint) {
        return None;
    }
    Some(ray_beyond(ray, hit, &sp, footprint))
}

/// `ray`'s differential carried to `hit` (at shading point `sp`); a clamp is counted.
fn footprint_at(ray: &Ray, hit: &Hit, sp: &ShadingPoint, counters: &mut TraceCounters) -> RayDifferential {
    let (footprint, clamped) = ray.diff.transfer_checked(ray.d, hit.t, sp.ng);
    counters.differential_clamps += u64::from(clamped);
    footprint
}

/// The rest of `ray` past `hit` (at shading point `sp`, with the differential `footprint` it has
/// there): from just beyond the surface, for what is left of its length.
fn ray_beyond(ray: &Ray, hit: &Hit, sp: &ShadingPoint, footprint: RayDifferential) -> Ray {
    let o = offset_origin(sp.p, hit.p_error, sp.ng, ray.d);
    Ray { o, t_min: 0.0, t_max: ray.t_max - hit.t, diff: footprint, ..*ray }
}

/// True when a surface that is not cut out blocks `ray` (leaving the surface at `from`) within
/// its (t_min, t_max): [`Tracer::occluded_from`] through cut-outs (see the module doc). More
/// than [`MAX_CUTOUTS`] cut-outs along it: blocked.
pub fn occluded_from(tracer: &Tracer<'_>, ray: &Ray, from: &Hit, counters: &mut TraceCounters) -> bool {
    let Some(any) = tracer.any_hit_from(ray, from, counters) else { return false };
    let scene = tracer.scene();
    if !scene.material_at(any.mesh as usize, any.patch as usize).may_cut_out() {
        return true;
    }
    first_opaque_from(tracer, ray, from, counters).is_some()
}

/// The first surface along `ray` (leaving the surface at `from`) that is not cut out, within
/// its (t_min, t_max): [`Tracer::intersect_from`] through cut-outs. After [`MAX_CUTOUTS`]
/// cut-outs, the one that exceeds the bound is returned as the blocker.
pub fn first_opaque_from(tracer: &Tracer<'_>, ray: &Ray, from: &Hit, counters: &mut TraceCounters) -> Option<Blocker> {
    let (mut ray, mut from) = (*ray, *from);
    let mut distance = 0.0;
    let mut passed = 0u32;
    loop {
        let hit = tracer.intersect_from(&ray, &from, counters)?;
        let Some(next) = pass_cutout(tracer, &ray, &hit, counters) else {
            return Some(Blocker { ray, hit, distance: distance + hit.t });
        };
        if passed == MAX_CUTOUTS {
            counters.cutout_limit += 1;
            return Some(Blocker { ray, hit, distance: distance + hit.t });
        }
        passed += 1;
        counters.cutout_passes += 1;
        distance += hit.t;
        (ray, from) = (next, hit);
    }
}

/// As [`occluded_from`] for a shadow-linked light: only the meshes in `casters` block `ray`;
/// others are passed through like cut-outs (counted among `render.cutout_passes`, and bounded by
/// [`MAX_CUTOUTS`] with them).
pub fn occluded_by(tracer: &Tracer<'_>, ray: &Ray, from: &Hit, casters: &MeshFilter, counters: &mut TraceCounters) -> bool {
    let (mut ray, mut from) = (*ray, *from);
    let mut passed = 0u32;
    loop {
        let Some(hit) = tracer.intersect_from(&ray, &from, counters) else { return false };
        let next = if casters.contains(hit.mesh) {
            match pass_cutout(tracer, &ray, &hit, counters) {
                Some(next) => next,
                None => return true,
            }
        } else {
            // Not a caster of this light's shadows: passed as a cut-out is.
            let sp = shading_point(tracer, tracer.scene(), &ray, &hit);
            let footprint = footprint_at(&ray, &hit, &sp, counters);
            ray_beyond(&ray, &hit, &sp, footprint)
        };
        if passed == MAX_CUTOUTS {
            counters.cutout_limit += 1;
            return true;
        }
        passed += 1;
        counters.cutout_passes += 1;
        (ray, from) = (next, hit);
    }
}
