//! Merging mixtures by concatenation with support-weighted renormalisation
//! (thesis Eqs. 3.4–3.5, paper Eqs. 5–6): mixtures `G_i` fitted to `N_i` points are
//! joined by concatenating means and covariances, with weights
//! `π* = [N_i π_i,1 / N*, …, N_j τ_j,1 / N*, …]`, `N* = Σ N_i`.
//!
//! Applying Eq. 3.5 pairwise, left to right, gives the same weights as applying it once
//! to all parts ([`merge_weights`]); the merged density is the support-weighted average
//! `p*(x) = Σ_i (N_i / N*) p_i(x)`.

use super::{Gmm, Gmm3, Gmm4, MixtureError};

/// Eqs. 3.4–3.5 for any number of parts: `supports[i]` is `N_i`, `weights[i]` the
/// weights of part `i`. Parts with zero support contribute nothing (their weights are
/// kept as zeros so indices stay aligned). The result is renormalised to sum to 1
/// exactly in floating point (it already does mathematically). Errors when the total
/// support is zero or a support is not finite and non-negative.
pub fn merge_weights(supports: &[f64], weights: &[&[f64]]) -> Result<Vec<f64>, MixtureError> {
    if supports.len() != weights.len() {
        return Err(MixtureError::InvalidMerge(
            "one support size is needed per mixture",
        ));
    }
    if supports.iter().any(|n| !n.is_finite() || *n < 0.0) {
        return Err(MixtureError::InvalidMerge(
            "support sizes must be finite and non-negative",
        ));
    }
    let n_star: f64 = supports.iter().sum();
    if n_star <= 0.0 {
        return Err(MixtureError::EmptyModel);
    }
    let mut out: Vec<f64> = supports
        .iter()
        .zip(weights)
        .flat_map(|(n, w)| w.iter().map(move |pi| n * pi / n_star))
        .collect();
    let sum: f64 = out.iter().sum();
    if !(sum.is_finite() && sum > 0.0) {
        return Err(MixtureError::EmptyModel);
    }
    out.iter_mut().for_each(|w| *w /= sum);
    Ok(out)
}

/// Merge mixtures `(N_i, G_i)` by Eqs. 3.4–3.5; components of zero weight are
/// dropped.
pub fn merge_gmm<const D: usize>(parts: &[(f64, &Gmm<D>)]) -> Result<Gmm<D>, MixtureError> {
    let supports: Vec<f64> = parts.iter().map(|(n, _)| *n).collect();
    let params: Vec<_> = parts
        .iter()
        .map(|(_, g)| (g.weights(), g.means(), g.covariances()))
        .collect();
    let (w, mu, cov) = merged_parameters(&supports, &params)?;
    Gmm::new(w, mu, cov)
}

/// [`merge_gmm`] of 4D mixtures.
pub fn merge_gmm4(parts: &[(f64, &Gmm4)]) -> Result<Gmm4, MixtureError> {
    merge_gmm(parts)
}

/// [`merge_gmm`] of 3D mixtures.
pub fn merge_gmm3(parts: &[(f64, &Gmm3)]) -> Result<Gmm3, MixtureError> {
    merge_gmm(parts)
}

/// Weights (Eq. 3.5), means and covariances of merged mixtures given as
/// `(weights, means, covariances)`, without the components of zero weight.
type Parameters<M, C> = (Vec<f64>, Vec<M>, Vec<C>);

fn merged_parameters<M: Copy, C: Copy>(
    supports: &[f64],
    parts: &[(&[f64], &[M], &[C])],
) -> Result<Parameters<M, C>, MixtureError> {
    let weights: Vec<&[f64]> = parts.iter().map(|p| p.0).collect();
    let merged = merge_weights(supports, &weights)?;
    let means = parts.iter().flat_map(|p| p.1.iter().copied());
    let covs = parts.iter().flat_map(|p| p.2.iter().copied());
    let (mut w, mut mu, mut cov) = (Vec::new(), Vec::new(), Vec::new());
    for ((wi, mi), ci) in merged.into_iter().zip(means).zip(covs) {
        if wi > 0.0 {
            w.push(wi);
            mu.push(mi);
            cov.push(ci);
        }
    }
    Ok((w, mu, cov))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

    use super::*;

    fn gmm4(offset: f64, k: usize) -> Gmm4 {
        let w = vec![1.0 / k as f64; k];
        let mu = (0..k)
            .map(|i| Vector4::new(offset + i as f64, 0.5 * i as f64, -1.0, 0.3))
            .collect();
        let cov = (0..k)
            .map(|i| Matrix4::identity() * (0.1 + 0.05 * i as f64))
            .collect();
        Gmm4::new(w, mu, cov).unwrap()
    }

    #[test]
    fn pairwise_merging_equals_merging_all_at_once() {
        let (a, b, c) = ([0.2, 0.8], [1.0], [0.5, 0.25, 0.25]);
        let once = merge_weights(&[10.0, 30.0, 60.0], &[&a, &b, &c]).unwrap();
        let ab = merge_weights(&[10.0, 30.0], &[&a, &b]).unwrap();
        let twice = merge_weights(&[40.0, 60.0], &[&ab, &c]).unwrap();
        for (x, y) in once.iter().zip(&twice) {
            assert!((x - y).abs() < 1e-15);
        }
        // Eq. 3.5 literally: N_i π / N*.
        assert!((once[0] - 10.0 * 0.2 / 100.0).abs() < 1e-15);
        assert!((once[2] - 30.0 / 100.0).abs() < 1e-15);
        assert!((once.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn merged_density_is_the_support_weighted_average() {
        let (g1, g2) = (gmm4(0.0, 3), gmm4(2.5, 2));
        let merged = merge_gmm4(&[(100.0, &g1), (300.0, &g2)]).unwrap();
        assert_eq!(merged.len(), 5);
        merged.validate().unwrap();
        for x in [
            Vector4::new(0.3, 0.1, -1.0, 0.3),
            Vector4::new(2.0, 0.4, -0.5, 0.2),
            Vector4::new(4.0, 1.0, -1.2, 0.4),
        ] {
            let expected = 0.25 * g1.log_likelihood(&x).exp() + 0.75 * g2.log_likelihood(&x).exp();
            let got = merged.log_likelihood(&x).exp();
            assert!(
                (got - expected).abs() <= 1e-12 * expected,
                "{got} {expected}"
            );
        }
        let g3 = Gmm3::new(vec![1.0], vec![Vector3::zeros()], vec![Matrix3::identity()]).unwrap();
        let m3 = merge_gmm3(&[(0.0, &g3), (5.0, &g3)]).unwrap();
        assert_eq!(m3.len(), 1, "a part with zero support adds no component");
    }

    #[test]
    fn bad_supports_are_errors() {
        let w = [1.0];
        assert!(merge_weights(&[0.0], &[&w]).is_err());
        assert!(merge_weights(&[f64::NAN], &[&w]).is_err());
        assert!(merge_weights(&[-1.0, 2.0], &[&w, &w]).is_err());
        assert!(merge_weights(&[1.0], &[]).is_err());
    }
}
