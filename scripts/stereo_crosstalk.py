#!/usr/bin/env python3
"""Per-channel tone and crosstalk of a 2-channel WAV (docs/ACCURACY.md, stereo rows): 1 ms dropped
at each end, the peak of the Hann-windowed DTFT on a 10 Hz grid from 100 Hz to 10 kHz refined by
golden-section search, and the power at the other channel's peak relative to the power at the
channel's own. Usage: python3 scripts/stereo_crosstalk.py clip.wav [LEFT_HZ RIGHT_HZ]."""
import math, struct, sys

def read(path):
    data = open(path, 'rb').read()
    pos, fmt, chans = 12, None, None
    while pos + 8 <= len(data):
        cid = data[pos:pos+4]; size = struct.unpack('<I', data[pos+4:pos+8])[0]
        body = data[pos+8:pos+8+size]
        if cid == b'fmt ':
            tag, ch, rate, _, _, bits = struct.unpack('<HHIIHH', body[:16]); fmt = (tag, ch, rate, bits)
        elif cid == b'data':
            tag, ch, rate, bits = fmt
            if bits == 24:
                vals = []
                for i in range(0, len(body) - 2, 3):
                    v = body[i] | body[i+1] << 8 | body[i+2] << 16
                    vals.append((v - (1 << 24) if v & 0x800000 else v) / 8388608)
            elif bits == 16:
                vals = [v / 32768 for v in struct.unpack('<%dh' % (len(body)//2), body)]
            else:
                vals = list(struct.unpack('<%df' % (len(body)//4), body))
            chans = [vals[c::ch] for c in range(ch)]
        pos += 8 + size + (size & 1)
    return fmt[2], chans

def power(x, rate, f):
    n = len(x); re = im = 0.0
    for i, v in enumerate(x):
        w = 0.5 - 0.5 * math.cos(2 * math.pi * i / (n - 1))
        a = 2 * math.pi * f * i / rate
        re += w * v * math.cos(a); im -= w * v * math.sin(a)
    return re * re + im * im

def peak(x, rate):
    grid = [100 + 10 * k for k in range(int((10000 - 100) / 10) + 1)]
    best = max(grid, key=lambda f: power(x, rate, f))
    a, b = best - 10, best + 10
    g = (math.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    for _ in range(40):
        if power(x, rate, c) > power(x, rate, d): b = d
        else: a = c
        c, d = b - g * (b - a), a + g * (b - a)
    return (a + b) / 2

rate, (l, r) = read(sys.argv[1])
want_l, want_r = (float(sys.argv[2]), float(sys.argv[3])) if len(sys.argv) > 3 else (3000.0, 800.0)
cut = int(round(rate * 0.001))
l, r = l[cut:-cut], r[cut:-cut]
fl, fr = peak(l, rate), peak(r, rate)
xl = 10 * math.log10(power(l, rate, fr) / power(l, rate, fl))
xr = 10 * math.log10(power(r, rate, fl) / power(r, rate, fr))
print(f'left peak {fl:.1f} Hz ({(fl / want_l - 1) * 100:+.2f} %), '
      f'right peak {fr:.1f} Hz ({(fr / want_r - 1) * 100:+.2f} %), '
      f'into left {xl:.1f} dB, into right {xr:.1f} dB')
