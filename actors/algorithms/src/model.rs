//! The map model a mapper fits to each keyframe, chosen by config: the SOGMM of thesis
//! §6 or the windowed fixed-size GMM of paper §IV-A / thesis §3.2. [`fit_keyframe`]
//! gives both the same shape of output ([`KeyframeFit`]).

use serde::{Deserialize, Serialize};

use crate::frame::DepthFrame;
use crate::sogmm::{Gmm3, Gmm4, SogmmConfig, SogmmError, fit_depth_frame};
use crate::windowed::{WindowedConfig, fit_windowed_frame};

/// Which mixture model represents a keyframe (`"sogmm"` or `"windowed"` in TOML/JSON).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MapModel {
    /// Self-organizing 4D GMM, size chosen by the data (thesis §6, App. A).
    #[default]
    Sogmm,
    /// Windowed fixed-size occupied + free-space GMMs (paper §IV-A, thesis §3.2.1–3.2.2).
    Windowed,
}

impl MapModel {
    /// The name used in config files and on the command line.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            MapModel::Sogmm => "sogmm",
            MapModel::Windowed => "windowed",
        }
    }
}

impl std::fmt::Display for MapModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MapModel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "sogmm" => Ok(MapModel::Sogmm),
            "windowed" => Ok(MapModel::Windowed),
            other => Err(format!(
                "unknown map model `{other}` (expected `sogmm` or `windowed`)"
            )),
        }
    }
}

/// One keyframe's mixtures, whichever the model.
#[derive(Clone, Debug)]
pub struct KeyframeFit {
    /// Occupied surface over (x, y, z, intensity).
    pub occupied: Gmm4,
    /// Points the occupied mixture represents (its support size, Eq. 3.4).
    pub support: usize,
    /// Free-space mixture (windowed model only, when the frame had free-space points).
    pub free: Option<Gmm3>,
    /// Support size of `free`.
    pub free_support: usize,
}

/// Fit the chosen model to one frame. The SOGMM's support is the frame's valid pixel
/// count; the windowed model's is the number of points inside some gate (Eq. 3.3).
pub fn fit_keyframe(
    frame: &DepthFrame,
    model: MapModel,
    sogmm: &SogmmConfig,
    windowed: &WindowedConfig,
) -> Result<KeyframeFit, SogmmError> {
    match model {
        MapModel::Sogmm => {
            let fit = fit_depth_frame(frame, sogmm)?;
            Ok(KeyframeFit {
                support: fit.report.points,
                occupied: fit.gmm,
                free: None,
                free_support: 0,
            })
        }
        MapModel::Windowed => {
            let fit = fit_windowed_frame(frame, windowed)?;
            Ok(KeyframeFit {
                occupied: fit.occupied,
                support: fit.occupied_support,
                free: fit.free,
                free_support: fit.free_support,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn model_names_round_trip_through_serde_and_from_str() {
        use serde::de::IntoDeserializer;
        use serde::de::value::{Error, StrDeserializer};
        for m in [MapModel::Sogmm, MapModel::Windowed] {
            let de: StrDeserializer<'_, Error> = m.name().into_deserializer();
            assert_eq!(MapModel::deserialize(de).unwrap(), m);
            assert_eq!(m.name().parse::<MapModel>().unwrap(), m);
        }
        let de: StrDeserializer<'_, Error> = "Sogmm".into_deserializer();
        assert!(MapModel::deserialize(de).is_err(), "lowercase only");
        assert!("Sogmm".parse::<MapModel>().is_err());
    }
}
