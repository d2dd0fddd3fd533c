#!/usr/bin/env python3
"""Self-test of compare_frames.py: it fails when it should. On the reference decoder's last
40P frame (nebula's reference frame: 56 762 points): a cloud shifted 6 mm fails and 3 mm passes;
2 % of the points removed, or 2 % added, fails at 0.99 and passes at 0.97; 2 % duplicated
fails only one-to-one; every PCD encoding
(ascii, binary with other fields around x y z, binary_compressed) reads the same points; among
several files the right one is picked; and the exit codes 0, 1 and 2.

    python3 tests/reference/test_compare_frames.py      (CTest: reference_compare_frames)

Pure Python 3 standard library. The capture is decoded once (the reference decode memoised).
"""

import contextlib
import io
import json
import os
import random
import struct
import subprocess
import sys
import tempfile
from array import array

HERE = os.path.dirname(os.path.abspath(__file__))
# No __pycache__ in the source tree (it may be read-only; git status stays clean).
sys.dont_write_bytecode = True
sys.path.insert(0, HERE)
import compare_frames as cf  # noqa: E402
import hesai_reference as ref  # noqa: E402

CAPTURES = os.path.normpath(os.path.join(HERE, "..", "..", "..", "shared", "captures"))
CAPTURE = os.path.join(CAPTURES, "pandar40p_nebula_dual_600rpm_1262B.pcap")
CALIBRATION = os.path.join(CAPTURES, "nebula_Pandar40P_calibration.csv")
# nebula's reference cloud for this capture (tier4/nebula decoder_ground_truth/40p/
# 1673400149711850138.pcd) holds 56 762 points; the reference decoder reproduced it to 0.48 µm.
NEBULA_40P_POINTS = 56762

failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def write_pcd(path, points, kind="binary", fields=("x", "y", "z")):
    """A PCD of points in the given encoding. Fields other than x y z are filled with a
    pattern (they must be skipped by the reader); 'i' is F4, 'ring' U2, 't' F8."""
    spec = {"x": ("F", 4, "f"), "y": ("F", 4, "f"), "z": ("F", 4, "f"), "i": ("F", 4, "f"),
            "ring": ("U", 2, "H"), "t": ("F", 8, "d")}
    n = len(points)
    head = ("# .PCD v0.7 - Point Cloud Data file format\n# a comment line\nVERSION 0.7\n"
            "FIELDS %s\nSIZE %s\nTYPE %s\nCOUNT %s\nWIDTH %d\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA %s\n" %
            (" ".join(fields), " ".join(str(spec[f][1]) for f in fields),
             " ".join(spec[f][0] for f in fields), " ".join("1" for _ in fields), n, n, kind))

    def value(f, i, p):
        return p["xyz".index(f)] if f in "xyz" else (i % 300 if f == "ring" else i * 0.5)

    if kind == "ascii":
        body = "".join(" ".join(repr(value(f, i, p)) for f in fields) + "\n"
                       for i, p in enumerate(points)).encode()
    elif kind == "binary":
        st = struct.Struct("<" + "".join(spec[f][2] for f in fields))
        body = b"".join(st.pack(*(value(f, i, p) for f in fields)) for i, p in enumerate(points))
    else:  # binary_compressed: field after field, LZF of literal runs (valid LZF)
        raw = b"".join(array(spec[f][2], [value(f, i, p) for i, p in enumerate(points)]).tobytes()
                       for f in fields)
        packed = b"".join(bytes([len(raw[k:k + 32]) - 1]) + raw[k:k + 32]
                          for k in range(0, len(raw), 32))
        body = struct.pack("<II", len(packed), len(raw)) + packed
    with open(path, "wb") as f:
        f.write(head.encode() + body)


def shifted(points, dx, dy=0.0, dz=0.0):
    return [(x + dx, y + dy, z + dz) for x, y, z in points]


