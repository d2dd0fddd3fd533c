#!/usr/bin/env python3
"""Independent reference decoder for Hesai Pandar40P, Pandar64, PandarXT32, PandarXT16 and
PandarQT128 captures: the project's own re-implementation of tier4/nebula's decode path (read
from nebula @606ac41f, written from scratch; see /work/research/hesai-models.md on the lead's
machine and docs/sensors.md). Tests use it to judge pandarcapd's frames without nebula's
reference clouds, which are not in the repository.

Checked once by hand against nebula's five reference PCDs: same point count, same order, every
point within 1 µm (figures in docs/sensors.md). To stay that close it emulates nebula's float32
arithmetic where a value is stored as float (angles, distances, x y z, range limits): the range
limits and the cut's tie rule decide on those float values.

Pure Python 3 standard library (CI machines have no numpy).

    python3 hesai_reference.py CAPTURE.pcap CALIBRATION.csv --min-range 0.3 --max-range 200
prints the frames nebula would emit (points, packets) and the decode time.
"""

import argparse
from array import array
import calendar
import json
import math
import struct
import sys
import time

_F32 = struct.Struct("<f")


def f32(x):
    """x rounded to the nearest float32, as C++ does when it stores a double into a float."""
    return _F32.unpack(_F32.pack(x))[0]


TWO_PI_F = f32(2.0 * math.pi)
DEG_TO_RAD_F = f32(math.pi / 180.0)  # nebula's deg2rad<float>: the factor is a float too


class ReferenceError(Exception):
    """Bad input: an unreadable capture or calibration, no packet of a known model."""


# ---------------------------------------------------------------------------------------------
# Capture files: classic pcap only, UDP payloads out.
# ---------------------------------------------------------------------------------------------

_LINK_ETHERNET = 1
_LINK_RAW = 101
_LINK_LINUX_SLL = 113
_LINK_LINUX_SLL2 = 276
_LINK_NULL = 0


def _ip_payload_offset(link_type, frame):
    """Offset of the IP header in a record of this link type, or None if it holds no IP."""
    if link_type == _LINK_ETHERNET:
        off = 14
        if len(frame) < 14:
            return None
        ethertype = struct.unpack_from(">H", frame, 12)[0]
        while ethertype in (0x8100, 0x88A8):  # VLAN tags (802.1Q, QinQ)
            if len(frame) < off + 4:
                return None
            ethertype = struct.unpack_from(">H", frame, off + 2)[0]
            off += 4
        return off if ethertype in (0x0800, 0x86DD) else None
    if link_type == _LINK_LINUX_SLL:  # 16-byte cooked header, protocol at 14
        if len(frame) < 16:
            return None
        return 16 if struct.unpack_from(">H", frame, 14)[0] in (0x0800, 0x86DD) else None
    if link_type == _LINK_LINUX_SLL2:  # 20-byte cooked header, protocol at 0
        if len(frame) < 20:
            return None
        return 20 if struct.unpack_from(">H", frame, 0)[0] in (0x0800, 0x86DD) else None
    if link_type == _LINK_RAW:
        return 0
    if link_type == _LINK_NULL:  # 4-byte address family in host order
        return 4 if len(frame) >= 4 else None
    raise ReferenceError("unsupported pcap link type %d (supported: Ethernet 1, Linux SLL 113, "
                         "SLL2 276, raw IP 101, null 0)" % link_type)


