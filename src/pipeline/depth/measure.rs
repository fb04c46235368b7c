//! The filter's input: each flow field's measurement weights and the warnings about it.

use super::*;

/// One frame's measurements: weight w and weight × normalised flow w·m per pixel.
#[derive(Default)]
pub(super) struct Measurements {
    pub(super) w: Vec<f32>,
    pub(super) wm: Vec<f32>,
    /// Pixels with enough confidence.
    pub(super) valid: usize,
    /// Confident pixels whose flow is not finite.
    pub(super) bad_flow: usize,
}

/// Pixels per parallel work item of the per-pixel passes.
pub(super) const CHUNK_PX: usize = 1 << 14;

impl Measurements {
    /// Fills the weights (confidence / mean confidence, 0 below `min_confidence`) and
    /// w·u/u_land of one flow field, reusing the buffers.
    pub(super) fn fill(&mut self, flow: &FlowField, u_land: f64, min_confidence: f32) {
        let usable = |u: f32, c: f32| c.is_finite() && c >= min_confidence && u.is_finite();
        let (sum, valid, bad_flow) = flow
            .u
            .data
            .par_chunks(CHUNK_PX)
            .zip(flow.confidence.data.par_chunks(CHUNK_PX))
            .map(|(us, cs)| {
                let (mut sum, mut valid, mut bad) = (0.0_f64, 0_usize, 0_usize);
                for (&u, &c) in us.iter().zip(cs) {
                    if usable(u, c) {
                        sum += f64::from(c);
                        valid += 1;
                    } else if c.is_finite() && c >= min_confidence {
                        bad += 1;
                    }
                }
                (sum, valid, bad)
            })
            // Summed in chunk order: a parallel reduce adds in whatever order the threads
            // split the work, and the last bits of the sum would vary from run to run.
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0.0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        // Weights are relative to the mean confidence; all-zero confidences weigh 1 each.
        let scale = if sum > 0.0 {
            (valid as f64 / sum) as f32
        } else {
            0.0
        };
        let inv_u_land = (1.0 / u_land) as f32;
        let n = flow.u.data.len();
        self.w.resize(n, 0.0);
        self.wm.resize(n, 0.0);
        self.w
            .par_chunks_mut(CHUNK_PX)
            .zip(self.wm.par_chunks_mut(CHUNK_PX))
            .zip(flow.u.data.par_chunks(CHUNK_PX))
            .zip(flow.confidence.data.par_chunks(CHUNK_PX))
            .for_each(|(((ws, wms), us), cs)| {
                for (((w, wm), &u), &c) in ws.iter_mut().zip(wms.iter_mut()).zip(us).zip(cs) {
                    (*w, *wm) = if usable(u, c) {
                        let wv = if scale > 0.0 { c * scale } else { 1.0 };
                        (wv, wv * u * inv_u_land)
                    } else {
                        (0.0, 0.0)
                    };
                }
            });
        self.valid = valid;
        self.bad_flow = bad_flow;
    }
}

/// One flow field as the filter reads it: its measurements and the frame steps since the
/// previous field (None for the first).
pub(super) struct FrameInput {
    pub(super) meas: Measurements,
    pub(super) steps: Option<f64>,
}

impl FrameInput {
    pub(super) fn measured(&self) -> bool {
        self.meas.valid > 0
    }
}
/// Adds the warnings about one flow field (dropped, non-finite flow, frame gap).
pub(super) fn note_frame(
    k: usize,
    flow: &FlowField,
    meas: &Measurements,
    prev_index: Option<usize>,
    warnings: &mut Vec<String>,
) {
    if meas.valid == 0 {
        warnings.push(format!(
            "flow {k} (frame {}) dropped: no pixel with usable flow and enough confidence",
            flow.frame_index
        ));
    }
    if meas.bad_flow > 0 {
        warnings.push(format!(
            "flow {k} (frame {}): {} confident pixels have non-finite flow and were skipped",
            flow.frame_index, meas.bad_flow
        ));
    }
    if let Some(p) = prev_index
        && flow.frame_index > p + 1
    {
        warnings.push(format!(
            "flow {k}: frames {} to {} are missing",
            p + 1,
            flow.frame_index - 1
        ));
    }
}
