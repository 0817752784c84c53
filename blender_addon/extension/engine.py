"""The Petzval render engine: F12 and animation renders through ``petzval.render``."""

from __future__ import annotations

import time
import traceback

import bpy
import numpy as np

from . import camera as camera_mod
from . import export as export_mod
from . import native
from . import viewport as viewport_mod
from .notes import Notes

# Background depth (Blender's Z pass convention: a large finite number, as Cycles writes).
BACKGROUND_DEPTH = 1.0e10

# Diagnostics of the most recent renders (what was sent to the native module, what came back),
# newest last, for tests and bug reports. Arrays are left out.
RENDER_LOG: list[dict] = []
_RENDER_LOG_MAX = 16


def _log(entry: dict) -> None:
    RENDER_LOG.append(entry)
    del RENDER_LOG[:-_RENDER_LOG_MAX]


def _to_rect(img: np.ndarray) -> np.ndarray:
    """A top-row-first (H, W[, C]) image as the flat bottom-row-first buffer of a RenderPass."""
    return np.ascontiguousarray(img[::-1], dtype=np.float32).reshape(-1)


class PetzvalRenderEngine(bpy.types.RenderEngine):
    bl_idname = "PETZVAL"
    bl_label = "Petzval"
    bl_use_preview = False
    bl_use_eevee_viewport = True  # Material Preview uses EEVEE; Rendered shading is our preview (view_draw)
    bl_use_postprocess = True

    # -- passes

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        if renderlayer is not None and renderlayer.use_pass_z:
            self.register_pass(scene, renderlayer, "Depth", 1, "Z", "VALUE")

    # -- cancel

    def _should_stop(self) -> bool:
        """True when the user cancelled (Esc); a separate method so tests can drive it."""
        return bool(self.test_break())

    # -- render

    def render(self, depsgraph):
        t0 = time.perf_counter()
        entry = {"frame": depsgraph.scene_eval.frame_current, "started": t0, "error": None}
        _log(entry)
        try:
            self._render(depsgraph, entry)
        except Exception as e:  # never let an exception escape into Blender's render loop
            msg = _error_message(e)
            entry["error"] = msg
            print(f"Petzval: render failed: {msg}\n{traceback.format_exc()}")
            self.report({"ERROR"}, f"Petzval: {msg}")
            self.error_set(f"Petzval: {msg}")
        finally:
            entry["seconds_total"] = time.perf_counter() - t0
            entry["returned"] = time.perf_counter()

    def _render(self, depsgraph, entry: dict) -> None:
        pz = native.get()
        scene = depsgraph.scene_eval
        view_layer = depsgraph.view_layer_eval
        notes = Notes()

        cam_obj = self.camera_override or scene.camera
        if cam_obj is None:
            raise camera_mod.SettingsError("the scene has no camera")
        if cam_obj.type != "CAMERA":
            raise camera_mod.SettingsError(f"the active camera '{cam_obj.name}' is not a camera")
        cam_eval = cam_obj.evaluated_get(depsgraph)

        width, height = self.resolution_x, self.resolution_y
        if width <= 0 or height <= 0:
            width, height = camera_mod.frame_size(scene)
        r = scene.render
        if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6:
            notes.warn("non-square pixel aspect (square pixels rendered)")
        if r.use_motion_blur:
            notes.warn("motion blur")
        if r.use_multiview:
            notes.warn("stereoscopy / multi-view (the active view rendered)")
        window = camera_mod.border_window(scene, width, height)
        crop = camera_mod.crop_top_first(window, height) if window else None
        out_w, out_h = (window[2] - window[0], window[3] - window[1]) if window else (width, height)

        cam_kw = camera_mod.camera_kwargs(scene, cam_eval, depsgraph, notes)
        # a bad camera setting or lens fails here, before the scene is translated
        pz_camera = pz.Camera(**cam_kw)
        if cam_kw["lens"] not in ("thin", "pinhole"):
            pz.Lens(cam_kw["lens"])
        render_kw = camera_mod.render_kwargs(scene, scene.frame_current)

        self.update_stats("", "Petzval | Translating scene")
        t_scene = time.perf_counter()
        pz_scene, stats = export_mod.build(pz, depsgraph, notes, stop=self._should_stop)
        entry["seconds_scene"] = time.perf_counter() - t_scene
        if pz_scene is None:
            entry["cancelled_before_render"] = True
            # Blender expects a result from every render (writing a still without one crashes
            # Blender 5.0): an empty, fully transparent image
            self._empty_result(out_w, out_h, view_layer.name)
            return
        export_mod.add_world(pz_scene, scene.world, notes, None)
        _apply_film(pz_scene, scene, notes)

        want_depth = bool(view_layer.use_pass_z)
        entry["kwargs"] = {
            k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in {**cam_kw, **render_kw}.items()
        }
        entry["kwargs"].update({"width": width, "height": height, "crop": crop})
        entry["triangles"] = pz_scene.triangle_count
        entry["stats"] = stats

        result = self.begin_result(0, 0, out_w, out_h, layer=view_layer.name)
        if result.resolution_x != out_w or result.resolution_y != out_h:
            self.end_result(result, cancel=True)
            raise camera_mod.SettingsError(
                f"render result is {result.resolution_x}x{result.resolution_y}, "
                f"expected {out_w}x{out_h} (border {window})"
            )
        layer = result.layers[0]
        spp = render_kw["spp"]
        lens_label = cam_kw["lens"] if cam_kw["lens"] in ("thin", "pinhole") else cam_eval.data.petzval.lens
        state = {"stop_at": None, "updates": 0, "callbacks": 0}

        def progress(fraction, spp_done, rgba):
            state["callbacks"] += 1
            try:
                if rgba is not None:
                    self._write(layer, rgba, opaque=not r.film_transparent)
                    self.update_result(result)
                    state["updates"] += 1
                self.update_progress(min(max(float(fraction), 0.0), 1.0))
                self.update_stats("", f"Petzval | {lens_label} | Sample {spp_done}/{spp}")
                stop = self._should_stop()
            except Exception:
                traceback.print_exc()
                stop = True
            if stop and state["stop_at"] is None:
                state["stop_at"] = time.perf_counter()
            return not stop

        completed = False
        try:
            t_render = time.perf_counter()
            try:
                out = pz.render(pz_scene, pz_camera, width, height, crop=crop,
                                progress=progress, progress_interval_s=0.1, **render_kw)
            except pz.CancelledError:
                entry["cancelled"] = True
                entry["seconds_render"] = time.perf_counter() - t_render
                entry["stop_requested"] = state["stop_at"]
                return
            entry["seconds_render"] = time.perf_counter() - t_render
            entry["stop_requested"] = state["stop_at"]
            entry["progress_callbacks"] = state["callbacks"]
            entry["result_updates"] = state["updates"]
            for k in ("spp", "complete", "seconds", "lens_model", "lens_model_reason"):
                entry[k] = out.get(k)
            rgba = out["rgba"]
            if rgba.shape[:2] != (out_h, out_w):
                raise RuntimeError(
                    f"petzval.render returned {rgba.shape[1]}x{rgba.shape[0]} pixels, expected {out_w}x{out_h}"
                )
            self._write(layer, rgba, opaque=not r.film_transparent)
            if want_depth and "Depth" in layer.passes:
                depth = np.where(np.isfinite(out["depth"]), out["depth"], BACKGROUND_DEPTH)
                layer.passes["Depth"].rect.foreach_set(_to_rect(depth))
            for w in list(out.get("warnings", [])) + list(pz_scene.warnings):
                notes.warn(w)
            completed = True
        finally:
            self.end_result(result)
        if completed:
            model = entry.get("lens_model")
            info = f"Petzval | {lens_label} ({model}) | {entry.get('spp')} spp in {entry.get('seconds', 0):.1f} s"
            if not entry.get("complete", True):
                info += " (stopped early)"
            self.update_stats("", info)
        summary = notes.summary()
        entry["notes"] = {"unsupported": notes.unsupported, "info": notes.info}
        if summary:
            print(f"Petzval: {summary}")
            if notes.unsupported:
                self.report({"WARNING"}, f"Petzval: {summary}")
            else:
                self.report({"INFO"}, f"Petzval: {summary}")

    # -- viewport preview (Rendered shading)

    def __del__(self):
        preview = getattr(self, "_preview", None)
        if preview is not None:
            preview.cancel(wait_s=0.0)

    def view_update(self, context, depsgraph):
        """Any change of the scene: translate it again; the next draw restarts the preview."""
        try:
            pz = native.get()
            notes = Notes()
            pz_scene, _ = export_mod.build(pz, depsgraph, notes)
            if pz_scene is not None:
                export_mod.add_world(pz_scene, depsgraph.scene_eval.world, notes, None)
                _apply_film(pz_scene, depsgraph.scene_eval, notes)
            self._vp_scene = pz_scene
            self._vp_error = None
        except Exception as e:
            self._vp_scene = None
            self._vp_error = _error_message(e)
            traceback.print_exc()
        self._vp_key = None

    def _view_kwargs(self, context, depsgraph) -> dict:
        """Camera arguments of the view being drawn (see viewport.py)."""
        scene = depsgraph.scene_eval
        rv3d = context.region_data
        if rv3d.view_perspective == "CAMERA" and scene.camera is not None and scene.camera.type == "CAMERA":
            return camera_mod.camera_kwargs(scene, scene.camera.evaluated_get(depsgraph), depsgraph, Notes())
        space = context.space_data
        view = rv3d.view_matrix.inverted()
        vignetting = bool(scene.petzval.natural_vignetting)
        if not rv3d.is_perspective:
            return viewport_mod.free_ortho_view_kwargs(
                view, rv3d.view_distance, space.lens, space.clip_end, natural_vignetting=vignetting
            )
        return viewport_mod.free_view_kwargs(
            view, space.lens, space.clip_start, space.clip_end, natural_vignetting=vignetting
        )

    def view_draw(self, context, depsgraph):
        """Draws the newest pass of the preview, (re)starting it when the view changed."""
        import gpu
        from gpu_extras.presets import draw_texture_2d

        region = context.region
        scene = depsgraph.scene_eval
        settings = scene.petzval
        divisor = max(1, int(settings.viewport_divisor))
        w, h = max(1, region.width // divisor), max(1, region.height // divisor)
        preview = getattr(self, "_preview", None)
        try:
            if getattr(self, "_vp_scene", None) is None and getattr(self, "_vp_error", None) is None:
                self.view_update(context, depsgraph)
            if self._vp_scene is not None:
                kw = self._view_kwargs(context, depsgraph)
                render_kw = camera_mod.render_kwargs(scene, scene.frame_current)
                render_kw.pop("spp")
                # the preview methods have no adaptive sampling; the viewport refines every pixel
                render_kw["adaptive_threshold"] = 0.0
                render_kw["method"] = settings.viewport_method.lower()
                key = viewport_mod.view_key({**kw, **render_kw}, w, h)
                if key != getattr(self, "_vp_key", None):
                    if preview is not None:
                        preview.cancel(wait_s=0.5)
                    preview = self._preview = viewport_mod.PreviewRender(
                        native.get(), self._vp_scene, kw, render_kw, w, h, int(settings.viewport_samples))
                    self._vp_key = key
        except Exception as e:
            self._vp_error = _error_message(e)
        error = getattr(self, "_vp_error", None) or (preview.error if preview is not None else None)
        if error:
            self.update_stats("", f"Petzval viewport: {error}")
        rgba = preview.latest() if preview is not None else None
        if rgba is not None:
            hh, ww = rgba.shape[:2]
            img = viewport_mod.display_pixels(rgba, transparent=bool(scene.render.film_transparent))
            buf = gpu.types.Buffer("FLOAT", ww * hh * 4, img.ravel())
            texture = gpu.types.GPUTexture((ww, hh), format="RGBA16F", data=buf)
            gpu.state.blend_set("ALPHA_PREMULT")
            self.bind_display_space_shader(scene)
            draw_texture_2d(texture, (0, 0), region.width, region.height)
            self.unbind_display_space_shader()
            gpu.state.blend_set("NONE")
            if not error:
                self.update_stats("", f"Petzval viewport | Sample {preview.spp_done}/{preview.spp}")
        if preview is not None and not preview.finished:
            self.tag_redraw()

    def _empty_result(self, width: int, height: int, layer: str) -> None:
        """Opens and closes a result of zeros (a render that stopped before it had pixels)."""
        result = self.begin_result(0, 0, width, height, layer=layer)
        if result is not None:
            self.end_result(result)

    @staticmethod
    def _write(layer, rgba: np.ndarray, opaque: bool) -> None:
        img = np.array(rgba, dtype=np.float32, copy=True)
        if opaque:
            img[..., 3] = 1.0
        layer.passes["Combined"].rect.foreach_set(_to_rect(img))


def _apply_film(pz_scene, scene, notes) -> None:
    """Film settings shared by the final render and the viewport preview. Film > Transparent: the
    world lights the scene but the background is RGBA 0 (premultiplied, as Cycles)."""
    transparent = bool(scene.render.film_transparent)
    pz_scene.transparent_background = transparent
    if transparent and getattr(getattr(scene, "cycles", None), "film_transparent_glass", False):
        notes.warn("transparent film: Transparent Glass (glass rendered opaque)")


def _error_message(e: Exception) -> str:
    """One line for the report: settings errors as they are, others with their type (petzval's
    errors name the file, line and field themselves)."""
    if isinstance(e, FileNotFoundError):
        return f"file not found: {e.filename or e}"
    text = str(e) or type(e).__name__
    if isinstance(e, (camera_mod.SettingsError, ImportError)):
        return text
    return f"{type(e).__name__}: {text}"


classes = (PetzvalRenderEngine,)
