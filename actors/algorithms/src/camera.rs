//! Pinhole camera geometry: intrinsics and the one back-projection every consumer of
//! depth frames uses (thesis §6.1: pixels with depth become 3D points).
//!
//! The camera body frame looks along body +x; image x (u, columns) is body −y and
//! image y (v, rows) is body −z. A pixel `(col, row)` is centred at
//! `(u, v) = (col + 0.5, row + 0.5)` and its return at z-depth `d` lies at
//! `(d, −(u − cx)/fx · d, −(v − cy)/fy · d)` in the body frame.

use nalgebra::{Point3, Vector3};

/// Pinhole intrinsics of a depth camera (pixel centres at integer + 0.5).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinholeIntrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Largest valid depth, metres.
    pub max_depth_m: f64,
}

impl PinholeIntrinsics {
    /// Pixels in one image (`width × height`).
    #[must_use]
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The image point `(u, v)` at the centre of pixel `(col, row)`.
    #[must_use]
    pub fn pixel_centre(col: u32, row: u32) -> (f64, f64) {
        (f64::from(col) + 0.5, f64::from(row) + 0.5)
    }

    /// Body-frame direction through image point `(u, v)`, scaled to unit z-depth (its
    /// body `x` component is 1): `(1, −(u − cx)/fx, −(v − cy)/fy)`.
    #[must_use]
    pub fn unit_depth_ray(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::new(1.0, -(u - self.cx) / self.fx, -(v - self.cy) / self.fy)
    }

    /// [`Self::unit_depth_ray`] through the centre of pixel `(col, row)`.
    #[must_use]
    pub fn pixel_ray(&self, col: u32, row: u32) -> Vector3<f64> {
        let (u, v) = Self::pixel_centre(col, row);
        self.unit_depth_ray(u, v)
    }

    /// The factor that brings an image `width` wide to at most `max_width_px` pixels
    /// ([`PinholeIntrinsics::decimated`]); 1 when it fits or `max_width_px` is 0.
    ///
    /// ```
    /// use troupe_algorithms::camera::PinholeIntrinsics;
    /// assert_eq!(PinholeIntrinsics::decimation(640, 160), 4);
    /// assert_eq!(PinholeIntrinsics::decimation(848, 160), 6);
    /// assert_eq!(PinholeIntrinsics::decimation(160, 160), 1);
    /// assert_eq!(PinholeIntrinsics::decimation(640, 0), 1);
    /// ```
    #[must_use]
    pub fn decimation(width: u32, max_width_px: u32) -> u32 {
        if max_width_px == 0 {
            1
        } else {
            width.div_ceil(max_width_px).max(1)
        }
    }

    /// The intrinsics of the image whose pixels are the `factor × factor` blocks of
    /// this one (a block's centre is its pixel's centre; partial blocks at the right
    /// and bottom edges are dropped).
    ///
    /// ```
    /// use troupe_algorithms::camera::PinholeIntrinsics;
    /// let k = PinholeIntrinsics { width: 640, height: 480, fx: 382.0, fy: 382.0, cx: 320.0, cy: 240.0, max_depth_m: 5.0 };
    /// let small = k.decimated(4);
    /// assert_eq!((small.width, small.height, small.fx, small.cx), (160, 120, 95.5, 80.0));
    /// // The same ray through a block's centre.
    /// assert_eq!(small.pixel_ray(10, 7), k.unit_depth_ray(42.0, 30.0));
    /// ```
    #[must_use]
    pub fn decimated(&self, factor: u32) -> PinholeIntrinsics {
        let k = factor.max(1);
        let scale = f64::from(k);
        PinholeIntrinsics {
            width: self.width / k,
            height: self.height / k,
            fx: self.fx / scale,
            fy: self.fy / scale,
            cx: self.cx / scale,
            cy: self.cy / scale,
            max_depth_m: self.max_depth_m,
        }
    }

    /// The body-frame point that pixel `(col, row)` sees at z-depth `depth_m`.
    ///
    /// ```
    /// use troupe_algorithms::camera::PinholeIntrinsics;
    /// let k = PinholeIntrinsics { width: 4, height: 2, fx: 2.0, fy: 2.0, cx: 2.0, cy: 1.0, max_depth_m: 5.0 };
    /// let p = k.back_project(3, 0, 2.0);
    /// // u = 3.5 is right of the centre (body −y), v = 0.5 above it (body +z).
    /// assert_eq!((p.x, p.y, p.z), (2.0, -1.5, 0.5));
    /// ```
    #[must_use]
    pub fn back_project(&self, col: u32, row: u32, depth_m: f64) -> Point3<f64> {
        Point3::from(self.pixel_ray(col, row) * depth_m)
    }
}
