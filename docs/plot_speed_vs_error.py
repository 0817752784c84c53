#!/usr/bin/env python3
"""Draw docs/speed-vs-error.svg from the JSON of `petzval bench lens-models` and
`petzval bench render-models` (standard library only).

    python3 docs/plot_speed_vs_error.py render-models.json lens-models-1.json [lens-models-2.json ...] \
        -o docs/speed-vs-error.svg

With several lens-models runs, each model's time is the smallest over the runs (the errors are
deterministic; on a shared machine interference only ever adds time).

Left: mean image error (px of a 1920-px-wide 36 mm sensor, log scale) against ns per camera
ray for each lens model, with the issue's targets (≤ 0.1 px, ≥ 10× faster than exact).
Right: mean LDR-FLIP of each model's render of the demo against the exact render, against
render seconds, with the noise floor (the exact model with another seed).
"""

import argparse
import json
import math
import sys

W, H = 980, 430
PANEL_W, PANEL_H = 400, 300
LEFT = (70, 60)
RIGHT = (560, 60)
COLOURS = {"exact": "#222", "pinhole": "#b35806", "thin": "#e08214", "thick": "#8073ac", "lrtf": "#1b7837"}


def esc(s):
    return str(s).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


class Axes:
    """A log-log or lin-log panel."""

    def __init__(self, origin, xr, yr, xlog, ylog):
        self.ox, self.oy = origin
        self.xr, self.yr, self.xlog, self.ylog = xr, yr, xlog, ylog
        self.out = []

    def _t(self, v, r, log):
        a, b = (math.log10(r[0]), math.log10(r[1])) if log else r
        v = math.log10(max(v, 1e-300)) if log else v
        return (v - a) / (b - a)

    def x(self, v):
        return self.ox + PANEL_W * self._t(v, self.xr, self.xlog)

    def y(self, v):
        return self.oy + PANEL_H * (1 - self._t(v, self.yr, self.ylog))

    def frame(self, title, xlabel, ylabel, xticks, yticks):
        o = self.out
        o.append(f'<rect x="{self.ox}" y="{self.oy}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#444"/>')
        o.append(
            f'<text x="{self.ox + PANEL_W / 2}" y="{self.oy - 22}" text-anchor="middle" font-size="14" '
            f'font-weight="bold">{esc(title)}</text>'
        )
        o.append(
            f'<text x="{self.ox + PANEL_W / 2}" y="{self.oy + PANEL_H + 38}" text-anchor="middle" '
            f'font-size="12">{esc(xlabel)}</text>'
        )
        cx, cy = self.ox - 52, self.oy + PANEL_H / 2
        o.append(
            f'<text x="{cx}" y="{cy}" text-anchor="middle" font-size="12" transform="rotate(-90 {cx} '
            f'{cy})">{esc(ylabel)}</text>'
        )
        for v in xticks:
            X = self.x(v)
            o.append(f'<line x1="{X:.1f}" y1="{self.oy}" x2="{X:.1f}" y2="{self.oy + PANEL_H}" stroke="#ddd"/>')
            o.append(f'<text x="{X:.1f}" y="{self.oy + PANEL_H + 16}" text-anchor="middle" font-size="11">{v:g}</text>')
        for v in yticks:
            Y = self.y(v)
            o.append(f'<line x1="{self.ox}" y1="{Y:.1f}" x2="{self.ox + PANEL_W}" y2="{Y:.1f}" stroke="#ddd"/>')
            o.append(f'<text x="{self.ox - 6}" y="{Y + 4:.1f}" text-anchor="end" font-size="11">{v:g}</text>')

    def hline(self, v, label, colour="#c51b7d"):
        Y = self.y(v)
        self.out.append(
            f'<line x1="{self.ox}" y1="{Y:.1f}" x2="{self.ox + PANEL_W}" y2="{Y:.1f}" stroke="{colour}" '
            'stroke-dasharray="5,4"/>'
        )
        self.out.append(
            f'<text x="{self.ox + PANEL_W - 4}" y="{Y - 5:.1f}" text-anchor="end" font-size="11" '
            f'fill="{colour}">{esc(label)}</text>'
        )

    def vline(self, v, label, colour="#c51b7d"):
        X = self.x(v)
        self.out.append(
            f'<line x1="{X:.1f}" y1="{self.oy}" x2="{X:.1f}" y2="{self.oy + PANEL_H}" stroke="{colour}" '
            'stroke-dasharray="5,4"/>'
        )
        self.out.append(f'<text x="{X + 4:.1f}" y="{self.oy + 14}" font-size="11" fill="{colour}">{esc(label)}</text>')

    def point(self, x, y, colour, label, dx=6, dy=-6, anchor="start"):
        X, Y = self.x(x), self.y(y)
        self.out.append(f'<circle cx="{X:.1f}" cy="{Y:.1f}" r="4" fill="{colour}"/>')
        if label:
            self.out.append(
                f'<text x="{X + dx:.1f}" y="{Y + dy:.1f}" font-size="11" text-anchor="{anchor}" '
                f'fill="{colour}">{esc(label)}</text>'
            )

    def polyline(self, pts, colour):
        d = " ".join(f"{self.x(a):.1f},{self.y(b):.1f}" for a, b in pts)
        self.out.append(f'<polyline points="{d}" fill="none" stroke="{colour}" stroke-width="1.5"/>')


