#!/usr/bin/env python3
"""Check the bytes `mavstack encode` wrote for a JSON-lines file, with pymavlink as the oracle.

Usage:
  check_encode.py JSONL ACTUAL.bin --orig ORIG.bin [--dialect D] [--key HEX] [--link-id N]
  check_encode.py JSONL --self-check --orig ORIG.bin [--dialect D] [--key HEX]

JSONL is in mavstack's format (typically make_corpus.py's PREFIX.jsonl, i.e. pymavlink's
decoding of ORIG.bin); ACTUAL.bin is what `mavstack encode --dialect D [--key HEX] JSONL`
wrote. Pass --key exactly when it was given to `mavstack encode`.

For frame i (line i) the expected bytes are pymavlink's packing of JSON object i
(mavinterop.pack_json): its seq/sysid/compid, MAVLink 1 via pack(force_mavlink1=True),
MAVLink 2 truncated by pymavlink, and with --key signed with the object's signature link_id
and timestamp. Checks:

 (a) ACTUAL frame i == that packing, byte for byte. The packing is also compared with the
     original frame i of ORIG.bin (found by pymavlink's parser); it is identical except, by
     construction, for
       - MAVLink 1 frames that the C library style sent with base fields only: pymavlink (and
         so mavstack) sends the full payload, extensions included;
       - frames whose original signature was made with another key (status "invalid"):
         `encode --key` signs them correctly;
       - MAVLink 2 objects without "signature" encoded with --key: docs/contracts/json-lines.md says they are
         signed with --link-id (default 0) and the current time; the expected bytes then use
         the timestamp found in ACTUAL (which must be within a day of now and strictly
         increasing over those frames);
     any other disagreement between the packing and the original is a harness error (the JSON
     is not lossless) and is reported as such.
 (b) pymavlink accepts every frame of ACTUAL: good CRC, good signature when signed with --key,
     the whole file parses as exactly N frames with no garbage, and decoding each frame gives
     back the JSON object's header and fields (decode(encode(x)) == x, judged by pymavlink).

Differences say which frame (line, offset) and how: header fields, payload (which fields,
with values), CRC (and whether the CRC written is right for the bytes written), signature
(link_id, timestamp, signature bytes).

--self-check: no ACTUAL; pymavlink's own packing of JSONL is checked against ORIG.bin and (b)
is run on it. This proves the JSON lines are complete and lossless.

--v1-base-ok: also accept a MAVLink 1 frame whose payload stops after the base fields when
the extension bytes pymavlink would send are all zero (the C library's length).

Exit 0 if everything matches, 1 on any difference, 2 on bad usage or inputs that do not
belong together.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compare_decode as cd  # noqa: E402
import mavinterop as mi  # noqa: E402

UNIX_2015 = 1420070400


def now_ts():
    return int((time.time() - UNIX_2015) * 100000)


class Report:
    def __init__(self, limit):
        self.limit = limit
        self.shown = 0
        self.count = 0
        self.frames = set()

    def add(self, where, lines, frame=None):
        self.count += 1
        if frame is not None:
            self.frames.add(frame)
        if self.shown < self.limit:
            self.shown += 1
            print("%s:" % where)
            for line in lines:
                print("    " + line)


def load_jsonl(path):
    objs = []
    for n, o in cd.load_lines(path):
        if not isinstance(o, dict):
            mi.die("%s line %d: %s" % (path, n, o))
        objs.append(o)
    return objs


def read(path):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        mi.die("cannot read %s: %s" % (path, e))


def classify(mod, obj, expect, orig, key):
    """How pymavlink's packing of `obj` relates to the original frame; None if unexplained."""
    if expect == orig:
        return "identical"
    try:
        he, ho = mi.frame_header(expect), mi.frame_header(orig)
    except ValueError:
        return None
    if he["version"] == 1 and ho["version"] == 1:
        _, pe, _, _ = mi.frame_parts(expect)
        _, po, _, _ = mi.frame_parts(orig)
        cls = mod.mavlink_map.get(he["msgid"])
        if (cls is not None and len(po) == mi.layout(cls).base_len < len(pe) and pe[: len(po)] == po
                and not any(pe[len(po):]) and {k: v for k, v in he.items() if k != "len"}
                == {k: v for k, v in ho.items() if k != "len"}):
            return "c_style_v1"
    sig = obj.get("signature")
    if key is not None and sig and sig.get("status") in ("invalid", "unchecked") and len(expect) == len(orig) and expect[:-6] == orig[:-6]:
        return "resigned"
    if key is not None and he["version"] == 2 and not sig:
        return "stamped"
    if key is None and sig:
        return "unsigned_no_key"
    return None


def same_frame(obj, frame):
    """Whether a written frame carries the header of a JSON object (seq, ids, version)."""
    try:
        h = mi.frame_header(frame)
    except ValueError:
        return False
    return all(h[k] == obj.get(k, 2 if k == "version" else None) for k in ("version", "seq", "sysid", "compid", "msgid"))


