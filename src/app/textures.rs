//! GPU textures of the current group's views, uploaded when new renderings arrive.

use std::collections::HashMap;
use std::sync::Arc;

use egui::{TextureHandle, TextureOptions};

use super::render::{self, Rendered};
use super::worker::ViewImage;
use crate::image::Image;
use crate::pipeline::optical_flow::FlowField;

/// One uploaded view texture and the rendering it came from.
#[derive(Clone)]
pub struct ViewTexture {
    /// The rendering (value range for colour bars).
    pub rendered: Arc<Rendered>,
    /// The texture.
    pub handle: TextureHandle,
    /// Identity of the stage output it shows ([`crate::pipeline::StageCache::output_id`]).
    pub source: u64,
}

/// Textures of the views and of the frame on screen.
#[derive(Default)]
pub struct Textures {
    views: HashMap<ViewImage, ViewTexture>,
    frame: Option<((usize, usize, usize), TextureHandle)>,
    /// Pre-rendered frames of one group: (group, frames address, images).
    frame_images: Option<(usize, usize, Vec<Arc<egui::ColorImage>>)>,
}

impl std::fmt::Debug for Textures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Textures")
            .field("views", &self.views.keys().collect::<Vec<_>>())
            .finish_non_exhaustive()
    }
}

fn options() -> TextureOptions {
    TextureOptions::NEAREST
}

impl Textures {
    /// Uploads a rendering of `key` made from the stage output with identity `source`.
    pub fn set(
        &mut self,
        ctx: &egui::Context,
        key: ViewImage,
        rendered: Arc<Rendered>,
        source: u64,
    ) {
        let name = format!("{key:?}");
        match self.views.get_mut(&key) {
            Some(t) => {
                t.handle.set(rendered.image.clone(), options());
                t.rendered = rendered;
                t.source = source;
            }
            None => {
                let handle = ctx.load_texture(name, rendered.image.clone(), options());
                self.views.insert(
                    key,
                    ViewTexture {
                        rendered,
                        handle,
                        source,
                    },
                );
            }
        }
    }

    /// The texture of `key`, if one was uploaded.
    #[must_use]
    pub fn get(&self, key: ViewImage) -> Option<&ViewTexture> {
        self.views.get(&key)
    }

    /// The texture of `key`; when none was uploaded, `missing` is drawn as the view's note
    /// instead.
    pub fn get_or_note(
        &self,
        ui: &mut egui::Ui,
        key: ViewImage,
        missing: &str,
    ) -> Option<&ViewTexture> {
        let tex = self.get(key);
        if tex.is_none() {
            super::views::empty_note(ui, missing);
        }
        tex
    }

    /// The flow-colour texture of field `index` (residual after `land_px`) of the flow output
    /// with identity `source`, rendered here when the worker did not (the operator picked
    /// another window).
    pub fn flow(
        &mut self,
        ctx: &egui::Context,
        flows: &Arc<Vec<FlowField>>,
        source: u64,
        index: usize,
        land_px: f32,
    ) -> Option<&ViewTexture> {
        let key = ViewImage::FlowColour(index);
        if self.views.get(&key).is_none_or(|t| t.source != source) {
            let field = flows.get(index)?;
            self.set(
                ctx,
                key,
                Arc::new(render::flow_colour(field, land_px)),
                source,
            );
        }
        self.views.get(&key)
    }

    /// The texture of frame `index` of group `group` (converted on first use).
    pub fn frame(
        &mut self,
        ctx: &egui::Context,
        group: usize,
        index: usize,
        frames: &Arc<Vec<Image>>,
    ) -> Option<&TextureHandle> {
        let id = (group, index, Arc::as_ptr(frames) as usize);
        if self.frame.as_ref().is_none_or(|(k, _)| *k != id) {
            let ready = self
                .frame_images
                .as_ref()
                .filter(|(g, p, _)| *g == group && *p == id.2)
                .and_then(|(_, _, v)| v.get(index).cloned());
            let colour = match ready {
                Some(c) => c,
                None => Arc::new(render::grey(frames.get(index)?)),
            };
            match &mut self.frame {
                Some((k, h)) => {
                    h.set(colour, options());
                    *k = id;
                }
                None => self.frame = Some((id, ctx.load_texture("frame", colour, options()))),
            }
        }
        self.frame.as_ref().map(|(_, h)| h)
    }

    /// Keeps a group's frames rendered elsewhere (the worker renders them when it loads a group),
    /// so showing one only uploads it.
    pub fn set_frames(
        &mut self,
        group: usize,
        frames: &Arc<Vec<Image>>,
        images: Vec<Arc<egui::ColorImage>>,
    ) {
        if images.len() == frames.len() {
            self.frame_images = Some((group, Arc::as_ptr(frames) as usize, images));
        }
    }

    /// Forgets every texture (a new scan).
    pub fn clear(&mut self) {
        self.views.clear();
        self.frame = None;
        self.frame_images = None;
    }
}
