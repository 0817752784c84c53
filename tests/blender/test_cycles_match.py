"""petzval against Blender's Cycles (bpy 5.0.1, CPU) on a scene built in Blender from code.

The scene (blender_scenes.py) is exported as GLB with Blender's own glTF exporter and rendered by
both: Cycles from the Blender data, petzval from the GLB plus the camera data glTF cannot carry.
See docs/cycles-comparison.md for the scene, the settings, the metric and the results.

Metric (whole image, `test_image_matches_cycles`): each side is rendered with seeds 0 and 1; the
per-pixel variance of the two-seed average is estimated from the seed difference, and 8x8-pixel
block means of luminance are compared with z_b = (P̄_b − C̄_b) / sqrt(var P̄_b + var C̄_b). With
no bias z_b ~ N(0, 1) (t with ~128 degrees of freedom): the test requires the mean of z² over the
600 blocks ≤ 1.5 (expected 1.0 ± 0.06) and every |z_b| ≤ 5 (expected max ≈ 3.3 over 600 blocks),
and the image mean of each channel within 1 % (its seed noise is ≤ 0.03 %). At 256 spp a block mean
has a median relative noise of ~0.4 % per side, so biases above ~2 % of a block are detected.

What glTF cannot carry and petzval takes as options: f-stop, focus distance, blades, blade
rotation, sensor width (yfov only), the world colour, the pixel filter. The whole-image and bokeh
comparisons pass Blender's camera as it is (blender_scenes.cycles_equivalent): petzval's thin
lens follows Blender's conventions (no focus breathing, aperture F/N, an edge middle at the blade
rotation, Cycles' filter_width). The three `test_direct_mapping_*` tests check each convention on
its own (they were strict xfails before petzval adopted them).

Run: .venv/bin/python -m pytest tests/blender -q -s
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(
        f"Blender's Python module cannot be imported ({type(e).__name__}: {e}); the Cycles comparison "
        "needs bpy==5.0.1 on Python 3.11 (tests/run installs it from tests/requirements.txt)",
        allow_module_level=True,
    )

import blender_compare as B
import blender_scenes as S

SPP = 256  # positive comparisons: both renderers, seeds 0 and 1
SPP_CONTROL = 128  # negative controls and single-seed checks
SEEDS = (0, 1)

MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01

BOKEH_RG_TOL = 0.01  # relative, radius of gyration of a bokeh
BOKEH_FLUX_TOL = 0.015  # relative
BOKEH_CENTROID_TOL_PX = 0.1
BOKEH_ANGLE_TOL_DEG = 3.0
MAGNIFICATION_TOL = 0.002


# ------------------------------------------------------------------------------------------
# helpers


def _glb_json(path):
    data = path.read_bytes()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF"
    chunk_len, chunk_type = struct.unpack_from("<I4s", data, 12)
    assert chunk_type == b"JSON"
    return json.loads(data[20 : 20 + chunk_len])


def _block_verdict(cmp: B.BlockComparison, keep_blocks=None) -> dict:
    """The block z-scores' summary, over the blocks `keep_blocks` selects (all by default)."""
    z = cmp.z if keep_blocks is None else cmp.z[keep_blocks]
    return {
        "mean_z2": float(np.mean(z**2)),
        "max_abs_z": float(np.max(np.abs(z))),
        "n_over_4": int(np.sum(np.abs(z) > 4)),
        "n_over_5": int(np.sum(np.abs(z) > 5)),
        "n_blocks": int(z.size),
        "rel_noise_c": cmp.rel_noise_c,
        "rel_noise_p": cmp.rel_noise_p,
    }


def _passes(v: dict) -> bool:
    return v["mean_z2"] <= MAX_MEAN_Z2 and v["max_abs_z"] <= MAX_ABS_Z


def _single_seed_comparison(cyc, pz_pair, other: np.ndarray, other_spp: int) -> B.BlockComparison:
    """Blocks of a single-seed petzval render `other` (at `other_spp`) against the Cycles pair;
    its variance is taken from the petzval seed pair at SPP (one seed: ×2, fewer samples:
    ×SPP/other_spp)."""
    lum = B.luminance
    blk = 8
    n = blk * blk
    c0, c1 = (lum(x) for x in cyc)
    q0, q1 = (lum(x) for x in pz_pair)
    mean_c = B.block_sum((c0 + c1) / 2, blk) / n
    var_c = B.block_sum((c0 - c1) ** 2 / 4, blk) / n**2
    var_other = B.block_sum((q0 - q1) ** 2 / 4, blk) / n**2 * 2.0 * SPP / other_spp
    mean_o = B.block_sum(lum(other), blk) / n
    sigma = B.block_sigma(var_c, var_other, mean_c)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_c = float(np.nanmedian(np.sqrt(var_c) / np.abs(mean_c)))
        rel_o = float(np.nanmedian(np.sqrt(var_other) / np.abs(mean_o)))
    return B.BlockComparison(blk, mean_c, mean_o, sigma, B.z_scores(mean_o, mean_c, sigma), rel_c, rel_o)


