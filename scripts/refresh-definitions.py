#!/usr/bin/env python3
"""Refresh definitions/ from the official MAVLink XML dialects shipped in a pymavlink wheel.

Usage: scripts/refresh-definitions.py [VERSION]   (default: the version named in PROVENANCE.md)

Downloads the pymavlink wheel of VERSION from PyPI with pip (no dependencies, nothing installed),
copies every `pymavlink/dialects/v20/*.xml` into definitions/ byte for byte, removes official files
that the new version no longer ships, and rewrites the file table in definitions/PROVENANCE.md.
Our own files under definitions/extras/ are never touched.
"""
import hashlib
import pathlib
import re
import subprocess
import sys
import tempfile
import zipfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFS = ROOT / "definitions"
PROVENANCE = DEFS / "PROVENANCE.md"
TABLE_START = "<!-- files:start -->"
TABLE_END = "<!-- files:end -->"


def current_version() -> str:
    match = re.search(r"pymavlink==([0-9.]+)", PROVENANCE.read_text())
    if not match:
        sys.exit("refresh-definitions: no 'pymavlink==VERSION' in definitions/PROVENANCE.md")
    return match.group(1)


def main() -> None:
    version = sys.argv[1] if len(sys.argv) > 1 else current_version()
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--disable-pip-version-check",
             "-d", tmp, f"pymavlink=={version}"],
            check=True,
        )
        wheels = sorted(pathlib.Path(tmp).glob("pymavlink-*.whl"))
        if not wheels:
            sys.exit(f"refresh-definitions: pip produced no wheel for pymavlink=={version}")
        wheel = wheels[0]
        with zipfile.ZipFile(wheel) as archive:
            members = sorted(n for n in archive.namelist()
                             if re.fullmatch(r"pymavlink/dialects/v20/[^/]+\.xml", n))
            if not members:
                sys.exit(f"refresh-definitions: {wheel.name} has no pymavlink/dialects/v20/*.xml")
            wanted = {pathlib.PurePosixPath(m).name for m in members}
            for old in DEFS.glob("*.xml"):
                if old.name not in wanted:
                    old.unlink()
            rows = []
            for member in members:
                data = archive.read(member)
                name = pathlib.PurePosixPath(member).name
                (DEFS / name).write_bytes(data)
                rows.append(f"| `{name}` | `{hashlib.sha256(data).hexdigest()}` |")
    text = PROVENANCE.read_text()
    text = re.sub(r"pymavlink==[0-9.]+", f"pymavlink=={version}", text)
    table = "\n".join(["| file | sha256 |", "| --- | --- |", *rows])
    text = re.sub(f"{re.escape(TABLE_START)}.*{re.escape(TABLE_END)}",
                  f"{TABLE_START}\n{table}\n{TABLE_END}", text, flags=re.S)
    PROVENANCE.write_text(text)
    print(f"definitions/: {len(rows)} official XML files from pymavlink=={version} ({wheel.name})")


if __name__ == "__main__":
    main()
