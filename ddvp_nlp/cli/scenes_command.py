"""``ddvp scenes``: each built-in scene with its parameters, run defaults, description, start,
fixed-endpoint data and default scheme."""

from __future__ import annotations

import textwrap

from ..discrete import Scheme
from ..scenes import HigherOrderScene, list_scenes, load_scene


def _describe(name: str) -> str:
    """A scene's entry of ``ddvp scenes``: parameters and run defaults, description, initial
    state, fixed-endpoint data and the scheme ``march`` and ``bvp`` use by default."""
    scene = load_scene(name)
    params = ", ".join(f"{k}={v:g}" for k, v in scene.params.items())
    defaults = f"t0={scene.t0:g} tau0={scene.tau0:g} t_end={scene.t_end:g}"
    scheme = (f"{scene.scheme} (the scene's)" if scene.scheme
              else f"{Scheme().rule} (default)")
    indent = " " * 17
    lines = [f"{name:16s} n={scene.n}  {params + '  ' if params else ''}{defaults}",
             *textwrap.wrap(scene.description, SCENES_WIDTH, initial_indent=indent,
                            subsequent_indent=indent, break_on_hyphens=False)]
    if isinstance(scene, HigherOrderScene):
        lines.append(f"{indent}start: the exact motion at {2 * scene.order} nodes tau0 apart "
                     "from t0")
        ends = scene.boundary
        span = (ends and ends.t_span) or (scene.t0, scene.t_end)
        lines.append(f"{indent}fixed ends: the exact motion's {scene.order} first and last "
                     f"nodes, t in [{span[0]:g}, {span[1]:g}], {scene.boundary_nodes()} "
                     f"nodes")
    else:
        config = scene.resolve({})
        start = (f"p0={_vector(config.p0)}" if config.p0 is not None
                 else f"v0={_vector(config.v0)}")
        lines.append(f"{indent}start: q0={_vector(config.q0)} {start}")
        lines.append(f"{indent}fixed ends: {_boundary(scene)}")
    lines.append(f"{indent}scheme: {scheme}")
    return "\n".join(lines)


# Width of the descriptions of `ddvp scenes`, wrapped at words (a terminal's 100 columns).
SCENES_WIDTH = 96


def _vector(values) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


def _boundary(scene) -> str:
    if scene.boundary is None:
        return "none (give --set q_start=... --set q_end=... --set t_end=... --nodes N)"
    data = scene.resolve_boundary({})
    return (f"q_start={_vector(data.q_start)} q_end={_vector(data.q_end)}, "
            f"t in [{data.t_span[0]:g}, {data.t_span[1]:g}], {data.nodes} nodes")


def run_scenes(args) -> int:
    print("\n\n".join(_describe(name) for name in list_scenes()))
    return 0
