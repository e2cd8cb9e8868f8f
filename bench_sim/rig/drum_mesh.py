"""Drum geometry as triangle meshes (trimesh): the body with end caps, the axle, two mounts
(pillow blocks) and the bench plate. Used when ``drum.geometry = "mesh"``.

World frame as in :mod:`bench_sim.rig.geometry`: the drum axis is ``x``, the camera is at ``+z``.
The body is a smooth-shaded tube (vertex normals point radially) with flat end caps built as
separate meshes so the rim does not smooth the tube's normals. The body carries UVs:
``u = theta / 2pi`` around the circumference, ``v`` along the axis.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from bench_sim.config import DrumConfig

if TYPE_CHECKING:
    import trimesh

__all__ = ["drum_meshes"]


def _tube(radius: float, length: float, segments: int) -> trimesh.Trimesh:
    """Open tube around the x axis, ``segments`` facets, with radial vertex normals and UVs."""
    import trimesh  # lazy: the scene module (and the CLI above it) stays light

    n = segments
    phi = np.linspace(0.0, 2.0 * np.pi, n + 1)  # duplicate seam column for UVs
    x = np.array([-0.5 * length, 0.5 * length])
    yy = radius * np.cos(phi)
    zz = radius * np.sin(phi)
    verts = np.concatenate(
        [np.stack([np.full(n + 1, xi), yy, zz], axis=1) for xi in x], axis=0
    )
    normals = np.concatenate([np.stack([np.zeros(n + 1), np.cos(phi), np.sin(phi)], axis=1)] * 2)
    theta = np.mod(np.arctan2(-yy, zz), 2.0 * np.pi)
    uv = np.concatenate([np.stack([theta / (2 * np.pi), np.full(n + 1, vi)], axis=1) for vi in (0.0, 1.0)])
    a = np.arange(n)
    b = a + n + 1
    # outward-facing winding (normals radially out)
    faces = np.concatenate([np.stack([a, a + 1, b + 1], 1), np.stack([a, b + 1, b], 1)])
    mesh = trimesh.Trimesh(verts, faces, vertex_normals=normals, process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv)
    if np.mean(np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center * [0, 1, 1])) < 0:
        mesh.invert()
    return mesh


def _cap(radius: float, x: float, segments: int, outward: float) -> trimesh.Trimesh:
    import trimesh

    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([np.full(segments, x), radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    verts = np.concatenate([[[x, 0.0, 0.0]], ring])
    i = np.arange(segments)
    faces = np.stack([np.zeros(segments, int), 1 + i, 1 + (i + 1) % segments], axis=1)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    if np.sign(mesh.face_normals[0, 0]) != np.sign(outward):
        mesh.invert()
    return mesh


def drum_meshes(drum: DrumConfig) -> dict[str, trimesh.Trimesh]:
    """Meshes of the rig's mechanics, keyed by part.

    Returns
    -------
    dict
        ``body`` (the target-carrying tube), ``caps`` (both end caps), ``axle``, ``mounts`` and,
        if ``drum.bench``, ``bench``. Units: metres.
    """
    import trimesh

    R, L, n = drum.radius_m, drum.length_m, drum.mesh_segments
    parts: dict[str, trimesh.Trimesh] = {"body": _tube(R, L, n)}
    caps = trimesh.util.concatenate([_cap(R, -0.5 * L, n, -1.0), _cap(R, 0.5 * L, n, 1.0)])
    parts["caps"] = cast("trimesh.Trimesh", caps)  # concatenate() is typed as returning a Geometry
    axle_len = L + 2.0 * drum.axle_overhang_m
    axle = trimesh.creation.cylinder(radius=drum.axle_radius_m, height=axle_len, sections=64)
    axle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    parts["axle"] = axle
    floor_y = -(R + 0.05)
    mount_h = -floor_y
    mounts = []
    for sx in (-1.0, 1.0):
        box = trimesh.creation.box(extents=[0.03, mount_h, 0.06])
        box.apply_translation([sx * (0.5 * L + 0.5 * drum.axle_overhang_m), floor_y + 0.5 * mount_h, 0])
        mounts.append(box)
    parts["mounts"] = cast("trimesh.Trimesh", trimesh.util.concatenate(mounts))
    if drum.bench:
        bench = trimesh.creation.box(extents=[L + 4 * drum.axle_overhang_m, 0.02, 4 * R])
        bench.apply_translation([0.0, floor_y - 0.01, 0.0])
        parts["bench"] = bench
    return parts
