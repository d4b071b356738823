"""Shared helpers of the interoperability harness (pymavlink 2.4.50 <-> mavstack JSON lines).

Everything that states an expectation goes through pymavlink: its generated dialect module
(`pymavlink.dialects.v20.<dialect>`) packs, parses, checks CRCs and signatures. This module only
converts between pymavlink's message objects and the JSON-lines format of
docs/contracts/json-lines.md, and describes byte-level differences between two frames.

JSON conventions (docs/contracts/json-lines.md):
- integers (enums and bitmasks too) are JSON integers;
- float/double are JSON numbers; NaN and infinities are the strings "NaN", "inf", "-inf";
- char[N] (and a scalar `char`, which the test dialect has) is a string cut at the first NUL,
  each byte >= 0x80 one character U+0080..U+00FF (latin-1, so the mapping is lossless);
- other arrays are JSON arrays of all N elements;
- every field is present, extensions included (zero when truncated or absent).
"""

import importlib
import inspect
import math
import struct
import sys

V1_MAGIC = 0xFE
V2_MAGIC = 0xFD
V1_HEADER = 6
V2_HEADER = 10
SIG_LEN = 13
IFLAG_SIGNED = 0x01

# XML base type -> (struct code, size)
TYPES = {
    "int8_t": ("b", 1),
    "uint8_t": ("B", 1),
    "int16_t": ("h", 2),
    "uint16_t": ("H", 2),
    "int32_t": ("i", 4),
    "uint32_t": ("I", 4),
    "int64_t": ("q", 8),
    "uint64_t": ("Q", 8),
    "float": ("f", 4),
    "double": ("d", 8),
    "char": ("c", 1),
}
INT_TYPES = ("int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t", "uint32_t", "int64_t", "uint64_t")
FLOAT_TYPES = ("float", "double")
SPECIAL_FLOATS = {"NaN": math.nan, "inf": math.inf, "-inf": -math.inf}


def die(msg, code=2):
    print("error: " + msg, file=sys.stderr)
    sys.exit(code)


def load_dialect(name):
    """pymavlink's generated MAVLink 2 module for a dialect name (e.g. ardupilotmega, all)."""
    try:
        mod = importlib.import_module("pymavlink.dialects.v20." + name)
    except ImportError as e:
        die("cannot import pymavlink.dialects.v20.%s (is pymavlink 2.4.50 installed? "
            "run scripts/setup-peers.sh): %s" % (name, e))
    return mod


def pymavlink_version():
    try:
        from importlib.metadata import version

        return version("pymavlink")
    except Exception:  # pragma: no cover - informational only
        return None


class Field:
    """One field of a message: XML base type, array length (0 = scalar), wire offset."""

    __slots__ = ("name", "type", "array_len", "is_ext", "offset", "size", "code")

    def __init__(self, name, type_, array_len, is_ext):
        self.name = name
        self.type = type_
        self.array_len = array_len
        self.is_ext = is_ext
        self.code, elem = TYPES[type_]
        self.size = elem * max(1, array_len)
        self.offset = None

    @property
    def is_text(self):
        return self.type == "char"

    def elem_size(self):
        return TYPES[self.type][1]


class Layout:
    """Wire layout of one pymavlink message class, derived from the class itself.

    fieldnames/fieldtypes are in XML order, ordered_fieldnames in wire order, and
    array_lengths is indexed by wire position. Extension fields are the constructor
    parameters that have a default value (mavgen_python gives only those a default; this
    agrees with mavparse's extensions_start for every message of every v20 dialect).
    """

    def __init__(self, cls):
        self.cls = cls
        self.id = cls.id
        self.name = cls.msgname
        params = inspect.signature(cls.__init__).parameters
        ext = {n for n, p in params.items() if p.default is not inspect.Parameter.empty}
        types = dict(zip(cls.fieldnames, cls.fieldtypes))
        self.wire = []
        offset = 0
        for i, name in enumerate(cls.ordered_fieldnames):
            t = types[name]
            if t.startswith("uint8_t_mavlink_version"):
                t = "uint8_t"
            f = Field(name, t, cls.array_lengths[i], name in ext)
            f.offset = offset
            offset += f.size
            self.wire.append(f)
        self.full_len = offset
        if self.full_len != cls.unpacker.size:
            raise AssertionError("%s: layout %d bytes, pymavlink unpacker %d" % (self.name, offset, cls.unpacker.size))
        self.by_name = {f.name: f for f in self.wire}
        self.fields = [self.by_name[n] for n in cls.fieldnames]  # XML order
        seen_ext = False
        for f in self.wire:
            if seen_ext and not f.is_ext:
                raise AssertionError("%s: base field %s after an extension" % (self.name, f.name))
            seen_ext |= f.is_ext
        self.base_len = sum(f.size for f in self.wire if not f.is_ext)
        self.has_ext = seen_ext

    def field_at(self, offset):
        """(field, element index or None) that holds payload byte `offset`."""
        for f in self.wire:
            if f.offset <= offset < f.offset + f.size:
                if f.array_len and not f.is_text:
                    return f, (offset - f.offset) // f.elem_size()
                return f, None
        return None, None


