//! Integrals over the hemisphere above a shading point: ambient occlusion. Hemisphere rays are
//! wide and incoherent (the paper's §4.6), so they read coarse tessellations.

use crate::differential::RayDifferential;
use crate::ray::{offset_origin, Ray, RayKind};
use crate::sampling::{cosine_hemisphere, frame, Sampler};
use crate::trace::{Hit, TraceCounters, Tracer};

use super::ShadingPoint;

/// Ambient occlusion's settings: rays per shading point and how far they look.
#[derive(Clone, Copy, Debug)]
pub struct Hemisphere {
    pub samples: u32,
    /// World units; infinite for unbounded.
    pub distance: f32,
}

impl Hemisphere {
    /// The unoccluded fraction of the cosine-weighted hemisphere within `ao_distance`, from
    /// `ao_samples` rays whose spread is √(1/(N·p(ω))) (the paper's §4.6): wide near the
    /// horizon, narrower at the pole.
    pub fn occlusion(
        &self,
        tracer: &Tracer<'_>,
        sp: &ShadingPoint,
        hit: &Hit,
        footprint: &RayDifferential,
        sampler: &mut Sampler,
        counters: &mut TraceCounters,
    ) -> f32 {
        let (t, b) = frame(sp.ns);
        let n = self.samples;
        let mut open = 0u32;
        for _ in 0..n {
            let (local, pdf) = cosine_hemisphere(sampler.next_f32(), sampler.next_f32());
            let d = t * local.x + b * local.y + sp.ns * local.z;
            if d.dot(sp.ng) <= 0.0 {
                continue;
            }
            let (diff, clamped) = footprint.hemisphere_checked(d, pdf, n);
            counters.differential_clamps += u64::from(clamped);
            let r = Ray { o: offset_origin(sp.p, hit.p_error, sp.ng, d), d, t_min: 0.0, t_max: self.distance, diff, kind: RayKind::Ao, time: hit.time };
            if !tracer.occluded_from(&r, hit, counters) {
                open += 1;
            }
        }
        open as f32 / n as f32
    }
}
