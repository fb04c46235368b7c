//! Group signals held back to back in large blocks, and the read-only view the stitcher takes of either form.
//!
//! A clip keeps every group's signal until it is finished. As [`GroupSignal`]s that is one
//! allocation for the positions and one per channel, per group: the edge stage's eight border
//! tracks make ten, each with its allocator overhead, which doubled what a long run held.
//! [`SignalPack`] copies each group's samples into shared blocks instead (a block is never
//! reallocated, so nothing is copied twice and at most one block is part-empty), and hands out
//! [`SignalView`]s that read exactly the same numbers.

use super::GroupSignal;

/// Samples (f32) per block; positions per block are this divided by the channel count.
const BLOCK_SAMPLES: usize = 16_384;

/// One group's signal, borrowed: what [`super::stitch`] reads.
#[derive(Clone, Copy, Debug)]
pub struct SignalView<'a> {
    /// Group index.
    pub group: usize,
    /// Groove position of each sample (µm from the scan start), increasing.
    pub positions_um: &'a [f64],
    /// Groove speed Vt at this group (mm/s).
    pub groove_speed_mm_s: f64,
    channels: Channels<'a>,
}

#[derive(Clone, Copy, Debug)]
enum Channels<'a> {
    /// A [`GroupSignal`]'s own buffers.
    Owned(&'a [Vec<f32>]),
    /// `count` channels of `positions_um.len()` samples each, one after the other; `ragged`
    /// when the signal's own channels were of other lengths (cut or padded with NaN here).
    Packed {
        samples: &'a [f32],
        count: usize,
        ragged: bool,
    },
}

impl<'a> SignalView<'a> {
    /// Number of channels.
    #[must_use]
    pub fn channel_count(&self) -> usize {
        match self.channels {
            Channels::Owned(c) => c.len(),
            Channels::Packed { count, .. } => count,
        }
    }

    /// Every channel has one sample per position (the stitcher refuses a group without).
    #[must_use]
    pub fn lengths_agree(&self) -> bool {
        match self.channels {
            Channels::Owned(ch) => ch.iter().all(|c| c.len() == self.positions_um.len()),
            Channels::Packed { ragged, .. } => !ragged,
        }
    }

    /// Channel `c`'s samples (velocity mm/s or a border track; NaN = gap); empty past the last.
    #[must_use]
    pub fn channel(&self, c: usize) -> &'a [f32] {
        match self.channels {
            Channels::Owned(ch) => ch.get(c).map_or(&[], Vec::as_slice),
            Channels::Packed { samples, count, .. } => {
                let n = self.positions_um.len();
                if c < count {
                    samples.get(c * n..(c + 1) * n).unwrap_or(&[])
                } else {
                    &[]
                }
            }
        }
    }
}

impl<'a> From<&'a GroupSignal> for SignalView<'a> {
    fn from(g: &'a GroupSignal) -> Self {
        Self {
            group: g.group,
            positions_um: &g.positions_um,
            groove_speed_mm_s: g.groove_speed_mm_s,
            channels: Channels::Owned(&g.channels),
        }
    }
}

/// Group signals in order, read one group at a time: a slice of [`GroupSignal`]s or a
/// [`SignalPack`].
pub trait GroupSignals {
    /// Number of groups.
    fn group_count(&self) -> usize;
    /// Group `i` (in order; `i < group_count()`).
    fn view(&self, i: usize) -> Option<SignalView<'_>>;
    /// Every group, in order.
    fn views(&self) -> impl Iterator<Item = SignalView<'_>> {
        (0..self.group_count()).filter_map(|i| self.view(i))
    }
}

/// A slice, array or `Vec` of [`GroupSignal`]s.
impl<T: AsRef<[GroupSignal]> + ?Sized> GroupSignals for T {
    fn group_count(&self) -> usize {
        self.as_ref().len()
    }
    fn view(&self, i: usize) -> Option<SignalView<'_>> {
        self.as_ref().get(i).map(SignalView::from)
    }
}

/// Where one group's samples lie in a [`SignalPack`].
#[derive(Clone, Copy, Debug)]
struct Entry {
    group: usize,
    groove_speed_mm_s: f64,
    block: usize,
    positions_start: usize,
    len: usize,
    samples_start: usize,
    channels: usize,
    ragged: bool,
}

/// One block: positions and samples of whole groups, never grown past its first capacity.
#[derive(Clone, Debug, Default)]
struct Block {
    positions_um: Vec<f64>,
    samples: Vec<f32>,
}

/// Group signals packed into shared blocks (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct SignalPack {
    entries: Vec<Entry>,
    blocks: Vec<Block>,
}

impl SignalPack {
    /// Room for `groups` groups' entries (the samples get blocks as they come).
    #[must_use]
    pub fn with_capacity(groups: usize) -> Self {
        Self {
            entries: Vec::with_capacity(groups),
            blocks: Vec::new(),
        }
    }