_LAYOUTS = {}


def layout(cls):
    key = (cls.__module__, cls.id)
    lay = _LAYOUTS.get(key)
    if lay is None:
        lay = _LAYOUTS[key] = Layout(cls)
    return lay


# ----------------------------------------------------------------------------- floats


def f32_bits(x):
    return struct.pack("<f", x)


def shortest_f32(x):
    """The shortest decimal (as a Python float) that reads back to the float32 value x."""
    want = f32_bits(x)
    for p in range(1, 10):
        y = float("%.*g" % (p, x))
        try:
            if f32_bits(y) == want:
                return y
        except OverflowError:
            continue
    return x


def float_to_json(x, type_):
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if type_ == "float":
        return shortest_f32(x)
    return x


def float_from_json(v, what="value"):
    """A JSON value of a float field as a Python float; raises ValueError if it is not one."""
    if isinstance(v, str):
        if v in SPECIAL_FLOATS:
            return SPECIAL_FLOATS[v]
        raise ValueError("%s: string %r is not one of \"NaN\", \"inf\", \"-inf\"" % (what, v))
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError("%s: %r is not a number" % (what, v))
    return float(v)


def wire_bits(v, type_):
    """The wire bytes of a JSON float value for a float/double field (NaN canonicalised)."""
    x = float_from_json(v)
    if math.isnan(x):
        return b"NaN"
    return struct.pack("<f" if type_ == "float" else "<d", x)


# ----------------------------------------------------------------------------- text


def text_to_json(raw):
    """char[N] bytes -> string: cut at the first NUL, latin-1 (one char per byte)."""
    return bytes(raw).split(b"\x00", 1)[0].decode("latin-1")


def text_from_json(s, n, what="value"):
    if not isinstance(s, str):
        raise ValueError("%s: %r is not a string" % (what, s))
    try:
        b = s.encode("latin-1")
    except UnicodeEncodeError:
        raise ValueError("%s: %r has characters above U+00FF" % (what, s))
    if len(b) > max(1, n):
        raise ValueError("%s: %d bytes do not fit char[%d]" % (what, len(b), n))
    if n == 0:  # a scalar `char`: struct wants exactly one byte
        b = b.ljust(1, b"\x00")
    return b


# ----------------------------------------------------------------------------- frames


def frame_header(frame):
    """Header fields of a raw v1/v2 frame as a dict (raises ValueError on a bad magic)."""
    magic = frame[0]
    if magic == V2_MAGIC:
        return {
            "version": 2,
            "len": frame[1],
            "incompat_flags": frame[2],
            "compat_flags": frame[3],
            "seq": frame[4],
            "sysid": frame[5],
            "compid": frame[6],
            "msgid": frame[7] | frame[8] << 8 | frame[9] << 16,
        }
    if magic == V1_MAGIC:
        return {"version": 1, "len": frame[1], "seq": frame[2], "sysid": frame[3], "compid": frame[4], "msgid": frame[5]}
    raise ValueError("bad start byte 0x%02x" % magic)


