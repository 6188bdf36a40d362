//! Deterministic lattice value noise, for rough walls and surface texture.
//!
//! Lattice values come from tables built from a seed with `ChaCha8Rng`, so the noise is
//! identical on every machine and thread. Also holds the small hash helpers used for
//! per-pixel randomness.

use nalgebra::Point3;
use rand::{Rng, SeedableRng, seq::SliceRandom};
use rand_chacha::ChaCha8Rng;

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

/// Lattice period of [`ValueNoise`] along each axis, in lattice units (a power of two).
pub const PERIOD: usize = 256;

/// `x.floor()` (`-0.0` as `0.0`) and the same as `i64` (saturating, as `as` casts), without
/// a call into libm (`floor` is not inlined for the baseline x86-64 target and was a
/// tenth of a cave render).
#[inline]
fn floor_parts(x: f64) -> (f64, i64) {
    // Below 2^52 every f64 converts to i64 exactly after truncation.
    const EXACT: f64 = 4_503_599_627_370_496.0;
    if x.abs() < EXACT {
        let t = x as i64;
        let i = if (t as f64) > x { t - 1 } else { t };
        (i as f64, i)
    } else {
        let f = x.floor();
        (f, f as i64)
    }
}

/// Value noise in `[-1, 1]` on the integer lattice, smoothstep-interpolated.
///
/// Lattice values come from a seeded permutation table (Perlin's scheme), so the noise
/// repeats every [`PERIOD`] lattice units.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueNoise {
    /// A permutation of `0..PERIOD`, stored twice so sums of two entries index it.
    perm: Vec<u8>,
    /// Lattice values in `[-1, 1]`.
    values: Vec<f64>,
}

impl ValueNoise {
    /// Noise whose tables derive from `seed`.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(mix64(seed ^ 0x5EED_CAFE_F00D_D00D));
        let mut perm: Vec<u8> = (0..PERIOD).map(|i| i as u8).collect();
        perm.shuffle(&mut rng);
        perm.extend_from_within(..);
        let values = (0..PERIOD).map(|_| rng.random_range(-1.0..=1.0)).collect();
        Self { perm, values }
    }

    /// The doubled permutation table (`2 * PERIOD` entries) and the `PERIOD` lattice
    /// values, for ports of [`ValueNoise::value`] (the GPU camera).
    #[must_use]
    pub fn tables(&self) -> (&[u8], &[f64]) {
        (&self.perm, &self.values)
    }

    /// Noise value at `p` (lattice units), in `[-1, 1]`; continuous with gradient norm at
    /// most [`GRADIENT_BOUND`].
    #[must_use]
    pub fn value(&self, p: &Point3<f64>) -> f64 {
        let ((fx, ix), (fy, iy), (fz, iz)) = (floor_parts(p.x), floor_parts(p.y), floor_parts(p.z));
        // PERIOD is a power of two: the mask is `rem_euclid` on two's complement.
        let wrap = |i: i64| (i & (PERIOD as i64 - 1)) as usize;
        let (x, y, z) = (wrap(ix), wrap(iy), wrap(iz));
        let fade = |t: f64| t * t * (3.0 - 2.0 * t);
        let (u, v, w) = (fade(p.x - fx), fade(p.y - fy), fade(p.z - fz));
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let (pm, val) = (&self.perm, &self.values);
        let at = |i: usize| val[usize::from(pm[i])];
        let a = usize::from(pm[x]) + y;
        let b = usize::from(pm[x + 1]) + y;
        let (aa, ab) = (usize::from(pm[a]) + z, usize::from(pm[a + 1]) + z);
        let (ba, bb) = (usize::from(pm[b]) + z, usize::from(pm[b + 1]) + z);
        let x00 = lerp(at(aa), at(ba), u);
        let x10 = lerp(at(ab), at(bb), u);
        let x01 = lerp(at(aa + 1), at(ba + 1), u);
        let x11 = lerp(at(ab + 1), at(bb + 1), u);
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
        if norm > 0.0 { sum / norm } else { 0.0 }
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
        let q = Point3::new(0.3, 0.2, 0.1);
        assert_ne!(ValueNoise::new(1).value(&q), ValueNoise::new(2).value(&q));
        // Periodic, and continuous across the wrap.
        let r = Point3::new(-0.5, 3.25, 255.999_999);
        let wrapped = Point3::new(r.x + PERIOD as f64, r.y - PERIOD as f64, r.z);
        assert!((a.value(&r) - a.value(&wrapped)).abs() < 1e-12);
        let s = Point3::new(-0.5, 3.25, 256.0);
        assert!((a.value(&r) - a.value(&s)).abs() < 1e-4);
    }

    #[test]
    fn floor_parts_is_floor() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let edge = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -0.5,
            1e-300,
            -1e-300,
            2.5e15,
            -2.5e15,
            4.5e15,
            -4.5e15,
            9.3e18,
            -9.3e18,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let random = (0..100_000).map(|i| {
            let scale = [1.0, 300.0, 1e12][i % 3];
            rng.random_range(-scale..scale)
        });
        for x in edge.into_iter().chain(random) {
            let (f, i) = floor_parts(x);
            // Equal as numbers (-0.0 comes back as 0.0, which `value` cannot tell apart).
            assert!(f == x.floor() || (f.is_nan() && x.is_nan()), "{x}");
            assert_eq!(i, x.floor() as i64, "{x}");
        }
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
            let d = |e: nalgebra::Vector3<f64>| {
                (n.value(&(p + e * h)) - n.value(&(p - e * h))) / (2.0 * h)
            };
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