def _udp_payload(frame, ip_off, port):
    """The UDP payload of the datagram at frame[ip_off:], or None (not UDP, a fragment,
    truncated, or another destination port than port when port is set)."""
    if len(frame) < ip_off + 1:
        return None
    version = frame[ip_off] >> 4
    if version == 4:
        if len(frame) < ip_off + 20:
            return None
        ihl = (frame[ip_off] & 0x0F) * 4
        total = struct.unpack_from(">H", frame, ip_off + 2)[0]
        flags_frag = struct.unpack_from(">H", frame, ip_off + 6)[0]
        if frame[ip_off + 9] != 17 or (flags_frag & 0x3FFF) != 0:  # not UDP, or a fragment
            return None
        udp = ip_off + ihl
        end = min(len(frame), ip_off + total)
    elif version == 6:
        if len(frame) < ip_off + 40 or frame[ip_off + 6] != 17:  # no extension headers
            return None
        udp = ip_off + 40
        end = min(len(frame), udp + struct.unpack_from(">H", frame, ip_off + 4)[0])
    else:
        return None
    if end < udp + 8:
        return None
    dst_port, udp_len = struct.unpack_from(">HH", frame, udp + 2)
    if port is not None and dst_port != port:
        return None
    if udp_len < 8 or udp + udp_len > end:
        return None  # truncated record: the payload is not whole
    return bytes(frame[udp + 8:udp + udp_len])