def decade_ticks(lo, hi):
    ticks = []
    e = math.floor(math.log10(lo))
    while 10**e <= hi * 1.0001:
        for m in (1, 2, 5):
            v = m * 10**e
            if lo <= v <= hi:
                ticks.append(round(v, 12))
        e += 1
    return ticks


def print_table(lm, runs):
    def f(v, fmt):
        return "" if v is None else format(v, fmt)

    print(f"Smallest time over {runs} runs (each run: best of 5).")
    print()
    print(
        "| model | res | ns/ray | lookup alone ns | speed-up | ns/ray raster | speed-up raster | pos µm | dir mrad | "
        "mean px | max px | misclassified | exact fallback | MiB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in lm:
        mis = r.get("misclassified_fraction")
        unc = r.get("uncertain_fraction")
        print(
            f"| {r['model']} | {f(r.get('resolution'), 'd')} | {r['ns_per_ray']:.0f} | "
            f"{f(r.get('lookup_ns'), '.0f')} | "
            f"{f(r.get('speedup_vs_exact'), '.1f')}{'×' if r.get('speedup_vs_exact') else ''} | "
            f"{f(r.get('ns_per_ray_raster'), '.0f')} | "
            f"{f(r.get('speedup_vs_exact_raster'), '.1f')}{'×' if r.get('speedup_vs_exact_raster') else ''} | "
            f"{f(r.get('mean_position_error_um'), '.1f') or '–'} | {r['mean_direction_error_mrad']:.4f} | "
            f"{r['mean_image_error_px']:.3f} | {r['max_image_error_px']:.2f} | "
            f"{'–' if mis is None else f'{100 * mis:.3f} %'} | {'' if unc is None else f'{100 * unc:.1f} %'} | "
            f"{f(r.get('table_mib'), '.1f')} |"
        )
    print()


TIME_KEYS = ("ns_per_ray", "lookup_ns", "ns_per_ray_raster", "lookup_ns_raster")


def min_times(runs, lens):
    """One row per (model, resolution): the first run's row with each time the smallest."""
    rows = {}
    for run in runs:
        for r in run:
            if r["lens"] != lens:
                continue
            k = (r["model"], r.get("resolution"))
            if k not in rows:
                rows[k] = dict(r)
                continue
            for t in TIME_KEYS:
                if r.get(t) is not None:
                    rows[k][t] = min(rows[k][t], r[t])
    for r in rows.values():
        if r.get("speedup_vs_exact") is not None:
            exact = rows[("exact", None)]["ns_per_ray"]
            r["speedup_vs_exact"] = exact / r["ns_per_ray"]
            r["speedup_vs_exact_raster"] = exact / r["ns_per_ray_raster"]
    return list(rows.values())


def _load_json(path):
    with open(path) as fh:
        return json.load(fh)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("render_models", help="JSON of `petzval bench render-models --json`")
    ap.add_argument("lens_models", nargs="+", help="JSON of `petzval bench lens-models --json` (one or more runs)")
    ap.add_argument("-o", "--output", default="docs/speed-vs-error.svg")
    ap.add_argument("--lens", default="double-gauss-50mm")
    ap.add_argument(
        "--table", action="store_true", help="also print the per-ray table (markdown) with the minimum times"
    )
    a = ap.parse_args()
    lm = min_times([_load_json(f) for f in a.lens_models], a.lens)
    rm = _load_json(a.render_models)
    if not lm or not rm:
        sys.exit(f"no rows for {a.lens}")
    exact = next(r for r in lm if r["model"] == "exact")
    if a.table:
        print_table(lm, len(a.lens_models))
    floor_px = 0.01  # where the exact model (error 0) is drawn
    # Left panel: error (px) against ns per ray.
    ns = [r["ns_per_ray"] for r in lm] + [exact["ns_per_ray"] / 10]
    xr = (min(ns) * 0.7, max(ns) * 1.6)
    left = Axes(LEFT, xr, (floor_px * 0.7, 30), True, True)
    left.frame(
        f"Per ray: {a.lens}",
        "ns per camera ray (1 thread, log)",
        "mean image error, px (log)",
        decade_ticks(*xr),
        [0.01, 0.1, 1, 10],
    )
    left.hline(0.1, "target ≤ 0.1 px")
    left.vline(exact["ns_per_ray"] / 10, "target ≥ 10× exact")
    left.point(exact["ns_per_ray"], floor_px, COLOURS["exact"], "exact (error 0)", dx=-6, anchor="end")
    lrtf = sorted((r for r in lm if r["model"] == "lrtf"), key=lambda r: r["resolution"])
    left.polyline([(r["ns_per_ray"], r["mean_image_error_px"]) for r in lrtf], COLOURS["lrtf"])
    for r in lrtf:
        left.point(r["ns_per_ray"], r["mean_image_error_px"], COLOURS["lrtf"], f'LRTF {r["resolution"]}³')
    analytic = [r for r in lm if r["model"] in ("pinhole", "thin", "thick")]
    for i, r in enumerate(analytic):
        left.point(
            r["ns_per_ray"], r["mean_image_error_px"], COLOURS[r["model"]], f"{r['model']} (distortion)", dy=-6 - 13 * i
        )
    # Right panel: mean FLIP against render seconds.
    secs = [r["seconds"] for r in rm]
    flips = [r["flip_mean"] for r in rm if r["flip_mean"] > 0]
    right = Axes(RIGHT, (0, max(secs) * 1.25), (min(flips) * 0.5, 1.0), False, True)
    step = 10 ** math.floor(math.log10(max(secs) * 1.25 / 2))
    xt = [i * step for i in range(0, int(max(secs) * 1.25 / step) + 1)]
    first = rm[0]
    right.frame(
        f"Demo render {first['width']}x{first['height']}, {first['spp']} spp",
        "render seconds (2 threads)",
        "mean LDR-FLIP vs exact (log)",
        xt,
        decade_ticks(min(flips) * 0.5, 1.0),
    )
    noise = next((r for r in rm if "noise" in r["model"]), None)
    if noise:
        right.hline(noise["flip_mean"], "noise floor (exact, other seed)", "#666")
    pts = []
    for r in rm:
        if r["flip_mean"] <= 0 or "noise" in r["model"]:
            continue
        name = r["model"] + (f' {r["resolution"]}³' if r.get("resolution") else "")
        colour = COLOURS.get(r["model"], "#000")
        below = r["model"] == "thin"
        right.point(
            r["seconds"],
            r["flip_mean"],
            colour,
            name,
            dx=-6 if below else 6,
            dy=16 if below else -6,
            anchor="end" if below else "start",
        )
        if r["model"] == "lrtf":
            pts.append((r["seconds"], r["flip_mean"]))
    right.point(rm[0]["seconds"], min(flips) * 0.5, COLOURS["exact"], "exact (0)", dy=-6)
    if pts:
        right.polyline(pts, COLOURS["lrtf"])
    body = "\n".join(left.out + right.out)
    svg = (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" '
        f'''font-family="sans-serif">
<rect width="{W}" height="{H}" fill="white"/>
{body}
</svg>
'''
    )
    with open(a.output, "w") as f:
        f.write(svg)
    print(f"wrote {a.output}")


if __name__ == "__main__":
    main()
