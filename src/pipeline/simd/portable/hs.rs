//! The Horn–Schunck half-row kernel in portable code: fixed 8-lane arrays ([`F32x8`]) that the compiler maps onto the target's vector registers, operation for operation the AVX2 build.

use crate::pipeline::simd::hs::{
    GROOVE_COEFS, HalfEdges, HalfRowInputs, LANES, PAIR, PLAIN_COEFS, SolveScalars,
};

/// Eight f32 lanes for the portable core: element-wise operations the compiler turns into
/// vector instructions of whatever the target has.
#[derive(Clone, Copy)]
pub(crate) struct F32x8([f32; LANES]);

impl F32x8 {
    /// The first 8 values of `s` (all zeros when it holds fewer).
    #[inline(always)]
    pub(crate) fn load(s: &[f32]) -> Self {
        let mut out = [0.0; LANES];
        if let Some(whole) = s.get(..LANES) {
            out.copy_from_slice(whole);
        }
        Self(out)
    }

    /// `[first, a0, …, a6]`: moved up a lane.
    #[inline(always)]
    pub(crate) fn up_lane(self, first: f32) -> Self {
        let mut out = [first; LANES];
        out[1..].copy_from_slice(&self.0[..LANES - 1]);
        Self(out)
    }

    /// `[a1, …, a7, last]`: moved down a lane.
    #[inline(always)]
    pub(crate) fn down_lane(self, last: f32) -> Self {
        let mut out = [last; LANES];
        out[..LANES - 1].copy_from_slice(&self.0[1..]);
        Self(out)
    }

    /// Lane by lane, `self` where `mask` is set, else `other`.
    #[inline(always)]
    pub(crate) fn select(self, other: Self, mask: [bool; LANES]) -> Self {
        Self(std::array::from_fn(|l| {
            if mask[l] { self.0[l] } else { other.0[l] }
        }))
    }

    #[inline(always)]
    pub(crate) fn splat(x: f32) -> Self {
        Self([x; LANES])
    }

    #[inline(always)]
    pub(crate) fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut out = self.0;
        for (a, &b) in out.iter_mut().zip(&o.0) {
            *a = f(*a, b);
        }
        Self(out)
    }

    #[inline(always)]
    pub(crate) fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }

    #[inline(always)]
    pub(crate) fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }

    #[inline(always)]
    pub(crate) fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
}

