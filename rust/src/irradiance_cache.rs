//! Irradiance and occlusion caching with gradients: the paper's §5.1 ("to avoid hemisphere
//! sampling from all shading points, we use interpolation of irradiance using irradiance
//! gradients and, similarly, interpolation of ambient occlusion using occlusion gradients").
//!
//! # What a record is
//! A hemisphere integral computed once, at a point `pᵢ` with unit normal `nᵢ` (render space),
//! from `M × N` cosine-weighted rays stratified in (sin²θ, φ) — M strata in θ, N ≈ πM in φ
//! ([`Strata`]) — and reused nearby (Ward, Rubinstein & Clear 1988):
//!
//! - `value`: the cosine-weighted mean of what the rays brought back, `(1/MN) Σ L_jk`. For ambient
//!   occlusion `L` is 1 for a ray that escapes within `aoDistance` and 0 for one that is blocked,
//!   so the value is the unoccluded fraction; for one-bounce color bleeding `L` is the radiance the
//!   ray finds (linear RGB), and the value is the indirect irradiance over π, `E/π` — what a
//!   lambertian surface multiplies by its diffuse reflectance to get outgoing radiance.
//! - `R`: the harmonic mean of the rays' hit distances, `MN / Σ 1/d_jk`, world units: how far
//!   away the things that change the integral are. Rays that hit nothing count 1/d = 0 — or,
//!   with a finite `aoDistance`, as hits at that distance, since what lies beyond changes nothing
//!   until it comes within reach. `R` is limited so that the translational gradient cannot
//!   change the value by more than the error bound's share of it within the validity radius
//!   (`R ≤ value / ‖∇ₜ‖`, Křivánek et al. 2006's gradient limit), then clamped so that the
//!   validity radius `a·R` stays within [`MIN_SPACING_PX`] and [`MAX_SPACING_PX`] pixel
//!   footprints at the record (records never closer than about a pixel — the image cannot show
//!   more — nor farther apart than a fixed fraction of the image).
//! - gradients (Ward & Heckbert 1992), per colour channel, from the same rays: the translational
//!   gradient `∇ₜ` from how the boundaries between neighbouring strata move as the point moves
//!   (each boundary weighted by the nearer of its two rays' hit distances), and the rotational
//!   gradient `∇ᵣ` from how each ray's cosine changes as the normal tilts.
//!
//! # Interpolation
//! At a point `p` with normal `n`, record `i` is valid when Ward's error estimate
//! `εᵢ = ‖p − pᵢ‖/Rᵢ + √(1 − n·nᵢ)` is below the error bound `a` (`irradianceCacheError`),
//! i.e. its weight `wᵢ = 1/εᵢ > 1/a`, and `pᵢ` is not in front of `p` (Ward's test against
//! records on an occluder above a crevice). The value is
//! `Σ wᵢ (valueᵢ + (nᵢ × n)·∇ᵣᵢ + (p − pᵢ)·∇ₜᵢ) / Σ wᵢ`, each record's extrapolation clamped to the
//! quantity's range (occlusion in [0, 1], irradiance ≥ 0). Where no record is valid the
//! integrator samples the hemisphere directly, as without the cache (the "fallback").
//!
//! # Determinism: a pre-pass, then a read-only cache
//! Ward's original cache grows during rendering — whichever thread gets to a point first adds a
//! record there, so the image would depend on thread scheduling. Here the records are made
//! before any pixel is rendered, by [`IrradianceCache::build`], from the camera rays through the
//! pixel centres (sample 0 of every pixel), in a fixed order:
//!
//! 1. Pixels are visited coarse to fine: first every [`PREPASS_SPACING_PX`]-th pixel in x and y,
//!    then the pixels that halve that spacing, and so on down to every pixel. Each level is split
//!    into phases by the parity of the pixel's coordinates in that level's grid (four phases at
//!    the coarsest level, three at each finer one), so that the points of one phase are two grid
//!    steps apart.
//! 2. In a phase, the points are found in parallel (camera ray, hit, shading point) and tested
//!    in parallel against the records of the earlier phases, which do not change during the
//!    phase. The points no record covers get a new record each, computed in parallel with a
//!    random stream that depends only on (seed, pixel); the new records are appended in pixel
//!    order.
//!
//! Every decision thus depends on the records of earlier phases only, never on which thread ran
//! first: the cache, and the image, are a function of the seed. The render pass only reads it.
//! Points the pre-pass never saw (the jittered samples of other camera rays, points seen in
//! mirrors) use the records when one is valid there and sample directly otherwise. With motion
//! blur the records see the scene at mid-shutter; with depth of field, through the lens centre.
//!
//! As each record is appended its `R` is clamped against the records already made in the screen
//! tiles around it, both ways (`Rᵢ ≤ Rⱼ + ‖pᵢ − pⱼ‖`, Křivánek et al. 2006's neighbour clamping):
//! a record in the open, whose harmonic mean hardly sees a wall at the edge of its reach, cannot
//! stay valid up to a neighbour beside that wall. Insertion order is fixed, so this too is
//! deterministic.
//!
//! # How this relates to the paper
//! PRMan interpolates on REYES grids: the shading points of a micropolygon grid are known to lie
//! on one surface, so it samples the hemisphere at some grid vertices and interpolates between
//! them in the grid's parameter space. A ray tracer's shading points are disconnected points in
//! 3-D, so this cache interpolates in 3-D instead, with Ward's error metric deciding which records
//! belong to the same smooth piece of the integral (distance relative to the harmonic-mean
//! distance, and normal difference), and a spatial index (a multi-level hashed grid) to find them.
//! The gradients play the role they play in the paper: they let records be sparse where the
//! integral changes smoothly, because first-order changes are extrapolated instead of sampled.
//! The hemisphere rays that make a record are §4.6's wide rays (their differentials come from
//! [`crate::differential::RayDifferential::hemisphere_checked`]), so they read coarse tessellations.

