"""Registrations and reconstructions in the browser: an interactive 3D page served by
viser (its client ships in its wheel and needs no network), for a remote machine or a
notebook as well as a desktop.

``pip install '.[view]'`` in the project folder installs viser. Every function returns
the running ``viser.ViserServer`` (``block=False``) or serves until Ctrl-C.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .open3d_interop import to_point_cloud
from .registration.pose_graph import bridges
from .registration.result import SCAN_COLOURS

__all__ = ["COLOURS", "DISPLAY_POINTS", "served_address", "show_multiway", "show_registration"]

#: Most points drawn per cloud (an even stride through larger clouds).
DISPLAY_POINTS = 200_000
#: What each kind of thing is drawn in (0-255 RGB; clouds with their own colours keep
#: them, except the aligned source): no two alike, and the panel's legend says which.
COLOURS = {
    "source": (255, 127, 14),
    "target": (31, 119, 180),
    "aligned": (44, 160, 44),
    "matches_kept": (188, 189, 34),
    "matches_other": (214, 39, 40),
    "correspondences": (148, 103, 189),
    "pose_graph": (20, 20, 20),
    "unchecked_edges": (227, 119, 194),
}


def _viser():
    try:
        import viser
    except ImportError:
        raise ImportError(
            "the viewer needs viser: pip install '.[view]' in the project folder "
            "(or pip install viser)"
        ) from None
    return viser


def _display(points: np.ndarray, limit: int) -> np.ndarray:
    if len(points) <= limit:
        return points
    return points[:: int(np.ceil(len(points) / limit))]


def _colours(cloud, default) -> np.ndarray | tuple:
    """A cloud's own colours as 0-255 bytes, or ``default``."""
    if cloud.has_colors():
        return (np.asarray(cloud.colors) * 255).round().astype(np.uint8)
    return default


def _toggle(server, label: str, handles: list, initial: bool = True):
    box = server.gui.add_checkbox(label, initial)

    @box.on_update
    def _(_event) -> None:
        for handle in handles:
            handle.visible = box.value

    for handle in handles:
        handle.visible = initial
    return box


def _frame(server, extent: float) -> None:
    """Point the first view at the scene (centred on the origin) from a distance that
    shows all of it, with z up."""
    extent = max(float(extent), 1e-9)
    server.initial_camera.look_at = (0.0, 0.0, 0.0)
    server.initial_camera.position = (0.6 * extent, -0.6 * extent, 0.45 * extent)
    server.initial_camera.up = (0.0, 0.0, 1.0)
    server.initial_camera.near = extent * 1e-3
    server.initial_camera.far = extent * 100


def _own_address() -> str:
    """This machine's address on its default route (a UDP socket is pointed there, which
    sends nothing), else its host name."""
    import socket

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: never answered, never sent to
            return probe.getsockname()[0]
    except OSError:
        return socket.gethostname()


def served_address(host: str, port: int) -> str:
    """The address a browser opens for a server bound to ``host``: the host itself, or
    for every interface (``0.0.0.0``, ``::``, ``""``) this machine's address on its
    default route, which other machines reach (the local address works on this one)."""
    if host in ("0.0.0.0", "::", ""):
        return (
            f"http://{_own_address()}:{port} (every interface; on this machine "
            f"http://127.0.0.1:{port})"
        )
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}"


def _legend(items: list[tuple[str, tuple[int, int, int]]]) -> str:
    """The panel's legend: a coloured square and a label per drawn thing."""
    import html

    rows = "".join(
        f'<div style="display:flex;align-items:center;gap:6px;margin:2px 0">'
        f'<span style="display:inline-block;width:12px;height:12px;'
        f'background:rgb{tuple(colour)}"></span>{html.escape(label)}</div>'
        for label, colour in items
    )
    return f'<div style="font-size:0.85em"><b>Legend</b>{rows}</div>'


def _serve(server, block: bool, host: str = "127.0.0.1"):
    if block:
        address = served_address(host, server.get_port())
        print(f"viewer: {address} (Ctrl-C to stop)", flush=True)
        try:
            server.sleep_forever()
        except KeyboardInterrupt:
            pass
        finally:
            server.stop()
    return server


def _points(cloud, origin, limit):
    pts = _display(np.asarray(cloud.points) - origin, limit)
    colours = _colours(cloud, None)
    if isinstance(colours, np.ndarray):
        colours = _display(colours, limit)
    return pts, colours


