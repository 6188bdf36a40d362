//! Occupancy-grid change set: the baseline the thesis compares GMM sharing with
//! (§8.2.5, "OG").
//!
//! # Size
//!
//! Exactly the thesis' accounting, **8 N + 24 bytes**: three `u32` grid
//! dimensions and three `f32` origin coordinates (24 bytes of metadata), then per
//! changed voxel one `u32` cell index and one `f32` log-odds value. On the wire a
//! postcard length prefix for the change list (varint: 1 byte below 128 changes,
//! 2 below 16384, 3 below 2²¹) and the payload variant byte come on top; they
//! are reported separately, never hidden.
//!
//! The voxel size is team configuration and not sent, as in the thesis'
//! metadata. Cell `index = x + width · (y + height · z)`, voxel `(x, y, z)`
//! spanning `origin + resolution · [x, x+1)` along each axis.

use serde::{Deserialize, Serialize};

use super::ContentError;

/// One changed voxel: 8 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellChange {
    /// Linear cell index (see the [module docs](self)).
    #[serde(with = "postcard::fixint::le")]
    pub index: u32,
    /// New log-odds of occupancy.
    pub log_odds: f32,
}

/// The voxels whose log-odds changed with one sensor observation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridChangeSet {
    /// Grid size in cells `(width, height, length)` along x, y, z.
    pub dims: GridDims,
    /// World position of the grid's minimum corner, metres.
    pub origin_m: [f32; 3],
    /// Changed cells, in strictly increasing index order (so each cell once).
    pub changes: Vec<CellChange>,
}

/// Grid dimensions in cells, each a fixed-width `u32`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GridDims {
    /// Cells along x.
    #[serde(with = "postcard::fixint::le")]
    pub width: u32,
    /// Cells along y.
    #[serde(with = "postcard::fixint::le")]
    pub height: u32,
    /// Cells along z.
    #[serde(with = "postcard::fixint::le")]
    pub length: u32,
}

impl GridDims {
    /// Number of cells, saturating at `u64::MAX` (three `u32` factors can exceed
    /// `u64`; every `u32` cell index is below the saturated value, so validation
    /// is unaffected).
    #[must_use]
    pub fn cells(&self) -> u64 {
        u64::from(self.width)
            .saturating_mul(u64::from(self.height))
            .saturating_mul(u64::from(self.length))
    }
}

impl GridChangeSet {
    /// Size in the thesis' accounting, `8 N + 24` bytes (§8.2.5).
    #[must_use]
    pub fn thesis_bytes(&self) -> usize {
        8 * self.changes.len() + 24
    }

    /// Sorts the changes by index and keeps the last value given for each cell,
    /// so that the set passes validation.
    pub fn normalise(&mut self) {
        // Stable sort keeps the order of equal indices; keep the last of each run.
        self.changes.sort_by_key(|c| c.index);
        let mut out: Vec<CellChange> = Vec::with_capacity(self.changes.len());
        for c in self.changes.drain(..) {
            match out.last_mut() {
                Some(last) if last.index == c.index => *last = c,
                _ => out.push(c),
            }
        }
        self.changes = out;
    }

    /// Checks the values: no zero dimension, a finite origin, indices inside the grid
    /// and strictly increasing, finite log-odds (what [`super::decode`] checks).
    pub fn validate(&self) -> Result<(), ContentError> {
        if self.dims.cells() == 0 {
            return Err(ContentError::Message("grid has a zero dimension"));
        }
        if !super::check::all_finite(&self.origin_m) {
            return Err(ContentError::Message(
                "grid origin contains NaN or infinity",
            ));
        }
        let cells = self.dims.cells();
        let mut previous: Option<u32> = None;
        for (index, c) in self.changes.iter().enumerate() {
            let at = |reason| ContentError::Element { index, reason };
            if u64::from(c.index) >= cells {
                return Err(at("cell index outside the grid"));
            }
            if previous.is_some_and(|p| c.index <= p) {
                return Err(at("cell indices are not strictly increasing"));
            }
            if !c.log_odds.is_finite() {
                return Err(at("cell log-odds is NaN or infinite"));
            }
            previous = Some(c.index);
        }
        Ok(())
    }
}