    /// No group yet.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Bytes it holds on the heap (its blocks' and entries' capacity).
    #[must_use]
    pub fn heap_bytes(&self) -> usize {
        let blocks: usize = self
            .blocks
            .iter()
            .map(|b| {
                b.positions_um.capacity() * std::mem::size_of::<f64>()
                    + b.samples.capacity() * std::mem::size_of::<f32>()
            })
            .sum();
        blocks
            + self.blocks.capacity() * std::mem::size_of::<Block>()
            + self.entries.capacity() * std::mem::size_of::<Entry>()
    }

    /// Appends a copy of `signal`'s samples. A channel whose length differs from the
    /// positions' is cut or padded with NaN and the group marked (its view's
    /// [`SignalView::lengths_agree`] is false), so the stitcher refuses it as it would the
    /// signal itself.
    pub fn push(&mut self, signal: &GroupSignal) {
        let len = signal.positions_um.len();
        let channels = signal.channels.len();
        let need = len * channels;
        let fits = self.blocks.last().is_some_and(|b| {
            b.positions_um.capacity() - b.positions_um.len() >= len
                && b.samples.capacity() - b.samples.len() >= need
        });
        if !fits {
            let samples = BLOCK_SAMPLES.max(need);
            let positions = (BLOCK_SAMPLES / channels.max(1)).max(len);
            self.blocks.push(Block {
                positions_um: Vec::with_capacity(positions),
                samples: Vec::with_capacity(samples),
            });
        }
        let block_index = self.blocks.len() - 1;
        let Some(block) = self.blocks.last_mut() else {
            return;
        };
        let entry = Entry {
            group: signal.group,
            groove_speed_mm_s: signal.groove_speed_mm_s,
            block: block_index,
            positions_start: block.positions_um.len(),
            len,
            samples_start: block.samples.len(),
            channels,
            ragged: signal.channels.iter().any(|c| c.len() != len),
        };
        block.positions_um.extend_from_slice(&signal.positions_um);
        for ch in &signal.channels {
            let kept = &ch[..ch.len().min(len)];
            block.samples.extend_from_slice(kept);
            block
                .samples
                .extend(std::iter::repeat_n(f32::NAN, len - kept.len()));
        }
        self.entries.push(entry);
    }
}

impl GroupSignals for SignalPack {
    fn group_count(&self) -> usize {
        self.entries.len()
    }
    fn view(&self, i: usize) -> Option<SignalView<'_>> {
        let e = self.entries.get(i)?;
        let block = self.blocks.get(e.block)?;
        Some(SignalView {
            group: e.group,
            positions_um: block
                .positions_um
                .get(e.positions_start..e.positions_start + e.len)?,
            groove_speed_mm_s: e.groove_speed_mm_s,
            channels: Channels::Packed {
                samples: block
                    .samples
                    .get(e.samples_start..e.samples_start + e.len * e.channels)?,
                count: e.channels,
                ragged: e.ragged,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(group: usize, len: usize, channels: usize) -> GroupSignal {
        #[allow(clippy::cast_precision_loss)]
        GroupSignal {
            group,
            positions_um: (0..len).map(|i| (group * 100 + i) as f64).collect(),
            channels: (0..channels)
                .map(|c| {
                    (0..len)
                        .map(|i| (group * 1000 + c * 10 + i) as f32)
                        .collect()
                })
                .collect(),
            groove_speed_mm_s: 100.0 + group as f64,
        }
    }

    #[test]
    fn a_pack_reads_back_what_went_in_across_blocks() {
        // Groups of 3000 samples x 8 channels: one block holds none whole, so each gets its own;
        // then small groups share one.
        let groups: Vec<GroupSignal> = (0..5)
            .map(|g| signal(g, 3000, 8))
            .chain((5..400).map(|g| signal(g, 7, 8)))
            .collect();
        let mut pack = SignalPack::with_capacity(groups.len());
        for g in &groups {
            pack.push(g);
        }
        assert_eq!(pack.group_count(), groups.len());
        for (a, b) in groups.views().zip(pack.views()) {
            assert_eq!(a.group, b.group);
            assert_eq!(a.positions_um, b.positions_um);
            assert_eq!(a.groove_speed_mm_s.to_bits(), b.groove_speed_mm_s.to_bits());
            assert_eq!(a.channel_count(), b.channel_count());
            for c in 0..=a.channel_count() {
                assert_eq!(a.channel(c), b.channel(c));
            }
            assert!(b.lengths_agree());
        }
        assert!(pack.blocks.len() < 12, "{} blocks", pack.blocks.len());
    }

    #[test]
    fn a_channel_of_the_wrong_length_reads_back_cut_or_padded() {
        let mut g = signal(0, 4, 2);
        g.channels[0].truncate(2);
        g.channels[1].push(9.0);
        let mut pack = SignalPack::default();
        pack.push(&g);
        let v = pack.view(0).unwrap();
        assert_eq!(&v.channel(0)[..2], &[0.0, 1.0]);
        assert!(v.channel(0)[2..].iter().all(|x| x.is_nan()));
        assert_eq!(v.channel(1), &[10.0, 11.0, 12.0, 13.0]);
        assert!(!v.lengths_agree());
        assert!(!SignalView::from(&g).lengths_agree());
        assert!(SignalView::from(&signal(1, 4, 2)).lengths_agree());
    }
}
