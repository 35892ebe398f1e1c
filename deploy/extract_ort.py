#!/usr/bin/env python3
"""Copy the ONNX Runtime shared libraries out of a PyPI wheel.

The container recipes use this to take `onnxruntime/capi/libonnxruntime.so.<version>` (and the
execution-provider libraries next to it, for the GPU wheel) out of the `onnxruntime` or
`onnxruntime-gpu` wheel, with no Python runtime left in the final image. The library must match
what the server's `ort` crate was built for (`api-31` -> ONNX Runtime 1.31).

    extract_ort.py WHEEL DEST_DIR VERSION

Writes DEST_DIR/libonnxruntime.so.VERSION plus every other `libonnxruntime*.so*` the wheel ships,
and the symlinks libonnxruntime.so.1 and libonnxruntime.so pointing at the versioned file.
Exits non-zero, naming what is missing, when the wheel does not hold the versioned library.
"""

import os
import sys
import zipfile

CAPI = "onnxruntime/capi/"


def extract(wheel: str, dest: str, version: str) -> list[str]:
    """Extracts the libraries and returns the file names written (symlinks excluded)."""
    wanted = f"libonnxruntime.so.{version}"
    os.makedirs(dest, exist_ok=True)
    written = []
    with zipfile.ZipFile(wheel) as archive:
        for member in archive.namelist():
            if not member.startswith(CAPI):
                continue
            name = member[len(CAPI):]
            if "/" in name or not name.startswith("libonnxruntime") or ".so" not in name:
                continue
            target = os.path.join(dest, name)
            with archive.open(member) as src, open(target, "wb") as out:
                while chunk := src.read(1 << 20):
                    out.write(chunk)
            os.chmod(target, 0o755)
            written.append(name)
    if wanted not in written:
        raise SystemExit(
            f"extract_ort: {wheel} has no {CAPI}{wanted} (found: {', '.join(sorted(written)) or 'none'})"
        )
    for link in ("libonnxruntime.so.1", "libonnxruntime.so"):
        path = os.path.join(dest, link)
        if os.path.lexists(path):
            os.remove(path)
        os.symlink(wanted, path)
    return sorted(written)


def main(argv: list[str]) -> int:
    if len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    for name in extract(argv[1], argv[2], argv[3]):
        print(f"extract_ort: {os.path.join(argv[2], name)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