def frame_parts(frame):
    """(header bytes, payload, crc bytes, signature block or b'') of a raw frame."""
    h = frame_header(frame)
    hl = V2_HEADER if h["version"] == 2 else V1_HEADER
    n = frame[1]
    signed = h["version"] == 2 and h["incompat_flags"] & IFLAG_SIGNED
    return frame[:hl], frame[hl : hl + n], frame[hl + n : hl + n + 2], frame[hl + n + 2 :] if signed else b""


def frame_len(buf, pos):
    """Length of the frame starting at buf[pos] from its header, or None if not a start byte."""
    magic = buf[pos]
    if magic == V2_MAGIC:
        if pos + 3 > len(buf):
            return 12
        return V2_HEADER + buf[pos + 1] + 2 + (SIG_LEN if buf[pos + 2] & IFLAG_SIGNED else 0)
    if magic == V1_MAGIC:
        if pos + 2 > len(buf):
            return 8
        return V1_HEADER + buf[pos + 1] + 2
    return None


def split_frames(data):
    """Split a stream that should hold nothing but back-to-back frames.

    Returns (frames, error): frames is a list of (offset, bytes); error is None or a
    message describing where the stream stopped being a sequence of frames.
    """
    out = []
    pos = 0
    while pos < len(data):
        n = frame_len(data, pos)
        if n is None:
            return out, "byte 0x%02x at offset %d is not a start marker (after %d frames)" % (data[pos], pos, len(out))
        if pos + n > len(data):
            return out, "frame %d at offset %d needs %d bytes, only %d left" % (len(out), pos, n, len(data) - pos)
        out.append((pos, bytes(data[pos : pos + n])))
        pos += n
    return out, None


def signature_info(frame):
    """(link_id, timestamp) of a signed v2 frame."""
    return frame[-13], int.from_bytes(frame[-12:-6], "little")


def new_parser(mod, key=None, accept_all=True):
    """A fresh pymavlink MAVLink object for parsing (robust parsing on).

    With a key, signatures are checked; accept_all installs an allow_unsigned_callback that
    accepts every unsigned or badly signed frame (the message then has get_signed() False).
    """
    mav = mod.MAVLink(None)
    mav.robust_parsing = True
    if key is not None:
        mav.signing.secret_key = key
        if accept_all:
            mav.signing.allow_unsigned_callback = lambda _mav, _msgid: True
    return mav


def parse_stream(mod, data, key=None):
    """Parse a byte stream with pymavlink; returns a list of (offset, kind, msg).

    kind is "msg" (a decoded message), "unknown" (an unknown message id: pymavlink does not
    check its CRC) or "bad" (BAD_DATA: garbage, bad CRC, rejected signature, ...).
    """
    mav = new_parser(mod, key)
    out = []
    offset = 0
    msgs = mav.parse_buffer(bytes(data)) or []
    for m in msgs:
        buf = m.get_msgbuf()
        t = m.get_type()
        if t == "BAD_DATA":
            kind = "bad"
        elif t.startswith("UNKNOWN_"):
            kind = "unknown"
        else:
            kind = "msg"
        out.append((offset, kind, m))
        offset += len(buf)
    return out


# ----------------------------------------------------------------------------- JSON


def message_to_json(msg, key_given):
    """A pymavlink-decoded message as mavstack's JSON object (docs/contracts/json-lines.md)."""
    buf = bytes(msg.get_msgbuf())
    lay = layout(type(msg))
    h = frame_header(buf)
    fields = {}
    for f in lay.fields:
        if f.is_text:
            raw = getattr(msg, "_%s_raw" % f.name, None)
            if raw is None:
                raw = getattr(msg, f.name)
            if not isinstance(raw, (bytes, bytearray)):
                raise AssertionError("%s.%s: pymavlink gave %r, not bytes" % (lay.name, f.name, raw))
            fields[f.name] = text_to_json(raw)
            continue
        v = getattr(msg, f.name)
        if f.array_len:
            if len(v) != f.array_len:
                raise AssertionError("%s.%s: %d elements, want %d" % (lay.name, f.name, len(v), f.array_len))
            vals = list(v)
        else:
            vals = [v]
        if f.type in FLOAT_TYPES:
            vals = [float_to_json(x, f.type) for x in vals]
        else:
            vals = [int(x) for x in vals]
        fields[f.name] = vals if f.array_len else vals[0]
    obj = {
        "version": h["version"],
        "seq": msg.get_seq(),
        "sysid": msg.get_srcSystem(),
        "compid": msg.get_srcComponent(),
        "msgid": msg.get_msgId(),
        "name": msg.get_type(),
        "fields": fields,
    }
    if h["version"] == 2 and h["incompat_flags"] & IFLAG_SIGNED:
        link_id, ts = signature_info(buf)
        if key_given:
            status = "valid" if msg.get_signed() else "invalid"
        else:
            status = "unchecked"
        obj["signature"] = {"link_id": link_id, "timestamp": ts, "status": status}
    return obj


