"""The Python API of the native module: lenses, scenes from buffers, render, and the mapping of
every error to a Python exception (never a crash). Optics against the CLI, which tests/optics
checks against optiland."""

from __future__ import annotations

import itertools
import json
import subprocess
import threading
import time

import numpy as np
import pytest

import petzval_cli  # tests/optics: where the CLI binary is (built if needed)


def ground_scene(pz, wall=True):
    """A grey ground plane (y = 0, 20 m square) under a white sky, and a wall 3 m ahead (which
    fills a level camera's frame; without it, the upper half of the frame is sky)."""
    s = pz.Scene()
    grey = s.add_material("grey", base_color=(0.5, 0.5, 0.5, 1.0), roughness=1.0, specular=0.0)
    quad = np.array([[-10, 0, -10], [10, 0, -10], [10, 0, 10], [-10, 0, 10]], np.float32)
    s.add_mesh(quad, np.array([[0, 2, 1], [0, 3, 2]]), material_ids=np.array([grey, grey]), name="ground")
    if wall:
        wall_quad = np.array([[-20, -20, -3], [20, -20, -3], [20, 20, -3], [-20, 20, -3]], np.float32)
        s.add_mesh(wall_quad, np.array([[0, 1, 2], [0, 2, 3]]), name="wall")
    s.set_environment_color((1.0, 1.0, 1.0))
    return s


def camera(height_m=1.0):
    m = np.eye(4)
    m[1, 3] = height_m
    return m


