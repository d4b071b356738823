#!/usr/bin/env python3
"""Write a MAVLink byte stream with pymavlink, and pymavlink's own decoding of it as the
expected output of `mavstack decode` (JSON lines, docs/contracts/json-lines.md).

Usage:
  make_corpus.py OUT_PREFIX --dialect ardupilotmega|all --seed N [--frames N] [--key HEX]

Writes:
  OUT_PREFIX.bin            the stream: frames packed by pymavlink's generated dialect module
  OUT_PREFIX.jsonl          expected `mavstack decode --dialect D [--key HEX] OUT_PREFIX.bin`
  OUT_PREFIX.unkeyed.jsonl  (only with --key) expected `mavstack decode --dialect D OUT_PREFIX.bin`,
                            i.e. the same stream decoded without a key (status "unchecked")
  OUT_PREFIX.summary.json   counts of what the stream holds and the options used

The stream holds every message of the dialect at least twice (two shuffled rounds over all
ids, then random picks), with random field values: integers over their full range
(0, min and max included), floats finite (subnormals, -0.0, extremes) plus a few NaN/inf,
char arrays of random length (empty, full length without NUL, printable ASCII, JSON
specials, a few control and 0x80-0xFF bytes), arrays element-wise; some messages have their
extensions, a tail of fields, or everything zero, so MAVLink 2 truncation happens
(down to a 1-byte payload).

Frame kinds:
  - MAVLink 2 (pymavlink `pack`), with random seq/sysid/compid;
  - MAVLink 1 for ids < 256 (--v1-frac), in two styles (--v1-style): "pymavlink"
    (`pack(force_mavlink1=True)`: the full payload, extension bytes included) and "c"
    (base fields only, as the C library sends them; extensions then decode as zero);
  - with --key: signed MAVLink 2 (--signed-frac) with pymavlink's signing (secret_key,
    sign_outgoing, link_id, timestamp), and a few signed with another key (--bad-sig-frac),
    which decode with status "invalid" when the key is given. Signature timestamps increase
    strictly over the whole stream (never a replay) and lie between 2040 and 2104, so no
    replay window, wall-clock based or not, rejects them;
  - noise that a decoder must count and skip, never printed: garbage bytes between frames
    (--garbage-frac; never 0xFD/0xFE), frames with an unknown message id (--unknown-frac)
    and frames with a corrupted CRC (--bad-crc-frac). The noise frames contain no 0xFD/0xFE
    byte after their start marker, so a decoder that resumes at STX+1 and one that skips the
    claimed length both land on the next real frame.

The expected JSON is NOT written from the values we generated: the whole .bin is parsed
again by a fresh pymavlink MAVLink object (`parse_buffer`, robust_parsing, with the key and
an accept-all allow_unsigned_callback when --key is given) and each decoded message is
converted (mavinterop.message_to_json). The script checks that pymavlink found exactly the
frames it wrote.
"""

import argparse
import datetime
import json
import math
import os
import random
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mavinterop as mi  # noqa: E402

INT_RANGES = {
    "int8_t": (-(1 << 7), (1 << 7) - 1),
    "uint8_t": (0, (1 << 8) - 1),
    "int16_t": (-(1 << 15), (1 << 15) - 1),
    "uint16_t": (0, (1 << 16) - 1),
    "int32_t": (-(1 << 31), (1 << 31) - 1),
    "uint32_t": (0, (1 << 32) - 1),
    "int64_t": (-(1 << 63), (1 << 63) - 1),
    "uint64_t": (0, (1 << 64) - 1),
}
NOISE_FREE = bytes(b for b in range(256) if b not in (mi.V1_MAGIC, mi.V2_MAGIC))
PRINTABLE = bytes(range(0x20, 0x7F))
CONTROL = bytes(list(range(0x01, 0x20)) + [0x7F])
HIGH = bytes(range(0x80, 0x100))
EPOCH_2015 = datetime.datetime(2015, 1, 1)
TS_LOW = int((datetime.datetime(2040, 1, 1) - EPOCH_2015).total_seconds()) * 100000
TS_HIGH = (1 << 48) - (1 << 40)