def show_registration(
    source: Any,
    target: Any,
    result: Any,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    point_size: float | None = None,
    max_lines: int = 500,
    block: bool = True,
):
    """Serve a pair registration: the source as given, the target, the aligned source,
    the global step's descriptor matches as lines (those its estimate kept, and the
    others; drawn between the clouds as given) and the result's inlier correspondences,
    each toggled from the panel, which also shows the result's numbers and flags.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        The clouds that were registered (their own colours are kept; others are drawn
        orange, blue and green).
    result : RegistrationResult
        Or anything with ``transformation`` (a 4x4 from elsewhere): then only the
        clouds are drawn.
    host, port : where to serve (``127.0.0.1``: this machine only; ``0.0.0.0`` to reach
        it from another machine).
    point_size : float, default=None
        In the clouds' units; ``None`` is the result's resolution (or 1 % of the
        target's extent).
    max_lines : int, default=500
        Most lines drawn per kind (an even stride through them).
    block : bool, default=True
        Serve until Ctrl-C; ``False`` returns the running server at once.

    Returns
    -------
    viser.ViserServer
    """
    viser = _viser()
    src, tgt = to_point_cloud(source, "source"), to_point_cloud(target, "target")
    transformation = np.asarray(result.transformation, dtype=np.float64)
    origin = np.asarray(tgt.get_center())  # survey coordinates stay precise on screen
    extent = float(np.linalg.norm(tgt.get_max_bound() - tgt.get_min_bound()))
    size = point_size or getattr(result, "voxel_size", 0.0) or 0.01 * extent
    server = viser.ViserServer(host=host, port=port, verbose=False)
    _frame(server, extent)
    limit = DISPLAY_POINTS
    aligned = to_point_cloud(source, "source").transform(transformation)
    handles = {}
    legend = []
    for name, label, cloud in (
        ("source", "source (as given)", src),
        ("target", "target", tgt),
        ("aligned", "aligned source", aligned),
    ):
        colour = COLOURS[name]
        pts, own = _points(cloud, origin, limit)
        kept_own = own is not None and name != "aligned"
        legend.append((label + (" (its own colours)" if kept_own else ""), colour))
        handles[name] = server.scene.add_point_cloud(
            f"/{name}",
            pts.astype(np.float32),
            own if kept_own else colour,
            point_size=size,
            precision="float32",
        )
    step = next(
        (t for t in getattr(result, "steps", []) if getattr(t, "matches", None) is not None),
        None,
    )
    toggles = []
    if step is not None and len(step.matches):  # the global step's descriptor matches
        ends = step.matches - origin
        inside = np.asarray(step.match_inliers, dtype=bool)
        for label, keep, colour, node in (
            ("global step: matches it kept", inside, COLOURS["matches_kept"], "/matches_kept"),
            ("global step: other matches", ~inside, COLOURS["matches_other"], "/matches_other"),
        ):
            chosen = ends[keep][:: max(1, int(np.ceil(keep.sum() / max_lines)))]
            if len(chosen):
                handle = server.scene.add_line_segments(
                    node,
                    chosen.astype(np.float32),
                    colour,
                    thickness=size / 4,
                )
                toggles.append((label, handle, False))
                legend.append((label, colour))
    pairs = np.asarray(getattr(result, "correspondence_set", np.empty((0, 2))), dtype=np.int64)
    if len(pairs):
        pairs = pairs[:: max(1, int(np.ceil(len(pairs) / max_lines)))]
        ends = np.stack(
            [
                np.asarray(src.points)[pairs[:, 0]] - origin,
                np.asarray(tgt.points)[pairs[:, 1]] - origin,
            ],
            axis=1,
        )
        handle = server.scene.add_line_segments(
            "/correspondences",
            ends.astype(np.float32),
            COLOURS["correspondences"],
            thickness=size / 4,
        )
        toggles.append(("inlier correspondences", handle, False))
        legend.append(("inlier correspondences", COLOURS["correspondences"]))
    server.gui.add_markdown(_summary(result, len(pairs), step))
    server.gui.add_html(_legend(legend))
    _toggle(server, "source (as given)", [handles["source"]], initial=False)
    _toggle(server, "target", [handles["target"]])
    _toggle(server, "aligned source", [handles["aligned"]])
    for label, handle, initial in toggles:
        _toggle(server, label, [handle], initial=initial)
    return _serve(server, block, host)


def _summary(result, n_lines: int, step=None) -> str:
    rows = ["**Registration**", ""]
    for label, attr, fmt in (
        ("fitness", "fitness", "{:.3f}"),
        ("inlier RMSE", "inlier_rmse", "{:.4g}"),
        ("distance", "distance", "{:.4g}"),
        ("resolution", "voxel_size", "{:.4g}"),
        ("seconds", "seconds", "{:.2f}"),
        ("converged", "converged", "{}"),
        ("ambiguous", "ambiguous", "{}"),
    ):
        if hasattr(result, attr):
            rows.append(f"- {label}: {fmt.format(getattr(result, attr))}")
    for each in getattr(result, "steps", []):
        rows.append(f"- step {each.name}: fitness {each.fitness:.3f}, {each.seconds:.2f} s")
    if step is not None:
        kept = int(np.asarray(step.match_inliers).sum())
        rows.append(f"- global step: {kept} of {len(step.matches)} matches kept")
    if n_lines:
        rows.append(f"- {n_lines} inlier correspondences to draw")
    return "\n".join(rows)


