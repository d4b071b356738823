#!/usr/bin/env python3
"""Print pymavlink's view of MAVLink dialects, for comparison with mavstack's dialect loader.

Usage: scripts/pymavlink_definitions.py [--json] [--definitions DIR] DIALECT...
       scripts/pymavlink_definitions.py [--json] [--definitions DIR] --all

Needs pymavlink (tested with 2.4.50): `python3 -m pip install pymavlink==2.4.50`.

For every message of pymavlink's generated module `pymavlink.dialects.v20.<DIALECT>` (its
`mavlink_map`) this prints the id, name, CRC_EXTRA, minimum and maximum payload length and the
fields in wire order (name, element type, array length, extension flag). Two independent
pymavlink sources are used and checked against each other:

- the generated module: `id`, `msgname`, `crc_extra`, `fieldnames`/`fieldtypes` (XML order),
  `ordered_fieldnames` (wire order), `orders` (XML index -> wire index), `array_lengths`
  (indexed by WIRE position: mavgen_python fills it from `ordered_fields[i]`), and
  `unpacker` (its struct format gives the element code and count of each wire field, its
  size the full payload length);
- pymavlink's XML parser `pymavlink.generator.mavparse.MAVXML`, run over every file of the
  dialect's include closure (resolved as mavgen does: relative to the including file): the
  minimum length (`wire_min_length`), the extension fields (`fields[extensions_start:]`),
  the offsets of the target system and component fields that routing uses
  (`message_flags`, `target_system_ofs`, `target_component_ofs`), and again the wire order,
  types, CRC_EXTRA and full length.

Any disagreement between the two is reported on stderr and the script exits with status 1.

With --definitions DIR, every file of each include closure must also be byte-identical to
DIR/<file name> (mavstack's vendored copies), else exit status 1.

Output (default): one token-separated line per item, easy to parse without a JSON library:

    pymavlink VERSION
    dialect NAME
    file FILE.xml                      (each file of the include closure)
    message ID NAME CRC_EXTRA MIN_LEN MAX_LEN FIELD_COUNT TARGET_SYSTEM_OFS|- TARGET_COMPONENT_OFS|-
    field NAME TYPE ARRAY_LEN|- base|ext (FIELD_COUNT lines, wire order)
    end NAME MESSAGE_COUNT

With --json: one JSON object {"pymavlink": VERSION, "dialects": {NAME: {"files": [...],
"messages": [{"id", "name", "crc_extra", "min_len", "max_len", "target_system_ofs",
"target_component_ofs", "fields": [{"name", "type", "array_len", "extension"}]}]}}}.

Exit status: 0 success, 1 inconsistency, 2 usage error or unknown dialect, 3 pymavlink missing.
"""

import argparse
import contextlib
import importlib
import io
import json
import os
import re
import sys

INSTALL_HINT = "install it with: python3 -m pip install pymavlink==2.4.50"

# struct format code -> MAVLink element type (mavgen_python's `mavfmt`, inverted).
STRUCT_TYPES = {
    "f": "float",
    "d": "double",
    "c": "char",
    "s": "char",
    "b": "int8_t",
    "B": "uint8_t",
    "h": "int16_t",
    "H": "uint16_t",
    "i": "int32_t",
    "I": "uint32_t",
    "q": "int64_t",
    "Q": "uint64_t",
}


class Inconsistent(Exception):
    """pymavlink's generated module and its parser disagree (or the XML copies differ)."""


def import_pymavlink():
    try:
        import pymavlink  # noqa: F401  (only to check that it is there)
        from pymavlink.generator import mavparse
    except ImportError as e:
        sys.stderr.write("pymavlink is not installed for %s (%s); %s\n" % (sys.executable, e, INSTALL_HINT))
        sys.exit(3)
    return pymavlink, mavparse


def dialect_dir(pymavlink):
    return os.path.join(os.path.dirname(pymavlink.__file__), "dialects", "v20")


def known_dialects(pymavlink):
    d = dialect_dir(pymavlink)
    return sorted(n[:-4] for n in os.listdir(d) if n.endswith(".xml") and os.path.exists(os.path.join(d, n[:-4] + ".py")))