def check_with_pymavlink(mod, frame, obj, key, where, rep, frame_no):
    """(b) for one frame: CRC, signature, and decode(frame) == obj."""
    mav = mi.new_parser(mod, key)
    try:
        m = mav.decode(bytearray(frame))
    except mod.MAVError as e:
        rep.add(where, ["pymavlink rejects the frame: %s" % e.message, "bytes: %s" % frame.hex()], frame_no)
        return
    if m.get_type().startswith("UNKNOWN_"):
        rep.add(where, ["pymavlink does not know msgid %d" % m.get_msgId()], frame_no)
        return
    h = mi.frame_header(frame)
    if key is not None and h["version"] == 2 and h["incompat_flags"] & mi.IFLAG_SIGNED and not m.get_signed():
        rep.add(where, ["pymavlink: the signature does not verify with the key"], frame_no)
    back = mi.message_to_json(m, key is not None)
    back.pop("signature", None)
    want = {k: v for k, v in obj.items() if k != "signature"}
    want.setdefault("version", 2)
    diffs = cd.compare_obj(mod, want, back)
    if diffs:
        rep.add(where, ["pymavlink decodes the frame differently from the JSON (decode(encode(x)) != x):"]
                + ["  " + d for d in diffs[:8]], frame_no)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("jsonl")
    ap.add_argument("actual", nargs="?")
    ap.add_argument("--orig", required=True, help="the original stream the JSONL was decoded from")
    ap.add_argument("--dialect", default="ardupilotmega")
    ap.add_argument("--key", help="the key given to `mavstack encode --key` (64 hex digits)")
    ap.add_argument("--link-id", type=int, default=0, help="the --link-id given to mavstack encode (default 0)")
    ap.add_argument("--self-check", action="store_true", help="check pymavlink's own packing of JSONL")
    ap.add_argument("--v1-base-ok", action="store_true", help="accept base-only MAVLink 1 payloads (zero extensions)")
    ap.add_argument("--max-diffs", type=int, default=20)
    args = ap.parse_args()
    if args.self_check == (args.actual is not None):
        mi.die("give ACTUAL.bin or --self-check, not both or neither")
    key = None
    if args.key is not None:
        try:
            key = bytes.fromhex(args.key)
        except ValueError:
            key = b""
        if len(key) != 32:
            mi.die("--key must be 64 hex digits")

    mod = mi.load_dialect(args.dialect)
    objs = load_jsonl(args.jsonl)
    orig_items = [(off, bytes(m.get_msgbuf())) for off, kind, m in mi.parse_stream(mod, read(args.orig), key) if kind == "msg"]
    if len(orig_items) != len(objs):
        mi.die("%s has %d frames (pymavlink), %s has %d lines: they do not belong together"
               % (args.orig, len(orig_items), args.jsonl, len(objs)))
    for i, (obj, (off, frame)) in enumerate(zip(objs, orig_items)):
        h = mi.frame_header(frame)
        mine = {k: obj.get(k, 2 if k == "version" else None) for k in ("version", "seq", "sysid", "compid", "msgid")}
        if any(h[k] != v for k, v in mine.items()):
            mi.die("line %d does not describe frame %d of %s (offset %d): %s vs %s" % (i + 1, i, args.orig, off, mine, h))

    rep = Report(args.max_diffs)
    if args.self_check:
        actual_data = None
        stamp = now_ts()
        actual = []
        pos = 0
        for obj in objs:
            ts = None
            if key is not None and obj.get("version", 2) == 2 and not obj.get("signature"):
                stamp += 1
                ts = stamp
            try:
                b = mi.pack_json(mod, obj, key, args.link_id, ts)
            except Exception as e:  # struct.error, ValueError, MAVError
                mi.die("pymavlink cannot pack line %d: %s" % (len(actual) + 1, e), 1)
            actual.append((pos, b))
            pos += len(b)
        actual_data = b"".join(b for _, b in actual)
        what = "pymavlink's packing"
    else:
        actual_data = read(args.actual)
        actual, err = mi.split_frames(actual_data)
        if err:
            rep.add("%s" % args.actual, ["the output is not a sequence of frames: " + err])
        what = args.actual

    cats = {"identical": 0, "c_style_v1": 0, "resigned": 0, "stamped": 0, "unsigned_no_key": 0}
    stamps = []
    now = now_ts()
    # Walk JSON lines and written frames together; a frame missing from (or extra in) the
    # output is reported once and skipped, so one dropped frame does not fail all later ones.
    i = j = 0
    while i < len(objs) and j < len(actual):
        obj, (ooff, orig) = objs[i], orig_items[i]
        aoff, act = actual[j]
        if not same_frame(obj, act):
            if i + 1 < len(objs) and same_frame(objs[i + 1], act):
                rep.add("frame %d (line %d, %s msgid %s)" % (i, i + 1, obj.get("name"), obj.get("msgid")),
                        ["MISSING: no frame written for this line (the frame at offset %d is the next line's)" % aoff], i)
                i += 1
                continue
            if j + 1 < len(actual) and same_frame(obj, actual[j + 1][1]):
                rep.add("offset %d in %s" % (aoff, os.path.basename(what)),
                        ["EXTRA frame before line %d's: %s" % (i + 1, act.hex())], i)
                j += 1
                continue
        where = "frame %d (line %d, %s msgid %s, offset %d in %s, original offset %d)" % (
            i, i + 1, obj.get("name"), obj.get("msgid"), aoff, os.path.basename(what), ooff)
        ts = None
        if key is not None and obj.get("version", 2) == 2 and not obj.get("signature"):
            try:
                ha = mi.frame_header(act)
            except ValueError:
                ha = {}
            if ha.get("version") == 2 and ha.get("incompat_flags", 0) & mi.IFLAG_SIGNED:
                _, ts = mi.signature_info(act)
                stamps.append((i, ts))
            else:
                ts = 0  # the comparison below reports the missing signature
        try:
            expect = mi.pack_json(mod, obj, key, args.link_id, ts)
        except Exception as e:  # any pymavlink failure (struct.error, ValueError, MAVError)
            rep.add(where, ["pymavlink cannot pack the JSON object: %s" % e], i)
            continue
        cat = classify(mod, obj, expect, orig, key)
        if cat is None:
            rep.add(where, ["HARNESS: pymavlink's packing of the JSON differs from the original frame "
                            "(the JSON is not lossless):"] + ["  " + d for d in mi.describe_frame_diff(mod, orig, expect)], i)
        else:
            cats[cat] += 1
        if act != expect:
            ok = False
            if args.v1_base_ok and expect[0] == mi.V1_MAGIC and act[:1] == expect[:1]:
                cls = mod.mavlink_map.get(obj.get("msgid"))
                _, pe, _, _ = mi.frame_parts(expect)
                _, pa, _, _ = mi.frame_parts(act)
                if cls is not None and len(pa) == mi.layout(cls).base_len and pe[: len(pa)] == pa and not any(pe[len(pa):]):
                    ok = True
            if not ok:
                lines = mi.describe_frame_diff(mod, expect, act)
                if cat not in (None, "identical"):
                    lines.append("(expected bytes: pymavlink's packing of the JSON; the original frame differs "
                                 "by design: %s)" % cat)
                lines.append("expected %s" % expect.hex())
                lines.append("got      %s" % act.hex())
                rep.add(where, lines, i)
        check_with_pymavlink(mod, act, obj, key, where, rep, i)
        i += 1
        j += 1
    if i < len(objs) or j < len(actual):
        rep.add(what, ["%d JSON lines, %d frames written; unmatched from line %d / written frame %d"
                       % (len(objs), len(actual), i + 1, j)])

    # Frames signed with the current time: plausible and strictly increasing.
    prev = None
    for i, ts in stamps:
        if abs(ts - now) > 86400 * 100000:
            rep.add("frame %d (line %d)" % (i, i + 1), [
                "signature timestamp %d is not the current time (now is about %d, in 10 us units since 2015)" % (ts, now)], i)
        if prev is not None and ts <= prev:
            rep.add("frame %d (line %d)" % (i, i + 1), [
                "signature timestamp %d does not increase (previous frame signed at %d)" % (ts, prev)], i)
        prev = ts

    # The whole output as one pymavlink stream: exactly the frames, nothing else.
    items = mi.parse_stream(mod, actual_data, key)
    kinds = [k for _, k, _ in items]
    if kinds.count("msg") != len(objs) or len(kinds) != len(objs):
        bad = [(off, k, m) for off, k, m in items if k != "msg"]
        lines = ["pymavlink's stream parser finds %d messages and %d other items (%d JSON lines)"
                 % (kinds.count("msg"), len(kinds) - kinds.count("msg"), len(objs))]
        for off, k, m in bad[:5]:
            lines.append("offset %d: %s %s" % (off, m.get_type(), getattr(m, "reason", "")))
        rep.add("%s as a stream" % what, lines)

    if rep.shown < rep.count:
        print("... %d more differences not shown" % (rep.count - rep.shown))
    explained = ", ".join("%s %d" % (k, v) for k, v in cats.items() if k != "identical" and v)
    print("%d frames checked: %d identical to the original frames%s; %d differences in %d frames" % (
        len(objs), cats["identical"],
        " (identical to pymavlink's packing, by design not to the original: %s)" % explained if explained else "",
        rep.count, len(rep.frames)))
    sys.exit(1 if rep.count else 0)


if __name__ == "__main__":
    main()