use std::collections::HashMap;
use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use glam::Vec3A;
use rayon::prelude::*;
use serde_json::{json, Value};

use crate::sampling::cosine_hemisphere;
use crate::trace::TraceCounters;

/// Smallest validity radius `a·R` of a record, in pixel footprints (the camera ray's beam width at
/// the record): closer records would resolve detail below a pixel.
pub const MIN_SPACING_PX: f32 = 1.0;
/// Largest validity radius `a·R`, in pixel footprints: even an unoccluded plane gets a record every
/// so many pixels, so that distant geometry the harmonic mean underweights is still sampled.
pub const MAX_SPACING_PX: f32 = 32.0;
/// Pixel spacing of the pre-pass's coarsest grid (a power of two).
pub const PREPASS_SPACING_PX: usize = 32;

/// What a cache holds; it decides the range extrapolated values are clamped to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// Ambient occlusion: the unoccluded fraction of the cosine-weighted hemisphere, in [0, 1]
    /// (stored in all three channels).
    Occlusion,
    /// Irradiance over π (linear RGB, ≥ 0): one-bounce indirect diffuse light.
    Irradiance,
}

impl Quantity {
    /// The stats name.
    pub const fn name(self) -> &'static str {
        match self {
            Quantity::Occlusion => "occlusion",
            Quantity::Irradiance => "irradiance",
        }
    }

    fn clamp(self, v: Vec3A) -> Vec3A {
        match self {
            Quantity::Occlusion => v.clamp(Vec3A::ZERO, Vec3A::ONE),
            Quantity::Irradiance => v.max(Vec3A::ZERO),
        }
    }
}

/// The stratification of a hemisphere integral: `theta` strata in sin²θ (so each holds the same
/// share of the cosine-weighted hemisphere) by `phi` strata in azimuth (Ward & Heckbert's M × N).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Strata {
    pub theta: u32,
    pub phi: u32,
}

impl Strata {
    /// The largest `M × N ≤ rays` with `M` near `√(rays/π)` (Ward & Heckbert: N ≈ πM), `rays`
    /// taken as at least 1: 16 → 2 × 8, 64 → 4 × 16, 256 → 9 × 28.
    pub fn for_rays(rays: u32) -> Strata {
        let rays = rays.max(1);
        let ideal = (rays as f32 / PI).sqrt();
        let lo = (ideal.floor() as u32).max(1);
        let mut best = Strata { theta: 1, phi: rays };
        let mut best_count = 0;
        for m in [lo, lo + 1] {
            let s = Strata { theta: m, phi: rays / m };
            if s.phi >= 1 && s.rays() > best_count {
                best = s;
                best_count = s.rays();
            }
        }
        best
    }

    /// Rays in all: `theta × phi`.
    pub const fn rays(self) -> u32 {
        self.theta * self.phi
    }

    /// The direction of ray `(j, k)` — θ stratum `j`, φ stratum `k` — jittered within its stratum
    /// by `(u1, u2)` ∈ [0, 1)², in the local frame whose +Z is the normal, and its density
    /// cos θ / π per steradian.
    pub fn direction(self, j: u32, k: u32, u1: f32, u2: f32) -> (Vec3A, f32) {
        cosine_hemisphere((j as f32 + u1) / self.theta as f32, (k as f32 + u2) / self.phi as f32)
    }

    /// Index of ray `(j, k)` in a slice of [`Strata::rays`] rays: φ stratum major.
    pub const fn index(self, j: u32, k: u32) -> usize {
        (k * self.theta + j) as usize
    }
}

/// What one hemisphere ray of a record found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HemisphereRay {
    /// Unit direction in the record's local frame (+Z the normal).
    pub dir: Vec3A,
    /// Distance to what the ray hit, world units; infinite when it hit nothing (or was not
    /// traced because it pointed below the geometric surface).
    pub distance: f32,
    /// What the ray brought back: 1 or 0 for occlusion (in every channel), radiance for
    /// irradiance.
    pub value: Vec3A,
}

/// A hemisphere integral and its gradients, in render space: what a record is made of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HemisphereEstimate {
    /// `(1/MN) Σ L`: unoccluded fraction, or irradiance over π.
    pub value: Vec3A,
    /// Harmonic mean of the hit distances (world units; infinite when nothing was hit).
    pub harmonic_distance: f32,
    /// Translational gradient of each channel of `value`, per world unit.
    pub grad_t: [Vec3A; 3],
    /// Rotational gradient of each channel: the change of `value` per radian of rotation of the
    /// normal about each axis ([`Record::extrapolate`] dots it with `nᵢ × n`).
    pub grad_r: [Vec3A; 3],
}

