//! The record file shared by journals and parts: a magic line, a checksummed identity header, then checksummed records.
//!
//! Layout (little-endian): the magic line, then frames of `u32 length | payload | u32 CRC-32
//! of the payload`. The first frame is the identity header (JSON); each later frame is one
//! record whose first byte says its kind: a group (its report row, its signal with exact f32
//! and f64 bits, what it added to the slope reference, its timings), the slope history a shard
//! starts from, or the end of a part (the group count and a CRC-32 of every byte before it).
//! A reader stops at the first frame that is short or fails its checksum; whether that is a torn
//! tail (nothing readable after it) or damage inside the file, [`next_record`] tells.

use std::io::Write;

use crate::engine::{GroupOutcome, GroupReport, SlopeEntry};
use crate::pipeline::Stage;
use crate::pipeline::audio_signal::GroupSignal;
use crate::pipeline::walls::WallSide;

/// Largest frame accepted (bytes): a group's record is a few kB, a header a few tens.
const MAX_FRAME_BYTES: usize = 256 << 20;

const TAG_GROUP: u8 = 1;
const TAG_SEED: u8 = 2;
const TAG_END: u8 = 3;

/// One record of a journal or part.
#[derive(Clone, Debug)]
pub enum Record {
    /// A finished group.
    Group(GroupOutcome),
    /// The slope history per wall side at the start of a shard's range, oldest first.
    Seed(Vec<(WallSide, Vec<f64>)>),
    /// The end of a part: how many group records it holds and the CRC-32 of every byte of the
    /// file before this frame.
    End {
        /// Group records in the part.
        groups: u64,
        /// CRC-32 of the file up to this frame.
        file_crc: u32,
    },
}

/// Appends `bytes` as one frame to `out`.
///
/// # Errors
/// The writer's error.
pub fn write_frame(out: &mut impl Write, bytes: &[u8]) -> std::io::Result<()> {
    let len = u32::try_from(bytes.len())
        .map_err(|_| std::io::Error::other("record too large for a frame"))?;
    out.write_all(&len.to_le_bytes())?;
    out.write_all(bytes)?;
    out.write_all(&crc32fast::hash(bytes).to_le_bytes())
}

/// The whole frame at `offset` whose checksum holds: its payload and the offset just past it.
/// An empty payload is no frame: no header or record is empty, and zeros (what a file system
/// may leave past the last write after a power cut) would otherwise read as empty frames, the
/// CRC-32 of nothing being 0.
fn frame_at(bytes: &[u8], offset: usize) -> Option<(&[u8], usize)> {
    let len = bytes
        .get(offset..offset.checked_add(4)?)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map(|b| u32::from_le_bytes(b) as usize)?;
    if len == 0 || len > MAX_FRAME_BYTES {
        return None;
    }
    let start = offset + 4;
    let payload = bytes.get(start..start + len)?;
    let crc = bytes
        .get(start + len..start + len + 4)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())?;
    (crc32fast::hash(payload) == u32::from_le_bytes(crc)).then_some((payload, start + len + 4))
}

/// The frames of `bytes` from `offset` on: each payload with the offset just past it. Stops
/// at the first short, empty or damaged frame.
#[must_use]
pub fn read_frames(bytes: &[u8], mut offset: usize) -> Vec<(&[u8], usize)> {
    let mut out = Vec::new();
    while let Some((payload, end)) = frame_at(bytes, offset) {
        offset = end;
        out.push((payload, offset));
    }
    out
}

/// Where the first frame at or after `from` lies that is whole, passes its checksum and decodes
/// as a record: after a frame that does not read, one found means the file is damaged inside
/// (records that read follow the bad one), none means its tail is torn (a run stopped while
/// writing its last record). Each byte is tried, since a damaged length cannot be followed; a
/// chance match needs a record kind byte and a CRC-32 to agree, and then to decode.
#[must_use]
pub fn next_record(bytes: &[u8], from: usize) -> Option<usize> {
    (from..bytes.len()).find(|&at| {
        let kind = bytes.get(at + 4);
        matches!(kind, Some(&(TAG_GROUP | TAG_SEED | TAG_END)))
            && frame_at(bytes, at).is_some_and(|(payload, _)| decode(payload).is_ok())
    })
}

fn side_code(side: WallSide) -> u8 {
    match side {
        WallSide::Left => 0,
        WallSide::Right => 1,
    }
}