def parse_closure(mavparse, root):
    """MAVXML of every file reachable from `root` through <include>, as mavgen resolves them."""
    parsed = {}
    pending = [os.path.abspath(root)]
    while pending:
        path = pending.pop(0)
        if path in parsed:
            continue
        # mavparse prints notes (e.g. about bitmask values) on stdout; keep stdout for our output.
        with contextlib.redirect_stdout(io.StringIO()):
            x = mavparse.MAVXML(path, mavparse.PROTOCOL_2_0)
        parsed[path] = x
        for inc in x.include:
            pending.append(os.path.abspath(os.path.join(os.path.dirname(path), inc.strip())))
    return parsed


def struct_items(fmt):
    """[(element type, count or None)] of a struct format such as '<fHH16sB'."""
    if not fmt.startswith("<"):
        raise Inconsistent("unexpected struct format %r" % fmt)
    items = []
    for count, code in re.findall(r"(\d*)(\D)", fmt[1:]):
        if code not in STRUCT_TYPES:
            raise Inconsistent("unexpected struct code %r in %r" % (code, fmt))
        items.append((STRUCT_TYPES[code], int(count) if count else None))
    return items


def check(cond, what):
    if not cond:
        raise Inconsistent(what)


def describe_message(mavparse, cls, xml_msg):
    """One message from the generated class `cls` and mavparse's MAVType `xml_msg`."""
    name = cls.msgname
    where = "message %s (id %d)" % (name, cls.id)
    check(xml_msg is not None, "%s: not found by mavparse in the include closure" % where)
    check(xml_msg.id == cls.id, "%s: mavparse says id %d" % (where, xml_msg.id))
    items = struct_items(cls.unpacker.format)
    wire = list(cls.ordered_fieldnames)
    check(len(items) == len(wire), "%s: %d struct items for %d fields" % (where, len(items), len(wire)))
    check(sorted(wire) == sorted(cls.fieldnames), "%s: ordered_fieldnames is not a permutation of fieldnames" % where)
    base_count = xml_msg.base_fields()
    extension_names = set(f.name for f in xml_msg.fields[base_count:])
    xml_wire = xml_msg.ordered_fields
    check([f.name for f in xml_wire] == wire, "%s: mavparse wire order %s" % (where, [f.name for f in xml_wire]))
    fields = []
    for j, fname in enumerate(wire):
        i = cls.fieldnames.index(fname)
        check(cls.orders[i] == j, "%s: orders[%d] = %d, expected %d" % (where, i, cls.orders[i], j))
        ftype = cls.fieldtypes[i]
        array_len = cls.array_lengths[j] or None
        s_type, s_count = items[j]
        check(s_type == ftype, "%s.%s: struct type %s, fieldtypes %s" % (where, fname, s_type, ftype))
        # A scalar char packs as 'c', a char array as 'Ns'; other arrays as 'N<code>'.
        check(s_count == array_len, "%s.%s: struct count %s, array_lengths %s" % (where, fname, s_count, array_len))
        xf = xml_wire[j]
        check(xf.type == ftype, "%s.%s: mavparse type %s" % (where, fname, xf.type))
        check((xf.array_length or None) == array_len, "%s.%s: mavparse array length %s" % (where, fname, xf.array_length))
        fields.append({"name": fname, "type": ftype, "array_len": array_len, "extension": fname in extension_names})
    check(xml_msg.crc_extra == cls.crc_extra, "%s: mavparse CRC_EXTRA %d, module %d" % (where, xml_msg.crc_extra, cls.crc_extra))
    check(xml_msg.wire_length == cls.unpacker.size, "%s: mavparse length %d, module %d" % (where, xml_msg.wire_length, cls.unpacker.size))
    # Extensions come after every base field in wire order.
    ext_flags = [f["extension"] for f in fields]
    check(ext_flags == sorted(ext_flags), "%s: an extension field precedes a base field in wire order" % where)
    flags = xml_msg.message_flags
    have_system = flags & mavparse.FLAG_HAVE_TARGET_SYSTEM
    have_component = flags & mavparse.FLAG_HAVE_TARGET_COMPONENT
    return {
        "id": cls.id,
        "name": name,
        "crc_extra": cls.crc_extra,
        "min_len": xml_msg.wire_min_length,
        "max_len": cls.unpacker.size,
        "target_system_ofs": xml_msg.target_system_ofs if have_system else None,
        "target_component_ofs": xml_msg.target_component_ofs if have_component else None,
        "fields": fields,
    }