class Gen:
    """Random values for the fields of one message class."""

    def __init__(self, rng):
        self.rng = rng

    def floating(self, type_):
        rng = self.rng
        bits = 32 if type_ == "float" else 64
        fmt = "<f" if bits == 32 else "<d"
        ifmt = "<I" if bits == 32 else "<Q"
        mant = 23 if bits == 32 else 52
        r = rng.random()
        if r < 0.08:
            return 0.0
        if r < 0.11:
            return -0.0
        if r < 0.14:
            return math.nan  # packs as the canonical quiet NaN (0x7fc00000 / 0x7ff8...)
        if r < 0.16:
            return math.inf
        if r < 0.18:
            return -math.inf
        if r < 0.28:  # subnormal
            v = rng.randrange(1, 1 << mant) | (rng.getrandbits(1) << (bits - 1))
            return struct.unpack(fmt, struct.pack(ifmt, v))[0]
        if r < 0.33:  # extremes: max, min normal, min subnormal, either sign
            pats = [(1 << mant) - 1 | ((1 << (bits - 1 - mant)) - 2) << mant, 1 << mant, 1]
            v = rng.choice(pats) | (rng.getrandbits(1) << (bits - 1))
            return struct.unpack(fmt, struct.pack(ifmt, v))[0]
        if r < 0.55:  # any finite bit pattern
            while True:
                x = struct.unpack(fmt, struct.pack(ifmt, rng.getrandbits(bits)))[0]
                if math.isfinite(x):
                    return x
        if r < 0.65:
            return float(rng.randint(-1000, 1000))
        return struct.unpack(fmt, struct.pack(fmt, rng.uniform(-1e4, 1e4)))[0]

    def integer(self, type_):
        rng = self.rng
        lo, hi = INT_RANGES[type_]
        r = rng.random()
        if r < 0.08:
            return 0
        if r < 0.18:
            return rng.choice((lo, hi))
        if r < 0.25:
            return rng.randint(max(lo, -3), 3)
        return rng.randint(lo, hi)

    def text(self, n):
        rng = self.rng
        n = max(1, n)
        r = rng.random()
        if r < 0.1:
            length = 0
        elif r < 0.35:
            length = n  # exactly full: no NUL on the wire
        else:
            length = rng.randint(1, n)
        kind = rng.random()
        if kind < 0.8:
            alphabet = PRINTABLE
        elif kind < 0.85:
            alphabet = b'"\\/{}[]:,\'' + PRINTABLE[:20]
        elif kind < 0.95:
            alphabet = PRINTABLE + HIGH
        else:
            alphabet = PRINTABLE + CONTROL + HIGH
        return bytes(rng.choice(alphabet) for _ in range(length))

    def value(self, f):
        if f.is_text and not f.array_len:  # a scalar `char`: exactly one byte
            return b"\x00" if self.rng.random() < 0.2 else self.text(1).ljust(1, b"\x00")
        if f.is_text:
            return self.text(f.array_len)
        one = self.floating if f.type in mi.FLOAT_TYPES else self.integer
        if f.array_len:
            if self.rng.random() < 0.1:
                return [0.0 if f.type in mi.FLOAT_TYPES else 0] * f.array_len
            return [one(f.type) for _ in range(f.array_len)]
        return one(f.type)

    @staticmethod
    def zero(f):
        if f.is_text:
            return b"" if f.array_len else b"\x00"
        z = 0.0 if f.type in mi.FLOAT_TYPES else 0
        return [z] * f.array_len if f.array_len else z

    def message(self, lay):
        """A pymavlink message object with random values (some zeroed to force truncation)."""
        rng = self.rng
        vals = {f.name: self.value(f) for f in lay.wire}
        r = rng.random()
        if r < 0.03:
            zeroed = lay.wire  # all zero: a 1-byte MAVLink 2 payload
        elif r < 0.13:
            zeroed = lay.wire[rng.randrange(len(lay.wire)) :]  # a wire-order tail, base fields too
        elif lay.has_ext and r < 0.40:
            zeroed = [f for f in lay.wire if f.is_ext]
        else:
            zeroed = []
        for f in zeroed:
            vals[f.name] = self.zero(f)
        return lay.cls(*[vals[f.name] for f in lay.fields])


