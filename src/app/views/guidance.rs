//! Plain language for archivists: one line per view on what its stage does, what a good result
//! looks like and which knob (or symptom preset) to try for a symptom; and the pipeline's
//! warnings said in an archivist's terms, with the technical text on hover.

use egui::{Color32, Ui};

use super::View;

/// Colour of warnings.
pub const WARNING_COLOUR: Color32 = Color32::from_rgb(220, 170, 60);

/// The guidance line of `view` (`dual`: the scan is on the dual-focus path).
#[must_use]
pub fn guidance(view: View, dual: bool) -> &'static str {
    match view {
        View::Overview => {
            "Every step for the group shown, frames to sound. Good: every panel says fresh. \
             Amber = waiting for a rerun, red = failed (the stage list says why)."
        }
        View::Frame => {
            "The group's frames as the microscope filmed them. Good: a sharp, evenly lit groove, \
             arrows all along it. Specks of dust: try the \"dusty\" preset."
        }
        View::Flow => {
            "How each point moves from frame to frame, beyond the record's own motion. Good: \
             smooth colour along the walls. A noisy, blotchy field: raise λ (smoothness) or the \
             \"noisy\" preset."
        }
        View::Hough => {
            "Finds the sharp (in-focus) stripes on the walls as bright peaks; each box is one \
             stripe's window. Good: one clear peak per wall inside its box. A stripe missed: \
             drag a box edge wider."
        }
        View::Stripes => {
            "The in-focus stripes found and their centre lines, which carry the sound. Good: \
             unbroken lines along both walls. Magenta gaps on a flaked wall: the \"flaked \
             wall\" preset."
        }
        View::Depth if dual => {
            "Depth from the movement; this scan reads its walls from the focus stripes instead \
             (see the stripes view)."
        }
        View::Depth => {
            "The groove's depth, from how much slower deeper points move, with the walls found in \
             it. Good: two clean walls and a smooth bottom. Speckles: raise the median (px) or \
             the \"dusty\" preset."
        }
        View::Orientation => {
            "The tilt of each wall along the groove: this tilt is the sound. Good: smooth curves \
             and bright (trusted) wall bands. Chunks missing from a wall: the \"flaked wall\" \
             preset."
        }
        View::Edges => {
            "Where each wall meets the land and the bottom; their movement is the sound. Good: \
             dots along all four borders, smooth wall curves. A grainy frame: the \"noisy\" preset."
        }
        View::Waveform => {
            "The sound of the whole clip, beside the reference when the scan has one. Good: the \
             envelopes agree; red cells in the health strip mark damaged groups. Hiss: lower \
             the low-pass cutoff or the \"noisy\" preset."
        }
        View::Metadata => {
            "The recording facts of this scan (speed, radius, camera, motion) from scan.toml. \
             Good: they match the capture notes; every stage depends on them."
        }
    }
}

/// A small colour key square (drawn, so it needs no glyph from the font).
pub fn swatch(ui: &mut Ui, colour: Color32) {
    let (rect, _) = ui.allocate_exact_size(egui::vec2(10.0, 10.0), egui::Sense::hover());
    ui.painter().rect_filled(rect, 1.0, colour);
}

/// Draws the guidance line of `view` (one line; the whole text on hover).
pub fn guidance_ui(ui: &mut Ui, view: View, dual: bool) {
    let text = guidance(view, dual);
    ui.add(egui::Label::new(egui::RichText::new(text).italics().weak()).truncate())
        .on_hover_text(text);
}

/// The numbers in `s`, in order (digits with an optional decimal point).
fn numbers(s: &str) -> Vec<f64> {
    let mut out = Vec::new();
    let mut cur = String::new();
    for c in s.chars().chain(std::iter::once(' ')) {
        if c.is_ascii_digit() || (c == '.' && !cur.is_empty()) {
            cur.push(c);
        } else if !cur.is_empty() {
            if let Ok(v) = cur.trim_end_matches('.').parse() {
                out.push(v);
            }
            cur.clear();
        }
    }
    out
}