/// The integral over the hemisphere of normal `n` (with tangents `t`, `b`: the frame the rays'
/// local directions are in) from its stratified rays, with Ward & Heckbert's gradients.
/// `rays` holds [`Strata::rays`] rays in [`Strata::index`] order.
///
/// The translational gradient (Ward & Heckbert 1992, eq. for `∇ₜE`, divided by π as `value` is
/// `E/π`): for each φ stratum `k`, along its centre direction `u_k`, the boundaries between θ
/// strata `j−1` and `j` at `sin²θ = j/M` move by `δ cos θ / R` when the point moves by `δ`, which
/// sweeps `(2π/N) sin θ cos²θ δ / R` of cosine-weighted solid angle from one stratum to the other;
/// and along `v_k` (perpendicular to the boundary at `φ = 2πk/N`), the boundary between φ strata
/// `k−1` and `k` sweeps `(sin θ_{j+1} − sin θ_j) δ / R`. `R` is the nearer of the two rays'
/// distances (the nearer surface moves more in angle). The rotational gradient: tilting the
/// normal by `ω` changes each ray's cosine by `sin θ (ω · v(φ))`, so
/// `∇ᵣ = (1/MN) Σ L tan θ v(φ)`; `tan θ` is capped at its value half a stratum from the horizon
/// (one jittered ray grazing the horizon would otherwise dominate).
///
/// Ward & Heckbert's translational estimate weights each boundary by its own angle and the
/// nearer ray's distance rather than by where the edge between the two rays really is, so it is
/// biased by O(1/M) (15% at 9 × 28 strata beside a wall, 4% at 36 × 113: see the tests) and
/// overestimates where a plane recedes to its horizon; the gradient limit on `R` keeps what that
/// costs within the error bound.
pub fn estimate(strata: Strata, rays: &[HemisphereRay], t: Vec3A, b: Vec3A, n: Vec3A) -> HemisphereEstimate {
    let (m, nphi) = (strata.theta, strata.phi);
    let count = strata.rays() as usize;
    debug_assert_eq!(rays.len(), count);
    let rays = &rays[..count.min(rays.len())];
    let mut value = Vec3A::ZERO;
    let mut inv_d = 0.0f64;
    // Rotational gradient in the local frame, one Vec3A of (x, y) components per channel.
    let mut grad_r = [Vec3A::ZERO; 3];
    let min_cos = (0.5 / m as f32).sqrt();
    for r in rays {
        value += r.value;
        if r.distance.is_finite() && r.distance > 0.0 {
            inv_d += 1.0 / f64::from(r.distance);
        }
        let z = r.dir.z.max(min_cos);
        // tan θ · v(φ) = (−sin φ, cos φ, 0) · sin θ / cos θ.
        let tv = Vec3A::new(-r.dir.y, r.dir.x, 0.0) / z;
        for (c, g) in grad_r.iter_mut().enumerate() {
            *g += tv * r.value[c];
        }
    }
    let inv_count = 1.0 / count.max(1) as f32;
    value *= inv_count;
    for g in &mut grad_r {
        *g *= inv_count;
    }
    let harmonic_distance = if inv_d > 0.0 { (count as f64 / inv_d) as f32 } else { f32::INFINITY };

    // Translational gradient, local frame.
    let mut grad_t = [Vec3A::ZERO; 3];
    let nearer = |a: &HemisphereRay, b: &HemisphereRay| a.distance.min(b.distance).max(1e-12);
    for k in 0..nphi {
        let phi_c = 2.0 * PI * (k as f32 + 0.5) / nphi as f32;
        let u_k = Vec3A::new(phi_c.cos(), phi_c.sin(), 0.0);
        let phi_b = 2.0 * PI * k as f32 / nphi as f32;
        let v_k = Vec3A::new(-phi_b.sin(), phi_b.cos(), 0.0);
        let mut radial = Vec3A::ZERO;
        for j in 1..m {
            let (lo, hi) = (&rays[strata.index(j - 1, k)], &rays[strata.index(j, k)]);
            let s2 = j as f32 / m as f32;
            let (sin, cos2) = (s2.sqrt(), 1.0 - s2);
            radial += (hi.value - lo.value) * (sin * cos2 / nearer(lo, hi));
        }
        let mut azimuthal = Vec3A::ZERO;
        let k_prev = (k + nphi - 1) % nphi;
        if nphi > 1 {
            for j in 0..m {
                let (prev, cur) = (&rays[strata.index(j, k_prev)], &rays[strata.index(j, k)]);
                let dsin = ((j + 1) as f32 / m as f32).sqrt() - (j as f32 / m as f32).sqrt();
                azimuthal += (cur.value - prev.value) * (dsin / nearer(prev, cur));
            }
        }
        for (c, g) in grad_t.iter_mut().enumerate() {
            *g += u_k * (2.0 * PI / nphi as f32 * radial[c]) + v_k * azimuthal[c];
        }
    }
    let to_world = |g: Vec3A| t * g.x + b * g.y + n * g.z;
    let mut out = HemisphereEstimate { value, harmonic_distance, grad_t: grad_t.map(|g| to_world(g / PI)), grad_r: grad_r.map(to_world) };
    // A non-finite gradient (a degenerate frame, overflow) is dropped rather than extrapolated.
    if !out.grad_t.iter().chain(out.grad_r.iter()).all(|g| g.is_finite()) {
        out.grad_t = [Vec3A::ZERO; 3];
        out.grad_r = [Vec3A::ZERO; 3];
    }
    out
}

/// One cached hemisphere integral (render space).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    pub p: Vec3A,
    /// Unit shading normal, on the side the integral was taken.
    pub n: Vec3A,
    pub value: Vec3A,
    /// Ward's `Rᵢ`, world units, after the gradient limit and the pixel clamps.
    pub r: f32,
    pub grad_t: [Vec3A; 3],
    pub grad_r: [Vec3A; 3],
}