def show_multiway(
    scans: list[Any],
    result: Any,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    point_size: float | None = None,
    block: bool = True,
    names: list[str] | None = None,
):
    """Serve a reconstruction: every placed scan in its own colour (toggled one by one),
    the pose graph's kept edges as lines between the scans' centres (the edges no loop
    checks, :meth:`MultiwayResult.unverified`'s, in a colour of their own), and the
    result's numbers and a legend in the panel.

    Parameters
    ----------
    scans : list of array-like or Open3D point clouds
        The scans given to :func:`~o3d_rpointhop.register_multiway`, in order.
    result : MultiwayResult
    host, port, point_size, block
        As in :func:`show_registration` (``point_size=None``: the common resolution).
    names : list of str, default=None
        What to call each scan (its file name, say); ``None``: ``scan 0``, ``scan 1``...

    Returns
    -------
    viser.ViserServer
    """
    viser = _viser()
    if len(scans) != len(result.poses):
        raise ValueError(f"{len(result.poses)} scans were registered, got {len(scans)}")
    names = [f"scan {k}" for k in range(len(scans))] if names is None else list(names)
    if len(names) != len(scans):
        raise ValueError(f"{len(names)} names for {len(scans)} scans")
    placed = {}
    for k, (scan, pose) in enumerate(zip(scans, result.poses, strict=True)):
        if pose is not None:
            placed[k] = to_point_cloud(scan, f"scans[{k}]").transform(pose)
    if not placed:
        raise ValueError("no scan was placed")
    origin = np.asarray(placed[0].get_center()) if 0 in placed else np.zeros(3)
    size = point_size or result.voxel_size or 0.01
    server = viser.ViserServer(host=host, port=port, verbose=False)
    every = np.concatenate([np.asarray(c.points) for c in placed.values()]) - origin
    _frame(server, float(np.linalg.norm(every.max(axis=0) - every.min(axis=0))))
    limit = max(1, DISPLAY_POINTS // len(placed))
    centres = {}
    boxes = []
    for k, cloud in placed.items():
        pts = _display(np.asarray(cloud.points) - origin, limit)
        centres[k] = pts.mean(axis=0)
        colour = tuple(int(round(255 * c)) for c in SCAN_COLOURS[k % len(SCAN_COLOURS)])
        handle = server.scene.add_point_cloud(
            f"/scan_{k}", pts.astype(np.float32), colour, point_size=size, precision="float32"
        )
        boxes.append((names[k], handle, colour))
    edges = [(i, j) for i, j in result.edges if i in centres and j in centres]
    # Bridges (edges no loop checks: MultiwayResult.unverified) apart, in their colour.
    unchecked = {edge for edge, _ in bridges(edges, result.frame)}
    graph, bridge_lines = [], []
    for kind, chosen, out in (
        ("pose_graph", [e for e in edges if e not in unchecked], graph),
        ("unchecked_edges", sorted(unchecked), bridge_lines),
    ):
        if chosen:
            ends = np.array([[centres[i], centres[j]] for i, j in chosen], dtype=np.float32)
            out.append(
                server.scene.add_line_segments(f"/{kind}", ends, COLOURS[kind], thickness=2 * size)
            )
    rows = [
        "**Reconstruction**",
        "",
        f"- {len(placed)} of {len(result.poses)} scans placed",
        f"- {len(result.edges)} edges kept",
        f"- resolution {result.voxel_size:.4g}, {result.seconds:.1f} s",
    ]
    if result.unconnected:
        rows.append(f"- unconnected: {', '.join(names[k] for k in result.unconnected)}")
    unverified = result.unverified(names)
    if unverified:
        rows.append(f"- {len(unverified)} scans joined by edges no loop checks")
    server.gui.add_markdown("\n".join(rows))
    legend = [(label, colour) for label, _, colour in boxes]
    if graph:
        legend.append(("pose graph edges", COLOURS["pose_graph"]))
    if bridge_lines:
        legend.append(("edges no loop checks", COLOURS["unchecked_edges"]))
    server.gui.add_html(_legend(legend))
    for label, handle, _ in boxes:
        _toggle(server, label, [handle])
    if graph:
        _toggle(server, "pose graph edges", graph)
    if bridge_lines:
        _toggle(server, "edges no loop checks", bridge_lines)
    return _serve(server, block, host)