def run_main(args):
    """compare_frames.main in-process: (exit code, parsed JSON line or None)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        try:
            code = cf.main(args)
        except SystemExit as e:  # argparse usage errors
            code = e.code
    text = out.getvalue().strip()
    return code, (json.loads(text) if text else None)


def main():
    # Decode once; main() below then reuses it (same function, same arguments).
    memo = {}
    real_decode = ref.decode_capture

    def decode_once(*a, **k):
        key = repr((a, sorted(k.items())))
        if key not in memo:
            memo[key] = real_decode(*a, **k)
        return memo[key]

    ref.decode_capture = decode_once
    result = ref.decode_capture(CAPTURE, CALIBRATION, 0.3, 200.0, "auto", 0.1)  # as the CLI
    frame = ref.pick_frame(result, "last")
    reference = frame.points
    check(result["model"] == "pandar40p", "the capture's model is detected: %s" % result["model"])
    check(len(reference) == NEBULA_40P_POINTS,
          "last complete frame has nebula's %d points: %d" % (NEBULA_40P_POINTS, len(reference)))

    # Fractions on a subset (every 4th point: a fifth of the time, the same geometry).
    sub = reference[::4]
    tol = 0.005
    f_ours, f_ref, worst = cf.compare_points(sub, list(sub), tol)
    check(f_ours == 1.0 and f_ref == 1.0 and worst == 0.0, "identical cloud: 1.0 / 1.0, 0 m")
    for d, should_pass in ((0.006, False), (0.003, True), (0.0049, True), (0.0051, False)):
        f_ours, f_ref, worst = cf.compare_points(sub, shifted(sub, d), tol)
        passed = f_ours >= 0.99 and f_ref >= 0.99
        check(passed == should_pass, "shift %.1f mm along x: %s (fractions %.4f / %.4f, max %.4f m)"
              % (d * 1000, "passes" if passed else "fails", f_ours, f_ref, worst))
    d = 0.006 / 3 ** 0.5  # 6 mm diagonally: no axis moves more than 3.5 mm
    f_ours, f_ref, _ = cf.compare_points(sub, shifted(sub, d, d, d), tol)
    check(f_ours < 0.99 and f_ref < 0.99, "shift 6 mm diagonally fails (%.4f / %.4f)"
          % (f_ours, f_ref))
    rng = random.Random(39)
    removed = [p for p in sub if rng.random() >= 0.02]
    f_ours, f_ref, _ = cf.compare_points(sub, removed, tol)
    check(f_ours == 1.0 and 0.975 < f_ref < 0.985 and not f_ref >= 0.99,
          "2 %% removed: ours %.4f, reference %.4f: fails at 0.99" % (f_ours, f_ref))
    check(f_ref >= 0.97, "2 % removed passes at 0.97")
    kept = [p for p in sub if rng.random() >= 0.005]
    _, f_ref, _ = cf.compare_points(sub, kept, tol)
    check(f_ref >= 0.99, "0.5 %% removed passes at 0.99 (%.4f)" % f_ref)
    extra = list(sub) + [(50.0 + rng.random(), 50.0 + rng.random(), rng.random())
                         for _ in range(len(sub) // 50)]
    f_ours, f_ref, _ = cf.compare_points(sub, extra, tol)
    check(f_ref == 1.0 and f_ours < 0.99, "2 %% extra points: ours %.4f fails" % f_ours)
    dup = list(sub) + sub[::50]  # 2 % of the points twice: nearest neighbours cannot see it
    f_ours, f_ref, _ = cf.compare_points(sub, dup, tol)
    pairs = cf.one_to_one(dup, sub, tol)
    check(f_ours == 1.0 and f_ref == 1.0 and pairs == len(sub) and pairs / len(dup) < 0.99,
          "2 %% duplicated: nearest neighbours 1.0 / 1.0, one-to-one %d pairs of %d fails"
          % (pairs, len(dup)))
    check(cf.one_to_one(sub, sub, tol) == len(sub) and
          cf.one_to_one(removed, sub, tol) == len(removed),
          "one-to-one pairs every point of an identical cloud, and of a thinned one")
    jitter = [(x + rng.uniform(-0.002, 0.002), y + rng.uniform(-0.002, 0.002),
               z + rng.uniform(-0.002, 0.002)) for x, y, z in sub]
    f_ours, f_ref, worst = cf.compare_points(sub, jitter, tol)
    check(f_ours == 1.0 and f_ref == 1.0 and worst < 0.0035,
          "+-2 mm jitter per axis passes (max %.4f m)" % worst)

    # LZF: a back reference that overlaps what it writes; corrupt input is an error.
    check(cf.lzf_decompress(b"\x02abc\xe0\x00\x02", 12) == b"abcabcabcabc",
          "LZF literal run + overlapping back reference")
    for bad in (b"\x05ab", b"\x20\x05", b"\xe0"):
        try:
            cf.lzf_decompress(bad, 8)
            check(False, "LZF rejects %r" % bad)
        except cf.InputError:
            check(True, "LZF rejects %r" % bad)

    with tempfile.TemporaryDirectory() as tmp:
        # Every encoding reads back the same points (float32 in the binary ones).
        f32 = [tuple(array("f", p)) for p in sub]
        for kind, fields in (("ascii", ("x", "y", "z")), ("binary", ("i", "y", "ring", "x", "z", "t")),
                             ("binary_compressed", ("x", "y", "z", "i", "ring", "t"))):
            path = os.path.join(tmp, "enc_%s.pcd" % kind)
            write_pcd(path, sub, kind, fields)
            back = cf.read_pcd_xyz(path)
            same = back == f32 if kind != "ascii" else \
                max(max(abs(a - b) for a, b in zip(p, q)) for p, q in zip(back, sub)) < 1e-9
            check(len(back) == len(sub) and same,
                  "PCD %s with fields %s reads back the same %d points" %
                  (kind, " ".join(fields), len(back)))
        bad = os.path.join(tmp, "bad.pcd")
        with open(bad, "wb") as f:
            f.write(b"VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\n"
                    b"POINTS 1\nDATA binary\n\0\0\0\0\0\0\0\0")
        try:
            cf.read_pcd_xyz(bad)
            check(False, "a PCD without z is an input error")
        except cf.InputError as e:
            check("no field z" in str(e), "a PCD without z is an input error: %s" % e)

        # The CLI on whole frames: the right file among decoys, exit 0; shifted, exit 1.
        good = os.path.join(tmp, "good")
        os.mkdir(good)
        write_pcd(os.path.join(good, "frame_1_partial.pcd"), reference[: len(reference) // 3])
        write_pcd(os.path.join(good, "frame_2.pcd"), shifted(reference, 0.5), "binary_compressed")
        write_pcd(os.path.join(good, "frame_3.pcd"), reference, "binary", ("x", "y", "z", "i"))
        args = ["--capture", CAPTURE, "--calibration", CALIBRATION, "--min-range", "0.3",
                "--max-range", "200", "--frames", good]
        code, line = run_main(args + ["--one-to-one"])
        check(code == 0 and line and line["fraction_reference_paired"] == 1.0 and line["our_file"].endswith("frame_3.pcd")
              and line["fraction_ours_matched"] == 1.0
              and line["fraction_reference_matched"] == 1.0,
              "CLI picks frame_3.pcd among decoys and passes: exit %s, %s" %
              (code, line and (line["our_file"], line["overlap_scores"])))
        moved = os.path.join(tmp, "moved")
        os.mkdir(moved)
        write_pcd(os.path.join(moved, "f.pcd"), shifted(reference, 0.0, 0.006))
        code, line = run_main(args[:-1] + [moved])
        check(code == 1 and line and line["pass"] is False,
              "CLI on a 6 mm shifted frame: exit %s (fractions %s / %s)" %
              (code, line and line["fraction_ours_matched"],
               line and line["fraction_reference_matched"]))
        code, _ = run_main(args[:-1] + [os.path.join(tmp, "missing")])
        check(code == 2, "CLI on a missing frames directory: exit %s" % code)
        code, _ = run_main(args[:-1] + [bad])
        check(code == 2, "CLI on a PCD without z: exit %s" % code)
        code, _ = run_main(["--capture", bad, "--calibration", CALIBRATION, "--min-range", "0.3",
                            "--max-range", "200", "--frames", good])
        check(code == 2, "CLI on a capture that is not a pcap: exit %s" % code)
    # The real entry point: a usage error exits 2.
    p = subprocess.run([sys.executable, os.path.join(HERE, "compare_frames.py"), "--frames"],
                       capture_output=True)
    check(p.returncode == 2, "usage error exits 2: %d" % p.returncode)

    print("%d failure(s)" % len(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
