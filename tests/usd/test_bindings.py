"""Material binding resolution (`usd/src/binding.rs`) against Pixar's USD (`usd-core`).

For every gprim the loader places (instance proxies included) and every GeomSubset, the
material `petzval usd info --json --instances` reports is compared with
`UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("full")`:

* on `usd/tests/data/bindings/bindings.usda` (the hand-written cases: purpose order,
  `strongerThanDescendants`, collection bindings with includes/excludes, `explicitOnly`,
  `includeRoot`, nested collections, dictionary order, malformed bindings, subsets, native and
  nested instances);
* on stages generated here from a seed: random hierarchies with direct bindings of both
  purposes and strengths, collection bindings (random members, excludes, expansion rules,
  `includeRoot`, nested collections) on ancestors and on the gprims themselves, GeomSubsets,
  and native instances whose prototypes carry bindings of their own and whose proxies are
  named by collections outside.
"""

from __future__ import annotations

import json
import random
import subprocess
from pathlib import Path

import pytest

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, UsdShade  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
FIXTURE = REPO / "usd" / "tests" / "data" / "bindings" / "bindings.usda"
MATERIALS = [f"/Looks/M{i}" for i in range(6)]


def ours(petzval: Path, path: Path) -> tuple[dict[str, str | None], dict[str, dict[str, str]], dict]:
    """Placed gprim → material (None: unbound), and placed gprim → {subset name: material}
    for the subsets with a material other than the gprim's."""
    r = subprocess.run(
        [str(petzval), "usd", "info", str(path), "--json", "--instances"], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0 and "panicked" not in r.stderr, r.stderr
    rep = json.loads(r.stdout)
    gprims, subsets = {}, {}
    for inst in rep["instances"]:
        mesh = rep["meshes"][inst["mesh"]]
        name = mesh["material"]
        gprims[inst["path"]] = None if name.startswith("displayColor:") else name
        subsets[inst["path"]] = {s.rsplit("/", 1)[1]: m for s, m in mesh.get("subset_materials", [])}
    return gprims, subsets, rep


def theirs(path: Path) -> tuple[dict[str, str | None], dict[str, dict[str, str]]]:
    """pxr's bound material (purpose full) for every gprim and the subsets whose material is
    set and differs from their gprim's (the faces a subset recolours)."""
    stage = Usd.Stage.Open(str(path))
    gprims, subsets = {}, {}

    def bound(prim: Usd.Prim) -> str | None:
        m = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(UsdShade.Tokens.full)[0]
        return str(m.GetPath()) if m else None

    for prim in Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies()):
        if not prim.IsA(UsdGeom.Gprim):
            continue
        path_s = str(prim.GetPath())
        gprims[path_s] = bound(prim)
        subsets[path_s] = {}
        for child in prim.GetFilteredChildren(Usd.TraverseInstanceProxies()):
            if child.GetTypeName() == "GeomSubset":
                m = bound(child)
                if m is not None and m != gprims[path_s]:
                    subsets[path_s][child.GetName()] = m
    return gprims, subsets


def assert_same(petzval: Path, path: Path) -> dict:
    got, got_sub, rep = ours(petzval, path)
    want, want_sub = theirs(path)
    assert got.keys() == want.keys()
    wrong = {p: (got[p], want[p]) for p in want if got[p] != want[p]}
    assert not wrong, f"(ours, pxr): {wrong}"
    wrong_sub = {p: (got_sub[p], want_sub[p]) for p in want if got_sub[p] != want_sub[p]}
    assert not wrong_sub, f"(ours, pxr): {wrong_sub}"
    return rep


def test_fixture_matches_pxr(petzval: Path) -> None:
    rep = assert_same(petzval, FIXTURE)
    assert len(rep["instances"]) == 50