def _fmt_verdict(v: dict) -> str:
    return (
        f"mean z² {v['mean_z2']:.3f} (≤ {MAX_MEAN_Z2}), max |z| {v['max_abs_z']:.2f} (≤ {MAX_ABS_Z}), "
        f"|z|>4: {v['n_over_4']}/{v['n_blocks']} blocks, |z|>5: {v['n_over_5']}"
    )


def _pixel_pitch_mm(spec: S.CameraSpec) -> float:
    return spec.sensor_mm / max(S.RESOLUTION)


def _bh_variance_1d(width_px: float) -> float:
    """Variance (px²) of a Blackman–Harris window spanning `width_px`."""
    x = np.linspace(-width_px / 2, width_px / 2, 20001)
    t = x / width_px + 0.5
    w = 0.35875 - 0.48829 * np.cos(2 * np.pi * t) + 0.14128 * np.cos(4 * np.pi * t) - 0.01168 * np.cos(6 * np.pi * t)
    return float((w * x * x).sum() / w.sum())


def _bokeh_prediction(e: S.BokehEmitter, fstop: float) -> dict:
    """Thin-lens prediction for Cycles' image of a BokehCam emitter: pixel position, circle of
    confusion (diameter across the polygon's vertices), radius of gyration of the blob
    (polygon ⊛ emitter disc ⊛ pixel filter: second moments add)."""
    spec = S.BOKEH_CAM
    F = spec.lens_mm
    pitch = _pixel_pitch_mm(spec)
    w, h = S.RESOLUTION
    d, s = e.distance_m * 1e3, spec.focus_m * 1e3
    coc_mm = (F / fstop) * F * abs(d - s) / (s * d)
    R = coc_mm / 2 / pitch
    rho = F * e.radius_m * 1e3 / d / pitch
    n = spec.blades
    poly = ((2 + math.cos(2 * math.pi / n)) / 6) * R * R
    filt = 2 * _bh_variance_1d(2 * 1.5)
    return {
        "x": w / 2 + F * math.tan(math.radians(e.side_deg)) / pitch,
        "y": h / 2,
        "coc_px": 2 * R,
        "rg": math.sqrt(poly + rho * rho / 2 + filt),
        "disc_and_filter_var": rho * rho / 2 + filt,
    }


def _coc_from_rg(rg: float, pred: dict) -> float:
    """Circle-of-confusion diameter (px, across vertices) from a measured radius of gyration."""
    n = S.BOKEH_CAM.blades
    poly = max(rg * rg - pred["disc_and_filter_var"], 0.0)
    return 2 * math.sqrt(poly / ((2 + math.cos(2 * math.pi / n)) / 6))


def _measure_bokehs(img: np.ndarray, fstop: float) -> dict:
    out = {}
    for e in S.BOKEH_EMITTERS:
        pred = _bokeh_prediction(e, fstop)
        out[e.name] = B.measure_bokeh(
            img, (pred["x"], pred["y"]), radius=max(1.6 * pred["coc_px"] / 2 + 6, 12), blades=S.BOKEH_CAM.blades
        )
    return out


# ------------------------------------------------------------------------------------------
# renders (module-scoped: each made once)


@pytest.fixture(scope="module")
def main_cycles(blender_run):
    return [B.read_rgb(blender_run.cycles(S.MAIN_CAM.name, s, SPP)) for s in SEEDS]


@pytest.fixture(scope="module")
def main_petzval(blender_run):
    args = S.petzval_cycles_args(S.MAIN_CAM)
    return [B.read_rgb(blender_run.petzval(args, s, SPP, "main")) for s in SEEDS]


@pytest.fixture(scope="module")
def bokeh_cycles(blender_run):
    return [B.read_rgb(blender_run.cycles(S.BOKEH_CAM.name, s, SPP)) for s in SEEDS]