impl Record {
    /// Ward's error estimate `‖p − pᵢ‖/Rᵢ + √(1 − n·nᵢ)` at `(p, n)`; the weight is its inverse.
    pub fn error(&self, p: Vec3A, n: Vec3A) -> f32 {
        (p - self.p).length() / self.r + (1.0 - n.dot(self.n)).max(0.0).sqrt()
    }

    /// Ward's test: the record lies in front of `p` (above its tangent plane, e.g. on the rim of
    /// a crevice `p` is in), beyond a tolerance of a hundredth of `Rᵢ`.
    pub fn in_front_of(&self, p: Vec3A, n: Vec3A) -> bool {
        (p - self.p).dot(n + self.n) * 0.5 < -0.01 * self.r
    }

    /// The record's value carried to `(p, n)`: first order in position and rotation with
    /// `gradients`, the constant value without.
    pub fn extrapolate(&self, p: Vec3A, n: Vec3A, gradients: bool) -> Vec3A {
        if !gradients {
            return self.value;
        }
        let dp = p - self.p;
        let rot = self.n.cross(n);
        let delta = |c: usize| dp.dot(self.grad_t[c]) + rot.dot(self.grad_r[c]);
        self.value + Vec3A::new(delta(0), delta(1), delta(2))
    }
}

/// A point where an integrator needs a hemisphere integral, found by a pre-pass camera ray, and
/// whatever the integrator needs to compute one there (`ctx`: the hit, shading point, footprint).
pub struct PrepassPoint<C> {
    pub p: Vec3A,
    /// Unit shading normal, facing the camera.
    pub n: Vec3A,
    /// The camera ray's beam width at the point, world units: one pixel there.
    pub pixel_width: f32,
    pub ctx: C,
}

/// The pre-pass was cancelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cancelled;

/// What one parallel chunk of the pre-pass yields: its items in order, and the rays it traced.
type Chunk<T> = (Vec<T>, TraceCounters);

/// Hashed grid key: level (cell size 2^level world units) and integer cell coordinates.
type CellKey = (i32, i64, i64, i64);

/// A read-mostly cache of [`Record`]s with Ward's interpolation, built by [`IrradianceCache::build`].
pub struct IrradianceCache {
    quantity: Quantity,
    /// Ward's `a` (`irradianceCacheError`).
    error_bound: f32,
    /// Extrapolate with the records' gradients (on in renders; off to measure what they buy).
    pub gradients: bool,
    records: Vec<Record>,
    /// A multi-level hashed grid: a record of validity radius ρ = a·R lives at the level whose
    /// cells are at least 2ρ wide, in the cell holding `pᵢ`; a query looks at the 2 × 2 × 2 cells
    /// of each level nearest to it.
    cells: HashMap<CellKey, Vec<u32>>,
    levels: Vec<i32>,
    /// Pre-pass figures.
    prepass_points: u64,
    prepass_rays: u64,
    prepass_s: f64,
    /// Render-pass figures (shared by the render threads; counts only).
    lookups: AtomicU64,
    interpolated: AtomicU64,
}

impl std::fmt::Debug for IrradianceCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IrradianceCache").field("quantity", &self.quantity).field("records", &self.records.len()).finish_non_exhaustive()
    }
}

impl IrradianceCache {
    /// An empty cache of `quantity` with error bound `a` (`irradianceCacheError`), gradients on.
    pub fn new(quantity: Quantity, error_bound: f32) -> Self {
        IrradianceCache {
            quantity,
            error_bound,
            gradients: true,
            records: Vec::new(),
            cells: HashMap::new(),
            levels: Vec::new(),
            prepass_points: 0,
            prepass_rays: 0,
            prepass_s: 0.0,
            lookups: AtomicU64::new(0),
            interpolated: AtomicU64::new(0),
        }
    }

    pub fn quantity(&self) -> Quantity {
        self.quantity
    }

    pub fn error_bound(&self) -> f32 {
        self.error_bound
    }

    /// The records, in the order they were made.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// A record at `(p, n)` from `est`, its `R` limited by the gradient and clamped to the pixel
    /// spacings ([`MIN_SPACING_PX`], [`MAX_SPACING_PX`]) of `pixel_width` (world units). `None`
    /// when the estimate is not finite, or when neither the hits nor the pixel width give `R` a
    /// finite size (the record would claim the whole scene).
    pub fn record(&self, p: Vec3A, n: Vec3A, est: &HemisphereEstimate, pixel_width: f32) -> Option<Record> {
        if !(est.value.is_finite() && p.is_finite() && n.is_finite()) {
            return None;
        }
        let mut r = est.harmonic_distance;
        for c in 0..3 {
            let g = est.grad_t[c].length();
            if g > 0.0 && est.value[c] > 0.0 {
                r = r.min(est.value[c] / g);
            }
        }
        let a = self.error_bound;
        if pixel_width.is_finite() && pixel_width > 0.0 {
            let (lo, hi) = (MIN_SPACING_PX * pixel_width / a, MAX_SPACING_PX * pixel_width / a);
            r = if r.is_nan() { hi } else { r.clamp(lo, hi) };
        }
        (r.is_finite() && r > 0.0).then_some(Record { p, n, value: est.value, r, grad_t: est.grad_t, grad_r: est.grad_r })
    }

    fn level_of(&self, r: f32) -> i32 {
        // Cells at least twice the validity radius wide.
        (2.0 * self.error_bound * r).log2().ceil().clamp(-126.0, 126.0) as i32
    }

