"""A pymavlink dialect generated from mavstack's own definitions, so pymavlink speaks
PROTOCOL_VERSION (id 300), the events protocol (EVENT 410-413, COMPONENT_METADATA 397) and the
standard modes (AVAILABLE_MODES, CURRENT_MODE, AVAILABLE_MODES_MONITOR: 435-437) too.

pymavlink's stock XML (the official files mavstack vendors) no longer defines
PROTOCOL_VERSION, the reply of the MAVLink 2 handshake, nor the events protocol. mavstack's
loader merges definitions/extras/*.xml into common.xml; this module does the same for
pymavlink: it copies definitions/*.xml into a cache directory, writes a wrapper XML that
includes ardupilotmega.xml and adds the extra messages and enums, and generates a Python module with
pymavlink's own generator (mavgen, wire protocol 2.0). The module is cached by the content
of the XML files.

    import mavstack_dialect
    mod = mavstack_dialect.load()      # the module (MAVLink, MAVLink_protocol_version_message, ...)
    mavstack_dialect.install()         # also make mavutil connections use it
"""

import contextlib
import glob
import hashlib
import importlib.util
import os
import re
import shutil
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DEFINITIONS = os.path.join(HERE, "..", "definitions")
NAME = "mavstack_ardupilotmega"


EXTRAS = [os.path.join(DEFINITIONS, "extras", name)
          for name in ("protocol_version.xml", "events.xml", "standard_modes.xml")]


def _extra(tag):
    """The contents of every extras file's <tag> element (messages or enums), joined."""
    parts = []
    for path in EXTRAS:
        with open(path, encoding="utf-8") as f:
            text = f.read()
        m = re.search(r"<%s>(.*)</%s>" % (tag, tag), text, re.S)
        if m:
            part = m.group(1)
            if tag == "enums":
                # An enum common.xml has already (MAV_STANDARD_MODE) is left out: mavgen
                # would see it twice.
                with open(os.path.join(DEFINITIONS, "common.xml"), encoding="utf-8") as f:
                    common = f.read()
                part = "".join(e for e in re.findall(r"<enum .*?</enum>", part, re.S)
                               if '<enum name="%s"' % re.search(r'name="([^"]+)"', e).group(1)
                               not in common)
            parts.append(part)
        elif tag == "messages":
            raise RuntimeError("%s has no <messages>" % path)
    return "".join(parts)


def _cache_dir():
    files = sorted(glob.glob(os.path.join(DEFINITIONS, "*.xml"))) + EXTRAS
    h = hashlib.sha256()
    for p in files:
        with open(p, "rb") as f:
            h.update(os.path.basename(p).encode() + b"\0" + f.read())
    base = os.environ.get("MAVSTACK_PYDIALECT_CACHE") or os.path.join(HERE, "..", "target", "pymavlink-dialect")
    return os.path.join(os.path.abspath(base), h.hexdigest()[:16]), files


def load():
    """The generated module (generated on first use)."""
    if NAME in sys.modules:
        return sys.modules[NAME]
    out, files = _cache_dir()
    module_path = os.path.join(out, NAME + ".py")
    if not os.path.exists(module_path):
        os.environ["MAVLINK20"] = "1"
        from pymavlink.generator import mavgen
        xml_dir = os.path.join(out, "xml")
        os.makedirs(xml_dir, exist_ok=True)
        for p in files[:-len(EXTRAS)]:
            shutil.copy(p, xml_dir)
        wrapper = os.path.join(xml_dir, NAME + ".xml")
        with open(wrapper, "w", encoding="utf-8") as f:
            f.write('<?xml version="1.0"?>\n<mavlink>\n  <include>ardupilotmega.xml</include>\n'
                    "  <enums>%s</enums>\n  <messages>%s</messages>\n</mavlink>\n"
                    % (_extra("enums"), _extra("messages")))
        # mavgen appends ".py"; one name per process (test processes may generate at once),
        # and the rename is atomic.
        tmp = os.path.join(out, "%s_tmp%d" % (NAME, os.getpid()))
        opts = mavgen.Opts(tmp, wire_protocol=mavgen.mavparse.PROTOCOL_2_0, language="Python3", validate=False)
        with contextlib.redirect_stdout(sys.stderr):  # mavgen reports on stdout
            ok = mavgen.mavgen(opts, [wrapper])
        if not ok:
            raise RuntimeError("mavgen failed on %s" % wrapper)
        os.replace(tmp + ".py", module_path)
    spec = importlib.util.spec_from_file_location(NAME, module_path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[NAME] = mod
    spec.loader.exec_module(mod)
    return mod


def install():
    """Make pymavlink's mavutil use the generated dialect for new connections."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    mod = load()
    mavutil.mavlink = mod
    mavutil.current_dialect = NAME
    return mod


if __name__ == "__main__":
    m = load()
    print(m.__file__, m.MAVLINK_MSG_ID_PROTOCOL_VERSION, m.MAVLink_protocol_version_message.crc_extra)
