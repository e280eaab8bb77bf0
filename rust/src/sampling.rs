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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_uniform() {
        let a: Vec<f32> = { let mut s = Sampler::new(7, 3, 1); (0..4).map(|_| s.next_f32()).collect() };
        let b: Vec<f32> = { let mut s = Sampler::new(7, 3, 1); (0..4).map(|_| s.next_f32()).collect() };
        let c: Vec<f32> = { let mut s = Sampler::new(8, 3, 1); (0..4).map(|_| s.next_f32()).collect() };
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mut s = Sampler::new(1, 2, 3);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| s.next_f32() as f64).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
    }
}
