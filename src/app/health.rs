//! The clip's health per group, for the strip under the navigation: how much of each group's
//! sound is missing (gaps, failed groups), how many wall fits were rejected, and how far its
//! robust fits' outlier share stands above the clip's usual level, folded into one severity.
//!
//! The outlier share alone is no damage measure: it counts points more than
//! `outlier_sigmas`·σ from the fitted wall plane, and σ anneals down to `σ min`, so on a clean
//! scan most points can count (93 % on a clip that scores r 0.994). What marks a damaged group
//! is a share well above the clip's median, so that is what the severity uses.

use std::ops::Range;

use crate::engine::GroupReport;
use crate::pipeline::audio_signal::GroupSignal;

/// Where one group's samples lie on the groove and how many of them are gaps.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupTrack {
    /// Group index.
    pub group: usize,
    /// Groove position of its first and last sample (µm; NaN when it has none).
    pub span_um: (f64, f64),
    /// Samples it produced.
    pub samples: usize,
    /// Samples where a channel has no value (NaN: no fit there).
    pub gap_samples: usize,
    /// True when the group produced no signal at all.
    pub failed: bool,
}

impl GroupTrack {
    /// The track of `group` from its signal (None: the group failed).
    #[must_use]
    pub fn new(group: usize, signal: Option<&GroupSignal>) -> Self {
        let Some(s) = signal else {
            return Self {
                group,
                span_um: (f64::NAN, f64::NAN),
                samples: 0,
                gap_samples: 0,
                failed: true,
            };
        };
        let samples = s.positions_um.len();
        let gap_samples = (0..samples)
            .filter(|&i| {
                s.channels
                    .iter()
                    .any(|c| c.get(i).is_none_or(|v| !v.is_finite()))
            })
            .count();
        Self {
            group,
            span_um: (
                s.positions_um.first().copied().unwrap_or(f64::NAN),
                s.positions_um.last().copied().unwrap_or(f64::NAN),
            ),
            samples,
            gap_samples,
            failed: false,
        }
    }

    /// Share of its samples that are gaps (1 when it failed or has none).
    #[must_use]
    pub fn gap_fraction(&self) -> f64 {
        if self.failed || self.samples == 0 {
            1.0
        } else {
            self.gap_samples as f64 / self.samples as f64
        }
    }
}

/// One group's health.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GroupHealth {
    /// True once the group was reconstructed.
    pub ran: bool,
    /// True when it produced no sound.
    pub failed: bool,
    /// Share of its samples that are gaps.
    pub gap_fraction: f32,
    /// Mean outlier share of its robust fits (known once the clip is finished).
    pub outlier_fraction: Option<f32>,
    /// Fits rejected for an implausible wall slope.
    pub rejected_fits: usize,
    /// Disagreement between two decoders, in `[0, 1]`, where the scan has two.
    pub disagreement: Option<f32>,
    /// Pixel noise of its frames (σ, grey levels of 255) where the edge stage read them; shown,
    /// not counted in the severity (a noisy camera is not a damaged groove).
    pub pixel_noise: Option<f32>,
    /// All of it in `[0, 1]`: 0 sound, 1 lost (see [`ClipHealth::new`]).
    pub severity: f32,
}

/// The health of every group of a scan.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClipHealth {
    cells: Vec<GroupHealth>,
    median_outlier: Option<f32>,
}

/// Median of `v` (None when empty); sorts it.
fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    Some(v[v.len() / 2])
}

impl ClipHealth {
    /// The health of a scan's `groups` groups from the tracks of those reconstructed and, once
    /// the clip is finished, its report rows. A group's severity is the largest of: its gap
    /// share; its rejected fits per sample; how far its outlier share stands above the median
    /// group's, as a share of the way to 1; and the decoders' disagreement. A failed group is 1.
    #[must_use]
    pub fn new(groups: usize, tracks: &[GroupTrack], reports: &[GroupReport]) -> Self {
        let mut cells = vec![GroupHealth::default(); groups];
        for t in tracks {
            if let Some(c) = cells.get_mut(t.group) {
                c.ran = true;
                c.failed = t.failed;
                c.gap_fraction = t.gap_fraction() as f32;
            }
        }
        for r in reports {
            if let Some(c) = cells.get_mut(r.group) {
                c.ran = true;
                c.outlier_fraction = r.outlier_fraction.map(|o| o as f32);
                c.rejected_fits = r.rejected_fits;
                c.pixel_noise = r.pixel_noise_grey_levels.map(|n| n as f32);
                // A fused group the flow method lost but the edges read has sound, though its
                // track (the flow method's signal) has none.
                if c.failed && r.samples > 0 {
                    c.failed = false;
                    c.gap_fraction = 0.0;
                }
                if r.outlier_fraction.is_none() && r.samples == 0 {
                    c.failed = true;
                    c.gap_fraction = 1.0;
                }
            }
        }
        let mut outliers: Vec<f32> = cells.iter().filter_map(|c| c.outlier_fraction).collect();
        let median_outlier = median(&mut outliers);
        let samples: Vec<usize> = {
            let mut s = vec![0; groups];
            for t in tracks {
                if let Some(v) = s.get_mut(t.group) {
                    *v = t.samples;
                }
            }
            s
        };
        for (c, n) in cells.iter_mut().zip(samples) {
            c.severity = if c.failed {
                1.0
            } else {
                let rejected = c.rejected_fits as f32 / n.max(1) as f32;
                let excess = match (c.outlier_fraction, median_outlier) {
                    (Some(o), Some(m)) if m < 1.0 => ((o - m) / (1.0 - m)).max(0.0),
                    _ => 0.0,
                };
                c.gap_fraction
                    .max(rejected)
                    .max(excess)
                    .max(c.disagreement.unwrap_or(0.0))
                    .clamp(0.0, 1.0)
            };
        }
        Self {
            cells,
            median_outlier,
        }
    }

