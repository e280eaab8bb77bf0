//! The MaterialX standard library's Perlin noise (`noise2d`, `noise3d`, `fractal2d`,
//! `fractal3d` of a float), for [`super::network`].
//!
//! A port of the arithmetic of MaterialX 1.39's `libraries/stdlib/genglsl/lib/mx_noise.glsl`
//! (`mx_perlin_noise_float`, `mx_fractal{2,3}d_noise_float` and the Bob Jenkins hash they use),
//! function for function and in f32 / u32 as the GLSL is: mipray evaluates node networks with
//! its own evaluator rather than generated shader code, so the noise must be the reference's own
//! for a marble to look as it does in Storm and MaterialX's viewer.

/// `mx_rotl32`.
#[inline]
fn rotl32(x: u32, k: u32) -> u32 {
    x.rotate_left(k)
}

/// `mx_bjfinal`: Bob Jenkins' `final` mix of three words.
#[inline]
fn bjfinal(mut a: u32, mut b: u32, mut c: u32) -> u32 {
    c ^= b;
    c = c.wrapping_sub(rotl32(b, 14));
    a ^= c;
    a = a.wrapping_sub(rotl32(c, 11));
    b ^= a;
    b = b.wrapping_sub(rotl32(a, 25));
    c ^= b;
    c = c.wrapping_sub(rotl32(b, 16));
    a ^= c;
    a = a.wrapping_sub(rotl32(c, 4));
    b ^= a;
    b = b.wrapping_sub(rotl32(a, 14));
    c ^= b;
    c = c.wrapping_sub(rotl32(b, 24));
    c
}

/// `mx_hash_int(x, y)`.
#[inline]
fn hash2(x: i32, y: i32) -> u32 {
    let seed = 0xdead_beef_u32.wrapping_add(2 << 2).wrapping_add(13);
    bjfinal(seed.wrapping_add(x as u32), seed.wrapping_add(y as u32), seed)
}

/// `mx_hash_int(x, y, z)`.
#[inline]
fn hash3(x: i32, y: i32, z: i32) -> u32 {
    let seed = 0xdead_beef_u32.wrapping_add(3 << 2).wrapping_add(13);
    bjfinal(seed.wrapping_add(x as u32), seed.wrapping_add(y as u32), seed.wrapping_add(z as u32))
}

/// `mx_negate_if`.
#[inline]
fn negate_if(v: f32, b: bool) -> f32 {
    if b {
        -v
    } else {
        v
    }
}

/// `mx_gradient_float(hash, x, y)`: one of 8 directions (±1, ±2), (±2, ±1), dotted with (x, y).
#[inline]
fn gradient2(hash: u32, x: f32, y: f32) -> f32 {
    let h = hash & 7;
    let u = if h < 4 { x } else { y };
    let v = 2.0 * if h < 4 { y } else { x };
    negate_if(u, h & 1 != 0) + negate_if(v, h & 2 != 0)
}

/// `mx_gradient_float(hash, x, y, z)`: one of the cube's 12 edge directions, dotted.
#[inline]
fn gradient3(hash: u32, x: f32, y: f32, z: f32) -> f32 {
    let h = hash & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    negate_if(u, h & 1 != 0) + negate_if(v, h & 2 != 0)
}

/// `mx_floorfrac`: (x − floor(x), floor(x) as an int). GLSL's `int()` of a float beyond i32 is
/// undefined; Rust's saturating cast is as good as any there.
#[inline]
fn floorfrac(x: f32) -> (f32, i32) {
    let i = x.floor() as i32;
    (x - i as f32, i)
}

/// `mx_fade`: 6t⁵ − 15t⁴ + 10t³.
#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// `mx_perlin_noise_float(vec2)`: about [−1, 1], 0 at every integer lattice point.
pub fn perlin2(p: [f32; 2]) -> f32 {
    let (fx, x) = floorfrac(p[0]);
    let (fy, y) = floorfrac(p[1]);
    let (u, v) = (fade(fx), fade(fy));
    let (x1, y1) = (x.wrapping_add(1), y.wrapping_add(1));
    // mx_bilerp
    let (v0, v1, v2, v3) = (
        gradient2(hash2(x, y), fx, fy),
        gradient2(hash2(x1, y), fx - 1.0, fy),
        gradient2(hash2(x, y1), fx, fy - 1.0),
        gradient2(hash2(x1, y1), fx - 1.0, fy - 1.0),
    );
    let s1 = 1.0 - u;
    let result = (1.0 - v) * (v0 * s1 + v1 * u) + v * (v2 * s1 + v3 * u);
    // mx_gradient_scale2d
    0.6616 * result
}

