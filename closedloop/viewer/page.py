"""The overlay of the viewer page: title, HTML legend in screen space, page script.

The legend (a fixed ``<div id="closedloop-legend">`` over the WebGL canvas, so it reads
the same from any view point; drawn at 70 % in a window narrower than 1100 px or lower
than 760 px, at 50 % below 700 x 500 px, to leave the robot in view) gives the model and
pose, the wrench components, the amplification, the real largest displacement and link
rotation with the caps of the automatic amplification, the loaded frame's displacement
(mm, deg), and the colour key of ghost, deflected robot, arrows, ellipsoids and grid.

The page script waits until the scene has loaded (both robots' meshes and the load-ramp
animation are in the page), then arms the animation: it loops (ping-pong: load, unload),
plays at once with ``autoplay``, else it rests on the fully loaded pose and the time
slider of meshcat's "Animations" panel scrubs it. ``document.body.dataset.closedloop``
becomes ``"ready"`` then.

In the live page an amplification slider (``<div id="closedloop-slider">``, logarithmic,
1/``SLIDER_RANGE`` to ``SLIDER_RANGE`` times the amplification shown) sends the chosen
amplification to the server (websocket message ``{"type": "closedloop",
"amplification": s}``); the Python side redraws the scene and the page reloads itself
once the new scene arrives.
"""

from __future__ import annotations

import html
import json

import numpy as np

from closedloop.viewer.ellipsoids import vector_norm

#: three.js loop mode of the ramp (THREE.LoopPingPong: 0 -> 1 -> 0 -> ...).
LOOP_PING_PONG = 2202
#: Milliseconds between two checks of the page script that the scene has loaded.
POLL_MS = 50
#: The live slider spans [s / SLIDER_RANGE, s * SLIDER_RANGE] (s the amplification shown).
SLIDER_RANGE = 20.0
#: Milliseconds the live page waits, after the first message of a redrawn scene, to reload.
RELOAD_MS = 800

_STYLE = """<style>
#closedloop-legend { position: fixed; left: 8px; top: 8px; z-index: 10; max-width: 44em;
  padding: 6px 9px; background: rgba(255, 255, 255, 0.88); color: #111; border-radius: 4px;
  font: 11px/1.3 sans-serif; pointer-events: none; box-shadow: 0 0 3px rgba(0, 0, 0, 0.3); }
#closedloop-legend .cl-head { font-weight: bold; font-size: 13px; }
#closedloop-legend table { border-collapse: collapse; margin-top: 3px; }
#closedloop-legend td { padding: 0 4px 0 0; vertical-align: middle; }
#closedloop-legend .cl-swatch { display: inline-block; height: 11px; border: 1px solid #555; }
#closedloop-legend td:first-child { white-space: nowrap; }
#closedloop-legend .cl-bar-title { margin-top: 4px; }
#closedloop-legend .cl-bar .cl-swatch { height: 10px; }
#closedloop-legend .cl-ticks { display: flex; justify-content: space-between; width: 302px; }
@media (max-width: 1100px), (max-height: 760px) {
  #closedloop-legend { transform: scale(0.7); transform-origin: 0 0; } }
@media (max-width: 700px), (max-height: 500px) {
  #closedloop-legend { transform: scale(0.5); } }
</style>"""