    fn cell(p: Vec3A, level: i32) -> (CellKey, [i64; 3]) {
        let inv = (-level as f32).exp2();
        let q = p * inv;
        let c = [q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64];
        // The neighbour on the side of the nearer face, per axis.
        let side = |x: f32| if x - x.floor() < 0.5 { -1 } else { 1 };
        ((level, c[0], c[1], c[2]), [side(q.x), side(q.y), side(q.z)])
    }

    /// Adds a record (the pre-pass does; the render pass only reads).
    pub fn insert(&mut self, rec: Record) {
        let level = self.level_of(rec.r);
        let (key, _) = Self::cell(rec.p, level);
        let id = self.records.len() as u32;
        self.records.push(rec);
        self.cells.entry(key).or_default().push(id);
        if let Err(i) = self.levels.binary_search(&level) {
            self.levels.insert(i, level);
        }
    }

    /// Visits every record valid at `(p, n)` with its weight, in a fixed order (levels
    /// ascending, cells in a fixed pattern, records in insertion order), so sums over them are
    /// the same on every run.
    fn for_valid(&self, p: Vec3A, n: Vec3A, mut f: impl FnMut(&Record, f32)) {
        let a = self.error_bound;
        for &level in &self.levels {
            let ((l, cx, cy, cz), side) = Self::cell(p, level);
            for corner in 0..8 {
                let key = (
                    l,
                    cx + if corner & 1 != 0 { side[0] } else { 0 },
                    cy + if corner & 2 != 0 { side[1] } else { 0 },
                    cz + if corner & 4 != 0 { side[2] } else { 0 },
                );
                let Some(ids) = self.cells.get(&key) else { continue };
                for &id in ids {
                    let rec = &self.records[id as usize];
                    let e = rec.error(p, n);
                    if e < a && !rec.in_front_of(p, n) {
                        // At a record's own point the error is 0: it takes (almost) all the weight.
                        f(rec, 1.0 / e.max(1e-6 * a));
                    }
                }
            }
        }
    }

    /// True when some record is valid at `(p, n)`.
    pub fn covers(&self, p: Vec3A, n: Vec3A) -> bool {
        let mut any = false;
        self.for_valid(p, n, |_, _| any = true);
        any
    }

    /// The interpolated value at `(p, n)`, or `None` where no record is valid (the caller then
    /// samples the hemisphere). Counted in the stats as a lookup, and as interpolated when found.
    pub fn interpolate(&self, p: Vec3A, n: Vec3A) -> Option<Vec3A> {
        self.lookups.fetch_add(1, Ordering::Relaxed);
        let mut sum = Vec3A::ZERO;
        let mut wsum = 0.0f32;
        let gradients = self.gradients;
        let q = self.quantity;
        self.for_valid(p, n, |rec, w| {
            sum += w * q.clamp(rec.extrapolate(p, n, gradients));
            wsum += w;
        });
        if wsum > 0.0 && (sum / wsum).is_finite() {
            self.interpolated.fetch_add(1, Ordering::Relaxed);
            Some(q.clamp(sum / wsum))
        } else {
            None
        }
    }

    /// Makes the records for an image of `width × height` pixels, deterministically (see the
    /// module doc): `visit(x, y)` traces the camera ray through the centre of pixel (x, y) and
    /// returns the point where the integrator would need the integral (or `None`: nothing hit, or
    /// a surface that does not need it); `compute(point, pixel)` samples the hemisphere there
    /// with the random stream of `pixel` (= y·width + x). Runs on the current rayon pool.
    /// Returns the rays both traced.
    ///
    /// # Errors
    /// [`Cancelled`] when `cancelled()` turns true (checked between phases and per chunk).
    pub fn build<C, V, G>(
        &mut self,
        width: usize,
        height: usize,
        visit: V,
        compute: G,
        cancelled: &(dyn Fn() -> bool + Sync),
    ) -> Result<TraceCounters, Cancelled>
    where
        C: Send + Sync,
        V: Fn(usize, usize, &mut TraceCounters) -> Option<PrepassPoint<C>> + Sync,
        G: Fn(&PrepassPoint<C>, u64, &mut TraceCounters) -> Option<HemisphereEstimate> + Sync,
    {
        const CHUNK: usize = 64;
        // Screen tiles of the records made so far, for neighbour clamping: a record's validity
        // radius is at most MAX_SPACING_PX pixels, so any record that could cover a point lies
        // in its tile or the eight around it.
        const TILE: usize = MAX_SPACING_PX as usize;
        let tiles_w = width.div_ceil(TILE);
        let mut near: Vec<Vec<(u32, f32)>> = vec![Vec::new(); tiles_w * height.div_ceil(TILE)];
        let start = Instant::now();
        let mut total = TraceCounters::default();
        for phase in prepass_phases(width, height, PREPASS_SPACING_PX) {
            if cancelled() {
                return Err(Cancelled);
            }
            // Points of this phase, and whether the records so far cover them (read-only).
            let found: Vec<Chunk<(u64, PrepassPoint<C>)>> = phase
                .par_chunks(CHUNK)
                .map(|chunk| {
                    let mut c = TraceCounters::default();
                    if cancelled() {
                        return (Vec::new(), c);
                    }
                    // The geometry a budget drops meanwhile stays readable (as per pixel).
                    let _pin = crate::geometry_budget::pin();
                    let pts = chunk
                        .iter()
                        .filter_map(|&(x, y)| visit(x, y, &mut c).map(|pt| ((y * width + x) as u64, pt)))
                        .filter(|(_, pt)| !self.covers(pt.p, pt.n))
                        .collect();
                    (pts, c)
                })
                .collect();
            let mut todo = Vec::new();
            for (pts, c) in found {
                total.add(&c);
                todo.extend(pts);
            }
            self.prepass_points += phase.len() as u64;
            // New records for the uncovered points, in parallel; appended in pixel order.
            let made: Vec<Chunk<(u64, Record, f32)>> = todo
                .par_chunks(4)
                .map(|chunk| {
                    let mut c = TraceCounters::default();
                    if cancelled() {
                        return (Vec::new(), c);
                    }
                    // The geometry a budget drops meanwhile stays readable (as per pixel).
                    let _pin = crate::geometry_budget::pin();
                    let recs = chunk
                        .iter()
                        .filter_map(|(pixel, pt)| {
                            let rec = compute(pt, *pixel, &mut c).and_then(|est| self.record(pt.p, pt.n, &est, pt.pixel_width))?;
                            Some((*pixel, rec, MIN_SPACING_PX * pt.pixel_width / self.error_bound))
                        })
                        .collect();
                    (recs, c)
                })
                .collect();
            if cancelled() {
                return Err(Cancelled);
            }
            for (recs, c) in made {
                self.prepass_rays += c.rays.iter().sum::<u64>();
                total.add(&c);
                for (pixel, mut rec, lo) in recs {
                    let (x, y) = (pixel as usize % width, pixel as usize / width);
                    self.clamp_to_neighbours(&mut rec, lo, &near, (x / TILE, y / TILE), tiles_w);
                    near[(y / TILE) * tiles_w + x / TILE].push((self.records.len() as u32, lo));
                    self.insert(rec);
                }
            }
        }
        self.prepass_s += start.elapsed().as_secs_f64();
        Ok(total)
    }

