//! Keyframe payload: a GMM fitted to one sensor observation, the sensor pose it was
//! taken from and its support size (thesis §8.2.2).
//!
//! # Layout and size
//!
//! Every number is fixed-width so that sizes can be predicted exactly and compared
//! with the thesis' accounting (§8.2.5: "each component requires 10 floating
//! point numbers"; App. A: `4 · M · (1 + 10 + 4)` bytes for 4D):
//!
//! | record | fields (in wire order) | bytes |
//! |---|---|---|
//! | [`Component3`] | mean 3×f32, covariance 6×f32, weight f32 | **40** |
//! | [`Component4`] | mean 4×f32, covariance 10×f32, weight f32 | **60** |
//! | [`CompactComponent3`] | mean 3×f32, ln σ 3×u16, correlation factor 5×i16, ln weight u16 | 30 |
//! | [`CompactComponent4`] | mean 4×f32, ln σ 4×u16, correlation factor 9×i16, ln weight u16 | 44 |
//! | [`SensorPose`] | position 3×f32, unit quaternion 4×f32 | 28 |
//!
//! A [`Keyframe`] is `keyframe_id` (u32) + [`SensorPose`] + `support_size` (u32) +
//! one byte naming the [`Mixture`] variant + the component count (postcard varint:
//! 1 byte below 128, 2 below 16384) + the components: **37 + varint(N) + 40 N**
//! bytes for a 3D mixture, **37 + varint(N) + 60 N** for 4D. The thesis counts
//! 28 bytes of overhead (6 floats of pose and a 32-bit support size); we send a
//! quaternion instead of three angles (+4 B), an id (+4 B) and the variant and
//! count (+2 B).
//!
//! Covariances are symmetric; only the upper triangle travels, row by row:
//! `(0,0), (0,1), …, (0,D−1), (1,1), …, (D−1,D−1)`.
//!
//! # Compact encoding
//!
//! [`Mixture::compact`] re-encodes a mixture in about three quarters of the bytes.
//! Means stay `f32` (they dominate the likelihood). The covariance is written as
//! `Σ = S R S` with `S = diag(σ)`: each σᵢ as a 16-bit code of `ln σᵢ` (steps of
//! 1/2048, so a relative error ≤ 2.4·10⁻⁴, range 10⁻⁶ … 7.9·10⁷), and the Cholesky
//! factor of the correlation matrix `R` (rows of unit length, entries in [−1, 1])
//! as `i16` in steps of 1/32767, without its first row (always `[1]`). The decoder
//! re-normalises every row, so the diagonal of `R` is exactly 1 and positive
//! definiteness is kept as long as the factor's diagonal codes are positive (the
//! encoder never writes less than 1). Keeping the diagonal entry of each row —
//! rather than deriving it from the others — preserves the small conditional
//! variances of thin, surface-like components. Weights travel as `−ln w` in steps
//! of 1/2048 (relative error ≤ 2.4·10⁻⁴) and are re-normalised on decode.

// Small fixed-size matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use serde::{Deserialize, Serialize};

use super::ContentError;
use super::check::{self, fixed_i16, fixed_u16};

/// The pose of the sensor when the keyframe's points were taken, in the sender's
/// world frame (a ray-tracing origin for peers, thesis §8.2.2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorPose {
    /// Position, metres.
    pub position_m: [f32; 3],
    /// Orientation as a unit quaternion `(x, y, z, w)`.
    pub orientation_xyzw: [f32; 4],
}

impl SensorPose {
    fn validate(&self) -> Result<(), ContentError> {
        if !(check::all_finite(&self.position_m) && check::all_finite(&self.orientation_xyzw)) {
            return Err(ContentError::Message(
                "sensor pose contains NaN or infinity",
            ));
        }
        if !check::unit_quaternion(&self.orientation_xyzw) {
            return Err(ContentError::Message(
                "sensor orientation is not a unit quaternion",
            ));
        }
        Ok(())
    }
}

/// A 3D (spatial) Gaussian component: 10 `f32`, 40 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Component3 {
    /// Mean `(x, y, z)`, metres.
    pub mean: [f32; 3],
    /// Covariance, upper triangle row by row (see the [module docs](self)), m².
    pub covariance: [f32; 6],
    /// Mixing weight, > 0; a mixture's weights sum to 1.
    pub weight: f32,
}

