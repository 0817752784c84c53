"""Fan the frames of a USD shot out over a Ray cluster: one task per chunk of frames, each
running `petzval render SHOT --frame N -o OUT` as its own process; a failed or killed frame is
retried, and no broken file is left behind (petzval writes to a temporary name and renames it
when complete; a task checks that the EXR is there and marked complete).

    python usd/farm/ray_render.py SHOT.usd --frames 1001-1010 -o /renders/shot.####.exr \\
        [--chunk 1] [--retries 3] [--address auto] [--petzval PATH] -- [petzval render options]

| option | meaning | default |
|---|---|---|
| `--frames` | START-END[xSTEP], inclusive | required |
| `-o` | output pattern; a run of `#` is the zero-padded frame | required |
| `--chunk` | frames per task | 1 |
| `--retries` | attempts after the first, per task | 3 |
| `--address` | Ray cluster address (`auto` = a running cluster); none = a local cluster on 127.0.0.1 | none |
| `--num-cpus` | CPUs a task asks for (petzval uses the threads it is given with `--threads`) | 1 |
| `--petzval` | the petzval binary on the workers | `petzval` on PATH |

Test hook: `PETZVAL_FARM_KILL_ONCE=FRAME:MARKER` kills the first attempt of FRAME's render
(SIGKILL, 0.3 s after it starts) and creates MARKER, so the retry path can be tested.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path


def parse_frames(text: str) -> list[int]:
    m = re.fullmatch(r"(-?\d+)(?:-(-?\d+))?(?:x(\d+))?", text.strip())
    if not m:
        raise ValueError(f"--frames: expected START-END[xSTEP], got {text!r}")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    step = int(m.group(3) or 1)
    if b < a or step <= 0:
        raise ValueError(f"--frames: empty range {text!r}")
    return list(range(a, b + 1, step))


def frame_path(pattern: str, frame: int) -> str:
    m = re.search(r"#+", pattern)
    if not m:
        raise ValueError(f"-o must name the frame with #### (got {pattern!r})")
    return pattern[: m.start()] + f"{frame:0{len(m.group())}d}" + pattern[m.end() :]


def exr_complete(path: Path) -> bool:
    """The EXR exists and its header says `petzval/complete` = true."""
    if not path.is_file():
        return False
    head = path.read_bytes()[:65536]
    i = head.find(b"petzval/complete\x00")
    return i >= 0 and b"true" in head[i : i + 64]


def render_frames(petzval: str, shot: str, frames: list[int], pattern: str, extra: list[str]) -> list[str]:
    """Renders `frames` one after another; raises on any failure (so Ray retries the task)."""
    done = []
    kill = os.environ.get("PETZVAL_FARM_KILL_ONCE", "")
    for f in frames:
        out = frame_path(pattern, f)
        if exr_complete(Path(out)):
            done.append(out)  # a retry skips frames an earlier attempt finished
            continue
        cmd = [petzval, "render", shot, "--frame", str(f), "-o", out, "--no-png", *extra]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if kill:
            kframe, marker = kill.split(":", 1)
            if int(kframe) == f and not Path(marker).exists():
                Path(marker).touch()
                time.sleep(0.3)
                proc.send_signal(signal.SIGKILL)
        _, err = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f"frame {f}: petzval exited with {proc.returncode}: {err[-2000:]}")
        if not exr_complete(Path(out)):
            raise RuntimeError(f"frame {f}: {out} is missing or incomplete")
        done.append(out)
    return done


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1 :]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shot")
    ap.add_argument("--frames", required=True)
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--chunk", type=int, default=1)
    ap.add_argument("--retries", type=int, default=3)
    ap.add_argument("--address", default=None)
    ap.add_argument("--num-cpus", type=float, default=1)
    ap.add_argument("--petzval", default="petzval")
    a = ap.parse_args(argv)
    frames = parse_frames(a.frames)
    frame_path(a.output, frames[0])  # check the pattern before starting anything
    if a.chunk < 1 or a.retries < 0:
        ap.error("--chunk must be at least 1 and --retries at least 0")

    import ray

    if a.address:
        ray.init(address=a.address, log_to_driver=False)
    else:
        ray.init(_node_ip_address="127.0.0.1", include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=a.num_cpus, max_retries=a.retries, retry_exceptions=True)(render_frames)
    chunks = [frames[i : i + a.chunk] for i in range(0, len(frames), a.chunk)]
    pending = {
        task.remote(a.petzval, str(Path(a.shot).resolve()), c, str(Path(a.output).resolve()), extra): c
        for c in chunks
    }
    failed = []
    n_done = 0
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            c = pending.pop(ref)
            try:
                outs = ray.get(ref)
                n_done += len(outs)
                print(f"[{n_done}/{len(frames)}] frames {c[0]}–{c[-1]} done", flush=True)
            except Exception as e:  # the task failed after its retries
                failed.append((c, e))
                print(f"frames {c[0]}–{c[-1]} failed after {a.retries} retries: {e}", file=sys.stderr, flush=True)
    ray.shutdown()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