    /// Křivánek et al. 2006's neighbour clamping: `Rᵢ ≤ Rⱼ + ‖pᵢ − pⱼ‖` both ways between a new
    /// record and the records of the screen tiles around it (each kept at or above its own
    /// minimum `lo`). A record in the open sees far-away walls only through the harmonic mean,
    /// which misses that one of them is near in some direction; its neighbour beside the wall
    /// knows, and its small `R` limits how far the open record's validity can reach toward it.
    fn clamp_to_neighbours(&mut self, rec: &mut Record, lo: f32, near: &[Vec<(u32, f32)>], (tx, ty): (usize, usize), tiles_w: usize) {
        let tiles_h = near.len() / tiles_w.max(1);
        let around = |t: usize, n: usize| t.saturating_sub(1)..(t + 2).min(n);
        for y in around(ty, tiles_h) {
            for x in around(tx, tiles_w) {
                for &(j, _) in &near[y * tiles_w + x] {
                    let other = &self.records[j as usize];
                    rec.r = rec.r.min(other.r + (rec.p - other.p).length());
                }
            }
        }
        rec.r = rec.r.max(lo);
        for y in around(ty, tiles_h) {
            for x in around(tx, tiles_w) {
                for &(j, lo_j) in &near[y * tiles_w + x] {
                    // Shrinking keeps the record inside the grid cell its level was chosen for.
                    let other = &mut self.records[j as usize];
                    other.r = other.r.min(rec.r + (rec.p - other.p).length()).max(lo_j).min(other.r);
                }
            }
        }
    }

    /// The stats JSON of this cache (under `irradiance_cache.<quantity>`): records, pre-pass
    /// points, rays and seconds, render-pass lookups and how many were interpolated (the rest
    /// sampled the hemisphere directly).
    pub fn stats(&self) -> Value {
        let lookups = self.lookups.load(Ordering::Relaxed);
        let interpolated = self.interpolated.load(Ordering::Relaxed);
        json!({
            "error_bound": self.error_bound,
            "gradients": self.gradients,
            "records": self.records.len(),
            "prepass_points": self.prepass_points,
            "prepass_rays": self.prepass_rays,
            "prepass_s": self.prepass_s,
            "lookups": lookups,
            "interpolated": interpolated,
            "fallbacks": lookups - interpolated,
        })
    }
}

/// The stats' `irradiance_cache` object of an integrator's caches: one member per quantity
/// (`occlusion`, `irradiance`) with [`IrradianceCache::stats`]; `None` when it has none.
pub fn stats_object(caches: &[Option<&IrradianceCache>]) -> Option<Value> {
    let map: serde_json::Map<String, Value> = caches.iter().flatten().map(|c| (c.quantity().name().to_string(), c.stats())).collect();
    (!map.is_empty()).then_some(Value::Object(map))
}

