//! Deterministic lattice value noise, for rough walls and surface texture.
//!
//! Values at integer lattice points come from a hash of the point and a seed, so the noise
//! needs no tables and is identical on every machine and thread.

use nalgebra::Point3;

/// Upper bound of `|∇ value(p)|` per lattice unit for [`ValueNoise`].
///
/// Along one axis the derivative is `fade'(t) * (b - a)` with `|fade'| <= 1.5` and
/// `|b - a| <= 2`, so each component is at most 3 (the crude bound on the norm is 3√3).
/// Maximising the norm numerically over the cell and all 256 corner sign patterns gives
/// exactly 3, attained on cell faces; the unit test `gradient_stays_within_bound` checks it.
pub const GRADIENT_BOUND: f64 = 3.0;

/// 64-bit finaliser of SplitMix64: a cheap, well-mixing hash.
#[must_use]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Map a hash to a float uniform in `[0, 1)` (53 random bits).
#[must_use]
pub fn unit_f64(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Value noise in `[-1, 1]` on the integer lattice, smoothstep-interpolated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ValueNoise {
    seed: u64,
}

impl ValueNoise {
    /// Noise whose lattice values derive from `seed`.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self { seed: mix64(seed ^ 0x5EED_CAFE_F00D_D00D) }
    }

    fn lattice(&self, x: i64, y: i64, z: i64) -> f64 {
        let h = mix64(
            self.seed
                ^ (x as u64).wrapping_mul(0x8CB9_2BA7_2F3D_8DD7)
                ^ (y as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93)
                ^ (z as u64).wrapping_mul(0xA076_1D64_78BD_642F),
        );
        2.0 * unit_f64(h) - 1.0
    }

    /// Noise value at `p` (lattice units), in `[-1, 1]`; continuous with gradient norm at
    /// most [`GRADIENT_BOUND`].
    #[must_use]
    pub fn value(&self, p: &Point3<f64>) -> f64 {
        let (fx, fy, fz) = (p.x.floor(), p.y.floor(), p.z.floor());
        let (x, y, z) = (fx as i64, fy as i64, fz as i64);
        let fade = |t: f64| t * t * (3.0 - 2.0 * t);
        let (u, v, w) = (fade(p.x - fx), fade(p.y - fy), fade(p.z - fz));
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let c = |dx: i64, dy: i64, dz: i64| self.lattice(x + dx, y + dy, z + dz);
        let x00 = lerp(c(0, 0, 0), c(1, 0, 0), u);
        let x10 = lerp(c(0, 1, 0), c(1, 1, 0), u);
        let x01 = lerp(c(0, 0, 1), c(1, 0, 1), u);
        let x11 = lerp(c(0, 1, 1), c(1, 1, 1), u);
        lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
    }

    /// Fractal sum of `octaves` octaves (each at twice the frequency and half the
    /// amplitude of the last), normalised back into `[-1, 1]`.
    #[must_use]
    pub fn fbm(&self, p: &Point3<f64>, octaves: u32) -> f64 {
        let (mut sum, mut amp, mut norm, mut q) = (0.0, 1.0, 0.0, *p);
        for _ in 0..octaves {
            sum += amp * self.value(&q);
            norm += amp;
            amp *= 0.5;
            q = Point3::from(q.coords * 2.0 + nalgebra::Vector3::new(17.3, -9.1, 4.7));
        }
        if norm > 0.0 {
            sum / norm
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn values_in_range_and_deterministic() {
        let (a, b) = (ValueNoise::new(1), ValueNoise::new(1));
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..10_000 {
            let p = Point3::new(
                rng.random_range(-50.0..50.0),
                rng.random_range(-50.0..50.0),
                rng.random_range(-50.0..50.0),
            );
            let v = a.value(&p);
            assert!((-1.0..=1.0).contains(&v));
            assert_eq!(v.to_bits(), b.value(&p).to_bits());
        }
        assert_ne!(ValueNoise::new(1).value(&Point3::new(0.3, 0.2, 0.1)), {
            ValueNoise::new(2).value(&Point3::new(0.3, 0.2, 0.1))
        });
    }

    #[test]
    fn gradient_stays_within_bound() {
        let n = ValueNoise::new(7);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let h = 1e-5;
        let mut max_seen: f64 = 0.0;
        for _ in 0..50_000 {
            let p = Point3::new(
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
            );
            let d = |e: nalgebra::Vector3<f64>| (n.value(&(p + e * h)) - n.value(&(p - e * h))) / (2.0 * h);
            let g = nalgebra::Vector3::new(
                d(nalgebra::Vector3::x()),
                d(nalgebra::Vector3::y()),
                d(nalgebra::Vector3::z()),
            );
            max_seen = max_seen.max(g.norm());
        }
        assert!(max_seen <= GRADIENT_BOUND + 1e-6, "max gradient {max_seen}");
        assert!(max_seen > 1.0, "noise too flat: {max_seen}");
    }
}