/// The half-row in portable code (see [`crate::pipeline::simd::hs::update_half_row`]): the AVX2
/// build operation for operation on [`F32x8`] (the lane moves at the edges move values only,
/// so both give the same bits).
#[inline(always)]
pub(in crate::pipeline::simd) fn blocks<const GROOVE: bool, const RELAX: bool>(
    k: SolveScalars,
    edges: HalfEdges,
    m: usize,
    rows: HalfRowInputs<'_>,
    dst: &mut [f32],
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    // A stored row as its m (u, v) vector pairs.
    fn pairs(s: &[f32], m: usize) -> &[[f32; PAIR]] {
        s.get(..m * PAIR)
            .map_or(&[][..], |p| p.as_chunks::<PAIR>().0)
    }
    // The u (`part` 0) or v (1) vector of a pair, copied as one fixed run (which stays in
    // vector registers; a lane-by-lane copy did not).
    #[inline(always)]
    fn half(p: &[f32; PAIR], part: usize) -> F32x8 {
        let (u, v) = p.split_at(LANES);
        F32x8::load(if part == 0 { u } else { v })
    }
    let HalfRowInputs {
        across,
        up,
        down,
        coef,
    } = rows;
    let across = pairs(across, m);
    let at = |i: usize| {
        across
            .get(i)
            .map_or((F32x8::splat(0.0), F32x8::splat(0.0)), |p| {
                (half(p, 0), half(p, 1))
            })
    };
    let (last_k, last_lane) = edges.last;
    // The mirrored lane as a mask: a lane written through a run-time index would push the
    // whole vector out of registers.
    let mirror: [bool; LANES] = std::array::from_fn(|l| l == last_lane);
    let outs = dst
        .get_mut(..m * PAIR)
        .map_or(&mut [][..], |d| d.as_chunks_mut::<PAIR>().0);
    let ins = pairs(up, m)
        .iter()
        .zip(pairs(down, m))
        .zip(coef.chunks_exact(LANES * ncoef));
    for (kk, (out, ((up, down), c))) in outs.iter_mut().zip(ins).enumerate() {
        let (left, mut right) = if edges.odd {
            let left = at(kk);
            let right = if kk + 1 < m {
                at(kk + 1)
            } else {
                let first = at(0);
                (
                    first.0.down_lane(left.0.0[LANES - 1]),
                    first.1.down_lane(left.1.0[LANES - 1]),
                )
            };
            (left, right)
        } else {
            let right = at(kk);
            let left = if kk > 0 {
                at(kk - 1)
            } else {
                let wrap = at(m - 1);
                (wrap.0.up_lane(right.0.0[0]), wrap.1.up_lane(right.1.0[0]))
            };
            (left, right)
        };
        if kk == last_k {
            right = (
                left.0.select(right.0, mirror),
                left.1.select(right.1, mirror),
            );
        }
        let inputs = BlockInputs {
            lu: left.0,
            ru: right.0,
            uu: half(up, 0),
            du: half(down, 0),
            lv: left.1,
            rv: right.1,
            uv: half(up, 1),
            dv: half(down, 1),
            old: (half(out, 0), half(out, 1)),
        };
        let (a, b) = portable_block::<GROOVE, RELAX>(k, &inputs, |j| {
            F32x8::load(c.get(j * LANES..).unwrap_or_default())
        });
        let (ou, ov) = out.split_at_mut(LANES);
        ou.copy_from_slice(&a.0);
        ov.copy_from_slice(&b.0);
    }
}

/// What one block of [`blocks`] reads: the neighbours of its 8 lanes and their old
/// u and v (used when relaxing).
struct BlockInputs {
    lu: F32x8,
    ru: F32x8,
    uu: F32x8,
    du: F32x8,
    lv: F32x8,
    rv: F32x8,
    uv: F32x8,
    dv: F32x8,
    old: (F32x8, F32x8),
}

/// The new u and v of one block of [`blocks`], coefficient j read by `c(j)`.
#[inline(always)]
fn portable_block<const GROOVE: bool, const RELAX: bool>(
    k: SolveScalars,
    x: &BlockInputs,
    c: impl Fn(usize) -> F32x8,
) -> (F32x8, F32x8) {
    let su = x.lu.add(x.ru).add(x.uu.add(x.du));
    let sv = x.lv.add(x.rv).add(x.uv.add(x.dv));
    let (mut a, mut b) = if GROOVE {
        let q = F32x8::splat(k.quarter_lambda);
        let nu = q.mul(su).add(c(0).mul(x.uu)).add(c(1).mul(x.du));
        let nv = q.mul(sv);
        let (puu, puv, pvv) = (c(2), c(3), c(4));
        (
            puu.mul(nu).add(puv.mul(nv)).add(c(5)),
            puv.mul(nu).add(pvv.mul(nv)).add(c(6)),
        )
    } else {
        let quarter = F32x8::splat(0.25);
        let (ub, vb) = (quarter.mul(su), quarter.mul(sv));
        let (gx, gy) = (c(0), c(1));
        let t = gx.mul(ub).add(gy.mul(vb)).add(c(2));
        (ub.sub(gx.mul(t)), vb.sub(gy.mul(t)))
    };
    if RELAX {
        let (omega, (old_u, old_v)) = (F32x8::splat(k.omega), x.old);
        a = old_u.add(omega.mul(a.sub(old_u)));
        b = old_v.add(omega.mul(b.sub(old_v)));
    }
    (a, b)
}
