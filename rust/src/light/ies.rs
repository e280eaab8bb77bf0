//! IESNA LM-63 photometric profiles (UsdLux `ShapingAPI`'s `shaping:ies:file`): the candela a
//! luminaire emits by vertical and horizontal angle, applied as Hydra's hdEmbree applies them.
//!
//! **Reading.** LM-63-1995 and -2002 files (`IESNA:LM-63-1995`, `IESNA:LM-63-2002`, or the
//! 1986 form without that line): keyword lines up to `TILT=`, which must be `TILT=NONE` (a
//! tilt table changes the output with the lamp's tilt, which a UsdLux light does not have);
//! then the numbers, whitespace- or comma-separated over any lines: lamp count, lumens per
//! lamp, candela multiplier, vertical and horizontal angle counts, photometric type (1 = type
//! C, the only one read: a type A or B profile is refused), units, the three luminous
//! dimensions, ballast factor, ballast-lamp photometric factor (the 1995 "future use"), input
//! watts, the vertical angles, the horizontal angles and the candela values (one row of
//! vertical angles per horizontal angle). Candela are the file's values × candela multiplier
//! × ballast factor × ballast-lamp factor.
//!
//! **Evaluation.** θ is the angle between the emission direction and the light's −Z (the
//! profile's nadir, vertical angle 0), φ the azimuth about that axis measured in the light's
//! XY plane of the direction toward the light (hdEmbree's `atan2(y, x)` of it), folded into
//! the file's horizontal range by its symmetry (one angle: symmetric about the axis; last
//! angle 90°: quadrant symmetry; 180°: bilateral; 360°: none). `ies:angleScale` s rescales θ
//! about the zenith as RenderMan does: θ' = (θ − π)/(1 + s) + π, clamped to [0, π]. Candela
//! are interpolated bilinearly in (θ', φ); outside the file's vertical range the profile is 0.
//! With `ies:normalize` the value is divided by the profile's mean candela over the sphere (or
//! the hemisphere, for a profile spanning no more than 90° + a little), so the shaping keeps
//! the light's power; without it the factor is the candela value itself.

/// A parsed type C profile.
#[derive(Clone, Debug, PartialEq)]
pub struct IesProfile {
    /// Vertical angles, radians, increasing.
    v: Vec<f32>,
    /// Horizontal angles, radians, increasing.
    h: Vec<f32>,
    /// Candela, `cd[hi * v.len() + vi]`.
    cd: Vec<f32>,
    /// Mean candela over the sphere or hemisphere the profile covers ([`IesProfile::mean`]).
    mean: f32,
    peak: f32,
}

impl IesProfile {
    /// Parses an LM-63 file's text.
    ///
    /// # Errors
    /// A one-line reason: no `TILT=` line, a tilt other than `NONE`, missing or non-numeric
    /// values, a photometric type other than C, angles that do not increase, negative candela.
    pub fn parse(text: &str) -> Result<IesProfile, String> {
        let mut lines = text.lines();
        let tilt = loop {
            let Some(line) = lines.next() else { return Err("no TILT= line".into()) };
            if let Some(rest) = line.trim_start().strip_prefix("TILT=") {
                break rest.trim().to_string();
            }
        };
        if !tilt.eq_ignore_ascii_case("NONE") {
            return Err(format!("TILT={tilt} is not supported (only TILT=NONE)"));
        }
        let rest: Vec<&str> = lines.collect();
        let mut nums = rest.iter().flat_map(|l| l.split(|c: char| c.is_whitespace() || c == ',')).filter(|t| !t.is_empty());
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
        if kind != 1.0 {
            return Err(format!("photometric type {kind} is not supported (only type C, 1)"));
        }
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
        if v[0] < 0.0 || v[nv - 1] > std::f32::consts::PI + 1e-4 {
            return Err("vertical angles outside [0, 180] degrees".into());
        }
        let mut p = IesProfile { v, h, cd, mean: 0.0, peak: 0.0 };
        p.peak = p.cd.iter().copied().fold(0.0, f32::max);
        p.mean = p.mean_candela();
        Ok(p)
    }

    /// Candela at vertical index `vi`, horizontal index `hi`.
    fn at(&self, hi: usize, vi: usize) -> f32 {
        self.cd[hi * self.v.len() + vi]
    }

    /// Mean candela over the solid angle the profile covers: the whole sphere, or the
    /// hemisphere when its vertical angles span no more than 90° (+0.1 rad, as hdEmbree).
    /// Integrated cell by cell (midpoint rule in θ, the profile's own bilinear values) over
    /// every azimuth, whatever horizontal symmetry the file uses.
    fn mean_candela(&self) -> f32 {
        let span = self.v[self.v.len() - 1] - self.v[0];
        let sphere = span > std::f32::consts::FRAC_PI_2 + 0.1;
        let (nt, np) = (720usize, 360usize);
        let (t0, t1) = (self.v[0], self.v[self.v.len() - 1]);
        let mut sum = 0.0f64;
        for i in 0..nt {
            let theta = t0 + (t1 - t0) * (i as f32 + 0.5) / nt as f32;
            let d_omega = f64::from((t1 - t0) / nt as f32 * theta.sin()) * (2.0 * std::f64::consts::PI / np as f64);
            for j in 0..np {
                let phi = 2.0 * std::f32::consts::PI * (j as f32 + 0.5) / np as f32;
                sum += f64::from(self.candela(theta, phi)) * d_omega;
            }
        }
        let area = if sphere { 4.0 } else { 2.0 } * std::f64::consts::PI;
        (sum / area) as f32
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
            ("TILT=INCLUDE\n1 2 3", "TILT=INCLUDE"),
            ("TILT=NONE\n1 1000 1 3 2 1 2 0 0 0 1 1 100\n0 45\n", "ends before"),
            ("TILT=NONE\n1 1000 1 2 1 2 2 0 0 0 1 1 100\n0 90\n0\n1 1\n", "type"),
            ("TILT=NONE\n1 1000 1 2 1 1 2 0 0 0 1 1 100\n0 x\n0\n1 1\n", "not a number"),
        ] {
            let e = IesProfile::parse(text).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }
}
