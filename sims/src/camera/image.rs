//! The rendered image type.

/// A depth + intensity image, row-major (`index = row * width + col`).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Z-depth along the optical axis in metres; `0.0` means no return.
    pub depth_m: Vec<f32>,
    /// Intensity in `[0, 1]`; `0.0` where there is no return.
    pub intensity: Vec<f32>,
}

impl DepthImage {
    /// An image with no returns.
    #[must_use]
    pub fn empty(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            depth_m: vec![0.0; n],
            intensity: vec![0.0; n],
        }
    }

    /// Row-major index of pixel `(col, row)`.
    #[must_use]
    pub fn index(&self, col: u32, row: u32) -> usize {
        row as usize * self.width as usize + col as usize
    }

    /// Depth of pixel `(col, row)` in metres (`0.0`: no return).
    #[must_use]
    pub fn depth_at(&self, col: u32, row: u32) -> f32 {
        self.depth_m[self.index(col, row)]
    }

    /// Intensity of pixel `(col, row)`.
    #[must_use]
    pub fn intensity_at(&self, col: u32, row: u32) -> f32 {
        self.intensity[self.index(col, row)]
    }

    /// Number of pixels with a return.
    #[must_use]
    pub fn valid_count(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }
}
