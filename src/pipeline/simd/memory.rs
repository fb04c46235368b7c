//! Buffers written straight into uninitialised memory: parallel zeroing, float arrays that start a cache line, and rows filled in parallel without a zeroing pass first.

use std::mem::MaybeUninit;

use rayon::prelude::*;

/// Values per parallel work item of the zero fills.
const ZERO_CHUNK: usize = 1 << 16;
/// Floats per 64-byte cache line.
const LINE_FLOATS: usize = 16;

/// `len` zeros, written by every rayon thread in parallel (a large `vec![0.0; len]` is one
/// thread's memset whenever the allocator recycles memory, which it does for repeated
/// frame-sized buffers).
#[must_use]
pub fn zeros_par(len: usize) -> Vec<f32> {
    let mut v: Vec<f32> = Vec::with_capacity(len);
    v.spare_capacity_mut()[..len]
        .par_chunks_mut(ZERO_CHUNK)
        .for_each(|c| c.fill(MaybeUninit::new(0.0)));
    // SAFETY: the capacity is at least `len`, and the fill above initialised all of the first
    // `len` elements.
    unsafe { v.set_len(len) };
    v
}

/// Writes one stretch of uninitialised floats in order, one [`RowWriter::push`] per value;
/// whatever it has not written when it is finished is set to 0, so every value ends up
/// initialised whatever the caller does.
pub struct RowWriter<'a> {
    rest: std::slice::IterMut<'a, MaybeUninit<f32>>,
}

impl<'a> RowWriter<'a> {
    fn new(slots: &'a mut [MaybeUninit<f32>]) -> Self {
        Self {
            rest: slots.iter_mut(),
        }
    }

    /// Writes the next value (nothing once the stretch is full).
    #[inline(always)]
    pub fn push(&mut self, x: f32) {
        if let Some(slot) = self.rest.next() {
            slot.write(x);
        }
    }

    /// Runs `write` on a copy of this writer held in a local and then takes back what it left,
    /// so that a loop of [`RowWriter::push`] keeps the write position in a register instead of
    /// storing it through `self` at every value.
    #[inline(always)]
    pub fn with_local(&mut self, write: impl FnOnce(&mut RowWriter<'a>)) {
        let mut local = RowWriter {
            rest: std::mem::take(&mut self.rest),
        };
        write(&mut local);
        self.rest = local.rest;
    }

    /// Zeroes what is left.
    fn finish(self) {
        for slot in self.rest {
            slot.write(0.0);
        }
    }
}

/// Fills two arrays of `rows` rows of `row_len` values, row by row in parallel: `fill(scratch,
/// y, a, b)` writes row y of `a` and of `b` (each scratch from `init` serves one thread's rows).
fn fill_row_pairs<S>(
    (a, b): (&mut [MaybeUninit<f32>], &mut [MaybeUninit<f32>]),
    row_len: usize,
    init: impl Fn() -> S + Sync + Send,
    fill: impl for<'w> Fn(&mut S, usize, &mut RowWriter<'w>, &mut RowWriter<'w>) + Sync + Send,
) {
    if row_len == 0 {
        return;
    }
    a.par_chunks_mut(row_len)
        .zip(b.par_chunks_mut(row_len))
        .enumerate()
        .for_each_init(init, |scratch, (y, (ra, rb))| {
            let (mut wa, mut wb) = (RowWriter::new(ra), RowWriter::new(rb));
            fill(scratch, y, &mut wa, &mut wb);
            wa.finish();
            wb.finish();
        });
}

/// Two vectors of `rows` rows of `row_len` values each, row y of both written by one call
/// `fill(scratch, y, a, b)`, rows in parallel, without zeroing them first.
pub fn vec_pair_from_rows<S>(
    row_len: usize,
    rows: usize,
    init: impl Fn() -> S + Sync + Send,
    fill: impl for<'w> Fn(&mut S, usize, &mut RowWriter<'w>, &mut RowWriter<'w>) + Sync + Send,
) -> (Vec<f32>, Vec<f32>) {
    let len = row_len * rows;
    let mut a: Vec<f32> = Vec::with_capacity(len);
    let mut b: Vec<f32> = Vec::with_capacity(len);
    fill_row_pairs(
        (
            &mut a.spare_capacity_mut()[..len],
            &mut b.spare_capacity_mut()[..len],
        ),
        row_len,
        init,
        fill,
    );
    if row_len > 0 {
        // SAFETY: both capacities are at least `len`, and `fill_row_pairs` cut the first `len`
        // slots of each into rows of `row_len` and initialised every one of them (a
        // `RowWriter` zeroes what `fill` leaves).
        unsafe {
            a.set_len(len);
            b.set_len(len);
        }
    }
    (a, b)
}

/// A float array that starts a 64-byte cache line: with rows a whole number of lines long, the
/// row kernels' 8-float loads and stores never straddle two lines (a straddling load costs two
/// cache accesses).
#[derive(Debug, Default)]
pub struct Aligned {
    buf: Vec<f32>,
    off: usize,
    len: usize,
}

impl Aligned {
    /// `len` values, written by `fill` into uninitialised slots.
    ///
    /// # Safety
    /// `fill` must initialise every element of the slice it is given.
    unsafe fn build(len: usize, fill: impl FnOnce(&mut [MaybeUninit<f32>])) -> Self {
        let mut buf: Vec<f32> = Vec::with_capacity(len + LINE_FLOATS);
        // f32 storage is 4-byte aligned, so whole floats reach the next line boundary.
        let at = (buf.as_ptr() as usize / std::mem::size_of::<f32>()) % LINE_FLOATS;
        let off = (LINE_FLOATS - at) % LINE_FLOATS;
        let spare = buf.spare_capacity_mut();
        for x in &mut spare[..off] {
            x.write(0.0);
        }
        fill(&mut spare[off..off + len]);
        // SAFETY: the capacity is at least `off + len`; the loop above initialised the first
        // `off` elements and `fill`, by the caller's contract, the next `len`.
        unsafe { buf.set_len(off + len) };
        Self { buf, off, len }
    }

