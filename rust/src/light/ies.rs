//! IESNA LM-63 photometric profiles (UsdLux `ShapingAPI`'s `shaping:ies:file`): the candela a
//! luminaire emits by vertical and horizontal angle, applied as Hydra's hdEmbree applies them.
//!
//! **Reading.** LM-63-1995 and -2002 files (`IESNA:LM-63-1995`, `IESNA:LM-63-2002`, or the
//! 1986 form without that line): keyword lines up to `TILT=`; then the tilt data when
//! `TILT=INCLUDE` (lamp-to-luminaire geometry, the number of tilt angles, the angles, the
//! multiplying factors), or from the file `TILT=<file>` names (the same four records; read by
//! the caller's `tilt_file`); then the numbers, whitespace- or comma-separated over any lines:
//! lamp count, lumens per lamp, candela multiplier, vertical and horizontal angle counts,
//! photometric type (1 = C, 2 = B, 3 = A), units, the three luminous dimensions, ballast factor,
//! ballast-lamp photometric factor (the 1995 "future use"), input watts, the vertical angles,
//! the horizontal angles and the candela values (one row of vertical angles per horizontal
//! angle). Candela are the file's values × candela multiplier × ballast factor × ballast-lamp
//! factor.
//!
//! **Evaluation.** In the light's frame, the luminaire aims along its −Z (the profile's nadir
//! for type C, its photometric axis — horizontal and vertical angle 0 — for types A and B).
//!
//! - Type C: θ is the angle between the emission direction and −Z (vertical angle 0), φ the
//!   azimuth about that axis measured in the light's XY plane of the direction toward the light
//!   (hdEmbree's `atan2(y, x)` of it), folded into the file's horizontal range by its symmetry
//!   (one angle: symmetric about the axis; last angle 90°: quadrant symmetry; 180°: bilateral;
//!   360°: none). `ies:angleScale` s rescales θ about the zenith as RenderMan does:
//!   θ' = (θ − π)/(1 + s) + π, clamped to [0, π].
//! - Type B (LM-63: "the planes share a common horizontal axis"; floodlights): the polar axis
//!   is the light's X. The vertical angle V turns the photometric plane about X (positive
//!   toward +Y), the horizontal angle H is the lateral angle within it (positive toward +X):
//!   for a unit emission direction d, H = asin(d·X), V = atan2(d·Y, −d·Z).
//! - Type A (LM-63: "the planes are all vertical and share a common vertical axis";
//!   automotive): the polar axis is the light's Y. H turns the plane about Y (positive toward
//!   +X), V is the elevation within it (positive toward +Y): V = asin(d·Y),
//!   H = atan2(d·X, −d·Z).
//! - For A and B a first angle of 0 means the file gives one side of a symmetric luminaire
//!   (|H| or |V| is looked up, as LM-63 describes); both cover the hemisphere in front of the
//!   luminaire (|H|, |V| ≤ 90°) and emit nothing behind it. `angleScale` applies to type C
//!   only (the front end warns when it is authored on another type).
//!
//! Candela are interpolated bilinearly in the two angles; outside the file's range the profile
//! is 0. With `ies:normalize` the value is divided by the profile's mean candela over the
//! sphere (or the hemisphere, for a profile spanning no more than 90° + a little; always the
//! front hemisphere for types A and B), so the shaping keeps the light's power; without it the
//! factor is the candela value itself.
//!
//! **Tilt.** A tilt table multiplies the candela by its factor at the luminaire's tilt,
//! interpolated linearly in the table's angles (clamped to its ends). Which tilt the table
//! means is LM-63's lamp-to-luminaire geometry ([`Tilt::tilt_angle`]), with the stage's down
//! (the front end gives it) and the light's aim (−Z) and photometric 0°–180° axis (+X):
//! geometry 1 (lamp vertical, base up or down, when aimed straight down) any tilt of the aim
//! from down; geometry 2 (lamp horizontal, staying horizontal as the luminaire tilts) the
//! tilt about the lamp's axis, which lies in the 0°–180° plane (the light's X); geometry 3
//! (lamp horizontal, tilting with the luminaire in the 0°–180° plane) the lamp axis's angle
//! from the horizontal.