@pytest.fixture(scope="module")
def bokeh_petzval(blender_run):
    args = S.petzval_cycles_args(S.BOKEH_CAM)
    return [B.read_rgb(blender_run.petzval(args, s, SPP, "bokeh")) for s in SEEDS]


@pytest.fixture(scope="module")
def bokeh_direct(blender_run):
    """BokehCam rendered by the direct (documented-convention) mapping."""
    return B.read_rgb(blender_run.petzval(S.petzval_direct_args(S.BOKEH_CAM), 0, SPP, "bokeh_direct"))


# ------------------------------------------------------------------------------------------
# tests


def test_gltf_export_carries_the_scene(blender_run, report):
    """What Blender's exporter writes (and what it cannot): checked so a change of exporter or
    scene shows up here first, not as an unexplained image difference."""
    g = _glb_json(blender_run.glb)
    cams = {n["name"]: g["cameras"][n["camera"]] for n in g["nodes"] if "camera" in n}
    assert set(cams) == {S.MAIN_CAM.name, S.BOKEH_CAM.name, S.ORTHO_CAM.name}
    w, h = S.RESOLUTION
    # orthographic: half the window, the larger (landscape: horizontal) side spanning the scale
    o = cams[S.ORTHO_CAM.name]["orthographic"]
    assert (o["xmag"], o["ymag"]) == (
        pytest.approx(S.ORTHO_CAM.ortho_scale / 2, rel=1e-6),
        pytest.approx(S.ORTHO_CAM.ortho_scale / 2 * h / w, rel=1e-6),
    )
    for spec in (S.MAIN_CAM, S.BOKEH_CAM):
        p = cams[spec.name]["perspective"]
        # AUTO fit, landscape: the sensor width spans the image width
        yfov = 2 * math.atan(spec.sensor_mm / 2 / spec.lens_mm * h / w)
        assert p["yfov"] == pytest.approx(yfov, rel=1e-6)
        assert p["aspectRatio"] == pytest.approx(w / h)
        # no depth of field in glTF: nothing but the projection is there
        assert set(cams[spec.name]) <= {"name", "type", "perspective"}
    lights = {lt["name"]: lt for lt in g["extensions"]["KHR_lights_punctual"]["lights"]}
    assert lights["Key"]["type"] == "point" and lights["Key"]["intensity"] == pytest.approx(
        60 / (4 * math.pi) * 683, rel=1e-5
    )
    assert lights["Spot"]["intensity"] == pytest.approx(100 / (4 * math.pi) * 683, rel=1e-5)
    assert lights["Spot"]["spot"]["outerConeAngle"] == pytest.approx(math.radians(25), rel=1e-5)
    assert lights["Sun"]["type"] == "directional" and lights["Sun"]["intensity"] == pytest.approx(0.8 * 683, rel=1e-5)
    mats = {m["name"]: m for m in g["materials"]}
    for name in ("Ground", "Red", "White"):
        ext = mats[name].get("extensions", {})
        assert ext.get("KHR_materials_specular", {}).get("specularFactor") == 0.0, (name, ext)
        assert mats[name]["pbrMetallicRoughness"].get("metallicFactor", 1.0) == 0.0
    assert mats["EmitWarm"]["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] == pytest.approx(30.0)
    report.line(
        f"glTF: {len(g['meshes'])} meshes, {len(lights)} lights (point {lights['Key']['intensity']:.1f} cd, "
        f"spot {lights['Spot']['intensity']:.1f} cd, sun {lights['Sun']['intensity']:.1f} lx), 2 cameras (yfov only)"
    )


def test_image_matches_cycles(blender_run, main_cycles, main_petzval, report):
    """The whole MainCam image, Cycles-equivalent thin lens: 8x8 block z-test and image means."""
    c0, c1 = main_cycles
    p0, p1 = main_petzval
    cmp = B.compare_blocks(c0, c1, p0, p1)
    v = _block_verdict(cmp)
    ratio = B.mean_ratio((p0 + p1) / 2, (c0 + c1) / 2)
    # noise of the image mean (two-seed averages), per channel, relative
    noise_c = np.abs(c0.mean((0, 1)) - c1.mean((0, 1))) / 2 / c0.mean((0, 1))
    noise_p = np.abs(p0.mean((0, 1)) - p1.mean((0, 1))) / 2 / p0.mean((0, 1))
    rel = np.abs(cmp.diff) / np.abs(cmp.mean_c)
    report.line(
        f"MainCam {S.RESOLUTION[0]}x{S.RESOLUTION[1]}, {SPP} spp x seeds {SEEDS}, petzval "
        + " ".join(S.petzval_cycles_args(S.MAIN_CAM))
    )
    report.line(
        "  noise floor: median relative std of an 8x8 block mean (two-seed average): Cycles "
        f"{v['rel_noise_c'] * 100:.2f} %, "
        f"petzval {v['rel_noise_p'] * 100:.2f} %; image mean seed noise ≤ "
        f"{max(noise_c.max(), noise_p.max()) * 100:.3f} %"
    )
    report.line(
        f"  blocks: {_fmt_verdict(v)}; |ΔL|/L median {np.median(rel) * 100:.2f} %, 95th pct "
        f"{np.percentile(rel, 95) * 100:.2f} %"
    )
    report.line(
        f"  image mean petzval/Cycles R,G,B: {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f} (tolerance "
        f"±{MEAN_TOL * 100:.0f} %)"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def test_bokeh_matches_cycles(bokeh_cycles, bokeh_petzval, report):
    """Depth of field itself: the blur of two tiny emitters (one 12 m away, behind the 1.2 m
    focus; one at 0.6 m, in front) on the 4x-crop BokehCam. Compared: flux, centroid, radius of
    gyration (→ circle of confusion), polygon orientation; Cycles is also checked against the
    thin-lens prediction so the measurement itself is validated."""
    n_cyc = float(bpy.data.objects[S.BOKEH_CAM.name].data.dof.aperture_fstop)
    # measured on the two-seed averages; the seed-to-seed spread of each quantity is its noise
    cyc_avg = _measure_bokehs((bokeh_cycles[0] + bokeh_cycles[1]) / 2, n_cyc)
    pz_avg = _measure_bokehs((bokeh_petzval[0] + bokeh_petzval[1]) / 2, n_cyc)
    cyc = [_measure_bokehs(im, n_cyc) for im in bokeh_cycles]
    pz = [_measure_bokehs(im, n_cyc) for im in bokeh_petzval]
    report.line(
        f"BokehCam (50 mm on a 9 mm sensor, f/{n_cyc:g}, focus {S.BOKEH_CAM.focus_m} m, 6 blades at "
        f"{S.BOKEH_CAM.rotation_deg}°), {SPP} spp x seeds {SEEDS}"
    )
    failures = []
    for e in S.BOKEH_EMITTERS:
        pred = _bokeh_prediction(e, n_cyc)
        c, p = cyc_avg[e.name], pz_avg[e.name]

        def spread(lst, attr, rel=True, name=e.name):
            a, b = (getattr(m[name], attr) for m in lst)
            d = B.angle_diff_mod(a, b, 60) if attr == "vertex_angle_deg" else a - b
            return abs(d) / 2 / (abs(a + b) / 2 if rel else 1.0)

        rg_c, rg_p = c.r_gyration, p.r_gyration
        fl_c, fl_p = c.flux, p.flux
        d_ang = B.angle_diff_mod(p.vertex_angle_deg, c.vertex_angle_deg, 60)
        dx, dy = p.cx - c.cx, p.cy - c.cy
        report.line(
            f"  {e.name} ({e.distance_m} m): CoC Cycles {_coc_from_rg(rg_c, pred):.2f} px, petzval "
            f"{_coc_from_rg(rg_p, pred):.2f} px, "
            f"thin-lens prediction {pred['coc_px']:.2f} px; r_g {rg_c:.3f} / {rg_p:.3f} px (ratio {rg_p / rg_c:.4f}, "
            f"seed noise ±{spread(cyc, 'r_gyration') * 100:.2f} % / ±{spread(pz, 'r_gyration') * 100:.2f} %, "
            f"predicted {pred['rg']:.3f}); flux ratio {fl_p / fl_c:.4f} (noise ±{spread(cyc, 'flux') * 100:.2f} % / "
            f"±{spread(pz, 'flux') * 100:.2f} %); centroid Δ ({dx:+.3f}, {dy:+.3f}) px (noise "
            f"±{math.hypot(spread(cyc, 'cx', False), spread(cyc, 'cy', False)):.3f} / "
            f"±{math.hypot(spread(pz, 'cx', False), spread(pz, 'cy', False)):.3f} px); "
            f"vertex angle Cycles {c.vertex_angle_deg:.1f}°, petzval {p.vertex_angle_deg:.1f}° (Δ {d_ang:+.1f}°, seed "
            f"noise ±{spread(cyc, 'vertex_angle_deg', False):.1f}° / ±{spread(pz, 'vertex_angle_deg', False):.1f}°)"
        )
        if abs(rg_p / rg_c - 1) > BOKEH_RG_TOL:
            failures.append(f"{e.name}: r_g ratio {rg_p/rg_c:.4f}")
        if abs(fl_p / fl_c - 1) > BOKEH_FLUX_TOL:
            failures.append(f"{e.name}: flux ratio {fl_p/fl_c:.4f}")
        if math.hypot(dx, dy) > BOKEH_CENTROID_TOL_PX:
            failures.append(f"{e.name}: centroid differs by ({dx:.3f}, {dy:.3f}) px")
        if abs(d_ang) > BOKEH_ANGLE_TOL_DEG:
            failures.append(f"{e.name}: polygon orientation differs by {d_ang:.1f}°")
        # the measurement itself: Cycles against the thin-lens prediction
        if abs(rg_c / pred["rg"] - 1) > 0.03:
            failures.append(
                f"{e.name}: Cycles r_g {rg_c:.3f} px is not the predicted {pred['rg']:.3f} px (measurement broken?)"
            )
    assert not failures, "; ".join(failures)


def test_negative_controls_fail_the_metric(blender_run, main_cycles, main_petzval, bokeh_cycles, report):
    """The metric must be able to fail: petzval rendered with the Cycles camera at f/1.4 instead
    of f/2.8, and focused at 1.0 m instead of 1.5 m (same field of view), must be rejected by the
    very criteria the real comparison passes, although their image means still agree (so only
    the depth of field is wrong); the bokeh at f/1.4 must be ~2x as large."""
    lines = []
    for label, kw in (
        ("f-stop halved (f/1.4)", {"fstop_scale": 0.5}),
        ("focus 1.0 m instead of 1.5 m", {"focus_m": 1.0}),
    ):
        args = S.petzval_cycles_args(S.MAIN_CAM, **kw)
        img = B.read_rgb(
            blender_run.petzval(args, 7, SPP_CONTROL, "control_" + ("fstop" if "fstop_scale" in kw else "focus"))
        )
        v = _block_verdict(_single_seed_comparison(main_cycles, main_petzval, img, SPP_CONTROL))
        ratio = B.mean_ratio(img, (main_cycles[0] + main_cycles[1]) / 2)
        lines.append((label, v, ratio))
        report.line(
            f"  negative control, MainCam {label} ({SPP_CONTROL} spp): {_fmt_verdict(v)}; image mean ratio "
            f"{ratio.mean():.4f}"
        )
        # a valid control differs in depth of field only: its overall brightness still matches
        assert np.all(np.abs(ratio - 1) <= MEAN_TOL), (
            f"control {label}: image mean ratio {ratio} (not a depth-of-field-only change)"
        )
        assert not _passes(v), f"the metric did not notice: {label}: {_fmt_verdict(v)}"
    n_cyc = float(bpy.data.objects[S.BOKEH_CAM.name].data.dof.aperture_fstop)
    img = B.read_rgb(
        blender_run.petzval(S.petzval_cycles_args(S.BOKEH_CAM, fstop_scale=0.5), 7, SPP_CONTROL, "control_bokeh_fstop")
    )
    wide = _measure_bokehs(img, n_cyc / 2)
    for e in S.BOKEH_EMITTERS:
        rg_c = np.mean([_measure_bokehs(im, n_cyc)[e.name].r_gyration for im in bokeh_cycles])
        r = wide[e.name].r_gyration / rg_c
        report.line(
            f"  negative control, BokehCam f-stop halved: {e.name} r_g ratio {r:.3f} (tolerance "
            f"±{BOKEH_RG_TOL * 100:.0f} %)"
        )
        assert abs(r - 1) > BOKEH_RG_TOL


def test_direct_mapping_field_of_view(bokeh_cycles, bokeh_direct, report):
    """Focal length from the exported yfov, Blender's f-stop and focus as they are: the image
    scale must be Cycles' (measured from the separation of the two emitters' centroids)."""
    n = float(bpy.data.objects[S.BOKEH_CAM.name].data.dof.aperture_fstop)
    c = _measure_bokehs(bokeh_cycles[0], n)
    p = _measure_bokehs(bokeh_direct, n)
    a, b = (e.name for e in S.BOKEH_EMITTERS)
    sep_c = math.hypot(c[a].cx - c[b].cx, c[a].cy - c[b].cy)
    sep_p = math.hypot(p[a].cx - p[b].cx, p[a].cy - p[b].cy)
    mag = sep_p / sep_c
    f, s = S.BOKEH_CAM.lens_mm, S.BOKEH_CAM.focus_m * 1e3
    report.line(
        f"  direct mapping (`{' '.join(S.petzval_direct_args(S.BOKEH_CAM))}`): image scale petzval/Cycles {mag:.4f} "
        f"(thin-lens breathing 1/(1 − f/s) = {1 / (1 - f / s):.4f}; tolerance ±{MAGNIFICATION_TOL*100:.1f} %)"
    )
    assert abs(mag - 1) <= MAGNIFICATION_TOL


def test_direct_mapping_blade_rotation(bokeh_cycles, bokeh_direct, report):
    """Blender's aperture_rotation passed as --aperture blades:N:ROT: the bokeh polygon must have
    Cycles' orientation."""
    n = float(bpy.data.objects[S.BOKEH_CAM.name].data.dof.aperture_fstop)
    c = _measure_bokehs(bokeh_cycles[0], n)
    p = _measure_bokehs(bokeh_direct, n)
    diffs = [B.angle_diff_mod(p[e.name].vertex_angle_deg, c[e.name].vertex_angle_deg, 60) for e in S.BOKEH_EMITTERS]
    report.line(
        f"  direct mapping: polygon vertex angle petzval − Cycles: {', '.join(f'{d:+.1f}°' for d in diffs)} "
        f"(180°/N = {180 / S.BOKEH_CAM.blades:.0f}°; tolerance ±{BOKEH_ANGLE_TOL_DEG:.0f}°)"
    )
    assert all(abs(d) <= BOKEH_ANGLE_TOL_DEG for d in diffs)


def test_direct_mapping_pixel_filter(blender_run, main_cycles, main_petzval, report):
    """Cycles' filter_width passed as --filter-width as it is (everything else Cycles-equivalent):
    the image must still match."""
    args = S.petzval_cycles_args(S.MAIN_CAM)
    i = args.index("--filter-width")
    args[i + 1] = S._num(bpy.context.scene.cycles.filter_width)
    img = B.read_rgb(blender_run.petzval(args, 7, SPP_CONTROL, "filter_direct"))
    v = _block_verdict(_single_seed_comparison(main_cycles, main_petzval, img, SPP_CONTROL))
    report.line(
        f"  direct mapping: --filter-width {args[i + 1]} (Cycles' filter_width as it is), MainCam {SPP_CONTROL} spp: "
        f"{_fmt_verdict(v)}"
    )
    assert _passes(v), _fmt_verdict(v)


def test_speed_against_cycles(blender_run, report):
    """The issue's benchmark: equal resolution, samples and threads (2) on MainCam, both timed
    here, back to back: wall time of one render call (Cycles: bpy.ops.render.render including
    its scene sync; petzval: the whole process including loading the GLB) and CPU time (all
    threads; less sensitive to other work on a shared machine). Reported, not asserted: the
    target is petzval ≤ 0.5x Cycles."""
    blender_run.cycles(S.MAIN_CAM.name, 0, 1, cache=False)  # warm-up (kernel and scene set-up)
    c_name = f"cycles_{S.MAIN_CAM.name}_spp{SPP}_seed3"
    blender_run.cycles(S.MAIN_CAM.name, 3, SPP, cache=False)
    out = blender_run.petzval(S.petzval_cycles_args(S.MAIN_CAM), 3, SPP, "speed")
    t_cyc, cpu_cyc = blender_run.timings[c_name], blender_run.cpu_times[c_name]
    t_pz, cpu_pz = blender_run.timings[out.stem], blender_run.cpu_times[out.stem]
    inner = [ln for ln in blender_run.stderr[out.stem].splitlines() if ln.startswith("rendered ")]
    w, h = S.RESOLUTION
    report.line(
        f"speed, MainCam {w}x{h} at {SPP} spp, 2 threads each: wall Cycles {t_cyc:.1f} s, petzval {t_pz:.1f} s "
        f"(ratio {t_pz / t_cyc:.2f}); CPU Cycles {cpu_cyc:.1f} s, petzval {cpu_pz:.1f} s (ratio "
        f"{cpu_pz / cpu_cyc:.2f}); "
        f"target ≤ 0.5. petzval: {inner[-1] if inner else '?'}"
    )