/// A 4D (spatial + intensity) Gaussian component: 15 `f32`, 60 bytes (§6.1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Component4 {
    /// Mean `(x, y, z, intensity)`; metres and the sensor's intensity unit.
    pub mean: [f32; 4],
    /// Covariance, upper triangle row by row (see the [module docs](self)).
    pub covariance: [f32; 10],
    /// Mixing weight, > 0; a mixture's weights sum to 1.
    pub weight: f32,
}

impl Component3 {
    /// The covariance as a full symmetric `f64` matrix.
    #[must_use]
    pub fn covariance_matrix(&self) -> [[f64; 3]; 3] {
        check::unpack_symmetric::<3>(&self.covariance)
    }
}

impl Component4 {
    /// The covariance as a full symmetric `f64` matrix.
    #[must_use]
    pub fn covariance_matrix(&self) -> [[f64; 4]; 4] {
        check::unpack_symmetric::<4>(&self.covariance)
    }
}

/// A 3D component in the compact encoding (30 bytes; see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompactComponent3 {
    mean: [f32; 3],
    #[serde(with = "fixed_u16")]
    ln_sigma: [u16; 3],
    #[serde(with = "fixed_i16")]
    correlation_factor: [i16; 5],
    #[serde(with = "postcard::fixint::le")]
    neg_ln_weight: u16,
}

/// A 4D component in the compact encoding (44 bytes; see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompactComponent4 {
    mean: [f32; 4],
    #[serde(with = "fixed_u16")]
    ln_sigma: [u16; 4],
    #[serde(with = "fixed_i16")]
    correlation_factor: [i16; 9],
    #[serde(with = "postcard::fixint::le")]
    neg_ln_weight: u16,
}

/// The mixture carried by a keyframe. Variant order is the protocol.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Mixture {
    /// 3D components, exact `f32`.
    Spatial(Vec<Component3>),
    /// 4D components (x, y, z, intensity), exact `f32` (§6).
    SpatialIntensity(Vec<Component4>),
    /// 3D components in the compact encoding.
    CompactSpatial(Vec<CompactComponent3>),
    /// 4D components in the compact encoding.
    CompactSpatialIntensity(Vec<CompactComponent4>),
}

/// A keyframe GMM with its sensor pose and support size (thesis §8.2.2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Keyframe {
    /// Per-sender keyframe counter.
    #[serde(with = "postcard::fixint::le")]
    pub keyframe_id: u32,
    /// Sensor pose at the observation, sender's world frame.
    pub sensor_pose: SensorPose,
    /// Number of points the mixture was fitted to; a receiver samples this many
    /// points to ray-trace the keyframe into its grid (§8.2.2).
    #[serde(with = "postcard::fixint::le")]
    pub support_size: u32,
    /// The mixture.
    pub mixture: Mixture,
}

impl Keyframe {
    pub(super) fn validate(&self) -> Result<(), ContentError> {
        self.sensor_pose.validate()?;
        self.mixture.validate()
    }
}

// Compact-encoding constants (see the module docs for the error they imply).
const LN_STEP: f64 = 1.0 / 2048.0;
const LN_SIGMA_MIN: f64 = -13.815_510_557_964_274; // ln(1e-6)
const FACTOR_SCALE: f64 = 32767.0;

impl Mixture {
    /// Number of components.
    #[must_use]
    pub fn len(&self) -> usize {
        match self {
            Mixture::Spatial(c) => c.len(),
            Mixture::SpatialIntensity(c) => c.len(),
            Mixture::CompactSpatial(c) => c.len(),
            Mixture::CompactSpatialIntensity(c) => c.len(),
        }
    }

    /// True when there are no components (never the case for a valid keyframe).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// 3 or 4.
    #[must_use]
    pub fn dimension(&self) -> usize {
        match self {
            Mixture::Spatial(_) | Mixture::CompactSpatial(_) => 3,
            Mixture::SpatialIntensity(_) | Mixture::CompactSpatialIntensity(_) => 4,
        }
    }

    /// True for the compact variants.
    #[must_use]
    pub fn is_compact(&self) -> bool {
        matches!(
            self,
            Mixture::CompactSpatial(_) | Mixture::CompactSpatialIntensity(_)
        )
    }

