//! First pass over a still: the median cross profile of every block of lines, and the gradient
//! energy along and across the lines, from rows fed in order.

use rayon::prelude::*;

use super::{
    Axis, StillError, StillParams, bad_input, check_all_rows, check_whole_rows, lines_and_cross,
};

/// Most profile values kept (blocks × cross samples); longer stills get longer blocks.
pub const PROFILE_BUDGET: usize = 1 << 25;
/// Columns per parallel task when taking column medians.
const COLUMN_CHUNK: usize = 64;

/// The block profiles of a still.
#[derive(Clone, Debug, PartialEq)]
pub struct Profiles {
    /// Which way the grooves run.
    pub axis: Axis,
    /// Lines (along the grooves).
    pub lines: usize,
    /// Cross samples per line.
    pub cross: usize,
    /// Lines per block (the last block may hold fewer).
    pub block_lines: usize,
    /// Blocks.
    pub blocks: usize,
    /// Median profile of each block, `blocks × cross`.
    pub data: Vec<f32>,
    /// Sum of squared differences of neighbouring samples across the lines.
    pub energy_across: f64,
    /// Sum of squared differences of neighbouring samples along the lines.
    pub energy_along: f64,
}

impl Profiles {
    /// Block `b`'s profile (empty past the end).
    #[must_use]
    pub fn block(&self, b: usize) -> &[f32] {
        self.data
            .get(b * self.cross..(b + 1) * self.cross)
            .unwrap_or(&[])
    }

    /// The line at the centre of block `b`.
    #[must_use]
    pub fn block_centre_line(&self, b: usize) -> f64 {
        let first = b * self.block_lines;
        let n = self
            .block_lines
            .min(self.lines.saturating_sub(first))
            .max(1);
        first as f64 + 0.5 * (n as f64 - 1.0)
    }
}

/// Builds [`Profiles`] from rows fed in order.
#[derive(Debug)]
pub struct ProfileBuilder {
    width: usize,
    height: usize,
    axis: Axis,
    block_lines: usize,
    rows_seen: usize,
    /// Vertical stills: the rows of the block being filled.
    band: Vec<f32>,
    prev_row: Vec<f32>,
    out: Profiles,
}

/// Median of `v` (the upper one of an even count), reordering it; NaN for none.
fn median_in_place(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f32::total_cmp).1
}

impl ProfileBuilder {
    /// A builder for a `width × height` still whose grooves run along `axis`.
    ///
    /// # Errors
    /// [`StillError::Param`] for an empty image or bad params.
    pub fn new(
        width: usize,
        height: usize,
        axis: Axis,
        params: &StillParams,
    ) -> Result<Self, StillError> {
        params.validate()?;
        if width < 2 || height < 2 {
            return Err(bad_input(format!(
                "a {width} × {height} px image is too small for a still"
            )));
        }
        let (lines, cross) = lines_and_cross(width, height, axis);
        let max_blocks = (PROFILE_BUDGET / cross).max(1);
        let block_lines = params.block_lines.max(lines.div_ceil(max_blocks));
        let blocks = lines.div_ceil(block_lines);
        Ok(Self {
            width,
            height,
            axis,
            block_lines,
            rows_seen: 0,
            band: Vec::new(),
            prev_row: Vec::new(),
            out: Profiles {
                axis,
                lines,
                cross,
                block_lines,
                blocks,
                data: vec![f32::NAN; blocks * cross],
                energy_across: 0.0,
                energy_along: 0.0,
            },
        })
    }

    /// Feeds the next whole rows (`width` values each, grey).
    ///
    /// # Errors
    /// [`StillError::Param`] when `rows` is not whole rows or runs past the image's height.
    pub fn push_rows(&mut self, rows: &[f32]) -> Result<(), StillError> {
        let w = self.width;
        check_whole_rows(rows.len(), w, self.rows_seen, self.height)?;
        for row in rows.chunks_exact(w) {
            self.add_energy(row);
        }
        match self.axis {
            Axis::Vertical => {
                for row in rows.chunks_exact(w) {
                    self.band.extend_from_slice(row);
                    self.rows_seen += 1;
                    if self.band.len() == self.block_lines * w || self.rows_seen == self.height {
                        self.flush_band();
                    }
                }
            }
            Axis::Horizontal => {
                let bl = self.block_lines;
                let medians: Vec<Vec<f32>> = rows
                    .par_chunks_exact(w)
                    .map_init(Vec::new, |buf, row| {
                        row.chunks(bl)
                            .map(|block| {
                                buf.clear();
                                buf.extend_from_slice(block);
                                median_in_place(buf)
                            })
                            .collect()
                    })
                    .collect();
                let cross = self.out.cross;
                for (i, m) in medians.iter().enumerate() {
                    let y = self.rows_seen + i;
                    for (b, v) in m.iter().enumerate() {
                        self.out.data[b * cross + y] = *v;
                    }
                }
                self.rows_seen += rows.len() / w;
            }
        }
        Ok(())
    }

    /// Adds one row's gradient energies (rows in order, so the sums have a fixed order).
    fn add_energy(&mut self, row: &[f32]) {
        let dx: f64 = row.windows(2).map(|p| f64::from(p[1] - p[0]).powi(2)).sum();
        let dy: f64 = if self.prev_row.len() == row.len() {
            row.iter()
                .zip(&self.prev_row)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum()
        } else {
            0.0
        };
        let (across, along) = match self.axis {
            Axis::Vertical => (dx, dy),
            Axis::Horizontal => (dy, dx),
        };
        self.out.energy_across += across;
        self.out.energy_along += along;
        self.prev_row.clear();
        self.prev_row.extend_from_slice(row);
    }

    /// Column medians of the buffered rows of a vertical still into the next block's profile.
    fn flush_band(&mut self) {
        let w = self.width;
        let rows = self.band.len() / w;
        if rows == 0 {
            return;
        }
        let b = (self.rows_seen - 1) / self.block_lines;
        let band = &self.band;
        if let Some(out) = self.out.data.get_mut(b * w..(b + 1) * w) {
            out.par_chunks_mut(COLUMN_CHUNK).enumerate().for_each_init(
                Vec::new,
                |buf, (chunk, dst)| {
                    for (i, d) in dst.iter_mut().enumerate() {
                        let x = chunk * COLUMN_CHUNK + i;
                        buf.clear();
                        buf.extend((0..rows).map(|r| band[r * w + x]));
                        *d = median_in_place(buf);
                    }
                },
            );
        }
        self.band.clear();
    }

    /// The profiles, once every row has been fed.
    ///
    /// # Errors
    /// [`StillError::Param`] when rows are missing.
    pub fn finish(mut self) -> Result<Profiles, StillError> {
        check_all_rows(self.rows_seen, self.height)?;
        self.flush_band();
        Ok(self.out)
    }
}