def noise_free(b):
    return all(x not in (mi.V1_MAGIC, mi.V2_MAGIC) for x in b[1:])


def unknown_frame(rng, mod, v1):
    """A frame with an id the dialect does not know; no 0xFD/0xFE after its start byte."""
    known = mod.mavlink_map
    for _ in range(1000):
        n = rng.randint(1, 40)
        payload = bytes(rng.choice(NOISE_FREE) for _ in range(n))
        seq, sysid, compid = (rng.choice(NOISE_FREE) for _ in range(3))
        if v1:
            free = [i for i in range(256) if i not in known and i not in (mi.V1_MAGIC, mi.V2_MAGIC)]
            msgid = rng.choice(free)
            hdr = struct.pack("<BBBBBB", mi.V1_MAGIC, n, seq, sysid, compid, msgid)
        else:
            # ids >= 65536 and not in the dialect; mavstack's own additions (PROTOCOL_VERSION, 300) are below
            msgid = rng.randrange(1 << 16, 1 << 24)
            if msgid in known:
                continue
            hdr = struct.pack("<BBBBBBBHB", mi.V2_MAGIC, n, 0, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16)
        crc = mod.x25crc(hdr[1:] + payload)
        crc.accumulate(bytes([rng.getrandbits(8)]))
        frame = hdr + payload + struct.pack("<H", crc.crc)
        if noise_free(frame):
            return frame
    return None


def bad_crc_frame(rng, mod, gen, layouts, ids, v1_ids):
    """A frame of a known message whose CRC is wrong; no 0xFD/0xFE after its start byte."""
    tx = mod.MAVLink(None)
    for _ in range(200):
        v1 = bool(v1_ids) and rng.random() < 0.3
        msgid = rng.choice(v1_ids if v1 else ids)
        msg = gen.message(layouts[msgid])
        tx.seq, tx.srcSystem, tx.srcComponent = (rng.choice(NOISE_FREE) for _ in range(3))
        frame = bytearray(msg.pack(tx, force_mavlink1=v1))
        frame[-2] ^= rng.randrange(1, 256)
        if noise_free(frame):
            return bytes(frame)
    return None


def c_style_v1(mod, msg, lay, seq, sysid, compid):
    """MAVLink 1 frame with only the base fields, as the C library sends it."""
    tx = mod.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    tx.seq = seq
    full = msg.pack(tx, force_mavlink1=True)
    payload = full[mi.V1_HEADER : mi.V1_HEADER + lay.base_len]
    hdr = struct.pack("<BBBBBB", mi.V1_MAGIC, len(payload), seq, sysid, compid, lay.id)
    crc = mod.x25crc(hdr[1:] + payload)
    crc.accumulate(struct.pack("B", lay.cls.crc_extra))
    return hdr + payload + struct.pack("<H", crc.crc)