/// The pixels of the pre-pass in phases (see the module doc): coarse grid of spacing `top` (a
/// power of two) in four parity phases, then each finer level's new pixels in three; every pixel
/// exactly once, each phase in scan order.
pub fn prepass_phases(width: usize, height: usize, top: usize) -> Vec<Vec<(usize, usize)>> {
    let top = top.max(1).next_power_of_two();
    let mut phases = Vec::new();
    let mut s = top;
    loop {
        let classes: &[(usize, usize)] = if s == top { &[(0, 0), (1, 1), (1, 0), (0, 1)] } else { &[(1, 1), (1, 0), (0, 1)] };
        for &(px, py) in classes {
            let mut pts = Vec::new();
            for y in (0..height).step_by(s) {
                for x in (0..width).step_by(s) {
                    if ((x / s) % 2, (y / s) % 2) == (px, py) {
                        pts.push((x, y));
                    }
                }
            }
            if !pts.is_empty() {
                phases.push(pts);
            }
        }
        if s == 1 {
            break;
        }
        s /= 2;
    }
    phases
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{frame, Sampler};

    #[test]
    fn strata_use_the_rays_asked_for_with_n_near_pi_m() {
        assert_eq!(Strata::for_rays(16), Strata { theta: 2, phi: 8 });
        assert_eq!(Strata::for_rays(64), Strata { theta: 4, phi: 16 });
        assert_eq!(Strata::for_rays(1), Strata { theta: 1, phi: 1 });
        assert_eq!(Strata::for_rays(0), Strata { theta: 1, phi: 1 });
        for n in 1..2000 {
            let s = Strata::for_rays(n);
            assert!(s.rays() <= n && s.rays() as f32 >= 0.9 * n as f32 - 1.0, "{n}: {s:?}");
        }
    }

    #[test]
    fn every_pixel_is_in_exactly_one_phase() {
        for (w, h) in [(1, 1), (37, 21), (64, 64), (100, 3)] {
            let mut seen = vec![0u32; w * h];
            for phase in prepass_phases(w, h, 32) {
                for (x, y) in phase {
                    seen[y * w + x] += 1;
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{w}x{h}");
        }
        // Points of one phase are two grid steps apart: the 4-pixel level's (1, 1) phase.
        let phases = prepass_phases(64, 64, 32);
        assert_eq!(phases.len(), 4 + 3 * 5);
    }

    /// Ground z = 0 (normal +z) beside a wall x = d of height h, infinitely wide: the hemisphere
    /// integral of occlusion traced analytically from (0, 0, 0) shifted by `p`.
    fn wall_rays(strata: Strata, p: Vec3A, n: Vec3A, d: f32, h: f32, seed: u64) -> Vec<HemisphereRay> {
        let (t, b) = frame(n);
        let mut s = Sampler::new(seed, 0, 0);
        let mut out = vec![HemisphereRay { dir: Vec3A::Z, distance: f32::INFINITY, value: Vec3A::ZERO }; strata.rays() as usize];
        for k in 0..strata.phi {
            for j in 0..strata.theta {
                let (local, _) = strata.direction(j, k, s.next_f32(), s.next_f32());
                let dir = t * local.x + b * local.y + n * local.z;
                let mut ray = HemisphereRay { dir: local, distance: f32::INFINITY, value: Vec3A::ONE };
                if dir.x > 0.0 {
                    let tw = (d - p.x) / dir.x;
                    let z = p.z + tw * dir.z;
                    if tw > 0.0 && (0.0..=h).contains(&z) {
                        ray = HemisphereRay { dir: local, distance: tw, value: Vec3A::ZERO };
                    }
                }
                out[strata.index(j, k)] = ray;
            }
        }
        out
    }

    /// The closed form: the unoccluded fraction of the cosine-weighted hemisphere beside an
    /// infinitely wide wall of height `h` at distance `d`, `1 − ½(1 − d/√(d² + h²))` (the form
    /// factor to an infinite strip, by Lambert's contour integral).
    fn wall_open(d: f32, h: f32) -> f32 {
        0.5 + 0.5 * d / (d * d + h * h).sqrt()
    }

    fn mean_estimate(strata: Strata, p: Vec3A, n: Vec3A, d: f32, h: f32, runs: u64) -> HemisphereEstimate {
        let mut acc = HemisphereEstimate { value: Vec3A::ZERO, harmonic_distance: 0.0, grad_t: [Vec3A::ZERO; 3], grad_r: [Vec3A::ZERO; 3] };
        for seed in 0..runs {
            let (t, b) = frame(n);
            let e = estimate(strata, &wall_rays(strata, p, n, d, h, seed), t, b, n);
            acc.value += e.value / runs as f32;
            acc.grad_t[0] += e.grad_t[0] / runs as f32;
            acc.grad_r[0] += e.grad_r[0] / runs as f32;
        }
        acc
    }

    #[test]
    fn occlusion_value_and_translational_gradient_match_the_closed_form() {
        let (d, h) = (1.0f32, 1.5f32);
        let strata = Strata::for_rays(256);
        let est = mean_estimate(strata, Vec3A::ZERO, Vec3A::Z, d, h, 64);
        let truth = wall_open(d, h);
        assert!((est.value.x - truth).abs() < 2e-3, "{} vs {truth}", est.value.x);
        // d(open)/dx: moving toward the wall (x up, distance d − x down).
        let dd = 1e-3;
        let slope = -(wall_open(d + dd, h) - wall_open(d - dd, h)) / (2.0 * dd);
        let g = est.grad_t[0];
        // Ward & Heckbert's estimator weights each boundary by its own angle, not the edge's
        // within the strata: a bias of order 1/M (15% at 9 × 28 strata, 4% at 36 × 113).
        assert!((g.x - slope).abs() < 0.2 * slope.abs(), "gradient {g} vs d/dx {slope}");
        assert!(g.y.abs() < 0.05 * slope.abs() && g.z.abs() < 1e-6, "{g}");
        let fine = mean_estimate(Strata::for_rays(4096), Vec3A::ZERO, Vec3A::Z, d, h, 16).grad_t[0];
        assert!((fine.x - slope).abs() < 0.06 * slope.abs() && (fine.x - slope).abs() < 0.5 * (g.x - slope).abs(), "{fine} vs {slope}");
    }

    #[test]
    fn rotational_gradient_matches_a_tilted_normal() {
        // Tilting the normal toward the wall (about +y, toward +x) hides more of the hemisphere.
        let (d, h) = (1.0f32, 1.5f32);
        let strata = Strata::for_rays(256);
        let est = mean_estimate(strata, Vec3A::ZERO, Vec3A::Z, d, h, 64);
        let angle = 0.05f32;
        let tilted = Vec3A::new(angle.sin(), 0.0, angle.cos());
        let e2 = mean_estimate(strata, Vec3A::ZERO, tilted, d, h, 64);
        let predicted = Vec3A::Z.cross(tilted).dot(est.grad_r[0]);
        let actual = e2.value.x - est.value.x;
        assert!(actual < 0.0, "{actual}");
        assert!((predicted - actual).abs() < 0.15 * actual.abs(), "predicted {predicted} vs {actual}");
    }

    #[test]
    fn gradients_cut_the_extrapolation_error_of_a_record() {
        let (d, h) = (1.0f32, 1.5f32);
        let strata = Strata::for_rays(256);
        let est = mean_estimate(strata, Vec3A::ZERO, Vec3A::Z, d, h, 16);
        let rec = Record { p: Vec3A::ZERO, n: Vec3A::Z, value: est.value, r: 1.0, grad_t: est.grad_t, grad_r: est.grad_r };
        let (mut with, mut without) = (0.0f32, 0.0f32);
        for i in 1..=10 {
            let x = 0.02 * i as f32;
            let truth = wall_open(d - x, h);
            let p = Vec3A::new(x, 0.0, 0.0);
            with = with.max((rec.extrapolate(p, Vec3A::Z, true).x - truth).abs());
            without = without.max((rec.extrapolate(p, Vec3A::Z, false).x - truth).abs());
        }
        assert!(with < 0.25 * without, "with gradients {with}, without {without}");
    }

    #[test]
    fn interpolation_uses_valid_records_only_in_a_fixed_order() {
        let mut cache = IrradianceCache::new(Quantity::Occlusion, 0.2);
        let g0 = [Vec3A::ZERO; 3];
        cache.insert(Record { p: Vec3A::ZERO, n: Vec3A::Z, value: Vec3A::splat(0.25), r: 1.0, grad_t: g0, grad_r: g0 });
        cache.insert(Record { p: Vec3A::new(0.1, 0.0, 0.0), n: Vec3A::Z, value: Vec3A::splat(0.75), r: 1.0, grad_t: g0, grad_r: g0 });
        // A far record in another level must not be seen.
        cache.insert(Record { p: Vec3A::new(50.0, 0.0, 0.0), n: Vec3A::Z, value: Vec3A::ONE, r: 100.0, grad_t: g0, grad_r: g0 });
        // Midway: equal weights.
        let v = cache.interpolate(Vec3A::new(0.05, 0.0, 0.0), Vec3A::Z).unwrap();
        assert!((v.x - 0.5).abs() < 1e-5, "{v}");
        // Beyond a·R of both (and of the far one's 20): nothing valid.
        assert!(cache.interpolate(Vec3A::new(0.0, 0.5, 0.0), Vec3A::Z).is_none());
        // A normal turned away: not valid (√(1 − cos) ≥ a).
        assert!(cache.interpolate(Vec3A::ZERO, Vec3A::new(0.3, 0.0, 0.954).normalize()).is_none());
        // A record in front of the point (above its tangent plane) is not used.
        assert!(cache.interpolate(Vec3A::new(0.0, 0.0, -0.1), Vec3A::Z).is_none());
        // The far record covers points within 20 of it across many cells.
        for i in 0..40 {
            let p = Vec3A::new(50.0 + (i as f32 - 20.0) * 0.49, 3.0, 0.0);
            assert!(cache.covers(p, Vec3A::Z), "{p}");
        }
        assert!(!cache.covers(Vec3A::new(50.0, 20.5, 0.0), Vec3A::Z));
    }

    #[test]
    fn records_clamp_r_to_pixel_spacings_and_the_gradient_limit() {
        let cache = IrradianceCache::new(Quantity::Occlusion, 0.2);
        let mut est =
            HemisphereEstimate { value: Vec3A::ONE, harmonic_distance: f32::INFINITY, grad_t: [Vec3A::ZERO; 3], grad_r: [Vec3A::ZERO; 3] };
        // Nothing hit: the largest spacing.
        let r = cache.record(Vec3A::ZERO, Vec3A::Z, &est, 0.01).unwrap();
        assert!((r.r * 0.2 - MAX_SPACING_PX * 0.01).abs() < 1e-6);
        // Everything at contact: the smallest.
        est.harmonic_distance = 1e-9;
        let r = cache.record(Vec3A::ZERO, Vec3A::Z, &est, 0.01).unwrap();
        assert!((r.r * 0.2 - MIN_SPACING_PX * 0.01).abs() < 1e-6);
        // A steep gradient limits R to value/|gradient|.
        est.harmonic_distance = 10.0;
        est.grad_t[1] = Vec3A::new(0.0, 0.0, 4.0);
        let r = cache.record(Vec3A::ZERO, Vec3A::Z, &est, 0.01).unwrap();
        assert!((r.r - 0.25).abs() < 1e-6, "{}", r.r);
        // No pixel width and nothing hit: no record claims the whole scene.
        est =
            HemisphereEstimate { value: Vec3A::ONE, harmonic_distance: f32::INFINITY, grad_t: [Vec3A::ZERO; 3], grad_r: [Vec3A::ZERO; 3] };
        assert!(cache.record(Vec3A::ZERO, Vec3A::Z, &est, 0.0).is_none());
    }
}
