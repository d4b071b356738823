#!/usr/bin/env python3
"""Writes the typed message stubs of the Python package from the vendored XML definitions.

Usage: stubgen.py [--check] [--definitions DIR] [--out DIR]

For every dialect the package has built in (every ``definitions/*.xml``, as
``mavstack.dialects()`` lists them) it writes ``python/mavstack/messages/<dialect>.pyi``:

- ``MAVLink_<name>_message``: one class per message (a subclass of ``MAVLinkMessage`` for
  type checkers), each field an attribute of the Python type the package returns (``int``,
  ``float``, ``str`` for ``char``, lists for the other arrays), its units, enum and
  description from the XML in its docstring;
- ``MAVLink``: the live connection's ``conn.mav`` for that dialect, ``<name>_encode(...)`` and
  ``<name>_send(...)`` with pymavlink's argument names, order and defaults (XML order;
  extensions last and optional; HEARTBEAT's ``mavlink_version`` 3).

and ``python/mavstack/messages/__init__.pyi``: ``TypedReceiver``, ``recv_match`` overloaded
on ``type="NAME"`` for the default dialect (ardupilotmega), which the connections' stubs
inherit, and ``TypedLatest`` / ``TypedMessages``, ``messages["NAME"]`` typed the same way (a
log's ``LatestMessages``, a live link's dict). The names are for type checkers only (like typeshed's ``_typeshed``): at run time
every message is a ``mavstack.MAVLinkMessage``; import them under ``typing.TYPE_CHECKING``.
Beside each stub a ``.py`` of a few lines makes the module importable (tools look for a
source) and answers any name with an ``ImportError`` saying so.

A dialect is read as the package's loader reads it: its file and its includes (relative to
it, each once), a message defined twice keeping its first definition, and each of
``definitions/extras/*.xml`` merged into ``common.xml`` unless that file defines its messages.

``--check`` writes nothing and exits 1, naming the files, when the committed stubs differ from
what would be written (tests/test_typing.py runs it).
"""

import argparse
import keyword
import os
import re
import sys
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
DEFAULT_DIALECT = "ardupilotmega"

INT_TYPES = {"int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t", "uint32_t", "int64_t",
             "uint64_t", "uint8_t_mavlink_version"}
FLOAT_TYPES = {"float", "double"}
TYPE_RE = re.compile(r"^([a-z0-9_]+)(?:\[(\d+)\])?$")


class Field:
    def __init__(self, el, extension):
        self.name = el.get("name")
        m = TYPE_RE.match(el.get("type").strip())
        if m is None:
            raise SystemExit("stubgen: field %s: unknown type %r" % (self.name, el.get("type")))
        self.base = m.group(1)
        self.array = int(m.group(2)) if m.group(2) else None
        if self.base not in INT_TYPES | FLOAT_TYPES | {"char"}:
            raise SystemExit("stubgen: field %s: unknown type %r" % (self.name, el.get("type")))
        self.units = el.get("units")
        self.enum = el.get("enum")
        self.description = clean(el.text)
        self.extension = extension

    def read_type(self):
        """The Python type of the value read (``m.field``)."""
        if self.base == "char":
            return "str"
        scalar = "float" if self.base in FLOAT_TYPES else "int"
        return scalar if self.array is None else "List[%s]" % scalar

    def arg_type(self):
        """The Python type of the argument of ``<name>_send`` / ``_encode``."""
        if self.base == "char":
            return "Union[str, bytes]" if self.array is not None else "Union[str, int]"
        scalar = "float" if self.base in FLOAT_TYPES else "int"
        return scalar if self.array is None else "Sequence[%s]" % scalar

    def arg_name(self):
        return self.name + "_" if keyword.iskeyword(self.name) else self.name

    def optional(self):
        return self.extension or self.base == "uint8_t_mavlink_version"

    def doc(self):
        parts = []
        if self.units:
            parts.append("[%s]" % self.units)
        if self.description:
            parts.append(self.description)
        if self.enum:
            parts.append("(enum %s)" % self.enum)
        if self.extension:
            parts.append("(extension)")
        return " ".join(parts)