    /// The same mixture in the compact encoding (a copy if it already is).
    ///
    /// Fails when the mixture is not valid, or when a standard deviation lies
    /// outside the compact range (10⁻⁶ … 7.9·10⁷) or the quantised covariance
    /// would no longer be positive definite (condition numbers beyond ~10⁹).
    pub fn compact(&self) -> Result<Mixture, ContentError> {
        self.validate()?;
        let compact = match self {
            Mixture::Spatial(c) => Mixture::CompactSpatial(
                c.iter()
                    .enumerate()
                    .map(|(i, c)| {
                        let (ln_sigma, correlation_factor, neg_ln_weight) =
                            compress::<3, 5>(&c.covariance_matrix(), c.weight, i)?;
                        Ok(CompactComponent3 {
                            mean: c.mean,
                            ln_sigma,
                            correlation_factor,
                            neg_ln_weight,
                        })
                    })
                    .collect::<Result<_, ContentError>>()?,
            ),
            Mixture::SpatialIntensity(c) => Mixture::CompactSpatialIntensity(
                c.iter()
                    .enumerate()
                    .map(|(i, c)| {
                        let (ln_sigma, correlation_factor, neg_ln_weight) =
                            compress::<4, 9>(&c.covariance_matrix(), c.weight, i)?;
                        Ok(CompactComponent4 {
                            mean: c.mean,
                            ln_sigma,
                            correlation_factor,
                            neg_ln_weight,
                        })
                    })
                    .collect::<Result<_, ContentError>>()?,
            ),
            Mixture::CompactSpatial(_) | Mixture::CompactSpatialIntensity(_) => {
                return Ok(self.clone());
            }
        };
        // Refuse to send what a receiver would refuse.
        compact.validate()?;
        Ok(compact)
    }

    /// The same mixture with exact `f32` components (a copy if it already is).
    ///
    /// For a compact mixture that passed validation (every decoded one) the
    /// result is valid too.
    #[must_use]
    pub fn expand(&self) -> Mixture {
        match self {
            Mixture::Spatial(_) | Mixture::SpatialIntensity(_) => self.clone(),
            Mixture::CompactSpatial(c) => {
                let weights = expand_weights(c.iter().map(|c| c.neg_ln_weight));
                Mixture::Spatial(
                    c.iter()
                        .zip(weights)
                        .map(|(c, weight)| {
                            let mut covariance = [0.0; 6];
                            check::pack_symmetric(
                                &expand_covariance::<3, 5>(&c.ln_sigma, &c.correlation_factor),
                                &mut covariance,
                            );
                            Component3 {
                                mean: c.mean,
                                covariance,
                                weight,
                            }
                        })
                        .collect(),
                )
            }
            Mixture::CompactSpatialIntensity(c) => {
                let weights = expand_weights(c.iter().map(|c| c.neg_ln_weight));
                Mixture::SpatialIntensity(
                    c.iter()
                        .zip(weights)
                        .map(|(c, weight)| {
                            let mut covariance = [0.0; 10];
                            check::pack_symmetric(
                                &expand_covariance::<4, 9>(&c.ln_sigma, &c.correlation_factor),
                                &mut covariance,
                            );
                            Component4 {
                                mean: c.mean,
                                covariance,
                                weight,
                            }
                        })
                        .collect(),
                )
            }
        }
    }

    /// Checks the mixture: not empty, no NaN or infinity, positive weights summing
    /// to 1 within [`WEIGHT_SUM_TOLERANCE`](super::WEIGHT_SUM_TOLERANCE), positive
    /// definite covariances (Cholesky of the `f64`-upcast matrix).
    pub fn validate(&self) -> Result<(), ContentError> {
        match self {
            Mixture::Spatial(c) => {
                check::mixture::<3>(c.iter().map(|c| (c.weight, &c.mean[..], &c.covariance[..])))
            }
            Mixture::SpatialIntensity(c) => {
                check::mixture::<4>(c.iter().map(|c| (c.weight, &c.mean[..], &c.covariance[..])))
            }
            Mixture::CompactSpatial(c) => {
                for (index, c) in c.iter().enumerate() {
                    compact_preconditions::<3, 5>(&c.mean, &c.correlation_factor, index)?;
                }
                self.expand().validate()
            }
            Mixture::CompactSpatialIntensity(c) => {
                for (index, c) in c.iter().enumerate() {
                    compact_preconditions::<4, 9>(&c.mean, &c.correlation_factor, index)?;
                }
                self.expand().validate()
            }
        }
    }
}