use glam::Vec3A;

/// LM-63's photometric types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Photometry {
    /// Type C (1): vertical angles from the nadir, horizontal angles about it.
    C,
    /// Type B (2): photometric planes about the luminaire's horizontal (X) axis.
    B,
    /// Type A (3): photometric planes about the luminaire's vertical (Y) axis.
    A,
}

/// A tilt table (`TILT=INCLUDE` or `TILT=<file>`): candela multipliers by lamp tilt.
#[derive(Clone, Debug, PartialEq)]
pub struct Tilt {
    /// Lamp-to-luminaire geometry, 1 to 3.
    pub geometry: u8,
    /// Radians, increasing.
    pub angles: Vec<f32>,
    /// One per angle, ≥ 0.
    pub factors: Vec<f32>,
}

impl Tilt {
    /// The tilt (radians, in [0, π]) at which a light aimed along unit `aim` (its −Z), its
    /// photometric 0° axis along unit `x` (its +X), in a world whose down is unit `down`,
    /// reads the table, by LM-63's lamp-to-luminaire geometry:
    ///
    /// 1. the lamp is vertical (along the aim) when the luminaire aims straight down, so any
    ///    tilt of the aim tilts it: ∠(aim, down);
    /// 2. the lamp is horizontal along the 0°–180° plane (`x`) and stays horizontal as the
    ///    luminaire tilts about it: the aim's angle from down about `x` (down projected onto the
    ///    plane normal to `x`; a tilt in the 0°–180° plane is not this geometry's and reads 0);
    /// 3. the lamp is horizontal when aimed down and tilts with the luminaire in the 0°–180°
    ///    plane: the lamp axis's angle from the horizontal, asin |x · down|.
    pub fn tilt_angle(&self, aim: Vec3A, x: Vec3A, down: Vec3A) -> f32 {
        match self.geometry {
            2 => {
                let across = down - x * down.dot(x);
                match across.try_normalize() {
                    Some(d) => aim.dot(d).clamp(-1.0, 1.0).acos(),
                    // The lamp stands vertical: the luminaire is tilted 90° (in the other plane).
                    None => std::f32::consts::FRAC_PI_2,
                }
            }
            3 => x.dot(down).abs().clamp(0.0, 1.0).asin(),
            _ => aim.dot(down).clamp(-1.0, 1.0).acos(),
        }
    }

    /// The factor at tilt `angle` (radians): linear between the table's angles, its end values
    /// beyond them.
    pub fn factor(&self, angle: f32) -> f32 {
        let (i, t) = bracket(&self.angles, angle);
        let j = (i + 1).min(self.angles.len() - 1);
        lerp(self.factors[i], self.factors[j], t)
    }
}

/// A parsed profile.
#[derive(Clone, Debug, PartialEq)]
pub struct IesProfile {
    /// The photometric type.
    pub kind: Photometry,
    /// The tilt table, if the file has one.
    pub tilt: Option<Tilt>,
    /// Vertical angles, radians, increasing.
    v: Vec<f32>,
    /// Horizontal angles, radians, increasing.
    h: Vec<f32>,
    /// Candela, `cd[hi * v.len() + vi]`.
    cd: Vec<f32>,
    /// Mean candela over the sphere or hemisphere the profile covers ([`IesProfile::mean`]).
    mean: f32,
    /// Per vertical angle, the largest candela over the horizontal angles.
    envelope: Vec<f32>,
    peak: f32,
}

impl IesProfile {
    /// Parses an LM-63 file's text (a `TILT=<file>` reference is refused: [`IesProfile::parse_with`]).
    ///
    /// # Errors
    /// As [`IesProfile::parse_with`].
    pub fn parse(text: &str) -> Result<IesProfile, String> {
        Self::parse_with(text, &|name| Err(format!("TILT={name}: a tilt file cannot be read here")))
    }