class Message:
    def __init__(self, el):
        self.id = int(el.get("id"))
        self.name = el.get("name")
        d = el.find("description")
        self.description = clean(d.text if d is not None else "")
        self.fields = []
        extension = False
        for child in el:
            if child.tag == "extensions":
                extension = True
            elif child.tag == "field":
                self.fields.append(Field(child, extension))


def clean(text):
    """One line of text for a docstring: whitespace collapsed, backslashes and quotes safe."""
    text = " ".join((text or "").split())
    return text.replace("\\", "\\\\").replace('"', '\\"')


def parse(path):
    root = ET.parse(path).getroot()
    includes = [i.text.strip() for i in root.findall("include")]
    messages = [Message(m) for m in root.findall("messages/message")]
    return includes, messages


def same(a, b):
    """Whether two definitions of a message are alike: its name and its fields' names,
    types and order."""
    return a.name == b.name and [(f.name, f.base, f.array) for f in a.fields] == \
        [(f.name, f.base, f.array) for f in b.fields]


def load(defs, name):
    """The messages of dialect ``name`` (its file and include closure) in id order, each with
    ``origin``, the stem of the file whose definition counts, and the dialect's direct
    includes (stems)."""
    extras_dir = os.path.join(defs, "extras")
    extras = [parse(os.path.join(extras_dir, f))[1] for f in sorted(os.listdir(extras_dir))
              if f.endswith(".xml")] if os.path.isdir(extras_dir) else []
    seen, by_id = set(), {}
    direct = []

    def visit(path, depth):
        path = os.path.normpath(path)
        if path in seen:
            return
        seen.add(path)
        stem = os.path.splitext(os.path.basename(path))[0]
        includes, messages = parse(path)
        if depth == 1:
            direct.append(stem)
        if os.path.basename(path) == "common.xml":
            ids = {m.id for m in messages}
            for supplement in extras:
                if not ids & {m.id for m in supplement}:
                    messages = messages + supplement
        for m in messages:
            first = by_id.get(m.id)
            # A message defined again, identically, by a file the first one includes (moved
            # into common.xml, development.xml keeping its copy) is the include's, so that
            # the dialects' stubs agree on its class.
            if first is None or (depth > first.depth and same(first, m)):
                m.origin = stem
                m.depth = depth
                by_id[m.id] = m
        for inc in includes:
            visit(os.path.join(os.path.dirname(path), inc), depth + 1)

    visit(os.path.join(defs, name + ".xml"), 0)
    return [by_id[i] for i in sorted(by_id)], direct


def closure(defs, name):
    """The stems of ``name`` and every file it includes, directly or not."""
    out, todo = set(), [name]
    while todo:
        stem = todo.pop()
        if stem not in out:
            out.add(stem)
            todo += [os.path.splitext(os.path.basename(i))[0]
                     for i in parse(os.path.join(defs, stem + ".xml"))[0]]
    return out


def class_name(msg):
    return "MAVLink_%s_message" % msg.name.lower()


def docstring(text, indent):
    return '%s"""%s"""\n' % (indent, text) if text else ""


def arg_list(msg):
    out = []
    for f in msg.fields:
        default = " = ..." if f.optional() else ""
        out.append("%s: %s%s" % (f.arg_name(), f.arg_type(), default))
    return out


def method(name, args, tail, ret, doc):
    params = ["self"] + args + tail
    one = "    def %s(%s) -> %s:" % (name, ", ".join(params), ret)
    if len(one) <= 100:
        head = one + "\n"
    else:
        head = "    def %s(\n%s    ) -> %s:\n" % (name, "".join("        %s,\n" % p for p in params), ret)
    return head + '        """%s"""\n' % doc + "        ...\n"