/// Finite means and positive factor diagonals: what must hold before a compact
/// component can be expanded at all.
fn compact_preconditions<const D: usize, const C: usize>(
    mean: &[f32; D],
    factor: &[i16; C],
    index: usize,
) -> Result<(), ContentError> {
    if !check::all_finite(mean) {
        return Err(ContentError::Element {
            index,
            reason: "component mean contains NaN or infinity",
        });
    }
    // The diagonal entry of row i (i ≥ 1) is the last of that row's i + 1 codes.
    let mut k = 0;
    for i in 1..D {
        k += i + 1;
        if factor[k - 1] <= 0 {
            return Err(ContentError::Element {
                index,
                reason: "compact covariance factor has a non-positive diagonal",
            });
        }
    }
    Ok(())
}

/// Quantises one covariance and weight (`C = D(D+1)/2 − 1` factor codes).
fn compress<const D: usize, const C: usize>(
    covariance: &[[f64; D]; D],
    weight: f32,
    index: usize,
) -> Result<([u16; D], [i16; C], u16), ContentError> {
    let at = |reason| ContentError::Element { index, reason };
    let mut ln_sigma = [0u16; D];
    let mut sigma = [0.0; D];
    for i in 0..D {
        sigma[i] = covariance[i][i].sqrt();
        let code = ((sigma[i].ln() - LN_SIGMA_MIN) / LN_STEP).round();
        if !(0.0..=f64::from(u16::MAX)).contains(&code) {
            return Err(at(
                "standard deviation outside the compact encoding's range 1e-6 .. 7.9e7",
            ));
        }
        ln_sigma[i] = code as u16;
    }
    let mut correlation = [[0.0; D]; D];
    for i in 0..D {
        for j in 0..D {
            correlation[i][j] = covariance[i][j] / (sigma[i] * sigma[j]);
        }
    }
    let factor =
        check::cholesky(&correlation).ok_or(at("component covariance is not positive definite"))?;
    let mut codes = [0i16; C];
    let mut k = 0;
    for (i, row) in factor.iter().enumerate().skip(1) {
        for (j, v) in row.iter().enumerate().take(i + 1) {
            let mut code = (v * FACTOR_SCALE)
                .round()
                .clamp(-FACTOR_SCALE, FACTOR_SCALE);
            if i == j {
                code = code.max(1.0);
            }
            codes[k] = code as i16;
            k += 1;
        }
    }
    let neg_ln = (-f64::from(weight).ln() / LN_STEP)
        .round()
        .clamp(0.0, f64::from(u16::MAX));
    Ok((ln_sigma, codes, neg_ln as u16))
}

/// The inverse of [`compress`] for the covariance.
fn expand_covariance<const D: usize, const C: usize>(
    ln_sigma: &[u16; D],
    codes: &[i16; C],
) -> [[f64; D]; D] {
    let sigma = ln_sigma.map(|q| (LN_SIGMA_MIN + f64::from(q) * LN_STEP).exp());
    let mut factor = [[0.0; D]; D];
    factor[0][0] = 1.0;
    let mut k = 0;
    for (i, row) in factor.iter_mut().enumerate().skip(1) {
        let mut norm2 = 0.0;
        for v in row.iter_mut().take(i + 1) {
            *v = f64::from(codes[k]) / FACTOR_SCALE;
            norm2 += *v * *v;
            k += 1;
        }
        // A positive diagonal code (checked before expanding) keeps norm2 > 0;
        // guard anyway so that an unchecked call cannot divide by zero.
        let norm = norm2.sqrt().max(f64::MIN_POSITIVE);
        for v in row.iter_mut().take(i + 1) {
            *v /= norm;
        }
    }
    let mut covariance = [[0.0; D]; D];
    for i in 0..D {
        for j in 0..D {
            let r: f64 = (0..D).map(|m| factor[i][m] * factor[j][m]).sum();
            covariance[i][j] = sigma[i] * sigma[j] * r;
        }
    }
    covariance
}

/// Weights from `−ln w` codes, re-normalised to sum to 1 (in `f64`).
fn expand_weights(codes: impl Iterator<Item = u16> + Clone) -> Vec<f32> {
    let min = codes.clone().min().unwrap_or(0);
    let raw: Vec<f64> = codes
        .map(|q| (-(f64::from(q) - f64::from(min)) * LN_STEP).exp())
        .collect();
    let total: f64 = raw.iter().sum();
    raw.iter().map(|w| (w / total) as f32).collect()
}