    /// Groups covered (the scan's).
    #[must_use]
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when the scan has no groups.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The health of group `g`.
    #[must_use]
    pub fn cell(&self, g: usize) -> Option<&GroupHealth> {
        self.cells.get(g)
    }

    /// The group of `groups` in the worst health (reconstructed ones first); None when empty.
    #[must_use]
    pub fn worst_in(&self, groups: Range<usize>) -> Option<usize> {
        let end = groups.end.min(self.cells.len());
        (groups.start..end).max_by(|&a, &b| {
            let key = |g: usize| {
                let c = &self.cells[g];
                (c.ran, c.severity)
            };
            let (ra, sa) = key(a);
            let (rb, sb) = key(b);
            ra.cmp(&rb).then(sa.total_cmp(&sb)).then(b.cmp(&a))
        })
    }

    /// A line for the hover text of group `g`.
    #[must_use]
    pub fn describe(&self, g: usize) -> String {
        let Some(c) = self.cells.get(g) else {
            return format!("group {g}");
        };
        if !c.ran {
            return format!("group {g}: not reconstructed yet");
        }
        if c.failed {
            return format!("group {g}: no sound (the group failed; see the messages)");
        }
        let mut s = format!("group {g}: {:.0} % gaps", 100.0 * c.gap_fraction);
        if c.rejected_fits > 0 {
            s += &format!(", {} wall fits rejected", c.rejected_fits);
        }
        if let Some(o) = c.outlier_fraction {
            s += &format!(", outliers {:.0} %", 100.0 * o);
            if let Some(m) = self.median_outlier {
                s += &format!(" (clip median {:.0} %)", 100.0 * m);
            }
        }
        if let Some(d) = c.disagreement {
            s += &format!(", decoders disagree {:.0} %", 100.0 * d);
        }
        if let Some(n) = c.pixel_noise {
            s += &format!(", pixel noise {n:.1} grey levels");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(group: usize, values: &[f32]) -> GroupSignal {
        GroupSignal {
            group,
            positions_um: (0..values.len())
                .map(|i| (group * 100 + i) as f64)
                .collect(),
            channels: vec![values.to_vec()],
            groove_speed_mm_s: 900.0,
        }
    }

    fn report(group: usize, outliers: Option<f64>, rejected: usize) -> GroupReport {
        GroupReport {
            group,
            outlier_fraction: outliers,
            rejected_fits: rejected,
            samples: 4,
            warning: None,
            pixel_noise_grey_levels: None,
        }
    }

    #[test]
    fn severity_follows_gaps_failures_and_outliers_above_the_clip_median() {
        let tracks = [
            GroupTrack::new(0, Some(&signal(0, &[0.1, 0.2, 0.3, 0.4]))),
            GroupTrack::new(1, Some(&signal(1, &[0.1, f32::NAN, 0.3, 0.4]))),
            GroupTrack::new(2, None),
            GroupTrack::new(3, Some(&signal(3, &[0.1, 0.2, 0.3, 0.4]))),
            // Fused, read by the edges alone: no flow signal, but its report row has samples.
            GroupTrack::new(5, None),
        ];
        assert_eq!(tracks[1].gap_samples, 1);
        assert_eq!(tracks[1].span_um, (100.0, 103.0));
        let reports = [
            report(0, Some(0.9), 0),
            report(1, Some(0.9), 0),
            GroupReport {
                samples: 0,
                ..report(2, None, 0)
            },
            GroupReport {
                pixel_noise_grey_levels: Some(2.31),
                ..report(3, Some(0.95), 2)
            },
            report(5, None, 0),
        ];
        let h = ClipHealth::new(6, &tracks, &reports);
        assert_eq!(h.len(), 6);
        assert_eq!(
            h.cell(0).unwrap().severity,
            0.0,
            "a high but usual outlier share"
        );
        assert_eq!(h.cell(1).unwrap().severity, 0.25, "a quarter of it is gaps");
        assert_eq!(h.cell(2).unwrap().severity, 1.0, "failed");
        // 2 rejected fits of 4 samples; outliers 0.95 against the median 0.9: (0.05 / 0.1).
        assert!((h.cell(3).unwrap().severity - 0.5).abs() < 1e-6);
        assert!(!h.cell(4).unwrap().ran);
        let alone = h.cell(5).unwrap();
        assert!(
            alone.ran && !alone.failed && alone.severity == 0.0,
            "{alone:?}"
        );
        assert_eq!(h.worst_in(0..5), Some(2));
        assert_eq!(h.worst_in(3..5), Some(3), "reconstructed groups first");
        assert!(
            h.describe(3).contains("2 wall fits rejected")
                && h.describe(3).contains("pixel noise 2.3 grey levels"),
            "{}",
            h.describe(3)
        );
        assert!(!h.describe(0).contains("pixel noise"));
        assert!(h.describe(4).contains("not reconstructed"));
    }
}