def read_pcap_payloads(path, port=None):
    """Every UDP payload of a classic pcap file, in record order, with its record time (ns)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise ReferenceError("%s: %s" % (path, e.strerror))
    if len(data) < 24:
        raise ReferenceError("%s: too short for a pcap file header" % path)
    magic = data[:4]
    formats = {b"\xd4\xc3\xb2\xa1": ("<", 1000), b"\xa1\xb2\xc3\xd4": (">", 1000),
               b"\x4d\x3c\xb2\xa1": ("<", 1), b"\xa1\xb2\x3c\x4d": (">", 1)}
    if magic == b"\x0a\x0d\x0d\x0a":
        raise ReferenceError("%s: pcapng is not supported; convert it with "
                             "'editcap -F pcap IN OUT'" % path)
    if magic not in formats:
        raise ReferenceError("%s: not a pcap file (magic %s)" % (path, magic.hex()))
    endian, sub_to_ns = formats[magic]
    link_type = struct.unpack_from(endian + "I", data, 20)[0] & 0x0FFFFFFF
    record = struct.Struct(endian + "IIII")
    payloads, off, skipped = [], 24, 0
    view = memoryview(data)
    while off + 16 <= len(data):
        sec, sub, incl, _orig = record.unpack_from(data, off)
        off += 16
        if off + incl > len(data):
            raise ReferenceError("%s: record at byte %d is cut short" % (path, off - 16))
        frame = view[off:off + incl]
        off += incl
        ip_off = _ip_payload_offset(link_type, frame)
        payload = None if ip_off is None else _udp_payload(frame, ip_off, port)
        if payload is None:
            skipped += 1
            continue
        payloads.append((sec * 1_000_000_000 + sub * sub_to_ns, payload))
    return payloads, skipped


# ---------------------------------------------------------------------------------------------
# Models: where the bytes are (hesai-models.md §2), nebula's built-in range limits (§5.3).
# ---------------------------------------------------------------------------------------------


class Model:
    def __init__(self, name, channels, blocks, unit_bytes, body, block_header, azimuth_at,
                 return_mode_at, date_at, micros_at, min_size, limits, fixed_unit_m=None):
        self.name = name
        self.channels = channels
        self.blocks = blocks
        self.unit_bytes = unit_bytes
        self.body = body  # offset of block 0
        self.block_header = block_header  # bytes before the channel units in a block
        self.azimuth_at = azimuth_at  # offset of the azimuth in a block
        self.block_bytes = block_header + channels * unit_bytes
        self.return_mode_at = return_mode_at
        self.date_at = date_at
        self.micros_at = micros_at
        self.min_size = min_size  # nebula's sizeof(packet): anything shorter it refuses
        # nebula's sensor class limits are float constants; it compares the float distance with them
        self.sensor_min_m, self.sensor_max_m = f32(limits[0]), f32(limits[1])
        self.fixed_unit_m = fixed_unit_m
        # One block's units as (distance, reflectivity[, confidence]) in one unpack.
        per_unit = "HB" if unit_bytes == 3 else "HBx"
        self.units = struct.Struct("<" + per_unit * channels)

    def distance_unit_m(self, p):
        # The 40P's unit is fixed at 4 mm; the others say it in millimetres in a header byte
        # (64: byte 5; XT, QT: byte 9). nebula divides by 1000.0 (double).
        if self.fixed_unit_m is not None:
            return self.fixed_unit_m
        return p[5 if self.name == "pandar64" else 9] / 1000.0

    def packet_time_ns(self, p):
        # Not used for x y z; only to say when a frame is. Year rule of Hesai's SDK (raw < 70:
        # 2000+raw, else 1900+raw): right for every model here, where nebula's 64 says 2120.
        y, mo, d, h, mi, s = p[self.date_at:self.date_at + 6]
        year = 2000 + y if y < 70 else 1900 + y
        try:
            secs = calendar.timegm((year, mo, d, h, mi, s, 0, 0, 0))
        except (ValueError, OverflowError):
            secs = 0
        return secs * 1_000_000_000 + struct.unpack_from("<I", p, self.micros_at)[0] * 1000


MODELS = {
    "pandar40p": Model("pandar40p", 40, 10, 3, 0, 4, 2, 1254, 1256, 1250, 1262, (0.3, 200.0),
                       fixed_unit_m=4 / 1000.0),
    "pandar64": Model("pandar64", 64, 6, 3, 8, 2, 0, 1186, 1188, 1182, 1194, (0.3, 200.0)),
    "pandarxt32": Model("pandarxt32", 32, 8, 4, 12, 2, 0, 1062, 1065, 1071, 1080, (0.05, 120.0)),
    "pandarxt16": Model("pandarxt16", 16, 8, 4, 12, 2, 0, 550, 553, 559, 568, (0.05, 120.0)),
    # QT128: nebula's packet struct has 4-byte units, the functional-safety block and the UDP
    # sequence (flags 0x15 at least); 0.05-50 m is its own limit, tighter than the test's 300 m.
    "pandarqt128": Model("pandarqt128", 128, 2, 4, 12, 2, 0, 1073, 1076, 1082, 1095,
                         (0.05, 50.0)),
}

# Returns per firing for each return-mode byte (hesai-models.md §2.6); nebula throws on others.
RETURNS = {0x33: 1, 0x34: 1, 0x37: 1, 0x38: 1, 0x39: 2, 0x3A: 2, 0x3B: 2, 0x3C: 2, 0x3E: 2,
           0x3D: 3}


def detect_model(p):
    """The model a payload is from, as hesai-models.md §1 says, or None. The 40P and 64 by
    length first (the 64's bytes 2-3 are 40 06, its laser and block counts, not a version);
    the others by the pre-header's protocol version and laser/block counts."""
    n = len(p)
    if n in (1262, 1266) and p[0:2] == b"\xff\xee":
        return "pandar40p"
    if n in (1194, 1198) and p[0:4] == b"\xee\xff\x40\x06":
        return "pandar64"
    if n < 12 or p[0:2] != b"\xee\xff":
        return None
    version, lasers, blocks = (p[2], p[3]), p[6], p[7]
    if version == (6, 1) and blocks == 8 and lasers == 32 and n >= 1080:
        return "pandarxt32"
    if version == (6, 1) and blocks == 8 and lasers == 16 and n >= 568:
        return "pandarxt16"
    # nebula's QT128 layout needs confidence bytes (0x10), functional safety (0x04) and the
    # UDP sequence (0x01); another flag set would move the tail.
    if version == (3, 2) and blocks == 2 and lasers == 128 and n >= 1095 \
            and (p[11] & 0x15) == 0x15:
        return "pandarqt128"
    return None


# ---------------------------------------------------------------------------------------------
# Calibration and angles (hesai-models.md §4).
# ---------------------------------------------------------------------------------------------


class Calibration:
    """nebula's CSV reading: split on ',', drop empty tokens, use lines of exactly 3 tokens
    whose first is an integer (so the header line is skipped); channel = id - 1; elevation and
    azimuth offset stored as float."""

    def __init__(self, path, channels):
        elevation, azimuth = {}, {}
        try:
            with open(path, encoding="utf-8") as f:
                lines = f.read().splitlines()
        except (OSError, UnicodeDecodeError) as e:
            raise ReferenceError("%s: %s" % (path, e))
        for line in lines:
            tokens = [t for t in line.split(",") if t != ""]
            if len(tokens) != 3:
                continue
            try:
                laser = int(tokens[0])
                elevation[laser - 1] = f32(float(tokens[1]))
                azimuth[laser - 1] = f32(float(tokens[2]))
            except ValueError:
                continue
        missing = [c + 1 for c in range(channels) if c not in elevation]
        if missing or len(elevation) != channels:
            raise ReferenceError("%s: expected %d channels, found %d" %
                                 (path, channels, len(elevation)))
        self.channels = channels
        elevation_rad = [f32(elevation[c] * DEG_TO_RAD_F) for c in range(channels)]
        self.azimuth_rad = [f32(azimuth[c] * DEG_TO_RAD_F) for c in range(channels)]
        self.cos_elevation = [f32(math.cos(e)) for e in elevation_rad]
        self.sin_elevation = [f32(math.sin(e)) for e in elevation_rad]
        # nebula's cutter watches the channels with the smallest and largest azimuth offset.
        self.min_channel = min(range(channels), key=lambda c: self.azimuth_rad[c])
        self.max_channel = max(range(channels), key=lambda c: self.azimuth_rad[c])
        self._block_rad = {}
        self._sin_cos = {}
        self._corrected = {}

    def block_rad(self, azimuth_cdeg):
        # nebula's table: the block angle in double, stored as float.
        r = self._block_rad.get(azimuth_cdeg)
        if r is None:
            r = self._block_rad[azimuth_cdeg] = f32(azimuth_cdeg / 100.0 * (math.pi / 180.0))
        return r

    def corrected_azimuths(self, azimuth_cdeg):
        """Each channel's azimuth in [0, 2pi) as float: what the cutter compares with the cut."""
        out = self._corrected.get(azimuth_cdeg)
        if out is None:
            b = self.block_rad(azimuth_cdeg)
            sums = array("f", [b + o for o in self.azimuth_rad]).tolist()
            out = self._corrected[azimuth_cdeg] = array(
                "f", [a - math.floor(a / TWO_PI_F) * TWO_PI_F for a in sums]).tolist()
        return out

    def sin_cos(self, azimuth_cdeg):
        """sin and cos of every channel's azimuth for a block azimuth (nebula: sinf/cosf of the
        float sum; here double then rounded, which differs from glibc by an ULP at most)."""
        sc = self._sin_cos.get(azimuth_cdeg)
        if sc is None:
            b = self.block_rad(azimuth_cdeg)
            sums = array("f", [b + o for o in self.azimuth_rad]).tolist()
            sc = self._sin_cos[azimuth_cdeg] = (array("f", map(math.sin, sums)).tolist(),
                                                array("f", map(math.cos, sums)).tolist())
        return sc


# ---------------------------------------------------------------------------------------------
# nebula's scan cutter at a cut angle, with the full 360-degree field of view (hesai-models.md
# §5.2). Each channel has a buffer index 0 or 1 and toggles it when its corrected azimuth passes
# the cut; a frame is emitted when the last channel has crossed.
# ---------------------------------------------------------------------------------------------


def _between(start, end, a, start_inclusive=True, end_inclusive=True):
    """nebula's angle_is_between on [0, 2pi) angles, wrap-around included. start == end is the
    full circle."""
    if start == end:
        return True if start != a else (start_inclusive or end_inclusive)
    if not start_inclusive and a == start:
        return False
    if not end_inclusive and a == end:
        return False
    if end < start:
        return a <= end or start <= a
    return start <= a <= end


def _normalize(a):
    return f32(a - math.floor(a / TWO_PI_F) * TWO_PI_F)


class Cutter:
    def __init__(self, cut_rad, min_channel, max_channel):
        self.cut = _normalize(f32(cut_rad))
        self.half_after = _normalize(f32(self.cut + f32(TWO_PI_F / 2)))
        self.min_channel, self.max_channel = min_channel, max_channel
        self.buffer_of = None  # per channel
        self.last = None
        self.current = 0  # the buffer being completed (emitted next)
        self.state = None

    def _after_cut(self, a):
        return _between(self.cut, self.half_after, a, False, True)

    def _state_name(self):
        b0, b1 = self.buffer_of[self.min_channel], self.buffer_of[self.max_channel]
        if b0 == b1:
            return "F%d" % b0  # every channel in buffer b0
        return "C01" if self.current == 0 else "C10"  # split, moving from current to the other

    # Transitions of nebula's cut-in-FoV machine: (reset this buffer's time, emit this buffer).
    _ACTIONS = {("F0", "C01"): (1, None), ("F0", "F1"): (1, 0), ("C01", "F1"): (None, 0),
                ("F1", "C10"): (0, None), ("F1", "F0"): (0, 1), ("C10", "F0"): (None, 1)}

    def step(self, azimuths):
        """Feeds one block group's corrected azimuths. Returns (buffers whose frame starts here,
        buffer to emit or None); the emit happens before this group's points are added."""
        if self.buffer_of is None:
            n = len(azimuths)
            quarter = f32(TWO_PI_F / 4)
            lo, hi = _normalize(f32(self.cut - quarter)), _normalize(f32(self.cut + quarter))
            ends = (azimuths[self.min_channel], azimuths[self.max_channel])
            straddles = all(_between(lo, hi, a) for a in ends) and \
                sum(1 for a in ends if self._after_cut(a)) == 1
            if straddles:
                self.buffer_of = [1 if self._after_cut(a) else 0 for a in azimuths]
            else:
                self.buffer_of = [0] * n
            self.last = list(azimuths)
            self.state = self._state_name()
            return sorted(set(self.buffer_of)), None
        for c, a in enumerate(azimuths):
            # last <= cut < current: a point exactly at the cut stays in the old frame.
            if _between(self.last[c], a, self.cut, True, False):
                self.buffer_of[c] ^= 1
            self.last[c] = a
        before, self.state = self.state, self._state_name()
        if before == self.state:
            return [], None
        if {before, self.state} == {"C01", "C10"}:
            raise ReferenceError("cutter: impossible transition %s -> %s" % (before, self.state))
        reset, emit = self._ACTIONS.get((before, self.state), (None, None))
        if emit is not None:
            self.current ^= 1
        return ([] if reset is None else [reset]), emit


# ---------------------------------------------------------------------------------------------
# The decoder.
# ---------------------------------------------------------------------------------------------


class Frame:
    def __init__(self):
        self.points = []  # (x, y, z) float32 values, nebula's order
        self.first_packet = None  # index (among the model's packets) of the first with a point
        self.last_packet = None
        self.time_ns = None  # packet time of the packet where the frame's time was set
        self.emitted_at = None  # packet index being decoded when the frame was emitted
        self.number = None  # 1-based emission order from the first decoded packet


class Decoder:
    def __init__(self, model, calibration, min_range_m, max_range_m, dual_threshold_m=0.1,
                 cut_deg=0.0):
        self.m = MODELS[model]
        self.cal = calibration
        # The test hands nebula float literals (0.3F): compare against those float values.
        self.min_range = max(self.m.sensor_min_m, f32(min_range_m))
        self.max_range = min(self.m.sensor_max_m, f32(max_range_m))
        self.threshold = dual_threshold_m
        self.cutter = Cutter(cut_deg * math.pi / 180.0, calibration.min_channel,
                             calibration.max_channel)
        self.buffers = [Frame(), Frame()]
        self.frames = []
        self.rejected = 0
        self._distance_tables = {}

    def feed(self, index, p):
        """Decodes one packet (index: its position among the model's packets). A packet nebula
        would misread (too short, unknown return mode, azimuth >= 360 deg) is counted, skipped."""
        m = self.m
        if len(p) < m.min_size or p[m.return_mode_at] not in RETURNS:
            self.rejected += 1
            return
        n = RETURNS[p[m.return_mode_at]]
        azimuths = [struct.unpack_from("<H", p, m.body + b * m.block_bytes + m.azimuth_at)[0]
                    for b in range(0, m.blocks, n)]
        if any(a >= 36000 for a in azimuths) or m.blocks % n:
            self.rejected += 1
            return
        unit = m.distance_unit_m(p)
        for g, b0 in enumerate(range(0, m.blocks, n)):
            resets, emit = self.cutter.step(self.cal.corrected_azimuths(azimuths[g]))
            if emit is not None:
                frame = self.buffers[emit]
                frame.emitted_at = index
                frame.number = len(self.frames) + 1
                self.frames.append(frame)
                self.buffers[emit] = Frame()
            for r in resets:
                self.buffers[r].time_ns = m.packet_time_ns(p)
            self._convert(index, p, b0, n, azimuths[g], unit)

    def _distances(self, unit):
        # raw x unit in double, stored as float: one table per unit, filled as raws appear.
        table = self._distance_tables.get(unit)
        if table is None:
            table = self._distance_tables[unit] = {}
        return table

    def _convert(self, index, p, b0, n, azimuth_cdeg, unit):
        m, cal = self.m, self.cal
        blocks = [m.units.unpack_from(p, m.body + (b0 + k) * m.block_bytes + m.block_header)
                  for k in range(n)]
        table = self._distances(unit)
        lo, hi, thr = self.min_range, self.max_range, self.threshold
        last = n - 1
        kept_c, kept_d = [], []
        for c in range(m.channels):
            units = [(blk[2 * c], blk[2 * c + 1]) for blk in blocks]
            dists = []
            for raw, _ in units:
                d = table.get(raw)
                if d is None:
                    d = table[raw] = f32(raw * unit)
                dists.append(d)
            for k in range(n):
                d = dists[k]
                if units[k][0] == 0 or d < lo or hi < d:
                    continue
                if k != last:
                    # Dual rules (§5.4): of byte-identical returns only the group's last is
                    # kept; an earlier return within the threshold of another one (even a
                    # zero or out-of-range one) is dropped. Strict <, float difference.
                    if any(units[i] == units[k] for i in range(n) if i != k):
                        continue
                    if any(abs(f32(dists[i] - d)) < thr for i in range(n) if i != k):
                        continue
                kept_c.append(c)
                kept_d.append(d)
        if not kept_c:
            return
        # x = (d cos w) sin a, y = (d cos w) cos a, z = d sin w, each product stored as float
        # (array('f') rounds a whole list to float32 at once).
        sin_a, cos_a = cal.sin_cos(azimuth_cdeg)
        cos_e, sin_e = cal.cos_elevation, cal.sin_elevation
        xy = array("f", [d * cos_e[c] for c, d in zip(kept_c, kept_d)]).tolist()
        xs = array("f", [v * sin_a[c] for c, v in zip(kept_c, xy)]).tolist()
        ys = array("f", [v * cos_a[c] for c, v in zip(kept_c, xy)]).tolist()
        zs = array("f", [d * sin_e[c] for c, d in zip(kept_c, kept_d)]).tolist()
        buffer_of = self.cutter.buffer_of
        for c, x, y, z in zip(kept_c, xs, ys, zs):
            frame = self.buffers[buffer_of[c]]
            frame.points.append((x, y, z))
            if frame.first_packet is None:
                frame.first_packet = index
            frame.last_packet = index


def start_for_last_frame(model, payloads, revolutions=2.0, margin_deg=30.0):
    """Index of the packet to start decoding at so that the last frame nebula emits is whole:
    the last emitted frame can span from up to ~2 revolutions before the end (the capture may
    end just before a crossing), plus the channels' azimuth offsets (QT128: +-10 deg). Walks
    back from the end adding the block-0 azimuth steps."""
    m = MODELS[model]
    need = revolutions * 36000 + margin_deg * 100
    total, i = 0, len(payloads) - 1
    prev = None
    while i >= 0:
        p = payloads[i]
        if len(p) >= m.min_size:
            a = struct.unpack_from("<H", p, m.body + m.azimuth_at)[0]
            if prev is not None:
                total += (prev - a) % 36000
                if total >= need:
                    return i
            prev = a
        i -= 1
    return 0


def decode_capture(capture, calibration_path, min_range_m, max_range_m, start="auto",
                   dual_threshold_m=0.1, cut_deg=0.0, port=None):
    """Decodes a capture as nebula would. start: a packet index (among the model's packets),
    or "auto" (enough for the last complete frame), or 0 for all. Returns a dict."""
    t0 = time.monotonic()
    records, skipped = read_pcap_payloads(capture, port)
    model = None
    for _, p in records:
        model = detect_model(p)
        if model:
            break
    if model is None:
        raise ReferenceError("%s: no packet of a supported Hesai model (%d UDP payloads)" %
                             (capture, len(records)))
    payloads = [p for _, p in records if detect_model(p) == model]
    calibration = Calibration(calibration_path, MODELS[model].channels)
    first = start_for_last_frame(model, payloads) if start == "auto" else int(start)
    decoder = Decoder(model, calibration, min_range_m, max_range_m, dual_threshold_m, cut_deg)
    for i in range(first, len(payloads)):
        decoder.feed(i, payloads[i])
    return {"model": model, "frames": decoder.frames, "start_packet": first,
            "packets": len(payloads), "other_payloads": len(records) - len(payloads) + skipped,
            "rejected": decoder.rejected, "open_points": [len(b.points) for b in decoder.buffers],
            "seconds": time.monotonic() - t0}


def pick_frame(result, which):
    """The frame a test compares: "last" = the last frame emitted (the first emitted after the
    decode start is partial, so at least two must have been); N = the N-th emitted (1-based,
    counted from the decode start: decode from packet 0 for that)."""
    frames = result["frames"]
    if which == "last":
        if len(frames) < 2:
            raise ReferenceError("fewer than two frames emitted: no complete frame")
        return frames[-1]
    n = int(which)
    if not 1 <= n <= len(frames):
        raise ReferenceError("frame %d asked, %d emitted" % (n, len(frames)))
    return frames[n - 1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture")
    ap.add_argument("calibration")
    ap.add_argument("--min-range", type=float, required=True)
    ap.add_argument("--max-range", type=float, required=True)
    ap.add_argument("--dual-threshold", type=float, default=0.1)
    ap.add_argument("--start", default="0", help="packet index to start at, or 'auto'")
    ap.add_argument("--write-pcd", metavar="FILE", help="write the last (or --frame) frame")
    ap.add_argument("--frame", default="last")
    a = ap.parse_args(argv)
    try:
        r = decode_capture(a.capture, a.calibration, a.min_range, a.max_range, a.start,
                           a.dual_threshold)
        out = {"model": r["model"], "packets": r["packets"], "start_packet": r["start_packet"],
               "rejected": r["rejected"], "seconds": round(r["seconds"], 3),
               "frames": [{"number": f.number, "points": len(f.points),
                           "packets": [f.first_packet, f.last_packet],
                           "emitted_at": f.emitted_at} for f in r["frames"]],
               "open_points": r["open_points"]}
        if a.write_pcd:
            f = pick_frame(r, a.frame)
            with open(a.write_pcd, "wb") as o:
                o.write(("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
                         "COUNT 1 1 1\nWIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
                         "POINTS %d\nDATA binary\n" % (len(f.points), len(f.points))).encode())
                o.write(b"".join(struct.pack("<fff", *pt) for pt in f.points))
    except ReferenceError as e:
        print("hesai_reference: %s" % e, file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
