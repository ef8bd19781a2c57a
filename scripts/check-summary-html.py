#!/usr/bin/env python3
"""Check an evaluation's summary.html the way a person would open it: in a browser.

    python scripts/check-summary-html.py OUT_DIR [--screenshot FILE]

Headless Chromium (Debian's `chromium`, WebGL on its software rasteriser) opens
OUT_DIR/summary.html from disk, with no network. The check passes when the page logs no
error to the console, the 3D replay plays (its status says `playing` and it has played
some time: it loops, so its current time alone does not tell; a page that drew too few
frames to tell, as on a busy machine, is opened again with more virtual time), its canvas is not blank
(more than 8 distinct colours on a 16 x 16 grid of the rendered frame, and likewise in the
screenshot), and, when the Khronos glTF validator is at hand (scripts/fetch-viewer.sh
installs it), every replay is a valid glTF file.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--window-size=1280,1400",
    "--enable-logging=stderr",
    "--v=0",
    # No network: the page must work offline.
    "--host-resolver-rules=MAP * ~NOTFOUND",
]


# Virtual time the page gets before its DOM is read, tried in turn until it draws MIN_FRAMES.
VIRTUAL_TIME_BUDGETS_MS = (10_000, 40_000, 160_000)
MIN_FRAMES = 3


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise SystemExit("no chromium on PATH (Debian: apt-get install chromium)")


def png_pixels(path: Path) -> tuple[int, int, list[bytes]]:
    """Width, height and rows of RGB(A) pixels of an 8-bit non-interlaced PNG."""
    data = path.read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise SystemExit(f"{path}: not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        chunk = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat += chunk
        pos += 12 + length
    width, height, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in (2, 6) or interlace:
        raise SystemExit(f"{path}: PNG of an unexpected kind {header}")
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * bpp
    rows, previous = [], bytearray(stride)
    for y in range(height):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b = previous[x]
            c = previous[x - bpp] if x >= bpp else 0
            if f == 1:
                line[x] = (line[x] + a) & 255
            elif f == 2:
                line[x] = (line[x] + b) & 255
            elif f == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        previous = line
    return width, height, [bytes(r) for r in rows], bpp


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path, help="an evaluation's output folder (with --gltf N)")
    parser.add_argument("--screenshot", type=Path, default=None, help="where to keep the screenshot")
    args = parser.parse_args()
    page = (args.out / "summary.html").resolve()
    if not page.is_file():
        raise SystemExit(f"{page}: no summary.html")
    url = page.as_uri()
    browser = chromium()
    failures = []

    # Chromium runs the page on virtual time, and a busy machine (the software rasteriser
    # shares the CPUs) can spend a budget in one or two frames: a page that drew fewer than
    # MIN_FRAMES tells nothing about playing, so it is opened again with four times the budget.
    for budget in VIRTUAL_TIME_BUDGETS_MS:
        dom = subprocess.run([browser, *CHROMIUM_FLAGS, f"--virtual-time-budget={budget}", "--dump-dom", url],
                             capture_output=True, text=True, timeout=600)
        frames = re.search(r'<p id="replay-status"[^>]*data-frames="([0-9]+)"', dom.stdout)
        if frames and int(frames.group(1)) >= MIN_FRAMES:
            break
        print(f"{frames.group(1) if frames else 'no'} frames in {budget / 1000:g} s of virtual time: opened again")
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line]
    bad = [line for line in console if re.search(r"error|uncaught", line, re.IGNORECASE)]
    if bad:
        failures.append("console errors:\n  " + "\n  ".join(bad))
    status = re.search(r'<p id="replay-status"([^>]*)>([^<]*)', dom.stdout)
    if not status:
        failures.append("the page has no replay (was the run made with --gltf N?)")
    else:
        attributes = dict(re.findall(r'data-([a-z]+)="([^"]*)"', status.group(1)))
        print(f"replay status: {attributes} {status.group(2)!r}")
        if attributes.get("state") != "playing":
            failures.append(f"the replay is {attributes.get('state')!r}, not playing: {status.group(2)}")
        # The replay loops: what it has played, not where it is, shows that it plays.
        if float(attributes.get("played", "0")) <= 0.0:
            failures.append("the replay did not advance")
        if attributes.get("errors") != "0":
            failures.append(f"the viewer counted errors: {status.group(2)}")
        if int(attributes.get("colours", "0")) <= 8:
            failures.append(f"the 3D canvas looks blank ({attributes.get('colours')} colours on a 16 x 16 grid)")

    shot = args.screenshot or args.out / "summary-screenshot.png"
    subprocess.run([browser, *CHROMIUM_FLAGS, f"--virtual-time-budget={budget}", f"--screenshot={shot.resolve()}", url],
                   capture_output=True, text=True, timeout=600)
    if not shot.is_file():
        failures.append("no screenshot was taken")
    else:
        width, height, rows, bpp = png_pixels(shot)
        # The lower half of the window holds the replay's canvas.
        seen = {rows[y][x * bpp : x * bpp + 3] for y in range(height // 2, height, 8) for x in range(0, width, 8)}
        print(f"screenshot {shot}: {width} x {height}, {len(seen)} colours in its lower half")
        if len(seen) <= 8:
            failures.append("the screenshot's lower half is blank")

    validator = Path.home() / ".cache/workcell/viewer/validate-gltf.js"
    glbs = sorted((args.out / "replays").glob("*.glb"))
    if validator.is_file() and shutil.which("node"):
        for glb in glbs:
            report = subprocess.run(["node", str(validator), str(glb)], capture_output=True, text=True)
            result = json.loads(report.stdout or "{}")
            print(f"glTF validator, {glb.name}: {result.get('errors')} errors, {result.get('warnings')} warnings")
            if report.returncode != 0 or result.get("errors") != 0:
                failures.append(f"{glb.name}: {result or report.stderr}")
    else:
        print("glTF validator not installed (scripts/fetch-viewer.sh): replays not validated")

    for f in failures:
        print(f"FAIL: {f}")
    if not failures:
        print(f"ok: {page} loads without console errors and its 3D replay plays")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