    /// Parses an LM-63 file's text; `tilt_file` gives the text of the file a `TILT=<file>`
    /// line names (or why it cannot).
    ///
    /// # Errors
    /// A one-line reason: no `TILT=` line, a tilt table that does not parse (its count, angles
    /// that do not increase, negative factors, a tilt file that cannot be read), missing or
    /// non-numeric values, an unknown photometric type, angles that do not increase or lie
    /// outside the type's range, negative candela.
    pub fn parse_with(text: &str, tilt_file: &dyn Fn(&str) -> Result<String, String>) -> Result<IesProfile, String> {
        let mut lines = text.lines();
        let tilt_spec = loop {
            let Some(line) = lines.next() else { return Err("no TILT= line".into()) };
            if let Some(rest) = line.trim_start().strip_prefix("TILT=") {
                break rest.trim().to_string();
            }
        };
        let rest: Vec<&str> = lines.collect();
        let mut nums = rest.iter().flat_map(|l| l.split(|c: char| c.is_whitespace() || c == ',')).filter(|t| !t.is_empty());
        let tilt = if tilt_spec.eq_ignore_ascii_case("NONE") {
            None
        } else if tilt_spec.eq_ignore_ascii_case("INCLUDE") {
            Some(parse_tilt(&mut nums).map_err(|e| format!("TILT=INCLUDE: {e}"))?)
        } else {
            let body = tilt_file(&tilt_spec).map_err(|e| format!("TILT={tilt_spec}: {e}"))?;
            let mut t = body.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty());
            Some(parse_tilt(&mut t).map_err(|e| format!("TILT={tilt_spec}: {e}"))?)
        };
        let mut next = |what: &str| -> Result<f64, String> {
            let t = nums.next().ok_or_else(|| format!("the file ends before {what}"))?;
            t.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("{what} '{t}' is not a number"))
        };
        let _lamps = next("the lamp count")?;
        let _lumens = next("the lumens per lamp")?;
        let multiplier = next("the candela multiplier")?;
        let nv = next("the vertical angle count")?;
        let nh = next("the horizontal angle count")?;
        let kind = next("the photometric type")?;
        let _units = next("the units type")?;
        for what in ["the width", "the length", "the height"] {
            next(what)?;
        }
        let ballast = next("the ballast factor")?;
        let ballast_lamp = next("the ballast-lamp photometric factor")?;
        let _watts = next("the input watts")?;
        let kind = match kind {
            1.0 => Photometry::C,
            2.0 => Photometry::B,
            3.0 => Photometry::A,
            _ => return Err(format!("photometric type {kind} is not one of 1 (C), 2 (B), 3 (A)")),
        };
        let count = |n: f64, what: &str| -> Result<usize, String> {
            if (1.0..=100_000.0).contains(&n) && n.fract() == 0.0 {
                Ok(n as usize)
            } else {
                Err(format!("{what} {n} is not a count"))
            }
        };
        let (nv, nh) = (count(nv, "the vertical angle count")?, count(nh, "the horizontal angle count")?);
        let mut angles = |n: usize, what: &str| -> Result<Vec<f32>, String> {
            let a: Vec<f32> = (0..n).map(|_| next(what).map(|x| (x as f32).to_radians())).collect::<Result<_, _>>()?;
            if a.windows(2).any(|w| !(w[1] > w[0])) {
                return Err(format!("{what} do not increase"));
            }
            Ok(a)
        };
        let v = angles(nv, "the vertical angles")?;
        let h = angles(nh, "the horizontal angles")?;
        let scale = multiplier * ballast * ballast_lamp;
        let mut cd = Vec::with_capacity(nv * nh);
        for _ in 0..nv * nh {
            let c = next("a candela value")? * scale;
            if c < 0.0 {
                return Err(format!("a candela value is negative ({c})"));
            }
            cd.push(c as f32);
        }
        let (pi, half) = (std::f32::consts::PI, std::f32::consts::FRAC_PI_2);
        match kind {
            Photometry::C if v[0] < 0.0 || v[nv - 1] > pi + 1e-4 => return Err("vertical angles outside [0, 180] degrees".into()),
            Photometry::A | Photometry::B if v[0] < -half - 1e-4 || v[nv - 1] > half + 1e-4 => {
                return Err("vertical angles outside [-90, 90] degrees (types A and B)".into())
            }
            Photometry::A | Photometry::B if h[0] < -half - 1e-4 || h[nh - 1] > half + 1e-4 => {
                return Err("horizontal angles outside [-90, 90] degrees (types A and B)".into())
            }
            _ => {}
        }
        let mut p = IesProfile { kind, tilt, v, h, cd, mean: 0.0, peak: 0.0, envelope: Vec::new() };
        p.peak = p.cd.iter().copied().fold(0.0, f32::max);
        p.envelope = (0..p.v.len()).map(|vi| (0..p.h.len()).map(|hi| p.at(hi, vi)).fold(0.0f32, f32::max)).collect();
        p.mean = p.mean_candela();
        Ok(p)
    }

    /// Candela at vertical index `vi`, horizontal index `hi`.
    fn at(&self, hi: usize, vi: usize) -> f32 {
        self.cd[hi * self.v.len() + vi]
    }

    /// Mean candela over the solid angle the profile covers: for type C the whole sphere, or
    /// the hemisphere when its vertical angles span no more than 90° (+0.1 rad, as hdEmbree);
    /// for types A and B the front hemisphere. Integrated cell by cell (midpoint rule in θ off
    /// the axis, the profile's own bilinear values) over every azimuth, whatever symmetry the
    /// file uses.
    fn mean_candela(&self) -> f32 {
        let (t0, t1, sphere) = match self.kind {
            Photometry::C => {
                let span = self.v[self.v.len() - 1] - self.v[0];
                (self.v[0], self.v[self.v.len() - 1], span > std::f32::consts::FRAC_PI_2 + 0.1)
            }
            Photometry::A | Photometry::B => (0.0, std::f32::consts::FRAC_PI_2, false),
        };
        let (nt, np) = (720usize, 360usize);
        let mut sum = 0.0f64;
        for i in 0..nt {
            let theta = t0 + (t1 - t0) * (i as f32 + 0.5) / nt as f32;
            let d_omega = f64::from((t1 - t0) / nt as f32 * theta.sin()) * (2.0 * std::f64::consts::PI / np as f64);
            for j in 0..np {
                let phi = 2.0 * std::f32::consts::PI * (j as f32 + 0.5) / np as f32;
                let c = match self.kind {
                    Photometry::C => self.candela(theta, phi),
                    // θ off the aim (−Z), φ about it.
                    _ => self.candela_local(Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), -theta.cos())),
                };
                sum += f64::from(c) * d_omega;
            }
        }
        let area = if sphere { 4.0 } else { 2.0 } * std::f64::consts::PI;
        (sum / area) as f32
    }

    /// Candela toward unit direction `d` in the light's frame (the luminaire aims along −Z),
    /// any photometric type ([`IesProfile::candela`]'s θ and φ for type C; see the module
    /// for A and B), before tilt.
    pub fn candela_local(&self, d: Vec3A) -> f32 {
        match self.kind {
            Photometry::C => self.candela((-d.z).clamp(-1.0, 1.0).acos(), (-d.y).atan2(-d.x)),
            Photometry::B => self.candela_hv(d.x.clamp(-1.0, 1.0).asin(), d.y.atan2(-d.z)),
            Photometry::A => self.candela_hv(d.x.atan2(-d.z), d.y.clamp(-1.0, 1.0).asin()),
        }
    }

    /// A type A or B profile's candela at horizontal angle `h` and vertical angle `v` (radians),
    /// bilinear; a file starting at 0 gives |h| (or |v|) its values; 0 outside its range.
    pub fn candela_hv(&self, h: f32, v: f32) -> f32 {
        let h = if self.h[0] >= 0.0 { h.abs() } else { h };
        let v = if self.v[0] >= 0.0 { v.abs() } else { v };
        let inside = |xs: &[f32], x: f32| x >= xs[0] - 1e-6 && x <= xs[xs.len() - 1] + 1e-6;
        if !(inside(&self.v, v) && inside(&self.h, h)) {
            return 0.0;
        }
        let (vi, tv) = bracket(&self.v, v);
        let vj = (vi + 1).min(self.v.len() - 1);
        let (hi, th) = bracket(&self.h, h);
        let hj = (hi + 1).min(self.h.len() - 1);
        let a = lerp(self.at(hi, vi), self.at(hi, vj), tv);
        let b = lerp(self.at(hj, vi), self.at(hj, vj), tv);
        lerp(a, b, th)
    }

    /// Mean candela over the sphere or hemisphere ([`IesProfile::mean_candela`]).
    pub fn mean(&self) -> f32 {
        self.mean
    }

    /// The largest candela value.
    pub fn peak(&self) -> f32 {
        self.peak
    }

    /// `φ` (radians) folded into the file's horizontal range by its symmetry.
    fn fold(&self, phi: f32) -> f32 {
        use std::f32::consts::PI;
        let last = self.h[self.h.len() - 1];
        let mut p = phi.rem_euclid(2.0 * PI);
        if last <= PI / 2.0 + 1e-4 {
            if p > PI {
                p = 2.0 * PI - p;
            }
            if p > PI / 2.0 {
                p = PI - p;
            }
        } else if last <= PI + 1e-4 && p > PI {
            p = 2.0 * PI - p;
        }
        p
    }

    /// An upper bound of [`IesProfile::candela`] over vertical angles [`lo`, `hi`] (radians)
    /// and every azimuth: the largest of the per-vertical-angle maxima over azimuth (bilinear
    /// interpolation never exceeds its corners) at the table's angles inside the interval and,
    /// interpolated, at its ends. 0 when the interval misses the vertical range.
    pub fn max_between(&self, lo: f32, hi: f32) -> f32 {
        let (v0, v1) = (self.v[0], self.v[self.v.len() - 1]);
        let (lo, hi) = (lo.max(v0), hi.min(v1));
        if !(lo <= hi + 1e-6) {
            return 0.0;
        }
        let envelope = |vi: usize| self.envelope[vi];
        let at = |theta: f32| {
            let (vi, tv) = bracket(&self.v, theta);
            let vj = (vi + 1).min(self.v.len() - 1);
            lerp(envelope(vi), envelope(vj), tv)
        };
        let start = self.v.partition_point(|&v| v <= lo);
        let inside = self.v[start..].iter().take_while(|&&v| v < hi).count();
        (start..start + inside).map(envelope).fold(at(lo).max(at(hi)), f32::max)
    }

    /// Candela at vertical angle `theta` and azimuth `phi` (radians), bilinear; 0 outside the
    /// vertical range.
    pub fn candela(&self, theta: f32, phi: f32) -> f32 {
        let (v0, v1) = (self.v[0], self.v[self.v.len() - 1]);
        if !(theta >= v0 - 1e-6 && theta <= v1 + 1e-6) {
            return 0.0;
        }
        let (vi, tv) = bracket(&self.v, theta);
        let vj = (vi + 1).min(self.v.len() - 1);
        if self.h.len() == 1 {
            return lerp(self.at(0, vi), self.at(0, vj), tv);
        }
        let (hi, th) = bracket(&self.h, self.fold(phi));
        let hj = (hi + 1).min(self.h.len() - 1);
        let a = lerp(self.at(hi, vi), self.at(hi, vj), tv);
        let b = lerp(self.at(hj, vi), self.at(hj, vj), tv);
        lerp(a, b, th)
    }
}

