"""OpenCue outline: render a USD shot's frames with petzval, one frame (or chunk) per OpenCue
frame. Needs OpenCue's `outline` package (pycue/pyoutline) and a configured Cuebot.

    python usd/farm/opencue_outline.py SHOT.usd --frames 1001-1010 -o /renders/shot.####.exr \\
        [--chunk 1] [--camera /World/Cam] [--petzval petzval] [--show SHOW --shot SHOT_NAME] \\
        -- [petzval render options]

Each OpenCue frame runs `petzval render SHOT --frame #IFRAME# -o OUT` (petzval names the file
from the `####` in OUT and writes it to a temporary name first, so a killed frame leaves no
broken file; OpenCue retries it).
"""

from __future__ import annotations

import argparse
import sys


def build_outline(args: argparse.Namespace, extra: list[str]):  # -> outline.Outline
    from outline import Outline
    from outline.modules.shell import Shell

    ol = Outline(f"petzval_{args.name}", frame_range=args.frames, show=args.show, shot=args.shot_name)
    cmd = [args.petzval, "render", args.shot, "--frame", "#IFRAME#", "-o", args.output, "--no-png"]
    if args.camera:
        cmd += ["--camera", args.camera]
    ol.add_layer(Shell("render", command=cmd + extra, range=args.frames, chunk=args.chunk, threads=1))
    return ol


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1 :]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shot")
    ap.add_argument("--frames", required=True, help="OpenCue frame range, e.g. 1001-1010 or 1-100x5")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--chunk", type=int, default=1)
    ap.add_argument("--camera")
    ap.add_argument("--petzval", default="petzval")
    ap.add_argument("--name", default="usd")
    ap.add_argument("--show", default=None)
    ap.add_argument("--shot-name", default=None)
    a = ap.parse_args(argv)
    if "#" not in a.output:
        ap.error("-o must name the frame with #### (e.g. shot.####.exr)")
    from outline import cuerun

    cuerun.launch(build_outline(a, extra), use_pycuerun=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
