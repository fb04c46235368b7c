//! Second pass over a still: keeps only a band of cross samples around the chosen groove's
//! predicted path on every line, from rows fed in order.

use super::detect::GrooveMap;
use super::{Axis, StillError, StillParams, bad_input, check_all_rows, check_whole_rows};

/// Widest band kept around a groove, px.
pub const MAX_RIBBON_PX: usize = 2048;
/// Samples kept beyond the search and fit reach on each side, px.
const RIBBON_SLACK_PX: f64 = 2.0;
/// Smallest border search half-width, px.
pub const MIN_SEARCH_PX: f64 = 2.0;

/// The samples around one groove, line by line.
#[derive(Clone, Debug, PartialEq)]
pub struct Ribbon {
    /// Which way the grooves run.
    pub axis: Axis,
    /// Lines.
    pub lines: usize,
    /// Samples kept per line.
    pub width: usize,
    /// Cross position of each line's first kept sample (may lie outside the image).
    pub first_cross: Vec<i64>,
    /// `lines × width` grey values (times [`GrooveMap::brightness_gain`]); NaN outside the image.
    pub data: Vec<f32>,
    /// The groove's predicted borders on every line (cross px; inner NaN when not seen).
    pub predicted: Vec<[f64; 4]>,
    /// Search half-width of each border around its prediction, px.
    pub search_px: [f64; 4],
}

impl Ribbon {
    /// Line `n`'s samples.
    #[must_use]
    pub fn line(&self, n: usize) -> &[f32] {
        self.data
            .get(n * self.width..(n + 1) * self.width)
            .unwrap_or(&[])
    }
}

/// Builds a [`Ribbon`] from rows fed in order.
#[derive(Debug)]
pub struct RibbonBuilder {
    image_width: usize,
    image_height: usize,
    rows_seen: usize,
    /// [`GrooveMap::brightness_gain`].
    gain: f32,
    ribbon: Ribbon,
}

impl RibbonBuilder {
    /// A builder for groove index `chosen` of `map` in a `width × height` still.
    ///
    /// # Errors
    /// [`StillError::Param`] for an index out of range, a groove never found, or a predicted
    /// band wider than [`MAX_RIBBON_PX`].
    pub fn new(
        map: &GrooveMap,
        chosen: usize,
        width: usize,
        height: usize,
        params: &StillParams,
    ) -> Result<Self, StillError> {
        let Some(track) = map.grooves.get(chosen) else {
            return Err(bad_input(format!("no groove index {chosen}")));
        };
        let path = track.path(map);
        let predicted: Vec<[f64; 4]> = (0..map.lines).map(|n| path.at(n as f64)).collect();
        if predicted
            .iter()
            .any(|p| !(p[0].is_finite() && p[3].is_finite()))
        {
            return Err(bad_input(format!(
                "groove {} was never found",
                track.number
            )));
        }
        let share = params.search_share;
        let walls = crate::pipeline::median(
            predicted
                .iter()
                .flat_map(|p| {
                    if p[1].is_finite() && p[2].is_finite() {
                        vec![p[1] - p[0], p[3] - p[2]]
                    } else {
                        vec![0.5 * (p[3] - p[0])]
                    }
                })
                .collect(),
        )
        .unwrap_or(0.0);
        let s = (share * walls).max(MIN_SEARCH_PX);
        let reach = s + params.border.fit_half_window_px + RIBBON_SLACK_PX;
        let span = predicted.iter().fold(0.0f64, |m, p| m.max(p[3] - p[0]));
        let w = (span + 2.0 * reach).ceil() as usize + 1;
        if w > MAX_RIBBON_PX {
            return Err(bad_input(format!(
                "groove {} would need a band {w} px wide (more than {MAX_RIBBON_PX})",
                track.number
            )));
        }
        let first_cross = predicted
            .iter()
            .map(|p| (p[0] - reach).floor() as i64)
            .collect();
        Ok(Self {
            image_width: width,
            image_height: height,
            rows_seen: 0,
            gain: map.brightness_gain as f32,
            ribbon: Ribbon {
                axis: map.axis,
                lines: map.lines,
                width: w,
                first_cross,
                data: vec![f32::NAN; map.lines * w],
                predicted,
                search_px: [s; 4],
            },
        })
    }

    /// Feeds the next whole rows (`width` values each, grey).
    ///
    /// # Errors
    /// [`StillError::Param`] when `rows` is not whole rows or runs past the image's height.
    pub fn push_rows(&mut self, rows: &[f32]) -> Result<(), StillError> {
        let iw = self.image_width;
        check_whole_rows(rows.len(), iw, self.rows_seen, self.image_height)?;
        let r = &mut self.ribbon;
        let w = r.width;
        for row in rows.chunks_exact(iw) {
            let y = self.rows_seen;
            match r.axis {
                Axis::Vertical => {
                    let lo = r.first_cross[y];
                    let dst = &mut r.data[y * w..(y + 1) * w];
                    for (j, d) in dst.iter_mut().enumerate() {
                        let x = lo + j as i64;
                        if let Some(v) = usize::try_from(x).ok().and_then(|x| row.get(x)) {
                            *d = *v * self.gain;
                        }
                    }
                }
                Axis::Horizontal => {
                    let y = y as i64;
                    for (n, (&lo, v)) in r.first_cross.iter().zip(row).enumerate() {
                        let j = y - lo;
                        if (0..w as i64).contains(&j) {
                            r.data[n * w + j as usize] = *v * self.gain;
                        }
                    }
                }
            }
            self.rows_seen += 1;
        }
        Ok(())
    }

    /// The ribbon, once every row has been fed.
    ///
    /// # Errors
    /// [`StillError::Param`] when rows are missing.
    pub fn finish(self) -> Result<Ribbon, StillError> {
        check_all_rows(self.rows_seen, self.image_height)?;
        Ok(self.ribbon)
    }
}