def dialect_stub(name, loaded):
    """The stub of one dialect: the classes of its own messages; those of its includes
    imported from their modules, its ``MAVLink`` a subclass of theirs."""
    messages, includes = loaded
    own = [m for m in messages if m.origin == name]
    out = []
    out.append('"""Typed messages of the %s dialect, for type checkers only (generated by\n'
               "crates/mavstack-python/stubgen.py from definitions/%s.xml: do not edit).\n\n"
               "At run time every message is a ``mavstack.MAVLinkMessage``: import these names\n"
               'under ``typing.TYPE_CHECKING``."""\n\n' % (name, name))
    out.append("from typing import List, Sequence, Union\n\n")
    out.append("from mavstack import mavutil\n")
    out.append("from mavstack._native import MAVLinkMessage\n")
    for inc in includes:
        out.append("from mavstack.messages import %s as _%s\n" % (inc, inc))
    for inc in includes:
        names = sorted(class_name(m) for m in messages if m.origin == inc)
        for n in names:
            out.append("from mavstack.messages.%s import %s as %s\n" % (inc, n, n))
    # Messages of files included further down, re-exported by a direct include.
    direct = set(includes) | {name}
    for m in messages:
        if m.origin not in direct:
            out.append("from mavstack.messages.%s import %s as %s\n" % (m.origin, class_name(m), class_name(m)))
    for m in own:
        out.append("\n\nclass %s(MAVLinkMessage):\n" % class_name(m))
        out.append('    """%s (id %d)"""\n\n' % (m.description or m.name, m.id))
        for f in m.fields:
            out.append("    %s: %s\n" % (f.name, f.read_type()))
            out.append(docstring(f.doc(), "    "))
        if not m.fields:
            out.append("    ...\n")
    # An include that another include brings in already is left out of the bases (its class is
    # theirs): listed as well, it would make the method resolution order inconsistent.
    defs = os.path.join(ROOT, "definitions")
    below = set()
    for inc in includes:
        below |= closure(defs, inc) - {inc}
    bases = ", ".join("_%s.MAVLink" % inc for inc in includes if inc not in below) or "mavutil.MAVLink"
    out.append("\n\nclass MAVLink(%s):\n" % bases)
    out.append('    """``conn.mav`` of a live connection with the %s dialect: ``<name>_encode``\n'
               "    and ``<name>_send`` for every message, with pymavlink's arguments.\"\"\"\n" % name)
    for m in own:
        args = arg_list(m)
        lower = m.name.lower()
        doc = "%s (id %d), fields in XML order." % (m.name, m.id)
        out.append("\n")
        out.append(method(lower + "_encode", args, [], class_name(m), doc))
        out.append(method(lower + "_send", args, ["force_mavlink1: bool = ..."], "None", doc))
    if not own:
        out.append("    ...\n")
    return "".join(out)


def receiver_stub(name, loaded):
    messages = loaded[0]
    out = []
    out.append('"""Typed messages per dialect, for type checkers only (generated by\n'
               "crates/mavstack-python/stubgen.py: do not edit).\n\n"
               "``mavstack.messages.<dialect>`` has ``MAVLink_<name>_message`` for every message of the\n"
               "dialect and ``MAVLink``, the ``conn.mav`` of a live connection with it. At run time\n"
               "every message is a ``mavstack.MAVLinkMessage``: import these modules under\n"
               '``typing.TYPE_CHECKING``."""\n\n')
    out.append("from typing import Dict, Literal, Optional, Sequence, Set, Union, overload\n\n")
    out.append("from mavstack._native import MAVLinkMessage\n")
    out.append("from mavstack.messages import %s as _d\n" % name)
    out.append("\n\nclass TypedReceiver:\n")
    out.append('    """``recv_match`` typed by ``type="NAME"`` (the %s dialect\'s messages): the\n'
               '    connections\' stubs inherit it."""\n' % name)
    for m in messages:
        out.append("\n    @overload\n")
        out.append("    def recv_match(\n"
                   "        self,\n"
                   "        condition: Optional[str] = ...,\n"
                   "        *,\n"
                   '        type: Literal["%s"],\n'
                   "        blocking: bool = ...,\n"
                   "        timeout: Optional[float] = ...,\n"
                   "    ) -> Optional[_d.%s]: ...\n" % (m.name, class_name(m)))
    out.append("\n    @overload\n"
               "    def recv_match(\n"
               "        self,\n"
               "        condition: Optional[str] = ...,\n"
               "        type: Union[str, Sequence[str], Set[str], None] = ...,\n"
               "        blocking: bool = ...,\n"
               "        timeout: Optional[float] = ...,\n"
               "    ) -> Optional[MAVLinkMessage]:\n"
               '        """The next message of ``type`` (a name, or a list or set of names) for which\n'
               "        ``condition`` holds; with ``blocking``, waits up to ``timeout`` seconds.\n"
               '        ``None`` when nothing matched."""\n'
               "        ...\n")
    # The latest message of each type by name: a log's LatestMessages, a live link's dict.
    for cls, base, doc in (
            ("TypedLatest", "", "``messages[\"NAME\"]`` of a log typed by the name: ``LatestMessages``' base."),
            ("TypedMessages", "(Dict[str, MAVLinkMessage])",
             "``messages[\"NAME\"]`` of a live link typed by the name: a dict at run time.")):
        out.append("\n\nclass %s%s:\n" % (cls, base))
        out.append('    """%s"""\n' % doc)
        for m in messages:
            out.append("\n    @overload\n")
            out.append('    def __getitem__(self, name: Literal["%s"], /) -> _d.%s: ...\n'
                       % (m.name, class_name(m)))
        out.append("\n    @overload\n")
        out.append("    def __getitem__(self, name: str, /) -> MAVLinkMessage: ...\n")
    return "".join(out)