/// The four tilt records from `nums`: geometry, count, angles (degrees), factors.
fn parse_tilt<'a>(nums: &mut impl Iterator<Item = &'a str>) -> Result<Tilt, String> {
    let mut next = |what: &str| -> Result<f64, String> {
        let t = nums.next().ok_or_else(|| format!("the tilt data end before {what}"))?;
        t.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("{what} '{t}' is not a number"))
    };
    let geometry = next("the lamp-to-luminaire geometry")?;
    if !matches!(geometry, 1.0 | 2.0 | 3.0) {
        return Err(format!("lamp-to-luminaire geometry {geometry} is not 1, 2 or 3"));
    }
    let n = next("the tilt angle count")?;
    if !((1.0..=10_000.0).contains(&n) && n.fract() == 0.0) {
        return Err(format!("the tilt angle count {n} is not a count"));
    }
    let n = n as usize;
    let angles: Vec<f32> = (0..n).map(|_| next("a tilt angle").map(|a| (a as f32).to_radians())).collect::<Result<_, _>>()?;
    let factors: Vec<f32> = (0..n).map(|_| next("a tilt factor").map(|f| f as f32)).collect::<Result<_, _>>()?;
    // A table of the wrong length shifts factors into the angles (or the photometric header
    // into the factors): the angles stop increasing, or run past 180°.
    if angles.windows(2).any(|w| !(w[1] > w[0])) || angles.iter().any(|a| !(0.0..=std::f32::consts::PI + 1e-4).contains(a)) {
        return Err(format!("the {n} tilt angles do not increase within [0, 180] degrees (a table of the wrong length?)"));
    }
    if factors.iter().any(|f| !(*f >= 0.0)) {
        return Err("a tilt factor is negative".into());
    }
    Ok(Tilt { geometry: geometry as u8, angles, factors })
}