def message_class(mod, obj):
    """pymavlink class of a JSON object (by msgid, else by name)."""
    if "msgid" in obj:
        cls = mod.mavlink_map.get(obj["msgid"])
        if cls is None:
            raise ValueError("msgid %r is not in pymavlink's dialect" % obj["msgid"])
        if "name" in obj and obj["name"] != cls.msgname:
            raise ValueError("msgid %d is %s, not %r" % (obj["msgid"], cls.msgname, obj["name"]))
        return cls
    for cls in mod.mavlink_map.values():
        if cls.msgname == obj.get("name"):
            return cls
    raise ValueError("no message named %r" % obj.get("name"))


def json_to_message(mod, obj):
    """Build the pymavlink message object for a JSON object (missing fields are zero)."""
    cls = message_class(mod, obj)
    lay = layout(cls)
    given = obj.get("fields", {}) or {}
    unknown = set(given) - set(lay.by_name)
    if unknown:
        raise ValueError("%s has no field(s) %s" % (lay.name, ", ".join(sorted(unknown))))
    args = []
    for f in lay.fields:
        what = "%s.%s" % (lay.name, f.name)
        v = given.get(f.name)
        if f.is_text:
            args.append(text_from_json("" if v is None else v, f.array_len, what))
            continue
        if v is None:
            v = [0] * f.array_len if f.array_len else 0
        vals = v if f.array_len else [v]
        if f.array_len:
            if not isinstance(v, list) or len(v) > f.array_len:
                raise ValueError("%s: want a list of at most %d elements, got %r" % (what, f.array_len, v))
            vals = list(v) + [0] * (f.array_len - len(v))
        conv = []
        for x in vals:
            if f.type in FLOAT_TYPES:
                conv.append(float_from_json(x, what))
            else:
                if isinstance(x, bool) or not isinstance(x, int):
                    raise ValueError("%s: %r is not an integer" % (what, x))
                conv.append(x)
        args.append(conv if f.array_len else conv[0])
    return cls(*args)


def pack_json(mod, obj, key=None, link_id=0, timestamp=None):
    """Pack a JSON object with pymavlink: the bytes `mavstack encode` must produce.

    version 1 -> pack(force_mavlink1=True) (pymavlink then sends the full payload, extensions
    included). With a key a version-2 frame is signed with the object's signature link_id and
    timestamp when present, else with `link_id` and `timestamp`.
    """
    msg = json_to_message(mod, obj)
    mav = mod.MAVLink(None, srcSystem=obj.get("sysid", 0), srcComponent=obj.get("compid", 0))
    mav.seq = obj.get("seq", 0)
    version = obj.get("version", 2)
    if version == 1:
        return bytes(msg.pack(mav, force_mavlink1=True))
    if key is not None:
        sig = obj.get("signature") or {}
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = sig.get("link_id", link_id)
        ts = sig.get("timestamp", timestamp)
        if ts is None:
            raise ValueError("no signature timestamp")
        mav.signing.timestamp = ts
    return bytes(msg.pack(mav))


# ----------------------------------------------------------------------------- differences


def _field_value(f, payload):
    """Decode one field from a (zero-extended) payload, for messages."""
    chunk = payload[f.offset : f.offset + f.size]
    if f.is_text:
        return repr(text_to_json(chunk))
    n = max(1, f.array_len)
    vals = struct.unpack("<%d%s" % (n, f.code), chunk)
    if f.type in FLOAT_TYPES:
        vals = [float_to_json(x, f.type) for x in vals]
    return repr(list(vals) if f.array_len else vals[0])