def runtime_module(name, what):
    """The module's run-time side: it imports, so that tools find a source beside the stub, and
    asking it for a name says the name is for type checkers only."""
    return ('"""%s: for type checkers only.\n\n'
            "The names are in the stub beside this file (generated by crates/mavstack-python/stubgen.py:\n"
            "do not edit). At run time every message is a ``mavstack.MAVLinkMessage``: import these\n"
            'names under ``typing.TYPE_CHECKING``."""\n\n\n'
            "def __getattr__(name):\n"
            '    if name.startswith("_"):\n'
            "        raise AttributeError(name)\n"
            '    raise ImportError("%%s.%%s is for type checkers only: import it under typing.TYPE_CHECKING"\n'
            "                      %% (__name__, name))\n" % what)


def dialect_names(defs):
    return sorted(f[:-4] for f in os.listdir(defs) if f.endswith(".xml"))


def generate(defs):
    """{relative path: text} of every generated stub."""
    files = {}
    for name in dialect_names(defs):
        files["%s.pyi" % name] = dialect_stub(name, load(defs, name))
    files["__init__.pyi"] = receiver_stub(DEFAULT_DIALECT, load(defs, DEFAULT_DIALECT))
    for name in dialect_names(defs):
        files["%s.py" % name] = runtime_module(name, "The typed messages of the %s dialect" % name)
    files["__init__.py"] = runtime_module("messages", "Typed messages per dialect")
    return files


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="compare with the files, write nothing")
    ap.add_argument("--definitions", default=os.path.join(ROOT, "definitions"))
    ap.add_argument("--out", default=os.path.join(HERE, "python", "mavstack", "messages"))
    a = ap.parse_args()
    files = generate(a.definitions)
    present = sorted(f for f in os.listdir(a.out) if f.endswith((".py", ".pyi"))) if os.path.isdir(a.out) else []
    if a.check:
        stale = [f for f in sorted(files) if not os.path.exists(os.path.join(a.out, f))
                 or open(os.path.join(a.out, f), encoding="utf-8").read() != files[f]]
        stale += [f for f in present if f not in files]
        if stale:
            print("stubgen: out of date in %s: %s (run crates/mavstack-python/stubgen.py)"
                  % (a.out, ", ".join(stale)), file=sys.stderr)
            return 1
        return 0
    os.makedirs(a.out, exist_ok=True)
    for f in present:
        if f not in files:
            os.remove(os.path.join(a.out, f))
    for f, text in files.items():
        with open(os.path.join(a.out, f), "w", encoding="utf-8") as out:
            out.write(text)
    print("stubgen: %d files in %s" % (len(files), a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
