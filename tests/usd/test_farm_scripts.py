"""The Flamenco job type and the OpenCue outline in usd/farm/, without a Flamenco Manager or a
Cuebot: the job type's JavaScript is checked by node (`node --check`) and its compileJob run
under stand-ins for Flamenco's `author` and `frameChunker`; the commands it compiles are then
run for real and render every frame. The outline is built with a stand-in `outline` module.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FARM = REPO / "usd" / "farm"

HARNESS = r"""
const fs = require("fs"); const vm = require("vm");
const tasks = [];
const ctx = {
  author: {
    Task: (name, type) => ({ name, type, commands: [], addCommand(c) { this.commands.push(c); } }),
    Command: (type, params) => ({ type, params }),
  },
  // Flamenco's chunker: frames "1-6" in chunks of N → "1-2", "3-4", …
  frameChunker: (frames, size) => {
    const all = [];
    for (const part of frames.split(",")) {
      const [a, b] = part.split("-").map(Number);
      for (let f = a; f <= (isNaN(b) ? a : b); f++) all.push(f);
    }
    const out = [];
    for (let i = 0; i < all.length; i += size) {
      const c = all.slice(i, i + size);
      out.push(c.length === 1 ? `${c[0]}` : `${c[0]}-${c[c.length - 1]}`);
    }
    return out;
  },
};
vm.createContext(ctx);
vm.runInContext(fs.readFileSync(process.argv[2], "utf8"), ctx);
const job = { settings: JSON.parse(process.argv[3]), addTask(t) { tasks.push(t); } };
vm.runInContext("compileJob", ctx)(job);
console.log(JSON.stringify(tasks.map((t) => ({ name: t.name, commands: t.commands }))));
"""


def petzval() -> Path:
    env = os.environ.get("PETZVAL_BIN")
    return Path(env) if env else REPO / "target" / "release" / "petzval"


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_flamenco_job_type_compiles_and_its_commands_render(tmp_path: Path) -> None:
    pxr = pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    _ = pxr
    script = FARM / "flamenco_petzval_usd.js"
    subprocess.run(["node", "--check", str(script)], check=True)
    shot = tmp_path / "shot.usda"
    stage = Usd.Stage.CreateNew(str(shot))
    m = UsdGeom.Mesh.Define(stage, "/Q")
    m.CreatePointsAttr([(-1, -1, -300), (1, -1, -300), (1, 1, -300)])
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 2])
    UsdGeom.Camera.Define(stage, "/Cam")
    stage.GetRootLayer().Save()
    settings = {
        "shot": str(shot),
        "frames": "1-5",
        "chunk_size": 2,
        "render_output_path": str(tmp_path / "out" / "f.####.exr"),
        "camera": "/Cam",
        "petzval": str(petzval()),
        "extra_args": "--resolution 16x12 --spp 1",
    }
    harness = tmp_path / "harness.js"
    harness.write_text(HARNESS)
    r = subprocess.run(["node", str(harness), str(script), json.dumps(settings)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    tasks = json.loads(r.stdout)
    assert [t["name"] for t in tasks] == ["render-1-2", "render-3-4", "render-5"]
    for t in tasks:
        for c in t["commands"]:
            assert c["type"] == "exec"
            p = subprocess.run([c["params"]["exe"], *c["params"]["args"]], capture_output=True, text=True)
            assert p.returncode == 0, p.stderr
    assert sorted(x.name for x in (tmp_path / "out").iterdir()) == [f"f.{i:04d}.exr" for i in range(1, 6)]


def test_opencue_outline_command(monkeypatch: pytest.MonkeyPatch) -> None:
    made = {}

    class Outline:
        def __init__(self, name, **kw):
            made["outline"] = (name, kw)
            self.layers = []

        def add_layer(self, layer):
            self.layers.append(layer)

    class Shell:
        def __init__(self, name, **kw):
            made["layer"] = (name, kw)

    outline = types.ModuleType("outline")
    outline.Outline = Outline
    shell = types.ModuleType("outline.modules.shell")
    shell.Shell = Shell
    monkeypatch.setitem(sys.modules, "outline", outline)
    monkeypatch.setitem(sys.modules, "outline.modules", types.ModuleType("outline.modules"))
    monkeypatch.setitem(sys.modules, "outline.modules.shell", shell)
    sys.path.insert(0, str(FARM))
    import opencue_outline

    args = opencue_outline.argparse.Namespace(
        shot="/s/shot.usd",
        frames="1001-1010",
        output="/r/shot.####.exr",
        chunk=2,
        camera="/Cam",
        petzval="petzval",
        name="shot",
        show=None,
        shot_name=None,
    )
    opencue_outline.build_outline(args, ["--spp", "64"])
    name, kw = made["layer"]
    assert name == "render" and kw["range"] == "1001-1010" and kw["chunk"] == 2
    assert kw["command"] == [
        "petzval",
        "render",
        "/s/shot.usd",
        "--frame",
        "#IFRAME#",
        "-o",
        "/r/shot.####.exr",
        "--no-png",
        "--camera",
        "/Cam",
        "--spp",
        "64",
    ]
