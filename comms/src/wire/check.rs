//! Content checks shared by the encoder (refuse to send garbage) and the decoder
//! (refuse to accept it), plus the small fixed-size linear algebra they need.
//!
//! Everything here runs in `f64` on values upcast from the wire's `f32`, so a
//! check never fails because of its own rounding.

// Small fixed-size matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use serde::de::{self, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserializer, Serializer};

use super::ContentError;

/// Tolerance on the sum of mixture weights: `|Σ w − 1| ≤ 1e-4`.
///
/// Weights travel as `f32` (relative rounding 6·10⁻⁸ each); a sender that
/// normalises in `f64` and rounds once lands within 10⁻⁶ even for 10⁴
/// components. 10⁻⁴ also admits senders that normalise in `f32`, and is still
/// tight enough that a missing or duplicated component is caught.
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-4;

/// Tolerance on the squared norm of an `f32` unit quaternion: `|‖q‖² − 1| ≤ 1e-5`
/// (an `f32` normalisation lands within a few 10⁻⁷).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-5;

pub(crate) fn all_finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

pub(crate) fn unit_quaternion(q: &[f32; 4]) -> bool {
    let n2: f64 = q.iter().map(|v| f64::from(*v) * f64::from(*v)).sum();
    (n2 - 1.0).abs() <= QUATERNION_NORM_TOLERANCE
}

/// Expands an upper triangle stored row by row — `(0,0), (0,1), …, (0,d−1),
/// (1,1), …, (d−1,d−1)` — into a full symmetric `f64` matrix.
pub(crate) fn unpack_symmetric<const D: usize>(packed: &[f32]) -> [[f64; D]; D] {
    let mut m = [[0.0; D]; D];
    let mut k = 0;
    for i in 0..D {
        for j in i..D {
            let v = f64::from(packed[k]);
            m[i][j] = v;
            m[j][i] = v;
            k += 1;
        }
    }
    m
}

/// The inverse of [`unpack_symmetric`] (reads the upper triangle, rounds to `f32`).
pub(crate) fn pack_symmetric<const D: usize>(m: &[[f64; D]; D], packed: &mut [f32]) {
    let mut k = 0;
    for i in 0..D {
        for j in i..D {
            packed[k] = m[i][j] as f32;
            k += 1;
        }
    }
}

/// Lower Cholesky factor `L` with `L Lᵀ = A`, or `None` if `A` is not positive
/// definite (a pivot ≤ 0 or not finite).
pub(crate) fn cholesky<const D: usize>(a: &[[f64; D]; D]) -> Option<[[f64; D]; D]> {
    let mut l = [[0.0; D]; D];
    for i in 0..D {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    Some(l)
}

/// Checks a mixture: every weight finite and > 0, every covariance positive
/// definite, weights summing to 1 within [`WEIGHT_SUM_TOLERANCE`].
pub(crate) fn mixture<'a, const D: usize>(
    components: impl ExactSizeIterator<Item = (f32, &'a [f32], &'a [f32])>,
) -> Result<(), ContentError> {
    if components.len() == 0 {
        return Err(ContentError::Message("mixture has no components"));
    }
    let mut sum = 0.0f64;
    for (index, (weight, mean, covariance)) in components.enumerate() {
        let at = |reason| ContentError::Element { index, reason };
        if !(all_finite(mean) && all_finite(covariance) && weight.is_finite()) {
            return Err(at("component contains NaN or infinity"));
        }
        if weight <= 0.0 {
            return Err(at("component weight is not positive"));
        }
        if cholesky::<D>(&unpack_symmetric::<D>(covariance)).is_none() {
            return Err(at("component covariance is not positive definite"));
        }
        sum += f64::from(weight);
    }
    if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
        return Err(ContentError::Message("mixture weights do not sum to 1"));
    }
    Ok(())
}

/// Serde helper: a `[u16; N]` as `2N` little-endian bytes (no varint), so that
/// fixed-size records stay fixed-size under postcard.
pub(crate) mod fixed_u16 {
    use super::*;

    pub(crate) fn serialize<S: Serializer, const N: usize>(
        values: &[u16; N],
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        let mut t = serializer.serialize_tuple(2 * N)?;
        for v in values {
            for b in v.to_le_bytes() {
                t.serialize_element(&b)?;
            }
        }
        t.end()
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        deserializer: D,
    ) -> Result<[u16; N], D::Error> {
        struct V<const N: usize>;
        impl<'de, const N: usize> Visitor<'de> for V<N> {
            type Value = [u16; N];
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "{} little-endian bytes", 2 * N)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[u16; N], A::Error> {
                let mut out = [0u16; N];
                for (i, slot) in out.iter_mut().enumerate() {
                    let lo: u8 = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(2 * i, &self))?;
                    let hi: u8 = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(2 * i + 1, &self))?;
                    *slot = u16::from_le_bytes([lo, hi]);
                }
                Ok(out)
            }
        }
        deserializer.deserialize_tuple(2 * N, V::<N>)
    }
}

/// Serde helper: a `[i16; N]` as `2N` little-endian bytes (two's complement).
pub(crate) mod fixed_i16 {
    use super::*;

    pub(crate) fn serialize<S: Serializer, const N: usize>(
        values: &[i16; N],
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        super::fixed_u16::serialize(&values.map(|v| v as u16), serializer)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        deserializer: D,
    ) -> Result<[i16; N], D::Error> {
        super::fixed_u16::deserialize::<D, N>(deserializer).map(|a| a.map(|v| v as i16))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_reconstructs_and_rejects() {
        let a = [[4.0, 2.0, 0.4], [2.0, 2.0, 0.2], [0.4, 0.2, 1.0]];
        let l = cholesky(&a).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| l[i][k] * l[j][k]).sum();
                assert!((s - a[i][j]).abs() < 1e-12);
            }
        }
        assert!(cholesky(&[[1.0, 2.0], [2.0, 1.0]]).is_none());
        assert!(cholesky(&[[f64::NAN, 0.0], [0.0, 1.0]]).is_none());
        assert!(cholesky(&[[0.0, 0.0], [0.0, 1.0]]).is_none());
    }

    #[test]
    fn packing_round_trips() {
        let packed: Vec<f32> = (1..=10).map(|v| v as f32).collect();
        let m = unpack_symmetric::<4>(&packed);
        assert_eq!(m[0], [1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m[3], [4.0, 7.0, 9.0, 10.0]);
        let mut back = [0.0f32; 10];
        pack_symmetric(&m, &mut back);
        assert_eq!(&back[..], &packed[..]);
    }
}