def test_library_and_lens_info(petzval):
    lib = petzval.library_lenses()
    assert len(lib) >= 13
    names = [e["name"] for e in lib]
    assert names == sorted(names) and "double-gauss-50mm" in names
    for e in lib:
        assert set(e) >= {"name", "description", "focal_length_mm", "f_number", "source"}
        assert e["focal_length_mm"] > 0 and e["f_number"] > 0 and e["source"]
    lens = petzval.Lens("double-gauss-50mm")
    assert abs(lens.focal_length_mm - 50.358) < 0.01
    info = lens.info()
    cli = json.loads(
        subprocess.run(
            [str(petzval_cli.ensure_binary()), "lens", "info", "double-gauss-50mm", "--json"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    )
    assert info == cli


def test_trace_matches_the_cli_and_reverses(petzval):
    lens = petzval.Lens("double-gauss-50mm")
    rng = np.random.default_rng(1)
    n = 200
    info = lens.info()
    film_z = info["sensor_z_mm"]
    film = np.column_stack([rng.uniform(-10, 10, n), rng.uniform(-10, 10, n), np.full(n, film_z)])
    rear = np.column_stack([rng.uniform(-8, 8, n), rng.uniform(-8, 8, n), np.full(n, info["lens_length_mm"])])
    d = rear - film
    d /= np.linalg.norm(d, axis=1)[:, None]
    o, dirs, ok = lens.trace(film, d)
    assert o.shape == (n, 3) and dirs.shape == (n, 3) and ok.dtype == bool
    assert 20 < ok.sum() < n, ok.sum()
    assert np.isnan(o[~ok]).all() and np.isfinite(o[ok]).all()
    # the CLI's `lens trace` (JSON lines) gives the same rays
    lines = "\n".join(json.dumps([*film[i], *d[i]]) for i in range(n))
    out = subprocess.run(
        [str(petzval_cli.ensure_binary()), "lens", "trace", "double-gauss-50mm", "--direction", "film-to-scene"],
        input=lines,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.splitlines()
    for i, line in enumerate(out):
        r = json.loads(line)
        assert r["ok"] == bool(ok[i])
        if r["ok"]:
            np.testing.assert_allclose(o[i], r["origin"], atol=1e-12)
            np.testing.assert_allclose(dirs[i], r["direction"], atol=1e-12)
    # scene → film: the reversed rays come back to their film points
    back_o, back_d, back_ok = lens.trace(o[ok] + 5 * dirs[ok], -dirs[ok], direction="scene_to_film")
    assert back_ok.all()
    t = (film_z - back_o[:, 2]) / back_d[:, 2]
    np.testing.assert_allclose(back_o + back_d * t[:, None], film[ok], atol=1e-8)


def test_render_thin_lens_exposure_depth_and_determinism(petzval):
    s = ground_scene(petzval)
    cam = petzval.Camera(camera(), lens="thin", focal_length_mm=20.0, fstop=None)
    r1 = petzval.render(s, cam, 64, 48, threads=1, spp=8, seed=3)
    r2 = petzval.render(s, cam, 64, 48, threads=2, spp=8, seed=3)
    assert r1["lens_model"] == "pinhole" and "pinhole" in r1["lens_model_reason"]
    assert r1["rgba"].shape == (48, 64, 4) and r1["rgba"].dtype == np.float32
    assert r1["depth"].shape == (48, 64)
    assert np.array_equal(r1["rgba"], r2["rgba"]) and np.array_equal(r1["depth"], r2["depth"]), (
        "thread count changed the image"
    )
    # the wall (white-lit Lambertian grey, half the sky visible: 0.5 * 0.5 = 0.25 at the top
    # rows; depth along the view axis = 3 m in every pixel that sees it
    top = r1["depth"][:8]
    assert np.allclose(top[np.isfinite(top)], 3.0, atol=1e-4), top
    # the ground below: row 0 is the top of the image
    assert np.all(r1["depth"][-1] < r1["depth"][0])


def test_adaptive_sampling_spends_samples_where_the_noise_is(petzval):
    """With a noise threshold, the sky (noiseless) stops at the first test while the lit ground
    keeps sampling: fewer camera rays than the most allowed, more than the first test's, the
    same image on 1 and 2 threads, and the render reports itself complete."""
    s = ground_scene(petzval, wall=False)  # the upper half of the frame is sky
    cam = petzval.Camera(camera(), lens="thin", focal_length_mm=20.0, fstop=None)
    kw = dict(spp=256, seed=2, adaptive_threshold=0.01, adaptive_min_samples=8)
    a1 = petzval.render(s, cam, 48, 32, threads=1, **kw)
    a2 = petzval.render(s, cam, 48, 32, threads=2, **kw)
    assert np.array_equal(a1["rgba"], a2["rgba"]), "thread count changed the adaptive image"
    assert a1["complete"]
    pixels = 48 * 32
    # more than the first test's 16 samples (Cycles' schedule for a minimum of 8) on the ground
    assert 16 * pixels < a1["camera_rays"] < 0.75 * 256 * pixels, a1["camera_rays"]
    fixed = petzval.render(s, cam, 48, 32, spp=8, seed=2)
    assert fixed["camera_rays"] == 8 * pixels


def test_progress_images_and_cancel(petzval):
    s = ground_scene(petzval)
    seen = []

    def progress(fraction, spp, rgba):
        seen.append((fraction, spp, None if rgba is None else rgba.shape))
        return None  # None continues

    r = petzval.render(s, petzval.Camera(camera()), 160, 120, spp=64, progress=progress, progress_interval_s=0.02)
    assert r["complete"] and r["spp"] == 64
    # every call reports the samples done so far; the finished image was shown
    assert seen and seen[-1][1] == 64, seen[-3:]
    assert (64, (120, 160, 4)) in [(n, shape) for _, n, shape in seen], seen
    assert all(a[1] <= b[1] for a, b in itertools.pairwise(seen)), "samples done go backwards"
    assert all(a[0] <= b[0] + 1e-6 for a, b in itertools.pairwise(seen)), "fraction goes backwards"
    # cancel before the first pass finishes: CancelledError
    with pytest.raises(petzval.CancelledError):
        petzval.render(
            s,
            petzval.Camera(camera(), lens="double-gauss-50mm", lens_model="exact"),
            2048,
            2048,
            spp=4,
            progress=lambda f, n, img: False,
            progress_interval_s=0.01,
        )
    # cancel later: what converged comes back, promptly
    t = {}

    def stop_after_first_pass(f, n, img):
        if n >= 1 and "at" not in t:
            t["at"] = time.perf_counter()
        return "at" not in t

    r = petzval.render(
        s, petzval.Camera(camera()), 400, 300, spp=100000, progress=stop_after_first_pass, progress_interval_s=0.05
    )
    latency = time.perf_counter() - t["at"]
    assert not r["complete"] and 1 <= r["spp"] < 100000
    assert latency < 0.5, f"render returned {latency:.3f} s after cancel"
    # an exception in the callback cancels and is re-raised
    with pytest.raises(ZeroDivisionError):
        petzval.render(s, petzval.Camera(camera()), 64, 48, spp=16, progress=lambda f, n, img: 1 / 0)


def test_render_releases_the_gil(petzval):
    s = ground_scene(petzval)
    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.01)

    th = threading.Thread(target=ticker)
    th.start()
    try:
        petzval.render(s, petzval.Camera(camera()), 256, 192, spp=16)
    finally:
        stop.set()
        th.join()
    gaps = np.diff(ticks)
    assert len(ticks) > 5 and gaps.max() < 0.3, f"another Python thread stalled {gaps.max():.2f} s"


def test_instances_render_like_copies(petzval):
    """A mesh added once and placed by add_instance / add_instances renders exactly like the
    same mesh added once per placement (mirrored and rotated placements included)."""
    box = np.array(
        [
            [-0.3, 0, -0.3],
            [0.3, 0, -0.3],
            [0.3, 0, 0.3],
            [-0.3, 0, 0.3],
            [-0.3, 0.6, -0.3],
            [0.3, 0.6, -0.3],
            [0.3, 0.6, 0.3],
            [-0.3, 0.6, 0.3],
        ],
        np.float32,
    )
    tris = np.array(
        [
            [0, 1, 2],
            [0, 2, 3],
            [4, 6, 5],
            [4, 7, 6],
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
            [3, 7, 4],
            [3, 4, 0],
        ]
    )
    placements = []
    for k, x in enumerate((-1.0, 0.0, 1.0)):
        m = np.eye(4)
        c, sn = np.cos(0.4 * k), np.sin(0.4 * k)
        m[:3, :3] = [[c, 0, sn], [0, 1, 0], [-sn, 0, c]]
        m[0, :3] *= -1.0 if k == 1 else 1.0  # the middle box mirrored
        m[:3, 3] = (x, 0.0, -2.0)
        placements.append(m)
    copies, inst = ground_scene(petzval), ground_scene(petzval)
    for m in placements:
        copies.add_mesh(box, tris, transform=m, name="box")
    mesh_id = inst.add_mesh(box, tris, transform=placements[0], name="box")
    inst.add_instance(mesh_id, placements[1], name="box")
    assert inst.add_instances(mesh_id, np.stack(placements[2:])) == 1
    assert (copies.mesh_count, copies.instance_count) == (5, 5)
    assert (inst.mesh_count, inst.instance_count) == (3, 5)
    assert inst.triangle_count == copies.triangle_count == 2 + 2 + 3 * 12
    cam = petzval.Camera(camera(0.5), lens="thin", focal_length_mm=20.0, fstop=None)
    a = petzval.render(copies, cam, 48, 32, spp=4, seed=1, threads=1)
    b = petzval.render(inst, cam, 48, 32, spp=4, seed=1, threads=1)
    assert np.allclose(a["depth"], b["depth"], rtol=1e-5, equal_nan=True)
    assert np.abs(a["rgba"] - b["rgba"]).max() < 1e-3
    with pytest.raises(petzval.InvalidSceneError, match="mesh_id"):
        inst.add_instance(99, np.eye(4))
    with pytest.raises(petzval.InvalidSceneError, match=r"transforms\[1\]"):
        inst.add_instances(mesh_id, np.stack([np.eye(4), np.zeros((4, 4))]))
    assert inst.instance_count == 5, "a failed add_instances adds none"


def _textured(pz):
    scene = pz.Scene()
    scene.add_texture(np.ones((2, 2, 4), dtype=np.float32))
    return scene


def _two_materials(pz):
    scene = pz.Scene()
    scene.add_material("a")
    scene.add_material("b")
    return scene


@pytest.mark.parametrize(
    "call, exc, words",
    [
        (lambda pz: pz.Lens("/nonexistent/lens.toml"), FileNotFoundError, ["lens.toml"]),
        (
            lambda pz: pz.Scene().add_mesh(np.zeros((3, 3)), np.array([[0, 1, 5]]), name="Cube"),
            "InvalidSceneError",
            ["Cube", "triangles", "5"],
        ),
        (
            lambda pz: pz.Scene().add_mesh(np.full((3, 3), np.nan), np.array([[0, 1, 2]]), name="Nan"),
            "InvalidSceneError",
            ["Nan", "positions"],
        ),
        (
            lambda pz: pz.Scene().add_mesh(
                np.zeros((3, 3)), np.array([[0, 1, 2]]), colors=np.ones((3, 2)), name="Painted"
            ),
            "InvalidSceneError",
            ["Painted", "colors", "(3, 3) or (3, 4)"],
        ),
        (
            lambda pz: pz.Scene().add_mesh(
                np.zeros((3, 3)), np.array([[0, 1, 2]]), colors=np.full((3, 4), np.inf), name="Painted"
            ),
            "InvalidSceneError",
            ["Painted", "colors", "non-finite"],
        ),
        (lambda pz: pz.Scene().add_material("m", base_color=(1, 2)), "InvalidSceneError", ["'m'", "base_color"]),
        (
            lambda pz: pz.Scene().add_material("m", base_color_texture=3),
            "InvalidSceneError",
            ["base_color_texture", "3"],
        ),
        (lambda pz: pz.Scene().add_material("m", mix_material=0), "InvalidSceneError", ["'m'", "mix_material", "0"]),
        (lambda pz: pz.Scene().add_material("m", mix_weight=0.5), "InvalidSceneError", ["mix_weight", "without"]),
        (
            lambda pz: _two_materials(pz).add_material("m", mix_material=1, mix_weight=1.5),
            "InvalidSceneError",
            ["mix_weight", "1.5"],
        ),
        (
            lambda pz: _textured(pz).add_material("m", base_color_texture=0, uv_transforms={"base": [[1, 0, 0]]}),
            "InvalidSceneError",
            ["uv_transforms", "base", "not a texture field"],
        ),
        (
            lambda pz: _textured(pz).add_material("m", uv_transforms={"normal_texture": [[1, 0, 0], [0, 1, 0]]}),
            "InvalidSceneError",
            ["uv_transforms", "normal_texture", "no texture"],
        ),
        (
            lambda pz: _textured(pz).add_material(
                "m", base_color_texture=0, uv_transforms={"base_color_texture": [[1, 0], [0, 1]]}
            ),
            "InvalidSceneError",
            ["uv_transforms", "2 rows of 3"],
        ),
        (
            lambda pz: _two_materials(pz).add_material("m", mix_material=0, mix_weight=1.0, mix_weight_texture=5),
            "InvalidSceneError",
            ["mix_weight_texture", "5"],
        ),
        (lambda pz: _textured(pz).add_material("m", mix_weight_texture=0), "InvalidSceneError", ["without"]),
        (
            lambda pz: _two_materials(pz).add_material("m", mix_material=0, mix_weight_angle=("facing", 0.5)),
            "InvalidSceneError",
            ["mix_weight_angle", "layer_facing"],
        ),
        (
            lambda pz: _two_materials(pz).add_material("m", mix_material=0, mix_weight_angle=("layer_fresnel", 2.0)),
            "InvalidSceneError",
            ["mix_weight_angle", "2.0"],
        ),
        (lambda pz: pz.Scene().add_material("m", metal_fresnel="conductor"), "InvalidSceneError", ["metal_fresnel"]),
        (lambda pz: pz.Scene().add_material("m", edge_tint=(1.2, 1, 1)), "InvalidSceneError", ["edge_tint"]),
        (lambda pz: pz.Scene().add_material("m", scatter_tint=(1, -1, 1)), "InvalidSceneError", ["scatter_tint"]),
        (lambda pz: pz.Scene().add_material("m", specular_tint=(1, 0.5, -0.1)), "InvalidSceneError", ["specular_tint"]),
        (lambda pz: pz.Scene().add_material("m", specular_tint=(1, 0.5)), "InvalidSceneError", ["specular_tint"]),
        (lambda pz: pz.render(pz.Scene(), pz.Camera(np.eye(4)), 0, 10), "InvalidSettingsError", ["resolution"]),
        (lambda pz: pz.Camera(np.eye(4), tilt_x_deg=80), "InvalidSettingsError", ["tilt_x_deg"]),
        (lambda pz: pz.Camera(np.eye(4), lens_model="fast"), "InvalidSettingsError", ["lens_model"]),
        (lambda pz: pz.Camera(np.zeros((4, 4))), "InvalidSettingsError", ["camera_to_world"]),
        (
            lambda pz: pz.render(pz.Scene(), pz.Camera(np.eye(4)), 10, 10, crop=(5, 5, 20, 20)),
            "InvalidSettingsError",
            ["crop"],
        ),
        (
            lambda pz: pz.Camera(np.eye(4), fstop=2.0, focus_distance_m=float("nan")),
            "InvalidSettingsError",
            ["focus_distance_m"],
        ),
        (
            lambda pz: pz.Camera(np.eye(4), aperture_blades=6, aperture_rotation_rad=float("nan")),
            "InvalidSettingsError",
            ["aperture_rotation_rad"],
        ),
        (lambda pz: pz.Camera(np.eye(4), aperture_ratio=0.0), "InvalidSettingsError", ["aperture_ratio"]),
        (
            lambda pz: pz.render(pz.Scene(), pz.Camera(np.eye(4)), 10, 10, adaptive_threshold=float("nan")),
            "InvalidSettingsError",
            ["adaptive_threshold"],
        ),
        (
            lambda pz: pz.render(pz.Scene(), pz.Camera(np.eye(4)), 10, 10, adaptive_threshold=0.01, method="ibrt"),
            "InvalidSettingsError",
            ["adaptive_threshold", "mc"],
        ),
        (lambda pz: pz.Camera(np.eye(4), sensor_fit="diagonal"), "InvalidSettingsError", ["sensor_fit"]),
        (lambda pz: pz.Camera(np.eye(4), clip_start_m=2.0, clip_end_m=1.0), "InvalidSettingsError", ["clip"]),
        (lambda pz: pz.Camera(np.eye(4), focal_length_mm=-5.0), "InvalidSettingsError", ["focal_length_mm"]),
        (lambda pz: pz.Camera(np.eye(4), shift_x=float("nan")), "InvalidSettingsError", ["shift"]),
        (lambda pz: pz.Camera(np.eye(4), fstop=float("nan")), "InvalidSettingsError", ["f_number"]),
        (lambda pz: pz.Camera(np.eye(4), lensmodel="exact"), TypeError, ["lensmodel"]),
        (
            lambda pz: pz.Lens("double-gauss-50mm").trace(np.zeros((2, 2)), np.zeros((2, 2))),
            "InvalidSettingsError",
            ["(N, 3)"],
        ),
    ],
)
def test_errors_map_to_python_exceptions(petzval, call, exc, words):
    exc_type = getattr(petzval, exc) if isinstance(exc, str) else exc
    with pytest.raises(exc_type) as info:
        call(petzval)
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    assert issubclass(petzval.InvalidLensError, petzval.PetzvalError)
    assert issubclass(petzval.CancelledError, petzval.PetzvalError)


def test_broken_lens_file_names_file_and_line(petzval, tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text(
        '[lens]\nname = "x"\nsource = "test"\n\n[[surface]]\nradius_mm = "a"\nthickness_mm = 1\nsemi_diameter_mm = 5\n'
    )
    with pytest.raises(petzval.InvalidLensError) as info:
        petzval.Lens(str(p))
    msg = str(info.value)
    assert "broken.toml" in msg and ":6" in msg and "radius_mm" in msg, msg


def test_crop_equals_the_full_frame(petzval):
    """Samples are keyed by absolute pixel, so a crop is the full frame's window to float noise."""
    s = ground_scene(petzval)
    cam = petzval.Camera(camera(), lens="thin", focal_length_mm=20.0, fstop=2.0, focus_distance_m=3.0)
    full = petzval.render(s, cam, 80, 60, spp=4, seed=1)
    crop = petzval.render(s, cam, 80, 60, spp=4, seed=1, crop=(20, 0, 60, 30))
    assert crop["rgba"].shape == (30, 40, 4)
    np.testing.assert_allclose(crop["rgba"], full["rgba"][0:30, 20:60], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(crop["depth"], full["depth"][0:30, 20:60], rtol=1e-6, atol=1e-7)


def test_camera_description_is_typed_and_named(petzval):
    cam = petzval.Camera(np.eye(4), lens="double-gauss-50mm", lens_model="lrtf")
    assert cam.lens == "double-gauss-50mm" and cam.lens_model == "lrtf:96"
    assert "double-gauss-50mm" in repr(cam)
    # inf focuses at infinity, as None does
    petzval.Camera(np.eye(4), fstop=2.0, focus_distance_m=float("inf"))


def test_stub_matches_the_module(petzval):
    """mypy's stubtest checks ``_native.pyi`` against the built module."""
    import os
    import sys
    from pathlib import Path

    pytest.importorskip("mypy")
    site = Path(petzval.__file__).resolve().parents[1]
    allowlist = Path(__file__).resolve().parent / "stubtest_allowlist.txt"
    env = {**os.environ, "PYTHONPATH": str(site), "MYPYPATH": str(site)}
    r = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "petzval._native", "--allowlist", str(allowlist)],
        capture_output=True,
        text=True,
        env=env,
        cwd=site,
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_fstop_wider_than_the_lens_opens_renders_fully_open_with_a_warning(petzval):
    """Issue 12: as a camera body does, f/0.5 on a double Gauss whose widest is f/2.03 renders
    fully open; the result's warnings say so (it raised InvalidLensError before)."""
    out = petzval.render(petzval.Scene(), petzval.Camera(np.eye(4), lens="double-gauss-50mm", fstop=0.5), 10, 10)
    assert any("opens only to f/2.03" in w for w in out["warnings"]), out["warnings"]