_SCRIPT = """<script>
(function () {
  var cfg = %(config)s;
  function robots() {
    var node = viewer.scene_tree.children["meshcat"];
    node = node && node.children["%(robots)s"];
    node = node && node.children["<object>"];
    return node ? node.object : null;
  }
  function meshes() {
    var n = 0, root = robots();
    if (root) root.traverse(function (o) { if (o.isMesh) n += 1; });
    return n;
  }
  var armed = null;
  function arm() {
    var animator = viewer.animator;
    if (meshes() < cfg.meshes) return;
    if (cfg.animate && (animator.actions.length < cfg.clips || armed === animator.actions)) return;
    if (cfg.animate) {
      // three.js binds a clip's tracks when the action is created: the animation may have
      // come before the meshes (commands load asynchronously), so bind it again now.
      var mixer = animator.mixer;
      armed = animator.actions = animator.actions.map(function (a) {
        var clip = a.getClip(), root = a.getRoot();
        a.stop();
        mixer.uncacheAction(clip, root);
        mixer.uncacheRoot(root);
        var fresh = mixer.clipAction(clip, root);
        fresh.clampWhenFinished = true;
        fresh.setLoop(%(loop)d, Infinity);
        return fresh;
      });
      animator.play();
      if (!cfg.autoplay) { animator.pause(); animator.seek(animator.duration); }
    }
    document.body.dataset.closedloop = "ready";
  }
  setInterval(arm, %(poll)d);
})();
</script>"""


_SLIDER = """<div id="closedloop-slider" style="position: fixed; left: 8px; bottom: 8px;
  z-index: 11; padding: 4px 8px; background: rgba(255, 255, 255, 0.88); border-radius: 4px;
  font: 12px sans-serif; box-shadow: 0 0 3px rgba(0, 0, 0, 0.3);">
  amplification <input id="closedloop-amplification" type="range" min="-1" max="1"
  step="0.01" value="0" style="width: 220px; vertical-align: middle;">
  <span id="closedloop-amplification-value">\u00d7%(scale).4g</span></div>
<script>
(function () {
  var base = %(base)r, range = %(range)r, input = document.getElementById(
    "closedloop-amplification"), label = document.getElementById(
    "closedloop-amplification-value");
  function value() { return base * Math.pow(range, parseFloat(input.value)); }
  input.addEventListener("input", function () {
    label.textContent = "\u00d7" + value().toPrecision(4) + " (release to apply)";
  });
  input.addEventListener("change", function () {
    var socket = viewer.connection, previous = socket.onmessage, pending = true;
    socket.onmessage = function (message) {
      previous(message);
      if (pending) { pending = false; setTimeout(function () { location.reload(); }, %(reload)d); }
    };
    socket.send(JSON.stringify({type: "closedloop", amplification: value()}));
    label.textContent = "\u00d7" + value().toPrecision(4) + " (redrawing)";
  });
})();
</script>"""


def _vector(v, digits: int = 4) -> str:
    """``(x, y, z)``; components below 1e-9 of the largest written as 0 (rounding)."""
    v = np.asarray(v, dtype=float)
    tiny = 1e-9 * float(np.max(np.abs(v))) if v.size else 0.0
    return "(" + ", ".join("0" if abs(x) <= tiny else f"{x:.{digits}g}" for x in v) + ")"


def _swatch(rgba, width: int = 22) -> str:
    r, g, b, a = (float(x) for x in rgba)
    colour = f"rgba({round(255 * r)}, {round(255 * g)}, {round(255 * b)}, {a:.2f})"
    return f'<span class="cl-swatch" style="background: {colour}; width: {width}px"></span>'


def _gradient(stops, width: int) -> str:
    """A horizontal colour bar (CSS gradient) of the RGB (0..1) ``stops``, ``width`` px."""
    colours = ", ".join(
        f"rgb({round(255 * r)}, {round(255 * g)}, {round(255 * b)})" for r, g, b in stops
    )
    return (
        f'<span class="cl-swatch" style="width: {width}px; '
        f'background: linear-gradient(to right, {colours})"></span>'
    )


def _hex_swatch(colour: int, alpha: float = 1.0) -> str:
    rgb = [(colour >> shift & 0xFF) / 255 for shift in (16, 8, 0)]
    return _swatch([*rgb, alpha])


