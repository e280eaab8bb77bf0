//! TEMPORARY stand-in while the full module is written (helper-3 replaces this file).
use glam::Vec3A;

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayDifferential {
    pub dpdx: Vec3A,
    pub dpdy: Vec3A,
    pub dddx: Vec3A,
    pub dddy: Vec3A,
}

impl RayDifferential {
    pub fn from_pinhole(d: Vec3A, dd_dx: Vec3A, dd_dy: Vec3A) -> Self {
        let dd = d.dot(d);
        let f = |e: Vec3A| (dd * e - d.dot(e) * d) / (dd * dd.sqrt());
        RayDifferential { dpdx: Vec3A::ZERO, dpdy: Vec3A::ZERO, dddx: f(dd_dx), dddy: f(dd_dy) }
    }
    pub fn from_orthographic(dpdx: Vec3A, dpdy: Vec3A) -> Self {
        RayDifferential { dpdx, dpdy, dddx: Vec3A::ZERO, dddy: Vec3A::ZERO }
    }
    pub fn beam_width_at(&self, t: f32) -> f32 {
        (self.dpdx + t * self.dddx).length().max((self.dpdy + t * self.dddy).length())
    }
    pub fn transfer(&self, d: Vec3A, t: f32, n: Vec3A) -> RayDifferential {
        let dn = d.dot(n);
        let px = self.dpdx + t * self.dddx;
        let py = self.dpdy + t * self.dddy;
        let (tx, ty) = if dn.abs() > 1e-6 { (-px.dot(n) / dn, -py.dot(n) / dn) } else { (0.0, 0.0) };
        RayDifferential { dpdx: px + tx * d, dpdy: py + ty * d, dddx: self.dddx, dddy: self.dddy }
    }
    pub fn scale(&mut self, s: f32) {
        self.dpdx *= s;
        self.dpdy *= s;
        self.dddx *= s;
        self.dddy *= s;
    }
}