/// Encodes a record as a frame payload.
#[must_use]
pub fn encode(record: &Record) -> Vec<u8> {
    let mut b = Vec::new();
    match record {
        Record::Group(o) => {
            b.push(TAG_GROUP);
            put_u64(&mut b, o.group as u64);
            match &o.report {
                Some(r) => {
                    b.push(1);
                    put_u64(&mut b, r.group as u64);
                    put_opt_f64(&mut b, r.outlier_fraction);
                    put_u64(&mut b, r.rejected_fits as u64);
                    put_u64(&mut b, r.samples as u64);
                    match &r.warning {
                        Some(w) => {
                            b.push(1);
                            put_bytes(&mut b, w.as_bytes());
                        }
                        None => b.push(0),
                    }
                }
                None => b.push(0),
            }
            put_signal(&mut b, o.signal.as_deref());
            put_u64(&mut b, o.slopes.len() as u64);
            for &(side, m) in &o.slopes {
                b.push(side_code(side));
                b.extend_from_slice(&m.to_bits().to_le_bytes());
            }
            b.extend_from_slice(&o.load_secs.to_bits().to_le_bytes());
            put_u64(&mut b, o.stage_secs.len() as u64);
            for t in &o.stage_secs {
                b.extend_from_slice(&t.to_bits().to_le_bytes());
            }
            // Fields added later go last, in the order added (the borders, then the pixel
            // noise), so a record written before one reads back with none (`Reader::trailing`).
            put_signal(&mut b, o.borders.as_deref());
            put_opt_f64(
                &mut b,
                o.report.as_ref().and_then(|r| r.pixel_noise_grey_levels),
            );
        }
        Record::Seed(history) => {
            b.push(TAG_SEED);
            put_u64(&mut b, history.len() as u64);
            for (side, values) in history {
                b.push(side_code(*side));
                put_u64(&mut b, values.len() as u64);
                for v in values {
                    b.extend_from_slice(&v.to_bits().to_le_bytes());
                }
            }
        }
        Record::End { groups, file_crc } => {
            b.push(TAG_END);
            put_u64(&mut b, *groups);
            b.extend_from_slice(&file_crc.to_le_bytes());
        }
    }
    b
}

/// Decodes a frame payload.
///
/// # Errors
/// A sentence saying what is malformed.
pub fn decode(payload: &[u8]) -> Result<Record, String> {
    let mut r = Reader { b: payload, at: 0 };
    let record = match r.u8()? {
        TAG_GROUP => {
            let group = r.usize()?;
            let mut report = match r.u8()? {
                0 => None,
                _ => Some(GroupReport {
                    group: r.usize()?,
                    outlier_fraction: r.opt_f64()?,
                    rejected_fits: r.usize()?,
                    samples: r.usize()?,
                    warning: match r.u8()? {
                        0 => None,
                        _ => Some(
                            String::from_utf8(r.bytes()?.to_vec())
                                .map_err(|_| "a warning is not UTF-8".to_string())?,
                        ),
                    },
                    // Read from the record's end, below.
                    pixel_noise_grey_levels: None,
                }),
            };
            let signal = r.signal()?;
            let n = r.count(9)?;
            let mut slopes: Vec<SlopeEntry> = Vec::with_capacity(n);
            for _ in 0..n {
                let side = r.side()?;
                slopes.push((side, r.f64()?));
            }
            let load_secs = r.f64()?;
            let n = r.count(8)?;
            let mut stage_secs: Vec<f64> = (0..n).map(|_| r.f64()).collect::<Result<_, _>>()?;
            stage_secs.resize(Stage::ALL.len(), 0.0);
            let borders = r.trailing(Reader::signal)?;
            let noise = r.trailing(Reader::opt_f64)?;
            if let Some(report) = &mut report {
                report.pixel_noise_grey_levels = noise;
            }
            Record::Group(GroupOutcome {
                group,
                report,
                signal,
                borders,
                slopes,
                load_secs,
                stage_secs,
            })
        }
        TAG_SEED => {
            let n = r.count(9)?;
            let mut history = Vec::with_capacity(n);
            for _ in 0..n {
                let side = r.side()?;
                let len = r.count(8)?;
                history.push((side, (0..len).map(|_| r.f64()).collect::<Result<_, _>>()?));
            }
            Record::Seed(history)
        }
        TAG_END => Record::End {
            groups: r.u64()?,
            file_crc: u32::from_le_bytes(r.array()?),
        },
        other => return Err(format!("unknown record kind {other}")),
    };
    if r.at != payload.len() {
        return Err("a record has trailing bytes".into());
    }
    Ok(record)
}