def legend_rows(info: dict) -> list[str]:
    """The legend's text lines (HTML-escaped) from
    :func:`~closedloop.viewer.draw.legend_info` (for tests and page)."""
    w = np.asarray(info["wrench"], dtype=float)
    frame = info["frame"]
    rows = [f"pose: {info['pose']}"]
    if info.get("skeleton"):
        rows.append("no visual geometry: drawn as its skeleton, a sphere at each joint and "
                    "rods to the joints and frames each link carries")  # fmt: skip
    if info.get("mode"):
        return [html.escape(r) for r in rows + _mode_rows(info)]
    if np.any(w):
        rows.append(
            f"load at {frame} (world axes): force {_vector(w[:3])} N, moment {_vector(w[3:])} N m"
        )
    else:
        rows.append(f"no load at {frame}: the deflected pose is the nominal one")
    how = "automatic" if info["auto_scaled"] else "given"
    rows.append(
        f"deflection amplified \u00d7{info['scale']:.4g} ({how}; {info['kind']} deflection)"
    )
    d_mm, t = 1e3 * info["max_displacement"], np.asarray(info["frame_twist"], dtype=float)
    rows.append(
        f"largest point displacement {d_mm:.4g} mm (real), drawn as {info['scale'] * d_mm:.4g} mm"
    )
    rows += _amplification_rows(info)
    rows.append(
        f"{frame} moves {_vector(1e3 * t[:3])} mm (norm {1e3 * vector_norm(t[:3]):.4g} mm) "
        f"and turns {_vector(np.rad2deg(t[3:]))} deg (norm "
        f"{np.rad2deg(vector_norm(t[3:])):.4g} deg), world axes, real, "
        + ("first order" if info["kind"] == "linear" else "nonlinear equilibrium")
    )
    return [html.escape(r) for r in rows]


def _amplification_rows(info: dict) -> list[str]:
    """How the deflected pose is drawn: the largest link rotation, real and drawn, and the
    caps of the automatic amplification (:mod:`closedloop.viewer.motion`)."""
    w_deg, cap = np.rad2deg(info["max_rotation"]), np.rad2deg(info["rotation_cap"])
    shown = 1e3 * info["auto_fraction"] * info["size"]
    if info.get("reassembled"):
        drawn = "; drawn: the amplified joint deflection, its loops re-closed"
    else:
        drawn = (
            f", drawn as {info['scale'] * w_deg:.4g} deg; each link drawn rigidly along its "
            "own twist"
        )
    return [
        f"largest link rotation {w_deg:.4g} deg (real){drawn}; automatic caps: {shown:.4g} mm "
        f"({info['auto_fraction']:g} of the model size) and {cap:.3g} deg"
    ]


def _mode_rows(info: dict) -> list[str]:
    """The legend lines of a natural mode: its frequency and the amplification of its
    shape (per unit modal amplitude: a mode has no size of its own)."""
    mode, frame = info["mode"], info["frame"]
    how = "automatic" if info["auto_scaled"] else "given"
    d_mm, t = 1e3 * info["max_displacement"], np.asarray(info["frame_twist"], dtype=float)
    return [
        f"mode {mode['number']}: natural frequency {mode['frequency_hz']:.6g} Hz, swinging "
        "between \u00b1 its shape",
        f"shape amplified \u00d7{info['scale']:.4g} ({how}): largest point displacement "
        f"{d_mm:.4g} mm per unit modal amplitude (mass-normalised shape), drawn as "
        f"{info['scale'] * d_mm:.4g} mm",
        f"{frame} moves {_vector(1e3 * t[:3])} mm and turns {_vector(np.rad2deg(t[3:]))} deg "
        "per unit modal amplitude, world axes",
        *_amplification_rows(info),
    ]


def _headline(info: dict) -> str:
    """What the page shows: a deflection under a load, or a natural mode."""
    if info.get("mode"):
        mode = info["mode"]
        return f"{info['model']}: mode {mode['number']}, {mode['frequency_hz']:.6g} Hz"
    return f"{info['model']}: deflection under a load at {info['frame']}"


