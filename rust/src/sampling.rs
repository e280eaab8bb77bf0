//! Random numbers that depend only on (seed, pixel, sample, dimension), so the image is a
//! function of the seed alone, whatever the thread count or tile order.

/// A PCG32 stream seeded by hashing (seed, pixel, sample).
#[derive(Clone, Debug)]
pub struct Sampler {
    state: u64,
    inc: u64,
}

#[inline]
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Sampler {
    /// The stream for one sample of one pixel.
    pub fn new(seed: u64, pixel: u64, sample: u64) -> Self {
        let h = splitmix64(seed ^ splitmix64(pixel ^ splitmix64(sample)));
        let mut s = Sampler { state: 0, inc: (splitmix64(h) << 1) | 1 };
        s.next_u32();
        s.state = s.state.wrapping_add(h);
        s.next_u32();
        s
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// A cosine-weighted direction about +Z from two uniform numbers (Malley's method), and its
/// density cos θ / π per steradian.
pub fn cosine_hemisphere(u1: f32, u2: f32) -> (glam::Vec3A, f32) {
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    let z = (1.0 - u1).max(0.0).sqrt();
    (glam::Vec3A::new(r * phi.cos(), r * phi.sin(), z), z * std::f32::consts::FRAC_1_PI)
}

/// An orthonormal frame (t, b, n) around unit `n` (Duff et al. 2017), for turning local
/// directions into world ones.
pub fn frame(n: glam::Vec3A) -> (glam::Vec3A, glam::Vec3A) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (glam::Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), glam::Vec3A::new(b, sign + n.y * n.y * a, -n.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_uniform() {
        let a: Vec<f32> = {
            let mut s = Sampler::new(7, 3, 1);
            (0..4).map(|_| s.next_f32()).collect()
        };
        let b: Vec<f32> = {
            let mut s = Sampler::new(7, 3, 1);
            (0..4).map(|_| s.next_f32()).collect()
        };
        let c: Vec<f32> = {
            let mut s = Sampler::new(8, 3, 1);
            (0..4).map(|_| s.next_f32()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mut s = Sampler::new(1, 2, 3);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| s.next_f32() as f64).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
    }

    #[test]
    fn cosine_samples_have_the_cosine_mean_and_frames_are_orthonormal() {
        let mut s = Sampler::new(3, 4, 5);
        let n = 200_000;
        // E[cos θ] under p = cos θ/π is 2/3.
        let mean: f64 = (0..n).map(|_| cosine_hemisphere(s.next_f32(), s.next_f32()).0.z as f64).sum::<f64>() / n as f64;
        assert!((mean - 2.0 / 3.0).abs() < 3e-3, "{mean}");
        for n in [glam::Vec3A::Z, -glam::Vec3A::Z, glam::Vec3A::new(0.3, -0.5, 0.81).normalize()] {
            let (t, b) = frame(n);
            assert!(t.dot(b).abs() < 1e-6 && t.dot(n).abs() < 1e-6 && b.dot(n).abs() < 1e-6);
            assert!((t.cross(b) - n).length() < 1e-5);
        }
    }
}