def describe_dialect(pymavlink, mavparse, name, definitions):
    root = os.path.join(dialect_dir(pymavlink), name + ".xml")
    module = importlib.import_module("pymavlink.dialects.v20." + name)
    parsed = parse_closure(mavparse, root)
    files = [os.path.basename(p) for p in parsed]
    if definitions is not None:
        for path in parsed:
            ours = os.path.join(definitions, os.path.basename(path))
            with open(path, "rb") as a:
                theirs_bytes = a.read()
            try:
                with open(ours, "rb") as b:
                    ours_bytes = b.read()
            except OSError as e:
                raise Inconsistent("dialect %s: cannot read %s: %s" % (name, ours, e))
            check(theirs_bytes == ours_bytes, "dialect %s: %s differs from %s" % (name, ours, path))
    by_name = {}
    for x in parsed.values():
        for m in x.message:
            check(m.name not in by_name, "dialect %s: mavparse found message %s twice" % (name, m.name))
            by_name[m.name] = m
    check(len(by_name) == len(module.mavlink_map),
          "dialect %s: mavparse found %d messages, mavlink_map has %d" % (name, len(by_name), len(module.mavlink_map)))
    messages = []
    for msg_id in sorted(module.mavlink_map):
        cls = module.mavlink_map[msg_id]
        check(cls.id == msg_id, "dialect %s: mavlink_map[%d] is %s with id %d" % (name, msg_id, cls.msgname, cls.id))
        messages.append(describe_message(mavparse, cls, by_name.get(cls.msgname)))
    return {"files": files, "messages": messages}


def write_lines(out, version, dialects):
    out.write("pymavlink %s\n" % version)
    for name, d in dialects.items():
        out.write("dialect %s\n" % name)
        for f in d["files"]:
            out.write("file %s\n" % f)
        for m in d["messages"]:
            ts, tc = ("-" if v is None else str(v) for v in (m["target_system_ofs"], m["target_component_ofs"]))
            out.write("message %d %s %d %d %d %d %s %s\n" % (m["id"], m["name"], m["crc_extra"], m["min_len"], m["max_len"], len(m["fields"]), ts, tc))
            for f in m["fields"]:
                length = "-" if f["array_len"] is None else str(f["array_len"])
                out.write("field %s %s %s %s\n" % (f["name"], f["type"], length, "ext" if f["extension"] else "base"))
        out.write("end %s %d\n" % (name, len(d["messages"])))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dialects", nargs="*", metavar="DIALECT", help="e.g. common, ardupilotmega")
    ap.add_argument("--all", action="store_true", help="every dialect pymavlink ships")
    ap.add_argument("--json", action="store_true", help="print JSON instead of lines")
    ap.add_argument("--definitions", metavar="DIR", help="require the XML files to be byte-identical to DIR/*.xml")
    args = ap.parse_args()
    pymavlink, mavparse = import_pymavlink()
    known = known_dialects(pymavlink)
    names = known if args.all else args.dialects
    if not names:
        ap.error("name at least one dialect, or --all")
    unknown = [n for n in names if n not in known]
    if unknown:
        sys.stderr.write("unknown dialect(s) %s; pymavlink has: %s\n" % (", ".join(unknown), ", ".join(known)))
        return 2
    version = getattr(pymavlink, "__version__", "unknown")
    try:
        dialects = {n: describe_dialect(pymavlink, mavparse, n, args.definitions) for n in names}
    except Inconsistent as e:
        sys.stderr.write("pymavlink_definitions: %s\n" % e)
        return 1
    if args.json:
        json.dump({"pymavlink": version, "dialects": dialects}, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        write_lines(sys.stdout, version, dialects)
    return 0


if __name__ == "__main__":
    sys.exit(main())