def legend_html(info: dict) -> str:
    """The legend ``<div>`` (module docstring) for the scene described by ``info``."""
    head = html.escape(_headline(info))
    key = [
        (_swatch(info["ghost_rgba"]), "nominal pose (unloaded), translucent ghost"),
    ]
    if info.get("colour_max") is not None:
        key.append(
            (
                _gradient(info["colormap"], 22),
                f"deflected pose, amplified \u00d7{info['scale']:.4g}, coloured by the real "
                "displacement of its surface (colour bar)",
            )
        )
    else:
        key.append(
            (
                "".join(
                    _swatch(c, 22 // min(4, len(info["deflected_rgba"])))
                    for c in info["deflected_rgba"][:4]
                ),
                f"deflected pose, amplified \u00d7{info['scale']:.4g}, model colours",
            )
        )
    length = f"{info['arrow_length']:.3g} m"
    if np.any(np.asarray(info["wrench"][:3])):
        key.append((_hex_swatch(info["force_color"]), f"force arrow (one head), length {length}"))
    if np.any(np.asarray(info["wrench"][3:])):
        key.append(
            (_hex_swatch(info["torque_color"]), f"moment arrow (two heads), length {length}")
        )
    for e in info["ellipsoids"]:
        what = "translation" if e["kind"] == "translation" else "rotation"
        scale = f"\u00d7{info['scale']:.4g}"
        if e["shrink"] < 1.0:
            scale += f", shrunk \u00d7{e['shrink']:.3g} to fit"
        key.append(
            (
                _hex_swatch(e["color"], 0.6),
                f"{what} compliance ellipsoid ({scale}), largest semi-axis "
                f"{max(e['radii_m']) * e['shrink']:.3g} m drawn",
            )
        )
    key.append((_hex_swatch(info["grid_color"]), f"grid: squares of {info['grid_step']:.3g} m"))
    table = "".join(
        f"<tr><td>{swatch}</td><td>{html.escape(text)}</td></tr>" for swatch, text in key
    )
    lines = "".join(f"<div>{r}</div>" for r in legend_rows(info))
    bar = ""
    if info.get("colour_max") is not None:
        top = 1e3 * info["colour_max"]
        ticks = "".join(
            f"<span>{html.escape(f'{t * top:.3g}')}</span>" for t in (0.0, 0.25, 0.5, 0.75, 1.0)
        )
        bar = (
            '<div class="cl-bar-title">|displacement| of the deflected surface, real, first '
            f"order [mm] (0 to {top:.4g} mm)</div>"
            f'<div class="cl-bar">{_gradient(info["colormap"], 300)}</div>'
            f'<div class="cl-ticks">{ticks}</div>'
        )
    return (
        f'<div id="closedloop-legend"><div class="cl-head">{head}</div>{lines}'
        f"<table>{table}</table>{bar}</div>"
    )


def overlay(
    info: dict | None,
    *,
    meshes: int,
    clips: int,
    autoplay: bool,
    robots: str,
    slider: float | None = None,
) -> dict:
    """The page overlay: title, legend (None: no legend), page script, live slider.

    Args:
        info: legend contents (:func:`legend_rows`), or None.
        meshes: number of robot meshes the scene holds when loaded.
        clips: number of animation clips (0: no animation).
        autoplay: play the load ramp at once.
        robots: name of the robots' node under ``/meshcat``.
        slider: amplification shown, for the live page's slider; None: no slider.
    """
    config = {"meshes": meshes, "clips": clips, "animate": clips > 0, "autoplay": autoplay}
    script = _SCRIPT % {
        "config": json.dumps(config),
        "robots": robots,
        "loop": LOOP_PING_PONG,
        "poll": POLL_MS,
    }
    title = "closedloop viewer"
    body = script
    if info is not None:
        shown = (
            _headline(info)
            if info.get("mode")
            else f"{info['model']}: deflection at {info['frame']}"
        )
        title = f"{shown} (closedloop viewer)"
        body = _STYLE + legend_html(info) + script
    if slider is not None:
        base = float(slider) if slider > 0.0 else 1.0
        body += _SLIDER % {
            "scale": slider,
            "base": base,
            "range": SLIDER_RANGE,
            "reload": RELOAD_MS,
        }
    return {"title": html.escape(title), "body": body}
