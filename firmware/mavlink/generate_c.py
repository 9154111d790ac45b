"""Generate the C MAVLink 2 headers of the propid dialect into a build directory.

Called by firmware/mavlink/CMakeLists.txt at build time (never at configure time,
never committed). mavgen resolves <include> relative to the dialect file, so the
standard definitions shipped in pymavlink's wheel are copied beside it first.

usage: python generate_c.py DIALECT_XML XML_WORK_DIR OUTPUT_DIR STAMP_FILE
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

INCLUDED_DEFINITIONS = ("common.xml", "standard.xml", "minimal.xml")


def main(argv: list[str]) -> int:
    if len(argv) != 5:
        print(__doc__, file=sys.stderr)
        return 2
    dialect_xml, work_dir, output_dir, stamp = (Path(a) for a in argv[1:])
    try:
        import pymavlink
    except ImportError:
        print("generate_c.py: pymavlink is not installed in this Python "
              f"({sys.executable}); run `make setup`", file=sys.stderr)
        return 1
    definitions = Path(pymavlink.__file__).parent / "dialects" / "v20"
    work_dir.mkdir(parents=True, exist_ok=True)
    for name in INCLUDED_DEFINITIONS:
        shutil.copyfile(definitions / name, work_dir / name)
    shutil.copyfile(dialect_xml, work_dir / dialect_xml.name)

    # Generate into a fresh directory and swap it in, so an interrupted run never
    # leaves a half-written header set that looks up to date.
    tmp_dir = output_dir.with_name(output_dir.name + ".tmp")
    shutil.rmtree(tmp_dir, ignore_errors=True)
    result = subprocess.run(
        [sys.executable, "-m", "pymavlink.tools.mavgen", "--lang=C", "--wire-protocol=2.0",
         f"--output={tmp_dir}", str(work_dir / dialect_xml.name)],
        capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(result.stdout + result.stderr)
        print("generate_c.py: mavgen failed", file=sys.stderr)
        return 1
    shutil.rmtree(output_dir, ignore_errors=True)
    os.replace(tmp_dir, output_dir)
    stamp.write_text(f"pymavlink {getattr(pymavlink, '__version__', '?')}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