def expected_json(mod, data, key, good_frames):
    """pymavlink's decoding of the stream as JSON objects; checks it found exactly good_frames."""
    items = mi.parse_stream(mod, data, key)
    objs, counts = [], {"messages": 0, "unknown": 0, "bad": 0, "valid_sig": 0, "invalid_sig": 0}
    found = []
    for _offset, kind, m in items:
        if kind == "bad":
            counts["bad"] += 1
            continue
        if kind == "unknown":
            counts["unknown"] += 1
            continue
        counts["messages"] += 1
        found.append(bytes(m.get_msgbuf()))
        obj = mi.message_to_json(m, key is not None)
        sig = obj.get("signature")
        if sig and sig["status"] == "valid":
            counts["valid_sig"] += 1
        elif sig and sig["status"] == "invalid":
            counts["invalid_sig"] += 1
        objs.append(obj)
    if found != good_frames:
        for i, (a, b) in enumerate(zip(found, good_frames)):
            if a != b:
                mi.die("pymavlink's parse disagrees with the frames written at frame %d: %s vs %s" % (i, a.hex(), b.hex()), 1)
        mi.die("pymavlink found %d frames, %d were written" % (len(found), len(good_frames)), 1)
    return objs, counts


def write_jsonl(path, objs):
    with open(path, "w", encoding="utf-8") as f:
        for o in objs:
            # allow_nan=False: NaN/inf must already be the strings "NaN"/"inf"/"-inf".
            f.write(json.dumps(o, separators=(",", ":"), ensure_ascii=False, allow_nan=False))
            f.write("\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_prefix", metavar="OUT_PREFIX")
    ap.add_argument("--dialect", default="ardupilotmega", help="pymavlink v20 dialect module (default ardupilotmega)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames", type=int, default=2000,
                    help="valid frames (raised to twice the number of messages of the dialect)")
    ap.add_argument("--key", help="signing key, 64 hex digits: adds signed frames")
    ap.add_argument("--v1-frac", type=float, default=0.15, help="MAVLink 1 frames, of frames with id < 256")
    ap.add_argument("--v1-style", choices=("pymavlink", "c", "mixed"), default="mixed")
    ap.add_argument("--signed-frac", type=float, default=0.5, help="signed frames when --key is given")
    ap.add_argument("--bad-sig-frac", type=float, default=0.05, help="of signed frames, signed with a wrong key")
    ap.add_argument("--garbage-frac", type=float, default=0.05, help="frames preceded by garbage bytes")
    ap.add_argument("--unknown-frac", type=float, default=0.01, help="frames of unknown ids (skipped by decoders)")
    ap.add_argument("--bad-crc-frac", type=float, default=0.01, help="frames with a bad CRC (skipped by decoders)")
    args = ap.parse_args()

    key = None
    if args.key is not None:
        try:
            key = bytes.fromhex(args.key)
        except ValueError:
            key = b""
        if len(key) != 32:
            mi.die("--key must be 64 hex digits")
    mod = mi.load_dialect(args.dialect)
    rng = random.Random(args.seed)
    gen = Gen(rng)
    layouts = {i: mi.layout(c) for i, c in mod.mavlink_map.items()}
    ids = sorted(layouts)
    v1_ids = [i for i in ids if i < 256]
    frames = max(args.frames, 2 * len(ids))

    # Message order: two full shuffled rounds, then random picks.
    order = []
    for _ in range(2):
        r = list(ids)
        rng.shuffle(r)
        order += r
    order += [rng.choice(ids) for _ in range(frames - len(order))]

    tx = mod.MAVLink(None)
    bad_key = bytes(b ^ 0x5A for b in key) if key else None
    ts = rng.randint(TS_LOW, TS_HIGH - 1000 * frames - 1)

    out = bytearray()
    good = []
    counts = {"v2": 0, "v1_pymavlink": 0, "v1_c": 0, "v2_signed": 0, "v2_bad_signature": 0,
              "unknown_id": 0, "bad_crc": 0, "garbage_chunks": 0, "garbage_bytes": 0}
    seq = rng.randrange(256)
    for msgid in order:
        r = rng.random()
        if r < args.garbage_frac:
            g = bytes(rng.choice(NOISE_FREE) for _ in range(rng.randint(1, 40)))
            out += g
            counts["garbage_chunks"] += 1
            counts["garbage_bytes"] += len(g)
        r = rng.random()
        if r < args.unknown_frac:
            f = unknown_frame(rng, mod, v1=rng.random() < 0.3)
            if f:
                out += f
                counts["unknown_id"] += 1
        elif r < args.unknown_frac + args.bad_crc_frac:
            f = bad_crc_frame(rng, mod, gen, layouts, ids, v1_ids)
            if f:
                out += f
                counts["bad_crc"] += 1

        lay = layouts[msgid]
        msg = gen.message(lay)
        seq = (seq + (1 if rng.random() < 0.9 else rng.randrange(256))) & 0xFF
        sysid = rng.randrange(256)
        compid = rng.randrange(256)
        tx.seq, tx.srcSystem, tx.srcComponent = seq, sysid, compid
        if key is not None and rng.random() < args.signed_frac:
            ts += rng.randint(1, 1000)
            bad = rng.random() < args.bad_sig_frac
            tx.signing.secret_key = bad_key if bad else key
            tx.signing.sign_outgoing = True
            tx.signing.link_id = rng.randrange(256)
            tx.signing.timestamp = ts
            frame = bytes(msg.pack(tx))
            tx.signing.sign_outgoing = False
            counts["v2_bad_signature" if bad else "v2_signed"] += 1
        elif msgid < 256 and rng.random() < args.v1_frac:
            style = args.v1_style if args.v1_style != "mixed" else rng.choice(("pymavlink", "c"))
            if style == "pymavlink":
                frame = bytes(msg.pack(tx, force_mavlink1=True))
            else:
                frame = c_style_v1(mod, msg, lay, seq, sysid, compid)
            counts["v1_" + style] += 1
        else:
            frame = bytes(msg.pack(tx))
            counts["v2"] += 1
        out += frame
        good.append(frame)
    if rng.random() < 0.5:  # trailing garbage
        g = bytes(rng.choice(NOISE_FREE) for _ in range(rng.randint(1, 40)))
        out += g
        counts["garbage_chunks"] += 1
        counts["garbage_bytes"] += len(g)

    with open(args.out_prefix + ".bin", "wb") as f:
        f.write(out)
    objs, parse_counts = expected_json(mod, out, key, good)
    write_jsonl(args.out_prefix + ".jsonl", objs)
    if key is not None:
        if parse_counts["invalid_sig"] != counts["v2_bad_signature"] or parse_counts["valid_sig"] != counts["v2_signed"]:
            mi.die("pymavlink accepted %d/%d signatures, expected %d/%d" % (
                parse_counts["valid_sig"], parse_counts["invalid_sig"], counts["v2_signed"], counts["v2_bad_signature"]), 1)
        unkeyed, _ = expected_json(mod, out, None, good)
        write_jsonl(args.out_prefix + ".unkeyed.jsonl", unkeyed)
    if parse_counts["unknown"] != counts["unknown_id"]:
        mi.die("pymavlink saw %d unknown-id frames, %d written" % (parse_counts["unknown"], counts["unknown_id"]), 1)

    summary = {
        "dialect": args.dialect,
        "pymavlink": mi.pymavlink_version(),
        "frames": len(good),
        "bytes": len(out),
        "message_types": len(set(order)),
        "message_types_in_dialect": len(ids),
        "counts": counts,
        "expected_decode_counts": {
            "frames": len(good),
            "bytes": len(out),
            "bad_crc": counts["bad_crc"],
            "unknown_id": counts["unknown_id"],
            "bad_signature_with_key": counts["v2_bad_signature"],
        },
        "options": {k: v for k, v in vars(args).items() if k != "out_prefix"},
    }
    with open(args.out_prefix + ".summary.json", "w") as f:
        json.dump(summary, f, indent=1)
    print("wrote %s.bin: %d frames, %d bytes, %d message types; %s" % (
        args.out_prefix, len(good), len(out), len(set(order)),
        ", ".join("%s=%d" % kv for kv in counts.items())))


if __name__ == "__main__":
    main()
