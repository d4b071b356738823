#!/usr/bin/env python3
"""Compare `mavstack decode` output with the expected JSON lines written by make_corpus.py.

Usage: compare_decode.py [--dialect D] [--max-diffs N] EXPECTED.jsonl ACTUAL.jsonl

Line i of ACTUAL must describe the same frame as line i of EXPECTED:
  - the same top-level keys (version, seq, sysid, compid, msgid, name, fields, and signature
    on signed frames), compared by value;
  - fields compared by name (JSON objects are unordered); the field types come from
    pymavlink's dialect module (--dialect, default ardupilotmega);
  - integer fields must be JSON integers with the same value;
  - float fields are compared as their wire type: both values are parsed and packed with
    struct '<f' (float) or '<d' (double) and the bytes compared, so 0.1 and
    0.10000000149011612 are equal for a float32 field, 0.0 and -0.0 are not; the strings
    "NaN", "inf", "-inf" stand for themselves (bare NaN/Infinity literals are invalid JSON);
  - char fields are strings; other arrays are lists of exactly N elements.

Prints the first --max-diffs (20) differences with their line numbers and exits 1 if there
is any, else prints "N frames compared, 0 differences" and exits 0. Exit 2 on bad usage or
unreadable input.
"""

import argparse
import json
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mavinterop as mi  # noqa: E402

TOP_KEYS_INT = ("version", "seq", "sysid", "compid", "msgid")


def _reject_constant(name):
    raise ValueError("bare %s is not JSON (use the string \"NaN\"/\"inf\"/\"-inf\")" % name)


def load_lines(path):
    """List of (line number, object or error string)."""
    out = []
    try:
        f = open(path, "r", encoding="utf-8")
    except OSError as e:
        mi.die("cannot read %s: %s" % (path, e))
    with f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                out.append((n, "empty line"))
                continue
            try:
                obj = json.loads(line, parse_constant=_reject_constant)
            except ValueError as e:
                out.append((n, "invalid JSON: %s: %.200s" % (e, line.rstrip())))
                continue
            if not isinstance(obj, dict):
                out.append((n, "not a JSON object: %.200s" % line.rstrip()))
                continue
            out.append((n, obj))
    return out


def is_int(v):
    return isinstance(v, int) and not isinstance(v, bool)


def float_equal(e, a, type_):
    """(equal, note) for two JSON values of a float/double field."""
    try:
        eb = mi.wire_bits(e, type_)
    except (ValueError, OverflowError) as err:
        return False, "expected value unusable: %s" % err
    try:
        ab = mi.wire_bits(a, type_)
    except OverflowError:
        return False, "%r overflows %s" % (a, type_)
    except ValueError as err:
        return False, str(err)
    if eb == ab:
        return True, None
    if eb != b"NaN" and ab != b"NaN":
        fmt = "<f" if type_ == "float" else "<d"
        return False, "wire bits %s vs %s (%r as %s)" % (eb.hex(), ab.hex(), struct.unpack(fmt, ab)[0], type_)
    return False, None


def compare_value(f, e, a, path, diffs):
    if f.is_text:
        if not isinstance(a, str) or a != e:
            diffs.append("%s: expected %s, got %s" % (path, json.dumps(e), json.dumps(a)))
        return
    if f.array_len:
        if not isinstance(a, list):
            diffs.append("%s: expected an array of %d, got %s" % (path, f.array_len, json.dumps(a)[:200]))
            return
        if len(a) != len(e):
            diffs.append("%s: expected %d elements, got %d" % (path, len(e), len(a)))
            return
        bad = []
        for i, (x, y) in enumerate(zip(e, a)):
            sub = []
            compare_scalar(f.type, x, y, "%s[%d]" % (path, i), sub)
            bad += sub
        if bad:
            diffs.append("%s: %d of %d elements differ; first: %s" % (path, len(bad), len(e), bad[0]))
        return
    compare_scalar(f.type, e, a, path, diffs)


def compare_scalar(type_, e, a, path, diffs):
    if type_ in mi.FLOAT_TYPES:
        ok, note = float_equal(e, a, type_)
        if not ok:
            diffs.append("%s (%s): expected %s, got %s%s" % (
                path, type_, json.dumps(e), json.dumps(a), " (%s)" % note if note else ""))
        return
    if not is_int(a) or a != e:
        diffs.append("%s (%s): expected %s, got %s" % (path, type_, json.dumps(e), json.dumps(a)))


