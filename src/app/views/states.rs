//! The per-view state of the open scan, gathered in one value so that a new scan starts from a
//! fresh one.

/// The per-view state of the open scan (read-outs, choices, the selection, the metadata form);
/// a new scan starts from a fresh one, so nothing of the previous disc shows.
#[derive(Debug, Default)]
pub struct ViewStates {
    /// Frame view.
    pub frame: super::frame_ui::FrameViewState,
    /// Flow view.
    pub flow: super::flow_ui::FlowViewState,
    /// Hough view.
    pub hough: super::hough_ui::HoughViewState,
    /// Stripes view.
    pub stripes: super::stripes_ui::StripesViewState,
    /// Depth view.
    pub depth: super::depth_ui::DepthViewState,
    /// Orientation view.
    pub orientation: super::orientation_ui::OrientationViewState,
    /// Edges view.
    pub edges: super::edges_ui::EdgesViewState,
    /// Waveform view.
    pub wave: super::transport_ui::WaveViewState,
    /// Navigation panel.
    pub nav: super::nav_ui::NavState,
    /// The all-knobs TOML editor.
    pub toml: super::params_ui::TomlEditor,
    /// The metadata form, while edited.
    pub meta_form: Option<super::meta_ui::MetaForm>,
    /// Where the tool windows open and stay, measured each frame.
    pub tool_place: super::ToolPlace,
    /// The window is small ([`COMPACT_BELOW`]): the panels scroll both ways, scroll bars shown.
    pub compact: bool,
}

/// A window narrower or shorter than this (points) is laid out compact ([`ViewStates::compact`]).
pub const COMPACT_BELOW: egui::Vec2 = egui::vec2(900.0, 640.0);

impl ViewStates {
    /// Forgets the hover read-outs (they describe another group).
    pub fn clear_readouts(&mut self) {
        self.frame.readout = None;
        self.flow.readout = None;
        self.hough.readout = None;
        self.stripes.readout = None;
        self.depth.readout = None;
        self.orientation.readout = None;
        self.edges.readout = None;
    }
}