/// The cell of increasing `xs` holding `x` (clamped to the ends) and the fraction across it.
fn bracket(xs: &[f32], x: f32) -> (usize, f32) {
    if xs.len() < 2 || x <= xs[0] {
        return (0, 0.0);
    }
    let i = xs.partition_point(|&a| a <= x).saturating_sub(1).min(xs.len() - 2);
    let t = ((x - xs[i]) / (xs[i + 1] - xs[i])).clamp(0.0, 1.0);
    (i, t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A type C profile: vertical 0, 45, 90; horizontal 0, 90 (quadrant symmetry).
    pub const QUADRANT: &str =
        "IESNA:LM-63-2002\n[TEST] unit\nTILT=NONE\n1 1000 2 3 2 1 2 0 0 0\n1.0 1.0 100\n0 45 90\n0 90\n100 80 10\n50, 40, 5\n";

    #[test]
    fn candela_is_the_files_times_its_multiplier_interpolated_bilinearly() {
        let p = IesProfile::parse(QUADRANT).unwrap();
        // At grid points: the value × 2.
        assert_eq!(p.candela(0.0, 0.0), 200.0);
        assert_eq!(p.candela(45f32.to_radians(), 90f32.to_radians()), 80.0);
        // Halfway in both: the mean of the four corners.
        let c = p.candela(22.5f32.to_radians(), 45f32.to_radians());
        assert!((c - 2.0 * (100.0 + 80.0 + 50.0 + 40.0) / 4.0).abs() < 1e-3, "{c}");
        // Quadrant symmetry: 180° − φ and 360° − φ read φ.
        for phi in [30f32, 150.0, 210.0, 330.0] {
            assert!((p.candela(0.3, phi.to_radians()) - p.candela(0.3, 30f32.to_radians())).abs() < 1e-3);
        }
        // Beyond 90° (the upper hemisphere): nothing.
        assert_eq!(p.candela(2.0, 0.0), 0.0);
    }

    /// Vertical 0, 30, 90 (symmetric about the horizontal plane); horizontal −90, 0, 90.
    fn type_ab(kind: u8, tilt: &str) -> String {
        format!("IESNA:LM-63-2002\nTILT={tilt}\n1 1000 2 3 3 {kind} 2 0 0 0\n1 1 100\n0 30 90\n-90 0 90\n1 2 3\n100 50 10\n4 5 6\n")
    }

    /// A unit direction at horizontal angle `h` and vertical angle `v` (degrees) of type B's
    /// planes (about the light's X) or type A's (about its Y), the aim being −Z.
    fn direction(kind: Photometry, h: f32, v: f32) -> Vec3A {
        let (h, v) = (h.to_radians(), v.to_radians());
        match kind {
            Photometry::B => Vec3A::new(h.sin(), h.cos() * v.sin(), -h.cos() * v.cos()),
            _ => Vec3A::new(v.cos() * h.sin(), v.sin(), -v.cos() * h.cos()),
        }
    }

    #[test]
    fn types_a_and_b_read_their_tables_in_their_own_planes() {
        for (code, kind) in [(2u8, Photometry::B), (3, Photometry::A)] {
            let p = IesProfile::parse(&type_ab(code, "NONE")).unwrap();
            assert_eq!(p.kind, kind);
            let at = |h: f32, v: f32| p.candela_local(direction(kind, h, v));
            // Grid points (× the multiplier 2); the aim is H = V = 0.
            assert!((at(0.0, 0.0) - 200.0).abs() < 1e-3, "{}", at(0.0, 0.0));
            assert!((at(0.0, 30.0) - 100.0).abs() < 1e-3);
            // H = −60 is a third of the way from the −90 row (2 at V = 30) to the 0 row (50).
            assert!((at(-60.0, 30.0) - 2.0 * 18.0).abs() < 1e-2, "{}", at(-60.0, 30.0));
            // The file starts at V = 0: below reads above.
            assert!((at(0.0, -30.0) - 100.0).abs() < 1e-3);
            // Between grid points: bilinear in (H, V).
            let c = at(45.0, 30.0);
            assert!((c - 2.0 * (50.0 + 5.0) / 2.0).abs() < 1e-2, "{kind:?} {c}");
            let c = at(-45.0, 15.0);
            assert!((c - 2.0 * (1.5 + 75.0) / 2.0).abs() < 1e-2, "{kind:?} {c}");
            // Behind the luminaire: nothing.
            assert_eq!(p.candela_local(Vec3A::Z), 0.0);
        }
        // The two types' planes differ: one direction reads different table cells.
        let (a, b) = (IesProfile::parse(&type_ab(3, "NONE")).unwrap(), IesProfile::parse(&type_ab(2, "NONE")).unwrap());
        let d = direction(Photometry::B, 45.0, 30.0);
        assert!((a.candela_local(d) - b.candela_local(d)).abs() > 5.0);
        // A constant profile over the front hemisphere has that constant as its mean.
        let flat = "TILT=NONE\n1 -1 1 2 2 2 2 0 0 0 1 1 10\n-90 90\n-90 90\n7 7\n7 7\n";
        let m = IesProfile::parse(flat).unwrap().mean();
        assert!((m - 7.0).abs() < 1e-2, "{m}");
    }

    #[test]
    fn the_tilt_a_table_is_read_at_follows_the_lamp_to_luminaire_geometry() {
        // A luminaire aimed straight down (−Z, down −Z), its 0°–180° plane along X, tilted 30°
        // about X (in the 90°–270° plane) or about Y (in the 0°–180° plane). LM-63: geometry 1's
        // vertical lamp tilts 30° either way; geometry 2's horizontal lamp (along X) stays
        // horizontal as the luminaire tilts about it, which the table's 30° row is for, while a
        // tilt in the 0°–180° plane is none of its; geometry 3's lamp tilts 30° with the
        // luminaire in the 0°–180° plane and not at all about its own axis.
        let down = Vec3A::NEG_Z;
        let turn = |m: glam::Mat3A| (m * Vec3A::NEG_Z, m * Vec3A::X);
        let about_x = turn(glam::Mat3A::from_rotation_x(30f32.to_radians()));
        let about_y = turn(glam::Mat3A::from_rotation_y(30f32.to_radians()));
        let tilt = |g: u8| Tilt { geometry: g, angles: vec![0.0, 1.0], factors: vec![1.0, 1.0] };
        for (g, want_x, want_y) in [(1, 30.0, 30.0), (2, 30.0, 0.0), (3, 0.0, 30.0)] {
            for ((aim, x), want) in [(about_x, want_x), (about_y, want_y)] {
                let got = tilt(g).tilt_angle(aim, x, down).to_degrees();
                assert!((got - want).abs() < 1e-3, "geometry {g}: {got}° vs {want}°");
            }
        }
        // Both at once: turned 20° about its lamp's axis, then tilted 30° in the 0°–180° plane.
        // Geometry 2 reads the 20° about the lamp's axis, geometry 3 the lamp's 30° from
        // horizontal, geometry 1 the aim's whole angle from down, acos(cos 30° cos 20°).
        let (aim, x) = turn(glam::Mat3A::from_rotation_y(30f32.to_radians()) * glam::Mat3A::from_rotation_x(20f32.to_radians()));
        let whole = (30f32.to_radians().cos() * 20f32.to_radians().cos()).acos().to_degrees();
        for (g, want) in [(1, whole), (2, 20.0), (3, 30.0)] {
            let got = tilt(g).tilt_angle(aim, x, down).to_degrees();
            assert!((got - want).abs() < 1e-3, "geometry {g}: {got}° vs {want}°");
        }
    }

    #[test]
    fn a_tilt_table_scales_the_candela_at_the_lights_tilt() {
        let table = "1\n3\n0 45 90\n1 0.8 0.5";
        let inline = IesProfile::parse(&type_ab(2, &format!("INCLUDE\n{table}"))).unwrap();
        let t = inline.tilt.as_ref().unwrap();
        assert_eq!((t.geometry, t.angles.len()), (1, 3));
        assert!((t.factor(22.5f32.to_radians()) - 0.9).abs() < 1e-5);
        assert!((t.factor(120f32.to_radians()) - 0.5).abs() < 1e-6);
        // TILT=<file>: the same table from the file it names.
        let from_file = IesProfile::parse_with(&type_ab(2, "lamp.tilt"), &|name| {
            assert_eq!(name, "lamp.tilt");
            Ok(table.to_string())
        })
        .unwrap();
        assert_eq!(from_file.tilt, inline.tilt);
        // On a light tilted 67.5° from down, the aim's candela × the factor there (0.65).
        let shaping = crate::light::IesShaping {
            profile: inline,
            file: "t.ies".into(),
            angle_scale: 0.0,
            normalize: false,
            x: Vec3A::X,
            y: Vec3A::Y,
            tilt: 67.5f32.to_radians(),
        };
        let f = shaping.factor(Vec3A::NEG_Z, Vec3A::NEG_Z);
        assert!((f - 200.0 * 0.65).abs() < 1e-3, "{f}");
        // A table one angle longer than its values: refused, naming the tilt data.
        let e = IesProfile::parse(&type_ab(2, "INCLUDE\n1\n4\n0 45 90\n1 0.8 0.5")).unwrap_err();
        assert!(e.contains("TILT=INCLUDE") && e.contains("wrong length"), "{e}");
        let e = IesProfile::parse_with(&type_ab(2, "gone.tilt"), &|_| Err("no such file".into())).unwrap_err();
        assert!(e.contains("gone.tilt") && e.contains("no such file"), "{e}");
    }

    #[test]
    fn the_mean_is_the_integral_over_the_hemisphere() {
        // A constant profile's mean is its constant; a cosine one (c·cos θ) over the lower
        // hemisphere has mean c/2.
        let flat = "TILT=NONE\n1 -1 1 2 1 1 2 0 0 0 1 1 10\n0 90\n0\n7 7\n";
        assert!((IesProfile::parse(flat).unwrap().mean() - 7.0).abs() < 1e-3);
        let angles: Vec<String> = (0..=90).map(|d| d.to_string()).collect();
        let values: Vec<String> = (0..=90).map(|d| (10.0 * f64::from(d).to_radians().cos()).to_string()).collect();
        let cosine = format!("TILT=NONE\n1 -1 1 91 1 1 2 0 0 0 1 1 10\n{}\n0\n{}\n", angles.join(" "), values.join(" "));
        let m = IesProfile::parse(&cosine).unwrap().mean();
        assert!((m - 5.0).abs() < 5e-3, "{m}");
    }

    #[test]
    fn bad_files_are_refused_with_a_reason() {
        for (text, says) in [
            ("no tilt here\n1 2 3", "TILT"),
            ("TILT=INCLUDE\n1 3 0 90 45 1 1 1\n", "TILT=INCLUDE"),
            ("TILT=other.tilt\n1 2 3", "TILT=other.tilt"),
            ("TILT=NONE\n1 1000 1 3 2 1 2 0 0 0 1 1 100\n0 45\n", "ends before"),
            ("TILT=NONE\n1 1000 1 2 1 4 2 0 0 0 1 1 100\n0 90\n0\n1 1\n", "type"),
            ("TILT=NONE\n1 1000 1 2 1 2 2 0 0 0 1 1 100\n0 120\n0\n1 1\n", "[-90, 90]"),
            ("TILT=NONE\n1 1000 1 2 1 1 2 0 0 0 1 1 100\n0 x\n0\n1 1\n", "not a number"),
        ] {
            let e = IesProfile::parse(text).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }
}
