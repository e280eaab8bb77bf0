//! A picture of the tessellation error on the surface: every patch tessellated at one rate,
//! each quad coloured by its largest error (relative to the bounding-box diagonal, on a
//! logarithmic scale from 1e-6, blue, to 1e-1, red), seen by an orthographic projection along a
//! fixed diagonal view and shaded by the facing ratio. A scale bar runs along the bottom edge.

use glam::Vec3A;
use mipray::image_io::ImageBuf;
use mipray::patch::{GridSamples, LimitSurface, UvRect};
use mipray::subpatch::Subpatch;
use mipray::tessellate::{tessellate, GridDomain, Rate};

use super::tessellation::grid_error;

/// Lowest and highest log₁₀ of the relative error on the colour scale.
pub const LOG_RANGE: (f32, f32) = (-6.0, -1.0);

/// What to draw.
#[derive(Clone, Copy, Debug)]
pub struct HeatmapOptions {
    pub width: usize,
    pub height: usize,
    /// The effective rate drawn.
    pub rate: Rate,
    /// Direction the camera looks along (object space).
    pub view: Vec3A,
}

impl Default for HeatmapOptions {
    fn default() -> Self {
        HeatmapOptions { width: 512, height: 512, rate: Rate::R4, view: Vec3A::new(-0.55, -0.45, -0.7) }
    }
}

/// A perceptual-ish blue → cyan → green → yellow → red ramp over s ∈ [0, 1].
pub fn colormap(s: f32) -> [f32; 3] {
    const STOPS: [[f32; 3]; 5] = [[0.1, 0.2, 0.8], [0.1, 0.7, 0.9], [0.2, 0.8, 0.3], [0.95, 0.85, 0.2], [0.9, 0.15, 0.1]];
    let s = if s.is_nan() { 1.0 } else { s.clamp(0.0, 1.0) } * 4.0;
    let i = (s.floor() as usize).min(3);
    let f = s - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f]
}

/// Position on the scale of a relative error.
fn scale_of(rel: f64) -> f32 {
    let l = (rel.max(1e-30)).log10() as f32;
    (l - LOG_RANGE.0) / (LOG_RANGE.1 - LOG_RANGE.0)
}

/// Renders the heatmap (RGB, display-ready values in [0, 1], row 0 at the top).
pub fn render(surface: &dyn LimitSurface, diag: f32, opts: &HeatmapOptions) -> ImageBuf {
    let (w, h) = (opts.width.max(8), opts.height.max(24));
    let (tier, stride) = opts.rate.tier_and_stride();
    let fwd = opts.view.normalize_or(Vec3A::NEG_Z);
    let up = if fwd.cross(Vec3A::Y).length() > 1e-3 { Vec3A::Y } else { Vec3A::X };
    let right = fwd.cross(up).normalize();
    let up = right.cross(fwd);
    // Triangles in view space (x right, y up, z depth) with a colour each.
    let mut tris: Vec<([Vec3A; 3], [f32; 3])> = Vec::new();
    let mut scratch = GridSamples::default();
    let to_view = |p: Vec3A| Vec3A::new(p.dot(right), p.dot(up), p.dot(fwd));
    for patch in 0..surface.patch_count() {
        let kind = surface.patch_param(patch).kind;
        let sub = Subpatch { patch: patch as u32, rect: UvRect::UNIT, bounds: surface.patch_bounds(patch), affine: false };
        let (t, _) = tessellate(surface, &sub, tier, None, &mut scratch);
        let q = (t.n - 1) / stride;
        let mut err = vec![0.0f64; q * q];
        grid_error(surface, patch, kind, UvRect::UNIT, &t, stride, |qi, qj, e| {
            let slot = &mut err[qj * q + qi];
            *slot = slot.max(e);
        });
        for qj in 0..q {
            for qi in 0..q {
                let triangle = t.domain == GridDomain::LowerTriangle;
                if t.domain == GridDomain::Empty || (triangle && qi + qj + 1 > q) {
                    continue;
                }
                let diagonal = triangle && qi + qj + 1 == q;
                let c = colormap(scale_of(err[qj * q + qi] / f64::from(diag)));
                let p = |i: usize, j: usize| to_view(t.vert(i * stride, j * stride));
                let (p00, p10, p11, p01) = (p(qi, qj), p(qi + 1, qj), p(qi + 1, qj + 1), p(qi, qj + 1));
                let n = (p10 - p00).cross(p01 - p00).normalize_or_zero();
                let shade = 0.35 + 0.65 * n.z.abs();
                let col = [c[0] * shade, c[1] * shade, c[2] * shade];
                if diagonal {
                    tris.push(([p00, p10, p01], col));
                } else {
                    tris.push(([p00, p10, p11], col));
                    tris.push(([p00, p11, p01], col));
                }
            }
        }
    }
    let bar = 16.min(h / 8);
    let plot_h = h - bar - 4;
    let mut img = vec![0.1f32; w * h * 3];
    let mut zbuf = vec![f32::INFINITY; w * plot_h];
    let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
    for (t, _) in &tris {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let ext = (hi - lo).max(Vec3A::splat(f32::MIN_POSITIVE));
    let scale = 0.92 * (w as f32 / ext.x).min(plot_h as f32 / ext.y);
    let (cx, cy) = ((lo.x + hi.x) * 0.5, (lo.y + hi.y) * 0.5);
    let to_px = |p: Vec3A| Vec3A::new(w as f32 * 0.5 + (p.x - cx) * scale, plot_h as f32 * 0.5 - (p.y - cy) * scale, p.z);
    for (t, col) in &tris {
        let [a, b, c] = t.map(to_px);
        let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        if !(area.abs() > 1e-12 && area.is_finite()) {
            continue;
        }
        let x0 = a.x.min(b.x).min(c.x).floor().max(0.0) as usize;
        let x1 = (a.x.max(b.x).max(c.x).ceil().max(0.0) as usize).min(w - 1);
        let y0 = a.y.min(b.y).min(c.y).floor().max(0.0) as usize;
        let y1 = (a.y.max(b.y).max(c.y).ceil().max(0.0) as usize).min(plot_h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let w0 = ((b.x - px) * (c.y - py) - (b.y - py) * (c.x - px)) / area;
                let w1 = ((c.x - px) * (a.y - py) - (c.y - py) * (a.x - px)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = a.z * w0 + b.z * w1 + c.z * w2;
                let k = y * w + x;
                if z < zbuf[k] {
                    zbuf[k] = z;
                    img[k * 3..k * 3 + 3].copy_from_slice(col);
                }
            }
        }
    }
    for y in h - bar..h {
        for x in 0..w {
            let c = colormap(x as f32 / (w - 1) as f32);
            img[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&c);
        }
    }
    ImageBuf { width: w, height: h, channels: vec!["R".into(), "G".into(), "B".into()], pixels: img, metadata: Vec::new() }
}