/// A warning of the pipeline or the engine in an archivist's terms (the text itself when it
/// is not one of the known kinds).
#[must_use]
pub fn plain_warning(w: &str) -> String {
    let n = numbers(w);
    let num = |i: usize| n.get(i).map_or_else(|| "some".into(), |v| format!("{v}"));
    // "1 sample", "3 samples", "some samples".
    let count = |i: usize, one: &str, many: &str| match n.get(i) {
        Some(v) if *v == 1.0 => format!("1 {one}"),
        _ => format!("{} {many}", num(i)),
    };
    let were = |i: usize| {
        if n.get(i) == Some(&1.0) {
            "was"
        } else {
            "were"
        }
    };
    if w.contains("plane scale") && w.contains("diverged") {
        format!(
            "depth: the tracker lost {} between frames (the surface seemed to tilt too \
             steeply) and started them afresh",
            count(0, "point", "points")
        )
    } else if w.contains("were never measured") {
        let share = match (n.first(), n.get(1)) {
            (Some(a), Some(b)) if *b > 0.0 => format!("{:.0} %", 100.0 * a / b),
            _ => "part".into(),
        };
        format!("depth: {share} of the picture gave no depth (too little texture or light there)")
    } else if w.contains("non-positive inverse depth") {
        format!(
            "depth: {} moved against the record (dust or glare) and {} left out",
            count(0, "point", "points"),
            were(0)
        )
    } else if w.contains("dropped: no pixel with usable flow") {
        format!(
            "frame {}: no usable movement, left out of the depth",
            num(1)
        )
    } else if w.contains("non-finite flow") {
        format!(
            "frame {}: {} had no valid movement and {} skipped",
            num(1),
            count(2, "point", "points"),
            were(2)
        )
    } else if w.contains("are missing") && w.starts_with("flow") {
        format!("frames {} to {} of this group are missing", num(1), num(2))
    } else if w.contains("fits rejected for an implausible wall slope") {
        format!(
            "{} did not match the wall's usual slope (a flaked or dusty wall?) and \
             {} left as short silences",
            count(0, "wall reading", "wall readings"),
            were(0)
        )
    } else if w.contains("short gaps") && w.contains("bridged") {
        format!(
            "{} filled in smoothly",
            count(0, "tiny dropout was", "tiny dropouts were"),
        )
    } else if w.starts_with("gap of") && w.contains("filled with silence") {
        format!("a dropout of {} is silent", count(0, "sample", "samples"))
    } else if w.starts_with("group") && w.contains("(filled with silence)") {
        format!("group {} could not be used and is silent", num(0))
    } else if w.starts_with("group") && w.contains("(read by the edges alone)") {
        format!(
            "group {} could not be read by the flow method; the edges alone give its sound",
            num(0)
        )
    } else if w.contains("the edges alone made the clip") {
        "the flow method could read no group, so the whole clip is the edge method's".into()
    } else {
        w.to_string()
    }
}

/// Draws up to `max` warnings in plain terms (each with its technical text on hover) and a
/// line counting the rest.
pub fn warnings_ui(ui: &mut Ui, warnings: &[String], max: usize) {
    for w in warnings.iter().take(max) {
        ui.colored_label(WARNING_COLOUR, plain_warning(w))
            .on_hover_text(w);
    }
    if warnings.len() > max {
        let rest = warnings[max..].join("\n");
        ui.weak(format!("… and {} more", warnings.len() - max))
            .on_hover_text(rest);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_warnings_read_plainly_and_others_stay() {
        let w = "12 pixel predictions diverged (plane scale 1 − f·U·α < 0.5) and restarted from \
                 the prior";
        let p = plain_warning(w);
        assert!(p.contains("12 points") && !p.contains("f·U"), "{p}");
        let p = plain_warning("250 of 1000 pixels were never measured");
        assert!(p.contains("25 %"), "{p}");
        let p = plain_warning(
            "3 orientation fits rejected for an implausible wall slope (left as gaps)",
        );
        assert!(
            p.starts_with("3 wall readings") && p.contains("were left"),
            "{p}"
        );
        let p = plain_warning("gap of 1 native sample at sample 480 filled with silence");
        assert_eq!(p, "a dropout of 1 sample is silent");
        let p = plain_warning("1 fits rejected for an implausible wall slope (left as gaps)");
        assert!(
            p.starts_with("1 wall reading did") && p.contains("was left"),
            "{p}"
        );
        let p = plain_warning(
            "group 41: stripes: stripe 1 has no pixels of its own (read by the edges alone)",
        );
        assert!(
            p.starts_with("group 41 could not") && p.contains("edges alone"),
            "{p}"
        );
        assert_eq!(plain_warning("something new"), "something new");
        assert_eq!(numbers("frames 4 to 7."), vec![4.0, 7.0]);
        for v in View::ALL {
            assert!(!guidance(v, false).is_empty() && !guidance(v, true).is_empty());
        }
    }
}