def compare_obj(mod, e, a):
    """List of differences between an expected and an actual object."""
    diffs = []
    for k in sorted(set(e) | set(a)):
        if k not in a:
            diffs.append("missing key %r" % k)
        elif k not in e:
            diffs.append("unexpected key %r: %.200s" % (k, json.dumps(a[k])))
    for k in TOP_KEYS_INT:
        if k in e and k in a and (not is_int(a[k]) or a[k] != e[k]):
            diffs.append("%s: expected %s, got %s" % (k, json.dumps(e[k]), json.dumps(a[k])))
    if "name" in a and a.get("name") != e.get("name"):
        diffs.append("name: expected %s, got %s" % (json.dumps(e.get("name")), json.dumps(a.get("name"))))
    if "signature" in e and "signature" in a:
        es, as_ = e["signature"], a["signature"]
        if not isinstance(as_, dict):
            diffs.append("signature: expected an object, got %s" % json.dumps(as_))
        else:
            for k in sorted(set(es) | set(as_)):
                if k not in as_:
                    diffs.append("signature: missing key %r" % k)
                elif k not in es:
                    diffs.append("signature: unexpected key %r" % k)
                elif as_[k] != es[k] or (k != "status" and not is_int(as_[k])):
                    diffs.append("signature.%s: expected %s, got %s" % (k, json.dumps(es[k]), json.dumps(as_[k])))
    if e.get("msgid") != a.get("msgid"):
        return diffs  # different frames: field differences would only be noise
    cls = mod.mavlink_map.get(e.get("msgid"))
    if cls is None:
        diffs.append("expected msgid %r is not in pymavlink's dialect (wrong --dialect?)" % e.get("msgid"))
        return diffs
    lay = mi.layout(cls)
    ef, af = e.get("fields", {}), a.get("fields")
    if not isinstance(af, dict):
        diffs.append("fields: expected an object, got %.200s" % json.dumps(af))
        return diffs
    for name in sorted(set(af) - set(ef)):
        diffs.append("fields: unexpected field %r" % name)
    for f in lay.fields:
        if f.name not in af:
            diffs.append("fields.%s: missing" % f.name)
            continue
        compare_value(f, ef[f.name], af[f.name], "fields.%s" % f.name, diffs)
    return diffs


def brief(obj):
    if not isinstance(obj, dict):
        return str(obj)
    return "%s (msgid %s, v%s, seq %s, sysid %s, compid %s)" % (
        obj.get("name"), obj.get("msgid"), obj.get("version"), obj.get("seq"), obj.get("sysid"), obj.get("compid"))


def same_frame(e, a):
    return isinstance(e, dict) and isinstance(a, dict) and all(e.get(k) == a.get(k) for k in TOP_KEYS_INT)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("expected")
    ap.add_argument("actual")
    ap.add_argument("--dialect", default="ardupilotmega")
    ap.add_argument("--max-diffs", type=int, default=20)
    args = ap.parse_args()

    mod = mi.load_dialect(args.dialect)
    exp = load_lines(args.expected)
    act = load_lines(args.actual)
    for n, o in exp:
        if not isinstance(o, dict):
            mi.die("%s line %d: %s" % (args.expected, n, o))

    shown = 0
    total = 0
    bad_lines = 0

    def report(line, what, items):
        nonlocal shown, total
        total += len(items)
        for it in items:
            if shown < args.max_diffs:
                print("line %d: %s: %s" % (line, what, it))
                shown += 1

    # Walk both lists; a frame missing from (or extra in) the actual output is reported once
    # and skipped, so that one dropped frame does not turn every later line into a difference.
    i = j = 0
    compared = 0
    while i < len(exp) and j < len(act):
        n, e = exp[i]
        m, a = act[j]
        if not isinstance(a, dict):
            report(n, "actual line %d" % m, [a])
            bad_lines += 1
            i += 1
            j += 1
            continue
        if not same_frame(e, a):
            if i + 1 < len(exp) and same_frame(exp[i + 1][1], a):
                report(n, brief(e), ["MISSING from the actual output (actual line %d is the next expected frame)" % m])
                bad_lines += 1
                i += 1
                continue
            if j + 1 < len(act) and same_frame(e, act[j + 1][1]):
                report(n, brief(e), ["EXTRA frame before it in the actual output, actual line %d: %.300s"
                                     % (m, json.dumps(a))])
                bad_lines += 1
                j += 1
                continue
        compared += 1
        d = compare_obj(mod, e, a)
        if d:
            bad_lines += 1
            report(n, brief(e) + ("" if m == n else " [actual line %d]" % m), d)
        i += 1
        j += 1
    if i < len(exp) or j < len(act):
        bad_lines += 1
        msg = "expected %d lines, actual has %d" % (len(exp), len(act))
        if j < len(act):
            msg += "; %d extra actual lines from line %d: %.200s" % (len(act) - j, act[j][0], json.dumps(act[j][1]))
        else:
            msg += "; %d expected lines unmatched from line %d: %s" % (len(exp) - i, exp[i][0], brief(exp[i][1]))
        report(exp[i][0] if i < len(exp) else len(exp) + 1, "end of output", [msg])
    if shown < total:
        print("... %d more differences not shown" % (total - shown))
    if total:
        print("%d frames compared, %d differences (in %d lines)" % (compared, total, bad_lines))
        sys.exit(1)
    print("%d frames compared, 0 differences" % compared)


if __name__ == "__main__":
    main()