/// `mx_perlin_noise_float(vec3)`: about [−1, 1], 0 at every integer lattice point.
pub fn perlin3(p: [f32; 3]) -> f32 {
    let (fx, x) = floorfrac(p[0]);
    let (fy, y) = floorfrac(p[1]);
    let (fz, z) = floorfrac(p[2]);
    let (u, v, w) = (fade(fx), fade(fy), fade(fz));
    let (x1, y1, z1) = (x.wrapping_add(1), y.wrapping_add(1), z.wrapping_add(1));
    let g = [
        gradient3(hash3(x, y, z), fx, fy, fz),
        gradient3(hash3(x1, y, z), fx - 1.0, fy, fz),
        gradient3(hash3(x, y1, z), fx, fy - 1.0, fz),
        gradient3(hash3(x1, y1, z), fx - 1.0, fy - 1.0, fz),
        gradient3(hash3(x, y, z1), fx, fy, fz - 1.0),
        gradient3(hash3(x1, y, z1), fx - 1.0, fy, fz - 1.0),
        gradient3(hash3(x, y1, z1), fx, fy - 1.0, fz - 1.0),
        gradient3(hash3(x1, y1, z1), fx - 1.0, fy - 1.0, fz - 1.0),
    ];
    // mx_trilerp
    let (s1, t1, r1) = (1.0 - u, 1.0 - v, 1.0 - w);
    let result =
        r1 * (t1 * (g[0] * s1 + g[1] * u) + v * (g[2] * s1 + g[3] * u)) + w * (t1 * (g[4] * s1 + g[5] * u) + v * (g[6] * s1 + g[7] * u));
    // mx_gradient_scale3d
    0.9820 * result
}

/// `mx_fractal2d_noise_float`: Σ diminishᵢ · perlin2(lacunarityⁱ · p) over `octaves` octaves.
pub fn fractal2(mut p: [f32; 2], octaves: u32, lacunarity: f32, diminish: f32) -> f32 {
    let (mut result, mut amplitude) = (0.0f32, 1.0f32);
    for _ in 0..octaves {
        result += amplitude * perlin2(p);
        amplitude *= diminish;
        p = p.map(|x| x * lacunarity);
    }
    result
}

/// `mx_fractal3d_noise_float`: Σ diminishᵢ · perlin3(lacunarityⁱ · p) over `octaves` octaves.
pub fn fractal3(mut p: [f32; 3], octaves: u32, lacunarity: f32, diminish: f32) -> f32 {
    let (mut result, mut amplitude) = (0.0f32, 1.0f32);
    for _ in 0..octaves {
        result += amplitude * perlin3(p);
        amplitude *= diminish;
        p = p.map(|x| x * lacunarity);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_points_are_zero_and_between_them_it_varies() {
        for &(x, y, z) in &[(0, 0, 0), (3, -2, 7), (-5, 11, -1), (100, 200, -300)] {
            assert_eq!(perlin3([x as f32, y as f32, z as f32]), 0.0);
            assert_eq!(perlin2([x as f32, y as f32]), 0.0);
        }
        let v = perlin3([0.3, 1.7, -2.2]);
        assert!(v != 0.0 && v.abs() < 1.1, "{v}");
        let mut lo: f32 = 0.0;
        let mut hi: f32 = 0.0;
        for i in 0..4000 {
            let t = i as f32 * 0.0137;
            let n = perlin3([t, 0.31 * t + 0.5, -0.7 * t]);
            lo = lo.min(n);
            hi = hi.max(n);
        }
        assert!(lo < -0.3 && hi > 0.3 && lo >= -1.1 && hi <= 1.1, "{lo} {hi}");
    }

    #[test]
    fn fractal_is_the_sum_of_scaled_octaves() {
        let p = [0.41, -1.3, 2.77];
        let want = perlin3(p) + 0.6 * perlin3(p.map(|x| x * 1.9)) + 0.36 * perlin3(p.map(|x| x * 1.9 * 1.9));
        assert!((fractal3(p, 3, 1.9, 0.6) - want).abs() < 1e-6);
        assert_eq!(fractal3(p, 1, 2.0, 0.5), perlin3(p));
        assert_eq!(fractal3(p, 0, 2.0, 0.5), 0.0);
        let q = [0.41, -1.3];
        assert_eq!(fractal2(q, 2, 2.0, 0.5), perlin2(q) + 0.5 * perlin2([0.82, -2.6]));
    }
}