def describe_payload_diff(lay, exp, act, limit=6):
    """Which fields differ between two payloads of one message type."""
    if lay is None:
        return ["payload differs (message layout unknown)"]
    size = max(lay.full_len, len(exp), len(act))
    e = bytes(exp) + bytes(size - len(exp))
    a = bytes(act) + bytes(size - len(act))
    out = []
    for f in lay.wire:
        if e[f.offset : f.offset + f.size] != a[f.offset : f.offset + f.size]:
            first = next(i for i in range(f.offset, f.offset + f.size) if e[i] != a[i])
            out.append(
                "field %s%s (payload bytes %d..%d, first difference at byte %d): expected %s, got %s"
                % (f.name, " [extension]" if f.is_ext else "", f.offset, f.offset + f.size - 1, first,
                   _field_value(f, e), _field_value(f, a))
            )
    if e[lay.full_len :] != a[lay.full_len :]:
        out.append("bytes beyond the message's %d-byte payload differ" % lay.full_len)
    if not out:
        out.append("the payloads differ only in trailing zero bytes: every field value is equal")
    if len(out) > limit:
        out = out[:limit] + ["... and %d more fields" % (len(out) - limit)]
    return out


def describe_frame_diff(mod, exp, act):
    """Human-readable list of how frame `act` differs from frame `exp` (both raw bytes)."""
    out = []
    try:
        he = frame_header(exp)
    except ValueError as e:
        return ["expected frame is malformed: %s" % e]
    try:
        ha = frame_header(act)
    except ValueError as e:
        return ["frame is malformed: %s" % e]
    if he["version"] != ha["version"]:
        return ["version: expected MAVLink %d (magic 0x%02x), got MAVLink %d (magic 0x%02x); expected %s, got %s"
                % (he["version"], exp[0], ha["version"], act[0], exp.hex(), act.hex())]
    hdr = ["%s %s -> %s" % (k, he[k], ha[k]) for k in he if he[k] != ha[k]]
    if hdr:
        out.append("header: " + ", ".join(hdr) + " (expected -> got)")
    _, pe, ce, se = frame_parts(exp)
    _, pa, ca, sa = frame_parts(act)
    cls = mod.mavlink_map.get(he["msgid"])
    lay = layout(cls) if cls is not None else None
    if pe != pa:
        if len(pe) != len(pa):
            out.append("payload length: expected %d, got %d%s" % (
                len(pe), len(pa),
                " (MAVLink 2 must drop trailing zero bytes, keeping at least one)" if he["version"] == 2 else
                " (pymavlink sends the full payload in MAVLink 1, extensions included)"))
        for line in describe_payload_diff(lay, pe, pa):
            out.append("payload: " + line)
    if ce != ca:
        msg = "crc: expected 0x%04x, got 0x%04x" % (int.from_bytes(ce, "little"), int.from_bytes(ca, "little"))
        if cls is not None and len(ca) == 2:
            hl = V2_HEADER if ha["version"] == 2 else V1_HEADER
            crc = mod.x25crc(act[1 : hl + len(pa)])
            crc.accumulate(struct.pack("B", cls.crc_extra))
            msg += " (the CRC written is %s for the frame's own bytes with CRC_EXTRA %d)" % (
                "correct" if crc.crc == int.from_bytes(ca, "little") else "WRONG (should be 0x%04x)" % crc.crc,
                cls.crc_extra)
        out.append(msg)
    if se != sa:
        if not se or not sa:
            out.append("signature block: expected %s, got %s" % ("13 bytes" if se else "none", "13 bytes" if sa else "none"))
        else:
            if se[0] != sa[0]:
                out.append("signature link_id: expected %d, got %d" % (se[0], sa[0]))
            te, ta = int.from_bytes(se[1:7], "little"), int.from_bytes(sa[1:7], "little")
            if te != ta:
                out.append("signature timestamp: expected %d, got %d" % (te, ta))
            if se[7:] != sa[7:]:
                out.append("signature bytes: expected %s, got %s" % (se[7:].hex(), sa[7:].hex()))
    if not out and exp != act:
        out.append("frames differ: expected %s, got %s" % (exp.hex(), act.hex()))
    return out
