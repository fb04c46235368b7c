//! A dense single-channel `f32` raster: frames, derivatives, flow components and depth maps.

/// A row-major `f32` raster. Grey frames hold values in `[0, 1]`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Image {
    /// Columns (the groove direction, x).
    pub width: usize,
    /// Rows (across the groove, y).
    pub height: usize,
    /// `width * height` values, row by row.
    pub data: Vec<f32>,
}

/// `len` zeros, written in parallel (see [`crate::pipeline::simd::zeros_par`]).
pub use crate::pipeline::simd::zeros_par;

impl Image {
    /// An image of zeros.
    #[must_use]
    pub fn zeros(width: usize, height: usize) -> Self {
        Self::filled(width, height, 0.0)
    }

    /// An image with every pixel set to `value`.
    #[must_use]
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// Wraps `data`; `None` when its length is not `width * height`.
    #[must_use]
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Builds an image by calling `f(x, y)` for every pixel.
    #[must_use]
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> f32) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// The pixel at `(x, y)`, or `None` outside the image.
    #[must_use]
    pub fn get(&self, x: usize, y: usize) -> Option<f32> {
        if x < self.width && y < self.height {
            self.data.get(y * self.width + x).copied()
        } else {
            None
        }
    }

    /// The pixel at `(x, y)` with coordinates clamped to the border.
    #[must_use]
    pub fn clamped(&self, x: isize, y: isize) -> f32 {
        if self.data.is_empty() {
            return 0.0;
        }
        let xc = x.clamp(0, self.width as isize - 1) as usize;
        let yc = y.clamp(0, self.height as isize - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// Row `y` as a slice (empty outside the image).
    #[must_use]
    pub fn row(&self, y: usize) -> &[f32] {
        if y < self.height {
            &self.data[y * self.width..(y + 1) * self.width]
        } else {
            &[]
        }
    }

    /// True when both images have the same width and height.
    #[must_use]
    pub fn same_size(&self, other: &Image) -> bool {
        self.width == other.width && self.height == other.height
    }

    /// Smallest and largest finite values, or `None` when there are none.
    #[must_use]
    pub fn finite_range(&self) -> Option<(f32, f32)> {
        let mut it = self.data.iter().copied().filter(|v| v.is_finite());
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_fn_is_row_major() {
        let im = Image::from_fn(3, 2, |x, y| (x + 10 * y) as f32);
        assert_eq!(im.get(2, 1), Some(12.0));
        assert_eq!(im.row(1), &[10.0, 11.0, 12.0]);
        assert_eq!(im.get(3, 0), None);
        assert_eq!(im.clamped(-5, 9), 10.0);
        assert_eq!(im.finite_range(), Some((0.0, 12.0)));
    }
}