/// A flag byte, then the signal with exact bits: group, speed, positions, channels.
fn put_signal(b: &mut Vec<u8>, signal: Option<&GroupSignal>) {
    let Some(s) = signal else {
        b.push(0);
        return;
    };
    b.push(1);
    put_u64(b, s.group as u64);
    b.extend_from_slice(&s.groove_speed_mm_s.to_bits().to_le_bytes());
    put_u64(b, s.positions_um.len() as u64);
    for p in &s.positions_um {
        b.extend_from_slice(&p.to_bits().to_le_bytes());
    }
    put_u64(b, s.channels.len() as u64);
    for ch in &s.channels {
        put_u64(b, ch.len() as u64);
        for v in ch {
            b.extend_from_slice(&v.to_bits().to_le_bytes());
        }
    }
}

fn put_u64(b: &mut Vec<u8>, v: u64) {
    b.extend_from_slice(&v.to_le_bytes());
}

fn put_opt_f64(b: &mut Vec<u8>, v: Option<f64>) {
    match v {
        Some(v) => {
            b.push(1);
            b.extend_from_slice(&v.to_bits().to_le_bytes());
        }
        None => b.push(0),
    }
}

fn put_bytes(b: &mut Vec<u8>, bytes: &[u8]) {
    put_u64(b, bytes.len() as u64);
    b.extend_from_slice(bytes);
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    /// A field a later version added at the end of a record: None where the record ends
    /// before it (one written before that version).
    fn trailing<T>(
        &mut self,
        read: impl FnOnce(&mut Self) -> Result<Option<T>, String>,
    ) -> Result<Option<T>, String> {
        if self.at < self.b.len() {
            read(self)
        } else {
            Ok(None)
        }
    }

    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let s = self
            .b
            .get(self.at..self.at.saturating_add(n))
            .ok_or_else(|| "a record ends early".to_string())?;
        self.at += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        <[u8; N]>::try_from(self.take(N)?).map_err(|_| "a record ends early".to_string())
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.array::<1>()?[0])
    }

    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array()?))
    }

    fn usize(&mut self) -> Result<usize, String> {
        usize::try_from(self.u64()?).map_err(|_| "a count does not fit this machine".to_string())
    }

    /// A count of items of at least `item_bytes` each, checked against the bytes left.
    fn count(&mut self, item_bytes: usize) -> Result<usize, String> {
        let n = self.usize()?;
        if n.saturating_mul(item_bytes) > self.b.len() - self.at {
            return Err("a count runs past the record".into());
        }
        Ok(n)
    }

    fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_bits(self.u64()?))
    }

    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_bits(u32::from_le_bytes(self.array()?)))
    }

    fn opt_f64(&mut self) -> Result<Option<f64>, String> {
        match self.u8()? {
            0 => Ok(None),
            _ => Ok(Some(self.f64()?)),
        }
    }

    /// A signal as [`put_signal`] writes it.
    fn signal(&mut self) -> Result<Option<std::sync::Arc<GroupSignal>>, String> {
        if self.u8()? == 0 {
            return Ok(None);
        }
        let group = self.usize()?;
        let groove_speed_mm_s = self.f64()?;
        let n = self.count(8)?;
        let positions_um = (0..n).map(|_| self.f64()).collect::<Result<_, _>>()?;
        let n_ch = self.count(8)?;
        let mut channels = Vec::with_capacity(n_ch);
        for _ in 0..n_ch {
            let len = self.count(4)?;
            channels.push((0..len).map(|_| self.f32()).collect::<Result<_, _>>()?);
        }
        Ok(Some(std::sync::Arc::new(GroupSignal {
            group,
            positions_um,
            channels,
            groove_speed_mm_s,
        })))
    }

    fn side(&mut self) -> Result<WallSide, String> {
        match self.u8()? {
            0 => Ok(WallSide::Left),
            1 => Ok(WallSide::Right),
            other => Err(format!("unknown wall side {other}")),
        }
    }

    fn bytes(&mut self) -> Result<&[u8], String> {
        let n = self.count(1)?;
        self.take(n)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn outcome() -> GroupOutcome {
        GroupOutcome {
            group: 7,
            report: Some(GroupReport {
                group: 7,
                outlier_fraction: Some(0.125),
                rejected_fits: 3,
                samples: 2,
                warning: Some("group 7: ünïcode".into()),
                pixel_noise_grey_levels: Some(1.75),
            }),
            signal: Some(std::sync::Arc::new(GroupSignal {
                group: 7,
                positions_um: vec![1.0 / 3.0, 2.5],
                channels: vec![vec![f32::NAN, -0.1]],
                groove_speed_mm_s: 939.3,
            })),
            borders: Some(std::sync::Arc::new(GroupSignal {
                group: 7,
                positions_um: vec![2.5],
                channels: vec![vec![3.25]; 8],
                groove_speed_mm_s: 939.3,
            })),
            slopes: vec![(WallSide::Left, 0.38), (WallSide::Right, 0.41)],
            load_secs: 0.01,
            stage_secs: vec![0.5; Stage::ALL.len()],
        }
    }

    #[test]
    fn records_round_trip_with_exact_bits() {
        let o = outcome();
        let Record::Group(back) = decode(&encode(&Record::Group(o.clone()))).unwrap() else {
            panic!("not a group record");
        };
        assert_eq!(back.report, o.report);
        assert_eq!(back.slopes, o.slopes);
        let (a, b) = (back.signal.clone().unwrap(), o.signal.clone().unwrap());
        assert_eq!(a.positions_um, b.positions_um);
        assert_eq!(a.channels[0][0].to_bits(), b.channels[0][0].to_bits());
        assert_eq!(a.channels[0][1], b.channels[0][1]);
        assert_eq!(back.borders, o.borders);
        // A record written before the pixel noise (no field after the borders) reads back with
        // none, its borders kept.
        let mut old = encode(&Record::Group(o.clone()));
        old.truncate(old.len() - 9);
        let Record::Group(back) = decode(&old).unwrap() else {
            panic!("not a group record");
        };
        let report = back.report.unwrap();
        assert_eq!(report.pixel_noise_grey_levels, None);
        assert_eq!(report.warning, o.report.as_ref().unwrap().warning);
        assert_eq!(back.borders, o.borders);
        // One written before the edge stage (no border field either) reads back with neither.
        let mut old = encode(&Record::Group(GroupOutcome {
            borders: None,
            report: o.report.clone().map(|r| GroupReport {
                pixel_noise_grey_levels: None,
                ..r
            }),
            ..o.clone()
        }));
        assert_eq!(old.pop(), Some(0));
        assert_eq!(old.pop(), Some(0));
        let Record::Group(back) = decode(&old).unwrap() else {
            panic!("not a group record");
        };
        assert!(back.borders.is_none() && back.signal.is_some());
        assert_eq!(back.report.unwrap().pixel_noise_grey_levels, None);
        let seed = vec![(WallSide::Right, vec![0.3, 0.31])];
        let Record::Seed(s) = decode(&encode(&Record::Seed(seed.clone()))).unwrap() else {
            panic!("not a seed");
        };
        assert_eq!(s, seed);
    }

    #[test]
    fn a_torn_or_damaged_tail_ends_the_frames() {
        let mut file = Vec::new();
        for _ in 0..3 {
            write_frame(&mut file, &encode(&Record::Group(outcome()))).unwrap();
        }
        assert_eq!(read_frames(&file, 0).len(), 3);
        assert_eq!(read_frames(&file[..file.len() - 1], 0).len(), 2);
        let mut damaged = file.clone();
        let mid = damaged.len() / 2;
        damaged[mid] ^= 0x40;
        assert_eq!(read_frames(&damaged, 0).len(), 1);
        // Records that read follow the damaged one: the next starts where the third frame does.
        let third = read_frames(&file, 0)[1].1;
        assert_eq!(
            next_record(&damaged, read_frames(&damaged, 0)[0].1 + 1),
            Some(third)
        );
        // A torn tail has none after it, nor do zeros past it (which no longer read as frames).
        let mut torn = file[..file.len() - 7].to_vec();
        assert_eq!(next_record(&torn, third + 1), None);
        torn.extend_from_slice(&[0; 64]);
        assert_eq!(read_frames(&torn, 0).len(), 2);
        assert_eq!(next_record(&torn, third + 1), None);
        assert!(decode(&[TAG_GROUP, 1, 2]).is_err());
        assert!(decode(&[99]).is_err());
    }
}