class Tree:
    """A random stage authored as usda: prims with their apiSchemas and properties."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.lines: list[str] = []
        self.collections = 0

    def bindings(self, path: str, candidates: list[str], own_apis: list[str]) -> list[str]:
        """Random direct and collection bindings on `path`; `candidates`: prim paths the
        collections may name. Adds the applied schemas to `own_apis`."""
        rng, props = self.rng, []

        def strength() -> str:
            return ' (\n bindMaterialAs = "strongerThanDescendants"\n )' if rng.random() < 0.3 else ""

        for rel, p in [("material:binding", 0.3), ("material:binding:full", 0.25), ("material:binding:preview", 0.1)]:
            if rng.random() < p:
                props.append(f"rel {rel} = <{rng.choice(MATERIALS)}>{strength()}")
        names: list[str] = []
        for _ in range(rng.choice([0, 0, 1, 2, 3])):
            self.collections += 1
            name = f"c{self.collections}"
            names.append(name)
            own_apis.append(f"CollectionAPI:{name}")
            inc = rng.sample(candidates, k=min(len(candidates), rng.randint(1, 3)))
            if len(names) > 1 and rng.random() < 0.3:
                inc.append(f"{path}.collection:{names[0]}")
            props.append(f"rel collection:{name}:includes = [{', '.join(f'<{t}>' for t in inc)}]")
            if rng.random() < 0.4:
                exc = rng.sample(candidates, k=min(len(candidates), rng.randint(1, 2)))
                props.append(f"rel collection:{name}:excludes = [{', '.join(f'<{t}>' for t in exc)}]")
            rule = rng.choice([None, None, "explicitOnly", "expandPrims", "expandPrimsAndProperties"])
            if rule:
                props.append(f'uniform token collection:{name}:expansionRule = "{rule}"')
            if rng.random() < 0.1:
                props.append(f"uniform bool collection:{name}:includeRoot = 1")
            purpose = rng.choice(["", "full:"])
            binding = rng.choice(["a", "b", "B", "x9", "x10", name])
            props.append(
                f"rel material:binding:collection:{purpose}{binding} = "
                f"[<{path}.collection:{name}>, <{rng.choice(MATERIALS)}>]{strength()}"
            )
        if props:
            own_apis.insert(0, "MaterialBindingAPI")
        return props

    def prim(self, ty: str, name: str, path: str, meta: list[str], props: list[str], kids: list[str]) -> list[str]:
        meta_s = " (\n" + "\n".join(meta) + "\n)" if meta else ""
        head = f'class "{name}"' if ty == "class" else f'def {ty} "{name}"'
        return [f"{head}{meta_s}", "{", *props, *kids, "}"]


def random_stage(seed: int, path: Path) -> None:
    rng = random.Random(seed)
    tree = Tree(rng)
    out = ["#usda 1.0", "(", " metersPerUnit = 1", ")", 'def Scope "Looks"', "{"]
    out += [f'def Material "{m.rsplit("/", 1)[1]}"\n{{\n}}' for m in MATERIALS] + ["}"]

    def shape(root: str, depth: int, names: list[str]) -> list[tuple[str, str, list]]:
        """(type, path, children) of a random hierarchy under `root`; gprims have subsets."""
        nodes = []
        for i in range(rng.randint(1, 3)):
            p = f"{root}/{'G' if depth == 0 or rng.random() < 0.4 else 'X'}{i}"
            if p.rsplit("/", 1)[1].startswith("G"):
                subs = [("GeomSubset", f"{p}/s{k}", []) for k in range(rng.randint(0, 2))]
                nodes.append(("Mesh", p, subs))
            else:
                nodes.append(("Xform", p, shape(p, depth - 1, names)))
            names.append(p)
        return nodes

    def paths(nodes: list) -> list[str]:
        return [q for _, p, kids in nodes for q in [p, *paths(kids)]]

    def emit(nodes: list, candidates: list[str], extra: dict[str, list[str]]) -> list[str]:
        lines = []
        for ty, p, kids in nodes:
            apis: list[str] = []
            props = tree.bindings(p, candidates, apis)
            meta = api_meta(apis) + extra.get(p, [])
            if ty == "Mesh":
                props += [
                    "int[] faceVertexCounts = [3, 3]",
                    "int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]",
                    "point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]",
                ]
            if ty == "GeomSubset":
                k = int(p.rsplit("s", 1)[1])
                props += ['uniform token elementType = "face"', f"int[] indices = [{k}]"]
            body = [] if extra.get(p) else emit(kids, candidates, extra)
            lines += tree.prim(ty, p.rsplit("/", 1)[1], p, meta, props, body)
        return lines

    # prototypes: classes with bindings of their own
    protos = []
    for k in range(2):
        root = f"/Proto{k}"
        nodes = shape(root, 2, [])
        protos.append((root, nodes))
        apis: list[str] = []
        props = tree.bindings(root, paths(nodes), apis)
        meta = api_meta(apis)
        out += tree.prim("class", f"Proto{k}", root, meta, props, emit(nodes, paths(nodes), {}))
    # trees: some Xforms are instances of a prototype, whose proxies collections may name
    for t in range(12):
        root = f"/T{t}"
        nodes = shape(root, 3, [])
        extra, proxies = {}, []
        for p in [p for ty, p, _ in walk(nodes) if ty == "Xform"]:
            if rng.random() < 0.3 and not any(p.startswith(q + "/") for q in extra):
                proto_root, proto_nodes = rng.choice(protos)
                extra[p] = ["instanceable = true", f"references = <{proto_root}>"]
                proxies += [q.replace(proto_root, p, 1) for q in paths(proto_nodes)]
        live = [p for p in paths(nodes) if not any(p.startswith(q + "/") for q in extra)]
        candidates = [root, *live, *proxies]
        apis: list[str] = []
        props = tree.bindings(root, candidates, apis)
        meta = api_meta(apis)
        out += tree.prim("Xform", f"T{t}", root, meta, props, emit(nodes, candidates, extra))
    path.write_text("\n".join(out) + "\n")


def api_meta(apis: list[str]) -> list[str]:
    """The `prepend apiSchemas` metadata line for `apis` (none when empty)."""
    quoted = ", ".join(f'"{a}"' for a in apis)
    return [f"prepend apiSchemas = [{quoted}]"] if apis else []


def walk(nodes: list):
    for node in nodes:
        yield node
        yield from walk(node[2])


@pytest.mark.parametrize("seed", range(8))
def test_random_stages_match_pxr(petzval: Path, tmp_path: Path, seed: int) -> None:
    path = tmp_path / f"random{seed}.usda"
    random_stage(seed, path)
    rep = assert_same(petzval, path)
    assert len(rep["instances"]) > 20