    /// `len` zeros, filled in parallel.
    #[must_use]
    pub fn zeros(len: usize) -> Self {
        // SAFETY: the chunks cover the slice, and each is filled whole.
        unsafe {
            Self::build(len, |s| {
                s.par_chunks_mut(ZERO_CHUNK)
                    .for_each(|c| c.fill(MaybeUninit::new(0.0)));
            })
        }
    }

    /// `2·rows` rows of `row_len` values: row y of the first `rows` and row y of the last
    /// `rows` both written by one call `fill(scratch, y, first, second)`, rows in parallel.
    pub fn from_row_pairs<S>(
        row_len: usize,
        rows: usize,
        init: impl Fn() -> S + Sync + Send,
        fill: impl for<'w> Fn(&mut S, usize, &mut RowWriter<'w>, &mut RowWriter<'w>) + Sync + Send,
    ) -> Self {
        let half = row_len * rows;
        // SAFETY: with `row_len` = 0 the slice is empty; otherwise its two halves are whole
        // rows, and `fill_row_pairs` initialises every row of both (a `RowWriter` zeroes what
        // `fill` leaves).
        unsafe {
            Self::build(2 * half, |all| {
                if row_len > 0 {
                    fill_row_pairs(all.split_at_mut(half), row_len, init, fill);
                }
            })
        }
    }
}

impl std::ops::Deref for Aligned {
    type Target = [f32];
    #[inline]
    fn deref(&self) -> &[f32] {
        &self.buf[self.off..self.off + self.len]
    }
}

impl std::ops::DerefMut for Aligned {
    #[inline]
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.buf[self.off..self.off + self.len]
    }
}

impl Clone for Aligned {
    /// A copy placed anew (a plain copy of the vector could start mid-line).
    fn clone(&self) -> Self {
        // SAFETY: `self` holds `len` values, so the zip writes every element.
        unsafe {
            Self::build(self.len, |s| {
                for (d, &x) in s.iter_mut().zip(self.iter()) {
                    d.write(x);
                }
            })
        }
    }
}

impl PartialEq for Aligned {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_start_cache_lines_and_every_slot_is_written() {
        for len in [0, 1, 17, 1000] {
            let a = Aligned::zeros(len);
            assert_eq!(a.len(), len);
            assert!(a.iter().all(|&x| x == 0.0));
            assert_eq!(a.as_ptr() as usize % 64, 0);
            assert_eq!(a.clone(), a);
            assert_eq!(a.clone().as_ptr() as usize % 64, 0);
        }
        // Rows that write only some of their values get zeros in the rest.
        let b = Aligned::from_row_pairs(
            5,
            3,
            || (),
            |(), y, first, second| {
                first.push(y as f32);
                second.with_local(|w| w.push(-(y as f32) - 1.0));
                for _ in 0..6 {
                    second.push(-(y as f32) - 1.0);
                }
            },
        );
        assert_eq!(b.as_ptr() as usize % 64, 0);
        let want: Vec<f32> = [0.0, 1.0, 2.0]
            .iter()
            .flat_map(|&y| [y, 0.0, 0.0, 0.0, 0.0])
            .chain((0..3).flat_map(|y| [-(y as f32) - 1.0; 5]))
            .collect();
        assert_eq!(&b[..], &want[..]);
        let (u, v) = vec_pair_from_rows(
            2,
            2,
            || 0,
            |n: &mut i32, y, a, b| {
                *n += 1;
                a.push(y as f32);
                a.push(10.0);
                b.push(7.0);
            },
        );
        assert_eq!(u, [0.0, 10.0, 1.0, 10.0]);
        assert_eq!(v, [7.0, 0.0, 7.0, 0.0]);
        assert_eq!(zeros_par(100_003), vec![0.0; 100_003]);
    }
}
